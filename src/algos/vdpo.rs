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
//! generator call per entry, which was a sixth of an update's time; on the CPU its GELU and
//! layer norms are dhrl's own ops, `learn::cpu_ops`, which took 13–22% off an update). Two
//! heads read it: a decoder reconstructing `s_{t−Δ+1+i}` at position `i` (trained every
//! update, and the only loss that trains the transformer) and a Gaussian policy head (2×256
//! ReLU, as the reference) read at every position by the cloning loss — position `i` is cloned
//! toward `π_ref(·|s_{t−Δ+1+i})` — and at the last position to act.
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
use std::ops::Range;
use std::path::Path;

use burn::module::{Module, Param};
use burn::nn::attention::generate_autoregressive_mask;
use burn::nn::transformer::{TransformerEncoder, TransformerEncoderConfig};
use burn::nn::{EmbeddingConfig, LayerNormConfig};
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use burn::tensor::activation::softmax;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::agent::{ActMode, Agent, AgentSpec, AlgoConfig, AlgoError, AlgoInfo, check};
use super::context::UpdateContext;
use super::sac::{Config as SacConfig, LearningRates, SacBatch, SacLearner};
use super::stats::Stats;
use crate::acting::{ActingNetwork, BeliefTransformer, TransformerBlock};
use crate::delay::{BatchExtras, ReplayError};
use crate::learn::{
    ActionScale, CheckpointDir, Devices, GaussianPolicy, LearnError, Noise, StackedLayerNorm,
    StackedLinear, TransitionTensors, adam, gelu, load_json_stack, load_optimizer_stack,
    load_stack, select_runs, stack, stacked_rows, times_mask, to_vec,
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
        cpu_runs_per_pass: 1,
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

    fn build_stack(&self, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Box<dyn Agent> {
        Box::new(Vdpo::new(self, spec, devices, seeds))
    }

    /// A cloning stage every `updates` steps at most, of as many head steps per environment
    /// step as configured (rounded, at least one): 1,000 every 1,000 steps timed over 5 updates
    /// is 5 every 5.
    fn schedule_within(&self, updates: u64) -> Config {
        let updates = updates.max(1);
        if self.bc_every <= updates {
            return self.clone();
        }
        let per_step = self.bc_updates as f64 / self.bc_every as f64;
        Config {
            bc_every: updates,
            bc_updates: ((per_step * updates as f64).round() as u64).max(1),
            ..self.clone()
        }
    }
}

/// Token positions' embeddings, `[S, Δ, width]` (burn's `Embedding` of Δ entries per run).
#[derive(Module, Debug)]
pub struct Positions {
    pub weight: Param<Tensor<3>>,
}

/// The belief network up to its last LayerNorm, and its decoder head, for each run of a stack
/// (fields named as burn's modules, so that a run's record is a solo run's).
#[derive(Module, Debug)]
pub struct Belief {
    state_embedding: StackedLinear,
    action_embedding: StackedLinear,
    /// `[embed(s); embed(a_i)]` → token.
    token: StackedLinear,
    position: Positions,
    input_norm: StackedLayerNorm,
    encoder: Encoder,
    output_norm: StackedLayerNorm,
    /// Token `i` → `ŝ_{t−Δ+1+i}`.
    decoder: StackedLinear,
}

impl Belief {
    /// One run's network, drawn in the order of its fields from the device's generator as
    /// burn's modules draw it (the transformer by burn's `TransformerEncoderConfig`).
    fn new(config: &Config, spec: &AgentSpec, device: &Device) -> Belief {
        let width = config.belief_width;
        let state_embedding = StackedLinear::new(spec.obs_dim, width, device);
        let action_embedding = StackedLinear::new(spec.act_dim, width, device);
        let token = StackedLinear::new(2 * width, width, device);
        let position = EmbeddingConfig::new(spec.delay, width).init(device);
        let position = Positions {
            weight: Param::from_tensor(position.weight.val().unsqueeze_dim(0).detach()),
        };
        let input_norm = StackedLayerNorm::from_burn(&LayerNormConfig::new(width).init(device));
        let encoder = Encoder::from_burn(
            &TransformerEncoderConfig::new(width, width, config.belief_heads, config.belief_blocks)
                .with_dropout(config.dropout)
                .with_norm_first(true)
                .init(device),
        );
        Belief {
            state_embedding,
            action_embedding,
            token,
            position,
            input_norm,
            encoder,
            output_norm: StackedLayerNorm::from_burn(&LayerNormConfig::new(width).init(device)),
            decoder: StackedLinear::new(width, spec.obs_dim, device),
        }
    }

    /// Each run's tokens' features `[S, B, Δ, width]` for its augmented states
    /// `[S, B, obs + Δ·act]`; position `i` attends to positions `0..=i` only. Each run's
    /// `dropout` masks while the belief trains, `None` off the graph.
    pub fn features(
        &self,
        augmented: Tensor<3>,
        spec: &AgentSpec,
        mut dropout: Option<&mut [DropoutMasks]>,
    ) -> Tensor<4> {
        let (obs, act, delay) = (spec.obs_dim, spec.act_dim, spec.delay);
        let [runs, rows, _] = augmented.dims();
        let state = augmented.clone().narrow(2, 0, obs);
        let actions = augmented
            .narrow(2, obs, delay * act)
            .reshape([runs, rows * delay, act]);
        // token([embed(s); embed(a_i)]) with the token layer's weight split in its two halves:
        // the state's half is the same for every position, so it is multiplied once per row.
        let weight = self.token.weight.val();
        let width = weight.dims()[2];
        let from_state = self
            .state_embedding
            .forward(state)
            .matmul(weight.clone().narrow(1, 0, width));
        let from_actions = self
            .action_embedding
            .forward(actions)
            .matmul(weight.narrow(1, width, width))
            .reshape([runs, rows, delay, width]);
        let tokens = from_actions
            + from_state.unsqueeze_dim(2)
            + self.position.weight.val().unsqueeze_dim(1)
            + self.token.bias.val().unsqueeze_dims(&[1, 2]);
        let tokens = dropped(dropout.as_deref_mut(), self.input_norm.forward(tokens)).reshape([
            runs,
            rows * delay,
            width,
        ]);
        let causal = generate_autoregressive_mask(runs * rows, delay, &tokens.device());
        self.output_norm
            .forward(self.encoder.forward(tokens, delay, causal, dropout))
            .reshape([runs, rows, delay, width])
    }

    /// `ŝ_{t−Δ+1+i}` per position, `[S, B, Δ, obs]`.
    pub fn reconstruct(&self, features: Tensor<4>) -> Tensor<4> {
        let [runs, rows, delay, width] = features.dims();
        let predicted = self
            .decoder
            .forward(features.reshape([runs, rows * delay, width]));
        let obs = predicted.dims()[2];
        predicted.reshape([runs, rows, delay, obs])
    }

    /// The policy head's input at the last position, `[S, B, width]`.
    fn last_features(&self, augmented: Tensor<3>, spec: &AgentSpec) -> Tensor<3> {
        let features = self.features(augmented, spec, None);
        let [runs, rows, delay, width] = features.dims();
        features
            .narrow(2, delay - 1, 1)
            .reshape([runs, rows, width])
    }

    /// What [`Belief::features`] computes for run `slice`, as plain numbers (for export; the
    /// decoder does not act).
    fn weights(&self, slice: usize) -> BeliefTransformer {
        let blocks = self
            .encoder
            .layers
            .iter()
            .map(|layer| TransformerBlock {
                attention_norm: layer.norm_2.norm(slice),
                query: layer.mha.query.dense(slice),
                key: layer.mha.key.dense(slice),
                value: layer.mha.value.dense(slice),
                attention_output: layer.mha.output.dense(slice),
                feed_forward_norm: layer.norm_1.norm(slice),
                feed_forward_inner: layer.pwff.linear_inner.dense(slice),
                feed_forward_outer: layer.pwff.linear_outer.dense(slice),
            })
            .collect();
        let first = &self.encoder.layers[0].mha;
        BeliefTransformer {
            state_embedding: self.state_embedding.dense(slice),
            action_embedding: self.action_embedding.dense(slice),
            token: self.token.dense(slice),
            position: to_vec(self.position.weight.val().narrow(0, slice, 1)),
            input_norm: self.input_norm.norm(slice),
            blocks,
            output_norm: self.output_norm.norm(slice),
            heads: first.heads,
            mask_fill: first.min_float as f32,
        }
    }
}

/// burn's pre-LN `TransformerEncoder` (`norm_first`) for each run of a stack: one set of
/// stacked weights, its forward pass written out (attention included) so that one batched
/// product serves every run. Fields named as burn's.
#[derive(Module, Debug)]
pub struct Encoder {
    pub layers: Vec<EncoderBlock>,
}

/// One pre-LN block: `x + drop(MHA(norm_2(x)))`, then `x + drop(FF(norm_1(x)))`.
#[derive(Module, Debug)]
pub struct EncoderBlock {
    pub mha: Attention,
    pub pwff: FeedForward,
    pub norm_1: StackedLayerNorm,
    pub norm_2: StackedLayerNorm,
}

/// Multi-head self-attention with stacked projections.
#[derive(Module, Debug)]
pub struct Attention {
    pub query: StackedLinear,
    pub key: StackedLinear,
    pub value: StackedLinear,
    pub output: StackedLinear,
    pub heads: usize,
    /// What masked scores are filled with before the softmax (burn's `min_float`).
    pub min_float: f64,
}

/// `outer(drop(GELU(inner(·))))`.
#[derive(Module, Debug)]
pub struct FeedForward {
    pub linear_inner: StackedLinear,
    pub linear_outer: StackedLinear,
}

impl Encoder {
    /// burn's encoder as a one-run stack, its weights as they are (drawn in the order of
    /// burn's fields if they are not yet).
    pub fn from_burn(encoder: &TransformerEncoder) -> Encoder {
        Encoder {
            layers: encoder
                .layers
                .iter()
                .map(|layer| EncoderBlock {
                    mha: Attention {
                        query: StackedLinear::from_burn(&layer.mha.query),
                        key: StackedLinear::from_burn(&layer.mha.key),
                        value: StackedLinear::from_burn(&layer.mha.value),
                        output: StackedLinear::from_burn(&layer.mha.output),
                        heads: layer.mha.n_heads,
                        min_float: layer.mha.min_float,
                    },
                    pwff: FeedForward {
                        linear_inner: StackedLinear::from_burn(&layer.pwff.linear_inner),
                        linear_outer: StackedLinear::from_burn(&layer.pwff.linear_outer),
                    },
                    norm_1: StackedLayerNorm::from_burn(&layer.norm_1),
                    norm_2: StackedLayerNorm::from_burn(&layer.norm_2),
                })
                .collect(),
        }
    }

    /// Each run's `x` `[S, B·T, width]` (B rows of T tokens) through the blocks, under
    /// `causal` `[S·B, T, T]`; attention weights dropped after the softmax. Without `dropout`
    /// it computes what burn's encoder computes in evaluation mode (tested).
    pub fn forward(
        &self,
        tokens: Tensor<3>,
        per_row: usize,
        causal: Tensor<3, Bool>,
        mut dropout: Option<&mut [DropoutMasks]>,
    ) -> Tensor<3> {
        let mut drop = |x: Tensor<3>| dropped(dropout.as_deref_mut(), x);
        let mut x = tokens;
        for layer in &self.layers {
            let attended = layer.mha.forward(
                layer.norm_2.forward(x.clone()),
                per_row,
                causal.clone(),
                &mut drop,
            );
            x = x + drop(attended);
            let ff = &layer.pwff;
            let hidden = gelu(ff.linear_inner.forward(layer.norm_1.forward(x.clone())));
            let out = ff.linear_outer.forward(drop(hidden));
            x = x + drop(out);
        }
        x
    }
}

impl Attention {
    /// Scaled dot-product self-attention of each run's `x` `[S, B·T, width]` under the causal
    /// mask `[S·B, T, T]`, its weights through `drop` after the softmax, as burn's
    /// `MultiHeadAttention`.
    fn forward(
        &self,
        x: Tensor<3>,
        per_row: usize,
        causal: Tensor<3, Bool>,
        drop: &mut impl FnMut(Tensor<3>) -> Tensor<3>,
    ) -> Tensor<3> {
        let [runs, n, width] = x.dims();
        let rows = runs * n / per_row;
        let (heads, head_width) = (self.heads, width / self.heads);
        let split = |linear: &StackedLinear| {
            linear
                .forward(x.clone())
                .reshape([rows, per_row, heads, head_width])
                .swap_dims(1, 2)
        };
        let (query, key, value) = (split(&self.query), split(&self.key), split(&self.value));
        let scores = query
            .matmul(key.transpose())
            .div_scalar((head_width as f32).sqrt())
            .mask_fill(causal.reshape([rows, 1, per_row, per_row]), self.min_float);
        let weights = softmax(scores, 3).reshape([runs, rows / runs * heads * per_row, per_row]);
        let weights = drop(weights).reshape([rows, heads, per_row, per_row]);
        let context = weights
            .matmul(value)
            .swap_dims(1, 2)
            .reshape([runs, n, width]);
        self.output.forward(context)
    }
}

/// Dropout masks for one update of one run, drawn from their own ChaCha8 stream in bulk: an
/// entry is kept (and scaled by `1/(1 − p)`) with probability `1 − p`, as burn's `Dropout`
/// does.
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

    /// `x` `[S, …]` with a fresh mask of each run's masks applied to its slice.
    fn apply_stacked<const D: usize>(runs: &mut [DropoutMasks], x: Tensor<D>) -> Tensor<D> {
        if runs[0].prob == 0.0 {
            return x;
        }
        let shape = x.shape();
        let per_run = shape.num_elements() / runs.len();
        let mut mask = vec![0.0f32; shape.num_elements()];
        for (run, slice) in runs.iter_mut().zip(mask.chunks_mut(per_run)) {
            run.fill_mask(slice);
        }
        times_mask(x, mask)
    }

    /// Fills `mask` with the next `mask.len()` entries of this run's masks: one `u32` of the
    /// stream per entry, written in place (an entry-by-entry collect was 4% of an update), an
    /// entry kept when its `u32` is below `(1 − p)·2³²`.
    fn fill_mask(&mut self, mask: &mut [f32]) {
        let bits: &mut [u32] = bytemuck::cast_slice_mut(mask);
        self.rng.fill(bits);
        let keep = 1.0 - self.prob;
        let scale = ((1.0 / keep) as f32).to_bits();
        // A 32-bit threshold keeps the comparison a vector one (a 64-bit compare was a scalar
        // loop, 3% of a VDPO update); it fits unless 1 − p rounds to 1, which keeps all.
        match u32::try_from((keep * 4_294_967_296.0) as u64) {
            Ok(threshold) => {
                for b in bits.iter_mut() {
                    *b = if *b < threshold { scale } else { 0 };
                }
            }
            Err(_) => bits.fill(scale),
        }
    }
}

