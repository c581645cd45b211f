//! Running a sweep's runs: one run in this process ([`run_one`], what every engine calls in the
//! end), or all of them on this machine, N child processes at a time ([`run_local`]).
use std::collections::VecDeque;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::SweepError;
use super::manifest::{ManifestRun, RunOutcome, RunState, Sweep};
use crate::progress::Progress;

use crate::train::{Start, TrainConfig, TrainError, TrainSummary, checkpoint_step, train_stack};

/// The exit code of `dhrl sweep run-one` for a run stopped by a signal after a checkpoint
/// (EX_TEMPFAIL): the engine should start it again.
pub const EXIT_INTERRUPTED: i32 = 75;
/// The exit code of `dhrl sweep run-one` for a run another process is running.
pub const EXIT_BUSY: i32 = 73;

/// What [`run_one`] did.
#[derive(Debug, Clone, PartialEq)]
pub enum RunOneResult {
    AlreadyFinished,
    /// Another process holds the run's lock.
    Busy,
    Ended(RunOutcome),
}

/// Runs (or resumes) the run at `index` in this process: nothing if it finished before; a
/// fresh start if it has no checkpoint (a folder without one holds only the logs of its first
/// steps: it is moved aside to `runs/<id>.without-checkpoint`); otherwise a resume from its
/// checkpoint. The outcome is recorded in the sweep folder. A lock file keeps two processes
/// from running the same run.
pub fn run_one(sweep: &Sweep, index: usize, progress: bool) -> Result<RunOneResult, SweepError> {
    Ok(run_group(sweep, &[index], progress)?.remove(0).1)
}

/// Runs (or resumes) the runs at `group` (of one cell: one configuration, their seeds apart)
/// as stacks in this process ([`crate::train::train_stack`]), each as [`run_one`] would run it
/// alone: the finished ones and those another process holds are left out, the others locked;
/// those without a checkpoint start as one stack, those with one resume in stacks of one
/// checkpoint step (a run's checkpoint is whole on its own). Each run's outcome is recorded.
pub fn run_group(
    sweep: &Sweep,
    group: &[usize],
    progress: bool,
) -> Result<Vec<(usize, RunOneResult)>, SweepError> {
    let mut results = Vec::new();
    let mut locks = Vec::new();
    // Runs to start, and runs to resume by their checkpoint's step.
    let mut fresh = Vec::new();
    let mut resumed: std::collections::BTreeMap<u64, Vec<&ManifestRun>> = Default::default();
    for &index in group {
        let run = sweep.run(index)?;
        if sweep.finished(run) {
            results.push((index, RunOneResult::AlreadyFinished));
            continue;
        }
        let Some(lock) = lock(sweep, run)? else {
            results.push((index, RunOneResult::Busy));
            continue;
        };
        // Another process may have finished it between the look above and the lock.
        if sweep.finished(run) {
            results.push((index, RunOneResult::AlreadyFinished));
            continue;
        }
        locks.push(lock);
        sweep.clear_outcome(run)?;
        let dir = sweep.run_dir(run);
        match checkpoint_step(&dir) {
            Some(step) => resumed.entry(step).or_default().push(run),
            None => {
                set_aside(&dir)?;
                fresh.push(run);
            }
        }
    }
    let stacks = std::iter::once((fresh, Start::Fresh))
        .chain(resumed.into_values().map(|runs| (runs, Start::Resume)));
    for (runs, start) in stacks {
        if runs.is_empty() {
            continue;
        }
        let members: Vec<(TrainConfig, PathBuf)> = runs
            .iter()
            .map(|run| (run.config.clone(), sweep.run_dir(run)))
            .collect();
        let outcomes: Vec<RunOutcome> = match train_stack(&members, &members[0].1, start, progress)
        {
            Ok(ended) => ended.into_iter().map(outcome).collect(),
            Err(whole) => {
                let shared = outcome(Err(whole));
                vec![shared; runs.len()]
            }
        };
        for (run, outcome) in runs.iter().zip(outcomes) {
            sweep.record(run, &outcome)?;
            results.push((run.index, RunOneResult::Ended(outcome)));
        }
    }
    results.sort_by_key(|(index, _)| group.iter().position(|i| i == index));
    Ok(results)
}

