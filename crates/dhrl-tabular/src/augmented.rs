//! The augmented (regular) MDP `M_Δ = (X, A, P_Δ, R_Δ)` of a delayed MDP `M⁺ = (M, Δ)`, paper
//! section 2.1: `X = S × A^Δ`, `x_t = (s_{t−Δ}, a_{t−Δ}, …, a_{t−1})`, the belief `b_Δ(·|x)` and
//! the belief-expected reward `R_Δ(x, a) = E_{b_Δ(·|x)}[R(s, a)]`.
//!
//! Augmented states are numbered `x = s·|A|^Δ + h`, where the action history `h` is read as a
//! base-`|A|` number with the oldest action `a_{t−Δ}` as its most significant digit. Transitions
//! are not stored: `P_Δ(x'|x, a)` is read off the base MDP on demand
//! (`x' = (s', a_{t−Δ+1}, …, a_{t−1}, a)` with probability `P(s'|s_{t−Δ}, a_{t−Δ})`), so the
//! memory cost is the belief-expected reward table, `|X|·|A|` numbers.

use crate::error::TabularError;
use crate::mdp::FiniteMdp;
use crate::model::TabularModel;
use crate::sparse::{SparseAccumulator, SparseDistribution};

/// The default upper bound on `|X| = |S|·|A|^Δ`.
pub const DEFAULT_MAX_AUGMENTED_STATES: usize = 2_000_000;

/// Size limits that make the exponential growth of `X` an error instead of an out-of-memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SizeLimits {
    /// Largest accepted `|X| = |S|·|A|^Δ`.
    pub max_augmented_states: usize,
}

impl Default for SizeLimits {
    fn default() -> Self {
        Self {
            max_augmented_states: DEFAULT_MAX_AUGMENTED_STATES,
        }
    }
}

/// `|S|·|A|^Δ`, saturating at `u128::MAX`.
fn augmented_size(states: usize, actions: usize, delay: usize) -> u128 {
    let mut size = states as u128;
    if actions > 1 {
        for _ in 0..delay {
            size = size.saturating_mul(actions as u128);
            if size == u128::MAX {
                break;
            }
        }
    }
    size
}

/// Checks, before anything is built or generated, that the augmented MDP of a base MDP with
/// `states` states and `actions` actions at delay `delay` is within `limits`, and that its tables
/// can be addressed: `|X| = |S|·|A|^Δ`, the `|X|·|A|` belief-expected rewards and the `|S|·|A|`
/// transition rows of the base MDP. Returns `|X|`.
///
/// # Errors
/// [`TabularError::TooLarge`] when `|X|` exceeds `limits.max_augmented_states`,
/// [`TabularError::TableTooLarge`] when a table size overflows `usize`.
pub(crate) fn check_augmented_size(
    states: usize,
    actions: usize,
    delay: usize,
    limits: &SizeLimits,
) -> Result<usize, TabularError> {
    let size = augmented_size(states, actions, delay);
    if size > limits.max_augmented_states as u128 {
        return Err(TabularError::TooLarge {
            states,
            actions,
            delay,
            augmented_states: size,
            limit: limits.max_augmented_states,
        });
    }
    // `size <= limit <= usize::MAX`, so this conversion is exact.
    let size = size as usize;
    table_entries("augmented reward table |X|*|A|", size, actions)?;
    table_entries("transition rows |S|*|A|", states, actions)?;
    Ok(size)
}

/// `rows·actions` as a table size, or [`TabularError::TableTooLarge`] on overflow.
pub(crate) fn table_entries(
    table: &'static str,
    rows: usize,
    actions: usize,
) -> Result<usize, TabularError> {
    rows.checked_mul(actions)
        .ok_or(TabularError::TableTooLarge {
            table,
            states: rows,
            actions,
            entries: rows as u128 * actions as u128,
        })
}

/// One step of the belief recursion: `b'(s') = Σ_s b(s)·P(s'|s, a)`.
fn push_forward(
    base: &FiniteMdp,
    belief: &[(usize, f64)],
    action: usize,
    accumulator: &mut SparseAccumulator,
) -> SparseDistribution {
    for &(state, mass) in belief {
        for (next, p) in base.successors(state, action) {
            accumulator.add(next, mass * p);
        }
    }
    accumulator.drain_sorted()
}