/// `x` through each run's `masks` when there are any (the belief in training), as it is
/// otherwise.
fn dropped<const D: usize>(masks: Option<&mut [DropoutMasks]>, x: Tensor<D>) -> Tensor<D> {
    match masks {
        Some(masks) => DropoutMasks::apply_stacked(masks, x),
        None => x,
    }
}

/// The belief's reconstruction loss per run `[S]`: the squared error of every predicted
/// intermediate state, averaged over positions and state dimensions,
/// `E_i[‖ŝ_{t−Δ+1+i} − s_{t−Δ+1+i}‖²] / dim(S)`.
pub fn reconstruction_loss(predicted: Tensor<4>, truth: Tensor<4>) -> Tensor<1> {
    let [runs, rows, delay, obs] = predicted.dims();
    (predicted - truth)
        .square()
        .reshape([runs, rows * delay * obs])
        .mean_dim(1)
        .reshape([runs])
}

/// `KL(N(μ_Δ, σ_Δ) ‖ N(μ_ref, σ_ref))` per action dimension, averaged over dimensions and each
/// run's rows, `[S]` (the cloning loss on the Gaussians before the squash):
/// `log σ_ref − log σ_Δ + (σ_Δ² + (μ_Δ − μ_ref)²) / (2σ_ref²) − 1/2`.
pub fn gaussian_kl(
    (mean, log_std): (Tensor<3>, Tensor<3>),
    (ref_mean, ref_log_std): (Tensor<3>, Tensor<3>),
) -> Tensor<1> {
    let [runs, rows, act] = mean.dims();
    let variance = log_std.clone().mul_scalar(2.0).exp();
    let ref_variance = ref_log_std.clone().mul_scalar(2.0).exp();
    (ref_log_std - log_std + (variance + (mean - ref_mean).square()) / ref_variance.mul_scalar(2.0))
        .sub_scalar(0.5)
        .reshape([runs, rows * act])
        .mean_dim(1)
        .reshape([runs])
}

