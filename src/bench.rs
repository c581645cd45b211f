//! Throughput of the batched simulator against the anchors it is measured by, in the same
//! process: a plain single-thread loop of raw `mj_step` calls on one copy, the same loop over
//! all the batch's copies, and as many such loops at once as the batch has threads.
use std::sync::Arc;
use std::time::Instant;

use mujoco_rs::prelude::{MjData, MjModel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::sim::{BatchConfig, BatchedEnv, MAX_EPISODE_STEPS, SimError, TaskModel};
use crate::tasks::TaskName;

/// A batch of pre-drawn uniform random actions to cycle through, so that drawing them is not
/// part of what is timed.
pub struct ActionTable {
    rows: Vec<Vec<f32>>,
}

impl ActionTable {
    pub fn uniform(low: &[f64], high: &[f64], batch: usize, rows: usize, seed: u64) -> ActionTable {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let rows = (0..rows)
            .map(|_| {
                (0..batch)
                    .flat_map(|_| {
                        low.iter()
                            .zip(high)
                            .map(|(&l, &h)| rng.random_range(l..h) as f32)
                            .collect::<Vec<_>>()
                    })
                    .collect()
            })
            .collect();
        ActionTable { rows }
    }

    pub fn row(&self, step: usize) -> &[f32] {
        &self.rows[step % self.rows.len()]
    }
}

/// Environment steps per second of `copies` copies stepped in turn by bare `mj_step` calls on
/// this thread: random controls, `frame_skip` substeps per environment step, a reset to `qpos0`
/// when the task terminates or hits the time limit (so the copies go through episodes as a
/// batch's do, without its reset noise; written as dhrl writes it, [`TaskModel::reset_data`]),
/// and nothing else: no observation, reward, `mj_rnePostConstraint` or copying. One copy stays
/// hot in the core's caches; many copies (a batch's worth) do not, as in a batch.
pub fn raw_mj_step_rate(task: TaskName, copies: usize, env_steps: usize) -> Result<f64, SimError> {
    let seconds = RawLoop::new(task, copies)?.run(env_steps);
    Ok(env_steps as f64 / seconds)
}

/// Environment steps per second of `threads` such bare loops at once, each on an OS thread of
/// its own over its own share of `copies` (`env_steps` steps in all), started together and
/// never synchronised: what a batch on `threads` threads would reach on this machine if
/// stepping it cost nothing but `mj_step`, cores slowing each other down included (all steps
/// over the last loop's time).
pub fn raw_parallel_rate(
    task: TaskName,
    copies: usize,
    threads: usize,
    env_steps: usize,
) -> Result<f64, SimError> {
    let threads = threads.clamp(1, copies.max(1));
    let per_thread = env_steps.div_ceil(threads);
    let start = std::sync::Barrier::new(threads);
    let seconds = std::thread::scope(|scope| {
        let loops: Vec<_> = (0..threads)
            .map(|t| {
                let start = &start;
                // Copies dealt out as a batch deals them: the first `copies % threads` loops
                // get one more.
                let share = copies / threads + usize::from(t < copies % threads);
                scope.spawn(move || {
                    crate::float_mode::apply_to_this_thread();
                    let raw = RawLoop::new(task, share);
                    start.wait();
                    raw.map(|mut raw| raw.run(per_thread))
                })
            })
            .collect();
        loops
            .into_iter()
            .map(|handle| handle.join().expect("a raw mj_step loop panicked"))
            .try_fold(0.0f64, |slowest, seconds| Ok(slowest.max(seconds?)))
    })?;
    Ok((per_thread * threads) as f64 / seconds)
}

/// The bare loop of [`raw_mj_step_rate`]: its copies and their pre-drawn controls.
struct RawLoop {
    model: Arc<TaskModel>,
    data: Vec<MjData<Arc<MjModel>>>,
    actions: ActionTable,
}

impl RawLoop {
    fn new(task: TaskName, copies: usize) -> Result<RawLoop, SimError> {
        let model = TaskModel::load(task)?;
        let copies = copies.max(1);
        let actions = ActionTable::uniform(&model.action_low, &model.action_high, copies, 64, 7);
        let data = (0..copies)
            .map(|_| MjData::new(model.model.clone()))
            .collect();
        Ok(RawLoop {
            model,
            data,
            actions,
        })
    }

    /// Steps the copies in turn `env_steps` times; the seconds it took.
    fn run(&mut self, env_steps: usize) -> f64 {
        let def = self.model.task;
        let copies = self.data.len();
        let act = self.model.action_low.len();
        let mut elapsed = vec![0; copies];
        let start = Instant::now();
        for step in 0..env_steps {
            let (i, round) = (step % copies, step / copies);
            let d = &mut self.data[i];
            for (c, &a) in d
                .ctrl_mut()
                .iter_mut()
                .zip(&self.actions.row(round)[i * act..(i + 1) * act])
            {
                *c = a as f64;
            }
            for _ in 0..def.frame_skip {
                d.step();
            }
            elapsed[i] += 1;
            if (def.terminated)(d) || elapsed[i] >= MAX_EPISODE_STEPS {
                self.model.reset_data(d);
                d.forward();
                elapsed[i] = 0;
            }
        }
        start.elapsed().as_secs_f64()
    }
}

/// The machine a measurement ran on: every `dhrl bench` report names it.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// The CPU's model name (`/proc/cpuinfo`), or "unknown".
    pub cpu: String,
    pub cores: usize,
    /// Whether the measuring threads flush subnormal floats ([`crate::float_mode`]).
    pub flush_subnormals: bool,
}