/// The augmented MDP `M_Δ` of a delayed MDP (paper section 2.1). With `Δ = 0` it is the base MDP.
#[derive(Clone, Debug)]
pub struct AugmentedMdp {
    base: FiniteMdp,
    delay: usize,
    /// `|A|^Δ`, the number of action histories.
    histories: usize,
    /// `|A|^(Δ−1)`, the place value of the oldest action in a history (1 when `Δ = 0`).
    oldest_place: usize,
    /// `R_Δ(x, a)` at `x·|A| + a`.
    rewards: Vec<f64>,
}

impl AugmentedMdp {
    /// Builds `M_Δ` for the delayed MDP `(base, delay)`, computing `R_Δ` from the beliefs.
    ///
    /// # Errors
    /// [`TabularError::TooLarge`] when `|S|·|A|^Δ` exceeds `limits.max_augmented_states`,
    /// [`TabularError::TableTooLarge`] when the `|X|·|A|` reward table overflows or cannot be
    /// allocated.
    pub fn new(base: &FiniteMdp, delay: usize, limits: &SizeLimits) -> Result<Self, TabularError> {
        let (states, actions) = (base.num_states(), base.num_actions());
        let size = check_augmented_size(states, actions, delay, limits)?;
        let histories = size / states;
        let oldest_place = if delay == 0 { 1 } else { histories / actions };
        let mut model = Self {
            base: base.clone(),
            delay,
            histories,
            oldest_place,
            rewards: Vec::new(),
        };
        let entries = table_entries("augmented reward table |X|*|A|", size, actions)?;
        let mut rewards: Vec<f64> = Vec::new();
        rewards
            .try_reserve_exact(entries)
            .map_err(|_| TabularError::TableTooLarge {
                table: "augmented reward table |X|*|A|",
                states: size,
                actions,
                entries: entries as u128,
            })?;
        rewards.resize(entries, 0.0);
        model.for_each_belief(|x, belief| {
            let slots = &mut rewards[x * actions..(x + 1) * actions];
            for (action, slot) in slots.iter_mut().enumerate() {
                *slot = belief
                    .iter()
                    .map(|&(s, p)| p * model.base.reward(s, action))
                    .sum();
            }
        });
        model.rewards = rewards;
        Ok(model)
    }

    /// The underlying delay-free MDP `M`.
    pub fn base(&self) -> &FiniteMdp {
        &self.base
    }

    /// The delay `Δ`.
    pub fn delay(&self) -> usize {
        self.delay
    }

    /// The index of `x = (state, actions[0], …, actions[Δ−1])`, actions oldest first.
    ///
    /// # Errors
    /// [`TabularError::IndexOutOfRange`] for a state or action out of range,
    /// [`TabularError::ShapeMismatch`] when `actions.len() != Δ`.
    pub fn encode(&self, state: usize, actions: &[usize]) -> Result<usize, TabularError> {
        let (num_states, num_actions) = (self.base.num_states(), self.base.num_actions());
        if state >= num_states {
            return Err(TabularError::IndexOutOfRange {
                what: "state",
                index: state,
                bound: num_states,
            });
        }
        if actions.len() != self.delay {
            return Err(TabularError::ShapeMismatch {
                location: "action history".to_string(),
                found: actions.len(),
                expected: self.delay,
                unit: "actions (one per step of delay)",
            });
        }
        let mut history = 0;
        for &action in actions {
            if action >= num_actions {
                return Err(TabularError::IndexOutOfRange {
                    what: "action",
                    index: action,
                    bound: num_actions,
                });
            }
            history = history * num_actions + action;
        }
        Ok(self.index_of(state, history))
    }

    /// The observed state `s_{t−Δ}` and the action history (oldest first) of augmented state `x`.
    ///
    /// # Errors
    /// [`TabularError::IndexOutOfRange`] when `x ≥ |X|`.
    pub fn decode(&self, x: usize) -> Result<(usize, Vec<usize>), TabularError> {
        let bound = self.num_states();
        if x >= bound {
            return Err(TabularError::IndexOutOfRange {
                what: "augmented state",
                index: x,
                bound,
            });
        }
        let num_actions = self.base.num_actions();
        let (state, mut history) = (x / self.histories, x % self.histories);
        let mut actions = vec![0; self.delay];
        for slot in actions.iter_mut().rev() {
            *slot = history % num_actions;
            history /= num_actions;
        }
        Ok((state, actions))
    }

