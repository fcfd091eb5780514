//! What walking several rays through the tree at once buys, and what sorting them buys, on a
//! real scene: the CPU time per ray of the same rays traced one by one in path order, `K` at a
//! time in turn (`Accel::intersect_batch`), and one by one after sorting each bounce's rays by
//! direction and origin. Every way must find the same hits, bit for bit.
//!
//! `cargo run --release -p tracer --example ray_batches -- SCENE.toml [SIZE] [BOUNCES] [ROUNDS]`
//!
//! The rays are a path tracer's: a camera ray per pixel, then up to `BOUNCES` diffuse bounces
//! from each hit (cosine-distributed about the facing normal, from a fixed hash, so every run
//! traces the same rays). One thread, wall-clock time (the thread's CPU time, as the kernel
//! keeps it, moves in scheduler ticks, too coarse for a pass of tens of milliseconds), the best
//! of `ROUNDS` interleaved rounds: run it on a quiet machine.

use glam::Vec3;
use std::path::Path;
use tracer::geometry::{Accel, Hit, Ray, TraversalStats};

/// A uniform number in [0, 1) from a counter (SplitMix64).
fn hash01(mut x: u64) -> f32 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^= x >> 31;
    (x >> 40) as f32 / (1u64 << 24) as f32
}

/// A cosine-distributed direction about the unit `n`.
fn cosine_about(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let (t, b) = n.any_orthonormal_pair();
    let r = u1.sqrt();
    let phi = std::f32::consts::TAU * u2;
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}

/// 30 bits of interleaved coordinates, each quantised to 10 bits in `[lo, hi]`.
fn morton(p: Vec3, lo: Vec3, hi: Vec3) -> u32 {
    let q = ((p - lo) / (hi - lo).max(Vec3::splat(1e-30)) * 1023.0)
        .clamp(Vec3::ZERO, Vec3::splat(1023.0));
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    spread(q.x as u32) | (spread(q.y as u32) << 1) | (spread(q.z as u32) << 2)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: ray_batches SCENE.toml [SIZE] [BOUNCES] [ROUNDS]");
        std::process::exit(2);
    };
    let number = |i: usize, default: u32| {
        args.get(i)
            .map_or(default, |s| s.parse().expect("a number"))
    };
    let (size, bounces, rounds) = (number(2, 128), number(3, 3), number(4, 3));
    let scene = tracer::scene::load(Path::new(path)).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
    let accel = Accel::build(&scene.triangles, Default::default());
    let camera = scene.camera.at(0).rays(size, size);
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for t in &scene.triangles {
        for p in t.p {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }

    // levels[d][pixel]: the ray of bounce d from that pixel, if its path got that far.
    let pixels = (size * size) as usize;
    let mut levels: Vec<Vec<Option<Ray>>> = vec![vec![None; pixels]; bounces as usize + 1];
    let mut stats = TraversalStats::default();
    for pixel in 0..pixels {
        let (x, y) = ((pixel as u32 % size) as f32, (pixel as u32 / size) as f32);
        let key = pixel as u64 * 64;
        let mut ray = camera.ray(x + hash01(key), y + hash01(key + 1));
        for depth in 0..=bounces as usize {
            levels[depth][pixel] = Some(ray);
            let Some(hit) = accel.intersect(&ray, &mut stats) else {
                break;
            };
            let mut n = accel.unit_normal(hit.triangle);
            if n.dot(ray.dir) > 0.0 {
                n = -n;
            }
            let p = ray.origin + ray.dir * hit.t;
            let scale = p.abs().max_element().max(1.0);
            let k = key + 2 + 2 * depth as u64;
            ray = Ray {
                origin: p + n * (1e-4 * scale),
                dir: cosine_about(n, hash01(k), hash01(k + 1)),
                t_max: f32::INFINITY,
            };
        }
    }
    // Path order (each pixel's rays, one after another) and bounce order (each bounce's rays,
    // pixel after pixel), the same rays; and bounce order with each bounce's rays sorted.
    let path_order: Vec<Ray> = (0..pixels)
        .flat_map(|p| levels.iter().filter_map(move |l| l[p]))
        .collect();
    let bounce_order: Vec<Ray> = levels
        .iter()
        .flat_map(|l| l.iter().flatten().copied())
        .collect();
    let sorted: Vec<Ray> = levels
        .iter()
        .flat_map(|l| {
            let mut l: Vec<Ray> = l.iter().flatten().copied().collect();
            l.sort_by_key(|r| {
                let octant = u32::from(r.dir.x < 0.0)
                    | u32::from(r.dir.y < 0.0) << 1
                    | u32::from(r.dir.z < 0.0) << 2;
                (octant, morton(r.origin, lo, hi))
            });
            l
        })
        .collect();
    println!(
        "{path}: {size}x{size}, {} rays ({} camera), {:?}",
        path_order.len(),
        levels[0].iter().flatten().count(),
        accel
    );

    let key = |r: &Ray| {
        (
            r.origin.to_array().map(f32::to_bits),
            r.dir.to_array().map(f32::to_bits),
        )
    };
    let reference: std::collections::HashMap<_, Option<Hit>> = path_order
        .iter()
        .map(|r| (key(r), accel.intersect(r, &mut TraversalStats::default())))
        .collect();
    let ways: [(&str, &[Ray], usize); 6] = [
        ("one by one, path order", &path_order, 1),
        ("one by one, bounce order", &bounce_order, 1),
        ("4 in turn, bounce order", &bounce_order, 4),
        ("8 in turn, bounce order", &bounce_order, 8),
        ("16 in turn, bounce order", &bounce_order, 16),
        ("one by one, sorted", &sorted, 1),
    ];
    let mut best = [f64::INFINITY; 6];
    let mut hits = vec![None; path_order.len()];
    for _ in 0..rounds {
        for (i, &(_, rays, k)) in ways.iter().enumerate() {
            let mut stats = TraversalStats::default();
            let start = std::time::Instant::now();
            match k {
                1 => {
                    for (r, h) in rays.iter().zip(hits.iter_mut()) {
                        *h = accel.intersect(r, &mut stats);
                    }
                }
                4 => accel.intersect_batch::<4>(rays, &mut hits, &mut stats),
                8 => accel.intersect_batch::<8>(rays, &mut hits, &mut stats),
                _ => accel.intersect_batch::<16>(rays, &mut hits, &mut stats),
            }
            let seconds = start.elapsed().as_secs_f64();
            best[i] = best[i].min(seconds * 1e9 / rays.len() as f64);
            for (r, h) in rays.iter().zip(&hits) {
                assert_eq!(reference[&key(r)], *h, "{}: a different hit", ways[i].0);
            }
        }
    }
    for (i, (name, _, _)) in ways.iter().enumerate() {
        println!(
            "  {name:28} {:6.0} ns per ray ({:.2}x path order)",
            best[i],
            best[0] / best[i]
        );
    }
}
