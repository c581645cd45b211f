//! N copies of one task against one shared model, stepped in parallel on a rayon pool, with
//! automatic resets and struct-of-arrays outputs ready to be uploaded to a GPU.
use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::{Env, SimError, TaskModel};
use crate::tasks::TaskName;

/// How to build a [`BatchedEnv`].
#[derive(Debug, Clone)]
pub struct BatchConfig {
    pub task: TaskName,
    pub envs: usize,
    /// Worker threads of the pool that steps the copies.
    pub threads: usize,
    /// Copy `i` draws from ChaCha8 stream `i` of this seed, whatever the thread count.
    pub seed: u64,
    /// σ of the Gaussian actuator noise: the executed action is `clip(a + N(0, σ²))` (docs/DESIGN.md §1.8).
    pub actuator_noise: f64,
}

/// What one copy does in a [`BatchedEnv::step_each`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u32)]
pub enum CopyStep {
    /// Apply its action and step once (resetting it where the episode ends).
    #[default]
    Step = 0,
    /// Stay as it is: no physics step, reward 0, no flags, its observation unchanged (a
    /// Gymnasium next-step autoreset, where the copy was already reset when its episode ended).
    Hold = 1,
    /// Start a new episode from its own random stream (a partial reset): reward 0, no flags.
    Restart = 2,
}

/// One copy with its own random stream and scratch space.
struct EnvCopy {
    env: Env,
    rng: ChaCha8Rng,
    executed_action: Vec<f64>,
    obs: Vec<f64>,
    episode_return: f64,
}

/// The outputs of one copy in one step, as slices of the batch arrays.
struct CopyOutputs<'a> {
    obs: &'a mut [f32],
    final_obs: &'a mut [f32],
    reward: &'a mut f32,
    terminated: &'a mut u32,
    truncated: &'a mut u32,
    diverged: &'a mut u32,
    episode_return: &'a mut f32,
    episode_length: &'a mut u32,
}

/// A batch of copies of one task. After every [`BatchedEnv::step`], row `i` of each array
/// belongs to copy `i`. A copy whose episode ended has already been reset: its row of
/// `observations` is the first observation of the new episode, and `final_observations`,
/// `episode_returns` and `episode_lengths` hold what the finished episode ended with.
pub struct BatchedEnv {
    model: Arc<TaskModel>,
    copies: Vec<EnvCopy>,
    pool: Arc<rayon::ThreadPool>,
    actuator_noise: Option<Normal<f64>>,
    observations: Vec<f32>,
    final_observations: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<u32>,
    truncated: Vec<u32>,
    /// Copies whose episode the last step ended because the simulation diverged
    /// ([`super::StepOutcome::diverged`]; their `truncated` is set too).
    diverged: Vec<u32>,
    episode_returns: Vec<f32>,
    episode_lengths: Vec<u32>,
    /// `[N]`: what each copy did in the last step.
    controls: Vec<CopyStep>,
}

/// Everything [`BatchedEnv::restore`] needs to continue a batch exactly.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct BatchSnapshot {
    pub task: TaskName,
    pub envs: Vec<super::env::EnvSnapshot>,
    pub rngs: Vec<ChaCha8Rng>,
    pub running_returns: Vec<f64>,
    pub observations: Vec<f32>,
    pub final_observations: Vec<f32>,
    pub rewards: Vec<f32>,
    pub terminated: Vec<u32>,
    pub truncated: Vec<u32>,
    pub episode_returns: Vec<f32>,
    pub episode_lengths: Vec<u32>,
}

impl BatchedEnv {
    /// The state of every copy and of the step outputs.
    pub fn snapshot(&self) -> BatchSnapshot {
        BatchSnapshot {
            task: self.task(),
            envs: self.copies.iter().map(|c| c.env.snapshot()).collect(),
            rngs: self.copies.iter().map(|c| c.rng.clone()).collect(),
            running_returns: self.copies.iter().map(|c| c.episode_return).collect(),
            observations: self.observations.clone(),
            final_observations: self.final_observations.clone(),
            rewards: self.rewards.clone(),
            terminated: self.terminated.clone(),
            truncated: self.truncated.clone(),
            episode_returns: self.episode_returns.clone(),
            episode_lengths: self.episode_lengths.clone(),
        }
    }

