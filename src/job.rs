//! What every command that renders a scene's frames shares (`render`, `serve`, and `slurm`'s
//! task 0): the scene with the command line's overrides, the node's options and limits, and
//! [`execute`]: the frames written as they come, the statistics, the charts and a summary.

use crate::cli::{BalancerKind, EffectsChoice, FrameArgs, flag_name};
use crate::progress::Progress;
use anyhow::Context;
use runtime::frames::{self, resume};
use runtime::node::{self, CompletedFrame, FrameSink, Job};
use runtime_core::stats::{Accepted, StatsFile};
use std::sync::Arc;
use std::time::Instant;
use tracer::{Scene, World};

/// Loads the scene, runs `drive` with a sink that writes frames, and writes the statistics,
/// the Gantt chart and a one-line summary.
pub fn execute(
    args: &FrameArgs,
    peers: usize,
    threads: usize,
    drive: impl FnOnce(Job, &mut Sink) -> anyhow::Result<node::LocalRun>,
) -> anyhow::Result<()> {
    let started = Instant::now();
    // A trace feeds the simulator every frame's costs in order; a resumed render has only some.
    anyhow::ensure!(
        !(args.resume && args.trace.is_some()),
        "--trace cannot be combined with --resume: a trace must hold every frame of the render"
    );
    let scene = load_scene(args)?;
    // Refused before anything is rendered, naming the flag: none may surface as a peer failure.
    let (width, height) = (scene.settings.width, scene.settings.height);
    let tiles = node::Options::default()
        .check_frame(width, height, args.tiles, node::limits::available_memory())
        .map_err(|e| match e.tiles() {
            Some(tiles) => anyhow::anyhow!("--tiles {tiles}: {e}"),
            None => anyhow::anyhow!("--width {width} --height {height}: {e}"),
        })?;
    let files = node::bundle::scene_files(&args.scene, &scene)?;
    let params = node::bundle::params(&scene, args.effects == EffectsChoice::All);
    let render_hash = node::bundle::render_hash(&files, &params);
    let settings = scene.settings.clone();
    let every = args.checkpoint_every;
    anyhow::ensure!(
        (0.0..1e9).contains(&every),
        "--checkpoint-every {every}: must be 0 (no checkpoints) or a number of seconds below 1e9"
    );
    check_out_folder("--out", &args.out)?;
    let (first, missing) = if args.resume {
        let removed = resume::remove_leftovers(&args.out)
            .with_context(|| format!("removing half-written files in {}", args.out.display()))?;
        if removed > 0 {
            tracing::info!("--resume: removed {removed} half-written files of a stopped render");
        }
        let (first, why) = resume::first_missing(&args.out, settings.frames, &render_hash);
        (first, Some(why))
    } else {
        (0, None)
    };
    let checkpoint = node::checkpoint::Checkpointing::for_render(
        &args.out,
        (every > 0.0).then(|| std::time::Duration::from_secs_f64(every)),
        &render_hash,
        first,
        args.resume,
    );
    let world = Arc::new(prepare_world(scene, args.effects));
    // Written only once every frame is done: a path that cannot take them is refused now, so
    // that it costs the user nothing but the message.
    for (flag, path) in [
        ("--stats", &args.stats),
        ("--gantt", &args.gantt),
        ("--trace", &args.trace),
    ] {
        if let Some(path) = path {
            check_writable(flag, path)?;
        }
    }
    // A regular grid is k x k tiles, so k cannot pass the image's shorter side: the default
    // count shrinks to fit a small image; a count given that cannot fit is refused by name.
    let tiles = match (args.balancer, args.tiles) {
        (BalancerKind::Regular, None) => tiles.min((width.min(height) as usize).pow(2)),
        _ => tiles,
    };
    let config =
        balancer::Config::with_tiles(args.balancer.into(), tiles, args.deal.into(), args.motion.0);
    let partitioner = balancer::Partitioner::new(settings.width, settings.height, &config)
        .map_err(|e| match args.tiles {
            Some(tiles) => anyhow::anyhow!("--tiles {tiles}: {e}"),
            None => e.into(),
        })?;
    let tiles = partitioner.tiles().len();
    let progress = Progress::new(settings.frames - first);
    progress.line(&format!(
        "{}: {}x{}, {} spp, {} frames, {} triangles, effects {}; {} peers, {} threads here, {:?} balancer with {} tiles, stealing {}",
        args.scene.display(),
        settings.width,
        settings.height,
        settings.samples_per_pixel,
        settings.frames,
        world.scene.triangles.len(),
        world.effects,
        peers,
        threads,
        args.balancer,
        tiles,
        if args.no_steal { "off" } else { "on" },
    ));
    if let Some(why) = &missing {
        progress.line(&resume::describe(first, settings.frames, why, &render_hash));
    }
    if let Some(kept) = checkpoint.as_ref().and_then(|c| c.resume.as_ref()) {
        progress.line(&format!(
            "--resume: frame {first} goes on from its checkpoint: {} results, {} of its {} tiles whole",
            kept.results.len(),
            kept.whole_tiles(),
            kept.tiles.len()
        ));
    }
    let ticks = progress.clone();
    let writer = frames::Writer::start(
        frames::Settings {
            out: args.out.clone(),
            exposure: args.exposure,
            tile_map: args.tile_map,
            render_hash: render_hash.clone(),
        },
        Box::new(move |frame, seconds| ticks.frame_done(frame, seconds)),
    )?;
    let mut sink = Sink {
        progress,
        stats: StatsFile {
            scene: args.scene.display().to_string(),
            width: settings.width,
            height: settings.height,
            samples_per_pixel: settings.samples_per_pixel,
            balancer: flag_name(&args.balancer),
            deal: flag_name(&args.deal),
            motion: args.motion.to_string(),
            effects: world.effects.to_string(),
            peers,
            render_hash,
            first_frame: first,
            frames: Vec::new(),
        },
        rays: 0,
        trace: match &args.trace {
            Some(_) => Some(sim::trace::Trace::new(
                settings.width,
                settings.height,
                tracer::BLOCK_SIZE,
                &args.scene.display().to_string(),
            )?),
            None => None,
        },
        accepted: Accepted::new(),
        files: writer,
    };
    let job = Job {
        world,
        files,
        params,
        frames: settings.frames,
        first,
        partitioner,
        checkpoint,
    };
    let render_started = Instant::now();
    let run = drive(job, &mut sink);
    // Every frame handed over is written before the render counts as done, or fails.
    let written = sink.files.finish();
    let run = run?;
    written?;
    let render_seconds = render_started.elapsed().as_secs_f64();
    sink.progress.finish();
    if first == settings.frames && missing.is_some() {
        // Nothing was rendered: the statistics and chart of the render that made the frames
        // are worth more than empty ones.
        println!(
            "all {} frames in {} were done already; stats.json and gantt.svg left as they were",
            settings.frames,
            args.out.display()
        );
        return Ok(());
    }
    let mut stats = sink.stats;
    stats.add_peer_accounts(&run.peers);
    if let (Some(path), Some(trace)) = (&args.trace, &sink.trace) {
        trace.write(path)?;
    }
    let stats_path = args
        .stats
        .clone()
        .unwrap_or_else(|| args.out.join("stats.json"));
    let json = serde_json::to_vec_pretty(&stats)?;
    std::fs::write(&stats_path, json)
        .map_err(|e| anyhow::anyhow!("{}: {e}", stats_path.display()))?;
    let gantt_path = args
        .gantt
        .clone()
        .unwrap_or_else(|| args.out.join("gantt.svg"));
    let charts = sim::plot::render_charts(&gantt_path, &stats, &run.timelines, &sink.accepted)?;
    println!(
        "rendered {} frames of {}x{} with {} peers in {:.2} s ({:.2} s in all): {:.2} Mrays/s; frames, stats.json and gantt.svg (per-frame charts in {}) in {}",
        settings.frames - first,
        settings.width,
        settings.height,
        stats.peers,
        render_seconds,
        started.elapsed().as_secs_f64(),
        sink.rays as f64 / render_seconds / 1e6,
        charts.display(),
        args.out.display(),
    );
    Ok(())
}

