//! Who rendered what when, in two pictures, because one cannot read at every scale: the
//! shipped 24-frame animation on 2 peers is over six thousand tiles, hair-thin at the width of a
//! page.
//! - [`gantt_svg`]: one frame in full. Every piece is a bar, in lanes per peer (one lane for
//!   each rendering thread busy at once), coloured by what it was: the peer's own tile, one
//!   taken over, a piece of a cut tile, a duplicate. The neighbouring frames' work is drawn in
//!   grey, so that a peer busy with frame f+1 during frame f's tail does not look idle.
//! - [`utilisation_svg`]: the whole run. One strip per peer, where each column's shade is how
//!   busy the peer's threads were and its hue which frames they were on; above it each frame's
//!   span from its first tile to its completion, so that frames in flight show as overlapping
//!   spans; below it the whole cluster's busy share over time, where idle time shows as dips.
//!
//! The second picture is in `utilisation`: it bins the run's time where the first draws bars,
//! and shares this module's bar types, palette, legend and lanes.

use super::{PlotError, error_at};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

mod utilisation;

pub use utilisation::utilisation_svg;

/// What a bar was, as the charts tell apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BarKind {
    /// A whole tile from the peer's own initial set.
    Own,
    /// A whole tile from another peer's set: stolen, or re-issued from a lost peer.
    Taken,
    /// A piece of a tile that was cut: halved for a thief, or the blocks a thief took from a
    /// tile being rendered, or what the victim kept.
    Piece,
    /// Work done twice: in a real render, a result the owner already had from another peer; in
    /// the simulator, a render of pixels another peer had already begun. A straggler's backup,
    /// or the straggler's own late copy.
    Duplicate,
}

impl BarKind {
    const ALL: [BarKind; 4] = [
        BarKind::Own,
        BarKind::Taken,
        BarKind::Piece,
        BarKind::Duplicate,
    ];

    fn color(self) -> RGBColor {
        match self {
            BarKind::Own => RGBColor(70, 120, 200),
            BarKind::Taken => RGBColor(240, 140, 40),
            BarKind::Piece => RGBColor(60, 170, 90),
            BarKind::Duplicate => RGBColor(200, 40, 60),
        }
    }

    fn label(self) -> &'static str {
        match self {
            BarKind::Own => "own tile",
            BarKind::Taken => "taken over",
            BarKind::Piece => "piece of a cut tile",
            BarKind::Duplicate => "duplicate",
        }
    }
}

/// One render of one tile or piece by one peer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GanttBar {
    /// The peer's row.
    pub row: u32,
    /// Seconds since the start of the run.
    pub start: f64,
    /// Seconds since the start of the run at which the render finished.
    pub end: f64,
    /// The frame the tile belongs to, which picks the bar's colour.
    pub frame: u32,
    /// What kind of render it was, which picks the bar's pattern.
    pub kind: BarKind,
}

/// One frame's span over the run: from its first tile's start to its completion, in seconds
/// since the start of the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSpan {
    /// The frame.
    pub frame: u32,
    /// When its first tile started.
    pub start: f64,
    /// When it was complete.
    pub end: f64,
}

/// The grey of work on other frames than the one drawn.
const OTHER_FRAMES: RGBColor = RGBColor(205, 205, 205);
/// The hues of even and odd frames in the utilisation strips: two suffice to tell neighbours
/// apart, and at most a few frames are ever in flight.
const FRAME_HUES: [RGBColor; 2] = [RGBColor(40, 90, 180), RGBColor(20, 150, 120)];
const WIDTH: u32 = 1200;
const LABEL_AREA: u32 = 70;

