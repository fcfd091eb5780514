//! `tessera bench`: the arguments, and [`lab::bench::run`] on them.

use crate::cli::{EffectsChoice, ImageArgs};
use std::path::PathBuf;

/// Measure the tracer: rays per second for camera rays alone and for full paths, BVH build time,
/// CPU-seconds and wall seconds, per scene.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Scene files (default: every `scenes/*/*.toml` under the current folder; the ones in
    /// `scenes/shared/` are skipped, and listed as skipped, when `../shared/scenes` is absent).
    pub scenes: Vec<PathBuf>,
    #[command(flatten)]
    pub image: ImageArgs,
    /// Maximum depth of the full-path pass, in scattering events as pbrt counts them: a path has
    /// at most `D + 1` segments, so Mitsuba's `max_depth = 8` is our 7 (default: each scene's).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Rendering threads (default: all cores).
    #[arg(long, value_parser = crate::cli::threads)]
    pub threads: Option<usize>,
    /// Write each full-path image to DIR/SCENE.exr, to compare with another renderer's.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also time this many steal exchanges (request, then a grant of tiles) between two peers
    /// over QUIC on loopback; 0 skips it, at most 1000000.
    #[arg(long, default_value_t = 0, value_parser = steal_rtt)]
    pub steal_rtt: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Wavelengths: `rgb` (RGB until dispersive glass, the default), or spectral from the
    /// camera on with three hero wavelengths (`spectral-hero`, what an always-spectral renderer
    /// pays) or one (`spectral-single`).
    #[arg(long, default_value = "rgb", value_parser = ["rgb", "spectral-hero", "spectral-single"])]
    pub spectral: String,
    /// How a tile's paths are advanced: `lanes` (eight at a time, their shading in
    /// vector instructions, where the scene allows it: the default) or `one-by-one`; the same
    /// image either way.
    #[arg(long, default_value = "lanes", value_parser = ["lanes", "one-by-one"])]
    pub paths: String,
    /// Which light-transport effects to pay for: those the scene calls for, or all of them
    /// (the generic pipeline, to measure what specialising saves; the same image either way).
    #[arg(long, value_enum, default_value_t = EffectsChoice::Auto)]
    pub effects: EffectsChoice,
}

/// Measures as the flags say; the image overrides are applied with `tessera render`'s checks.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let image = args.image.clone();
    let available = runtime::node::limits::available_memory();
    lab::bench::run(&lab::bench::Config {
        scenes: args.scenes.clone(),
        // The image flags, then the frame's memory as `render` checks it (its other limits
        // concern messages between peers, which a bench does not send).
        adjust: Box::new(move |settings| {
            image.apply(settings).map_err(|e| e.to_string())?;
            let (width, height) = (settings.width, settings.height);
            match runtime::node::Options::default().check_frame(width, height, None, available) {
                Err(e @ runtime::node::limits::LimitError::Memory { .. }) => {
                    Err(format!("--width {width} --height {height}: {e}"))
                }
                _ => Ok(()),
            }
        }),
        max_depth: args.max_depth,
        threads: args.threads,
        out: args.out.clone(),
        steal_rtt: args.steal_rtt,
        json: args.json,
        spectral: tracer::spectrum::SpectralSampling::ALL
            .into_iter()
            .find(|s| s.name() == args.spectral)
            .unwrap_or_default(),
        paths: tracer::PathLanes::ALL
            .into_iter()
            .find(|p| p.name() == args.paths)
            .unwrap_or_default(),
        effects: args.effects.forced(),
    })?;
    Ok(())
}

/// `--steal-rtt`: 0 to a million exchanges (each keeps its time; 2^32 asked for 32 GB).
fn steal_rtt(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if n <= 1_000_000 => Ok(n),
        _ => Err("a number of exchanges from 0 to 1000000".to_string()),
    }
}
