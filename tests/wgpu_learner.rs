//! burn's wgpu learner (cargo feature `wgpu-learner`) against the CPU reference: every
//! algorithm's stacked updates agree with Flex's from the same networks and batches, and SAC
//! learns InvertedPendulum end to end on wgpu.
//!
//! They run on a real GPU adapter, or on a software one opted into with
//! `DHRL_WGPU_SOFTWARE=vulkan` (Mesa's lavapipe: what `scripts/test.sh`, and so CI, does);
//! without either they return early and say so, and `DHRL_REQUIRE_WGPU_LEARNER=1` (set by
//! `scripts/test.sh`) turns that into a failure so that nothing skips silently.
#![cfg(all(feature = "wgpu-learner", feature = "cli"))]

mod common;

use dhrl::algos::{ActMode, Agent, AgentSpec, AlgoSettings, UpdateContext, names, random_batch};
use dhrl::learn::{Devices, LearnDevice, SOFTWARE_WGPU, real_gpu_adapters};

/// One test on the device at a time: on a software adapter (Mesa's lavapipe spreads each
/// device's work over every core) three tests side by side took 688 s in CI against ~125 s
/// for two one after the other.
static DEVICE: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Whether a real GPU is there, or a software adapter was opted into with
/// `DHRL_WGPU_SOFTWARE`; without either the test returns early (or fails when required).
fn gpu_present(test: &str) -> bool {
    let (real, all) = real_gpu_adapters();
    if !real.is_empty() {
        eprintln!("{test}: running on {real:?}");
        return true;
    }
    if let Ok(api) = std::env::var(SOFTWARE_WGPU) {
        eprintln!(
            "{test}: running on a software {api} adapter ({SOFTWARE_WGPU}; wgpu sees {all:?})"
        );
        return true;
    }
    let message = format!("{test}: no real GPU adapter (wgpu sees {all:?})");
    assert!(
        std::env::var("DHRL_REQUIRE_WGPU_LEARNER").as_deref() != Ok("1"),
        "{message}, but DHRL_REQUIRE_WGPU_LEARNER=1"
    );
    eprintln!("{message}: skipped");
    false
}

/// The CPU and the wgpu devices.
fn both_devices() -> (Devices, Devices) {
    (
        Devices::new(LearnDevice::Cpu).unwrap(),
        Devices::new(LearnDevice::Wgpu).unwrap(),
    )
}

/// `algo`'s default settings, made small where it has the fields: VDPO's transformer one
/// block deep and its cloning stage two steps long (on a software adapter every new shape
/// costs kernel compilation). Dropout stays: its masks are drawn on the host, the same on
/// both devices.
fn small_settings(algo: &str) -> AlgoSettings {
    let mut settings = AlgoSettings::new(algo).unwrap();
    for assignment in ["belief_blocks=1", "bc_updates=2"] {
        let field = assignment.split('=').next().unwrap();
        if settings.fields().contains_key(field) {
            settings.set(assignment).unwrap();
        }
    }
    settings
}

fn spec(delay: usize) -> AgentSpec {
    AgentSpec {
        obs_dim: 5,
        act_dim: 2,
        delay,
        action_low: vec![-1.0, -3.0],
        action_high: vec![1.0, 3.0],
    }
}

/// `|a − b| ≤ tol·max(1, |a|)`.
fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(1.0)
}

/// Both action lists agree entry by entry to [`close`]'s 1e-3.
fn assert_actions_close(a: &[f32], b: &[f32], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: {a:?} vs {b:?}");
    assert!(
        a.iter()
            .zip(b)
            .all(|(x, y)| close(f64::from(*x), f64::from(*y), 1e-3)),
        "{what}: {a:?} vs {b:?}"
    );
}

