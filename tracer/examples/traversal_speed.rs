//! The 8-wide traversal against the binary one on a real scene: the same image (hashed, bit for
//! bit), and the CPU time per ray of each, the best of several interleaved rounds.
//!
//! `cargo run --release -p tracer --example traversal_speed -- SCENE.toml [SIZE] [SPP] [ROUNDS] [wide] [QUALITY]`
//!
//! With `wide`, only the 8-wide traversal runs: for comparing two builds of it, binary
//! against binary, where the binary traversal's rounds would only add time. `QUALITY`
//! (`fastest`, `fast`, `medium`, `slow`, `very-slow`) builds the tree at that quality instead of
//! the default, and the tree's build time (thread CPU) is printed.
//!
//! Why thread CPU time and the best round: on a machine shared with other work a wall clock
//! counts the other work too, and interference only ever adds time. The render runs as one tile
//! on a pool of one thread and is measured on that thread, so the thread's CPU time (Linux's
//! `/proc/thread-self/schedstat`) is the render's. Depth is Mitsuba's comparison setting, 7
//! bounces.

use tracer::geometry::{Accel, BuildQuality, Traversal};
use tracer::{FrameConfig, World, render_frame};

#[path = "support/thread_cpu.rs"]
mod thread_cpu;
use thread_cpu::thread_cpu_seconds;

#[path = "support/args.rs"]
mod args;

fn main() {
    let (mut scene, args) =
        args::scene_and_words("traversal_speed SCENE.toml [SIZE] [SPP] [ROUNDS] [wide]");
    let path = &args[1];
    let number = |i: usize, default: u32| args::number(&args, i, default);
    let (size, spp, rounds) = (number(2, 96), number(3, 8), number(4, 3));
    scene.settings.samples_per_pixel = spp;
    scene.settings.max_depth = Some(7);
    scene.settings.width = size;
    scene.settings.height = size;
    // A build quality among the trailing words (`fastest` ... `very-slow`), else the default.
    let quality = args[2..]
        .iter()
        .find_map(|a| {
            BuildQuality::ALL
                .into_iter()
                .find(|q| format!("{q:?}").eq_ignore_ascii_case(&a.replace('-', "")))
        })
        .unwrap_or_default();
    let effects = tracer::Effects::of(&scene);
    let start = thread_cpu_seconds();
    let accel = Accel::build(&scene.triangles, quality);
    let build = thread_cpu_seconds() - start;
    let mut world = World::new(scene, accel, effects);
    println!(
        "{path}: {size}x{size}, {spp} spp, {quality:?} tree built in {build:.2} CPU-s, {:?}",
        world.accel()
    );
    let wide_only = args[2..].iter().any(|a| a == "wide");
    let traversals: &[Traversal] = if wide_only {
        &[Traversal::Robust]
    } else {
        &[Traversal::RobustBinary, Traversal::Robust]
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool of one thread builds");
    let mut best = [f64::INFINITY; 2];
    let mut hashes = Vec::new();
    for _ in 0..rounds {
        for (i, &traversal) in traversals.iter().enumerate() {
            world.set_traversal(traversal);
            // One tile of the whole image on a pool of one thread, measured on that thread:
            // `install` from inside the pool runs the frame right there.
            let (film, seconds) = pool.install(|| {
                let start = thread_cpu_seconds();
                let film = render_frame(&world, 0, &pool, FrameConfig { tile: size });
                (film, thread_cpu_seconds() - start)
            });
            let s = film.stats;
            let rays = (s.rays + s.shadow_rays) as f64;
            best[i] = best[i].min(seconds * 1e9 / rays);
            // FNV-1a over every channel's bits.
            let hash = film
                .pixels
                .iter()
                .flatten()
                .fold(0xcbf2_9ce4_8422_2325u64, |h, c| {
                    (h ^ u64::from(c.to_bits())).wrapping_mul(0x0100_0000_01b3)
                });
            hashes.push(hash);
            println!(
                "  {traversal:?}: {seconds:.3} CPU-s, {:.0} ns per ray, {:.2} boxes and {:.2} triangles per ray, image {hash:016x}",
                seconds * 1e9 / rays,
                s.traversal.nodes as f64 / rays,
                s.traversal.triangles as f64 / rays,
            );
        }
    }
    if wide_only {
        println!("best: 8-wide {:.0} ns per ray", best[0]);
    } else {
        println!(
            "best: binary {:.0} ns per ray, 8-wide {:.0} ({:.2}x)",
            best[0],
            best[1],
            best[0] / best[1]
        );
    }
    if hashes.iter().any(|&h| h != hashes[0]) {
        eprintln!("the traversals rendered different images");
        std::process::exit(1);
    }
}
