//! `dhrl train`'s arguments, and how they resolve into a run: defaults, then `--config`, then
//! flags (`--set FIELD=VALUE` for any field of the algorithm); `--resume` takes the run's own
//! `config.toml` and only `--steps` (to extend it); any other setting beside it is refused,
//! by name.
use std::path::PathBuf;

use clap::Args;

use super::{ConfigError, Start, TrainConfig, TrainError};
use crate::algos::{AlgoError, AlgoSettings, names, parse_assignment, proposed};
use crate::delay::{DelayArgs, DelayDevice};
use crate::learn::LearnDevice;
use crate::protocol::Protocol;
use crate::tasks::TaskName;

fn algo_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(names())
}

#[derive(Args, Debug, Clone, Default)]
pub struct TrainArgs {
    /// Whose settings fill in what the paper leaves open: dhrl's own, or the authors' released
    /// code's (λ = 10 held then decayed over the run's steps, K = 100, one shared α, 10,000
    /// random steps, orthogonal initialisation; docs/DESIGN.md §3.4). Every setting it fills
    /// in can still be overridden.
    #[arg(long, value_enum)]
    pub protocol: Option<Protocol>,
    /// The MuJoCo task (Gymnasium v4).
    #[arg(long, value_enum)]
    pub task: Option<TaskName>,
    /// The algorithm (`--help-config` lists its fields). Default: d2hpg, the paper's method,
    /// at --delay 5 unless a delay option is given (the main job; with --config, the file's).
    #[arg(long, value_parser = algo_names())]
    pub algo: Option<String>,
    /// Set a field of the algorithm's configuration (repeatable), e.g. --set lifting_weight=10.
    #[arg(long = "set", value_name = "FIELD=VALUE")]
    pub set: Vec<String>,
    /// Print the fields of the algorithm's configuration, with their defaults, and exit.
    #[arg(long)]
    pub help_config: bool,
    #[command(flatten)]
    pub delay: DelayArgs,
    /// Environment steps in total.
    #[arg(long)]
    pub steps: Option<u64>,
    /// The run's seed: networks, exploration, environment copies and evaluations derive
    /// their random streams from it.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Train several seeds as one stack, one learner pass serving them all: a list (0,1,2) or
    /// a range (0..8, end excluded). Each seed gets an ordinary run folder, OUT/seed-<seed>
    /// (OUT/stack.toml lists them); `--resume OUT` continues the stack.
    #[arg(long, value_name = "SEEDS", conflicts_with = "seed", value_parser = parse_seeds)]
    pub seeds: Option<Seeds>,
    /// Copies collecting in parallel (1: the paper's protocol, one update per step).
    #[arg(long)]
    pub envs: Option<usize>,
    /// Simulation threads.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Uniform random steps before the policy acts.
    #[arg(long)]
    pub warmup_steps: Option<u64>,
    /// The environment step from which updates run (default: when the warm-up ends).
    #[arg(long, value_name = "STEP")]
    pub learning_starts: Option<u64>,
    /// Run updates in blocks, one every N environment steps (N × updates per step each).
    #[arg(long, value_name = "N")]
    pub update_every: Option<u64>,
    /// Environment steps between evaluations of the deterministic policy (one at the end too).
    #[arg(long)]
    pub eval_every: Option<u64>,
    /// Episodes per evaluation, each on a fresh copy under the run's delay.
    #[arg(long)]
    pub eval_episodes: Option<usize>,
    /// Environment steps between checkpoints (a run resumes from its last one).
    #[arg(long)]
    pub checkpoint_every: Option<u64>,
    /// Write no TensorBoard event files (the CSVs only).
    #[arg(long)]
    pub no_tensorboard: bool,
    /// Transitions per gradient update, drawn uniformly from the replay.
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// Initial entropy temperature α (--set initial_alpha=…).
    #[arg(long)]
    pub alpha: Option<f64>,
    /// Keep α fixed instead of learning it (--set autotune_alpha=false).
    #[arg(long)]
    pub fixed_alpha: bool,
    /// D2HPG's lifting weight λ (--set lifting_weight=…).
    #[arg(long)]
    pub lifting_weight: Option<f64>,
    /// D2HPG's lifting samples K per state, ≥ 2 (--set lifting_samples=…).
    #[arg(long)]
    pub lifting_samples: Option<usize>,
    /// Where the learners run.
    #[arg(long, value_enum)]
    pub device: Option<LearnDevice>,
    /// With --seeds: runs per learner pass (0: on the CPU 2, VDPO 1; all on a GPU); the same
    /// numbers whatever it is.
    #[arg(long, value_name = "N")]
    pub runs_per_pass: Option<usize>,
    /// Where the delay layer runs: cpu (the reference), or gpu (the WGSL kernels on any
    /// Vulkan adapter, read back every step; the same results).
    #[arg(long, value_enum)]
    pub delay_device: Option<DelayDevice>,
    /// TOML file with any fields of config.toml; flags override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Run folder (must not exist; default runs/<task>-<algo>-d<delay>-s<seed>-<time>).
    #[arg(long, value_name = "DIR", conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Continue the run in DIR from its last checkpoint (with --steps to extend it).
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
}

