//! Principled D2HPG (`src/algos/d2hpg_principled.rs`): W₂, L_lax, L_h and L_lift through the
//! action map by hand; which losses move which parameters; learning a small delayed task.
// Needs the `dhrl` program (tests/common): the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use std::sync::Mutex;

use burn::module::Param;
use burn::prelude::*;
use common::{parameters, small_spec as spec, update};
use dhrl::algos::{
    AbstractReward, ActMode, ActionMap, Agent, AlgoSettings, Bpql, D2hpgPrincipled,
    D2hpgPrincipledConfig, Distance, Homomorphism, LaxMetric, LiftingConfig, MetricReduction,
    Reduction, RegularCritic, SacConfig, TransitionLoss, TransitionStd, abstract_model_loss,
    gaussian_w2, lax_loss, random_batch,
};
use dhrl::learn::{
    Devices, LearnDevice, Mlp, Noise, StackedLinear, TransitionTensors, lifting_loss, matrix,
    to_vec,
};
use dhrl::protocol::Protocol;

/// burn's generator is process-wide: networks built by concurrent tests would interleave draws.
static BUILD: Mutex<()> = Mutex::new(());

fn devices() -> Devices {
    Devices::new(LearnDevice::Cpu).unwrap()
}

fn close(found: f32, expected: f64, what: &str) {
    assert!(
        (f64::from(found) - expected).abs() < 1e-5 * expected.abs().max(1.0),
        "{what}: {found}, by hand {expected}"
    );
}

/// One run's `[1, rows, ·]`.
fn m(values: &[f32], rows: usize, device: &Device) -> Tensor<3> {
    matrix(values.to_vec(), rows, values.len() / rows, device).unsqueeze_dim(0)
}

#[test]
fn w2_of_diagonal_gaussians_matches_hand_values() {
    let d = devices().plain;
    // Row 0: N((0, 0), diag(1, 1)) against N((3, 0), diag(1, 25)): Δμ = (3, 0), Δσ = (0, 4).
    //   Closed form √(9 + 0 + 0 + 16) = 5; per dimension (√9 + √16)/2 = 3.5.
    // Row 1: the same Gaussian twice: 0 (to the floor's √1e-12 = 1e-6).
    let gi = (
        m(&[0.0, 0.0, 1.0, 2.0], 2, &d),
        m(&[1.0, 1.0, 0.5, 0.5], 2, &d),
    );
    let gj = (
        m(&[3.0, 0.0, 1.0, 2.0], 2, &d),
        m(&[1.0, 5.0, 0.5, 0.5], 2, &d),
    );
    let sum = to_vec(gaussian_w2(gi.clone(), gj.clone(), MetricReduction::Sum));
    close(sum[0], 5.0, "W₂, closed form");
    close(sum[1], 0.0, "W₂ of a Gaussian with itself");
    let mean = to_vec(gaussian_w2(gi, gj, MetricReduction::Mean));
    close(mean[0], 3.5, "W₂, per-dimension mean");
    close(mean[1], 0.0, "per-dimension W₂ of a Gaussian with itself");
}

fn metric(reduction: MetricReduction, distance: Distance, stop: bool) -> LaxMetric {
    LaxMetric {
        reduction,
        distance,
        stop_transition_gradient: stop,
    }
}

/// A two-sample batch, shift 1: the pairs (0, 1) and (1, 0), which give the same term.
/// x̄_0 = (0, 0), x̄_1 = (1, −2); r̃ = (1, 0.5); P̄_0 = N((0, 0), diag(1, 1)),
/// P̄_1 = N((3, 0), diag(1, 25)); γ = 0.9.
fn two_pairs(device: &Device) -> (Tensor<3>, Tensor<3>, (Tensor<3>, Tensor<3>)) {
    (
        m(&[0.0, 0.0, 1.0, -2.0], 2, device),
        m(&[1.0, 0.5], 2, device),
        (
            m(&[0.0, 0.0, 3.0, 0.0], 2, device),
            m(&[1.0, 1.0, 1.0, 5.0], 2, device),
        ),
    )
}

