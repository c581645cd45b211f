//! Soft Actor-Critic (Haarnoja et al. 2018) in burn: twin critics with Polyak-averaged targets
//! kept off the autodiff graph, a tanh-squashed Gaussian actor, and a learned temperature.
//!
//! [`SacLearner`] is the algorithm on an abstract input (whatever the policy conditions on);
//! [`SacAgent`] chooses that input from a transition. `sac` below is the delay-free reference
//! on the true state; `naive_sac.rs` and `augmented_sac.rs` are the two delayed baselines.
//! BPQL and D2HPG reuse [`SacLearner`] for their delay-free parts.
use std::path::Path;

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::prelude::*;

use super::agent::{
    ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, Role, Stats, check,
};
use super::context::UpdateContext;
use crate::acting::{ActingNetwork, PolicyInput};
use crate::delay::{ReplayError, Transitions};
use crate::learn::{
    ActionScale, CheckpointDir, Devices, GaussianPolicy, LearnError, Noise, Temperature,
    TransitionTensors, TwinQ, actor_loss, adam, critic_loss, critic_target, materialize, matrix,
    polyak, rows, squashed_sample, temperature_loss, to_vec,
};

crate::algo_config! {
    /// SAC's hyperparameters (docs/DESIGN.md §3.3): the configuration of `sac`, and the shared part of
    /// every algorithm built on [`SacLearner`].
    pub struct Config {
        /// Discount factor γ.
        pub gamma: f64 = 0.99,
        /// Polyak coefficient τ of the target critics.
        pub tau: f64 = 0.005,
        /// Adam learning rate of every network and of the temperature.
        pub learning_rate: f64 = 3e-4,
        /// Adam's ε (PyTorch's 1e-8, not burn's default 1e-5).
        pub adam_epsilon: f64 = 1e-8,
        /// Initial entropy temperature α.
        pub initial_alpha: f64 = 0.2,
        /// Learn α toward the target entropy −dim(A); false keeps it fixed.
        pub autotune_alpha: bool = true,
    }
}

impl Config {
    /// Checks the SAC fields, naming `algo` in the errors.
    pub fn check(&self, algo: &'static str) -> Result<(), AlgoError> {
        check(
            (0.0..1.0).contains(&self.gamma),
            algo,
            "gamma",
            "in [0, 1)",
            self.gamma,
        )?;
        check(
            self.tau > 0.0 && self.tau <= 1.0,
            algo,
            "tau",
            "in (0, 1]",
            self.tau,
        )?;
        check(
            self.learning_rate > 0.0 && self.learning_rate.is_finite(),
            algo,
            "learning_rate",
            "a positive number",
            self.learning_rate,
        )?;
        check(
            self.adam_epsilon > 0.0 && self.adam_epsilon.is_finite(),
            algo,
            "adam_epsilon",
            "a positive number",
            self.adam_epsilon,
        )?;
        check(
            self.initial_alpha > 0.0 && self.initial_alpha.is_finite(),
            algo,
            "initial_alpha",
            "a positive number",
            self.initial_alpha,
        )
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo {
        undelayed_only: true,
        role: Role::Reference,
        ..AlgoInfo::single_learner(
            "sac",
            "Delay-free SAC",
            "delay-free SAC on the true state (Δ = 0 only): the upper reference",
            false,
        )
    };

    fn validate(&self) -> Result<(), AlgoError> {
        self.check(Self::INFO.name)
    }

    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        Box::new(SacAgent::new(
            InputView::TrueState,
            spec,
            self,
            devices,
            seed,
        ))
    }
}

/// Losses and temperature of one update.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SacStats {
    pub critic_loss: f64,
    pub actor_loss: f64,
    pub alpha: f64,
    pub alpha_loss: f64,
}

