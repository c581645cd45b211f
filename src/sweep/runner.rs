//! Running a sweep's runs: one run in this process ([`run_one`], what every engine calls in the
//! end), or all of them on this machine, N child processes at a time ([`run_local`]).
use std::collections::VecDeque;
use std::fs::File;
use std::path::Path;
use std::process::Child;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

use super::SweepError;
use super::manifest::{ManifestRun, RunOutcome, RunState, Sweep};
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
/// fresh start if it has no checkpoint (a folder without one holds nothing a resume could
/// use); otherwise a resume from its checkpoint. The outcome is recorded in the sweep folder.
/// A lock file keeps two processes from running the same run.
pub fn run_one(sweep: &Sweep, index: usize, progress: bool) -> Result<RunOneResult, SweepError> {
    let run = sweep.run(index)?;
    if let RunState::Ended(RunOutcome::Finished { .. }) = sweep.state(run) {
        return Ok(RunOneResult::AlreadyFinished);
    }
    let Some(_lock) = lock(sweep, run)? else {
        return Ok(RunOneResult::Busy);
    };
    sweep.clear_outcome(run)?;
    let dir = sweep.run_dir(run);
    let start = if has_checkpoint(&dir) {
        Start::Resume
    } else {
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| SweepError::Io {
                path: dir.display().to_string(),
                message: e.to_string(),
            })?;
        }
        if let Some(parent) = dir.parent() {
            std::fs::create_dir_all(parent).map_err(|e| SweepError::Io {
                path: parent.display().to_string(),
                message: e.to_string(),
            })?;
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
        message: e.to_string(),
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
    pub interrupted: usize,
    /// Held by another process (another runner, a Slurm task) when this one came to them.
    pub busy: usize,
}

/// Runs every run of `sweep` that has not finished, `jobs` at a time, each in a child process
/// from `spawn(index, log)` (which runs [`run_one`] with its output into `log`). Failed runs
/// are recorded and skipped unless `retry_failed`; one failure never stops the others. The
/// sweep can be killed at any moment: started again, it resumes the cut runs.
pub fn run_local(
    sweep: &Sweep,
    jobs: usize,
    retry_failed: bool,
    progress: bool,
    spawn: impl Fn(usize, File) -> std::io::Result<Child>,
) -> Result<LocalSummary, SweepError> {
    let mut summary = LocalSummary::default();
    let mut todo: VecDeque<&ManifestRun> = VecDeque::new();
    for run in &sweep.runs {
        match sweep.state(run) {
            RunState::Ended(RunOutcome::Finished { .. }) => summary.finished += 1,
            RunState::Ended(RunOutcome::Failed { .. }) if !retry_failed => summary.failed += 1,
            _ => todo.push_back(run),
        }
    }
    let mine: Vec<&ManifestRun> = todo.iter().copied().collect();
    let total_steps: u64 = mine.iter().map(|r| r.config.steps).sum();
    let steps_before: u64 = mine.iter().map(|r| steps_done(sweep, r)).sum();
    let bar = if progress {
        ProgressBar::new(total_steps)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps  ETA {eta}  {msg}")
            .expect("a valid template"),
    );
    let logs = sweep.dir.join("logs");
    std::fs::create_dir_all(&logs).map_err(|e| SweepError::Io {
        path: logs.display().to_string(),
        message: e.to_string(),
    })?;
    let started = Instant::now();
    let mut running: Vec<(&ManifestRun, Child)> = Vec::new();
    while !todo.is_empty() || !running.is_empty() {
        while running.len() < jobs.max(1)
            && let Some(run) = todo.pop_front()
        {
            let path = logs.join(format!("{}.log", run.id));
            let log = File::options()
                .create(true)
                .append(true)
                .open(&path)
                .and_then(|log| spawn(run.index, log))
                .map_err(|e| SweepError::Io {
                    path: path.display().to_string(),
                    message: format!("could not start run {}: {e}", run.id),
                })?;
            running.push((run, log));
        }
        std::thread::sleep(Duration::from_millis(200));
        let mut k = 0;
        while k < running.len() {
            let exited = running[k].1.try_wait().map_err(|e| SweepError::Io {
                path: running[k].0.id.clone(),
                message: e.to_string(),
            })?;
            let Some(status) = exited else {
                k += 1;
                continue;
            };
            let (run, _) = running.swap_remove(k);
            match sweep.state(run) {
                RunState::Ended(RunOutcome::Finished { .. }) => summary.finished += 1,
                RunState::Ended(RunOutcome::Interrupted { .. }) => summary.interrupted += 1,
                RunState::Ended(RunOutcome::Failed { .. }) => summary.failed += 1,
                _ if status.code() == Some(EXIT_BUSY) => summary.busy += 1,
                _ => {
                    // Died without recording (killed, crashed): say so, keep its checkpoint.
                    sweep.record(
                        run,
                        &RunOutcome::Failed {
                            error: format!(
                                "the run's process ended with {status} (see logs/{}.log)",
                                run.id
                            ),
                        },
                    )?;
                    summary.failed += 1;
                }
            }
        }
        let steps_now: u64 = mine
            .iter()
            .map(|r| steps_done(sweep, r).min(r.config.steps))
            .sum();
        let done_here = steps_now.saturating_sub(steps_before);
        bar.set_position(steps_now);
        if done_here > 0 {
            let rate = done_here as f64 / started.elapsed().as_secs_f64();
            bar.set_message(format!(
                "runs: {} finished, {} running, {} failed, {} to start  ({rate:.0} steps/s)",
                summary.finished,
                running.len(),
                summary.failed,
                todo.len()
            ));
        }
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
