//! What accuracy costs in time, measured rather than asserted (`tessera accuracy`).
//!
//! Every accuracy knob of the renderer trades time for error, and a reader choosing settings needs
//! both numbers side by side. So the command renders one scene over a ladder of values per knob,
//! times each render with the wall clock (the tracer has none), measures its error against a
//! reference, and writes a table, a log-log plot and the equal-time / equal-error comparisons.
//!
//! Every rung changes one thing from a *baseline*: unlimited path depth ended by Russian roulette
//! (unbiased), our robust traversal, the default BVH quality. The reference is the baseline at
//! many samples per pixel with seeds of its own, so that its noise is independent of the rungs'
//! (a rung at n spp uses sample indices 0..n, and a reference with the same seed would share
//! them); it is cached in the output folder with a sidecar of its settings, or replaced by an
//! exact value when the scene is a furnace whose answer is known (`--analytic-mean`).
//!
//! - `bench`: the timed render of a whole frame, and the one-knob-at-a-time ladders.
//! - `reference`: the reference image: analytic, cached, or rendered and cached.
//! - `sampling`: the sampling knobs' ladders: area lights, the environment, wavelengths and
//!   media (free flights and shadow rays through participating media).
//! - `leaks`: robust against obvhs's traversal on a closed sphere, and the two spawn offsets on
//!   the sphere far from the origin: leaks and self-hits.
//! - `report`: accuracy.csv and accuracy.md; `plot`: accuracy.svg.
//! - `findings`: the equal-time and equal-error comparisons, in sentences; `curve`: the spp
//!   ladder as the yardstick they are read off.

pub mod bench;
mod curve;
mod findings;
mod leaks;
mod plot;
pub mod reference;
mod report;
mod sampling;

use crate::{LabError, ensure};
use clap::ValueEnum;
use std::path::PathBuf;
use tracer::World;
use tracer::geometry::BuildQuality;
use tracer::scene::RenderSettings;

/// The default image width (and height, for a square scene): small enough that the full set of
/// ladders runs in minutes on two cores, large enough for a few thousand pixels of statistics.
pub const DEFAULT_SIZE: u32 = 128;

/// What [`run`] measures and where it writes: the command line's flags, defaults resolved by the
/// binary's argument parser.
#[derive(Clone, Debug)]
pub struct Config {
    /// The scene file (TOML; see scenes/README.md).
    pub scene: PathBuf,
    /// Output folder; the cached reference (reference.exr and reference.json) lives here too.
    pub out: PathBuf,
    /// The top of the samples-per-pixel ladder 1, 2, 4, ... (rounded down to a power of two).
    pub max_spp: u32,
    /// Image width (default: 128 pixels on the scene's longer side, keeping its aspect ratio).
    pub width: Option<u32>,
    /// Image height (default: as for the width).
    pub height: Option<u32>,
    /// Samples per pixel of the depth, roulette, BVH and traversal ladders.
    pub knob_spp: u32,
    /// Samples per pixel of the rendered reference (default: 4 x max-spp).
    pub reference_spp: Option<u32>,
    /// The exact mean radiance of every pixel, "R,G,B", for scenes that have one (a furnace):
    /// used as the reference instead of a render.
    pub analytic_mean: Option<Rgb>,
    /// Seed of the ladders' pixel sampler (default: the scene's).
    pub seed: Option<u64>,
    /// Which knobs to measure, comma-separated.
    pub knobs: Vec<Knob>,
    /// Rays shot per traversal by the closed-sphere leak check.
    pub leak_rays: u32,
    /// Renders (and BVH builds) faster than this many seconds are repeated and the fastest run
    /// kept, for times that scheduler noise and other processes disturb less; 0 times each once.
    pub repeat_below: f64,
    /// Time every render (and BVH build) at least this many times and keep the fastest: on a
    /// machine busy with other work, more runs give steadier comparisons.
    pub repeats: u32,
    /// What the comparisons (equal cost, efficiency, the plot) count as cost: wall time, or the
    /// tracer's counted work, which the machine's load does not change (for a shared machine).
    pub cost: Cost,
    /// Rendering threads (default: all cores).
    pub threads: Option<usize>,
    /// Memory free on this machine in bytes, if known: an image whose films would not fit is
    /// refused before anything is rendered.
    pub available_memory: Option<u64>,
    /// The command as a reader would retype it, for the report's header.
    pub command: String,
}

/// What a rung costs, for the comparisons between rungs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Cost {
    /// Wall-clock seconds (BVH: build plus render).
    Time,
    /// The tracer's counted work in millions of units: nodes visited, triangles tested and a
    /// charge per ray (see `tracer::PathStats::work`). Deterministic, and close to proportional
    /// to time on one machine.
    Work,
}

