//! What a render tells people: a progress bar with ETA on a terminal (plain log lines otherwise),
//! the per-frame statistics file (`--stats`), and the tile-map pictures (`--tile-map`).
//!
//! The stats schema (JSON) is documented on [`StatsFile`] and its parts; fields are only ever added.

use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::io::IsTerminal;
use std::path::Path;

/// Progress over the frames of a render. Clones share one bar: the frame writer ticks it.
#[derive(Clone)]
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    pub fn new(frames: u32) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new(u64::from(frames));
            bar.set_style(
                ProgressStyle::with_template(
                    "[{bar:40}] frame {pos}/{len}, {elapsed} elapsed, ETA {eta} {msg}",
                )
                .expect("the template is a valid indicatif template")
                .progress_chars("=> "),
            );
            bar
        });
        Self { bar }
    }

    pub fn frame_done(&self, frame: u32, seconds: f64) {
        match &self.bar {
            Some(bar) => {
                bar.set_message(format!("(last {seconds:.2} s)"));
                bar.inc(1);
            }
            None => tracing::info!("frame {frame} done in {seconds:.3} s"),
        }
    }

    /// A line for the log, above the bar on a terminal.
    pub fn line(&self, text: &str) {
        match &self.bar {
            Some(bar) => bar.println(text),
            None => tracing::info!("{text}"),
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// The `--stats` file: one entry per frame, plus what the render was. The one schema of
/// `stats.json` (documented in `docs/stats.md`): `render` and `serve` write it and
/// `simulate --validate` reads it back. Fields missing from older files read as their defaults.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct StatsFile {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub samples_per_pixel: u32,
    /// `pbt` or `regular`.
    pub balancer: String,
    /// How tiles were dealt to peers: `interleaved`, `contiguous` or `round-robin` (empty in
    /// files written before dealing was a choice, which always dealt contiguously).
    pub deal: String,
    /// Motion-compensated prediction (`--motion`): the largest shift searched, in blocks per
    /// frame, or `off` (empty in files written before it existed, which predicted still: off).
    pub motion: String,
    /// The light-transport effects the render paid for (see `tracer::Effects`).
    pub effects: String,
    pub peers: usize,
    /// The render's identity: a hash of the scene files and the render settings
    /// (`runtime::node::bundle::render_hash`), also in every frame's EXR header. Empty in files
    /// written before `--resume` existed.
    pub render_hash: String,
    /// The first frame this run rendered: 0, or with `--resume` the first frame missing. The
    /// frames before it were done already and have no entry in `frames`.
    pub first_frame: u32,
    pub frames: Vec<FrameStats>,
}

/// One frame.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct FrameStats {
    pub frame: u32,
    /// Wall time from the first tile handed out to the last tile received, in seconds.
    pub seconds: f64,
    /// When the frame was complete, in seconds since the render started (0 in older files).
    /// Frames overlap, so the difference between two frames' is what each added to the render.
    pub completed_at: f64,
    pub rays: u64,
    /// Counted work of the whole frame (the tracer's deterministic cost unit).
    pub work: u64,
    /// Population variance of the measured leaf costs (counted work).
    pub leaf_cost_variance: f64,
    /// Largest measured leaf cost divided by the mean: 1 is a perfect partition.
    pub leaf_cost_max_over_mean: f64,
    pub tiles: Vec<TileStats>,
    /// Each peer's own account of the frame.
    pub peers: Vec<PeerFrameStats>,
    /// Duplicate results (backups of stragglers, re-issued tiles) the owner compared with the
    /// first and found bit-identical, and found different: a free audit of determinism.
    pub duplicates_agreed: u32,
    pub duplicates_disagreed: u32,
}

/// One peer's account of one frame (times in seconds of slot time: a peer with 2 rendering
/// threads busy for 1 s reports 2 s busy).
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct PeerFrameStats {
    pub peer: u32,
    pub threads: u32,
    pub busy_seconds: f64,
    pub idle_seconds: f64,
    pub tiles_rendered: u32,
    /// Tiles this peer took from others.
    pub tiles_stolen: u32,
    /// Tiles this peer gave to thieves.
    pub tiles_given: u32,
    pub steal_requests_sent: u32,
    pub steal_requests_refused: u32,
    pub bytes_sent: u64,
    pub bytes_received: u64,
}

