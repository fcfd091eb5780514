//! `tessera compare`, `tessera accuracy` and `tessera meshes`, run as a user runs them: the binary, real EXR files,
//! real scene files in a temporary folder. What is tested here is the command line (flags,
//! output, error messages); the metrics and the ladders themselves are tested through the
//! library in `tracer/lab/tests/`.
//!
//! The analytic scene is a furnace whose radiance is exactly 1 everywhere
//! (`tracer/lab/tests/furnace.toml` says why).

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

fn tessera(args: &[&str]) -> Output {
    common::tessera()
        .args(args)
        .output()
        .expect("the tessera binary runs")
}

/// Runs tessera, fails with its stderr unless it succeeds, and returns its stdout.
fn tessera_ok(args: &[&str]) -> String {
    let out = common::run_ok(common::tessera().args(args));
    String::from_utf8(out.stdout).expect("stdout is UTF-8")
}

/// The furnace scene file.
fn furnace() -> PathBuf {
    common::repo("tracer/lab/tests/furnace.toml")
}

/// Writes a constant `width` x `height` image of `value` as OpenEXR, through the tracer's writer.
fn write_flat(path: &Path, width: u32, height: u32, value: f32) {
    let pixels = vec![[value; 3]; (width * height) as usize];
    tracer::output::write_exr(path, width, height, &pixels).unwrap();
}

fn compare_json(a: &Path, b: &Path) -> Value {
    let stdout = tessera_ok(&[
        "compare",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--json",
    ]);
    serde_json::from_str(&stdout).expect("compare --json prints JSON")
}

#[test]
fn compare_prints_its_metrics_as_json_or_as_text() {
    let dir = tempfile::tempdir().unwrap();
    let (test, reference) = (
        dir.path().join("test.exr"),
        dir.path().join("reference.exr"),
    );
    // 3x1 pixels, 9 values of 0.5; the test image has 0.75 in the red of pixel (2, 0). Both
    // under 1, so that FLIP's clamped tone mapping sees the difference.
    write_flat(&reference, 3, 1, 0.5);
    let mut pixels = vec![[0.5f32; 3]; 3];
    pixels[2][0] = 0.75;
    tracer::output::write_exr(&test, 3, 1, &pixels).unwrap();
    let json = compare_json(&test, &reference);
    assert_eq!(json["mse"].as_f64(), Some(0.0625 / 9.0), "{json}");
    let max = &json["max_difference"];
    assert_eq!(
        (max["value"].as_f64(), max["x"].as_u64(), max["y"].as_u64()),
        (Some(0.25), Some(2), Some(0))
    );
    assert_eq!(max["channel"], "R");
    assert!(json["flip"]["mean"].as_f64().unwrap() > 0.0, "{json}");
    // The text report says how FLIP saw the images.
    let text = tessera_ok(&[
        "compare",
        test.to_str().unwrap(),
        reference.to_str().unwrap(),
    ]);
    assert!(
        text.contains("exposure 1") && text.contains("8-bit sRGB"),
        "{text}"
    );
}

#[test]
fn different_sizes_or_channels_are_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let (wide, tall, rgba) = (
        dir.path().join("wide.exr"),
        dir.path().join("tall.exr"),
        dir.path().join("rgba.exr"),
    );
    write_flat(&wide, 4, 2, 1.0);
    write_flat(&tall, 2, 4, 1.0);
    exr::prelude::write_rgba_file(&rgba, 4, 2, |_, _| (1.0f32, 1.0f32, 1.0f32, 1.0f32)).unwrap();
    let sizes = tessera(&["compare", wide.to_str().unwrap(), tall.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&sizes.stderr);
    assert!(!sizes.status.success());
    assert!(
        stderr.contains("different sizes") && stderr.contains("4x2") && stderr.contains("2x4"),
        "{stderr}"
    );
    let channels = tessera(&["compare", wide.to_str().unwrap(), rgba.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&channels.stderr);
    assert!(!channels.status.success());
    assert!(
        stderr.contains("different channel sets") && stderr.contains("A,B,G,R"),
        "{stderr}"
    );
}

#[test]
fn accuracy_runs_the_ladders_the_flags_name() {
    let dir = tempfile::tempdir().unwrap();
    let scene = furnace();
    let out = dir.path().join("out");
    let stdout = tessera_ok(&[
        "accuracy",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--analytic-mean",
        "1",
        "--max-spp",
        "4",
        "--knob-spp",
        "2",
        "--width",
        "8",
        "--height",
        "8",
        "--knobs",
        "spp,depth",
        "--repeat-below",
        "0",
    ]);
    assert!(stdout.contains("reference: analytic"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("accuracy.csv")).unwrap();
    let knobs: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(knobs.iter().filter(|k| **k == "spp").count(), 3, "{csv}");
    assert_eq!(knobs.iter().filter(|k| **k == "depth").count(), 6, "{csv}");
    assert_eq!(knobs.len(), 9, "{csv}");
    for file in ["accuracy.md", "accuracy.svg"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
}

#[test]
fn meshes_writes_every_still_triangle_the_bench_counts_and_refuses_a_missing_scene() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/cornell-box/cornell-box.toml");
    let out = dir.path().join("meshes");
    let printed = tessera_ok(&[
        "meshes",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let index: Value =
        serde_json::from_slice(&std::fs::read(out.join("meshes.json")).unwrap()).unwrap();
    let meshes = index.as_array().unwrap();
    let triangles: u64 = meshes
        .iter()
        .map(|m| m["triangles"].as_u64().unwrap())
        .sum();
    assert!(
        printed.starts_with(&format!("{} meshes, {triangles} triangles", meshes.len())),
        "{printed}"
    );
    for mesh in meshes {
        let file = out.join(mesh["file"].as_str().unwrap());
        assert!(
            std::fs::read(&file).unwrap().starts_with(b"ply\n"),
            "{}",
            file.display()
        );
    }
    // The benchmark counts the triangles the tracer traces: every one is in a file.
    let bench: Value = serde_json::from_str(&tessera_ok(&[
        "bench",
        scene.to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "8",
        "--spp",
        "1",
        "--json",
    ]))
    .unwrap();
    assert_eq!(Some(triangles), bench["scenes"][0]["triangles"].as_u64());
    // The process's memory, as the comparison with Mitsuba reads it: the peak holds the rest.
    let memory = &bench["scenes"][0]["memory"];
    let kib = |key: &str| {
        memory[key]
            .as_u64()
            .unwrap_or_else(|| panic!("{key} in {memory}"))
    };
    let (built, rendered, peak) = (
        kib("resident_after_build_kib"),
        kib("resident_after_render_kib"),
        kib("peak_resident_kib"),
    );
    assert!(built > 0 && peak >= built.max(rendered), "{memory}");

    let missing = dir.path().join("absent.toml");
    let failed = tessera(&[
        "meshes",
        missing.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&missing.display().to_string()) && !stderr.contains("backtrace"),
        "{stderr}"
    );
}
