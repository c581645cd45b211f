//! Delayed SAC: the model-based baseline of Derman, Dalal & Mannor, "Acting in Delayed
//! Environments with Non-Stationary Markov Policies" (ICLR 2021). Their Delayed-Q (discrete,
//! `galdl/rl_delay_basic`) learns a deterministic one-step forward model `f(s, a) → s'` by MSE on
//! the agent's own replay batches, trains the Q-learner on true, time-aligned states, and acts on
//! the state predicted by rolling `f` over the pending actions. The continuous version here:
//!
//! - SAC on the true time-aligned `(s_τ, a_τ, r_τ, s_{τ+1})` of the replay (exactly `sac.rs`'s
//!   learner: critic Eq. 5, actor Eq. 7, temperature Eq. 18 of Haarnoja et al. 2018);
//! - an MLP forward model trained by `L_f = E[‖f(s_τ, a_τ) − s_{τ+1}‖²] / dim(S)` on the same
//!   batch, which predicts the difference `s' − s` (added back to `s`) from inputs normalised by
//!   running means and standard deviations of the states and actions it was trained on (both
//!   are fields);
//! - acting: `a_t ~ π(f^Δ(s_{t−Δ}, a_{t−Δ}, …, a_{t−1}))`, `f^Δ` the model applied Δ times to
//!   the observation and the pending actions of `x_t`.
//!
//! The paper attributes delayed SAC's weakness to the error that accumulates over the Δ
//! predictions, so `train.csv` logs it on every batch: `model_loss` (one step, against the true
//! `s_{τ+1}`), `rollout_error` (Δ steps from `s_{τ−Δ}`, against the true `s_τ` the policy
//! should have seen) and `rollout_error_mean` (the mean over the Δ intermediate true states
//! `s_{τ−Δ+1..τ}`), each per state dimension, by the model before its step.
use std::ops::Range;
use std::path::Path;

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use serde::{Deserialize, Serialize};

use super::agent::{ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, check};
use super::context::UpdateContext;
use super::sac::{Config as SacConfig, SAC_STATS, SacBatch, SacLearner};
use super::stats::Stats;
use crate::acting::{ActingNetwork, RolloutModel};
use crate::delay::{BatchExtras, ReplayError, Transitions};
use crate::learn::{
    CheckpointDir, Devices, LearnError, Mlp, MlpConfig, TransitionTensors, adam, load_json_stack,
    load_optimizer_stack, load_stack, matrix, select_runs, stack, stacked_rows,
};
use crate::seeds;

/// What the model's network outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelOutput {
    /// `s' − s`, added back to `s` (`f(s, a) = s + g(s, a)`).
    Difference,
    /// `s'` itself (`f(s, a) = g(s, a)`).
    NextState,
}

crate::algo_config! {
    /// Delayed SAC's configuration: SAC's, and the forward model's.
    pub struct Config {
        ..sac: SacConfig;
        /// What the model's network predicts: "difference" (s' − s) or "next-state" (s').
        pub model_output: ModelOutput = ModelOutput::Difference,
        /// Normalise the model's inputs (s, a) by the running mean and standard deviation of
        /// every batch it has been trained on.
        pub normalise_model_inputs: bool = true,
        /// Hidden layer widths of the model (ReLU MLP).
        pub model_hidden: Vec<usize> = vec![256, 256],
        /// Adam learning rate of the model.
        pub model_learning_rate: f64 = 1e-3,
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo::single_learner(
        "delayed-sac",
        "Delayed SAC",
        "SAC on s_t, acting on the state a learned one-step model predicts over the Δ pending actions",
        false,
    );

    fn validate(&self) -> Result<(), AlgoError> {
        let algo = Self::INFO.name;
        self.sac.check(algo)?;
        check(
            !self.model_hidden.contains(&0),
            algo,
            "model_hidden",
            "a list of positive widths",
            format!("{:?}", self.model_hidden),
        )?;
        check(
            self.model_learning_rate > 0.0 && self.model_learning_rate.is_finite(),
            algo,
            "model_learning_rate",
            "a positive number",
            self.model_learning_rate,
        )
    }

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(DelayedSac::new(self, spec, devices, seeds))
    }
}

/// `train.csv` columns beside SAC's.
const MODEL_STATS: [&str; 3] = ["model_loss", "rollout_error", "rollout_error_mean"];

