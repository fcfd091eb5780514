//! Our traversal on rays written by another renderer: the per-ray cost of the tree and its walk
//! alone, without shading, on exactly the rays Mitsuba 3 (Embree) traced, and whether both found
//! the same hits. `scripts/traversal_compare.py` writes the ray files and runs this.
//!
//! `cargo run --release -p tracer --example trace_rays -- SCENE.toml ROUNDS [QUALITY] FILE.rays closest|any|packets ...`
//!
//! `packets` is `closest` with the file's rays taken [`PACKET`] at a time through
//! `Accel::intersect_packet`, the walk the renderer gives a pixel's camera rays (which the file
//! holds a pixel's in a row): the same answers, for comparison with the other renderer's
//! coherent rays.
//!
//! `QUALITY` (`fastest` ... `very-slow`) builds the tree at that quality instead of the default.
//!
//! A ray file is little-endian: a `u64` count, then per ray eight `f32`s, origin, direction,
//! `t_max` and the other renderer's answer: the hit distance (infinite for a miss) for `closest`,
//! 1 or 0 for `any`. For each file this prints one JSON line: the best of `ROUNDS` thread-CPU
//! times (one thread, as `traversal_speed` measures), rays per CPU-second, boxes and triangles
//! tested per ray, and how many answers differ from the file's. A distance agrees within a
//! relative 1e-4: the two renderers offset ray origins the same way (the file's origins are used
//! as they are) but test triangles by different exact methods, so grazing hits on shared edges
//! may differ, which the count shows rather than hides.

use std::path::Path;
use tracer::geometry::{Accel, BuildQuality, PACKET, Ray, TraversalStats};

#[path = "support/thread_cpu.rs"]
mod thread_cpu;
use thread_cpu::thread_cpu_seconds;

/// The rays of one file and the other renderer's answer for each.
fn read_rays(path: &str) -> (Vec<Ray>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
    let count = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes")) as usize;
    if bytes.len() != 8 + count * 32 {
        eprintln!(
            "{path}: {} bytes, not a count and {count} rays",
            bytes.len()
        );
        std::process::exit(1);
    }
    let floats: Vec<f32> = bytes[8..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    floats
        .chunks_exact(8)
        .map(|r| {
            let ray = Ray {
                origin: glam::Vec3::new(r[0], r[1], r[2]),
                dir: glam::Vec3::new(r[3], r[4], r[5]),
                t_max: r[6],
            };
            (ray, r[7])
        })
        .unzip()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // A build quality as the third word (`fastest` ... `very-slow`), else the default.
    let quality = args.get(3).and_then(|a| {
        BuildQuality::ALL
            .into_iter()
            .find(|q| format!("{q:?}").eq_ignore_ascii_case(&a.replace('-', "")))
    });
    let files = if quality.is_some() { 4 } else { 3 };
    if args.len() < files + 2 || !(args.len() - files).is_multiple_of(2) {
        eprintln!(
            "usage: trace_rays SCENE.toml ROUNDS [QUALITY] FILE.rays closest|any|packets [FILE.rays closest|any|packets ...]"
        );
        std::process::exit(2);
    }
    let scene = tracer::scene::load(Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{}: {e}", args[1]);
        std::process::exit(1);
    });
    let rounds: u32 = args[2].parse().expect("ROUNDS is a number");
    let start = thread_cpu_seconds();
    let accel = Accel::build(&scene.triangles, quality.unwrap_or_default());
    let build = thread_cpu_seconds() - start;
    println!(
        "{{\"build_cpu_seconds\": {build:.3}, \"quality\": \"{:?}\", \"simd\": \"{:?}\"}}",
        quality.unwrap_or_default(),
        accel.box_simd()
    );
    for pair in args[files..].chunks_exact(2) {
        let (path, query) = (&pair[0], pair[1].as_str());
        let (any, packets) = match query {
            "closest" => (false, false),
            "any" => (true, false),
            "packets" => (false, true),
            other => {
                eprintln!("{other}: the query is closest, any or packets");
                std::process::exit(2);
            }
        };
        let (rays, theirs) = read_rays(path);
        let mut best = f64::INFINITY;
        let mut answers = Vec::with_capacity(rays.len());
        let mut stats = TraversalStats::default();
        for _ in 0..rounds {
            answers.clear();
            stats = TraversalStats::default();
            let start = thread_cpu_seconds();
            if any {
                answers.extend(
                    rays.iter()
                        .map(|ray| f32::from(u8::from(accel.occluded(ray, &mut stats)))),
                );
            } else if packets {
                let mut hits = [None; PACKET];
                for packet in rays.chunks(PACKET) {
                    let found = &mut hits[..packet.len()];
                    accel.intersect_packet(packet, found, &mut stats);
                    answers.extend(found.iter().map(|h| h.map_or(f32::INFINITY, |h| h.t)));
                }
            } else {
                answers.extend(rays.iter().map(|ray| {
                    accel
                        .intersect(ray, &mut stats)
                        .map_or(f32::INFINITY, |h| h.t)
                }));
            }
            best = best.min(thread_cpu_seconds() - start);
        }
        let differ = answers
            .iter()
            .zip(&theirs)
            .filter(|&(&ours, &theirs)| {
                if ours.is_infinite() || theirs.is_infinite() || any {
                    ours != theirs
                } else {
                    (ours - theirs).abs() > 1e-4 * ours.abs().max(1.0)
                }
            })
            .count();
        let n = rays.len() as f64;
        // A set traced faster than the clock ticks has no rate: `null`, where a division by
        // zero would print `inf`, which is not JSON.
        let rate = if best > 0.0 {
            format!("{:.3}", n / best / 1e6)
        } else {
            "null".to_owned()
        };
        println!(
            "{{\"file\": \"{path}\", \"query\": \"{query}\", \"rays\": {}, \"cpu_seconds\": {best:.4}, \
             \"mrays_per_cpu_second\": {rate}, \"boxes_per_ray\": {:.2}, \"triangles_per_ray\": {:.2}, \
             \"differ\": {differ}}}",
            rays.len(),
            stats.nodes as f64 / n,
            stats.triangles as f64 / n,
        );
    }
}
