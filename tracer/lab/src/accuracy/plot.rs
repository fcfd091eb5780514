//! accuracy.svg: the error of every rung against its cost, log-log, one curve per knob (see
//! `report.rs` for the other two outputs).

use super::Knob;
use super::bench::Row;
use super::report::Run;
use plotters::prelude::*;
use std::path::Path;

const SIZE: (u32, u32) = (960, 640);

/// A point of the plot: seconds, relMSE, and its label.
type Point = (f64, f64, String);

/// accuracy.svg: relative MSE against time, log-log, one curve per knob. Log-log because both
/// axes span orders of magnitude and because Monte Carlo noise is a straight line there (slope -1
/// against time when time grows with samples), so a knob that beats "just render longer" shows as
/// a point below the spp curve, and a bias as a curve that flattens. Each point is labelled with
/// its knob value; the reference's own noise is drawn as a dashed floor.
pub fn write_svg(path: &Path, run: &Run) -> Result<(), crate::LabError> {
    draw(path, run).map_err(|e| crate::LabError::Plot {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

fn draw(path: &Path, run: &Run) -> Result<(), Box<dyn std::error::Error>> {
    let curves: Vec<(Knob, Vec<Point>)> = Knob::ALL
        .into_iter()
        .map(|knob| {
            let points = run
                .rows_of(knob)
                .filter(|r| r.cost(run.cost) > 0.0 && r.metrics.rel_mse > 0.0)
                .map(|r| (r.cost(run.cost), r.metrics.rel_mse, label(r)))
                .collect::<Vec<_>>();
            (knob, points)
        })
        // obvhs's counted work leaves out its inner nodes: not a cost to set beside ours.
        .filter(|(knob, _)| !(run.cost == super::Cost::Work && *knob == Knob::Traversal))
        .filter(|(_, points)| !points.is_empty())
        .collect();
    let root = SVGBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let floor = run.reference.noise_rel_mse;
    let all = || curves.iter().flat_map(|(_, p)| p.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for (x, y, _) in all() {
        (x0, x1, y0, y1) = (x0.min(*x), x1.max(*x), y0.min(*y), y1.max(*y));
    }
    if floor > 0.0 {
        (y0, y1) = (y0.min(floor), y1.max(floor));
    }
    if !x0.is_finite() || !y0.is_finite() {
        // Nothing measured with a positive time and error: an empty chart says so.
        (x0, x1, y0, y1) = (1e-3, 1.0, 1e-3, 1.0);
    }
    let (x0, x1, y0, y1) = (x0 / 1.5, x1 * 1.5, y0 / 1.5, y1 * 1.5);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Error against {}: {} ({}x{})",
                run.cost.name(),
                run.scene,
                run.width,
                run.height
            ),
            ("sans-serif", 20),
        )
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc(match run.cost {
            super::Cost::Time => "seconds per frame (BVH: build + render)",
            super::Cost::Work => "counted work per frame (millions of units)",
        })
        .y_desc("relMSE against the reference")
        .x_labels(8)
        .y_labels(8)
        .max_light_lines(2)
        .light_line_style(BLACK.mix(0.05))
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    for (knob, points) in &curves {
        let color = colour(*knob);
        let legend = match knob {
            Knob::Spp => "samples per pixel".to_owned(),
            other => format!("{} (at {} spp)", other.name(), run.knob_spp),
        };
        chart
            .draw_series(
                LineSeries::new(points.iter().map(|p| (p.0, p.1)), color.stroke_width(2))
                    .point_size(3),
            )?
            .label(legend)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        // The BVH and traversal rungs sit on top of each other (same image, similar time): their
        // labels would be a smudge, and the legend and the tables name them.
        if matches!(knob, Knob::Spp | Knob::Depth | Knob::Roulette | Knob::Media) {
            chart.draw_series(points.iter().map(|(x, y, text)| {
                Text::new(
                    text.clone(),
                    (*x, *y),
                    ("sans-serif", 11).into_font().color(&color),
                )
            }))?;
        }
    }
    if floor > 0.0 {
        chart
            .draw_series(DashedLineSeries::new(
                vec![(x0, floor), (x1, floor)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))?
            .label("reference's own noise")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.5)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The short label beside a point: the knob's value alone (the legend names the knob).
fn label(row: &Row) -> String {
    match row.knob {
        Knob::Spp => row.settings.samples_per_pixel.to_string(),
        Knob::Depth => row
            .settings
            .max_depth
            .map_or("unlimited".to_owned(), |d| d.to_string()),
        Knob::Roulette => row
            .settings
            .russian_roulette_depth
            .map_or("off".to_owned(), |d| format!("rr {d}")),
        Knob::Bvh
        | Knob::Traversal
        | Knob::Offset
        | Knob::Lights
        | Knob::Environment
        | Knob::Spectral
        | Knob::Media => row.setting.clone(),
    }
}

fn colour(knob: Knob) -> RGBColor {
    match knob {
        Knob::Spp => RGBColor(31, 119, 180),
        Knob::Depth => RGBColor(214, 39, 40),
        Knob::Roulette => RGBColor(44, 160, 44),
        Knob::Bvh => RGBColor(255, 127, 14),
        Knob::Traversal => RGBColor(148, 103, 189),
        Knob::Offset => RGBColor(140, 86, 75),
        Knob::Lights => RGBColor(227, 119, 194),
        Knob::Environment => RGBColor(23, 190, 207),
        Knob::Spectral => RGBColor(188, 189, 34),
        Knob::Media => RGBColor(127, 127, 127),
    }
}
