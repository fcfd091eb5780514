//! How fast the tracer is, in rays per second, on real scenes (`tessera bench`).
//!
//! The figures are meant to be set beside other renderers' (Mitsuba 3, Cycles) and beside our own
//! earlier runs, so the command measures the tracer alone: frame 0 of each scene is rendered
//! straight through [`tracer::render_frame`] on every core, with no peers, no
//! network and no file output in the timed part. That is the same timed render `tessera accuracy`
//! uses, so the two commands cannot disagree about what "one render" costs.
//!
//! Each scene gets two passes. *Primary* sets the maximum depth to 0 (pbrt's convention: emitters
//! seen directly), so it traces exactly one camera ray per sample and measures the BVH and camera
//! alone. *Paths* uses the scene's depth (or `--max-depth`) and measures what a user waits for:
//! closest-hit and shadow rays together, with shading. Every pass reports wall seconds and the
//! CPU-seconds of the whole process over the same interval, because other renderers quote
//! CPU-seconds and because on a shared machine the two differ.
//!
//! A scene whose files are absent (the `scenes/shared/` files point at `../shared/scenes`, which
//! is not part of the repository) is skipped and listed as such; any other loading error stops the
//! command, as it would stop a render.
//!
//! - `rtt`: the steal round trip between two peers on loopback (`--steal-rtt N`).

mod rtt;

use crate::accuracy::bench::render;
use crate::{LabError, ensure};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tracer::scene::RenderSettings;

/// Changes a scene's settings after loading, or says what is wrong with them.
pub type Adjust = Box<dyn Fn(&mut RenderSettings) -> Result<(), String>>;

/// What [`run`] measures, and how it reports.
pub struct Config {
    /// Scene files (empty: every `scenes/*/*.toml` under the current folder).
    pub scenes: Vec<PathBuf>,
    /// Applied to each scene's settings after loading, with the checks `tessera render` makes
    /// (the command line's image overrides); an error names what is wrong.
    pub adjust: Adjust,
    /// Maximum depth of the full-path pass (`None`: each scene's).
    pub max_depth: Option<u32>,
    /// Rendering threads (`None`: all cores).
    pub threads: Option<usize>,
    /// Where each full-path image is written as SCENE.exr, if anywhere.
    pub out: Option<PathBuf>,
    /// Steal exchanges to time between two peers on loopback; 0 skips them.
    pub steal_rtt: usize,
    /// Print JSON instead of text.
    pub json: bool,
    /// Which wavelengths paths sample: RGB until dispersive glass (the default), or spectral
    /// from the camera on, to measure what the always-spectral pipeline costs.
    pub spectral: tracer::spectrum::SpectralSampling,
    /// How a tile's paths are advanced: in lanes where the scene allows it (the default), or
    /// one by one, to measure what the lanes buy (the same image either way).
    pub paths: tracer::PathLanes,
    /// The effects paid for: `None`, those each scene calls for (the default), or a set
    /// forced on (`tracer::Effects::ALL`: the generic pipeline, to measure what specialising
    /// saves; the same image either way).
    pub effects: Option<tracer::Effects>,
}

/// Everything one `tessera bench` run measured.
#[derive(Debug, Serialize)]
pub struct Report {
    /// Rendering threads.
    pub threads: usize,
    /// The wavelength sampling measured (`rgb`: the default, specialised pipeline).
    pub spectral: &'static str,
    /// The machine's load average (1, 5, 15 minutes) before and after, so a reader can tell a
    /// quiet machine from one shared with other work.
    pub load_before: Option<[f64; 3]>,
    /// The load average after the last measurement.
    pub load_after: Option<[f64; 3]>,
    /// Every scene measured.
    pub scenes: Vec<SceneBench>,
    /// Every scene left out, with why.
    pub skipped: Vec<Skipped>,
    /// The steal round trip, if asked for.
    pub steal_rtt: Option<rtt::StealRtt>,
}

