//! D2HPG, the deep delayed homomorphic policy gradient (this repository's paper, section 4 and
//! the appendix "Pseudo-code for D2HPG"), in its practical instantiation: under (near-)
//! deterministic dynamics the delay-free MDP is the homomorphic image of the delayed one
//! (Prop. 4.2), so the abstract policy and critic are a delay-free SAC trained on the
//! time-aligned `(s, a, r, s')` of the replay, and the regular policy on `x` is pulled toward
//! it by the lifting loss (Eq. 4).
//!
//! One update, top to bottom:
//! 1. both critics step: the regular learner's beta critic on `s` (BPQL, see `bpql.rs`; not
//!    in `d2hpg-naive`) and the delay-free (abstract) SAC critic on `(s, a, r, s')`;
//! 2. the delay-free policy's squashed actions at `s` — K samples per state, from its
//!    distribution before this update — are drawn and held fixed;
//! 3. `d2hpg`: the regular actor on `x` takes BPQL's actor step whose loss also carries
//!    `λ·L_lift`; `d2hpg-naive`: the regular policy is updated by `λ·L_lift` alone; the
//!    delay-free actor takes its SAC step; temperatures and targets follow.
//!
//! The two learners share no parameters, so steps 1 and 3 run them side by side on rayon's
//! threads (one after the other on one thread, with the same numbers).
//!
//! The regular policy is the one that acts; the delay-free one can be evaluated undelayed.
use std::ops::Range;
use std::path::Path;

use burn::prelude::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::agent::{
    ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, ConfigFields, FieldDoc, Role, check,
};
use super::bpql::{beta_batch, bpql_learner};
use super::context::UpdateContext;
use super::sac::{Config as SacConfig, SacBatch, SacLearner};
use super::stats::Stats;
use crate::acting::{ActingNetwork, PolicyInput};
use crate::delay::ReplayError;
use crate::learn::{
    CheckpointDir, Devices, LearnError, Noise, lifting_loss, load_json_stack, squashed_samples_k,
};
use crate::seeds;

crate::algo_config! {
    /// D2HPG's configuration: SAC's, for both learners, and the lifting loss.
    pub struct Config {
        ..sac: SacConfig;
        /// λ, the weight of L_lift in the regular actor's loss (1: ahead of the settings
        /// compared in docs/experiments.md on HalfCheetah at Δ = 10, two seeds).
        pub lifting_weight: f64 = 1.0,
        /// K, samples per state for the means and standard deviations of L_lift (at least 2).
        pub lifting_samples: usize = 2,
    }
}

impl Config {
    fn check(&self, algo: &'static str) -> Result<(), AlgoError> {
        self.sac.check(algo)?;
        check_lifting(algo, self.lifting_weight, self.lifting_samples)
    }
}

/// Checks λ and K, naming `algo` in the errors (principled D2HPG's lifting loss too).
pub(super) fn check_lifting(
    algo: &'static str,
    lifting_weight: f64,
    lifting_samples: usize,
) -> Result<(), AlgoError> {
    check(
        lifting_weight >= 0.0 && lifting_weight.is_finite(),
        algo,
        "lifting_weight",
        "a finite number ≥ 0",
        lifting_weight,
    )?;
    check(
        lifting_samples >= 2,
        algo,
        "lifting_samples",
        "at least 2 (standard deviations need two samples)",
        lifting_samples,
    )
}

/// What both variants declare, but for their names.
const D2HPG_INFO: AlgoInfo = AlgoInfo {
    name: "d2hpg",
    paper_name: "D2HPG",
    role: Role::Proposed,
    in_lifting_ablation: true,
    about: "the paper's D2HPG(-BPQL): BPQL, a delay-free SAC, and the lifting loss",
    acts_on_augmented_state: true,
    delay_free_policy: true,
    undelayed_only: false,
    delayed_only: false,
    learner_threads: 2,
    cpu_runs_per_pass: 2,
    label_fields: &[("λ", "lifting_weight"), ("K", "lifting_samples")],
};

impl AlgoConfig for Config {
    const INFO: AlgoInfo = D2HPG_INFO;

    fn validate(&self) -> Result<(), AlgoError> {
        self.check(Self::INFO.name)
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(D2hpg::new(Regular::Bpql, self, spec, devices, seeds))
    }
}

