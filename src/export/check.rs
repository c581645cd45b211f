//! `check.safetensors`: a recorded stretch of the delayed task driven by the Rust
//! [`DelayedPolicy`] around the exported agent, checked against training's own delay layer as
//! it is recorded, for another runtime (onnxruntime, the Python `DelayedPolicy`) to replay.
use std::collections::HashMap;

use super::ExportError;
use super::state_dict::{Parameter, safetensors_bytes};
use crate::algos::{ActMode, Agent};
use crate::delay::{
    DelayConfig, DelayDevice, DelayError, DelayedBatch, WarmupActions, arrival_delay,
};
use crate::deploy::{ActionSource, DelayedPolicy, PolicyManifest};
use crate::sim::BatchConfig;
use crate::train::{TrainConfig, TrainError};

/// Decisions the policy takes in a record (the warm-up's come on top).
pub const CHECK_POLICY_STEPS: usize = 1000;

/// One decision after another, in one copy of the task, episodes following each other.
#[derive(Debug, Clone, Default)]
pub struct CheckRecord {
    obs_dim: usize,
    act_dim: usize,
    width: usize,
    /// 1 where the decision is the first of an episode (reset the runtime before it).
    pub episode_start: Vec<f32>,
    /// 1 where the policy chose (not the warm-up).
    pub policy_step: Vec<f32>,
    /// `x_t` of the policy's decisions, `[P, obs + Δ·act]`.
    pub augmented_state: Vec<f32>,
    /// The action executed, `[T, act]`.
    pub action: Vec<f32>,
    /// Each observation's arrival: the decision it arrives before, the step it shows and the
    /// observation itself `[K, obs]`, in the order they arrived.
    pub arrival_decision: Vec<f32>,
    pub arrival_step: Vec<f32>,
    pub arrival_observation: Vec<f32>,
}

impl CheckRecord {
    pub fn steps(&self) -> usize {
        self.episode_start.len()
    }

    pub fn policy_steps(&self) -> usize {
        self.augmented_state.len() / self.width.max(1)
    }

    /// The record as safetensors (every tensor f32; flags are 0 or 1).
    pub fn to_safetensors(&self) -> Result<Vec<u8>, ExportError> {
        let (steps, policy, arrivals) =
            (self.steps(), self.policy_steps(), self.arrival_step.len());
        let tensors = [
            Parameter::new("episode_start", vec![steps], &self.episode_start),
            Parameter::new("policy_step", vec![steps], &self.policy_step),
            Parameter::new(
                "augmented_state",
                vec![policy, self.width],
                &self.augmented_state,
            ),
            Parameter::new("action", vec![steps, self.act_dim], &self.action),
            Parameter::new("arrival_decision", vec![arrivals], &self.arrival_decision),
            Parameter::new("arrival_step", vec![arrivals], &self.arrival_step),
            Parameter::new(
                "arrival_observation",
                vec![arrivals, self.obs_dim],
                &self.arrival_observation,
            ),
        ];
        let metadata = HashMap::from([(
            "about".to_string(),
            "dhrl export's recorded decisions (docs/deploy.md): before decision t, observe each \
             arrival with arrival_decision t; reset at episode_start; warm-up zeros"
                .to_string(),
        )]);
        Ok(safetensors_bytes(&tensors, metadata)?)
    }
}

/// The agent as the runtime's policy, one row at a time.
struct AgentSource<'a>(&'a mut dyn Agent);

impl ActionSource for AgentSource<'_> {
    fn action(&mut self, augmented_state: &[f32]) -> Vec<f32> {
        self.0.act(augmented_state, 1, ActMode::Deterministic)
    }
}

/// An observation on its way to the agent.
struct InFlight {
    arrives_before: usize,
    step: usize,
    observation: Vec<f32>,
}

