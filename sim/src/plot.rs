//! Charts as SVG files (plotters): the Gantt chart of who rendered what when, shared by real
//! renders (`tessera render --gantt`) and simulated ones.

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
    let error = |e: &dyn std::fmt::Display| PlotError { path: path.display().to_string(), message: e.to_string() };
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
            Rectangle::new([(b.start, y0), (b.end.max(b.start), y0 + 0.8)], color.filled())
        }))
        .map_err(|e| error(&e))?;
    // Thin borders keep neighbouring tiles of one row apart.
    chart
        .draw_series(bars.iter().map(|b| {
            let y0 = f64::from(b.row) + 0.1;
            Rectangle::new([(b.start, y0), (b.end.max(b.start), y0 + 0.8)], WHITE.stroke_width(1))
        }))
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
            GanttBar { row: 0, start: 0.0, end: 1.0, stolen: false },
            GanttBar { row: 1, start: 0.5, end: 2.0, stolen: true },
        ];
        gantt_svg(&path, "test", 2, &bars).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"));
        // Two filled bars, in the two colours.
        assert!(svg.contains("#4678C8") || svg.contains("#4678c8"), "initial colour missing");
        assert!(svg.contains("#F08C28") || svg.contains("#f08c28"), "stolen colour missing");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