#[test]
fn lax_loss_matches_hand_values_on_two_pairs() {
    let d = devices().plain;
    let (states, rewards, transition) = two_pairs(&d);
    let loss = |metric: LaxMetric| {
        to_vec(lax_loss(
            states.clone(),
            rewards.clone(),
            transition.clone(),
            &[1],
            0.9,
            &metric,
        ))[0]
    };
    // Eq. 2: d_x̄ = |0 − 1| + |0 + 2| = 3; d_r = 0.5; W₂ = 5: (3 − (0.5 + 0.9·5))² = 4.
    close(
        loss(metric(MetricReduction::Sum, Distance::L1, false)),
        4.0,
        "L_lax, sum, L1",
    );
    // Holding the transition fixed changes the gradient, not the value.
    close(
        loss(metric(MetricReduction::Sum, Distance::L1, true)),
        4.0,
        "L_lax, sum, L1, transition held fixed",
    );
    // Per-dimension means: d_x̄ = 1.5, d_r = 0.5, W₂ = 3.5: (1.5 − (0.5 + 3.15))² = 4.6225.
    close(
        loss(metric(MetricReduction::Mean, Distance::L1, false)),
        4.6225,
        "L_lax, mean, L1",
    );
    // Huber: gaps 1 and 2 give 0.5 and 1.5 (sum 2); the reward gap 0.5 gives 0.125:
    // (2 − (0.125 + 4.5))² = 6.890625.
    close(
        loss(metric(MetricReduction::Sum, Distance::Huber, false)),
        6.890625,
        "L_lax, sum, Huber",
    );
}

#[test]
fn stopping_the_transition_gradient_leaves_the_abstract_transition_out_of_l_lax() {
    let d = devices();
    let (states, rewards, (mean, std)) = two_pairs(&d.plain);
    // The gradients reaching the transition's μ and σ.
    let gradients = |stop: bool| {
        let tracked_mean = Tensor::from_inner(mean.clone()).require_grad();
        let tracked_std = Tensor::from_inner(std.clone()).require_grad();
        let loss = lax_loss(
            Tensor::from_inner(states.clone()),
            Tensor::from_inner(rewards.clone()),
            (tracked_mean.clone(), tracked_std.clone()),
            &[1],
            0.9,
            &metric(MetricReduction::Sum, Distance::L1, stop),
        );
        let grads = loss.backward();
        (
            tracked_mean.grad(&grads).map(to_vec),
            tracked_std.grad(&grads).map(to_vec),
        )
    };
    let (free, free_std) = gradients(false);
    let free = free.expect("L_lax reaches μ when the transition is free");
    // ∂W₂/∂σ_01 = (σ_01 − σ_11)/W₂ = −4/5 in each term: ∂L/∂σ_01 = −2(d − c)·0.9·(−0.8) = −2.88.
    let free_std = free_std.expect("L_lax reaches σ when the transition is free");
    close(free_std[1], -2.88, "∂L_lax/∂σ_01");
    // By hand: L = mean of two equal terms (d − c)², c = 0.5 + 0.9·W₂, W₂ = |Δμ| along the
    // first dimension (Δσ fixed): ∂L/∂μ_00 = −2(d − c)·0.9·∂W₂/∂μ_00 per term, both terms.
    // d − c = −2, ∂W₂/∂μ_00 = (μ_00 − μ_10)/W₂ = −3/5 in each term: ∂L/∂μ_00 = 2·(−2·−0.9·−0.6)
    // ·½ = −2.16 (and +2.16 for μ_10).
    close(free[0], -2.16, "∂L_lax/∂μ_00");
    close(free[2], 2.16, "∂L_lax/∂μ_10");
    let (held_mean, held_std) = gradients(true);
    for (name, held) in [("μ", held_mean), ("σ", held_std)] {
        if let Some(grad) = held {
            assert!(
                grad.iter().all(|g| *g == 0.0),
                "a held transition's {name} still gets a gradient: {grad:?}"
            );
        }
    }
}