/// Running mean and variance of the model's inputs, merged batch by batch (Chan et al.).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputMoments {
    count: f64,
    mean: Vec<f64>,
    /// Sums of squared deviations from the mean.
    m2: Vec<f64>,
}

impl InputMoments {
    fn new(width: usize) -> InputMoments {
        InputMoments {
            count: 0.0,
            mean: vec![0.0; width],
            m2: vec![0.0; width],
        }
    }

    /// Merges the rows of `inputs` (`[n, width]`, row-major).
    fn add(&mut self, inputs: &[f32]) {
        let width = self.mean.len();
        let n = (inputs.len() / width) as f64;
        for j in 0..width {
            let column = inputs.iter().skip(j).step_by(width).map(|&v| f64::from(v));
            let batch_mean = column.clone().sum::<f64>() / n;
            let batch_m2: f64 = column.map(|v| (v - batch_mean).powi(2)).sum();
            let delta = batch_mean - self.mean[j];
            let total = self.count + n;
            self.mean[j] += delta * n / total;
            self.m2[j] += batch_m2 + delta * delta * self.count * n / total;
        }
        self.count += n;
    }

    /// `(mean, std)` per input; a dimension that has not varied keeps scale 1.
    fn mean_std(&self) -> (Vec<f32>, Vec<f32>) {
        let std = self
            .m2
            .iter()
            .map(|m2| (m2 / self.count.max(1.0)).sqrt())
            .map(|s| if s < 1e-12 { 1.0 } else { s as f32 });
        (self.mean.iter().map(|&m| m as f32).collect(), std.collect())
    }

    /// Each run's [`InputMoments::mean_std`] as a stack of `[1, width]` rows, `[S, 1, width]`.
    fn tensors(runs: &[InputMoments], device: &Device) -> (Tensor<3>, Tensor<3>) {
        let width = runs[0].mean.len();
        let (means, stds): (Vec<Vec<f32>>, Vec<Vec<f32>>) =
            runs.iter().map(InputMoments::mean_std).unzip();
        let rows = |values: Vec<Vec<f32>>| {
            matrix(values.concat(), runs.len(), width, device).unsqueeze_dim(1)
        };
        (rows(means), rows(stds))
    }
}

/// The learned one-step model `f(s, a)` of each run of a stack.
pub struct ForwardModel {
    /// Stacked, one slice per run.
    pub network: Mlp,
    pub output: ModelOutput,
    /// Each run's input statistics; `None` when inputs are not normalised.
    pub moments: Option<Vec<InputMoments>>,
}

/// The runs' input `(mean, std)`, `[S, 1, width]` each, or `None`.
pub type Normaliser = Option<(Tensor<3>, Tensor<3>)>;

impl ForwardModel {
    /// The inputs' `(mean, std)` rows of runs `runs` on `device`, when inputs are normalised:
    /// built once per batch or rollout and handed to every [`ForwardModel::predict`] of it.
    pub fn normaliser(&self, runs: std::ops::Range<usize>, device: &Device) -> Normaliser {
        self.moments
            .as_ref()
            .map(|moments| InputMoments::tensors(&moments[runs], device))
    }

    /// `f(s, a)` for `[S, B, obs]` states and `[S, B, act]` actions, with `network` (the model
    /// itself, or its plain copy off the graph) and the runs' [`ForwardModel::normaliser`].
    pub fn predict(
        &self,
        network: &Mlp,
        normaliser: &Normaliser,
        state: Tensor<3>,
        action: Tensor<3>,
    ) -> Tensor<3> {
        let input = Tensor::cat(vec![state.clone(), action], 2);
        let input = match normaliser {
            Some((mean, std)) => (input - mean.clone()) / std.clone(),
            None => input,
        };
        let out = network.forward(input);
        match self.output {
            ModelOutput::Difference => state + out,
            ModelOutput::NextState => out,
        }
    }

    /// `f^k(s_{τ−Δ}, a_{τ−Δ}, …)` for k = 1..=Δ from augmented states `[S, B, obs + Δ·act]`,
    /// off the graph, with `network` and `normaliser` (every run's, or one run's slice): the
    /// predicted `ŝ_{τ−Δ+k}`, oldest first.
    pub fn rollout(
        &self,
        network: &Mlp,
        normaliser: &Normaliser,
        augmented: Tensor<3>,
        spec: &AgentSpec,
    ) -> Vec<Tensor<3>> {
        let (obs, act) = (spec.obs_dim, spec.act_dim);
        let mut state = augmented.clone().narrow(2, 0, obs);
        (0..spec.delay)
            .map(|k| {
                let action = augmented.clone().narrow(2, obs + k * act, act);
                state = self.predict(network, normaliser, state.clone(), action);
                state.clone()
            })
            .collect()
    }
}

