//! Evaluation on separate delayed copies with deterministic actions (docs/DESIGN.md §4.1): an episode's
//! return is the sum of the true rewards of all its steps, the warm-up steps before the first
//! observation arrives included, up to termination or the time limit.
use crate::algos::{ActMode, Agent};
use crate::delay::{DelayConfig, DelayDevice, DelayedBatch};
use crate::sim::BatchConfig;
use crate::tasks::TaskName;

use super::TrainError;

/// Which of an agent's policies is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EvalPolicy {
    /// The policy that acts on `x_t` in the delayed task (of run `run`, in a stack).
    Regular { run: usize },
    /// A delay-free policy on the true state (D2HPG's abstract policy); run it with Δ = 0.
    DelayFree,
}

/// Mean and spread of evaluation episodes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalResult {
    pub return_mean: f64,
    /// Population standard deviation over the episodes.
    pub return_std: f64,
    pub length_mean: f64,
    pub episodes: usize,
}

/// Plays one episode on each of `episodes` fresh copies (seeded by `seed`) under `delay`,
/// the delay layer on `device`.
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    agent: &mut dyn Agent,
    policy: EvalPolicy,
    task: TaskName,
    delay: &DelayConfig,
    device: DelayDevice,
    episodes: usize,
    threads: usize,
    seed: u64,
) -> Result<EvalResult, TrainError> {
    let mut batch = DelayedBatch::new(
        &BatchConfig {
            task,
            envs: episodes,
            threads,
            seed,
            actuator_noise: delay.actuator_noise,
        },
        delay,
        device,
        seed,
    )?;
    let act_dim = batch.env().act_dim();
    let mut finished = vec![false; episodes];
    let mut returns = vec![0.0f64; episodes];
    let mut lengths = vec![0u32; episodes];
    while finished.iter().any(|f| !f) {
        let mut actions = vec![0.0f32; episodes * act_dim];
        batch.choose_actions(
            &mut actions,
            |i| !finished[i],
            |inputs, rows| match policy {
                EvalPolicy::Regular { run } => {
                    Ok(agent.act_run(run, inputs, rows, ActMode::Deterministic))
                }
                EvalPolicy::DelayFree => agent.act_delay_free(inputs, rows).ok_or_else(|| {
                    TrainError::Config(super::ConfigError::no_delay_free_policy(
                        "the evaluated agent",
                    ))
                }),
            },
        )?;
        batch.step(&actions)?;
        let env = batch.env();
        for i in 0..episodes {
            if !finished[i] {
                returns[i] += f64::from(env.rewards()[i]);
                lengths[i] += 1;
                finished[i] = env.terminated()[i] == 1 || env.truncated()[i] == 1;
            }
        }
    }
    let n = episodes as f64;
    let return_mean = returns.iter().sum::<f64>() / n;
    let return_std = (returns
        .iter()
        .map(|r| (r - return_mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let length_mean = lengths.iter().map(|&l| f64::from(l)).sum::<f64>() / n;
    Ok(EvalResult {
        return_mean,
        return_std,
        length_mean,
        episodes,
    })
}
