//! `dhrl rollout`.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use dhrl::delay::{DelayArgs, DelayConfig, DelayDevice};
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
    /// Where the delayed trace's delay layer runs (its ring buffers on the CPU, or in WGSL
    /// kernels on any Vulkan adapter); cpu unless given. Giving it asks for the delayed trace.
    #[arg(long, value_enum)]
    delay_device: Option<DelayDevice>,
    /// Seed of actuator noise and random delays.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(args: &RolloutArgs) -> anyhow::Result<()> {
    let state = read_state(&args.init_state)?;
    let actions = read_actions(&args.actions, args.task)?;
    let delay = if args.delay.any() || args.delay_device.is_some() {
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
        delay
            .as_ref()
            .map(|config| (config, args.delay_device.unwrap_or_default())),
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
