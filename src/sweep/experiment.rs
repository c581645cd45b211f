//! An experiment as data: the grid a study runs (tasks × algorithms × delays × delay kinds ×
//! actuator noise × seeds), with settings shared by every run and settings per algorithm, read
//! from TOML or taken from a built-in preset of the paper's protocol, and expanded into one
//! resolved [`TrainConfig`] per run with an id derived from that configuration.
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::SweepError;
use crate::algos::{AlgoSettings, algorithm};
use crate::delay::DelayConfig;
use crate::tasks::TaskName;
use crate::train::TrainConfig;

/// How the delay of a run is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DelayKind {
    /// Every observation is exactly Δ steps late.
    Fixed,
    /// Observation delays uniform in 1..=Δ, out of order; the conservative agent acts on
    /// observations exactly Δ old.
    Random,
}

/// An experiment file (`dhrl sweep plan FILE`); the presets are files of the same form.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// What the experiment reproduces, printed by `plan`.
    #[serde(default)]
    pub description: String,
    pub tasks: Vec<TaskName>,
    /// Algorithm names, as `dhrl train --algo` takes them.
    pub algorithms: Vec<String>,
    /// Total delays Δ. An algorithm that runs only undelayed (the delay-free SAC reference)
    /// runs once at Δ = 0 whatever this lists; one that needs a delay skips Δ = 0.
    pub delays: Vec<usize>,
    pub seeds: Vec<u64>,
    /// Environment steps of every run.
    pub steps: u64,
    /// σ of the actuator noise, one run per value.
    #[serde(default = "noise_free")]
    pub actuator_noise: Vec<f64>,
    #[serde(default = "fixed_only")]
    pub delay_kinds: Vec<DelayKind>,
    /// Fields of `config.toml` shared by every run (e.g. `eval_every`, `[train.delay] warmup`).
    #[serde(default)]
    pub train: toml::Table,
    /// Fields of one algorithm's configuration, for its runs (`[algo.d2hpg] lifting_weight = 10`).
    #[serde(default)]
    pub algo: BTreeMap<String, toml::Table>,
}

fn noise_free() -> Vec<f64> {
    vec![0.0]
}

fn fixed_only() -> Vec<DelayKind> {
    vec![DelayKind::Fixed]
}

/// One run of an experiment, resolved.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedRun {
    pub id: String,
    pub config: TrainConfig,
}

/// Built-in experiments: the paper's protocol (1M steps, five seeds), as TOML.
pub const PRESETS: &[(&str, &str)] = &[
    ("table1", include_str!("presets/table1.toml")),
    ("noise", include_str!("presets/noise.toml")),
    ("random-delay", include_str!("presets/random-delay.toml")),
    ("ablation", include_str!("presets/ablation.toml")),
    ("runtime", include_str!("presets/runtime.toml")),
];

impl Experiment {
    pub fn from_toml(text: &str, source: &str) -> Result<Experiment, SweepError> {
        toml::from_str(text).map_err(|e| SweepError::Experiment {
            source_name: source.to_string(),
            message: e.to_string(),
        })
    }

    /// The built-in experiment `name`.
    pub fn preset(name: &str) -> Result<Experiment, SweepError> {
        let (_, text) = PRESETS
            .iter()
            .find(|(preset, _)| *preset == name)
            .ok_or_else(|| SweepError::UnknownPreset {
                name: name.to_string(),
                valid: PRESETS
                    .iter()
                    .map(|(p, _)| *p)
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
        Experiment::from_toml(text, &format!("preset {name}"))
    }

    /// Every run, in a fixed order (task, algorithm, delay kind, delay, noise, seed). Runs that
    /// resolve to the same configuration (the undelayed reference under several delays) appear
    /// once.
    pub fn expand(&self) -> Result<Vec<PlannedRun>, SweepError> {
        self.check_lists()?;
        let base = base_config(&self.train)?;
        let mut runs: Vec<PlannedRun> = Vec::new();
        for &task in &self.tasks {
            for name in &self.algorithms {
                let info = algorithm(name)?.info();
                let given = self.algo.get(name).cloned().unwrap_or_default();
                let algo = AlgoSettings::under(base.protocol, name, &given)?;
                let grid: Vec<(DelayKind, usize)> = if info.undelayed_only {
                    vec![(DelayKind::Fixed, 0)]
                } else {
                    self.delay_kinds
                        .iter()
                        .flat_map(|&kind| self.delays.iter().map(move |&d| (kind, d)))
                        .filter(|&(kind, d)| {
                            d > 0 || (kind == DelayKind::Fixed && !info.delayed_only)
                        })
                        .collect()
                };
                for (kind, delay) in grid {
                    for &sigma in &self.actuator_noise {
                        for &seed in &self.seeds {
                            let config = TrainConfig {
                                task,
                                algo: algo.clone(),
                                delay: DelayConfig {
                                    observation_delay: if kind == DelayKind::Fixed {
                                        delay
                                    } else {
                                        0
                                    },
                                    random_delay: kind == DelayKind::Random,
                                    max_random_delay: (kind == DelayKind::Random).then_some(delay),
                                    actuator_noise: sigma,
                                    ..base.delay.clone()
                                },
                                steps: self.steps,
                                seed,
                                ..base.clone()
                            };
                            config.validate()?;
                            let run = PlannedRun {
                                id: run_id(&config),
                                config,
                            };
                            if !runs.iter().any(|r| r.id == run.id) {
                                runs.push(run);
                            }
                        }
                    }
                }
            }
        }
        if runs.is_empty() {
            return Err(SweepError::Invalid(
                "the experiment expands into no runs (are its delays all 0 with algorithms that \
                 need a delay?)"
                    .into(),
            ));
        }
        Ok(runs)
    }

    /// Keeps only the given tasks, algorithms, delays and seeds (an empty list keeps all).
    pub fn restrict(
        &mut self,
        tasks: &[TaskName],
        algorithms: &[String],
        delays: &[usize],
        seeds: &[u64],
    ) {
        if !tasks.is_empty() {
            self.tasks = tasks.to_vec();
        }
        if !algorithms.is_empty() {
            self.algorithms = algorithms.to_vec();
            self.algo.retain(|name, _| algorithms.contains(name));
        }
        if !delays.is_empty() {
            self.delays = delays.to_vec();
        }
        if !seeds.is_empty() {
            self.seeds = seeds.to_vec();
        }
    }

    /// Multiplies the steps of every run, and the checkpoint interval with them, by `factor`
    /// (a quick look at a preset: `0.05` runs 50k of its 1M steps).
    pub fn scale(&mut self, factor: f64) -> Result<(), SweepError> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(SweepError::Invalid(format!(
                "--scale must be a positive number, got {factor}"
            )));
        }
        let scaled = |n: u64| ((n as f64 * factor).round() as u64).max(1);
        self.steps = scaled(self.steps);
        if let Some(toml::Value::Integer(every)) = self.train.get_mut("checkpoint_every") {
            *every = scaled(u64::try_from(*every).unwrap_or(1)) as i64;
        }
        Ok(())
    }

