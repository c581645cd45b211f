//! `dhrl export`.
use std::path::PathBuf;

use clap::Args;

use dhrl::export::export_run;

#[derive(Args)]
pub struct ExportArgs {
    /// A run folder written by `dhrl train`.
    run: PathBuf,
    /// Where the files go (default: RUN/export).
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    let out = args.out.clone().unwrap_or_else(|| args.run.join("export"));
    let summary = export_run(&args.run, &out)?;
    let manifest = &summary.manifest;
    println!(
        "exported {} ({} on {}, Δ = {}) to {}:",
        manifest.algorithm,
        manifest.network.kind,
        manifest.task,
        manifest.delay.total,
        out.display()
    );
    for file in &summary.files {
        println!("  {}", file.display());
    }
    println!(
        "the runtime reproduced training's x_t and actions at all {} recorded decisions ({} by the policy)",
        summary.check_steps, summary.check_policy_steps
    );
    Ok(())
}