/// `train.csv` columns.
const REFERENCE_STATS: [&str; 3] = ["ref_critic_loss", "ref_actor_loss", "ref_alpha"];
const RECONSTRUCTION_STAT: &str = "reconstruction_loss";
/// Logged on the updates that end in a cloning stage: its mean KL and its length.
const BC_STATS: [&str; 2] = ["bc_kl", "bc_updates"];

/// What a VDPO run carries between updates besides its networks.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Schedule {
    /// Environment steps at the previous update (none before the first): a cloning stage runs
    /// on the first update after the count crosses a multiple of `bc_every`.
    last_env_steps: Option<u64>,
    /// The delayed policy's exploration noise.
    noise: Noise,
}

/// VDPO for a stack of runs (a solo run is S = 1): every network stacked, a schedule, noise
/// and dropout stream per run.
pub struct Vdpo {
    spec: AgentSpec,
    seeds: Vec<u64>,
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
    schedules: Vec<Schedule>,
}

impl Vdpo {
    /// The runs of `seeds`.
    pub fn new(config: &Config, spec: &AgentSpec, devices: &Devices, seeds: &[u64]) -> Vdpo {
        let mut reference = SacLearner::on_state(spec, &config.sac, devices, seeds);
        reference.rates = LearningRates {
            critic: config.critic_learning_rate,
            actor: config.sac.learning_rate,
            temperature: config.temperature_learning_rate,
        };
        let (beliefs, heads): (Vec<_>, Vec<_>) = seeds
            .iter()
            .map(|&seed| {
                devices.train.seed(seeds::named(seed, "vdpo/belief"));
                let belief = Belief::new(config, spec, &devices.train);
                let head = GaussianPolicy::new(config.belief_width, spec.act_dim, &devices.train);
                (belief, head)
            })
            .unzip();
        Vdpo {
            spec: spec.clone(),
            seeds: seeds.to_vec(),
            actor_every: config.actor_every,
            bc_every: config.bc_every,
            bc_updates: config.bc_updates,
            belief_learning_rate: config.belief_learning_rate,
            bc_learning_rate: config.bc_learning_rate,
            dropout: config.dropout,
            reference,
            belief: stack(beliefs),
            belief_opt: adam(config.sac.adam_epsilon),
            policy_head: stack(heads),
            policy_head_opt: adam(config.sac.adam_epsilon),
            scale: ActionScale::new(&spec.action_low, &spec.action_high, &devices.plain),
            devices: devices.clone(),
            schedules: seeds
                .iter()
                .map(|&seed| Schedule {
                    last_env_steps: None,
                    noise: Noise::new(seeds::named(seed, "vdpo/exploration")),
                })
                .collect(),
        }
    }

