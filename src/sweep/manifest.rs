//! A sweep folder: `manifest.jsonl` (one line per run: its index, id and whole configuration),
//! `runs/<id>/` (each run's own folder, as `dhrl train` writes it) and `status/<id>.json`
//! (how a run ended). Re-planning adds new runs at the end and keeps every existing one at its
//! index, so Slurm array indices and run folders never move.
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::SweepError;
use super::experiment::PlannedRun;
use crate::train::TrainConfig;

const MANIFEST: &str = "manifest.jsonl";

/// One line of the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestRun {
    pub index: usize,
    pub id: String,
    pub config: TrainConfig,
}

/// How a run ended, as `status/<id>.json` records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "state", rename_all = "kebab-case")]
pub enum RunOutcome {
    Finished {
        env_steps: u64,
        wall_seconds: f64,
        /// The last evaluation's mean return.
        final_return: Option<f64>,
    },
    Failed {
        error: String,
    },
    /// Stopped by a signal after writing a checkpoint; the next start resumes it.
    Interrupted {
        env_steps: u64,
    },
}

/// Where a run stands.
#[derive(Debug, Clone, PartialEq)]
pub enum RunState {
    /// No run folder yet.
    Pending,
    /// A run folder without an outcome: running now, or cut off (it resumes from its
    /// checkpoint).
    Started,
    Ended(RunOutcome),
}

/// A sweep folder and its manifest.
#[derive(Debug, Clone)]
pub struct Sweep {
    pub dir: PathBuf,
    pub runs: Vec<ManifestRun>,
}

/// What [`Sweep::plan`] did to the manifest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlanChange {
    pub added: usize,
    pub kept: usize,
    /// Runs of an earlier plan that this one does not name (kept, never deleted).
    pub not_in_plan: usize,
    /// New runs named like an earlier one but for the configuration hash: a setting changed
    /// (or a newer dhrl resolves more fields), so they run beside the earlier ones.
    pub like_earlier: usize,
}

/// An id without its configuration hash: what a run is, not exactly how it is configured.
fn readable_part(id: &str) -> &str {
    id.rsplit_once('-').map_or(id, |(readable, _)| readable)
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> SweepError + '_ {
    move |e| SweepError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Writes `text` to `path` through a temporary file and a rename, so readers see the old
/// file or the new one, never a part.
pub fn write_atomically(path: &Path, text: &str) -> Result<(), SweepError> {
    crate::files::write_atomically(path, text).map_err(io(path))
}

impl Sweep {
    /// Opens the sweep in `dir`.
    pub fn open(dir: &Path) -> Result<Sweep, SweepError> {
        let path = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&path).map_err(|e| SweepError::Io {
            path: path.display().to_string(),
            message: format!(
                "{e} (is {} a sweep folder? `dhrl sweep plan` makes one)",
                dir.display()
            ),
        })?;
        let runs = text
            .lines()
            .enumerate()
            .filter(|(_, line)| !line.trim().is_empty())
            .map(|(k, line)| {
                serde_json::from_str::<ManifestRun>(line).map_err(|e| SweepError::Io {
                    path: path.display().to_string(),
                    message: format!("line {}: {e}", k + 1),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        if let Some((k, run)) = runs.iter().enumerate().find(|(k, run)| run.index != *k) {
            return Err(SweepError::Io {
                path: path.display().to_string(),
                message: format!(
                    "line {} holds index {}; indices must count up from 0",
                    k + 1,
                    run.index
                ),
            });
        }
        Ok(Sweep {
            dir: dir.to_path_buf(),
            runs,
        })
    }

    /// Opens the sweep in `dir` (or starts one there) and adds the planned runs it lacks.
    pub fn plan(dir: &Path, planned: &[PlannedRun]) -> Result<(Sweep, PlanChange), SweepError> {
        let mut sweep = if dir.join(MANIFEST).exists() {
            Sweep::open(dir)?
        } else {
            std::fs::create_dir_all(dir).map_err(io(dir))?;
            Sweep {
                dir: dir.to_path_buf(),
                runs: Vec::new(),
            }
        };
        let before = sweep.runs.len();
        let mut kept = 0;
        for run in planned {
            match sweep.runs.iter().find(|r| r.id == run.id) {
                Some(existing) if existing.config == run.config => kept += 1,
                Some(_) => {
                    return Err(SweepError::Invalid(format!(
                        "run {} is in the manifest with another configuration (edited by hand?)",
                        run.id
                    )));
                }
                None => sweep.runs.push(ManifestRun {
                    index: sweep.runs.len(),
                    id: run.id.clone(),
                    config: run.config.clone(),
                }),
            }
        }
        let added = sweep.runs.len() - before;
        let like_earlier = sweep.runs[before..]
            .iter()
            .filter(|new| {
                sweep.runs[..before]
                    .iter()
                    .any(|old| readable_part(&old.id) == readable_part(&new.id))
            })
            .count();
        let text: String = sweep
            .runs
            .iter()
            .map(|run| serde_json::to_string(run).expect("a manifest line serialises") + "\n")
            .collect();
        write_atomically(&dir.join(MANIFEST), &text)?;
        Ok((
            sweep,
            PlanChange {
                added,
                kept,
                not_in_plan: before - kept,
                like_earlier,
            },
        ))
    }

    /// The run at Slurm array index / manifest line `index`.
    pub fn run(&self, index: usize) -> Result<&ManifestRun, SweepError> {
        self.runs.get(index).ok_or_else(|| {
            SweepError::Invalid(format!(
                "no run at index {index}: the manifest of {} holds indices 0..={}",
                self.dir.display(),
                self.runs.len().saturating_sub(1)
            ))
        })
    }

    pub fn run_dir(&self, run: &ManifestRun) -> PathBuf {
        self.dir.join("runs").join(&run.id)
    }

    fn status_path(&self, run: &ManifestRun) -> PathBuf {
        self.dir.join("status").join(format!("{}.json", run.id))
    }

    pub fn state(&self, run: &ManifestRun) -> RunState {
        let outcome = std::fs::read_to_string(self.status_path(run))
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok());
        match outcome {
            Some(outcome) => RunState::Ended(outcome),
            None if self.run_dir(run).exists() => RunState::Started,
            None => RunState::Pending,
        }
    }

    /// Whether the run finished (its outcome says so).
    pub fn finished(&self, run: &ManifestRun) -> bool {
        matches!(
            self.state(run),
            RunState::Ended(RunOutcome::Finished { .. })
        )
    }

    /// Records how a run ended.
    pub fn record(&self, run: &ManifestRun, outcome: &RunOutcome) -> Result<(), SweepError> {
        let path = self.status_path(run);
        let dir = path.parent().expect("status files live in a folder");
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let text = serde_json::to_string_pretty(outcome).expect("an outcome serialises");
        write_atomically(&path, &text)
    }

    /// Forgets a run's outcome (before it is run again).
    pub fn clear_outcome(&self, run: &ManifestRun) -> Result<(), SweepError> {
        let path = self.status_path(run);
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(&path)(e)),
            _ => Ok(()),
        }
    }
}