/// `--seeds`' list, in order, each seed once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Seeds(pub Vec<u64>);

/// `0,1,2` or `0..8` (end excluded).
fn parse_seeds(text: &str) -> Result<Seeds, String> {
    let bad = || {
        format!("`{text}`: --seeds takes a list of seeds (0,1,2) or a range (0..8, end excluded)")
    };
    let seeds: Vec<u64> = match text.split_once("..") {
        Some((start, end)) => {
            let (start, end): (u64, u64) = (
                start.trim().parse().map_err(|_| bad())?,
                end.trim().parse().map_err(|_| bad())?,
            );
            (start..end).collect()
        }
        None => text
            .split(',')
            .map(|seed| seed.trim().parse().map_err(|_| bad()))
            .collect::<Result<_, _>>()?,
    };
    if seeds.is_empty() {
        return Err(format!("`{text}`: --seeds names no seed"));
    }
    let mut seen = std::collections::BTreeSet::new();
    if let Some(twice) = seeds.iter().find(|seed| !seen.insert(**seed)) {
        return Err(format!("`{text}`: --seeds names seed {twice} twice"));
    }
    Ok(Seeds(seeds))
}

/// A run (or a stack of runs) to start or continue.
#[derive(Debug, Clone)]
pub struct TrainPlan {
    /// The run folder, or the stack's folder.
    pub run: PathBuf,
    /// A stack's seeds (`--seeds`, or the stack `--resume` names); `None` for one run.
    pub seeds: Option<Vec<u64>>,
    pub start: Start,
    /// For [`Start::Resume`], only `steps` is used (the run's own config.toml holds the rest).
    pub config: TrainConfig,
}

impl TrainArgs {
    /// The algorithm configuration the flags ask for, over `base` (the config file's): the
    /// flags' typed values and `--set`'s, read together once.
    fn algo(&self, base: AlgoSettings) -> Result<AlgoSettings, AlgoError> {
        use toml::Value;
        let mut values = toml::Table::new();
        let flags = [
            ("initial_alpha", self.alpha.map(Value::Float)),
            (
                "autotune_alpha",
                self.fixed_alpha.then_some(Value::Boolean(false)),
            ),
            ("lifting_weight", self.lifting_weight.map(Value::Float)),
            (
                "lifting_samples",
                self.lifting_samples.map(|k| Value::Integer(k as i64)),
            ),
        ];
        for (field, value) in flags {
            if let Some(value) = value {
                values.insert(field.to_string(), value);
            }
        }
        for assignment in &self.set {
            let (field, value) = parse_assignment(assignment)?;
            values.insert(field, value);
        }
        base.with(self.algo.as_deref(), &values)
    }

    /// The configuration of a new run: defaults, then `--config`, then flags.
    pub fn config(&self) -> Result<TrainConfig, TrainError> {
        let mut c = match &self.config {
            Some(path) => TrainConfig::from_toml_file(path, self.protocol)?,
            // Without --algo, the paper's method; without a delay either, the main job's.
            None => {
                let protocol = self.protocol.unwrap_or_default();
                match (&self.algo, self.delay.sets_a_delay()) {
                    (None, false) => TrainConfig::main_job(protocol)?,
                    (None, true) => TrainConfig::for_protocol(protocol, Some(proposed().name))?,
                    (Some(_), _) => TrainConfig::for_protocol(protocol, None)?,
                }
            }
        };
        c.task = self.task.unwrap_or(c.task);
        c.algo = self.algo(c.algo)?;
        c.delay = self.delay.apply(c.delay).map_err(ConfigError::from)?;
        c.steps = self.steps.unwrap_or(c.steps);
        c.seed = self.seed.unwrap_or(c.seed);
        c.envs = self.envs.unwrap_or(c.envs);
        c.threads = self.threads.unwrap_or(c.threads);
        c.warmup_steps = self.warmup_steps.unwrap_or(c.warmup_steps);
        c.learning_starts = self.learning_starts.or(c.learning_starts);
        c.update_every = self.update_every.unwrap_or(c.update_every);
        c.eval_every = self.eval_every.unwrap_or(c.eval_every);
        c.eval_episodes = self.eval_episodes.unwrap_or(c.eval_episodes);
        c.checkpoint_every = self.checkpoint_every.unwrap_or(c.checkpoint_every);
        c.batch_size = self.batch_size.unwrap_or(c.batch_size);
        c.tensorboard &= !self.no_tensorboard;
        c.device = self.device.unwrap_or(c.device);
        c.runs_per_pass = self.runs_per_pass.unwrap_or(c.runs_per_pass);
        c.delay_device = self.delay_device.unwrap_or(c.delay_device);
        Ok(c)
    }

