//! Soft Actor-Critic (Haarnoja et al. 2018) in burn: twin critics with Polyak-averaged targets
//! kept off the autodiff graph, a tanh-squashed Gaussian actor, and a learned temperature.
//!
//! [`SacLearner`] is the algorithm on an abstract input (whatever the policy conditions on);
//! [`SacAgent`] chooses that input from a transition. `sac` below is the delay-free reference
//! on the true state; `naive_sac.rs` and `augmented_sac.rs` are the two delayed baselines.
//! BPQL and D2HPG reuse [`SacLearner`] for their delay-free parts.
use std::ops::Range;
use std::path::Path;

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::prelude::*;

use super::agent::{ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, Role, check};
use super::context::UpdateContext;
use super::stats::Stats;
use crate::acting::{ActingNetwork, PolicyInput};
use crate::delay::{ReplayError, Transitions};
use crate::learn::{
    ActionScale, CheckpointDir, Devices, GaussianPolicy, LearnError, NetworkInit, Noise,
    Temperature, TransitionTensors, TwinQ, actor_loss, adam, batch_mean, critic_loss,
    critic_target, initialise, load_json_stack, load_optimizer_stack, load_stack, polyak,
    select_runs, squashed_sample, stack, temperature_loss, to_vec, upload_rows,
};
use crate::protocol::Protocol;

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
        /// How the actor's and critics' linear layers are drawn: "burn" (Kaiming-uniform by
        /// fan-in, about PyTorch's default) or "orthogonal" (gain 1, zero biases: the authors'
        /// code, and the `authors` protocol's).
        pub network_init: NetworkInit = NetworkInit::Burn,
    }
}

impl Config {
    /// SAC's settings under `protocol`, which every algorithm built on [`SacLearner`] shares:
    /// the authors' code draws its networks orthogonally; its other SAC hyperparameters are
    /// dhrl's defaults already (docs/DESIGN.md §3.3).
    pub fn protocol_defaults(protocol: Protocol) -> Config {
        match protocol {
            Protocol::Dhrl => Config::default(),
            Protocol::Authors => Config {
                network_init: NetworkInit::Orthogonal,
                ..Config::default()
            },
        }
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

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(SacAgent::stacked(
            InputView::TrueState,
            spec,
            self,
            devices,
            seeds,
        ))
    }
}

/// The statistics of a SAC update, as `train.csv` columns: losses and temperature.
pub const SAC_STATS: [&str; 4] = ["critic_loss", "actor_loss", "alpha", "alpha_loss"];

/// One SAC batch: what the actor and the critics condition on (the same for SAC itself; the
/// augmented state for the actor and the true state for the critics in BPQL), now and next.
/// All `[S, B, ·]` tensors on the plain device, one batch per run of the stack; `done` is 1
/// where the MDP terminated.
#[derive(Debug, Clone)]
pub struct SacBatch {
    pub actor_input: Tensor<3>,
    pub critic_input: Tensor<3>,
    pub action: Tensor<3>,
    pub reward: Tensor<3>,
    pub next_actor_input: Tensor<3>,
    pub next_critic_input: Tensor<3>,
    pub done: Tensor<3>,
}

