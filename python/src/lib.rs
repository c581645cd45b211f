//! `dhrl._dhrl`: the batched delayed tasks of the `dhrl` library as one Python class. It only
//! moves arrays across: every semantic (delay layer, warm-up, autoreset, records) is the
//! library's [`DelayedBatch`], the path training runs; `dhrl/vector.py` builds Gymnasium's
//! interface on top. Whatever runs on the caller's thread runs under a [`FlushGuard`]: dhrl's
//! float mode while it runs, the caller's own restored when it returns.
use std::str::FromStr;
use std::sync::Mutex;

use dhrl::delay::{DelayConfig, DelayDevice, DelayedBatch, WarmupActions};
use dhrl::float_mode::FlushGuard;
use dhrl::seeds;
use dhrl::sim::{BatchConfig, CopyStep};
use dhrl::tasks::TaskName;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The copies and the buffers one step reuses.
struct Core {
    batch: DelayedBatch,
    config: BatchConfig,
    delay: DelayConfig,
    /// `[N, act]`: the actions applied by the last step (warm-up rows filled in).
    actions: Vec<f32>,
    controls: Vec<CopyStep>,
}

impl Core {
    fn build(config: BatchConfig, delay: DelayConfig) -> PyResult<Core> {
        let _mode = FlushGuard::new();
        let batch = DelayedBatch::new(
            &config,
            &delay,
            DelayDevice::Cpu,
            seeds::delay_layer(config.seed),
        )
        .map_err(value_error)?;
        let (n, act) = (batch.env().len(), batch.env().act_dim());
        Ok(Core {
            batch,
            config,
            delay,
            actions: vec![0.0; n * act],
            controls: vec![CopyStep::Step; n],
        })
    }

    /// One step of every copy with `actions` (warm-up rows filled in) and `controls`, in
    /// dhrl's float mode: what `Batch.step` and `Batch.time_native_steps` both run.
    fn step(&mut self) -> PyResult<()> {
        let _mode = FlushGuard::new();
        let Core {
            batch,
            actions,
            controls,
            ..
        } = self;
        batch
            .layer_mut()
            .fill_warmup(actions)
            .map_err(value_error)?;
        batch.step_each(actions, controls).map_err(value_error)
    }
}

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// N copies of one task under one delay, as the delayed agent lives in them.
#[pyclass(module = "dhrl._dhrl")]
struct Batch {
    core: Mutex<Core>,
    task: TaskName,
    num_envs: usize,
    obs_dim: usize,
    act_dim: usize,
    delay: usize,
}

fn f32_rows<'py>(
    py: Python<'py>,
    values: Vec<f32>,
    width: usize,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let rows = if width == 0 { 0 } else { values.len() / width };
    values
        .into_pyarray(py)
        .reshape([rows, width])
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

fn flags<'py>(py: Python<'py>, values: &[u32]) -> Bound<'py, PyArray1<bool>> {
    values
        .iter()
        .map(|&v| v != 0)
        .collect::<Vec<bool>>()
        .into_pyarray(py)
}

