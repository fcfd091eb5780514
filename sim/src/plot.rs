//! Charts as SVG files (plotters): the Gantt chart of who rendered what when, shared by real
//! renders (`tessera render --gantt`) and simulated ones, and the line charts of experiments
//! (efficiency against peers, against tiles).
//!
//! Charts are SVG so that they diff as text, render in any browser and need no font files.

use plotters::prelude::*;
use std::path::Path;

/// One tile rendered by one peer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GanttBar {
    /// The peer's row.
    pub row: u32,
    /// Seconds since the start of the run.
    pub start: f64,
    pub end: f64,
    /// Whether the tile came from another peer's set (stolen or re-issued) rather than the
    /// peer's own initial set.
    pub stolen: bool,
}

#[derive(Debug, thiserror::Error)]
#[error("drawing {path}: {message}")]
pub struct PlotError {
    path: String,
    message: String,
}

/// Draws one row per peer over time, each tile a bar: blue from the peer's initial set, orange
/// when stolen. Frame boundaries show as gaps where every row idles together.
pub fn gantt_svg(path: &Path, title: &str, rows: u32, bars: &[GanttBar]) -> Result<(), PlotError> {
    let error = |e: &dyn std::fmt::Display| PlotError {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let end = bars.iter().map(|b| b.end).fold(0.0f64, f64::max).max(1e-3);
    let rows = rows.max(1);
    let height = (120 + 40 * rows).min(2000);
    let root = SVGBackend::new(path, (1200, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| error(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..end, 0.0..f64::from(rows))
        .map_err(|e| error(&e))?;
    chart
        .configure_mesh()
        .x_desc("seconds")
        .y_desc("peer")
        .y_labels(rows as usize + 1)
        .y_label_formatter(&|y| format!("{}", y.floor() as u32))
        .disable_y_mesh()
        .draw()
        .map_err(|e| error(&e))?;
    let initial = RGBColor(70, 120, 200);
    let stolen = RGBColor(240, 140, 40);
    chart
        .draw_series(bars.iter().map(|b| {
            let y0 = f64::from(b.row) + 0.1;
            let color = if b.stolen { stolen } else { initial };
            Rectangle::new(
                [(b.start, y0), (b.end.max(b.start), y0 + 0.8)],
                color.filled(),
            )
        }))
        .map_err(|e| error(&e))?;
    // Thin borders keep neighbouring tiles of one row apart.
    chart
        .draw_series(bars.iter().map(|b| {
            let y0 = f64::from(b.row) + 0.1;
            Rectangle::new(
                [(b.start, y0), (b.end.max(b.start), y0 + 0.8)],
                WHITE.stroke_width(1),
            )
        }))
        .map_err(|e| error(&e))?;
    root.present().map_err(|e| error(&e))
}

/// One line of a [`lines_svg`] chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub label: String,
    /// (x, y) points, drawn in order.
    pub points: Vec<(f64, f64)>,
    /// Index into the chart's palette: series of one colour belong together (a policy and its
    /// bound).
    pub color: usize,
    /// Dashed, without markers: a bound or a reference rather than a measurement.
    pub dashed: bool,
}

/// The palette of line charts: distinguishable, and readable in grey.
const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Draws `series` as lines over a base-2 logarithmic x axis (peers and tiles grow by
/// doubling; one grid line per doubling) and a linear y axis from 0 to `y_max`, with a legend.
pub fn lines_svg(
    path: &Path,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    y_max: f64,
    series: &[Series],
) -> Result<(), PlotError> {
    let error = |e: &dyn std::fmt::Display| PlotError {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let log = |x: f64| x.max(1e-9).log2();
    let xs = || {
        series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| log(p.0)))
    };
    let x_min = xs().fold(f64::INFINITY, f64::min).floor();
    let x_max = xs()
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .max(x_min + 1.0);
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| error(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x_min - 0.25..x_max + 0.25, 0.0..y_max)
        .map_err(|e| error(&e))?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_labels((x_max - x_min) as usize + 1)
        .x_label_formatter(&|x| format!("{}", 2f64.powf(x.round())))
        .disable_x_mesh()
        .draw()
        .map_err(|e| error(&e))?;
    for s in series {
        let color = PALETTE[s.color % PALETTE.len()];
        let style = color.stroke_width(2);
        let points = s.points.iter().map(|&(x, y)| (log(x), y));
        let legend = if s.dashed {
            chart
                .draw_series(DashedLineSeries::new(points, 6, 4, style))
                .map_err(|e| error(&e))?
        } else {
            chart
                .draw_series(points.clone().map(|p| Circle::new(p, 3, color.filled())))
                .map_err(|e| error(&e))?;
            chart
                .draw_series(LineSeries::new(points, style))
                .map_err(|e| error(&e))?
        };
        // The legend's sample line is dashed like its series: two short strokes instead of one.
        let (first, second) = match s.dashed {
            true => ((0, 7), (12, 20)),
            false => ((0, 20), (0, 20)),
        };
        legend.label(s.label.as_str()).legend(move |(x, y)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(first.0, 0), (first.1, 0)], color.stroke_width(2))
                + PathElement::new(vec![(second.0, 0), (second.1, 0)], color.stroke_width(2))
        });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerLeft)
        .draw()
        .map_err(|e| error(&e))?;
    root.present().map_err(|e| error(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gantt_writes_an_svg_with_one_bar_per_tile() {
        let dir = std::env::temp_dir().join(format!("tessera-gantt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("g.svg");
        let bars = [
            GanttBar {
                row: 0,
                start: 0.0,
                end: 1.0,
                stolen: false,
            },
            GanttBar {
                row: 1,
                start: 0.5,
                end: 2.0,
                stolen: true,
            },
        ];
        gantt_svg(&path, "test", 2, &bars).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"));
        // Two filled bars, in the two colours.
        assert!(
            svg.contains("#4678C8") || svg.contains("#4678c8"),
            "initial colour missing"
        );
        assert!(
            svg.contains("#F08C28") || svg.contains("#f08c28"),
            "stolen colour missing"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_line_chart_has_its_lines_and_legend() {
        let dir = std::env::temp_dir().join(format!("tessera-lines-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("l.svg");
        let series = [
            Series {
                label: "pbt".into(),
                points: vec![(1.0, 1.0), (4.0, 0.8)],
                color: 0,
                dashed: false,
            },
            Series {
                label: "pbt bound".into(),
                points: vec![(1.0, 1.0), (4.0, 0.9)],
                color: 0,
                dashed: true,
            },
        ];
        lines_svg(&path, "t", ("peers", "efficiency"), 1.0, &series).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("pbt bound") && svg.contains("peers"));
        assert!(svg.matches("<polyline").count() >= 2, "{svg}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