#[test]
fn abstract_model_loss_matches_hand_values() {
    let d = devices().plain;
    // Two samples, two latent dimensions. The first: μ = (0, 1), σ = (1, 2), f(x') = (1, 1),
    // ε = (0.5, −1), r̄⁺ = 0.3, r̃ = 1. The second fits exactly (μ = f(x') = 0, σ = 1, ε = 0,
    // r̄⁺ = r̃) and costs 0 in both forms, so the batch's mean is half the first's term.
    let transition = (
        m(&[0.0, 1.0, 0.0, 0.0], 2, &d),
        m(&[1.0, 2.0, 1.0, 1.0], 2, &d),
    );
    let next = m(&[1.0, 1.0, 0.0, 0.0], 2, &d);
    let eps = m(&[0.5, -1.0, 0.0, 0.0], 2, &d);
    let rewards = (m(&[0.3, 1.0], 2, &d), m(&[1.0, 1.0], 2, &d));
    let loss_in = |form, reduction| {
        to_vec(abstract_model_loss(
            transition.clone(),
            next.clone(),
            eps.clone(),
            rewards.clone(),
            (form, reduction),
        ))[0]
    };
    let loss = |form| loss_in(form, Reduction::Sum);
    // NLL: ½(−1/1)² + ln 1 + ½(0/2)² + ln 2, plus (0.3 − 1)² = 0.49; halved by the mean.
    close(
        loss(TransitionLoss::GaussianNll),
        (0.5 + 2f64.ln() + 0.49) / 2.0,
        "L_h, Gaussian NLL",
    );
    // Eq. 3: the sample (0.5, −1) against (1, 1): 0.25 + 4, plus 0.49; halved by the mean.
    close(
        loss(TransitionLoss::SampleSquared),
        4.74 / 2.0,
        "L_h, sampled squared error",
    );
    // The authors' NLL averages over the two dimensions (the reward's term stays whole).
    close(
        loss_in(TransitionLoss::GaussianNll, Reduction::Mean),
        ((0.5 + 2f64.ln()) / 2.0 + 0.49) / 2.0,
        "L_h, Gaussian NLL averaged over dimensions",
    );
}

/// `P̄_τ`'s σ from its network's output u: the authors' `exp(clamp(u, −5, 2))`, against the
/// logistic into (1e-4, 10); one linear layer whose output is its bias, (μ, u) = (0.3, u).
#[test]
fn the_transition_std_follows_its_form() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let d = devices();
    for (u, clamped_exp, logistic) in [
        (
            -7.0f64,
            (-5.0f64).exp(),
            1e-4 + (10.0 - 1e-4) / (1.0 + 7f64.exp()),
        ),
        (
            0.5,
            0.5f64.exp(),
            1e-4 + (10.0 - 1e-4) / (1.0 + (-0.5f64).exp()),
        ),
        (
            3.0,
            2f64.exp(),
            1e-4 + (10.0 - 1e-4) / (1.0 + (-3f64).exp()),
        ),
    ] {
        for (form, expected) in [
            (TransitionStd::ClampedExp, clamped_exp),
            (TransitionStd::Logistic, logistic),
        ] {
            let mut h = Homomorphism::new((1, 1), (1, 1), &[4], &d.train)
                .with_forms(ActionMap::Learned, form);
            h.transition = Mlp {
                layers: vec![StackedLinear {
                    weight: Param::from_data([[[0.0f32, 0.0], [0.0, 0.0]]], &d.train),
                    bias: Param::from_data([[0.3f32, u as f32]], &d.train),
                }],
            };
            let (mean, std) = h
                .valid()
                .transition(m(&[1.0], 1, &d.plain), m(&[0.5], 1, &d.plain));
            close(to_vec(mean)[0], 0.3, "μ");
            close(
                to_vec(std)[0],
                expected,
                &format!("σ at u = {u} ({form:?})"),
            );
        }
    }
}

