//! The chart of a whole run, [`utilisation_svg`]: each frame's span, one strip per peer shaded by
//! how busy its threads were, and the cluster's busy share over time. It is a unit of its own
//! because it bins the run's time into columns rather than drawing each bar, and it borrows the
//! parent's bar types, palette, legend and lanes for the rest.

use super::{BarKind, FRAME_HUES, FrameSpan, GanttBar, LABEL_AREA, Lanes, WIDTH, draw_legend};
use crate::plot::{PlotError, error_at};
use plotters::prelude::*;
use std::path::Path;

/// Draws the whole run: frame spans, one utilisation strip per peer (`slots[row]` threads; 1
/// where missing), and the cluster's busy share over time.
pub fn utilisation_svg(
    path: &Path,
    title: &str,
    slots: &[u32],
    bars: &[GanttBar],
    frames: &[FrameSpan],
) -> Result<(), PlotError> {
    const BINS: usize = 300;
    let error = error_at(path);
    let rows = bars
        .iter()
        .map(|b| b.row + 1)
        .max()
        .unwrap_or(1)
        .max(slots.len() as u32);
    let end = bars
        .iter()
        .map(|b| b.end)
        .chain(frames.iter().map(|f| f.end))
        .fold(1e-3, f64::max);
    let width = end / BINS as f64;
    let slots_of = |row: u32| f64::from(slots.get(row as usize).copied().unwrap_or(1).max(1));
    // Busy thread-seconds per row and bin, split by the colour they count toward.
    let mut busy = vec![[0.0f64; 3]; rows as usize * BINS];
    for bar in bars {
        let hue = match bar.kind {
            BarKind::Duplicate => 2,
            _ => (bar.frame % 2) as usize,
        };
        let first = ((bar.start / width) as usize).min(BINS - 1);
        let last = ((bar.end / width) as usize).min(BINS - 1);
        for bin in first..=last {
            let (b0, b1) = (bin as f64 * width, (bin + 1) as f64 * width);
            let overlap = bar.end.min(b1) - bar.start.max(b0);
            if overlap > 0.0 {
                busy[bar.row as usize * BINS + bin][hue] += overlap;
            }
        }
    }
    let span_lanes = Lanes::of_spans(frames);
    let band = 40 + 16 * span_lanes.count();
    let strips = (28 * rows).clamp(120, 1400);
    let root = SVGBackend::new(path, (WIDTH, 70 + band + strips + 200)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| error(&e))?;
    let root = root
        .titled(title, ("sans-serif", 20))
        .map_err(|e| error(&e))?;
    let (legend, root) = root.split_vertically(30);
    let keys = [
        (FRAME_HUES[0], "even frames"),
        (FRAME_HUES[1], "odd frames"),
        (
            BarKind::Duplicate.color(),
            "duplicates (paler: threads idle)",
        ),
    ];
    draw_legend(&legend, &keys).map_err(|e| error(&e))?;
    let (top, rest) = root.split_vertically(band);
    let (middle, bottom) = rest.split_vertically(strips);

    // Frames: one bar per frame from its first tile to its completion.
    let mut chart = ChartBuilder::on(&top)
        .margin_right(10)
        .margin_left(10)
        .y_label_area_size(LABEL_AREA)
        .x_label_area_size(0)
        .build_cartesian_2d(0.0..end, 0.0..span_lanes.count() as f64)
        .map_err(|e| error(&e))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(0)
        .y_desc("frames")
        .draw()
        .map_err(|e| error(&e))?;
    for (i, f) in frames.iter().enumerate() {
        let lane = span_lanes.lane[i] as f64;
        let color = FRAME_HUES[(f.frame % 2) as usize];
        chart
            .draw_series([Rectangle::new(
                [(f.start, lane + 0.1), (f.end, lane + 0.9)],
                color.mix(0.8).filled(),
            )])
            .map_err(|e| error(&e))?;
        // A label where the bar is wide enough to hold one (about 8 px a digit).
        let pixels = (f.end - f.start) / end * f64::from(WIDTH - LABEL_AREA - 20);
        let text = f.frame.to_string();
        if pixels > 8.0 * text.len() as f64 + 4.0 {
            chart
                .draw_series([Text::new(
                    text,
                    (f.start + 0.1 * end / f64::from(WIDTH), lane + 0.85),
                    ("sans-serif", 12).into_font().color(&WHITE),
                )])
                .map_err(|e| error(&e))?;
        }
    }

    // One strip per peer: white where idle, deep where every thread was busy.
    let mut chart = ChartBuilder::on(&middle)
        .margin_right(10)
        .margin_left(10)
        .y_label_area_size(LABEL_AREA)
        .x_label_area_size(0)
        .build_cartesian_2d(0.0..end, 0.0..f64::from(rows))
        .map_err(|e| error(&e))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc("peer")
        .y_labels(rows.min(32) as usize + 1)
        .y_label_formatter(&|y| format!("{}", y.floor() as u32))
        .draw()
        .map_err(|e| error(&e))?;
    let cells = (0..rows).flat_map(|row| (0..BINS).map(move |bin| (row, bin)));
    chart
        .draw_series(cells.filter_map(|(row, bin)| {
            let parts = busy[row as usize * BINS + bin];
            let total: f64 = parts.iter().sum();
            if total <= 0.0 {
                return None;
            }
            let share = (total / (width * slots_of(row))).min(1.0);
            let hues = [FRAME_HUES[0], FRAME_HUES[1], BarKind::Duplicate.color()];
            let channel = |c: fn(&RGBColor) -> u8| {
                let hue: f64 = (0..3)
                    .map(|k| parts[k] * f64::from(c(&hues[k])))
                    .sum::<f64>();
                (255.0 * (1.0 - share) + hue / total * share).round() as u8
            };
            let color = RGBColor(channel(|c| c.0), channel(|c| c.1), channel(|c| c.2));
            let (x0, x1) = (bin as f64 * width, (bin + 1) as f64 * width);
            let y0 = f64::from(row) + 0.1;
            Some(Rectangle::new([(x0, y0), (x1, y0 + 0.8)], color.filled()))
        }))
        .map_err(|e| error(&e))?;

    // The cluster's busy share: every thread of every peer.
    let threads: f64 = (0..rows).map(slots_of).sum();
    let share: Vec<(f64, f64)> = (0..BINS)
        .map(|bin| {
            let total: f64 = (0..rows as usize)
                .map(|row| busy[row * BINS + bin].iter().sum::<f64>())
                .sum();
            ((bin as f64 + 0.5) * width, total / (width * threads))
        })
        .collect();
    let mut chart = ChartBuilder::on(&bottom)
        .margin(10)
        .y_label_area_size(LABEL_AREA)
        .x_label_area_size(40)
        .build_cartesian_2d(0.0..end, 0.0..1.05)
        .map_err(|e| error(&e))?;
    chart
        .configure_mesh()
        .x_desc("seconds since the run started")
        .y_desc("busy share")
        .y_labels(6)
        .draw()
        .map_err(|e| error(&e))?;
    chart
        .draw_series(LineSeries::new(share, FRAME_HUES[0].stroke_width(2)))
        .map_err(|e| error(&e))?;
    root.present().map_err(|e| error(&e))
}
