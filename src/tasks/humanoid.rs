//! Humanoid-v4: walk forward; the observation includes com-based inertia, velocities and forces.
use super::{Progress, ResetNoise, SimData, TaskDef, TaskName, put, strictly_between};

pub static HUMANOID: TaskDef = TaskDef {
    name: TaskName::Humanoid,
    xml: "humanoid.xml",
    frame_skip: 5,
    obs_dim: 376,
    act_dim: 17,
    reset_noise: ResetNoise::Uniform { scale: 1e-2 },
    progress: Progress::CenterOfMassX,
    forward_weight: 1.25,
    healthy_reward: 5.0,
    ctrl_cost_weight: 0.1,
    observe,
    observes_constraint_forces: true,
    terminated,
};

/// qpos[2:] 22 ++ qvel 23 ++ cinert 140 ++ cvel 84 ++ qfrc_actuator 23 ++ cfrc_ext 84.
fn observe(data: &SimData, out: &mut [f64]) {
    let mut at = 0;
    put(out, &mut at, &data.qpos()[2..]);
    put(out, &mut at, data.qvel());
    put(out, &mut at, data.cinert().as_flattened());
    put(out, &mut at, data.cvel().as_flattened());
    put(out, &mut at, data.qfrc_actuator());
    put(out, &mut at, data.cfrc_ext().as_flattened());
}

/// Unhealthy unless 1.0 < z < 2.0.
fn terminated(data: &SimData) -> bool {
    !strictly_between(data.qpos()[2], 1.0, 2.0)
}
