//! `dhrl report`: runs (or whole sweeps) turned into the paper's Table 1 layout (Markdown,
//! LaTeX, CSV, the published numbers beside ours), an rliable-style aggregate, figures, and a
//! long-format CSV of every evaluation.
//!
//! Returns are normalised per task by the paper's delay-free SAC return on that task (Table 1's
//! first row): 1.0 is what SAC reaches without delay in the paper, so a normalised score says
//! how much of the undelayed performance an agent keeps under delay. The aggregate, per
//! condition (Δ, and actuator noise or random delays), is the IQM of those scores over every
//! run of every task with a 95% stratified-bootstrap interval, and the probability that D2HPG's
//! final return beats each other algorithm's (per task, over run pairs, then averaged over
//! tasks), with its interval. Runs are kept apart by their protocol (`config.toml`) and, for
//! runs converted from another implementation's logs, by that implementation
//! ([`IMPLEMENTATION_FILE`]); dhrl's runs of an algorithm are then compared with the other
//! implementation's the same way.
use std::path::{Path, PathBuf};

mod figures;
mod results;
mod stats;
mod table;

pub use results::{Condition, IMPLEMENTATION_FILE, RunResult, Variant, entries, load_runs};
pub use stats::{iqm, mean_std, probability_of_improvement};
pub use table::{PaperCell, Table, paper_table1, table1};

