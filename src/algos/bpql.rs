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
//! `s` ([`beta_batch`]). BPQL is also the regular learner of D2HPG (`d2hpg.rs`).
use std::ops::Range;
use std::path::Path;

use burn::prelude::{Device, Tensor};

use super::agent::{ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo};
use super::context::UpdateContext;
use super::sac::{Config as SacConfig, SAC_STATS, SacBatch, SacLearner};
use super::stats::Stats;
use crate::acting::{ActingNetwork, PolicyInput};
use crate::delay::{ReplayError, Transitions};
use crate::learn::{Devices, LearnError, TransitionTensors};

crate::algo_config! {
    /// BPQL's configuration: SAC's.
    pub struct Config {
        ..sac: SacConfig;
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo {
        in_lifting_ablation: true,
        ..AlgoInfo::single_learner(
            "bpql",
            "BPQL",
            "actor on x_t, beta critic on the time-aligned true state s_t",
            true,
        )
    };

    fn validate(&self) -> Result<(), AlgoError> {
        self.sac.check(Self::INFO.name)
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(Bpql::stacked(spec, &self.sac, devices, seeds))
    }
}

pub struct Bpql {
    spec: AgentSpec,
    learner: SacLearner,
}

/// BPQL's learner for the runs of `seeds`: a [`SacLearner`] with the actor on `x` and the
/// critics on `s`. D2HPG's regular learner is the same.
pub fn bpql_learner(
    spec: &AgentSpec,
    hyper: &SacConfig,
    devices: &Devices,
    seeds: &[u64],
) -> SacLearner {
    SacLearner::stacked(
        spec.augmented_dim(),
        spec.obs_dim,
        spec,
        hyper,
        devices,
        seeds,
    )
}

impl Bpql {
    /// One run's agent.
    pub fn new(spec: &AgentSpec, hyper: &SacConfig, devices: &Devices, seed: u64) -> Bpql {
        Bpql::stacked(spec, hyper, devices, &[seed])
    }

    /// The runs of `seeds`, one stacked learner.
    pub fn stacked(spec: &AgentSpec, hyper: &SacConfig, devices: &Devices, seeds: &[u64]) -> Bpql {
        Bpql {
            spec: spec.clone(),
            learner: bpql_learner(spec, hyper, devices, seeds),
        }
    }
}

impl Agent for Bpql {
    fn acting_network(&self) -> ActingNetwork {
        ActingNetwork::Policy {
            input: PolicyInput::AugmentedState,
            policy: self.learner.actor.weights(0),
        }
    }

    fn stat_names(&self) -> Vec<&'static str> {
        SAC_STATS.to_vec()
    }

    fn runs(&self) -> usize {
        self.learner.runs()
    }

    fn spec(&self) -> &AgentSpec {
        &self.spec
    }

    fn acting_device(&self) -> &Device {
        &self.learner.devices.plain
    }

    fn act_tensor(
        &mut self,
        runs: Range<usize>,
        augmented: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3> {
        self.learner.act_tensor(runs, augmented, counts, mode)
    }

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        self.learner.update_runs(contexts, beta_batch)
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.learner.save(dirs, "")
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.learner.load(dirs, "")
    }
}

/// BPQL's split of the runs' batches: the actor on `(x, x')`, the beta critic on `(s, s')`.
pub(super) fn beta_batch(batches: &[Transitions], device: &Device) -> SacBatch {
    let t = TransitionTensors::stacked(batches, device);
    SacBatch::new(
        &t,
        (t.augmented.clone(), t.next_augmented.clone()),
        (t.state.clone(), t.next_state.clone()),
    )
}
