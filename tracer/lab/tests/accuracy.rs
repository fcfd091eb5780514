//! The accuracy ladders through the library, on real scene files in a temporary folder: what
//! `tessera accuracy` computes, without the command line (`tests/accuracy.rs` at the top runs
//! the command itself).
//!
//! The analytic scene is a furnace whose radiance is exactly 1 everywhere
//! (`tracer/lab/tests/furnace.toml` says why).

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use lab::accuracy::{Config, Cost, Knob, Rgb};
use std::path::{Path, PathBuf};

/// The furnace scene file.
fn furnace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/furnace.toml")
}

/// The command's defaults (`tessera accuracy --help`), timing each render once, for `scene`
/// written to `out`.
fn config(scene: &Path, out: &Path) -> Config {
    Config {
        scene: scene.to_owned(),
        out: out.to_owned(),
        max_spp: 1024,
        width: None,
        height: None,
        knob_spp: 64,
        reference_spp: None,
        analytic_mean: None,
        seed: None,
        knobs: Knob::ALL.to_vec(),
        leak_rays: 1 << 19,
        repeat_below: 0.0,
        repeats: 1,
        cost: Cost::Time,
        threads: None,
        available_memory: None,
        command: "tessera accuracy (a test)".into(),
    }
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
    let scene = furnace();
    for seed in 1..=4u64 {
        let out = dir.path().join(format!("seed-{seed}"));
        lab::accuracy::run(&Config {
            analytic_mean: Some(Rgb([1.0; 3])),
            max_spp: 64,
            width: Some(64),
            height: Some(64),
            knobs: vec![Knob::Spp],
            seed: Some(seed),
            ..config(&scene, &out)
        })
        .unwrap();
        let markdown = std::fs::read_to_string(out.join("accuracy.md")).unwrap();
        assert!(markdown.contains("**Reference**: analytic"), "{markdown}");
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
fn every_knob_is_measured_and_the_reference_is_cached_until_stale() {
    let dir = tempfile::tempdir().unwrap();
    let scene = furnace();
    let out = dir.path().join("out");
    // Each run's reference, as accuracy.md states it.
    let run = |size: u32| {
        lab::accuracy::run(&Config {
            max_spp: 4,
            knob_spp: 2,
            reference_spp: Some(16),
            leak_rays: 2000,
            width: Some(size),
            height: Some(size),
            ..config(&scene, &out)
        })
        .unwrap();
        let markdown = std::fs::read_to_string(out.join("accuracy.md")).unwrap();
        let line = markdown.lines().find(|l| l.starts_with("**Reference**"));
        line.expect("accuracy.md states its reference").to_owned()
    };
    let first = run(16);
    assert!(first.contains("rendered (16 spp"), "{first}");
    let second = run(16);
    assert!(second.contains("cached"), "{second}");
    let third = run(8);
    assert!(
        third.contains("rendered, the cache was stale") && third.contains("width 16 -> 8"),
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
            count("lights"),
            count("environment"),
            count("spectral"),
            count("media")
        ],
        [3, 6, 6, 5, 5, 2, 3, 4, 3, 6]
    );
    // The furnace is one area light: each strategy alone renders other bits than the two
    // weighted (the knob reaches the integrator).
    for row in rows.iter().filter(|r| r["knob"] == "lights").skip(1) {
        assert!(
            row["note"].starts_with("differs"),
            "an area-light strategy alone gave the weighted render's bits: {row:?}"
        );
    }
    // The furnace is white: the spectral rungs differ from the RGB one by noise alone. The
    // CIE sensor makes one wavelength per path noisy (its channels' sum varies with the
    // wavelength), so the bound is four standard errors of the image mean, estimated from the
    // rung's own RMSE over the last run's 8 x 8 x 3 values, and never tighter than 5 %.
    let values = (8 * 8 * 3) as f64;
    for row in rows.iter().filter(|r| r["knob"] == "spectral").skip(1) {
        assert!(
            row["note"].starts_with("differs"),
            "an always-spectral render gave the RGB render's bits: {row:?}"
        );
        let bias = number(row, "mean_bias").abs();
        let bound = (4.0 * number(row, "rmse") / values.sqrt()).max(0.05);
        assert!(
            bias < bound,
            "a spectral white furnace is off by {bias}, beyond {bound}: {row:?}"
        );
    }
    // The binary tree opens other nodes than the 8-wide one, never another hit; nor do camera
    // rays walked one by one instead of in packets, nor paths one by one instead of in lanes.
    for setting in [
        "robustbinary",
        "robust-one-by-one",
        "robust-paths-one-by-one",
    ] {
        let row = rows
            .iter()
            .find(|r| r["knob"] == "traversal" && r["setting"] == setting)
            .expect("a row for each of our traversals");
        assert!(
            row["note"].starts_with("bit-identical"),
            "{setting} changed the image: {row:?}"
        );
    }
    // The furnace has no environment: how it would be sampled changes no bit.
    for row in rows.iter().filter(|r| r["knob"] == "environment").skip(1) {
        assert!(
            row["note"].starts_with("bit-identical"),
            "environment sampling changed an image without an environment: {row:?}"
        );
    }
    // Nor has it media: no flight or shadow ray meets one, however they would be sampled.
    for row in rows.iter().filter(|r| r["knob"] == "media").skip(1) {
        assert!(
            row["note"].starts_with("bit-identical"),
            "media sampling changed an image without media: {row:?}"
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
        "## Wavelength sampling",
        "## Media sampling",
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
