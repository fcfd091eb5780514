//! `tessera bench`: the arguments, and [`lab::bench::run`] on them.

use crate::cli::ImageArgs;
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
    /// over QUIC on loopback; 0 skips it.
    #[arg(long, default_value_t = 0)]
    pub steal_rtt: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Wavelengths: `rgb` (RGB until dispersive glass, the default), or spectral from the
    /// camera on with three hero wavelengths (`spectral-hero`, what an always-spectral renderer
    /// pays) or one (`spectral-single`).
    #[arg(long, default_value = "rgb", value_parser = ["rgb", "spectral-hero", "spectral-single"])]
    pub spectral: String,
}

/// Measures as the flags say; the image overrides are applied with `tessera render`'s checks.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let image = args.image.clone();
    lab::bench::run(&lab::bench::Config {
        scenes: args.scenes.clone(),
        adjust: Box::new(move |settings| image.apply(settings).map_err(|e| e.to_string())),
        max_depth: args.max_depth,
        threads: args.threads,
        out: args.out.clone(),
        steal_rtt: args.steal_rtt,
        json: args.json,
        spectral: tracer::spectrum::SpectralSampling::ALL
            .into_iter()
            .find(|s| s.name() == args.spectral)
            .unwrap_or_default(),
    })?;
    Ok(())
}
