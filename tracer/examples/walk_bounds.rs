//! What bounds a ray's walk through the tree: the same random rays traced four ways, so that
//! only one thing differs between two of them (docs/bench.md, issue 12, twenty-third round).
//!
//! `cargo run --release -p tracer --example walk_bounds -- SCENE.toml [RAYS] [ROUNDS]`
//!
//! - **independent** against **chained**: each ray traced as given, then each ray's origin made
//!   to depend on the previous ray's hit distance (times a zero the compiler cannot see, so the
//!   rays are the same). Equal times mean a walk does not overlap the one before it anyway.
//! - **repeated** against **shuffled**: each of an eighth of the rays eight times in a row
//!   (after the first, every branch of the walk is predicted and its memory is in cache), and
//!   that same multiset shuffled. The difference is what mispredicted branches (and, on large
//!   scenes, cache misses) cost.
//!
//! Rays start at random points inside the middle 80 % of the scene's box, in uniformly random
//! directions: closest-hit rays to infinity, shadow rays to a third of the box's diagonal.
//! Times are nanoseconds per ray on the wall clock, the best of the rounds (interference only
//! ever adds time); every set is traced on this one thread.

use glam::Vec3;
use std::hint::black_box;
use std::time::Instant;
use tracer::geometry::{Accel, BuildQuality, Ray, TraversalStats};

#[path = "support/args.rs"]
mod args;

fn main() {
    let (scene, words) = args::scene_and_words("walk_bounds SCENE.toml [RAYS] [ROUNDS]");
    let path = &words[1];
    let (count, rounds) = (
        args::number(&words, 2, 1usize << 20),
        args::number(&words, 3, 8),
    );
    let accel = Accel::build(&scene.triangles, BuildQuality::default());
    let (lo, hi) = scene
        .triangles
        .iter()
        .flat_map(|t| t.p)
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        });
    let rays = random_rays(count, lo, hi);
    // The same rays as shadow rays, ending a third of the box's diagonal away.
    let length = (hi - lo).length() / 3.0;
    let with_end = |rays: &[Ray]| -> Vec<Ray> {
        rays.iter()
            .map(|&ray| Ray {
                t_max: length,
                ..ray
            })
            .collect()
    };
    let repeated: Vec<Ray> = rays[..count / 8]
        .iter()
        .flat_map(|&ray| std::iter::repeat_n(ray, 8))
        .collect();
    let mut shuffled = repeated.clone();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    for i in (1..shuffled.len()).rev() {
        shuffled.swap(i, (xorshift(&mut state) % (i as u64 + 1)) as usize);
    }
    let (shadows, repeated_shadows, shuffled_shadows) =
        (with_end(&rays), with_end(&repeated), with_end(&shuffled));
    println!("{path}: {count} rays, best of {rounds} rounds, ns per ray");
    let mut best = [f64::INFINITY; 8];
    for _ in 0..rounds {
        let times = [
            closest::<false>(&accel, &rays),
            shadow::<false>(&accel, &shadows),
            closest::<true>(&accel, &rays),
            shadow::<true>(&accel, &shadows),
            closest::<false>(&accel, &repeated),
            shadow::<false>(&accel, &repeated_shadows),
            closest::<false>(&accel, &shuffled),
            shadow::<false>(&accel, &shuffled_shadows),
        ];
        for (b, t) in best.iter_mut().zip(times) {
            *b = b.min(t);
        }
    }
    for (name, pair) in ["independent", "chained", "repeated", "shuffled"]
        .iter()
        .zip(best.chunks(2))
    {
        println!(
            "  {name:<12} closest {:6.1}   shadow {:6.1}",
            pair[0], pair[1]
        );
    }
}

/// Nanoseconds per closest-hit query over `rays`; `CHAINED` makes each origin depend on the
/// previous hit. Unchained, each ray is passed where it lies: a copy built on the stack is read
/// back by the walk at other widths than it was written, a stall of its own.
fn closest<const CHAINED: bool>(accel: &Accel, rays: &[Ray]) -> f64 {
    let zero = black_box(0.0f32);
    let mut stats = TraversalStats::default();
    let (start, mut previous, mut sum) = (Instant::now(), 0.0f32, 0.0f32);
    for ray in rays {
        let hit = if CHAINED {
            let origin = ray.origin + Vec3::splat(previous * zero);
            accel.intersect(&Ray { origin, ..*ray }, &mut stats)
        } else {
            accel.intersect(ray, &mut stats)
        };
        previous = hit.map_or(0.0, |h| h.t);
        sum += previous;
    }
    black_box(sum);
    start.elapsed().as_secs_f64() * 1e9 / rays.len() as f64
}

/// Nanoseconds per shadow query over `rays` (which end where shadow rays do); `CHAINED` as for
/// [`closest`].
fn shadow<const CHAINED: bool>(accel: &Accel, rays: &[Ray]) -> f64 {
    let zero = black_box(0.0f32);
    let mut stats = TraversalStats::default();
    let (start, mut previous, mut blocked) = (Instant::now(), 0u32, 0u32);
    for ray in rays {
        let hit = if CHAINED {
            let origin = ray.origin + Vec3::splat(previous as f32 * zero);
            accel.occluded(&Ray { origin, ..*ray }, &mut stats)
        } else {
            accel.occluded(ray, &mut stats)
        };
        previous = u32::from(hit);
        blocked += previous;
    }
    black_box(blocked);
    start.elapsed().as_secs_f64() * 1e9 / rays.len() as f64
}

/// `count` rays from points inside the middle 80 % of the box `lo`..`hi`, in uniformly random
/// unit directions, to infinity.
fn random_rays(count: usize, lo: Vec3, hi: Vec3) -> Vec<Ray> {
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut unit = move || (xorshift(&mut state) >> 40) as f32 / (1u64 << 24) as f32;
    (0..count)
        .map(|_| {
            let inside = Vec3::new(unit(), unit(), unit()) * 0.8 + Vec3::splat(0.1);
            let z = 1.0 - 2.0 * unit();
            let angle = std::f32::consts::TAU * unit();
            let across = (1.0 - z * z).max(0.0).sqrt();
            Ray {
                origin: lo + (hi - lo) * inside,
                dir: Vec3::new(across * angle.cos(), across * angle.sin(), z),
                t_max: f32::INFINITY,
            }
        })
        .collect()
}

/// One xorshift64 step: the example's own stream, the same in every run.
fn xorshift(state: &mut u64) -> u64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    *state
}
