//! BPQL, belief-projection-based Q-learning (Kim et al., 2023): the actor acts on the
//! augmented state `x_t`, but its "beta" critic evaluates the true, time-aligned state `s_t`,
//! which the replay holds for every transition. With `a' ~ π(·|x')`:
//!
//! - critic target `y = r + γ·(1 − d)·(min_j Q̄_j(s', a') − α log π(a'|x'))`,
//! - critic loss `Σ_j E[(Q_j(s, a) − y)²]`,
//! - actor loss `E[α log π(a|x) − min_j Q_j(s, a)]`, `a ~ π(·|x)`,
//! - temperature and targets as in SAC.
//!
//! These are exactly [`SacLearner`]'s steps with the actor's input `x` and the critics' input
//! `s`, which is what [`transition_tensors`] hands it. BPQL is also the regular learner of
//! D2HPG (`d2hpg.rs`).
use std::path::Path;

use super::sac::{SacLearner, transition_tensors};
use super::{ActMode, Agent, AgentSpec, Hyper};
use crate::delay::Transitions;
use crate::learn::{Devices, LearnError};

pub struct Bpql {
    spec: AgentSpec,
    learner: SacLearner,
}

/// BPQL's learner: a [`SacLearner`] with the actor on `x` and the critics on `s`. D2HPG's
/// regular learner is the same.
pub fn bpql_learner(spec: &AgentSpec, hyper: &Hyper, devices: &Devices, seed: u64) -> SacLearner {
    SacLearner::new(
        spec.augmented_dim(),
        spec.obs_dim,
        spec,
        hyper,
        devices,
        seed,
    )
}

impl Bpql {
    pub fn new(spec: &AgentSpec, hyper: &Hyper, devices: &Devices, seed: u64) -> Bpql {
        Bpql {
            spec: spec.clone(),
            learner: bpql_learner(spec, hyper, devices, seed),
        }
    }
}

impl Agent for Bpql {
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        self.learner
            .act(augmented, rows, self.spec.augmented_dim(), mode)
    }

    fn update(&mut self, batch: &Transitions) -> Vec<(&'static str, f64)> {
        let stats = self
            .learner
            .update(&transition_tensors(batch, &self.learner.devices.plain));
        stats.named()
    }

    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.learner.save(dir, "")
    }

    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.learner.load(dir, "")
    }
}
