//! The full configuration of a training run: what `DIR/config.toml` holds, what `--config`
//! reads, and what the flags override.
use serde::{Deserialize, Serialize};

use crate::algos::{AlgoError, AlgoSettings, algorithm, names_where, reference};
use crate::delay::{DEFAULT_CAPACITY, DelayConfig, DelayDevice, DelayError};
use crate::learn::LearnDevice;
use crate::tasks::TaskName;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The MuJoCo task.
    pub task: TaskName,
    /// The delays, their warm-up actions and the actuator noise (`[delay]`).
    pub delay: DelayConfig,
    /// Environment steps in total (all copies together).
    pub steps: u64,
    /// The run's seed, from which every random stream is derived.
    pub seed: u64,
    /// Copies collecting in parallel; 1 is the paper's protocol.
    pub envs: usize,
    /// Simulation threads.
    pub threads: usize,
    /// Environment steps with uniform random actions before learning starts.
    pub warmup_steps: u64,
    /// Gradient updates per environment step.
    pub updates_per_step: f64,
    /// Transitions per gradient update.
    pub batch_size: usize,
    /// Steps the replay keeps (the oldest are overwritten).
    pub replay_capacity: usize,
    /// Environment steps between evaluations.
    pub eval_every: u64,
    /// Episodes per evaluation.
    pub eval_episodes: usize,
    /// Environment steps between checkpoints.
    pub checkpoint_every: u64,
    /// Gradient updates between rows of `train.csv`.
    pub log_every: u64,
    /// Whether the logs are also written as TensorBoard event files (`RUN/tensorboard/`).
    pub tensorboard: bool,
    /// Where the learners run.
    pub device: LearnDevice,
    /// In a stack (`dhrl train --seeds`), the runs one learner pass serves; the stack's runs
    /// go through in passes of this many. 0: the device's default, on the CPU the algorithm's
    /// ([`crate::algos::AlgoInfo::cpu_runs_per_pass`], 2 but for VDPO's 1: more runs per pass
    /// outgrow the caches, docs/results/stacking.md) and all of them on a GPU. The numbers are
    /// the same whatever it is.
    pub runs_per_pass: usize,
    /// Where the delay layer runs (training and evaluation copies).
    pub delay_device: DelayDevice,
    /// The algorithm and its configuration (`[algo]`, with `name`).
    pub algo: AlgoSettings,
}

impl Default for TrainConfig {
    /// A short, sensible default: delay-free SAC on InvertedPendulum, learning within minutes.
    fn default() -> TrainConfig {
        TrainConfig {
            task: TaskName::InvertedPendulum,
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
            tensorboard: true,
            device: LearnDevice::Cpu,
            runs_per_pass: 0,
            delay_device: DelayDevice::Cpu,
            algo: AlgoSettings::default(),
        }
    }
}

impl TrainConfig {
    /// The runs one learner pass serves ([`TrainConfig::runs_per_pass`], 0 resolved).
    pub fn runs_per_learner_pass(&self) -> usize {
        match (self.runs_per_pass, self.device) {
            (0, LearnDevice::Cpu) => self.algo.info().cpu_runs_per_pass,
            (0, LearnDevice::Wgpu) => usize::MAX,
            (runs, _) => runs,
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
    #[error(transparent)]
    Algo(#[from] AlgoError),
    #[error(transparent)]
    NegativeDelay(#[from] crate::delay::NegativeDelay),
    #[error("cannot read config file {path}: {message}")]
    Read { path: String, message: String },
    #[error(
        "--delay-free-policy needs an algorithm that learns a delay-free policy ({learners}); {algo} learns none"
    )]
    NoDelayFreePolicy { algo: String, learners: String },
}

impl ConfigError {
    /// `--delay-free-policy` asked of a run of `algo`, which learns none.
    pub fn no_delay_free_policy(algo: &str) -> ConfigError {
        ConfigError::NoDelayFreePolicy {
            algo: algo.to_string(),
            learners: names_where(|info| info.delay_free_policy).join(", "),
        }
    }
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
    /// Reads a TOML config (any subset of the fields; the rest default). Files written before
    /// the `[algo]` table (`algo = "NAME"` with `[hyper]` and `[lifting]`) are read too.
    pub fn from_toml_file(path: &std::path::Path) -> Result<TrainConfig, ConfigError> {
        let read_error = |message: String| ConfigError::Read {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| read_error(e.to_string()))?;
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| read_error(e.to_string()))?;
        fold_legacy_algo_tables(&mut table)?;
        toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| read_error(e.to_string()))
    }

    /// Checks every field and returns the total delay Δ (the algorithm's fields are checked
    /// when they are set).
    pub fn validate(&self) -> Result<usize, ConfigError> {
        let delay = self.delay.total_delay()?;
        if self.algo.info().undelayed_only && delay > 0 {
            return Err(AlgoError::UndelayedOnly {
                algo: self.algo.name(),
                delayed: names_where(|info| !info.undelayed_only).join(", "),
            }
            .into());
        }
        if self.algo.info().delayed_only && delay == 0 {
            return Err(AlgoError::DelayedOnly {
                algo: self.algo.name(),
                undelayed: names_where(|info| !info.delayed_only).join(", "),
            }
            .into());
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
        Ok(delay)
    }
}

/// Moves the `[hyper]` and `[lifting]` tables of an older `config.toml` (beside `algo = "NAME"`,
/// or no algo for sac) into `[algo]`, keeping the fields the algorithm has (older files wrote
/// `[lifting]` for every algorithm).
fn fold_legacy_algo_tables(table: &mut toml::Table) -> Result<(), ConfigError> {
    if !table.contains_key("hyper") && !table.contains_key("lifting") {
        return Ok(());
    }
    let name = match table.get("algo") {
        // Files of that age wrote no algorithm for the delay-free reference.
        None => reference().name.to_string(),
        Some(toml::Value::String(name)) => name.clone(),
        Some(_) => {
            return Err(ConfigError::Invalid {
                what: "[hyper] and [lifting]",
                accepted: "absent beside an [algo] table (their fields belong in [algo])",
                value: "given with [algo]".into(),
            });
        }
    };
    let mut fields = toml::Table::new();
    if let Some(toml::Value::Table(hyper)) = table.remove("hyper") {
        fields.extend(hyper);
    }
    if let Some(toml::Value::Table(lifting)) = table.remove("lifting") {
        for (old, new) in [("weight", "lifting_weight"), ("samples", "lifting_samples")] {
            if let Some(value) = lifting.get(old) {
                fields.insert(new.into(), value.clone());
            }
        }
    }
    let known: Vec<&str> = algorithm(&name)?
        .field_docs()
        .iter()
        .map(|d| d.name)
        .collect();
    fields.retain(|k, _| known.iter().any(|name| *name == k));
    fields.insert("name".into(), toml::Value::String(name));
    table.insert("algo".into(), toml::Value::Table(fields));
    Ok(())
}
