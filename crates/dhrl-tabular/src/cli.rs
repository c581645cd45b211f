//! The `dhrl tabular` and `dhrl tabular-bench` commands.

use std::path::PathBuf;

use anyhow::{Context, anyhow};

use crate::analysis::{AnalysisOptions, analyze};
use crate::augmented::{DEFAULT_MAX_AUGMENTED_STATES, SizeLimits, check_augmented_size};
use crate::bench::{BenchConfig, run_bench};
use crate::generate::{RandomMdpSpec, random_mdp};
use crate::mdp::FiniteMdp;
use crate::plot::write_bench_plot;
use crate::qlearning::QLearningConfig;

/// Check the paper's finite-domain guarantees (Prop. 3.3, 3.5, Cor. 3.4, Lemma 3.7) on a delayed
/// MDP read from JSON or generated at random.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["mdp", "random"])))]
pub struct TabularArgs {
    /// MDP file: {"gamma": g, "transitions": [[[p(s'|s,a) for s'] for a] for s],
    /// "rewards": [[r(s,a) for a] for s]}.
    #[arg(long, value_name = "FILE.json")]
    pub mdp: Option<PathBuf>,

    /// Generate a random MDP (needs --states and --actions): rewards uniform in [0, 1), next
    /// state uniform.
    #[arg(long)]
    pub random: bool,

    /// Number of states of the random MDP.
    #[arg(long, value_name = "N", conflicts_with = "mdp")]
    pub states: Option<usize>,

    /// Number of actions of the random MDP.
    #[arg(long, value_name = "M", conflicts_with = "mdp")]
    pub actions: Option<usize>,

    /// Seed of the random MDP [default: 0].
    #[arg(long, value_name = "S", conflicts_with = "mdp")]
    pub seed: Option<u64>,

    /// Make the random MDP stochastic: probability mass P moves to another random next state.
    #[arg(long, value_name = "P", conflicts_with = "mdp")]
    pub stochastic: Option<f64>,

    /// Discount factor of the random MDP [default: 0.9].
    #[arg(long, value_name = "GAMMA", conflicts_with = "mdp")]
    pub gamma: Option<f64>,

    /// Observation delay Δ.
    #[arg(long, value_name = "D")]
    pub delay: usize,

    /// Also build the ε-abstract partition (total-variation radius E in [0, 1)) and report the
    /// Lemma 3.7 value-loss bound with the loss it bounds.
    #[arg(long, value_name = "E")]
    pub epsilon: Option<f64>,

    /// Refuse augmented state spaces |S|·|A|^Δ larger than this.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_AUGMENTED_STATES)]
    pub max_augmented_states: usize,

    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Q-learning sample complexity on the augmented MDP against the belief abstraction, per delay.
#[derive(clap::Args, Debug)]
pub struct TabularBenchArgs {
    /// Number of states of the generated (deterministic) MDPs.
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub states: usize,

    /// Number of actions of the generated MDPs.
    #[arg(long, value_name = "M", default_value_t = 2)]
    pub actions: usize,

    /// Discount factor.
    #[arg(long, default_value_t = 0.9)]
    pub gamma: f64,

    /// Smallest delay.
    #[arg(long, value_name = "D", default_value_t = 1)]
    pub min_delay: usize,

    /// Largest delay (inclusive).
    #[arg(long, value_name = "D", default_value_t = 6)]
    pub max_delay: usize,

    /// Runs per delay (MDP and learner seeds 0..N).
    #[arg(long, value_name = "N", default_value_t = 5)]
    pub seeds: u64,

    /// Converged when the greedy policy's value is within this of V* at every augmented state.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,

    /// Sample budget per run; runs that spend it are reported as not reached.
    #[arg(long, value_name = "N", default_value_t = 2_000_000)]
    pub max_samples: u64,

    /// Test the greedy policy every K samples.
    #[arg(long, value_name = "K", default_value_t = 500)]
    pub check_every: u64,

    /// ε-greedy exploration probability.
    #[arg(long, default_value_t = 0.2)]
    pub exploration: f64,

    /// Steps per episode before a reset.
    #[arg(long, value_name = "T", default_value_t = 20)]
    pub episode_length: usize,

    /// Refuse augmented state spaces |S|·|A|^Δ larger than this.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_AUGMENTED_STATES)]
    pub max_augmented_states: usize,

    /// Where to write the SVG plot.
    #[arg(long, value_name = "FILE.svg", default_value = "tabular-bench.svg")]
    pub out: PathBuf,

    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn size_limits(max_augmented_states: usize) -> SizeLimits {
    SizeLimits {
        max_augmented_states,
    }
}

fn load_mdp(args: &TabularArgs) -> anyhow::Result<FiniteMdp> {
    if let Some(path) = &args.mdp {
        return FiniteMdp::from_json_file(path)
            .with_context(|| format!("loading the MDP from {}", path.display()));
    }
    let states = args
        .states
        .ok_or_else(|| anyhow!("--random needs --states N (the number of states, at least 1)"))?;
    let actions = args
        .actions
        .ok_or_else(|| anyhow!("--random needs --actions M (the number of actions, at least 1)"))?;
    // Refuse an oversized augmented MDP before generating the base MDP, whose |S|·|A| rows alone
    // can exhaust memory.
    check_augmented_size(
        states,
        actions,
        args.delay,
        &size_limits(args.max_augmented_states),
    )?;
    let spec = RandomMdpSpec {
        states,
        actions,
        gamma: args.gamma.unwrap_or(0.9),
        stochastic: args.stochastic.unwrap_or(0.0),
        seed: args.seed.unwrap_or(0),
    };
    random_mdp(&spec).context("generating the random MDP")
}

/// Runs `dhrl tabular`.
///
/// # Errors
/// Invalid input (file, MDP, flags) or an augmented MDP above the size limit (for `--random`,
/// checked before the MDP is generated).
pub fn run_tabular(args: &TabularArgs) -> anyhow::Result<()> {
    let mdp = load_mdp(args)?;
    let options = AnalysisOptions {
        epsilon: args.epsilon,
        limits: size_limits(args.max_augmented_states),
        ..AnalysisOptions::default()
    };
    let report = analyze(&mdp, args.delay, &options)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_table());
    }
    Ok(())
}

/// Runs `dhrl tabular-bench`.
///
/// # Errors
/// Invalid settings, an augmented MDP above the size limit (checked for the largest delay before
/// any run), or an unwritable plot path (reported after the results are printed).
pub fn run_tabular_bench(args: &TabularBenchArgs) -> anyhow::Result<()> {
    let config = BenchConfig {
        states: args.states,
        actions: args.actions,
        gamma: args.gamma,
        min_delay: args.min_delay,
        max_delay: args.max_delay,
        seeds: args.seeds,
        tolerance: args.tolerance,
        learning: QLearningConfig {
            exploration: args.exploration,
            episode_length: args.episode_length,
            max_samples: args.max_samples,
            check_every: args.check_every,
        },
        limits: size_limits(args.max_augmented_states),
    };
    let report = run_bench(&config)?;
    // Results first: an unwritable --out must not discard a finished experiment.
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_table());
    }
    write_bench_plot(&report, &args.out)?;
    if args.json {
        eprintln!("wrote {}", args.out.display());
    } else {
        println!("plot: {}", args.out.display());
    }
    Ok(())
}
