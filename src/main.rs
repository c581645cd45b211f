//! The `dhrl` command line.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};

use dhrl::bench::{bench_delay, bench_env};
use dhrl::delay::{DelayArgs, DelayConfig};
use dhrl::rollout::{read_actions, read_state, rollout};
use dhrl::tabular::{TabularArgs, TabularBenchArgs, run_tabular, run_tabular_bench};
use dhrl::tasks::TaskName;

#[derive(Parser)]
#[command(
    name = "dhrl",
    version,
    about = "Delayed homomorphic RL on batched MuJoCo tasks"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Trace one episode from a given state and action sequence, one JSON object per line.
    Rollout(RolloutArgs),
    /// Measure throughput.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Finite-domain DHRL: augmented MDP, belief abstraction and the paper's guarantees.
    Tabular(TabularArgs),
    /// Q-learning sample complexity on the augmented vs the abstract MDP, across delays.
    TabularBench(TabularBenchArgs),
}

#[derive(Args)]
struct RolloutArgs {
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

#[derive(Subcommand)]
enum BenchCommand {
    /// Batched simulator steps per second beside a raw single-thread `mj_step` loop.
    Env(BenchEnvArgs),
    /// The delay layer alone, on CPU and GPU, beside the simulation step it adds to.
    Delay(BenchDelayArgs),
}

#[derive(Args)]
struct BenchDelayArgs {
    #[arg(long, value_enum, default_value_t = TaskName::HalfCheetah)]
    task: TaskName,
    /// Copies (comma-separated list).
    #[arg(long, value_delimiter = ',', default_values_t = [1024, 4096, 16384])]
    envs: Vec<usize>,
    /// Total delays Δ (comma-separated list).
    #[arg(long, value_delimiter = ',', default_values_t = [5, 10, 20])]
    delay: Vec<usize>,
    /// Simulation threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Steps timed per configuration.
    #[arg(long, default_value_t = 20)]
    steps: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct BenchEnvArgs {
    #[arg(long, value_enum, default_value_t = TaskName::HalfCheetah)]
    task: TaskName,
    /// Copies stepped in parallel.
    #[arg(long, default_value_t = 1024)]
    envs: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Batched steps to time.
    #[arg(long, default_value_t = 100)]
    steps: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Rollout(args) => run_rollout(&args),
        Command::Bench(BenchCommand::Env(args)) => run_bench_env(&args),
        Command::Bench(BenchCommand::Delay(args)) => run_bench_delay(&args),
        Command::Tabular(args) => run_tabular(&args),
        Command::TabularBench(args) => run_tabular_bench(&args),
    }
}

fn run_rollout(args: &RolloutArgs) -> anyhow::Result<()> {
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

fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn run_bench_delay(args: &BenchDelayArgs) -> anyhow::Result<()> {
    let threads = args.threads.unwrap_or_else(all_cores);
    if !args.json {
        println!(
            "{:<14} {:>6} {:>5} {:>14} {:>14} {:>9} {:>14} {:>9}  gpu adapter",
            "task",
            "envs",
            "delay",
            "sim steps/s",
            "cpu delay/s",
            "cpu share",
            "gpu delay/s",
            "gpu share"
        );
    }
    for &envs in &args.envs {
        for row in bench_delay(args.task, envs, &args.delay, threads, args.steps, args.seed)? {
            if args.json {
                println!("{}", serde_json::to_string(&row)?);
                continue;
            }
            let or_dash = |v: Option<String>| v.unwrap_or_else(|| "-".to_string());
            println!(
                "{:<14} {:>6} {:>5} {:>14.0} {:>14.0} {:>8.2}% {:>14} {:>9}  {}",
                row.task.as_str(),
                row.envs,
                row.delay,
                row.sim_env_steps_per_sec,
                row.cpu_env_steps_per_sec,
                100.0 * row.cpu_share_of_sim_step,
                or_dash(row.gpu_env_steps_per_sec.map(|v| format!("{v:.0}"))),
                or_dash(
                    row.gpu_share_of_sim_step
                        .map(|v| format!("{:.2}%", 100.0 * v))
                ),
                row.gpu_adapter.as_deref().unwrap_or("none"),
            );
        }
    }
    Ok(())
}

fn run_bench_env(args: &BenchEnvArgs) -> anyhow::Result<()> {
    let threads = args.threads.unwrap_or_else(all_cores);
    let report = bench_env(args.task, args.envs, threads, args.steps, args.seed)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{:<18} {:>6} {:>7} {:>16} {:>20} {:>7}",
            "task", "envs", "threads", "env steps/s", "raw mj_step env/s", "ratio"
        );
        println!(
            "{:<18} {:>6} {:>7} {:>16.0} {:>20.0} {:>7.2}",
            report.task.as_str(),
            report.envs,
            report.threads,
            report.env_steps_per_sec,
            report.raw_env_steps_per_sec,
            report.ratio
        );
    }
    Ok(())
}
