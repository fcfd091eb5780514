//! How well counted work predicts time: renders frames of scenes in 16x16 tiles on one thread
//! (at most 256x256 pixels and 8 samples per pixel, to keep it quick), times each tile, and fits
//! time = a·nodes + b·triangles + c·camera rays + d·bounce rays + e·shadow rays by least squares. Prints the fit, and for the tracer's own formula (nodes + triangles + 16 per
//! ray) and the fitted one, how far each tile's predicted time is from its measured time. A
//! measurement, not a test.
//!
//! ```text
//! cargo run --release -p sim --example fit_work -- SCENE [SCENE...]
//! ```

use std::time::Instant;

use tracer::Rect;

/// One timed tile: its counters and the seconds it took.
struct Sample {
    scene: usize,
    features: [f64; 5],
    work: f64,
    seconds: f64,
}

const NAMES: [&str; 5] = [
    "nodes",
    "triangles",
    "camera rays",
    "bounce rays",
    "shadow rays",
];

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
        let world = runtime::node::prepare_world(scene, None);
        let frames = [0, settings.frames / 2];
        let spp = f64::from(settings.samples_per_pixel);
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
                    let camera = rect.area() as f64 * spp;
                    samples.push(Sample {
                        scene: index,
                        features: [
                            s.traversal.nodes as f64,
                            s.traversal.triangles as f64,
                            camera,
                            s.rays as f64 - camera,
                            s.shadow_rays as f64,
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
    println!("\nrelative error of each tile's predicted time, each formula scaled per scene:");
    println!(
        "  {:<48} {:>32} {:>32}",
        "scene", "nodes + triangles + 16 per ray", "fitted"
    );
    for (index, path) in scenes.iter().enumerate() {
        let tiles: Vec<&Sample> = samples.iter().filter(|s| s.scene == index).collect();
        println!(
            "  {path:<48} {:>32} {:>32}",
            errors(&tiles, &counted),
            errors(&tiles, &fitted)
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

// Index loops read best in a 5x5 elimination.
#[allow(clippy::needless_range_loop)]
/// Ordinary least squares on the normal equations, weighting each tile by 1 / its time so
/// that cheap and expensive tiles count alike in relative terms.
fn least_squares(samples: &[Sample]) -> [f64; 5] {
    let mut a = [[0.0f64; 5]; 5];
    let mut b = [0.0f64; 5];
    for s in samples {
        let w = 1.0 / (s.seconds * s.seconds);
        for i in 0..5 {
            b[i] += w * s.features[i] * s.seconds;
            for j in 0..5 {
                a[i][j] += w * s.features[i] * s.features[j];
            }
        }
    }
    // Gaussian elimination with partial pivoting.
    for col in 0..5 {
        let pivot = (col..5)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .expect("a non-empty range");
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..5 {
            let factor = a[row][col] / a[col][col];
            for k in col..5 {
                a[row][k] -= factor * a[col][k];
            }
            b[row] -= factor * b[col];
        }
    }
    let mut x = [0.0; 5];
    for row in (0..5).rev() {
        let rest: f64 = (row + 1..5).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - rest) / a[row][row];
    }
    x
}
