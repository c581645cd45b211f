//! The lifting loss's settings (Eq. 4 of this repository's paper), shared by every D2HPG variant
//! (`d2hpg`, `d2hpg-sac`, `d2hpg-naive`, `d2hpg-principled`): λ and its schedule over the run's
//! steps, K samples per state, whether the two policies' samples share their noise, and the
//! reduction over action dimensions. The paper states none of them; dhrl's defaults come from
//! its grid (docs/experiments.md, "Lifting defaults"), the `authors` protocol's from the
//! released code.
use burn::prelude::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::agent::{AlgoError, check};
use crate::learn::{Noise, lifting_loss};
use crate::protocol::Protocol;

crate::algo_config! {
    /// The lifting loss's weight, schedule, samples, noise and reduction.
    pub struct LiftingConfig {
        /// λ, the weight of L_lift in the regular actor's loss, and its largest value under a
        /// schedule (1: ahead of the settings compared in docs/experiments.md on HalfCheetah at
        /// Δ = 10, two seeds; the authors' code: 10).
        pub lifting_weight: f64 = 1.0,
        /// How λ moves over the run: "constant", or "hold-decay" (λ until `lifting_hold` of the
        /// budget, then linearly to 0 at `lifting_decay_end`: the authors' code).
        pub lifting_schedule: LiftingSchedule = LiftingSchedule::Constant,
        /// Under "hold-decay", the fraction of the budget λ is held for.
        pub lifting_hold: f64 = 0.25,
        /// Under "hold-decay", the fraction of the budget at which λ reaches 0.
        pub lifting_decay_end: f64 = 0.75,
        /// Environment steps the schedule spans: 0 takes the run's `steps` when it starts and
        /// records them, so a run extended on resume keeps its original schedule.
        pub lifting_budget: u64 = 0,
        /// K, samples per state for the means and standard deviations of L_lift (at least 2;
        /// the authors' code: 100).
        pub lifting_samples: usize = 2,
        /// L_lift over action dimensions: "sum" (Eq. 4's squared norms) or "mean" (the authors'
        /// `F.mse_loss`, 1/dim(A) of the sum).
        pub lifting_reduction: Reduction = Reduction::Sum,
        /// The two policies' K samples: "common" (the same ε for both, so that the moments
        /// agree exactly when the distributions do) or "independent" (the authors' code).
        pub lifting_noise: LiftingNoise = LiftingNoise::Common,
    }
}

/// How λ moves over a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LiftingSchedule {
    Constant,
    HoldDecay,
}

/// A loss's reduction over a vector's dimensions: summed, or averaged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reduction {
    Sum,
    Mean,
}

/// Whether the two policies' lifting samples share their noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LiftingNoise {
    Common,
    Independent,
}

impl LiftingConfig {
    /// The settings under `protocol`: the authors' code holds λ = 10 to a quarter of the run
    /// and decays it to 0 at three quarters (`--update-type decay`, their default), with
    /// K = 100 independent samples and the loss averaged over action dimensions.
    pub fn protocol_defaults(protocol: Protocol) -> LiftingConfig {
        match protocol {
            Protocol::Dhrl => LiftingConfig::default(),
            Protocol::Authors => LiftingConfig {
                lifting_weight: 10.0,
                lifting_schedule: LiftingSchedule::HoldDecay,
                lifting_samples: 100,
                lifting_reduction: Reduction::Mean,
                lifting_noise: LiftingNoise::Independent,
                ..LiftingConfig::default()
            },
        }
    }

    /// Checks λ, K and the schedule's fractions, naming `algo` in the errors.
    pub fn check(&self, algo: &'static str) -> Result<(), AlgoError> {
        check(
            self.lifting_weight >= 0.0 && self.lifting_weight.is_finite(),
            algo,
            "lifting_weight",
            "a finite number ≥ 0",
            self.lifting_weight,
        )?;
        check(
            self.lifting_samples >= 2,
            algo,
            "lifting_samples",
            "at least 2 (standard deviations need two samples)",
            self.lifting_samples,
        )?;
        check(
            (0.0..=1.0).contains(&self.lifting_hold)
                && self.lifting_hold <= self.lifting_decay_end
                && self.lifting_decay_end <= 1.0,
            algo,
            "lifting_hold and lifting_decay_end",
            "fractions of the budget with 0 ≤ lifting_hold ≤ lifting_decay_end ≤ 1",
            format!("{} and {}", self.lifting_hold, self.lifting_decay_end),
        )
    }

    /// λ at `env_steps` environment steps: constant, or under "hold-decay" λ while
    /// `env_steps ≤ ⌊hold·budget⌋`, 0 from `⌊decay_end·budget⌋` on and linear between (the
    /// authors' `lifting_coef`).
    pub fn weight_at(&self, env_steps: u64) -> f64 {
        if self.lifting_schedule == LiftingSchedule::Constant {
            return self.lifting_weight;
        }
        let budget = self.lifting_budget as f64;
        let (hold, end) = (
            (budget * self.lifting_hold).floor(),
            (budget * self.lifting_decay_end).floor(),
        );
        let step = env_steps as f64;
        if step <= hold {
            self.lifting_weight
        } else if step >= end {
            0.0
        } else {
            self.lifting_weight * (1.0 - (step - hold) / (end - hold))
        }
    }

    /// [`super::AlgoConfig::for_budget`]: a "hold-decay" schedule not yet fixed spans `steps`.
    pub fn with_budget(&self, steps: u64) -> LiftingConfig {
        let unfixed =
            self.lifting_schedule == LiftingSchedule::HoldDecay && self.lifting_budget == 0;
        LiftingConfig {
            lifting_budget: if unfixed { steps } else { self.lifting_budget },
            ..self.clone()
        }
    }

    /// [`super::AlgoConfig::budget`].
    pub fn scheduled_budget(&self) -> Option<u64> {
        (self.lifting_schedule == LiftingSchedule::HoldDecay).then_some(self.lifting_budget)
    }

    /// The standard normal draws of both sides, each `[K, S, rows, ·]`: the target policy's
    /// (`target_width` wide) and the regular policy's (`width` wide), the same tensor under
    /// "common" noise where the widths agree, else a draw of its own.
    pub fn draws(
        &self,
        noise: &mut [Noise],
        rows: usize,
        (target_width, width): (usize, usize),
        device: &Device,
    ) -> (Tensor<4>, Tensor<4>) {
        let k = self.lifting_samples;
        let target = Noise::stacked_normal_k(noise, k, rows, target_width, device);
        let regular = match self.lifting_noise {
            LiftingNoise::Common if target_width == width => target.clone(),
            _ => Noise::stacked_normal_k(noise, k, rows, width, device),
        };
        (target, regular)
    }

    /// L_lift (Eq. 4) per run `[S]` of the regular policy's `[K, S, B, A]` samples against the
    /// target's, in the configured reduction over the A action dimensions.
    pub fn loss(&self, regular: Tensor<4>, target: Tensor<4>) -> Tensor<1> {
        let act = regular.dims()[3];
        let summed = lifting_loss(regular, target);
        match self.lifting_reduction {
            Reduction::Sum => summed,
            Reduction::Mean => summed.div_scalar(act as f64),
        }
    }
}
