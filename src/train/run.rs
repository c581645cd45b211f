//! The training loop.
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::checkpoint::{self, read_json, write_binary, write_json};
use super::eval::{EvalPolicy, EvalResult, evaluate};
use super::logs::{CsvLog, truncate_after};
use super::{ConfigError, TrainConfig, TrainError, io_error};
use crate::algos::{ActMode, Agent, AgentSpec, build_agent};
use crate::delay::{CpuDelayLayer, DelayConfig, DelayLayout, ReplayStore, StepInput};
use crate::learn::Devices;
use crate::sim::{BatchConfig, BatchSnapshot, BatchedEnv};

/// Whether `train` starts a new run or continues one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    Fresh,
    Resume,
}

/// What a finished run reports.
#[derive(Debug, Clone, Serialize)]
pub struct TrainSummary {
    pub env_steps: u64,
    pub updates: u64,
    pub wall_seconds: f64,
    pub last_eval: Option<EvalResult>,
}

/// Counters and random streams of the loop itself, saved with every checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct LoopState {
    env_steps: u64,
    updates: u64,
    /// Fractional updates owed (`updates_per_step` need not be an integer).
    update_debt: f64,
    evals_done: u64,
    checkpoints_done: u64,
    wall_seconds: f64,
    /// Draws replay batches.
    sample_rng: ChaCha8Rng,
    /// Draws the uniform random actions of the warm-up phase.
    warmup_rng: ChaCha8Rng,
    last_eval: Option<EvalResult>,
    /// Sums of the agent's statistics since the last `train.csv` row, and their count.
    stat_sums: Vec<f64>,
    stat_count: u64,
    /// Environment steps and wall seconds at the last `train.csv` row.
    logged_steps: u64,
    logged_updates: u64,
    logged_wall: f64,
}

const EVAL_HEADER: [&str; 6] = [
    "step",
    "wall_seconds",
    "return_mean",
    "return_std",
    "length_mean",
    "episodes",
];
const TRAIN_HEADER: [&str; 5] = [
    "step",
    "updates",
    "wall_seconds",
    "env_steps_per_sec",
    "updates_per_sec",
];

struct Trainer {
    config: TrainConfig,
    run: PathBuf,
    env: BatchedEnv,
    layer: CpuDelayLayer,
    replay: ReplayStore,
    agent: Box<dyn Agent>,
    state: LoopState,
    /// Opened when the loop starts, after a resume has cut the files back.
    evals: Option<CsvLog>,
    train_log: Option<CsvLog>,
    stat_names: Vec<&'static str>,
}

/// The agent's sizes for a task under a delay.
fn agent_spec(env: &BatchedEnv, delay: usize) -> AgentSpec {
    let (low, high) = env.action_bounds();
    AgentSpec {
        obs_dim: env.obs_dim(),
        act_dim: env.act_dim(),
        delay,
        action_low: low.to_vec(),
        action_high: high.to_vec(),
    }
}

/// Trains as configured, writing into `run`; with [`Start::Resume`], continues the run saved
/// there (its own `config.toml` wins over `config`, except `steps`).
pub fn train(
    config: &TrainConfig,
    run: &Path,
    start: Start,
    progress: bool,
) -> Result<TrainSummary, TrainError> {
    let config = match start {
        Start::Fresh => {
            if run.exists() {
                return Err(TrainError::OutputExists(run.display().to_string()));
            }
            config.validate()?;
            std::fs::create_dir_all(run).map_err(io_error(run))?;
            let text = toml::to_string(config).map_err(|e| TrainError::Io {
                path: "config.toml".into(),
                message: e.to_string(),
            })?;
            let path = run.join("config.toml");
            std::fs::write(&path, text).map_err(io_error(&path))?;
            config.clone()
        }
        Start::Resume => {
            let saved = TrainConfig::from_toml_file(&run.join("config.toml"))?;
            let merged = TrainConfig {
                steps: config.steps.max(saved.steps),
                ..saved
            };
            if merged.steps != saved.steps {
                let path = run.join("config.toml");
                let text = toml::to_string(&merged).map_err(|e| TrainError::Io {
                    path: "config.toml".into(),
                    message: e.to_string(),
                })?;
                std::fs::write(&path, text).map_err(io_error(&path))?;
            }
            merged
        }
    };
    let mut trainer = Trainer::new(config, run)?;
    if start == Start::Resume {
        trainer.resume()?;
    }
    trainer.run(progress)
}

