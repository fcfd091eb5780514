//! `tessera render`: load a scene, then for each frame cut it into tiles with the chosen balancer,
//! render the tiles on a rayon pool, assemble and write the frame, and feed the measured costs back
//! to the balancer for the next frame.

use crate::cli::{BalancerKind, EffectsChoice, RenderArgs};
use crate::report::{self, FrameStats, Progress, StatsFile, TileStats};
use anyhow::Context;
use rayon::prelude::*;
use std::time::Instant;
use tracer::geometry::{Accel, BuildQuality};
use tracer::{Effects, Film, Scene, World};

pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let scene = load_scene(args)?;
    let settings = scene.settings.clone();
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let world = prepare_world(scene, args.effects);
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;

    let mut partitioner = partitioner(args.balancer, args.tiles, settings.width, settings.height)?;
    let progress = Progress::new(settings.frames, partitioner.tiles().len() as u64);
    progress.line(&format!(
        "{}: {}x{}, {} spp, {} frames, {} triangles, effects {}, {} threads, {:?} balancer with {} tiles",
        args.scene.display(),
        settings.width,
        settings.height,
        settings.samples_per_pixel,
        settings.frames,
        world.scene.triangles.len(),
        world.effects,
        threads,
        args.balancer,
        partitioner.tiles().len(),
    ));
    let mut stats = StatsFile {
        scene: args.scene.display().to_string(),
        width: settings.width,
        height: settings.height,
        samples_per_pixel: settings.samples_per_pixel,
        balancer: format!("{:?}", args.balancer).to_lowercase(),
        effects: world.effects.to_string(),
        peers: 1,
        frames: Vec::new(),
    };
    let mut total_rays = 0u64;
    let render_started = Instant::now();
    for frame in 0..settings.frames {
        progress.frame_started(frame, settings.frames);
        let tiles = partitioner.tiles();
        let frame_started = Instant::now();
        let rendered: Vec<_> = pool.install(|| {
            tiles
                .par_iter()
                .map(|tile| {
                    let begun = Instant::now();
                    let output = tracer::render_tile(&world, frame, to_tracer(tile.rect));
                    progress.tile_done();
                    (output, begun.elapsed())
                })
                .collect()
        });
        let seconds = frame_started.elapsed().as_secs_f64();
        let mut film = Film::new(settings.width, settings.height);
        let mut frame_stats = FrameStats { frame, seconds, ..FrameStats::default() };
        for (tile, (output, took)) in tiles.iter().zip(&rendered) {
            film.insert(output.rect, &output.pixels, &output.cost);
            film.stats.add(&output.stats);
            frame_stats.tiles.push(TileStats {
                rect: [tile.rect.x, tile.rect.y, tile.rect.w, tile.rect.h],
                predicted: tile.predicted,
                measured: output.cost.work,
                seconds: took.as_secs_f64(),
                peer: 0,
            });
        }
        frame_stats.rays = film.stats.rays + film.stats.shadow_rays;
        frame_stats.work = film.stats.work();
        frame_stats.summarise_leaves();
        total_rays += frame_stats.rays;
        write_frame(args, frame, &film, &frame_stats)?;
        partitioner
            .observe(&cost_map(&film))
            .context("the balancer rejected the frame's cost map")?;
        if film.stats.invalid_samples > 0 {
            tracing::warn!("frame {frame}: {} non-finite samples were dropped", film.stats.invalid_samples);
        }
        stats.frames.push(frame_stats);
    }
    progress.finish();
    let render_seconds = render_started.elapsed().as_secs_f64();
    if let Some(path) = &args.stats {
        report::write_stats(path, &stats)?;
    }
    println!(
        "rendered {} frames of {}x{} in {:.2} s ({:.2} s total): {:.2} Mrays/s, output in {}",
        settings.frames,
        settings.width,
        settings.height,
        render_seconds,
        started.elapsed().as_secs_f64(),
        total_rays as f64 / render_seconds / 1e6,
        args.out.display(),
    );
    Ok(())
}

/// Loads the scene and applies the command line's overrides.
pub fn load_scene(args: &RenderArgs) -> anyhow::Result<Scene> {
    let mut scene = tracer::scene::load(&args.scene)?;
    let s = &mut scene.settings;
    s.frames = args.frames.unwrap_or(s.frames);
    s.samples_per_pixel = args.spp.unwrap_or(s.samples_per_pixel);
    s.width = args.width.unwrap_or(s.width);
    s.height = args.height.unwrap_or(s.height);
    s.seed = args.seed.unwrap_or(s.seed);
    anyhow::ensure!(s.width > 0 && s.height > 0, "the image must be at least 1x1 pixels");
    anyhow::ensure!(s.samples_per_pixel > 0, "samples per pixel must be at least 1");
    Ok(scene)
}

/// Builds the BVH and the lights.
pub fn prepare_world(scene: Scene, effects: EffectsChoice) -> World {
    let effects = match effects {
        EffectsChoice::Auto => Effects::of(&scene),
        EffectsChoice::All => Effects::ALL,
    };
    let built = Instant::now();
    let accel = Accel::build(&scene.triangles, BuildQuality::default());
    tracing::debug!("BVH over {} triangles built in {:.3} s", scene.triangles.len(), built.elapsed().as_secs_f64());
    World::new(scene, accel, effects)
}

fn write_frame(args: &RenderArgs, frame: u32, film: &Film, stats: &FrameStats) -> anyhow::Result<()> {
    let name = |ext: &str| args.out.join(format!("frame-{frame:04}.{ext}"));
    tracer::output::write_exr(&name("exr"), film.width, film.height, &film.pixels)?;
    tracer::output::write_png(&name("png"), film.width, film.height, &film.pixels, args.exposure)?;
    if args.tile_map {
        let preview = tracer::output::tone_map(&film.pixels, args.exposure);
        let path = args.out.join(format!("tiles-{frame:04}.png"));
        report::write_tile_map(&path, film.width, film.height, &preview, &stats.tiles)?;
    }
    Ok(())
}

/// The balancer the flags ask for. `--tiles M` is the PBT's leaf count, or for the regular grid
/// the nearest k x k grid (k = round(sqrt(M))), so equal flags mean comparable tile counts.
pub fn partitioner(kind: BalancerKind, tiles: usize, width: u32, height: u32) -> anyhow::Result<balancer::Partitioner> {
    let side = ((tiles as f64).sqrt().round() as u32).max(1);
    let config = balancer::Config {
        kind: match kind {
            BalancerKind::Pbt => balancer::Kind::Pbt,
            BalancerKind::Regular => balancer::Kind::Regular,
        },
        leaves: tiles,
        grid: balancer::Grid::Count { columns: side, rows: side },
        ..balancer::Config::default()
    };
    Ok(balancer::Partitioner::new(width, height, &config)?)
}

/// The frame's per-block counted work as the balancer's cost map.
fn cost_map(film: &Film) -> balancer::CostMap {
    balancer::CostMap::from_counts(film.width, film.height, tracer::BLOCK_SIZE, &film.block_work)
        .expect("the film's block grid matches its size and counted work is never negative")
}

fn to_tracer(r: balancer::Rect) -> tracer::Rect {
    tracer::Rect { x: r.x, y: r.y, w: r.w, h: r.h }
}

