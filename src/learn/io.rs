//! Saving and restoring what learners are made of — burn modules, optimiser states and JSON
//! (random streams, schedules) — each under its file name in a checkpoint folder, with errors
//! that name the file.
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::store::ModuleRecord;
use burn::tensor::Bytes;
use serde::{Serialize, de::DeserializeOwned};

use super::LearnError;

/// A checkpoint folder, with a prefix before every file name (D2HPG keeps two learners in one
/// folder: `free_actor.bpk` beside `actor.bpk`).
#[derive(Debug, Clone, Copy)]
pub struct CheckpointDir<'a> {
    dir: &'a Path,
    prefix: &'a str,
}

impl<'a> CheckpointDir<'a> {
    pub fn new(dir: &'a Path) -> CheckpointDir<'a> {
        CheckpointDir { dir, prefix: "" }
    }

    pub fn with_prefix(dir: &'a Path, prefix: &'a str) -> CheckpointDir<'a> {
        CheckpointDir { dir, prefix }
    }

    /// The folders of a stack's runs, in run order, each with `prefix`.
    pub fn each(dirs: &[&'a Path], prefix: &'a str) -> Vec<CheckpointDir<'a>> {
        dirs.iter()
            .map(|dir| CheckpointDir::with_prefix(dir, prefix))
            .collect()
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(format!("{}{name}", self.prefix))
    }

    /// Writes `module` as `name` (burn's record format).
    pub fn save_module<M: Module>(&self, name: &str, module: &M) -> Result<(), LearnError> {
        let path = self.path(name);
        module
            .clone()
            .save_file(&path)
            .map_err(|e| save_error(&path, e))
    }

    /// `module` with the parameters saved as `name`, read whole into memory first.
    pub fn load_module<M: Module>(&self, name: &str, module: M) -> Result<M, LearnError> {
        let path = self.path(name);
        let record =
            ModuleRecord::from_bytes(read_whole(&path)?).map_err(|e| load_error(&path, e))?;
        module
            .try_load_record(record)
            .map_err(|e| load_error(&path, e))
    }

    /// Writes slice `slice` of a stacked module as `name`, in the solo shapes
    /// ([`super::slice_pack`]): what a solo run of that slice would write.
    pub fn save_slice<M: Module>(
        &self,
        name: &str,
        module: &M,
        slice: usize,
    ) -> Result<(), LearnError> {
        let path = self.path(name);
        let bytes = module
            .clone()
            .into_record()
            .into_bytes()
            .map_err(|e| save_error(&path, e))?;
        let bytes = super::slice_pack(bytes, slice).map_err(|e| save_error(&path, e))?;
        std::fs::write(&path, &*bytes).map_err(|e| save_error(&path, e))
    }

    /// Writes slice `slice` of a stacked module's optimiser state as `name`, in the solo shapes.
    pub fn save_optimizer_slice(
        &self,
        name: &str,
        optimizer: &ModuleOptimizer,
        slice: usize,
    ) -> Result<(), LearnError> {
        let path = self.path(name);
        let bytes = optimizer.into_bytes().map_err(|e| save_error(&path, e))?;
        let bytes = super::slice_pack(bytes, slice).map_err(|e| save_error(&path, e))?;
        std::fs::write(&path, &*bytes).map_err(|e| save_error(&path, e))
    }

    /// Writes an optimiser's state (Adam's moments and step counts) as `name`.
    pub fn save_optimizer(
        &self,
        name: &str,
        optimizer: &ModuleOptimizer,
    ) -> Result<(), LearnError> {
        let path = self.path(name);
        optimizer.save(&path).map_err(|e| save_error(&path, e))
    }

    /// `optimizer` with the state saved as `name`, read whole into memory first.
    pub fn load_optimizer(
        &self,
        name: &str,
        optimizer: ModuleOptimizer,
    ) -> Result<ModuleOptimizer, LearnError> {
        let path = self.path(name);
        optimizer
            .from_bytes(read_whole(&path)?)
            .map_err(|e| load_error(&path, e))
    }

