//! Simulation: one task model shared by many copies, a single copy with Gymnasium's step
//! semantics ([`Env`]), and the batch of copies stepped on a thread pool ([`BatchedEnv`]).

mod batch;
mod env;
mod model;

pub use batch::{BatchConfig, BatchSnapshot, BatchedEnv, CopyStep};
pub use env::{Env, EnvSnapshot, StepOutcome};
pub use model::{TaskModel, assets_dir, set_assets_dir};

/// Gymnasium's `TimeLimit` for every benchmark task.
pub const MAX_EPISODE_STEPS: u32 = 1000;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(
        "task model {path} not found; run `scripts/setup.sh` (it installs the Gymnasium XMLs), \
         or point DHRL_ASSETS_DIR at gymnasium/envs/mujoco/assets"
    )]
    MissingModel { path: std::path::PathBuf },
    #[error("MuJoCo could not load {path}: {message}")]
    LoadFailed {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("task model {xml} has no body named '{body}'")]
    MissingBody {
        xml: &'static str,
        body: &'static str,
    },
    #[error("model {xml} has {found} {what}, the {task} task expects {expected}")]
    ModelMismatch {
        xml: &'static str,
        task: &'static str,
        what: &'static str,
        found: usize,
        expected: usize,
    },
    #[error("{what} has length {found}, expected {expected}")]
    WrongLength {
        what: &'static str,
        found: usize,
        expected: usize,
    },
    #[error("{what}[{index}] is {value}; only finite numbers are accepted")]
    NotFinite {
        what: &'static str,
        index: usize,
        value: f64,
    },
    #[error("{what} must be at least {min}, got {found}")]
    TooSmall {
        what: &'static str,
        found: f64,
        min: f64,
    },
    #[error("cannot continue from the saved simulation state: {0}")]
    Snapshot(String),
    #[error("could not build a thread pool of {threads} threads: {message}")]
    ThreadPool { threads: usize, message: String },
}

/// Checks that `values` has `expected` entries, all finite.
pub fn check_vector(what: &'static str, values: &[f64], expected: usize) -> Result<(), SimError> {
    if values.len() != expected {
        return Err(SimError::WrongLength {
            what,
            found: values.len(),
            expected,
        });
    }
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(SimError::NotFinite {
            what,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}
