//! The training loop.
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, LazyLock};
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::checkpoint::{self, read_json, write_binary, write_json};
use super::eval::{EvalPolicy, EvalResult, evaluate};
use super::logs::{CsvLog, stat_means, truncate_after};
use super::tensorboard::{self, EventLog};
use super::{ConfigError, TrainConfig, TrainError, io_error};
use crate::algos::{ActMode, Agent, AgentSpec, UpdateContext};
use crate::delay::{DelayArgs, DelayConfig, DelayedBatch, ReplayError, ReplayStore};
use crate::learn::Devices;
use crate::progress::Progress;
use crate::seeds;
use crate::sim::{BatchConfig, BatchSnapshot};

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
    /// Per statistic the agent declared: the sum of its values since the last `train.csv`
    /// row, and how many updates reported it.
    stat_sums: Vec<f64>,
    #[serde(default)]
    stat_counts: Vec<u64>,
    /// Read from checkpoints written before `stat_counts` only (their updates since the last
    /// row, every statistic reported on each).
    #[serde(default, skip_serializing)]
    stat_count: u64,
    /// Environment steps and wall seconds at the last `train.csv` row.
    logged_steps: u64,
    logged_updates: u64,
    logged_wall: f64,
    /// Training episodes the simulation's divergence ended (their last step not learnt from).
    #[serde(default)]
    diverged_episodes: u64,
}

const EVAL_HEADER: [&str; 6] = [
    "step",
    "wall_seconds",
    "return_mean",
    "return_std",
    "length_mean",
    "episodes",
];
const TRAIN_HEADER: [&str; 6] = [
    "step",
    "updates",
    "wall_seconds",
    "env_steps_per_sec",
    "updates_per_sec",
    "diverged_episodes",
];

struct Trainer {
    config: TrainConfig,
    run: PathBuf,
    /// The training copies and their delay layer.
    batch: DelayedBatch,
    replay: ReplayStore,
    agent: Box<dyn Agent>,
    /// The threads the agent's learners run on (its declared learner count).
    learner_pool: rayon::ThreadPool,
    state: LoopState,
    /// Opened when the loop starts, after a resume has cut the files back.
    evals: Option<CsvLog>,
    train_log: Option<CsvLog>,
    /// TensorBoard's copy of both logs (unless the config turns it off).
    events: Option<EventLog>,
    /// The checkpoint's step when the run was resumed.
    resumed_after: Option<u64>,
    stat_names: Vec<&'static str>,
}

/// A pool of `threads` threads for the learners: burn's CPU backend splits the products of a
/// single learner across rayon's threads, which costs more than it gains at these sizes, so an
/// agent gets as many threads as it has learners to update side by side. Its threads flush
/// subnormals ([`crate::float_mode`]).
pub fn learner_pool(threads: usize) -> Result<rayon::ThreadPool, TrainError> {
    crate::float_mode::thread_pool(threads, "dhrl-learner").map_err(|e| TrainError::Io {
        path: "learner threads".into(),
        message: e.to_string(),
    })
}

/// Set when the process is asked to stop (SIGTERM, SIGINT, SIGUSR1 once
/// `stop_on_signals` is installed): the loop writes a checkpoint at the end of the current
/// step and returns [`TrainError::Interrupted`].
static STOP: LazyLock<Arc<AtomicBool>> = LazyLock::new(|| Arc::new(AtomicBool::new(false)));

fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Makes SIGTERM (a cluster's preemption or time limit), SIGINT (Ctrl-C), SIGHUP (a closed
/// terminal) and SIGUSR1 (a cluster's warning before its time limit) stop training at the end
/// of the current step with a checkpoint, so that `--resume` continues exactly. A second
/// SIGTERM, SIGINT or SIGHUP (not one after SIGUSR1's warning) ends the process at once.
#[cfg(feature = "cli")]
pub fn stop_on_signals() -> Result<(), TrainError> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM, SIGUSR1};
    use signal_hook::flag::{register, register_conditional_shutdown};
    static TERMINATING: LazyLock<Arc<AtomicBool>> =
        LazyLock::new(|| Arc::new(AtomicBool::new(false)));
    let failed = |e: std::io::Error| TrainError::Io {
        path: "signal handlers".into(),
        message: e.to_string(),
    };
    for signal in [SIGTERM, SIGINT, SIGHUP] {
        // Registered first, so it sees the flag as the first such signal left it.
        register_conditional_shutdown(signal, 128 + signal, Arc::clone(&TERMINATING))
            .map_err(failed)?;
        register(signal, Arc::clone(&TERMINATING)).map_err(failed)?;
        register(signal, Arc::clone(&STOP)).map_err(failed)?;
    }
    register(SIGUSR1, Arc::clone(&STOP)).map_err(failed)?;
    Ok(())
}

/// Trains as configured, writing into `run`; with [`Start::Resume`], continues the run saved
/// there (its own `config.toml` wins over `config`, except `steps`).
pub fn train(
    config: &TrainConfig,
    run: &Path,
    start: Start,
    progress: bool,
) -> Result<TrainSummary, TrainError> {
    // Held until the run returns: a second `dhrl train` on the folder is refused.
    let lock;
    let config = match start {
        Start::Fresh => {
            if run.exists() {
                return Err(TrainError::OutputExists(run.display().to_string()));
            }
            config.validate()?;
            std::fs::create_dir_all(run).map_err(io_error(run))?;
            lock = lock_run(run)?;
            let text = toml::to_string(config).map_err(|e| TrainError::Io {
                path: "config.toml".into(),
                message: e.to_string(),
            })?;
            let path = run.join("config.toml");
            crate::files::write_atomically(&path, text).map_err(io_error(&path))?;
            config.clone()
        }
        Start::Resume => {
            let saved = TrainConfig::from_toml_file(&run.join("config.toml"))?;
            lock = lock_run(run)?;
            // 0: no --steps given.
            if config.steps != 0 && config.steps < saved.steps {
                return Err(TrainError::Config(ConfigError::Invalid {
                    what: "--steps with --resume",
                    accepted: "at least the run's own steps (a resumed run can only be extended)",
                    value: format!("{} (the run has {})", config.steps, saved.steps),
                }));
            }
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
                crate::files::write_atomically(&path, text).map_err(io_error(&path))?;
            }
            merged
        }
    };
    let mut trainer = Trainer::new(config, run)?;
    if start == Start::Resume {
        trainer.resume()?;
    }
    let summary = trainer.run(progress);
    drop(lock);
    summary
}

/// The run folder's lock file, `RUN/.lock`, locked exclusively (the lock goes with the
/// returned file): two processes training one folder would interleave its logs and
/// checkpoints.
fn lock_run(run: &Path) -> Result<std::fs::File, TrainError> {
    let path = run.join(".lock");
    let file = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .truncate(false)
        .open(&path)
        .map_err(io_error(&path))?;
    match file.try_lock() {
        Ok(()) => Ok(file),
        Err(std::fs::TryLockError::WouldBlock) => {
            Err(TrainError::RunInUse(run.display().to_string()))
        }
        Err(std::fs::TryLockError::Error(e)) => Err(io_error(&path)(e)),
    }
}

