//! The finite MDP `M = (S, A, P, R, γ)` of the paper's section 2.1, with validation and the JSON
//! file format of the `dhrl tabular` command.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::TabularError;
use crate::model::TabularModel;

/// How far a transition row may sum away from one.
pub const ROW_SUM_TOLERANCE: f64 = 1e-9;

/// The JSON form of a finite MDP, dense and indexed state-first:
/// `{"gamma": 0.9, "transitions": [[[p(s'|s,a) for s'] for a] for s], "rewards": [[r(s,a) for a] for s]}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MdpFile {
    /// Discount factor `γ ∈ [0, 1)`.
    pub gamma: f64,
    /// `transitions[s][a][s'] = P(s' | s, a)`.
    pub transitions: Vec<Vec<Vec<f64>>>,
    /// `rewards[s][a] = R(s, a)`.
    pub rewards: Vec<Vec<f64>>,
}

/// Transition rows in compressed sparse row form: row `s·|A| + a` holds the next states of
/// `(s, a)` with positive probability, sorted by next state.
#[derive(Clone, Debug)]
pub(crate) struct TransitionRows {
    offsets: Vec<usize>,
    next_states: Vec<usize>,
    probabilities: Vec<f64>,
}

impl TransitionRows {
    /// No rows yet, room for `rows` rows.
    pub(crate) fn with_capacity(rows: usize) -> Self {
        let mut offsets = Vec::with_capacity(rows + 1);
        offsets.push(0);
        Self {
            offsets,
            next_states: Vec::new(),
            probabilities: Vec::new(),
        }
    }

    /// Appends a row given as `(next state, probability)` pairs sorted by next state.
    pub(crate) fn push_row(&mut self, row: &[(usize, f64)]) {
        for &(next, probability) in row {
            self.next_states.push(next);
            self.probabilities.push(probability);
        }
        self.offsets.push(self.next_states.len());
    }

    /// Number of rows stored.
    fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The entries of row `row`.
    fn row(&self, row: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.offsets[row]..self.offsets[row + 1];
        self.next_states[range.clone()]
            .iter()
            .copied()
            .zip(self.probabilities[range].iter().copied())
    }
}

/// A validated finite MDP with the same actions in every state (paper section 2.1). Transitions
/// are stored sparsely, so large deterministic MDPs cost `O(|S|·|A|)` memory.
#[derive(Clone, Debug)]
pub struct FiniteMdp {
    num_states: usize,
    num_actions: usize,
    gamma: f64,
    rewards: Vec<f64>,
    rows: TransitionRows,
}

fn validate_gamma(gamma: f64) -> Result<(), TabularError> {
    if (0.0..1.0).contains(&gamma) {
        Ok(())
    } else {
        Err(TabularError::InvalidGamma { gamma })
    }
}

