//! The core promise, end to end through the binary: a frame's bits do not depend on how many
//! peers rendered it, how it was cut into tiles, whether tiles were stolen, or on thread counts.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use common::{frames, pixels, repo, run_ok, tessera};
use std::path::Path;

/// Renders the shipped uneven animation small, with `extra` flags, into `out`.
fn render(out: &Path, extra: &[&str]) {
    let scene = repo("scenes/glass-cluster-pan/glass-cluster-pan.toml");
    let mut command = tessera();
    command.args(["render"]).arg(&scene).arg("--out").arg(out);
    command.args([
        "--width", "48", "--height", "40", "--spp", "2", "--frames", "3",
    ]);
    command.args(extra);
    run_ok(&mut command);
}

#[test]
fn any_peer_count_partition_and_stealing_gives_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let reference_dir = dir.path().join("reference");
    render(
        &reference_dir,
        &[
            "--peers",
            "1",
            "--threads",
            "1",
            "--balancer",
            "regular",
            "--tiles",
            "1",
        ],
    );
    let reference = frames(&reference_dir);
    assert_eq!(reference.len(), 3);
    for (name, _) in &reference {
        for p in pixels(&reference_dir.join(name)) {
            assert!(
                p.iter().all(|c| c.is_finite() && *c >= 0.0),
                "{name} has a bad pixel {p:?}"
            );
        }
    }
    let variants: &[&[&str]] = &[
        &["--peers", "1", "--threads", "2", "--tiles", "64"],
        &["--peers", "2", "--balancer", "pbt", "--tiles", "32"],
        &[
            "--peers",
            "2",
            "--balancer",
            "regular",
            "--tiles",
            "25",
            "--no-steal",
        ],
        &["--peers", "5", "--balancer", "pbt", "--tiles", "40"],
        &[
            "--peers",
            "5",
            "--balancer",
            "regular",
            "--tiles",
            "16",
            "--no-steal",
        ],
        &[
            "--peers",
            "5",
            "--balancer",
            "pbt",
            "--tiles",
            "7",
            "--no-steal",
        ],
    ];
    for (i, flags) in variants.iter().enumerate() {
        let out = dir.path().join(format!("v{i}"));
        render(&out, flags);
        let got = frames(&out);
        assert_eq!(got.len(), reference.len(), "{flags:?}");
        for ((name, a), (_, b)) in reference.iter().zip(&got) {
            assert!(a == b, "{name} differs with {flags:?}");
        }
    }
}

#[test]
fn a_different_seed_gives_a_different_image() {
    // Guards the test above: if the seed were ignored, or output constant, equality would be empty.
    let dir = tempfile::tempdir().unwrap();
    render(&dir.path().join("a"), &["--peers", "1"]);
    render(&dir.path().join("b"), &["--peers", "1", "--seed", "7"]);
    let (a, b) = (frames(&dir.path().join("a")), frames(&dir.path().join("b")));
    assert_ne!(a[0].1, b[0].1);
}

/// `tessera bench` renders the very pixels `tessera render` does, seed for seed, so that the
/// images a benchmark compares with another renderer's (`scripts/mitsuba_compare.py`, which
/// takes a second seed for the noise floor) are the renderer's own: the same `--seed` gives the
/// same bits, and another seed another image.
#[test]
fn bench_draws_what_render_draws_seed_for_seed() {
    let dir = tempfile::tempdir().unwrap();
    let scene = repo("scenes/glass-cluster-pan/glass-cluster-pan.toml");
    let bench = |seed: &str| {
        let out = dir.path().join(format!("bench-{seed}"));
        let mut command = tessera();
        command.arg("bench").arg(&scene).args([
            "--width", "48", "--height", "40", "--spp", "2", "--seed", seed, "--out",
        ]);
        run_ok(command.arg(&out));
        pixels(&out.join("glass-cluster-pan.exr"))
    };
    render(&dir.path().join("render"), &["--peers", "1", "--seed", "7"]);
    let rendered = pixels(&dir.path().join("render/frame-0000.exr"));
    let (seven, eight) = (bench("7"), bench("8"));
    assert!(
        seven == rendered,
        "bench --seed 7 differs from render --seed 7"
    );
    assert!(seven != eight, "bench ignores --seed");
}