/// The model's loss (and logged error) per state dimension, per run: `E[‖ŝ − s‖²] / dim(S)`
/// over each run's `[B, obs]`, `[S]` (the last axis of `[S, B·obs]`, reduced as a solo run's
/// whole-tensor mean).
pub fn prediction_error(predicted: Tensor<3>, truth: Tensor<3>) -> Tensor<1> {
    let [runs, rows, obs] = predicted.dims();
    (predicted - truth)
        .square()
        .reshape([runs, rows * obs])
        .mean_dim(1)
        .reshape([runs])
}

/// Delayed SAC for a stack of runs (a solo run is S = 1).
pub struct DelayedSac {
    spec: AgentSpec,
    /// SAC on the true state.
    learner: SacLearner,
    model: ForwardModel,
    model_opt: ModuleOptimizer,
    model_learning_rate: f64,
}

impl DelayedSac {
    /// The runs of `seeds`: each run's model drawn after seeding the device with its own seed.
    pub fn new(config: &Config, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> DelayedSac {
        let learner = SacLearner::on_state(spec, &config.sac, devices, seeds);
        let width = spec.obs_dim + spec.act_dim;
        let network = stack(
            seeds
                .iter()
                .map(|&seed| {
                    devices.train.seed(seeds::named(seed, "delayed-sac/model"));
                    MlpConfig::new(width, &config.model_hidden, spec.obs_dim).init(&devices.train)
                })
                .collect(),
        );
        DelayedSac {
            spec: spec.clone(),
            learner,
            model: ForwardModel {
                network,
                output: config.model_output,
                moments: config
                    .normalise_model_inputs
                    .then(|| seeds.iter().map(|_| InputMoments::new(width)).collect()),
            },
            model_opt: adam(config.sac.adam_epsilon),
            model_learning_rate: config.model_learning_rate,
        }
    }

    /// Each run's errors of its model on its batch after 1, …, Δ steps, `[S]` each (the last
    /// is the error at `s_τ`); none for Δ = 0.
    fn rollout_errors(
        &self,
        batches: &[Transitions],
        augmented: Tensor<3>,
        device: &Device,
    ) -> Vec<Tensor<1>> {
        let (obs, delay) = (self.spec.obs_dim, self.spec.delay);
        if delay == 0 {
            return Vec::new();
        }
        let predicted = self.model.rollout(
            &self.model.network.valid(),
            &self.model.normaliser(0..batches.len(), device),
            augmented,
            &self.spec,
        );
        let truth = stacked_rows(
            batches.iter().map(|b| b.intermediate_states.as_slice()),
            batches,
            device,
        );
        predicted
            .into_iter()
            .enumerate()
            .map(|(k, p)| prediction_error(p, truth.clone().narrow(2, k * obs, obs)))
            .collect()
    }
}

impl Agent for DelayedSac {
    fn runs(&self) -> usize {
        self.learner.runs()
    }

    fn spec(&self) -> &AgentSpec {
        &self.spec
    }

    fn acting_device(&self) -> &Device {
        &self.learner.devices.plain
    }

    /// Each run's model rolls its last observation forward through the pending actions, and
    /// its policy acts on the predicted state.
    fn act_tensor(
        &mut self,
        runs: Range<usize>,
        augmented: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3> {
        let plain = self.learner.devices.plain.clone();
        let network = select_runs(self.model.network.valid(), runs.clone(), self.runs());
        let normaliser = self.model.normaliser(runs.clone(), &plain);
        let state = self
            .model
            .rollout(&network, &normaliser, augmented.clone(), &self.spec)
            .pop()
            .unwrap_or(augmented); // Δ = 0: x_t = s_t
        self.learner.act_tensor(runs, state, counts, mode)
    }

    fn acting_network(&self) -> ActingNetwork {
        ActingNetwork::ModelRollout {
            model: RolloutModel {
                layers: self.model.network.weights(0),
                input_moments: self.model.moments.as_ref().map(|m| m[0].mean_std()),
                predicts_difference: self.model.output == ModelOutput::Difference,
            },
            policy: self.learner.actor.weights(0),
        }
    }

    fn stat_names(&self) -> Vec<&'static str> {
        SAC_STATS.iter().chain(&MODEL_STATS).copied().collect()
    }

