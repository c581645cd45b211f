//! Ant-v4 (without contact forces in the observation, as the benchmark uses it).
use super::{Progress, ResetNoise, SimData, TaskDef, TaskName, put};

pub static ANT: TaskDef = TaskDef {
    name: TaskName::Ant,
    xml: "ant.xml",
    frame_skip: 5,
    obs_dim: 27,
    act_dim: 8,
    reset_noise: ResetNoise::UniformPositionNormalVelocity { scale: 0.1 },
    progress: Progress::BodyX { body: "torso" },
    forward_weight: 1.0,
    healthy_reward: 1.0,
    ctrl_cost_weight: 0.5,
    observe,
    observes_constraint_forces: false,
    terminated,
};

/// qpos[2:] ++ qvel.
fn observe(data: &SimData, out: &mut [f64]) {
    let mut at = 0;
    put(out, &mut at, &data.qpos()[2..]);
    put(out, &mut at, data.qvel());
}

/// Unhealthy unless the whole state is finite and 0.2 ≤ z ≤ 1.0.
fn terminated(data: &SimData) -> bool {
    let finite = data.qpos().iter().chain(data.qvel()).all(|v| v.is_finite());
    let z = data.qpos()[2];
    !(finite && (0.2..=1.0).contains(&z))
}
