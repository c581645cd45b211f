//! D2HPG, the deep delayed homomorphic policy gradient (this repository's paper, section 4 and
//! the appendix "Pseudo-code for D2HPG"), in its practical instantiation: under (near-)
//! deterministic dynamics the delay-free MDP is the homomorphic image of the delayed one
//! (Prop. 4.2), so the abstract policy and critic are a delay-free SAC trained on the
//! time-aligned `(s, a, r, s')` of the replay, and the regular policy on `x` is pulled toward
//! it by the lifting loss (Eq. 5).
//!
//! One update, top to bottom:
//! 1. the delay-free (abstract) SAC learner takes a SAC step on `(s, a, r, s')`;
//! 2. the delay-free policy's squashed actions at `s` — K samples per state, from its
//!    distribution as it was before step 1 (computed there anyway) — are drawn and held fixed;
//! 3. `d2hpg`: the regular learner takes a BPQL step (beta critic on `s`, actor on `x`, see
//!    `bpql.rs`) whose actor loss also carries `λ·L_lift`;
//!    `d2hpg-naive`: the regular policy is updated by `λ·L_lift` alone.
//!
//! The regular policy is the one that acts; the delay-free one can be evaluated undelayed.
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::bpql::bpql_learner;
use super::sac::{SacBatch, SacLearner, transition_tensors};
use super::{ActMode, Agent, AgentSpec, Hyper};
use crate::delay::Transitions;
use crate::learn::{Devices, LearnError, Noise, lifting_loss, squashed_samples_k};

/// How strongly, and from how many samples, the regular policy is lifted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Lifting {
    /// λ, the weight of `L_lift` in the regular actor's loss.
    pub weight: f64,
    /// K, samples per state for the means and standard deviations (at least 2).
    pub samples: usize,
}

impl Default for Lifting {
    /// λ = 1, K = 2: ahead of the other settings compared in the README on HalfCheetah at
    /// Δ = 10 (two seeds); InvertedPendulum at Δ = 10 does not separate them.
    fn default() -> Lifting {
        Lifting {
            weight: 1.0,
            samples: 2,
        }
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

/// The seed of the delay-free learner of a D2HPG agent seeded with `seed`: the learner is the
/// same as a delay-free [`SacLearner`] built with this seed.
pub fn delay_free_seed(seed: u64) -> u64 {
    seed ^ 0xA857_AC7
}
/// Seed offset of the lifting loss's samples.
const LIFTING_SEED: u64 = 0x11F7;

pub struct D2hpg {
    spec: AgentSpec,
    regular_kind: Regular,
    lifting: Lifting,
    /// Actor on `x`, beta critic on `s` (BPQL); only the actor is used by `d2hpg-naive`.
    regular: SacLearner,
    /// SAC on the true state: the abstract policy and critic.
    delay_free: SacLearner,
    lifting_noise: Noise,
}

impl D2hpg {
    pub fn new(
        regular_kind: Regular,
        lifting: Lifting,
        spec: &AgentSpec,
        hyper: &Hyper,
        devices: &Devices,
        seed: u64,
    ) -> D2hpg {
        D2hpg {
            spec: spec.clone(),
            regular_kind,
            lifting,
            regular: bpql_learner(spec, hyper, devices, seed),
            delay_free: SacLearner::new(
                spec.obs_dim,
                spec.obs_dim,
                spec,
                hyper,
                devices,
                delay_free_seed(seed),
            ),
            lifting_noise: Noise::new(seed ^ LIFTING_SEED),
        }
    }
}

impl Agent for D2hpg {
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        self.regular
            .act(augmented, rows, self.spec.augmented_dim(), mode)
    }

    fn act_delay_free(&mut self, states: &[f32], rows: usize) -> Option<Vec<f32>> {
        Some(
            self.delay_free
                .act(states, rows, self.spec.obs_dim, ActMode::Deterministic),
        )
    }

    fn update(&mut self, batch: &Transitions) -> Vec<(&'static str, f64)> {
        let plain = self.regular.devices.plain.clone();
        let regular_batch = transition_tensors(batch, &plain);
        let (rows, k, act) = (batch.len(), self.lifting.samples, self.spec.act_dim);

        // 1. The delay-free (abstract) SAC on the time-aligned (s, a, r, s'); its actor's
        //    distribution at s, as it was before this step, is kept off the graph.
        let free_batch = SacBatch {
            actor_input: regular_batch.critic_input.clone(),
            next_actor_input: regular_batch.next_critic_input.clone(),
            ..regular_batch.clone()
        };
        let mut free_distribution = None;
        let free = self.delay_free.update_with(&free_batch, |(mean, log_std)| {
            free_distribution = Some((mean.inner(), log_std.inner()));
            None
        });
        let free_distribution = free_distribution.expect("the actor step hands its distribution");

        // 2. Its squashed actions at s, K per state, held fixed for this update. The regular
        //    policy's K samples below reuse the same ε (common random numbers): the two sets
        //    of moments are then equal exactly when the two distributions are.
        let eps = self.lifting_noise.normal3(k, rows, act, &plain);
        let free_actions =
            squashed_samples_k(free_distribution, eps.clone(), &self.delay_free.scale);

        // 3. The regular policy, pulled toward it by λ·L_lift (Eq. 5), from its distribution
        //    at x (the BPQL actor term shares that trunk pass). train.csv logs L_lift itself.
        let (weight, scale) = (self.lifting.weight, self.regular.scale.clone());
        let mut lifting = 0.0;
        let lift = |distribution| {
            let loss = lifting_loss(squashed_samples_k(distribution, eps, &scale), free_actions);
            lifting = f64::from(loss.clone().inner().into_scalar::<f32>());
            loss.mul_scalar(weight)
        };
        let mut stats = vec![
            ("free_critic_loss", free.critic_loss),
            ("free_actor_loss", free.actor_loss),
            ("free_alpha", free.alpha),
        ];
        match self.regular_kind {
            Regular::Bpql => {
                let regular = self
                    .regular
                    .update_with(&regular_batch, |distribution| Some(lift(distribution)));
                stats.extend([
                    ("critic_loss", regular.critic_loss),
                    ("actor_loss", regular.actor_loss),
                    ("alpha", regular.alpha),
                ]);
            }
            Regular::LiftingOnly => {
                let x = regular_batch.actor_input;
                self.regular
                    .update_actor_with(|actor| lift(actor.distribution(x)));
            }
        }
        stats.push(("lifting_loss", lifting));
        stats
    }

    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.regular.save(dir, "regular_")?;
        self.delay_free.save(dir, "delay_free_")?;
        let path = dir.join("lifting_noise.json");
        let text = serde_json::to_vec(&self.lifting_noise).map_err(|e| LearnError::Save {
            what: path.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(&path, text).map_err(|e| LearnError::Save {
            what: path.display().to_string(),
            message: e.to_string(),
        })
    }

    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.regular.load(dir, "regular_")?;
        self.delay_free.load(dir, "delay_free_")?;
        let path = dir.join("lifting_noise.json");
        let load_error = |e: String| LearnError::Load {
            what: path.display().to_string(),
            message: e,
        };
        let bytes = std::fs::read(&path).map_err(|e| load_error(e.to_string()))?;
        self.lifting_noise =
            serde_json::from_slice(&bytes).map_err(|e| load_error(e.to_string()))?;
        Ok(())
    }
}