impl SacStats {
    /// Their `train.csv` columns.
    pub const NAMES: [&'static str; 4] = ["critic_loss", "actor_loss", "alpha", "alpha_loss"];

    /// The statistics as `train.csv` columns.
    pub fn named(&self) -> Stats {
        let values = [
            self.critic_loss,
            self.actor_loss,
            self.alpha,
            self.alpha_loss,
        ];
        Self::NAMES.into_iter().zip(values).collect()
    }
}

/// One SAC batch: what the actor and the critics condition on (the same for SAC itself; the
/// augmented state for the actor and the true state for the critics in BPQL), now and next.
/// All `[B, ·]` tensors on the plain device; `done` is 1 where the MDP terminated.
#[derive(Debug, Clone)]
pub struct SacBatch {
    pub actor_input: Tensor<2>,
    pub critic_input: Tensor<2>,
    pub action: Tensor<2>,
    pub reward: Tensor<2>,
    pub next_actor_input: Tensor<2>,
    pub next_critic_input: Tensor<2>,
    pub done: Tensor<2>,
}

impl SacBatch {
    /// The actions, rewards and terminations of `t`, with the actor on `actor` and the critics
    /// on `critic` (each `(now, next)`).
    pub fn new(
        t: &TransitionTensors,
        (actor_input, next_actor_input): (Tensor<2>, Tensor<2>),
        (critic_input, next_critic_input): (Tensor<2>, Tensor<2>),
    ) -> SacBatch {
        SacBatch {
            actor_input,
            critic_input,
            action: t.action.clone(),
            reward: t.reward.clone(),
            next_actor_input,
            next_critic_input,
            done: t.done.clone(),
        }
    }
}

/// Adam learning rates of a [`SacLearner`]'s parts (all `learning_rate` unless an algorithm
/// sets them apart, as VDPO's reference SAC does).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearningRates {
    pub critic: f64,
    pub actor: f64,
    pub temperature: f64,
}

/// SAC with a policy `π(a | actor input)` and twin critics `Q(critic input, a)`.
pub struct SacLearner {
    pub actor: GaussianPolicy,
    pub critic: TwinQ,
    /// Polyak-averaged copy of `critic` on the plain device: never on an autodiff graph.
    pub target: TwinQ,
    pub temperature: Temperature,
    actor_opt: ModuleOptimizer,
    critic_opt: ModuleOptimizer,
    temperature_opt: ModuleOptimizer,
    pub scale: ActionScale,
    hyper: Config,
    pub rates: LearningRates,
    /// `H̄ = −dim(A)`.
    target_entropy: f64,
    pub devices: Devices,
    pub noise: Noise,
    act_dim: usize,
}

impl SacLearner {
    /// Networks drawn from burn's generator seeded with `seed` (so a learner is reproducible
    /// whatever was built before it), exploration noise from its own stream.
    pub fn new(
        actor_dim: usize,
        critic_dim: usize,
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seed: u64,
    ) -> SacLearner {
        devices.train.seed(seed);
        let actor = GaussianPolicy::new(actor_dim, spec.act_dim, &devices.train);
        materialize(&actor);
        let critic = TwinQ::new(critic_dim, spec.act_dim, &devices.train);
        materialize(&critic);
        SacLearner {
            target: critic.valid(),
            actor,
            critic,
            temperature: Temperature::new(hyper.initial_alpha, &devices.train),
            actor_opt: adam(hyper.adam_epsilon),
            critic_opt: adam(hyper.adam_epsilon),
            temperature_opt: adam(hyper.adam_epsilon),
            scale: ActionScale::new(&spec.action_low, &spec.action_high, &devices.plain),
            hyper: hyper.clone(),
            rates: LearningRates {
                critic: hyper.learning_rate,
                actor: hyper.learning_rate,
                temperature: hyper.learning_rate,
            },
            target_entropy: -(spec.act_dim as f64),
            devices: devices.clone(),
            noise: Noise::new(crate::seeds::learner_noise(seed)),
            act_dim: spec.act_dim,
        }
    }