    /// The flags given that set a run's configuration, `--steps` aside: what `--resume` refuses.
    pub fn settings_given(&self) -> Vec<&'static str> {
        let d = &self.delay;
        [
            ("--protocol", self.protocol.is_some()),
            ("--task", self.task.is_some()),
            ("--algo", self.algo.is_some()),
            ("--set", !self.set.is_empty()),
            ("--delay", d.delay.is_some()),
            ("--action-delay", d.action_delay.is_some()),
            ("--random-delay", d.random_delay),
            ("--max-delay", d.max_delay.is_some()),
            ("--actuator-noise", d.actuator_noise.is_some()),
            ("--warmup", d.warmup.is_some()),
            ("--seed", self.seed.is_some()),
            ("--seeds", self.seeds.is_some()),
            ("--envs", self.envs.is_some()),
            ("--threads", self.threads.is_some()),
            ("--warmup-steps", self.warmup_steps.is_some()),
            ("--learning-starts", self.learning_starts.is_some()),
            ("--update-every", self.update_every.is_some()),
            ("--eval-every", self.eval_every.is_some()),
            ("--eval-episodes", self.eval_episodes.is_some()),
            ("--checkpoint-every", self.checkpoint_every.is_some()),
            ("--batch-size", self.batch_size.is_some()),
            ("--no-tensorboard", self.no_tensorboard),
            ("--alpha", self.alpha.is_some()),
            ("--fixed-alpha", self.fixed_alpha),
            ("--lifting-weight", self.lifting_weight.is_some()),
            ("--lifting-samples", self.lifting_samples.is_some()),
            ("--device", self.device.is_some()),
            ("--runs-per-pass", self.runs_per_pass.is_some()),
            ("--delay-device", self.delay_device.is_some()),
            ("--config", self.config.is_some()),
        ]
        .into_iter()
        .filter_map(|(flag, given)| given.then_some(flag))
        .collect()
    }

    /// Where and how to train: a new run (checked, in `--out` or a fresh folder under
    /// `runs/`), or `--resume DIR` with at most `--steps` beside it.
    pub fn plan(&self) -> Result<TrainPlan, TrainError> {
        if let Some(dir) = &self.resume {
            let given = self.settings_given();
            if !given.is_empty() {
                return Err(ConfigError::Invalid {
                    what: "--resume",
                    accepted: "given alone or with --steps (the run continues with its own config.toml)",
                    value: format!("given with {} for {}", given.join(", "), dir.display()),
                }
                .into());
            }
            return Ok(TrainPlan {
                run: dir.clone(),
                seeds: super::stack_seeds(dir)?,
                start: Start::Resume,
                config: TrainConfig {
                    steps: self.steps.unwrap_or(0),
                    ..TrainConfig::default()
                },
            });
        }
        if self.runs_per_pass.is_some() && self.seeds.is_none() {
            return Err(ConfigError::Invalid {
                what: "--runs-per-pass",
                accepted: "given with --seeds (a stack); one run is one run per pass",
                value: "given without --seeds".into(),
            }
            .into());
        }
        let config = self.config()?;
        let delay = config.validate()?;
        let run = self.out.clone().unwrap_or_else(|| {
            let stamp = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs());
            let seeds = match &self.seeds {
                Some(Seeds(seeds)) => format!("seeds{}-{}", seeds[0], seeds[seeds.len() - 1]),
                None => format!("s{}", config.seed),
            };
            PathBuf::from(format!(
                "runs/{}-{}-d{delay}-{seeds}-{stamp}",
                config.task, config.algo
            ))
        });
        Ok(TrainPlan {
            run,
            seeds: self.seeds.clone().map(|Seeds(seeds)| seeds),
            start: Start::Fresh,
            config,
        })
    }
}
