//! VDPO, Variational Delayed Policy Optimization (Wu et al., NeurIPS 2024), as its reference
//! implementation (`QingyuanWuNothing/VDPO`) does it. Each update takes three steps, numbered
//! as [`Vdpo`]'s `update` numbers them:
//!
//! 1. TD learning in the delay-free problem: a SAC reference policy `π_ref(·|s_t)` on the true,
//!    time-aligned states of the replay (critic every update at its own learning rate; actor and
//!    temperature `actor_every` steps every `actor_every`-th update; targets every update).
//! 2. The belief: the transformer's decoder reconstructs the Δ true states `s_{τ−Δ+1..τ}` from
//!    `x_τ` (MSE), every update.
//! 3. Behaviour cloning: every `bc_every` environment steps, `bc_updates` updates of the delayed
//!    policy minimising `KL(π_Δ(·|x) ‖ π_ref(·|s))` on the Gaussians before the tanh squash.
//!
//! The delayed policy is a belief network over Δ tokens, token `i` built from
//! `(s_{t−Δ}, a_{t−Δ+i}, position i)`, through a small causal transformer (burn's
//! `TransformerEncoder` holds the weights: `belief_blocks` pre-LN blocks, `belief_heads` heads,
//! width `belief_width`, GELU feed-forward of the same width, then a LayerNorm; [`encode`] is
//! its forward pass written out, with dropout masks drawn in bulk on the host instead of one
//! generator call per entry, which was a sixth of an update's time). Two heads read it: a
//! decoder reconstructing `s_{t−Δ+1+i}` at position `i` (trained every update, and the only loss
//! that trains the transformer) and a Gaussian policy head (2×256 ReLU, as the reference) read at
//! every position by the cloning loss — position `i` is cloned toward `π_ref(·|s_{t−Δ+1+i})` —
//! and at the last position to act.
//!
//! Acting is unprivileged: the delayed policy acts on `x_t` alone, always. The reference code,
//! while training, runs in an undelayed environment and executes whichever of the delayed and
//! the delay-free action has the lower Q at the *true* current state `s_t`; a delayed agent
//! does not have `s_t`, so dhrl does not do that. Other differences from the reference, each
//! for one replay and one protocol shared by every algorithm here: 1-step returns (not 3-step),
//! time-limit truncation bootstraps (not terminal), every position of every replayed `x_t`
//! holds a real action (so the reference's padding mask for the first Δ steps of an episode has
//! nothing to mask), dhrl's log σ clamp [−20, 2] (not tanh-scaled [−5, 2]), the transformer's
//! weights from burn's initialiser (not N(0, 0.02)), and a cloning stage whose transformer runs
//! without dropout (it is off the graph; the reference keeps it in training mode).
use std::path::Path;

