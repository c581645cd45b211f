//! Running a sweep's runs: one run in this process ([`run_one`], what every engine calls in the
//! end), or all of them on this machine, N child processes at a time ([`run_local`]).
use std::collections::VecDeque;
use std::fs::File;
use std::path::Path;
use std::process::Child;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use super::SweepError;
use super::manifest::{ManifestRun, RunOutcome, RunState, Sweep};
use crate::progress::Progress;
use crate::train::{Start, TrainError, has_checkpoint, train};

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
    let run = sweep.run(index)?;
    if sweep.finished(run) {
        return Ok(RunOneResult::AlreadyFinished);
    }
    let Some(_lock) = lock(sweep, run)? else {
        return Ok(RunOneResult::Busy);
    };
    // Another process may have finished it between the look above and the lock.
    if sweep.finished(run) {
        return Ok(RunOneResult::AlreadyFinished);
    }
    sweep.clear_outcome(run)?;
    let dir = sweep.run_dir(run);
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |e: std::io::Error| SweepError::Io {
            path,
            message: e.to_string(),
        }
    };
    let start = if has_checkpoint(&dir) {
        Start::Resume
    } else {
        if dir.exists() {
            let aside = dir.with_extension("without-checkpoint");
            if aside.exists() {
                std::fs::remove_dir_all(&aside).map_err(io(&aside))?;
            }
            std::fs::rename(&dir, &aside).map_err(io(&dir))?;
        }
        Start::Fresh
    };
    let outcome = match train(&run.config, &dir, start, progress) {
        Ok(summary) => RunOutcome::Finished {
            env_steps: summary.env_steps,
            wall_seconds: summary.wall_seconds,
            final_return: summary.last_eval.map(|e| e.return_mean),
        },
        Err(TrainError::Interrupted { env_steps, .. }) => RunOutcome::Interrupted { env_steps },
        Err(e) => RunOutcome::Failed {
            error: e.to_string(),
        },
    };
    sweep.record(run, &outcome)?;
    Ok(RunOneResult::Ended(outcome))
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

/// Runs every run of `sweep` that has not finished, `jobs` at a time, each in a child process
/// from `spawn(index, log)` (which runs [`run_one`] with its output into `log`). Failed runs
/// are recorded and skipped unless `retry_failed`; one failure never stops the others. When
/// `stop` becomes true (the runner's own SIGTERM, SIGINT or SIGHUP), no run is started any
/// more, the running ones get SIGTERM (they checkpoint and exit) and the runner waits for
/// them. Killed outright, the sweep resumes its cut runs when started again.
pub fn run_local(
    sweep: &Sweep,
    jobs: usize,
    retry_failed: bool,
    progress: bool,
    stop: &AtomicBool,
    spawn: impl Fn(usize, File) -> std::io::Result<Child>,
) -> Result<LocalSummary, SweepError> {
    let mut summary = LocalSummary::default();
    let mut todo: VecDeque<(&ManifestRun, u32)> = VecDeque::new();
    for run in &sweep.runs {
        match sweep.state(run) {
            RunState::Ended(RunOutcome::Finished { .. }) => summary.finished += 1,
            RunState::Ended(RunOutcome::Failed { .. }) if !retry_failed => summary.failed += 1,
            _ => todo.push_back((run, 0)),
        }
    }
    // Steps done per run of this runner's, refreshed for the running ones only.
    let mut steps: Vec<(&ManifestRun, u64)> = todo
        .iter()
        .map(|(r, _)| (*r, steps_done(sweep, r)))
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
    let mut running: Vec<(&ManifestRun, u32, Child)> = Vec::new();
    let mut stopping = false;
    while !running.is_empty() || (!todo.is_empty() && !stopping) {
        if stop.load(Ordering::Relaxed) && !stopping {
            stopping = true;
            say(format!(
                "stopping: {} running runs checkpoint and exit",
                running.len()
            ));
            for (_, _, child) in &running {
                // SAFETY: kill(2) on our own child's pid, which we have not waited for yet.
                unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
            }
        }
        while !stopping
            && running.len() < jobs.max(1)
            && let Some((run, tries)) = todo.pop_front()
        {
            let path = logs.join(format!("{}.log", run.id));
            let child = File::options()
                .create(true)
                .append(true)
                .open(&path)
                .and_then(|log| spawn(run.index, log))
                .map_err(|e| SweepError::Io {
                    path: path.display().to_string(),
                    message: format!("could not start run {}: {e}", run.id),
                })?;
            running.push((run, tries, child));
        }
        std::thread::sleep(TICK);
        let mut k = 0;
        while k < running.len() {
            let exited = running[k].2.try_wait().map_err(|e| SweepError::Io {
                path: running[k].0.id.clone(),
                message: e.to_string(),
            })?;
            let Some(status) = exited else {
                k += 1;
                continue;
            };
            let (run, tries, _) = running.swap_remove(k);
            match (status.code(), sweep.state(run)) {
                (Some(EXIT_BUSY), _) if tries < BUSY_RETRIES && !stopping => {
                    // Perhaps a killed process still lets go of it: try again later.
                    todo.push_back((run, tries + 1));
                }
                (Some(EXIT_BUSY), _) => {
                    summary.busy += 1;
                    say(format!("{}: another process is running it", run.id));
                }
                (Some(0), RunState::Ended(RunOutcome::Finished { final_return, .. })) => {
                    summary.finished += 1;
                    say(format!(
                        "{}: finished, final return {}",
                        run.id,
                        final_return.map_or("-".into(), |r| format!("{r:.1}"))
                    ));
                }
                (Some(EXIT_INTERRUPTED), _) => {
                    summary.interrupted += 1;
                    say(format!("{}: stopped with a checkpoint", run.id));
                }
                (Some(_), RunState::Ended(RunOutcome::Failed { error })) => {
                    summary.failed += 1;
                    say(format!("{}: failed: {error}", run.id));
                }
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
        for (run, done) in steps.iter_mut() {
            // Only a run that is or was just running can have moved (a look at its log).
            if *done < run.config.steps && sweep.run_dir(run).exists() {
                *done = steps_done(sweep, run).min(run.config.steps);
            }
        }
        bar.set_position(steps.iter().map(|(_, s)| s).sum());
        bar.set_message(format!(
            "runs: {} finished, {} running, {} failed, {} to start",
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
