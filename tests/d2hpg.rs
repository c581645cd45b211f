//! BPQL and D2HPG: the lifting loss by hand, its gradient reaching the regular policy only,
//! D2HPG without lifting being exactly BPQL beside an independent delay-free SAC, and both
//! learning a small delayed task.
mod common;

use std::process::Command;
use std::sync::Mutex;

use burn::optim::GradientsParams;
use burn::prelude::*;
use dhrl::algos::{
    ActMode, Agent, AgentSpec, Bpql, D2hpg, Hyper, InputView, Lifting, Regular, SacAgent,
    delay_free_seed, random_batch,
};
use dhrl::delay::Transitions;
use dhrl::learn::{ActionScale, Devices, GaussianPolicy, LearnDevice, Noise, lifting_loss, to_vec};

/// burn's generator is process-wide: networks built by concurrent tests would interleave draws.
static BUILD: Mutex<()> = Mutex::new(());

fn devices() -> Devices {
    Devices::new(LearnDevice::Cpu).unwrap()
}

/// `[K, B, A]` actions: K samples of a batch of B states.
fn actions(values: Vec<f32>, k: usize, b: usize, a: usize, device: &Device) -> Tensor<3> {
    Tensor::from_data(TensorData::new(values, [k, b, a]), device)
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

#[test]
fn lifting_gradient_reaches_the_regular_policy_only() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let d = devices();
    let (obs, aug, act, b, k) = (3, 7, 2, 4, 5);
    let regular = GaussianPolicy::new(aug, act, &d.train);
    let delay_free = GaussianPolicy::new(obs, act, &d.train);
    let scale = ActionScale::new(&[-1.0, -1.0], &[1.0, 1.0], &d.plain);
    let mut noise = Noise::new(1);
    let x = noise.normal(b, aug, &d.plain);
    let s = noise.normal(b, obs, &d.plain);
    let target = delay_free
        .valid()
        .sample_k(s, noise.normal3(k, b, act, &d.plain), &scale);
    let loss = lifting_loss(
        regular.sample_k(x, noise.normal3(k, b, act, &d.plain), &scale),
        target,
    );
    let mut grads = loss.backward();
    assert!(
        !GradientsParams::from_module(&mut grads, &regular).is_empty(),
        "the regular policy is pulled"
    );
    assert!(
        GradientsParams::from_module(&mut grads, &delay_free).is_empty(),
        "the delay-free side is a fixed target"
    );
}

fn spec(delay: usize) -> AgentSpec {
    AgentSpec {
        obs_dim: 3,
        act_dim: 2,
        delay,
        action_low: vec![-1.0, -2.0],
        action_high: vec![1.0, 2.0],
    }
}

fn batch(spec: &AgentSpec, n: usize, seed: u64) -> Transitions {
    random_batch(spec, n, seed)
}

#[test]
fn bpql_actor_reads_x_and_its_critic_reads_s() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let spec = spec(4);
    let mut bpql = Bpql::new(&spec, &Hyper::default(), &devices(), 3);
    // The actor takes obs + 4·act = 11 inputs, the beta critic obs + act = 5: an update with the
    // inputs swapped would not even run.
    let stats = bpql.update(&batch(&spec, 16, 1));
    assert!(stats.iter().all(|(_, v)| v.is_finite()), "{stats:?}");
    let acts = bpql.act(&batch(&spec, 2, 2).augmented, 2, ActMode::Deterministic);
    assert_eq!(acts.len(), 4);
    assert!(
        acts.chunks(2)
            .all(|a| a[0].abs() <= 1.0 && a[1].abs() <= 2.0),
        "{acts:?}"
    );
}

