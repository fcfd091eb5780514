//! `tessera compare` and `tessera accuracy`, run as a user runs them: the binary, real EXR files,
//! real scene files in a temporary folder.
//!
//! The analytic scene is a furnace: a closed sphere, seen from inside, whose every surface emits
//! 0.5 and reflects half of what arrives (diffuse albedo 0.5), so the radiance everywhere is
//! exactly 0.5 / (1 - 0.5) = 1 whatever the tessellation. Flat shading: interpolated normals are
//! not energy-conserving, which would make the exact answer something else.

mod common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

const FURNACE: &str = r#"
[render]
width = 16
height = 16
spp = 1
seed = 0

[camera]
position = [0, 0, 0]
look_at = [0, 0, -1]
vfov = 60

[materials.furnace]
type = "emissive"
albedo = 0.5
emission = 0.5

[[object]]
shape = "sphere"
material = "furnace"
radius = 1
subdivisions = 3
inward = true
perturb = 0.1
smooth = false
"#;

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

fn furnace(dir: &Path) -> PathBuf {
    let path = dir.join("furnace.toml");
    std::fs::write(&path, FURNACE).unwrap();
    path
}

fn write_rgb(
    path: &Path,
    width: usize,
    height: usize,
    pixel: impl Fn(usize, usize) -> [f32; 3] + Sync,
) {
    exr::prelude::write_rgb_file(path, width, height, |x, y| {
        let [r, g, b] = pixel(x, y);
        (r, g, b)
    })
    .unwrap();
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

/// The rows of a CSV file with a header, as maps from column name to text.
fn csv_rows(path: &Path) -> Vec<std::collections::BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header line").split(',').collect();
    lines
        .map(|line| {
            // The columns read here never contain commas, so a plain split is enough even though
            // the note column may be quoted.
            let fields: Vec<&str> = line.split(',').collect();
            header
                .iter()
                .zip(fields)
                .map(|(h, f)| (h.to_string(), f.to_string()))
                .collect()
        })
        .collect()
}

fn number(row: &std::collections::BTreeMap<String, String>, column: &str) -> f64 {
    row[column]
        .parse()
        .unwrap_or_else(|e| panic!("column {column} = {:?}: {e}", row[column]))
}

#[test]
fn rmse_falls_as_one_over_the_square_root_of_spp_on_the_furnace() {
    let dir = tempfile::tempdir().unwrap();
    let scene = furnace(dir.path());
    for seed in 1..=4u64 {
        let out = dir.path().join(format!("seed-{seed}"));
        let stdout = tessera_ok(&[
            "accuracy",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--analytic-mean",
            "1,1,1",
            "--max-spp",
            "64",
            "--width",
            "64",
            "--height",
            "64",
            "--knobs",
            "spp",
            "--seed",
            &seed.to_string(),
            "--repeat-below",
            "0",
        ]);
        assert!(stdout.contains("reference: analytic"), "{stdout}");
        let rows = csv_rows(&out.join("accuracy.csv"));
        let spp: Vec<f64> = rows.iter().map(|r| number(r, "spp")).collect();
        assert_eq!(spp, [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0]);
        // Least-squares slope of ln(RMSE) against ln(spp), computed here, not by the command.
        let points: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| (number(r, "spp").ln(), number(r, "rmse").ln()))
            .collect();
        let n = points.len() as f64;
        let (mx, my) = (
            points.iter().map(|p| p.0).sum::<f64>() / n,
            points.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let slope = points.iter().map(|(x, y)| (x - mx) * (y - my)).sum::<f64>()
            / points.iter().map(|(x, _)| (x - mx) * (x - mx)).sum::<f64>();
        assert!((slope + 0.5).abs() < 0.05, "seed {seed}: slope {slope}");
        // Unbiased: at 64 spp the image mean is within half a percent of the exact 1.
        let last = rows.last().unwrap();
        assert!(
            number(last, "mean_bias").abs() < 0.005,
            "seed {seed}: {last:?}"
        );
    }
}

#[test]
fn an_image_compared_with_itself_is_exactly_zero() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.exr");
    write_rgb(&a, 5, 3, |x, y| {
        [x as f32 * 0.3, y as f32 * 1.7, 0.25 + (x * y) as f32]
    });
    let json = compare_json(&a, &a);
    for metric in ["mse", "rmse", "rel_mse", "mae"] {
        assert_eq!(json[metric].as_f64(), Some(0.0), "{metric}: {json}");
    }
    assert_eq!(
        json["max_difference"]["value"].as_f64(),
        Some(0.0),
        "{json}"
    );
    assert_eq!(json["flip"]["mean"].as_f64(), Some(0.0), "{json}");
}

