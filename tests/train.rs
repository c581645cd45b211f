//! `dhrl train` end to end: it learns, every delayed algorithm runs on every task and delay
//! option, it refuses to overwrite, and a killed run resumes to exactly the run that was never
//! interrupted.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::dhrl;

fn ok(out: Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

const SMALL: [&str; 14] = [
    "--task",
    "inverted-pendulum",
    "--warmup-steps",
    "300",
    "--eval-every",
    "500",
    "--eval-episodes",
    "3",
    "--checkpoint-every",
    "500",
    "--batch-size",
    "64",
    "--seed",
    "4",
];

/// Random actions keep the pole up for a few steps; SAC keeps it up far longer after a few
/// thousand steps.
#[test]
fn sac_clearly_beats_a_random_policy_on_inverted_pendulum() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(dhrl(&[
        "train",
        "--task",
        "inverted-pendulum",
        "--algo",
        "sac",
        "--steps",
        "3000",
        "--warmup-steps",
        "500",
        "--eval-every",
        "1000",
        "--eval-episodes",
        "5",
        "--seed",
        "1",
        "--out",
        run.to_str().unwrap(),
    ]));
    let returns: Vec<f64> = common::column(&run.join("evals.csv"), "return_mean")
        .iter()
        .map(|v| v.parse().unwrap())
        .collect();
    // What the warm-up's random actions achieve: an episode of a uniform random policy.
    let random = 10.0;
    let best = returns.iter().cloned().fold(f64::MIN, f64::max);
    assert!(
        best > 5.0 * random,
        "SAC's evaluation returns {returns:?} are not clearly above a random policy's ~{random}"
    );
    let eval = ok(dhrl(&["eval", run.to_str().unwrap(), "--episodes", "3"]));
    assert!(eval.starts_with("return "), "{eval}");
    let svg = dir.path().join("curves.svg");
    let table = ok(dhrl(&[
        "plot",
        run.to_str().unwrap(),
        "--out",
        svg.to_str().unwrap(),
    ]));
    let last = returns.last().unwrap();
    assert!(
        table.contains(&format!(
            "| inverted-pendulum sac Δ=0 | 1 | 3000 | {last:.1} ±"
        )),
        "{table}"
    );
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    assert!(
        std::fs::read_to_string(run.join("config.toml"))
            .unwrap()
            .contains("[algo]\nname = \"sac\"")
    );
}

/// Naive SAC at Δ = 1 and augmented SAC at Δ = 2 on InvertedPendulum must each clear a bar set
/// between what they reach and what a broken variant reaches. Measured with these settings
/// (8,000 steps, batch 64, seed 2; best of 4 evaluations of 5 episodes; a uniform random policy
/// scores ~5–10): naive 160.4 (seeds 3, 4: 127.0, 145.2), augmented 79.2 (85.4, 88.0); with the actions
/// one step misaligned in the replay (`a_{τ−1}` stored with `x_τ`) naive 9.6, augmented 17.0.
#[test]
fn naive_and_augmented_sac_learn_where_broken_variants_do_not() {
    for (algo, delay, bar) in [("naive-sac", 1, 60.0), ("augmented-sac", 2, 40.0)] {
        let (best, text) = common::learn_delayed_pendulum(algo, delay, &[]);
        assert!(
            best > bar,
            "{algo} Δ={delay}: best evaluation return {best}, below the bar of {bar} that \
             separates it from a broken variant\n{text}"
        );
    }
}

/// The two baselines added last learn too (VDPO with a narrower transformer, to fit CI's
/// minutes; its delayed policy is cloned from the reference every 1,000 steps).
#[test]
fn delayed_sac_and_vdpo_beat_a_random_policy() {
    for (algo, extra) in [
        ("delayed-sac", &[][..]),
        ("vdpo", &["--set", "belief_width=64"][..]),
    ] {
        let (best, text) = common::learn_delayed_pendulum(algo, 2, extra);
        assert!(
            best > 40.0,
            "{algo}: best evaluation return {best}, below the bar of 40 (random ≤ 17)\n{text}"
        );
    }
}

/// `dhrl eval`'s delay options are laid over the run's own: `--warmup random` or
/// `--actuator-noise` alone keep the delay the policy was trained for (an augmented policy
/// evaluated at another Δ would be refused).
#[test]
fn eval_options_keep_the_runs_other_delay_settings() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let mut args = vec!["--steps", "600", "--algo", "augmented-sac", "--delay", "2"];
    args.extend_from_slice(&SMALL);
    common::train(&args, &run);
    for options in [
        &["--warmup", "random"][..],
        &["--actuator-noise", "0.1"][..],
    ] {
        let mut eval = vec!["eval", run.to_str().unwrap(), "--episodes", "2"];
        eval.extend_from_slice(options);
        let printed = ok(dhrl(&eval));
        assert!(printed.starts_with("return "), "{options:?}: {printed}");
    }
}

