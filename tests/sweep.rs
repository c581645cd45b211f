//! Sweeps: experiments expand into manifests with stable run ids, the local runner finishes
//! every run and picks up where a killed sweep stopped, and a run stopped by a signal leaves
//! a checkpoint that resumes to the uninterrupted result.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use dhrl::delay::WarmupActions;
use dhrl::sweep::{Experiment, ManifestRun, RunOutcome, RunState, Sweep};

use common::dhrl;

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A small experiment: InvertedPendulum, two algorithms, Δ 2, two seeds, a few hundred steps.
const TINY: &str = r#"
tasks = ["inverted-pendulum"]
algorithms = ["sac", "bpql"]
delays = [2]
seeds = [0, 1]
steps = 600

[train]
warmup_steps = 200
eval_every = 300
eval_episodes = 2
checkpoint_every = 200
batch_size = 32
log_every = 100
"#;

#[test]
fn presets_expand_into_the_papers_grid_with_stable_ids() {
    let table1 = Experiment::preset("table1").unwrap().expand().unwrap();
    // 6 tasks × (delay-free SAC once + 6 delayed algorithms × 3 delays) × 5 seeds.
    assert_eq!(table1.len(), 6 * (1 + 6 * 3) * 5);
    let mut ids: Vec<&str> = table1.iter().map(|r| r.id.as_str()).collect();
    ids.sort();
    ids.dedup();
    assert_eq!(ids.len(), table1.len(), "run ids are unique");
    assert!(
        table1
            .iter()
            .filter(|r| r.config.algo.name() == "sac")
            .all(|r| r.config.delay.observation_delay == 0),
        "the delay-free reference runs undelayed"
    );
    assert!(
        table1
            .iter()
            .all(|r| r.config.steps == 1_000_000 && r.config.eval_every == 5_000)
    );
    for preset in ["table1", "noise", "random-delay", "ablation", "runtime"] {
        assert!(
            Experiment::preset(preset)
                .unwrap()
                .expand()
                .unwrap()
                .iter()
                .all(|r| r.config.delay.warmup == WarmupActions::Zeros),
            "{preset}: zero warm-up actions, as the paper's numbers need (docs/results/warmup-evidence.md)"
        );
    }
    let noise = Experiment::preset("noise").unwrap().expand().unwrap();
    assert_eq!(
        noise.len(),
        6 * 5 * 5,
        "6 tasks × σ ∈ {{0, .01, .03, .05, .07}} × 5 seeds"
    );
    let random = Experiment::preset("random-delay")
        .unwrap()
        .expand()
        .unwrap();
    assert_eq!(
        random
            .iter()
            .filter(|r| r.config.delay.random_bound() == Some(10))
            .count(),
        30
    );
    // The same plan twice gives the same ids; a changed setting gives new ones.
    let again = Experiment::preset("table1").unwrap().expand().unwrap();
    assert_eq!(table1, again);
    // (A weight neither protocol's default: the presets run the authors', λ = 10.)
    let mut changed = Experiment::preset("ablation").unwrap();
    let before = changed.expand().unwrap();
    changed.algo.insert(
        "d2hpg".into(),
        toml::from_str("lifting_weight = 3.0").unwrap(),
    );
    let after = changed.expand().unwrap();
    for (b, a) in before.iter().zip(&after) {
        assert_eq!(
            b.id == a.id,
            b.config.algo.name() != "d2hpg",
            "{} / {}",
            b.id,
            a.id
        );
    }
}

/// A quick look at a preset: restricted, scaled (steps and checkpoint interval) and evaluated
/// more often, as the reduced reproduction of docs/repro/README.md was planned.
#[test]
fn a_preset_is_restricted_scaled_and_evaluated_more_often() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("quick");
    let printed = ok(&dhrl(&[
        "sweep",
        "plan",
        "table1",
        "--out",
        out.to_str().unwrap(),
        "--tasks",
        "inverted-pendulum",
        "--algos",
        "bpql,d2hpg",
        "--delays",
        "5,20",
        "--seeds",
        "0",
        "--scale",
        "0.01",
        "--eval-every",
        "1000",
        "--cost-updates",
        "0",
    ]));
    assert!(printed.contains("4 runs planned (4 new"), "{printed}");
    let sweep = Sweep::open(&out).unwrap();
    for run in &sweep.runs {
        let c = &run.config;
        assert_eq!(
            (c.steps, c.eval_every, c.checkpoint_every, c.eval_episodes),
            (10_000, 1_000, 500, 10),
            "{}",
            run.id
        );
    }
}