    /// A sampled action `a ~ π(·|input)` per row, from the current actor (no graph).
    pub fn explore(&mut self, input: Tensor<2>) -> Tensor<2> {
        let rows = input.dims()[0];
        let eps = self.noise.normal(rows, self.act_dim, &self.devices.plain);
        self.actor.valid().sample(input, eps, &self.scale).action
    }

    /// The deterministic action `tanh(μ)` per row.
    pub fn exploit(&self, input: Tensor<2>) -> Tensor<2> {
        self.actor.valid().mode(input, &self.scale)
    }

    /// Actions `[rows, act_dim]` for `rows` inputs of width `width` (row-major).
    pub fn act(&mut self, inputs: &[f32], rows: usize, width: usize, mode: ActMode) -> Vec<f32> {
        let input = matrix(
            inputs[..rows * width].to_vec(),
            rows,
            width,
            &self.devices.plain,
        );
        to_vec(match mode {
            ActMode::Explore => self.explore(input),
            ActMode::Deterministic => self.exploit(input),
        })
    }

    /// Critics (Eq. 3, 5): `y = r + γ(1 − d)(min Q̄(s', a') − α log π(a'|x'))`, `a' ~ π(·|x')`.
    /// Returns the loss. Leaves the actor as it is, so that [`SacLearner::distribution`] may
    /// run before or after it.
    pub fn update_critics(&mut self, batch: &SacBatch) -> f64 {
        let rows = batch.reward.dims()[0];
        let alpha = self.temperature.alpha();
        let next_eps = self.noise.normal(rows, self.act_dim, &self.devices.plain);
        let next = self
            .actor
            .valid()
            .sample(batch.next_actor_input.clone(), next_eps, &self.scale);
        let next_q = self
            .target
            .min(batch.next_critic_input.clone(), next.action);
        let y = critic_target(
            batch.reward.clone(),
            batch.done.clone(),
            next_q,
            next.log_prob,
            alpha,
            self.hyper.gamma,
        );
        let q1 = self
            .critic
            .q1
            .forward(batch.critic_input.clone(), batch.action.clone());
        let q2 = self
            .critic
            .q2
            .forward(batch.critic_input.clone(), batch.action.clone());
        let loss = critic_loss(q1, q2, y);
        let value = f64::from(loss.clone().inner().into_scalar::<f32>());
        let grads = GradientsParams::from_grads(loss.backward(), &self.critic);
        self.critic = self
            .critic_opt
            .step(self.rates.critic, self.critic.clone(), grads);
        value
    }

    /// The actor's `(μ, log σ)` at the batch's actor input, on the autodiff graph: what
    /// [`SacLearner::update_policy`] steps from, and what other losses on the same policy
    /// (D2HPG's lifting term) share.
    pub fn distribution(&self, batch: &SacBatch) -> (Tensor<2>, Tensor<2>) {
        self.actor.distribution(batch.actor_input.clone())
    }

    /// [`SacLearner::update_actor_and_temperature`], then the targets. Returns the actor's SAC
    /// loss and the temperature's loss.
    pub fn update_policy(
        &mut self,
        batch: &SacBatch,
        distribution: (Tensor<2>, Tensor<2>),
        extra: Option<Tensor<1>>,
    ) -> (f64, f64) {
        let losses = self.update_actor_and_temperature(batch, distribution, extra);
        self.update_targets();
        losses
    }