    /// Continues from a [`BatchedEnv::snapshot`] of a batch of the same task and size.
    pub fn restore(&mut self, snapshot: &BatchSnapshot) -> Result<(), SimError> {
        let n = self.copies.len();
        if snapshot.task != self.task() {
            return Err(SimError::Snapshot(format!(
                "it is of task {}, this batch runs {}",
                snapshot.task,
                self.task()
            )));
        }
        let same_sizes = [
            snapshot.envs.len(),
            snapshot.rngs.len(),
            snapshot.running_returns.len(),
            snapshot.rewards.len(),
        ]
        .iter()
        .all(|&len| len == n)
            && snapshot.observations.len() == self.observations.len();
        if !same_sizes {
            return Err(SimError::Snapshot(format!(
                "it holds {} copies, this batch has {n}",
                snapshot.envs.len()
            )));
        }
        for (i, copy) in self.copies.iter_mut().enumerate() {
            copy.env.restore(&snapshot.envs[i])?;
            copy.rng = snapshot.rngs[i].clone();
            copy.episode_return = snapshot.running_returns[i];
            let obs_dim = copy.obs.len();
            for (o, v) in copy
                .obs
                .iter_mut()
                .zip(&snapshot.observations[i * obs_dim..(i + 1) * obs_dim])
            {
                *o = f64::from(*v);
            }
        }
        self.observations.clone_from(&snapshot.observations);
        self.final_observations
            .clone_from(&snapshot.final_observations);
        self.rewards.clone_from(&snapshot.rewards);
        self.terminated.clone_from(&snapshot.terminated);
        self.truncated.clone_from(&snapshot.truncated);
        // Snapshots are taken between steps, when a divergence has been dealt with.
        self.diverged.fill(0);
        self.episode_returns.clone_from(&snapshot.episode_returns);
        self.episode_lengths.clone_from(&snapshot.episode_lengths);
        Ok(())
    }

    pub fn new(config: &BatchConfig) -> Result<BatchedEnv, SimError> {
        if config.envs == 0 {
            return Err(SimError::TooSmall {
                what: "the number of environment copies",
                found: 0.0,
                min: 1.0,
            });
        }
        if config.threads == 0 {
            return Err(SimError::TooSmall {
                what: "the number of threads",
                found: 0.0,
                min: 1.0,
            });
        }
        let actuator_noise = actuator_noise(config.actuator_noise)?;
        let model = TaskModel::load(config.task)?;
        let pool = crate::float_mode::thread_pool(config.threads, "dhrl-sim").map_err(|e| {
            SimError::ThreadPool {
                threads: config.threads,
                message: e.to_string(),
            }
        })?;
        let pool = Arc::new(pool);
        let (n, obs_dim) = (config.envs, model.task.obs_dim);
        let copies = (0..n)
            .map(|i| {
                let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
                rng.set_stream(i as u64);
                EnvCopy {
                    env: Env::new(model.clone()),
                    rng,
                    executed_action: vec![0.0; model.task.act_dim],
                    obs: vec![0.0; obs_dim],
                    episode_return: 0.0,
                }
            })
            .collect();
        let mut batch = BatchedEnv {
            model,
            copies,
            pool,
            actuator_noise,
            observations: vec![0.0; n * obs_dim],
            final_observations: vec![0.0; n * obs_dim],
            rewards: vec![0.0; n],
            terminated: vec![0; n],
            truncated: vec![0; n],
            diverged: vec![0; n],
            episode_returns: vec![0.0; n],
            episode_lengths: vec![0; n],
            controls: vec![CopyStep::Step; n],
        };
        batch.reset_all();
        Ok(batch)
    }