/// One scene's figures.
#[derive(Debug, Serialize)]
pub struct SceneBench {
    /// The scene file, as given.
    pub scene: String,
    /// Triangles after loading.
    pub triangles: usize,
    /// Image width rendered.
    pub width: u32,
    /// Image height rendered.
    pub height: u32,
    /// Samples per pixel rendered.
    pub samples_per_pixel: u32,
    /// The effects the world paid for (`tracer::Effects`'s list).
    pub effects: String,
    /// Whether the full paths ran in lanes (`tracer::World::lanes_fit`), or one by one.
    pub path_lanes: bool,
    /// Reading and validating the TOML and OBJ/MTL files.
    pub load_seconds: f64,
    /// Building the BVH (and the light tables, which take a small fraction of it).
    pub build_seconds: f64,
    /// CPU-seconds of the whole process during the build.
    pub build_cpu_seconds: Option<f64>,
    /// Camera rays alone (maximum depth 0).
    pub primary: Pass,
    /// Full paths at the scene's (or `--max-depth`'s) depth.
    pub paths: Pass,
    /// Where the full-path image was written (`--out`).
    pub image: Option<String>,
    /// The whole process's memory around this scene, as the comparison with another renderer
    /// reports it (`scripts/mitsuba_compare.py`); `None` where there is no procfs.
    pub memory: Option<Memory>,
}

/// Resident memory of the whole process, in KiB, from Linux's `/proc/self/status`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Memory {
    /// Resident once the scene is loaded and its trees built (`VmRSS`).
    pub resident_after_build_kib: u64,
    /// Resident after the full-path render (`VmRSS`).
    pub resident_after_render_kib: u64,
    /// The most the process has held so far (`VmHWM`): this scene's peak for the first scene
    /// of a run, the largest of the scenes so far for a later one.
    pub peak_resident_kib: u64,
}

/// One timed render of frame 0.
#[derive(Debug, Serialize)]
pub struct Pass {
    /// `None`: unlimited, ended by Russian roulette.
    pub max_depth: Option<u32>,
    /// The depth from which Russian roulette may end paths (the scene's); `None`: off. Reported
    /// so that a comparison with another renderer can set that renderer's to the same
    /// (`scripts/mitsuba_compare.py`): where paths are rouletted from changes how many segments
    /// a render traces, not its mean.
    pub russian_roulette_depth: Option<u32>,
    /// Closest-hit plus shadow rays.
    pub rays: u64,
    /// Wall seconds of the render.
    pub seconds: f64,
    /// User plus system CPU time of the whole process during the render (all threads).
    pub cpu_seconds: Option<f64>,
    /// Closest-hit plus shadow rays per wall second.
    pub rays_per_second: f64,
    /// Samples dropped as non-finite (a bug if ever non-zero).
    pub invalid_samples: u64,
}

/// A scene that was not measured, and why.
#[derive(Debug, Serialize)]
pub struct Skipped {
    /// The scene file, as given.
    pub scene: String,
    /// Why it was skipped.
    pub reason: String,
}

/// Measures every scene (and the steal round trip, if asked) and prints the figures.
pub fn run(args: &Config) -> Result<Report, LabError> {
    let scenes = if args.scenes.is_empty() {
        shipped_scenes(Path::new("scenes"))?
    } else {
        args.scenes.clone()
    };
    ensure(
        !scenes.is_empty(),
        "no scenes given and no scenes/*/*.toml here; run from the repository root",
    )?;
    let (threads, pool) = crate::pool(args.threads)?;
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).map_err(LabError::io("create", out))?;
    }
    let mut report = Report {
        threads,
        spectral: args.spectral.name(),
        load_before: load_average(),
        load_after: None,
        scenes: Vec::new(),
        skipped: Vec::new(),
        steal_rtt: None,
    };
    for path in &scenes {
        match bench_scene(path, args, &pool)? {
            Ok(scene) => {
                if !args.json {
                    print_scene(&scene);
                }
                report.scenes.push(scene);
            }
            Err(skipped) => {
                if !args.json {
                    println!("{}: skipped, {}", skipped.scene, skipped.reason);
                }
                report.skipped.push(skipped);
            }
        }
    }
    if args.steal_rtt > 0 {
        let measured = rtt::measure(args.steal_rtt)?;
        if !args.json {
            println!("{measured}");
        }
        report.steal_rtt = Some(measured);
    }
    report.load_after = load_average();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let load = |l: Option<[f64; 3]>| {
            l.map_or("unknown".to_owned(), |l| {
                format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2])
            })
        };
        println!(
            "{} threads, wavelengths {}; load average before {}, after {}; {} scenes measured, {} skipped",
            threads,
            report.spectral,
            load(report.load_before),
            load(report.load_after),
            report.scenes.len(),
            report.skipped.len()
        );
    }
    Ok(report)
}

