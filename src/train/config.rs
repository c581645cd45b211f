//! The full configuration of a training run: what `DIR/config.toml` holds, what `--config`
//! reads, and what the flags override.
use serde::{Deserialize, Serialize};

use crate::algos::{Algo, Hyper, Lifting};
use crate::delay::{DEFAULT_CAPACITY, DelayConfig, DelayError};
use crate::learn::LearnDevice;
use crate::tasks::TaskName;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    pub task: TaskName,
    pub algo: Algo,
    pub delay: DelayConfig,
    /// Environment steps in total (all copies together).
    pub steps: u64,
    pub seed: u64,
    /// Copies collecting in parallel; 1 is the paper's protocol.
    pub envs: usize,
    /// Simulation threads.
    pub threads: usize,
    /// Environment steps with uniform random actions before learning starts.
    pub warmup_steps: u64,
    /// Gradient updates per environment step.
    pub updates_per_step: f64,
    pub batch_size: usize,
    pub replay_capacity: usize,
    pub eval_every: u64,
    pub eval_episodes: usize,
    /// Environment steps between checkpoints.
    pub checkpoint_every: u64,
    /// Gradient updates between rows of `train.csv`.
    pub log_every: u64,
    pub device: LearnDevice,
    pub hyper: Hyper,
    /// D2HPG's lifting loss (ignored by the other algorithms).
    pub lifting: Lifting,
}

impl Default for TrainConfig {
    /// A short, sensible default: delay-free SAC on InvertedPendulum, learning within minutes.
    fn default() -> TrainConfig {
        TrainConfig {
            task: TaskName::InvertedPendulum,
            algo: Algo::Sac,
            delay: DelayConfig::default(),
            steps: 20_000,
            seed: 0,
            envs: 1,
            threads: 1,
            warmup_steps: 1_000,
            updates_per_step: 1.0,
            batch_size: 256,
            replay_capacity: DEFAULT_CAPACITY,
            eval_every: 5_000,
            eval_episodes: 10,
            checkpoint_every: 5_000,
            log_every: 1_000,
            device: LearnDevice::Cpu,
            hyper: Hyper::default(),
            lifting: Lifting::default(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error(transparent)]
    Delay(#[from] DelayError),
    #[error("{what} must be {accepted}, got {value}")]
    Invalid {
        what: &'static str,
        accepted: &'static str,
        value: String,
    },
    #[error(
        "sac is the delay-free reference and runs with Δ = 0; use augmented-sac, naive-sac (or a D2HPG variant) under a delay"
    )]
    SacWithDelay,
    #[error("cannot read config file {path}: {message}")]
    Read { path: String, message: String },
}

fn check(
    ok: bool,
    what: &'static str,
    accepted: &'static str,
    value: impl ToString,
) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::Invalid {
            what,
            accepted,
            value: value.to_string(),
        })
    }
}

impl TrainConfig {
    /// Reads a TOML config (any subset of the fields; the rest default).
    pub fn from_toml_file(path: &std::path::Path) -> Result<TrainConfig, ConfigError> {
        let read_error = |message: String| ConfigError::Read {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| read_error(e.to_string()))?;
        toml::from_str(&text).map_err(|e| read_error(e.to_string()))
    }

    /// Checks every field and returns the total delay Δ.
    pub fn validate(&self) -> Result<usize, ConfigError> {
        let delay = self.delay.total_delay()?;
        if self.algo == Algo::Sac && delay > 0 {
            return Err(ConfigError::SacWithDelay);
        }
        check(self.steps > 0, "steps", "at least 1", self.steps)?;
        check(self.envs > 0, "envs", "at least 1", self.envs)?;
        check(self.threads > 0, "threads", "at least 1", self.threads)?;
        check(
            self.batch_size > 0,
            "batch_size",
            "at least 1",
            self.batch_size,
        )?;
        check(
            self.updates_per_step > 0.0 && self.updates_per_step.is_finite(),
            "updates_per_step",
            "a positive number",
            self.updates_per_step,
        )?;
        check(
            self.eval_every > 0,
            "eval_every",
            "at least 1",
            self.eval_every,
        )?;
        check(
            self.eval_episodes > 0,
            "eval_episodes",
            "at least 1",
            self.eval_episodes,
        )?;
        check(
            self.checkpoint_every > 0,
            "checkpoint_every",
            "at least 1",
            self.checkpoint_every,
        )?;
        check(
            self.log_every > 0,
            "log_every",
            "at least 1",
            self.log_every,
        )?;
        let h = &self.hyper;
        check((0.0..1.0).contains(&h.gamma), "gamma", "in [0, 1)", h.gamma)?;
        check(h.tau > 0.0 && h.tau <= 1.0, "tau", "in (0, 1]", h.tau)?;
        check(
            h.learning_rate > 0.0 && h.learning_rate.is_finite(),
            "learning_rate",
            "a positive number",
            h.learning_rate,
        )?;
        check(
            h.adam_epsilon > 0.0,
            "adam_epsilon",
            "a positive number",
            h.adam_epsilon,
        )?;
        check(
            h.initial_alpha > 0.0 && h.initial_alpha.is_finite(),
            "initial_alpha",
            "a positive number",
            h.initial_alpha,
        )?;
        let l = &self.lifting;
        check(
            l.weight >= 0.0 && l.weight.is_finite(),
            "lifting weight",
            "a finite number ≥ 0",
            l.weight,
        )?;
        check(
            l.samples >= 2,
            "lifting samples",
            "at least 2 (standard deviations need two samples)",
            l.samples,
        )?;
        Ok(delay)
    }
}
