//! The report's figures, each an SVG and a PNG: learning curves per task × Δ, normalised
//! return against actuator noise σ, random against fixed delays, the D2HPG ablation, and
//! wall-clock per 1M steps.
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::ReportError;
use super::normalised;
use super::results::{Condition, RunResult, Variant, entries};
use super::stats::mean_std;
use crate::algos::{Role, names_where, paper_name};
use crate::charts::{CategorySeries, Labels, Line, category_chart, line_chart, svg_to_png};
use crate::protocol::Protocol;
use crate::tasks::TaskName;
use crate::train::{curve_summary, plot_curves};

fn chart_error(path: &Path) -> impl Fn(Box<dyn std::error::Error>) -> ReportError + '_ {
    move |e| ReportError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Writes `name.svg` with `draw`, then its PNG; returns both paths.
fn figure(
    out: &Path,
    name: &str,
    draw: impl FnOnce(&Path) -> Result<(), ReportError>,
) -> Result<Vec<PathBuf>, ReportError> {
    let svg = out.join(format!("{name}.svg"));
    draw(&svg)?;
    let png = svg_to_png(&svg).map_err(chart_error(&svg))?;
    Ok(vec![svg, png])
}

/// How a figure names an algorithm in a variant: its paper name, and the variant where it is
/// not dhrl's own protocol and code.
fn entry_label(algorithm: &str, variant: &Variant) -> String {
    match (variant.protocol, &variant.implementation) {
        (Protocol::Dhrl, None) => paper_name(algorithm).to_string(),
        _ => format!("{} [{}]", paper_name(algorithm), variant.label()),
    }
}

/// Every figure the runs allow.
pub fn all(runs: &[RunResult], out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let mut files = learning_curves(runs, out)?;
    files.extend(noise(runs, out)?);
    files.extend(random_delay(runs, out)?);
    files.extend(ablation(runs, out)?);
    files.extend(runtime(runs, out)?);
    Ok(files)
}

/// One chart per task and condition under a delay: a curve per algorithm, with the task's
/// delay-free reference beside Table 1's (fixed Δ, no noise) conditions.
fn learning_curves(runs: &[RunResult], out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let mut cells: Vec<(TaskName, Condition)> = runs
        .iter()
        .filter(|r| r.condition.delay > 0)
        .map(|r| (r.task, r.condition))
        .collect();
    cells.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.order(&b.1)));
    cells.dedup();
    let mut files = Vec::new();
    for (task, condition) in cells {
        let curves: Vec<_> = entries(runs)
            .into_iter()
            .filter_map(|(algorithm, variant)| {
                let members: Vec<_> = runs
                    .iter()
                    .filter(|r| {
                        r.task == task
                            && r.is(algorithm, &variant)
                            && (r.condition == condition
                                || (condition.is_table1()
                                    && r.condition.is_table1()
                                    && r.condition.delay == 0))
                    })
                    .map(|r| (r.seed, r.evals.clone()))
                    .collect();
                (!members.is_empty())
                    .then(|| curve_summary(entry_label(algorithm, &variant), &members))
            })
            .collect();
        let title = format!("{} at {}", task.gymnasium_id(), condition.label());
        files.extend(figure(
            out,
            &format!("curves-{task}-{}", condition.slug()),
            |svg| Ok(plot_curves(&curves, &title, svg)?),
        )?);
    }
    Ok(files)
}

/// Mean ± std over seeds of the normalised final returns of `runs`.
fn normalised_mean(runs: &[&RunResult]) -> Option<(f64, f64)> {
    let values: Vec<f64> = runs
        .iter()
        .map(|r| normalised(r.task, r.final_eval().1))
        .collect();
    (!values.is_empty()).then(|| mean_std(&values))
}

/// Normalised final return against σ, a line per task (and algorithm, Δ) that has noisy runs;
/// its σ = 0 runs are the first point.
fn noise(runs: &[RunResult], out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let fixed: Vec<&RunResult> = runs.iter().filter(|r| !r.condition.random_delay).collect();
    let noisy: BTreeSet<(TaskName, &str, &Variant, usize)> = fixed
        .iter()
        .filter(|r| r.condition.actuator_noise > 0.0)
        .map(|r| (r.task, r.algorithm, &r.variant, r.condition.delay))
        .collect();
    if noisy.is_empty() {
        return Ok(Vec::new());
    }
    let lines: Vec<Line> = noisy
        .iter()
        .map(|&(task, algorithm, variant, delay)| {
            let same: Vec<&RunResult> = fixed
                .iter()
                .copied()
                .filter(|r| {
                    r.task == task && r.is(algorithm, variant) && r.condition.delay == delay
                })
                .collect();
            let sigmas: BTreeSet<u64> = same
                .iter()
                .map(|r| r.condition.actuator_noise.to_bits())
                .collect();
            let mut points: Vec<(f64, f64, f64)> = sigmas
                .into_iter()
                .filter_map(|bits| {
                    let at: Vec<&RunResult> = same
                        .iter()
                        .copied()
                        .filter(|r| r.condition.actuator_noise.to_bits() == bits)
                        .collect();
                    normalised_mean(&at).map(|(m, s)| (f64::from_bits(bits), m, s))
                })
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            Line {
                label: format!("{task} {} Δ={delay}", entry_label(algorithm, variant)),
                points,
            }
        })
        .collect();
    let labels = Labels {
        title: "Final return under actuator noise",
        x: "actuator noise σ",
        y: "normalised return (mean over seeds ± std)",
    };
    figure(out, "noise", |svg| {
        line_chart(&lines, &labels, svg).map_err(chart_error(svg))
    })
}

