//! The trace behind `dhrl rollout`: one episode of one copy from a given state and a given
//! action sequence, one JSON object per step, for outside checkers. With delay options the
//! trace shows what the delayed agent receives, produced by the delay layer itself.
use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::delay::{BatchError, DelayConfig, DelayDevice, DelayLayer, DelayedBatch, arrival_delay};
use crate::delay::{RECORD_FINAL_STATE, RECORD_TERMINATED, RECORD_TRUNCATED};
use crate::sim::{BatchConfig, Env, SimError, TaskModel, check_vector};
use crate::tasks::TaskName;

#[derive(Debug, thiserror::Error)]
pub enum RolloutError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path} is not a state file: {source}; expected {{\"qpos\": [...], \"qvel\": [...]}}")]
    StateFormat {
        path: String,
        source: serde_json::Error,
    },
    #[error("{path} line {line}: '{field}' is not a number")]
    ActionNotNumber {
        path: String,
        line: usize,
        field: String,
    },
    #[error(
        "{path} line {line}: {count} values, but {task} takes actions of {expected} (comma-separated, one action per line)"
    )]
    ActionWidth {
        path: String,
        line: usize,
        count: usize,
        task: TaskName,
        expected: usize,
    },
    #[error("{path} line {line}: value {value} is not finite; only finite numbers are accepted")]
    ActionNotFinite {
        path: String,
        line: usize,
        value: f64,
    },
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Delay(#[from] crate::delay::DelayError),
    #[error(transparent)]
    Batch(#[from] BatchError),
}

/// `{"qpos": [...], "qvel": [...]}`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialState {
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
}

/// An observation delivered together with the reward and flags of the step that produced it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Delivered {
    pub obs: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reward: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminated: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truncated: Option<bool>,
}

/// An observation that arrived under random delays: the state `s_τ`, `t − τ` steps old.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Arrival {
    pub tau: usize,
    pub obs: Vec<f64>,
}

/// One printed line of the trace.
///
/// Undelayed: `obs` is the state after step `t`, with that step's reward and flags (`t = 0`
/// carries only the state as set). Delayed by Δ: `obs` is what reached the agent at `t`, the
/// state `s_{t-Δ}` with the reward and flags of the step that produced it; `augmented` is
/// `x_t = (s_{t-Δ}, a_{t-Δ}, …, a_{t-1})`, absent while `t < Δ`; on the line that ends the
/// episode, `delivered` holds the states `s_{t-Δ+1} … s_t` handed over at once, and no
/// `augmented` (no decision follows). Delayed values are f32, the delay layer's precision.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TraceStep {
    pub t: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub obs: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reward: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminated: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truncated: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub augmented: Option<Vec<f64>>,
    /// The action the actuators received at step `t − 1`, under actuator noise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub executed: Option<Vec<f64>>,
    /// Under random delays: the observations that arrived at `t` (possibly out of order).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arrived: Option<Vec<Arrival>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delivered: Option<Vec<Delivered>>,
}

impl TraceStep {
    fn at(t: usize) -> TraceStep {
        TraceStep {
            t,
            obs: None,
            reward: None,
            terminated: None,
            truncated: None,
            augmented: None,
            executed: None,
            arrived: None,
            delivered: None,
        }
    }
}

fn read(path: &Path) -> Result<String, RolloutError> {
    std::fs::read_to_string(path).map_err(|source| RolloutError::Read {
        path: path.display().to_string(),
        source,
    })
}

pub fn read_state(path: &Path) -> Result<InitialState, RolloutError> {
    serde_json::from_str(&read(path)?).map_err(|source| RolloutError::StateFormat {
        path: path.display().to_string(),
        source,
    })
}

/// Parses one action per non-empty line, comma-separated, checking width and finiteness.
pub fn read_actions(path: &Path, task: TaskName) -> Result<Vec<Vec<f64>>, RolloutError> {
    let text = read(path)?;
    let name = || path.display().to_string();
    let expected = task.def().act_dim;
    let mut actions = Vec::new();
    for (index, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let line_no = index + 1;
        let action = line
            .split(',')
            .map(|field| {
                let field = field.trim();
                let value: f64 = field.parse().map_err(|_| RolloutError::ActionNotNumber {
                    path: name(),
                    line: line_no,
                    field: field.to_string(),
                })?;
                if value.is_finite() {
                    Ok(value)
                } else {
                    Err(RolloutError::ActionNotFinite {
                        path: name(),
                        line: line_no,
                        value,
                    })
                }
            })
            .collect::<Result<Vec<f64>, _>>()?;
        if action.len() != expected {
            return Err(RolloutError::ActionWidth {
                path: name(),
                line: line_no,
                count: action.len(),
                task,
                expected,
            });
        }
        actions.push(action);
    }
    Ok(actions)
}

fn widen(values: &[f32]) -> Vec<f64> {
    values.iter().map(|&v| f64::from(v)).collect()
}

fn narrow(values: &[f64]) -> Vec<f32> {
    values.iter().map(|&v| v as f32).collect()
}

/// Sets the state, then applies the actions until they run out or the episode ends, calling
/// `emit` for the initial line and after every step.
///
/// Without `delay` the trace is one [`Env`]'s, in f64 (Gymnasium's own precision, for parity
/// checks). With `delay` it is the [`DelayedBatch`] that training and evaluation run (one
/// copy, its delay layer on `device`): the actions reach it as f32, as a policy's do, so an
/// action file meant to match the undelayed trace step for step should hold f32 values.
/// `seed` drives actuator noise and random delays. The file's actions are applied from the
/// first step on: no warm-up actions replace them.
pub fn rollout(
    task: TaskName,
    state: &InitialState,
    actions: &[Vec<f64>],
    delay: Option<(&DelayConfig, DelayDevice)>,
    seed: u64,
    emit: impl FnMut(&TraceStep),
) -> Result<(), RolloutError> {
    match delay {
        None => undelayed(task, state, actions, emit),
        Some((config, device)) => delayed(task, state, actions, config, device, seed, emit),
    }
}

