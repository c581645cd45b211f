//! The SVG figure of the sample-complexity experiment: samples needed against the delay, one line
//! per learner (mean with ± one standard deviation bars over the runs that converged), on a
//! logarithmic axis, with the sample budget drawn as a grey line.

use std::path::Path;

use plotters::prelude::*;

use super::bench::BenchReport;
use super::error::TabularError;

/// Writes the figure for `report` to `path` (SVG).
///
/// # Errors
/// [`TabularError::Plot`] when the file cannot be written.
pub fn write_bench_plot(report: &BenchReport, path: &Path) -> Result<(), TabularError> {
    draw(report, path).map_err(|error| TabularError::Plot {
        path: path.to_path_buf(),
        message: error.to_string(),
    })
}

/// `(delay, mean, std)` of the rows where one learner converged at least once.
fn side_points(report: &BenchReport, abstract_side: bool) -> Vec<(i32, f64, f64)> {
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
                (Some(mean), Some(std)) => Some((row.delay as i32, mean, std)),
                _ => None,
            }
        })
        .collect()
}

fn draw(report: &BenchReport, path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let first = report.rows.first().map_or(0, |row| row.delay) as i32;
    let last = report.rows.last().map_or(0, |row| row.delay) as i32;
    let cap = report.max_samples as f64;
    let series = [
        ("augmented MDP: Q(x, a)", RED, side_points(report, false)),
        ("abstract MDP: Q(f(x), a)", BLUE, side_points(report, true)),
    ];
    let (mut low, mut high) = (cap, cap);
    for (_, _, points) in &series {
        for &(_, mean, std) in points {
            low = low.min((mean - std).max(mean * 0.5));
            high = high.max(mean + std);
        }
    }
    let low = (low * 0.5).max(1.0);
    let high = high * 2.0;

    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let caption = format!(
        "Samples until the greedy policy is {}-optimal ({} states, {} actions, {} seeds)",
        report.tolerance, report.states, report.actions, report.seeds
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d((first - 1)..(last + 1), (low..high).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("delay")
        .y_desc("environment samples (log scale)")
        .x_labels((last - first + 3).max(1) as usize)
        .draw()?;

    let grey = BLACK.mix(0.35);
    chart
        .draw_series(LineSeries::new(
            [(first - 1, cap), (last + 1, cap)],
            grey.stroke_width(1),
        ))?
        .label("sample budget (runs reaching it: not reached)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(1)));

    for (label, color, points) in &series {
        let color = *color;
        chart
            .draw_series(LineSeries::new(
                points.iter().map(|&(delay, mean, _)| (delay, mean)),
                color.stroke_width(2),
            ))?
            .label(*label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart.draw_series(
            points
                .iter()
                .map(|&(delay, mean, _)| Circle::new((delay, mean), 4, color.filled())),
        )?;
        chart.draw_series(points.iter().map(|&(delay, mean, std)| {
            PathElement::new(
                vec![(delay, (mean - std).max(low)), (delay, mean + std)],
                color.stroke_width(1),
            )
        }))?;
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