#[pymethods]
impl Batch {
    /// `task`: a dhrl name (`half-cheetah`) or a Gymnasium id (`HalfCheetah-v4`); the delays
    /// and options as `dhrl train` takes them (checked by the library).
    #[new]
    #[pyo3(signature = (task, num_envs, delay, action_delay, max_delay, actuator_noise, warmup, seed, num_threads))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        task: &str,
        num_envs: usize,
        delay: usize,
        action_delay: usize,
        max_delay: Option<usize>,
        actuator_noise: f64,
        warmup: &str,
        seed: u64,
        num_threads: usize,
    ) -> PyResult<Batch> {
        let task = TaskName::from_str(task).map_err(value_error)?;
        let warmup = match warmup {
            "zeros" => WarmupActions::Zeros,
            "random" => WarmupActions::Random,
            other => {
                return Err(PyValueError::new_err(format!(
                    "warmup is {other:?}; accepted: \"zeros\" or \"random\""
                )));
            }
        };
        let delay_config = DelayConfig {
            observation_delay: delay,
            action_delay,
            random_delay: max_delay.is_some(),
            max_random_delay: max_delay,
            actuator_noise,
            warmup,
        };
        let total = delay_config.total_delay().map_err(value_error)?;
        let config = BatchConfig {
            task,
            envs: num_envs,
            threads: num_threads,
            seed,
            actuator_noise,
        };
        let core = Core::build(config, delay_config)?;
        Ok(Batch {
            num_envs,
            obs_dim: core.batch.env().obs_dim(),
            act_dim: core.batch.env().act_dim(),
            core: Mutex::new(core),
            task,
            delay: total,
        })
    }

    #[getter]
    fn task(&self) -> &'static str {
        self.task.as_str()
    }
    #[getter]
    fn gymnasium_id(&self) -> &'static str {
        self.task.gymnasium_id()
    }
    #[getter]
    fn num_envs(&self) -> usize {
        self.num_envs
    }
    #[getter]
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }
    #[getter]
    fn act_dim(&self) -> usize {
        self.act_dim
    }
    /// Δ: the total delay the agent sees (a random delay counts as its bound).
    #[getter]
    fn delay(&self) -> usize {
        self.delay
    }
    #[getter]
    fn augmented_dim(&self) -> usize {
        self.obs_dim + self.delay * self.act_dim
    }
    /// Per worker thread of the copies' pool, whether it flushes subnormal floats (the caller's
    /// own thread is left as it was).
    fn workers_flush_subnormals(&self) -> PyResult<Vec<bool>> {
        Ok(self.lock()?.batch.env().workers_flush_subnormals())
    }
    #[getter]
    fn num_threads(&self) -> PyResult<usize> {
        Ok(self.lock()?.batch.env().threads())
    }
    /// `(low, high)` of each action dimension.
    fn action_bounds<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
        let core = self.lock()?;
        let (low, high) = core.batch.env().action_bounds();
        Ok((
            low.to_vec().into_pyarray(py),
            high.to_vec().into_pyarray(py),
        ))
    }

    /// Rebuilds every copy from `seed` (initial states, actuator noise, warm-up actions and
    /// random delays all follow from it): the state of a fresh `Batch` with that seed.
    fn reseed<'py>(&self, py: Python<'py>, seed: u64) -> PyResult<Bound<'py, PyDict>> {
        let mut core = self.lock()?;
        let (config, delay) = (
            BatchConfig {
                seed,
                ..core.config.clone()
            },
            core.delay,
        );
        *core = py.detach(|| Core::build(config, delay))?;
        current(py, &core)
    }

    /// Starts every copy's episode from `(qpos, qvel)` (Gymnasium's `set_state`), the delay
    /// layer with them: the next step is step 1 of the new episodes.
    fn set_state<'py>(
        &self,
        py: Python<'py>,
        qpos: Vec<f64>,
        qvel: Vec<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut core = self.lock()?;
        {
            let _mode = FlushGuard::new();
            core.batch.restart_from(&qpos, &qvel).map_err(value_error)?;
        }
        current(py, &core)
    }

    /// What the agent holds now, without stepping.
    fn current<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let core = self.lock()?;
        current(py, &core)
    }

    /// Seconds `steps` steps of every copy take inside the library, actions cycling through the
    /// `[K, N, act]` float32 table, each step the one [`Batch::step`] runs, with nothing built
    /// for Python: the native rate `python/benchmarks/env_throughput.py` sets the Python
    /// path beside, in the same process.
    fn time_native_steps(
        &self,
        py: Python<'_>,
        actions: numpy::PyReadonlyArray3<'_, f32>,
        steps: usize,
    ) -> PyResult<f64> {
        let mut guard = self.lock()?;
        let core = &mut *guard;
        let table = actions.as_slice().map_err(value_error)?;
        let row = core.actions.len();
        if row == 0 || table.is_empty() || table.len() % row != 0 {
            return Err(PyValueError::new_err(format!(
                "actions hold {} values; expected [K, {}, {}] with K ≥ 1",
                table.len(),
                self.num_envs,
                self.act_dim
            )));
        }
        core.controls.fill(CopyStep::Step);
        py.detach(|| -> PyResult<f64> {
            let rows = table.len() / row;
            let start = std::time::Instant::now();
            for k in 0..steps {
                let at = (k % rows) * row;
                core.actions.copy_from_slice(&table[at..at + row]);
                core.step()?;
            }
            Ok(start.elapsed().as_secs_f64())
        })
    }

    /// One step of every copy. `actions`: `[N, act]` float32, all finite (checked: nothing is
    /// stepped otherwise); the rows of copies still in warm-up are replaced by warm-up actions.
    /// `controls`: `[N]` uint8 (0 step, 1 hold, 2 restart), every copy stepping when `None`.
    #[pyo3(signature = (actions, controls=None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: PyReadonlyArray2<'py, f32>,
        controls: Option<PyReadonlyArray1<'py, u8>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut guard = self.lock()?;
        let core = &mut *guard;
        let given = actions.as_slice().map_err(value_error)?;
        if given.len() != core.actions.len() {
            return Err(PyValueError::new_err(format!(
                "actions hold {} values; expected {} ({} copies × {} action dimensions)",
                given.len(),
                core.actions.len(),
                self.num_envs,
                self.act_dim
            )));
        }
        if let Some(at) = given.iter().position(|v| !v.is_finite()) {
            let value = match given[at] {
                v if v.is_nan() => "nan",
                v if v > 0.0 => "inf",
                _ => "-inf",
            };
            return Err(PyValueError::new_err(format!(
                "actions[{}, {}] is {value}; only finite numbers are accepted (nothing was stepped)",
                at / self.act_dim,
                at % self.act_dim
            )));
        }
        core.actions.copy_from_slice(given);
        match controls {
            None => core.controls.fill(CopyStep::Step),
            Some(controls) => {
                let controls = controls.as_slice().map_err(value_error)?;
                if controls.len() != self.num_envs {
                    return Err(PyValueError::new_err(format!(
                        "{} copy controls; expected one per copy ({})",
                        controls.len(),
                        self.num_envs
                    )));
                }
                for (slot, &code) in core.controls.iter_mut().zip(controls) {
                    *slot = match code {
                        0 => CopyStep::Step,
                        1 => CopyStep::Hold,
                        2 => CopyStep::Restart,
                        other => {
                            return Err(PyValueError::new_err(format!(
                                "copy control {other}; accepted: 0 (step), 1 (hold), 2 (restart)"
                            )));
                        }
                    };
                }
            }
        }
        py.detach(|| core.step())?;
        stepped(py, core)
    }
}