#[test]
fn lifting_loss_through_a_linear_action_map_matches_hand_values() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let d = devices();
    // x of one entry, one action: g_ω(x, a) = tanh(0.5·x + 1.0·a + 0.1), one linear layer.
    let mut h = Homomorphism::new((1, 1), (2, 1), &[4], &d.train);
    h.action_map = Some(Mlp {
        layers: vec![StackedLinear {
            weight: Param::from_data([[[0.5f32], [1.0]]], &d.train),
            bias: Param::from_data([[0.1f32]], &d.train),
        }],
    });
    // Two states x = (1, −1), K = 2 regular actions each: {0.2, 0.6} at the first, {−0.4, 0}
    // at the second, laid out sample by sample ([K, S, B, A], one run); the abstract policy's
    // {0.5, 0.5} and {0.1, −0.1}.
    let x = m(&[1.0, -1.0], 2, &d.plain);
    let three = |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [2, 1, 2, 1]), &d.plain);
    let lifted = h
        .valid()
        .abstract_actions_k(x, three(vec![0.2, -0.4, 0.6, 0.0]));
    let g = |x: f64, a: f64| (0.5 * x + a + 0.1).tanh();
    let by_hand = [g(1.0, 0.2), g(-1.0, -0.4), g(1.0, 0.6), g(-1.0, 0.0)];
    for (k, (found, expected)) in to_vec(lifted.clone()).iter().zip(by_hand).enumerate() {
        close(
            *found,
            expected,
            &format!("g_ω of sample {} at state {}", k / 2, k % 2),
        );
    }
    // Per state ‖E[g] − E[ā]‖² + ‖σ[g] − σ[ā]‖², σ with the N − 1 correction (|u − v|/√2 for
    // two samples; the abstract side's σ at state 0 is its floor, 1e-6), averaged over states.
    let term = |(g1, g2): (f64, f64), (a1, a2): (f64, f64)| {
        let spread = |u: f64, v: f64| ((u - v).abs() / 2f64.sqrt()).max(1e-6);
        ((g1 + g2) / 2.0 - (a1 + a2) / 2.0).powi(2) + (spread(g1, g2) - spread(a1, a2)).powi(2)
    };
    let expected = (term((by_hand[0], by_hand[2]), (0.5, 0.5))
        + term((by_hand[1], by_hand[3]), (0.1, -0.1)))
        / 2.0;
    close(
        to_vec(lifting_loss(lifted, three(vec![0.5, 0.1, 0.5, -0.1])))[0],
        expected,
        "L_lift through g_ω",
    );
}

fn config(lifting_weight: f64) -> D2hpgPrincipledConfig {
    D2hpgPrincipledConfig {
        lifting: LiftingConfig {
            lifting_weight,
            ..LiftingConfig::default()
        },
        latent_dim: 6,
        ..D2hpgPrincipledConfig::default()
    }
}

/// Every parameter of the agent by part: the four networks of the homomorphism, the regular
/// actor, critic and target, the abstract actor, critic and target.
fn parts(agent: &D2hpgPrincipled) -> Vec<(&'static str, Vec<f32>)> {
    let h = &agent.homomorphism;
    vec![
        ("f_ξ", parameters(&h.state_map)),
        ("g_ω", parameters(&h.action_map)),
        ("P̄_τ", parameters(&h.transition)),
        ("R̄_ν", parameters(&h.reward)),
        ("regular actor", parameters(&agent.regular.actor)),
        ("regular critic", parameters(&agent.regular.critic)),
        ("regular target", parameters(&agent.regular.target)),
        ("abstract actor", parameters(&agent.abstract_learner.actor)),
        (
            "abstract critic",
            parameters(&agent.abstract_learner.critic),
        ),
        (
            "abstract target",
            parameters(&agent.abstract_learner.target),
        ),
    ]
}

