//! Command-line arguments.

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// A distributed parallel ray tracer: tiles from a Prediction Binary Tree, work stealing over QUIC.
#[derive(Debug, Parser)]
#[command(name = "tessera", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render a scene (all frames of its animation) to EXR and PNG files.
    Render(RenderArgs),
    /// Compare two OpenEXR images (B is the reference): RMSE, relative MSE, FLIP, ...
    Compare(crate::compare::CompareArgs),
    /// Measure what accuracy costs in time: error against time for each accuracy knob.
    Accuracy(crate::accuracy::AccuracyArgs),
}

#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The scene file (TOML; see scenes/README.md).
    pub scene: PathBuf,
    /// Output folder for frame-NNNN.exr and frame-NNNN.png (created if missing).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Number of frames to render (default: the scene's `frames`).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Samples per pixel (default: the scene's).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Image width in pixels (default: the scene's).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (default: the scene's).
    #[arg(long)]
    pub height: Option<u32>,
    /// Peers in this process, each with its own rendering threads, talking QUIC on loopback
    /// with certificates made in memory. Peer 0 owns the frames. `--peers 1` renders alone.
    #[arg(long, default_value_t = 2)]
    pub peers: usize,
    /// Rendering threads in all, shared evenly by the peers (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Turn work stealing between peers off (each renders its initial set only).
    #[arg(long)]
    pub no_steal: bool,
    /// Write a Gantt chart (SVG): one row per peer over time, each tile a bar coloured by
    /// whether it was the peer's own or taken from another peer.
    #[arg(long)]
    pub gantt: Option<PathBuf>,
    /// Seed of the pixel sampler (default: the scene's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// How frames are cut into tiles.
    #[arg(long, value_enum, default_value_t = BalancerKind::Pbt)]
    pub balancer: BalancerKind,
    /// Number of tiles per frame (PBT leaves, or grid cells rounded to a k x k grid).
    #[arg(long, default_value_t = 256)]
    pub tiles: usize,
    /// Which light-transport effects to pay for: those the scene calls for, or all of them.
    #[arg(long, value_enum, default_value_t = EffectsChoice::Auto)]
    pub effects: EffectsChoice,
    /// Write per-frame statistics (tiles, costs, times) as JSON to this file.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Write OUT/tiles-NNNN.png per frame: the image dimmed, tile borders, tiles tinted by cost.
    #[arg(long)]
    pub tile_map: bool,
    /// Exposure of the PNG previews (the EXR files are always linear and unscaled).
    #[arg(long, default_value_t = 1.0)]
    pub exposure: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BalancerKind {
    /// The Prediction Binary Tree: tiles sized by last frame's measured cost.
    Pbt,
    /// A regular grid of equal tiles.
    Regular,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum EffectsChoice {
    /// Only the effects the scene calls for.
    Auto,
    /// Every effect forced on (bit-identical images; for checking and timing).
    All,
}
