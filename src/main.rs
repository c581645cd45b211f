//! The `dhrl` command line.
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};

use dhrl::algos::{Algo, Lifting};
use dhrl::bench::{bench_delay, bench_env, bench_update};
use dhrl::delay::{DelayArgs, DelayConfig};
use dhrl::learn::LearnDevice;
use dhrl::rollout::{read_actions, read_state, rollout};
use dhrl::tabular::{TabularArgs, TabularBenchArgs, run_tabular, run_tabular_bench};
use dhrl::tasks::TaskName;
use dhrl::train::{Start, TrainConfig, evaluate_saved, plot_curves, summarize_runs, train};

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
    /// Train an agent (defaults: delay-free SAC on InvertedPendulum, a few minutes).
    Train(Box<TrainArgs>),
    /// Evaluate the saved policy of a run.
    Eval(EvalArgs),
    /// Learning curves of finished runs (grouped by task, algorithm and delay) as SVG, and a
    /// table of their final evaluations.
    Plot(PlotArgs),
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
struct TrainArgs {
    #[arg(long, value_enum)]
    task: Option<TaskName>,
    #[arg(long, value_enum)]
    algo: Option<Algo>,
    #[command(flatten)]
    delay: DelayArgs,
    /// Environment steps in total.
    #[arg(long)]
    steps: Option<u64>,
    #[arg(long)]
    seed: Option<u64>,
    /// Copies collecting in parallel (1: the paper's protocol, one update per step).
    #[arg(long)]
    envs: Option<usize>,
    /// Simulation threads.
    #[arg(long)]
    threads: Option<usize>,
    /// Uniform random steps before learning starts.
    #[arg(long)]
    warmup_steps: Option<u64>,
    #[arg(long)]
    eval_every: Option<u64>,
    #[arg(long)]
    eval_episodes: Option<usize>,
    #[arg(long)]
    checkpoint_every: Option<u64>,
    #[arg(long)]
    batch_size: Option<usize>,
    /// Initial entropy temperature α.
    #[arg(long)]
    alpha: Option<f64>,
    /// Keep α fixed instead of learning it.
    #[arg(long)]
    fixed_alpha: bool,
    /// D2HPG's lifting weight λ.
    #[arg(long)]
    lifting_weight: Option<f64>,
    /// D2HPG's lifting samples K per state (≥ 2).
    #[arg(long)]
    lifting_samples: Option<usize>,
    #[arg(long, value_enum)]
    device: Option<LearnDevice>,
    /// TOML file with any fields of config.toml; flags override it.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Run folder (must not exist; default runs/<task>-<algo>-d<delay>-s<seed>-<time>).
    #[arg(long, value_name = "DIR", conflicts_with = "resume")]
    out: Option<PathBuf>,
    /// Continue the run in DIR from its last checkpoint (with --steps to extend it).
    #[arg(long, value_name = "DIR")]
    resume: Option<PathBuf>,
}

#[derive(Args)]
struct PlotArgs {
    /// Run folders written by `dhrl train`.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    #[arg(long, value_name = "FILE.svg")]
    out: PathBuf,
    #[arg(long, default_value = "Evaluation return")]
    title: String,
}

#[derive(Args)]
struct EvalArgs {
    /// A run folder written by `dhrl train`.
    run: PathBuf,
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Evaluate under other delay options than the run's.
    #[command(flatten)]
    delay: DelayArgs,
    /// Evaluate D2HPG's delay-free policy in the undelayed task instead of the regular one.
    #[arg(long)]
    delay_free_policy: bool,
    #[arg(long, default_value_t = 12345)]
    seed: u64,
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
    /// Gradient updates per second of an algorithm at a task's sizes.
    Update(BenchUpdateArgs),
}

#[derive(Args)]
struct BenchUpdateArgs {
    #[arg(long, value_enum, default_value_t = Algo::Sac)]
    algo: Algo,
    #[arg(long, value_enum, default_value_t = TaskName::HalfCheetah)]
    task: TaskName,
    /// Total delay Δ (sizes the augmented input).
    #[arg(long, default_value_t = 0)]
    delay: usize,
    #[arg(long, default_value_t = 256)]
    batch_size: usize,
    #[arg(long, value_enum, default_value_t = LearnDevice::Cpu)]
    device: LearnDevice,
    /// Updates to time.
    #[arg(long, default_value_t = 200)]
    updates: usize,
    /// D2HPG's lifting weight λ.
    #[arg(long, default_value_t = Lifting::default().weight)]
    lifting_weight: f64,
    /// D2HPG's lifting samples K per state.
    #[arg(long, default_value_t = Lifting::default().samples)]
    lifting_samples: usize,
    #[arg(long)]
    json: bool,
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
        Command::Train(args) => run_train(&args),
        Command::Eval(args) => run_eval(&args),
        Command::Plot(args) => run_plot(&args),
        Command::Rollout(args) => run_rollout(&args),
        Command::Bench(BenchCommand::Env(args)) => run_bench_env(&args),
        Command::Bench(BenchCommand::Delay(args)) => run_bench_delay(&args),
        Command::Bench(BenchCommand::Update(args)) => run_bench_update(&args),
        Command::Tabular(args) => run_tabular(&args),
        Command::TabularBench(args) => run_tabular_bench(&args),
    }
}