    /// Writes `value` as JSON to `name`.
    pub fn save_json<T: Serialize>(&self, name: &str, value: &T) -> Result<(), LearnError> {
        let path = self.path(name);
        let bytes = serde_json::to_vec(value).map_err(|e| save_error(&path, e))?;
        std::fs::write(&path, bytes).map_err(|e| save_error(&path, e))
    }

    /// The JSON value saved as `name`.
    pub fn load_json<T: DeserializeOwned>(&self, name: &str) -> Result<T, LearnError> {
        let path = self.path(name);
        let bytes = std::fs::read(&path).map_err(|e| load_error(&path, e))?;
        serde_json::from_slice(&bytes).map_err(|e| load_error(&path, e))
    }
}

/// A stacked module with its slice `i` read from `slices[i]`'s `name` (as
/// [`CheckpointDir::save_slice`] wrote it, or a solo run's record of the same network).
pub fn load_stack<M: Module>(
    slices: &[CheckpointDir<'_>],
    name: &str,
    module: M,
) -> Result<M, LearnError> {
    let what = first_path(slices, name);
    let record = stacked_bytes(slices, name)
        .and_then(|bytes| ModuleRecord::from_bytes(bytes).map_err(|e| load_error(&what, e)))?;
    module
        .try_load_record(record)
        .map_err(|e| load_error(&what, e))
}

/// A stacked module's optimiser with its slice `i`'s state read from `slices[i]`'s `name`.
pub fn load_optimizer_stack(
    slices: &[CheckpointDir<'_>],
    name: &str,
    optimizer: ModuleOptimizer,
) -> Result<ModuleOptimizer, LearnError> {
    let what = first_path(slices, name);
    optimizer
        .from_bytes(stacked_bytes(slices, name)?)
        .map_err(|e| load_error(&what, e))
}

/// Each run's JSON value saved as `name` in `slices[i]`, in run order.
pub fn load_json_stack<T: DeserializeOwned>(
    slices: &[CheckpointDir<'_>],
    name: &str,
) -> Result<Vec<T>, LearnError> {
    slices.iter().map(|dir| dir.load_json(name)).collect()
}

/// `name` in the first slice's folder: what errors about a stacked record name.
fn first_path(slices: &[CheckpointDir<'_>], name: &str) -> PathBuf {
    slices
        .first()
        .map_or_else(|| PathBuf::from(name), |dir| dir.path(name))
}

/// The slices' records of `name`, read whole and stacked.
fn stacked_bytes(slices: &[CheckpointDir<'_>], name: &str) -> Result<Bytes, LearnError> {
    let parts = slices
        .iter()
        .map(|dir| read_whole(&dir.path(name)))
        .collect::<Result<Vec<_>, _>>()?;
    let what = first_path(slices, name);
    super::stack_packs(parts).map_err(|e| load_error(&what, e))
}

fn save_error(what: &Path, e: impl std::fmt::Display) -> LearnError {
    LearnError::Save {
        what: what.display().to_string(),
        message: e.to_string(),
    }
}

fn load_error(what: &Path, e: impl std::fmt::Display) -> LearnError {
    LearnError::Load {
        what: what.display().to_string(),
        message: e.to_string(),
    }
}

/// Reads a saved file whole into memory. burn's own `load_file`s read tensors lazily, from the
/// path, when a device first touches them: on wgpu that can come after the next checkpoint
/// replaced the file (then it silently loads the wrong weights) or after the folder was removed
/// (then burn's device thread panics). Loading from memory has neither window.
fn read_whole(path: &Path) -> Result<Bytes, LearnError> {
    let bytes = std::fs::read(path).map_err(|e| load_error(path, e))?;
    Ok(Bytes::from_bytes_vec(bytes))
}
