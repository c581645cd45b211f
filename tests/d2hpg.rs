//! BPQL and D2HPG: the lifting loss by hand, BPQL's critic on the true state by hand, the
//! production update's lifting gradient reaching the regular policy only,
//! D2HPG without lifting being exactly BPQL beside an independent delay-free SAC, and both
//! learning a small delayed task.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use std::sync::Mutex;

use burn::prelude::*;
use common::{parameters, small_spec as spec, update};
use dhrl::algos::{
    ActMode, Agent, AgentSpec, AlgoSettings, Bpql, D2hpg, D2hpgConfig, InputView, LiftingConfig,
    LiftingNoise, LiftingSchedule, Reduction, Regular, SacAgent, SacBatch, SacConfig, SacLearner,
    random_batch,
};
use dhrl::delay::Transitions;
use dhrl::learn::{
    Devices, LearnDevice, NetworkInit, Noise, TransitionTensors, lifting_loss, matrix, to_vec,
};
use dhrl::protocol::Protocol;

/// burn's generator is process-wide: networks built by concurrent tests would interleave draws.
static BUILD: Mutex<()> = Mutex::new(());

fn devices() -> Devices {
    Devices::new(LearnDevice::Cpu).unwrap()
}

/// `[K, 1, B, A]` actions: K samples of a batch of B states, of one run.
fn actions(values: Vec<f32>, k: usize, b: usize, a: usize, device: &Device) -> Tensor<4> {
    Tensor::from_data(TensorData::new(values, [k, 1, b, a]), device)
}

#[test]
fn lifting_loss_matches_hand_values() {
    let d = devices();
    // One state, K = 2 samples, one action dimension.
    // Regular: {0, 1}: mean 0.5, std √((0.25 + 0.25)/1) = √0.5.   Abstract: {0.5, 0.5}: mean 0.5, std 0.
    // L = (0.5 − 0.5)² + (√0.5 − 0)² = 0.5.
    let loss = lifting_loss(
        actions(vec![0.0, 1.0], 2, 1, 1, &d.plain),
        actions(vec![0.5, 0.5], 2, 1, 1, &d.plain),
    );
    assert!((to_vec(loss)[0] - 0.5).abs() < 1e-5);
    // Two states, two dimensions, K = 3; summed over dimensions, averaged over states.
    // State 1: regular dim0 {1,2,3} (mean 2, std 1), dim1 {0,0,0} (0, 0); abstract dim0 {0,0,0}, dim1 {2,2,2}:
    //   (2−0)² + (1−0)² + (0−2)² + (0−0)² = 9.   State 2: both {1,1,1} → 0.   Mean: 4.5.
    // Laid out sample by sample: [state 1 (dim0, dim1), state 2 (dim0, dim1)] per sample.
    let regular = vec![1.0, 0.0, 1.0, 1.0, 2.0, 0.0, 1.0, 1.0, 3.0, 0.0, 1.0, 1.0];
    let abstract_ = vec![0.0, 2.0, 1.0, 1.0, 0.0, 2.0, 1.0, 1.0, 0.0, 2.0, 1.0, 1.0];
    let loss = lifting_loss(
        actions(regular, 3, 2, 2, &d.plain),
        actions(abstract_, 3, 2, 2, &d.plain),
    );
    assert!((to_vec(loss)[0] - 4.5).abs() < 1e-4);
}

/// D2HPG's defaults with lifting weight λ and K samples.
fn lifting(weight: f64, samples: usize) -> D2hpgConfig {
    D2hpgConfig {
        lifting: LiftingConfig {
            lifting_weight: weight,
            lifting_samples: samples,
            ..LiftingConfig::default()
        },
        ..D2hpgConfig::default()
    }
}

fn batch(spec: &AgentSpec, n: usize, seed: u64) -> Transitions {
    random_batch(spec, n, seed)
}

/// A learner's whole state: actor, critics, target critics, temperature, noise stream.
fn learner_state(learner: &SacLearner) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>, String) {
    (
        parameters(&learner.actor),
        parameters(&learner.critic),
        parameters(&learner.target),
        parameters(&learner.temperature),
        serde_json::to_string(&learner.noise).unwrap(),
    )
}

/// The learner an agent saved under `prefix` in `dir`, loaded into a fresh one of its sizes.
fn saved_learner(
    dir: &std::path::Path,
    prefix: &str,
    actor: usize,
    critic: usize,
    spec: &AgentSpec,
) -> SacLearner {
    let mut learner = SacLearner::new(actor, critic, spec, &SacConfig::default(), &devices(), 0);
    learner.load(&[dir], prefix).unwrap();
    learner
}

