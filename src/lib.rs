//! dhrl: delayed homomorphic reinforcement learning on batched MuJoCo tasks.
pub mod bench;
pub mod delay;
pub mod rollout;
pub mod sim;
pub mod tabular;
pub mod tasks;
