//! Records a cost trace of a scene straight through the tracer library, and measures the work
//! rate of this machine's rendering threads (the simulator's `--rate`).
//!
//! `tessera render SCENE --trace FILE` records traces of real renders; this helper needs no
//! peers, no network and no output images, which makes it the quick way to a trace and the
//! way to calibrate: every tile is timed alone, so the rate is counted work per second of one
//! busy thread while all of them render.
//!
//! ```text
//! cargo run -p sim --example record_trace -- SCENE OUT.jsonl [FRAMES]
//! ```

use std::time::Instant;

use sim::TraceWriter;
use std::sync::atomic::{AtomicU64, Ordering};
use tracer::{BLOCK_SIZE, FrameConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(scene_path), Some(out)) = (args.get(1), args.get(2)) else {
        return Err("usage: record_trace SCENE OUT.jsonl [FRAMES]".into());
    };
    let scene = tracer::scene::load(std::path::Path::new(scene_path))?;
    let settings = scene.settings.clone();
    let frames = match args.get(3) {
        Some(frames) => frames.parse()?,
        None => settings.frames,
    };
    let world = tracer::World::prepare(scene, None);
    let (w, h) = (settings.width, settings.height);
    let mut writer = TraceWriter::create(std::path::Path::new(out), w, h, BLOCK_SIZE, scene_path)?;
    // Tiles of 32x32 pixels (the default), block-aligned, so that every block's cost comes from
    // one tile; every tile is timed alone, and the busy time summed in nanoseconds.
    let pool = rayon::ThreadPoolBuilder::new().build()?;
    let busy_nanos = AtomicU64::new(0);
    let mut work = 0u64;
    let started = Instant::now();
    for frame in 0..frames {
        let film = tracer::render_frame_by(&world, &pool, FrameConfig::default(), |rect| {
            let start = Instant::now();
            let output = tracer::render_tile(&world, frame, rect);
            let nanos = u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX);
            busy_nanos.fetch_add(nanos, Ordering::Relaxed);
            output
        });
        work += film.stats.work();
        writer.push(&film.block_work)?;
        eprintln!(
            "frame {frame}: {} units of work",
            film.block_work.iter().sum::<u64>()
        );
    }
    let busy = busy_nanos.into_inner() as f64 / 1e9;
    println!(
        "{frames} frames of {w}x{h} in {:.1} s on {} threads: {work} units of work in {busy:.2} thread-seconds, {:.4e} units per thread-second",
        started.elapsed().as_secs_f64(),
        pool.current_num_threads(),
        work as f64 / busy
    );
    Ok(())
}