/// Line 23's wiring: `update` logs L_lax and L_h of the homomorphism before its step, on the
/// batch's `x`, `a`, `r̃` and `x'` with the configured γ; recomputed here from a copy of the
/// same networks and of the model stream (the pairing shift, then ε) through the loss
/// functions checked by hand above. A wrong input (`x` for `x'`, R̄'s reward for `r̃` in the
/// metric, `x` for the action map's action) or a wrong γ changes a logged value.
#[test]
fn update_logs_l_lax_and_l_h_of_the_batch_it_was_given() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(3), devices());
    let b = random_batch(&spec, 32, 5);
    for transition_loss in [TransitionLoss::GaussianNll, TransitionLoss::SampleSquared] {
        let config = D2hpgPrincipledConfig {
            transition_loss,
            ..config(1.0)
        };
        let mut agent = D2hpgPrincipled::new(&config, &spec, &d, &[8]);
        let h = agent.homomorphism.valid();
        let mut noise = agent.model_noise[0].clone();
        let t = TransitionTensors::new(&b, &d.plain);
        let shift = 1 + noise.below(b.len() - 1);
        let eps = Noise::stacked_normal(
            std::slice::from_mut(&mut noise),
            b.len(),
            config.latent_dim,
            &d.plain,
        );
        let state = h.abstract_state(t.augmented.clone());
        let action = h.abstract_action(t.augmented.clone(), t.action.clone());
        let transition = h.transition(state.clone(), action.clone());
        let expected_lax = to_vec(lax_loss(
            state.clone(),
            t.reward.clone(),
            transition.clone(),
            &[shift],
            config.sac.gamma,
            &LaxMetric::of(&config),
        ))[0];
        let expected_model = to_vec(abstract_model_loss(
            transition,
            h.abstract_state(t.next_augmented.clone()),
            eps,
            (h.reward(state, action), t.reward.clone()),
            (transition_loss, config.transition_reduction),
        ))[0];
        let stats = update(&mut agent, &b);
        let logged = |name: &str| stats.iter().find(|(n, _)| *n == name).unwrap().1;
        close(
            expected_lax,
            logged("lax_loss"),
            &format!("L_lax ({transition_loss:?})"),
        );
        close(
            expected_model,
            logged("model_loss"),
            &format!("L_h ({transition_loss:?})"),
        );
    }
}

/// One update: line 23 moves all four networks of the homomorphism; L_lift (λ = 10 against
/// λ = 0 from the same seed and batch) moves the regular actor and nothing else — not the
/// critics, not g_ω it flows through, not the abstract learner.
#[test]
fn each_loss_moves_only_its_own_parameters() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(3), devices());
    let b = random_batch(&spec, 32, 4);
    let after_one = |weight: f64| {
        let mut agent = D2hpgPrincipled::new(&config(weight), &spec, &d, &[8]);
        let before = parts(&agent);
        update(&mut agent, &b);
        (before, parts(&agent))
    };
    let (before, lifted) = after_one(10.0);
    for (name, values) in &before[..4] {
        let moved = &lifted.iter().find(|(n, _)| n == name).unwrap().1;
        assert_ne!(values, moved, "{name} did not move under L_lax + L_h");
    }
    let (_, unlifted) = after_one(0.0);
    for ((name, with), (_, without)) in lifted.iter().zip(&unlifted) {
        if *name == "regular actor" {
            assert_ne!(with, without, "L_lift did not move the regular actor");
        } else {
            assert!(with == without, "L_lift moved the {name}");
        }
    }
}

