//! Stacked learners: S runs in one set of tensors compute, slice by slice, what each run
//! computes alone — bit for bit on burn's CPU backend — and store each slice as a solo run.
// Needs tests/common's helpers, which run the `dhrl` program: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::optim::GradientsParams;
use burn::prelude::*;
use burn::tensor::activation::relu;
use common::{parameters, small_spec};
use dhrl::algos::{ActMode, AgentSpec, RunStats, SacBatch, SacConfig, SacLearner, random_batch};
use dhrl::delay::Transitions;
use dhrl::learn::{Devices, LearnDevice, StackedLinear, TransitionTensors, stack, to_vec};

fn devices() -> Devices {
    Devices::new(LearnDevice::Cpu).unwrap()
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

/// Deterministic inputs `[rows, cols]` in [−1, 1).
fn inputs(rows: usize, cols: usize, seed: u64, device: &Device) -> Tensor<2> {
    let values: Vec<f32> = (0..rows * cols)
        .map(|i| ((i as u64 * 2_654_435_761 + seed * 97) % 1000) as f32 / 500.0 - 1.0)
        .collect();
    Tensor::from_data(TensorData::new(values, [rows, cols]), device)
}

/// A stacked layer pair is burn's `Linear` pair run by run: the same draws for the same seed,
/// and, for each of three runs, the same outputs and gradients to the last bit.
#[test]
fn stacked_layers_compute_each_runs_solo_values_and_gradients_bit_for_bit() {
    let d = devices();
    let seeds = [10u64, 11, 12];
    let solo: Vec<(Linear, Linear)> = seeds
        .iter()
        .map(|&seed| {
            d.train.seed(seed);
            let pair = (
                LinearConfig::new(7, 256).init(&d.train),
                LinearConfig::new(256, 3).init(&d.train),
            );
            for layer in [&pair.0, &pair.1] {
                // burn draws a layer's weight, then its bias, when first read.
                let _ = (
                    layer.weight.val(),
                    layer.bias.as_ref().map(|bias| bias.val()),
                );
            }
            pair
        })
        .collect();
    let (first, second): (Vec<StackedLinear>, Vec<StackedLinear>) = seeds
        .iter()
        .map(|&seed| {
            d.train.seed(seed);
            (
                StackedLinear::new(7, 256, &d.train),
                StackedLinear::new(256, 3, &d.train),
            )
        })
        .unzip();
    let (first, second) = (stack(first), stack(second));
    assert_eq!(first.weight.val().dims(), [3, 7, 256]);
    assert_eq!(first.bias.val().dims(), [3, 256]);

    let x: Vec<Tensor<2>> = (0..3).map(|i| inputs(64, 7, i, &d.train)).collect();
    let y = second.forward(relu(first.forward(Tensor::stack(x.clone(), 0))));
    // Each run's mean over its batch, summed over the stack.
    let loss = y.clone().square().mean_dim(1).mean_dim(2).sum();
    let stacked_grads = GradientsParams::from_grads(loss.backward(), &first);
    for (i, (l1, l2)) in solo.iter().enumerate() {
        let y_solo = l2.forward(relu(l1.forward(x[i].clone())));
        assert_eq!(
            bits(&to_vec(y_solo.clone().inner())),
            bits(&to_vec(y.clone().inner().slice(i..i + 1))),
            "run {i}'s outputs"
        );
        let solo_grads = GradientsParams::from_grads(y_solo.square().mean().backward(), l1);
        let weight: Tensor<2> = solo_grads.get(l1.weight.id).unwrap();
        let stacked: Tensor<3> = stacked_grads.get(first.weight.id).unwrap();
        assert_eq!(
            bits(&to_vec(weight)),
            bits(&to_vec(stacked.slice(i..i + 1))),
            "run {i}'s weight gradient"
        );
        let bias: Tensor<1> = solo_grads.get(l1.bias.as_ref().unwrap().id).unwrap();
        let stacked: Tensor<2> = stacked_grads.get(first.bias.id).unwrap();
        assert_eq!(
            bits(&to_vec(bias)),
            bits(&to_vec(stacked.slice(i..i + 1))),
            "run {i}'s bias gradient"
        );
    }
}

/// 32 random transitions of each of `seeds`.
fn transitions(spec: &AgentSpec, seeds: impl Iterator<Item = u64>) -> Vec<Transitions> {
    seeds.map(|seed| random_batch(spec, 32, seed)).collect()
}

/// The runs' batches for SAC on the true state.
fn on_state(batches: &[Transitions], d: &Devices) -> SacBatch {
    let t = TransitionTensors::stacked(batches, &d.plain);
    SacBatch::new(
        &t,
        (t.state.clone(), t.next_state.clone()),
        (t.state.clone(), t.next_state.clone()),
    )
}

fn learner_parameters(learner: &SacLearner) -> Vec<Vec<f32>> {
    vec![
        parameters(&learner.actor),
        parameters(&learner.critic),
        parameters(&learner.target),
        parameters(&learner.temperature),
    ]
}

/// Every parameter of run `slice` of a stacked module: each `[S, …]` tensor cut at `slice`.
fn slice_of<M: Module>(module: &M, slice: usize) -> Vec<f32> {
    struct Cut(Vec<f32>, usize);
    impl burn::module::ModuleVisitor for Cut {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            self.0.extend(to_vec(param.val().slice(self.1..self.1 + 1)));
        }
    }
    let mut cut = Cut(Vec::new(), slice);
    module.visit(&mut cut);
    cut.0
}

