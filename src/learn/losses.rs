//! The SAC losses as the papers write them, each a small function of tensors. Equation
//! numbers refer to Haarnoja et al., "Soft Actor-Critic Algorithms and Applications" (2018).
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::prelude::*;
use burn::tensor::activation::softplus;

/// `ln √(2π)`.
const HALF_LN_TWO_PI: f64 = 0.918_938_533_204_672_7;

/// Log-density of `a = scale·tanh(u)`, `u = μ + σ·ε ~ N(μ, σ²)` (Eq. 26 of Haarnoja et al.):
/// `Σ_j [log N(u_j; μ_j, σ_j) − log(1 − tanh²(u_j))] − Σ_j ln scale_j`, with the stable form
/// `log(1 − tanh² u) = 2(ln 2 − u − softplus(−2u))`. Inputs `[…, A]` (a stack's `[S, B, A]`),
/// the result `[…, 1]`.
pub fn squashed_gaussian_log_prob<const D: usize>(
    u: Tensor<D>,
    eps: Tensor<D>,
    log_std: Tensor<D>,
    log_scale_sum: f64,
) -> Tensor<D> {
    let gaussian = eps.square().mul_scalar(-0.5) - log_std - HALF_LN_TWO_PI;
    let log_det_tanh = (u.clone().neg() - softplus(u.mul_scalar(-2.0), 1.0))
        .add_scalar(std::f64::consts::LN_2)
        .mul_scalar(2.0);
    (gaussian - log_det_tanh)
        .sum_dim(D - 1)
        .sub_scalar(log_scale_sum)
}

/// The soft Bellman target (Eq. 3, with the twin-critic minimum):
/// `y = r + γ·(1 − done)·(min_j Q̄_j(s', a') − α·log π(a'|s'))`, `[S, B, 1]`, with each run's
/// `α` (`[S, 1, 1]`).
pub fn critic_target(
    reward: Tensor<3>,
    done: Tensor<3>,
    next_q_min: Tensor<3>,
    next_log_prob: Tensor<3>,
    alpha: Tensor<3>,
    gamma: f64,
) -> Tensor<3> {
    let soft_value = next_q_min - next_log_prob * alpha;
    reward + done.neg().add_scalar(1.0) * soft_value.mul_scalar(gamma)
}

/// Each run's mean over its batch: `[S, B, 1]` → `[S]`. Reduced along the last axis of
/// `[S, B]`, which burn's CPU backend sums with the kernel of a whole-tensor `mean`: a run's
/// mean is the solo `[B, 1]` mean to the last bit (a middle-axis reduction rounds otherwise).
pub fn batch_mean(x: Tensor<3>) -> Tensor<1> {
    let [runs, rows, _] = x.dims();
    x.reshape([runs, rows]).mean_dim(1).reshape([runs])
}

/// `J_Q = E[(Q_1(s, a) − y)²] + E[(Q_2(s, a) − y)²]` (Eq. 5, both critics), per run `[S]`.
pub fn critic_loss(q1: Tensor<3>, q2: Tensor<3>, target: Tensor<3>) -> Tensor<1> {
    batch_mean((q1 - target.clone()).square()) + batch_mean((q2 - target).square())
}

/// `J_π = E[α·log π(a|s) − min_j Q_j(s, a)]`, `a ~ π(·|s)` (Eq. 7), per run `[S]`.
pub fn actor_loss(log_prob: Tensor<3>, q_min: Tensor<3>, alpha: Tensor<3>) -> Tensor<1> {
    batch_mean(log_prob * alpha - q_min)
}

/// `J(α) = E[−α·(log π(a|s) + H̄)]` with `α = exp(log α)` and the log-probabilities held
/// fixed (Eq. 18), per run `[S]`: `log_alpha` `[S, 1]`, `mean_log_prob` each run's batch mean
/// `[S]`.
pub fn temperature_loss(
    log_alpha: Tensor<2>,
    mean_log_prob: Tensor<1>,
    target_entropy: f64,
) -> Tensor<1> {
    let coefficients = mean_log_prob.inner().add_scalar(target_entropy).neg();
    (log_alpha.exp() * coefficients.unsqueeze_dim(1)).reshape([-1])
}

/// Polyak averaging `θ̄ ← τ·θ + (1 − τ)·θ̄` of every parameter of `target` toward `online`.
/// `target` lives on the plain device, so the result never enters an autodiff graph.
pub fn polyak<M: Module>(target: M, online: &M, tau: f64) -> M {
    struct Collect(Vec<Tensor<1>>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.push(param.val().inner().reshape([-1]));
        }
    }
    struct Blend {
        online: std::vec::IntoIter<Tensor<1>>,
        tau: f64,
    }
    impl ModuleMapper for Blend {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let online = self
                .online
                .next()
                .expect("target and online networks have the same parameters");
            let tau = self.tau;
            param.map(|theta_bar| {
                let theta: Tensor<D> = online.reshape(theta_bar.shape());
                theta_bar.mul_scalar(1.0 - tau) + theta.mul_scalar(tau)
            })
        }
    }
    let mut online_params = Collect(Vec::new());
    online.visit(&mut online_params);
    target.map(&mut Blend {
        online: online_params.0.into_iter(),
        tau,
    })
}

/// The lifting loss (Eq. 4 of the DHRL paper): the squared distance between the per-dimension
/// mean and standard deviation of the regular policy's squashed actions at `x` and those of
/// the abstract (here: delay-free) policy at `s`, `‖E[a↑] − E[ā]‖² + ‖σ[a↑] − σ[ā]‖²`, averaged
/// over each run's batch, per run `[S]`. Both sides are `[K, S, B, A]`: K samples per state,
/// standard deviations with the N − 1 correction. `abstract_actions` is a constant (plain
/// tensor): the gradient flows into the regular policy only.
pub fn lifting_loss(regular_actions: Tensor<4>, abstract_actions: Tensor<4>) -> Tensor<1> {
    let (mean_r, std_r) = action_moments(regular_actions);
    let (mean_a, std_a) = action_moments(abstract_actions);
    let per_state = ((mean_r - mean_a).square() + (std_r - std_a).square()).sum_dim(3);
    batch_mean(per_state.squeeze_dim(0))
}

/// Per-state mean and standard deviation (N − 1) over the K samples of `[K, S, B, A]`
/// actions, each `[1, S, B, A]`.
fn action_moments(actions: Tensor<4>) -> (Tensor<4>, Tensor<4>) {
    let k = actions.dims()[0];
    let mean = actions.clone().mean_dim(0);
    let variance = (actions - mean.clone())
        .square()
        .sum_dim(0)
        .div_scalar((k.max(2) - 1) as f64);
    // The small floor keeps the square root differentiable where all samples coincide.
    (mean, variance.add_scalar(1e-12).sqrt())
}