/// BPQL's critic reads the true state: its loss on a batch whose `s_τ` differs from the
/// observation inside `x_τ` equals, to f32 rounding, the loss computed here from the same
/// networks and noise with `Q(s, a)` and the target on `s'`, and is far from what reading the
/// observation inside `x` would give.
#[test]
fn bpql_critic_reads_the_true_state_and_its_actor_reads_x() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, hyper, d) = (spec(4), SacConfig::default(), devices());
    let (obs, aug, act, n) = (spec.obs_dim, spec.augmented_dim(), spec.act_dim, 16);
    let mut bpql = Bpql::new(&spec, &hyper, &d, 3);
    let dir = tempfile::tempdir().unwrap();
    bpql.save(dir.path()).unwrap();
    let mut copy = saved_learner(dir.path(), "", aug, obs, &spec);
    let b = batch(&spec, n, 1);
    let observed =
        |x: &[f32]| -> Vec<f32> { x.chunks(aug).flat_map(|r| r[..obs].to_vec()).collect() };
    assert_ne!(
        observed(&b.augmented),
        b.state,
        "s_τ must differ from the observation in x_τ"
    );

    // By hand: J_Q = mean (Q1(s,a) − y)² + mean (Q2(s,a) − y)²,
    // y = r + γ(1 − d)(min Q̄(s', a') − α log π(a'|x')), a' = π(x', ε) with the learner's first ε.
    let plain = d.plain.clone();
    let m = |v: &[f32], cols: usize| matrix(v.to_vec(), n, cols, &plain).unsqueeze_dim::<3>(0);
    let alpha = copy.temperature.alphas()[0];
    let eps = Noise::stacked_normal(&mut copy.noise[..1], n, act, &plain);
    let next = copy
        .actor
        .valid()
        .sample(m(&b.next_augmented, aug), eps, &copy.scale);
    let (next_action, next_log_prob) = (to_vec(next.action.clone()), to_vec(next.log_prob));
    let by_hand = |state: &[f32], next_state: &[f32]| -> f64 {
        let target =
            |q: &dhrl::learn::QNetwork| to_vec(q.forward(m(next_state, obs), m(&next_action, act)));
        let critic = copy.critic.valid();
        let (t1, t2) = (target(&copy.target.q1), target(&copy.target.q2));
        let q = |q: &dhrl::learn::QNetwork| to_vec(q.forward(m(state, obs), m(&b.action, act)));
        let (q1, q2) = (q(&critic.q1), q(&critic.q2));
        let mut loss = 0.0;
        for i in 0..n {
            let soft = f64::from(t1[i].min(t2[i])) - alpha * f64::from(next_log_prob[i]);
            let y =
                f64::from(b.reward[i]) + hyper.gamma * (1.0 - f64::from(b.terminated[i])) * soft;
            loss += ((f64::from(q1[i]) - y).powi(2) + (f64::from(q2[i]) - y).powi(2)) / n as f64;
        }
        loss
    };
    let on_s = by_hand(&b.state, &b.next_state);
    let on_observation = by_hand(&observed(&b.augmented), &observed(&b.next_augmented));
    let stats = update(&mut bpql, &b);
    let reported = stats
        .iter()
        .find(|(name, _)| *name == "critic_loss")
        .unwrap()
        .1;
    assert!(
        (reported - on_s).abs() <= 1e-4 * on_s.abs().max(1.0),
        "BPQL's critic loss {reported}, by hand on s {on_s}"
    );
    assert!(
        (reported - on_observation).abs() > 100.0 * 1e-4 * on_s.abs().max(1.0),
        "the batch does not tell s from the observation in x: {reported} vs {on_observation}"
    );
    // The actor takes obs + 4·act = 11 inputs: acting reads x.
    let acts = bpql.act(&batch(&spec, 2, 2).augmented, 2, ActMode::Deterministic);
    assert_eq!(acts.len(), 4);
    assert!(
        acts.chunks(2)
            .all(|a| a[0].abs() <= 1.0 && a[1].abs() <= 2.0),
        "{acts:?}"
    );
}