    /// Actor (Eq. 7): `α log π(a|x) − min Q(s, a)`, `a ~ π(·|x)` from `distribution`, critics
    /// held fixed, plus `extra` (a loss on the same distribution) in the same step; then the
    /// temperature. Returns the actor's SAC loss and the temperature's loss.
    pub fn update_actor_and_temperature(
        &mut self,
        batch: &SacBatch,
        distribution: (Tensor<2>, Tensor<2>),
        extra: Option<Tensor<1>>,
    ) -> (f64, f64) {
        let rows = batch.reward.dims()[0];
        let alpha = self.temperature.alpha();
        let eps = self.noise.normal(rows, self.act_dim, &self.devices.plain);
        let pi = squashed_sample(distribution, eps, &self.scale);
        let mean_log_prob = f64::from(pi.log_prob.clone().inner().mean().into_scalar::<f32>());
        let q = self
            .critic
            .valid()
            .min(batch.critic_input.clone(), pi.action);
        let loss = actor_loss(pi.log_prob, q, alpha);
        let actor_loss = f64::from(loss.clone().inner().into_scalar::<f32>());
        self.update_actor_by(match extra {
            Some(extra) => loss + extra,
            None => loss,
        });
        let alpha_loss = self.update_temperature(mean_log_prob);
        (actor_loss, alpha_loss)
    }

    /// One Adam step of the actor on `loss`.
    pub fn update_actor_by(&mut self, loss: Tensor<1>) {
        let grads = GradientsParams::from_grads(loss.backward(), &self.actor);
        self.actor = self
            .actor_opt
            .step(self.rates.actor, self.actor.clone(), grads);
    }

    /// Temperature (Eq. 18): `−α(log π + H̄)`, toward the target entropy; returns the loss
    /// (0 when α is fixed).
    fn update_temperature(&mut self, mean_log_prob: f64) -> f64 {
        if !self.hyper.autotune_alpha {
            return 0.0;
        }
        let loss = temperature_loss(
            self.temperature.log_alpha.val(),
            mean_log_prob,
            self.target_entropy,
        );
        let value = f64::from(loss.clone().inner().into_scalar::<f32>());
        let grads = GradientsParams::from_grads(loss.backward(), &self.temperature);
        self.temperature =
            self.temperature_opt
                .step(self.rates.temperature, self.temperature.clone(), grads);
        value
    }

    /// Targets: `θ̄ ← τθ + (1 − τ)θ̄`.
    pub fn update_targets(&mut self) {
        self.target = polyak(self.target.clone(), &self.critic, self.hyper.tau);
    }

    /// One SAC update: critics, actor, temperature, targets.
    pub fn update(&mut self, batch: &SacBatch) -> SacStats {
        let alpha = self.temperature.alpha();
        let critic_loss = self.update_critics(batch);
        let distribution = self.distribution(batch);
        let (actor_loss, alpha_loss) = self.update_policy(batch, distribution, None);
        SacStats {
            critic_loss,
            actor_loss,
            alpha,
            alpha_loss,
        }
    }

    /// Saves networks, optimiser states and the noise stream as `dir/{prefix}*.bpk|json`.
    pub fn save(&self, dir: &Path, prefix: &str) -> Result<(), LearnError> {
        let files = CheckpointDir::with_prefix(dir, prefix);
        files.save_module("actor.bpk", &self.actor)?;
        files.save_module("critic.bpk", &self.critic)?;
        files.save_module("critic_target.bpk", &self.target)?;
        files.save_module("temperature.bpk", &self.temperature)?;
        files.save_optimizer("actor_adam.bpk", &self.actor_opt)?;
        files.save_optimizer("critic_adam.bpk", &self.critic_opt)?;
        files.save_optimizer("temperature_adam.bpk", &self.temperature_opt)?;
        files.save_json("noise.json", &self.noise)
    }

    /// Restores what [`SacLearner::save`] wrote with the same `prefix`.
    pub fn load(&mut self, dir: &Path, prefix: &str) -> Result<(), LearnError> {
        let files = CheckpointDir::with_prefix(dir, prefix);
        self.actor = files.load_module("actor.bpk", self.actor.clone())?;
        self.critic = files.load_module("critic.bpk", self.critic.clone())?;
        self.target = files
            .load_module("critic_target.bpk", self.target.clone())?
            .valid();
        self.temperature = files.load_module("temperature.bpk", self.temperature.clone())?;
        self.actor_opt = files.load_optimizer("actor_adam.bpk", self.actor_opt.clone())?;
        self.critic_opt = files.load_optimizer("critic_adam.bpk", self.critic_opt.clone())?;
        self.temperature_opt =
            files.load_optimizer("temperature_adam.bpk", self.temperature_opt.clone())?;
        self.noise = files.load_json("noise.json")?;
        Ok(())
    }
}

