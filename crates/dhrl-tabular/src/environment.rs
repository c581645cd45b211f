//! Sampling environments for Q-learning: any [`TabularModel`] as a generative simulator, and the
//! delayed environment `M⁺ = (M, Δ)` that simulates the true process and shows the agent only the
//! augmented state `x_t = (s_{t−Δ}, a_{t−Δ}, …, a_{t−1})` (paper section 2.1; docs/DESIGN.md §1.2).

use std::collections::VecDeque;

use rand::Rng;

use crate::augmented::AugmentedMdp;
use crate::model::TabularModel;

/// An episodic simulator with finitely many observations and actions.
pub trait Environment {
    /// Number of distinct observations (`0..num_observations()`).
    fn num_observations(&self) -> usize;

    /// Number of actions.
    fn num_actions(&self) -> usize;

    /// Discount factor of the task.
    fn gamma(&self) -> f64;

    /// Starts a new episode and returns its first observation.
    fn reset<R: Rng>(&mut self, rng: &mut R) -> usize;

    /// Applies `action` and returns the reward and the next observation.
    fn step<R: Rng>(&mut self, action: usize, rng: &mut R) -> (f64, usize);
}

/// Draws a next state from `P(·|state, action)`.
fn sample_successor<M: TabularModel, R: Rng>(
    model: &M,
    state: usize,
    action: usize,
    rng: &mut R,
) -> usize {
    let u: f64 = rng.random();
    let mut cumulative = 0.0;
    let mut last = state;
    for (next, p) in model.successors(state, action) {
        cumulative += p;
        last = next;
        if u < cumulative {
            return next;
        }
    }
    last
}

/// A [`TabularModel`] used as a simulator: episodes start in a uniformly random state, rewards are
/// the model's expected rewards `R(x, a)` and next states are drawn from `P(·|x, a)`.
#[derive(Clone, Debug)]
pub struct ModelEnv<'a, M: TabularModel> {
    model: &'a M,
    state: usize,
}

impl<'a, M: TabularModel> ModelEnv<'a, M> {
    /// A simulator of `model`, positioned in state 0 until the first reset.
    pub fn new(model: &'a M) -> Self {
        Self { model, state: 0 }
    }
}

impl<M: TabularModel> Environment for ModelEnv<'_, M> {
    fn num_observations(&self) -> usize {
        self.model.num_states()
    }

    fn num_actions(&self) -> usize {
        self.model.num_actions()
    }

    fn gamma(&self) -> f64 {
        self.model.gamma()
    }

    fn reset<R: Rng>(&mut self, rng: &mut R) -> usize {
        self.state = rng.random_range(0..self.model.num_states());
        self.state
    }

    fn step<R: Rng>(&mut self, action: usize, rng: &mut R) -> (f64, usize) {
        let reward = self.model.reward(self.state, action);
        self.state = sample_successor(self.model, self.state, action, rng);
        (reward, self.state)
    }
}

/// The delayed environment: it runs the true MDP, receives the true reward `r_t = R(s_t, a_t)`,
/// and observes `x_t` (the index of the augmented MDP it is built from).
///
/// A reset draws `s_0` uniformly and executes `Δ` uniformly random warm-up actions (paper,
/// Algorithm 1), so the first observation is uniform over `X` and the true state `s_Δ` follows the
/// belief `b_Δ(·|x_Δ)`. The warm-up steps are not returned to the agent.
#[derive(Clone, Debug)]
pub struct DelayedEnv<'a> {
    model: &'a AugmentedMdp,
    /// True states `s_{t−Δ}, …, s_t`, oldest first (empty before the first reset).
    true_states: VecDeque<usize>,
    /// The action history `a_{t−Δ}, …, a_{t−1}` as a history number.
    history: usize,
}

impl<'a> DelayedEnv<'a> {
    /// A delayed environment for the MDP and delay of `model`. Call
    /// [`Environment::reset`] first; a step before any reset resets implicitly.
    pub fn new(model: &'a AugmentedMdp) -> Self {
        Self {
            model,
            true_states: VecDeque::with_capacity(model.delay() + 2),
            history: 0,
        }
    }

    /// The true current state `s_t`, hidden from the agent (`None` before the first reset).
    pub fn true_state(&self) -> Option<usize> {
        self.true_states.back().copied()
    }

    fn observation(&self) -> usize {
        let oldest = self.true_states.front().copied().unwrap_or(0);
        self.model.index_of(oldest, self.history)
    }
}

impl Environment for DelayedEnv<'_> {
    fn num_observations(&self) -> usize {
        self.model.num_states()
    }

    fn num_actions(&self) -> usize {
        self.model.num_actions()
    }

    fn gamma(&self) -> f64 {
        self.model.gamma()
    }

    fn reset<R: Rng>(&mut self, rng: &mut R) -> usize {
        let model = self.model;
        let base = model.base();
        let num_actions = base.num_actions();
        let mut current = rng.random_range(0..base.num_states());
        self.true_states.clear();
        self.true_states.push_back(current);
        self.history = 0;
        for _ in 0..model.delay() {
            let action = rng.random_range(0..num_actions);
            current = sample_successor(base, current, action, rng);
            self.true_states.push_back(current);
            self.history = self.history * num_actions + action;
        }
        self.observation()
    }

    fn step<R: Rng>(&mut self, action: usize, rng: &mut R) -> (f64, usize) {
        if self.true_states.is_empty() {
            self.reset(rng);
        }
        let model = self.model;
        let base = model.base();
        let current = self.true_states.back().copied().unwrap_or(0);
        let reward = base.reward(current, action);
        let next = sample_successor(base, current, action, rng);
        self.true_states.push_back(next);
        self.true_states.pop_front();
        self.history = model.shift_history(self.history, action);
        (reward, self.observation())
    }
}
