//! `dhrl report`.
use std::path::PathBuf;

use clap::Args;

use dhrl::report::write_report;

#[derive(Args)]
pub struct ReportArgs {
    /// Run folders written by `dhrl train`, or sweep folders (every run of the sweep with an
    /// evaluation).
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The folder the tables, the aggregate, returns.csv and the figures go to.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Stratified-bootstrap resamples for the 95% intervals.
    #[arg(long, default_value_t = 10_000)]
    bootstrap: usize,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let report = write_report(&args.runs, &args.out, args.bootstrap)?;
    println!(
        "{} runs{}",
        report.runs,
        if report.skipped > 0 {
            format!(
                " ({} more without an evaluation yet, left out)",
                report.skipped
            )
        } else {
            String::new()
        }
    );
    println!("{}", report.table_markdown);
    println!("{}", report.aggregate_markdown);
    for file in &report.files {
        println!("wrote {}", file.display());
    }
    Ok(())
}