/// Loads, builds and renders one scene twice. The outer error stops the command (a malformed
/// scene, an unwritable output); the inner one is a scene skipped because its files are absent.
fn bench_scene(
    path: &Path,
    args: &Config,
    pool: &rayon::ThreadPool,
) -> Result<Result<SceneBench, Skipped>, LabError> {
    let started = Instant::now();
    let mut scene = match tracer::scene::load(path) {
        Ok(scene) => scene,
        Err(error) => {
            // Only a file the scene refers to may be absent: a scene file named on the command
            // line that does not exist is a mistake, not a scene to skip.
            return match absent_file(&error).filter(|_| path.is_file()) {
                Some(file) => Ok(Err(Skipped {
                    scene: path.display().to_string(),
                    reason: format!("{file} is absent"),
                })),
                None => {
                    Err(LabError::from(error).context(format!("benchmarking {}", path.display())))
                }
            };
        }
    };
    // The same overrides, with the same checks, as `tessera render` applies.
    (args.adjust)(&mut scene.settings).map_err(|message| {
        LabError::Invalid(message).context(format!("benchmarking {}", path.display()))
    })?;
    let load_seconds = started.elapsed().as_secs_f64();
    let build = timed(|| tracer::World::prepare(scene, args.effects));
    let (mut world, build_seconds, build_cpu_seconds) =
        (build.value, build.seconds, build.cpu_seconds);
    let resident_after_build = process_status_kib("VmRSS");
    if let Some(depth) = args.max_depth {
        world.scene.settings.max_depth = Some(depth);
    }
    world.spectral = args.spectral;
    world.paths = args.paths;
    let full_depth = world.scene.settings.max_depth;

    world.scene.settings.max_depth = Some(0);
    let (primary, _) = pass(&world, pool);
    world.scene.settings.max_depth = full_depth;
    let (paths, image) = pass(&world, pool);
    let memory = (|| {
        Some(Memory {
            resident_after_build_kib: resident_after_build?,
            resident_after_render_kib: process_status_kib("VmRSS")?,
            peak_resident_kib: process_status_kib("VmHWM")?,
        })
    })();

    let settings = &world.scene.settings;
    let written = match &args.out {
        Some(out) => {
            let stem = path
                .file_stem()
                .map_or("scene".into(), |s| s.to_string_lossy());
            let file = out.join(format!("{stem}.exr"));
            tracer::output::write_exr(&file, image.width, image.height, &image.pixels)?;
            Some(file.display().to_string())
        }
        None => None,
    };
    Ok(Ok(SceneBench {
        scene: path.display().to_string(),
        triangles: world.scene.triangles.len(),
        width: settings.width,
        height: settings.height,
        samples_per_pixel: settings.samples_per_pixel,
        effects: world.effects.to_string(),
        path_lanes: world.lanes_fit(),
        load_seconds,
        build_seconds,
        build_cpu_seconds,
        primary,
        paths,
        image: written,
        memory,
    }))
}

/// One render of frame 0 at the world's settings, timed once (no repeats: the CPU-seconds must
/// belong to the same interval as the wall seconds).
fn pass(world: &tracer::World, pool: &rayon::ThreadPool) -> (Pass, tracer::output::RgbImage) {
    let measured = timed(|| render(world, pool, 0.0));
    // The render's own timing covers the tiles alone, without the pool's start-up.
    let rendered = measured.value;
    let pass = Pass {
        max_depth: world.scene.settings.max_depth,
        russian_roulette_depth: world.scene.settings.russian_roulette_depth,
        rays: rendered.rays,
        seconds: rendered.seconds,
        cpu_seconds: measured.cpu_seconds,
        rays_per_second: rendered.rays as f64 / rendered.seconds.max(1e-9),
        invalid_samples: rendered.invalid_samples,
    };
    (pass, rendered.image)
}

/// A value with the wall seconds and the process's CPU-seconds it took to make.
struct Timed<T> {
    value: T,
    seconds: f64,
    cpu_seconds: Option<f64>,
}

fn timed<T>(f: impl FnOnce() -> T) -> Timed<T> {
    let cpu = process_cpu_seconds();
    let started = Instant::now();
    let value = f();
    let seconds = started.elapsed().as_secs_f64();
    let cpu_seconds = cpu
        .zip(process_cpu_seconds())
        .map(|(before, after)| after - before);
    Timed {
        value,
        seconds,
        cpu_seconds,
    }
}

