//! `dhrl train` end to end: it learns, every delayed algorithm runs on every task and delay
//! option, it refuses to overwrite, and a killed run resumes to exactly the run that was never
//! interrupted.
mod common;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn dhrl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(args)
        .output()
        .unwrap()
}

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
            .contains("algo = \"sac\"")
    );
}

/// The columns of a run's CSV file that a resumed run must reproduce: all but the timings.
fn reproducible_columns(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let header = text.lines().next().unwrap();
    header
        .split(',')
        .filter(|c| !["wall_seconds", "env_steps_per_sec", "updates_per_sec"].contains(c))
        .map(String::from)
        .collect()
}

#[test]
fn killed_run_resumes_to_the_uninterrupted_run() {
    // augmented-sac: one learner; d2hpg: two learners and the lifting noise in one checkpoint.
    for algo in ["augmented-sac", "d2hpg"] {
        let dir = tempfile::tempdir().unwrap();
        let (whole, killed) = (dir.path().join("whole"), dir.path().join("killed"));
        let with_out = |out: &Path| {
            let mut args = vec!["train", "--steps", "2000", "--algo", algo, "--delay", "2"];
            args.extend_from_slice(&SMALL);
            args.extend_from_slice(&["--out", out.to_str().unwrap()]);
            args.into_iter().map(String::from).collect::<Vec<_>>()
        };
        ok(Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(with_out(&whole))
            .output()
            .unwrap());

        // Start the same run, kill it once its first checkpoint is on disk, resume it.
        let mut child = Command::new(env!("CARGO_BIN_EXE_dhrl"))
            .args(with_out(&killed))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while !killed.join("checkpoint/state.json").exists() {
            assert!(
                start.elapsed() < Duration::from_secs(300),
                "no checkpoint appeared"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(700));
        child.kill().unwrap();
        child.wait().unwrap();
        let resumed = dhrl(&["train", "--resume", killed.to_str().unwrap()]);
        ok(resumed);

        for file in ["evals.csv", "train.csv"] {
            let columns = reproducible_columns(&whole.join(file));
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
        &["--delay", "2", "--warmup", "zeros"],
    ];
    let algos = ["naive-sac", "augmented-sac", "bpql", "d2hpg-naive", "d2hpg"];
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
            for name in reproducible_columns(&train) {
                for value in common::column(&train, &name) {
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