/// The production update: with λ > 0 the lifting gradient reaches the regular policy only —
/// D2HPG's delay-free learner ends exactly where an independent SAC fed the same batches and
/// noise ends (every parameter, target and noise state), while its regular policy ends away
/// from where λ = 0 leaves it.
#[test]
fn lifting_moves_the_regular_policy_and_leaves_the_delay_free_learner_alone() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, hyper, d, seed) = (spec(3), SacConfig::default(), devices(), 21);
    let (obs, aug) = (spec.obs_dim, spec.augmented_dim());
    let lifted = |weight: f64| {
        let mut agent = D2hpg::new(Regular::Bpql, &lifting(weight, 4), &spec, &d, &[seed]);
        for step in 0..5 {
            update(&mut agent, &batch(&spec, 32, 200 + step));
        }
        // burn reads loaded parameters from their files lazily: the folder must outlive them.
        let dir = tempfile::tempdir().unwrap();
        agent.save(dir.path()).unwrap();
        (
            saved_learner(dir.path(), "regular_", aug, obs, &spec),
            saved_learner(dir.path(), "delay_free_", obs, obs, &spec),
            dir,
        )
    };
    let (regular, delay_free, _kept) = lifted(10.0);
    let mut independent = SacAgent::new(
        InputView::TrueState,
        &spec,
        &hyper,
        &d,
        dhrl::seeds::delay_free_learner(seed),
    );
    for step in 0..5 {
        update(&mut independent, &batch(&spec, 32, 200 + step));
    }
    let dir = tempfile::tempdir().unwrap();
    independent.save(dir.path()).unwrap();
    let reference = saved_learner(dir.path(), "", obs, obs, &spec);
    assert!(
        learner_state(&delay_free) == learner_state(&reference),
        "the delay-free learner moved under the lifting loss"
    );
    let (unlifted, _, _kept_too) = lifted(0.0);
    assert_ne!(
        parameters(&regular.actor),
        parameters(&unlifted.actor),
        "λ = 10 left the regular policy where λ = 0 does"
    );
}

#[test]
fn d2hpg_without_lifting_is_bpql_beside_an_independent_delay_free_sac() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, hyper, d, seed) = (spec(3), SacConfig::default(), devices(), 11);
    let mut d2hpg = D2hpg::new(Regular::Bpql, &lifting(0.0, 4), &spec, &d, &[seed]);
    let mut bpql = Bpql::new(&spec, &hyper, &d, seed);
    let mut delay_free = SacAgent::new(
        InputView::TrueState,
        &spec,
        &hyper,
        &d,
        dhrl::seeds::delay_free_learner(seed),
    );
    for step in 0..4 {
        let b = batch(&spec, 32, 100 + step);
        update(&mut d2hpg, &b);
        update(&mut bpql, &b);
        update(&mut delay_free, &b);
    }
    let probe = batch(&spec, 8, 7);
    let regular = d2hpg.act(&probe.augmented, 8, ActMode::Deterministic);
    assert_eq!(
        regular,
        bpql.act(&probe.augmented, 8, ActMode::Deterministic),
        "regular policy = BPQL's"
    );
    let states = d2hpg.act_delay_free(&probe.state, 8).unwrap();
    // The SAC baseline acts on the first obs entries of augmented rows: pad each state.
    let padded: Vec<f32> = probe
        .state
        .chunks(3)
        .flat_map(|s| s.iter().copied().chain([0.0; 6]))
        .collect();
    let reference = delay_free.act(&padded, 8, ActMode::Deterministic);
    assert_eq!(
        states, reference,
        "delay-free policy = an independent SAC's"
    );

    // With lifting on, the regular policy moves away from BPQL's.
    let mut lifted = D2hpg::new(Regular::Bpql, &lifting(10.0, 4), &spec, &d, &[seed]);
    for step in 0..4 {
        update(&mut lifted, &batch(&spec, 32, 100 + step));
    }
    assert_ne!(
        lifted.act(&probe.augmented, 8, ActMode::Deterministic),
        regular
    );
}

#[test]
fn d2hpg_naive_moves_its_regular_policy_toward_the_delay_free_one() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(2), devices());
    // Two agents from the same seed: their delay-free learners take the same steps, so the
    // lifting loss of the one with λ = 0 (a regular policy left where it started) is the
    // yardstick for how far the lifted one has closed in.
    let lifting_after = |weight: f64| {
        let mut agent = D2hpg::new(Regular::LiftingOnly, &lifting(weight, 8), &spec, &d, &[5]);
        let b = batch(&spec, 64, 9);
        let mut stats = update(&mut agent, &b);
        for _ in 0..300 {
            stats = update(&mut agent, &b);
        }
        stats.iter().find(|(n, _)| *n == "lifting_loss").unwrap().1
    };
    let (pulled, left) = (lifting_after(1.0), lifting_after(0.0));
    assert!(
        pulled < 0.25 * left,
        "lifting loss after 300 updates: {pulled} with λ = 1, {left} with λ = 0"
    );
}

