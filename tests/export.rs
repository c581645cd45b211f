//! `dhrl export`: every algorithm's policy leaves as ONNX, safetensors and a manifest, and the
//! runtime reproduces training's x_t and actions on a recorded stretch of the task (the
//! export itself checks that, decision by decision, and fails otherwise).
mod common;

use std::path::Path;

use dhrl::deploy::PolicyManifest;
use dhrl::export::{CHECK_FILE, MANIFEST_FILE, ONNX_FILE, OPSET, SAFETENSORS_FILE};
use onnx_protobuf::{Message, ModelProto};

use common::dhrl;

/// A run of a few dozen updates (what is exported need not have learned anything).
fn tiny_run(dir: &Path, algo: &str, task: &str, delay: &[&str]) -> std::path::PathBuf {
    let run = dir.join(format!("{algo}-{task}"));
    let mut args = vec![
        "--task",
        task,
        "--algo",
        algo,
        "--steps",
        "60",
        "--warmup-steps",
        "30",
        "--batch-size",
        "16",
        "--eval-every",
        "60",
        "--eval-episodes",
        "1",
    ];
    args.extend_from_slice(delay);
    common::train(&args, &run);
    run
}

#[test]
fn every_algorithm_exports_and_the_runtime_reproduces_training() {
    let dir = tempfile::tempdir().unwrap();
    let undelayed = dhrl::algos::names_where(|info| info.undelayed_only);
    for (i, name) in dhrl::algos::names().into_iter().enumerate() {
        let undelayed_only = undelayed.contains(&name);
        // Random delays (the conservative agent) on HalfCheetah, or observation and action
        // delays on InvertedPendulum: Δ = 3 either way.
        let (task, delay): (&str, &[&str]) = if undelayed_only {
            ("inverted-pendulum", &[])
        } else if i % 2 == 0 {
            ("half-cheetah", &["--random-delay", "--max-delay", "3"])
        } else {
            (
                "inverted-pendulum",
                &["--delay", "2", "--action-delay", "1"],
            )
        };
        let run = tiny_run(dir.path(), name, task, delay);
        let out = dir.path().join(format!("{name}-export"));
        let done = dhrl(&[
            "export",
            run.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            done.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&done.stderr)
        );
        let stdout = String::from_utf8_lossy(&done.stdout);
        assert!(stdout.contains("(1000 by the policy)"), "{name}: {stdout}");

        let manifest = PolicyManifest::read(&out.join(MANIFEST_FILE)).unwrap();
        let total = if undelayed_only { 0 } else { 3 };
        assert_eq!(manifest.algorithm, name);
        assert_eq!(manifest.delay.total, total, "{name}");
        assert_eq!(manifest.warmup.steps, total);
        let (obs, act) = (manifest.observation_dim, manifest.action_dim);
        assert_eq!(manifest.augmented_state.width, obs + total * act);
        assert_eq!(manifest.augmented_state.action_columns.len(), total);
        assert_eq!(manifest.run.steps, 60);

        // The ONNX model: opset, one input of x_t's width, three outputs of the action size.
        let model =
            ModelProto::parse_from_bytes(&std::fs::read(out.join(ONNX_FILE)).unwrap()).unwrap();
        assert_eq!(model.opset_import[0].version, OPSET);
        let graph = model.graph.as_ref().unwrap();
        let width = |info: &onnx_protobuf::ValueInfoProto| {
            info.type_.tensor_type().shape.dim[1].dim_value()
        };
        assert_eq!(graph.input.len(), 1);
        assert_eq!(
            width(&graph.input[0]) as usize,
            manifest.augmented_state.width
        );
        let outputs: Vec<&str> = graph.output.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(outputs, manifest.files.onnx_outputs);
        assert!(graph.output.iter().all(|o| width(o) as usize == act));

        // The safetensors hold exactly the manifest's parameters, shapes included.
        let bytes = std::fs::read(out.join(SAFETENSORS_FILE)).unwrap();
        let weights = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        assert_eq!(weights.len(), manifest.network.parameters.len(), "{name}");
        for parameter in &manifest.network.parameters {
            let tensor = weights.tensor(&parameter.name).unwrap();
            assert_eq!(
                tensor.shape(),
                parameter.shape.as_slice(),
                "{}",
                parameter.name
            );
        }
        let policy_mean = weights.tensor("policy.mean.weight").unwrap();
        assert_eq!(policy_mean.shape(), [act, 256], "PyTorch's [out, in]");

        let check = std::fs::read(out.join(CHECK_FILE)).unwrap();
        let check = safetensors::SafeTensors::deserialize(&check).unwrap();
        assert_eq!(
            check.tensor("augmented_state").unwrap().shape(),
            [1000, manifest.augmented_state.width]
        );
    }
}

#[test]
fn export_of_a_folder_without_a_run_says_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let done = dhrl(&["export", dir.path().to_str().unwrap()]);
    assert!(!done.status.success());
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert!(stderr.contains("config.toml"), "{stderr}");
}

/// A policy on s_{t−Δ} alone (naive SAC) evaluated at another Δ than it trained with acts on
/// each row of the wider x_t as on that row alone (it used to split the rows by the trained Δ).
#[test]
fn a_policy_on_the_last_observation_acts_row_by_row_at_another_delay() {
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run(
        dir.path(),
        "naive-sac",
        "inverted-pendulum",
        &["--delay", "1"],
    );
    let mut saved = dhrl::train::load_saved(&run, Some(3)).unwrap();
    let width = 4 + 3;
    let rows: Vec<f32> = (0..2 * width).map(|i| (i as f32 * 0.37).sin()).collect();
    let mode = dhrl::algos::ActMode::Deterministic;
    let both = saved.agent.act(&rows, 2, mode);
    let first = saved.agent.act(&rows[..width], 1, mode);
    let second = saved.agent.act(&rows[width..], 1, mode);
    assert_eq!(both, [first, second].concat());
    let done = dhrl(&[
        "eval",
        run.to_str().unwrap(),
        "--delay",
        "3",
        "--episodes",
        "2",
    ]);
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
}