fn undelayed(
    task: TaskName,
    state: &InitialState,
    actions: &[Vec<f64>],
    mut emit: impl FnMut(&TraceStep),
) -> Result<(), RolloutError> {
    let mut env = Env::new(TaskModel::load(task)?);
    env.set_state(&state.qpos, &state.qvel)?;
    let mut obs = vec![0.0; task.def().obs_dim];
    env.observe(&mut obs);
    emit(&TraceStep {
        obs: Some(obs.clone()),
        ..TraceStep::at(0)
    });
    for (k, action) in actions.iter().enumerate() {
        check_vector("action", action, task.def().act_dim)?;
        let outcome = env.step(action, &mut obs);
        emit(&TraceStep {
            obs: Some(obs.clone()),
            reward: Some(outcome.reward),
            terminated: Some(outcome.terminated),
            truncated: Some(outcome.truncated),
            ..TraceStep::at(k + 1)
        });
        if outcome.done() {
            break;
        }
    }
    Ok(())
}

fn delayed(
    task: TaskName,
    state: &InitialState,
    actions: &[Vec<f64>],
    config: &DelayConfig,
    device: DelayDevice,
    seed: u64,
    mut emit: impl FnMut(&TraceStep),
) -> Result<(), RolloutError> {
    let (obs_dim, act_dim) = (task.def().obs_dim, task.def().act_dim);
    let delay_steps = config.total_delay()?;
    let mut batch = DelayedBatch::new(
        &BatchConfig {
            task,
            envs: 1,
            threads: 1,
            seed,
            actuator_noise: config.actuator_noise,
        },
        config,
        device,
        seed,
    )?;
    batch.restart_from(&state.qpos, &state.qvel)?;
    // The states sent so far, s_0 … s_t, for the arrivals of random delays.
    let mut sent = vec![batch.env().observations().to_vec()];
    let ready_line = |layer: &dyn DelayLayer, t: usize| {
        let ready = layer.ready()[0] == 1;
        TraceStep {
            obs: ready.then(|| widen(&layer.augmented()[..obs_dim])),
            augmented: ready.then(|| widen(layer.augmented())),
            ..TraceStep::at(t)
        }
    };
    emit(&ready_line(batch.layer(), 0));
    for (k, action) in actions.iter().enumerate() {
        check_vector("action", action, act_dim)?;
        batch.step(&narrow(action))?;
        let env = batch.env();
        let done = env.terminated()[0] == 1 || env.truncated()[0] == 1;
        sent.push(if done {
            env.final_observations().to_vec()
        } else {
            env.observations().to_vec()
        });
        let t = k + 1;
        let layer = batch.layer();
        let mut line = if done {
            end_line(layer, t, delay_steps)
        } else {
            ready_line(layer, t)
        };
        if !done && let Some(record) = layer.records().iter().next() {
            // The record of step t − Δ − 1 completed: its reward travels with s_{t-Δ}.
            line.reward = Some(f64::from(record.reward));
            (line.terminated, line.truncated) = (Some(false), Some(false));
        }
        if config.actuator_noise > 0.0 {
            line.executed = Some(env.executed_action(0).to_vec());
        }
        if let Some(bound) = config.random_bound() {
            let arrived = (t.saturating_sub(bound)..t)
                .filter(|&tau| tau + arrival_delay(seed, 0, 0, tau as u32, bound) == t)
                .map(|tau| Arrival {
                    tau,
                    obs: widen(&sent[tau]),
                });
            line.arrived = Some(arrived.collect());
        }
        emit(&line);
        if done {
            break;
        }
    }
    Ok(())
}

/// The line of the step that ended the episode at `t = T`: the regular arrival `s_{T-Δ}` and,
/// delivered at once, `s_{T-Δ+1} … s_T`, each with the reward and flags of its step.
fn end_line(layer: &dyn DelayLayer, t: usize, delay: usize) -> TraceStep {
    let mut states = BTreeMap::new();
    let mut steps = BTreeMap::new();
    for record in layer.records().iter() {
        let tau = record.meta.tau as usize;
        states.insert(tau, widen(record.state));
        if record.meta.flags & RECORD_FINAL_STATE == 0 {
            let flags = record.meta.flags;
            steps.insert(
                tau + 1,
                (
                    f64::from(record.reward),
                    flags & RECORD_TERMINATED != 0,
                    flags & RECORD_TRUNCATED != 0,
                ),
            );
        }
    }
    let delivered = |j: usize| {
        let step = steps.get(&j);
        Delivered {
            obs: states[&j].clone(),
            reward: step.map(|s| s.0),
            terminated: step.map(|s| s.1),
            truncated: step.map(|s| s.2),
        }
    };
    let mut line = TraceStep::at(t);
    if let Some(j) = t.checked_sub(delay) {
        let regular = delivered(j);
        (line.obs, line.reward, line.terminated, line.truncated) = (
            Some(regular.obs),
            regular.reward,
            regular.terminated,
            regular.truncated,
        );
    }
    if delay > 0 {
        line.delivered = Some(
            (t.saturating_sub(delay) + usize::from(t >= delay)..=t)
                .map(delivered)
                .collect(),
        );
    }
    line
}