#[test]
fn killed_run_resumes_to_the_uninterrupted_run() {
    // augmented-sac: one learner; d2hpg: two learners and the lifting noise in one checkpoint;
    // d2hpg under the authors' protocol: λ's schedule over the budget, updates in blocks of 50,
    // two lifting draws and one α; d2hpg-principled: two learners, the homomorphism with its
    // Adam and two noise streams.
    for (algo, protocol) in [
        ("augmented-sac", "dhrl"),
        ("d2hpg", "dhrl"),
        ("d2hpg", "authors"),
        ("d2hpg-principled", "dhrl"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (whole, killed) = (dir.path().join("whole"), dir.path().join("killed"));
        let with_out = |out: &Path| {
            let mut args = vec![
                "train",
                "--steps",
                "2000",
                "--algo",
                algo,
                "--delay",
                "2",
                "--protocol",
                protocol,
            ];
            args.extend_from_slice(&SMALL);
            args.extend_from_slice(&["--out", out.to_str().unwrap()]);
            args.into_iter().map(String::from).collect::<Vec<_>>()
        };
        ok(Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(with_out(&whole))
            .output()
            .unwrap());

        // Start the same run, kill it once train.csv has its first row (step 1,299, after 1,000
        // updates): past the checkpoint of step 1,000, so that the resumed run redoes steps,
        // and ~700 steps (about a second here) before the run would end.
        let mut child = Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(with_out(&killed))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        assert!(
            common::wait_for_a_log_row(&killed.join("train.csv"), Duration::from_secs(300)),
            "{algo}: no train.csv row appeared"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "{algo}: the run finished before it could be killed; the test would prove nothing"
        );
        child.kill().unwrap();
        let status = child.wait().unwrap();
        assert_eq!(
            std::os::unix::process::ExitStatusExt::signal(&status),
            Some(9),
            "{algo}: the child must die by SIGKILL, not exit ({status})"
        );
        // What the killed run left: a checkpoint short of the whole run, and fewer evaluations.
        let saved = std::fs::read_to_string(killed.join("checkpoint/state.json")).unwrap();
        let saved: serde_json::Value = serde_json::from_str(&saved).unwrap();
        let saved_steps = saved["env_steps"].as_u64().unwrap();
        assert!(
            saved_steps < 2000,
            "{algo}: the killed run's checkpoint is at step {saved_steps}, not short of 2000"
        );
        let evals_left = common::column(&killed.join("evals.csv"), "step").len();
        let evals_whole = common::column(&whole.join("evals.csv"), "step").len();
        assert!(
            evals_left < evals_whole,
            "{algo}: the killed run already has {evals_left} of {evals_whole} evaluations"
        );
        let resumed = dhrl(&["train", "--resume", killed.to_str().unwrap()]);
        ok(resumed);

        for file in ["evals.csv", "train.csv"] {
            let columns = common::reproducible_columns(&whole.join(file));
            assert!(columns.len() >= 4, "{algo} {file}: {columns:?}");
            for name in &columns {
                assert_eq!(
                    common::column(&killed.join(file), name),
                    common::column(&whole.join(file), name),
                    "{algo}: {file} column {name}"
                );
            }
        }
        assert!(common::column(&whole.join("evals.csv"), "step").len() >= 4);
    }
}

/// Under the authors' protocol λ follows its schedule over the run's own budget — 10 until 25%
/// of the steps, linear to 0 at 75% — which `train.csv`'s `lifting_weight` shows block by block
/// (50 updates at one step each); updates start at step 100 once the replay holds 256 steps, in
/// blocks of 50; and a run extended on resume keeps the schedule of its original budget (and
/// says so), so that λ stays 0 for the added steps.
#[test]
fn the_authors_schedule_follows_the_budget_and_survives_an_extension() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("rows.toml");
    std::fs::write(&config, "log_every = 50\n").unwrap();
    let run = dir.path().join("run");
    let out = dhrl(&[
        "train",
        "--protocol",
        "authors",
        "--algo",
        "d2hpg",
        "--task",
        "inverted-pendulum",
        "--delay",
        "2",
        "--steps",
        "1000",
        "--warmup-steps",
        "400",
        "--batch-size",
        "32",
        "--set",
        "lifting_samples=4",
        "--eval-every",
        "1000",
        "--eval-episodes",
        "1",
        "--config",
        config.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ]);
    ok(out);
    let saved = std::fs::read_to_string(run.join("config.toml")).unwrap();
    for line in [
        "protocol = \"authors\"",
        "lifting_budget = 1000",
        "lifting_schedule = \"hold-decay\"",
        "network_init = \"orthogonal\"",
        "shared_temperature = true",
        "lifting_noise = \"independent\"",
        "lifting_reduction = \"mean\"",
        "update_every = 50",
        "learning_starts = 100",
    ] {
        assert!(saved.contains(line), "config.toml lacks `{line}`:\n{saved}");
    }
    let number =
        |values: Vec<String>| -> Vec<f64> { values.iter().map(|v| v.parse().unwrap()).collect() };
    let expected = |step: f64| match step {
        s if s <= 250.0 => 10.0,
        s if s >= 750.0 => 0.0,
        s => 10.0 * (1.0 - (s - 250.0) / 500.0),
    };
    let check = |last: f64| {
        let train = run.join("train.csv");
        let (steps, updates, weights) = (
            number(common::column(&train, "step")),
            number(common::column(&train, "updates")),
            number(common::column(&train, "lifting_weight")),
        );
        let expected_rows = (last - steps[0]) / 50.0 + 1.0;
        assert_eq!(
            steps.len() as f64,
            expected_rows,
            "a block every 50 steps: {steps:?}"
        );
        assert_eq!(steps[steps.len() - 1], last, "{steps:?}");
        for ((step, updates), weight) in steps.iter().zip(&updates).zip(&weights) {
            assert_eq!(step % 50.0, 0.0, "a block of updates at step {step}");
            assert!(
                (weight - expected(*step)).abs() < 1e-4,
                "λ at step {step} (update {updates}) is {weight}, the schedule's {}",
                expected(*step)
            );
        }
        steps[0]
    };
    // Updates from step 100 once the replay holds 256 steps (each episode's Δ context steps
    // count too): the first block comes at a multiple of 50 between, the last at 1000.
    let first = check(1000.0);
    assert!(
        (150.0..=400.0).contains(&first),
        "the first block came at step {first}"
    );

    let extended = dhrl(&[
        "train",
        "--resume",
        run.to_str().unwrap(),
        "--steps",
        "1500",
    ]);
    let printed = String::from_utf8_lossy(&extended.stderr).to_string();
    ok(extended);
    assert!(
        printed.contains("keeps its original 1000 steps"),
        "the extension did not say the schedule stays: {printed}"
    );
    let saved = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(saved.contains("steps = 1500") && saved.contains("lifting_budget = 1000"));
    assert_eq!(check(1500.0), first);
}