use burn::module::Module;
use burn::nn::attention::MultiHeadAttention;
use burn::nn::attention::generate_autoregressive_mask;
use burn::nn::transformer::{TransformerEncoder, TransformerEncoderConfig};
use burn::nn::{Embedding, EmbeddingConfig, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use burn::tensor::activation::softmax;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::agent::{ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, Stats, check};
use super::context::UpdateContext;
use super::sac::{Config as SacConfig, LearningRates, SacBatch, SacLearner};
use crate::acting::{ActingNetwork, BeliefTransformer, TransformerBlock};
use crate::delay::{BatchExtras, ReplayError};
use crate::learn::{
    ActionScale, CheckpointDir, Devices, GaussianPolicy, LearnError, Noise, TransitionTensors,
    adam, dense, load_optimizer_stack, load_stack, materialize, matrix, norm, one_run, rows,
    to_vec,
};
use crate::seeds;

crate::algo_config! {
    /// VDPO's configuration: SAC's for the reference policy (its `learning_rate` is the actor's),
    /// and the belief network's and the cloning stage's, with the reference code's defaults.
    pub struct Config {
        ..sac: SacConfig;
        /// Adam learning rate of the reference critics.
        pub critic_learning_rate: f64 = 1e-3,
        /// Adam learning rate of the reference policy's temperature.
        pub temperature_learning_rate: f64 = 1e-3,
        /// The reference actor and temperature take `actor_every` steps on every
        /// `actor_every`-th update (one per update on average).
        pub actor_every: u64 = 2,
        /// Transformer width (token size).
        pub belief_width: usize = 256,
        /// Transformer blocks.
        pub belief_blocks: usize = 3,
        /// Attention heads per block (they must divide the width).
        pub belief_heads: usize = 1,
        /// Dropout in the transformer and on its input tokens while it is trained.
        pub dropout: f64 = 0.1,
        /// Adam learning rate of the belief network (tokens, transformer, decoder).
        pub belief_learning_rate: f64 = 3e-4,
        /// Environment steps between cloning stages.
        pub bc_every: u64 = 1000,
        /// Updates of the policy head in one cloning stage, each on a fresh batch.
        pub bc_updates: u64 = 1000,
        /// Adam learning rate of the policy head.
        pub bc_learning_rate: f64 = 3e-4,
    }
}

impl AlgoConfig for Config {
    const INFO: AlgoInfo = AlgoInfo {
        delay_free_policy: true,
        delayed_only: true,
        ..AlgoInfo::single_learner(
            "vdpo",
            "VDPO",
            "a delay-free SAC reference cloned into a transformer belief policy on x_t by KL",
            true,
        )
    };

    fn validate(&self) -> Result<(), AlgoError> {
        let algo = Self::INFO.name;
        self.sac.check(algo)?;
        for (what, rate) in [
            ("critic_learning_rate", self.critic_learning_rate),
            ("temperature_learning_rate", self.temperature_learning_rate),
            ("belief_learning_rate", self.belief_learning_rate),
            ("bc_learning_rate", self.bc_learning_rate),
        ] {
            check(
                rate > 0.0 && rate.is_finite(),
                algo,
                what,
                "a positive number",
                rate,
            )?;
        }
        check(
            self.actor_every >= 1,
            algo,
            "actor_every",
            "at least 1",
            self.actor_every,
        )?;
        check(
            self.belief_blocks >= 1,
            algo,
            "belief_blocks",
            "at least 1",
            self.belief_blocks,
        )?;
        check(
            self.belief_heads >= 1 && self.belief_width % self.belief_heads == 0,
            algo,
            "belief_heads",
            "at least 1 and a divisor of belief_width",
            self.belief_heads,
        )?;
        check(
            self.belief_width >= 1,
            algo,
            "belief_width",
            "at least 1",
            self.belief_width,
        )?;
        check(
            (0.0..1.0).contains(&self.dropout),
            algo,
            "dropout",
            "in [0, 1)",
            self.dropout,
        )?;
        check(
            self.bc_every >= 1,
            algo,
            "bc_every",
            "at least 1",
            self.bc_every,
        )?;
        check(
            self.bc_updates >= 1,
            algo,
            "bc_updates",
            "at least 1",
            self.bc_updates,
        )
    }

    fn build(&self, spec: &AgentSpec, devices: &Devices, seed: u64) -> Box<dyn Agent> {
        Box::new(Vdpo::new(self, spec, devices, seed))
    }
}

/// The belief network up to its last LayerNorm, and its decoder head.
#[derive(Module, Debug)]
pub struct Belief {
    state_embedding: Linear,
    action_embedding: Linear,
    /// `[embed(s); embed(a_i)]` → token.
    token: Linear,
    position: Embedding,
    input_norm: LayerNorm,
    encoder: TransformerEncoder,
    output_norm: LayerNorm,
    /// Token `i` → `ŝ_{t−Δ+1+i}`.
    decoder: Linear,
}

impl Belief {
    fn new(config: &Config, spec: &AgentSpec, device: &Device) -> Belief {
        let width = config.belief_width;
        Belief {
            state_embedding: LinearConfig::new(spec.obs_dim, width).init(device),
            action_embedding: LinearConfig::new(spec.act_dim, width).init(device),
            token: LinearConfig::new(2 * width, width).init(device),
            position: EmbeddingConfig::new(spec.delay, width).init(device),
            input_norm: LayerNormConfig::new(width).init(device),
            encoder: TransformerEncoderConfig::new(
                width,
                width,
                config.belief_heads,
                config.belief_blocks,
            )
            .with_dropout(config.dropout)
            .with_norm_first(true)
            .init(device),
            output_norm: LayerNormConfig::new(width).init(device),
            decoder: LinearConfig::new(width, spec.obs_dim).init(device),
        }
    }

    /// The tokens' features `[B, Δ, width]` for augmented states `[B, obs + Δ·act]`; position
    /// `i` attends to positions `0..=i` only. `dropout` while the belief trains, `None` off the
    /// graph.
    pub fn features(
        &self,
        augmented: Tensor<2>,
        spec: &AgentSpec,
        mut dropout: Option<&mut DropoutMasks>,
    ) -> Tensor<3> {
        let (obs, act, delay) = (spec.obs_dim, spec.act_dim, spec.delay);
        let rows = augmented.dims()[0];
        let state = augmented.clone().slice([0..rows, 0..obs]);
        let actions = augmented
            .slice([0..rows, obs..obs + delay * act])
            .reshape([rows * delay, act]);
        // token([embed(s); embed(a_i)]) with the token layer's weight split in its two halves:
        // the state's half is the same for every position, so it is multiplied once per row.
        let weight = self.token.weight.val();
        let width = weight.dims()[1];
        let from_state = self
            .state_embedding
            .forward(state)
            .matmul(weight.clone().slice([0..width, 0..width]));
        let from_actions = self
            .action_embedding
            .forward(actions)
            .matmul(weight.slice([width..2 * width, 0..width]))
            .reshape([rows, delay, width]);
        let mut tokens = from_actions
            + from_state.unsqueeze_dim(1)
            + self.position.weight.val().unsqueeze_dim(0);
        if let Some(bias) = &self.token.bias {
            tokens = tokens + bias.val().unsqueeze_dims(&[0, 1]);
        }
        let tokens = dropped(dropout.as_deref_mut(), self.input_norm.forward(tokens));
        let causal = generate_autoregressive_mask(rows, delay, &tokens.device());
        self.output_norm
            .forward(encode(&self.encoder, tokens, causal, dropout))
    }

    /// `ŝ_{t−Δ+1+i}` per position, `[B, Δ, obs]`.
    pub fn reconstruct(&self, features: Tensor<3>) -> Tensor<3> {
        self.decoder.forward(features)
    }

    /// What [`Belief::features`] computes, as plain numbers (for export; the decoder does
    /// not act).
    fn weights(&self) -> BeliefTransformer {
        let blocks = self
            .encoder
            .layers
            .iter()
            .map(|layer| TransformerBlock {
                attention_norm: norm(&layer.norm_2),
                query: dense(&layer.mha.query),
                key: dense(&layer.mha.key),
                value: dense(&layer.mha.value),
                attention_output: dense(&layer.mha.output),
                feed_forward_norm: norm(&layer.norm_1),
                feed_forward_inner: dense(&layer.pwff.linear_inner),
                feed_forward_outer: dense(&layer.pwff.linear_outer),
            })
            .collect();
        let first = &self.encoder.layers[0].mha;
        BeliefTransformer {
            state_embedding: dense(&self.state_embedding),
            action_embedding: dense(&self.action_embedding),
            token: dense(&self.token),
            position: to_vec(self.position.weight.val()),
            input_norm: norm(&self.input_norm),
            blocks,
            output_norm: norm(&self.output_norm),
            heads: first.n_heads,
            mask_fill: first.min_float as f32,
        }
    }
}

/// Dropout masks for one update, drawn from their own ChaCha8 stream in bulk: an entry is kept
/// (and scaled by `1/(1 − p)`) with probability `1 − p`, as burn's `Dropout` does.
pub struct DropoutMasks {
    rng: ChaCha8Rng,
    prob: f64,
}

impl DropoutMasks {
    pub fn new(seed: u64, prob: f64) -> DropoutMasks {
        DropoutMasks {
            rng: ChaCha8Rng::seed_from_u64(seed),
            prob,
        }
    }

    /// `x` with a fresh mask applied.
    pub fn apply<const D: usize>(&mut self, x: Tensor<D>) -> Tensor<D> {
        if self.prob == 0.0 {
            return x;
        }
        let shape = x.shape();
        let mut bits = vec![0u32; shape.num_elements()];
        self.rng.fill(&mut bits[..]);
        let keep = 1.0 - self.prob;
        let threshold = (keep * 4_294_967_296.0) as u64;
        let scale = (1.0 / keep) as f32;
        let mask: Vec<f32> = bits
            .into_iter()
            .map(|b| if u64::from(b) < threshold { scale } else { 0.0 })
            .collect();
        let mask = Tensor::from_data(TensorData::new(mask, shape), &x.device());
        x * mask
    }
}

/// `x` through `masks` when there are any (the belief in training), as it is otherwise.
fn dropped<const D: usize>(masks: Option<&mut DropoutMasks>, x: Tensor<D>) -> Tensor<D> {
    match masks {
        Some(masks) => masks.apply(x),
        None => x,
    }
}

/// The forward pass of burn's pre-LN `TransformerEncoder` (`norm_first`), its weights as they
/// are: per block `x + drop(MHA(norm_2(x)))`, then `x + drop(FF(norm_1(x)))` with
/// `FF = outer(drop(GELU(inner(·))))`; attention weights dropped after the softmax. Without
/// `dropout` it computes what burn's encoder computes in evaluation mode (tested).
pub fn encode(
    encoder: &TransformerEncoder,
    tokens: Tensor<3>,
    causal: Tensor<3, Bool>,
    mut dropout: Option<&mut DropoutMasks>,
) -> Tensor<3> {
    let mut drop = |x: Tensor<3>| dropped(dropout.as_deref_mut(), x);
    let mut x = tokens;
    for layer in &encoder.layers {
        let attended = attention(
            &layer.mha,
            layer.norm_2.forward(x.clone()),
            causal.clone(),
            &mut drop,
        );
        x = x + drop(attended);
        let ff = &layer.pwff;
        let hidden = ff
            .activation
            .forward(ff.linear_inner.forward(layer.norm_1.forward(x.clone())));
        let out = ff.linear_outer.forward(drop(hidden));
        x = x + drop(out);
    }
    x
}

/// Scaled dot-product self-attention of `x` `[B, T, width]` under the causal mask, its
/// weights through `drop` after the softmax, as burn's `MultiHeadAttention`.
fn attention(
    mha: &MultiHeadAttention,
    x: Tensor<3>,
    causal: Tensor<3, Bool>,
    drop: &mut impl FnMut(Tensor<3>) -> Tensor<3>,
) -> Tensor<3> {
    let [rows, tokens, width] = x.dims();
    let (heads, head_width) = (mha.n_heads, mha.d_k);
    let split = |linear: &Linear| {
        linear
            .forward(x.clone())
            .reshape([rows, tokens, heads, head_width])
            .swap_dims(1, 2)
    };
    let (query, key, value) = (split(&mha.query), split(&mha.key), split(&mha.value));
    let scores = query
        .matmul(key.transpose())
        .div_scalar((head_width as f32).sqrt())
        .mask_fill(causal.reshape([rows, 1, tokens, tokens]), mha.min_float);
    let weights = softmax(scores, 3).reshape([rows * heads, tokens, tokens]);
    let weights = drop(weights).reshape([rows, heads, tokens, tokens]);
    let context = weights
        .matmul(value)
        .swap_dims(1, 2)
        .reshape([rows, tokens, width]);
    mha.output.forward(context)
}

/// The belief's reconstruction loss: the squared error of every predicted intermediate state,
/// averaged over positions and state dimensions, `E_i[‖ŝ_{t−Δ+1+i} − s_{t−Δ+1+i}‖²] / dim(S)`.
pub fn reconstruction_loss(predicted: Tensor<3>, truth: Tensor<3>) -> Tensor<1> {
    (predicted - truth).square().mean()
}

/// `KL(N(μ_Δ, σ_Δ) ‖ N(μ_ref, σ_ref))` per action dimension, averaged over dimensions and rows
/// (the cloning loss on the Gaussians before the squash):
/// `log σ_ref − log σ_Δ + (σ_Δ² + (μ_Δ − μ_ref)²) / (2σ_ref²) − 1/2`.
pub fn gaussian_kl(
    (mean, log_std): (Tensor<2>, Tensor<2>),
    (ref_mean, ref_log_std): (Tensor<2>, Tensor<2>),
) -> Tensor<1> {
    let variance = log_std.clone().mul_scalar(2.0).exp();
    let ref_variance = ref_log_std.clone().mul_scalar(2.0).exp();
    (ref_log_std - log_std + (variance + (mean - ref_mean).square()) / ref_variance.mul_scalar(2.0))
        .sub_scalar(0.5)
        .mean()
}

/// `train.csv` columns.
const REFERENCE_STATS: [&str; 3] = ["ref_critic_loss", "ref_actor_loss", "ref_alpha"];
const RECONSTRUCTION_STAT: &str = "reconstruction_loss";
/// Logged on the updates that end in a cloning stage: its mean KL and its length.
const BC_STATS: [&str; 2] = ["bc_kl", "bc_updates"];

/// What VDPO carries between updates besides its networks.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Schedule {
    /// Environment steps at the previous update (none before the first): a cloning stage runs
    /// on the first update after the count crosses a multiple of `bc_every`.
    last_env_steps: Option<u64>,
    /// The delayed policy's exploration noise.
    noise: Noise,
}