/// The file a scene failed to load for because it does not exist, if that was the reason.
fn absent_file(error: &tracer::SceneError) -> Option<String> {
    match error {
        tracer::SceneError::Read { file, source, .. }
            if source.kind() == std::io::ErrorKind::NotFound =>
        {
            Some(file.clone())
        }
        _ => None,
    }
}

/// `DIR/*/*.toml`, sorted.
fn shipped_scenes(dir: &Path) -> Result<Vec<PathBuf>, LabError> {
    let mut scenes = Vec::new();
    if !dir.is_dir() {
        return Ok(scenes);
    }
    for entry in std::fs::read_dir(dir).map_err(LabError::io("read", dir))? {
        let folder = entry.map_err(LabError::io("read", dir))?.path();
        if !folder.is_dir() {
            continue;
        }
        for file in std::fs::read_dir(&folder).map_err(LabError::io("read", &folder))? {
            let file = file.map_err(LabError::io("read", &folder))?.path();
            if file.extension().is_some_and(|e| e == "toml") {
                scenes.push(file);
            }
        }
    }
    scenes.sort();
    Ok(scenes)
}

fn print_scene(s: &SceneBench) {
    let cpu = |seconds: Option<f64>| seconds.map_or("?".to_owned(), |s| format!("{s:.2}"));
    println!(
        "{}: {} triangles, {}x{}, {} spp, effects {}, paths {}; load {:.3} s, BVH build {:.3} s ({} CPU-s)",
        s.scene,
        s.triangles,
        s.width,
        s.height,
        s.samples_per_pixel,
        s.effects,
        if s.path_lanes {
            "in lanes"
        } else {
            "one by one"
        },
        s.load_seconds,
        s.build_seconds,
        cpu(s.build_cpu_seconds)
    );
    for (name, pass) in [("primary", &s.primary), ("paths", &s.paths)] {
        let depth = pass
            .max_depth
            .map_or("unlimited".to_owned(), |d| d.to_string());
        let roulette = pass
            .russian_roulette_depth
            .map_or("off".to_owned(), |d| d.to_string());
        println!(
            "  {name:<7} depth {depth:<9} roulette from {roulette:<3} {:>12} rays in {:>7.3} s wall, {:>7} CPU-s: {:>7.2} Mrays/s{}",
            pass.rays,
            pass.seconds,
            cpu(pass.cpu_seconds),
            pass.rays_per_second / 1e6,
            if pass.invalid_samples > 0 {
                format!(" ({} invalid samples)", pass.invalid_samples)
            } else {
                String::new()
            }
        );
    }
    if let Some(m) = &s.memory {
        let mb = |kib: u64| kib as f64 / 1024.0;
        println!(
            "  memory: {:.1} MB resident after the build, {:.1} MB after the render, {:.1} MB at the process's peak",
            mb(m.resident_after_build_kib),
            mb(m.resident_after_render_kib),
            mb(m.peak_resident_kib)
        );
    }
    if let Some(image) = &s.image {
        println!("  image: {image}");
    }
}

/// CPU time used so far by this process, all threads, user plus system, from `/proc/self/stat`
/// (in ticks of Linux's fixed USER_HZ of 100, so to 10 ms). `None` where there is no procfs.
fn process_cpu_seconds() -> Option<f64> {
    const TICKS_PER_SECOND: f64 = 100.0;
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) is in parentheses and may hold spaces; the rest is plain.
    // After it, field 3 comes first, so utime (field 14) and stime (15) are at 11 and 12.
    let fields: Vec<&str> = stat[stat.rfind(')')? + 1..].split_whitespace().collect();
    let user: u64 = fields.get(11)?.parse().ok()?;
    let system: u64 = fields.get(12)?.parse().ok()?;
    Some((user + system) as f64 / TICKS_PER_SECOND)
}

/// A field of `/proc/self/status` given in kB (`VmRSS`, `VmHWM`), in KiB as Linux means it.
/// `None` where there is no procfs.
fn process_status_kib(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status
        .lines()
        .find(|l| l.split(':').next() == Some(field))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut values = text.split_whitespace().map(|v| v.parse::<f64>().ok());
    Some([values.next()??, values.next()??, values.next()??])
}

#[cfg(test)]
mod tests;
