//! The algorithms, each readable top to bottom in its own file, behind one [`Agent`]
//! interface that the training loop drives: act on the augmented states of the ready copies,
//! update from a batch of time-aligned transitions, save and load.
//!
//! Every transition carries both what the delayed agent saw (`x_τ`, `x_{τ+1}`) and the true
//! states (`s_τ`, `s_{τ+1}`), so learners on the true state (BPQL's critic, D2HPG's delay-free
//! SAC) and learners on `x` train from the same replay.

mod augmented_sac;
mod bpql;
mod d2hpg;
mod naive_sac;
mod sac;

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::delay::Transitions;
use crate::learn::{Devices, LearnError};

pub use bpql::Bpql;
pub use d2hpg::{D2hpg, Lifting, Regular, delay_free_seed};
pub use sac::{InputView, SacAgent, SacBatch, SacLearner, SacStats};

/// The algorithms `dhrl train --algo` accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
#[value(rename_all = "kebab-case")]
pub enum Algo {
    /// Delay-free SAC on the true state (Δ = 0 only): the upper reference.
    Sac,
    /// SAC on the last received observation `s_{t-Δ}` only (memoryless).
    NaiveSac,
    /// SAC with actor and critic on the augmented state `x_t`.
    AugmentedSac,
    /// Actor on `x_t`, "beta" critic on the time-aligned true state.
    Bpql,
    /// Delay-free SAC plus a regular policy trained by the lifting loss only.
    D2hpgNaive,
    /// The paper's D2HPG(-BPQL): BPQL, a delay-free SAC, and the lifting loss.
    D2hpg,
}

impl Algo {
    pub fn as_str(self) -> &'static str {
        match self {
            Algo::Sac => "sac",
            Algo::NaiveSac => "naive-sac",
            Algo::AugmentedSac => "augmented-sac",
            Algo::Bpql => "bpql",
            Algo::D2hpgNaive => "d2hpg-naive",
            Algo::D2hpg => "d2hpg",
        }
    }
}

impl Algo {
    /// Whether the acting policy's input is the augmented state `x_t` (its size grows with Δ).
    pub fn acts_on_augmented_state(self) -> bool {
        matches!(
            self,
            Algo::AugmentedSac | Algo::Bpql | Algo::D2hpgNaive | Algo::D2hpg
        )
    }
}

impl std::fmt::Display for Algo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
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
    pub fn augmented_dim(&self) -> usize {
        self.obs_dim + self.delay * self.act_dim
    }
}

/// Hyperparameters shared by the SAC family (SPEC §3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Hyper {
    pub gamma: f64,
    /// Polyak coefficient of the target critics.
    pub tau: f64,
    /// Adam learning rate of every network and of the temperature.
    pub learning_rate: f64,
    /// Adam's ε (PyTorch's 1e-8, not burn's default 1e-5).
    pub adam_epsilon: f64,
    pub initial_alpha: f64,
    /// Learn α toward the target entropy −dim(A); false keeps it fixed.
    pub autotune_alpha: bool,
}

impl Default for Hyper {
    fn default() -> Hyper {
        Hyper {
            gamma: 0.99,
            tau: 0.005,
            learning_rate: 3e-4,
            adam_epsilon: 1e-8,
            initial_alpha: 0.2,
            autotune_alpha: true,
        }
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

/// What the training loop needs of an algorithm.
pub trait Agent {
    /// Actions `[rows, act_dim]` for `rows` augmented states `[rows, obs + Δ·act]`.
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32>;
    /// Deterministic actions of a delay-free policy for `rows` true states `[rows, obs]`, for
    /// algorithms that learn one (D2HPG's abstract policy), evaluated undelayed.
    fn act_delay_free(&mut self, _states: &[f32], _rows: usize) -> Option<Vec<f32>> {
        None
    }
    /// One gradient update of every learner from a batch; returns named statistics.
    fn update(&mut self, batch: &Transitions) -> Vec<(&'static str, f64)>;
    /// Networks, optimiser states and random streams, into `dir`.
    fn save(&self, dir: &Path) -> Result<(), LearnError>;
    /// Restores what [`Agent::save`] wrote.
    fn load(&mut self, dir: &Path) -> Result<(), LearnError>;
}

/// Builds the agent of `algo` (`lifting` is used by the D2HPG variants only).
pub fn build_agent(
    algo: Algo,
    spec: &AgentSpec,
    hyper: &Hyper,
    lifting: &Lifting,
    devices: &Devices,
    seed: u64,
) -> Box<dyn Agent> {
    match algo {
        Algo::Bpql => Box::new(Bpql::new(spec, hyper, devices, seed)),
        Algo::D2hpgNaive => Box::new(D2hpg::new(
            Regular::LiftingOnly,
            *lifting,
            spec,
            hyper,
            devices,
            seed,
        )),
        Algo::D2hpg => Box::new(D2hpg::new(
            Regular::Bpql,
            *lifting,
            spec,
            hyper,
            devices,
            seed,
        )),
        Algo::Sac => Box::new(sac::delay_free_sac(spec, hyper, devices, seed)),
        Algo::NaiveSac => Box::new(naive_sac::naive_sac(spec, hyper, devices, seed)),
        Algo::AugmentedSac => Box::new(augmented_sac::augmented_sac(spec, hyper, devices, seed)),
    }
}

/// `n` random transitions at `spec`'s sizes (values uniform in [−1, 1), every fifth one
/// terminal): what update benchmarks and tests feed the learners, whose cost does not depend on
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
    }
}