/// `--protocol authors` is refused where it cannot apply, in one line that says why: with more
/// than one copy (their loop steps one environment), and beside a config file that names the
/// other protocol.
#[test]
fn the_authors_protocol_is_refused_where_it_cannot_apply() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("dhrl.toml");
    std::fs::write(&file, "protocol = \"dhrl\"\n").unwrap();
    for (extra, says) in [
        (
            vec!["--algo", "d2hpg", "--envs", "4"],
            "1 under the authors' protocol",
        ),
        (
            vec!["--algo", "d2hpg", "--config", file.to_str().unwrap()],
            "where the file says protocol = \"dhrl\"",
        ),
    ] {
        let mut args = vec!["train", "--protocol", "authors", "--delay", "2"];
        args.extend(extra);
        // As a user sees it: without a backtrace under the message.
        let out = Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(&args)
            .env_remove("RUST_BACKTRACE")
            .env_remove("RUST_LIB_BACKTRACE")
            .output()
            .unwrap();
        let printed = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(!out.status.success(), "{args:?} was accepted");
        assert!(printed.contains(says), "{args:?}: {printed}");
        assert_eq!(printed.trim().lines().count(), 1, "{args:?}: {printed}");
    }
}

/// VDPO's cloning stage is one long update (here 1,000 policy-head steps every 100 env steps):
/// a run killed inside one resumes from the checkpoint before it to exactly the run left alone.
#[test]
fn vdpo_killed_inside_a_cloning_stage_resumes_to_the_uninterrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("often.toml");
    std::fs::write(&config, "log_every = 1\ncheckpoint_every = 50\n").unwrap();
    let (whole, killed) = (dir.path().join("whole"), dir.path().join("killed"));
    let with_out = |out: &Path| -> Vec<String> {
        [
            "train",
            "--task",
            "inverted-pendulum",
            "--algo",
            "vdpo",
            "--delay",
            "2",
            "--steps",
            "150",
            "--warmup-steps",
            "20",
            "--batch-size",
            "16",
            "--eval-every",
            "50",
            "--eval-episodes",
            "2",
            "--seed",
            "6",
            "--set",
            "belief_width=32",
            "--set",
            "bc_every=100",
            "--set",
            "bc_updates=1000",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]
        .into_iter()
        .map(String::from)
        .collect()
    };
    ok(Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(with_out(&whole))
        .output()
        .unwrap());
    let steps = common::column(&whole.join("train.csv"), "step");
    assert!(steps.contains(&"99".to_string()) && steps.contains(&"100".to_string()));
    let bursts = common::column(&whole.join("train.csv"), "bc_updates");
    let at_100 = steps.iter().position(|s| s == "100").unwrap();
    assert_eq!(
        bursts[at_100].parse::<f64>().ok(),
        Some(1000.0),
        "the stage runs on the update at step 100"
    );

    // Kill as soon as the row of step 99 is written: the next update is the stage's.
    let mut child = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(with_out(&killed))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let last_step = || {
        std::fs::read_to_string(killed.join("train.csv"))
            .ok()
            .and_then(|t| {
                t.lines()
                    .last()
                    .map(|l| l.split(',').next().unwrap().to_string())
            })
    };
    while last_step().as_deref() != Some("99") {
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "step 99 never came"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before step 99"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(
        last_step().as_deref(),
        Some("99"),
        "the kill must land inside the stage at step 100"
    );
    let saved = std::fs::read_to_string(killed.join("checkpoint/state.json")).unwrap();
    let saved: serde_json::Value = serde_json::from_str(&saved).unwrap();
    assert_eq!(saved["env_steps"].as_u64(), Some(50));

    ok(dhrl(&["train", "--resume", killed.to_str().unwrap()]));
    for file in ["evals.csv", "train.csv"] {
        for name in common::reproducible_columns(&whole.join(file)) {
            assert_eq!(
                common::column(&killed.join(file), &name),
                common::column(&whole.join(file), &name),
                "{file} column {name}"
            );
        }
    }
}