impl Cost {
    /// The cost's name in a sentence.
    pub fn name(self) -> &'static str {
        match self {
            Cost::Time => "time",
            Cost::Work => "counted work",
        }
    }

    /// The unit after a number.
    pub fn unit(self) -> &'static str {
        match self {
            Cost::Time => "s",
            Cost::Work => "M work units",
        }
    }
}

/// An RGB triple given on the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rgb(pub [f32; 3]);

/// The accuracy knobs, each a ladder of values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Knob {
    /// Samples per pixel 1, 2, 4, ... max-spp.
    Spp,
    /// Maximum path depth 1, 2, 4, 8, 16 and unlimited (Russian roulette).
    Depth,
    /// Russian roulette off, or on from a start depth.
    Roulette,
    /// Each BVH build quality.
    Bvh,
    /// Our robust traversal, 8-wide (what renders use, a pixel's camera rays in packets), the
    /// same with every ray alone, and binary, against obvhs's own.
    Traversal,
    /// Spawn offsets from each hit point's error bound against the fixed 256 ULPs.
    Offset,
    /// Area lights found by both strategies weighted by the power heuristic (the default), by
    /// next-event estimation alone, or by BSDF sampling alone
    /// (`tracer::integrator::AreaLightSampling`).
    Lights,
    /// The environment sampled by importance (a map by luminance, and through the scene's
    /// portals where it has them), by importance with the portals ignored, uniformly, or by
    /// BSDF sampling alone (no MIS).
    Environment,
    /// Wavelengths: RGB until dispersive glass (the default), or spectral from the camera on,
    /// with three hero wavelengths or one (`tracer::spectrum::SpectralSampling`).
    Spectral,
    /// Participating media sampled analytically by a hero channel (the default), by a
    /// per-flight channel mixture, or by delta and ratio tracking with a grey majorant.
    Media,
}

impl Knob {
    /// Every knob, in the order the report shows them.
    pub const ALL: [Knob; 10] = [
        Knob::Spp,
        Knob::Depth,
        Knob::Roulette,
        Knob::Bvh,
        Knob::Traversal,
        Knob::Offset,
        Knob::Lights,
        Knob::Environment,
        Knob::Spectral,
        Knob::Media,
    ];

    /// The knob's name in the CSV, the report and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Knob::Spp => "spp",
            Knob::Depth => "depth",
            Knob::Roulette => "roulette",
            Knob::Bvh => "bvh",
            Knob::Traversal => "traversal",
            Knob::Offset => "offset",
            Knob::Lights => "lights",
            Knob::Environment => "environment",
            Knob::Spectral => "spectral",
            Knob::Media => "media",
        }
    }
}

