//! dhrl: delayed homomorphic reinforcement learning on batched MuJoCo tasks.
pub mod acting;
pub mod algos;
pub mod bench;
pub mod delay;
pub mod deploy;
pub mod export;
pub mod files;
pub mod float_mode;
pub mod learn;
pub mod progress;
pub mod protocol;
#[cfg(feature = "cli")]
pub mod report;
pub mod rollout;
pub mod seeds;
pub mod sim;
pub mod snapshot;
pub mod sweep;
pub mod tasks;
pub mod train;

/// The charts, from the workspace crate `dhrl-charts`.
#[cfg(feature = "cli")]
pub use dhrl_charts as charts;
/// Finite-domain DHRL (`dhrl tabular`), from the workspace crate `dhrl-tabular`.
#[cfg(feature = "cli")]
pub use dhrl_tabular as tabular;
