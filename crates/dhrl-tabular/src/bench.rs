//! The sample-complexity experiment behind Cor. 3.6: Q-learning on the augmented MDP (`Q(x, a)`,
//! `|S|·|A|^Δ` states) against Q-learning on the belief abstraction (`Q̄(f(x), a)`, at most `|S|`
//! states under deterministic dynamics), both sampling the same delayed environment.
//!
//! Protocol, per delay and seed: a deterministic random MDP (seed = run index), ε-greedy
//! Q-learning along trajectories of the delayed environment (resets to a uniformly random
//! augmented state, see [`DelayedEnv`]), one sample per environment transition used for an update
//! (reset warm-up steps are not counted). Every `check_every` samples the greedy policy
//! (`x ↦ argmax_a Q(f(x), a)`) is evaluated exactly on the augmented MDP; the run has converged
//! when `V*(x) − V^greedy(x) ≤ tolerance` at every augmented state. Runs that spend
//! `max_samples` without converging are reported as not reached and left out of mean and standard
//! deviation (sample standard deviation, `n − 1`).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::augmented::{AugmentedMdp, SizeLimits, check_augmented_size};
use crate::environment::DelayedEnv;
use crate::error::TabularError;
use crate::generate::{RandomMdpSpec, random_mdp};
use crate::model::TabularModel;
use crate::partition::{Partition, belief_partition};
use crate::qlearning::{QLearningConfig, QTable, q_learning};
use crate::solve::{SolveOptions, evaluate_policy, value_iteration};

/// Settings of [`run_bench`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BenchConfig {
    /// `|S|` of the generated MDPs.
    pub states: usize,
    /// `|A|` of the generated MDPs.
    pub actions: usize,
    /// Discount factor.
    pub gamma: f64,
    /// Smallest delay.
    pub min_delay: usize,
    /// Largest delay (inclusive).
    pub max_delay: usize,
    /// Number of runs per delay (seeds `0..seeds`).
    pub seeds: u64,
    /// Allowed value loss of the greedy policy at every augmented state.
    pub tolerance: f64,
    /// Q-learning settings shared by both learners.
    pub learning: QLearningConfig,
    /// Size limit of the augmented MDPs.
    pub limits: SizeLimits,
}

impl Default for BenchConfig {
    fn default() -> Self {
        Self {
            states: 8,
            actions: 2,
            gamma: 0.9,
            min_delay: 1,
            max_delay: 6,
            seeds: 5,
            tolerance: 0.1,
            learning: QLearningConfig::default(),
            limits: SizeLimits::default(),
        }
    }
}

impl BenchConfig {
    fn validate(&self) -> Result<(), TabularError> {
        if self.min_delay > self.max_delay {
            return Err(TabularError::InvalidParameter {
                name: "min_delay",
                value: self.min_delay.to_string(),
                accepted: format!("at most max_delay ({})", self.max_delay),
            });
        }
        if self.seeds == 0 {
            return Err(TabularError::InvalidParameter {
                name: "seeds",
                value: "0".to_string(),
                accepted: "at least 1".to_string(),
            });
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(TabularError::InvalidParameter {
                name: "tolerance",
                value: self.tolerance.to_string(),
                accepted: "a finite number > 0".to_string(),
            });
        }
        self.learning.validate()?;
        // The largest delay has the largest augmented MDP: refuse it before any run.
        check_augmented_size(self.states, self.actions, self.max_delay, &self.limits)?;
        Ok(())
    }
}

/// Samples-to-tolerance of one learner over all seeds of one delay.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SampleStats {
    /// Per seed: the samples needed, or `None` (JSON `null`) when the budget ran out.
    pub samples: Vec<Option<u64>>,
    /// Number of runs.
    pub runs: usize,
    /// Runs that reached the tolerance.
    pub reached: usize,
    /// Mean over the runs that reached it.
    pub mean: Option<f64>,
    /// Sample standard deviation over the runs that reached it (0 for a single run).
    pub std: Option<f64>,
}

