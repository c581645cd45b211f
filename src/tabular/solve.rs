//! Exact dynamic programming on any [`TabularModel`]: value iteration for `V*` and iterative
//! policy evaluation for `V^π` of a deterministic policy.
//!
//! Both iterate the Bellman operator (a `γ`-contraction) and stop once the a-posteriori error
//! bound `γ/(1−γ)·‖V_{k+1} − V_k‖_∞` is at most `tolerance·max(1, ‖V_{k+1}‖_∞)`, so the returned
//! values are within that distance of the exact fixed point.

use super::error::TabularError;
use super::model::TabularModel;

/// Stopping rule of the iterative solvers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveOptions {
    /// Relative accuracy of the returned values (see the module documentation).
    pub tolerance: f64,
    /// Iteration limit; reaching it is a [`TabularError::NotConverged`] error.
    pub max_iterations: usize,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-10,
            max_iterations: 1_000_000,
        }
    }
}

impl SolveOptions {
    fn validate(&self) -> Result<(), TabularError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(TabularError::InvalidParameter {
                name: "solver tolerance",
                value: self.tolerance.to_string(),
                accepted: "a finite number > 0".to_string(),
            });
        }
        if self.max_iterations == 0 {
            return Err(TabularError::InvalidParameter {
                name: "solver max_iterations",
                value: "0".to_string(),
                accepted: "at least 1".to_string(),
            });
        }
        Ok(())
    }
}

/// The result of value iteration.
#[derive(Clone, Debug)]
pub struct ValueSolution {
    /// `V*(x)` for every state.
    pub values: Vec<f64>,
    /// A greedy (optimal) deterministic policy, first maximising action on ties.
    pub policy: Vec<usize>,
    /// Sweeps performed.
    pub iterations: usize,
}

/// `R(x, a) + γ Σ_y P(y|x, a) V(y)`.
fn backup<M: TabularModel>(model: &M, values: &[f64], state: usize, action: usize) -> f64 {
    let expected: f64 = model
        .successors(state, action)
        .map(|(next, p)| p * values[next])
        .sum();
    model.reward(state, action) + model.gamma() * expected
}

fn converged(change: f64, scale: f64, gamma: f64, tolerance: f64) -> bool {
    gamma * change <= tolerance * scale.max(1.0) * (1.0 - gamma)
}

/// The greedy policy of `values`, first maximising action on ties.
pub(crate) fn greedy_policy<M: TabularModel>(model: &M, values: &[f64]) -> Vec<usize> {
    (0..model.num_states())
        .map(|state| {
            let mut best_action = 0;
            let mut best = f64::NEG_INFINITY;
            for action in 0..model.num_actions() {
                let q = backup(model, values, state, action);
                if q > best {
                    best = q;
                    best_action = action;
                }
            }
            best_action
        })
        .collect()
}

/// Value iteration: the optimal values `V*` and a greedy optimal policy.
///
/// # Errors
/// [`TabularError::InvalidParameter`] for bad options, [`TabularError::NotConverged`] when the
/// iteration limit is reached.
pub fn value_iteration<M: TabularModel>(
    model: &M,
    options: &SolveOptions,
) -> Result<ValueSolution, TabularError> {
    options.validate()?;
    let n = model.num_states();
    let gamma = model.gamma();
    let mut values = vec![0.0; n];
    let mut next = vec![0.0; n];
    let mut change = f64::INFINITY;
    for iteration in 1..=options.max_iterations {
        change = 0.0;
        let mut scale = 0.0f64;
        for (state, slot) in next.iter_mut().enumerate() {
            let best = (0..model.num_actions())
                .map(|action| backup(model, &values, state, action))
                .fold(f64::NEG_INFINITY, f64::max);
            change = change.max((best - values[state]).abs());
            scale = scale.max(best.abs());
            *slot = best;
        }
        std::mem::swap(&mut values, &mut next);
        if converged(change, scale, gamma, options.tolerance) {
            let policy = greedy_policy(model, &values);
            return Ok(ValueSolution {
                values,
                policy,
                iterations: iteration,
            });
        }
    }
    Err(TabularError::NotConverged {
        what: "value iteration",
        iterations: options.max_iterations,
        residual: change,
    })
}

/// Iterative policy evaluation of a deterministic policy (`policy[x]` is the action in `x`),
/// starting from `initial` when given (a warm start) and from zero otherwise.
///
/// # Errors
/// [`TabularError::ShapeMismatch`] for a policy or start vector of the wrong length,
/// [`TabularError::IndexOutOfRange`] for an action `≥ |A|`, [`TabularError::InvalidParameter`] for
/// bad options and [`TabularError::NotConverged`] when the iteration limit is reached.
pub fn evaluate_policy<M: TabularModel>(
    model: &M,
    policy: &[usize],
    initial: Option<&[f64]>,
    options: &SolveOptions,
) -> Result<Vec<f64>, TabularError> {
    options.validate()?;
    let n = model.num_states();
    if policy.len() != n {
        return Err(TabularError::ShapeMismatch {
            location: "policy".to_string(),
            found: policy.len(),
            expected: n,
            unit: "actions (one per state)",
        });
    }
    if let Some(&action) = policy.iter().find(|&&action| action >= model.num_actions()) {
        return Err(TabularError::IndexOutOfRange {
            what: "policy action",
            index: action,
            bound: model.num_actions(),
        });
    }
    let mut values = match initial {
        None => vec![0.0; n],
        Some(start) if start.len() == n => start.to_vec(),
        Some(start) => {
            return Err(TabularError::ShapeMismatch {
                location: "initial values".to_string(),
                found: start.len(),
                expected: n,
                unit: "values (one per state)",
            });
        }
    };
    let gamma = model.gamma();
    let mut next = vec![0.0; n];
    let mut change = f64::INFINITY;
    for _ in 0..options.max_iterations {
        change = 0.0;
        let mut scale = 0.0f64;
        for (state, slot) in next.iter_mut().enumerate() {
            let value = backup(model, &values, state, policy[state]);
            change = change.max((value - values[state]).abs());
            scale = scale.max(value.abs());
            *slot = value;
        }
        std::mem::swap(&mut values, &mut next);
        if converged(change, scale, gamma, options.tolerance) {
            return Ok(values);
        }
    }
    Err(TabularError::NotConverged {
        what: "policy evaluation",
        iterations: options.max_iterations,
        residual: change,
    })
}
