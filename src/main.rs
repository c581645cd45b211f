//! The `dhrl` command line.
mod cli;

use clap::{Parser, Subcommand};

use cli::bench::BenchCommand;
use cli::eval::EvalArgs;
use cli::export::ExportArgs;
use cli::plot::PlotArgs;
use cli::report::ReportArgs;
use cli::rollout::RolloutArgs;
use cli::sweep::SweepCommand;
use dhrl::tabular::{TabularArgs, TabularBenchArgs, run_tabular, run_tabular_bench};
use dhrl::train::TrainArgs;

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
    /// Write a run's policy for deployment: ONNX, safetensors, a manifest and a recorded check.
    Export(ExportArgs),
    /// Learning curves of finished runs (grouped by task, algorithm and delay) as SVG, and a
    /// table of their final evaluations.
    Plot(PlotArgs),
    /// The paper's Table 1 layout (Markdown, LaTeX, CSV, the published numbers beside), an
    /// rliable-style aggregate, figures (SVG, PNG) and a long-format CSV from runs or sweeps.
    Report(ReportArgs),
    /// Trace one episode from a given state and action sequence, one JSON object per line.
    Rollout(RolloutArgs),
    /// Experiments as data: plan a grid of runs (the paper's presets or a TOML file), run it
    /// here or on a cluster, resuming whatever was cut off.
    #[command(subcommand)]
    Sweep(SweepCommand),
    /// Measure throughput.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Finite-domain DHRL: augmented MDP, belief abstraction and the paper's guarantees.
    Tabular(TabularArgs),
    /// Q-learning sample complexity on the augmented vs the abstract MDP, across delays.
    TabularBench(TabularBenchArgs),
}

/// glibc's malloc gives blocks above 128 KiB straight back to the kernel when freed, so the
/// learners' tensors (every update allocates the same large activations again) paid a fresh
/// mapping and its page faults each time: ~8% of a VDPO update, ~5% of a SAC one. This process
/// keeps them in its heap instead (blocks up to 32 MiB, glibc's ceiling for the setting; up to
/// 512 MiB of free heap kept). One arena for every thread: a learner on a pool thread
/// allocated from a thread arena, whose extra 64 MiB heaps glibc unmaps as soon as they empty,
/// whatever the trim threshold (13.7% of a VDPO update in the kernel's page faults, 0.4% with
/// one arena; SAC and two-thread D2HPG updates unchanged). Only the CLI does this: the Python
/// package leaves its host process's allocator alone.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes the allocator's parameters (under its own lock); it runs
    // first in main, before this process starts any thread.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 512 << 20);
        libc::mallopt(libc::M_ARENA_MAX, 1);
    }
}

fn main() -> anyhow::Result<()> {
    keep_freed_memory();
    // Every thread of this process that does math flushes subnormal floats (src/float_mode.rs):
    // this one, and rayon's global pool, which the CPU delay layer's larger batches use when the
    // simulation has one thread outside training (evaluation, rollouts; in training they run on
    // the learner threads the loop runs on, and with more simulation threads on its own pool).
    dhrl::float_mode::apply_to_this_thread();
    rayon::ThreadPoolBuilder::new()
        .start_handler(|_| dhrl::float_mode::apply_to_this_thread())
        .build_global()?;
    match Cli::parse().command {
        Command::Train(args) => cli::train::run(&args),
        Command::Eval(args) => cli::eval::run(&args),
        Command::Export(args) => cli::export::run(&args),
        Command::Plot(args) => cli::plot::run(&args),
        Command::Report(args) => cli::report::run(&args),
        Command::Rollout(args) => cli::rollout::run(&args),
        Command::Sweep(command) => cli::sweep::run(&command),
        Command::Bench(command) => cli::bench::run(&command),
        Command::Tabular(args) => run_tabular(&args),
        Command::TabularBench(args) => run_tabular_bench(&args),
    }
}
