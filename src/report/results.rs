//! The runs a report covers: run folders (`config.toml` + `evals.csv`), or sweep folders, whose
//! `runs/<id>/` folders with an evaluation are taken.
use std::path::{Path, PathBuf};

use super::ReportError;
use crate::algos::names;
use crate::protocol::Protocol;
use crate::tasks::TaskName;
use crate::train::{EvalRow, TrainConfig, read_evals};

/// A run folder's file naming the code it came from when that is not dhrl: its first line
/// (e.g. `authors' code, JongsooLee/DHRL 296ac7b`), for runs converted from another
/// implementation's logs (`scripts/authors_logs_to_runs.py`).
pub const IMPLEMENTATION_FILE: &str = "implementation.txt";

/// Which settings and code a run came from: dhrl under one of its protocols, or another
/// implementation run under that protocol's settings. Tables, aggregates and curves keep
/// variants apart.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Variant {
    pub protocol: Protocol,
    /// `None`: dhrl; else the implementation the run folder names.
    pub implementation: Option<String>,
}

impl Variant {
    /// `dhrl`, `authors`, or `authors (authors' code, …)`: the protocol, and the code where
    /// it is not dhrl.
    pub fn label(&self) -> String {
        match &self.implementation {
            None => self.protocol.name().to_string(),
            Some(code) => format!("{} ({code})", self.protocol),
        }
    }

    /// Its two CSV fields, `protocol,implementation` (`dhrl` for dhrl's own code; commas in
    /// an implementation's name become semicolons).
    pub fn csv_fields(&self) -> String {
        let code = self.implementation.as_deref().unwrap_or("dhrl");
        format!("{},{}", self.protocol, code.replace(',', ";"))
    }
}

/// The (algorithm, variant) pairs `runs` hold: algorithms in registry order, each one's
/// variants in order (dhrl's own code first).
pub fn entries<'a>(runs: impl IntoIterator<Item = &'a RunResult>) -> Vec<(&'static str, Variant)> {
    let present: std::collections::BTreeSet<(usize, Option<String>, Protocol)> = {
        let order = names();
        runs.into_iter()
            .map(|r| {
                let at = order
                    .iter()
                    .position(|a| *a == r.algorithm)
                    .unwrap_or(usize::MAX);
                (at, r.variant.implementation.clone(), r.variant.protocol)
            })
            .collect()
    };
    let order = names();
    present
        .into_iter()
        .filter_map(|(at, implementation, protocol)| {
            order.get(at).map(|a| {
                (
                    *a,
                    Variant {
                        protocol,
                        implementation,
                    },
                )
            })
        })
        .collect()
}

/// What a run's configuration puts it under: Table 1's cells are fixed delays without noise.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct Condition {
    /// Δ, or the bound of random delays.
    pub delay: usize,
    pub random_delay: bool,
    pub actuator_noise: f64,
}

impl Condition {
    pub fn is_table1(&self) -> bool {
        !self.random_delay && self.actuator_noise == 0.0
    }

    /// `fixed` or `random`, as the long-format CSV writes it.
    pub fn delay_kind(&self) -> &'static str {
        if self.random_delay { "random" } else { "fixed" }
    }

    /// How tables and figure titles name it: `Δ = 10`, `Δ = 10, σ = 0.1`, `random Δ ≤ 10`.
    pub fn label(&self) -> String {
        let delay = if self.random_delay {
            format!("random Δ ≤ {}", self.delay)
        } else {
            format!("Δ = {}", self.delay)
        };
        self.with_noise(delay, ", σ = ")
    }

    /// How file names carry it: `d10`, `d10-noise0.1`, `random-d10`.
    pub fn slug(&self) -> String {
        let delay = if self.random_delay {
            format!("random-d{}", self.delay)
        } else {
            format!("d{}", self.delay)
        };
        self.with_noise(delay, "-noise")
    }

    /// `delay`, followed by `prefix` and σ where there is actuator noise.
    fn with_noise(&self, delay: String, prefix: &str) -> String {
        if self.actuator_noise > 0.0 {
            format!("{delay}{prefix}{}", self.actuator_noise)
        } else {
            delay
        }
    }

    /// Fixed delays before random ones, then by Δ, then by σ.
    pub fn order(&self, other: &Condition) -> std::cmp::Ordering {
        (self.random_delay, self.delay)
            .cmp(&(other.random_delay, other.delay))
            .then(self.actuator_noise.total_cmp(&other.actuator_noise))
    }
}

