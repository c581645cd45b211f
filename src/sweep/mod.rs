//! Sweeps: an experiment (a TOML file, or a preset of the paper's protocol) expands into a
//! manifest of runs in a sweep folder; engines work through it — this machine's
//! [`run_local`], one command per run for any scheduler, Slurm job arrays — each run going
//! through [`run_one`], which resumes whatever was cut off.

mod cost;
mod experiment;
mod manifest;
mod runner;
mod slurm;

pub use cost::{CostRow, estimate_cost};
pub use experiment::{DelayKind, Experiment, PRESETS, PlannedRun, run_id};
pub use manifest::{ManifestRun, PlanChange, RunOutcome, RunState, Sweep, write_atomically};
pub use runner::{
    EXIT_BUSY, EXIT_INTERRUPTED, LocalSummary, RunOneResult, run_group, run_local, run_one,
    stack_groups, steps_done,
};
pub use slurm::{ArrayScript, SlurmOptions, shell_quote, time_limit_seconds, write_array_scripts};

#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("{source_name}: {message}")]
    Experiment {
        source_name: String,
        message: String,
    },
    #[error("unknown preset '{name}'; the presets are {valid} (or give an experiment file)")]
    UnknownPreset { name: String, valid: String },
    #[error("{0}")]
    Invalid(String),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    #[error(transparent)]
    Algo(#[from] crate::algos::AlgoError),
    #[error(transparent)]
    Train(#[from] crate::train::TrainError),
}

impl From<crate::train::ConfigError> for SweepError {
    fn from(e: crate::train::ConfigError) -> SweepError {
        SweepError::Train(e.into())
    }
}
