//! The `dhrl` command line.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};

use dhrl::bench::bench_env;
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
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Batched simulator steps per second beside a raw single-thread `mj_step` loop.
    Env(BenchEnvArgs),
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
        Command::Tabular(args) => run_tabular(&args),
        Command::TabularBench(args) => run_tabular_bench(&args),
    }
}

fn run_rollout(args: &RolloutArgs) -> anyhow::Result<()> {
    let state = read_state(&args.init_state)?;
    let actions = read_actions(&args.actions, args.task)?;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let mut write_error = None;
    rollout(args.task, &state, &actions, |step| {
        if write_error.is_none()
            && let Err(e) = serde_json::to_writer(&mut out, step)
                .map_err(std::io::Error::from)
                .and_then(|_| writeln!(out))
        {
            write_error = Some(e);
        }
    })?;
    match write_error.map_or_else(|| out.flush(), Err) {
        // A reader that stops early (`| head`) is not an error.
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        result => result.context("writing the trace to stdout"),
    }
}

fn run_bench_env(args: &BenchEnvArgs) -> anyhow::Result<()> {
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
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
