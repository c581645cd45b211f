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
use crate::algos::{ActMode, Agent, AgentSpec, Stats, UpdateContext};
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

/// One update whose statistics are still on the device.
struct PendingUpdate {
    stats: Stats,
    /// Per run: its update count and environment steps at this update; `None` for a run that
    /// had already stopped.
    counters: Vec<Option<(u64, u64)>>,
}

/// One run of a stack: its copies and delay layer, replay, counters, logs and folder.
struct RunSlot {
    config: TrainConfig,
    run: PathBuf,
    /// Held while the run trains: a second `dhrl train` on the folder is refused.
    _lock: std::fs::File,
    /// The training copies and their delay layer.
    batch: DelayedBatch,
    replay: ReplayStore,
    state: LoopState,
    /// Opened when the loop starts, after a resume has cut the files back.
    evals: Option<CsvLog>,
    train_log: Option<CsvLog>,
    /// TensorBoard's copy of both logs (unless the config turns it off).
    events: Option<EventLog>,
    /// The checkpoint's step when the run was resumed.
    resumed_after: Option<u64>,
    /// Why the run stopped while the rest of its stack went on: it then neither steps, logs
    /// nor saves, and its folder keeps its last checkpoint.
    failed: Option<TrainError>,
}

/// The loop over a stack of runs (one run: a solo run), their learners one agent.
struct Trainer {
    slots: Vec<RunSlot>,
    agent: Box<dyn Agent>,
    /// The threads the agent's learners run on (its declared learner count); the loop itself
    /// runs on one of them.
    learner_pool: Arc<rayon::ThreadPool>,
    stat_names: Vec<&'static str>,
    /// The updates whose statistics are still on the learner's device: downloaded together
    /// when a `train.csv` row is due, and before every evaluation and checkpoint.
    pending: Vec<PendingUpdate>,
    /// What `dhrl train --resume` takes to continue: the run, or the stack's folder.
    resume_target: PathBuf,
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
    let runs = [(config.clone(), run.to_path_buf())];
    train_stack(&runs, run, start, progress)?.remove(0)
}

/// Trains the runs of one configuration, their seeds apart, as one stack: one learner pass
/// serves all of them, and each writes its own ordinary run folder (as a solo run of its seed
/// would, [`crate::learn::stack`]). With [`Start::Resume`] each continues from its folder
/// (`config` gives only `steps`). `resume_target` is what a stop message tells to resume. A
/// run that fails (a non-finite statistic) stops alone, with its error in its result and in
/// its folder's `failed.txt`; the others go on.
pub fn train_stack(
    runs: &[(TrainConfig, PathBuf)],
    resume_target: &Path,
    start: Start,
    progress: bool,
) -> Result<Vec<Result<TrainSummary, TrainError>>, TrainError> {
    let prepared = runs
        .iter()
        .map(|(config, run)| prepare(config, run, start))
        .collect::<Result<Vec<_>, _>>()?;
    same_but_seed(&prepared)?;
    let mut trainer = Trainer::new(prepared, resume_target)?;
    if start == Start::Resume {
        trainer.resume()?;
    }
    trainer.run(progress)
}