/// Every choice of the configuration is honoured: one update from the same seed and batch with
/// one field changed moves the part that field concerns elsewhere than the defaults do (and,
/// where the field concerns one side only, leaves the other side where the defaults leave it).
#[test]
fn every_choice_changes_the_part_it_concerns() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(3), devices());
    let b = random_batch(&spec, 32, 6);
    let after_one = |config: &D2hpgPrincipledConfig| {
        let mut agent = D2hpgPrincipled::new(config, &spec, &d, &[2]);
        let initial_alpha = parameters(&agent.regular.temperature);
        let stats = update(&mut agent, &b);
        assert!(
            stats.iter().all(|(_, v)| v.is_finite()),
            "{config:?}: {stats:?}"
        );
        (
            parts(&agent),
            stats,
            initial_alpha,
            parameters(&agent.regular.temperature),
        )
    };
    let defaults = after_one(&config(1.0));
    let part = |parts: &[(&str, Vec<f32>)], name: &str| {
        parts.iter().find(|(n, _)| *n == name).unwrap().1.clone()
    };
    let homomorphism = ["f_ξ", "g_ω", "P̄_τ", "R̄_ν"];
    let cases: [(&str, D2hpgPrincipledConfig, &str); 6] = [
        (
            "lax_weight = 0",
            D2hpgPrincipledConfig {
                lax_weight: 0.0,
                ..config(1.0)
            },
            "f_ξ",
        ),
        (
            "metric_reduction = sum",
            D2hpgPrincipledConfig {
                metric_reduction: MetricReduction::Sum,
                ..config(1.0)
            },
            "f_ξ",
        ),
        (
            "distance = huber",
            D2hpgPrincipledConfig {
                distance: Distance::Huber,
                ..config(1.0)
            },
            "f_ξ",
        ),
        (
            "stop_transition_gradient",
            D2hpgPrincipledConfig {
                stop_transition_gradient: true,
                ..config(1.0)
            },
            "P̄_τ",
        ),
        (
            "transition_loss = sample-squared",
            D2hpgPrincipledConfig {
                transition_loss: TransitionLoss::SampleSquared,
                ..config(1.0)
            },
            "P̄_τ",
        ),
        (
            "abstract_reward = replay",
            D2hpgPrincipledConfig {
                abstract_reward: AbstractReward::Replay,
                ..config(1.0)
            },
            "abstract critic",
        ),
    ];
    for (what, changed, concerned) in cases {
        let (found, ..) = after_one(&changed);
        assert_ne!(
            part(&found, concerned),
            part(&defaults.0, concerned),
            "{what} left the {concerned} where the defaults leave it"
        );
        if what == "abstract_reward = replay" {
            for name in homomorphism {
                assert!(
                    part(&found, name) == part(&defaults.0, name),
                    "{what} moved {name}, which line 23 trains before the critics"
                );
            }
        }
    }
    // The regular critic on x: wider inputs, so more parameters.
    let (on_x, ..) = after_one(&D2hpgPrincipledConfig {
        regular_critic: RegularCritic::Augmented,
        ..config(1.0)
    });
    assert!(
        part(&on_x, "regular critic").len() > part(&defaults.0, "regular critic").len(),
        "regular_critic = augmented: the critic does not read x"
    );
    // Without the optional line 25 the regular policy has no actor loss and its temperature
    // stays where it started; with it, α moves.
    let (_, stats, initial, alpha) = after_one(&D2hpgPrincipledConfig {
        regular_policy_step: false,
        ..config(1.0)
    });
    assert!(stats.iter().all(|(n, _)| *n != "actor_loss"), "{stats:?}");
    assert_eq!(alpha, initial, "regular_policy_step = false moved α");
    assert_ne!(
        defaults.3, defaults.2,
        "the defaults' BPQL step left α alone"
    );
    // Abstract actions of another width than the actions: g_ω maps 2 to 3 dimensions, the
    // abstract policy acts in 3, and L_lift compares 3-dimensional moments.
    let (wider, stats, ..) = after_one(&D2hpgPrincipledConfig {
        abstract_action_dim: 3,
        ..config(1.0)
    });
    assert!(
        part(&wider, "abstract actor").len() > part(&defaults.0, "abstract actor").len(),
        "abstract_action_dim = 3: the abstract policy still acts in 2 dimensions"
    );
    assert!(
        stats.iter().any(|(n, v)| *n == "lifting_loss" && *v > 0.0),
        "{stats:?}"
    );
}