#[test]
fn bad_experiments_are_clear_errors() {
    let error = |text: &str| {
        Experiment::from_toml(text, "x.toml")
            .and_then(|e| e.expand())
            .unwrap_err()
            .to_string()
    };
    let base = |extra: &str| TINY.replace("steps = 600", &format!("steps = 600\n{extra}"));
    assert!(
        error(&TINY.replace("\"bpql\"", "\"bqpl\"")).contains("d2hpg"),
        "an unknown algorithm lists the valid ones"
    );
    assert!(error(&base("stepz = 3")).contains("stepz"));
    assert!(error(&TINY.replace("seeds = [0, 1]", "seeds = []")).contains("`seeds` list is empty"));
    assert!(error(&format!("{TINY}\n[algo.vdpo]\ndropout = 0.2\n")).contains("does not run"));
    assert!(error(&TINY.replace("batch_size = 32", "batch_sise = 32")).contains("batch_sise"));
    let out = dhrl(&["sweep", "plan", "tabel1", "--out", "/nonexistent/x"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("table1, noise, random-delay"));
}

fn plan_tiny(dir: &Path) -> Sweep {
    plan(dir, TINY, "sweep", 4)
}

/// Plans `experiment` (of `runs` runs) into `dir/name`, twice: the second plan adds nothing.
fn plan(dir: &Path, experiment: &str, name: &str, runs: usize) -> Sweep {
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, experiment).unwrap();
    let sweep = dir.join(name);
    let args = [
        "sweep",
        "plan",
        file.to_str().unwrap(),
        "--out",
        sweep.to_str().unwrap(),
        "--cost-updates",
        "0",
    ];
    let printed = ok(&dhrl(&args));
    assert!(
        printed.contains(&format!("{runs} runs planned ({runs} new")),
        "{printed}"
    );
    // Planning again adds nothing and moves nothing.
    let printed = ok(&dhrl(&args));
    assert!(
        printed.contains(&format!("(0 new, {runs} planned before")),
        "{printed}"
    );
    Sweep::open(&sweep).unwrap()
}

fn finished_return(sweep: &Sweep, index: usize) -> f64 {
    match sweep.state(&sweep.runs[index]) {
        RunState::Ended(RunOutcome::Finished { final_return, .. }) => final_return.unwrap(),
        other => panic!("run {index}: {other:?}"),
    }
}