/// Run `slice`'s actor, critic, target and temperature.
fn slice_parameters(learner: &SacLearner, slice: usize) -> Vec<Vec<f32>> {
    vec![
        slice_of(&learner.actor, slice),
        slice_of(&learner.critic, slice),
        slice_of(&learner.target, slice),
        slice_of(&learner.temperature, slice),
    ]
}

/// A stack of three SAC learners (seeds 3, 5, 7), each fed its own batches, computes every
/// logged number, action and parameter of the three solo learners bit for bit, over updates
/// that move the temperature, the targets and each run's noise stream.
#[test]
fn a_stack_of_three_sac_learners_is_three_solo_learners_bit_for_bit() {
    let (spec, d) = (small_spec(0), devices());
    let hyper = SacConfig::default();
    let seeds = [3u64, 5, 7];
    let (obs, updates) = (spec.obs_dim, 4);
    let mut stack_learner = SacLearner::stacked(obs, obs, &spec, &hyper, &d, &seeds);
    let mut solos: Vec<SacLearner> = seeds
        .iter()
        .map(|&seed| SacLearner::new(obs, obs, &spec, &hyper, &d, seed))
        .collect();
    for i in 0..3 {
        assert_eq!(
            slice_parameters(&stack_learner, i),
            learner_parameters(&solos[i]),
            "run {i} is drawn as its solo learner"
        );
    }
    assert_ne!(
        learner_parameters(&solos[0])[0],
        learner_parameters(&solos[1])[0],
        "the seeds draw different networks"
    );
    for update in 0..updates {
        let batches = transitions(&spec, seeds.iter().map(|&seed| seed * 100 + update));
        let stats = stack_learner.update(&on_state(&batches, &d)).values();
        let solo_stats: Vec<RunStats> = solos
            .iter_mut()
            .zip(&batches)
            .map(|(learner, batch)| {
                let stats = learner.update(&on_state(std::slice::from_ref(batch), &d));
                stats.values().remove(0)
            })
            .collect();
        assert_eq!(stats, solo_stats, "update {update}'s statistics");
    }
    assert_ne!(
        stack_learner.temperature.alphas()[0],
        hyper.initial_alpha,
        "the updates moved α"
    );
    for i in 0..3 {
        assert_eq!(
            slice_parameters(&stack_learner, i),
            learner_parameters(&solos[i]),
            "run {i}'s parameters after {updates} updates"
        );
    }
    // Acting: each run's rows through its own policy and noise stream.
    let states: Vec<f32> = (0..3 * 2 * obs).map(|i| (i as f32 * 0.37).sin()).collect();
    for mode in [ActMode::Deterministic, ActMode::Explore] {
        for (i, solo) in solos.iter_mut().enumerate() {
            let rows = &states[i * 2 * obs..(i + 1) * 2 * obs];
            assert_eq!(
                bits(&stack_learner.act_run(i, rows, 2, obs, mode)),
                bits(&solo.act_run(0, rows, 2, obs, mode)),
                "run {i}'s {mode:?} actions"
            );
        }
    }
    // Acting in one pass for the whole stack, as training does: run i acts for its first
    // counts[i] rows of two (the others padding) as its solo learner does given the same rows.
    let counts = [2, 1, 0];
    for mode in [ActMode::Deterministic, ActMode::Explore] {
        let together = stack_learner.act_runs(&states, &counts, 2, obs, mode);
        for (i, solo) in solos.iter_mut().enumerate() {
            let rows = &states[i * 2 * obs..(i + 1) * 2 * obs];
            let alone = solo.act_runs(rows, &counts[i..=i], 2, obs, mode);
            let act = spec.act_dim;
            assert_eq!(
                bits(&together[i * 2 * act..(i * 2 + counts[i]) * act]),
                bits(&alone[..counts[i] * act]),
                "run {i}'s {mode:?} actions in one pass of the stack"
            );
        }
    }
    // The streams moved alike: the next draws agree too.
    for (i, solo) in solos.iter_mut().enumerate() {
        let rows = &states[i * 2 * obs..(i + 1) * 2 * obs];
        assert_eq!(
            bits(&stack_learner.act_run(i, rows, 2, obs, ActMode::Explore)),
            bits(&solo.act_run(0, rows, 2, obs, ActMode::Explore)),
            "run {i}'s noise stream after acting in one pass"
        );
    }
}

