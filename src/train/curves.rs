//! Learning curves of finished runs: `dhrl plot` reads each run's `config.toml` and
//! `evals.csv`, groups the runs by (task, algorithm, delay; D2HPG's λ and K too), averages the
//! seeds, draws the curves as SVG with plotters, and summarises the final evaluations.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{TrainConfig, TrainError, io_error};

/// One group of runs (the same task, algorithm, delay and lifting settings; several seeds).
#[derive(Debug, Clone, Serialize)]
pub struct CurveSummary {
    pub label: String,
    pub seeds: Vec<u64>,
    /// Evaluation steps present in every run of the group.
    pub steps: Vec<u64>,
    /// Mean over seeds of each evaluation's mean return.
    pub mean: Vec<f64>,
    /// Standard deviation over seeds (over a single run's episodes when there is one seed).
    pub std: Vec<f64>,
}

impl CurveSummary {
    /// `(step, mean, std)` of the last evaluation.
    pub fn last(&self) -> Option<(u64, f64, f64)> {
        let k = self.steps.len().checked_sub(1)?;
        Some((self.steps[k], self.mean[k], self.std[k]))
    }
}

/// One row of a run's `evals.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalRow {
    pub step: u64,
    /// Training wall-clock seconds up to this evaluation (carried across resumes).
    pub wall_seconds: f64,
    pub return_mean: f64,
    /// Over the evaluation's episodes.
    pub return_std: f64,
}

/// The rows of a run's `evals.csv`.
pub fn read_evals(run: &Path) -> Result<Vec<EvalRow>, TrainError> {
    let path = run.join("evals.csv");
    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    let bad = |line: usize| TrainError::Io {
        path: path.display().to_string(),
        message: format!("line {line} is not step,wall_seconds,return_mean,return_std,..."),
    };
    text.lines()
        .enumerate()
        .skip(1)
        .map(|(i, line)| {
            let fields: Vec<&str> = line.split(',').collect();
            let number = |k: usize| {
                fields
                    .get(k)
                    .and_then(|f| f.parse::<f64>().ok())
                    .ok_or_else(|| bad(i + 1))
            };
            Ok(EvalRow {
                step: number(0)? as u64,
                wall_seconds: number(1)?,
                return_mean: number(2)?,
                return_std: number(3)?,
            })
        })
        .collect()
}

/// Groups and averages the runs.
pub fn summarize_runs(runs: &[PathBuf]) -> Result<Vec<CurveSummary>, TrainError> {
    let mut groups: BTreeMap<String, Vec<(u64, Vec<EvalRow>)>> = BTreeMap::new();
    for run in runs {
        let config = TrainConfig::from_toml_file(&run.join("config.toml"), None)?;
        let delay = config.validate()?;
        let mut label = format!("{} {} Δ={delay}", config.task, config.algo);
        for (symbol, field) in config.algo.info().label_fields {
            let value = match config.algo.fields().get(*field) {
                Some(toml::Value::Float(v)) => v.to_string(),
                Some(toml::Value::String(v)) => v.clone(),
                Some(other) => other.to_string(),
                None => continue,
            };
            label += &format!(" {symbol}={value}");
        }
        groups
            .entry(label)
            .or_default()
            .push((config.seed, read_evals(run)?));
    }
    Ok(groups
        .into_iter()
        .map(|(label, members)| curve_summary(label, &members))
        .collect())
}

/// The mean and spread over seeds of `members`' `(seed, evaluations)`, at the evaluation steps
/// every member has.
pub fn curve_summary(label: String, members: &[(u64, Vec<EvalRow>)]) -> CurveSummary {
    let steps: Vec<u64> = members[0]
        .1
        .iter()
        .map(|row| row.step)
        .filter(|step| {
            members
                .iter()
                .all(|(_, rows)| rows.iter().any(|r| r.step == *step))
        })
        .collect();
    let at = |rows: &[EvalRow], step: u64| {
        *rows
            .iter()
            .find(|r| r.step == step)
            .expect("filtered above")
    };
    let (mut mean, mut std) = (Vec::new(), Vec::new());
    for &step in &steps {
        let values: Vec<(f64, f64)> = members
            .iter()
            .map(|(_, rows)| {
                let r = at(rows, step);
                (r.return_mean, r.return_std)
            })
            .collect();
        let n = values.len() as f64;
        let m = values.iter().map(|v| v.0).sum::<f64>() / n;
        mean.push(m);
        std.push(if values.len() == 1 {
            values[0].1
        } else {
            (values.iter().map(|v| (v.0 - m).powi(2)).sum::<f64>() / n).sqrt()
        });
    }
    CurveSummary {
        label,
        seeds: members.iter().map(|m| m.0).collect(),
        steps,
        mean,
        std,
    }
}

/// Draws the curves (mean over seeds, with a shaded ± std band) to an SVG file.
#[cfg(feature = "cli")]
pub fn plot_curves(curves: &[CurveSummary], title: &str, out: &Path) -> Result<(), TrainError> {
    use crate::charts::{Labels, Line, line_chart};
    let lines: Vec<Line> = curves
        .iter()
        .map(|curve| Line {
            label: format!(
                "{} ({} seed{})",
                curve.label,
                curve.seeds.len(),
                if curve.seeds.len() == 1 { "" } else { "s" }
            ),
            points: curve
                .steps
                .iter()
                .zip(curve.mean.iter().zip(&curve.std))
                .map(|(&s, (&m, &d))| (s as f64, m, d))
                .collect(),
        })
        .collect();
    let labels = Labels {
        title,
        x: "environment steps",
        y: "evaluation return (mean over seeds ± std)",
    };
    line_chart(&lines, &labels, out).map_err(|e| TrainError::Io {
        path: out.display().to_string(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs that differ in a label field (λ here) are separate curves, labelled with it.
    #[test]
    fn label_fields_split_and_name_the_curves() {
        let dir = tempfile::tempdir().unwrap();
        let runs: Vec<PathBuf> = ["0.1", "1.0"]
            .iter()
            .map(|weight| {
                let run = dir.path().join(format!("w{weight}"));
                std::fs::create_dir(&run).unwrap();
                std::fs::write(
                    run.join("config.toml"),
                    format!(
                        "task = \"inverted-pendulum\"\n[delay]\nobservation_delay = 3\n\
                         [algo]\nname = \"d2hpg\"\nlifting_weight = {weight}\n"
                    ),
                )
                .unwrap();
                std::fs::write(
                    run.join("evals.csv"),
                    "step,wall_seconds,return_mean,return_std,length_mean,episodes\n\
                     500,1.0,10.0,1.0,10.0,3\n",
                )
                .unwrap();
                run
            })
            .collect();
        let labels: Vec<String> = summarize_runs(&runs)
            .unwrap()
            .into_iter()
            .map(|curve| curve.label)
            .collect();
        assert_eq!(
            labels,
            [
                "inverted-pendulum d2hpg Δ=3 λ=0.1 K=2",
                "inverted-pendulum d2hpg Δ=3 λ=1 K=2"
            ]
        );
    }
}