/// Principled D2HPG under `--protocol authors` is the authors' `d2hpg_principled.py`: their
/// settings through the registry, and an agent of them that is their algorithm — `ā = a` (no
/// `g_ω`; the abstract policy acts in the task's bounds), `x̄` as wide as the observation, SAC
/// on `x` as the regular learner, λ = 10 on its schedule, one α (the abstract learner's
/// entropy terms read the regular learner's, and its own never moves).
#[test]
fn the_authors_principled_form_is_their_code() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let fields = AlgoSettings::under(Protocol::Authors, "d2hpg-principled", &toml::Table::new())
        .unwrap()
        .fields();
    let text = |v: &str| toml::Value::String(v.into());
    for (field, value) in [
        ("action_map", text("identity")),
        ("latent_dim", toml::Value::Integer(0)),
        ("metric_reduction", text("sum")),
        ("distance", text("l1")),
        ("stop_transition_gradient", toml::Value::Boolean(true)),
        ("transition_loss", text("gaussian-nll")),
        ("transition_reduction", text("mean")),
        ("transition_std", text("clamped-exp")),
        ("gradient_clip_norm", toml::Value::Float(10.0)),
        ("abstract_reward", text("replay")),
        ("regular_critic", text("augmented")),
        ("shared_temperature", toml::Value::Boolean(true)),
        ("lifting_weight", toml::Value::Float(10.0)),
        ("lifting_schedule", text("hold-decay")),
        ("lifting_samples", toml::Value::Integer(100)),
        ("lifting_noise", text("independent")),
        ("lifting_reduction", text("mean")),
        ("network_init", text("orthogonal")),
    ] {
        assert_eq!(
            fields[field], value,
            "d2hpg-principled's {field} under the authors' protocol"
        );
    }
    let authors: D2hpgPrincipledConfig = toml::Value::Table(fields).try_into().unwrap();
    let (spec, d) = (spec(3), devices());
    let mut agent = D2hpgPrincipled::new(&authors, &spec, &d, &[4]);
    assert!(
        agent.homomorphism.action_map.is_none(),
        "g_ω is not the identity"
    );
    let b = random_batch(&spec, 32, 7);
    let t = TransitionTensors::new(&b, &d.plain);
    let h = agent.homomorphism.valid();
    assert_eq!(
        to_vec(h.abstract_action(t.augmented.clone(), t.action.clone())),
        to_vec(t.action.clone()),
        "ā is not a"
    );
    assert_eq!(
        h.abstract_state(t.augmented.clone()).dims()[2],
        spec.obs_dim,
        "x̄ is not as wide as the observation"
    );
    // The abstract policy's actions lie in the task's bounds (the second dimension's ±2).
    let abstract_actions = agent.abstract_learner.act_run(
        0,
        &vec![10.0; 64 * spec.obs_dim],
        64,
        spec.obs_dim,
        ActMode::Explore,
    );
    assert!(
        abstract_actions.chunks(2).any(|a| a[1].abs() > 1.0),
        "{abstract_actions:?}"
    );
    // SAC on x: the regular critic reads the augmented state (wider than BPQL's on s).
    let bpql = D2hpgPrincipled::new(&config(1.0), &spec, &d, &[4]);
    assert!(
        parameters(&agent.regular.critic).len() > parameters(&bpql.regular.critic).len(),
        "the regular critic does not read x"
    );
    let abstract_alpha = parameters(&agent.abstract_learner.temperature);
    for step in 0..4 {
        let stats = update(&mut agent, &random_batch(&spec, 32, 20 + step));
        let logged = |name: &str| stats.iter().find(|(n, _)| *n == name).unwrap().1;
        assert_eq!(logged("lifting_weight"), 10.0);
        assert_eq!(
            logged("abstract_alpha"),
            logged("alpha"),
            "two temperatures"
        );
    }
    assert_eq!(
        parameters(&agent.abstract_learner.temperature),
        abstract_alpha,
        "the abstract learner tuned an α of its own"
    );
    assert_ne!(
        parameters(&agent.regular.temperature),
        abstract_alpha,
        "the shared α was never tuned"
    );
}

