//! `tessera simulate` through the real binary: the files it writes, their contents, that a saved
//! trace gives the same runs as the recipe it came from, and clear errors for bad input.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use common::{run_ok, tessera};
use std::path::Path;

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The CSV's rows without the wall-time column, which is the only one allowed to differ
/// between two identical runs.
fn without_wall_time(csv: &str) -> Vec<String> {
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let wall = header.iter().position(|c| *c == "wall_s").unwrap();
    csv.lines()
        .map(|line| {
            let mut cells: Vec<&str> = line.split(',').collect();
            cells.remove(wall);
            cells.join(",")
        })
        .collect()
}

#[test]
fn simulate_writes_tables_charts_and_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let trace = dir.path().join("spot.jsonl");
    let mut command = tessera();
    command.args([
        "simulate",
        "synthetic:64x64:3",
        "--peers",
        "1,2,4",
        "--tiles",
        "16,64",
    ]);
    command
        .args(["--latency", "0.2", "--seed", "3", "--out"])
        .arg(&out);
    command.arg("--save-trace").arg(&trace);
    let stdout = String::from_utf8(run_ok(&mut command).stdout).unwrap();
    assert!(stdout.contains("24 runs"), "{stdout}");

    let runs = read(&out.join("runs.csv"));
    assert_eq!(runs.lines().count(), 1 + 24, "{runs}");
    assert!(runs.starts_with("policy,peers,slots,tiles,frames,"));
    let frames = read(&out.join("frames.csv"));
    assert_eq!(frames.lines().count(), 1 + 24 * 3);
    let json: serde_json::Value = serde_json::from_str(&read(&out.join("runs.json"))).unwrap();
    let json = json.as_array().expect("runs.json holds an array of runs");
    assert_eq!(json.len(), 24);
    for run in json {
        let efficiency = run["efficiency"].as_f64().unwrap();
        assert!(efficiency > 0.0 && efficiency <= run["bound_efficiency"].as_f64().unwrap() + 1e-9);
        assert_eq!(run["frames"].as_array().unwrap().len(), 3);
        assert!(run["frames"][0]["results_ok"].as_bool().unwrap());
    }
    let summary = read(&out.join("summary.md"));
    for heading in [
        "Efficiency vs peers, 16 tiles",
        "Best tile count",
        "PBT with stealing",
    ] {
        assert!(
            summary.contains(heading),
            "{heading} missing from:\n{summary}"
        );
    }
    let charts = [
        "efficiency-vs-peers-16.svg",
        "efficiency-vs-peers-64.svg",
        "efficiency-vs-tiles-1.svg",
        "efficiency-vs-tiles-2.svg",
        "efficiency-vs-tiles-4.svg",
        "gantt.svg",
    ];
    for chart in charts {
        let svg = read(&out.join(chart));
        assert!(svg.starts_with("<svg"), "{chart} is not an SVG");
    }
    assert!(read(&out.join("efficiency-vs-peers-16.svg")).contains("pbt bound"));

    // The saved trace is the synthetic one: simulating it again gives the same runs.
    let again = dir.path().join("again");
    let mut command = tessera();
    command
        .arg("simulate")
        .arg(&trace)
        .args(["--peers", "1,2,4", "--tiles", "16,64"]);
    command
        .args(["--latency", "0.2", "--seed", "3", "--out"])
        .arg(&again);
    run_ok(&mut command);
    assert_eq!(
        without_wall_time(&runs),
        without_wall_time(&read(&again.join("runs.csv")))
    );
}

#[test]
fn network_effects_and_crashes_reach_the_runs() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        let out = dir.path().join(extra.join("_").replace(['@', ','], "-"));
        let mut command = tessera();
        command.args([
            "simulate",
            "synthetic:64x64:2",
            "--peers",
            "4",
            "--tiles",
            "64",
        ]);
        command
            .args(["--policy", "pbt+steal", "--out"])
            .arg(&out)
            .args(extra);
        run_ok(&mut command);
        let json: serde_json::Value = serde_json::from_str(&read(&out.join("runs.json"))).unwrap();
        json[0].clone()
    };
    let ideal = run(&[]);
    let slow = run(&["--bandwidth", "1", "--latency", "5"]);
    assert!(slow["makespan"].as_f64() > ideal["makespan"].as_f64());
    assert_eq!(slow["bandwidth_bytes_per_second"].as_f64(), Some(125_000.0));
    for crash in ["2@0.01", "3@tile:5"] {
        let crashed = run(&["--crash", crash]);
        let frames = crashed["frames"].as_array().unwrap();
        let failures: u64 = frames.iter().map(|f| f["failures"].as_u64().unwrap()).sum();
        // The crash reaches the run: the crashed peer is dealt nothing more, whether the owner
        // noticed it as lost (a failure) or first backed up its overdue work and excluded it.
        assert!(failures <= 1, "--crash {crash}: {failures} failures");
        let last = frames.last().unwrap();
        assert_eq!(last["participants"].as_u64(), Some(3), "--crash {crash}");
    }
}

#[test]
fn bad_arguments_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (
            &["synthetic:8x8:1", "--policy", "fastest"],
            "unknown policy",
        ),
        (&["no-such-trace.jsonl"], "no-such-trace.jsonl"),
        (&["synthetic:8x8:1", "--crash", "3"], "PEER@SECONDS"),
        (&["synthetic:8x8:1", "--crash", "3@tile:0"], "PEER@tile:N"),
        (
            &[
                "synthetic:8x8:1",
                "--tiles",
                "4",
                "--peers",
                "2",
                "--crash",
                "0@1",
            ],
            "owner",
        ),
    ];
    for (args, expected) in cases {
        let output = tessera()
            .arg("simulate")
            .args(args)
            .arg("--out")
            .arg(dir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

/// Links whose round trip reaches or outlasts the peers' silence timeout (10 s) were refused
/// while the simulated cores were not told their links' round trips (the owner would have
/// declared every peer failed before it could answer, and a run of 16 peers did not end);
/// told them, as the QUIC driver tells real ones, the owner waits out three round trips, and
/// such links simply work.
#[test]
fn simulated_links_slower_than_the_silence_timeout_work() {
    let dir = tempfile::tempdir().unwrap();
    for flags in [
        &["--latency", "5000"][..],
        &["--latency", "4000", "--jitter", "1000"],
        &["--latency", "8000", "--link-spread", "0.25"],
    ] {
        let output = common::small_simulation(dir.path(), flags)
            .output()
            .unwrap();
        assert!(output.status.success(), "{flags:?}: {output:?}");
    }
}