    fn check_lists(&self) -> Result<(), SweepError> {
        let empty = [
            ("tasks", self.tasks.is_empty()),
            ("algorithms", self.algorithms.is_empty()),
            ("delays", self.delays.is_empty()),
            ("seeds", self.seeds.is_empty()),
            ("actuator_noise", self.actuator_noise.is_empty()),
            ("delay_kinds", self.delay_kinds.is_empty()),
        ];
        if let Some((list, _)) = empty.iter().find(|(_, e)| *e) {
            return Err(SweepError::Invalid(format!(
                "the experiment's `{list}` list is empty; it needs at least one value"
            )));
        }
        if self.steps == 0 {
            return Err(SweepError::Invalid(
                "the experiment's `steps` is 0; runs need at least one environment step".into(),
            ));
        }
        for name in &self.algorithms {
            algorithm(name)?;
        }
        if let Some(name) = self.algo.keys().find(|n| !self.algorithms.contains(n)) {
            return Err(SweepError::Invalid(format!(
                "[algo.{name}] sets fields of an algorithm the experiment does not run; its \
                 algorithms are {}",
                self.algorithms.join(", ")
            )));
        }
        Ok(())
    }
}

/// `config.toml`'s defaults with `train` laid over them (tables merged field by field).
fn base_config(train: &toml::Table) -> Result<TrainConfig, SweepError> {
    for field in ["task", "algo", "steps", "seed"] {
        if train.contains_key(field) {
            return Err(SweepError::Invalid(format!(
                "[train] sets `{field}`, which the experiment's own lists decide"
            )));
        }
    }
    if let Some(toml::Value::Table(delay)) = train.get("delay") {
        let decided = [
            "observation_delay",
            "action_delay",
            "random_delay",
            "max_random_delay",
            "actuator_noise",
        ];
        if let Some(field) = decided.iter().find(|f| delay.contains_key(**f)) {
            return Err(SweepError::Invalid(format!(
                "[train.delay] sets `{field}`, which the experiment's `delays`, `delay_kinds` and \
                 `actuator_noise` decide; [train.delay] takes only `warmup`"
            )));
        }
    }
    TrainConfig::over_protocol_defaults(train.clone(), None)
        .map_err(|e| SweepError::Invalid(format!("[train]: {e}")))
}

/// `<task>-<algo>-d<Δ>[-n<σ>]-s<seed>-<hash>` (`r<Δ>` for random delays): readable, and
/// unique to the whole configuration through a hash of it, so that re-planning an
/// experiment finds the same ids and a changed setting gives a new one.
pub fn run_id(config: &TrainConfig) -> String {
    let delay = &config.delay;
    let (kind, value) = match delay.random_bound() {
        Some(bound) => ("r", bound),
        None => ("d", delay.observation_delay + delay.action_delay),
    };
    let noise = if delay.actuator_noise > 0.0 {
        format!("-n{}", delay.actuator_noise)
    } else {
        String::new()
    };
    let canonical = serde_json::to_string(config).expect("a configuration serialises");
    format!(
        "{}-{}-{kind}{value}{noise}-s{}-{:08x}",
        config.task,
        config.algo.name(),
        config.seed,
        fnv1a(canonical.as_bytes()) as u32
    )
}

/// FNV-1a, 64 bits: a hash that stays the same across builds and platforms.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |hash, &b| {
        (hash ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}