/// `dhrl sweep run FOLDER --jobs 2 EXTRA…` in the background, its output kept.
fn start_runner(folder: &str, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(["sweep", "run", folder, "--jobs", "2"])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Starts `dhrl sweep run FOLDER --jobs 2 EXTRA…` and kills it (runner and runs, which have
/// their own process groups) once the first checkpoints exist.
fn start_and_kill_runner(sweep: &Sweep, folder: &str, extra: &[&str]) {
    let mut runner = start_runner(folder, extra);
    wait_for_a_checkpoint(sweep, &sweep.runs);
    // Every process whose command line names this sweep's (temporary, unique) folder.
    Command::new("pkill")
        .args(["-KILL", "-f", folder])
        .status()
        .unwrap();
    runner.wait().unwrap();
}

/// Waits (two minutes at most) until one of `runs` has written a checkpoint.
fn wait_for_a_checkpoint(sweep: &Sweep, runs: &[ManifestRun]) {
    let start = Instant::now();
    while !runs
        .iter()
        .any(|r| sweep.run_dir(r).join("checkpoint").exists())
    {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no checkpoint within 2 min"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The run's configuration trained by `dhrl train` without interruption, in `dir/whole-<index>`.
fn train_in_one_go(dir: &Path, run: &ManifestRun) -> PathBuf {
    let config = dir.join(format!("config-{}.toml", run.index));
    std::fs::write(&config, toml::to_string(&run.config).unwrap()).unwrap();
    let whole = dir.join(format!("whole-{}", run.index));
    common::train(&["--config", config.to_str().unwrap()], &whole);
    whole
}

/// Every non-timing column of both logs of a sweep's run equals those of `reference`.
fn assert_same_logs(run: &Path, reference: &Path) {
    for file in ["evals.csv", "train.csv"] {
        for name in common::reproducible_columns(&reference.join(file)) {
            assert_eq!(
                common::column(&run.join(file), &name),
                common::column(&reference.join(file), &name),
                "{}: {file} column {name}",
                run.display()
            );
        }
    }
}

#[test]
fn local_runner_finishes_every_run_and_a_killed_sweep_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = plan_tiny(dir.path());
    let folder = sweep.dir.to_str().unwrap().to_string();
    // Start the sweep, kill it once the first checkpoints exist, start it again.
    start_and_kill_runner(&sweep, &folder, &[]);
    let cut = sweep.runs.iter().filter(|r| !sweep.finished(r)).count();
    assert!(cut > 0, "the kill came after every run had finished");
    let printed = ok(&dhrl(&["sweep", "run", &folder, "--jobs", "2"]));
    assert!(printed.contains("4 finished, 0 failed"), "{printed}");
    // Each run equals the same configuration trained in one go by `dhrl train`.
    for run in &sweep.runs {
        let whole = train_in_one_go(dir.path(), run);
        assert_same_logs(&sweep.run_dir(run), &whole);
        assert!(finished_return(&sweep, run.index).is_finite());
    }
    // Nothing left to do: a second start runs nothing.
    let printed = ok(&dhrl(&["sweep", "run", &folder]));
    assert!(printed.contains("4 finished, 0 failed"), "{printed}");
    let commands = ok(&dhrl(&["sweep", "commands", &folder]));
    assert!(
        commands.is_empty(),
        "finished runs need no command: {commands}"
    );
}

#[test]
fn a_run_stopped_by_sigterm_checkpoints_and_resumes_to_the_same_result() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = plan_tiny(dir.path());
    let folder = sweep.dir.to_str().unwrap().to_string();
    let commands = ok(&dhrl(&["sweep", "commands", &folder]));
    assert_eq!(commands.lines().count(), 4, "{commands}");
    assert!(commands.lines().all(|l| l.contains("sweep run-one")));
    let run = &sweep.runs[1];
    let child = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(["sweep", "run-one", &folder, "--index", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_a_checkpoint(&sweep, std::slice::from_ref(run));
    // And for a first train.csv row (step 300 of 600), so that there is a log to keep.
    let log = sweep.run_dir(run).join("train.csv");
    assert!(
        common::wait_for_a_log_row(&log, Duration::from_secs(120)),
        "no train.csv row within 2 min"
    );
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(dhrl::sweep::EXIT_INTERRUPTED),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let RunState::Ended(RunOutcome::Interrupted { env_steps }) = sweep.state(run) else {
        panic!("{:?}", sweep.state(run));
    };
    assert!(env_steps < run.config.steps, "stopped at {env_steps}");
    // The rows logged before the stop, wall seconds included: a run that continues keeps them
    // byte for byte; one started over (the same numbers, other timings) would not.
    let run_dir = sweep.run_dir(run);
    let before = std::fs::read_to_string(run_dir.join("train.csv")).unwrap();
    assert!(
        before.lines().count() > 1,
        "no train.csv row before the stop"
    );
    ok(&dhrl(&["sweep", "run-one", &folder, "--index", "1"]));
    assert!(
        !run_dir.with_extension("without-checkpoint").exists(),
        "the run was moved aside and started over instead of resuming"
    );
    let after = std::fs::read_to_string(run_dir.join("train.csv")).unwrap();
    assert!(
        after.starts_with(&before),
        "the rows before the stop changed:\n{before}\n---\n{after}"
    );
    assert!(
        after.len() > before.len(),
        "nothing was trained after the stop"
    );
    let whole = train_in_one_go(dir.path(), run);
    assert_same_logs(&run_dir, &whole);
}

/// `dhrl sweep run` stopped by SIGTERM passes the stop on to its running runs, which
/// checkpoint and exit, and the next start ends them as if they had run in one go. The runs
/// are frozen (SIGSTOP) from the first checkpoint until the runner has passed the stop on, so
/// that no run can end in between however fast the machine: the hand-over is tested, not a
/// race against 400 training steps.
#[test]
fn a_runner_stopped_by_sigterm_stops_its_runs_with_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = plan_tiny(dir.path());
    let folder = sweep.dir.to_str().unwrap().to_string();
    let mut runner = start_runner(&folder, &[]);
    wait_for_a_checkpoint(&sweep, &sweep.runs);
    let runner_pid = runner.id().to_string();
    let signal_runs = |signal: &str| {
        Command::new("pkill")
            .args([signal, "-P", &runner_pid])
            .status()
            .unwrap()
    };
    signal_runs("-STOP");
    Command::new("kill")
        .args(["-TERM", &runner_pid])
        .status()
        .unwrap();
    // The runner says so once it has sent SIGTERM to its (frozen) runs; its runs go on after
    // that line, or after two minutes without it (then the assertions below say what it did).
    let (said_tx, said_rx) = std::sync::mpsc::channel();
    let stderr = runner.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            said_tx.send(line.unwrap()).unwrap();
        }
    });
    let mut said = Vec::new();
    while let Ok(line) = said_rx.recv_timeout(Duration::from_secs(120)) {
        let passed_on = line.starts_with("stopping:");
        said.push(line);
        if passed_on {
            break;
        }
    }
    signal_runs("-CONT");
    let out = runner.wait_with_output().unwrap();
    reader.join().unwrap();
    said.extend(said_rx.try_iter());
    let printed = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        said.join("\n")
    );
    assert_eq!(
        out.status.code(),
        Some(dhrl::sweep::EXIT_INTERRUPTED),
        "{printed}"
    );
    let stopped: Vec<_> = sweep
        .runs
        .iter()
        .filter(|r| {
            matches!(
                sweep.state(r),
                RunState::Ended(RunOutcome::Interrupted { .. })
            )
        })
        .collect();
    assert!(!stopped.is_empty(), "no run was stopped: {printed}");
    let printed = ok(&dhrl(&["sweep", "run", &folder, "--jobs", "2"]));
    assert!(printed.contains("4 finished, 0 failed"), "{printed}");
    for run in stopped {
        let whole = train_in_one_go(dir.path(), run);
        assert_same_logs(&sweep.run_dir(run), &whole);
    }
}