    /// Resets every copy (each from its own random stream) and clears the step outputs.
    pub fn reset_all(&mut self) {
        let obs_dim = self.obs_dim();
        self.pool.install(|| {
            (
                self.copies.par_iter_mut(),
                self.observations.par_chunks_mut(obs_dim),
            )
                .into_par_iter()
                .for_each(|(copy, obs)| copy.begin_episode(obs));
        });
        self.rewards.fill(0.0);
        self.terminated.fill(0);
        self.truncated.fill(0);
        self.diverged.fill(0);
    }

    /// Applies `actions` (`[N, act_dim]`, row `i` to copy `i`) and steps every copy once.
    pub fn step(&mut self, actions: &[f32]) -> Result<(), SimError> {
        self.controls.fill(CopyStep::Step);
        self.run_step(actions)
    }

    /// Like [`BatchedEnv::step`], copy `i` doing what `controls[i]` says (its action row is
    /// ignored unless it steps).
    pub fn step_each(&mut self, actions: &[f32], controls: &[CopyStep]) -> Result<(), SimError> {
        if controls.len() != self.copies.len() {
            return Err(SimError::WrongLength {
                what: "the per-copy step controls",
                found: controls.len(),
                expected: self.copies.len(),
            });
        }
        self.controls.copy_from_slice(controls);
        self.run_step(actions)
    }

    /// `[N]`: what each copy did in the last step (all [`CopyStep::Step`] after a plain step).
    pub fn controls(&self) -> &[CopyStep] {
        &self.controls
    }

