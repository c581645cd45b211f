//! The acting network of a trained agent as plain numbers: what every algorithm hands over to
//! leave dhrl ([`crate::algos::Agent::acting_network`]), and what `dhrl export`'s ONNX and
//! safetensors writers read. Nothing here depends on burn, or on anything else of dhrl.

/// One affine layer `y = x·W + b`, with `W` `[input, output]` row-major (burn's layout;
/// PyTorch's `nn.Linear` stores `Wᵀ`).
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    pub input: usize,
    pub output: usize,
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

impl Dense {
    /// `W` transposed, `[output, input]` row-major: PyTorch's `nn.Linear.weight`.
    pub fn weight_output_major(&self) -> Vec<f32> {
        let mut transposed = vec![0.0; self.weight.len()];
        for i in 0..self.input {
            for o in 0..self.output {
                transposed[o * self.input + i] = self.weight[i * self.output + o];
            }
        }
        transposed
    }
}

/// A layer normalisation's scale and shift (ε = 1e-5, biased variance; burn's `gamma` and
/// `beta`, PyTorch's `weight` and `bias`).
#[derive(Debug, Clone, PartialEq)]
pub struct Norm {
    pub scale: Vec<f32>,
    pub shift: Vec<f32>,
}

/// The tanh-squashed Gaussian policy: ReLU hidden layers, then a mean head and a log-std head
/// (clamped to `[LOG_STD_MIN, LOG_STD_MAX]`); the deterministic action is
/// `scale·tanh(mean) + bias` within the task's bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianPolicyWeights {
    pub hidden: Vec<Dense>,
    pub mean: Dense,
    pub log_std: Dense,
}

/// What of `x_t = (s_{t−Δ}, a_{t−Δ}, …, a_{t−1})` a policy reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PolicyInput {
    /// Only the observation `s_{t−Δ}`, the first `obs_dim` entries (delay-free and naive SAC).
    LastObservation,
    /// All of `x_t`.
    AugmentedState,
}

/// Delayed SAC's forward model: rolled once per pending action, oldest first, from `s_{t−Δ}`
/// to an estimate of `s_t` that the policy acts on.
#[derive(Debug, Clone, PartialEq)]
pub struct RolloutModel {
    /// ReLU between the layers, the last linear; input `(state, action)`, output a state or
    /// its change.
    pub layers: Vec<Dense>,
    /// Per-input `(mean, std)` the input is standardised with at every step, if any.
    pub input_moments: Option<(Vec<f32>, Vec<f32>)>,
    /// Whether the output is the change of the state (else the next state itself).
    pub predicts_difference: bool,
}

/// One pre-LN block of VDPO's causal belief transformer.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformerBlock {
    /// Before the attention.
    pub attention_norm: Norm,
    pub query: Dense,
    pub key: Dense,
    pub value: Dense,
    pub attention_output: Dense,
    /// Before the feed-forward layers.
    pub feed_forward_norm: Norm,
    /// GELU (exact, erf) between the two.
    pub feed_forward_inner: Dense,
    pub feed_forward_outer: Dense,
}

/// VDPO's belief: one token per pending action, oldest first,
/// `token_i = token([state_embedding(s_{t−Δ}), action_embedding(a_{t−Δ+i})]) + position_i`,
/// normalised, through causal pre-LN blocks, normalised again; the policy reads the last token.
#[derive(Debug, Clone, PartialEq)]
pub struct BeliefTransformer {
    pub state_embedding: Dense,
    pub action_embedding: Dense,
    pub token: Dense,
    /// `[Δ, width]` row-major.
    pub position: Vec<f32>,
    pub input_norm: Norm,
    pub blocks: Vec<TransformerBlock>,
    pub output_norm: Norm,
    pub heads: usize,
    /// The value causal attention gives the scores of later tokens before the softmax.
    pub mask_fill: f32,
}

impl BeliefTransformer {
    pub fn width(&self) -> usize {
        self.token.output
    }
}

/// Everything an agent computes to act deterministically on `x_t`.
#[derive(Debug, Clone, PartialEq)]
pub enum ActingNetwork {
    /// The policy on `s_{t−Δ}` or on `x_t`.
    Policy {
        input: PolicyInput,
        policy: GaussianPolicyWeights,
    },
    /// Delayed SAC: the forward model rolled over the Δ pending actions, then the policy on
    /// the estimated state.
    ModelRollout {
        model: RolloutModel,
        policy: GaussianPolicyWeights,
    },
    /// VDPO: the belief transformer, then the policy on its last token.
    Belief {
        belief: BeliefTransformer,
        policy: GaussianPolicyWeights,
    },
}

impl ActingNetwork {
    /// The policy at the end of the computation.
    pub fn policy(&self) -> &GaussianPolicyWeights {
        match self {
            ActingNetwork::Policy { policy, .. }
            | ActingNetwork::ModelRollout { policy, .. }
            | ActingNetwork::Belief { policy, .. } => policy,
        }
    }

    /// A short name of the computation's kind (the manifest's `network.kind`).
    pub fn kind(&self) -> &'static str {
        match self {
            ActingNetwork::Policy {
                input: PolicyInput::LastObservation,
                ..
            } => "gaussian-policy-on-last-observation",
            ActingNetwork::Policy {
                input: PolicyInput::AugmentedState,
                ..
            } => "gaussian-policy-on-augmented-state",
            ActingNetwork::ModelRollout { .. } => "forward-model-rollout-then-gaussian-policy",
            ActingNetwork::Belief { .. } => "belief-transformer-then-gaussian-policy",
        }
    }
}
