//! `dhrl bench env|delay|update`: each prints its figures beside the anchor measured in the
//! same run.
use clap::{Args, Subcommand};

use dhrl::algos::{AlgoSettings, names, parse_assignment, reference};
use dhrl::bench::{bench_delay, bench_env, bench_update};
use dhrl::learn::LearnDevice;
use dhrl::protocol::Protocol;
use dhrl::tasks::TaskName;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Batched simulator steps per second beside a raw single-thread `mj_step` loop.
    Env(BenchEnvArgs),
    /// The delay layer alone, on CPU and GPU, beside the simulation step it adds to.
    Delay(BenchDelayArgs),
    /// Gradient updates per second of an algorithm at a task's sizes.
    Update(BenchUpdateArgs),
}

#[derive(Args)]
pub struct BenchUpdateArgs {
    #[arg(long, default_value_t = reference().name.to_string(), value_parser = clap::builder::PossibleValuesParser::new(names()))]
    algo: String,
    /// Set a field of the algorithm's configuration (repeatable), e.g. --set lifting_weight=10.
    #[arg(long = "set", value_name = "FIELD=VALUE")]
    set: Vec<String>,
    #[arg(long, value_enum, default_value_t = TaskName::HalfCheetah)]
    task: TaskName,
    /// Total delay Δ (sizes the augmented input).
    #[arg(long, default_value_t = 0)]
    delay: usize,
    #[arg(long, default_value_t = 256)]
    batch_size: usize,
    #[arg(long, value_enum, default_value_t = LearnDevice::Cpu)]
    device: LearnDevice,
    /// Updates to time, one environment step each; work scheduled by environment steps
    /// (VDPO's cloning stages) is brought within them in the same amount per step.
    #[arg(long, default_value_t = 200)]
    updates: usize,
    /// Rayon threads for the updates (default: the algorithm's learner count, as in training).
    #[arg(long)]
    threads: Option<usize>,
    /// D2HPG's lifting weight λ (--set lifting_weight=…).
    #[arg(long)]
    lifting_weight: Option<f64>,
    /// D2HPG's lifting samples K per state (--set lifting_samples=…).
    #[arg(long)]
    lifting_samples: Option<usize>,
    /// Whose defaults the algorithm's fields start from (`dhrl train --protocol`).
    #[arg(long, value_enum, default_value_t = Protocol::Dhrl)]
    protocol: Protocol,
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct BenchDelayArgs {
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
pub struct BenchEnvArgs {
    #[arg(long, value_enum, default_value_t = TaskName::HalfCheetah)]
    task: TaskName,
    /// Copies stepped in parallel.
    #[arg(long, default_value_t = 1024)]
    envs: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Total delay Δ: above 0, the delayed batch of training is timed (delay layer on the CPU).
    #[arg(long, default_value_t = 0)]
    delay: usize,
    /// Batched steps to time.
    #[arg(long, default_value_t = 100)]
    steps: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(command: &BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Env(args) => run_bench_env(args),
        BenchCommand::Delay(args) => run_bench_delay(args),
        BenchCommand::Update(args) => run_bench_update(args),
    }
}

fn run_bench_update(args: &BenchUpdateArgs) -> anyhow::Result<()> {
    let mut values = toml::Table::new();
    if let Some(weight) = args.lifting_weight {
        values.insert("lifting_weight".into(), toml::Value::Float(weight));
    }
    if let Some(samples) = args.lifting_samples {
        values.insert(
            "lifting_samples".into(),
            toml::Value::Integer(samples as i64),
        );
    }
    for assignment in &args.set {
        let (field, value) = parse_assignment(assignment)?;
        values.insert(field, value);
    }
    let algo = AlgoSettings::under(args.protocol, &args.algo, &values)?;
    let report = bench_update(
        &algo,
        args.task,
        args.delay,
        args.batch_size,
        args.device,
        args.threads,
        args.updates,
    )?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("{}", report.machine);
        println!(
            "{} on {} sizes, delay {}, batch {}, {:?}, {} threads: {:.1} updates/s ({:.2} ms per update)",
            report.algo,
            report.task,
            report.delay,
            report.batch_size,
            report.device,
            report.threads,
            report.updates_per_sec,
            report.ms_per_update
        );
    }
    Ok(())
}

fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn run_bench_delay(args: &BenchDelayArgs) -> anyhow::Result<()> {
    let threads = args.threads.unwrap_or_else(all_cores);
    if !args.json {
        println!("{}", dhrl::bench::Machine::here());
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
    let report = bench_env(
        args.task, args.envs, threads, args.delay, args.steps, args.seed,
    )?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("{}", report.machine);
        println!(
            "{:<18} {:>6} {:>7} {:>5} {:>12} {:>16} {:>7} {:>20} {:>7} {:>26} {:>7}",
            "task",
            "envs",
            "threads",
            "delay",
            "env steps/s",
            "raw, 1 copy",
            "ratio",
            "raw, all copies",
            "ratio",
            "raw, all copies, threads",
            "ratio"
        );
        println!(
            "{:<18} {:>6} {:>7} {:>5} {:>12.0} {:>16.0} {:>7.2} {:>20.0} {:>7.2} {:>26.0} {:>7.2}",
            report.task.as_str(),
            report.envs,
            report.threads,
            report.delay,
            report.env_steps_per_sec,
            report.raw_env_steps_per_sec,
            report.ratio,
            report.raw_batch_env_steps_per_sec,
            report.ratio_to_raw_batch,
            report.raw_parallel_env_steps_per_sec,
            report.ratio_to_raw_parallel
        );
    }
    Ok(())
}
