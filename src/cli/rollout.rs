//! `dhrl rollout`.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use dhrl::delay::{DelayArgs, DelayConfig};
use dhrl::rollout::{read_actions, read_state, rollout};
use dhrl::tasks::TaskName;

#[derive(Args)]
pub struct RolloutArgs {
    #[arg(long, value_enum)]
    task: TaskName,
    /// JSON file {"qpos": [...], "qvel": [...]}.
    #[arg(long)]
    init_state: PathBuf,
    /// CSV file, one action per line, comma-separated.
    #[arg(long)]
    actions: PathBuf,
    /// Any delay option turns the trace into what the delayed agent receives.
    #[command(flatten)]
    delay: DelayArgs,
    /// Seed of actuator noise and random delays.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(args: &RolloutArgs) -> anyhow::Result<()> {
    let state = read_state(&args.init_state)?;
    let actions = read_actions(&args.actions, args.task)?;
    let delay = if args.delay.any() {
        Some(args.delay.apply(DelayConfig::default())?)
    } else {
        None
    };
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let mut write_error = None;
    rollout(
        args.task,
        &state,
        &actions,
        delay.as_ref(),
        args.seed,
        |step| {
            if write_error.is_none()
                && let Err(e) = serde_json::to_writer(&mut out, step)
                    .map_err(std::io::Error::from)
                    .and_then(|_| writeln!(out))
            {
                write_error = Some(e);
            }
        },
    )?;
    match write_error.map_or_else(|| out.flush(), Err) {
        // A reader that stops early (`| head`) is not an error.
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        result => result.context("writing the trace to stdout"),
    }
}
