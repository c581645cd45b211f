//! The SVG figure of the sample-complexity experiment: samples needed against the delay, one line
//! per learner (mean with ± one standard deviation bars over the runs that converged), on a
//! logarithmic axis, with the sample budget drawn as a grey line — drawn by `dhrl-charts`.

use std::path::Path;

use dhrl_charts::{Labels, Line, log_line_chart};

use crate::bench::BenchReport;
use crate::error::TabularError;

/// Writes the figure for `report` to `path` (SVG).
///
/// # Errors
/// [`TabularError::Plot`] when the file cannot be written.
pub fn write_bench_plot(report: &BenchReport, path: &Path) -> Result<(), TabularError> {
    let lines = [
        ("augmented MDP: Q(x, a)", false),
        ("abstract MDP: Q(f(x), a)", true),
    ]
    .map(|(label, abstract_side)| Line {
        label: label.to_string(),
        points: side_points(report, abstract_side),
    });
    let title = format!(
        "Samples until the greedy policy is {}-optimal ({} states, {} actions, {} seeds)",
        report.tolerance, report.states, report.actions, report.seeds
    );
    let labels = Labels {
        title: &title,
        x: "delay",
        y: "environment samples (log scale)",
    };
    let budget = (
        "sample budget (runs reaching it: not reached)",
        report.max_samples as f64,
    );
    log_line_chart(&lines, Some(budget), &labels, path).map_err(|error| TabularError::Plot {
        path: path.to_path_buf(),
        message: error.to_string(),
    })
}

/// `(delay, mean, std)` of the rows where one learner converged at least once.
fn side_points(report: &BenchReport, abstract_side: bool) -> Vec<(f64, f64, f64)> {
    report
        .rows
        .iter()
        .filter_map(|row| {
            let stats = if abstract_side {
                &row.abstraction
            } else {
                &row.augmented
            };
            match (stats.mean, stats.std) {
                (Some(mean), Some(std)) => Some((row.delay as f64, mean, std)),
                _ => None,
            }
        })
        .collect()
}