/// A run's folder made (fresh) or its configuration read (resume), and its lock.
fn prepare(
    config: &TrainConfig,
    run: &Path,
    start: Start,
) -> Result<(TrainConfig, PathBuf, std::fs::File), TrainError> {
    let lock;
    let config = match start {
        Start::Fresh => {
            if run.exists() {
                return Err(TrainError::OutputExists(run.display().to_string()));
            }
            config.validate()?;
            let config = config.with_budget_fixed();
            std::fs::create_dir_all(run).map_err(io_error(run))?;
            lock = lock_run(run)?;
            let text = toml::to_string(&config).map_err(|e| TrainError::Io {
                path: "config.toml".into(),
                message: e.to_string(),
            })?;
            let path = run.join("config.toml");
            crate::files::write_atomically(&path, text).map_err(io_error(&path))?;
            config
        }
        Start::Resume => {
            let saved = TrainConfig::from_toml_file(&run.join("config.toml"), None)?;
            lock = lock_run(run)?;
            // A run that failed in a stack and is tried again.
            let failed = run.join(FAILED);
            if failed.exists() {
                std::fs::remove_file(&failed).map_err(io_error(&failed))?;
            }
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
                if let Some(budget) = merged.algo.budget() {
                    eprintln!(
                        "note: {}: extended to {} steps; the schedule [algo] spans over the \
                         run's budget keeps its original {budget} steps (config.toml)",
                        run.display(),
                        merged.steps,
                    );
                }
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
    Ok((config, run.to_path_buf(), lock))
}

/// Refuses a stack whose runs differ in more than their seeds (they share one schedule and
/// one learner configuration).
fn same_but_seed(runs: &[(TrainConfig, PathBuf, std::fs::File)]) -> Result<(), TrainError> {
    let without_seed = |config: &TrainConfig| {
        toml::to_string(&TrainConfig {
            seed: 0,
            ..config.clone()
        })
        .unwrap_or_default()
    };
    let first = without_seed(&runs[0].0);
    match runs[1..].iter().find(|(c, _, _)| without_seed(c) != first) {
        Some((_, run, _)) => Err(TrainError::Config(ConfigError::Invalid {
            what: "a stack's runs",
            accepted: "one configuration, their seeds apart",
            value: format!(
                "{} differs from {} in more than its seed",
                run.display(),
                runs[0].1.display()
            ),
        })),
        None => Ok(()),
    }
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

impl RunSlot {
    fn new(config: TrainConfig, run: PathBuf, lock: std::fs::File) -> Result<RunSlot, TrainError> {
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
        let replay = ReplayStore::new(batch.layout(), config.replay_capacity)?;
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
            stat_sums: Vec::new(),
            stat_counts: Vec::new(),
            stat_count: 0,
            logged_steps: 0,
            logged_updates: 0,
            logged_wall: 0.0,
            diverged_episodes: 0,
        };
        Ok(RunSlot {
            config,
            run,
            _lock: lock,
            batch,
            replay,
            state,
            evals: None,
            train_log: None,
            events: None,
            resumed_after: None,
            failed: None,
        })
    }

    fn active(&self) -> bool {
        self.failed.is_none()
    }

    /// Loads the loop's state, the copies, delay layer and replay of the checkpoint `dir`, and
    /// cuts the logs back to it.
    fn resume_from(&mut self, dir: &Path, stat_names: usize) -> Result<(), TrainError> {
        self.state = read_json(&dir.join("state.json"))?;
        // Checkpoints written before per-statistic counts: every statistic on every update.
        if self.state.stat_counts.len() != stat_names {
            self.state.stat_counts = vec![self.state.stat_count; stat_names];
        }
        if self.state.stat_sums.len() != stat_names {
            self.state.stat_sums = vec![0.0; stat_names];
        }
        let env: BatchSnapshot = read_json(&dir.join("env.json"))?;
        self.batch.env_mut().restore(&env)?;
        self.batch
            .layer_mut()
            .load(&mut checkpoint::open_binary(&dir.join("delay.bin"))?)?;
        self.replay
            .load(&mut checkpoint::open_binary(&dir.join("replay.bin"))?)?;
        truncate_after(&self.run.join("evals.csv"), self.state.env_steps)?;
        truncate_after(&self.run.join("train.csv"), self.state.env_steps)?;
        tensorboard::truncate_after(&self.run, self.state.env_steps)?;
        self.resumed_after = Some(self.state.env_steps);
        Ok(())
    }

    /// Writes the loop's part of a checkpoint into a new partial folder; returns it.
    fn write_partial(&self) -> Result<PathBuf, TrainError> {
        let dir = checkpoint::begin(&self.run)?;
        write_json(&dir.join("state.json"), &self.state)?;
        write_json(&dir.join("env.json"), &self.batch.env().snapshot())?;
        write_binary(&dir.join("delay.bin"), |out| {
            Ok(self.batch.layer().save(out)?)
        })?;
        write_binary(&dir.join("replay.bin"), |out| Ok(self.replay.save(out)?))?;
        Ok(dir)
    }

    /// A failed checkpoint as [`TrainError::CheckpointFailed`], the partial one removed.
    fn checkpoint_failed(&self, cause: TrainError) -> TrainError {
        let partial_removed = checkpoint::discard_partial(&self.run).is_ok();
        let kept = match checkpoint::latest(&self.run) {
            Some(previous) => format!("the previous checkpoint {} is intact", previous.display()),
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
    }

    fn write_train_row(&mut self, stat_names: &[&'static str]) -> Result<(), TrainError> {
        if self.train_log.is_none() {
            let header: Vec<&str> = TRAIN_HEADER
                .iter()
                .copied()
                .chain(stat_names.iter().copied())
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
            .chain(stat_names)
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

    fn record_eval(&mut self, result: EvalResult) -> Result<(), TrainError> {
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
        Ok(())
    }

    /// Stops this run for `error`: the whole training when it is `solo`, else the run alone
    /// ([`RunSlot::fail`]) while the rest of its stack goes on.
    fn stop(&mut self, error: TrainError, solo: bool) -> Result<(), TrainError> {
        if solo {
            return Err(error);
        }
        eprintln!(
            "{}: stopped alone, the rest of its stack goes on: {error}",
            self.run.display()
        );
        self.fail(error);
        Ok(())
    }

    /// Stops the run alone: its error goes to `RUN/failed.txt` and to its result.
    fn fail(&mut self, error: TrainError) {
        let path = self.run.join(FAILED);
        let _ = crate::files::write_atomically(&path, format!("{error}\n"));
        self.failed = Some(error);
    }

    fn summary(self) -> Result<TrainSummary, TrainError> {
        match self.failed {
            Some(error) => Err(error),
            None => Ok(TrainSummary {
                env_steps: self.state.env_steps,
                updates: self.state.updates,
                wall_seconds: self.state.wall_seconds,
                last_eval: self.state.last_eval,
            }),
        }
    }
}

/// A stack's folder: `stack.toml` (its seeds) and one ordinary run folder per seed.
pub const STACK: &str = "stack.toml";

/// The run folder of seed `seed` in the stack folder `dir`.
pub fn stack_member(dir: &Path, seed: u64) -> PathBuf {
    dir.join(format!("seed-{seed}"))
}

#[derive(Serialize, Deserialize)]
struct StackFile {
    seeds: Vec<u64>,
}

/// The seeds of the stack in `dir`, or `None` when `dir` holds no stack.
pub fn stack_seeds(dir: &Path) -> Result<Option<Vec<u64>>, TrainError> {
    let path = dir.join(STACK);
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    let file: StackFile = toml::from_str(&text).map_err(|e| TrainError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    Ok(Some(file.seeds))
}

/// `dhrl train --seeds`: the runs of `config` with each of `seeds`, trained as one stack in
/// `dir` (fresh: `dir/stack.toml` and one run folder per seed, `dir/seed-<seed>`); with
/// [`Start::Resume`], the stack in `dir` continues (`config` gives only `steps`), without the
/// runs that failed before. Each run's result, with its folder.
pub fn train_seeds(
    config: &TrainConfig,
    dir: &Path,
    seeds: &[u64],
    start: Start,
    progress: bool,
) -> Result<Vec<(PathBuf, Result<TrainSummary, TrainError>)>, TrainError> {
    let seeds = match start {
        Start::Fresh => {
            if dir.exists() {
                return Err(TrainError::OutputExists(dir.display().to_string()));
            }
            config.validate()?;
            std::fs::create_dir_all(dir).map_err(io_error(dir))?;
            let text = toml::to_string(&StackFile {
                seeds: seeds.to_vec(),
            })
            .map_err(|e| TrainError::Io {
                path: STACK.into(),
                message: e.to_string(),
            })?;
            let path = dir.join(STACK);
            crate::files::write_atomically(&path, text).map_err(io_error(&path))?;
            seeds.to_vec()
        }
        Start::Resume => stack_seeds(dir)?
            .ok_or_else(|| TrainError::NoCheckpoint(dir.display().to_string()))?
            .into_iter()
            .filter(|&seed| !stack_member(dir, seed).join(FAILED).is_file())
            .collect(),
    };
    let runs: Vec<(TrainConfig, PathBuf)> = seeds
        .iter()
        .map(|&seed| {
            (
                TrainConfig {
                    seed,
                    ..config.clone()
                },
                stack_member(dir, seed),
            )
        })
        .collect();
    if runs.is_empty() {
        return Err(TrainError::Io {
            path: dir.display().to_string(),
            message: format!("every run of the stack failed (each says why in its {FAILED})"),
        });
    }
    let results = train_stack(&runs, dir, start, progress)?;
    Ok(runs.into_iter().map(|(_, run)| run).zip(results).collect())
}

/// A run that stopped while the rest of its stack went on says why here.
pub const FAILED: &str = "failed.txt";

impl Trainer {
    fn new(
        runs: Vec<(TrainConfig, PathBuf, std::fs::File)>,
        resume_target: &Path,
    ) -> Result<Trainer, TrainError> {
        let first = runs[0].0.clone();
        let delay = first.validate()?;
        let mut slots = runs
            .into_iter()
            .map(|(config, run, lock)| RunSlot::new(config, run, lock))
            .collect::<Result<Vec<_>, _>>()?;
        let spec = AgentSpec::for_model(slots[0].batch.env().model(), delay);
        let devices = Devices::new(first.device)?;
        let seeds: Vec<u64> = slots.iter().map(|slot| slot.config.seed).collect();
        let agent =
            first
                .algo
                .build_in_passes(&spec, &devices, &seeds, first.runs_per_learner_pass());
        let stat_names = agent.stat_names();
        for slot in &mut slots {
            slot.state.stat_sums = vec![0.0; stat_names.len()];
            slot.state.stat_counts = vec![0; stat_names.len()];
        }
        Ok(Trainer {
            slots,
            agent,
            learner_pool: Arc::new(learner_pool(first.algo.info().learner_threads)?),
            stat_names,
            pending: Vec::new(),
            resume_target: resume_target.to_path_buf(),
        })
    }

    /// Loads every run's checkpoint of one step: the latest all of them hold (a stack's
    /// checkpoints are committed together, see [`checkpoint::commit_all`]), and cuts the logs
    /// back to it.
    fn resume(&mut self) -> Result<(), TrainError> {
        let mut latest = Vec::with_capacity(self.slots.len());
        for slot in &self.slots {
            let steps = checkpoint::available(&slot.run)?;
            let newest = steps
                .iter()
                .map(|(steps, _)| *steps)
                .max()
                .ok_or_else(|| TrainError::NoCheckpoint(slot.run.display().to_string()))?;
            latest.push((newest, steps));
        }
        let common = latest.iter().map(|(newest, _)| *newest).min().unwrap_or(0);
        let mut dirs = Vec::with_capacity(self.slots.len());
        for (slot, (_, available)) in self.slots.iter_mut().zip(&latest) {
            let dir = available
                .iter()
                .find(|(steps, _)| *steps == common)
                .map(|(_, dir)| dir.clone())
                .ok_or_else(|| TrainError::Io {
                    path: slot.run.display().to_string(),
                    message: format!(
                        "holds no checkpoint of step {common}, where the rest of its stack is"
                    ),
                })?;
            slot.resume_from(&dir, self.stat_names.len())?;
            dirs.push(dir.join("agent"));
        }
        let dirs: Vec<&Path> = dirs.iter().map(PathBuf::as_path).collect();
        self.agent.load_runs(&dirs)?;
        Ok(())
    }

    /// Writes every active run's checkpoint and commits them together, or fails with
    /// [`TrainError::CheckpointFailed`] (a full disk, an unwritable folder), the partial ones
    /// removed and the previous ones intact.
    fn save_checkpoint(&mut self) -> Result<(), TrainError> {
        let mut partials = Vec::with_capacity(self.slots.len());
        for slot in &self.slots {
            partials.push(
                slot.write_partial()
                    .map_err(|e| slot.checkpoint_failed(e))?,
            );
        }
        let agent_dirs: Vec<PathBuf> = partials.iter().map(|dir| dir.join("agent")).collect();
        let agent_dirs: Vec<&Path> = agent_dirs.iter().map(PathBuf::as_path).collect();
        if let Err(e) = self.agent.save_runs(&agent_dirs) {
            return Err(self.slots[0].checkpoint_failed(e.into()));
        }
        let mut committed = Vec::new();
        for slot in &self.slots {
            if slot.active() {
                committed.push(slot.run.as_path());
            } else {
                checkpoint::discard_partial(&slot.run)?;
            }
        }
        checkpoint::commit_all(&committed)
    }

    /// Actions for every copy of every active run: uniform random during the warm-up phase,
    /// the policy's samples for copies whose augmented state exists (every run's in one pass
    /// of the agent), the delay layer's warm-up actions for the rest.
    fn choose_actions(&mut self) -> Result<Vec<Vec<f32>>, TrainError> {
        let env = self.slots[0].batch.env();
        let (copies, act, aug) = (
            env.len(),
            env.act_dim(),
            self.slots[0].batch.layout().augmented_dim(),
        );
        let runs = self.slots.len();
        let mut actions = vec![vec![0.0f32; copies * act]; runs];
        let mut acting = vec![Vec::new(); runs];
        let mut augmented = vec![0.0f32; runs * copies * aug];
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if !slot.active() {
                continue;
            }
            if slot.state.env_steps < slot.config.warmup_steps {
                let (low, high) = slot.batch.env().action_bounds();
                for row in actions[i].chunks_mut(act) {
                    for (j, a) in row.iter_mut().enumerate() {
                        *a = slot
                            .state
                            .warmup_rng
                            .random_range(low[j] as f32..=high[j] as f32);
                    }
                }
                continue;
            }
            let (ready, states) = slot.batch.acting_states(|_| true);
            let start = i * copies * aug;
            augmented[start..start + states.len()].copy_from_slice(&states);
            acting[i] = ready;
        }
        let counts: Vec<usize> = acting.iter().map(Vec::len).collect();
        let chosen = match counts.iter().any(|&count| count > 0) {
            true => self
                .agent
                .act_runs(&augmented, &counts, copies, ActMode::Explore),
            false => Vec::new(),
        };
        let chosen_by = |i: usize| match counts[i] {
            0 => &[][..],
            count => &chosen[i * copies * act..(i * copies + count) * act],
        };
        if (0..runs).any(|i| chosen_by(i).iter().any(|a| !a.is_finite())) {
            // A policy gone non-finite: the statistics say at which update it happened.
            self.take_statistics()?;
            let solo = runs == 1;
            for (i, slot) in self.slots.iter_mut().enumerate() {
                let bad = chosen_by(i).iter().find(|a| !a.is_finite());
                if let (true, Some(&value)) = (slot.active(), bad) {
                    let error = TrainError::NonFinite {
                        run: slot.run.display().to_string(),
                        statistic: "action",
                        value: f64::from(value),
                        update: slot.state.updates,
                        env_steps: slot.state.env_steps,
                    };
                    slot.stop(error, solo)?;
                }
            }
        }
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if slot.active() {
                slot.batch
                    .set_actions(&mut actions[i], &acting[i], chosen_by(i))?;
            }
        }
        Ok(actions)
    }

    /// One update of every run: each draws its batch from its own replay and stream. Its
    /// statistics stay on the device until a `train.csv` row is due.
    fn update(&mut self) -> Result<(), TrainError> {
        let extras = self.agent.batch_extras();
        let mut contexts: Vec<UpdateContext<'_>> = self
            .slots
            .iter_mut()
            .map(|slot| {
                UpdateContext::replay(
                    &slot.replay,
                    &mut slot.state.sample_rng,
                    extras,
                    slot.config.batch_size,
                    slot.state.env_steps,
                    slot.state.updates,
                )
            })
            .collect();
        let stats = match self.agent.update_runs(&mut contexts) {
            Ok(stats) => stats,
            // Nothing complete yet (e.g. delay longer than the warm-up): learn later. A stack
            // updates when every run has a complete transition.
            Err(ReplayError::Empty) => return Ok(()),
            Err(e) => return Err(e.into()),
        };
        drop(contexts);
        let mut row_due = false;
        let counters = self
            .slots
            .iter_mut()
            .map(|slot| {
                slot.active().then(|| {
                    slot.state.updates += 1;
                    row_due |= slot.state.updates % slot.config.log_every == 0;
                    (slot.state.updates, slot.state.env_steps)
                })
            })
            .collect();
        self.pending.push(PendingUpdate { stats, counters });
        if row_due {
            self.take_statistics()?;
            for slot in &mut self.slots {
                if slot.active() && slot.state.updates % slot.config.log_every == 0 {
                    slot.write_train_row(&self.stat_names)?;
                }
            }
        }
        Ok(())
    }

    /// Downloads the statistics of the pending updates (one transfer) into each run's sums
    /// for its next `train.csv` row. A run with a non-finite one stops there, with the update
    /// it came from: alone in a stack, the whole training when it is solo.
    fn take_statistics(&mut self) -> Result<(), TrainError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let (stats, counters): (Vec<Stats>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .map(|update| (update.stats, update.counters))
            .unzip();
        let values = Stats::download(&stats);
        let solo = self.slots.len() == 1;
        for (counters, runs) in counters.iter().zip(values) {
            for ((slot, counters), stats) in self.slots.iter_mut().zip(counters).zip(runs) {
                let Some((updates, env_steps)) = *counters else {
                    continue;
                };
                if !slot.active() {
                    continue;
                }
                if let Some((name, value)) = stats.iter().find(|(_, v)| !v.is_finite()) {
                    let error = TrainError::NonFinite {
                        run: slot.run.display().to_string(),
                        statistic: name,
                        value: *value,
                        update: updates,
                        env_steps,
                    };
                    slot.stop(error, solo)?;
                    continue;
                }
                for (name, value) in stats {
                    let k = self
                        .stat_names
                        .iter()
                        .position(|n| *n == name)
                        .ok_or(TrainError::UndeclaredStatistic(name))?;
                    slot.state.stat_sums[k] += value;
                    slot.state.stat_counts[k] += 1;
                }
            }
        }
        Ok(())
    }

    fn evaluate_now(&mut self, i: usize) -> Result<EvalResult, TrainError> {
        let slot = &self.slots[i];
        let seed = seeds::evaluation(slot.config.seed, slot.state.evals_done);
        let (agent, config) = (&mut self.agent, &slot.config);
        let result = evaluate(
            agent.as_mut(),
            EvalPolicy::Regular { run: i },
            config.task,
            &config.delay,
            config.delay_device,
            config.eval_episodes,
            config.threads,
            seed,
        )?;
        self.slots[i].record_eval(result)?;
        Ok(result)
    }

    /// Trains to the configured step count, the whole loop on a learner thread: acting and
    /// updating, nearly all of a step, are learner work, which a loop elsewhere would hand over
    /// and wait for twice a step (measured in docs/results/performance-amd-epyc.md).
    fn run(self, show_progress: bool) -> Result<Vec<Result<TrainSummary, TrainError>>, TrainError> {
        let pool = Arc::clone(&self.learner_pool);
        pool.install(move || self.run_here(show_progress))
    }

    fn run_here(
        mut self,
        show_progress: bool,
    ) -> Result<Vec<Result<TrainSummary, TrainError>>, TrainError> {
        debug_assert!(self.learner_pool.current_thread_index().is_some());
        // The runs share one schedule: every counter below moves alike in each of them.
        let c = self.slots[0].config.clone();
        let bar = Progress::new(
            c.steps,
            "{bar:30} {pos}/{len} steps  {per_sec}  ETA {eta}  {msg}",
            show_progress,
        );
        bar.set_position(self.slots[0].state.env_steps);
        let session_start = Instant::now();
        let walls_at_start: Vec<f64> = self.slots.iter().map(|s| s.state.wall_seconds).collect();
        let set_walls = |slots: &mut [RunSlot]| {
            let elapsed = session_start.elapsed().as_secs_f64();
            for (slot, wall) in slots.iter_mut().zip(&walls_at_start) {
                if slot.active() {
                    slot.state.wall_seconds = wall + elapsed;
                }
            }
        };
        while self.slots[0].state.env_steps < c.steps && self.slots.iter().any(RunSlot::active) {
            let actions = self.choose_actions()?;
            for (slot, actions) in self.slots.iter_mut().zip(actions) {
                if !slot.active() {
                    continue;
                }
                slot.batch.step(&actions)?;
                let count = slot.replay.push_step(&slot.batch)?;
                if count > 0 {
                    slot.state.diverged_episodes += count;
                    bar.suspend(|| {
                        eprintln!(
                            "warning: {}: step {}: {count} training episode(s) ended because \
                             MuJoCo found the simulation unstable (a bad qpos, qvel or qacc) and \
                             reset it; the step is kept out of the replay ({} so far, in \
                             train.csv)",
                            slot.run.display(),
                            slot.state.env_steps + c.envs as u64,
                            slot.state.diverged_episodes
                        )
                    });
                }
            }
            for slot in &mut self.slots {
                slot.state.env_steps += c.envs as u64;
            }
            let env_steps = self.slots[0].state.env_steps;
            bar.set_position(env_steps);
            set_walls(&mut self.slots);
            let learning = env_steps >= c.first_update_step()
                && self
                    .slots
                    .iter()
                    .all(|slot| slot.replay.len() >= c.min_replay_steps);
            if learning {
                // One block of `update_every × updates_per_step` updates each time the step
                // count passes a multiple of `update_every` (every step's share when it is 1).
                let blocks =
                    env_steps / c.update_every - (env_steps - c.envs as u64) / c.update_every;
                let owed = (blocks * c.update_every) as f64 * c.updates_per_step;
                for slot in &mut self.slots {
                    slot.state.update_debt += owed;
                }
                while self.slots[0].state.update_debt >= 1.0 {
                    for slot in &mut self.slots {
                        slot.state.update_debt -= 1.0;
                    }
                    self.update()?;
                }
            }
            set_walls(&mut self.slots);
            let finished = env_steps >= c.steps;
            // A run whose statistics turned non-finite stops before it is evaluated or saved:
            // the pending ones are taken first.
            if env_steps / c.eval_every > self.slots[0].state.evals_done || finished {
                self.take_statistics()?;
                let mut message = Vec::new();
                for i in 0..self.slots.len() {
                    if !self.slots[i].active() {
                        continue;
                    }
                    let result = self.evaluate_now(i)?;
                    message.push(format!(
                        "{:.1} ± {:.1}",
                        result.return_mean, result.return_std
                    ));
                }
                for slot in &mut self.slots {
                    slot.state.evals_done = env_steps / c.eval_every;
                }
                bar.set_message(format!("eval {}", message.join(", ")));
            }
            let scheduled = env_steps / c.checkpoint_every > self.slots[0].state.checkpoints_done;
            if scheduled || finished || stop_requested() {
                self.take_statistics()?;
                for slot in &mut self.slots {
                    slot.state.checkpoints_done = env_steps / c.checkpoint_every;
                }
                self.save_checkpoint()?;
            }
            if stop_requested() && !finished {
                bar.abandon();
                return Err(TrainError::Interrupted {
                    run: self.resume_target.display().to_string(),
                    env_steps,
                });
            }
        }
        bar.finish();
        Ok(self.slots.into_iter().map(RunSlot::summary).collect())
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
    let config = TrainConfig::from_toml_file(&run.join("config.toml"), None)?;
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

/// The environment steps of `run`'s latest checkpoint; `None` without one.
pub fn checkpoint_step(run: &Path) -> Option<u64> {
    checkpoint_steps(run).ok().map(|(_, steps)| steps)
}

/// `run`'s latest checkpoint folder and its environment steps.
fn checkpoint_steps(run: &Path) -> Result<(PathBuf, u64), TrainError> {
    let dir = checkpoint::latest(run)
        .ok_or_else(|| TrainError::NoCheckpoint(run.display().to_string()))?;
    let env_steps = checkpoint::env_steps(&dir)?;
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
    let config = TrainConfig::from_toml_file(&run.join("config.toml"), None)?;
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
        EvalPolicy::Regular { run: 0 }
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