/// `d2hpg-naive`'s configuration: D2HPG's (its regular learner uses the actor part only).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct NaiveConfig(pub Config);

impl ConfigFields for NaiveConfig {
    fn field_docs() -> Vec<FieldDoc> {
        Config::field_docs()
    }
}

impl AlgoConfig for NaiveConfig {
    const INFO: AlgoInfo = AlgoInfo {
        name: "d2hpg-naive",
        paper_name: "D2HPG-naive",
        role: Role::Ablation,
        about: "a delay-free SAC plus a regular policy trained by the lifting loss only",
        ..D2HPG_INFO
    };

    fn validate(&self) -> Result<(), AlgoError> {
        self.0.check(Self::INFO.name)
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(D2hpg::new(
            Regular::LiftingOnly,
            &self.0,
            spec,
            devices,
            seeds,
        ))
    }
}

/// Which regular learner D2HPG pairs with the delay-free one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regular {
    /// BPQL plus the lifting loss (`d2hpg`, the paper's D2HPG-BPQL).
    Bpql,
    /// The lifting loss alone (`d2hpg-naive`).
    LiftingOnly,
}

/// `train.csv` columns: the delay-free learner's, the regular BPQL learner's (`d2hpg` only),
/// and the unweighted lifting loss.
const FREE_STATS: [&str; 3] = ["free_critic_loss", "free_actor_loss", "free_alpha"];
const REGULAR_STATS: [&str; 3] = ["critic_loss", "actor_loss", "alpha"];
const LIFTING_STAT: &str = "lifting_loss";

/// D2HPG for a stack of runs (a solo run is S = 1): both learners stacked, a lifting noise
/// stream per run.
pub struct D2hpg {
    spec: AgentSpec,
    regular_kind: Regular,
    /// λ and K.
    lifting_weight: f64,
    lifting_samples: usize,
    /// Actor on `x`, beta critic on `s` (BPQL); only the actor is used by `d2hpg-naive`.
    regular: SacLearner,
    /// SAC on the true state: the abstract policy and critic.
    delay_free: SacLearner,
    lifting_noise: Vec<Noise>,
}

impl D2hpg {
    /// The runs of `seeds`.
    pub fn new(
        regular_kind: Regular,
        config: &Config,
        spec: &AgentSpec,
        devices: &Devices,
        seeds: &[u64],
    ) -> D2hpg {
        let free_seeds: Vec<u64> = seeds
            .iter()
            .map(|&s| seeds::delay_free_learner(s))
            .collect();
        D2hpg {
            spec: spec.clone(),
            regular_kind,
            lifting_weight: config.lifting_weight,
            lifting_samples: config.lifting_samples,
            regular: bpql_learner(spec, &config.sac, devices, seeds),
            delay_free: SacLearner::on_state(spec, &config.sac, devices, &free_seeds),
            lifting_noise: seeds
                .iter()
                .map(|&seed| Noise::new(seeds::lifting_noise(seed)))
                .collect(),
        }
    }
}

impl Agent for D2hpg {
    fn runs(&self) -> usize {
        self.regular.runs()
    }

    fn spec(&self) -> &AgentSpec {
        &self.spec
    }

    fn acting_device(&self) -> &Device {
        &self.regular.devices.plain
    }

    fn act_tensor(
        &mut self,
        runs: Range<usize>,
        augmented: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3> {
        self.regular.act_tensor(runs, augmented, counts, mode)
    }

    fn acting_network(&self) -> ActingNetwork {
        ActingNetwork::Policy {
            input: PolicyInput::AugmentedState,
            policy: self.regular.actor.weights(0),
        }
    }

    fn act_delay_free(&mut self, states: &[f32], rows: usize) -> Option<Vec<f32>> {
        Some(
            self.delay_free
                .act_run(0, states, rows, self.spec.obs_dim, ActMode::Deterministic),
        )
    }

    fn stat_names(&self) -> Vec<&'static str> {
        let regular: &[&'static str] = match self.regular_kind {
            Regular::Bpql => &REGULAR_STATS,
            Regular::LiftingOnly => &[],
        };
        FREE_STATS
            .iter()
            .chain(regular)
            .chain(&[LIFTING_STAT])
            .copied()
            .collect()
    }

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        let plain = self.regular.devices.plain.clone();
        let regular_batch = beta_batch(&UpdateContext::batches(contexts)?, &plain);
        // The delay-free learner: actor and critics on the true state.
        let free_batch = SacBatch {
            actor_input: regular_batch.critic_input.clone(),
            next_actor_input: regular_batch.next_critic_input.clone(),
            ..regular_batch.clone()
        };
        let (rows, k, act) = (
            regular_batch.rows(),
            self.lifting_samples,
            self.spec.act_dim,
        );
        let with_bpql = self.regular_kind == Regular::Bpql;
        let (regular, delay_free) = (&mut self.regular, &mut self.delay_free);
        let (alphas, free_alphas) = (
            regular.temperature.alpha_values(),
            delay_free.temperature.alpha_values(),
        );