impl PeerFrameStats {
    pub fn new(peer: u32, s: &runtime_core::peer::PeerStats) -> Self {
        Self {
            peer,
            threads: s.slots,
            busy_seconds: s.busy.as_secs_f64(),
            idle_seconds: s.idle.as_secs_f64(),
            tiles_rendered: s.tiles_rendered,
            tiles_stolen: s.tiles_stolen,
            tiles_given: s.tiles_given,
            steal_requests_sent: s.steal_requests_sent,
            steal_requests_refused: s.steal_requests_refused,
            bytes_sent: s.bytes_sent,
            bytes_received: s.bytes_received,
        }
    }
}

/// One tile of one frame.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct TileStats {
    /// The tile's index in the frame's partition (depth-first leaf order for the PBT).
    pub tile: u32,
    /// `[x, y, w, h]` in pixels, origin at the top-left.
    pub rect: [u32; 4],
    /// The balancer's prediction, in counted work.
    pub predicted: f64,
    /// The measured counted work.
    pub measured: u64,
    /// The peer that rendered it (0 is the frame owner); of a tile rendered in pieces, the
    /// peer that rendered most of its pixels.
    pub peer: u32,
    /// The peer whose initial set held it; differs from `peer` when stolen or re-issued.
    pub initial_peer: u32,
    /// The pieces it arrived in: 1, or more where it was cut on the way (rendered half by half,
    /// or halved for a thief).
    pub pieces: u32,
}

impl TileStats {
    /// One entry per tile of the partition from a frame's pieces (in tile order, a tile's
    /// pieces together): the tile's rectangle is their bounding box, its costs their sums.
    pub fn per_tile(records: &[runtime::node::TileRecord]) -> Vec<TileStats> {
        let mut tiles: Vec<TileStats> = Vec::new();
        let mut rendered: Vec<(u32, u64)> = Vec::new();
        for record in records {
            let r = record.rect;
            let area = r.area();
            match tiles.last_mut().filter(|t| t.tile == record.tile.0) {
                Some(tile) => {
                    let [x, y, w, h] = tile.rect;
                    let (x1, y1) = ((x + w).max(r.x + r.w), (y + h).max(r.y + r.h));
                    let (x0, y0) = (x.min(r.x), y.min(r.y));
                    tile.rect = [x0, y0, x1 - x0, y1 - y0];
                    tile.predicted += record.predicted;
                    tile.measured += record.measured;
                    tile.pieces += 1;
                }
                None => {
                    if let Some(tile) = tiles.last_mut() {
                        tile.peer = most_pixels(&rendered);
                    }
                    rendered.clear();
                    tiles.push(TileStats {
                        tile: record.tile.0,
                        rect: [r.x, r.y, r.w, r.h],
                        predicted: record.predicted,
                        measured: record.measured,
                        peer: record.peer.0,
                        initial_peer: record.initial.0,
                        pieces: 1,
                    });
                }
            }
            match rendered.iter_mut().find(|(peer, _)| *peer == record.peer.0) {
                Some((_, pixels)) => *pixels += area,
                None => rendered.push((record.peer.0, area)),
            }
        }
        if let Some(tile) = tiles.last_mut() {
            tile.peer = most_pixels(&rendered);
        }
        tiles
    }
}

/// The peer with the most pixels (the first of equals).
fn most_pixels(rendered: &[(u32, u64)]) -> u32 {
    let mut best = (0, 0);
    for &(peer, pixels) in rendered {
        if pixels > best.1 {
            best = (peer, pixels);
        }
    }
    best.0
}

