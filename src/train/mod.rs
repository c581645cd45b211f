//! `dhrl train` and `dhrl eval`: the loop every algorithm runs in — random warm-up, then one
//! gradient update per environment step, periodic evaluation on separate delayed copies,
//! CSV logs, and atomic checkpoints that a killed run resumes from.

#[cfg(feature = "cli")]
mod args;
mod checkpoint;
mod config;
mod curves;
mod eval;
mod logs;
mod run;
mod tensorboard;

#[cfg(feature = "cli")]
pub use args::{TrainArgs, TrainPlan};
pub use checkpoint::has_checkpoint;
pub use config::{ConfigError, MAIN_JOB_DELAY, TrainConfig};
#[cfg(feature = "cli")]
pub use curves::plot_curves;
pub use curves::{CurveSummary, EvalRow, curve_summary, read_evals, summarize_runs};
pub use eval::{EvalResult, evaluate};
#[cfg(feature = "cli")]
pub use run::stop_on_signals;
pub use run::{
    FAILED, STACK, SavedRun, Start, TrainSummary, checkpoint_step, evaluate_saved, learner_pool,
    load_saved, stack_member, stack_seeds, train, train_seeds, train_stack,
};

use crate::delay::{DelayError, ReplayError};
use crate::learn::LearnError;
use crate::sim::SimError;
use crate::snapshot::SnapshotError;

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Delay(#[from] DelayError),
    #[error(transparent)]
    Batch(#[from] crate::delay::BatchError),
    #[error(transparent)]
    Replay(#[from] ReplayError),
    #[error(transparent)]
    Learn(#[from] LearnError),
    #[error("checkpoint: {0}")]
    Snapshot(#[from] SnapshotError),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    #[error("{0} already exists; pick another --out, or continue it with --resume {0}")]
    OutputExists(String),
    #[error(
        "{0} is being trained by another dhrl process (it holds {0}/.lock): wait for it to end, or stop it, first"
    )]
    RunInUse(String),
    #[error("{0} holds no checkpoint to resume from (nothing was saved before the run stopped)")]
    NoCheckpoint(String),
    #[error(transparent)]
    Algo(#[from] crate::algos::AlgoError),
    #[error(
        "stopped by a signal at step {env_steps} after writing a checkpoint; continue with \
         `dhrl train --resume {run}`"
    )]
    Interrupted { run: String, env_steps: u64 },
    #[error(
        "update {update} at step {env_steps}: {statistic} is {value}, not finite; the run stopped \
         and its last checkpoint is kept (lower the learning rates, or check the task's inputs, \
         then `dhrl train --resume {run}`)"
    )]
    NonFinite {
        run: String,
        statistic: &'static str,
        value: f64,
        update: u64,
        env_steps: u64,
    },
    #[error(
        "writing the checkpoint of step {env_steps} into {run} failed: {cause}; {kept} (free \
         space or make the folder writable, then `dhrl train --resume {run}`)"
    )]
    CheckpointFailed {
        run: String,
        env_steps: u64,
        cause: Box<TrainError>,
        /// What is left to resume from.
        kept: String,
    },
    #[error("the agent reported a statistic `{0}` it did not declare in stat_names")]
    UndeclaredStatistic(&'static str),
}

/// Wraps an I/O error with the path it concerns.
pub(crate) fn io_error(path: &std::path::Path) -> impl Fn(std::io::Error) -> TrainError + '_ {
    move |e| TrainError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}
