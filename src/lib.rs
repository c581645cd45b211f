//! dhrl: delayed homomorphic reinforcement learning on batched MuJoCo tasks.
pub mod bench;
pub mod rollout;
pub mod sim;
pub mod tasks;