impl Batch {
    fn lock(&self) -> PyResult<std::sync::MutexGuard<'_, Core>> {
        self.core.lock().map_err(|_| {
            PyRuntimeError::new_err("an earlier step panicked; build a new environment")
        })
    }
}

/// `augmented`, `ready` and `state` of every copy.
fn current<'py>(py: Python<'py>, core: &Core) -> PyResult<Bound<'py, PyDict>> {
    let (layer, env) = (core.batch.layer(), core.batch.env());
    let out = PyDict::new(py);
    let aug = core.batch.layout().augmented_dim();
    out.set_item("augmented", f32_rows(py, layer.augmented().to_vec(), aug)?)?;
    out.set_item("ready", flags(py, layer.ready()))?;
    out.set_item(
        "state",
        f32_rows(py, env.observations().to_vec(), env.obs_dim())?,
    )?;
    Ok(out)
}

/// Everything the last step produced, as NumPy arrays that own their memory.
fn stepped<'py>(py: Python<'py>, core: &Core) -> PyResult<Bound<'py, PyDict>> {
    let out = current(py, core)?;
    let (layer, env, layout) = (core.batch.layer(), core.batch.env(), core.batch.layout());
    let (n, obs, act, aug) = (
        env.len(),
        layout.obs_dim,
        layout.act_dim,
        layout.augmented_dim(),
    );
    let records = layer.records();
    let rewards: Vec<f32> = (0..n).map(|i| records.delivered_reward(i)).collect();
    let mut final_augmented = Vec::with_capacity(n * aug);
    for i in 0..n {
        if !records.push_final_augmented(i, &mut final_augmented) {
            final_augmented.resize(final_augmented.len() + aug, 0.0);
        }
    }
    out.set_item("reward", rewards.into_pyarray(py))?;
    out.set_item("terminated", flags(py, env.terminated()))?;
    out.set_item("truncated", flags(py, env.truncated()))?;
    // Their union and whether it holds anywhere, so that the wrapper's every step needs no
    // numpy operation of its own to learn whether an episode ended.
    let done: Vec<bool> = (env.terminated().iter().zip(env.truncated()))
        .map(|(&t, &u)| t != 0 || u != 0)
        .collect();
    out.set_item("ended", done.contains(&true))?;
    out.set_item("done", done.into_pyarray(py))?;
    out.set_item("diverged", flags(py, env.diverged()))?;
    out.set_item("final_augmented", f32_rows(py, final_augmented, aug)?)?;
    out.set_item(
        "final_state",
        f32_rows(py, env.final_observations().to_vec(), obs)?,
    )?;
    out.set_item(
        "episode_return",
        env.episode_returns().to_vec().into_pyarray(py),
    )?;
    out.set_item(
        "episode_length",
        env.episode_lengths().to_vec().into_pyarray(py),
    )?;
    out.set_item("action", f32_rows(py, core.actions.clone(), act)?)?;
    let t = layer.transitions().map_err(value_error)?;
    let transitions = PyDict::new(py);
    let copies: Vec<i64> = t.copy.iter().map(|&c| c as i64).collect();
    transitions.set_item("env", copies.into_pyarray(py))?;
    transitions.set_item("episode", t.episode.into_pyarray(py))?;
    transitions.set_item("tau", t.tau.into_pyarray(py))?;
    transitions.set_item("augmented", f32_rows(py, t.augmented, aug)?)?;
    transitions.set_item("state", f32_rows(py, t.state, obs)?)?;
    transitions.set_item("action", f32_rows(py, t.action, act)?)?;
    transitions.set_item("reward", t.reward.into_pyarray(py))?;
    transitions.set_item("next_augmented", f32_rows(py, t.next_augmented, aug)?)?;
    transitions.set_item("next_state", f32_rows(py, t.next_state, obs)?)?;
    transitions.set_item("terminated", flags(py, &t.terminated))?;
    out.set_item("transitions", transitions)?;
    Ok(out)
}

