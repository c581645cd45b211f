//! Networks: 256-256 ReLU MLPs, a tanh-squashed Gaussian policy, twin Q-networks and the
//! learned temperature.
use burn::module::Param;
use burn::prelude::*;
use burn::tensor::activation::sigmoid;

use super::losses::squashed_gaussian_log_prob;
use super::stack::StackedLinear;
use super::tensors::{matrix, to_vec};
use crate::acting::{Dense, GaussianPolicyWeights};

/// Hidden width of every network (docs/DESIGN.md §3.3).
pub const HIDDEN: usize = 256;
/// Bounds of the policy's log standard deviation.
pub const LOG_STD_MIN: f64 = -20.0;
pub const LOG_STD_MAX: f64 = 2.0;

/// Two hidden ReLU layers.
#[derive(Module, Debug)]
struct Trunk {
    l1: StackedLinear,
    l2: StackedLinear,
}

impl Trunk {
    fn new(input: usize, device: &Device) -> Trunk {
        Trunk {
            l1: StackedLinear::new(input, HIDDEN, device),
            l2: StackedLinear::new(HIDDEN, HIDDEN, device),
        }
    }

    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        self.l2.forward_relu(self.l1.forward_relu(x))
    }
}

/// `Q(input, a)`.
#[derive(Module, Debug)]
pub struct QNetwork {
    trunk: Trunk,
    out: StackedLinear,
}

impl QNetwork {
    /// One run's critic (stack them with [`super::stack`]).
    pub fn new(input: usize, act_dim: usize, device: &Device) -> QNetwork {
        QNetwork {
            trunk: Trunk::new(input + act_dim, device),
            out: StackedLinear::new(HIDDEN, 1, device),
        }
    }

    /// `[S, B, 1]` from `[S, B, ·]` inputs and actions.
    pub fn forward(&self, input: Tensor<3>, action: Tensor<3>) -> Tensor<3> {
        self.out
            .forward(self.trunk.forward(Tensor::cat(vec![input, action], 2)))
    }
}

/// Twin critics; the learners use the minimum of the two.
#[derive(Module, Debug)]
pub struct TwinQ {
    pub q1: QNetwork,
    pub q2: QNetwork,
}

impl TwinQ {
    /// Two independently initialised critics of one run.
    pub fn new(input: usize, act_dim: usize, device: &Device) -> TwinQ {
        TwinQ {
            q1: QNetwork::new(input, act_dim, device),
            q2: QNetwork::new(input, act_dim, device),
        }
    }

    /// `min(Q1, Q2)`, `[S, B, 1]`.
    pub fn min(&self, input: Tensor<3>, action: Tensor<3>) -> Tensor<3> {
        self.q1
            .forward(input.clone(), action.clone())
            .min_pair(self.q2.forward(input, action))
    }
}

/// The affine map from `tanh(u) ∈ (-1, 1)` to the action bounds.
#[derive(Debug, Clone)]
pub struct ActionScale {
    /// `(high − low) / 2`, `[1, A]` on the plain device.
    pub scale: Tensor<2>,
    /// `(high + low) / 2`, `[1, A]`.
    pub bias: Tensor<2>,
    /// `Σ_j ln scale_j`: the log-determinant of the affine map.
    pub log_scale_sum: f64,
}

impl ActionScale {
    pub fn new(low: &[f64], high: &[f64], device: &Device) -> ActionScale {
        let scale: Vec<f32> = low
            .iter()
            .zip(high)
            .map(|(l, h)| ((h - l) / 2.0) as f32)
            .collect();
        let bias: Vec<f32> = low
            .iter()
            .zip(high)
            .map(|(l, h)| ((h + l) / 2.0) as f32)
            .collect();
        let log_scale_sum = scale.iter().map(|s| f64::from(*s).ln()).sum();
        let a = scale.len();
        ActionScale {
            scale: matrix(scale, 1, a, device),
            bias: matrix(bias, 1, a, device),
            log_scale_sum,
        }
    }
}

/// An action drawn from the policy with its log-density.
pub struct PolicySample {
    /// `[S, B, A]`, within the action bounds.
    pub action: Tensor<3>,
    /// `[S, B, 1]`
    pub log_prob: Tensor<3>,
}

/// The tanh-squashed Gaussian policy `π(a|input)`.
#[derive(Module, Debug)]
pub struct GaussianPolicy {
    trunk: Trunk,
    mean: StackedLinear,
    log_std: StackedLinear,
}

impl GaussianPolicy {
    /// One run's policy (stack them with [`super::stack`]).
    pub fn new(input: usize, act_dim: usize, device: &Device) -> GaussianPolicy {
        GaussianPolicy {
            trunk: Trunk::new(input, device),
            mean: StackedLinear::new(HIDDEN, act_dim, device),
            log_std: StackedLinear::new(HIDDEN, act_dim, device),
        }
    }

    /// Mean and clamped log standard deviation of the Gaussian before squashing, `[S, B, A]`.
    pub fn distribution(&self, input: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
        let h = self.trunk.forward(input);
        (
            self.mean.forward(h.clone()),
            self.log_std.forward(h).clamp(LOG_STD_MIN, LOG_STD_MAX),
        )
    }

    /// `a = scale·tanh(μ + σ·ε) + bias` with its log-density, reparameterised through `ε`.
    pub fn sample(&self, input: Tensor<3>, eps: Tensor<3>, scale: &ActionScale) -> PolicySample {
        squashed_sample(self.distribution(input), eps, scale)
    }