impl FiniteMdp {
    /// Builds an MDP from dense tables: `transitions[s][a][s'] = P(s'|s,a)` and
    /// `rewards[s][a] = R(s,a)`.
    ///
    /// # Errors
    /// [`TabularError::NoStates`], [`TabularError::NoActions`], [`TabularError::ShapeMismatch`]
    /// (inconsistent lengths, naming the offending list), [`TabularError::InvalidGamma`]
    /// (`γ ∉ [0, 1)`), [`TabularError::InvalidProbability`] (outside `[0, 1]` or not finite),
    /// [`TabularError::RowSum`] (a row off one by more than [`ROW_SUM_TOLERANCE`]) and
    /// [`TabularError::InvalidReward`] (NaN or infinite), each naming the state and action.
    pub fn new(
        gamma: f64,
        transitions: &[Vec<Vec<f64>>],
        rewards: &[Vec<f64>],
    ) -> Result<Self, TabularError> {
        let num_states = transitions.len();
        if num_states == 0 {
            return Err(TabularError::NoStates);
        }
        if rewards.len() != num_states {
            return Err(TabularError::ShapeMismatch {
                location: "rewards".to_string(),
                found: rewards.len(),
                expected: num_states,
                unit: "states (transitions lists one entry per state)",
            });
        }
        let num_actions = transitions[0].len();
        if num_actions == 0 {
            // Only "no actions" when no state lists any; otherwise state 0 is the odd one out.
            return Err(
                match transitions.iter().map(Vec::len).find(|&count| count > 0) {
                    None => TabularError::NoActions,
                    Some(expected) => TabularError::ShapeMismatch {
                        location: "transitions[0]".to_string(),
                        found: 0,
                        expected,
                        unit: "actions (a later state lists that many)",
                    },
                },
            );
        }
        for (state, per_action) in transitions.iter().enumerate() {
            if per_action.len() != num_actions {
                return Err(TabularError::ShapeMismatch {
                    location: format!("transitions[{state}]"),
                    found: per_action.len(),
                    expected: num_actions,
                    unit: "actions (state 0 has that many)",
                });
            }
            for (action, row) in per_action.iter().enumerate() {
                if row.len() != num_states {
                    return Err(TabularError::ShapeMismatch {
                        location: format!("transitions[{state}][{action}]"),
                        found: row.len(),
                        expected: num_states,
                        unit: "next-state probabilities (one per state)",
                    });
                }
            }
        }
        for (state, row) in rewards.iter().enumerate() {
            if row.len() != num_actions {
                return Err(TabularError::ShapeMismatch {
                    location: format!("rewards[{state}]"),
                    found: row.len(),
                    expected: num_actions,
                    unit: "rewards (one per action)",
                });
            }
        }
        let rows = transitions
            .iter()
            .flat_map(|per_action| {
                per_action.iter().map(|row| {
                    row.iter()
                        .enumerate()
                        .filter(|&(_, &p)| p != 0.0)
                        .map(|(next, &p)| (next, p))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let flat_rewards = rewards.iter().flatten().copied().collect();
        Self::from_sparse(num_states, num_actions, gamma, rows, flat_rewards)
    }

    /// Builds an MDP from sparse rows: `rows[s·|A| + a]` lists `(s', P(s'|s,a))` pairs in any order
    /// (repeated next states are summed, zero entries dropped) and `rewards[s·|A| + a] = R(s,a)`.
    ///
    /// # Errors
    /// As [`FiniteMdp::new`], plus [`TabularError::InvalidNextState`] for a next state `≥ |S|`.
    pub fn from_sparse(
        num_states: usize,
        num_actions: usize,
        gamma: f64,
        rows: Vec<Vec<(usize, f64)>>,
        rewards: Vec<f64>,
    ) -> Result<Self, TabularError> {
        if num_states == 0 {
            return Err(TabularError::NoStates);
        }
        if num_actions == 0 {
            return Err(TabularError::NoActions);
        }
        let pairs = num_states * num_actions;
        if rows.len() != pairs {
            return Err(TabularError::ShapeMismatch {
                location: "transition rows".to_string(),
                found: rows.len(),
                expected: pairs,
                unit: "rows (one per state-action pair)",
            });
        }
        if rewards.len() != pairs {
            return Err(TabularError::ShapeMismatch {
                location: "rewards".to_string(),
                found: rewards.len(),
                expected: pairs,
                unit: "rewards (one per state-action pair)",
            });
        }
        validate_gamma(gamma)?;
        let mut csr = TransitionRows::with_capacity(pairs);
        let mut merged: Vec<(usize, f64)> = Vec::new();
        for (index, mut row) in rows.into_iter().enumerate() {
            let (state, action) = (index / num_actions, index % num_actions);
            row.sort_by_key(|&(next, _)| next);
            merged.clear();
            let mut sum = 0.0;
            for (next_state, value) in row {
                if next_state >= num_states {
                    return Err(TabularError::InvalidNextState {
                        state,
                        action,
                        next_state,
                        num_states,
                    });
                }
                if !(0.0..=1.0).contains(&value) {
                    return Err(TabularError::InvalidProbability {
                        state,
                        action,
                        next_state,
                        value,
                    });
                }
                sum += value;
                if value == 0.0 {
                    continue;
                }
                let len = merged.len();
                if len > 0 && merged[len - 1].0 == next_state {
                    merged[len - 1].1 += value;
                } else {
                    merged.push((next_state, value));
                }
            }
            if (sum - 1.0).abs() > ROW_SUM_TOLERANCE {
                return Err(TabularError::RowSum { state, action, sum });
            }
            csr.push_row(&merged);
        }
        if let Some((index, &value)) = rewards.iter().enumerate().find(|(_, r)| !r.is_finite()) {
            return Err(TabularError::InvalidReward {
                state: index / num_actions,
                action: index % num_actions,
                value,
            });
        }
        Ok(Self {
            num_states,
            num_actions,
            gamma,
            rewards,
            rows: csr,
        })
    }

    /// Assembles an MDP from parts that are valid by construction (the quotient MDP, whose rows
    /// are convex combinations of validated rows).
    pub(crate) fn from_parts(
        num_states: usize,
        num_actions: usize,
        gamma: f64,
        rewards: Vec<f64>,
        rows: TransitionRows,
    ) -> Self {
        debug_assert_eq!(rows.len(), num_states * num_actions);
        debug_assert_eq!(rewards.len(), num_states * num_actions);
        Self {
            num_states,
            num_actions,
            gamma,
            rewards,
            rows,
        }
    }

    /// Builds an MDP from its JSON form (see [`MdpFile`]), validating it as [`FiniteMdp::new`].
    ///
    /// # Errors
    /// As [`FiniteMdp::new`].
    pub fn from_file_format(file: &MdpFile) -> Result<Self, TabularError> {
        Self::new(file.gamma, &file.transitions, &file.rewards)
    }

    /// Parses and validates an MDP from JSON text.
    ///
    /// # Errors
    /// [`TabularError::Json`] for malformed JSON or missing fields, otherwise as [`FiniteMdp::new`].
    pub fn from_json_str(text: &str) -> Result<Self, TabularError> {
        let file: MdpFile =
            serde_json::from_str(text).map_err(|source| TabularError::Json { source })?;
        Self::from_file_format(&file)
    }

    /// Reads, parses and validates an MDP JSON file.
    ///
    /// # Errors
    /// [`TabularError::Io`] when the file cannot be read, otherwise as
    /// [`FiniteMdp::from_json_str`].
    pub fn from_json_file(path: impl AsRef<Path>) -> Result<Self, TabularError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| TabularError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_json_str(&text)
    }

    /// The dense JSON form of this MDP.
    pub fn to_file_format(&self) -> MdpFile {
        let transitions = (0..self.num_states)
            .map(|state| {
                (0..self.num_actions)
                    .map(|action| {
                        let mut dense = vec![0.0; self.num_states];
                        for (next, p) in self.successors(state, action) {
                            dense[next] = p;
                        }
                        dense
                    })
                    .collect()
            })
            .collect();
        let rewards = self
            .rewards
            .chunks(self.num_actions)
            .map(<[f64]>::to_vec)
            .collect();
        MdpFile {
            gamma: self.gamma,
            transitions,
            rewards,
        }
    }

    /// `P(next | state, action)`; zero for pairs outside the support.
    ///
    /// # Panics
    /// If `state` or `action` is out of range.
    pub fn probability(&self, state: usize, action: usize, next: usize) -> f64 {
        self.successors(state, action)
            .find(|&(s, _)| s == next)
            .map_or(0.0, |(_, p)| p)
    }

    /// Whether every state-action pair has a single successor (deterministic dynamics, the
    /// setting of Prop. 3.3 and 3.5).
    pub fn is_deterministic(&self) -> bool {
        (0..self.rows.len()).all(|row| self.rows.row(row).count() == 1)
    }
}

impl TabularModel for FiniteMdp {
    fn num_states(&self) -> usize {
        self.num_states
    }

    fn num_actions(&self) -> usize {
        self.num_actions
    }

    fn gamma(&self) -> f64 {
        self.gamma
    }

    fn reward(&self, state: usize, action: usize) -> f64 {
        self.rewards[state * self.num_actions + action]
    }

    fn successors(&self, state: usize, action: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.rows.row(state * self.num_actions + action)
    }
}