    /// One update of the reference SAC on the true `(s, a, r, s')`; returns its statistics.
    fn update_reference(&mut self, batch: &SacBatch, updates_before: u64) -> Stats {
        let mut stats = Stats::new();
        stats.push(
            REFERENCE_STATS[2],
            self.reference.temperature.alpha_values(),
        );
        stats.push(REFERENCE_STATS[0], self.reference.update_critics(batch));
        if (updates_before + 1) % self.actor_every == 0 {
            let losses = (0..self.actor_every)
                .map(|_| {
                    let distribution = self.reference.distribution(batch);
                    let (losses, _) =
                        self.reference
                            .update_actor_and_temperature(batch, distribution, None);
                    losses
                })
                .collect();
            stats.push_mean(REFERENCE_STATS[1], losses);
        }
        self.reference.update_targets();
        stats
    }

    /// One step of the belief network on the runs' reconstruction losses (summed); returns
    /// each run's loss. Dropout masks draw from a stream seeded per run and update, so that a
    /// resumed run draws the same.
    fn update_belief(
        &mut self,
        augmented: Tensor<3>,
        truth: Tensor<4>,
        updates_before: u64,
    ) -> Tensor<1> {
        let mut masks: Vec<DropoutMasks> = self
            .seeds
            .iter()
            .map(|seed| {
                let stream = seeds::named(seed.wrapping_add(updates_before), "vdpo/dropout");
                DropoutMasks::new(stream, self.dropout)
            })
            .collect();
        let features = self
            .belief
            .features(augmented, &self.spec, Some(&mut masks));
        let losses = reconstruction_loss(self.belief.reconstruct(features), truth);
        let values = losses.clone().inner();
        let grads = GradientsParams::from_grads(losses.sum().backward(), &self.belief);
        self.belief = self
            .belief_opt
            .step(self.belief_learning_rate, self.belief.clone(), grads);
        values
    }