    /// The deterministic action `scale·tanh(μ) + bias` (evaluation), `[S, B, A]`.
    pub fn mode(&self, input: Tensor<3>, scale: &ActionScale) -> Tensor<3> {
        let (mean, _) = self.distribution(input);
        mean.tanh() * scale.scale.clone().unsqueeze_dim(0) + scale.bias.clone().unsqueeze_dim(0)
    }

    /// Slice `slice`'s weights as plain numbers (for export).
    pub fn weights(&self, slice: usize) -> GaussianPolicyWeights {
        GaussianPolicyWeights {
            hidden: vec![self.trunk.l1.dense(slice), self.trunk.l2.dense(slice)],
            mean: self.mean.dense(slice),
            log_std: self.log_std.dense(slice),
        }
    }
}

/// [`GaussianPolicy::sample`] from a distribution already computed (so that two losses on
/// the same states share one trunk pass).
pub fn squashed_sample(
    (mean, log_std): (Tensor<3>, Tensor<3>),
    eps: Tensor<3>,
    scale: &ActionScale,
) -> PolicySample {
    let u = mean + log_std.clone().exp() * eps.clone();
    let log_prob = squashed_gaussian_log_prob(u.clone(), eps, log_std, scale.log_scale_sum);
    PolicySample {
        action: u.tanh() * scale.scale.clone().unsqueeze_dim(0)
            + scale.bias.clone().unsqueeze_dim(0),
        log_prob,
    }
}

/// `K` squashed actions per row from a distribution already computed (each run's `[B, A]`
/// mean and log-std, `[S, B, A]`), `[K, S, B, A]`, from `eps` `[K, S, B, A]`. The K samples
/// lead, so that broadcasting `μ`, `σ` over them and reducing over them walk contiguous
/// `[S, B, A]` blocks.
pub fn squashed_samples_k(
    (mean, log_std): (Tensor<3>, Tensor<3>),
    eps: Tensor<4>,
    scale: &ActionScale,
) -> Tensor<4> {
    let (mean, std): (Tensor<4>, Tensor<4>) =
        (mean.unsqueeze_dim(0), log_std.exp().unsqueeze_dim(0));
    let u = mean + std * eps;
    // tanh(u) = 2·σ(2u) − 1, evaluated through the logistic: on B·K·A entries, Flex's tanh
    // (libm's scalar tanhf, called again by its backward) costs about three logistics.
    let squashed = sigmoid(u.mul_scalar(2.0)).mul_scalar(2.0).sub_scalar(1.0);
    squashed * scale.scale.clone().unsqueeze() + scale.bias.clone().unsqueeze()
}

/// The entropy temperature `α = exp(log α)`, one per run of a stack: `log α` is `[S, 1]`.
#[derive(Module, Debug)]
pub struct Temperature {
    pub log_alpha: Param<Tensor<2>>,
}

impl Temperature {
    /// One run's temperature.
    pub fn new(initial_alpha: f64, device: &Device) -> Temperature {
        Temperature {
            log_alpha: Param::from_data([[initial_alpha.ln() as f32]], device),
        }
    }

    /// `α` per run, `[S, 1, 1]`, off the graph.
    pub fn alpha_tensor(&self) -> Tensor<3> {
        self.log_alpha.val().inner().exp().unsqueeze_dim(2)
    }

    /// The current α of each run, `[S]`, off the graph.
    pub fn alpha_values(&self) -> Tensor<1> {
        self.log_alpha.val().inner().exp().reshape([-1])
    }

    /// The current α of each run, downloaded.
    pub fn alphas(&self) -> Vec<f64> {
        to_vec(self.alpha_values())
            .into_iter()
            .map(f64::from)
            .collect()
    }
}

/// A multilayer perceptron: `Linear` layers of the given widths with ReLU between them and a
/// linear output, for networks an algorithm needs beyond the SAC family's (e.g. a dynamics
/// model). `MlpConfig::new(obs + act, &[256, 256], obs).init(device)`.
#[derive(Debug, Clone)]
pub struct MlpConfig {
    pub input: usize,
    pub hidden: Vec<usize>,
    pub output: usize,
}

impl MlpConfig {
    pub fn new(input: usize, hidden: &[usize], output: usize) -> MlpConfig {
        MlpConfig {
            input,
            hidden: hidden.to_vec(),
            output,
        }
    }

    /// One run's network, its layers drawn in order from burn's generator on `device` (each as
    /// burn's `LinearConfig` draws it); [`super::stack`] several for a stack.
    pub fn init(&self, device: &Device) -> Mlp {
        let widths: Vec<usize> = std::iter::once(self.input)
            .chain(self.hidden.iter().copied())
            .chain(std::iter::once(self.output))
            .collect();
        Mlp {
            layers: widths
                .windows(2)
                .map(|w| StackedLinear::new(w[0], w[1], device))
                .collect(),
        }
    }
}

/// See [`MlpConfig`]; stacked, inputs `[S, B, input]`.
#[derive(Module, Debug)]
pub struct Mlp {
    pub layers: Vec<StackedLinear>,
}

impl Mlp {
    /// Slice `slice`'s layers as plain numbers (for export).
    pub fn weights(&self, slice: usize) -> Vec<Dense> {
        self.layers.iter().map(|layer| layer.dense(slice)).collect()
    }

    /// `[S, B, input]` → `[S, B, output]`.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let last = self.layers.len() - 1;
        self.layers.iter().enumerate().fold(x, |x, (i, layer)| {
            if i < last {
                layer.forward_relu(x)
            } else {
                layer.forward(x)
            }
        })
    }
}
