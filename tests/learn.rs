//! The SAC pieces against values computed by hand on tiny inputs.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use burn::module::{ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;
use common::parameters;
use dhrl::learn::{
    Devices, LearnDevice, MlpConfig, QNetwork, Temperature, TwinQ, actor_loss, critic_loss,
    critic_target, matrix, polyak, squashed_gaussian_log_prob, stack, temperature_loss, to_vec,
};

fn devices() -> Devices {
    Devices::new(LearnDevice::Cpu).unwrap()
}

fn close(a: f32, b: f64, tol: f64) {
    assert!(
        (f64::from(a) - b).abs() <= tol * b.abs().max(1.0),
        "{a} vs {b}"
    );
}

/// log N(u; μ, σ) − log(1 − tanh²u) − ln scale, written the naive way.
fn naive_log_prob(eps: f64, log_std: f64, u: f64, scale: f64) -> f64 {
    let gaussian = -0.5 * eps * eps - log_std - 0.5 * (2.0 * std::f64::consts::PI).ln();
    gaussian - (1.0 - u.tanh().powi(2)).ln() - scale.ln()
}

#[test]
fn squashed_gaussian_log_prob_matches_the_formula() {
    let d = devices();
    // Two rows, two action dimensions; action scale 3 on both (InvertedPendulum-like bounds).
    let (eps, log_std, mean) = (
        [0.5, -1.2, 0.0, 2.0],
        [0.0, -0.5, 0.3, -1.0],
        [0.1, 0.4, -0.7, 0.0],
    );
    let u: Vec<f32> = (0..4)
        .map(|i| (mean[i] + (log_std[i] as f64).exp() * eps[i]) as f32)
        .collect();
    let log_prob = squashed_gaussian_log_prob(
        matrix(u.clone(), 2, 2, &d.plain),
        matrix(eps.map(|v| v as f32).to_vec(), 2, 2, &d.plain),
        matrix(log_std.map(|v| v as f32).to_vec(), 2, 2, &d.plain),
        2.0 * 3.0f64.ln(),
    );
    let got = to_vec(log_prob);
    for row in 0..2 {
        let want: f64 = (0..2)
            .map(|j| {
                naive_log_prob(
                    eps[2 * row + j],
                    log_std[2 * row + j],
                    f64::from(u[2 * row + j]),
                    3.0,
                )
            })
            .sum();
        close(got[row], want, 1e-5);
    }
}

#[test]
fn squashed_gaussian_log_prob_is_stable_where_tanh_saturates() {
    let d = devices();
    // u = 20: 1 − tanh²u underflows in f32, the stable form gives 2(ln 2 − 20 − softplus(−40)).
    let got = to_vec(squashed_gaussian_log_prob(
        matrix(vec![20.0], 1, 1, &d.plain),
        matrix(vec![0.0], 1, 1, &d.plain),
        matrix(vec![0.0], 1, 1, &d.plain),
        0.0,
    ));
    let want = -0.5 * (2.0 * std::f64::consts::PI).ln() - 2.0 * (std::f64::consts::LN_2 - 20.0);
    assert!(got[0].is_finite());
    close(got[0], want, 1e-5);
}

/// `[runs, len / runs, 1]`: one column per run of a stack.
fn columns(values: Vec<f32>, runs: usize, d: &Devices) -> Tensor<3> {
    let rows = values.len() / runs;
    Tensor::from_data(TensorData::new(values, [runs, rows, 1]), &d.plain)
}

/// `α` per run, `[runs, 1, 1]`.
fn alphas(values: Vec<f32>, d: &Devices) -> Tensor<3> {
    let runs = values.len();
    Tensor::from_data(TensorData::new(values, [runs, 1, 1]), &d.plain)
}

#[test]
fn critic_target_bootstraps_unless_terminated_with_each_runs_alpha() {
    let d = devices();
    // Two runs of two rows: run 0 with α = 0.2, run 1 with α = 0.5.
    let y = critic_target(
        columns(vec![1.0, 2.0, 1.0, 2.0], 2, &d),
        columns(vec![0.0, 1.0, 0.0, 1.0], 2, &d),
        columns(vec![10.0, 10.0, 10.0, 10.0], 2, &d),
        columns(vec![-1.0, -1.0, -1.0, -1.0], 2, &d),
        alphas(vec![0.2, 0.5], &d),
        0.99,
    );
    let y = to_vec(y);
    close(y[0], 1.0 + 0.99 * (10.0 + 0.2), 1e-6); // 11.098
    close(y[1], 2.0, 1e-6); // terminal: reward only
    close(y[2], 1.0 + 0.99 * (10.0 + 0.5), 1e-6);
    close(y[3], 2.0, 1e-6);
}

#[test]
fn critic_and_actor_losses_match_hand_values_per_run() {
    let d = devices();
    // Run 0: mean((0, 1)²) + mean((−1, −1)²) = 0.5 + 1; run 1: mean((1, 1)²) + mean((0, 2)²) = 1 + 2.
    let q1 = columns(vec![1.0, 2.0, 2.0, 2.0], 2, &d);
    let q2 = columns(vec![0.0, 0.0, 1.0, 3.0], 2, &d);
    let y = columns(vec![1.0, 1.0, 1.0, 1.0], 2, &d);
    let critic = to_vec(critic_loss(q1, q2, y));
    assert_eq!(critic.len(), 2);
    close(critic[0], 1.5, 1e-6);
    close(critic[1], 3.0, 1e-6);
    // Run 0, α = 0.5: mean(0.5·(−1) − 2, 0.5·1 − 4) = −3; run 1, α = 1: mean(−1 − 0, 1 − 2) = −1.
    let loss = actor_loss(
        columns(vec![-1.0, 1.0, -1.0, 1.0], 2, &d),
        columns(vec![2.0, 4.0, 0.0, 2.0], 2, &d),
        alphas(vec![0.5, 1.0], &d),
    );
    let actor = to_vec(loss);
    close(actor[0], -3.0, 1e-6);
    close(actor[1], -1.0, 1e-6);
}