/// Every delayed algorithm trains on every task, and each of them under every option of the
/// delay layer (a few dozen updates per run: the pieces fit together, their losses stay
/// finite and the evaluation runs; learning is the other tests' business).
#[test]
fn every_delayed_algorithm_trains_on_every_task_and_delay_option() {
    let options: [&[&str]; 5] = [
        &["--delay", "3"],
        &["--delay", "1", "--action-delay", "2"],
        &["--random-delay", "--max-delay", "3"],
        &["--delay", "2", "--actuator-noise", "0.1"],
        &["--delay", "2", "--warmup", "random"],
    ];
    let algos = dhrl::algos::names_where(|info| !info.undelayed_only);
    let tasks = [
        "ant",
        "half-cheetah",
        "hopper",
        "walker2d",
        "humanoid",
        "inverted-pendulum",
    ];
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("log-often.toml");
    std::fs::write(&config, "log_every = 10\n").unwrap();
    for (i, algo) in algos.iter().enumerate() {
        for (j, task) in tasks.iter().enumerate() {
            // 6 tasks over 5 options: every algorithm meets every option.
            let option = options[(i + j) % options.len()];
            let run = dir.path().join(format!("{algo}-{task}"));
            let mut args = vec![
                "--task",
                task,
                "--algo",
                algo,
                "--steps",
                "80",
                "--warmup-steps",
                "40",
                "--batch-size",
                "16",
                "--eval-every",
                "80",
                "--eval-episodes",
                "1",
                "--config",
                config.to_str().unwrap(),
            ];
            args.extend_from_slice(option);
            common::train(&args, &run);
            assert_eq!(common::column(&run.join("evals.csv"), "step"), ["80"]);
            let train = run.join("train.csv");
            assert_eq!(
                common::column(&train, "updates"),
                ["10", "20", "30", "40"],
                "{algo} on {task}"
            );
            for name in common::reproducible_columns(&train) {
                // A statistic absent from every update of a row is an empty cell (VDPO's
                // cloning stage runs every 1,000 steps, not in these 80).
                for value in common::column(&train, &name) {
                    if value.is_empty() {
                        continue;
                    }
                    let value: f64 = value.parse().unwrap();
                    assert!(
                        value.is_finite(),
                        "{algo} on {task} {option:?}: {name} = {value}"
                    );
                }
            }
        }
    }
}

#[test]
fn existing_run_folders_are_never_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let out = dhrl(&[
        "train",
        "--steps",
        "10",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let msg = String::from_utf8_lossy(&out.stderr);
    assert!(
        msg.contains("already exists") && msg.contains("--resume"),
        "{msg}"
    );
    let out = dhrl(&["train", "--resume", dir.path().to_str().unwrap()]);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("config.toml"),
        "resume needs a run folder"
    );
}