impl Machine {
    pub fn here() -> Machine {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|info| {
                info.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, name)| name.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".into());
        Machine {
            cpu,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            flush_subnormals: crate::float_mode::flushing(),
        }
    }
}

impl std::fmt::Display for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({} cores), subnormals flushed: {}",
            self.cpu,
            self.cores,
            if self.flush_subnormals { "yes" } else { "no" }
        )
    }
}

/// A batch without actuator noise and 16 rows of random actions to cycle through.
fn noiseless_batch(
    task: TaskName,
    envs: usize,
    threads: usize,
    seed: u64,
) -> Result<(BatchedEnv, ActionTable), SimError> {
    let batch = BatchedEnv::new(&BatchConfig {
        task,
        envs,
        threads,
        seed,
        actuator_noise: 0.0,
    })?;
    let (low, high) = batch.action_bounds();
    let actions = ActionTable::uniform(low, high, envs, 16, seed);
    Ok((batch, actions))
}

/// The figures `dhrl bench env` prints.
#[derive(Debug, Clone, Serialize)]
pub struct EnvBenchReport {
    pub task: TaskName,
    pub envs: usize,
    pub threads: usize,
    /// Total delay Δ of the timed batch (0: the simulator alone; above: the delayed batch of
    /// training, delay layer on the CPU, random warm-up actions).
    pub delay: usize,
    pub steps: usize,
    pub env_steps_per_sec: f64,
    /// The anchor: one copy, bare `mj_step`, one thread, hot in cache.
    pub raw_env_steps_per_sec: f64,
    /// `env_steps_per_sec / raw_env_steps_per_sec`; the ideal is the thread count.
    pub ratio: f64,
    /// The same bare loop over `envs` copies in turn on one thread: what the physics costs
    /// once a batch's copies no longer fit in the core's caches.
    pub raw_batch_env_steps_per_sec: f64,
    /// `env_steps_per_sec / raw_batch_env_steps_per_sec`.
    pub ratio_to_raw_batch: f64,
    /// The machine's ceiling for the batch: `threads` bare loops at once, each over its own
    /// share of the `envs` copies ([`raw_parallel_rate`]).
    pub raw_parallel_env_steps_per_sec: f64,
    /// `env_steps_per_sec / raw_parallel_env_steps_per_sec`: what dhrl's batching, delay
    /// layer and synchronisation leave of the ceiling.
    pub ratio_to_raw_parallel: f64,
    pub episodes_finished: u64,
    #[serde(flatten)]
    pub machine: Machine,
}