    /// The belief `b_Δ(·|x)`: the distribution of the current state `s_t` given
    /// `x_t = (s_{t−Δ}, a_{t−Δ}, …, a_{t−1})`, obtained by rolling `P` forward through the `Δ`
    /// actions. Sorted by state.
    ///
    /// # Errors
    /// [`TabularError::IndexOutOfRange`] when `x ≥ |X|`.
    pub fn belief(&self, x: usize) -> Result<SparseDistribution, TabularError> {
        let (state, actions) = self.decode(x)?;
        let mut accumulator = SparseAccumulator::new(self.base.num_states());
        let mut belief = vec![(state, 1.0)];
        for &action in &actions {
            belief = push_forward(&self.base, &belief, action, &mut accumulator);
        }
        Ok(belief)
    }

    /// Calls `visit(x, b_Δ(·|x))` for every augmented state in increasing order of `x`.
    ///
    /// Walks the tree of action histories depth first and shares belief prefixes, so the cost is
    /// about `|X|·|A|/(|A|−1)` belief updates instead of `|X|·Δ`.
    pub fn for_each_belief(&self, mut visit: impl FnMut(usize, &[(usize, f64)])) {
        let num_actions = self.base.num_actions();
        let delay = self.delay;
        let mut accumulator = SparseAccumulator::new(self.base.num_states());
        // levels[k]: belief after the first k actions of the current history.
        let mut levels: Vec<SparseDistribution> = vec![Vec::new(); delay + 1];
        let mut digits = vec![0usize; delay];
        for state in 0..self.base.num_states() {
            levels[0] = vec![(state, 1.0)];
            digits.fill(0);
            for k in 0..delay {
                levels[k + 1] = push_forward(&self.base, &levels[k], 0, &mut accumulator);
            }
            for history in 0..self.histories {
                visit(self.index_of(state, history), levels[delay].as_slice());
                if history + 1 == self.histories {
                    break;
                }
                // Odometer increment, last digit fastest; some digit is below |A|−1 because this
                // is not the last history, so `k` never goes below zero.
                let mut k = delay - 1;
                loop {
                    digits[k] += 1;
                    if digits[k] < num_actions {
                        break;
                    }
                    digits[k] = 0;
                    k -= 1;
                }
                for j in k..delay {
                    levels[j + 1] =
                        push_forward(&self.base, &levels[j], digits[j], &mut accumulator);
                }
            }
        }
    }

    /// `x = s·|A|^Δ + h`.
    pub(crate) fn index_of(&self, state: usize, history: usize) -> usize {
        state * self.histories + history
    }

    /// Splits `x` into the observed state and the history number.
    pub(crate) fn split(&self, x: usize) -> (usize, usize) {
        (x / self.histories, x % self.histories)
    }

    /// The action applied to the observed state by the transition `x → x'` under `action`: the
    /// oldest action of the history (or `action` itself when `Δ = 0`).
    fn applied_action(&self, history: usize, action: usize) -> usize {
        if self.delay == 0 {
            action
        } else {
            history / self.oldest_place
        }
    }

    /// The history after taking `action`: drop the oldest action, append `action`.
    pub(crate) fn shift_history(&self, history: usize, action: usize) -> usize {
        if self.delay == 0 {
            0
        } else {
            (history % self.oldest_place) * self.base.num_actions() + action
        }
    }
}

impl TabularModel for AugmentedMdp {
    fn num_states(&self) -> usize {
        self.base.num_states() * self.histories
    }

    fn num_actions(&self) -> usize {
        self.base.num_actions()
    }

    fn gamma(&self) -> f64 {
        self.base.gamma()
    }

    /// `R_Δ(x, a) = E_{b_Δ(·|x)}[R(s, a)]`.
    fn reward(&self, state: usize, action: usize) -> f64 {
        self.rewards[state * self.base.num_actions() + action]
    }

    /// `P_Δ(x'|x, a) = P(s'|s_{t−Δ}, a_{t−Δ})` for `x' = (s', a_{t−Δ+1}, …, a_{t−1}, a)`.
    fn successors(&self, state: usize, action: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (observed, history) = self.split(state);
        let applied = self.applied_action(history, action);
        let next_history = self.shift_history(history, action);
        let histories = self.histories;
        self.base
            .successors(observed, applied)
            .map(move |(next, p)| (next * histories + next_history, p))
    }
}