/// Drives one copy of `config`'s task (no actuator noise, warm-up zeros) with the runtime
/// until the policy has taken [`CHECK_POLICY_STEPS`] decisions. The runtime gets the
/// simulator's observations as they are emitted, each after the run's delay (under random
/// delays, after a random one within the bound, as training draws them: out of order), and
/// at every decision its `x_t` must be the one training's delay layer built from the same
/// episode, and its action the agent's on that `x_t`.
pub fn record_check(
    agent: &mut dyn Agent,
    config: &TrainConfig,
    manifest: &PolicyManifest,
) -> Result<CheckRecord, ExportError> {
    let (obs, act, delay) = (
        manifest.observation_dim,
        manifest.action_dim,
        manifest.delay.total,
    );
    let width = manifest.augmented_state.width;
    let delay_config = DelayConfig {
        warmup: WarmupActions::Zeros,
        ..DelayConfig::fixed(delay)
    };
    let mut batch = DelayedBatch::new(
        &BatchConfig {
            task: config.task,
            envs: 1,
            threads: 1,
            seed: config.seed,
            actuator_noise: 0.0,
        },
        &delay_config,
        DelayDevice::Cpu,
        config.seed,
    )
    .map_err(TrainError::from)?;
    // How long the observation of `step` in `episode` takes to arrive.
    let random_bound = config.delay.random_bound();
    let travel = |episode: u32, step: usize| match random_bound {
        Some(bound) => {
            arrival_delay(config.seed, 0, episode, step as u32, bound) + config.delay.action_delay
        }
        None => delay,
    };
    let mut runtime = DelayedPolicy::new(manifest, AgentSource(agent), config.seed)
        .with_warmup(WarmupActions::Zeros);
    let mut record = CheckRecord {
        obs_dim: obs,
        act_dim: act,
        width,
        ..CheckRecord::default()
    };
    let mut episode = 0u32;
    let mut in_flight = vec![InFlight {
        arrives_before: travel(episode, 0),
        step: 0,
        observation: batch.env().observations()[..obs].to_vec(),
    }];
    let mut episode_start = true;
    while record.policy_steps() < CHECK_POLICY_STEPS {
        if episode_start {
            runtime.reset();
        }
        let t = runtime.decision();
        let fail = |what: String| ExportError::Check(format!("decision {t}: {what}"));
        let (arrived, travelling) = in_flight.into_iter().partition(|o| o.arrives_before <= t);
        in_flight = travelling;
        for observation in arrived {
            runtime
                .observe(observation.step, &observation.observation)
                .map_err(|e| fail(e.to_string()))?;
            record.arrival_decision.push(record.steps() as f32);
            record.arrival_step.push(observation.step as f32);
            record
                .arrival_observation
                .extend_from_slice(&observation.observation);
        }
        let ready = batch.layer().ready()[0] == 1;
        let layer_x = batch.layer().augmented()[..width].to_vec();
        if runtime.augmented_state().as_deref() != ready.then_some(&layer_x[..]) {
            return Err(fail(format!(
                "the runtime's x_t differs from training's delay layer's (policy step: {ready})"
            )));
        }
        let mut trained = vec![0.0f32; act];
        batch
            .choose_actions(
                &mut trained,
                |_| true,
                |x, rows| Ok::<_, DelayError>(training_action(&mut runtime, x, rows)),
            )
            .map_err(TrainError::from)?;
        let action = runtime.act().map_err(|e| fail(e.to_string()))?;
        if action != trained {
            return Err(fail(format!(
                "the runtime chose {action:?}, training's loop {trained:?}"
            )));
        }
        record
            .episode_start
            .push(f32::from(u8::from(episode_start)));
        record.policy_step.push(f32::from(u8::from(ready)));
        if ready {
            record.augmented_state.extend_from_slice(&layer_x);
        }
        record.action.extend_from_slice(&action);
        batch.step(&action).map_err(TrainError::from)?;
        let env = batch.env();
        episode_start = env.terminated()[0] == 1 || env.truncated()[0] == 1;
        // The next state's observation sets off (a new episode's s_0 after an end; what was
        // still on its way from the old episode is of no use any more).
        let step = if episode_start {
            in_flight.clear();
            episode += 1;
            0
        } else {
            t + 1
        };
        in_flight.push(InFlight {
            arrives_before: step + travel(episode, step),
            step,
            observation: env.observations()[..obs].to_vec(),
        });
    }
    Ok(record)
}

/// Training's path to an action: the agent's `act` on the delay layer's rows.
fn training_action(
    runtime: &mut DelayedPolicy<AgentSource<'_>>,
    x: &[f32],
    rows: usize,
) -> Vec<f32> {
    runtime.policy_mut().0.act(x, rows, ActMode::Deterministic)
}
