//! InvertedPendulum-v4: keep the pole up; reward 1 per step.
use super::{Progress, ResetNoise, SimData, TaskDef, TaskName, put};

pub static INVERTED_PENDULUM: TaskDef = TaskDef {
    name: TaskName::InvertedPendulum,
    xml: "inverted_pendulum.xml",
    frame_skip: 2,
    obs_dim: 4,
    act_dim: 1,
    reset_noise: ResetNoise::Uniform { scale: 0.01 },
    progress: Progress::None,
    forward_weight: 0.0,
    healthy_reward: 1.0,
    ctrl_cost_weight: 0.0,
    observe,
    observes_constraint_forces: false,
    terminated,
};

/// qpos ++ qvel.
fn observe(data: &SimData, out: &mut [f64]) {
    let mut at = 0;
    put(out, &mut at, data.qpos());
    put(out, &mut at, data.qvel());
}

/// Ends when the state is not finite or the pole leaves |angle| ≤ 0.2.
fn terminated(data: &SimData) -> bool {
    let finite = data.qpos().iter().chain(data.qvel()).all(|v| v.is_finite());
    !finite || data.qpos()[1].abs() > 0.2
}
