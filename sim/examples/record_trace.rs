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

use rayon::prelude::*;
use sim::TraceWriter;
use tracer::{BLOCK_SIZE, Film, Rect};

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
    // Tiles of 32x32 pixels, block-aligned, so that every block's cost comes from one tile.
    let side = 4 * BLOCK_SIZE;
    let rects: Vec<Rect> = (0..h.div_ceil(side))
        .flat_map(|row| {
            (0..w.div_ceil(side)).map(move |column| {
                let (x, y) = (column * side, row * side);
                Rect {
                    x,
                    y,
                    w: side.min(w - x),
                    h: side.min(h - y),
                }
            })
        })
        .collect();
    let (mut work, mut busy) = (0u64, 0.0f64);
    let started = Instant::now();
    for frame in 0..frames {
        let outputs: Vec<_> = rects
            .par_iter()
            .map(|&rect| {
                let start = Instant::now();
                let output = tracer::render_tile(&world, frame, rect);
                (output, start.elapsed().as_secs_f64())
            })
            .collect();
        let mut film = Film::new(w, h);
        for (output, seconds) in &outputs {
            film.insert(output.rect, &output.pixels, &output.cost);
            work += output.cost.work;
            busy += seconds;
        }
        writer.push(&film.block_work)?;
        eprintln!(
            "frame {frame}: {} units of work",
            film.block_work.iter().sum::<u64>()
        );
    }
    println!(
        "{frames} frames of {w}x{h} in {:.1} s on {} threads: {work} units of work in {busy:.2} thread-seconds, {:.4e} units per thread-second",
        started.elapsed().as_secs_f64(),
        rayon::current_num_threads(),
        work as f64 / busy
    );
    Ok(())
}
