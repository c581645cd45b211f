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
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::agent::{
    ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, ConfigFields, FieldDoc, Role,
    Stats, check,
};
use super::bpql::{beta_batch, bpql_learner};
use super::context::UpdateContext;
use super::sac::{Config as SacConfig, SacBatch, SacLearner};
use crate::acting::{ActingNetwork, PolicyInput};
use crate::delay::ReplayError;
use crate::learn::{
    CheckpointDir, Devices, LearnError, Noise, lifting_loss, one_run, squashed_samples_k,
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
    stacked_learner: false,
    label_fields: &[("λ", "lifting_weight"), ("K", "lifting_samples")],
};

impl AlgoConfig for Config {
    const INFO: AlgoInfo = D2HPG_INFO;

    fn validate(&self) -> Result<(), AlgoError> {
        self.check(Self::INFO.name)
    }

    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        Box::new(D2hpg::new(Regular::Bpql, self, spec, devices, seed))
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

    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        Box::new(D2hpg::new(
            Regular::LiftingOnly,
            &self.0,
            spec,
            devices,
            seed,
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
    lifting_noise: Noise,
}

impl D2hpg {
    pub fn new(
        regular_kind: Regular,
        config: &Config,
        spec: &AgentSpec,
        devices: &Devices,
        seed: u64,
    ) -> D2hpg {
        D2hpg {
            spec: spec.clone(),
            regular_kind,
            lifting_weight: config.lifting_weight,
            lifting_samples: config.lifting_samples,
            regular: bpql_learner(spec, &config.sac, devices, &[seed]),
            delay_free: SacLearner::new(
                spec.obs_dim,
                spec.obs_dim,
                spec,
                &config.sac,
                devices,
                seeds::delay_free_learner(seed),
            ),
            lifting_noise: Noise::new(seeds::lifting_noise(seed)),
        }
    }
}

impl Agent for D2hpg {
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        self.regular
            .act_run(0, augmented, rows, self.spec.augmented_dim(), mode)
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

    fn update(&mut self, ctx: &mut UpdateContext<'_>) -> Result<Stats, ReplayError> {
        let batch = &ctx.batch()?;
        let plain = self.regular.devices.plain.clone();
        let regular_batch = beta_batch(batch, &plain);
        // The delay-free learner: actor and critics on the true state.
        let free_batch = SacBatch {
            actor_input: regular_batch.critic_input.clone(),
            next_actor_input: regular_batch.next_critic_input.clone(),
            ..regular_batch.clone()
        };
        let (rows, k, act) = (batch.len(), self.lifting_samples, self.spec.act_dim);
        let with_bpql = self.regular_kind == Regular::Bpql;
        let (regular, delay_free) = (&mut self.regular, &mut self.delay_free);
        let (alpha, free_alpha) = (
            regular.temperature.alphas()[0],
            delay_free.temperature.alphas()[0],
        );

        // 1. The critics of both learners (the pseudo-code's joint critic step): the beta
        //    critic on (s, a) for BPQL, the delay-free critic on the time-aligned (s, a, r, s');
        //    and both policies' distributions, at x and at s, before either policy moves. The
        //    learners share no parameters and draw from their own noise streams, so rayon runs
        //    them side by side when it has two threads, with the same numbers as one after
        //    the other.
        let ((critic_loss, regular_distribution), (free_critic_loss, free_distribution)) =
            rayon::join(
                || {
                    let loss = with_bpql.then(|| regular.update_critics(&regular_batch));
                    (loss, regular.distribution(&regular_batch))
                },
                || {
                    let loss = delay_free.update_critics(&free_batch);
                    (loss, delay_free.distribution(&free_batch))
                },
            );

        // 2. The delay-free policy's squashed actions at s, K per state, from its distribution
        //    before this update, held fixed. The regular policy's K samples reuse the same ε
        //    (common random numbers): the two sets of moments are then equal exactly when the
        //    two distributions are. L_lift (Eq. 4) is logged unweighted.
        let eps = self.lifting_noise.normal3(k, rows, act, &plain);
        let (free_mean, free_log_std) = one_run(free_distribution.clone());
        let free_actions = squashed_samples_k(
            (free_mean.inner(), free_log_std.inner()),
            eps.clone(),
            &delay_free.scale,
        );
        let regular_actions =
            squashed_samples_k(one_run(regular_distribution.clone()), eps, &regular.scale);
        let lifting = lifting_loss(regular_actions, free_actions);
        let lifting_value = f64::from(lifting.clone().inner().into_scalar::<f32>());
        let lift = lifting.mul_scalar(self.lifting_weight);

        // 3. The policies, side by side again: `d2hpg` takes BPQL's actor step with λ·L_lift
        //    in its loss, `d2hpg-naive` steps on λ·L_lift alone; the delay-free learner takes
        //    its SAC actor step; then each its temperature and targets.
        let (actor_loss, (free_actor_loss, _)) = rayon::join(
            || {
                if with_bpql {
                    let (actor_loss, _) =
                        regular.update_policy(&regular_batch, regular_distribution, Some(lift));
                    Some(actor_loss)
                } else {
                    regular.update_actor_by(lift);
                    None
                }
            },
            || delay_free.update_policy(&free_batch, free_distribution, None),
        );

        let mut stats: Stats = FREE_STATS
            .into_iter()
            .zip([free_critic_loss[0], free_actor_loss[0], free_alpha])
            .collect();
        if let (Some(critic_loss), Some(actor_loss)) = (critic_loss, actor_loss) {
            stats.extend(
                REGULAR_STATS
                    .into_iter()
                    .zip([critic_loss[0], actor_loss[0], alpha]),
            );
        }
        stats.push((LIFTING_STAT, lifting_value));
        Ok(stats)
    }

    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.regular.save(&[dir], "regular_")?;
        self.delay_free.save(&[dir], "delay_free_")?;
        CheckpointDir::new(dir).save_json("lifting_noise.json", &self.lifting_noise)
    }

    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.regular.load(&[dir], "regular_")?;
        self.delay_free.load(&[dir], "delay_free_")?;
        self.lifting_noise = CheckpointDir::new(dir).load_json("lifting_noise.json")?;
        Ok(())
    }
}
