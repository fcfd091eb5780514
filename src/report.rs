//! What a render tells people: a progress bar with ETA on a terminal (plain log lines otherwise),
//! the per-frame statistics file (`--stats`), and the tile-map pictures (`--tile-map`).
//!
//! The stats schema (JSON) is documented on [`StatsFile`] and its parts; fields are only ever added.

use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::io::IsTerminal;
use std::path::Path;
use std::time::Duration;

/// Progress over all tiles of all frames.
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    pub fn new(frames: u32, tiles_per_frame: u64) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new(u64::from(frames) * tiles_per_frame);
            bar.set_style(
                ProgressStyle::with_template(
                    "{spinner} frame {msg} [{bar:40}] {pos}/{len} tiles, {elapsed} elapsed, ETA {eta}",
                )
                .expect("the template is a valid indicatif template")
                .progress_chars("=> "),
            );
            bar
        });
        Self { bar }
    }

    pub fn frame_started(&self, frame: u32, frames: u32) {
        if let Some(bar) = &self.bar {
            bar.set_message(format!("{}/{}", frame + 1, frames));
        }
    }

    /// Called from rendering threads whenever a tile is done.
    pub fn tile_done(&self) {
        if let Some(bar) = &self.bar {
            bar.inc(1);
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

/// The `--stats` file: one entry per frame, plus what the render was.
#[derive(Debug, Default, Serialize)]
pub struct StatsFile {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub samples_per_pixel: u32,
    /// `pbt` or `regular`.
    pub balancer: String,
    /// The light-transport effects the render paid for (see `tracer::Effects`).
    pub effects: String,
    pub peers: usize,
    pub frames: Vec<FrameStats>,
}

/// One frame.
#[derive(Debug, Default, Serialize)]
pub struct FrameStats {
    pub frame: u32,
    /// Wall time from the first tile handed out to the last tile received, in seconds.
    pub seconds: f64,
    pub rays: u64,
    /// Counted work of the whole frame (the tracer's deterministic cost unit).
    pub work: u64,
    /// Population variance of the measured leaf costs (counted work).
    pub leaf_cost_variance: f64,
    /// Largest measured leaf cost divided by the mean: 1 is a perfect partition.
    pub leaf_cost_max_over_mean: f64,
    pub tiles: Vec<TileStats>,
}

/// One tile of one frame.
#[derive(Debug, Default, Serialize)]
pub struct TileStats {
    /// `[x, y, w, h]` in pixels, origin at the top-left.
    pub rect: [u32; 4],
    /// The balancer's prediction, in counted work.
    pub predicted: f64,
    /// The measured counted work.
    pub measured: u64,
    /// Wall time spent rendering the tile, in seconds.
    pub seconds: f64,
    /// The peer that rendered it (0 is the frame owner).
    pub peer: u32,
}

impl FrameStats {
    /// Fills the variance and max/mean from the tiles' measured costs.
    pub fn summarise_leaves(&mut self) {
        let n = self.tiles.len() as f64;
        if n == 0.0 {
            return;
        }
        let mean = self.tiles.iter().map(|t| t.measured as f64).sum::<f64>() / n;
        self.leaf_cost_variance =
            self.tiles.iter().map(|t| (t.measured as f64 - mean).powi(2)).sum::<f64>() / n;
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
    tiles: &[TileStats],
) -> anyhow::Result<()> {
    let mut image = image::RgbImage::from_raw(width, height, preview.to_vec())
        .ok_or_else(|| anyhow::anyhow!("preview has the wrong size"))?;
    let max = tiles.iter().map(|t| t.measured).max().unwrap_or(1).max(1) as f32;
    for tile in tiles {
        let [x0, y0, w, h] = tile.rect;
        let heat = tile.measured as f32 / max;
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

pub fn seconds(d: Duration) -> f64 {
    d.as_secs_f64()
}
