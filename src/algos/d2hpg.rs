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
//! What the paper leaves open is a field each, with dhrl's choice as its default and the
//! authors' released code's under `--protocol authors` ([`Config::protocol_defaults`]): λ and its
//! schedule over the run's steps, K, whether the two policies' samples share their noise,
//! the loss's reduction over action dimensions, and whether the delay-free learner reads the
//! regular learner's α instead of its own.
//!
//! The regular policy is the one that acts; the delay-free one can be evaluated undelayed.
use std::ops::Range;
use std::path::Path;

use burn::prelude::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::agent::{
    ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, ConfigFields, FieldDoc, Role,
};
use super::bpql::bpql_learner;
use super::context::UpdateContext;
use super::lifting::{LiftingConfig, LiftingSchedule};
use super::sac::{Config as SacConfig, SacBatch, SacLearner};
use super::stats::Stats;
use crate::acting::{ActingNetwork, PolicyInput};
use crate::delay::ReplayError;
use crate::learn::{
    CheckpointDir, Devices, LearnError, Noise, TransitionTensors, load_json_stack,
    squashed_samples_k,
};
use crate::protocol::Protocol;
use crate::seeds;

crate::algo_config! {
    /// D2HPG's configuration: SAC's, for both learners, and the lifting loss's.
    pub struct Config {
        ..sac: SacConfig;
        ..lifting: LiftingConfig;
        /// One α for both learners (the authors' code): the delay-free learner's entropy terms
        /// read the regular learner's α, which the regular policy's entropy tunes; false: each
        /// learner its own.
        pub shared_temperature: bool = false,
    }
}

impl Config {
    fn check(&self, algo: &'static str) -> Result<(), AlgoError> {
        self.sac.check(algo)?;
        self.lifting.check(algo)
    }

    /// D2HPG's defaults under `protocol`: the authors' code adds to their lifting settings
    /// ([`LiftingConfig::protocol_defaults`]) one α for both learners.
    pub fn protocol_defaults(protocol: Protocol) -> Config {
        Config {
            sac: SacConfig::protocol_defaults(protocol),
            lifting: LiftingConfig::protocol_defaults(protocol),
            shared_temperature: protocol == Protocol::Authors,
        }
    }
}