/// The homomorphism's gradient is clipped before its Adam step: at a norm far below Adam's ε
/// the networks barely move, where unclipped they move by about the learning rate.
#[test]
fn the_homomorphism_gradient_is_clipped_as_configured() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(3), devices());
    let b = random_batch(&spec, 32, 11);
    let moved = |gradient_clip_norm: f64| {
        let config = D2hpgPrincipledConfig {
            gradient_clip_norm,
            ..config(1.0)
        };
        let mut agent = D2hpgPrincipled::new(&config, &spec, &d, &[6]);
        let before = parameters(&agent.homomorphism);
        update(&mut agent, &b);
        let after = parameters(&agent.homomorphism);
        before
            .iter()
            .zip(&after)
            .map(|(u, v)| f64::from((u - v).abs()))
            .fold(0.0, f64::max)
    };
    // Adam's first step is lr·g/(|g| + ε) per entry: about lr unclipped; with the whole
    // gradient's norm at 1e-12, every |g| ≤ 1e-12 and the step at most lr·1e-12/ε.
    let (free, clipped) = (moved(0.0), moved(1e-12));
    assert!(free > 1e-4, "the unclipped step moved at most {free}");
    assert!(
        clipped < 0.01 * free,
        "clipped at 1e-12 the step still moved {clipped} (free: {free})"
    );
}

/// With λ = 0 the regular learner is BPQL exactly (every parameter and action, over several
/// updates), whatever the homomorphism and the abstract learner do beside it; with the paper's
/// `L_regular-critic` on x (`regular_critic = "augmented"`) it is not.
#[test]
fn without_lifting_the_regular_learner_is_bpql() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d, seed) = (spec(3), devices(), 13);
    let mut principled = D2hpgPrincipled::new(&config(0.0), &spec, &d, &[seed]);
    let mut bpql = Bpql::new(&spec, &SacConfig::default(), &d, seed);
    let mut on_x = D2hpgPrincipled::new(
        &D2hpgPrincipledConfig {
            regular_critic: RegularCritic::Augmented,
            ..config(0.0)
        },
        &spec,
        &d,
        &[seed],
    );
    for step in 0..4 {
        let b = random_batch(&spec, 32, 300 + step);
        update(&mut principled, &b);
        update(&mut bpql, &b);
        update(&mut on_x, &b);
    }
    let probe = random_batch(&spec, 8, 9);
    let act = |agent: &mut dyn Agent| agent.act(&probe.augmented, 8, ActMode::Deterministic);
    let regular = act(&mut principled);
    assert_eq!(
        regular,
        act(&mut bpql),
        "λ = 0: the regular policy is BPQL's"
    );
    assert_ne!(
        regular,
        act(&mut on_x),
        "a critic on x trains a different policy"
    );
}

/// End to end on InvertedPendulum with Δ = 2 (the settings of the other algorithms' learning
/// tests, `common::learn_delayed_pendulum`): the best evaluation must clear the bar those tests
/// use to separate working algorithms from broken variants (a uniform random policy scores
/// about 5–10, the broken variants of `tests/d2hpg.rs` ≤ 17).
#[test]
fn principled_d2hpg_learns_a_small_delayed_task() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (best, text) = common::train_delayed_pendulum(&run, "d2hpg-principled", 2, &[]);
    assert!(
        best > 40.0,
        "d2hpg-principled: best evaluation return {best}, below the bar of 40\n{text}"
    );
    // The return alone would pass with the abstract side broken (the regular learner is BPQL
    // plus the lifting term): the homomorphism must fit its metric too, L_lax of the last
    // quarter of the logged rows below that of the first quarter.
    let lax: Vec<f64> = common::column(&run.join("train.csv"), "lax_loss")
        .iter()
        .map(|v| v.parse().unwrap())
        .collect();
    let quarter = (lax.len() / 4).max(1);
    let mean = |rows: &[f64]| rows.iter().sum::<f64>() / rows.len() as f64;
    let (first, last) = (mean(&lax[..quarter]), mean(&lax[lax.len() - quarter..]));
    assert!(
        last < first,
        "L_lax did not fall: first quarter {first}, last quarter {last} ({lax:?})"
    );
}
