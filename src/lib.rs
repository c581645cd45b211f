//! dhrl: delayed homomorphic reinforcement learning on batched MuJoCo tasks.
pub mod algos;
pub mod bench;
pub mod charts;
pub mod delay;
pub mod float_mode;
pub mod learn;
pub mod report;
pub mod rollout;
pub mod seeds;
pub mod sim;
pub mod snapshot;
pub mod sweep;
pub mod tabular;
pub mod tasks;
pub mod train;
