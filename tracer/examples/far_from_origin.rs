//! The figures of issue 13: the shipped point-in-sphere (one bounce: every pixel 0.5) and an
//! inward furnace (albedo 0.5, emission 0.5, unlimited depth: radiance 1) moved by `(d, 0, 0)`,
//! rendered with each spawn offset method. Prints mean, standard error and smallest pixel.
//!
//! `cargo run --release -p tracer --example far_from_origin`

use tracer::geometry::{Accel, BuildQuality, OffsetMethod};
use tracer::{Effects, Rect, World, render_tile};

/// The shipped scene's TOML with its sphere, camera and light moved by `(d, 0, 0)`.
fn moved(toml: &str, d: f32, edits: &[(&str, &str)]) -> String {
    let mut text = toml.to_owned();
    for (from, to) in edits {
        text = text.replace(from, to);
    }
    text = text.replace("position = [0, 0, 0]", &format!("position = [{d}, 0, 0]"));
    text = text.replace("look_at = [0, 0, 1]", &format!("look_at = [{d}, 0, 1]"));
    text.replace(
        "[[object]]\n",
        &format!("[[object]]\ntranslate = [{d}, 0, 0]\n"),
    )
}

fn main() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/");
    let read = |p: &str| std::fs::read_to_string(format!("{root}{p}")).expect("shipped scene");
    let point = read("point-in-sphere/point-in-sphere.toml");
    let furnace = read("furnace/furnace.toml");
    let families = [
        (
            "point-in-sphere, depth 1",
            point,
            0.5,
            vec![("max_depth = \"unlimited\"", "max_depth = 1")],
        ),
        (
            "furnace 0.5/0.5, unlimited",
            furnace,
            1.0,
            vec![
                ("max_depth = 8", "max_depth = \"unlimited\""),
                (
                    "russian_roulette_depth = \"off\"",
                    "russian_roulette_depth = 3",
                ),
                ("emission = 1", "emission = 0.5"),
            ],
        ),
    ];
    println!("family | d | offset | mean | standard error | smallest pixel | expected");
    for (name, toml, expected, edits) in &families {
        for d in [0.0f32, 1e3, 1e4, 1e5, 3e5, 1e6, 2e6] {
            for offset in OffsetMethod::ALL {
                let scene = tracer::scene::load_str(&moved(toml, d, edits)).expect("loads");
                let accel = Accel::build(&scene.triangles, BuildQuality::default());
                let effects = Effects::of(&scene);
                let (w, h) = (scene.settings.width, scene.settings.height);
                let mut world = World::new(scene, accel, effects);
                world.offset = offset;
                let out = render_tile(&world, 0, Rect { x: 0, y: 0, w, h });
                let values: Vec<f64> = out.pixels.iter().map(|p| f64::from(p[0])).collect();
                let n = values.len() as f64;
                let mean = values.iter().sum::<f64>() / n;
                let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
                let min = values.iter().cloned().fold(f64::INFINITY, f64::min);
                println!(
                    "{name} | {d:e} | {} | {mean:.4} | {:.4} | {min:.3} | {expected}",
                    offset.name(),
                    (var / n).sqrt()
                );
            }
        }
    }
}
