//! `dhrl train`: its arguments and their rules live in the library (`dhrl::train::TrainArgs`).
use dhrl::train::{TrainArgs, TrainSummary, train, train_seeds};

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    if args.help_config {
        print!("{}", args.config()?.algo.describe());
        return Ok(());
    }
    let plan = args.plan()?;
    dhrl::train::stop_on_signals()?;
    let progress = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let Some(seeds) = &plan.seeds else {
        eprintln!("run folder: {}", plan.run.display());
        let summary = train(&plan.config, &plan.run, plan.start, progress)?;
        println!("{}", describe(&summary));
        eprintln!("{}", next_steps(&plan.run));
        return Ok(());
    };
    eprintln!(
        "stack of {} runs (seeds {seeds:?}) in {}",
        seeds.len(),
        plan.run.display()
    );
    let results = train_seeds(&plan.config, &plan.run, seeds, plan.start, progress)?;
    let mut failed = Vec::new();
    for (run, result) in &results {
        match result {
            Ok(summary) => println!("{}: {}", run.display(), describe(summary)),
            Err(e) => {
                println!("{}: failed: {e}", run.display());
                failed.push(run.display().to_string());
            }
        }
    }
    eprintln!("{}", next_steps(&plan.run));
    match (failed.len(), results.len()) {
        (0, _) => Ok(()),
        (n, total) if n == total => anyhow::bail!("all {n} runs failed ({})", failed.join(", ")),
        (n, total) => anyhow::bail!(
            "{n} of {total} runs failed ({}); the others finished",
            failed.join(", ")
        ),
    }
}

/// The closing line: where to look next.
fn next_steps(run: &std::path::Path) -> String {
    let run = run.display();
    format!(
        "next: {run} holds config.toml, evals.csv, train.csv and the checkpoint; \
         `dhrl plot {run} --out curve.svg` draws the learning curve, \
         `tensorboard --logdir {run}` shows every logged column, \
         `dhrl eval {run}` scores the policy, `dhrl export {run}` writes it for deployment"
    )
}

fn describe(summary: &TrainSummary) -> String {
    match summary.last_eval {
        Some(e) => format!(
            "{} env steps, {} updates in {:.0} s; last evaluation: return {:.1} ± {:.1} over {} episodes (mean length {:.0})",
            summary.env_steps,
            summary.updates,
            summary.wall_seconds,
            e.return_mean,
            e.return_std,
            e.episodes,
            e.length_mean
        ),
        None => format!(
            "{} env steps, {} updates in {:.0} s",
            summary.env_steps, summary.updates, summary.wall_seconds
        ),
    }
}