/// One run's evaluations.
#[derive(Debug, Clone)]
pub struct RunResult {
    pub folder: PathBuf,
    pub task: TaskName,
    pub algorithm: &'static str,
    pub condition: Condition,
    pub seed: u64,
    pub variant: Variant,
    /// The run's whole configuration but its seed (runs differing in more than the seed are
    /// other settings).
    pub setting: String,
    pub evals: Vec<EvalRow>,
}

impl RunResult {
    /// Whether the run is of `algorithm` in `variant`.
    pub fn is(&self, algorithm: &str, variant: &Variant) -> bool {
        self.algorithm == algorithm && self.variant == *variant
    }

    /// The last evaluation's step and mean return.
    pub fn final_eval(&self) -> (u64, f64) {
        let last = self
            .evals
            .last()
            .expect("runs without evaluations are skipped");
        (last.step, last.return_mean)
    }

    /// Wall-clock seconds per million environment steps, from the last evaluation.
    pub fn seconds_per_million(&self) -> Option<f64> {
        let last = self.evals.last()?;
        (last.step > 0).then(|| last.wall_seconds / last.step as f64 * 1e6)
    }
}

/// Every run under `inputs`, in the order given (a sweep's in manifest order). A folder that
/// is neither a run nor a sweep is an error; a run without an evaluation yet is skipped.
pub fn load_runs(inputs: &[PathBuf]) -> Result<(Vec<RunResult>, usize), ReportError> {
    let mut runs = Vec::new();
    let mut skipped = 0;
    for input in inputs {
        for folder in run_folders(input)? {
            match load_run(&folder)? {
                Some(run) => runs.push(run),
                None => skipped += 1,
            }
        }
    }
    if runs.is_empty() {
        return Err(ReportError::NoResults(format!(
            "none of {} holds a run with an evaluation (a run folder has config.toml and \
             evals.csv; a sweep folder has manifest.jsonl and runs/)",
            inputs
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok((runs, skipped))
}

fn run_folders(input: &Path) -> Result<Vec<PathBuf>, ReportError> {
    if input.join("config.toml").is_file() {
        return Ok(vec![input.to_path_buf()]);
    }
    if input.join("manifest.jsonl").is_file() {
        let sweep = crate::sweep::Sweep::open(input)?;
        return Ok(sweep
            .runs
            .iter()
            .map(|r| sweep.run_dir(r))
            .filter(|d| d.join("config.toml").is_file())
            .collect());
    }
    Err(ReportError::NoResults(format!(
        "{} is neither a run folder (config.toml, evals.csv) nor a sweep folder (manifest.jsonl)",
        input.display()
    )))
}

fn load_run(folder: &Path) -> Result<Option<RunResult>, ReportError> {
    let config = TrainConfig::from_toml_file(&folder.join("config.toml"), None)?;
    if !folder.join("evals.csv").is_file() {
        return Ok(None);
    }
    let evals = read_evals(folder)?;
    if evals.is_empty() {
        return Ok(None);
    }
    let delay = config.validate().map_err(crate::train::TrainError::from)?;
    let delay = config.delay.random_bound().unwrap_or(delay);
    let implementation = match std::fs::read_to_string(folder.join(IMPLEMENTATION_FILE)) {
        Ok(text) => text.lines().next().map(|line| line.trim().to_string()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            return Err(ReportError::Io {
                path: folder.join(IMPLEMENTATION_FILE).display().to_string(),
                message: e.to_string(),
            });
        }
    };
    Ok(Some(RunResult {
        folder: folder.to_path_buf(),
        task: config.task,
        algorithm: config.algo.name(),
        condition: Condition {
            delay,
            random_delay: config.delay.random_delay,
            actuator_noise: config.delay.actuator_noise,
        },
        seed: config.seed,
        variant: Variant {
            protocol: config.protocol,
            implementation,
        },
        setting: toml::to_string(&TrainConfig {
            seed: 0,
            ..config.clone()
        })
        .expect("a loaded configuration serialises"),
        evals,
    }))
}
