//! HalfCheetah-v4: run forward; never terminates.
use super::{Progress, ResetNoise, SimData, TaskDef, TaskName, put};

pub static HALF_CHEETAH: TaskDef = TaskDef {
    name: TaskName::HalfCheetah,
    xml: "half_cheetah.xml",
    frame_skip: 5,
    obs_dim: 17,
    act_dim: 6,
    reset_noise: ResetNoise::UniformPositionNormalVelocity { scale: 0.1 },
    progress: Progress::RootX,
    forward_weight: 1.0,
    healthy_reward: 0.0,
    ctrl_cost_weight: 0.1,
    observe,
    observes_constraint_forces: false,
    terminated: |_| false,
};

/// qpos[1:] ++ qvel.
fn observe(data: &SimData, out: &mut [f64]) {
    let mut at = 0;
    put(out, &mut at, &data.qpos()[1..]);
    put(out, &mut at, data.qvel());
}
