//! Helpers shared by the integration tests that train end to end.
#![allow(dead_code)] // each test file uses its own subset

pub mod slurm;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::Tensor;
use dhrl::algos::{Agent, AgentSpec, RunStats, UpdateContext};
use dhrl::delay::Transitions;
use dhrl::learn::to_vec;

/// Every float parameter of a module, flattened, in declaration order.
pub fn parameters<M: Module>(module: &M) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.extend(to_vec(param.val()));
        }
    }
    let mut all = Collect(Vec::new());
    module.visit(&mut all);
    all.0
}

/// Small agent sizes for the learners' tests: 3 observation entries, 2 action dimensions with
/// unequal bounds, a delay Δ.
pub fn small_spec(delay: usize) -> AgentSpec {
    AgentSpec {
        obs_dim: 3,
        act_dim: 2,
        delay,
        action_low: vec![-1.0, -2.0],
        action_high: vec![1.0, 2.0],
    }
}

/// One update of `agent` (a solo run) from exactly `batch`: its statistics, downloaded.
pub fn update(agent: &mut dyn Agent, batch: &Transitions) -> RunStats {
    agent
        .update(&mut UpdateContext::fixed(batch, 0, 0))
        .expect("a fixed batch is never empty")
        .values()
        .remove(0)
}

/// Runs the `dhrl` program with `args`, waiting for it.
pub fn dhrl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs `dhrl train ARGS --out RUN`, failing the test with its stderr if it fails.
pub fn train(args: &[&str], run: &Path) {
    let out = dhrl(&[&["train"], args, &["--out", run.to_str().unwrap()]].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Waits until the CSV log at `path` has a row below its header, polling every 5 ms: true
/// once it has, false if it has none within `within`.
pub fn wait_for_a_log_row(path: &Path, within: Duration) -> bool {
    let start = Instant::now();
    while std::fs::read_to_string(path).map_or(0, |t| t.lines().count()) < 2 {
        if start.elapsed() >= within {
            return false;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    true
}

/// Column `name` of a CSV file.
pub fn column(path: &Path, name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"));
    lines
        .map(|l| l.split(',').nth(k).unwrap().to_string())
        .collect()
}

/// The best evaluation `return_mean` of a run, and its `evals.csv` for messages.
pub fn best_return(run: &Path) -> (f64, String) {
    let evals = run.join("evals.csv");
    let best = column(&evals, "return_mean")
        .iter()
        .map(|v| v.parse::<f64>().unwrap())
        .fold(f64::MIN, f64::max);
    (best, std::fs::read_to_string(evals).unwrap())
}

/// Trains `algo` on InvertedPendulum under a fixed delay for the learning tests (8,000
/// steps, batch 64, seed 2, four evaluations of 5 episodes, the random warm-up with which
/// their bars were measured), with `extra` flags; returns the best evaluation.
pub fn learn_delayed_pendulum(algo: &str, delay: usize, extra: &[&str]) -> (f64, String) {
    let dir = tempfile::tempdir().unwrap();
    train_delayed_pendulum(&dir.path().join("run"), algo, delay, extra)
}

/// [`learn_delayed_pendulum`] into the run folder `run`, which the caller keeps (to read its
/// `train.csv`).
pub fn train_delayed_pendulum(
    run: &Path,
    algo: &str,
    delay: usize,
    extra: &[&str],
) -> (f64, String) {
    let delay = delay.to_string();
    let mut args = vec![
        "--task",
        "inverted-pendulum",
        "--algo",
        algo,
        "--delay",
        &delay,
        "--steps",
        "8000",
        "--warmup-steps",
        "500",
        "--eval-every",
        "2000",
        "--eval-episodes",
        "5",
        "--batch-size",
        "64",
        "--seed",
        "2",
        "--warmup",
        "random",
    ];
    args.extend_from_slice(extra);
    train(&args, run);
    best_return(run)
}

/// The columns of a CSV log that do not depend on timing (all but the wall-clock ones).
pub fn reproducible_columns(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let header = text.lines().next().unwrap();
    header
        .split(',')
        .filter(|c| !["wall_seconds", "env_steps_per_sec", "updates_per_sec"].contains(c))
        .map(String::from)
        .collect()
}