impl FrameStats {
    /// Fills the variance and max/mean from the tiles' measured costs.
    pub fn summarise_leaves(&mut self) {
        let n = self.tiles.len() as f64;
        if n == 0.0 {
            return;
        }
        let mean = self.tiles.iter().map(|t| t.measured as f64).sum::<f64>() / n;
        self.leaf_cost_variance = self
            .tiles
            .iter()
            .map(|t| (t.measured as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
        let max = self.tiles.iter().map(|t| t.measured).max().unwrap_or(0) as f64;
        self.leaf_cost_max_over_mean = if mean > 0.0 { max / mean } else { 1.0 };
    }
}

pub fn write_stats(path: &Path, stats: &StatsFile) -> anyhow::Result<()> {
    let json = serde_json::to_vec_pretty(stats)?;
    std::fs::write(path, json).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Draws the tile map of a frame: the tone-mapped image dimmed, each tile tinted from blue (cheap)
/// to red (expensive) by its measured cost relative to the frame's most expensive tile, and tile
/// borders in white.
pub fn write_tile_map(
    path: &Path,
    width: u32,
    height: u32,
    preview: &[u8],
    tiles: &[([u32; 4], u64)],
) -> anyhow::Result<()> {
    let mut image = image::RgbImage::from_raw(width, height, preview.to_vec())
        .ok_or_else(|| anyhow::anyhow!("preview has the wrong size"))?;
    let max = tiles.iter().map(|t| t.1).max().unwrap_or(1).max(1) as f32;
    for &([x0, y0, w, h], measured) in tiles {
        let heat = measured as f32 / max;
        let tint = [255.0 * heat, 64.0, 255.0 * (1.0 - heat)];
        for y in y0..y0 + h {
            for x in x0..x0 + w {
                let border = x == x0 || y == y0 || x + 1 == x0 + w || y + 1 == y0 + h;
                let pixel = image.get_pixel_mut(x, y);
                pixel.0 = if border {
                    [255, 255, 255]
                } else {
                    std::array::from_fn(|c| (0.35 * f32::from(pixel.0[c]) + 0.45 * tint[c]) as u8)
                };
            }
        }
    }
    image.save_with_format(path, image::ImageFormat::Png)?;
    Ok(())
}

/// Results the owner kept, by (frame, peer, rectangle `[x, y, w, h]`): a render not among them
/// was a duplicate of one that arrived first.
pub type Accepted = std::collections::HashSet<(u64, u32, [u32; 4])>;

/// Draws the `--gantt` pictures: at `path` the whole run (frame spans, one utilisation strip
/// per peer, the cluster's busy share), and beside it, in a folder named after the file
/// (`gantt/` for `gantt.svg`), one chart per frame with every piece a bar. Returns the folder.
pub fn write_gantt(
    path: &Path,
    stats: &StatsFile,
    timelines: &[(runtime_core::wire::PeerId, Vec<runtime::node::LocalTile>)],
    accepted: &Accepted,
) -> anyhow::Result<std::path::PathBuf> {
    use sim::plot::{BarKind, FrameSpan, GanttBar};
    // Each tile's initial peer by (frame, tile), by number: a resumed render's entries start at
    // its first frame. Looked up once per bar, not searched for.
    let initial: std::collections::HashMap<(u64, u32), u32> = stats
        .frames
        .iter()
        .flat_map(|f| {
            f.tiles
                .iter()
                .map(move |t| ((u64::from(f.frame), t.tile), t.initial_peer))
        })
        .collect();
    let mut bars = Vec::new();
    for (peer, tiles) in timelines {
        for t in tiles {
            let rect = [t.rect.x, t.rect.y, t.rect.w, t.rect.h];
            let taken = initial
                .get(&(t.frame, t.tile))
                .is_some_and(|&first| first != peer.0);
            let kind = if !accepted.contains(&(t.frame, peer.0, rect)) {
                BarKind::Duplicate
            } else if t.piece {
                BarKind::Piece
            } else if taken {
                BarKind::Taken
            } else {
                BarKind::Own
            };
            bars.push(GanttBar {
                row: peer.0,
                start: t.start.as_secs_f64(),
                end: t.end.as_secs_f64(),
                frame: t.frame,
                kind,
            });
        }
    }
    let spans: Vec<FrameSpan> = stats
        .frames
        .iter()
        .map(|f| FrameSpan {
            frame: u64::from(f.frame),
            start: (f.completed_at - f.seconds).max(0.0),
            end: f.completed_at,
        })
        .collect();
    let rows = timelines.iter().map(|(p, _)| p.0 + 1).max().unwrap_or(1);
    // Threads per peer, as the peers reported them.
    let mut slots = vec![1u32; rows as usize];
    for peer in stats.frames.iter().flat_map(|f| &f.peers) {
        if let Some(s) = slots.get_mut(peer.peer as usize) {
            *s = (*s).max(peer.threads);
        }
    }
    let title = format!("{} ({} peers)", stats.scene, stats.peers);
    sim::plot::utilisation_svg(path, &title, &slots, &bars, &spans)?;
    let folder = path.with_extension("");
    std::fs::create_dir_all(&folder).map_err(|e| anyhow::anyhow!("{}: {e}", folder.display()))?;
    for span in &spans {
        let chart = folder.join(format!("frame-{:04}.svg", span.frame));
        let title = format!("{}: frame {}", stats.scene, span.frame);
        sim::plot::gantt_svg(&chart, &title, rows, &bars, span.frame)?;
    }
    Ok(folder)
}
