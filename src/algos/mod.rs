//! The algorithms, each readable top to bottom in its own file — its configuration first, then
//! its losses and its [`Agent`] — and the one registry line per algorithm that makes it known
//! to `dhrl train --algo`, `config.toml`, evaluation and the benches.
//!
//! Every transition carries both what the delayed agent saw (`x_τ`, `x_{τ+1}`) and the true
//! states (`s_τ`, `s_{τ+1}`), so learners on the true state (BPQL's critic, D2HPG's delay-free
//! SAC) and learners on `x` train from the same replay.

mod augmented_sac;
mod bpql;
mod context;
mod d2hpg;
mod delayed_sac;
mod naive_sac;
mod registry;
mod sac;
mod settings;
mod vdpo;

use std::path::Path;

pub use bpql::Bpql;
pub use context::UpdateContext;
pub use d2hpg::{Config as D2hpgConfig, D2hpg, Regular};
pub use registry::{
    AlgoConfig, AlgoError, AlgoInfo, Algorithm, ConfigFields, FieldDoc, Registered, check,
    toml_value,
};
pub use sac::{
    Config as SacConfig, InputView, LearningRates, SacAgent, SacBatch, SacLearner, SacStats,
};
pub use settings::AlgoSettings;

use crate::delay::{BatchExtras, ReplayError, Transitions};
use crate::learn::LearnError;
use crate::sim::{SimError, TaskModel};
use crate::tasks::TaskName;

/// Every algorithm, one line each: the registry.
pub static ALGORITHMS: &[&dyn Algorithm] = &[
    &Registered::<sac::Config>::new(),
    &Registered::<naive_sac::Config>::new(),
    &Registered::<augmented_sac::Config>::new(),
    &Registered::<delayed_sac::Config>::new(),
    &Registered::<vdpo::Config>::new(),
    &Registered::<bpql::Config>::new(),
    &Registered::<d2hpg::NaiveConfig>::new(),
    &Registered::<d2hpg::Config>::new(),
];

/// The registered algorithm called `name`.
pub fn algorithm(name: &str) -> Result<&'static dyn Algorithm, AlgoError> {
    ALGORITHMS
        .iter()
        .copied()
        .find(|a| a.info().name == name)
        .ok_or_else(|| AlgoError::UnknownAlgorithm {
            name: name.to_string(),
            valid: names().join(", "),
        })
}

/// The names `--algo` accepts, in registry order.
pub fn names() -> Vec<&'static str> {
    ALGORITHMS.iter().map(|a| a.info().name).collect()
}

/// Sizes an agent is built for.
#[derive(Debug, Clone)]
pub struct AgentSpec {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Total delay Δ: augmented states have `obs_dim + Δ·act_dim` entries.
    pub delay: usize,
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
}

impl AgentSpec {
    /// The sizes of a task's model under a total delay Δ.
    pub fn for_model(model: &TaskModel, delay: usize) -> AgentSpec {
        AgentSpec {
            obs_dim: model.task.obs_dim,
            act_dim: model.task.act_dim,
            delay,
            action_low: model.action_low.clone(),
            action_high: model.action_high.clone(),
        }
    }

    /// The sizes of `task` under a total delay Δ (loads its model for the action bounds).
    pub fn for_task(task: TaskName, delay: usize) -> Result<AgentSpec, SimError> {
        Ok(AgentSpec::for_model(&*TaskModel::load(task)?, delay))
    }

    pub fn augmented_dim(&self) -> usize {
        self.obs_dim + self.delay * self.act_dim
    }
}

/// How actions are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActMode {
    /// Sampled from the policy (training).
    Explore,
    /// The policy's mode, `tanh` of the mean (evaluation).
    Deterministic,
}

/// Named statistics of one update, a subset of the agent's [`Agent::stat_names`].
pub type Stats = Vec<(&'static str, f64)>;

/// What the training loop needs of an algorithm.
pub trait Agent: Send {
    /// Actions `[rows, act_dim]` for `rows` augmented states `[rows, obs + Δ·act]`.
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32>;
    /// Deterministic actions of the delay-free policy for `rows` true states `[rows, obs]`,
    /// evaluated undelayed; `None` unless [`AlgoInfo::delay_free_policy`] says there is one.
    fn act_delay_free(&mut self, _states: &[f32], _rows: usize) -> Option<Vec<f32>> {
        None
    }
    /// The statistics [`Agent::update`] may report, in `train.csv`'s column order.
    fn stat_names(&self) -> Vec<&'static str>;
    /// The optional batch fields the agent samples (none by default).
    fn batch_extras(&self) -> BatchExtras {
        BatchExtras::default()
    }
    /// One update of every learner: draws its batches from `ctx` (as many as it needs),
    /// returns the statistics it computed this time (an absent one is logged empty).
    fn update(&mut self, ctx: &mut UpdateContext<'_>) -> Result<Stats, ReplayError>;
    /// Networks, optimiser states and random streams, into `dir`.
    fn save(&self, dir: &Path) -> Result<(), LearnError>;
    /// Restores what [`Agent::save`] wrote.
    fn load(&mut self, dir: &Path) -> Result<(), LearnError>;
}

/// `n` random transitions at `spec`'s sizes, with their intermediate states (values uniform
/// in [−1, 1), every fifth one terminal): what update benchmarks and tests feed the learners, whose cost does not depend on
/// the values.
pub fn random_batch(spec: &AgentSpec, n: usize, seed: u64) -> Transitions {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut random = |len: usize| {
        (0..len)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect::<Vec<f32>>()
    };
    let (aug, obs, act) = (spec.augmented_dim(), spec.obs_dim, spec.act_dim);
    Transitions {
        copy: vec![0; n],
        episode: vec![0; n],
        tau: vec![0; n],
        augmented: random(n * aug),
        state: random(n * obs),
        action: random(n * act),
        reward: random(n),
        next_augmented: random(n * aug),
        next_state: random(n * obs),
        terminated: (0..n).map(|i| u32::from(i % 5 == 0)).collect(),
        intermediate_states: random(n * spec.delay * obs),
    }
}