#[test]
fn d2hpg_without_lifting_is_bpql_beside_an_independent_delay_free_sac() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, hyper, d, seed) = (spec(3), Hyper::default(), devices(), 11);
    let off = Lifting {
        weight: 0.0,
        samples: 4,
    };
    let mut d2hpg = D2hpg::new(Regular::Bpql, off, &spec, &hyper, &d, seed);
    let mut bpql = Bpql::new(&spec, &hyper, &d, seed);
    let mut delay_free = SacAgent::new(
        InputView::TrueState,
        &spec,
        &hyper,
        &d,
        delay_free_seed(seed),
    );
    for step in 0..4 {
        let b = batch(&spec, 32, 100 + step);
        d2hpg.update(&b);
        bpql.update(&b);
        delay_free.update(&b);
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
    let mut lifted = D2hpg::new(
        Regular::Bpql,
        Lifting {
            weight: 10.0,
            samples: 4,
        },
        &spec,
        &hyper,
        &d,
        seed,
    );
    for step in 0..4 {
        lifted.update(&batch(&spec, 32, 100 + step));
    }
    assert_ne!(
        lifted.act(&probe.augmented, 8, ActMode::Deterministic),
        regular
    );
}

#[test]
fn d2hpg_naive_moves_its_regular_policy_toward_the_delay_free_one() {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let (spec, hyper, d) = (spec(2), Hyper::default(), devices());
    // Two agents from the same seed: their delay-free learners take the same steps, so the
    // lifting loss of the one with λ = 0 (a regular policy left where it started) is the
    // yardstick for how far the lifted one has closed in.
    let lifting_after = |weight: f64| {
        let lifting = Lifting { weight, samples: 8 };
        let mut agent = D2hpg::new(Regular::LiftingOnly, lifting, &spec, &hyper, &d, 5);
        let b = batch(&spec, 64, 9);
        let mut stats = agent.update(&b);
        for _ in 0..300 {
            stats = agent.update(&b);
        }
        stats.iter().find(|(n, _)| *n == "lifting_loss").unwrap().1
    };
    let (pulled, left) = (lifting_after(1.0), lifting_after(0.0));
    assert!(
        pulled < 0.25 * left,
        "lifting loss after 300 updates: {pulled} with λ = 1, {left} with λ = 0"
    );
}

/// The return of a uniform random policy on InvertedPendulum (the same with or without delay),
/// measured with `dhrl rollout` from small random initial states: 20 episodes.
fn random_policy_return() -> f64 {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(77);
    let dir = tempfile::tempdir().unwrap();
    let (state, actions) = (
        dir.path().join("state.json"),
        dir.path().join("actions.csv"),
    );
    let mut total = 0.0;
    for _ in 0..20 {
        let q: Vec<f64> = (0..4).map(|_| rng.random_range(-0.01..0.01)).collect();
        std::fs::write(
            &state,
            format!(
                r#"{{"qpos": [{}, {}], "qvel": [{}, {}]}}"#,
                q[0], q[1], q[2], q[3]
            ),
        )
        .unwrap();
        let text: String = (0..1000)
            .map(|_| format!("{}\n", rng.random_range(-3.0..3.0)))
            .collect();
        std::fs::write(&actions, text).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(["rollout", "--task", "inverted-pendulum", "--init-state"])
            .arg(&state)
            .arg("--actions")
            .arg(&actions)
            .output()
            .unwrap();
        assert!(out.status.success());
        total += (String::from_utf8(out.stdout).unwrap().lines().count() - 1) as f64; // reward 1 per step
    }
    total / 20.0
}

/// End to end on a small delayed task: InvertedPendulum with Δ = 3.
#[test]
fn bpql_and_d2hpg_clearly_beat_a_random_policy_under_delay() {
    let random = random_policy_return();
    assert!(
        random > 1.0 && random < 50.0,
        "random policy return {random}"
    );
    for algo in ["bpql", "d2hpg"] {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        common::train(
            &[
                "--task",
                "inverted-pendulum",
                "--algo",
                algo,
                "--delay",
                "3",
                "--steps",
                "4000",
                "--warmup-steps",
                "500",
                "--eval-every",
                "1000",
                "--eval-episodes",
                "5",
                "--batch-size",
                "128",
                "--seed",
                "2",
            ],
            &run,
        );
        let (best, text) = common::best_return(&run);
        assert!(
            best > 4.0 * random,
            "{algo}: best evaluation return {best}, a random policy's {random:.1}\n{text}"
        );
    }
}
