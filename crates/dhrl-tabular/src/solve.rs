//! Exact dynamic programming on any [`TabularModel`]: value iteration for `V*` and iterative
//! policy evaluation for `V^π` of a deterministic policy.
//!
//! Both iterate the Bellman operator (a `γ`-contraction) and stop once the a-posteriori error
//! bound `γ/(1−γ)·‖V_{k+1} − V_k‖_∞` is at most `tolerance·max(1, ‖V_{k+1}‖_∞)`, so the returned
//! values are within that distance of the exact fixed point.
//!
//! # Sweep limit
//! The change of sweep `k` is at most `γ^{k−1}·c₁`, where `c₁` is the change of the first sweep,
//! so the stopping rule holds after at most
//! `n = ⌈ln(tolerance·(1−γ)/c₁) / ln γ⌉` sweeps (the sweeps "needed"). After the first sweep the
//! solvers compute `n`; when `n` exceeds [`SolveOptions::max_iterations`] they stop at once with
//! [`TabularError::NotConverged`] (naming `γ` and `n`) instead of spending the whole limit, and
//! otherwise they allow `min(max_iterations, 2n + 16)` sweeps, the slack covering rounding noise.

use crate::error::TabularError;
use crate::model::TabularModel;

/// Stopping rule of the iterative solvers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveOptions {
    /// Relative accuracy of the returned values (see the module documentation).
    pub tolerance: f64,
    /// Largest number of sweeps; a problem whose contraction bound needs more (see the module
    /// documentation) is a [`TabularError::NotConverged`] error after the first sweep.
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

/// `⌈ln(tolerance·(1−γ)/c₁) / ln γ⌉`, at least 1: the sweeps after which the `γ`-contraction
/// guarantees the stopping rule, given the first sweep's change `c₁` (module documentation).
fn sweeps_needed(gamma: f64, tolerance: f64, first_change: f64) -> usize {
    if gamma <= 0.0 || first_change <= 0.0 || !first_change.is_finite() {
        return 1;
    }
    let ratio = tolerance * (1.0 - gamma) / first_change;
    if ratio >= 1.0 {
        return 1;
    }
    // ln γ = ln(1 − (1−γ)), accurate for γ close to one.
    let log_gamma = (-(1.0 - gamma)).ln_1p();
    let sweeps = (ratio.ln() / log_gamma).ceil();
    // `as` saturates, so an astronomically large estimate becomes `usize::MAX`.
    (sweeps as usize).max(1)
}

/// The sweep limit of one solver run (module documentation, "Sweep limit").
struct SweepLimit {
    what: &'static str,
    gamma: f64,
    tolerance: f64,
    max_iterations: usize,
    limit: usize,
    needed: usize,
}

impl SweepLimit {
    fn new<M: TabularModel>(what: &'static str, model: &M, options: &SolveOptions) -> Self {
        Self {
            what,
            gamma: model.gamma(),
            tolerance: options.tolerance,
            max_iterations: options.max_iterations,
            limit: options.max_iterations,
            needed: 0,
        }
    }

    fn error(&self, iterations: usize, residual: f64, reason: &'static str) -> TabularError {
        TabularError::NotConverged {
            what: self.what,
            iterations,
            limit: self.limit,
            needed: self.needed,
            gamma: self.gamma,
            residual,
            reason,
        }
    }

    /// Called after sweep number `sweep` (from 1) did not meet the stopping rule; an error stops
    /// the solver.
    fn after_sweep(&mut self, sweep: usize, change: f64) -> Result<(), TabularError> {
        if sweep == 1 {
            self.needed = sweeps_needed(self.gamma, self.tolerance, change);
            if self.needed > self.max_iterations {
                return Err(self.error(
                    sweep,
                    change,
                    "that is more than the sweep limit, so the solver stopped at once",
                ));
            }
            self.limit = self
                .max_iterations
                .min(self.needed.saturating_mul(2).saturating_add(16));
        }
        if sweep >= self.limit {
            let reason = if self.limit == self.max_iterations {
                "the sweep limit was reached"
            } else {
                "rounding noise kept the change above the stopping threshold (the tolerance is \
                 too tight for double precision at this gamma)"
            };
            return Err(self.error(sweep, change, reason));
        }
        Ok(())
    }
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
/// sweep limit is reached or `γ` needs more sweeps than it allows (module documentation).
pub fn value_iteration<M: TabularModel>(
    model: &M,
    options: &SolveOptions,
) -> Result<ValueSolution, TabularError> {
    options.validate()?;
    let n = model.num_states();
    let gamma = model.gamma();
    let mut values = vec![0.0; n];
    let mut next = vec![0.0; n];
    let mut limit = SweepLimit::new("value iteration", model, options);
    for iteration in 1.. {
        let mut change = 0.0f64;
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
        limit.after_sweep(iteration, change)?;
    }
    unreachable!("the sweep limit ends the loop")
}

/// Iterative policy evaluation of a deterministic policy (`policy[x]` is the action in `x`),
/// starting from `initial` when given (a warm start) and from zero otherwise.
///
/// # Errors
/// [`TabularError::ShapeMismatch`] for a policy or start vector of the wrong length,
/// [`TabularError::IndexOutOfRange`] for an action `≥ |A|`, [`TabularError::InvalidParameter`] for
/// bad options and [`TabularError::NotConverged`] when the sweep limit is reached or `γ` needs
/// more sweeps than it allows (module documentation).
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
    let mut limit = SweepLimit::new("policy evaluation", model, options);
    for sweep in 1.. {
        let mut change = 0.0f64;
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
        limit.after_sweep(sweep, change)?;
    }
    unreachable!("the sweep limit ends the loop")
}
