//! The one delayed-batch path: a batched simulator and a delay layer (CPU or GPU) stepped
//! together, with warm-up actions for copies that have observed nothing yet and a policy
//! acting on the augmented states of the ready ones. Training, evaluation and the delayed
//! trace of `dhrl rollout` all run it.
use super::{
    DelayConfig, DelayDevice, DelayError, DelayLayer, DelayLayout, StepInput, delay_layer,
};
use crate::sim::{BatchConfig, BatchedEnv, CopyStep, SimError};

#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Delay(#[from] DelayError),
}

/// `N` copies of a task as the delayed agent lives in them.
pub struct DelayedBatch {
    env: BatchedEnv,
    layer: Box<dyn DelayLayer>,
}

impl DelayedBatch {
    /// The copies of `batch` (its `actuator_noise` is `delay`'s σ) under `delay`, the layer on
    /// `device` (its warm-up actions and random delays drawn from `layer_seed`), every copy at
    /// the start of its first episode.
    pub fn new(
        batch: &BatchConfig,
        delay: &DelayConfig,
        device: DelayDevice,
        layer_seed: u64,
    ) -> Result<DelayedBatch, BatchError> {
        let env = BatchedEnv::new(batch)?;
        let (low, high) = env.action_bounds();
        let mut layer = delay_layer(
            device,
            delay,
            env.len(),
            env.obs_dim(),
            low,
            high,
            layer_seed,
        )?;
        layer.reset(env.observations())?;
        Ok(DelayedBatch { env, layer })
    }

    pub fn env(&self) -> &BatchedEnv {
        &self.env
    }

    pub fn env_mut(&mut self) -> &mut BatchedEnv {
        &mut self.env
    }

    pub fn layer(&self) -> &dyn DelayLayer {
        self.layer.as_ref()
    }

    pub fn layer_mut(&mut self) -> &mut dyn DelayLayer {
        self.layer.as_mut()
    }

    pub fn layout(&self) -> DelayLayout {
        self.layer.layout()
    }

    /// Restarts every copy's episode from the state `(qpos, qvel)` (Gymnasium's `set_state`),
    /// and the delay layer with them: the first step after it is step 1 of the new episodes.
    pub fn restart_from(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), BatchError> {
        for copy in 0..self.env.len() {
            self.env.set_state(copy, qpos, qvel)?;
        }
        self.layer.reset(self.env.observations())?;
        Ok(())
    }

    /// Fills `actions` (`[N, act_dim]`): `policy` chooses for the ready copies that `acting`
    /// selects — it gets their augmented states `[rows, obs + Δ·act]` and the row count — the
    /// copies still in warm-up get warm-up actions, and the other rows keep what they hold.
    pub fn choose_actions<E>(
        &mut self,
        actions: &mut [f32],
        acting: impl Fn(usize) -> bool,
        policy: impl FnOnce(&[f32], usize) -> Result<Vec<f32>, E>,
    ) -> Result<(), E>
    where
        E: From<DelayError>,
    {
        let (copies, inputs) = self.acting_states(acting);
        let chosen = match copies.is_empty() {
            true => Vec::new(),
            false => policy(&inputs, copies.len())?,
        };
        self.set_actions(actions, &copies, &chosen)?;
        Ok(())
    }

    /// The ready copies that `acting` selects (those whose augmented state exists), and their
    /// augmented states `[copies, obs + Δ·act]`: what a policy chooses for.
    pub fn acting_states(&self, acting: impl Fn(usize) -> bool) -> (Vec<usize>, Vec<f32>) {
        let aug = self.layout().augmented_dim();
        let (ready, augmented) = (self.layer.ready(), self.layer.augmented());
        let copies: Vec<usize> = (0..ready.len())
            .filter(|&i| ready[i] == 1 && acting(i))
            .collect();
        let inputs = copies
            .iter()
            .flat_map(|&i| &augmented[i * aug..(i + 1) * aug])
            .copied()
            .collect();
        (copies, inputs)
    }

    /// Writes `chosen` (`[copies, act_dim]`, a policy's actions for the copies that
    /// [`DelayedBatch::acting_states`] named) into `actions` (`[N, act_dim]`), and warm-up
    /// actions into the rows of copies still in warm-up.
    pub fn set_actions(
        &mut self,
        actions: &mut [f32],
        copies: &[usize],
        chosen: &[f32],
    ) -> Result<(), DelayError> {
        let act = self.layout().act_dim;
        for (k, &i) in copies.iter().enumerate() {
            actions[i * act..(i + 1) * act].copy_from_slice(&chosen[k * act..(k + 1) * act]);
        }
        self.layer.fill_warmup(actions)
    }

    /// Steps the simulator with `actions`, then the delay layer with what it returned.
    pub fn step(&mut self, actions: &[f32]) -> Result<(), BatchError> {
        self.on_simulation_threads(|batch| {
            batch.env.step(actions)?;
            batch.step_layer(actions)
        })
    }

    /// [`DelayedBatch::step`] with copy `i` doing what `controls[i]` says: held copies stay
    /// as they are (simulation and delay layer alike), restarted ones begin a new episode.
    pub fn step_each(&mut self, actions: &[f32], controls: &[CopyStep]) -> Result<(), BatchError> {
        self.on_simulation_threads(|batch| {
            batch.env.step_each(actions, controls)?;
            batch.step_layer(actions)
        })
    }

    /// Runs `f` on the simulation's pool in one hand-off, so that the simulation's parallel
    /// pass and the delay layer's (the CPU layer splits large batches across the current
    /// pool) follow each other on threads still awake, without returning to the calling thread
    /// in between: each return and hand-off wakes a sleeping thread.
    fn on_simulation_threads<R: Send>(
        &mut self,
        f: impl FnOnce(&mut DelayedBatch) -> R + Send,
    ) -> R {
        if self.env.threads() > 1 {
            let pool = self.env.pool();
            pool.install(|| f(self))
        } else {
            f(self)
        }
    }

    fn step_layer(&mut self, actions: &[f32]) -> Result<(), BatchError> {
        let input = StepInput::from_env(&self.env, actions);
        self.layer.step(&input)?;
        Ok(())
    }
}
