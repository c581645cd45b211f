//! Walker2d-v4: walk forward without falling.
use super::{
    Progress, ResetNoise, SimData, TaskDef, TaskName, observe_planar_walker, strictly_between,
};

pub static WALKER2D: TaskDef = TaskDef {
    name: TaskName::Walker2d,
    xml: "walker2d.xml",
    frame_skip: 4,
    obs_dim: 17,
    act_dim: 6,
    reset_noise: ResetNoise::Uniform { scale: 5e-3 },
    progress: Progress::RootX,
    forward_weight: 1.0,
    healthy_reward: 1.0,
    ctrl_cost_weight: 1e-3,
    observe: observe_planar_walker,
    observes_constraint_forces: false,
    terminated,
};

/// Unhealthy unless 0.8 < z < 2.0 and −1 < angle < 1.
fn terminated(data: &SimData) -> bool {
    let qpos = data.qpos();
    !(strictly_between(qpos[1], 0.8, 2.0) && strictly_between(qpos[2], -1.0, 1.0))
}