/// The configuration of `dhrl train`: defaults, then `--config`, then flags.
fn train_config(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    let mut c = match &args.config {
        Some(path) => TrainConfig::from_toml_file(path)?,
        None => TrainConfig::default(),
    };
    c.task = args.task.unwrap_or(c.task);
    c.algo = args.algo.unwrap_or(c.algo);
    c.delay = args.delay.apply(c.delay)?;
    c.steps = args.steps.unwrap_or(c.steps);
    c.seed = args.seed.unwrap_or(c.seed);
    c.envs = args.envs.unwrap_or(c.envs);
    c.threads = args.threads.unwrap_or(c.threads);
    c.warmup_steps = args.warmup_steps.unwrap_or(c.warmup_steps);
    c.eval_every = args.eval_every.unwrap_or(c.eval_every);
    c.eval_episodes = args.eval_episodes.unwrap_or(c.eval_episodes);
    c.checkpoint_every = args.checkpoint_every.unwrap_or(c.checkpoint_every);
    c.batch_size = args.batch_size.unwrap_or(c.batch_size);
    c.hyper.initial_alpha = args.alpha.unwrap_or(c.hyper.initial_alpha);
    c.hyper.autotune_alpha &= !args.fixed_alpha;
    c.lifting.weight = args.lifting_weight.unwrap_or(c.lifting.weight);
    c.lifting.samples = args.lifting_samples.unwrap_or(c.lifting.samples);
    c.device = args.device.unwrap_or(c.device);
    Ok(c)
}

fn run_train(args: &TrainArgs) -> anyhow::Result<()> {
    let (run, start, config) = match &args.resume {
        Some(dir) => {
            let given = args.task.is_some()
                || args.algo.is_some()
                || args.delay.any()
                || args.config.is_some()
                || args.seed.is_some();
            anyhow::ensure!(
                !given,
                "--resume continues {} with its own config.toml; only --steps may be given with it",
                dir.display()
            );
            let steps = args.steps.unwrap_or(0);
            (
                dir.clone(),
                Start::Resume,
                TrainConfig {
                    steps,
                    ..TrainConfig::default()
                },
            )
        }
        None => {
            let config = train_config(args)?;
            let delay = config.validate()?;
            let run = args.out.clone().unwrap_or_else(|| {
                let stamp = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_secs());
                PathBuf::from(format!(
                    "runs/{}-{}-d{delay}-s{}-{stamp}",
                    config.task, config.algo, config.seed
                ))
            });
            (run, Start::Fresh, config)
        }
    };
    eprintln!("run folder: {}", run.display());
    let summary = train(
        &config,
        &run,
        start,
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

fn run_plot(args: &PlotArgs) -> anyhow::Result<()> {
    let curves = summarize_runs(&args.runs)?;
    println!("| runs | seeds | final step | final return (mean ± std) |");
    println!("|---|---|---|---|");
    for curve in &curves {
        if let Some((step, mean, std)) = curve.last() {
            let seeds: Vec<String> = curve.seeds.iter().map(u64::to_string).collect();
            println!(
                "| {} | {} | {step} | {mean:.1} ± {std:.1} |",
                curve.label,
                seeds.join(", ")
            );
        }
    }
    plot_curves(&curves, &args.title, &args.out)?;
    println!("plot: {}", args.out.display());
    Ok(())
}

fn run_eval(args: &EvalArgs) -> anyhow::Result<()> {
    let delay = if args.delay.any() {
        Some(args.delay.apply(DelayConfig::default())?)
    } else {
        None
    };
    let result = evaluate_saved(
        &args.run,
        args.episodes,
        delay,
        args.delay_free_policy,
        args.seed,
    )?;
    println!(
        "return {:.2} ± {:.2} over {} episodes (mean length {:.1})",
        result.return_mean, result.return_std, result.episodes, result.length_mean
    );
    Ok(())
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

fn run_bench_update(args: &BenchUpdateArgs) -> anyhow::Result<()> {
    let lifting = Lifting {
        weight: args.lifting_weight,
        samples: args.lifting_samples,
    };
    let report = bench_update(
        args.algo,
        args.task,
        args.delay,
        args.batch_size,
        args.device,
        lifting,
        args.updates,
    )?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{} on {} sizes, delay {}, batch {}, {:?}: {:.1} updates/s ({:.2} ms per update)",
            report.algo,
            report.task,
            report.delay,
            report.batch_size,
            report.device,
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
