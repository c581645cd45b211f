//! `dhrl eval`.
use std::path::PathBuf;

use clap::Args;

use dhrl::delay::DelayArgs;
use dhrl::train::evaluate_saved;

#[derive(Args)]
pub struct EvalArgs {
    /// A run folder written by `dhrl train`.
    run: PathBuf,
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Evaluate under other delay options than the run's (those not given keep the run's).
    #[command(flatten)]
    delay: DelayArgs,
    /// Evaluate D2HPG's delay-free policy in the undelayed task instead of the regular one.
    #[arg(long)]
    delay_free_policy: bool,
    #[arg(long, default_value_t = 12345)]
    seed: u64,
}

pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    let result = evaluate_saved(
        &args.run,
        args.episodes,
        &args.delay,
        args.delay_free_policy,
        args.seed,
    )?;
    println!(
        "return {:.2} ± {:.2} over {} episodes (mean length {:.1})",
        result.return_mean, result.return_std, result.episodes, result.length_mean
    );
    Ok(())
}