/// The same agent on both devices (the CPU one's networks, optimisers and noise saved and
/// loaded onto the GPU), the same batches: the losses of every update, the deterministic and
/// sampled actions afterwards agree within 1e-3 (relative, or absolute below 1): the devices
/// sum in other orders (tiled GPU products against gemm's), which moves f32 results by
/// ~1e-6 per operation, and five Adam steps on tiny gradients amplify that. A wgpu agent
/// saved and loaded on the CPU acts as it did on wgpu (to the same tolerance).
/// Every algorithm as a stack of two runs on both devices (each run's networks, optimisers and
/// noise saved on the CPU and loaded onto the GPU; a solo run is the stack of one of the same
/// code): every run's statistics of two updates, each run on its own batches, agree within
/// 1e-3, the second update at 1,000 environment steps so that every stage runs and reports
/// (VDPO's reference actor and temperature and its cloning stage); so do each run's
/// deterministic and sampled actions, the delay-free policy's actions where there is one, and
/// the actions of runs saved on wgpu and loaded on the CPU.
#[test]
fn every_algorithm_stacked_updates_the_same_on_wgpu_as_on_cpu() {
    let _device = DEVICE.lock().unwrap_or_else(|e| e.into_inner());
    if !gpu_present("every_algorithm_stacked_updates_the_same_on_wgpu_as_on_cpu") {
        return;
    }
    let (cpu, gpu) = both_devices();
    for algo in names() {
        let settings = small_settings(algo);
        let spec = spec(if settings.info().undelayed_only { 0 } else { 3 });
        let mut on_cpu = settings.build_stack(&spec, &cpu, &[7, 8]);
        // The same seeds: VDPO's dropout streams are keyed on them (the rest is loaded).
        let mut on_gpu = settings.build_stack(&spec, &gpu, &[7, 8]);
        assert_eq!((on_cpu.runs(), on_gpu.runs()), (2, 2), "{algo}");
        let saved = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
        let dirs: Vec<&std::path::Path> = saved.iter().map(|d| d.path()).collect();
        on_cpu.save_runs(&dirs).unwrap();
        on_gpu.load_runs(&dirs).unwrap();
        for step in 0..2u64 {
            // 16 rows a run: the stacked products are what is checked, and on a software
            // adapter every row costs.
            let batches = [
                random_batch(&spec, 16, 100 + step),
                random_batch(&spec, 16, 200 + step),
            ];
            let update = |agent: &mut dyn Agent| {
                let mut contexts: Vec<UpdateContext> = batches
                    .iter()
                    .map(|batch| UpdateContext::fixed(batch, 1000 * step, step))
                    .collect();
                agent.update_runs(&mut contexts).unwrap().values()
            };
            let (a, b) = (update(on_cpu.as_mut()), update(on_gpu.as_mut()));
            assert_eq!(a.len(), 2, "{algo}: one set of statistics per run");
            assert_ne!(a[0], a[1], "{algo}: the runs' batches and networks differ");
            if step == 1 {
                let mut reported: Vec<&str> = a[0].iter().map(|(name, _)| *name).collect();
                let mut named = on_cpu.stat_names();
                reported.sort();
                named.sort();
                assert_eq!(
                    reported, named,
                    "{algo}: every stage ran in the second update"
                );
            }
            for (run, (a, b)) in a.iter().zip(&b).enumerate() {
                assert_eq!(a.len(), b.len(), "{algo}: {a:?} on CPU, {b:?} on wgpu");
                for ((name, x), (other, y)) in a.iter().zip(b) {
                    assert_eq!(name, other);
                    assert!(
                        close(*x, *y, 1e-3),
                        "{algo} run {run} update {step}: {name} {x} on CPU, {y} on wgpu"
                    );
                }
            }
        }
        let probe = random_batch(&spec, 16, 9);
        let from_gpu = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
        let dirs: Vec<&std::path::Path> = from_gpu.iter().map(|d| d.path()).collect();
        on_gpu.save_runs(&dirs).unwrap();
        let mut reloaded = settings.build_stack(&spec, &cpu, &[3, 4]);
        reloaded.load_runs(&dirs).unwrap();
        for run in 0..2 {
            let act =
                |agent: &mut Box<dyn Agent>, mode| agent.act_run(run, &probe.augmented, 16, mode);
            for mode in [ActMode::Deterministic, ActMode::Explore] {
                // Sampled actions: the noise is drawn on the host from each run's stream.
                let (a, b) = (act(&mut on_cpu, mode), act(&mut on_gpu, mode));
                assert_eq!(
                    (a.len(), b.len()),
                    (16 * 2, 16 * 2),
                    "{algo}: an action a row"
                );
                assert_actions_close(&a, &b, &format!("{algo} run {run}: {mode:?} on CPU, wgpu"));
            }
            let (a, b) = (
                act(&mut on_gpu, ActMode::Deterministic),
                act(&mut reloaded, ActMode::Deterministic),
            );
            assert_actions_close(
                &a,
                &b,
                &format!("{algo} run {run}: on wgpu, saved and loaded on the CPU"),
            );
        }
        // Both runs in one pass, run 1 acting for half its rows.
        let both = [probe.augmented.as_slice(), probe.augmented.as_slice()].concat();
        for mode in [ActMode::Deterministic, ActMode::Explore] {
            let act = |agent: &mut Box<dyn Agent>| agent.act_runs(&both, &[16, 8], 16, mode);
            let (a, b) = (act(&mut on_cpu), act(&mut on_gpu));
            let acted = |actions: &[f32]| [&actions[..32], &actions[32..48]].concat();
            assert_actions_close(
                &acted(&a),
                &acted(&b),
                &format!("{algo}: {mode:?} in one pass of both runs on CPU, wgpu"),
            );
        }
        let learns_delay_free = settings.info().delay_free_policy;
        let (reference, free) = (
            on_cpu.act_delay_free(&probe.state, 16),
            on_gpu.act_delay_free(&probe.state, 16),
        );
        assert_eq!(
            (reference.is_some(), free.is_some()),
            (learns_delay_free, learns_delay_free),
            "{algo}: a delay-free policy on CPU and on wgpu exactly where one is learned"
        );
        if let (Some(reference), Some(free)) = (reference, free) {
            assert_actions_close(
                &reference,
                &free,
                &format!("{algo}: delay-free actions on CPU, on wgpu"),
            );
        }
    }
}

/// `dhrl train --device wgpu` learns: SAC on InvertedPendulum beats a random policy's ~10
/// (the CPU twin of this test is in tests/train.rs).
#[test]
fn sac_learns_inverted_pendulum_on_wgpu() {
    let _device = DEVICE.lock().unwrap_or_else(|e| e.into_inner());
    if !gpu_present("sac_learns_inverted_pendulum_on_wgpu") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    common::train(
        &[
            "--task",
            "inverted-pendulum",
            "--algo",
            "sac",
            "--device",
            "wgpu",
            "--steps",
            "2000",
            "--warmup-steps",
            "500",
            "--batch-size",
            "64",
            "--eval-every",
            "500",
            "--eval-episodes",
            "5",
            "--seed",
            "1",
        ],
        &run,
    );
    let (best, text) = common::best_return(&run);
    assert!(
        best > 50.0,
        "SAC on wgpu: best evaluation return {best}, a random policy's ~10\n{text}"
    );
    assert!(
        std::fs::read_to_string(run.join("config.toml"))
            .unwrap()
            .contains("device = \"wgpu\"")
    );
}
