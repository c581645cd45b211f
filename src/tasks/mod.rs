//! The six benchmark tasks of the paper, with Gymnasium MuJoCo v4 semantics (docs/DESIGN.md §2).
//!
//! A task is a small, declarative definition over one simulation copy: its model file, frame
//! skip, reset noise, observation, reward weights and termination. Stepping, batching, threading
//! and delays live elsewhere (`crate::sim`), once for all tasks.

mod ant;
mod half_cheetah;
mod hopper;
mod humanoid;
mod inverted_pendulum;
mod walker2d;

use std::fmt;
use std::str::FromStr;

use mujoco_rs::prelude::{MjData, MjModel};
use serde::{Deserialize, Serialize};

/// The simulation data of one copy, sharing its model with every other copy.
pub type SimData = MjData<std::sync::Arc<MjModel>>;

/// Noise added to `qpos0` / zero `qvel` on reset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ResetNoise {
    /// qpos += U(±scale), qvel += U(±scale).
    Uniform { scale: f64 },
    /// qpos += U(±scale), qvel += scale·N(0, 1) (Ant, HalfCheetah).
    UniformPositionNormalVelocity { scale: f64 },
}

/// Which quantity's change over one environment step is the forward velocity of the reward.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// No forward term (InvertedPendulum).
    None,
    /// `qpos[0]`, the root slider (HalfCheetah, Hopper, Walker2d).
    RootX,
    /// x of the `xpos` of a body frame (Ant: the torso).
    BodyX { body: &'static str },
    /// x of the mass-weighted mean of the bodies' `xipos` (Humanoid).
    CenterOfMassX,
}

/// One task: everything that differs between the benchmark environments.
pub struct TaskDef {
    pub name: TaskName,
    pub xml: &'static str,
    pub frame_skip: usize,
    pub obs_dim: usize,
    pub act_dim: usize,
    pub reset_noise: ResetNoise,
    pub progress: Progress,
    /// reward = forward_weight·velocity + healthy_reward − ctrl_cost_weight·Σa²
    /// (v4 pays the healthy reward on every step, the terminating one included).
    pub forward_weight: f64,
    pub healthy_reward: f64,
    pub ctrl_cost_weight: f64,
    /// Writes the observation of the current state into `out` (`obs_dim` long).
    pub observe: fn(&SimData, &mut [f64]),
    /// Whether `observe` reads the forces `mj_rnePostConstraint` computes after a step
    /// (`cfrc_ext`). Gymnasium v4 calls it after every step, but nothing else reads what it
    /// writes (`cacc`, `cfrc_int`, `cfrc_ext` are outputs, never the next step's inputs), so
    /// a task whose observation does not read them leaves it out: the same observations,
    /// rewards and flags, without its cost.
    pub observes_constraint_forces: bool,
    /// Whether the current state ends the episode (the MDP's terminal condition).
    pub terminated: fn(&SimData) -> bool,
}

impl fmt::Debug for TaskDef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TaskDef")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

/// The task names accepted on the command line and in configs (kebab-case).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "cli", value(rename_all = "kebab-case"))]
pub enum TaskName {
    Ant,
    HalfCheetah,
    Hopper,
    Walker2d,
    Humanoid,
    InvertedPendulum,
}

impl TaskName {
    pub const ALL: [TaskName; 6] = [
        TaskName::Ant,
        TaskName::HalfCheetah,
        TaskName::Hopper,
        TaskName::Walker2d,
        TaskName::Humanoid,
        TaskName::InvertedPendulum,
    ];

    /// The kebab-case name used on the CLI.
    pub fn as_str(self) -> &'static str {
        match self {
            TaskName::Ant => "ant",
            TaskName::HalfCheetah => "half-cheetah",
            TaskName::Hopper => "hopper",
            TaskName::Walker2d => "walker2d",
            TaskName::Humanoid => "humanoid",
            TaskName::InvertedPendulum => "inverted-pendulum",
        }
    }

    /// The Gymnasium id whose semantics the task reproduces.
    pub fn gymnasium_id(self) -> &'static str {
        match self {
            TaskName::Ant => "Ant-v4",
            TaskName::HalfCheetah => "HalfCheetah-v4",
            TaskName::Hopper => "Hopper-v4",
            TaskName::Walker2d => "Walker2d-v4",
            TaskName::Humanoid => "Humanoid-v4",
            TaskName::InvertedPendulum => "InvertedPendulum-v4",
        }
    }

    /// The task's definition.
    pub fn def(self) -> &'static TaskDef {
        match self {
            TaskName::Ant => &ant::ANT,
            TaskName::HalfCheetah => &half_cheetah::HALF_CHEETAH,
            TaskName::Hopper => &hopper::HOPPER,
            TaskName::Walker2d => &walker2d::WALKER2D,
            TaskName::Humanoid => &humanoid::HUMANOID,
            TaskName::InvertedPendulum => &inverted_pendulum::INVERTED_PENDULUM,
        }
    }
}

impl fmt::Display for TaskName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A task name that is not one of the six.
#[derive(Debug, thiserror::Error)]
#[error("unknown task '{given}'; valid tasks are: {}", valid_task_names())]
pub struct UnknownTask {
    pub given: String,
}

fn valid_task_names() -> String {
    TaskName::ALL.map(TaskName::as_str).join(", ")
}

impl FromStr for TaskName {
    type Err = UnknownTask;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TaskName::ALL
            .into_iter()
            .find(|t| t.as_str() == s)
            .ok_or_else(|| UnknownTask {
                given: s.to_string(),
            })
    }
}

/// Copies `src` into `out` starting at `*at`, advancing `*at`.
fn put(out: &mut [f64], at: &mut usize, src: &[f64]) {
    out[*at..*at + src.len()].copy_from_slice(src);
    *at += src.len();
}

/// Like [`put`], clipping every value to `[-limit, limit]` (Hopper and Walker2d velocities).
fn put_clipped(out: &mut [f64], at: &mut usize, src: &[f64], limit: f64) {
    for (o, v) in out[*at..*at + src.len()].iter_mut().zip(src) {
        *o = v.clamp(-limit, limit);
    }
    *at += src.len();
}

/// qpos[1:] ++ clip(qvel, ±10): the observation of Hopper and Walker2d.
fn observe_planar_walker(data: &SimData, out: &mut [f64]) {
    let mut at = 0;
    put(out, &mut at, &data.qpos()[1..]);
    put_clipped(out, &mut at, data.qvel(), 10.0);
}

/// `lo < v < hi`, false for NaN (as NumPy's comparisons).
fn strictly_between(v: f64, lo: f64, hi: f64) -> bool {
    lo < v && v < hi
}
