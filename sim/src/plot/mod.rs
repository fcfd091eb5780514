//! Charts as SVG files (plotters): the line charts of experiments (efficiency against peers,
//! against tiles), here, and in `gantt` the charts of who rendered what when, shared by real
//! renders (`tessera render --gantt`) and simulated ones, and in `render` the charts of a real
//! render from its statistics and its peers' timelines.
//!
//! Charts are SVG so that they diff as text, render in any browser and need no font files.

mod gantt;
mod render;

pub use gantt::{BarKind, FrameSpan, GanttBar, gantt_svg, utilisation_svg};
pub use render::render_charts;

use plotters::prelude::*;
use std::path::Path;

/// A chart that could not be drawn: the file, and what the drawing library said.
#[derive(Debug, thiserror::Error)]
#[error("drawing {path}: {message}")]
pub struct PlotError {
    path: String,
    message: String,
}

/// Turns a drawing error into a [`PlotError`] naming the file being drawn.
fn error_at(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// One line of a [`lines_svg`] chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// The legend's text for the line.
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
    let error = error_at(path);
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