impl SampleStats {
    /// Summarises per-seed results.
    pub fn from_samples(samples: Vec<Option<u64>>) -> Self {
        let reached: Vec<f64> = samples.iter().flatten().map(|&s| s as f64).collect();
        let (mean, std) = if reached.is_empty() {
            (None, None)
        } else {
            let n = reached.len() as f64;
            let mean = reached.iter().sum::<f64>() / n;
            let variance = if reached.len() > 1 {
                reached.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
            } else {
                0.0
            };
            (Some(mean), Some(variance.sqrt()))
        };
        Self {
            runs: samples.len(),
            reached: reached.len(),
            samples,
            mean,
            std,
        }
    }

    fn summary(&self) -> String {
        match (self.mean, self.std) {
            (Some(mean), Some(std)) => format!("{mean:.0} ± {std:.0}"),
            _ => "not reached".to_string(),
        }
    }
}

/// Results for one delay.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchRow {
    /// `Δ`.
    pub delay: usize,
    /// `|X| = |S|·|A|^Δ`.
    pub augmented_states: usize,
    /// Mean `|X̄|` of the belief partitions over the seeds.
    pub abstract_states_mean: f64,
    /// Q-learning over augmented states.
    pub augmented: SampleStats,
    /// Q-learning over belief classes `f(x)`.
    #[serde(rename = "abstract")]
    pub abstraction: SampleStats,
}

/// The whole experiment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchReport {
    /// `|S|`.
    pub states: usize,
    /// `|A|`.
    pub actions: usize,
    /// `γ`.
    pub gamma: f64,
    /// Runs per delay.
    pub seeds: u64,
    /// Allowed value loss of the greedy policy.
    pub tolerance: f64,
    /// Sample budget per run.
    pub max_samples: u64,
    /// Check interval in samples.
    pub check_every: u64,
    /// ε-greedy exploration probability.
    pub exploration: f64,
    /// Episode length.
    pub episode_length: usize,
    /// How samples are collected and counted.
    pub sampling: String,
    /// One row per delay.
    pub rows: Vec<BenchRow>,
}

/// Evaluates greedy policies on the augmented MDP, reusing the last result while the greedy
/// policy is unchanged and warm-starting policy evaluation from the last values.
struct GreedyChecker<'a> {
    model: &'a AugmentedMdp,
    partition: &'a Partition,
    optimal: &'a [f64],
    tolerance: f64,
    options: SolveOptions,
    policy: Vec<usize>,
    values: Vec<f64>,
    last: Option<bool>,
}

impl<'a> GreedyChecker<'a> {
    fn new(
        model: &'a AugmentedMdp,
        partition: &'a Partition,
        optimal: &'a [f64],
        tolerance: f64,
    ) -> Self {
        Self {
            model,
            partition,
            optimal,
            tolerance,
            options: SolveOptions {
                tolerance: 1e-8,
                ..SolveOptions::default()
            },
            policy: Vec::new(),
            values: vec![0.0; model.num_states()],
            last: None,
        }
    }

    fn is_near_optimal(&mut self, q: &QTable) -> Result<bool, TabularError> {
        let policy: Vec<usize> = self
            .partition
            .block_map()
            .iter()
            .map(|&block| q.greedy_action(block))
            .collect();
        if let Some(result) = self.last
            && policy == self.policy
        {
            return Ok(result);
        }
        let values = evaluate_policy(
            self.model,
            &policy,
            Some(self.values.as_slice()),
            &self.options,
        )?;
        let result = self
            .optimal
            .iter()
            .zip(&values)
            .all(|(best, value)| best - value <= self.tolerance);
        self.policy = policy;
        self.values = values;
        self.last = Some(result);
        Ok(result)
    }
}

/// Samples one learner needs on `model`, or `None` when the budget runs out.
fn samples_to_tolerance(
    model: &AugmentedMdp,
    partition: &Partition,
    optimal: &[f64],
    config: &BenchConfig,
    seed: u64,
) -> Result<Option<u64>, TabularError> {
    let mut env = DelayedEnv::new(model);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut checker = GreedyChecker::new(model, partition, optimal, config.tolerance);
    let run = q_learning(&mut env, partition, &config.learning, &mut rng, |q| {
        checker.is_near_optimal(q)
    })?;
    Ok(run.reached_at)
}