/// How a run's training ended, as the sweep records it.
fn outcome(ended: Result<TrainSummary, TrainError>) -> RunOutcome {
    match ended {
        Ok(summary) => RunOutcome::Finished {
            env_steps: summary.env_steps,
            wall_seconds: summary.wall_seconds,
            final_return: summary.last_eval.map(|e| e.return_mean),
        },
        Err(TrainError::Interrupted { env_steps, .. }) => RunOutcome::Interrupted { env_steps },
        Err(e) => RunOutcome::Failed {
            error: e.to_string(),
        },
    }
}

/// Moves a run folder without a checkpoint (the logs of its first steps only) aside to
/// `<folder>.without-checkpoint`, so that the run starts afresh.
fn set_aside(dir: &Path) -> Result<(), SweepError> {
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |e: std::io::Error| SweepError::Io {
            path,
            message: e.to_string(),
        }
    };
    if dir.exists() {
        let aside = dir.with_extension("without-checkpoint");
        if aside.exists() {
            std::fs::remove_dir_all(&aside).map_err(io(&aside))?;
        }
        std::fs::rename(dir, &aside).map_err(io(dir))?;
    }
    Ok(())
}

/// The sweep's runs in stacks of at most `size`: each cell's runs (one configuration, their
/// seeds apart) in manifest order, cut into groups of `size`; with `size` 1, every run alone in
/// manifest order. Fixed by the manifest alone (finished runs keep their place), so that a
/// group's number names the same runs in every engine and after every restart.
pub fn stack_groups(sweep: &Sweep, size: usize) -> Vec<Vec<usize>> {
    if size <= 1 {
        return sweep.runs.iter().map(|run| vec![run.index]).collect();
    }
    let mut cells: Vec<(String, Vec<usize>)> = Vec::new();
    for run in &sweep.runs {
        let cell = toml::to_string(&TrainConfig {
            seed: 0,
            ..run.config.clone()
        })
        .unwrap_or_default();
        match cells.iter_mut().find(|(key, _)| *key == cell) {
            Some((_, runs)) => runs.push(run.index),
            None => cells.push((cell, vec![run.index])),
        }
    }
    cells
        .into_iter()
        .flat_map(|(_, runs)| runs.chunks(size).map(<[usize]>::to_vec).collect::<Vec<_>>())
        .collect()
}

/// An exclusive lock on `runs/<id>.lock`, or `None` when another process holds it.
fn lock(sweep: &Sweep, run: &ManifestRun) -> Result<Option<File>, SweepError> {
    let path = sweep.dir.join("runs").join(format!("{}.lock", run.id));
    let io = |e: std::io::Error| SweepError::Io {
        path: path.display().to_string(),
        message: format!(
            "{e} (runs are locked with flock: the sweep folder must be on a filesystem that \
             supports it; NFS needs lockd, Lustre the flock mount option)"
        ),
    };
    std::fs::create_dir_all(sweep.dir.join("runs")).map_err(io)?;
    let file = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(io)?;
    match file.try_lock() {
        Ok(()) => Ok(Some(file)),
        Err(std::fs::TryLockError::WouldBlock) => Ok(None),
        Err(std::fs::TryLockError::Error(e)) => Err(io(e)),
    }
}

/// What [`run_local`] counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LocalSummary {
    pub finished: usize,
    pub failed: usize,
    /// Stopped with a checkpoint (by a signal, or by this runner's own stop): the next start
    /// resumes them.
    pub interrupted: usize,
    /// Held by another process (another runner, a Slurm task) whenever this one tried them.
    pub busy: usize,
}

/// How often the runner looks at its children, and how often it retries a run another
/// process holds before leaving it to that process.
const TICK: Duration = Duration::from_millis(500);
const BUSY_RETRIES: u32 = 10;

