//! Every scene we ship loads and renders: each `scenes/NAME/*.toml`, and each
//! `scenes/shared/*.toml` when `../shared/scenes` (beside the work tree, which those point into)
//! is present; when it is absent the test says what it did not load.
//!
//! The loader refuses what it cannot render honestly (unused tables, keys that do not apply,
//! outside media and indices that contradict the geometry), so a check that grows stricter must
//! not refuse a scene we ship: this is where that shows. Each renders its first and last frames
//! at 6x6 pixels, one sample, a few bounces, with no NaN or infinite sample (`render`'s own
//! check) and some light.

mod common;

use common::render;
use std::path::{Path, PathBuf};
use tracer::scene::load;

fn scenes_folder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// The TOML files directly inside each folder of `scenes/` (`shared` apart), sorted.
fn shipped() -> Vec<PathBuf> {
    let mut found = Vec::new();
    for folder in std::fs::read_dir(scenes_folder()).expect("scenes/ is readable") {
        let folder = folder.expect("a readable entry").path();
        if !folder.is_dir() || folder.ends_with("shared") {
            continue;
        }
        for file in std::fs::read_dir(&folder).expect("a readable scene folder") {
            let file = file.expect("a readable entry").path();
            if file.extension().is_some_and(|e| e == "toml") {
                found.push(file);
            }
        }
    }
    found.sort();
    found
}

/// `scenes/shared/*.toml`, sorted.
fn shared() -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(scenes_folder().join("shared"))
        .expect("scenes/shared is readable")
        .map(|e| e.expect("a readable entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    found.sort();
    found
}

fn loads_and_renders(path: &Path) {
    let mut scene = load(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    scene.settings.width = 6;
    scene.settings.height = 6;
    scene.settings.samples_per_pixel = 1;
    scene.settings.max_depth = Some(3);
    let last = scene.settings.frames.max(1) - 1;
    for frame in [0, last] {
        let out = render(&scene, None, frame);
        let light: f32 = out.pixels.iter().flatten().sum();
        assert!(
            light > 0.0,
            "{} frame {frame}: a black image",
            path.display()
        );
    }
}

#[test]
fn every_shipped_scene_loads_and_renders() {
    let scenes = shipped();
    // cornell-blur, cornell-box, fog-window, furnace, glass-cluster-pan, point-in-sphere,
    // prism, swinging-lamp at least.
    assert!(scenes.len() >= 8, "found only {scenes:?}");
    for path in &scenes {
        loads_and_renders(path);
    }
}

#[test]
fn every_shared_scene_loads_and_renders() {
    let data = scenes_folder().join("../../shared/scenes");
    let scenes = shared();
    if !data.is_dir() {
        println!(
            "NOT TESTED: {} is absent, so these were not loaded: {scenes:?}",
            data.display()
        );
        return;
    }
    assert!(scenes.len() >= 12, "found only {scenes:?}");
    for path in &scenes {
        loads_and_renders(path);
    }
}