/// Makes the folder `path` (named by `flag`) where a command writes its results, and checks that
/// files can be made in it, before any work is done: a study or a render that ends by failing to
/// write would lose everything it computed.
pub(crate) fn check_out_folder(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    let shown = path.display();
    std::fs::create_dir_all(path).with_context(|| format!("{flag} {shown}: cannot create it"))?;
    let probe = path.join(".tessera-write-check");
    std::fs::write(&probe, b"")
        .with_context(|| format!("{flag} {shown}: cannot write files in it"))?;
    std::fs::remove_file(&probe)
        .with_context(|| format!("{flag} {shown}: cannot write files in it"))
}

/// Whether a file can be written at `path` (named by `flag`) once the render is over: not a
/// folder, in a folder that exists or can be made (as `--out` is), and open for writing. A file
/// made by the check is removed again.
fn check_writable(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    let shown = path.display();
    anyhow::ensure!(!path.is_dir(), "{flag} {shown}: is a folder; name a file");
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{flag} {shown}: cannot create its folder"))?;
    }
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .with_context(|| format!("{flag} {shown}: cannot be written"))?;
    if !existed {
        std::fs::remove_file(path).with_context(|| format!("{flag} {shown}: cannot be written"))?;
    }
    Ok(())
}

/// The node's options from the flags, with `threads` rendering threads per peer.
pub fn options(args: &FrameArgs, threads: usize) -> node::Options {
    let mut options = node::Options {
        threads,
        seed: args.image.seed.unwrap_or(0),
        ..node::Options::default()
    };
    options.core.steal = !args.no_steal;
    // In range: the flag's parser (`cli::peer_timeout`) refuses the rest.
    options.set_peer_timeout(std::time::Duration::from_secs_f64(args.peer_timeout));
    options
}