/// Which part of a transition the SAC baselines condition on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputView {
    /// The true state `s_t` (delay-free SAC; with Δ = 0, `x_t = s_t`).
    TrueState,
    /// The last received observation `s_{t-Δ}`: the first `obs_dim` entries of `x_t`.
    LastObservation,
    /// The whole augmented state `x_t`.
    Augmented,
}

impl InputView {
    fn width(self, spec: &AgentSpec) -> usize {
        match self {
            InputView::TrueState | InputView::LastObservation => spec.obs_dim,
            InputView::Augmented => spec.augmented_dim(),
        }
    }

    /// The view's rows out of `rows` augmented states.
    fn from_augmented(self, augmented: &[f32], rows: usize, spec: &AgentSpec) -> Vec<f32> {
        let (aug, width) = (spec.augmented_dim(), self.width(spec));
        if width == aug {
            return augmented[..rows * aug].to_vec();
        }
        augmented
            .chunks(aug)
            .take(rows)
            .flat_map(|x| &x[..width])
            .copied()
            .collect()
    }

    /// `(input, next input)` of a batch of transitions.
    fn of_batch(self, batch: &Transitions, spec: &AgentSpec) -> (Vec<f32>, Vec<f32>) {
        let rows = batch.len();
        match self {
            InputView::TrueState => (batch.state.clone(), batch.next_state.clone()),
            InputView::LastObservation | InputView::Augmented => (
                self.from_augmented(&batch.augmented, rows, spec),
                self.from_augmented(&batch.next_augmented, rows, spec),
            ),
        }
    }
}

/// A SAC baseline: [`SacLearner`] on one [`InputView`].
pub struct SacAgent {
    view: InputView,
    spec: AgentSpec,
    learner: SacLearner,
}

impl SacAgent {
    pub fn new(
        view: InputView,
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seed: u64,
    ) -> SacAgent {
        SacAgent {
            view,
            spec: spec.clone(),
            learner: SacLearner::new(
                view.width(spec),
                view.width(spec),
                spec,
                hyper,
                devices,
                seed,
            ),
        }
    }
}

impl Agent for SacAgent {
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        let view = match self.view {
            // At Δ = 0 the first obs_dim entries of x_t are s_t.
            InputView::TrueState => InputView::LastObservation,
            view => view,
        };
        let inputs = view.from_augmented(augmented, rows, &self.spec);
        self.learner
            .act(&inputs, rows, view.width(&self.spec), mode)
    }

    fn acting_network(&self) -> ActingNetwork {
        let input = match self.view {
            InputView::Augmented => PolicyInput::AugmentedState,
            InputView::TrueState | InputView::LastObservation => PolicyInput::LastObservation,
        };
        ActingNetwork::Policy {
            input,
            policy: self.learner.actor.weights(),
        }
    }

    fn stat_names(&self) -> Vec<&'static str> {
        SacStats::NAMES.to_vec()
    }

    fn update(&mut self, ctx: &mut UpdateContext<'_>) -> Result<Stats, ReplayError> {
        let batch = &ctx.batch()?;
        let plain = self.learner.devices.plain.clone();
        let (input, next_input) = self.view.of_batch(batch, &self.spec);
        let (input, next_input) = (
            rows(input, batch.len(), &plain),
            rows(next_input, batch.len(), &plain),
        );
        let tensors = TransitionTensors::new(batch, &plain);
        let stats = self.learner.update(&SacBatch::new(
            &tensors,
            (input.clone(), next_input.clone()),
            (input, next_input),
        ));
        Ok(stats.named())
    }

    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.learner.save(dir, "")
    }

    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.learner.load(dir, "")
    }
}