/// A stacked learner saves each run as a solo learner would (a solo learner loads run i's
/// folder and equals slice i, optimiser state and noise included: their next updates agree),
/// and the folders load back into a stack that continues exactly.
#[test]
fn each_run_of_a_stack_is_saved_as_a_solo_run_and_the_stack_resumes_exactly() {
    let (spec, d) = (small_spec(0), devices());
    let hyper = SacConfig::default();
    let seeds = [1u64, 2];
    let obs = spec.obs_dim;
    let batches = |update: u64| transitions(&spec, seeds.iter().map(|&seed| seed * 10 + update));
    let mut original = SacLearner::stacked(obs, obs, &spec, &hyper, &d, &seeds);
    original.update(&on_state(&batches(0), &d));
    let folders = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    let paths: Vec<&std::path::Path> = folders.iter().map(|f| f.path()).collect();
    original.save(&paths, "").unwrap();

    let mut resumed = SacLearner::stacked(obs, obs, &spec, &hyper, &d, &[8, 9]);
    resumed.load(&paths, "").unwrap();
    let mut solos: Vec<SacLearner> = paths
        .iter()
        .map(|path| {
            let mut solo = SacLearner::new(obs, obs, &spec, &hyper, &d, 99);
            solo.load(&[path], "").unwrap();
            solo
        })
        .collect();
    for i in 0..2 {
        assert_eq!(
            slice_parameters(&resumed, i),
            slice_parameters(&original, i)
        );
        assert_eq!(
            learner_parameters(&solos[i]),
            slice_parameters(&original, i)
        );
    }
    let next = batches(1);
    let after = original.update(&on_state(&next, &d)).values();
    assert_eq!(resumed.update(&on_state(&next, &d)).values(), after);
    for (i, solo) in solos.iter_mut().enumerate() {
        let alone = solo.update(&on_state(std::slice::from_ref(&next[i]), &d));
        assert_eq!(alone.values()[0], after[i], "run {i} resumed alone");
    }
}

/// Every reproducible column of a CSV log (all but the wall-clock ones), column by column.
fn reproducible(path: &std::path::Path) -> Vec<(String, Vec<String>)> {
    common::reproducible_columns(path)
        .into_iter()
        .map(|name| {
            let values = common::column(path, &name);
            (name, values)
        })
        .collect()
}