    fn run_step(&mut self, actions: &[f32]) -> Result<(), SimError> {
        let (obs_dim, act_dim) = (self.obs_dim(), self.act_dim());
        let expected = self.copies.len() * act_dim;
        if actions.len() != expected {
            return Err(SimError::WrongLength {
                what: "the batch of actions",
                found: actions.len(),
                expected,
            });
        }
        let noise = self.actuator_noise;
        let model = &self.model;
        let step_one =
            |copy: &mut EnvCopy, control: CopyStep, action: &[f32], out: CopyOutputs<'_>| {
                match control {
                    CopyStep::Step => copy.step(model, action, noise, out),
                    CopyStep::Hold => out.clear_step(),
                    CopyStep::Restart => copy.restart(out),
                }
            };
        let threads = self.pool.current_num_threads();
        if threads == 1 || self.copies.len() == 1 {
            // One worker's work: stepped on the calling thread, without the hand-off to the pool.
            for (i, copy) in self.copies.iter_mut().enumerate() {
                let rows = i * obs_dim..(i + 1) * obs_dim;
                let out = CopyOutputs {
                    obs: &mut self.observations[rows.clone()],
                    final_obs: &mut self.final_observations[rows],
                    reward: &mut self.rewards[i],
                    terminated: &mut self.terminated[i],
                    truncated: &mut self.truncated[i],
                    diverged: &mut self.diverged[i],
                    episode_return: &mut self.episode_returns[i],
                    episode_length: &mut self.episode_lengths[i],
                };
                step_one(
                    copy,
                    self.controls[i],
                    &actions[i * act_dim..(i + 1) * act_dim],
                    out,
                );
            }
            return Ok(());
        }
        // Small enough chunks that the threads finish together, big enough that the pool's
        // overhead stays small for cheap tasks.
        let min_len = (self.copies.len() / (64 * threads)).max(1);
        self.pool.install(|| {
            (
                self.copies.par_iter_mut(),
                self.controls.par_iter(),
                actions.par_chunks(act_dim),
                self.observations.par_chunks_mut(obs_dim),
                self.final_observations.par_chunks_mut(obs_dim),
                self.rewards.par_iter_mut(),
                self.terminated.par_iter_mut(),
                self.truncated.par_iter_mut(),
                self.diverged.par_iter_mut(),
                self.episode_returns.par_iter_mut(),
                self.episode_lengths.par_iter_mut(),
            )
                .into_par_iter()
                .with_min_len(min_len)
                .for_each(
                    |(
                        copy,
                        &control,
                        action,
                        obs,
                        final_obs,
                        reward,
                        terminated,
                        truncated,
                        diverged,
                        episode_return,
                        episode_length,
                    )| {
                        let out = CopyOutputs {
                            obs,
                            final_obs,
                            reward,
                            terminated,
                            truncated,
                            diverged,
                            episode_return,
                            episode_length,
                        };
                        step_one(copy, control, action, out);
                    },
                );
        });
        Ok(())
    }

    /// Puts copy `copy` into the state `(qpos, qvel)` (Gymnasium's `set_state`) at the start
    /// of an episode: its time limit and running return restart and its row of
    /// `observations` becomes the observation of that state.
    pub fn set_state(&mut self, copy: usize, qpos: &[f64], qvel: &[f64]) -> Result<(), SimError> {
        let n = self.copies.len();
        let obs_dim = self.obs_dim();
        let Some(target) = self.copies.get_mut(copy) else {
            return Err(SimError::WrongLength {
                what: "the batch of copies (for the copy to set)",
                found: n,
                expected: copy + 1,
            });
        };
        target.env.set_state(qpos, qvel)?;
        target.episode_return = 0.0;
        target.env.observe(&mut target.obs);
        write_f32(
            &mut self.observations[copy * obs_dim..(copy + 1) * obs_dim],
            &target.obs,
        );
        Ok(())
    }

    /// The action copy `copy`'s actuators received in the last step (the chosen one, or with
    /// actuator noise added and clipped).
    pub fn executed_action(&self, copy: usize) -> &[f64] {
        &self.copies[copy].executed_action
    }

    pub fn task(&self) -> TaskName {
        self.model.task.name
    }
    /// The task's compiled model and constants.
    pub fn model(&self) -> &TaskModel {
        &self.model
    }
    pub fn len(&self) -> usize {
        self.copies.len()
    }
    pub fn is_empty(&self) -> bool {
        self.copies.is_empty()
    }
    pub fn obs_dim(&self) -> usize {
        self.model.task.obs_dim
    }
    pub fn act_dim(&self) -> usize {
        self.model.task.act_dim
    }
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }
    /// The pool that steps the copies: parallel work that goes with a step (the delay layer)
    /// runs on it, in the same hand-off, rather than on another pool.
    pub fn pool(&self) -> Arc<rayon::ThreadPool> {
        self.pool.clone()
    }
    /// Per worker thread, whether it flushes subnormal floats ([`crate::float_mode`]): a
    /// subnormal product computed there comes out as zero.
    pub fn workers_flush_subnormals(&self) -> Vec<bool> {
        self.pool
            .broadcast(|_| crate::float_mode::subnormal_product_is_zero())
    }
    /// Lower and upper bounds of each action dimension.
    pub fn action_bounds(&self) -> (&[f64], &[f64]) {
        (&self.model.action_low, &self.model.action_high)
    }
    /// `[N, obs_dim]`: the current observation of every copy.
    pub fn observations(&self) -> &[f32] {
        &self.observations
    }
    /// `[N, obs_dim]`: the last observation of an episode that ended this step (rows of copies
    /// whose `terminated` or `truncated` flag is set; other rows are stale).
    pub fn final_observations(&self) -> &[f32] {
        &self.final_observations
    }
    /// `[N]`: the reward of the last step.
    pub fn rewards(&self) -> &[f32] {
        &self.rewards
    }
    /// `[N]`: 1 where the last step ended the MDP.
    pub fn terminated(&self) -> &[u32] {
        &self.terminated
    }
    /// `[N]`: 1 where the last step hit the time limit.
    pub fn truncated(&self) -> &[u32] {
        &self.truncated
    }

    /// Copies whose episode the last step ended because the simulation diverged.
    pub fn diverged(&self) -> &[u32] {
        &self.diverged
    }
    /// `[N]`: the undiscounted return of the episode that ended this step (where done).
    pub fn episode_returns(&self) -> &[f32] {
        &self.episode_returns
    }
    /// `[N]`: the length of the episode that ended this step (where done).
    pub fn episode_lengths(&self) -> &[u32] {
        &self.episode_lengths
    }
}

impl CopyOutputs<'_> {
    /// No reward and no flags: the step outputs of a copy that did not step.
    fn clear_step(self) {
        *self.reward = 0.0;
        *self.terminated = 0;
        *self.truncated = 0;
        *self.diverged = 0;
    }
}