#[test]
fn one_changed_value_gives_the_hand_computed_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let (test, reference) = (
        dir.path().join("test.exr"),
        dir.path().join("reference.exr"),
    );
    // 4x2 pixels, 24 values of 0.5; the test image has 0.75 in the green of pixel (3, 1).
    write_rgb(&reference, 4, 2, |_, _| [0.5; 3]);
    write_rgb(&test, 4, 2, |x, y| {
        if (x, y) == (3, 1) {
            [0.5, 0.75, 0.5]
        } else {
            [0.5; 3]
        }
    });
    let json = compare_json(&test, &reference);
    let value = |key: &str| {
        json[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} missing: {json}"))
    };
    let n = 24.0;
    assert_eq!(value("mse"), 0.0625 / n);
    assert_eq!(value("rmse"), (0.0625f64 / n).sqrt());
    assert!((value("rel_mse") - 0.0625 / (0.51 * 0.51) / n).abs() < 1e-15);
    assert_eq!(value("mae"), 0.25 / n);
    let max = &json["max_difference"];
    assert_eq!(
        (max["value"].as_f64(), max["x"].as_u64(), max["y"].as_u64()),
        (Some(0.25), Some(3), Some(1))
    );
    assert_eq!(max["channel"], "G");
    assert_eq!(json["mean_test"][1].as_f64(), Some(0.5 + 0.25 / 8.0));
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
    write_rgb(&wide, 4, 2, |_, _| [1.0; 3]);
    write_rgb(&tall, 2, 4, |_, _| [1.0; 3]);
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
fn every_knob_is_measured_and_the_reference_is_cached_until_stale() {
    let dir = tempfile::tempdir().unwrap();
    let scene = furnace(dir.path());
    let out = dir.path().join("out");
    let run = |size: &str| {
        tessera_ok(&[
            "accuracy",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--max-spp",
            "4",
            "--knob-spp",
            "2",
            "--reference-spp",
            "16",
            "--leak-rays",
            "2000",
            "--repeat-below",
            "0",
            "--width",
            size,
            "--height",
            size,
        ])
    };
    let first = run("16");
    assert!(first.contains("reference: rendered (16 spp"), "{first}");
    let second = run("16");
    assert!(second.contains("reference: cached"), "{second}");
    let third = run("8");
    assert!(
        third.contains("reference: rendered, the cache was stale")
            && third.contains("width 16 -> 8"),
        "{third}"
    );

    let rows = csv_rows(&out.join("accuracy.csv"));
    let count = |knob: &str| rows.iter().filter(|r| r["knob"] == knob).count();
    assert_eq!(
        [
            count("spp"),
            count("depth"),
            count("roulette"),
            count("bvh"),
            count("traversal"),
            count("offset"),
            count("environment")
        ],
        [3, 6, 6, 5, 3, 2, 3]
    );
    // The binary tree opens other nodes than the 4-wide one, never another hit.
    let binary = rows
        .iter()
        .find(|r| r["knob"] == "traversal" && r["setting"] == "robustbinary")
        .expect("a row for the binary traversal");
    assert!(
        binary["note"].starts_with("bit-identical"),
        "the binary traversal changed the image: {binary:?}"
    );
    // The furnace has no environment: how it would be sampled changes no bit.
    for row in rows.iter().filter(|r| r["knob"] == "environment").skip(1) {
        assert!(
            row["note"].starts_with("bit-identical"),
            "environment sampling changed an image without an environment: {row:?}"
        );
    }
    for row in rows.iter().filter(|r| r["knob"] == "bvh") {
        assert!(
            row["note"].starts_with("bit-identical"),
            "the BVH changed the image: {row:?}"
        );
    }
    for row in &rows {
        assert!(
            number(row, "seconds") > 0.0 && number(row, "rel_mse") > 0.0,
            "{row:?}"
        );
    }
    let markdown = std::fs::read_to_string(out.join("accuracy.md")).unwrap();
    for section in [
        "## Findings",
        "## Samples per pixel",
        "## Maximum path depth",
        "## Russian roulette",
        "## BVH",
        "## Traversal",
        "## Spawn offset",
        "## Environment sampling",
    ] {
        assert!(
            markdown.contains(section),
            "{section} missing from accuracy.md"
        );
    }
    let svg = std::fs::read_to_string(out.join("accuracy.svg")).unwrap();
    assert!(
        svg.starts_with("<svg") && svg.contains("samples per pixel") && svg.contains("traversal"),
        "{svg}"
    );
}
