//! One simulation copy with Gymnasium v4's step, reset and time-limit semantics.
use std::sync::Arc;

use mujoco_rs::prelude::MjData;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::{MAX_EPISODE_STEPS, SimError, TaskModel, check_vector};
use crate::tasks::{Progress, ResetNoise, SimData};

/// What one environment step returned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    pub reward: f64,
    /// The MDP ended (no bootstrapping).
    pub terminated: bool,
    /// The time limit ended the episode (bootstrap from the last state), or the simulation
    /// diverged.
    pub truncated: bool,
    /// MuJoCo found the state unstable (a bad qpos, qvel or qacc: a NaN or a value beyond
    /// `mjMAXVAL`) and reset it to `qpos0` in the middle of this step: the step's next state
    /// and reward are not the task's, so the episode ends here, truncated, with reward 0, and
    /// the step is no transition to learn from.
    pub diverged: bool,
}

impl StepOutcome {
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// One copy of a task.
pub struct Env {
    model: Arc<TaskModel>,
    data: SimData,
    /// Steps since the last reset (Gymnasium's `TimeLimit` counter).
    elapsed: u32,
    /// The reward's forward coordinate as of the last step or reset (read from MuJoCo's
    /// derived quantities, which a restored state does not carry).
    progress: f64,
}

/// Everything that determines a copy's future: MuJoCo's integration state
/// (`mjSTATE_INTEGRATION`, warm start included) and the wrapper's counters.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnvSnapshot {
    pub physics: Vec<f64>,
    pub elapsed: u32,
    pub progress: f64,
}

const INTEGRATION_STATE: u32 = mujoco_rs::prelude::MjtState::mjSTATE_INTEGRATION as u32;

impl Env {
    /// A copy in MuJoCo's initial state (`qpos0`, zero velocity), not yet reset with noise.
    pub fn new(model: Arc<TaskModel>) -> Env {
        let mut data = MjData::new(model.model.clone());
        data.forward();
        let mut env = Env {
            model,
            data,
            elapsed: 0,
            progress: 0.0,
        };
        env.progress = env.read_progress();
        env
    }

    pub fn model(&self) -> &TaskModel {
        &self.model
    }

    /// Steps taken since the last reset or `set_state`.
    pub fn elapsed(&self) -> u32 {
        self.elapsed
    }

    /// `mj_resetData`, the task's reset noise on `qpos0` / zero `qvel`, then `mj_forward`.
    pub fn reset(&mut self, rng: &mut impl Rng) {
        let m = &self.model;
        let (qpos, qvel): (Vec<f64>, Vec<f64>) = match m.task.reset_noise {
            ResetNoise::Uniform { scale } => (
                m.init_qpos
                    .iter()
                    .map(|q| q + rng.random_range(-scale..scale))
                    .collect(),
                (0..m.nv).map(|_| rng.random_range(-scale..scale)).collect(),
            ),
            ResetNoise::UniformPositionNormalVelocity { scale } => (
                m.init_qpos
                    .iter()
                    .map(|q| q + rng.random_range(-scale..scale))
                    .collect(),
                (0..m.nv)
                    .map(|_| {
                        scale * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng)
                    })
                    .collect(),
            ),
        };
        self.data.reset();
        self.write_state(&qpos, &qvel);
    }

    /// Gymnasium's `set_state`: copy `qpos`/`qvel` in, then `mj_forward`; restarts the time limit.
    pub fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), SimError> {
        check_vector("qpos", qpos, self.model.nq)?;
        check_vector("qvel", qvel, self.model.nv)?;
        self.write_state(qpos, qvel);
        Ok(())
    }

    fn write_state(&mut self, qpos: &[f64], qvel: &[f64]) {
        self.data.qpos_mut().copy_from_slice(qpos);
        self.data.qvel_mut().copy_from_slice(qvel);
        self.data.forward();
        self.elapsed = 0;
        self.progress = self.read_progress();
    }

    /// The state to continue from exactly, with [`Env::restore`].
    pub fn snapshot(&self) -> EnvSnapshot {
        EnvSnapshot {
            physics: self.data.state(INTEGRATION_STATE).into_vec(),
            elapsed: self.elapsed,
            progress: self.progress,
        }
    }

    /// Continues from a [`Env::snapshot`] of a copy of the same task.
    pub fn restore(&mut self, snapshot: &EnvSnapshot) -> Result<(), SimError> {
        let expected = self.model.model.state_size(INTEGRATION_STATE);
        if snapshot.physics.len() != expected {
            return Err(SimError::WrongLength {
                what: "a saved physics state",
                found: snapshot.physics.len(),
                expected,
            });
        }
        self.data
            .set_state(&snapshot.physics, INTEGRATION_STATE)
            .map_err(|e| SimError::LoadFailed {
                path: "a saved physics state".into(),
                message: e.to_string(),
            })?;
        self.elapsed = snapshot.elapsed;
        self.progress = snapshot.progress;
        Ok(())
    }

    /// The task's observation of the current state.
    pub fn observe(&self, out: &mut [f64]) {
        (self.model.task.observe)(&self.data, out)
    }

    /// `ctrl = action`, `mj_step` × frame_skip, `mj_rnePostConstraint`; writes the new
    /// observation into `obs`. The action is not clipped (MuJoCo clamps controls itself), and
    /// the control cost uses it as given, as in Gymnasium.
    pub fn step(&mut self, action: &[f64], obs: &mut [f64]) -> StepOutcome {
        let task = self.model.task;
        let before = self.progress;
        let resets_before = self.instability_resets();
        self.data.ctrl_mut().copy_from_slice(action);
        for _ in 0..task.frame_skip {
            self.data.step();
        }
        self.data.rne_post_constraint();
        self.progress = self.read_progress();
        self.observe(obs);
        self.elapsed += 1;
        if self.instability_resets() > resets_before {
            return StepOutcome {
                reward: 0.0,
                terminated: false,
                truncated: true,
                diverged: true,
            };
        }
        let velocity = (self.progress - before) / self.model.dt;
        let ctrl_cost = task.ctrl_cost_weight * action.iter().map(|a| a * a).sum::<f64>();
        let reward = task.forward_weight * velocity + task.healthy_reward - ctrl_cost;
        StepOutcome {
            reward,
            terminated: (task.terminated)(&self.data),
            truncated: self.elapsed >= MAX_EPISODE_STEPS,
            diverged: false,
        }
    }

    /// How often MuJoCo has reset this copy's state for instability (its bad-qpos, bad-qvel and
    /// bad-qacc warning counters together).
    fn instability_resets(&self) -> i64 {
        use mujoco_rs::mujoco_c::mjtWarning::{mjWARN_BADQACC, mjWARN_BADQPOS, mjWARN_BADQVEL};
        let warnings = self.data.warning();
        [mjWARN_BADQPOS, mjWARN_BADQVEL, mjWARN_BADQACC]
            .iter()
            .map(|&w| i64::from(warnings[w as usize].number))
            .sum()
    }

    /// The coordinate whose change per `dt` is the forward velocity of the reward.
    fn read_progress(&self) -> f64 {
        let m = &self.model;
        match m.task.progress {
            Progress::None => 0.0,
            Progress::RootX => self.data.qpos()[0],
            Progress::BodyX { .. } => self.data.xpos()[m.progress_body][0],
            Progress::CenterOfMassX => {
                let weighted: f64 = m
                    .body_mass
                    .iter()
                    .zip(self.data.xipos())
                    .map(|(mass, p)| mass * p[0])
                    .sum();
                weighted / m.total_mass
            }
        }
    }
}