#[test]
fn temperature_loss_and_its_gradient_match_hand_values_per_run() {
    let d = devices();
    let temperature = stack(vec![
        Temperature::new(0.2, &d.train),
        Temperature::new(0.5, &d.train),
    ]);
    // J(α) = −α(mean log π + H̄): run 0 −0.2·(−2 − 1) = 0.6, run 1 −0.5·(0.5 − 1) = 0.25; each
    // run's gradient dJ/d log α is its own J (the losses are summed over the stack).
    let mean_log_prob = matrix(vec![-2.0, 0.5], 1, 2, &d.plain).reshape([-1]);
    let loss = temperature_loss(temperature.log_alpha.val(), mean_log_prob, -1.0);
    let values = to_vec(loss.clone().inner());
    close(values[0], 0.6, 1e-6);
    close(values[1], 0.25, 1e-6);
    let mut grads = loss.sum().backward();
    let grads = GradientsParams::from_module(&mut grads, &temperature);
    let grad: Tensor<2> = grads
        .get(temperature.log_alpha.id)
        .expect("log α has a gradient");
    let grad = to_vec(grad);
    close(grad[0], 0.6, 1e-5);
    close(grad[1], 0.25, 1e-5);
}

#[test]
fn polyak_moves_the_target_by_tau() {
    let d = devices();
    let online = QNetwork::new(3, 2, &d.train);
    let target = QNetwork::new(3, 2, &d.train).valid();
    let (before, theta) = (parameters(&target), parameters(&online));
    let after = parameters(&polyak(target, &online, 0.005));
    assert_eq!(after.len(), theta.len());
    for ((a, b), t) in after.iter().zip(&before).zip(&theta) {
        close(*a, 0.995 * f64::from(*b) + 0.005 * f64::from(*t), 1e-6);
    }
}

#[test]
fn target_networks_receive_no_gradient() {
    let d = devices();
    let critic = TwinQ::new(3, 1, &d.train);
    let target = critic.valid();
    let input = matrix(vec![0.1, 0.2, 0.3, -0.1, 0.0, 0.5], 2, 3, &d.plain).unsqueeze_dim(0);
    let action = matrix(vec![0.3, -0.3], 2, 1, &d.plain).unsqueeze_dim(0);
    let y = target.min(input.clone(), action.clone());
    assert!(!y.is_tracked(), "the target's output is a constant");
    let loss = critic_loss(
        critic.q1.forward(input.clone(), action.clone()),
        critic.q2.forward(input, action),
        y,
    );
    let mut grads = loss.sum().backward();
    assert!(
        GradientsParams::from_module(&mut grads, &target).is_empty(),
        "no gradient reaches the target critics"
    );
    assert!(
        !GradientsParams::from_module(&mut grads, &critic).is_empty(),
        "the online critics do get gradients"
    );
    let moved = polyak(target, &critic, 0.5);
    assert!(parameters(&moved).iter().all(|v| v.is_finite()));
    let mut untracked = true;
    struct Check<'a>(&'a mut bool);
    impl ModuleVisitor for Check<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            *self.0 &= !param.val().is_autodiff();
        }
    }
    moved.visit(&mut Check(&mut untracked));
    assert!(
        untracked,
        "Polyak averaging keeps the targets off the autodiff graph"
    );
}

/// `MlpConfig::new(3, &[4], 2)`: `relu(x·W1 + b1)·W2 + b2`, by hand from its own weights.
#[test]
fn mlp_is_linear_layers_with_relu_between() {
    let d = devices();
    let mlp = MlpConfig::new(3, &[4], 2).init(&d.plain);
    assert_eq!(mlp.layers.len(), 2);
    let weights = |k: usize| to_vec(mlp.layers[k].weight.val());
    let bias = |k: usize| to_vec(mlp.layers[k].bias.val());
    let (w1, b1, w2, b2) = (weights(0), bias(0), weights(1), bias(1));
    assert_eq!((w1.len(), b1.len(), w2.len(), b2.len()), (12, 4, 8, 2));
    let x = [0.5f32, -1.0, 2.0, -0.3, 0.8, 0.1];
    let y = to_vec(mlp.forward(matrix(x.to_vec(), 2, 3, &d.plain).unsqueeze_dim(0)));
    for row in 0..2 {
        let h: Vec<f64> = (0..4)
            .map(|j| {
                let z = f64::from(b1[j])
                    + (0..3)
                        .map(|i| f64::from(x[row * 3 + i]) * f64::from(w1[i * 4 + j]))
                        .sum::<f64>();
                z.max(0.0)
            })
            .collect();
        for k in 0..2 {
            let out =
                f64::from(b2[k]) + (0..4).map(|j| h[j] * f64::from(w2[j * 2 + k])).sum::<f64>();
            close(y[row * 2 + k], out, 1e-5);
        }
    }
}
