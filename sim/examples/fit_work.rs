//! How well counted work predicts time: renders frames of scenes in 16x16 tiles on one thread
//! (at most 256x256 pixels and 8 samples per pixel, to keep it quick), times each tile, and fits
//! time = a·nodes + b·triangles + c·(shaded rays + shadow rays) + d·escaped rays by
//! non-negative least squares. (Shaded and shadow rays are one term: nearly every shaded hit
//! casts one shadow ray, and fitted apart their weights swing from scene set to scene set.)
//! Prints the fit, and for the tracer's counted work, the fit, and the formula used before
//! (16 per ray), how far each tile's predicted time is from its measured time, per scene. The
//! tracer's weights (`PathStats::work`) were chosen from this output. A measurement, not a test.
//!
//! ```text
//! cargo run --release -p sim --example fit_work -- SCENE [SCENE...]
//! ```

use std::time::Instant;

use tracer::Rect;

/// One timed tile: its counters and the seconds it took.
struct Sample {
    scene: usize,
    features: [f64; 4],
    work: f64,
    seconds: f64,
}

const NAMES: [&str; 4] = ["nodes", "triangles", "hits + shadow rays", "escapes"];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scenes: Vec<String> = std::env::args().skip(1).collect();
    if scenes.is_empty() {
        return Err("usage: fit_work SCENE [SCENE...]".into());
    }
    let mut samples = Vec::new();
    for (index, path) in scenes.iter().enumerate() {
        let mut scene = tracer::scene::load(std::path::Path::new(path))?;
        let scale = (256.0 / f64::from(scene.settings.width.max(scene.settings.height))).min(1.0);
        scene.settings.width = (f64::from(scene.settings.width) * scale).round() as u32;
        scene.settings.height = (f64::from(scene.settings.height) * scale).round() as u32;
        scene.settings.samples_per_pixel = scene.settings.samples_per_pixel.min(8);
        let settings = scene.settings.clone();
        let world = tracer::World::prepare(scene, None);
        let frames = [0, settings.frames / 2];
        let before = samples.len();
        for frame in frames {
            for y in (0..settings.height).step_by(16) {
                for x in (0..settings.width).step_by(16) {
                    let rect = Rect {
                        x,
                        y,
                        w: 16.min(settings.width - x),
                        h: 16.min(settings.height - y),
                    };
                    let started = Instant::now();
                    let out = tracer::render_tile(&world, frame, rect);
                    let seconds = started.elapsed().as_secs_f64();
                    let s = out.stats;
                    samples.push(Sample {
                        scene: index,
                        features: [
                            s.traversal.nodes as f64,
                            s.traversal.triangles as f64,
                            (s.hits + s.shadow_rays) as f64,
                            (s.rays - s.hits) as f64,
                        ],
                        work: out.cost.work as f64,
                        seconds,
                    });
                }
            }
        }
        println!("{path}: {} tiles", samples.len() - before);
    }
    let fit = least_squares(&samples);
    let per_node = fit[0];
    println!("\nfitted seconds per unit (and relative to a node):");
    for (name, c) in NAMES.iter().zip(fit) {
        println!("  {name:>12}: {c:.3e} s ({:.2} nodes)", c / per_node);
    }
    // Within a scene only relative costs matter (the balancer compares tiles of one frame), so
    // each formula is scaled to each scene's total time before its errors are taken.
    let fitted = |s: &Sample| -> f64 { s.features.iter().zip(fit).map(|(f, c)| f * c).sum() };
    let counted = |s: &Sample| s.work;
    // The formula the tracer used before these weights: 16 for every ray, shaded or not.
    let before =
        |s: &Sample| s.features[0] + s.features[1] + 16.0 * (s.features[2] + s.features[3]);
    println!("\nrelative error of each tile's predicted time, each formula scaled per scene:");
    println!(
        "  {:<48} {:>24} {:>24} {:>24}",
        "scene", "counted work", "fitted", "before: 16 per ray"
    );
    for (index, path) in scenes.iter().enumerate() {
        let tiles: Vec<&Sample> = samples.iter().filter(|s| s.scene == index).collect();
        println!(
            "  {path:<48} {:>24} {:>24} {:>24}",
            errors(&tiles, &counted),
            errors(&tiles, &fitted),
            errors(&tiles, &before)
        );
    }
    Ok(())
}

/// The 5th, 50th and 95th percentiles of (predicted - measured) / measured over `tiles`, with
/// `predict` scaled so that the tiles' predicted and measured times add up alike.
fn errors(tiles: &[&Sample], predict: &dyn Fn(&Sample) -> f64) -> String {
    let scale = tiles.iter().map(|s| s.seconds).sum::<f64>()
        / tiles.iter().map(|s| predict(s)).sum::<f64>();
    let mut relative: Vec<f64> = tiles
        .iter()
        .map(|s| (predict(s) * scale - s.seconds) / s.seconds)
        .collect();
    relative.sort_by(f64::total_cmp);
    let q = |p: f64| relative[((relative.len() - 1) as f64 * p) as usize];
    format!("{:+.2} / {:+.2} / {:+.2}", q(0.05), q(0.5), q(0.95))
}

/// Non-negative least squares, each tile weighted by 1 / its time squared so that cheap and
/// expensive tiles count alike in relative terms: projected coordinate descent on the normal
/// equations, after scaling every feature to a unit diagonal (costs of a few nanoseconds
/// against counts of millions would otherwise stall it).
fn least_squares(samples: &[Sample]) -> [f64; 4] {
    const N: usize = 4;
    let mut q = [[0.0f64; N]; N];
    let mut p = [0.0f64; N];
    for s in samples {
        let w = 1.0 / (s.seconds * s.seconds);
        for (i, fi) in s.features.iter().enumerate() {
            p[i] += w * fi * s.seconds;
            for (j, fj) in s.features.iter().enumerate() {
                q[i][j] += w * fi * fj;
            }
        }
    }
    let scale: Vec<f64> = (0..N)
        .map(|i| q[i][i].sqrt().max(f64::MIN_POSITIVE))
        .collect();
    let mut c = [0.0f64; N];
    for _ in 0..100_000 {
        for i in 0..N {
            let qii = q[i][i] / (scale[i] * scale[i]);
            if qii <= 0.0 {
                continue;
            }
            let gradient: f64 = (0..N)
                .map(|j| q[i][j] / (scale[i] * scale[j]) * c[j])
                .sum::<f64>()
                - p[i] / scale[i];
            c[i] = (c[i] - gradient / qii).max(0.0);
        }
    }
    let mut fit = [0.0; N];
    for i in 0..N {
        fit[i] = c[i] / scale[i];
    }
    fit
}