impl Trainer {
    fn new(config: TrainConfig, run: &Path) -> Result<Trainer, TrainError> {
        let delay = config.validate()?;
        let env = BatchedEnv::new(&BatchConfig {
            task: config.task,
            envs: config.envs,
            threads: config.threads,
            seed: config.seed,
            actuator_noise: config.delay.actuator_noise,
        })?;
        let spec = agent_spec(&env, delay);
        let mut layer = CpuDelayLayer::new(
            &config.delay,
            config.envs,
            spec.obs_dim,
            &spec.action_low,
            &spec.action_high,
            config.seed ^ 0xDE1A,
        )?;
        layer.reset(env.observations())?;
        let layout = DelayLayout {
            copies: config.envs,
            obs_dim: spec.obs_dim,
            act_dim: spec.act_dim,
            delay,
        };
        let replay = ReplayStore::new(layout, config.replay_capacity)?;
        let devices = Devices::new(config.device)?;
        let agent = build_agent(
            config.algo,
            &spec,
            &config.hyper,
            &config.lifting,
            &devices,
            config.seed,
        );
        let state = LoopState {
            env_steps: 0,
            updates: 0,
            update_debt: 0.0,
            evals_done: 0,
            checkpoints_done: 0,
            wall_seconds: 0.0,
            sample_rng: ChaCha8Rng::seed_from_u64(config.seed ^ 0x5A3B),
            warmup_rng: ChaCha8Rng::seed_from_u64(config.seed ^ 0x3A3),
            last_eval: None,
            stat_sums: Vec::new(),
            stat_count: 0,
            logged_steps: 0,
            logged_updates: 0,
            logged_wall: 0.0,
        };
        Ok(Trainer {
            config,
            run: run.to_path_buf(),
            env,
            layer,
            replay,
            agent,
            state,
            evals: None,
            train_log: None,
            stat_names: Vec::new(),
        })
    }

    /// Loads the latest checkpoint and cuts the logs back to it.
    fn resume(&mut self) -> Result<(), TrainError> {
        let dir = checkpoint::latest(&self.run)
            .ok_or_else(|| TrainError::NoCheckpoint(self.run.display().to_string()))?;
        self.state = read_json(&dir.join("state.json"))?;
        let env: BatchSnapshot = read_json(&dir.join("env.json"))?;
        self.env.restore(&env)?;
        self.layer
            .load(&mut checkpoint::open_binary(&dir.join("delay.bin"))?)?;
        self.replay
            .load(&mut checkpoint::open_binary(&dir.join("replay.bin"))?)?;
        self.agent.load(&dir.join("agent"))?;
        truncate_after(&self.run.join("evals.csv"), self.state.env_steps)?;
        truncate_after(&self.run.join("train.csv"), self.state.env_steps)?;
        Ok(())
    }

    fn save_checkpoint(&mut self) -> Result<(), TrainError> {
        let dir = checkpoint::begin(&self.run)?;
        write_json(&dir.join("state.json"), &self.state)?;
        write_json(&dir.join("env.json"), &self.env.snapshot())?;
        write_binary(&dir.join("delay.bin"), |out| Ok(self.layer.save(out)?))?;
        write_binary(&dir.join("replay.bin"), |out| Ok(self.replay.save(out)?))?;
        self.agent.save(&dir.join("agent"))?;
        checkpoint::commit(&self.run)
    }

    /// Actions for every copy: uniform random during the warm-up phase, the policy's samples
    /// for copies whose augmented state exists, the delay layer's warm-up actions for the rest.
    fn choose_actions(&mut self) -> Result<Vec<f32>, TrainError> {
        let (n, act) = (self.env.len(), self.env.act_dim());
        let mut actions = vec![0.0f32; n * act];
        if self.state.env_steps < self.config.warmup_steps {
            let (low, high) = self.env.action_bounds();
            for row in actions.chunks_mut(act) {
                for (j, a) in row.iter_mut().enumerate() {
                    *a = self
                        .state
                        .warmup_rng
                        .random_range(low[j] as f32..=high[j] as f32);
                }
            }
        } else {
            let aug = self.layer.layout().augmented_dim();
            let ready: Vec<usize> = (0..n).filter(|&i| self.layer.ready()[i] == 1).collect();
            if !ready.is_empty() {
                let inputs: Vec<f32> = ready
                    .iter()
                    .flat_map(|&i| &self.layer.augmented()[i * aug..(i + 1) * aug])
                    .copied()
                    .collect();
                let chosen = self.agent.act(&inputs, ready.len(), ActMode::Explore);
                for (k, &i) in ready.iter().enumerate() {
                    actions[i * act..(i + 1) * act]
                        .copy_from_slice(&chosen[k * act..(k + 1) * act]);
                }
            }
        }
        self.layer.fill_warmup(&mut actions)?;
        Ok(actions)
    }