#[test]
fn bad_training_options_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    let out = dhrl(&[
        "train",
        "--algo",
        "sac",
        "--delay",
        "3",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("delay-free reference"));
    let out = dhrl(&[
        "train",
        "--eval-episodes",
        "0",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("eval_episodes must be at least 1, got 0")
    );
    assert!(
        !run.exists(),
        "nothing is written for a rejected configuration"
    );
    let config = dir.path().join("c.toml");
    std::fs::write(&config, "task = \"half-cheetah\"\nstepz = 5\n").unwrap();
    let out = dhrl(&[
        "train",
        "--config",
        config.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("unknown field `stepz`"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `--set FIELD=VALUE` reaches any field of the chosen algorithm's `[algo]` table, the old
/// flags still work, a typo lists the valid fields, and `--help-config` documents them.
#[test]
fn algorithm_fields_are_set_by_name_and_typos_list_the_fields() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    let quick = [
        "--task",
        "inverted-pendulum",
        "--steps",
        "5",
        "--eval-episodes",
        "1",
        "--warmup-steps",
        "5",
    ];
    let mut args = quick.to_vec();
    args.extend_from_slice(&[
        "--algo",
        "d2hpg",
        "--delay",
        "2",
        "--set",
        "lifting_weight=10",
        "--set",
        "gamma=0.98",
        "--lifting-samples",
        "4",
        "--fixed-alpha",
    ]);
    common::train(&args, &run);
    let saved: toml::Table = std::fs::read_to_string(run.join("config.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let algo = saved["algo"].as_table().unwrap();
    assert_eq!(algo["name"].as_str(), Some("d2hpg"));
    assert_eq!(algo["lifting_weight"].as_float(), Some(10.0));
    assert_eq!(algo["gamma"].as_float(), Some(0.98));
    assert_eq!(algo["lifting_samples"].as_integer(), Some(4));
    assert_eq!(algo["autotune_alpha"].as_bool(), Some(false));
    assert_eq!(algo["tau"].as_float(), Some(0.005), "the rest default");

    let out = dhrl(&["train", "--algo", "d2hpg", "--set", "lifting_wieght=3"]);
    let message = String::from_utf8_lossy(&out.stderr);
    // The list of fields the message names, each one whole.
    let listed: Vec<&str> = message
        .split_once("its fields are: ")
        .and_then(|(_, rest)| rest.split_once(" ("))
        .map_or(vec![], |(list, _)| list.split(", ").collect());
    assert!(
        out.status.code() == Some(1)
            && message.contains("no field `lifting_wieght`")
            && [
                "lifting_weight",
                "lifting_schedule",
                "lifting_samples",
                "shared_temperature"
            ]
            .iter()
            .all(|field| listed.contains(field)),
        "{message}"
    );
    let out = dhrl(&["train", "--algo", "bpql", "--lifting-weight", "3"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("bpql has no field `lifting_weight`"));
    let out = dhrl(&["train", "--algo", "d2hpg", "--set", "lifting_samples=1"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains(
        "lifting_samples must be at least 2 (standard deviations need two samples), got 1"
    ));
    let out = dhrl(&["train", "--algo", "d2hpg", "--set", "gamma=fast"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("gamma = \"fast\""));
    let help = ok(dhrl(&["train", "--algo", "d2hpg", "--help-config"]));
    for field in [
        "gamma = 0.99",
        "lifting_weight = 1.0",
        "lifting_samples = 2",
        "λ, the weight",
    ] {
        assert!(help.contains(field), "{field} in\n{help}");
    }
}

/// A `config.toml` written before the `[algo]` table (`algo = "…"` with `[hyper]` and
/// `[lifting]`, the latter written for every algorithm) still reads, as the same settings.
#[test]
fn older_config_files_still_read() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("old.toml");
    let old = "task = \"inverted-pendulum\"\nalgo = \"ALGO\"\nsteps = 5\nwarmup_steps = 5\n\
               eval_episodes = 1\n[delay]\nobservation_delay = 1\n\
               [hyper]\ngamma = 0.97\ntau = 0.01\n[lifting]\nweight = 3.0\nsamples = 5\n";
    for (algo, lifting) in [("d2hpg", true), ("bpql", false)] {
        std::fs::write(&config, old.replace("ALGO", algo)).unwrap();
        let run = dir.path().join(algo);
        common::train(&["--config", config.to_str().unwrap()], &run);
        let saved: toml::Table = std::fs::read_to_string(run.join("config.toml"))
            .unwrap()
            .parse()
            .unwrap();
        let fields = saved["algo"].as_table().unwrap();
        assert_eq!(fields["name"].as_str(), Some(algo));
        assert_eq!(fields["gamma"].as_float(), Some(0.97));
        assert_eq!(fields["tau"].as_float(), Some(0.01));
        assert_eq!(
            fields.get("lifting_weight").and_then(|v| v.as_float()),
            lifting.then_some(3.0)
        );
        assert_eq!(
            fields.get("lifting_samples").and_then(|v| v.as_integer()),
            lifting.then_some(5)
        );
    }
}

/// `--delay-device gpu` (the WGSL kernels; Mesa's software Vulkan in CI) trains exactly as the
/// CPU reference: the same `evals.csv` and `train.csv`, and the same replay contents and delay
/// state in the final checkpoint, byte for byte.
#[test]
fn training_on_the_gpu_delay_layer_equals_the_cpu_layer() {
    if std::env::var("DHRL_SKIP_GPU_TESTS").as_deref() == Ok("1") {
        eprintln!("SKIPPED (DHRL_SKIP_GPU_TESTS=1): training on the GPU delay layer");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("log-often.toml");
    std::fs::write(&config, "log_every = 100\n").unwrap();
    let runs: Vec<_> = ["cpu", "gpu"]
        .iter()
        .map(|device| {
            let run = dir.path().join(device);
            let mut args = vec![
                "--config",
                config.to_str().unwrap(),
                "--steps",
                "1200",
                "--algo",
                "bpql",
                "--delay",
                "2",
                "--action-delay",
                "1",
                // Random warm-up actions, so the layers' warm-up streams are compared too.
                "--warmup",
                "random",
                "--delay-device",
                device,
            ];
            args.extend_from_slice(&SMALL);
            common::train(&args, &run);
            run
        })
        .collect();
    let (cpu, gpu) = (&runs[0], &runs[1]);
    for file in ["evals.csv", "train.csv"] {
        for name in common::reproducible_columns(&cpu.join(file)) {
            assert_eq!(
                common::column(&gpu.join(file), &name),
                common::column(&cpu.join(file), &name),
                "{file} column {name}"
            );
        }
    }
    for file in ["replay.bin", "delay.bin", "env.json"] {
        let read = |run: &Path| std::fs::read(run.join("checkpoint").join(file)).unwrap();
        assert!(read(cpu) == read(gpu), "checkpoint/{file} differs");
    }
}

/// `TrainArgs::plan`, the library's one place for `dhrl train`'s rules: defaults, then
/// `--config`, then flags; `--resume` alone or with `--steps`.
#[test]
fn train_arguments_resolve_in_order_and_resume_takes_only_steps() {
    use dhrl::train::{Start, TrainArgs};
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("c.toml");
    std::fs::write(
        &file,
        "seed = 7\nsteps = 900\n[algo]\nname = \"d2hpg\"\ngamma = 0.95\nlifting_weight = 2.0\n",
    )
    .unwrap();
    let args = TrainArgs {
        config: Some(file.clone()),
        seed: Some(8),
        algo: Some("bpql".into()),
        set: vec!["tau=0.01".into()],
        out: Some(dir.path().join("run")),
        ..TrainArgs::default()
    };
    let plan = args.plan().unwrap();
    assert_eq!(plan.start, Start::Fresh);
    let c = &plan.config;
    assert_eq!(
        (c.seed, c.steps),
        (8, 900),
        "flags over the file over the defaults"
    );
    assert_eq!(c.algo.name(), "bpql");
    let fields = c.algo.fields();
    assert_eq!(
        fields["gamma"].as_float(),
        Some(0.95),
        "shared fields carry over"
    );
    assert_eq!(fields["tau"].as_float(), Some(0.01));
    assert!(
        !fields.contains_key("lifting_weight"),
        "bpql has no lifting"
    );

    let resume = TrainArgs {
        resume: Some(dir.path().join("run")),
        steps: Some(5000),
        ..TrainArgs::default()
    };
    let plan = resume.plan().unwrap();
    assert_eq!((plan.start, plan.config.steps), (Start::Resume, 5000));
    let mixed = TrainArgs {
        seed: Some(1),
        ..resume
    };
    let error = mixed.plan().unwrap_err().to_string();
    assert!(
        error.contains("--resume") && error.contains("--steps"),
        "{error}"
    );
}

/// Without flags, `dhrl train` is the main job: D2HPG on InvertedPendulum at Δ = 5. A delay
/// option replaces that delay (it is not added to it), `--algo` takes its algorithm's defaults
/// with Δ = 0, and a config file keeps what it says.
#[test]
fn the_main_job_is_d2hpg_under_delay_and_every_flag_replaces_its_part() {
    use dhrl::delay::DelayArgs;
    use dhrl::train::{MAIN_JOB_DELAY, TrainArgs};
    let resolved = |args: TrainArgs| {
        let c = args.config().unwrap();
        let delay = (c.delay.observation_delay, c.delay.action_delay);
        (c.task, c.algo.name().to_string(), delay)
    };
    let ip = dhrl::tasks::TaskName::InvertedPendulum;
    assert_eq!(MAIN_JOB_DELAY, 5);
    assert_eq!(resolved(TrainArgs::default()), (ip, "d2hpg".into(), (5, 0)));
    let delay = |delay: Option<i64>, action_delay: Option<i64>| DelayArgs {
        delay,
        action_delay,
        ..DelayArgs::default()
    };
    let with_delay = |d: DelayArgs| TrainArgs {
        delay: d,
        ..TrainArgs::default()
    };
    assert_eq!(
        resolved(with_delay(delay(Some(3), None))),
        (ip, "d2hpg".into(), (3, 0))
    );
    assert_eq!(
        resolved(with_delay(delay(None, Some(2)))),
        (ip, "d2hpg".into(), (0, 2)),
        "an action delay alone is the whole delay"
    );
    let noisy = DelayArgs {
        actuator_noise: Some(0.1),
        ..DelayArgs::default()
    };
    assert_eq!(resolved(with_delay(noisy)), (ip, "d2hpg".into(), (5, 0)));
    let sac = TrainArgs {
        algo: Some("sac".into()),
        ..TrainArgs::default()
    };
    assert_eq!(resolved(sac), (ip, "sac".into(), (0, 0)));
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("c.toml");
    std::fs::write(&file, "seed = 7\n").unwrap();
    let from_file = TrainArgs {
        config: Some(file),
        ..TrainArgs::default()
    };
    assert_eq!(
        resolved(from_file),
        (ip, "sac".into(), (0, 0)),
        "a config file's missing fields are the library's defaults"
    );
}

/// Every flag of `dhrl train` that sets a run's configuration is refused beside `--resume`,
/// by name (none is silently ignored); clap's own list of the arguments drives the test, so a
/// new flag without a sample value here fails it. A `--steps` below the run's own is refused
/// too: a resumed run can only be extended.
#[test]
fn resume_refuses_every_other_setting_by_name_and_never_shortens_a_run() {
    use clap::{Args, Command, FromArgMatches};
    use dhrl::train::{Start, TrainArgs, TrainConfig, train};
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("c.toml");
    std::fs::write(&file, "seed = 7\n").unwrap();
    let sample = |flag: &str| -> Option<&str> {
        Some(match flag {
            "task" => "ant",
            "algo" => "bpql",
            "set" => "tau=0.01",
            "delay" | "action-delay" | "max-delay" => "2",
            "actuator-noise" => "0.1",
            "warmup" => "random",
            "seed" | "envs" | "threads" | "eval-episodes" => "3",
            "seeds" => "0,1",
            "runs-per-pass" => "2",
            "warmup-steps" | "learning-starts" | "update-every" | "eval-every"
            | "checkpoint-every" | "batch-size" => "64",
            "alpha" | "lifting-weight" => "0.5",
            "lifting-samples" => "4",
            "protocol" => "authors",
            "device" | "delay-device" => "cpu",
            "config" => file.to_str().unwrap(),
            _ => return None,
        })
    };
    let command = TrainArgs::augment_args(Command::new("train").no_binary_name(true));
    let mut checked = 0;
    for arg in command.get_arguments() {
        let flag = arg.get_long().expect("every train argument is a long flag");
        if ["resume", "steps", "out", "help-config"].contains(&flag) {
            continue;
        }
        let mut line = vec![
            "--resume".to_string(),
            "somewhere".into(),
            format!("--{flag}"),
        ];
        if arg.get_action().takes_values() {
            let value =
                sample(flag).unwrap_or_else(|| panic!("--{flag}: add a sample value to this test"));
            line.push(value.into());
        }
        let matches = command.clone().try_get_matches_from(&line).unwrap();
        let args = TrainArgs::from_arg_matches(&matches).unwrap();
        let error = args.plan().unwrap_err().to_string();
        assert!(
            error.contains(&format!("--{flag}")) && error.contains("--resume"),
            "--{flag}: {error}"
        );
        checked += 1;
    }
    assert!(checked >= 20, "{checked} flags checked");

    // A run of 1,000 steps: --steps 500 is refused, before anything is loaded.
    let run = dir.path().join("run");
    std::fs::create_dir(&run).unwrap();
    let saved = TrainConfig {
        steps: 1000,
        ..TrainConfig::default()
    };
    std::fs::write(run.join("config.toml"), toml::to_string(&saved).unwrap()).unwrap();
    let shorter = TrainConfig {
        steps: 500,
        ..TrainConfig::default()
    };
    let error = train(&shorter, &run, Start::Resume, false)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("--steps") && error.contains("500") && error.contains("1000"),
        "{error}"
    );
}

/// A loss that stops being finite stops the run with an error naming the update, the step and
/// the statistic, and the last checkpoint (before the first update here) is kept to resume.
#[test]
fn a_non_finite_loss_stops_the_run_and_keeps_the_last_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args([
            "train",
            "--task",
            "inverted-pendulum",
            "--steps",
            "1500",
            "--warmup-steps",
            "600",
            "--checkpoint-every",
            "500",
            "--eval-every",
            "500",
            "--set",
            "learning_rate=1e30",
            "--out",
        ])
        .arg(&run)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("not finite") && stderr.contains("update ") && stderr.contains("--resume"),
        "{stderr}"
    );
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("checkpoint/state.json")).unwrap())
            .unwrap();
    assert_eq!(state["env_steps"], 500, "the last good checkpoint");
}

/// A full disk (a tmpfs with room for one checkpoint and a half: the second one cannot be
/// written beside the first) stops the run with an error that names the step, the cause and
/// the checkpoint kept; no partial checkpoint is left, and the run, moved to a disk with room,
/// resumes to exactly the run that had room all along. Needs root to mount the tmpfs (as CI
/// has); elsewhere it says so and returns, unless `DHRL_REQUIRE_TMPFS=1` (which
/// `scripts/test.sh` sets when run as root, and so CI) makes that a failure.
#[test]
fn a_full_disk_fails_the_checkpoint_clearly_and_keeps_the_previous_one() {
    let dir = tempfile::tempdir().unwrap();
    let args = |steps: &str, out: &Path| -> Vec<String> {
        let mut args = vec!["train", "--steps", steps];
        args.extend_from_slice(&SMALL);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        args.into_iter().map(String::from).collect()
    };
    // The size of a run folder with one checkpoint (SMALL checkpoints every 500 steps).
    let measured = dir.path().join("measured");
    ok(Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(args("500", &measured))
        .output()
        .unwrap());
    let size: u64 = walk_sizes(&measured);
    let disk = dir.path().join("disk");
    std::fs::create_dir(&disk).unwrap();
    let mount = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={}", size * 3 / 2)])
        .arg("tmpfs")
        .arg(&disk)
        .output()
        .unwrap();
    if !mount.status.success() {
        let why = String::from_utf8_lossy(&mount.stderr).trim().to_string();
        assert!(
            std::env::var("DHRL_REQUIRE_TMPFS").as_deref() != Ok("1"),
            "cannot mount a tmpfs ({why}) and DHRL_REQUIRE_TMPFS=1: the full-disk test must run"
        );
        eprintln!(
            "a_full_disk_fails_the_checkpoint_clearly_and_keeps_the_previous_one: cannot mount a \
             tmpfs here ({why}): SKIPPED (set DHRL_REQUIRE_TMPFS=1 to make this a failure)"
        );
        return;
    }
    struct Unmount<'a>(&'a Path);
    impl Drop for Unmount<'_> {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(self.0).status();
        }
    }
    let _unmount = Unmount(&disk);
    let cramped = disk.join("run");
    let out = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(args("1500", &cramped))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "the run had room after all: {stderr}"
    );
    for expected in [
        "writing the checkpoint of step 1000",
        "No space left on device",
        "checkpoint is intact",
        "--resume",
    ] {
        assert!(stderr.contains(expected), "'{expected}' not in: {stderr}");
    }
    assert!(
        !cramped.join("checkpoint.partial").exists(),
        "the partial checkpoint is removed"
    );
    let saved = std::fs::read_to_string(cramped.join("checkpoint/state.json")).unwrap();
    let saved: serde_json::Value = serde_json::from_str(&saved).unwrap();
    assert_eq!(saved["env_steps"].as_u64(), Some(500));
    // Moved to a disk with room, it resumes to the run that never ran out.
    let moved = dir.path().join("moved");
    assert!(
        Command::new("cp")
            .arg("-a")
            .arg(&cramped)
            .arg(&moved)
            .status()
            .unwrap()
            .success()
    );
    ok(dhrl(&["train", "--resume", moved.to_str().unwrap()]));
    let whole = dir.path().join("whole");
    ok(Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(args("1500", &whole))
        .output()
        .unwrap());
    for file in ["evals.csv", "train.csv"] {
        for name in common::reproducible_columns(&whole.join(file)) {
            assert_eq!(
                common::column(&moved.join(file), &name),
                common::column(&whole.join(file), &name),
                "{file} column {name}"
            );
        }
    }
}