/// Sleeps one [`TICK`], cut short when `stop` is set while the runner is not `stopping` yet:
/// the children hear the runner's stop within milliseconds, not up to a tick later (a
/// cluster's grace time between its SIGTERM and its SIGKILL is short).
fn wait_a_tick(stop: &AtomicBool, stopping: bool) {
    let start = Instant::now();
    while start.elapsed() < TICK && (stopping || !stop.load(Ordering::Relaxed)) {
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Runs every run of `sweep` that has not finished, `jobs` processes at a time: with `stack`
/// 1 each run in its own child process, with `stack` S the runs in the groups of
/// [`stack_groups`], one child per group, from `spawn(unit, log)` (which runs [`run_one`] on
/// run `unit`, or [`run_group`] on group `unit`, with its output into `log`). Failed runs are
/// recorded and skipped unless `retry_failed`; one failure never stops the others. When `stop`
/// becomes true (the runner's own SIGTERM, SIGINT or SIGHUP), nothing is started any more,
/// the running children get SIGTERM (their runs checkpoint and exit) and the runner waits for
/// them. Killed outright, the sweep resumes its cut runs when started again.
pub fn run_local(
    sweep: &Sweep,
    jobs: usize,
    stack: usize,
    retry_failed: bool,
    progress: bool,
    stop: &AtomicBool,
    spawn: impl Fn(usize, File) -> std::io::Result<Child>,
) -> Result<LocalSummary, SweepError> {
    let mut summary = LocalSummary::default();
    let to_run = |run: &ManifestRun| match sweep.state(run) {
        RunState::Ended(RunOutcome::Finished { .. }) => false,
        RunState::Ended(RunOutcome::Failed { .. }) => retry_failed,
        _ => true,
    };
    for run in sweep.runs.iter().filter(|run| !to_run(run)) {
        match sweep.state(run) {
            RunState::Ended(RunOutcome::Finished { .. }) => summary.finished += 1,
            _ => summary.failed += 1,
        }
    }
    // Each unit: its number for `spawn`, its runs still to run, the tries so far.
    type Unit<'a> = (usize, Vec<&'a ManifestRun>, u32);
    let mut todo: VecDeque<Unit> = stack_groups(sweep, stack)
        .into_iter()
        .enumerate()
        .filter_map(|(group, indices)| {
            let runs: Vec<&ManifestRun> = indices
                .iter()
                .map(|&i| &sweep.runs[i])
                .filter(|run| to_run(run))
                .collect();
            let unit = if stack <= 1 { indices[0] } else { group };
            (!runs.is_empty()).then_some((unit, runs, 0))
        })
        .collect();
    // Steps done per run of this runner's, refreshed for the running ones only.
    let mut steps: Vec<(&ManifestRun, u64)> = todo
        .iter()
        .flat_map(|(_, runs, _)| runs.iter().map(|r| (*r, steps_done(sweep, r))))
        .collect();
    let total_steps: u64 = steps.iter().map(|(r, _)| r.config.steps).sum();
    let steps_before: u64 = steps.iter().map(|(_, s)| s).sum();
    let bar = Progress::new(
        total_steps,
        "{bar:30} {pos}/{len} steps  ETA {eta}  {msg}",
        progress,
    );
    bar.set_position(steps_before);
    bar.reset_eta();
    let say = |line: String| bar.println(line);
    let logs = sweep.dir.join("logs");
    std::fs::create_dir_all(&logs).map_err(|e| SweepError::Io {
        path: logs.display().to_string(),
        message: e.to_string(),
    })?;
    let mut running: Vec<(Unit, Child)> = Vec::new();
    let mut stopping = false;
    while !running.is_empty() || (!todo.is_empty() && !stopping) {
        if stop.load(Ordering::Relaxed) && !stopping {
            stopping = true;
            say(format!(
                "stopping: {} running processes checkpoint and exit",
                running.len()
            ));
            for (_, child) in &running {
                // SAFETY: kill(2) on our own child's pid, which we have not waited for yet.
                unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
            }
        }
        while !stopping
            && running.len() < jobs.max(1)
            && let Some(unit) = todo.pop_front()
        {
            // A stack's output goes to its first run's log.
            let path = logs.join(format!("{}.log", unit.1[0].id));
            let child = File::options()
                .create(true)
                .append(true)
                .open(&path)
                .and_then(|log| spawn(unit.0, log))
                .map_err(|e| SweepError::Io {
                    path: path.display().to_string(),
                    message: format!("could not start run {}: {e}", unit.1[0].id),
                })?;
            running.push((unit, child));
        }
        wait_a_tick(stop, stopping);
        let mut k = 0;
        while k < running.len() {
            let exited = running[k].1.try_wait().map_err(|e| SweepError::Io {
                path: running[k].0.1[0].id.clone(),
                message: e.to_string(),
            })?;
            let Some(status) = exited else {
                k += 1;
                continue;
            };
            let ((unit, runs, tries), _) = running.swap_remove(k);
            let mut busy = Vec::new();
            for run in runs {
                match (status.code(), sweep.state(run)) {
                    (_, RunState::Ended(RunOutcome::Finished { final_return, .. })) => {
                        summary.finished += 1;
                        say(format!(
                            "{}: finished, final return {}",
                            run.id,
                            final_return.map_or("-".into(), |r| format!("{r:.1}"))
                        ));
                    }
                    (_, RunState::Ended(RunOutcome::Failed { error })) => {
                        summary.failed += 1;
                        say(format!("{}: failed: {error}", run.id));
                    }
                    (Some(EXIT_INTERRUPTED), _)
                    | (_, RunState::Ended(RunOutcome::Interrupted { .. })) => {
                        summary.interrupted += 1;
                        say(format!("{}: stopped with a checkpoint", run.id));
                    }
                    (Some(EXIT_BUSY), _) => busy.push(run),
                    (None, _) => {
                        // Killed by a signal: its last checkpoint stands, the next start resumes it.
                        summary.interrupted += 1;
                        say(format!(
                            "{}: its process was killed ({status}); the next start resumes it",
                            run.id
                        ));
                    }
                    (Some(_), _) => {
                        // Ended before it could record anything (see its log).
                        let error = format!(
                            "the run's process ended with {status} (see logs/{}.log)",
                            run.id
                        );
                        if let Some(_lock) = lock(sweep, run)? {
                            sweep.record(
                                run,
                                &RunOutcome::Failed {
                                    error: error.clone(),
                                },
                            )?;
                        }
                        summary.failed += 1;
                        say(format!("{}: failed: {error}", run.id));
                    }
                }
            }
            if !busy.is_empty() {
                if tries < BUSY_RETRIES && !stopping {
                    // Perhaps a killed process still lets go of them: try again later.
                    todo.push_back((unit, busy, tries + 1));
                } else {
                    for run in busy {
                        summary.busy += 1;
                        say(format!("{}: another process is running it", run.id));
                    }
                }
            }
        }
        for (run, done) in steps.iter_mut() {
            // Only a run that is or was just running can have moved (a look at its log).
            if *done < run.config.steps && sweep.run_dir(run).exists() {
                *done = steps_done(sweep, run).min(run.config.steps);
            }
        }
        bar.set_position(steps.iter().map(|(_, s)| s).sum());
        bar.set_message(format!(
            "runs: {} finished, {} processes running, {} failed, {} to start",
            summary.finished,
            running.len(),
            summary.failed,
            todo.len()
        ));
    }
    bar.finish();
    Ok(summary)
}

/// Environment steps a run has logged (its last `train.csv` row; 0 before one).
pub fn steps_done(sweep: &Sweep, run: &ManifestRun) -> u64 {
    if let RunState::Ended(RunOutcome::Finished { env_steps, .. }) = sweep.state(run) {
        return env_steps;
    }
    last_logged_step(&sweep.run_dir(run).join("train.csv"))
}

fn last_logged_step(csv: &Path) -> u64 {
    std::fs::read_to_string(csv)
        .ok()
        .and_then(|text| {
            text.lines()
                .rev()
                .find_map(|line| line.split(',').next()?.parse::<u64>().ok())
        })
        .unwrap_or(0)
}