/// End to end on a small delayed task, InvertedPendulum with Δ = 2: each algorithm's best
/// evaluation must clear a bar set between what it reaches and what a broken variant reaches.
/// Measured with this test's settings (8,000 steps, batch 64, seed 2; best of 4 evaluations of
/// 5 episodes; a uniform random policy scores ~5–10):
///
/// | variant                                                | bpql  | d2hpg |
/// |--------------------------------------------------------|-------|-------|
/// | working, seed 2 (seeds 3, 4)                           | 80.8 (125.4, 85.2) | 80.0 (94.6, 74.4) |
/// | critics on the observation inside `x` instead of `s`   | 9.0   | 6.8   |
/// | actions one step misaligned in the replay (`a_{τ−1}`)  | 4.6   | 5.0   |
#[test]
fn bpql_and_d2hpg_learn_where_broken_variants_do_not() {
    for algo in ["bpql", "d2hpg"] {
        let (best, text) = common::learn_delayed_pendulum(algo, 2, &[]);
        assert!(
            best > 40.0,
            "{algo}: best evaluation return {best}, below the bar of 40 that separates it from \
             broken variants (≤ 17)\n{text}"
        );
    }
}

/// The authors' λ over a run of 20,000 steps: 10 to 25% of it (step 5,000 included), linear to
/// 0 at 75%, 0 after; dhrl's constant. The budget is the run's own, fixed when it starts.
#[test]
fn the_authors_lifting_weight_holds_then_decays_over_the_budget() {
    let authors = D2hpgConfig::protocol_defaults(Protocol::Authors)
        .lifting
        .with_budget(20_000);
    assert_eq!(authors.lifting_schedule, LiftingSchedule::HoldDecay);
    for (step, weight) in [
        (0, 10.0),
        (4_980, 10.0), // 24.9%
        (5_000, 10.0),
        (10_000, 5.0), // 50%
        (12_500, 2.5),
        (15_000, 0.0), // 75%
        (20_000, 0.0), // 100%
        (40_000, 0.0), // an extension's steps
    ] {
        let at = authors.weight_at(step);
        assert!(
            (at - weight).abs() < 1e-12,
            "λ at step {step}: {at}, not {weight}"
        );
    }
    // Fixed once: a later budget (an extended run) leaves the schedule where it was.
    assert_eq!(authors.with_budget(40_000).lifting_budget, 20_000);
    assert_eq!(authors.scheduled_budget(), Some(20_000));
    let dhrl = D2hpgConfig::protocol_defaults(Protocol::Dhrl)
        .lifting
        .with_budget(20_000);
    assert_eq!(dhrl.lifting_budget, 0, "a constant λ is fixed to no budget");
    assert_eq!(dhrl.scheduled_budget(), None);
    for step in [0, 10_000, 20_000] {
        assert_eq!(dhrl.weight_at(step), 1.0);
    }
    // What each protocol sets, through the registry (as `--protocol` reads it).
    let fields = AlgoSettings::under(Protocol::Authors, "d2hpg", &toml::Table::new())
        .unwrap()
        .fields();
    for (field, value) in [
        ("lifting_weight", toml::Value::Float(10.0)),
        ("lifting_samples", toml::Value::Integer(100)),
        ("lifting_noise", toml::Value::String("independent".into())),
        ("lifting_reduction", toml::Value::String("mean".into())),
        ("shared_temperature", toml::Value::Boolean(true)),
        ("network_init", toml::Value::String("orthogonal".into())),
    ] {
        assert_eq!(
            fields[field], value,
            "d2hpg's {field} under the authors' protocol"
        );
    }
    let naive = AlgoSettings::under(Protocol::Authors, "d2hpg-naive", &toml::Table::new())
        .unwrap()
        .fields();
    assert_eq!(naive["lifting_schedule"].as_str(), Some("constant"));
    assert_eq!(
        naive["autotune_alpha"].as_bool(),
        Some(false),
        "their naive α stays at 0.2"
    );
    assert_eq!(naive["lifting_weight"].as_float(), Some(10.0));
    let bpql = AlgoSettings::under(Protocol::Authors, "bpql", &toml::Table::new())
        .unwrap()
        .fields();
    assert_eq!(bpql["network_init"].as_str(), Some("orthogonal"));
}