/// Bytes of every file under `dir`.
fn walk_sizes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            let meta = e.metadata().unwrap();
            if meta.is_dir() {
                walk_sizes(&e.path())
            } else {
                meta.len()
            }
        })
        .sum()
}

/// `dhrl train --help` explains every flag: none is listed without a line of help.
#[test]
fn every_train_flag_has_help() {
    use clap::Args;
    let command = dhrl::train::TrainArgs::augment_args(clap::Command::new("train"));
    let mut checked = 0;
    for arg in command.get_arguments() {
        let help = arg.get_help().map(|h| h.to_string()).unwrap_or_default();
        assert!(
            help.trim().len() > 10,
            "--{}: no help text in `dhrl train --help`",
            arg.get_id()
        );
        checked += 1;
    }
    assert!(checked >= 20, "{checked} flags checked");
}

/// A run folder being trained is locked: `--resume` of it from a second process is refused
/// with a message saying so (two trainers would interleave its logs and checkpoints), and
/// goes through once the first has stopped.
#[test]
fn a_run_in_training_cannot_be_resumed_by_a_second_process() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let mut first = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args([
            "train",
            "--steps",
            "1000000",
            "--checkpoint-every",
            "200",
            "--out",
        ])
        .arg(&run)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !run.join("checkpoint/state.json").is_file() {
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "no checkpoint came"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let resume = || {
        Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(["train", "--steps", "1000000", "--resume"])
            .arg(&run)
            .output()
            .unwrap()
    };
    let second = resume();
    first.kill().unwrap();
    first.wait().unwrap();
    assert!(!second.status.success());
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(
        stderr.contains("is being trained by another dhrl process"),
        "{stderr}"
    );
    // With the first gone, the lock is free: a resume starts (and is stopped here).
    let mut third = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(["train", "--steps", "1000000", "--resume"])
        .arg(&run)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        third.try_wait().unwrap().is_none(),
        "the resume ended early"
    );
    third.kill().unwrap();
    third.wait().unwrap();
}