/// Every core this process may use.
pub fn available_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Rendering runs on rayon pools; tokio only moves bytes and timers, so two workers suffice.
pub fn tokio_runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?)
}

/// Writes each finished frame and keeps its statistics.
pub struct Sink {
    progress: Progress,
    stats: StatsFile,
    rays: u64,
    /// Every frame's block costs, when `--trace` asks for them.
    trace: Option<sim::trace::Trace>,
    /// The results the owner kept, telling the Gantt charts which renders were duplicates.
    accepted: Accepted,
    /// Writes the frames' files off the owner's loop.
    files: frames::Writer,
}

impl FrameSink for Sink {
    fn frame(&mut self, done: CompletedFrame) -> Result<(), String> {
        self.rays += done.rays;
        if let Some(trace) = &mut self.trace {
            trace
                .push(done.film.block_work.clone())
                .map_err(|e| e.to_string())?;
        }
        for t in &done.tiles {
            self.accepted.insert((done.frame, t.peer, t.rect));
        }
        self.stats.frames.push(done.stats());
        let costs = done.tiles.iter().map(|t| (t.rect, t.measured)).collect();
        self.files
            .send(frames::Frame {
                frame: done.frame,
                seconds: done.seconds,
                film: done.film,
                costs,
            })
            .map_err(|e| e.to_string())
    }
}

/// Loads the scene and applies the command line's overrides.
pub fn load_scene(args: &FrameArgs) -> anyhow::Result<Scene> {
    let mut scene = tracer::scene::load(&args.scene)?;
    let s = &mut scene.settings;
    s.frames = args.frames.unwrap_or(s.frames);
    args.image.apply(s)?;
    Ok(scene)
}

/// Builds the BVH and the lights, with the effect set the flags ask for.
pub fn prepare_world(scene: Scene, effects: EffectsChoice) -> World {
    World::prepare(scene, effects.forced())
}