impl EnvCopy {
    /// A new episode from the copy's own stream, its first observation written to `obs`.
    fn begin_episode(&mut self, obs: &mut [f32]) {
        self.env.reset(&mut self.rng);
        self.episode_return = 0.0;
        self.env.observe(&mut self.obs);
        write_f32(obs, &self.obs);
    }

    /// [`EnvCopy::begin_episode`] in place of a step.
    fn restart(&mut self, out: CopyOutputs<'_>) {
        self.begin_episode(out.obs);
        out.clear_step();
    }

    fn step(
        &mut self,
        model: &TaskModel,
        action: &[f32],
        noise: Option<Normal<f64>>,
        out: CopyOutputs<'_>,
    ) {
        executed_action(
            action,
            noise,
            &mut self.rng,
            model,
            &mut self.executed_action,
        );
        let outcome = self.env.step(&self.executed_action, &mut self.obs);
        self.episode_return += outcome.reward;
        *out.reward = outcome.reward as f32;
        *out.terminated = outcome.terminated as u32;
        *out.truncated = outcome.truncated as u32;
        *out.diverged = outcome.diverged as u32;
        if outcome.done() {
            write_f32(out.final_obs, &self.obs);
            *out.episode_return = self.episode_return as f32;
            *out.episode_length = self.env.elapsed();
            self.episode_return = 0.0;
            self.env.reset(&mut self.rng);
            self.env.observe(&mut self.obs);
        }
        write_f32(out.obs, &self.obs);
    }
}

/// The action the actuators receive: the chosen one, or `clip(a + N(0, σ²))` under actuator
/// noise (docs/DESIGN.md §1.8). Without noise it is passed on unclipped, as Gymnasium does.
fn executed_action(
    action: &[impl Copy + Into<f64>],
    noise: Option<Normal<f64>>,
    rng: &mut impl rand::Rng,
    model: &TaskModel,
    out: &mut [f64],
) {
    for (i, (executed, &a)) in out.iter_mut().zip(action).enumerate() {
        *executed = match noise {
            Some(n) => (a.into() + n.sample(rng)).clamp(model.action_low[i], model.action_high[i]),
            None => a.into(),
        };
    }
}

/// The actuator noise distribution for σ (`None` for σ = 0), or an error for a negative or
/// non-finite σ.
fn actuator_noise(sigma: f64) -> Result<Option<Normal<f64>>, SimError> {
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(SimError::TooSmall {
            what: "the actuator noise σ (finite)",
            found: sigma,
            min: 0.0,
        });
    }
    Ok((sigma > 0.0).then(|| Normal::new(0.0, sigma).expect("σ is finite and positive")))
}

fn write_f32(out: &mut [f32], values: &[f64]) {
    for (o, v) in out.iter_mut().zip(values) {
        *o = *v as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn actuator_noise_is_added_then_clipped_to_the_control_range() {
        let model = TaskModel::load(TaskName::HalfCheetah).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut out = vec![0.0; 6];
        let chosen = [0.5f32, -0.5, 0.0, 0.9, -0.9, 2.0];
        executed_action(&chosen, None, &mut rng, &model, &mut out);
        assert_eq!(
            out,
            chosen.map(f64::from).to_vec(),
            "no noise: passed on as chosen"
        );
        let huge = Normal::new(0.0, 1e6).unwrap();
        executed_action(&chosen, Some(huge), &mut rng, &model, &mut out);
        assert!(
            out.iter().all(|a| a.abs() == 1.0),
            "clipped to [-1, 1]: {out:?}"
        );
        let small = Normal::new(0.0, 0.01).unwrap();
        let mut twin = ChaCha8Rng::seed_from_u64(4);
        executed_action(&chosen[..5], Some(small), &mut twin, &model, &mut out[..5]);
        let mut replay = ChaCha8Rng::seed_from_u64(4);
        for (i, &a) in chosen[..5].iter().enumerate() {
            let expected = (a as f64 + small.sample(&mut replay)).clamp(-1.0, 1.0);
            assert_eq!(out[i], expected);
        }
    }
}