/// What both variants declare, but for their names.
pub(super) const D2HPG_INFO: AlgoInfo = AlgoInfo {
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

    fn for_protocol(protocol: Protocol) -> Config {
        Config::protocol_defaults(protocol)
    }

    fn for_budget(&self, steps: u64) -> Config {
        Config {
            lifting: self.lifting.with_budget(steps),
            ..self.clone()
        }
    }

    fn budget(&self) -> Option<u64> {
        self.lifting.scheduled_budget()
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

    /// The authors' `d2hpg_naive.py`: λ = 10 without a schedule, K = 100 independent samples
    /// averaged over action dimensions, and the delay-free SAC's α never tuned (0.2).
    fn for_protocol(protocol: Protocol) -> NaiveConfig {
        let defaults = Config::protocol_defaults(protocol);
        NaiveConfig(match protocol {
            Protocol::Dhrl => defaults,
            Protocol::Authors => Config {
                sac: SacConfig {
                    autotune_alpha: false,
                    ..defaults.sac
                },
                lifting: LiftingConfig {
                    lifting_schedule: LiftingSchedule::Constant,
                    ..defaults.lifting
                },
                shared_temperature: false,
            },
        })
    }

    fn for_budget(&self, steps: u64) -> NaiveConfig {
        NaiveConfig(self.0.for_budget(steps))
    }

    fn budget(&self) -> Option<u64> {
        self.0.budget()
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
    /// Augmented SAC, actor and critic on `x`, plus the lifting loss (`d2hpg-sac`).
    AugmentedSac,
    /// The lifting loss alone (`d2hpg-naive`).
    LiftingOnly,
}

impl Regular {
    /// Whether the regular learner has a critic (and its own SAC step).
    fn has_critic(self) -> bool {
        self != Regular::LiftingOnly
    }
}

/// `train.csv` columns: the delay-free learner's, the regular learner's (not `d2hpg-naive`'s),
/// the unweighted lifting loss and its weight λ at the update.
const FREE_STATS: [&str; 3] = ["free_critic_loss", "free_actor_loss", "free_alpha"];
const REGULAR_STATS: [&str; 3] = ["critic_loss", "actor_loss", "alpha"];
const LIFTING_STATS: [&str; 2] = ["lifting_loss", "lifting_weight"];

/// D2HPG for a stack of runs (a solo run is S = 1): both learners stacked, a lifting noise
/// stream per run.
pub struct D2hpg {
    spec: AgentSpec,
    regular_kind: Regular,
    /// λ and its schedule, K, the noise, the reduction and the temperature's sharing.
    config: Config,
    /// Actor on `x`, critic on `s` (BPQL) or on `x` (augmented SAC); only the actor is used by
    /// `d2hpg-naive`.
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
        let regular = match regular_kind {
            Regular::AugmentedSac => SacLearner::stacked(
                spec.augmented_dim(),
                spec.augmented_dim(),
                spec,
                &config.sac,
                devices,
                seeds,
            ),
            Regular::Bpql | Regular::LiftingOnly => bpql_learner(spec, &config.sac, devices, seeds),
        };
        D2hpg {
            spec: spec.clone(),
            regular_kind,
            config: config.clone(),
            regular,
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
        let regular: &[&'static str] = match self.regular_kind.has_critic() {
            true => &REGULAR_STATS,
            false => &[],
        };
        FREE_STATS
            .iter()
            .chain(regular)
            .chain(&LIFTING_STATS)
            .copied()
            .collect()
    }

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        let plain = self.regular.devices.plain.clone();
        // The runs of a stack share one schedule: λ at this update's step.
        let lifting_weight = self.config.lifting.weight_at(contexts[0].env_steps);
        let t = TransitionTensors::stacked(&UpdateContext::batches(contexts)?, &plain);
        let state = (t.state.clone(), t.next_state.clone());
        let augmented = (t.augmented.clone(), t.next_augmented.clone());
        // The regular learner: its actor on x, its critic on s (BPQL) or on x (augmented SAC).
        let regular_batch = match self.regular_kind {
            Regular::AugmentedSac => SacBatch::new(&t, augmented.clone(), augmented),
            Regular::Bpql | Regular::LiftingOnly => SacBatch::new(&t, augmented, state.clone()),
        };
        // The delay-free learner: actor and critics on the true state.
        let free_batch = SacBatch::new(&t, state.clone(), state);
        let (rows, act) = (regular_batch.rows(), self.spec.act_dim);
        let with_critic = self.regular_kind.has_critic();
        let (regular, delay_free) = (&mut self.regular, &mut self.delay_free);
        // One α (the authors' code): the delay-free learner reads the regular learner's, as it
        // stands before this update's temperature step.
        delay_free.borrowed_alpha = self
            .config
            .shared_temperature
            .then(|| regular.temperature.alpha_tensor());
        let alphas = regular.temperature.alpha_values();
        let free_alphas = match self.config.shared_temperature {
            true => alphas.clone(),
            false => delay_free.temperature.alpha_values(),
        };

        // 1. The critics of both learners (the pseudo-code's joint critic step): the regular
        //    critic for BPQL (on s) or augmented SAC (on x), the delay-free critic on the
        //    time-aligned (s, a, r, s'); and both policies' distributions, at x and at s, before
        //    either policy moves. The learners share no parameters and draw from their own
        //    noise streams, so rayon runs them side by side when it has two threads, with the
        //    same numbers as one after the other.
        let ((critic_losses, regular_distribution), (free_critic_losses, free_distribution)) =
            rayon::join(
                || {
                    let losses = with_critic.then(|| regular.update_critics(&regular_batch));
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
        //    under "common" noise (the two sets of moments are then equal exactly when the two
        //    distributions are) and draw their own under "independent". L_lift (Eq. 4) is
        //    logged unweighted, per run, in the configured reduction.
        let (free_eps, regular_eps) =
            self.config
                .lifting
                .draws(&mut self.lifting_noise, rows, (act, act), &plain);
        let (free_mean, free_log_std) = free_distribution.clone();
        let free_actions = squashed_samples_k(
            (free_mean.inner(), free_log_std.inner()),
            free_eps,
            &delay_free.scale,
        );
        let regular_actions =
            squashed_samples_k(regular_distribution.clone(), regular_eps, &regular.scale);
        let lifting = self.config.lifting.loss(regular_actions, free_actions);
        let lifting_values = lifting.clone().inner();
        let lift = lifting.mul_scalar(lifting_weight).sum();

        // 3. The policies, side by side again: `d2hpg` and `d2hpg-sac` take their actor step
        //    with λ·L_lift in its loss, `d2hpg-naive` steps on λ·L_lift alone; the delay-free
        //    learner takes its SAC actor step; then each its temperature and targets.
        let (actor_losses, (free_actor_losses, _)) = rayon::join(
            || {
                if with_critic {
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
        let runs = lifting_values.dims()[0];
        stats.push(LIFTING_STATS[0], lifting_values);
        stats.push(
            LIFTING_STATS[1],
            Tensor::full([runs], lifting_weight, &plain),
        );
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
