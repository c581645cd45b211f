//! `dhrl plot`.
use std::path::PathBuf;

use clap::Args;

use dhrl::train::{plot_curves, summarize_runs};

#[derive(Args)]
pub struct PlotArgs {
    /// Run folders written by `dhrl train`.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    #[arg(long, value_name = "FILE.svg")]
    out: PathBuf,
    #[arg(long, default_value = "Evaluation return")]
    title: String,
}

pub fn run(args: &PlotArgs) -> anyhow::Result<()> {
    let curves = summarize_runs(&args.runs)?;
    println!("| runs | seeds | final step | final return (mean ± std) |");
    println!("|---|---|---|---|");
    for curve in &curves {
        if let Some((step, mean, std)) = curve.last() {
            let seeds: Vec<String> = curve.seeds.iter().map(u64::to_string).collect();
            println!(
                "| {} | {} | {step} | {mean:.1} ± {std:.1} |",
                curve.label,
                seeds.join(", ")
            );
        }
    }
    plot_curves(&curves, &args.title, &args.out)?;
    println!("plot: {}", args.out.display());
    Ok(())
}
