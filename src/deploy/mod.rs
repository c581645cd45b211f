//! Running an exported policy under delay: its manifest (`policy.json`) and the delay-aware
//! runtime [`DelayedPolicy`] (docs/deploy.md).
mod manifest;
mod runtime;

pub use manifest::{
    AugmentedStateLayout, DelayManifest, FORMAT, FORMAT_VERSION, FilesManifest, ManifestError,
    NetworkManifest, ParameterManifest, PolicyManifest, RunManifest, WarmupManifest,
};
pub use runtime::{ActionSource, DelayedPolicy, RuntimeError};
