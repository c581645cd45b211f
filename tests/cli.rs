//! The command line: bad input is a clear error (exit code 2 for usage, 1 otherwise), never a panic.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;
use std::path::Path;
use std::process::{Command, Output};

use common::dhrl;

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

/// Runs `dhrl rollout` on inverted-pendulum (nq = nv = 2, one action dimension).
fn rollout(state: &str, actions: &str) -> Output {
    rollout_with(state, actions, &[])
}

/// [`rollout`] with `extra` options.
fn rollout_with(state: &str, actions: &str, extra: &[&str]) -> Output {
    let dir = tempfile::tempdir().unwrap();
    let state = write(dir.path(), "state.json", state);
    let actions = write(dir.path(), "actions.csv", actions);
    let mut args = vec![
        "rollout",
        "--task",
        "inverted-pendulum",
        "--init-state",
        &state,
        "--actions",
        &actions,
    ];
    args.extend_from_slice(extra);
    dhrl(&args)
}

fn assert_error(out: &Output, needle: &str) {
    assert_eq!(out.status.code(), Some(1), "{}", stderr(out));
    assert!(
        stderr(out).contains(needle),
        "expected '{needle}' in: {}",
        stderr(out)
    );
    assert!(!stderr(out).contains("panicked"), "{}", stderr(out));
}

#[test]
fn rollout_prints_one_json_object_per_step_and_stops_at_the_end() {
    let out = rollout(
        r#"{"qpos": [0.0, 0.19], "qvel": [0.0, 1.0]}"#,
        "0.0\n0.0\n0.0\n0.0\n0.0\n0.0\n0.0\n0.0\n0.0\n0.0\n",
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let lines: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        lines[0],
        serde_json::json!({"t": 0, "obs": [0.0, 0.19, 0.0, 1.0]})
    );
    let last = lines.last().unwrap();
    assert_eq!(
        last["terminated"], true,
        "the pole starts falling past 0.2 rad"
    );
    assert!(
        lines.len() < 11,
        "stops after the step that ends the episode"
    );
    for (t, line) in lines.iter().enumerate().skip(1) {
        assert_eq!(line["t"], t);
        assert_eq!(line["reward"], 1.0);
        assert_eq!(line["truncated"], false);
    }
}

