//! Checkpoints: everything a run needs to continue exactly — networks, optimiser states,
//! random streams, the simulator and delay layer, and the replay store — written to
//! `DIR/checkpoint.partial/` and then swapped in by renames, so a crash at any moment leaves
//! either the previous or the new checkpoint whole.
use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Serialize, de::DeserializeOwned};

use super::{TrainError, io_error};

pub const CHECKPOINT: &str = "checkpoint";
const PARTIAL: &str = "checkpoint.partial";
const PREVIOUS: &str = "checkpoint.previous";

/// The folder a new checkpoint is written into (emptied first).
pub fn begin(run: &Path) -> Result<PathBuf, TrainError> {
    let partial = run.join(PARTIAL);
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(io_error(&partial))?;
    }
    std::fs::create_dir_all(partial.join("agent")).map_err(io_error(&partial))?;
    Ok(partial)
}

/// Removes a partial checkpoint whose writing failed (it would hold the space a full disk
/// needs back).
pub fn discard_partial(run: &Path) -> Result<(), TrainError> {
    let partial = run.join(PARTIAL);
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(io_error(&partial))?;
    }
    Ok(())
}

/// Makes each run's partial checkpoint its current one. A stack's runs are committed
/// together, in two passes: every run first swaps its new checkpoint in and keeps its previous
/// one, and only then are the previous ones removed. A crash in the first pass leaves each run
/// holding the step before (current or previous), which [`available`] finds, so that a stack
/// resumes from one step.
pub fn commit_all(runs: &[&Path]) -> Result<(), TrainError> {
    for run in runs {
        let (partial, current, previous) =
            (run.join(PARTIAL), run.join(CHECKPOINT), run.join(PREVIOUS));
        sync_dir(&partial)?;
        if current.exists() {
            if previous.exists() {
                std::fs::remove_dir_all(&previous).map_err(io_error(&previous))?;
            }
            std::fs::rename(&current, &previous).map_err(io_error(&current))?;
        }
        std::fs::rename(&partial, &current).map_err(io_error(&partial))?;
        sync_dir(run)?;
    }
    for run in runs {
        let previous = run.join(PREVIOUS);
        if previous.exists() {
            std::fs::remove_dir_all(&previous).map_err(io_error(&previous))?;
        }
    }
    Ok(())
}

/// Every whole checkpoint `run` holds (the current one, and the previous one while a commit
/// is under way), with its environment steps.
pub fn available(run: &Path) -> Result<Vec<(u64, PathBuf)>, TrainError> {
    let mut found = Vec::new();
    for name in [CHECKPOINT, PREVIOUS] {
        let dir = run.join(name);
        if dir.join("state.json").is_file() {
            found.push((env_steps(&dir)?, dir));
        }
    }
    Ok(found)
}

/// The environment steps of the checkpoint in `dir` (its `state.json`).
pub fn env_steps(dir: &Path) -> Result<u64, TrainError> {
    let state = dir.join("state.json");
    let value: serde_json::Value = read_json(&state)?;
    value["env_steps"].as_u64().ok_or_else(|| TrainError::Io {
        path: state.display().to_string(),
        message: "no env_steps in the checkpoint's state".into(),
    })
}

/// The checkpoint to resume from: the current one, or the previous one when a crash hit
/// between the renames of [`commit_all`].
pub fn latest(run: &Path) -> Option<PathBuf> {
    [CHECKPOINT, PREVIOUS]
        .iter()
        .map(|name| run.join(name))
        .find(|dir| dir.join("state.json").is_file())
}

/// Whether `run` holds a checkpoint to resume from.
pub fn has_checkpoint(run: &Path) -> bool {
    latest(run).is_some()
}

fn sync_dir(dir: &Path) -> Result<(), TrainError> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(io_error(dir))
}

pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), TrainError> {
    let mut out = BufWriter::new(File::create(path).map_err(io_error(path))?);
    serde_json::to_writer(&mut out, value).map_err(|e| TrainError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    let file = out
        .into_inner()
        .map_err(|e| io_error(path)(e.into_error()))?;
    file.sync_all().map_err(io_error(path))
}

pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, TrainError> {
    let input = BufReader::new(File::open(path).map_err(io_error(path))?);
    serde_json::from_reader(input).map_err(|e| TrainError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// Writes a binary file through `write`, synced to disk.
pub fn write_binary(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), TrainError>,
) -> Result<(), TrainError> {
    let mut out = BufWriter::new(File::create(path).map_err(io_error(path))?);
    write(&mut out)?;
    out.flush().map_err(io_error(path))?;
    out.get_ref().sync_all().map_err(io_error(path))
}

pub fn open_binary(path: &Path) -> Result<BufReader<File>, TrainError> {
    Ok(BufReader::new(File::open(path).map_err(io_error(path))?))
}