impl Trainer {
    fn new(config: TrainConfig, run: &Path) -> Result<Trainer, TrainError> {
        let delay = config.validate()?;
        let batch = DelayedBatch::new(
            &BatchConfig {
                task: config.task,
                envs: config.envs,
                threads: config.threads,
                seed: config.seed,
                actuator_noise: config.delay.actuator_noise,
            },
            &config.delay,
            config.delay_device,
            seeds::delay_layer(config.seed),
        )?;
        let spec = AgentSpec::for_model(batch.env().model(), delay);
        let layout = batch.layout();
        let replay = ReplayStore::new(layout, config.replay_capacity)?;
        let devices = Devices::new(config.device)?;
        let agent = config.algo.build(&spec, &devices, config.seed);
        let stat_names = agent.stat_names();
        let learner_pool = learner_pool(config.algo.info().learner_threads)?;
        let state = LoopState {
            env_steps: 0,
            updates: 0,
            update_debt: 0.0,
            evals_done: 0,
            checkpoints_done: 0,
            wall_seconds: 0.0,
            sample_rng: ChaCha8Rng::seed_from_u64(seeds::replay_sampling(config.seed)),
            warmup_rng: ChaCha8Rng::seed_from_u64(seeds::warmup_phase(config.seed)),
            last_eval: None,
            stat_sums: vec![0.0; stat_names.len()],
            stat_counts: vec![0; stat_names.len()],
            stat_count: 0,
            logged_steps: 0,
            logged_updates: 0,
            logged_wall: 0.0,
            diverged_episodes: 0,
        };
        Ok(Trainer {
            config,
            run: run.to_path_buf(),
            batch,
            replay,
            learner_pool,
            agent,
            state,
            evals: None,
            train_log: None,
            events: None,
            resumed_after: None,
            stat_names,
        })
    }

    /// Loads the latest checkpoint and cuts the logs back to it.
    fn resume(&mut self) -> Result<(), TrainError> {
        let dir = checkpoint::latest(&self.run)
            .ok_or_else(|| TrainError::NoCheckpoint(self.run.display().to_string()))?;
        self.state = read_json(&dir.join("state.json"))?;
        // Checkpoints written before per-statistic counts: every statistic on every update.
        let n = self.stat_names.len();
        if self.state.stat_counts.len() != n {
            self.state.stat_counts = vec![self.state.stat_count; n];
        }
        if self.state.stat_sums.len() != n {
            self.state.stat_sums = vec![0.0; n];
        }
        let env: BatchSnapshot = read_json(&dir.join("env.json"))?;
        self.batch.env_mut().restore(&env)?;
        self.batch
            .layer_mut()
            .load(&mut checkpoint::open_binary(&dir.join("delay.bin"))?)?;
        self.replay
            .load(&mut checkpoint::open_binary(&dir.join("replay.bin"))?)?;
        self.agent.load(&dir.join("agent"))?;
        truncate_after(&self.run.join("evals.csv"), self.state.env_steps)?;
        truncate_after(&self.run.join("train.csv"), self.state.env_steps)?;
        tensorboard::truncate_after(&self.run, self.state.env_steps)?;
        self.resumed_after = Some(self.state.env_steps);
        Ok(())
    }

    /// Writes a checkpoint, or fails with [`TrainError::CheckpointFailed`] (a full disk, an
    /// unwritable folder), the partial one removed and the previous one intact.
    fn save_checkpoint(&mut self) -> Result<(), TrainError> {
        self.write_checkpoint().map_err(|cause| {
            let partial_removed = checkpoint::discard_partial(&self.run).is_ok();
            let kept = match checkpoint::latest(&self.run) {
                Some(previous) => {
                    format!("the previous checkpoint {} is intact", previous.display())
                }
                None => "there is no earlier checkpoint".into(),
            };
            TrainError::CheckpointFailed {
                run: self.run.display().to_string(),
                env_steps: self.state.env_steps,
                cause: Box::new(cause),
                kept: if partial_removed {
                    kept
                } else {
                    format!("{kept} (the partial one could not be removed either)")
                },
            }
        })
    }

    fn write_checkpoint(&mut self) -> Result<(), TrainError> {
        let dir = checkpoint::begin(&self.run)?;
        write_json(&dir.join("state.json"), &self.state)?;
        write_json(&dir.join("env.json"), &self.batch.env().snapshot())?;
        write_binary(&dir.join("delay.bin"), |out| {
            Ok(self.batch.layer().save(out)?)
        })?;
        write_binary(&dir.join("replay.bin"), |out| Ok(self.replay.save(out)?))?;
        self.agent.save(&dir.join("agent"))?;
        checkpoint::commit(&self.run)
    }