/// Measures every knob `args.knobs` names, prints progress, and writes DIR/accuracy.csv,
/// DIR/accuracy.md and DIR/accuracy.svg.
pub fn run(args: &Config) -> Result<(), LabError> {
    ensure(
        args.max_spp >= 1 && args.knob_spp >= 1,
        "samples per pixel must be at least 1",
    )?;
    for (i, knob) in args.knobs.iter().enumerate() {
        ensure(
            !args.knobs[..i].contains(knob),
            &format!(
                "--knobs names `{}` twice; each knob is measured once",
                knob.to_possible_value()
                    .map_or_else(|| format!("{knob:?}"), |v| v.get_name().to_owned())
            ),
        )?;
    }
    ensure(
        args.reference_spp.is_none_or(|n| n >= 2),
        "the reference needs at least 2 samples per pixel",
    )?;
    ensure(
        args.repeat_below.is_finite() && args.repeat_below >= 0.0,
        "--repeat-below must be a number of seconds, 0 or more",
    )?;
    let mut scene = tracer::scene::load(&args.scene)?;
    let (width, height) = image_size(
        args.width,
        args.height,
        scene.settings.width,
        scene.settings.height,
    )?;
    if let Some(available) = args.available_memory {
        let needed = u64::from(width) * u64::from(height) * BYTES_PER_PIXEL;
        ensure(
            needed <= available,
            &format!(
                "--width {width} --height {height}: the images need about {} MiB, and this \
                 machine has {} MiB free",
                needed >> 20,
                available >> 20
            ),
        )?;
    }
    let scene_settings = scene.settings.clone();
    scene.settings = RenderSettings {
        width,
        height,
        samples_per_pixel: 1,
        max_depth: None,
        russian_roulette_depth: Some(scene_settings.russian_roulette_depth.unwrap_or(3)),
        seed: args.seed.unwrap_or(scene_settings.seed),
        frames: 1,
        media: tracer::medium::MediaSampling::default(),
    };
    let files_hash = reference::hash_scene_files(&args.scene, &scene.files)?;
    let (threads, pool) = crate::pool(args.threads)?;
    let mut world = World::prepare(scene, None);
    std::fs::create_dir_all(&args.out).map_err(LabError::io("create", &args.out))?;

    println!(
        "{}: {}x{}, {} triangles, effects {}, {} threads; baseline: unlimited depth, roulette from depth {}, robust traversal, {:?} BVH",
        args.scene.display(),
        width,
        height,
        world.scene.triangles.len(),
        world.effects,
        threads,
        world.scene.settings.russian_roulette_depth.unwrap_or(0),
        BuildQuality::default(),
    );
    let reference_spp = args
        .reference_spp
        .unwrap_or(args.max_spp.saturating_mul(4))
        .max(2);
    let reference = match args.analytic_mean {
        Some(Rgb(mean)) => reference::Reference::analytic(width, height, mean),
        None => reference::Reference::cached_or_rendered(
            &args.out,
            &args.scene,
            files_hash,
            reference_spp,
            &mut world,
            &pool,
        )?,
    };
    println!("reference: {}", reference.describe());

    let timing = bench::Timing {
        repeat_below: args.repeat_below,
        repeats: args.repeats.max(1),
    };
    let load_before = load_average();
    let mut bench = bench::Bench::new(world, &pool, &reference, timing);
    let mut rows = Vec::new();
    let mut leak_checks = Vec::new();
    let mut offset_checks = Vec::new();
    for &knob in &args.knobs {
        rows.extend(match knob {
            Knob::Spp => bench.spp_ladder(args.max_spp),
            Knob::Depth => bench.depth_ladder(args.knob_spp),
            Knob::Roulette => bench.roulette_ladder(args.knob_spp),
            Knob::Bvh => bench.bvh_ladder(args.knob_spp),
            Knob::Traversal => {
                leak_checks = leaks::closed_sphere(&pool, args.leak_rays);
                for check in &leak_checks {
                    println!("  {}", check.describe());
                }
                bench.traversal_ladder(args.knob_spp)
            }
            Knob::Offset => {
                offset_checks = leaks::far_sphere(&pool, args.leak_rays);
                for check in &offset_checks {
                    println!("  {}", check.describe());
                }
                bench.offset_ladder(args.knob_spp)
            }
            Knob::Lights => bench.lights_ladder(args.knob_spp),
            Knob::Environment => bench.environment_ladder(args.knob_spp),
            Knob::Spectral => bench.spectral_ladder(args.knob_spp),
            Knob::Media => bench.media_ladder(args.knob_spp),
        });
    }
    let run = report::Run {
        command: args.command.clone(),
        load_average: [load_before, load_average()],
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        scene: args.scene.display().to_string(),
        width,
        height,
        threads,
        triangles: bench.world().scene.triangles.len(),
        scene_settings,
        baseline: bench.world().scene.settings.clone(),
        knob_spp: args.knob_spp,
        timing,
        cost: args.cost,
        reference: &reference,
        rows: &rows,
        leak_checks: &leak_checks,
        offset_checks: &offset_checks,
    };
    report::write_all(&args.out, &run)?;
    println!(
        "wrote {0}/accuracy.csv, {0}/accuracy.md and {0}/accuracy.svg",
        args.out.display()
    );
    Ok(())
}

/// What the measurement holds per pixel at once, about: the reference's sums in `f64` and its
/// image, a rung's film and image, and their error maps.
const BYTES_PER_PIXEL: u64 = 64;

/// The image size: the flags, or the scene's size scaled so its longer side is [`DEFAULT_SIZE`]
/// pixels; a single flag keeps the scene's aspect ratio.
fn image_size(
    width: Option<u32>,
    height: Option<u32>,
    scene_w: u32,
    scene_h: u32,
) -> Result<(u32, u32), LabError> {
    let aspect = f64::from(scene_w) / f64::from(scene_h);
    let scaled = |v: f64| (v.round() as u32).max(1);
    let size = match (width, height) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, scaled(f64::from(w) / aspect)),
        (None, Some(h)) => (scaled(f64::from(h) * aspect), h),
        (None, None) if scene_w >= scene_h => {
            (DEFAULT_SIZE, scaled(f64::from(DEFAULT_SIZE) / aspect))
        }
        (None, None) => (scaled(f64::from(DEFAULT_SIZE) * aspect), DEFAULT_SIZE),
    };
    ensure(
        size.0 > 0 && size.1 > 0,
        "the image must be at least 1x1 pixels",
    )?;
    Ok(size)
}

/// The one-minute load average (`/proc/loadavg`, Linux only): how many threads wanted a core. Above
/// the number of cores, other work was sharing them and wall times are inflated.
fn load_average() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_size_keeps_the_aspect_ratio() {
        assert_eq!(image_size(None, None, 512, 512).unwrap(), (128, 128));
        assert_eq!(image_size(None, None, 1920, 1080).unwrap(), (128, 72));
        assert_eq!(image_size(None, None, 600, 800).unwrap(), (96, 128));
        assert_eq!(image_size(Some(64), None, 1920, 1080).unwrap(), (64, 36));
        assert_eq!(image_size(Some(10), Some(20), 512, 512).unwrap(), (10, 20));
    }
}