use crate::algos::{paper_name, proposed, reference};
use crate::sweep::write_atomically;
use crate::tasks::TaskName;
use stats::{Strata, bootstrap_interval, iqm_of_strata};

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("{0}")]
    NoResults(String),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    #[error(transparent)]
    Train(#[from] crate::train::TrainError),
    #[error(transparent)]
    Sweep(#[from] crate::sweep::SweepError),
}

impl From<crate::train::ConfigError> for ReportError {
    fn from(e: crate::train::ConfigError) -> ReportError {
        ReportError::Train(e.into())
    }
}

/// A final return as a fraction of the paper's delay-free SAC return on the task.
pub fn normalised(task: TaskName, final_return: f64) -> f64 {
    let reference = paper_table1()
        .into_iter()
        .find(|c| c.delay == 0 && c.algorithm == reference().name && c.task == task)
        .expect("Table 1 has the delay-free reference on every task");
    final_return / reference.mean
}

/// One row of the aggregate: an algorithm's IQM under a condition, over `tasks`.
#[derive(Debug, Clone, PartialEq)]
pub struct IqmRow {
    pub condition: Condition,
    pub algorithm: &'static str,
    pub variant: Variant,
    pub tasks: Vec<TaskName>,
    pub runs: usize,
    pub iqm: f64,
    pub interval: (f64, f64),
}

/// The probability that one entry's final return beats another's under a condition: the
/// paper's method over each baseline of its variant, and dhrl's runs of an algorithm over
/// another implementation's runs of it under the same protocol.
#[derive(Debug, Clone, PartialEq)]
pub struct ImprovementRow {
    pub condition: Condition,
    /// The paper's method (`algos::proposed`), or the algorithm another implementation also ran.
    pub algorithm: &'static str,
    pub variant: Variant,
    pub baseline: &'static str,
    pub baseline_variant: Variant,
    pub probability: f64,
    pub interval: (f64, f64),
}

/// Normalised final returns of `algorithm` in `variant` under `condition`, one list per task.
fn strata(
    runs: &[RunResult],
    (algorithm, variant): &(&'static str, Variant),
    condition: &Condition,
    tasks: &[TaskName],
) -> Strata {
    tasks
        .iter()
        .map(|&task| {
            runs.iter()
                .filter(|r| r.condition == *condition && r.is(algorithm, variant) && r.task == task)
                .map(|r| normalised(task, r.final_eval().1))
                .collect()
        })
        .collect()
}

/// Per condition under a delay (Table 1's fixed Δ, and those with actuator noise or random
/// delays): every algorithm's IQM over the tasks that every algorithm under it has runs on, and
/// D2HPG's probability of improvement over each other.
pub fn aggregate(runs: &[RunResult], reps: usize) -> (Vec<IqmRow>, Vec<ImprovementRow>) {
    let mut conditions: Vec<Condition> = runs
        .iter()
        .map(|r| r.condition)
        .filter(|c| c.delay > 0)
        .collect();
    conditions.sort_by(Condition::order);
    conditions.dedup();
    let (mut iqms, mut improvements) = (Vec::new(), Vec::new());
    for condition in &conditions {
        let under = |r: &&RunResult| r.condition == *condition;
        let entries = entries(runs.iter().filter(under));
        let tasks: Vec<TaskName> = TaskName::ALL
            .into_iter()
            .filter(|&t| {
                entries
                    .iter()
                    .all(|(a, v)| runs.iter().filter(under).any(|r| r.is(a, v) && r.task == t))
            })
            .collect();
        if tasks.is_empty() {
            continue;
        }
        // Resampling streams: one per condition and entry (pair), from the condition itself
        // so that other runs in the report do not move its intervals.
        let stream = resampling_stream(condition);
        for (k, entry) in entries.iter().enumerate() {
            let scores = strata(runs, entry, condition, &tasks);
            iqms.push(IqmRow {
                condition: *condition,
                algorithm: entry.0,
                variant: entry.1.clone(),
                tasks: tasks.clone(),
                runs: scores.iter().map(Vec::len).sum(),
                iqm: iqm_of_strata(&scores),
                interval: bootstrap_interval(
                    &[&scores],
                    reps,
                    stream.wrapping_mul(100).wrapping_add(k as u64),
                    |g| iqm_of_strata(&g[0]),
                ),
            });
        }
        // The pairs compared: the paper's method over each baseline of its variant, then
        // dhrl's runs of an algorithm over another implementation's of the same protocol.
        let proposed = proposed().name;
        let mut pairs = Vec::new();
        for ours in entries.iter().filter(|(a, _)| *a == proposed) {
            for theirs in entries
                .iter()
                .filter(|(a, v)| *a != proposed && *v == ours.1)
            {
                pairs.push((ours, theirs));
            }
        }
        for theirs in entries.iter().filter(|(_, v)| v.implementation.is_some()) {
            let dhrl = Variant {
                implementation: None,
                ..theirs.1.clone()
            };
            if let Some(ours) = entries.iter().find(|(a, v)| *a == theirs.0 && *v == dhrl) {
                pairs.push((ours, theirs));
            }
        }
        for (k, (ours, theirs)) in pairs.into_iter().enumerate() {
            let (x, y) = (
                strata(runs, ours, condition, &tasks),
                strata(runs, theirs, condition, &tasks),
            );
            improvements.push(ImprovementRow {
                condition: *condition,
                algorithm: ours.0,
                variant: ours.1.clone(),
                baseline: theirs.0,
                baseline_variant: theirs.1.clone(),
                probability: probability_of_improvement(&x, &y),
                interval: bootstrap_interval(
                    &[&x, &y],
                    reps,
                    stream.wrapping_mul(1000).wrapping_add(k as u64),
                    |g| probability_of_improvement(&g[0], &g[1]),
                ),
            });
        }
    }
    (iqms, improvements)
}

/// The seed of a condition's bootstrap resampling: Δ for Table 1's (fixed, noise-free), as
/// before there were other conditions; Δ mixed with the random flag and σ's bits otherwise.
fn resampling_stream(condition: &Condition) -> u64 {
    let delay = condition.delay as u64;
    if condition.is_table1() {
        delay
    } else {
        delay ^ (u64::from(condition.random_delay) << 40) ^ condition.actuator_noise.to_bits()
    }
}

fn aggregate_markdown(iqms: &[IqmRow], improvements: &[ImprovementRow], reps: usize) -> String {
    let mut out = format!(
        "Normalised score: final return / the return of Table 1's {} on the task. IQM over \
         every run of the tasks listed; 95% stratified-bootstrap intervals ({reps} resamples).\n\n\
         | condition | algorithm | protocol | tasks | runs | IQM | 95% interval |\n|---|---|---|---|---:|---:|---|\n",
        reference().paper_name
    );
    for row in iqms {
        let tasks: Vec<String> = row.tasks.iter().map(|t| t.to_string()).collect();
        out += &format!(
            "| {} | {} | {} | {} | {} | {:.3} | [{:.3}, {:.3}] |\n",
            row.condition.label(),
            paper_name(row.algorithm),
            row.variant.label(),
            tasks.join(", "),
            row.runs,
            row.iqm,
            row.interval.0,
            row.interval.1
        );
    }
    if !improvements.is_empty() {
        out += "\n| condition | P(algorithm > baseline) | algorithm | protocol | baseline | protocol | 95% interval |\n|---|---:|---|---|---|---|---|\n";
        for row in improvements {
            out += &format!(
                "| {} | {:.3} | {} | {} | {} | {} | [{:.3}, {:.3}] |\n",
                row.condition.label(),
                row.probability,
                paper_name(row.algorithm),
                row.variant.label(),
                paper_name(row.baseline),
                row.baseline_variant.label(),
                row.interval.0,
                row.interval.1
            );
        }
    }
    out
}

fn aggregate_csv(iqms: &[IqmRow], improvements: &[ImprovementRow]) -> String {
    let mut out = String::from(
        "statistic,delay,delay_kind,actuator_noise,algorithm,protocol,implementation,baseline,baseline_protocol,baseline_implementation,runs,value,low,high\n",
    );
    let condition = |c: &Condition| format!("{},{},{}", c.delay, c.delay_kind(), c.actuator_noise);
    for r in iqms {
        out += &format!(
            "iqm,{},{},{},,,,{},{:.6},{:.6},{:.6}\n",
            condition(&r.condition),
            r.algorithm,
            r.variant.csv_fields(),
            r.runs,
            r.iqm,
            r.interval.0,
            r.interval.1
        );
    }
    for r in improvements {
        out += &format!(
            "probability_of_improvement,{},{},{},{},{},,{:.6},{:.6},{:.6}\n",
            condition(&r.condition),
            r.algorithm,
            r.variant.csv_fields(),
            r.baseline,
            r.baseline_variant.csv_fields(),
            r.probability,
            r.interval.0,
            r.interval.1
        );
    }
    out
}

/// Every evaluation of every run, one row each: what pandas or rliable load directly.
fn long_csv(runs: &[RunResult]) -> String {
    let mut out = String::from(
        "algorithm,protocol,implementation,task,delay,delay_kind,actuator_noise,seed,step,return\n",
    );
    for r in runs {
        for e in &r.evals {
            out += &format!(
                "{},{},{},{},{},{},{},{},{}\n",
                r.algorithm,
                r.variant.csv_fields(),
                r.task,
                r.condition.delay,
                r.condition.delay_kind(),
                r.condition.actuator_noise,
                r.seed,
                e.step,
                e.return_mean
            );
        }
    }
    out
}

/// What [`write_report`] wrote.
#[derive(Debug, Clone)]
pub struct Report {
    pub runs: usize,
    /// Runs without an evaluation yet.
    pub skipped: usize,
    /// `table1.md`'s text.
    pub table_markdown: String,
    pub aggregate_markdown: String,
    pub files: Vec<PathBuf>,
}

/// Reads the runs under `inputs` and writes into `out`: `table1.md`, `table1.tex`,
/// `table1.csv`, `aggregate.md`, `aggregate.csv`, `returns.csv` and the figures.
pub fn write_report(inputs: &[PathBuf], out: &Path, reps: usize) -> Result<Report, ReportError> {
    if reps < 100 {
        return Err(ReportError::NoResults(format!(
            "--bootstrap {reps}: at least 100 resamples are needed for a 95% interval"
        )));
    }
    let (runs, skipped) = load_runs(inputs)?;
    std::fs::create_dir_all(out).map_err(|e| ReportError::Io {
        path: out.display().to_string(),
        message: e.to_string(),
    })?;
    let table = table1(&runs);
    let (iqms, improvements) = aggregate(&runs, reps);
    let steps: Vec<String> = table.final_steps().iter().map(u64::to_string).collect();
    let markdown = format!(
        "{}\nMean ± std over seeds (their number in brackets) of the final evaluation (at step {}); \
         the best of each Δ in bold. Paper: Table 1 of the DHRL paper (1M steps, 5 seeds).{}\n",
        table.markdown(),
        steps.join(", "),
        if table.mixed() {
            " †: the cell pools runs that differ in more than their seed (other settings, \
             budgets or algorithm fields)."
        } else {
            ""
        }
    );
    let aggregate_markdown = aggregate_markdown(&iqms, &improvements, reps);
    let mut files = Vec::new();
    for (name, text) in [
        ("table1.md", markdown.clone()),
        ("table1.tex", table.latex()),
        ("table1.csv", table.csv()),
        ("aggregate.md", aggregate_markdown.clone()),
        ("aggregate.csv", aggregate_csv(&iqms, &improvements)),
        ("returns.csv", long_csv(&runs)),
    ] {
        let path = out.join(name);
        write_atomically(&path, &text)?;
        files.push(path);
    }
    files.extend(figures::all(&runs, out)?);
    Ok(Report {
        runs: runs.len(),
        skipped,
        table_markdown: markdown,
        aggregate_markdown,
        files,
    })
}