impl SacBatch {
    /// The batch of the runs of `t`: their actions, rewards and terminations, with the actor
    /// on `actor` and the critics on `critic` (each `(now, next)`, `[S, B, ·]`).
    pub fn new(
        t: &TransitionTensors,
        (actor_input, next_actor_input): (Tensor<3>, Tensor<3>),
        (critic_input, next_critic_input): (Tensor<3>, Tensor<3>),
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

    /// Rows per run.
    pub fn rows(&self) -> usize {
        self.reward.dims()[1]
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

/// SAC with a policy `π(a | actor input)` and twin critics `Q(critic input, a)`, for a stack
/// of S independent runs (a solo run is S = 1): every network stacked
/// ([`crate::learn::stack`]), every loss summed over the runs so that each run's gradient is
/// its solo gradient, a temperature and a noise stream per run.
pub struct SacLearner {
    pub actor: GaussianPolicy,
    pub critic: TwinQ,
    /// Polyak-averaged copy of `critic` on the plain device: never on an autodiff graph.
    pub target: TwinQ,
    pub temperature: Temperature,
    /// Another learner's α `[S, 1, 1]` for the update under way, when this learner shares it
    /// (D2HPG's one temperature under the `authors` protocol, set before each update): the
    /// entropy terms read it and this learner's own temperature is left as it is.
    pub borrowed_alpha: Option<Tensor<3>>,
    actor_opt: ModuleOptimizer,
    critic_opt: ModuleOptimizer,
    temperature_opt: ModuleOptimizer,
    pub scale: ActionScale,
    hyper: Config,
    pub rates: LearningRates,
    /// `H̄ = −dim(A)`.
    target_entropy: f64,
    pub devices: Devices,
    /// One stream per run: exploration and the updates' samples.
    pub noise: Vec<Noise>,
    act_dim: usize,
}

impl SacLearner {
    /// One run's learner: networks drawn from burn's generator seeded with `seed` (so a
    /// learner is reproducible whatever was built before it), noise from its own stream.
    pub fn new(
        actor_dim: usize,
        critic_dim: usize,
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seed: u64,
    ) -> SacLearner {
        SacLearner::stacked(actor_dim, critic_dim, spec, hyper, devices, &[seed])
    }

    /// The learners of runs `seeds` in one stack: slice `i` is drawn as
    /// [`SacLearner::new`] with `seeds[i]` draws it.
    pub fn stacked(
        actor_dim: usize,
        critic_dim: usize,
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seeds: &[u64],
    ) -> SacLearner {
        let (actors, critics): (Vec<_>, Vec<_>) = seeds
            .iter()
            .map(|&seed| {
                devices.train.seed(seed);
                let actor = GaussianPolicy::new(actor_dim, spec.act_dim, &devices.train);
                let critic = TwinQ::new(critic_dim, spec.act_dim, &devices.train);
                let init = hyper.network_init;
                (
                    initialise(actor, init, crate::seeds::named(seed, "init/actor")),
                    initialise(critic, init, crate::seeds::named(seed, "init/critic")),
                )
            })
            .unzip();
        let critic = stack(critics);
        SacLearner {
            target: critic.valid(),
            actor: stack(actors),
            critic,
            temperature: stack(
                seeds
                    .iter()
                    .map(|_| Temperature::new(hyper.initial_alpha, &devices.train))
                    .collect(),
            ),
            borrowed_alpha: None,
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
            noise: seeds
                .iter()
                .map(|&seed| Noise::new(crate::seeds::learner_noise(seed)))
                .collect(),
            act_dim: spec.act_dim,
        }
    }

    /// [`SacLearner::stacked`] with the actor and the critics both on the state of `spec`
    /// (`obs_dim` entries): a delay-free SAC.
    pub fn on_state(
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seeds: &[u64],
    ) -> SacLearner {
        SacLearner::stacked(spec.obs_dim, spec.obs_dim, spec, hyper, devices, seeds)
    }

    /// Each run's α `[S, 1, 1]` for this update: its own, or the one it borrows.
    pub fn alpha(&self) -> Tensor<3> {
        match &self.borrowed_alpha {
            Some(alpha) => alpha.clone(),
            None => self.temperature.alpha_tensor(),
        }
    }

    /// How many runs the stack holds.
    pub fn runs(&self) -> usize {
        self.noise.len()
    }

    /// `[S, rows, A]` standard normal draws, each run's from its own stream.
    fn normal(&mut self, rows: usize) -> Tensor<3> {
        Noise::stacked_normal(&mut self.noise, rows, self.act_dim, &self.devices.plain)
    }

    /// Actions `[rows, act_dim]` of run `run` for its `rows` inputs of width `width`
    /// (row-major), from its policy and its noise stream.
    pub fn act_run(
        &mut self,
        run: usize,
        inputs: &[f32],
        rows: usize,
        width: usize,
        mode: ActMode,
    ) -> Vec<f32> {
        let input = upload_rows(inputs, 1, rows, width, &self.devices.plain);
        to_vec(self.act_tensor(run..run + 1, input, &[rows], mode))
    }

    /// Actions `[S, rows, act_dim]` of every run for inputs `[S, rows, width]` (row-major),
    /// run `i` acting for its first `counts[i]` rows ([`crate::algos::Agent::act_runs`]).
    pub fn act_runs(
        &mut self,
        inputs: &[f32],
        counts: &[usize],
        rows: usize,
        width: usize,
        mode: ActMode,
    ) -> Vec<f32> {
        let input = upload_rows(inputs, self.runs(), rows, width, &self.devices.plain);
        to_vec(self.act_tensor(0..self.runs(), input, counts, mode))
    }

    /// Actions `[s, rows, A]` of the runs `runs` (the whole stack, or one run) for their inputs
    /// `[s, rows, width]` on the plain device, run `runs.start + i` sampling for its first
    /// `counts[i]` rows from its noise stream.
    pub fn act_tensor(
        &mut self,
        runs: Range<usize>,
        input: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3> {
        let actor = select_runs(self.actor.valid(), runs.clone(), self.runs());
        match mode {
            ActMode::Explore => {
                let rows = input.dims()[1];
                let eps = Noise::stacked_normal_rows(
                    &mut self.noise[runs],
                    counts,
                    rows,
                    self.act_dim,
                    &self.devices.plain,
                );
                actor.sample(input, eps, &self.scale).action
            }
            ActMode::Deterministic => actor.mode(input, &self.scale),
        }
    }

    /// Critics (Eq. 3, 5): `y = r + γ(1 − d)(min Q̄(s', a') − α log π(a'|x'))`, `a' ~ π(·|x')`.
    /// Returns each run's loss `[S]`. Leaves the actor as it is, so that
    /// [`SacLearner::distribution`] may run before or after it.
    pub fn update_critics(&mut self, batch: &SacBatch) -> Tensor<1> {
        let alpha = self.alpha();
        let next_eps = self.normal(batch.rows());
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
        let losses = critic_loss(q1, q2, y);
        let values = losses.clone().inner();
        let grads = GradientsParams::from_grads(losses.sum().backward(), &self.critic);
        self.critic = self
            .critic_opt
            .step(self.rates.critic, self.critic.clone(), grads);
        values
    }

    /// The actor's `(μ, log σ)` at the batch's actor input, `[S, B, A]`, on the autodiff
    /// graph: what [`SacLearner::update_policy`] steps from, and what other losses on the same
    /// policy (D2HPG's lifting term) share.
    pub fn distribution(&self, batch: &SacBatch) -> (Tensor<3>, Tensor<3>) {
        self.actor.distribution(batch.actor_input.clone())
    }

    /// [`SacLearner::update_actor_and_temperature`], then the targets. Returns each run's
    /// actor SAC loss and temperature loss, `[S]` each.
    pub fn update_policy(
        &mut self,
        batch: &SacBatch,
        distribution: (Tensor<3>, Tensor<3>),
        extra: Option<Tensor<1>>,
    ) -> (Tensor<1>, Tensor<1>) {
        let losses = self.update_actor_and_temperature(batch, distribution, extra);
        self.update_targets();
        losses
    }

    /// Actor (Eq. 7): `α log π(a|x) − min Q(s, a)`, `a ~ π(·|x)` from `distribution`, critics
    /// held fixed, plus `extra` (a loss on the same distribution, summed over the runs) in the
    /// same step; then the temperature. Returns each run's actor SAC loss and temperature
    /// loss, `[S]` each.
    pub fn update_actor_and_temperature(
        &mut self,
        batch: &SacBatch,
        distribution: (Tensor<3>, Tensor<3>),
        extra: Option<Tensor<1>>,
    ) -> (Tensor<1>, Tensor<1>) {
        let alpha = self.alpha();
        let eps = self.normal(batch.rows());
        let pi = squashed_sample(distribution, eps, &self.scale);
        let mean_log_prob = batch_mean(pi.log_prob.clone().inner());
        let q = self
            .critic
            .valid()
            .min(batch.critic_input.clone(), pi.action);
        let losses = actor_loss(pi.log_prob, q, alpha);
        let actor_losses = losses.clone().inner();
        let loss = losses.sum();
        self.update_actor_by(match extra {
            Some(extra) => loss + extra,
            None => loss,
        });
        let alpha_losses = self.update_temperature(mean_log_prob);
        (actor_losses, alpha_losses)
    }

    /// One Adam step of the actor on `loss` (one number: the runs' losses summed).
    pub fn update_actor_by(&mut self, loss: Tensor<1>) {
        let grads = GradientsParams::from_grads(loss.backward(), &self.actor);
        self.actor = self
            .actor_opt
            .step(self.rates.actor, self.actor.clone(), grads);
    }

    /// Temperature (Eq. 18): `−α(log π + H̄)`, toward the target entropy, from each run's
    /// mean `log π` `[S]`; returns each run's loss (0 when α is fixed).
    fn update_temperature(&mut self, mean_log_prob: Tensor<1>) -> Tensor<1> {
        if !self.hyper.autotune_alpha || self.borrowed_alpha.is_some() {
            return Tensor::zeros([self.runs()], &self.devices.plain);
        }
        let losses = temperature_loss(
            self.temperature.log_alpha.val(),
            mean_log_prob,
            self.target_entropy,
        );
        let values = losses.clone().inner();
        let grads = GradientsParams::from_grads(losses.sum().backward(), &self.temperature);
        self.temperature =
            self.temperature_opt
                .step(self.rates.temperature, self.temperature.clone(), grads);
        values
    }

    /// Targets: `θ̄ ← τθ + (1 − τ)θ̄`.
    pub fn update_targets(&mut self) {
        self.target = polyak(self.target.clone(), &self.critic, self.hyper.tau);
    }

    /// One SAC update of every run: critics, actor, temperature, targets; the statistics
    /// [`SAC_STATS`].
    pub fn update(&mut self, batch: &SacBatch) -> Stats {
        let alphas = self.temperature.alpha_values();
        let critic_losses = self.update_critics(batch);
        self.devices.settle();
        let distribution = self.distribution(batch);
        let (actor_losses, alpha_losses) = self.update_policy(batch, distribution, None);
        let mut stats = Stats::new();
        for (name, values) in
            SAC_STATS
                .into_iter()
                .zip([critic_losses, actor_losses, alphas, alpha_losses])
        {
            stats.push(name, values);
        }
        self.devices.settle();
        stats
    }

    /// One update of every run, run `i`'s batch drawn from `contexts[i]`, the runs' batches
    /// made into one [`SacBatch`] by `batch`.
    pub fn update_runs(
        &mut self,
        contexts: &mut [UpdateContext<'_>],
        batch: impl Fn(&[Transitions], &Device) -> SacBatch,
    ) -> Result<Stats, ReplayError> {
        let batches = UpdateContext::batches(contexts)?;
        Ok(self.update(&batch(&batches, &self.devices.plain)))
    }

    /// Saves run `i`'s networks, optimiser states and noise stream as
    /// `dirs[i]/{prefix}*.bpk|json`, each in a solo run's shapes.
    pub fn save(&self, dirs: &[&Path], prefix: &str) -> Result<(), LearnError> {
        for (slice, dir) in dirs.iter().enumerate() {
            let files = CheckpointDir::with_prefix(dir, prefix);
            files.save_slice("actor.bpk", &self.actor, slice)?;
            files.save_slice("critic.bpk", &self.critic, slice)?;
            files.save_slice("critic_target.bpk", &self.target, slice)?;
            files.save_slice("temperature.bpk", &self.temperature, slice)?;
            files.save_optimizer_slice("actor_adam.bpk", &self.actor_opt, slice)?;
            files.save_optimizer_slice("critic_adam.bpk", &self.critic_opt, slice)?;
            files.save_optimizer_slice("temperature_adam.bpk", &self.temperature_opt, slice)?;
            files.save_json("noise.json", &self.noise[slice])?;
        }
        Ok(())
    }

    /// Restores what [`SacLearner::save`] wrote with the same `prefix`, run `i` from `dirs[i]`.
    pub fn load(&mut self, dirs: &[&Path], prefix: &str) -> Result<(), LearnError> {
        let files = CheckpointDir::each(dirs, prefix);
        self.actor = load_stack(&files, "actor.bpk", self.actor.clone())?;
        self.critic = load_stack(&files, "critic.bpk", self.critic.clone())?;
        self.target = load_stack(&files, "critic_target.bpk", self.target.clone())?.valid();
        self.temperature = load_stack(&files, "temperature.bpk", self.temperature.clone())?;
        self.actor_opt = load_optimizer_stack(&files, "actor_adam.bpk", self.actor_opt.clone())?;
        self.critic_opt = load_optimizer_stack(&files, "critic_adam.bpk", self.critic_opt.clone())?;
        self.temperature_opt =
            load_optimizer_stack(&files, "temperature_adam.bpk", self.temperature_opt.clone())?;
        self.noise = load_json_stack(&files, "noise.json")?;
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

    /// The view of augmented states `[S, rows, obs + Δ·act]` (what acting reads). `TrueState`
    /// reads their first `obs_dim` entries, `s_t` at Δ = 0; a batch holds `s_t` apart.
    fn of_augmented(self, augmented: Tensor<3>, spec: &AgentSpec) -> Tensor<3> {
        match self {
            InputView::TrueState | InputView::LastObservation => {
                augmented.narrow(2, 0, spec.obs_dim)
            }
            InputView::Augmented => augmented,
        }
    }

    /// `(input, next input)` of the runs' batches, `[S, B, width]` each, from their tensors.
    fn of_batch(self, t: &TransitionTensors, spec: &AgentSpec) -> (Tensor<3>, Tensor<3>) {
        match self {
            InputView::TrueState => (t.state.clone(), t.next_state.clone()),
            view => (
                view.of_augmented(t.augmented.clone(), spec),
                view.of_augmented(t.next_augmented.clone(), spec),
            ),
        }
    }
}

/// A SAC baseline: [`SacLearner`] on one [`InputView`], for a stack of runs.
pub struct SacAgent {
    view: InputView,
    spec: AgentSpec,
    learner: SacLearner,
}

impl SacAgent {
    /// One run's agent.
    pub fn new(
        view: InputView,
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seed: u64,
    ) -> SacAgent {
        SacAgent::stacked(view, spec, hyper, devices, &[seed])
    }

    /// The runs of `seeds`, one stacked learner.
    pub fn stacked(
        view: InputView,
        spec: &AgentSpec,
        hyper: &Config,
        devices: &Devices,
        seeds: &[u64],
    ) -> SacAgent {
        SacAgent {
            view,
            spec: spec.clone(),
            learner: SacLearner::stacked(
                view.width(spec),
                view.width(spec),
                spec,
                hyper,
                devices,
                seeds,
            ),
        }
    }

    /// The runs' batches on `view`.
    fn batch(
        view: InputView,
        spec: &AgentSpec,
        batches: &[Transitions],
        plain: &Device,
    ) -> SacBatch {
        let t = TransitionTensors::stacked(batches, plain);
        let inputs = view.of_batch(&t, spec);
        SacBatch::new(&t, inputs.clone(), inputs)
    }
}

impl Agent for SacAgent {
    fn acting_network(&self) -> ActingNetwork {
        let input = match self.view {
            InputView::Augmented => PolicyInput::AugmentedState,
            InputView::TrueState | InputView::LastObservation => PolicyInput::LastObservation,
        };
        ActingNetwork::Policy {
            input,
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
        let input = self.view.of_augmented(augmented, &self.spec);
        self.learner.act_tensor(runs, input, counts, mode)
    }

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        let (view, spec) = (self.view, &self.spec);
        self.learner.update_runs(contexts, |batches, plain| {
            SacAgent::batch(view, spec, batches, plain)
        })
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.learner.save(dirs, "")
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.learner.load(dirs, "")
    }
}