pub struct Vdpo {
    spec: AgentSpec,
    seed: u64,
    actor_every: u64,
    bc_every: u64,
    bc_updates: u64,
    belief_learning_rate: f64,
    bc_learning_rate: f64,
    /// Dropout probability in the belief while it trains.
    dropout: f64,
    /// The delay-free SAC on the true state.
    reference: SacLearner,
    belief: Belief,
    belief_opt: ModuleOptimizer,
    policy_head: GaussianPolicy,
    policy_head_opt: ModuleOptimizer,
    scale: ActionScale,
    devices: Devices,
    schedule: Schedule,
}

impl Vdpo {
    pub fn new(config: &Config, spec: &AgentSpec, devices: &Devices, seed: u64) -> Vdpo {
        let mut reference =
            SacLearner::new(spec.obs_dim, spec.obs_dim, spec, &config.sac, devices, seed);
        reference.rates = LearningRates {
            critic: config.critic_learning_rate,
            actor: config.sac.learning_rate,
            temperature: config.temperature_learning_rate,
        };
        devices.train.seed(seeds::named(seed, "vdpo/belief"));
        let belief = Belief::new(config, spec, &devices.train);
        materialize(&belief);
        let policy_head = GaussianPolicy::new(config.belief_width, spec.act_dim, &devices.train);
        materialize(&policy_head);
        Vdpo {
            spec: spec.clone(),
            seed,
            actor_every: config.actor_every,
            bc_every: config.bc_every,
            bc_updates: config.bc_updates,
            belief_learning_rate: config.belief_learning_rate,
            bc_learning_rate: config.bc_learning_rate,
            dropout: config.dropout,
            reference,
            belief,
            belief_opt: adam(config.sac.adam_epsilon),
            policy_head,
            policy_head_opt: adam(config.sac.adam_epsilon),
            scale: ActionScale::new(&spec.action_low, &spec.action_high, &devices.plain),
            devices: devices.clone(),
            schedule: Schedule {
                last_env_steps: None,
                noise: Noise::new(seeds::named(seed, "vdpo/exploration")),
            },
        }
    }

