//! `dhrl train`: its arguments and their rules live in the library (`dhrl::train::TrainArgs`).
use dhrl::train::{TrainArgs, train};

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    if args.help_config {
        print!("{}", args.config()?.algo.describe());
        return Ok(());
    }
    let plan = args.plan()?;
    dhrl::train::stop_on_signals()?;
    eprintln!("run folder: {}", plan.run.display());
    let summary = train(
        &plan.config,
        &plan.run,
        plan.start,
        std::io::IsTerminal::is_terminal(&std::io::stderr()),
    )?;
    match summary.last_eval {
        Some(e) => println!(
            "{} env steps, {} updates in {:.0} s; last evaluation: return {:.1} ± {:.1} over {} episodes (mean length {:.0})",
            summary.env_steps,
            summary.updates,
            summary.wall_seconds,
            e.return_mean,
            e.return_std,
            e.episodes,
            e.length_mean
        ),
        None => println!(
            "{} env steps, {} updates in {:.0} s",
            summary.env_steps, summary.updates, summary.wall_seconds
        ),
    }
    Ok(())
}