/// At Δ = 0 with the regular policy set to the delay-free one, L_lift compares one
/// distribution with itself: with common noise its two sets of samples are the same numbers,
/// so the loss is 0; with independent noise they are two draws, and the loss is their sampling
/// spread — larger under the sum over action dimensions than under the mean, by dim(A).
#[test]
fn the_lifting_draws_are_common_or_independent_as_configured() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(0), devices());
    let loss = |noise: LiftingNoise, reduction: Reduction| {
        let mut config = lifting(1.0, 8);
        config.lifting.lifting_noise = noise;
        config.lifting.lifting_reduction = reduction;
        let mut agent = D2hpg::new(Regular::Bpql, &config, &spec, &d, &[3]);
        let dir = tempfile::tempdir().unwrap();
        agent.save(dir.path()).unwrap();
        std::fs::copy(
            dir.path().join("delay_free_actor.bpk"),
            dir.path().join("regular_actor.bpk"),
        )
        .unwrap();
        agent.load(dir.path()).unwrap();
        // At Δ = 0 the augmented state is the state.
        let mut b = batch(&spec, 64, 5);
        b.augmented = b.state.clone();
        b.next_augmented = b.next_state.clone();
        let stats = update(&mut agent, &b);
        stats.iter().find(|(n, _)| *n == "lifting_loss").unwrap().1
    };
    let common = loss(LiftingNoise::Common, Reduction::Sum);
    assert!(
        common.abs() < 1e-9,
        "one distribution, common noise: L_lift = {common}"
    );
    let (summed, averaged) = (
        loss(LiftingNoise::Independent, Reduction::Sum),
        loss(LiftingNoise::Independent, Reduction::Mean),
    );
    assert!(
        summed > 1e-3,
        "independent draws of one distribution: L_lift = {summed}"
    );
    assert!(
        (summed - 2.0 * averaged).abs() < 1e-6 * summed,
        "the mean over 2 action dimensions is half the sum: {summed} vs {averaged}"
    );
}

/// One α (the authors' code): the delay-free learner's entropy terms read the regular
/// learner's α, which only the regular policy's entropy tunes. After a few updates the two α
/// differ from where a learner of its own would be; the next update of the delay-free learner
/// equals, in every parameter and noise state, a copy of it stepped with the regular α
/// borrowed, and not a copy stepped with its own.
#[test]
fn the_delay_free_learner_reads_the_regular_alpha_when_one_is_shared() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(2), devices());
    let (obs, aug) = (spec.obs_dim, spec.augmented_dim());
    let config = D2hpgConfig {
        shared_temperature: true,
        ..lifting(1.0, 4)
    };
    let mut agent = D2hpg::new(Regular::Bpql, &config, &spec, &d, &[8]);
    for step in 0..6 {
        update(&mut agent, &batch(&spec, 32, 40 + step));
    }
    let before = tempfile::tempdir().unwrap();
    agent.save(before.path()).unwrap();
    let regular = saved_learner(before.path(), "regular_", aug, obs, &spec);
    let free = |borrow: bool| {
        let mut copy = saved_learner(before.path(), "delay_free_", obs, obs, &spec);
        if borrow {
            copy.borrowed_alpha = Some(regular.temperature.alpha_tensor());
        }
        copy
    };
    let (regular_alpha, own_alpha) = (
        regular.temperature.alphas()[0],
        free(false).temperature.alphas()[0],
    );
    assert!(
        (own_alpha - 0.2).abs() < 1e-6,
        "the delay-free α was tuned: {own_alpha}"
    );
    assert!(
        (regular_alpha - 0.2).abs() > 1e-5,
        "the regular α did not move: {regular_alpha}"
    );

    let b = batch(&spec, 32, 99);
    let stats = update(&mut agent, &b);
    let free_alpha = stats.iter().find(|(n, _)| *n == "free_alpha").unwrap().1;
    assert!(
        (free_alpha - regular_alpha).abs() < 1e-6,
        "free_alpha logs {free_alpha}"
    );
    let after = tempfile::tempdir().unwrap();
    agent.save(after.path()).unwrap();
    let stepped = saved_learner(after.path(), "delay_free_", obs, obs, &spec);
    let state = TransitionTensors::stacked(std::slice::from_ref(&b), &d.plain);
    let on_state = (state.state.clone(), state.next_state.clone());
    let sac_batch = SacBatch::new(&state, on_state.clone(), on_state);
    let (mut borrowing, mut own) = (free(true), free(false));
    borrowing.update(&sac_batch);
    own.update(&sac_batch);
    assert!(
        learner_state(&stepped) == learner_state(&borrowing),
        "the delay-free learner did not step with the regular α"
    );
    assert!(
        parameters(&stepped.critic) != parameters(&own.critic),
        "its own α gives the same step: the test cannot tell the two apart"
    );
}