#[test]
fn rollout_rejects_wrong_state_dimensions() {
    assert_error(
        &rollout(r#"{"qpos": [0.0], "qvel": [0.0, 0.0]}"#, "0\n"),
        "qpos has length 1, expected 2",
    );
    assert_error(
        &rollout(r#"{"qpos": [0.0, 0.0]}"#, "0\n"),
        "missing field `qvel`",
    );
}

#[test]
fn rollout_rejects_non_finite_numbers() {
    assert_error(
        &rollout(r#"{"qpos": [0.0, 1e999], "qvel": [0.0, 0.0]}"#, "0\n"),
        "not a state file",
    );
    assert_error(
        &rollout(r#"{"qpos": [0.0, 0.0], "qvel": [0.0, 0.0]}"#, "0.1\nNaN\n"),
        "line 2: value NaN is not finite",
    );
    assert_error(
        &rollout(r#"{"qpos": [0.0, 0.0], "qvel": [0.0, 0.0]}"#, "inf\n"),
        "line 1: value inf is not finite",
    );
}

#[test]
fn rollout_rejects_wrong_action_width_and_garbage() {
    let state = r#"{"qpos": [0.0, 0.0], "qvel": [0.0, 0.0]}"#;
    assert_error(
        &rollout(state, "0.1\n0.1,0.2\n"),
        "line 2: 2 values, but inverted-pendulum takes actions of 1",
    );
    assert_error(
        &rollout(state, "0.1\nabc\n"),
        "line 2: 'abc' is not a number",
    );
}

#[test]
fn unknown_task_lists_valid_names() {
    let out = dhrl(&[
        "rollout",
        "--task",
        "cheetah",
        "--init-state",
        "x",
        "--actions",
        "y",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let msg = stderr(&out);
    for name in [
        "ant",
        "half-cheetah",
        "hopper",
        "walker2d",
        "humanoid",
        "inverted-pendulum",
    ] {
        assert!(msg.contains(name), "{msg}");
    }
}

#[test]
fn bench_env_json_has_the_anchor_side_by_side() {
    let out = dhrl(&[
        "bench",
        "env",
        "--task",
        "inverted-pendulum",
        "--envs",
        "8",
        "--threads",
        "2",
        "--steps",
        "5",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let ours = report["env_steps_per_sec"].as_f64().unwrap();
    assert!(ours > 0.0);
    // Each anchor beside its ratio: one copy hot, all copies on one thread, and the ceiling
    // (two loops at once, each over its four copies).
    for (anchor, ratio) in [
        ("raw_env_steps_per_sec", "ratio"),
        ("raw_batch_env_steps_per_sec", "ratio_to_raw_batch"),
        ("raw_parallel_env_steps_per_sec", "ratio_to_raw_parallel"),
    ] {
        let (raw, ratio) = (
            report[anchor].as_f64().unwrap(),
            report[ratio].as_f64().unwrap(),
        );
        assert!(raw.is_finite() && raw > 0.0, "{anchor}: {raw}");
        assert!((ratio - ours / raw).abs() < 1e-9 * ratio, "{anchor}");
    }
}

fn trace(args: &[&str]) -> String {
    let out = dhrl(args);
    assert!(out.status.success(), "{}", stderr(&out));
    String::from_utf8(out.stdout).unwrap()
}

/// `dhrl rollout --delay ...` checked by an outside script against the undelayed trace of the
/// same state and actions (Hopper, which falls: episodes end before and after Δ steps). The
/// delayed trace runs the training path (`DelayedBatch`, f32 actions), so the actions are
/// f32 values and both traces step the same physics. With the delay layer on the GPU (the
/// WGSL kernels; Mesa's software Vulkan in CI) every trace is the CPU layer's, byte for byte.
#[test]
fn delayed_rollout_passes_the_outside_check() {
    let dir = tempfile::tempdir().unwrap();
    let state = write(
        dir.path(),
        "state.json",
        r#"{"qpos": [0, 1.25, 0.01, 0, 0, 0], "qvel": [0, 0, 0, 0, 0, 0]}"#,
    );
    let actions: String = (0..300)
        .map(|k| {
            format!(
                "{},{},{}\n",
                ((k * 37) % 17) as f64 / 8.0 - 1.0,
                0.75,
                -0.625
            )
        })
        .collect();
    let actions = write(dir.path(), "actions.csv", &actions);
    let base = [
        "rollout",
        "--task",
        "hopper",
        "--init-state",
        &state,
        "--actions",
        &actions,
    ];
    let undelayed_text = trace(&base);
    let undelayed = write(dir.path(), "undelayed.jsonl", &undelayed_text);
    // The episode must end by falling, between the short delays and the longest one, so that
    // episodes end both after and before Δ steps.
    let steps = undelayed_text.lines().count() - 1;
    let last: serde_json::Value =
        serde_json::from_str(undelayed_text.lines().last().unwrap()).unwrap();
    assert_eq!(last["terminated"], true, "the Hopper falls: {last}");
    assert!(
        (8..60).contains(&steps),
        "the Hopper fell after {steps} steps"
    );
    let cases: [(&str, Option<&str>, &[&str]); 6] = [
        ("0", None, &["--delay", "0"]),
        ("3", None, &["--delay", "3"]),
        ("7", None, &["--delay", "7"]),
        ("5", None, &["--delay", "2", "--action-delay", "3"]),
        (
            "4",
            Some("4"),
            &["--random-delay", "--max-delay", "4", "--seed", "9"],
        ),
        ("60", None, &["--delay", "60"]),
    ];
    let gpu = std::env::var("DHRL_SKIP_GPU_TESTS").as_deref() != Ok("1");
    if !gpu {
        eprintln!("SKIPPED (DHRL_SKIP_GPU_TESTS=1): the delayed traces on the GPU delay layer");
    }
    for (delay, random_bound, options) in cases {
        let mut args = base.to_vec();
        args.extend_from_slice(options);
        let text = trace(&args);
        if gpu {
            args.extend_from_slice(&["--delay-device", "gpu"]);
            assert_eq!(
                trace(&args),
                text,
                "Δ {delay} {options:?}: GPU layer ≠ CPU layer"
            );
        }
        let delayed = write(dir.path(), "delayed.jsonl", &text);
        let mut check = vec![
            "--delay",
            delay,
            "--undelayed",
            &undelayed,
            "--delayed",
            &delayed,
            "--actions",
            &actions,
        ];
        if let Some(bound) = random_bound {
            check.extend_from_slice(&["--random-bound", bound]);
        }
        let out = Command::new(env!("DHRL_PYTHON"))
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check_delayed_trace.py"))
            .args(&check)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "Δ {delay} {options:?}: {}",
            stderr(&out)
        );
        let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert!(
            summary["ended"].as_bool().unwrap(),
            "the Hopper episode must end: {summary}"
        );
        if delay != "60" {
            assert!(
                summary["augmented_checked"].as_u64().unwrap() > 5,
                "{summary}"
            );
        }
        if random_bound.is_some() {
            // The checker verified every arrival; here: they were really random.
            assert!(
                summary["out_of_order"].as_u64().unwrap() > 0,
                "random delays never reordered observations: {summary}"
            );
            for age in 1..=4 {
                assert!(
                    summary["ages"][age.to_string()].as_u64().unwrap() > 0,
                    "no observation arrived {age} steps old: {summary}"
                );
            }
        }
    }
}

#[test]
fn bad_delay_options_are_clear_errors() {
    let state = r#"{"qpos": [0.0, 0.0], "qvel": [0.0, 0.0]}"#;
    let run = |extra: &[&str]| rollout_with(state, "0\n", extra);
    assert_error(
        &run(&["--delay", "-2"]),
        "--delay must be a whole number of steps ≥ 0, got -2",
    );
    assert_error(&run(&["--random-delay"]), "needs its bound");
    assert_error(&run(&["--delay", "200"]), "above the supported maximum 64");
    assert_error(
        &run(&["--actuator-noise", "-1"]),
        "actuator noise σ must be a finite number ≥ 0",
    );
}