    /// The policy head's input at the last position, `[B, width]`, off the graph.
    fn last_features(&self, augmented: Tensor<2>) -> Tensor<2> {
        let rows = augmented.dims()[0];
        let features = self.belief.valid().features(augmented, &self.spec, None);
        let [_, delay, width] = features.dims();
        features
            .slice([0..rows, delay - 1..delay, 0..width])
            .reshape([rows, width])
    }

    /// One update of the reference SAC on the true `(s, a, r, s')`; returns its statistics.
    fn update_reference(&mut self, batch: &SacBatch, updates_before: u64) -> Stats {
        let alpha = self.reference.temperature.alphas()[0];
        let critic_loss = self.reference.update_critics(batch)[0];
        let mut stats: Stats = vec![
            (REFERENCE_STATS[0], critic_loss),
            (REFERENCE_STATS[2], alpha),
        ];
        if (updates_before + 1) % self.actor_every == 0 {
            let mut actor_loss = 0.0;
            for _ in 0..self.actor_every {
                let distribution = self.reference.distribution(batch);
                actor_loss += self
                    .reference
                    .update_actor_and_temperature(batch, distribution, None)
                    .0[0];
            }
            stats.push((REFERENCE_STATS[1], actor_loss / self.actor_every as f64));
        }
        self.reference.update_targets();
        stats
    }

