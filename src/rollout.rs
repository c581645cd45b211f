//! The trace behind `dhrl rollout`: one episode of one copy from a given state and a given
//! action sequence, one JSON object per step, for outside checkers. With delay options the
//! trace shows what the delayed agent receives, produced by the delay layer itself.
use std::collections::BTreeMap;
use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::delay::{CpuDelayLayer, DelayConfig, DelayError, DelayLayer, StepInput, arrival_delay};
use crate::delay::{RECORD_FINAL_STATE, RECORD_TERMINATED, RECORD_TRUNCATED};
use crate::sim::{Env, SimError, TaskModel, actuator_noise, check_vector, executed_action};
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
    Delay(#[from] DelayError),
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
/// `emit` for the initial line and after every step. `delay` switches to the delayed trace;
/// `seed` drives actuator noise and random delays.
pub fn rollout(
    task: TaskName,
    state: &InitialState,
    actions: &[Vec<f64>],
    delay: Option<&DelayConfig>,
    seed: u64,
    mut emit: impl FnMut(&TraceStep),
) -> Result<(), RolloutError> {
    let model = TaskModel::load(task)?;
    let mut env = Env::new(model.clone());
    env.set_state(&state.qpos, &state.qvel)?;
    let (obs_dim, act_dim) = (task.def().obs_dim, task.def().act_dim);
    let mut obs = vec![0.0; obs_dim];
    env.observe(&mut obs);
    let Some(config) = delay else {
        emit(&TraceStep {
            obs: Some(obs.clone()),
            ..TraceStep::at(0)
        });
        for (k, action) in actions.iter().enumerate() {
            check_vector("action", action, act_dim)?;
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
        return Ok(());
    };

    let delay_steps = config.total_delay()?;
    let noise = actuator_noise(config.actuator_noise)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut layer = CpuDelayLayer::new(
        config,
        1,
        obs_dim,
        &model.action_low,
        &model.action_high,
        seed,
    )?;
    layer.reset(&narrow(&obs))?;
    // The states sent so far, s_0 … s_t, for the arrivals of random delays.
    let mut sent = vec![narrow(&obs)];
    let ready_line = |layer: &CpuDelayLayer, t: usize| {
        let ready = layer.ready()[0] == 1;
        TraceStep {
            obs: ready.then(|| widen(&layer.augmented()[..obs_dim])),
            augmented: ready.then(|| widen(layer.augmented())),
            ..TraceStep::at(t)
        }
    };
    emit(&ready_line(&layer, 0));
    let mut executed = vec![0.0; act_dim];
    for (k, action) in actions.iter().enumerate() {
        check_vector("action", action, act_dim)?;
        executed_action(action, noise, &mut rng, &model, &mut executed);
        let outcome = env.step(&executed, &mut obs);
        let (chosen, next) = (narrow(action), narrow(&obs));
        sent.push(next.clone());
        layer.step(&StepInput {
            actions: &chosen,
            observations: &next,
            final_observations: &next,
            rewards: &[outcome.reward as f32],
            terminated: &[u32::from(outcome.terminated)],
            truncated: &[u32::from(outcome.truncated)],
        })?;
        let t = k + 1;
        let mut line = if outcome.done() {
            end_line(&layer, t, delay_steps)
        } else {
            ready_line(&layer, t)
        };
        if !outcome.done()
            && let Some(record) = layer.records().iter().next()
        {
            // The record of step t − Δ − 1 completed: its reward travels with s_{t-Δ}.
            line.reward = Some(f64::from(record.reward));
            (line.terminated, line.truncated) = (Some(false), Some(false));
        }
        if noise.is_some() {
            line.executed = Some(executed.clone());
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
        if outcome.done() {
            break;
        }
    }
    Ok(())
}

/// The line of the step that ended the episode at `t = T`: the regular arrival `s_{T-Δ}` and,
/// delivered at once, `s_{T-Δ+1} … s_T`, each with the reward and flags of its step.
fn end_line(layer: &CpuDelayLayer, t: usize, delay: usize) -> TraceStep {
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