    fn batch_extras(&self) -> BatchExtras {
        BatchExtras {
            intermediate_states: true,
        }
    }

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        let batches = UpdateContext::batches(contexts)?;
        let plain = self.learner.devices.plain.clone();
        let t = TransitionTensors::stacked(&batches, &plain);

        // SAC on the true, time-aligned (s, a, r, s').
        let on_state = (t.state.clone(), t.next_state.clone());
        let mut stats = self
            .learner
            .update(&SacBatch::new(&t, on_state.clone(), on_state));

        // The Δ-step errors, then one model step on L_f, after merging each run's batch into its
        // normalisation statistics.
        let rollout = self.rollout_errors(&batches, t.augmented.clone(), &plain);
        if let Some(moments) = &mut self.model.moments {
            for (moments, batch) in moments.iter_mut().zip(&batches) {
                let inputs: Vec<f32> = batch
                    .state
                    .chunks(self.spec.obs_dim)
                    .zip(batch.action.chunks(self.spec.act_dim))
                    .flat_map(|(s, a)| s.iter().chain(a).copied())
                    .collect();
                moments.add(&inputs);
            }
        }
        let predicted = self.model.predict(
            &self.model.network,
            &self.model.normaliser(0..batches.len(), &plain),
            t.state.clone(),
            t.action.clone(),
        );
        let losses = prediction_error(predicted, t.next_state);
        let model_losses = losses.clone().inner();
        let grads = GradientsParams::from_grads(losses.sum().backward(), &self.model.network);
        self.model.network =
            self.model_opt
                .step(self.model_learning_rate, self.model.network.clone(), grads);

        stats.push(MODEL_STATS[0], model_losses);
        if let Some(at_state) = rollout.last() {
            stats.push(MODEL_STATS[1], at_state.clone());
            stats.push_mean(MODEL_STATS[2], rollout);
        }
        self.learner.devices.settle();
        Ok(stats)
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.learner.save(dirs, "")?;
        for (run, dir) in dirs.iter().enumerate() {
            let files = CheckpointDir::new(dir);
            files.save_slice("model.bpk", &self.model.network, run)?;
            files.save_optimizer_slice("model_adam.bpk", &self.model_opt, run)?;
            let moments = self.model.moments.as_ref().map(|m| &m[run]);
            files.save_json("model_inputs.json", &moments)?;
        }
        Ok(())
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.learner.load(dirs, "")?;
        let files = CheckpointDir::each(dirs, "");
        self.model.network = load_stack(&files, "model.bpk", self.model.network.clone())?;
        self.model_opt = load_optimizer_stack(&files, "model_adam.bpk", self.model_opt.clone())?;
        let moments: Vec<Option<InputMoments>> = load_json_stack(&files, "model_inputs.json")?;
        self.model.moments = moments.into_iter().collect();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use burn::module::Param;

    use super::*;
    use crate::learn::{LearnDevice, StackedLinear, assert_close as close, to_vec};

    /// One run's network of one linear layer `g(s, a) = w_s·s + w_a·a`.
    fn one_layer(w_s: f32, w_a: f32, device: &Device) -> Mlp {
        Mlp {
            layers: vec![StackedLinear {
                weight: Param::from_data([[[w_s], [w_a]]], device),
                bias: Param::from_data([[0.0f32]], device),
            }],
        }
    }