/// Environment steps per second of `copies` copies of `task` stepped in turn by bare `mj_step`
/// calls on this thread (the anchor of `dhrl bench env`); with `threads` above 1, that many such
/// loops at once on threads of their own, each over its share of the copies (the machine's
/// ceiling for a batch on that many threads).
#[pyfunction]
#[pyo3(signature = (task, copies, env_steps, threads = 1))]
fn raw_mj_step_rate(
    py: Python<'_>,
    task: &str,
    copies: usize,
    env_steps: usize,
    threads: usize,
) -> PyResult<f64> {
    let task = TaskName::from_str(task).map_err(value_error)?;
    if threads == 0 {
        return Err(PyValueError::new_err(
            "threads must be ≥ 1 (1: this thread; more: that many loops at once); got 0",
        ));
    }
    py.detach(|| {
        let _mode = FlushGuard::new();
        if threads == 1 {
            dhrl::bench::raw_mj_step_rate(task, copies, env_steps)
        } else {
            dhrl::bench::raw_parallel_rate(task, copies, threads, env_steps)
        }
        .map_err(value_error)
    })
}

/// Reads the task XMLs from `path` from now on (`dhrl/__init__.py` points it at the installed
/// Gymnasium's `envs/mujoco/assets`); `$DHRL_ASSETS_DIR` still wins.
#[pyfunction]
fn set_assets_dir(path: std::path::PathBuf) {
    dhrl::sim::set_assets_dir(path);
}

/// The folder the task XMLs are read from.
#[pyfunction]
fn assets_dir() -> String {
    dhrl::sim::assets_dir().display().to_string()
}

#[pymodule]
fn _dhrl(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Batch>()?;
    m.add_function(wrap_pyfunction!(raw_mj_step_rate, m)?)?;
    m.add_function(wrap_pyfunction!(set_assets_dir, m)?)?;
    m.add_function(wrap_pyfunction!(assets_dir, m)?)?;
    m.add(
        "TASKS",
        TaskName::ALL
            .iter()
            .map(|t| (t.as_str(), t.gymnasium_id()))
            .collect::<Vec<_>>(),
    )?;
    m.add("MAX_DELAY", dhrl::delay::MAX_DELAY)?;
    Ok(())
}