    fn update(&mut self) -> Result<(), TrainError> {
        let batch = match self
            .replay
            .sample(self.config.batch_size, &mut self.state.sample_rng)
        {
            Ok(batch) => batch,
            // Nothing complete yet (e.g. delay longer than the warm-up): learn later.
            Err(crate::delay::ReplayError::Empty) => return Ok(()),
            Err(e) => return Err(e.into()),
        };
        let stats = self.agent.update(&batch);
        self.state.updates += 1;
        if self.stat_names.is_empty() {
            self.stat_names = stats.iter().map(|(name, _)| *name).collect();
        }
        if self.state.stat_sums.len() != stats.len() {
            self.state.stat_sums = vec![0.0; stats.len()];
        }
        for (sum, (_, value)) in self.state.stat_sums.iter_mut().zip(&stats) {
            *sum += value;
        }
        self.state.stat_count += 1;
        if self.state.updates % self.config.log_every == 0 {
            self.write_train_row()?;
        }
        Ok(())
    }

    fn write_train_row(&mut self) -> Result<(), TrainError> {
        if self.train_log.is_none() {
            let header: Vec<&str> = TRAIN_HEADER
                .iter()
                .copied()
                .chain(self.stat_names.iter().copied())
                .collect();
            self.train_log = Some(CsvLog::open(self.run.join("train.csv"), &header)?);
        }
        let s = &mut self.state;
        let seconds = (s.wall_seconds - s.logged_wall).max(1e-9);
        let mut row = vec![
            s.env_steps.to_string(),
            s.updates.to_string(),
            format!("{:.3}", s.wall_seconds),
            format!("{:.1}", (s.env_steps - s.logged_steps) as f64 / seconds),
            format!("{:.1}", (s.updates - s.logged_updates) as f64 / seconds),
        ];
        row.extend(
            s.stat_sums
                .iter()
                .map(|sum| format!("{:.6}", sum / s.stat_count.max(1) as f64)),
        );
        (s.logged_steps, s.logged_updates, s.logged_wall) =
            (s.env_steps, s.updates, s.wall_seconds);
        s.stat_sums.iter_mut().for_each(|v| *v = 0.0);
        s.stat_count = 0;
        self.train_log.as_mut().expect("opened above").append(&row)
    }

    fn evaluate_now(&mut self) -> Result<EvalResult, TrainError> {
        let seed = self.config.seed ^ 0xE7A1 ^ (self.state.evals_done << 20);
        let result = evaluate(
            self.agent.as_mut(),
            EvalPolicy::Regular,
            self.config.task,
            &self.config.delay,
            self.config.eval_episodes,
            self.config.threads,
            seed,
        )?;
        let evals = match &mut self.evals {
            Some(log) => log,
            None => self
                .evals
                .insert(CsvLog::open(self.run.join("evals.csv"), &EVAL_HEADER)?),
        };
        evals.append(&[
            self.state.env_steps.to_string(),
            format!("{:.3}", self.state.wall_seconds),
            format!("{:.4}", result.return_mean),
            format!("{:.4}", result.return_std),
            format!("{:.2}", result.length_mean),
            result.episodes.to_string(),
        ])?;
        self.state.last_eval = Some(result);
        Ok(result)
    }

