//! One simulation copy with Gymnasium v4's step, reset and time-limit semantics.
use std::sync::Arc;

use mujoco_rs::prelude::MjData;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::model::INTEGRATION_STATE;
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

    /// Gymnasium's reset: `mj_resetData` ([`TaskModel::reset_data`], which writes what that
    /// call leaves), the task's reset noise on `qpos0` / zero `qvel`, then `mj_forward`.
    pub fn reset(&mut self, rng: &mut impl Rng) {
        let (qpos, qvel) = self.reset_noise(rng);
        self.model.reset_data(&mut self.data);
        self.write_state(&qpos, &qvel);
    }

    /// `qpos0` and zero `qvel` with the task's reset noise drawn from `rng`.
    fn reset_noise(&self, rng: &mut impl Rng) -> (Vec<f64>, Vec<f64>) {
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
        (qpos, qvel)
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

    /// `ctrl = action`, `mj_step` × frame_skip, `mj_rnePostConstraint` where the observation
    /// reads its forces ([`crate::tasks::TaskDef::observes_constraint_forces`]); writes the new
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
        if task.observes_constraint_forces {
            self.data.rne_post_constraint();
        }
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

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::tasks::TaskName;

    /// dhrl's two shortcuts change nothing: a copy reset and stepped as dhrl does it, and its
    /// twin reset and stepped as Gymnasium v4 does (`mj_resetData` before the reset state is
    /// written; `mj_rnePostConstraint` after every step, then the observation), stay
    /// bit-identical in physics state, observation, reward and flags over episodes of random
    /// actions on every task, and the flag that leaves `mj_rnePostConstraint` out is set
    /// exactly where the observation reads `cfrc_ext`.
    #[test]
    fn resets_and_steps_match_gymnasiums_sequence_bit_for_bit() {
        for task in TaskName::ALL {
            let model = TaskModel::load(task).unwrap();
            let (low, high) = (model.action_low.clone(), model.action_high.clone());
            let obs_dim = task.def().obs_dim;
            let (mut ours, mut gymnasium) = (Env::new(model.clone()), Env::new(model));
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let (mut obs, mut gym_obs) = (vec![0.0; obs_dim], vec![0.0; obs_dim]);
            let (mut episodes, mut ended) = (0, true);
            // Past HalfCheetah's time limit, and past a few terminations elsewhere.
            for step in 0..1_100 {
                if ended {
                    let (qpos, qvel) = gymnasium.reset_noise(&mut rng.clone());
                    gymnasium.data.reset();
                    gymnasium.write_state(&qpos, &qvel);
                    ours.reset(&mut rng);
                    episodes += 1;
                    ours.observe(&mut obs);
                    gymnasium.observe(&mut gym_obs);
                    assert_bits_equal(&obs, &gym_obs, &format!("{task} reset {episodes}"));
                }
                let action: Vec<f64> = low
                    .iter()
                    .zip(&high)
                    .map(|(&l, &h)| rng.random_range(l..h))
                    .collect();
                let outcome = ours.step(&action, &mut obs);
                let gym_outcome = gymnasium.step(&action, &mut gym_obs);
                gymnasium.data.rne_post_constraint();
                gymnasium.observe(&mut gym_obs);
                let at = format!("{task} step {step}");
                assert_eq!(outcome, gym_outcome, "{at}");
                assert_bits_equal(&obs, &gym_obs, &at);
                assert_eq!(
                    ours.snapshot().physics,
                    gymnasium.snapshot().physics,
                    "{at}"
                );
                ended = outcome.terminated || outcome.truncated;
            }
            assert!(episodes > 1, "{task}: no episode ended");
            // The flag is right: only an observation of constraint forces changes with them.
            ours.observe(&mut obs);
            for force in ours.data.cfrc_ext_mut().as_flattened_mut() {
                *force += 1.0;
            }
            ours.observe(&mut gym_obs);
            assert_eq!(
                obs != gym_obs,
                task.def().observes_constraint_forces,
                "{task}: whether its observation reads cfrc_ext"
            );
        }
    }

    fn assert_bits_equal(ours: &[f64], gymnasium: &[f64], at: &str) {
        if let Some(i) = (0..ours.len()).find(|&i| ours[i].to_bits() != gymnasium[i].to_bits()) {
            panic!(
                "{at}: obs[{i}] is {} here, {} in Gymnasium's sequence",
                ours[i], gymnasium[i]
            );
        }
    }
}
