//! Hopper-v4: hop forward without falling.
use super::{
    Progress, ResetNoise, SimData, TaskDef, TaskName, observe_planar_walker, strictly_between,
};

pub static HOPPER: TaskDef = TaskDef {
    name: TaskName::Hopper,
    xml: "hopper.xml",
    frame_skip: 4,
    obs_dim: 11,
    act_dim: 3,
    reset_noise: ResetNoise::Uniform { scale: 5e-3 },
    progress: Progress::RootX,
    forward_weight: 1.0,
    healthy_reward: 1.0,
    ctrl_cost_weight: 1e-3,
    observe: observe_planar_walker,
    observes_constraint_forces: false,
    terminated,
};

/// Unhealthy unless qpos[2:] and qvel lie in (−100, 100), z > 0.7 and |angle| < 0.2.
fn terminated(data: &SimData) -> bool {
    let qpos = data.qpos();
    let state_ok = qpos[2..]
        .iter()
        .chain(data.qvel())
        .all(|&v| strictly_between(v, -100.0, 100.0));
    let z_ok = strictly_between(qpos[1], 0.7, f64::INFINITY);
    let angle_ok = strictly_between(qpos[2], -0.2, 0.2);
    !(state_ok && z_ok && angle_ok)
}