    fn run(mut self, show_progress: bool) -> Result<TrainSummary, TrainError> {
        let c = self.config.clone();
        let bar = if show_progress {
            ProgressBar::new(c.steps)
        } else {
            ProgressBar::hidden()
        };
        bar.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} steps  {per_sec}  ETA {eta}  {msg}")
                .expect("a valid template"),
        );
        bar.set_position(self.state.env_steps);
        let session_start = Instant::now();
        let wall_at_start = self.state.wall_seconds;
        while self.state.env_steps < c.steps {
            let actions = self.choose_actions()?;
            self.env.step(&actions)?;
            self.layer.step(&StepInput::from_env(&self.env, &actions))?;
            self.replay.push(self.layer.records())?;
            self.state.env_steps += c.envs as u64;
            self.state.wall_seconds = wall_at_start + session_start.elapsed().as_secs_f64();
            if self.state.env_steps >= c.warmup_steps {
                self.state.update_debt += c.envs as f64 * c.updates_per_step;
                while self.state.update_debt >= 1.0 {
                    self.state.update_debt -= 1.0;
                    self.update()?;
                }
            }
            self.state.wall_seconds = wall_at_start + session_start.elapsed().as_secs_f64();
            if self.state.env_steps / c.eval_every > self.state.evals_done
                || self.state.env_steps >= c.steps
            {
                let result = self.evaluate_now()?;
                self.state.evals_done = self.state.env_steps / c.eval_every;
                bar.set_message(format!(
                    "eval {:.1} ± {:.1}",
                    result.return_mean, result.return_std
                ));
            }
            if self.state.env_steps / c.checkpoint_every > self.state.checkpoints_done
                || self.state.env_steps >= c.steps
            {
                self.state.checkpoints_done = self.state.env_steps / c.checkpoint_every;
                self.save_checkpoint()?;
            }
            bar.set_position(self.state.env_steps);
        }
        bar.finish();
        Ok(TrainSummary {
            env_steps: self.state.env_steps,
            updates: self.state.updates,
            wall_seconds: self.state.wall_seconds,
            last_eval: self.state.last_eval,
        })
    }
}

/// `dhrl eval`: the saved policy of `run` on `episodes` fresh copies, under `delay` (the
/// run's own delay when `None`). With `delay_free_policy`, D2HPG's delay-free policy is
/// evaluated instead, in the undelayed task.
pub fn evaluate_saved(
    run: &Path,
    episodes: usize,
    delay: Option<DelayConfig>,
    delay_free_policy: bool,
    seed: u64,
) -> Result<EvalResult, TrainError> {
    let config = TrainConfig::from_toml_file(&run.join("config.toml"))?;
    let trained_delay = config.validate()?;
    let eval_delay = match (delay_free_policy, delay) {
        (true, Some(_)) => {
            return Err(TrainError::Config(ConfigError::Invalid {
                what: "--delay-free-policy",
                accepted: "used without delay options (the delay-free policy is evaluated undelayed)",
                value: "given with delay options".into(),
            }));
        }
        (true, None) => DelayConfig::default(),
        (false, delay) => delay.unwrap_or(config.delay),
    };
    let total = eval_delay.total_delay()?;
    if !delay_free_policy && total != trained_delay && config.algo.acts_on_augmented_state() {
        return Err(TrainError::Config(ConfigError::Invalid {
            what: "the evaluation delay",
            accepted: "the total delay the policy was trained with, since its input x_t grows with Δ",
            value: format!("{total} (trained with {trained_delay})"),
        }));
    }
    let dir = checkpoint::latest(run)
        .ok_or_else(|| TrainError::NoCheckpoint(run.display().to_string()))?;
    let env = BatchedEnv::new(&BatchConfig {
        task: config.task,
        envs: 1,
        threads: 1,
        seed,
        actuator_noise: 0.0,
    })?;
    let devices = Devices::new(config.device)?;
    let mut agent = build_agent(
        config.algo,
        &agent_spec(&env, trained_delay),
        &config.hyper,
        &config.lifting,
        &devices,
        config.seed,
    );
    agent.load(&dir.join("agent"))?;
    let policy = if delay_free_policy {
        EvalPolicy::DelayFree
    } else {
        EvalPolicy::Regular
    };
    if delay_free_policy && agent.act_delay_free(&vec![0.0; env.obs_dim()], 1).is_none() {
        return Err(TrainError::Config(ConfigError::Invalid {
            what: "--delay-free-policy",
            accepted: "a run of d2hpg or d2hpg-naive (the algorithms that learn a delay-free policy)",
            value: config.algo.to_string(),
        }));
    }
    evaluate(
        agent.as_mut(),
        policy,
        config.task,
        &eval_delay,
        episodes,
        config.threads,
        seed,
    )
}