    /// `[1, rows, cols]`: one run's rows.
    fn run_rows(values: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<3> {
        matrix(values, rows, cols, device).unsqueeze_dim(0)
    }

    /// The linear system `s' = s + (0.5·s + 2·a)`, i.e. `s' = 1.5·s + 2·a`, as a model whose
    /// network is one linear layer `g(s, a) = 0.5·s + 2·a` predicting the difference.
    fn linear_model(device: &Device) -> ForwardModel {
        ForwardModel {
            network: one_layer(0.5, 2.0, device),
            output: ModelOutput::Difference,
            moments: None,
        }
    }

    fn spec(delay: usize) -> AgentSpec {
        AgentSpec {
            obs_dim: 1,
            act_dim: 1,
            delay,
            action_low: vec![-1.0],
            action_high: vec![1.0],
        }
    }

    #[test]
    fn model_loss_and_delta_step_rollout_match_hand_values_on_a_linear_system() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        let model = linear_model(&device);
        // One step: f(1, 0) = 1.5, f(2, 1) = 3 + 2 = 5; against s' = (1, 5) the errors are
        // 0.5 and 0, so L_f = (0.25 + 0) / 2.
        let predicted = model.predict(
            &model.network,
            &None,
            run_rows(vec![1.0, 2.0], 2, 1, &device),
            run_rows(vec![0.0, 1.0], 2, 1, &device),
        );
        close(&to_vec(predicted.clone()), &[1.5, 5.0]);
        let loss = prediction_error(predicted, run_rows(vec![1.0, 5.0], 2, 1, &device));
        close(&to_vec(loss), &[0.125]);

        // Δ = 3 from x = (s = 1; a = 1, −1, 0.5): 1.5 + 2 = 3.5, 5.25 − 2 = 3.25,
        // 4.875 + 1 = 5.875.
        let x = run_rows(vec![1.0, 1.0, -1.0, 0.5], 1, 4, &device);
        let rollout: Vec<f32> = model
            .rollout(&model.network, &None, x, &spec(3))
            .into_iter()
            .flat_map(to_vec)
            .collect();
        close(&rollout, &[3.5, 3.25, 5.875]);

        // The same system with the network predicting s' itself: g = 1.5·s + 2·a.
        let next_state = ForwardModel {
            network: one_layer(1.5, 2.0, &device),
            output: ModelOutput::NextState,
            moments: None,
        };
        let x = run_rows(vec![1.0, 1.0, -1.0, 0.5], 1, 4, &device);
        let rollout: Vec<f32> = next_state
            .rollout(&next_state.network, &None, x, &spec(3))
            .into_iter()
            .flat_map(to_vec)
            .collect();
        close(&rollout, &[3.5, 3.25, 5.875]);
    }

    /// The agent acts on `f^Δ(x)`, the state its model predicts for now: on the linear system,
    /// `x = (1; 1, −1, 0.5)` at Δ = 3 acts as the policy does at 5.875, not at `f^1` (3.5) or
    /// at the observation itself (1).
    #[test]
    fn the_agent_acts_on_the_state_rolled_delta_steps_forward() {
        let devices = Devices::new(LearnDevice::Cpu).unwrap();
        let mut agent = DelayedSac::new(&Config::default(), &spec(3), &devices, &[0]);
        agent.model = linear_model(&devices.plain);
        let acted = agent.act(&[1.0, 1.0, -1.0, 0.5], 1, ActMode::Deterministic);
        let mut policy_at = |s: f32| agent.learner.act_run(0, &[s], 1, 1, ActMode::Deterministic);
        assert_eq!(acted, policy_at(5.875));
        assert_ne!(acted, policy_at(3.5));
        assert_ne!(acted, policy_at(1.0));
    }

    #[test]
    fn normalised_inputs_use_the_moments_of_every_batch_seen() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        let mut moments = InputMoments::new(2);
        // Rows (s, a): (1, 0), (3, 0) then (5, 0): mean (3, 0), population std (√(8/3), 0).
        moments.add(&[1.0, 0.0, 3.0, 0.0]);
        moments.add(&[5.0, 0.0]);
        let (mean, std) = InputMoments::tensors(std::slice::from_ref(&moments), &device);
        close(&to_vec(mean), &[3.0, 0.0]);
        // A dimension that never varied keeps scale 1.
        close(&to_vec(std), &[(8.0f32 / 3.0).sqrt(), 1.0]);

        // The model sees ((s − 3)/σ, a): with g = 0.5·ŝ + 2·a and s = 3 + σ, a = 1, f = s + 2.5.
        let model = ForwardModel {
            moments: Some(vec![moments]),
            ..linear_model(&device)
        };
        let sigma = (8.0f32 / 3.0).sqrt();
        let predicted = model.predict(
            &model.network,
            &model.normaliser(0..1, &device),
            run_rows(vec![3.0 + sigma], 1, 1, &device),
            run_rows(vec![1.0], 1, 1, &device),
        );
        close(&to_vec(predicted), &[3.0 + sigma + 2.5]);
    }
}