/// Runs the experiment described in the module documentation.
///
/// # Errors
/// [`TabularError::InvalidParameter`] for bad settings, [`TabularError::TooLarge`] when the
/// largest delay exceeds the size limit (checked before any run), and solver errors.
pub fn run_bench(config: &BenchConfig) -> Result<BenchReport, TabularError> {
    config.validate()?;
    let solve = SolveOptions::default();
    let mut rows = Vec::new();
    for delay in config.min_delay..=config.max_delay {
        let mut augmented_samples = Vec::new();
        let mut abstract_samples = Vec::new();
        let mut abstract_sizes = Vec::new();
        let mut augmented_states = 0;
        for seed in 0..config.seeds {
            let mdp = random_mdp(&RandomMdpSpec {
                states: config.states,
                actions: config.actions,
                gamma: config.gamma,
                stochastic: 0.0,
                seed,
            })?;
            let model = AugmentedMdp::new(&mdp, delay, &config.limits)?;
            augmented_states = model.num_states();
            let optimal = value_iteration(&model, &solve)?;
            let belief = belief_partition(&model);
            abstract_sizes.push(belief.num_blocks() as f64);
            let discrete = Partition::discrete(model.num_states());
            let learner_seed = seed.wrapping_mul(1_000_003).wrapping_add(delay as u64);
            augmented_samples.push(samples_to_tolerance(
                &model,
                &discrete,
                &optimal.values,
                config,
                learner_seed,
            )?);
            abstract_samples.push(samples_to_tolerance(
                &model,
                &belief,
                &optimal.values,
                config,
                learner_seed,
            )?);
        }
        rows.push(BenchRow {
            delay,
            augmented_states,
            abstract_states_mean: abstract_sizes.iter().sum::<f64>() / abstract_sizes.len() as f64,
            augmented: SampleStats::from_samples(augmented_samples),
            abstraction: SampleStats::from_samples(abstract_samples),
        });
    }
    Ok(BenchReport {
        states: config.states,
        actions: config.actions,
        gamma: config.gamma,
        seeds: config.seeds,
        tolerance: config.tolerance,
        max_samples: config.learning.max_samples,
        check_every: config.learning.check_every,
        exploration: config.learning.exploration,
        episode_length: config.learning.episode_length,
        sampling:
            "epsilon-greedy Q-learning along trajectories of the delayed environment; a sample \
                   is one environment transition used for an update (reset warm-up steps excluded)"
                .to_string(),
        rows,
    })
}

impl BenchReport {
    /// The results as an aligned text table (mean ± std of the samples needed, per delay).
    pub fn to_table(&self) -> String {
        let header = [
            "delay",
            "|X|",
            "abstract |X| (mean)",
            "augmented Q: samples",
            "reached",
            "abstract Q: samples",
            "reached",
        ];
        let mut table: Vec<Vec<String>> = vec![header.iter().map(|h| h.to_string()).collect()];
        for row in &self.rows {
            table.push(vec![
                row.delay.to_string(),
                row.augmented_states.to_string(),
                format!("{:.1}", row.abstract_states_mean),
                row.augmented.summary(),
                format!("{}/{}", row.augmented.reached, row.augmented.runs),
                row.abstraction.summary(),
                format!("{}/{}", row.abstraction.reached, row.abstraction.runs),
            ]);
        }
        let widths: Vec<usize> = (0..header.len())
            .map(|column| {
                table
                    .iter()
                    .map(|cells| cells[column].chars().count())
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        let mut out = format!(
            "Q-learning samples to a greedy policy within {} of V* at every augmented state\n\
             ({} states, {} actions, gamma {}, {} seeds, cap {} samples, check every {}, \
             exploration {}, episodes of {} steps; mean ± std over runs that reached it)\n",
            self.tolerance,
            self.states,
            self.actions,
            self.gamma,
            self.seeds,
            self.max_samples,
            self.check_every,
            self.exploration,
            self.episode_length,
        );
        for cells in &table {
            let line: Vec<String> = cells
                .iter()
                .zip(&widths)
                .map(|(cell, &width)| format!("{cell:<width$}"))
                .collect();
            out.push_str(line.join("  ").trim_end());
            out.push('\n');
        }
        out
    }
}
