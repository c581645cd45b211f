//! Learning curves of finished runs: `dhrl plot` reads each run's `config.toml` and
//! `evals.csv`, groups the runs by (task, algorithm, delay; D2HPG's λ and K too), averages the
//! seeds, draws the curves as SVG with plotters, and summarises the final evaluations.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::prelude::*;
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

/// `(step, return_mean, return_std)` rows of a run's `evals.csv`.
fn read_evals(run: &Path) -> Result<Vec<(u64, f64, f64)>, TrainError> {
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
            Ok((number(0)? as u64, number(2)?, number(3)?))
        })
        .collect()
}

/// Groups and averages the runs.
pub fn summarize_runs(runs: &[PathBuf]) -> Result<Vec<CurveSummary>, TrainError> {
    let mut groups: BTreeMap<String, Vec<(u64, Vec<(u64, f64, f64)>)>> = BTreeMap::new();
    for run in runs {
        let config = TrainConfig::from_toml_file(&run.join("config.toml"))?;
        let delay = config.validate()?;
        let mut label = format!("{} {} Δ={delay}", config.task, config.algo);
        for (field, symbol) in config.algo.info().label_fields {
            let value = match config.algo.fields().get(*field) {
                Some(toml::Value::Float(v)) => v.to_string(),
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
        .map(|(label, members)| {
            let steps: Vec<u64> = members[0]
                .1
                .iter()
                .map(|row| row.0)
                .filter(|step| {
                    members
                        .iter()
                        .all(|(_, rows)| rows.iter().any(|r| r.0 == *step))
                })
                .collect();
            let at = |rows: &[(u64, f64, f64)], step: u64| {
                *rows.iter().find(|r| r.0 == step).expect("filtered above")
            };
            let (mut mean, mut std) = (Vec::new(), Vec::new());
            for &step in &steps {
                let values: Vec<(f64, f64)> = members
                    .iter()
                    .map(|(_, rows)| {
                        let r = at(rows, step);
                        (r.1, r.2)
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
        })
        .collect())
}

/// Draws the curves (mean over seeds, with ± std bars) to an SVG file.
pub fn plot_curves(curves: &[CurveSummary], title: &str, out: &Path) -> Result<(), TrainError> {
    draw(curves, title, out).map_err(|e| TrainError::Io {
        path: out.display().to_string(),
        message: e.to_string(),
    })
}

fn draw(
    curves: &[CurveSummary],
    title: &str,
    out: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    let max_step = curves
        .iter()
        .flat_map(|c| c.steps.iter().copied())
        .max()
        .unwrap_or(1) as f64;
    let (mut low, mut high) = (0.0f64, 1.0f64);
    for c in curves {
        for (m, s) in c.mean.iter().zip(&c.std) {
            low = low.min(m - s);
            high = high.max(m + s);
        }
    }
    let margin = 0.05 * (high - low);
    let root = SVGBackend::new(out, (900, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..max_step * 1.02, (low - margin)..(high + margin))?;
    chart
        .configure_mesh()
        .x_desc("environment steps")
        .y_desc("evaluation return (mean over seeds ± std)")
        .draw()?;
    for (i, curve) in curves.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let points: Vec<(f64, f64)> = curve
            .steps
            .iter()
            .zip(&curve.mean)
            .map(|(&s, &m)| (s as f64, m))
            .collect();
        chart
            .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
            .label(format!(
                "{} ({} seed{})",
                curve.label,
                curve.seeds.len(),
                if curve.seeds.len() == 1 { "" } else { "s" }
            ))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart.draw_series(
            curve
                .steps
                .iter()
                .zip(curve.mean.iter().zip(&curve.std))
                .map(|(&s, (&m, &d))| {
                    PathElement::new(
                        vec![(s as f64, m - d), (s as f64, m + d)],
                        color.mix(0.5).stroke_width(1),
                    )
                }),
        )?;
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 3, color.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
