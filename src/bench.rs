//! Throughput of the batched simulator against the anchor it is measured by: a plain
//! single-thread loop of raw `mj_step` calls on one copy, in the same process.
use std::time::Instant;

use mujoco_rs::prelude::MjData;
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

/// Environment steps per second of one copy stepped by bare `mj_step` calls on this thread:
/// random controls, `frame_skip` substeps per environment step, `mj_resetData` when the task
/// terminates or hits the time limit (so the states visited match the batched run's), and
/// nothing else: no observation, reward, `mj_rnePostConstraint` or copying.
pub fn raw_mj_step_rate(task: TaskName, env_steps: usize) -> Result<f64, SimError> {
    let model = TaskModel::load(task)?;
    let def = model.task;
    let actions = ActionTable::uniform(&model.action_low, &model.action_high, 1, 64, 7);
    let mut data = MjData::new(model.model.clone());
    let mut elapsed = 0;
    let start = Instant::now();
    for step in 0..env_steps {
        for (c, &a) in data.ctrl_mut().iter_mut().zip(actions.row(step)) {
            *c = a as f64;
        }
        for _ in 0..def.frame_skip {
            data.step();
        }
        elapsed += 1;
        if (def.terminated)(&data) || elapsed >= MAX_EPISODE_STEPS {
            data.reset();
            data.forward();
            elapsed = 0;
        }
    }
    Ok(env_steps as f64 / start.elapsed().as_secs_f64())
}

/// The figures `dhrl bench env` prints.
#[derive(Debug, Clone, Serialize)]
pub struct EnvBenchReport {
    pub task: TaskName,
    pub envs: usize,
    pub threads: usize,
    pub steps: usize,
    pub env_steps_per_sec: f64,
    pub raw_env_steps_per_sec: f64,
    /// `env_steps_per_sec / raw_env_steps_per_sec`; the ideal is the thread count.
    pub ratio: f64,
    pub episodes_finished: u64,
}

/// Steps a batch of `envs` copies `steps` times with random actions, then times the raw
/// single-thread `mj_step` loop over one thread's share of those environment steps (at least
/// 1,000), so both sides run for about as long.
pub fn bench_env(
    task: TaskName,
    envs: usize,
    threads: usize,
    steps: usize,
    seed: u64,
) -> Result<EnvBenchReport, SimError> {
    let mut batch = BatchedEnv::new(&BatchConfig {
        task,
        envs,
        threads,
        seed,
        actuator_noise: 0.0,
    })?;
    let (low, high) = batch.action_bounds();
    let actions = ActionTable::uniform(low, high, envs, 16, seed);
    // Warm up caches and the pool before timing.
    batch.step(actions.row(0))?;
    let mut episodes_finished = 0u64;
    let start = Instant::now();
    for step in 0..steps {
        batch.step(actions.row(step + 1))?;
        episodes_finished += batch
            .terminated()
            .iter()
            .zip(batch.truncated())
            .filter(|(t, u)| **t + **u > 0)
            .count() as u64;
    }
    let env_steps_per_sec = (envs * steps) as f64 / start.elapsed().as_secs_f64();
    let raw_steps = (envs * steps / threads).max(1000);
    let raw_env_steps_per_sec = raw_mj_step_rate(task, raw_steps)?;
    Ok(EnvBenchReport {
        task,
        envs,
        threads,
        steps,
        env_steps_per_sec,
        raw_env_steps_per_sec,
        ratio: env_steps_per_sec / raw_env_steps_per_sec,
        episodes_finished,
    })
}
