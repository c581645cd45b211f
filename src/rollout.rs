//! The trace behind `dhrl rollout`: one episode of one copy from a given state and a given
//! action sequence, one JSON object per step, for outside checkers.
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::sim::{Env, SimError, TaskModel, check_vector};
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
    #[error("{path}: {source}")]
    State { path: String, source: SimError },
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
}

/// `{"qpos": [...], "qvel": [...]}`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialState {
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
}

/// One printed line of the trace. `t = 0` carries only the observation of the state as set.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TraceStep {
    pub t: usize,
    pub obs: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reward: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminated: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truncated: Option<bool>,
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

/// Sets the state, then applies the actions until they run out or the episode ends,
/// calling `emit` for the initial observation and after every step.
pub fn rollout(
    task: TaskName,
    state: &InitialState,
    actions: &[Vec<f64>],
    mut emit: impl FnMut(&TraceStep),
) -> Result<(), RolloutError> {
    let model = TaskModel::load(task)?;
    let mut env = Env::new(model);
    env.set_state(&state.qpos, &state.qvel)?;
    let mut obs = vec![0.0; task.def().obs_dim];
    env.observe(&mut obs);
    emit(&TraceStep {
        t: 0,
        obs: obs.clone(),
        reward: None,
        terminated: None,
        truncated: None,
    });
    for (k, action) in actions.iter().enumerate() {
        check_vector("action", action, task.def().act_dim)?;
        let outcome = env.step(action, &mut obs);
        emit(&TraceStep {
            t: k + 1,
            obs: obs.clone(),
            reward: Some(outcome.reward),
            terminated: Some(outcome.terminated),
            truncated: Some(outcome.truncated),
        });
        if outcome.done() {
            break;
        }
    }
    Ok(())
}