    /// One step of the belief network on the reconstruction loss; returns the loss. Dropout
    /// masks draw from a stream seeded per update, so that a resumed run draws the same.
    fn update_belief(
        &mut self,
        augmented: Tensor<2>,
        truth: Tensor<3>,
        updates_before: u64,
    ) -> f64 {
        let mut masks = DropoutMasks::new(
            seeds::named(self.seed.wrapping_add(updates_before), "vdpo/dropout"),
            self.dropout,
        );
        let features = self
            .belief
            .features(augmented, &self.spec, Some(&mut masks));
        let loss = reconstruction_loss(self.belief.reconstruct(features), truth);
        let value = f64::from(loss.clone().inner().into_scalar::<f32>());
        let grads = GradientsParams::from_grads(loss.backward(), &self.belief);
        self.belief = self
            .belief_opt
            .step(self.belief_learning_rate, self.belief.clone(), grads);
        value
    }

    /// The cloning stage: `bc_updates` steps of the policy head on fresh batches, the
    /// transformer held fixed; returns the mean KL and the steps taken.
    fn clone_reference(&mut self, ctx: &mut UpdateContext<'_>) -> Result<(f64, u64), ReplayError> {
        let (obs, delay) = (self.spec.obs_dim, self.spec.delay);
        let plain = self.devices.plain.clone();
        let (belief, reference) = (self.belief.valid(), self.reference.actor.valid());
        let (mut kl_sum, mut steps) = (0.0, 0u64);
        while steps < self.bc_updates {
            let batch = ctx.batch()?;
            let n = batch.len();
            let features = belief.features(rows(batch.augmented, n, &plain), &self.spec, None);
            let width = features.dims()[2];
            let features = features.reshape([n * delay, width]);
            let targets = matrix(batch.intermediate_states, n * delay, obs, &plain);
            let loss = gaussian_kl(
                one_run(self.policy_head.distribution(features.unsqueeze_dim(0))),
                one_run(reference.distribution(targets.unsqueeze_dim(0))),
            );
            kl_sum += f64::from(loss.clone().inner().into_scalar::<f32>());
            let grads = GradientsParams::from_grads(loss.backward(), &self.policy_head);
            self.policy_head =
                self.policy_head_opt
                    .step(self.bc_learning_rate, self.policy_head.clone(), grads);
            steps += 1;
        }
        Ok((kl_sum / steps as f64, steps))
    }
}