/// D2HPG-SAC's regular learner is augmented SAC, its critic on `x`: without lifting its
/// regular policy is exactly augmented SAC's, and not BPQL's (whose critic reads `s`).
#[test]
fn d2hpg_sac_without_lifting_is_augmented_sac_whose_critic_reads_x() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, hyper, d, seed) = (spec(3), SacConfig::default(), devices(), 13);
    let mut d2hpg_sac = D2hpg::new(Regular::AugmentedSac, &lifting(0.0, 4), &spec, &d, &[seed]);
    let mut augmented = SacAgent::new(InputView::Augmented, &spec, &hyper, &d, seed);
    let mut bpql = Bpql::new(&spec, &hyper, &d, seed);
    for step in 0..4 {
        let b = batch(&spec, 32, 300 + step);
        update(&mut d2hpg_sac, &b);
        update(&mut augmented, &b);
        update(&mut bpql, &b);
    }
    let probe = batch(&spec, 8, 17);
    let acts = d2hpg_sac.act(&probe.augmented, 8, ActMode::Deterministic);
    assert_eq!(
        acts,
        augmented.act(&probe.augmented, 8, ActMode::Deterministic)
    );
    assert_ne!(acts, bpql.act(&probe.augmented, 8, ActMode::Deterministic));
}

/// Orthogonal initialisation (the authors' `orthogonal_`, gain 1): every layer of the actor and
/// the critics has orthonormal columns in its short direction (`WᵀW = I` for a layer with more
/// inputs than outputs, `WWᵀ = I` otherwise) and zero biases; burn's draw has neither.
#[test]
fn orthogonal_layers_are_orthonormal_with_zero_biases() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, d) = (spec(2), devices());
    let learner = |init: NetworkInit| {
        let hyper = SacConfig {
            network_init: init,
            ..SacConfig::default()
        };
        SacLearner::new(spec.augmented_dim(), spec.obs_dim, &spec, &hyper, &d, 5)
    };
    struct Layers(Vec<(Vec<usize>, Vec<f32>)>);
    impl burn::module::ModuleVisitor for Layers {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            self.0
                .push((param.val().dims().to_vec(), to_vec(param.val())));
        }
    }
    let layers = |l: &SacLearner| {
        let mut all = Layers(Vec::new());
        burn::module::Module::visit(&l.actor, &mut all);
        burn::module::Module::visit(&l.critic, &mut all);
        all.0
    };
    let orthonormal = |dims: &[usize], w: &[f32]| -> f64 {
        // The largest distance from the identity of the short direction's Gram matrix.
        let (input, output) = (dims[1], dims[2]);
        let (n, at): (usize, Box<dyn Fn(usize, usize) -> f64>) = if input >= output {
            (output, Box::new(|r, c| f64::from(w[r * output + c])))
        } else {
            (input, Box::new(|r, c| f64::from(w[c * output + r])))
        };
        let long = input.max(output);
        let mut worst: f64 = 0.0;
        for a in 0..n {
            for b in 0..n {
                let dot: f64 = (0..long).map(|r| at(r, a) * at(r, b)).sum();
                worst = worst.max((dot - if a == b { 1.0 } else { 0.0 }).abs());
            }
        }
        worst
    };
    let drawn = layers(&learner(NetworkInit::Orthogonal));
    assert_eq!(
        drawn.iter().filter(|(d, _)| d.len() == 3).count(),
        10,
        "4 actor and 2 × 3 critic layers"
    );
    for (dims, values) in &drawn {
        match dims.len() {
            3 => assert!(orthonormal(dims, values) < 1e-5, "layer {dims:?}"),
            2 => assert!(values.iter().all(|v| *v == 0.0), "bias {dims:?}"),
            _ => {}
        }
    }
    let default = layers(&learner(NetworkInit::Burn));
    assert!(
        default
            .iter()
            .any(|(d, v)| d.len() == 2 && v.iter().any(|b| *b != 0.0))
    );
    assert!(
        default
            .iter()
            .filter(|(d, _)| d.len() == 3)
            .any(|(d, v)| orthonormal(d, v) > 0.1)
    );
}