#[test]
fn the_render_leaves_stats_tile_maps_and_a_gantt_chart() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    render(&out, &["--peers", "3", "--tile-map", "--tiles", "16"]);
    for name in [
        "stats.json",
        "gantt.svg",
        "tiles-0000.png",
        "frame-0002.png",
    ] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    // One chart per frame beside the run's, each drawing that frame's tiles in full.
    for frame in 0..3 {
        let chart = out.join(format!("gantt/frame-{frame:04}.svg"));
        let svg =
            std::fs::read_to_string(&chart).unwrap_or_else(|e| panic!("{}: {e}", chart.display()));
        assert!(
            svg.contains(&format!("frame {frame}")),
            "{}",
            chart.display()
        );
        assert!(svg.matches("<rect").count() >= 16, "fewer bars than tiles");
    }
    let overview = std::fs::read_to_string(out.join("gantt.svg")).unwrap();
    assert!(
        overview.contains("busy share"),
        "the run's chart lacks its utilisation"
    );
    let stats = common::stats(&out);
    let frames = stats["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 3);
    let mut rendered = 0;
    for frame in frames {
        let tiles = frame["tiles"].as_array().unwrap();
        assert_eq!(tiles.len(), 16);
        let area: u64 = tiles
            .iter()
            .map(|t| t["rect"][2].as_u64().unwrap() * t["rect"][3].as_u64().unwrap())
            .sum();
        assert_eq!(area, 48 * 40, "tiles cover the image");
        rendered += frame["peers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["tiles_rendered"].as_u64().unwrap())
            .sum::<u64>();
    }
    // Frames overlap, and a peer's report covers the time since its previous one, so only the
    // run's sum is bound to count every tile.
    assert!(
        rendered >= 3 * 16,
        "peers report at least every tile rendered once"
    );
}

#[test]
fn a_recorded_trace_drives_the_simulator() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let trace = dir.path().join("trace.jsonl");
    render(&out, &["--peers", "2", "--trace", trace.to_str().unwrap()]);
    let text = std::fs::read_to_string(&trace).unwrap();
    assert_eq!(
        text.lines().count(),
        1 + 3,
        "a header and one line per frame"
    );
    let sim = dir.path().join("sim");
    run_ok(
        tessera()
            .arg("simulate")
            .arg(&trace)
            .args([
                "--peers",
                "1,2",
                "--policy",
                "pbt,pbt+steal",
                "--tiles",
                "8",
                "--out",
            ])
            .arg(&sim),
    );
    let runs = std::fs::read_to_string(sim.join("runs.csv")).unwrap();
    assert_eq!(
        runs.lines().count(),
        1 + 4,
        "a header and one row per (peers, policy)"
    );
}

/// The simulator deals the same initial tile sets as the runtime did, frame after frame (the
/// PBT re-cut from the same measured costs), for both balancers and both ways of dealing; frame times are compared too,
/// but only printed, since they depend on this machine.
#[test]
fn the_simulator_deals_the_tiles_the_runtime_dealt() {
    // The third render predicts without motion: the simulator must read that from stats.json.
    for (balancer, peers, deal, motion) in [
        ("pbt", "3", "contiguous", "16"),
        ("regular", "4", "round-robin", "16"),
        ("pbt", "3", "interleaved", "off"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let trace = dir.path().join("trace.jsonl");
        let stats = dir.path().join("stats.json");
        render(
            &out,
            &[
                "--peers",
                peers,
                "--balancer",
                balancer,
                "--tiles",
                "12",
                "--deal",
                deal,
                "--motion",
                motion,
                "--trace",
                trace.to_str().unwrap(),
                "--stats",
                stats.to_str().unwrap(),
            ],
        );
        let output = run_ok(
            tessera()
                .arg("simulate")
                .arg(&trace)
                .arg("--validate")
                .arg(&stats)
                .arg("--out")
                .arg(dir.path().join("validation")),
        );
        let stdout = String::from_utf8(output.stdout).unwrap();
        assert!(
            stdout.contains("initial tile sets identical in 3 of 3 frames"),
            "{balancer} dealt {deal} to {peers} peers:\n{stdout}"
        );
        // The prediction is the render's, read from stats.json, not the simulator's default.
        assert!(
            stdout.contains(&format!("motion {motion},")),
            "{balancer}, motion {motion}:\n{stdout}"
        );
        let csv = std::fs::read_to_string(dir.path().join("validation/validation.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 3, "{csv}");
    }
}
