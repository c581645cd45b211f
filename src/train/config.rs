//! The full configuration of a training run: what `DIR/config.toml` holds, what `--config`
//! reads, and what the flags override.
use serde::{Deserialize, Serialize};

use crate::algos::{AlgoError, AlgoSettings, algorithm, names_where, proposed, reference};
use crate::delay::{DEFAULT_CAPACITY, DelayConfig, DelayDevice, DelayError};
use crate::learn::LearnDevice;
use crate::protocol::{Protocol, merge_tables};
use crate::tasks::TaskName;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Whose settings filled in what the paper leaves open ([`Protocol`]): the defaults of
    /// every field below and of `[algo]`'s.
    pub protocol: Protocol,
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
    /// Environment steps with uniform random actions.
    pub warmup_steps: u64,
    /// The environment step from which updates run (absent: when the warm-up ends; the
    /// authors' code updates from step 100, inside its random phase).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learning_starts: Option<u64>,
    /// Steps the replay must hold before the first update (0: any complete transition; the
    /// authors' code waits for a batch, 256).
    pub min_replay_steps: usize,
    /// Updates come in blocks, one every this many environment steps, each of
    /// `update_every × updates_per_step` updates (1: every step; the authors' code runs 50
    /// updates every 50 steps).
    pub update_every: u64,
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

/// The observation delay of [`TrainConfig::main_job`].
pub const MAIN_JOB_DELAY: usize = 5;

impl Default for TrainConfig {
    /// The library's defaults: delay-free SAC on InvertedPendulum, learning within minutes
    /// (what a config file leaves out; `dhrl train` alone runs [`TrainConfig::main_job`]).
    fn default() -> TrainConfig {
        TrainConfig {
            protocol: Protocol::Dhrl,
            task: TaskName::InvertedPendulum,
            delay: DelayConfig::default(),
            steps: 20_000,
            seed: 0,
            envs: 1,
            threads: 1,
            warmup_steps: 1_000,
            learning_starts: None,
            min_replay_steps: 0,
            update_every: 1,
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
    /// The defaults of `protocol`, with `algo`'s (the delay-free reference when `None`).
    pub fn for_protocol(
        protocol: Protocol,
        algo: Option<&str>,
    ) -> Result<TrainConfig, ConfigError> {
        let algo = AlgoSettings::under(
            protocol,
            algo.unwrap_or(reference().name),
            &toml::Table::new(),
        )?;
        let dhrl = TrainConfig {
            protocol,
            algo,
            ..TrainConfig::default()
        };
        Ok(match protocol {
            Protocol::Dhrl => dhrl,
            Protocol::Authors => TrainConfig {
                warmup_steps: 10_000,
                learning_starts: Some(100),
                min_replay_steps: 256,
                update_every: 50,
                ..dhrl
            },
        })
    }

    /// The main job, what `dhrl train` runs without `--algo`, `--config` or a delay: the
    /// paper's method (D2HPG) on InvertedPendulum at an observation delay of
    /// [`MAIN_JOB_DELAY`] steps, which it learns on two cores within its 20,000 steps.
    pub fn main_job(protocol: Protocol) -> Result<TrainConfig, ConfigError> {
        let mut config = TrainConfig::for_protocol(protocol, Some(proposed().name))?;
        config.delay.observation_delay = MAIN_JOB_DELAY;
        Ok(config)
    }

    /// The environment step from which updates run.
    pub fn first_update_step(&self) -> u64 {
        self.learning_starts.unwrap_or(self.warmup_steps)
    }

    /// This configuration with what its algorithm schedules over the run's budget fixed to
    /// [`TrainConfig::steps`] ([`crate::algos::AlgoConfig::for_budget`]): what a fresh run
    /// records.
    pub fn with_budget_fixed(&self) -> TrainConfig {
        TrainConfig {
            algo: self.algo.for_budget(self.steps),
            ..self.clone()
        }
    }

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
    /// A config table's fields do not read (what [`ConfigError::Read`] names the file of).
    #[error("{0}")]
    Fields(String),
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
    /// Reads a TOML config (any subset of the fields; the rest take the defaults of the
    /// file's `protocol`, else of `protocol`, else dhrl's). Files written before the `[algo]`
    /// table (`algo = "NAME"` with `[hyper]` and `[lifting]`) are read too.
    pub fn from_toml_file(
        path: &std::path::Path,
        protocol: Option<Protocol>,
    ) -> Result<TrainConfig, ConfigError> {
        let read_error = |message: String| ConfigError::Read {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| read_error(e.to_string()))?;
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| read_error(e.to_string()))?;
        fold_legacy_algo_tables(&mut table)?;
        TrainConfig::over_protocol_defaults(table, protocol).map_err(|e| match e {
            ConfigError::Fields(message) => read_error(message),
            other => other,
        })
    }

    /// A config table (any subset of the fields) over the defaults of its `protocol`, else of
    /// `protocol`, else dhrl's; a table that names another protocol than `protocol` is refused.
    pub fn over_protocol_defaults(
        mut table: toml::Table,
        protocol: Option<Protocol>,
    ) -> Result<TrainConfig, ConfigError> {
        let read_error = ConfigError::Fields;
        let named: Option<Protocol> = match table.get("protocol") {
            Some(value) => Some(
                value
                    .clone()
                    .try_into()
                    .map_err(|e: toml::de::Error| read_error(format!("protocol: {e}")))?,
            ),
            None => None,
        };
        if let (Some(named), Some(asked)) = (named, protocol)
            && named != asked
        {
            return Err(ConfigError::Invalid {
                what: "--protocol",
                accepted: "the protocol the config file names, or none",
                value: format!("{asked}, where the file says protocol = \"{named}\""),
            });
        }
        let protocol = named.or(protocol).unwrap_or_default();
        let algo = match table.get("algo") {
            Some(toml::Value::String(name)) => Some(name.clone()),
            Some(toml::Value::Table(algo)) => algo
                .get("name")
                .and_then(toml::Value::as_str)
                .map(str::to_string),
            _ => None,
        };
        let defaults = TrainConfig::for_protocol(protocol, algo.as_deref())?;
        let mut merged = toml::Table::try_from(&defaults)
            .map_err(|e| read_error(format!("the defaults do not serialise: {e}")))?;
        if let Some(toml::Value::String(name)) = table.get("algo") {
            let name = toml::Value::String(name.clone());
            table.insert(
                "algo".into(),
                toml::Value::Table(toml::Table::from_iter([("name".into(), name)])),
            );
        }
        merge_tables(&mut merged, table);
        let config: TrainConfig = toml::Value::Table(merged)
            .try_into()
            .map_err(|e: toml::de::Error| read_error(e.to_string()))?;
        Ok(TrainConfig {
            algo: config.algo.clone().tagged(config.protocol),
            ..config
        })
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
        check(
            self.protocol != Protocol::Authors || self.envs == 1,
            "envs",
            "1 under the authors' protocol (their code steps one environment copy)",
            self.envs,
        )?;
        check(
            self.update_every > 0,
            "update_every",
            "at least 1",
            self.update_every,
        )?;
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