    /// Actions for every copy: uniform random during the warm-up phase, the policy's samples
    /// for copies whose augmented state exists, the delay layer's warm-up actions for the rest.
    fn choose_actions(&mut self) -> Result<Vec<f32>, TrainError> {
        let env = self.batch.env();
        let (n, act) = (env.len(), env.act_dim());
        let mut actions = vec![0.0f32; n * act];
        let warming_up = self.state.env_steps < self.config.warmup_steps;
        if warming_up {
            let (low, high) = env.action_bounds();
            for row in actions.chunks_mut(act) {
                for (j, a) in row.iter_mut().enumerate() {
                    *a = self
                        .state
                        .warmup_rng
                        .random_range(low[j] as f32..=high[j] as f32);
                }
            }
        }
        let (agent, pool) = (&mut self.agent, &self.learner_pool);
        self.batch.choose_actions(
            &mut actions,
            |_| !warming_up,
            |inputs, rows| {
                Ok::<_, TrainError>(pool.install(|| agent.act(inputs, rows, ActMode::Explore)))
            },
        )?;
        Ok(actions)
    }

    fn update(&mut self) -> Result<(), TrainError> {
        let mut ctx = UpdateContext::replay(
            &self.replay,
            &mut self.state.sample_rng,
            self.agent.batch_extras(),
            self.config.batch_size,
            self.state.env_steps,
            self.state.updates,
        );
        let agent = &mut self.agent;
        let stats = match self.learner_pool.install(|| agent.update(&mut ctx)) {
            Ok(stats) => stats,
            // Nothing complete yet (e.g. delay longer than the warm-up): learn later.
            Err(ReplayError::Empty) => return Ok(()),
            Err(e) => return Err(e.into()),
        };
        self.state.updates += 1;
        if let Some((name, value)) = stats.iter().find(|(_, v)| !v.is_finite()) {
            return Err(TrainError::NonFinite {
                run: self.run.display().to_string(),
                statistic: name,
                value: *value,
                update: self.state.updates,
                env_steps: self.state.env_steps,
            });
        }
        for (name, value) in stats {
            let k = self
                .stat_names
                .iter()
                .position(|n| *n == name)
                .ok_or(TrainError::UndeclaredStatistic(name))?;
            self.state.stat_sums[k] += value;
            self.state.stat_counts[k] += 1;
        }
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
            s.diverged_episodes.to_string(),
        ];
        row.extend(stat_means(&s.stat_sums, &s.stat_counts));
        (s.logged_steps, s.logged_updates, s.logged_wall) =
            (s.env_steps, s.updates, s.wall_seconds);
        s.stat_sums.iter_mut().for_each(|v| *v = 0.0);
        s.stat_counts.iter_mut().for_each(|v| *v = 0);
        let scalars: Vec<(String, f64)> = TRAIN_HEADER
            .iter()
            .chain(&self.stat_names)
            .zip(&row)
            .skip(1) // the step
            .filter_map(|(name, cell)| Some((format!("train/{name}"), cell.parse().ok()?)))
            .collect();
        self.train_log
            .as_mut()
            .expect("opened above")
            .append(&row)?;
        self.tensorboard(&scalars)
    }

    /// `scalars` into the run's TensorBoard events at the current step (opening its file
    /// first), unless the config turns TensorBoard off.
    fn tensorboard(&mut self, scalars: &[(String, f64)]) -> Result<(), TrainError> {
        if !self.config.tensorboard {
            return Ok(());
        }
        let events = match &mut self.events {
            Some(events) => events,
            None => self
                .events
                .insert(EventLog::create(&self.run, self.resumed_after)?),
        };
        events.scalars(self.state.env_steps, scalars)
    }

    fn evaluate_now(&mut self) -> Result<EvalResult, TrainError> {
        let seed = seeds::evaluation(self.config.seed, self.state.evals_done);
        let (agent, config) = (&mut self.agent, &self.config);
        let result = self.learner_pool.install(|| {
            evaluate(
                agent.as_mut(),
                EvalPolicy::Regular,
                config.task,
                &config.delay,
                config.delay_device,
                config.eval_episodes,
                config.threads,
                seed,
            )
        })?;
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
        self.tensorboard(&[
            ("eval/return_mean".into(), result.return_mean),
            ("eval/return_std".into(), result.return_std),
            ("eval/length_mean".into(), result.length_mean),
        ])?;
        self.state.last_eval = Some(result);
        Ok(result)
    }

    fn run(mut self, show_progress: bool) -> Result<TrainSummary, TrainError> {
        let c = self.config.clone();
        let bar = Progress::new(
            c.steps,
            "{bar:30} {pos}/{len} steps  {per_sec}  ETA {eta}  {msg}",
            show_progress,
        );
        bar.set_position(self.state.env_steps);
        let session_start = Instant::now();
        let wall_at_start = self.state.wall_seconds;
        while self.state.env_steps < c.steps {
            let actions = self.choose_actions()?;
            self.batch.step(&actions)?;
            let count = self.replay.push_step(&self.batch)?;
            if count > 0 {
                self.state.diverged_episodes += count;
                bar.suspend(|| {
                    eprintln!(
                        "warning: step {}: {count} training episode(s) ended because MuJoCo \
                         found the simulation unstable (a bad qpos, qvel or qacc) and reset it; \
                         the step is kept out of the replay ({} so far, in train.csv)",
                        self.state.env_steps + c.envs as u64,
                        self.state.diverged_episodes
                    )
                });
            }
            self.state.env_steps += c.envs as u64;
            bar.set_position(self.state.env_steps);
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
            let finished = self.state.env_steps >= c.steps;
            let scheduled = self.state.env_steps / c.checkpoint_every > self.state.checkpoints_done;
            if scheduled || finished || stop_requested() {
                self.state.checkpoints_done = self.state.env_steps / c.checkpoint_every;
                self.save_checkpoint()?;
            }
            if stop_requested() && !finished {
                bar.abandon();
                return Err(TrainError::Interrupted {
                    run: self.run.display().to_string(),
                    env_steps: self.state.env_steps,
                });
            }
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

/// A finished or stopped run's agent, as its latest checkpoint holds it.
pub struct SavedRun {
    pub config: TrainConfig,
    /// The total delay Δ the run trained under.
    pub trained_delay: usize,
    /// Environment steps the run had taken at its checkpoint.
    pub env_steps: u64,
    pub agent: Box<dyn Agent>,
}

/// Loads the agent of `run`'s latest checkpoint, built for the total delay `delay` (by
/// default the trained one, the only one a policy on `x_t` takes).
pub fn load_saved(run: &Path, delay: Option<usize>) -> Result<SavedRun, TrainError> {
    let config = TrainConfig::from_toml_file(&run.join("config.toml"))?;
    load_checkpoint(run, config, delay)
}

/// [`load_saved`] with `run`'s configuration already read.
fn load_checkpoint(
    run: &Path,
    config: TrainConfig,
    delay: Option<usize>,
) -> Result<SavedRun, TrainError> {
    let trained_delay = config.validate()?;
    if !checkpoint::has_checkpoint(run) {
        return Err(TrainError::NoCheckpoint(run.display().to_string()));
    }
    let devices = Devices::new(config.device)?;
    let spec = AgentSpec::for_task(config.task, delay.unwrap_or(trained_delay))?;
    // A run still training replaces its checkpoint while it is read (the new one renamed into
    // place, the old one removed). A read is kept only if the checkpoint's step count is the
    // same after it as before, so that the agent and its step count come from one checkpoint;
    // a read that failed while the checkpoint changed is taken again. Three tries.
    let mut tries = 0;
    loop {
        tries += 1;
        let before = checkpoint_steps(run);
        let steps_before = before.as_ref().ok().map(|&(_, steps)| steps);
        let read = before.and_then(|(dir, env_steps)| {
            let mut agent = config.algo.build(&spec, &devices, config.seed);
            agent.load(&dir.join("agent"))?;
            Ok((env_steps, agent))
        });
        let steps_after = checkpoint_steps(run).ok().map(|(_, steps)| steps);
        match read {
            Ok((env_steps, agent)) if steps_after == Some(env_steps) => {
                return Ok(SavedRun {
                    config,
                    trained_delay,
                    env_steps,
                    agent,
                });
            }
            // The checkpoint did not change: the error is its own.
            Err(e) if tries == 3 || steps_after == steps_before => return Err(e),
            _ if tries == 3 => {
                return Err(TrainError::Io {
                    path: run.display().to_string(),
                    message: "its checkpoint was replaced during each of three reads (a run still \
                              training): try again"
                        .into(),
                });
            }
            _ => std::thread::sleep(std::time::Duration::from_millis(200)),
        }
    }
}

/// `run`'s latest checkpoint folder and its environment steps.
fn checkpoint_steps(run: &Path) -> Result<(PathBuf, u64), TrainError> {
    let dir = checkpoint::latest(run)
        .ok_or_else(|| TrainError::NoCheckpoint(run.display().to_string()))?;
    let state: serde_json::Value = read_json(&dir.join("state.json"))?;
    let env_steps = state["env_steps"].as_u64().ok_or_else(|| TrainError::Io {
        path: dir.join("state.json").display().to_string(),
        message: "no env_steps in the checkpoint's state".into(),
    })?;
    Ok((dir, env_steps))
}

/// `dhrl eval`: the saved policy of `run` on `episodes` fresh copies, under the run's own
/// delay with `delay`'s options laid over it. With `delay_free_policy`, D2HPG's delay-free
/// policy is evaluated instead, in the undelayed task.
pub fn evaluate_saved(
    run: &Path,
    episodes: usize,
    delay: &DelayArgs,
    delay_free_policy: bool,
    seed: u64,
) -> Result<EvalResult, TrainError> {
    let config = TrainConfig::from_toml_file(&run.join("config.toml"))?;
    let trained_delay = config.validate()?;
    let eval_delay = match (delay_free_policy, delay.any()) {
        (true, true) => {
            return Err(TrainError::Config(ConfigError::Invalid {
                what: "--delay-free-policy",
                accepted: "used without delay options (the delay-free policy is evaluated undelayed)",
                value: "given with delay options".into(),
            }));
        }
        (true, false) => DelayConfig::default(),
        (false, _) => delay.apply(config.delay).map_err(ConfigError::from)?,
    };
    let total = eval_delay.total_delay()?;
    let info = config.algo.info();
    if delay_free_policy && !info.delay_free_policy {
        return Err(TrainError::Config(ConfigError::no_delay_free_policy(
            config.algo.name(),
        )));
    }
    if !delay_free_policy && total != trained_delay && info.acts_on_augmented_state {
        return Err(TrainError::Config(ConfigError::Invalid {
            what: "the evaluation delay",
            accepted: "the total delay the policy was trained with, since its input x_t grows with Δ",
            value: format!("{total} (trained with {trained_delay})"),
        }));
    }
    // A policy that does not read x_t whole is built for the evaluation's Δ, so that it splits
    // the evaluation's rows of x_t (and delayed SAC rolls its model over all Δ actions).
    let acting_delay = if info.acts_on_augmented_state {
        trained_delay
    } else {
        total
    };
    let SavedRun {
        mut agent, config, ..
    } = load_checkpoint(run, config, Some(acting_delay))?;
    let policy = if delay_free_policy {
        EvalPolicy::DelayFree
    } else {
        EvalPolicy::Regular
    };
    learner_pool(info.learner_threads)?.install(|| {
        evaluate(
            agent.as_mut(),
            policy,
            config.task,
            &eval_delay,
            config.delay_device,
            episodes,
            config.threads,
            seed,
        )
    })
}