        // 1. The critics of both learners (the pseudo-code's joint critic step): the beta
        //    critic on (s, a) for BPQL, the delay-free critic on the time-aligned (s, a, r, s');
        //    and both policies' distributions, at x and at s, before either policy moves. The
        //    learners share no parameters and draw from their own noise streams, so rayon runs
        //    them side by side when it has two threads, with the same numbers as one after
        //    the other.
        let ((critic_losses, regular_distribution), (free_critic_losses, free_distribution)) =
            rayon::join(
                || {
                    let losses = with_bpql.then(|| regular.update_critics(&regular_batch));
                    (losses, regular.distribution(&regular_batch))
                },
                || {
                    let losses = delay_free.update_critics(&free_batch);
                    (losses, delay_free.distribution(&free_batch))
                },
            );
        regular.devices.settle();

        // 2. The delay-free policy's squashed actions at s, K per state, from its distribution
        //    before this update, held fixed. The regular policy's K samples reuse the same ε
        //    (common random numbers): the two sets of moments are then equal exactly when the
        //    two distributions are. L_lift (Eq. 4) is logged unweighted, per run.
        let eps = Noise::stacked_normal_k(&mut self.lifting_noise, k, rows, act, &plain);
        let (free_mean, free_log_std) = free_distribution.clone();
        let free_actions = squashed_samples_k(
            (free_mean.inner(), free_log_std.inner()),
            eps.clone(),
            &delay_free.scale,
        );
        let regular_actions = squashed_samples_k(regular_distribution.clone(), eps, &regular.scale);
        let lifting = lifting_loss(regular_actions, free_actions);
        let lifting_values = lifting.clone().inner();
        let lift = lifting.mul_scalar(self.lifting_weight).sum();

        // 3. The policies, side by side again: `d2hpg` takes BPQL's actor step with λ·L_lift
        //    in its loss, `d2hpg-naive` steps on λ·L_lift alone; the delay-free learner takes
        //    its SAC actor step; then each its temperature and targets.
        let (actor_losses, (free_actor_losses, _)) = rayon::join(
            || {
                if with_bpql {
                    let (actor_losses, _) =
                        regular.update_policy(&regular_batch, regular_distribution, Some(lift));
                    Some(actor_losses)
                } else {
                    regular.update_actor_by(lift);
                    None
                }
            },
            || delay_free.update_policy(&free_batch, free_distribution, None),
        );

        let mut stats = Stats::new();
        for (name, values) in
            FREE_STATS
                .into_iter()
                .zip([free_critic_losses, free_actor_losses, free_alphas])
        {
            stats.push(name, values);
        }
        if let (Some(critic_losses), Some(actor_losses)) = (critic_losses, actor_losses) {
            for (name, values) in
                REGULAR_STATS
                    .into_iter()
                    .zip([critic_losses, actor_losses, alphas])
            {
                stats.push(name, values);
            }
        }
        stats.push(LIFTING_STAT, lifting_values);
        regular.devices.settle();
        Ok(stats)
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.regular.save(dirs, "regular_")?;
        self.delay_free.save(dirs, "delay_free_")?;
        for (dir, noise) in dirs.iter().zip(&self.lifting_noise) {
            CheckpointDir::new(dir).save_json("lifting_noise.json", noise)?;
        }
        Ok(())
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.regular.load(dirs, "regular_")?;
        self.delay_free.load(dirs, "delay_free_")?;
        self.lifting_noise = load_json_stack(&CheckpointDir::each(dirs, ""), "lifting_noise.json")?;
        Ok(())
    }
}