    /// The cloning stage: `bc_updates` steps of the policy heads, each run on fresh batches of
    /// its own, the transformer held fixed; returns each run's KL `[S]` at each step.
    fn clone_reference(
        &mut self,
        contexts: &mut [UpdateContext<'_>],
    ) -> Result<Vec<Tensor<1>>, ReplayError> {
        let (runs, obs, delay) = (self.seeds.len(), self.spec.obs_dim, self.spec.delay);
        let plain = self.devices.plain.clone();
        let (belief, reference) = (self.belief.valid(), self.reference.actor.valid());
        let mut kls = Vec::new();
        while (kls.len() as u64) < self.bc_updates {
            let batches = UpdateContext::batches(contexts)?;
            let n = batches[0].len();
            let augmented = stacked_rows(
                batches.iter().map(|b| b.augmented.as_slice()),
                &batches,
                &plain,
            );
            let features = belief.features(augmented, &self.spec, None);
            let width = features.dims()[3];
            let features = features.reshape([runs, n * delay, width]);
            let targets = stacked_rows(
                batches.iter().map(|b| b.intermediate_states.as_slice()),
                &batches,
                &plain,
            )
            .reshape([runs, n * delay, obs]);
            let losses = gaussian_kl(
                self.policy_head.distribution(features),
                reference.distribution(targets),
            );
            kls.push(losses.clone().inner());
            let grads = GradientsParams::from_grads(losses.sum().backward(), &self.policy_head);
            self.policy_head =
                self.policy_head_opt
                    .step(self.bc_learning_rate, self.policy_head.clone(), grads);
        }
        Ok(kls)
    }
}

impl Agent for Vdpo {
    fn runs(&self) -> usize {
        self.seeds.len()
    }

