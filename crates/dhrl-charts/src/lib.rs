//! The charts dhrl draws, as SVG with plotters (PNG copies rendered with resvg): lines over a
//! numeric axis with a shaded ± band, the same on a logarithmic axis with ± bars and a reference
//! level, and points with ± bars over named categories. `dhrl plot`, `dhrl report` and
//! `dhrl tabular-bench` all draw through here.
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use plotters::coord::Shift;
use plotters::prelude::*;

/// What every chart returns: `Ok`, or why the file could not be drawn.
pub type ChartResult = Result<(), Box<dyn std::error::Error>>;

/// One line: its label and `(x, mean, spread)` points.
pub struct Line {
    pub label: String,
    pub points: Vec<(f64, f64, f64)>,
}

/// Axis texts and title.
pub struct Labels<'a> {
    pub title: &'a str,
    pub x: &'a str,
    pub y: &'a str,
}

/// A point's spread as drawn: none where it is undefined (one seed's standard deviation, a
/// log without the spread), so that the mean is still drawn and held by the axes.
fn drawn_spread(spread: f64) -> f64 {
    if spread.is_finite() { spread } else { 0.0 }
}

/// The y range holding every `mean ± spread`, with a margin.
fn y_range(values: impl Iterator<Item = (f64, f64)>) -> std::ops::Range<f64> {
    let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
    for (m, s) in values {
        let s = drawn_spread(s);
        low = low.min(m - s);
        high = high.max(m + s);
    }
    if !low.is_finite() || !high.is_finite() {
        return 0.0..1.0;
    }
    let margin = 0.05 * (high - low).max(1e-9);
    (low - margin)..(high + margin)
}

/// A blank 900×560 SVG canvas at `out`.
fn canvas(out: &Path) -> Result<DrawingArea<SVGBackend<'_>, Shift>, Box<dyn std::error::Error>> {
    let root = SVGBackend::new(out, (900, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    Ok(root)
}

/// Every chart's frame: the title, margins and axis label areas (`y_label_area` wide).
fn frame<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, Shift>,
    labels: &Labels,
    y_label_area: u32,
) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
    let mut builder = ChartBuilder::on(root);
    builder
        .caption(labels.title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(y_label_area);
    builder
}

/// A legend entry drawn as a short line in `color`.
fn legend_line(color: RGBAColor, width: u32) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(width))
}

/// Draws the legend at `position` and writes the file.
fn legend_and_save<'a, 'b: 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, SVGBackend<'b>, CT>,
    root: &DrawingArea<SVGBackend<'b>, Shift>,
    position: SeriesLabelPosition,
) -> ChartResult {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Lines with a shaded `mean ± spread` band and a dot at each point, legend top left.
pub fn line_chart(lines: &[Line], labels: &Labels, out: &Path) -> ChartResult {
    let x_max = lines
        .iter()
        .flat_map(|l| l.points.iter().map(|p| p.0))
        .fold(0.0f64, f64::max);
    let x_min = lines
        .iter()
        .flat_map(|l| l.points.iter().map(|p| p.0))
        .fold(0.0f64, f64::min);
    let y = y_range(
        lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| (p.1, p.2))),
    );
    let root = canvas(out)?;
    let mut chart =
        frame(&root, labels, 70).build_cartesian_2d(x_min..(x_max * 1.02).max(x_min + 1e-9), y)?;
    chart
        .configure_mesh()
        .x_desc(labels.x)
        .y_desc(labels.y)
        .draw()?;
    for (i, line) in lines.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        // The band: the upper edge forward, the lower edge back.
        let band: Vec<(f64, f64)> = line
            .points
            .iter()
            .map(|&(x, m, s)| (x, m + drawn_spread(s)))
            .chain(
                line.points
                    .iter()
                    .rev()
                    .map(|&(x, m, s)| (x, m - drawn_spread(s))),
            )
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(
            band,
            color.mix(0.15).filled(),
        )))?;
        let points: Vec<(f64, f64)> = line.points.iter().map(|&(x, m, _)| (x, m)).collect();
        chart
            .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
            .label(line.label.clone())
            .legend(legend_line(color, 2));
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 3, color.filled())),
        )?;
    }
    legend_and_save(&mut chart, &root, SeriesLabelPosition::UpperLeft)
}

/// Lines with `mean ± spread` bars and a dot at each point on a logarithmic y axis, and, when
/// given, a grey horizontal `reference` level with its label (e.g. a sample budget); legend top
/// left. Bars are cut at the axis' lower end.
pub fn log_line_chart(
    lines: &[Line],
    reference: Option<(&str, f64)>,
    labels: &Labels,
    out: &Path,
) -> ChartResult {
    let points = || lines.iter().flat_map(|l| l.points.iter());
    let (x_min, x_max) = points().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p.0), hi.max(p.0))
    });
    let (x_min, x_max) = if x_min.is_finite() {
        (x_min - 1.0, x_max + 1.0)
    } else {
        (0.0, 1.0)
    };
    let (mut low, mut high) = reference.map_or((f64::INFINITY, 0.0), |(_, y)| (y, y));
    for &(_, mean, spread) in points() {
        let spread = drawn_spread(spread);
        low = low.min((mean - spread).max(mean * 0.5));
        high = high.max(mean + spread);
    }
    if !low.is_finite() || low <= 0.0 {
        low = 1.0;
    }
    let (low, high) = (
        (low * 0.5).max(f64::MIN_POSITIVE),
        (high * 2.0).max(low * 2.0),
    );
    let root = canvas(out)?;
    let mut chart =
        frame(&root, labels, 80).build_cartesian_2d(x_min..x_max, (low..high).log_scale())?;
    chart
        .configure_mesh()
        .x_desc(labels.x)
        .y_desc(labels.y)
        .x_labels(((x_max - x_min) as usize + 1).clamp(2, 30))
        .draw()?;
    if let Some((label, y)) = reference {
        let grey = BLACK.mix(0.35);
        chart
            .draw_series(LineSeries::new(
                [(x_min, y), (x_max, y)],
                grey.stroke_width(1),
            ))?
            .label(label)
            .legend(legend_line(grey, 1));
    }
    for (i, line) in lines.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let means: Vec<(f64, f64)> = line.points.iter().map(|&(x, m, _)| (x, m)).collect();
        chart
            .draw_series(LineSeries::new(means.clone(), color.stroke_width(2)))?
            .label(line.label.clone())
            .legend(legend_line(color, 2));
        chart.draw_series(means.into_iter().map(|p| Circle::new(p, 4, color.filled())))?;
        chart.draw_series(line.points.iter().map(|&(x, m, s)| {
            let s = drawn_spread(s);
            PathElement::new(
                vec![(x, (m - s).max(low)), (x, m + s)],
                color.stroke_width(1),
            )
        }))?;
    }
    legend_and_save(&mut chart, &root, SeriesLabelPosition::UpperLeft)
}