/// Random delays (uniform in 1..=Δ) against fixed Δ, per task, for each algorithm that has
/// random-delay runs.
fn random_delay(runs: &[RunResult], out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let random: BTreeSet<(&str, &Variant, usize)> = runs
        .iter()
        .filter(|r| r.condition.random_delay && r.condition.actuator_noise == 0.0)
        .map(|r| (r.algorithm, &r.variant, r.condition.delay))
        .collect();
    if random.is_empty() {
        return Ok(Vec::new());
    }
    let tasks: Vec<TaskName> = TaskName::ALL
        .into_iter()
        .filter(|t| {
            runs.iter()
                .any(|r| r.task == *t && r.condition.random_delay)
        })
        .collect();
    let mut series = Vec::new();
    for &(algorithm, variant, delay) in &random {
        for kind in [false, true] {
            let values = tasks
                .iter()
                .map(|&task| {
                    let at: Vec<&RunResult> = runs
                        .iter()
                        .filter(|r| {
                            r.task == task
                                && r.is(algorithm, variant)
                                && r.condition.delay == delay
                                && r.condition.random_delay == kind
                                && r.condition.actuator_noise == 0.0
                        })
                        .collect();
                    normalised_mean(&at)
                })
                .collect();
            series.push(CategorySeries {
                label: format!(
                    "{} {}",
                    entry_label(algorithm, variant),
                    if kind {
                        format!("random Δ in 1..={delay}")
                    } else {
                        format!("fixed Δ={delay}")
                    }
                ),
                values,
            });
        }
    }
    let categories: Vec<String> = tasks.iter().map(|t| t.to_string()).collect();
    let labels = Labels {
        title: "Random against fixed delays",
        x: "task",
        y: "normalised return (mean over seeds ± std)",
    };
    figure(out, "random-delay", |svg| {
        category_chart(&categories, &series, &labels, svg).map_err(chart_error(svg))
    })
}

/// The lifting ablation's algorithms (`AlgoInfo::in_lifting_ablation`: D2HPG-naive, BPQL and
/// D2HPG) per task and Δ, where the ablation-only one ran.
fn ablation(runs: &[RunResult], out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let table: Vec<&RunResult> = runs.iter().filter(|r| r.condition.is_table1()).collect();
    let ablation_only = names_where(|info| info.role == Role::Ablation && info.in_lifting_ablation);
    let cells: Vec<(TaskName, usize)> = table
        .iter()
        .filter(|r| ablation_only.contains(&r.algorithm))
        .map(|r| (r.task, r.condition.delay))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    if cells.is_empty() {
        return Ok(Vec::new());
    }
    let in_ablation = names_where(|info| info.in_lifting_ablation);
    let series: Vec<CategorySeries> = entries(table.iter().copied())
        .into_iter()
        .filter(|(algorithm, _)| in_ablation.contains(algorithm))
        .map(|(algorithm, variant)| CategorySeries {
            label: entry_label(algorithm, &variant),
            values: cells
                .iter()
                .map(|&(task, delay)| {
                    let at: Vec<&RunResult> = table
                        .iter()
                        .copied()
                        .filter(|r| {
                            r.task == task
                                && r.is(algorithm, &variant)
                                && r.condition.delay == delay
                        })
                        .collect();
                    normalised_mean(&at)
                })
                .collect(),
        })
        .collect();
    let categories: Vec<String> = cells.iter().map(|(t, d)| format!("{t} Δ={d}")).collect();
    let labels = Labels {
        title: "Ablation of the lifting loss: with it, without it, and the naive abstraction",
        x: "task and delay",
        y: "normalised return (mean over seeds ± std)",
    };
    figure(out, "ablation", |svg| {
        category_chart(&categories, &series, &labels, svg).map_err(chart_error(svg))
    })
}

/// Hours of wall-clock per 1M environment steps, per algorithm, a series per task and Δ.
fn runtime(runs: &[RunResult], out: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let algorithms = entries(runs);
    let cells: BTreeSet<(TaskName, usize)> =
        runs.iter().map(|r| (r.task, r.condition.delay)).collect();
    let series: Vec<CategorySeries> = cells
        .iter()
        .map(|&(task, delay)| CategorySeries {
            label: format!("{task} Δ={delay}"),
            values: algorithms
                .iter()
                .map(|(algorithm, variant)| {
                    let hours: Vec<f64> = runs
                        .iter()
                        .filter(|r| {
                            r.task == task && r.condition.delay == delay && r.is(algorithm, variant)
                        })
                        .filter_map(|r| r.seconds_per_million().map(|s| s / 3600.0))
                        .collect();
                    (!hours.is_empty()).then(|| mean_std(&hours))
                })
                .collect(),
        })
        .collect();
    let categories: Vec<String> = algorithms.iter().map(|(a, v)| entry_label(a, v)).collect();
    let labels = Labels {
        title: "Wall-clock per 1M environment steps (this machine)",
        x: "algorithm",
        y: "hours per 1M steps (mean over runs ± std)",
    };
    figure(out, "runtime", |svg| {
        category_chart(&categories, &series, &labels, svg).map_err(chart_error(svg))
    })
}