    fn spec(&self) -> &AgentSpec {
        &self.spec
    }

    fn acting_device(&self) -> &Device {
        &self.devices.plain
    }

    /// The policy head on the belief's features at the newest position.
    fn act_tensor(
        &mut self,
        runs: Range<usize>,
        augmented: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3> {
        let stack = self.runs();
        let belief = select_runs(self.belief.valid(), runs.clone(), stack);
        let head = select_runs(self.policy_head.valid(), runs.clone(), stack);
        let rows = augmented.dims()[1];
        let h = belief.last_features(augmented, &self.spec);
        match mode {
            ActMode::Explore => {
                let eps = Noise::stacked_normal_rows(
                    self.schedules[runs].iter_mut().map(|s| &mut s.noise),
                    counts,
                    rows,
                    self.spec.act_dim,
                    &self.devices.plain,
                );
                head.sample(h, eps, &self.scale).action
            }
            ActMode::Deterministic => head.mode(h, &self.scale),
        }
    }

    fn acting_network(&self) -> ActingNetwork {
        ActingNetwork::Belief {
            belief: self.belief.weights(0),
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

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        // The runs of a stack step together: their counters are the same.
        let (updates, env_steps) = (contexts[0].updates, contexts[0].env_steps);
        let batches = UpdateContext::batches(contexts)?;
        let plain = self.devices.plain.clone();
        let (runs, n) = (batches.len(), batches[0].len());
        let t = TransitionTensors::stacked(&batches, &plain);
        let on_state = (t.state.clone(), t.next_state.clone());

        // 1. The reference SAC on the true, time-aligned (s, a, r, s').
        let mut stats =
            self.update_reference(&SacBatch::new(&t, on_state.clone(), on_state), updates);

        // 2. The belief: reconstruct s_{τ−Δ+1..τ} from x_τ.
        let truth = stacked_rows(
            batches.iter().map(|b| b.intermediate_states.as_slice()),
            &batches,
            &plain,
        )
        .reshape([runs, n, self.spec.delay, self.spec.obs_dim]);
        let losses = self.update_belief(t.augmented, truth, updates);
        stats.push(RECONSTRUCTION_STAT, losses);

        // 3. The cloning stage, on its schedule.
        let due = self.schedules[0]
            .last_env_steps
            .is_some_and(|last| env_steps / self.bc_every > last / self.bc_every);
        for schedule in &mut self.schedules {
            schedule.last_env_steps = Some(env_steps);
        }
        if due {
            let kls = self.clone_reference(contexts)?;
            let steps = Tensor::full([runs], kls.len() as f32, &plain);
            stats.push_mean(BC_STATS[0], kls);
            stats.push(BC_STATS[1], steps);
        }
        self.devices.settle();
        Ok(stats)
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.reference.save(dirs, "reference_")?;
        for (run, dir) in dirs.iter().enumerate() {
            let files = CheckpointDir::new(dir);
            files.save_slice("belief.bpk", &self.belief, run)?;
            files.save_slice("policy_head.bpk", &self.policy_head, run)?;
            files.save_optimizer_slice("belief_adam.bpk", &self.belief_opt, run)?;
            files.save_optimizer_slice("policy_head_adam.bpk", &self.policy_head_opt, run)?;
            files.save_json("vdpo.json", &self.schedules[run])?;
        }
        Ok(())
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.reference.load(dirs, "reference_")?;
        let files = CheckpointDir::each(dirs, "");
        self.belief = load_stack(&files, "belief.bpk", self.belief.clone())?;
        self.policy_head = load_stack(&files, "policy_head.bpk", self.policy_head.clone())?;
        self.belief_opt = load_optimizer_stack(&files, "belief_adam.bpk", self.belief_opt.clone())?;
        self.policy_head_opt =
            load_optimizer_stack(&files, "policy_head_adam.bpk", self.policy_head_opt.clone())?;
        self.schedules = load_json_stack(&files, "vdpo.json")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algos::random_batch;
    use crate::learn::{LearnDevice, assert_close as close, matrix};
    use burn::nn::transformer::TransformerEncoderInput;

    /// One run's `[1, rows, cols]`.
    fn run_rows(values: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<3> {
        matrix(values, rows, cols, device).unsqueeze_dim(0)
    }

    #[test]
    fn gaussian_kl_matches_hand_values() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        // Dimension 1: N(0, 1) against N(1, 2²): ln 2 + (1 + 1) / 8 − 1/2. Dimension 2: equal
        // Gaussians, 0. The loss averages the two.
        let kl = gaussian_kl(
            (
                run_rows(vec![0.0, 0.3], 1, 2, &device),
                run_rows(vec![0.0, -1.0], 1, 2, &device),
            ),
            (
                run_rows(vec![1.0, 0.3], 1, 2, &device),
                run_rows(vec![2.0f32.ln(), -1.0], 1, 2, &device),
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
        (Vdpo::new(&config, &spec, &devices, &[4]), spec)
    }

    /// Timing a few updates (`dhrl bench update`, `sweep plan`'s cost) brings the cloning
    /// stage within them with as many head steps per environment step as configured, and the
    /// agent built from it runs the stage there.
    #[test]
    fn a_schedule_within_a_few_updates_keeps_the_cloning_per_step() {
        let within = |bc_every, bc_updates, updates| {
            let config = Config {
                bc_every,
                bc_updates,
                ..Config::default()
            }
            .schedule_within(updates);
            (config.bc_every, config.bc_updates)
        };
        assert_eq!(within(1000, 1000, 5), (5, 5));
        assert_eq!(within(500, 2000, 10), (10, 40));
        assert_eq!(within(1000, 100, 3), (3, 1), "rounded, at least one");
        assert_eq!(within(4, 7, 10), (4, 7), "already within: unchanged");

        let (_, spec) = small_agent(1);
        let config = Config {
            belief_width: 8,
            belief_blocks: 1,
            belief_heads: 2,
            ..Config::default()
        }
        .schedule_within(3);
        let devices = Devices::new(LearnDevice::Cpu).unwrap();
        let mut agent = Vdpo::new(&config, &spec, &devices, &[4]);
        let batch = random_batch(&spec, 4, 2);
        // As the bench: an untimed update at step 0, then one update per environment step.
        let staged: Vec<bool> = (0..=3u64)
            .map(|k| {
                let stats = agent
                    .update(&mut UpdateContext::fixed(&batch, k, k))
                    .unwrap();
                stats.names().contains(&BC_STATS[1])
            })
            .collect();
        assert_eq!(staged, [false, false, false, true]);
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
            let input = run_rows(x, 2, spec.augmented_dim(), &agent.devices.plain);
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
            .features(
                run_rows(batch.augmented.clone(), n, spec.augmented_dim(), &plain),
                &spec,
                None,
            )
            .reshape([1, n * spec.delay, 8]);
        let targets = run_rows(
            batch.intermediate_states.clone(),
            n * spec.delay,
            spec.obs_dim,
            &plain,
        );
        let (head, reference) = (
            agent.policy_head.valid().distribution(features),
            agent.reference.actor.valid().distribution(targets),
        );
        let forward = f64::from(to_vec(gaussian_kl(head.clone(), reference.clone()))[0]);
        let backward = f64::from(to_vec(gaussian_kl(reference, head))[0]);
        let gap = (forward - backward).abs();
        assert!(gap > 1e-4 * forward.abs(), "{forward} {backward}");
        let kls = agent
            .clone_reference(&mut [UpdateContext::fixed(&batch, 0, 0)])
            .unwrap();
        assert_eq!(kls.len(), 1, "one step");
        let kl = f64::from(to_vec(kls[0].clone())[0]);
        assert!(
            (kl - forward).abs() < gap / 100.0,
            "{kl}: KL(head ‖ reference) {forward}, KL(reference ‖ head) {backward}"
        );
    }

    /// The written-out, stacked forward pass (attention included) is burn's
    /// `TransformerEncoder` in evaluation mode with the same weights: one encoder as a stack of
    /// one (S = 1), and each run of a stack of three encoders fed its own tokens.
    #[test]
    fn the_stacked_encoder_is_burns_encoder_in_evaluation_run_by_run() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        let (rows, tokens, width) = (3, 4, 8);
        let encoders: Vec<TransformerEncoder> = (0..3)
            .map(|seed| {
                device.seed(5 + seed);
                TransformerEncoderConfig::new(width, width, 2, 2)
                    .with_dropout(0.1)
                    .with_norm_first(true)
                    .init(&device)
            })
            .collect();
        let inputs: Vec<Tensor<3>> = (0..3)
            .map(|_| {
                Tensor::random(
                    [rows, tokens, width],
                    burn::tensor::Distribution::Default,
                    &device,
                )
            })
            .collect();
        let burns = |run: usize| {
            let causal = generate_autoregressive_mask(rows, tokens, &device);
            to_vec(
                encoders[run]
                    .forward(TransformerEncoderInput::new(inputs[run].clone()).mask_attn(causal)),
            )
        };
        let ours = |encoder: &Encoder, x: Tensor<3>| {
            let runs = x.dims()[0] / rows;
            let causal = generate_autoregressive_mask(runs * rows, tokens, &device);
            to_vec(encoder.forward(
                x.reshape([runs, rows * tokens, width]),
                tokens,
                causal,
                None,
            ))
        };
        close(
            &ours(&Encoder::from_burn(&encoders[0]), inputs[0].clone()),
            &burns(0),
        );
        let stacked = stack(encoders.iter().map(Encoder::from_burn).collect());
        let all = ours(&stacked, Tensor::cat(inputs.clone(), 0));
        let per_run = rows * tokens * width;
        for run in 0..3 {
            close(&all[run * per_run..(run + 1) * per_run], &burns(run));
        }
    }

    /// A mask keeps about 1 − p of the entries, scaled by 1/(1 − p), and repeats for a seed.
    #[test]
    fn dropout_masks_keep_one_minus_p_scaled_and_repeat_per_seed() {
        let device = Devices::new(LearnDevice::Cpu).unwrap().plain;
        let ones = Tensor::<2>::ones([100, 100], &device);
        let mask = |seed| {
            let mut masks = [DropoutMasks::new(seed, 0.1)];
            to_vec(DropoutMasks::apply_stacked(&mut masks, ones.clone()))
        };
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
        let predicted: Tensor<4> = matrix(vec![0.0, 0.0], 2, 1, &device).reshape([1, 1, 2, 1]);
        let truth: Tensor<4> = matrix(vec![1.0, 3.0], 2, 1, &device).reshape([1, 1, 2, 1]);
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
            let mut agent = Vdpo::new(&config, &spec, &devices, &[3]);
            let mut bursts = Vec::new();
            for (updates, env_steps) in (first..=33).step_by(stride as usize).enumerate() {
                let before = head(&agent);
                let stats = agent
                    .update(&mut UpdateContext::fixed(&batch, env_steps, updates as u64))
                    .unwrap()
                    .values()
                    .remove(0);
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
