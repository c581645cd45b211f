//! What a sweep will cost on this machine: each distinct (algorithm, task, Δ) of its runs
//! has its gradient update timed here (`dhrl bench update`'s measurement), and a run's
//! core-hours are its updates times that cost on the algorithm's learner threads.
use serde::Serialize;

use super::SweepError;
use super::manifest::ManifestRun;
use crate::bench::bench_update;
use crate::tasks::TaskName;

/// The measured cost of one (algorithm, task, Δ) and the runs it applies to.
#[derive(Debug, Clone, Serialize)]
pub struct CostRow {
    pub algo: String,
    /// The algorithm's whole configuration, the batch size and the device timed.
    #[serde(skip)]
    settings: String,
    pub task: TaskName,
    pub delay: usize,
    pub runs: usize,
    pub env_steps: u64,
    pub ms_per_update: f64,
    /// Threads an update of this algorithm keeps busy.
    pub threads: usize,
    pub core_hours: f64,
}

/// Times `updates` gradient updates (after one untimed) for every distinct (algorithm, task, Δ)
/// among `runs`. Only the updates are counted: simulation and acting add a few percent at
/// one update per step (docs/experiments.md and docs/results/update-costs.md).
pub fn estimate_cost(runs: &[&ManifestRun], updates: usize) -> Result<Vec<CostRow>, SweepError> {
    let mut rows: Vec<CostRow> = Vec::new();
    for run in runs {
        let c = &run.config;
        let delay = c.validate()?;
        // Runs with other network sizes, batch or device are timed apart.
        let settings = format!("{:?} {} {:?}", c.algo, c.batch_size, c.device);
        let updates_of_run =
            (c.steps.saturating_sub(c.warmup_steps) as f64 * c.updates_per_step) as u64;
        if let Some(row) = rows
            .iter_mut()
            .find(|r| (r.settings.as_str(), r.task, r.delay) == (settings.as_str(), c.task, delay))
        {
            row.runs += 1;
            row.env_steps += c.steps;
            row.core_hours += core_hours(updates_of_run, row.ms_per_update, row.threads);
            continue;
        }
        let measured = bench_update(
            &c.algo,
            c.task,
            delay,
            c.batch_size,
            c.device,
            None,
            updates,
        )?;
        rows.push(CostRow {
            algo: c.algo.name().to_string(),
            settings,
            task: c.task,
            delay,
            runs: 1,
            env_steps: c.steps,
            ms_per_update: measured.ms_per_update,
            threads: measured.threads,
            core_hours: core_hours(updates_of_run, measured.ms_per_update, measured.threads),
        });
    }
    Ok(rows)
}

fn core_hours(updates: u64, ms_per_update: f64, threads: usize) -> f64 {
    updates as f64 * ms_per_update * threads as f64 / 3.6e6
}