/// Draws frame `focus` in full: one row per peer, split into lanes where its threads overlap,
/// over seconds since the frame's first piece started. Bars of other frames that fall in that
/// window are grey.
pub fn gantt_svg(
    path: &Path,
    title: &str,
    rows: u32,
    bars: &[GanttBar],
    focus: u32,
) -> Result<(), PlotError> {
    let error = error_at(path);
    let focused = || bars.iter().filter(|b| b.frame == focus);
    let origin = focused().map(|b| b.start).fold(f64::INFINITY, f64::min);
    let origin = if origin.is_finite() { origin } else { 0.0 };
    let span = (focused().map(|b| b.end).fold(origin, f64::max) - origin).max(1e-3);
    let pad = span * 0.02;
    let (x0, x1) = (-pad, span + pad);
    // Bars relative to the frame, clipped to the window.
    let shown: Vec<GanttBar> = bars
        .iter()
        .map(|b| GanttBar {
            start: (b.start - origin).max(x0),
            end: (b.end - origin).min(x1),
            ..*b
        })
        .filter(|b| b.end > b.start)
        .collect();
    let lanes = Lanes::of(rows, &shown);
    let rows = rows.max(1);
    let height = (160 + 40 * rows).clamp(320, 2000);
    let root = SVGBackend::new(path, (WIDTH, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| error(&e))?;
    let root = root
        .titled(title, ("sans-serif", 20))
        .map_err(|e| error(&e))?;
    let (legend, body) = root.split_vertically(30);
    let mut keys: Vec<(RGBColor, &str)> = BarKind::ALL.map(|k| (k.color(), k.label())).to_vec();
    keys.push((OTHER_FRAMES, "other frames"));
    draw_legend(&legend, &keys).map_err(|e| error(&e))?;
    let mut chart = ChartBuilder::on(&body)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(LABEL_AREA)
        .build_cartesian_2d(x0..x1, 0.0..f64::from(rows))
        .map_err(|e| error(&e))?;
    chart
        .configure_mesh()
        .x_desc(format!("seconds since frame {focus}'s first piece started"))
        .y_desc("peer")
        .y_labels(rows.min(32) as usize + 1)
        .y_label_formatter(&|y| format!("{}", y.floor() as u32))
        .disable_y_mesh()
        .draw()
        .map_err(|e| error(&e))?;
    let rect = |i: usize| {
        let (y0, y1) = lanes.band(i, shown[i].row);
        [(shown[i].start, y0), (shown[i].end, y1)]
    };
    // Other frames first, so the frame drawn lies on top where the two touch.
    let order = (0..shown.len())
        .filter(|&i| shown[i].frame != focus)
        .chain((0..shown.len()).filter(|&i| shown[i].frame == focus));
    chart
        .draw_series(order.map(|i| {
            let color = match shown[i].frame == focus {
                true => shown[i].kind.color(),
                false => OTHER_FRAMES,
            };
            Rectangle::new(rect(i), color.filled())
        }))
        .map_err(|e| error(&e))?;
    // Thin borders keep neighbouring pieces of one lane apart, where a bar is wide enough to
    // keep its colour inside them; on a narrower one they would read as idle time.
    let pixels_per_second = f64::from(WIDTH - LABEL_AREA - 20) / (x1 - x0);
    let wide = |i: &usize| (shown[*i].end - shown[*i].start) * pixels_per_second >= 6.0;
    chart
        .draw_series(
            (0..shown.len())
                .filter(wide)
                .map(|i| Rectangle::new(rect(i), WHITE.stroke_width(1))),
        )
        .map_err(|e| error(&e))?;
    root.present().map_err(|e| error(&e))
}

/// Colour keys in a row: a swatch and its name each.
fn draw_legend(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    keys: &[(RGBColor, &str)],
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    let mut x = i32::try_from(LABEL_AREA).unwrap_or(70) + 10;
    for &(color, label) in keys {
        area.draw(&Rectangle::new([(x, 8), (x + 16, 22)], color.filled()))?;
        area.draw(&Text::new(label, (x + 22, 8), ("sans-serif", 14)))?;
        // About 7 px a character at 14 px, and a gap.
        x += 22 + 7 * label.len() as i32 + 24;
    }
    Ok(())
}

/// Where bars that overlap in time go: each row split into as many lanes as it has bars at
/// once, each bar in the first lane free when it starts (interval partitioning, which uses the
/// fewest lanes possible).
struct Lanes {
    /// The lane of each bar, in the order given.
    lane: Vec<u32>,
    /// Lanes per row (one row holding all, for spans).
    per_row: Vec<u32>,
}

impl Lanes {
    fn of(rows: u32, bars: &[GanttBar]) -> Lanes {
        let mut lane = vec![0; bars.len()];
        let mut per_row = vec![1; rows.max(1) as usize];
        let mut free_at: Vec<Vec<f64>> = vec![Vec::new(); per_row.len()];
        let mut order: Vec<usize> = (0..bars.len()).collect();
        order.sort_by(|&a, &b| bars[a].start.total_cmp(&bars[b].start));
        for i in order {
            let row = (bars[i].row as usize).min(per_row.len() - 1);
            lane[i] = place(&mut free_at[row], bars[i].start, bars[i].end);
            per_row[row] = per_row[row].max(lane[i] + 1);
        }
        Lanes { lane, per_row }
    }

    fn of_spans(spans: &[FrameSpan]) -> Lanes {
        let mut lane = vec![0; spans.len()];
        let mut free_at = Vec::new();
        let mut order: Vec<usize> = (0..spans.len()).collect();
        order.sort_by(|&a, &b| spans[a].start.total_cmp(&spans[b].start));
        for i in order {
            lane[i] = place(&mut free_at, spans[i].start, spans[i].end);
        }
        Lanes {
            lane,
            per_row: vec![free_at.len().max(1) as u32],
        }
    }

    /// The most lanes any row has.
    fn count(&self) -> u32 {
        self.per_row.iter().copied().max().unwrap_or(1)
    }

    /// The vertical extent of bar `i` in row `row`.
    fn band(&self, i: usize, row: u32) -> (f64, f64) {
        let lanes = f64::from(self.per_row[(row as usize).min(self.per_row.len() - 1)]);
        let height = 0.8 / lanes;
        let y0 = f64::from(row) + 0.1 + f64::from(self.lane[i]) * height;
        (y0, y0 + height)
    }
}

/// Puts an interval in the first lane free by its start (a little slack absorbs clock
/// rounding between one piece's end and the next one's start), opening a lane if none is.
fn place(free_at: &mut Vec<f64>, start: f64, end: f64) -> u32 {
    let slack = (end - start).abs() * 1e-3;
    let lane = match free_at.iter().position(|&free| free <= start + slack) {
        Some(lane) => lane,
        None => {
            free_at.push(0.0);
            free_at.len() - 1
        }
    };
    free_at[lane] = end;
    lane as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bar(row: u32, start: f64, end: f64, frame: u32, kind: BarKind) -> GanttBar {
        GanttBar {
            row,
            start,
            end,
            frame,
            kind,
        }
    }

    fn temp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("tessera-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(format!("{name}.svg"))
    }

    fn has_color(svg: &str, color: RGBColor) -> bool {
        let hex = format!("#{:02X}{:02X}{:02X}", color.0, color.1, color.2);
        svg.contains(&hex) || svg.contains(&hex.to_lowercase())
    }

    #[test]
    fn a_frame_chart_colours_each_kind_and_greys_other_frames() {
        let path = temp("gantt");
        let bars = [
            bar(0, 1.0, 2.0, 3, BarKind::Own),
            bar(1, 1.5, 3.0, 3, BarKind::Taken),
            bar(1, 1.2, 1.4, 3, BarKind::Piece),
            bar(0, 2.0, 2.5, 3, BarKind::Duplicate),
            bar(0, 2.5, 3.0, 4, BarKind::Own),
        ];
        gantt_svg(&path, "test", 2, &bars, 3).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"));
        for kind in BarKind::ALL {
            assert!(has_color(&svg, kind.color()), "{kind:?} missing");
            assert!(svg.contains(kind.label()), "{kind:?}'s key missing");
        }
        assert!(svg.contains("frame 3"));
        // The legend's swatch is grey too: frame 4's bar is one more grey rectangle.
        let greys = |svg: &str| {
            let hex = format!(
                "#{:02X}{:02X}{:02X}",
                OTHER_FRAMES.0, OTHER_FRAMES.1, OTHER_FRAMES.2
            );
            svg.matches(&hex).count() + svg.matches(&hex.to_lowercase()).count()
        };
        let with_other = greys(&svg);
        gantt_svg(&path, "test", 2, &bars[..4], 3).unwrap();
        let without = greys(&std::fs::read_to_string(&path).unwrap());
        assert_eq!(with_other, without + 1, "frame 4's bar is not grey");
        std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    }

    #[test]
    fn overlapping_bars_get_lanes_and_sequential_ones_share_one() {
        let bars = [
            bar(0, 0.0, 1.0, 0, BarKind::Own),
            bar(0, 1.0, 2.0, 0, BarKind::Own),
            bar(0, 0.5, 1.5, 0, BarKind::Own),
            bar(1, 0.0, 3.0, 0, BarKind::Own),
        ];
        let lanes = Lanes::of(2, &bars);
        assert_eq!(lanes.lane, vec![0, 0, 1, 0]);
        assert_eq!(lanes.per_row, vec![2, 1]);
        let (a0, a1) = lanes.band(0, 0);
        let (b0, b1) = lanes.band(2, 0);
        assert!(a1 <= b0 + 1e-12 && a0 < a1 && b0 < b1 && b1 <= 0.9 + 1e-12);
        let (c0, c1) = lanes.band(3, 1);
        assert!(
            (c0 - 1.1).abs() < 1e-12 && (c1 - 1.9).abs() < 1e-12,
            "{c0} {c1}"
        );
    }

    #[test]
    fn utilisation_shades_busy_time_and_stacks_overlapping_frames() {
        let path = temp("utilisation");
        let bars = [
            bar(0, 0.0, 1.0, 0, BarKind::Own),
            bar(1, 0.0, 0.5, 0, BarKind::Own),
            bar(1, 0.5, 1.0, 1, BarKind::Own),
        ];
        let frames = [
            FrameSpan {
                frame: 0,
                start: 0.0,
                end: 0.8,
            },
            FrameSpan {
                frame: 1,
                start: 0.4,
                end: 1.0,
            },
        ];
        assert_eq!(
            Lanes::of_spans(&frames).count(),
            2,
            "frames in flight overlap"
        );
        utilisation_svg(&path, "run", &[1, 1], &bars, &frames).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        // A fully busy single thread on an even frame is the even hue itself; the odd frame
        // shows in its own hue.
        assert!(has_color(&svg, FRAME_HUES[0]) && has_color(&svg, FRAME_HUES[1]));
        assert!(svg.contains("busy share") && svg.contains("frames"));
        // Two threads on one peer, one busy: half shade, never the full hue.
        utilisation_svg(&path, "run", &[2], &bars[..1], &frames[..1]).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        let half = RGBColor(148, 173, 218);
        assert!(has_color(&svg, half), "half-busy shade missing");
        std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    }
}