/// `dhrl sweep slurm --submit` against a real one-node Slurm (tests/common/slurm.rs): one
/// array task per run. Once its run has a checkpoint, one task is preempted with `scontrol
/// requeue` (Slurm's SIGTERM reaches the run), the other gets the script's pre-limit signal
/// (USR1 to the batch shell, as `--signal=B:USR1@…` sends it; the script requeues the task
/// itself). Both resume from their checkpoints when Slurm starts them again, and every run
/// ends as it does under the local runner.
#[test]
fn a_slurm_array_requeues_stopped_tasks_and_ends_like_the_local_runner() {
    let Some(slurm) = common::slurm::Slurm::start(
        "a_slurm_array_requeues_stopped_tasks_and_ends_like_the_local_runner",
    ) else {
        return;
    };
    // Two runs long enough (checkpoints every 200 of 3,000 steps) to be caught mid-way.
    let experiment = TINY
        .replace("seeds = [0, 1]", "seeds = [3]")
        .replace("steps = 600", "steps = 3000");
    let dir = tempfile::tempdir().unwrap();
    let sweep = plan(dir.path(), &experiment, "on-slurm", 2);
    let folder = sweep.dir.to_str().unwrap().to_string();
    let out = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args([
            "sweep",
            "slurm",
            &folder,
            "--time",
            "20",
            "--signal-lead",
            "60",
        ])
        .arg("--submit")
        .env("SLURM_CONF", slurm.conf())
        .output()
        .unwrap();
    let printed = ok(&out);
    let job = printed
        .lines()
        .find_map(|l| {
            l.split_once(": job ")
                .map(|(_, job)| job.trim().to_string())
        })
        .unwrap_or_else(|| panic!("no job id in: {printed}"));
    let script = std::fs::read_to_string(sweep.dir.join("slurm/array-0.sbatch")).unwrap();
    for directive in [
        "--array=0-1",
        "--requeue",
        "--signal=B:USR1@60",
        "--time=20",
    ] {
        assert!(script.contains(&format!("#SBATCH {directive}")), "{script}");
    }
    let stop = |run: &ManifestRun, program: &str, args: &[&str]| {
        wait_for_a_checkpoint(&sweep, std::slice::from_ref(run));
        let out = slurm.command(program, args);
        assert!(
            out.status.success(),
            "{program} {args:?}: {}\n{}",
            String::from_utf8_lossy(&out.stderr),
            slurm.logs()
        );
    };
    let (preempted, warned) = (&sweep.runs[0], &sweep.runs[1]);
    stop(preempted, "scontrol", &["requeue", &format!("{job}_0")]);
    stop(
        warned,
        "scancel",
        &["--batch", "--signal=USR1", &format!("{job}_1")],
    );
    // Slurm holds a requeued task back for a while (BeginTime); the test releases it, but not in
    // the second of its requeue: slurmd refuses a launch whose credential dates from the second
    // the previous one was revoked in ("Job credential revoked"), and the task then ends with
    // exit 1 instead of running again (seen in CI). The array has ended when every run has
    // finished and Slurm lists none of its tasks, or when Slurm has listed none for 2 s (a
    // failed `squeue` prints nothing, so only successful answers count).
    let start = Instant::now();
    let mut pending_since = std::collections::HashMap::new();
    let mut empty_since: Option<Instant> = None;
    loop {
        let answer = slurm.command("squeue", &["-h", "-j", &job, "-o", "%i %T %r"]);
        let queue = String::from_utf8_lossy(&answer.stdout).into_owned();
        if answer.status.success() && queue.trim().is_empty() {
            let since = *empty_since.get_or_insert_with(Instant::now);
            if sweep.runs.iter().all(|run| sweep.finished(run))
                || since.elapsed() > Duration::from_secs(2)
            {
                break;
            }
        } else {
            empty_since = None;
        }
        for line in queue.lines().filter(|l| l.ends_with("PENDING BeginTime")) {
            let task = line.split(' ').next().unwrap().to_string();
            let since = *pending_since
                .entry(task.clone())
                .or_insert_with(Instant::now);
            if since.elapsed() > Duration::from_secs(3) {
                slurm.command(
                    "scontrol",
                    &["update", &format!("JobId={task}"), "StartTime=now"],
                );
                pending_since.remove(&task);
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(600),
            "the array has not ended after 10 min: {queue}{}\n{}",
            String::from_utf8_lossy(&answer.stderr),
            slurm.logs()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let logs = |run: &ManifestRun| {
        std::fs::read_to_string(
            sweep
                .dir
                .join(format!("slurm/logs/{job}_{}.log", run.index)),
        )
        .unwrap_or_default()
    };
    for run in [preempted, warned] {
        let log = logs(run);
        assert!(
            log.contains("(restart 0)") && log.contains("(restart 1)"),
            "{}: the stopped task ran twice: {log}",
            run.id
        );
    }
    assert!(
        logs(warned).contains("requeueing"),
        "the pre-limit signal requeued the task: {}",
        logs(warned)
    );
    for run in &sweep.runs {
        assert!(
            sweep.finished(run),
            "{}: {:?}\n{}",
            run.id,
            sweep.state(run),
            logs(run)
        );
    }
    // The same experiment under the local runner: the same runs, the same logs.
    let local = plan(dir.path(), &experiment, "local", 2);
    let printed = ok(&dhrl(&[
        "sweep",
        "run",
        local.dir.to_str().unwrap(),
        "--jobs",
        "2",
    ]));
    assert!(printed.contains("2 finished, 0 failed"), "{printed}");
    for (run, reference) in sweep.runs.iter().zip(&local.runs) {
        assert_eq!(run.id, reference.id);
        assert_same_logs(&sweep.run_dir(run), &local.run_dir(reference));
    }
    // Nothing is left to submit.
    let printed = ok(&dhrl(&["sweep", "slurm", &folder]));
    assert!(printed.contains("every run has finished"), "{printed}");
}

/// `dhrl sweep run --stack 2` trains each cell's two seeds as one stack per process: killed
/// once the first checkpoints exist and started again, every run ends with the logs of its
/// configuration trained alone in one go, its status recorded. `sweep slurm --stack 2` writes
/// one array task per stack group, and `run-one --stack 2 --group G` finds a finished group
/// finished.
#[test]
fn a_stacked_sweep_resumes_and_ends_as_its_runs_alone() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = plan_tiny(dir.path());
    let folder = sweep.dir.to_str().unwrap().to_string();
    let groups = dhrl::sweep::stack_groups(&sweep, 2);
    assert_eq!(groups.len(), 2, "{groups:?}");
    for group in &groups {
        let (a, b) = (&sweep.runs[group[0]].config, &sweep.runs[group[1]].config);
        assert_ne!(a.seed, b.seed);
        assert_eq!(
            (a.algo.name(), a.delay.observation_delay),
            (b.algo.name(), b.delay.observation_delay)
        );
    }
    let printed = ok(&dhrl(&["sweep", "slurm", &folder, "--stack", "2"]));
    assert!(
        printed.contains("2 stacks (manifest stack groups 0..=1)"),
        "{printed}"
    );
    let script = std::fs::read_to_string(sweep.dir.join("slurm/array-0.sbatch")).unwrap();
    for line in [
        "#SBATCH --array=0-1",
        "runs=(0 1)",
        "--stack 2 --group \"$index\"",
    ] {
        assert!(script.contains(line), "{line} not in {script}");
    }
    start_and_kill_runner(&sweep, &folder, &["--stack", "2"]);
    let printed = ok(&dhrl(&[
        "sweep", "run", &folder, "--jobs", "2", "--stack", "2",
    ]));
    assert!(printed.contains("4 finished, 0 failed"), "{printed}");
    for run in &sweep.runs {
        let whole = train_in_one_go(dir.path(), run);
        assert_same_logs(&sweep.run_dir(run), &whole);
        assert!(finished_return(&sweep, run.index).is_finite());
    }
    let printed = ok(&dhrl(&[
        "sweep", "run-one", &folder, "--stack", "2", "--group", "1",
    ]));
    assert_eq!(printed.matches("finished before").count(), 2, "{printed}");
}