impl Agent for Vdpo {
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        let width = self.spec.augmented_dim();
        let x = matrix(
            augmented[..rows * width].to_vec(),
            rows,
            width,
            &self.devices.plain,
        );
        let h = self.last_features(x);
        let head = self.policy_head.valid();
        to_vec(match mode {
            ActMode::Explore => {
                let eps = self
                    .schedule
                    .noise
                    .normal(rows, self.spec.act_dim, &self.devices.plain);
                head.sample(h.unsqueeze_dim(0), eps.unsqueeze_dim(0), &self.scale)
                    .action
            }
            ActMode::Deterministic => head.mode(h.unsqueeze_dim(0), &self.scale),
        })
    }

    fn acting_network(&self) -> ActingNetwork {
        ActingNetwork::Belief {
            belief: self.belief.weights(),
            policy: self.policy_head.weights(0),
        }
    }

    fn act_delay_free(&mut self, states: &[f32], rows: usize) -> Option<Vec<f32>> {
        Some(
            self.reference
                .act_run(0, states, rows, self.spec.obs_dim, ActMode::Deterministic),
        )
    }

    fn stat_names(&self) -> Vec<&'static str> {
        REFERENCE_STATS
            .iter()
            .chain(&[RECONSTRUCTION_STAT])
            .chain(&BC_STATS)
            .copied()
            .collect()
    }

    fn batch_extras(&self) -> BatchExtras {
        BatchExtras {
            intermediate_states: true,
        }
    }

    fn update(&mut self, ctx: &mut UpdateContext<'_>) -> Result<Stats, ReplayError> {
        let batch = ctx.batch()?;
        let plain = self.devices.plain.clone();
        let (n, obs, delay) = (batch.len(), self.spec.obs_dim, self.spec.delay);
        let tensors = TransitionTensors::new(&batch, &plain);
        let on_state = (tensors.state.clone(), tensors.next_state.clone());

        // 1. The reference SAC on the true, time-aligned (s, a, r, s').
        let mut stats = self.update_reference(
            &SacBatch::new(&tensors, on_state.clone(), on_state),
            ctx.updates,
        );

        // 2. The belief: reconstruct s_{τ−Δ+1..τ} from x_τ.
        let truth: Tensor<3> =
            matrix(batch.intermediate_states, n * delay, obs, &plain).reshape([n, delay, obs]);
        stats.push((
            RECONSTRUCTION_STAT,
            self.update_belief(tensors.augmented.squeeze_dim(0), truth, ctx.updates),
        ));

        // 3. The cloning stage, on its schedule.
        let due = self
            .schedule
            .last_env_steps
            .is_some_and(|last| ctx.env_steps / self.bc_every > last / self.bc_every);
        self.schedule.last_env_steps = Some(ctx.env_steps);
        if due {
            let (kl, steps) = self.clone_reference(ctx)?;
            stats.extend([(BC_STATS[0], kl), (BC_STATS[1], steps as f64)]);
        }
        Ok(stats)
    }

    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.reference.save(&[dir], "reference_")?;
        let files = CheckpointDir::new(dir);
        files.save_module("belief.bpk", &self.belief)?;
        files.save_slice("policy_head.bpk", &self.policy_head, 0)?;
        files.save_optimizer("belief_adam.bpk", &self.belief_opt)?;
        files.save_optimizer_slice("policy_head_adam.bpk", &self.policy_head_opt, 0)?;
        files.save_json("vdpo.json", &self.schedule)
    }

    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.reference.load(&[dir], "reference_")?;
        let files = CheckpointDir::new(dir);
        self.belief = files.load_module("belief.bpk", self.belief.clone())?;
        self.policy_head = load_stack(&[files], "policy_head.bpk", self.policy_head.clone())?;
        self.belief_opt = files.load_optimizer("belief_adam.bpk", self.belief_opt.clone())?;
        self.policy_head_opt = load_optimizer_stack(
            &[files],
            "policy_head_adam.bpk",
            self.policy_head_opt.clone(),
        )?;
        self.schedule = files.load_json("vdpo.json")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algos::random_batch;
    use crate::learn::{LearnDevice, assert_close as close};
    use burn::nn::transformer::TransformerEncoderInput;

    #[test]
    fn gaussian_kl_matches_hand_values() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        // Dimension 1: N(0, 1) against N(1, 2²): ln 2 + (1 + 1) / 8 − 1/2. Dimension 2: equal
        // Gaussians, 0. The loss averages the two.
        let kl = gaussian_kl(
            (
                matrix(vec![0.0, 0.3], 1, 2, &device),
                matrix(vec![0.0, -1.0], 1, 2, &device),
            ),
            (
                matrix(vec![1.0, 0.3], 1, 2, &device),
                matrix(vec![2.0f32.ln(), -1.0], 1, 2, &device),
            ),
        );
        close(&to_vec(kl), &[(2.0f32.ln() + 0.25 - 0.5) / 2.0]);
    }

    fn small_agent(bc_updates: u64) -> (Vdpo, AgentSpec) {
        let devices = Devices::new(LearnDevice::Cpu).unwrap();
        let spec = AgentSpec {
            obs_dim: 3,
            act_dim: 2,
            delay: 4,
            action_low: vec![-1.0; 2],
            action_high: vec![1.0; 2],
        };
        let config = Config {
            belief_width: 8,
            belief_blocks: 2,
            belief_heads: 2,
            bc_every: 10,
            bc_updates,
            ..Config::default()
        };
        (Vdpo::new(&config, &spec, &devices, 4), spec)
    }

    /// Two augmented states that differ only in their last action `a_{t−1}`.
    fn differing_in_the_last_action(spec: &AgentSpec) -> (Vec<f32>, Vec<f32>) {
        let x = random_batch(spec, 2, 6).augmented;
        let mut changed = x.clone();
        let aug = spec.augmented_dim();
        for row in changed.chunks_mut(aug) {
            for a in &mut row[aug - spec.act_dim..] {
                *a = -*a + 0.5;
            }
        }
        (x, changed)
    }

    /// The causal mask: the features at positions before the last do not see the last action;
    /// the last position does.
    #[test]
    fn a_position_sees_no_later_action() {
        let (agent, spec) = small_agent(1);
        let (x, changed) = differing_in_the_last_action(&spec);
        let features = |x: Vec<f32>| {
            let input = matrix(x, 2, spec.augmented_dim(), &agent.devices.plain);
            to_vec(agent.belief.valid().features(input, &spec, None))
        };
        let (a, b) = (features(x), features(changed));
        let per_position = 8;
        for (k, (p, q)) in a.iter().zip(&b).enumerate() {
            let position = (k / per_position) % spec.delay;
            if position + 1 < spec.delay {
                assert!(
                    (p - q).abs() < 1e-6,
                    "position {position} saw a later action"
                );
            }
        }
        let last_moved = a.iter().zip(&b).enumerate().any(|(k, (p, q))| {
            (k / per_position) % spec.delay == spec.delay - 1 && (p - q).abs() > 1e-4
        });
        assert!(last_moved, "the last position does not see a_(t-1)");
    }

    /// The delayed policy acts from the last position, the only one that has seen every action.
    #[test]
    fn the_policy_acts_from_the_last_position() {
        let (mut agent, spec) = small_agent(1);
        let (x, changed) = differing_in_the_last_action(&spec);
        let a = agent.act(&x, 2, ActMode::Deterministic);
        let b = agent.act(&changed, 2, ActMode::Deterministic);
        assert!(
            a.iter().zip(&b).any(|(p, q)| (p - q).abs() > 1e-5),
            "{a:?} {b:?}: the action ignores a_(t-1)"
        );
    }

    /// The cloning loss is KL(π_Δ(·|x) ‖ π_ref(·|s)), the delayed policy first: the stage's
    /// logged KL is that direction computed here, far closer to it than to the other one.
    /// (The networks' initial weights come from burn's process-wide generator, which tests in
    /// other threads draw from too, so the values vary between runs; the relations do not.)
    #[test]
    fn the_cloning_loss_is_kl_of_the_delayed_policy_from_the_reference() {
        let (mut agent, spec) = small_agent(1);
        let mut batch = random_batch(&spec, 4, 2);
        // States far apart, so that the reference's Gaussians differ from the head's and the
        // two directions of the KL from each other.
        batch
            .intermediate_states
            .iter_mut()
            .for_each(|s| *s *= 20.0);
        let plain = agent.devices.plain.clone();
        let n = batch.len();
        let features = agent
            .belief
            .valid()
            .features(rows(batch.augmented.clone(), n, &plain), &spec, None)
            .reshape([n * spec.delay, 8]);
        let targets = matrix(
            batch.intermediate_states.clone(),
            n * spec.delay,
            spec.obs_dim,
            &plain,
        );
        let (head, reference) = (
            one_run(
                agent
                    .policy_head
                    .valid()
                    .distribution(features.unsqueeze_dim(0)),
            ),
            one_run(
                agent
                    .reference
                    .actor
                    .valid()
                    .distribution(targets.unsqueeze_dim(0)),
            ),
        );
        let forward = f64::from(to_vec(gaussian_kl(head.clone(), reference.clone()))[0]);
        let backward = f64::from(to_vec(gaussian_kl(reference, head))[0]);
        let gap = (forward - backward).abs();
        assert!(gap > 1e-4 * forward.abs(), "{forward} {backward}");
        let (kl, steps) = agent
            .clone_reference(&mut UpdateContext::fixed(&batch, 0, 0))
            .unwrap();
        assert_eq!(steps, 1);
        assert!(
            (kl - forward).abs() < gap / 100.0,
            "{kl}: KL(head ‖ reference) {forward}, KL(reference ‖ head) {backward}"
        );
    }

    /// The written-out forward pass is burn's encoder in evaluation mode, weights as they are.
    #[test]
    fn encode_without_dropout_is_burns_encoder_in_evaluation() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        device.seed(5);
        let encoder = TransformerEncoderConfig::new(8, 8, 2, 2)
            .with_dropout(0.1)
            .with_norm_first(true)
            .init(&device);
        let tokens = Tensor::<3>::random([3, 4, 8], burn::tensor::Distribution::Default, &device);
        let causal = generate_autoregressive_mask(3, 4, &device);
        let burns =
            encoder.forward(TransformerEncoderInput::new(tokens.clone()).mask_attn(causal.clone()));
        close(
            &to_vec(encode(&encoder, tokens, causal, None)),
            &to_vec(burns),
        );
    }

    /// A mask keeps about 1 − p of the entries, scaled by 1/(1 − p), and repeats for a seed.
    #[test]
    fn dropout_masks_keep_one_minus_p_scaled_and_repeat_per_seed() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        let ones = Tensor::<2>::ones([100, 100], &device);
        let mask = |seed| to_vec(DropoutMasks::new(seed, 0.1).apply(ones.clone()));
        let first = mask(9);
        assert_eq!(first, mask(9));
        assert_ne!(first, mask(10));
        // Binomial(10,000, 0.9): standard deviation 30.
        let kept = first.iter().filter(|&&v| v != 0.0).count();
        assert!((8800..=9200).contains(&kept), "{kept} kept");
        assert!(
            first
                .iter()
                .all(|&v| v == 0.0 || (v - 1.0 / 0.9).abs() < 1e-6)
        );
    }

    #[test]
    fn reconstruction_loss_matches_hand_values() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        // Two positions of a 1-dimensional state: errors 1 and 3, so (1 + 9) / 2; every
        // position of a replayed x_t is a real state, so none is masked.
        let predicted: Tensor<3> = matrix(vec![0.0, 0.0], 2, 1, &device).reshape([1, 2, 1]);
        let truth: Tensor<3> = matrix(vec![1.0, 3.0], 2, 1, &device).reshape([1, 2, 1]);
        close(&to_vec(reconstruction_loss(predicted, truth)), &[5.0]);
    }

    /// The cloning stage runs on the first update after every multiple of `bc_every`
    /// environment steps (never on the first update), exactly `bc_updates` head steps long,
    /// and nothing else moves the policy head.
    #[test]
    fn the_cloning_stage_runs_exactly_its_burst_at_its_schedule() {
        let devices = Devices::new(LearnDevice::Cpu).unwrap();
        let spec = AgentSpec {
            obs_dim: 3,
            act_dim: 2,
            delay: 2,
            action_low: vec![-1.0; 2],
            action_high: vec![1.0; 2],
        };
        let config = Config {
            belief_width: 8,
            belief_blocks: 1,
            bc_every: 10,
            bc_updates: 3,
            ..Config::default()
        };
        let batch = random_batch(&spec, 4, 1);
        let head = |agent: &Vdpo| {
            let mut values = Vec::new();
            struct Collect<'a>(&'a mut Vec<f32>);
            impl burn::module::ModuleVisitor for Collect<'_> {
                fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
                    self.0.extend(to_vec(param.val()));
                }
            }
            agent.policy_head.visit(&mut Collect(&mut values));
            values
        };
        // One copy (env steps 5, 6, …) and four copies (4, 8, 12, …).
        for (first, stride, expected) in
            [(5u64, 1u64, vec![10u64, 20, 30]), (4, 4, vec![12, 20, 32])]
        {
            let mut agent = Vdpo::new(&config, &spec, &devices, 3);
            let mut bursts = Vec::new();
            for (updates, env_steps) in (first..=33).step_by(stride as usize).enumerate() {
                let before = head(&agent);
                let stats = agent
                    .update(&mut UpdateContext::fixed(&batch, env_steps, updates as u64))
                    .unwrap();
                let moved = head(&agent) != before;
                match stats.iter().find(|(name, _)| *name == BC_STATS[1]) {
                    Some(&(_, steps)) => {
                        assert_eq!(steps, 3.0, "burst at {env_steps}");
                        assert!(moved, "the burst at {env_steps} left the head as it was");
                        bursts.push(env_steps);
                    }
                    None => assert!(!moved, "the head moved outside a burst at {env_steps}"),
                }
            }
            assert_eq!(bursts, expected);
        }
    }
}