/// Steps a batch of `envs` copies (under delay `delay` when above 0) `steps` times with random
/// actions, then times the raw single-thread `mj_step` loops (one copy, and `envs` copies) over
/// one thread's share of those environment steps (at least 1,000), and `threads` raw loops at
/// once over as many steps each, so every side runs for about as long.
pub fn bench_env(
    task: TaskName,
    envs: usize,
    threads: usize,
    delay: usize,
    steps: usize,
    seed: u64,
) -> Result<EnvBenchReport, BenchError> {
    use crate::delay::{DelayConfig, DelayDevice, DelayedBatch, WarmupActions};
    let config = BatchConfig {
        task,
        envs,
        threads,
        seed,
        actuator_noise: 0.0,
    };
    let delay_config = DelayConfig {
        warmup: WarmupActions::Random,
        ..DelayConfig::fixed(delay)
    };
    let mut batch = DelayedBatch::new(&config, &delay_config, DelayDevice::Cpu, seed)?;
    let (low, high) = batch.env().action_bounds();
    let actions = ActionTable::uniform(low, high, envs, 16, seed);
    let mut row = actions.row(0).to_vec();
    let mut step = |batch: &mut DelayedBatch, k: usize| -> Result<(), BenchError> {
        row.copy_from_slice(actions.row(k));
        batch.layer_mut().fill_warmup(&mut row)?;
        Ok(batch.step(&row)?)
    };
    // Warm up caches and the pool before timing.
    step(&mut batch, 0)?;
    let mut episodes_finished = 0u64;
    let start = Instant::now();
    for k in 0..steps {
        step(&mut batch, k + 1)?;
        let env = batch.env();
        episodes_finished += env
            .terminated()
            .iter()
            .zip(env.truncated())
            .filter(|(t, u)| **t + **u > 0)
            .count() as u64;
    }
    let env_steps_per_sec = (envs * steps) as f64 / start.elapsed().as_secs_f64();
    let raw_steps = (envs * steps / threads).max(1000);
    let raw_env_steps_per_sec = raw_mj_step_rate(task, 1, raw_steps)?;
    let raw_batch_env_steps_per_sec = raw_mj_step_rate(task, envs, raw_steps)?;
    let raw_parallel_env_steps_per_sec =
        raw_parallel_rate(task, envs, threads, raw_steps * threads)?;
    Ok(EnvBenchReport {
        task,
        envs,
        threads,
        delay,
        steps,
        env_steps_per_sec,
        raw_env_steps_per_sec,
        ratio: env_steps_per_sec / raw_env_steps_per_sec,
        raw_batch_env_steps_per_sec,
        ratio_to_raw_batch: env_steps_per_sec / raw_batch_env_steps_per_sec,
        raw_parallel_env_steps_per_sec,
        ratio_to_raw_parallel: env_steps_per_sec / raw_parallel_env_steps_per_sec,
        episodes_finished,
        machine: Machine::here(),
    })
}

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Batch(#[from] crate::delay::BatchError),
    #[error(transparent)]
    Delay(#[from] crate::delay::DelayError),
    #[error(transparent)]
    Gpu(#[from] crate::delay::GpuError),
}

/// One row of `dhrl bench delay`.
#[derive(Debug, Clone, Serialize)]
pub struct DelayBenchRow {
    pub task: TaskName,
    pub envs: usize,
    pub delay: usize,
    /// Batched simulator steps per second (copies × steps / s), delay layer excluded.
    pub sim_env_steps_per_sec: f64,
    /// Delay-layer-only throughput on the CPU, in environment steps per second.
    pub cpu_env_steps_per_sec: f64,
    /// The CPU delay layer's time as a share of a full batched simulation step.
    pub cpu_share_of_sim_step: f64,
    /// Same on the GPU (upload, kernel, completion; no readback), when an adapter exists.
    pub gpu_env_steps_per_sec: Option<f64>,
    pub gpu_share_of_sim_step: Option<f64>,
    pub gpu_adapter: Option<String>,
}

/// Times the delay layer alone, on the CPU and (when an adapter exists) on the GPU, fed with
/// the outputs of a real batched simulation, beside the simulation step itself.
pub fn bench_delay(
    task: TaskName,
    envs: usize,
    delays: &[usize],
    threads: usize,
    steps: usize,
    seed: u64,
) -> Result<Vec<DelayBenchRow>, BenchError> {
    use crate::delay::{CpuDelayLayer, DelayConfig, DelayLayer, GpuDelayLayer, StepInput};
    let (mut batch, actions) = noiseless_batch(task, envs, threads, seed)?;
    let (low, high) = (
        batch.action_bounds().0.to_vec(),
        batch.action_bounds().1.to_vec(),
    );
    let obs_dim = batch.obs_dim();
    let mut cpu = Vec::new();
    let mut gpu = Vec::new();
    for &delay in delays {
        let config = DelayConfig::fixed(delay);
        let mut layer = CpuDelayLayer::new(&config, envs, obs_dim, &low, &high, seed)?;
        layer.reset(batch.observations())?;
        cpu.push(layer);
        // No adapter is not an error here: the GPU columns stay empty.
        if let Ok(mut layer) = GpuDelayLayer::new(&config, envs, obs_dim, &low, &high, seed) {
            layer.reset_device(batch.observations())?;
            gpu.push(layer);
        }
    }
    let (mut sim_time, mut cpu_time, mut gpu_time) =
        (0.0, vec![0.0; delays.len()], vec![0.0; delays.len()]);
    // Run the pools once before timing.
    batch.step(actions.row(0))?;
    for step in 0..steps {
        let row = actions.row(step + 1);
        let start = Instant::now();
        batch.step(row)?;
        sim_time += start.elapsed().as_secs_f64();
        let input = StepInput::from_env(&batch, row);
        for (i, layer) in cpu.iter_mut().enumerate() {
            let start = Instant::now();
            layer.step(&input)?;
            cpu_time[i] += start.elapsed().as_secs_f64();
        }
        for (i, layer) in gpu.iter_mut().enumerate() {
            let start = Instant::now();
            // The kernel alone: the training path also reads the outputs back.
            layer.step_device(&input)?;
            layer.wait()?;
            gpu_time[i] += start.elapsed().as_secs_f64();
        }
    }
    let env_steps = (envs * steps) as f64;
    Ok(delays
        .iter()
        .enumerate()
        .map(|(i, &delay)| DelayBenchRow {
            task,
            envs,
            delay,
            sim_env_steps_per_sec: env_steps / sim_time,
            cpu_env_steps_per_sec: env_steps / cpu_time[i],
            cpu_share_of_sim_step: cpu_time[i] / sim_time,
            gpu_env_steps_per_sec: gpu.get(i).map(|_| env_steps / gpu_time[i]),
            gpu_share_of_sim_step: gpu.get(i).map(|_| gpu_time[i] / sim_time),
            gpu_adapter: gpu.get(i).map(|layer| layer.adapter_name().to_string()),
        })
        .collect())
}

/// The figures `dhrl bench update` prints.
#[derive(Debug, Clone, Serialize)]
pub struct UpdateBenchReport {
    pub algo: &'static str,
    pub task: TaskName,
    pub delay: usize,
    pub batch_size: usize,
    pub device: crate::learn::LearnDevice,
    /// Rayon threads the updates ran on (the algorithm's learner count, as in training).
    pub threads: usize,
    pub updates: usize,
    pub updates_per_sec: f64,
    pub ms_per_update: f64,
    #[serde(flatten)]
    pub machine: Machine,
}

/// Gradient updates per second of `algo` at the sizes of `task` under delay `delay`, on
/// random batches (the update's cost does not depend on the values), on as many threads as
/// training gives the algorithm's learners unless `threads` says otherwise.
pub fn bench_update(
    algo: &crate::algos::AlgoSettings,
    task: TaskName,
    delay: usize,
    batch_size: usize,
    device: crate::learn::LearnDevice,
    threads: Option<usize>,
    updates: usize,
) -> Result<UpdateBenchReport, crate::train::TrainError> {
    use crate::algos::{AgentSpec, UpdateContext, random_batch};
    let spec = AgentSpec::for_task(task, delay)?;
    let devices = crate::learn::Devices::new(device)?;
    let mut agent = algo
        .schedule_within(updates as u64)
        .build(&spec, &devices, 0);
    let batch = random_batch(&spec, batch_size, 1);
    let threads = threads.unwrap_or(algo.info().learner_threads);
    let pool = crate::train::learner_pool(threads)?;
    let seconds = pool.install(|| {
        // One environment step per update, as training's default: work an agent schedules by
        // environment steps (VDPO's cloning stage) runs on its schedule, brought within the
        // timed updates in the same amount per step, and is in the mean.
        // The statistics stay on the device, as in training; downloading the last update's
        // waits for the device to finish the work queued (a GPU runs ahead of the host).
        let mut update =
            |k: usize| agent.update(&mut UpdateContext::fixed(&batch, k as u64, k as u64));
        update(0)?.values(); // warm-up: allocations, lazy initialisation
        let start = Instant::now();
        let mut last = None;
        for k in 0..updates {
            last = Some(update(k + 1)?);
        }
        if let Some(stats) = last {
            stats.values();
        }
        Ok::<f64, crate::delay::ReplayError>(start.elapsed().as_secs_f64())
    })?;
    Ok(UpdateBenchReport {
        algo: algo.name(),
        task,
        delay,
        batch_size,
        device,
        threads,
        updates,
        updates_per_sec: updates as f64 / seconds,
        ms_per_update: 1e3 * seconds / updates as f64,
        // The threads that ran the updates.
        machine: pool.install(Machine::here),
    })
}