/// A short InvertedPendulum run's flags: `steps` steps (300 of warm-up), batch `batch`,
/// evaluations of 2 episodes every 300 steps, a train.csv row every 50 updates (a config file
/// written into `dir`).
fn short_run(
    dir: &std::path::Path,
    algo: &str,
    delay: &str,
    steps: &str,
    batch: &str,
) -> Vec<String> {
    let config = dir.join("log-every-50.toml");
    std::fs::write(&config, "log_every = 50\n").unwrap();
    [
        "--config",
        config.to_str().unwrap(),
        "--task",
        "inverted-pendulum",
        "--algo",
        algo,
        "--delay",
        delay,
        "--steps",
        steps,
        "--warmup-steps",
        "300",
        "--eval-every",
        "300",
        "--eval-episodes",
        "2",
        "--batch-size",
        batch,
        "--threads",
        "1",
    ]
    .map(String::from)
    .to_vec()
}

/// VDPO made small, with a cloning stage every 200 steps (after the 300 of warm-up: at 400,
/// 600, …) and dropout in its belief.
const SMALL_VDPO: [&str; 6] = [
    "--set",
    "belief_width=32",
    "--set",
    "bc_every=200",
    "--set",
    "bc_updates=20",
];

/// `dhrl ARGS…`, failing the test with its stderr if it fails.
fn dhrl_ok(args: &[&str]) {
    let out = common::dhrl(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `dhrl train --seeds 0..3` writes one ordinary run folder per seed, each logging what the
/// solo run of its seed logs (every column of train.csv and evals.csv but the wall-clock
/// ones, to the last digit), for every algorithm family (the CPU's default passes of two runs
/// and one, or all three in one pass); the seeds' runs differ.
#[test]
fn each_run_of_a_stack_logs_exactly_what_its_solo_run_logs() {
    for (algo, delay, passes, extra) in [
        ("sac", "0", "0", &[][..]),
        ("sac", "0", "3", &[]),
        ("naive-sac", "2", "0", &[]),
        ("bpql", "2", "3", &[]),
        ("d2hpg", "2", "0", &[]),
        ("d2hpg-naive", "2", "3", &[]),
        ("d2hpg-principled", "2", "0", &[]),
        ("delayed-sac", "2", "3", &[]),
        ("vdpo", "2", "3", &SMALL_VDPO[..]),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let stack = dir.path().join("stack");
        let flags = short_run(dir.path(), algo, delay, "600", "64");
        let flags: Vec<&str> = flags
            .iter()
            .map(String::as_str)
            .chain(extra.iter().copied())
            .collect();
        dhrl_ok(
            &[
                &["train"],
                flags.as_slice(),
                &["--seeds", "0..3", "--runs-per-pass", passes],
                &["--out", stack.to_str().unwrap()],
            ]
            .concat(),
        );
        let mut finals = Vec::new();
        for seed in 0..3 {
            let member = stack.join(format!("seed-{seed}"));
            let solo = dir.path().join(format!("solo-{seed}"));
            let seed = seed.to_string();
            common::train(&[flags.as_slice(), &["--seed", &seed]].concat(), &solo);
            for log in ["train.csv", "evals.csv"] {
                assert_eq!(
                    reproducible(&member.join(log)),
                    reproducible(&solo.join(log)),
                    "{algo}: seed {seed}'s {log} in the stack and alone"
                );
            }
            let config = std::fs::read_to_string(member.join("config.toml")).unwrap();
            assert!(config.contains(&format!("seed = {seed}")), "{config}");
            finals.push(common::column(&member.join("evals.csv"), "return_mean"));
        }
        assert!(
            finals[0] != finals[1] || finals[1] != finals[2],
            "{algo}: the seeds' runs do not differ: {finals:?}"
        );
    }
}

/// A stack stopped at 600 steps and continued with `--resume DIR --steps 1200` logs what a
/// stack trained to 1200 at once logs, run by run.
#[test]
fn a_resumed_stack_continues_exactly() {
    for (algo, extra) in [("bpql", &[][..]), ("d2hpg", &[]), ("vdpo", &SMALL_VDPO[..])] {
        let dir = tempfile::tempdir().unwrap();
        let (straight, resumed) = (dir.path().join("straight"), dir.path().join("resumed"));
        for (steps, out) in [("1200", &straight), ("600", &resumed)] {
            let flags = short_run(dir.path(), algo, "2", steps, "64");
            let flags: Vec<&str> = flags
                .iter()
                .map(String::as_str)
                .chain(extra.iter().copied())
                .collect();
            dhrl_ok(
                &[
                    &["train"],
                    flags.as_slice(),
                    &["--seeds", "4,7", "--out", out.to_str().unwrap()],
                ]
                .concat(),
            );
        }
        dhrl_ok(&[
            "train",
            "--resume",
            resumed.to_str().unwrap(),
            "--steps",
            "1200",
        ]);
        for seed in [4, 7] {
            for log in ["train.csv", "evals.csv"] {
                let member = |stack: &std::path::Path| stack.join(format!("seed-{seed}")).join(log);
                assert_eq!(
                    reproducible(&member(&resumed)),
                    reproducible(&member(&straight)),
                    "{algo}: seed {seed}'s {log}, resumed and straight"
                );
            }
        }
    }
}

/// With a learning rate that drives every critic to infinity within a few dozen updates, the
/// runs of a stack fail one by one: each stops alone (its reason in its failed.txt), the
/// others go on, and each fails at the update and step its solo run fails at.
#[test]
fn a_failing_run_stops_alone_and_the_rest_of_its_stack_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let stack = dir.path().join("stack");
    let flags = short_run(dir.path(), "sac", "0", "1000", "32");
    let mut flags: Vec<&str> = flags.iter().map(String::as_str).collect();
    flags.extend(["--set", "learning_rate=1"]);
    let out = common::dhrl(
        &[
            &["train"],
            flags.as_slice(),
            &["--seeds", "0..4", "--out", stack.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("all 4 runs failed"), "{stderr}");
    let update_of = |text: &str| -> u64 {
        let rest = &text[text.find("update ").expect("an update number") + 7..];
        rest.split_whitespace().next().unwrap().parse().unwrap()
    };
    let mut failed_at = Vec::new();
    for seed in 0..4 {
        let reason =
            std::fs::read_to_string(stack.join(format!("seed-{seed}")).join("failed.txt")).unwrap();
        assert!(reason.contains("not finite"), "{reason}");
        let solo = common::dhrl(
            &[
                &["train"],
                flags.as_slice(),
                &[
                    "--seed",
                    &seed.to_string(),
                    "--out",
                    dir.path().join(format!("solo-{seed}")).to_str().unwrap(),
                ],
            ]
            .concat(),
        );
        let solo = String::from_utf8_lossy(&solo.stderr).to_string();
        assert_eq!(
            update_of(&reason),
            update_of(&solo),
            "seed {seed}: in the stack `{reason}`, alone `{solo}`"
        );
        failed_at.push(update_of(&reason));
    }
    assert!(
        failed_at.iter().min() < failed_at.iter().max(),
        "the runs failed at once ({failed_at:?}): nothing shows the stack going on without one"
    );
}

/// `--seeds` refuses what it cannot take, in one line.
#[test]
fn bad_seed_lists_are_refused_saying_what_is_accepted() {
    for (seeds, says) in [
        ("a,b", "takes a list of seeds"),
        ("3..3", "names no seed"),
        ("1,2,1", "seed 1 twice"),
    ] {
        let out = common::dhrl(&["train", "--seeds", seeds, "--steps", "10"]);
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(says), "{seeds}: {stderr}");
    }
    let out = common::dhrl(&["train", "--seeds", "0,1", "--seed", "3"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    let out = common::dhrl(&["train", "--runs-per-pass", "2", "--steps", "10"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--runs-per-pass") && stderr.contains("with --seeds"),
        "{stderr}"
    );
}

/// A checkpoint written before the networks were stacked (the checked-in deployment run,
/// trained before) loads and plays as it did: its policy keeps InvertedPendulum up.
#[test]
fn a_checkpoint_from_before_stacking_loads() {
    let run = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("docs/runs/inverted-pendulum_bpql_delay3_30k-steps_deploy");
    let out = common::dhrl(&["eval", run.to_str().unwrap(), "--episodes", "2"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("return 1000.00 ± 0.00 over 2 episodes"),
        "{stdout}"
    );
}
