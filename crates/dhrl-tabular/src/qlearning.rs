//! Tabular Q-learning with ε-greedy exploration along trajectories, over the blocks of a state
//! partition: with the discrete partition it learns `Q(x, a)` on the environment's own
//! observations; with a belief partition it samples the delayed environment but updates
//! `Q̄(f(x), a)`, which is what DHRL does (section 3, Cor. 3.6).
//!
//! Update for a sample `(x, a, r, x')`:
//! `Q(f(x), a) ← Q(f(x), a) + α_n (r + γ max_{a'} Q(f(x'), a') − Q(f(x), a))` with the rescaled
//! linear step size `α_n = 1 / (1 + (1−γ) n)`, `n` the number of earlier updates of `(f(x), a)`.
//! Episodes are truncated after a fixed number of steps (bootstrapping continues; there are no
//! terminal states).

use rand::Rng;

use crate::environment::Environment;
use crate::error::TabularError;
use crate::partition::Partition;

/// Settings of [`q_learning`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QLearningConfig {
    /// Probability of a uniformly random action instead of the greedy one.
    pub exploration: f64,
    /// Steps per episode before a reset.
    pub episode_length: usize,
    /// Budget of environment samples (transitions used for updates).
    pub max_samples: u64,
    /// The stopping test runs every this many samples.
    pub check_every: u64,
}

impl Default for QLearningConfig {
    fn default() -> Self {
        Self {
            exploration: 0.2,
            episode_length: 20,
            max_samples: 2_000_000,
            check_every: 500,
        }
    }
}

impl QLearningConfig {
    /// Rejects settings outside their ranges.
    ///
    /// # Errors
    /// [`TabularError::InvalidParameter`] naming the offending setting.
    pub fn validate(&self) -> Result<(), TabularError> {
        if !(0.0..=1.0).contains(&self.exploration) {
            return Err(TabularError::InvalidParameter {
                name: "exploration",
                value: self.exploration.to_string(),
                accepted: "a probability in [0, 1]".to_string(),
            });
        }
        let positive: [(&'static str, u64); 3] = [
            ("episode_length", self.episode_length as u64),
            ("max_samples", self.max_samples),
            ("check_every", self.check_every),
        ];
        for (name, value) in positive {
            if value == 0 {
                return Err(TabularError::InvalidParameter {
                    name,
                    value: "0".to_string(),
                    accepted: "at least 1".to_string(),
                });
            }
        }
        Ok(())
    }
}

/// A table of action values `Q(z, a)` over learner states `z`.
#[derive(Clone, Debug, PartialEq)]
pub struct QTable {
    values: Vec<f64>,
    num_actions: usize,
}

impl QTable {
    /// All-zero values.
    pub fn new(num_states: usize, num_actions: usize) -> Self {
        Self {
            values: vec![0.0; num_states * num_actions],
            num_actions,
        }
    }

    /// Number of learner states.
    pub fn num_states(&self) -> usize {
        self.values.len() / self.num_actions.max(1)
    }

    /// Number of actions.
    pub fn num_actions(&self) -> usize {
        self.num_actions
    }

    /// `Q(state, action)`.
    ///
    /// # Panics
    /// If `state` or `action` is out of range.
    pub fn get(&self, state: usize, action: usize) -> f64 {
        self.values[state * self.num_actions + action]
    }

    fn row(&self, state: usize) -> &[f64] {
        &self.values[state * self.num_actions..(state + 1) * self.num_actions]
    }

    /// `argmax_a Q(state, a)`, the first maximising action on ties.
    ///
    /// # Panics
    /// If `state` is out of range.
    pub fn greedy_action(&self, state: usize) -> usize {
        let row = self.row(state);
        row.iter().enumerate().skip(1).fold(
            0,
            |best, (action, &q)| if q > row[best] { action } else { best },
        )
    }

    /// `max_a Q(state, a)`.
    ///
    /// # Panics
    /// If `state` is out of range.
    pub fn max_value(&self, state: usize) -> f64 {
        self.row(state)
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The greedy policy over learner states.
    pub fn greedy_policy(&self) -> Vec<usize> {
        (0..self.num_states())
            .map(|state| self.greedy_action(state))
            .collect()
    }
}

/// The outcome of a Q-learning run.
#[derive(Clone, Debug)]
pub struct QLearningRun {
    /// The learned values over the partition's blocks.
    pub q: QTable,
    /// Samples used.
    pub samples: u64,
    /// The sample count at which the stopping test first passed, if it did.
    pub reached_at: Option<u64>,
}

/// Runs Q-learning in `env` over the blocks of `partition` (see the module documentation) until
/// `reached(&q)` returns `true` at a check (every `config.check_every` samples) or the sample
/// budget is spent.
///
/// # Errors
/// [`TabularError::InvalidParameter`] for bad settings, [`TabularError::ShapeMismatch`] when the
/// partition does not cover the environment's observations, and any error of `reached`.
pub fn q_learning<E, R, F>(
    env: &mut E,
    partition: &Partition,
    config: &QLearningConfig,
    rng: &mut R,
    mut reached: F,
) -> Result<QLearningRun, TabularError>
where
    E: Environment,
    R: Rng,
    F: FnMut(&QTable) -> Result<bool, TabularError>,
{
    config.validate()?;
    if partition.num_elements() != env.num_observations() {
        return Err(TabularError::ShapeMismatch {
            location: "learner partition".to_string(),
            found: partition.num_elements(),
            expected: env.num_observations(),
            unit: "elements (one per observation)",
        });
    }
    let num_actions = env.num_actions();
    let gamma = env.gamma();
    let mut q = QTable::new(partition.num_blocks(), num_actions);
    let mut counts = vec![0u64; q.values.len()];
    let mut observation = env.reset(rng);
    let mut steps_in_episode = 0;
    for samples in 1..=config.max_samples {
        let state = partition.block_of(observation);
        let action = if rng.random::<f64>() < config.exploration {
            rng.random_range(0..num_actions)
        } else {
            q.greedy_action(state)
        };
        let (reward, next) = env.step(action, rng);
        let target = reward + gamma * q.max_value(partition.block_of(next));
        let index = state * num_actions + action;
        let step_size = 1.0 / (1.0 + (1.0 - gamma) * counts[index] as f64);
        counts[index] += 1;
        q.values[index] += step_size * (target - q.values[index]);
        observation = next;
        steps_in_episode += 1;
        if steps_in_episode == config.episode_length {
            observation = env.reset(rng);
            steps_in_episode = 0;
        }
        if samples % config.check_every == 0 && reached(&q)? {
            return Ok(QLearningRun {
                q,
                samples,
                reached_at: Some(samples),
            });
        }
    }
    Ok(QLearningRun {
        q,
        samples: config.max_samples,
        reached_at: None,
    })
}