/// One series over the categories: its label and, per category, `(mean, spread)` if any.
pub struct CategorySeries {
    pub label: String,
    pub values: Vec<Option<(f64, f64)>>,
}

/// Each series as dots with ± bars, side by side within each named category.
pub fn category_chart(
    categories: &[String],
    series: &[CategorySeries],
    labels: &Labels,
    out: &Path,
) -> ChartResult {
    let y = y_range(
        series
            .iter()
            .flat_map(|s| s.values.iter().flatten().copied()),
    );
    let root = canvas(out)?;
    let n = categories.len() as f64;
    let mut chart = frame(&root, labels, 70).build_cartesian_2d(-0.5..(n - 0.5), y)?;
    let names = categories.to_vec();
    chart
        .configure_mesh()
        .x_labels(categories.len().max(2))
        .x_label_formatter(&move |x: &f64| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                names[i as usize].clone()
            } else {
                String::new()
            }
        })
        .x_desc(labels.x)
        .y_desc(labels.y)
        .draw()?;
    let width = 0.6 / series.len().max(1) as f64;
    for (k, s) in series.iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let offset = (k as f64 - (series.len() - 1) as f64 / 2.0) * width;
        let points: Vec<(f64, f64, f64)> = s
            .values
            .iter()
            .enumerate()
            .filter_map(|(i, v)| v.map(|(m, d)| (i as f64 + offset, m, d)))
            .collect();
        chart
            .draw_series(
                points
                    .iter()
                    .map(|&(x, m, _)| Circle::new((x, m), 5, color.filled())),
            )?
            .label(s.label.clone())
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
        chart.draw_series(points.iter().map(|&(x, m, d)| {
            PathElement::new(vec![(x, m - d), (x, m + d)], color.stroke_width(2))
        }))?;
    }
    legend_and_save(&mut chart, &root, SeriesLabelPosition::UpperRight)
}

/// The system's fonts, loaded once, with a sans-serif family that exists here (plotters
/// writes `font-family="sans-serif"`; DejaVu Sans where it is installed).
fn fonts() -> Arc<resvg::usvg::fontdb::Database> {
    static FONTS: OnceLock<Arc<resvg::usvg::fontdb::Database>> = OnceLock::new();
    FONTS
        .get_or_init(|| {
            let mut db = resvg::usvg::fontdb::Database::new();
            db.load_system_fonts();
            let families: Vec<String> = db
                .faces()
                .flat_map(|f| f.families.iter().map(|(name, _)| name.clone()))
                .collect();
            if let Some(sans) = families
                .iter()
                .find(|f| *f == "DejaVu Sans")
                .or_else(|| families.iter().find(|f| f.contains("Sans")))
                .or(families.first())
            {
                db.set_sans_serif_family(sans.clone());
            }
            Arc::new(db)
        })
        .clone()
}

/// Renders `svg` to a PNG beside it (same name, `.png`), at twice its size; returns its path.
/// Without any system font the PNG has no text (the SVG keeps it).
pub fn svg_to_png(svg: &Path) -> Result<PathBuf, Box<dyn std::error::Error>> {
    use resvg::{tiny_skia, usvg};
    let text = std::fs::read_to_string(svg)?;
    let options = usvg::Options {
        fontdb: fonts(),
        ..usvg::Options::default()
    };
    let tree = usvg::Tree::from_str(&text, &options)?;
    let size = tree.size().to_int_size().scale_by(2.0).ok_or("empty SVG")?;
    let mut pixmap =
        tiny_skia::Pixmap::new(size.width(), size.height()).ok_or("PNG size out of range")?;
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(2.0, 2.0),
        &mut pixmap.as_mut(),
    );
    let png = svg.with_extension("png");
    pixmap.save_png(&png)?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point without a defined spread (one seed) still sets the axis: a series of one seed
    /// above every other series is drawn inside the chart, not clipped at its edge.
    #[test]
    fn a_point_without_a_spread_is_held_by_the_axis() {
        let range = y_range([(0.0, 10.0), (287.6, f64::NAN), (-420.0, 80.0)].into_iter());
        assert!(range.start < -500.0 && range.end > 287.6, "{range:?}");
        let range = y_range([(5.0, f64::INFINITY)].into_iter());
        assert!(range.start < 5.0 && range.end > 5.0, "{range:?}");
    }
}
