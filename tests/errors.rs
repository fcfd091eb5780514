//! What a user sees when something is wrong: the message and its causes, and exit status 1;
//! never a backtrace, even with `RUST_BACKTRACE` set, as many Rust users have it.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use common::tessera;
use std::process::Command;

/// Runs `command` with backtraces asked for, expects it to fail as a user error, and returns
/// its standard error.
fn user_error(command: &mut Command) -> String {
    let output = command
        .env("RUST_BACKTRACE", "1")
        .env("RUST_LIB_BACKTRACE", "1")
        .output()
        .expect("the tessera binary runs");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(1), "{command:?}:\n{stderr}");
    assert!(stderr.contains("error: "), "{command:?}:\n{stderr}");
    assert!(
        !stderr.to_lowercase().contains("backtrace"),
        "{command:?} printed a backtrace:\n{stderr}"
    );
    stderr
}

#[test]
fn user_errors_print_their_message_and_causes_without_a_backtrace() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");

    // A setting refused before rendering.
    let stderr = user_error(
        tessera()
            .arg("render")
            .arg(&scene)
            .args(["--spp", "0"])
            .arg("--out")
            .arg(&out),
    );
    assert!(stderr.contains("samples per pixel"), "{stderr}");

    // A bad OBJ line: the file and line are named.
    std::fs::write(
        dir.path().join("bad.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
    )
    .unwrap();
    let toml = dir.path().join("bad.toml");
    std::fs::write(
        &toml,
        "[render]\nwidth = 8\nheight = 8\nspp = 1\n[camera]\nposition = [0, 0, 3]\n\
         look_at = [0, 0, 0]\nvfov = 40\n[[object]]\nobj = \"bad.obj\"\n",
    )
    .unwrap();
    let stderr = user_error(tessera().arg("render").arg(&toml).arg("--out").arg(&out));
    assert!(
        stderr.contains("bad.obj") && stderr.contains(":4"),
        "{stderr}"
    );

    // A file that is not there: the cause (the operating system's word) is on a line of its own.
    let stderr = user_error(tessera().args(["compare", "missing-a.exr", "missing-b.exr"]));
    assert!(stderr.contains("missing-a.exr"), "{stderr}");

    // A simulator setting out of range names its flag.
    let stderr = user_error(
        tessera()
            .args(["simulate", "synthetic:64x64:2", "--bandwidth=-1"])
            .arg("--out")
            .arg(&out),
    );
    assert!(stderr.contains("--bandwidth"), "{stderr}");
}

/// More in-process peers than can connect to each other is refused before rendering, naming
/// the flag, instead of waiting forever for refused connections.
#[test]
fn more_peers_than_can_connect_are_refused_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let started = std::time::Instant::now();
    let stderr = user_error(
        tessera()
            .arg("render")
            .arg(&scene)
            .args(["--peers", "500", "--out"])
            .arg(dir.path()),
    );
    assert!(stderr.contains("--peers 500"), "{stderr}");
    assert!(started.elapsed() < std::time::Duration::from_secs(10));
    assert!(!dir.path().join("frame-0000.exr").exists());
}

/// Settings whose messages or buffers cannot exist are refused before rendering, each naming
/// its flag and the limit, instead of surfacing as a lost peer.
#[test]
fn settings_past_the_limits_are_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let render = |flags: &[&str]| {
        let mut command = tessera();
        command
            .arg("render")
            .arg(&scene)
            .args(flags)
            .arg("--out")
            .arg(dir.path());
        user_error(&mut command)
    };
    let stderr = render(&["--width", "512", "--height", "512", "--tiles", "100000000"]);
    assert!(
        stderr.contains("--tiles 100000000") && stderr.contains("262144 pixels"),
        "{stderr}"
    );
    let stderr = render(&["--width", "4096", "--height", "4096", "--tiles", "100000"]);
    assert!(
        stderr.contains("--tiles 100000") && stderr.contains("65536"),
        "{stderr}"
    );
    // A frame of 4e10 pixels needs far more memory than any machine running these tests.
    let stderr = render(&["--width", "200000", "--height", "200000", "--spp", "1"]);
    assert!(
        stderr.contains("--width 200000 --height 200000"),
        "{stderr}"
    );
    // Two tiles of an 8192x8192 frame would be results of 400 MB each.
    let stderr = render(&["--width", "8192", "--height", "8192", "--tiles", "2"]);
    assert!(
        stderr.contains("--tiles 2") && stderr.contains("too large"),
        "{stderr}"
    );
    assert!(!dir.path().join("frame-0000.exr").exists());
}

/// Runs `command`, expects the command line's parser to refuse it (exit status 2, the usage
/// error's), and returns its standard error.
fn usage_error(command: &mut Command) -> String {
    let output = command
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("the tessera binary runs");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(2), "{command:?}:\n{stderr}");
    assert!(
        !stderr.contains("panicked") && !stderr.to_lowercase().contains("backtrace"),
        "{command:?}:\n{stderr}"
    );
    stderr
}

/// Flag values that could not work are refused before anything starts, naming the flag and
/// what it takes: infinite, NaN, too short or too long timeouts (an infinite one panicked),
/// thread counts of zero or of a hundred thousand (which spent a minute spawning threads),
/// previews of NaN or infinite exposure (black or white), and zero peers, tiles or frames
/// (which ran one peer, failed under another name, or rendered nothing).
#[test]
fn flag_values_that_cannot_work_are_refused_before_anything_starts() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let started = std::time::Instant::now();
    let cases: [(&str, &[&str]); 6] = [
        ("--peer-timeout", &["inf", "nan", "1e20", "0.05", "-1", "0"]),
        ("--threads", &["0", "4097", "100000", "4294967296", "-2"]),
        ("--exposure", &["nan", "inf", "-inf", "-1", "1e39"]),
        ("--peers", &["0", "-1"]),
        ("--tiles", &["0"]),
        ("--frames", &["0", "16777217", "4294967295"]),
    ];
    for (flag, values) in cases {
        for value in values {
            let stderr = usage_error(
                tessera()
                    .arg("render")
                    .arg(&scene)
                    .arg(format!("{flag}={value}"))
                    .arg("--out")
                    .arg(dir.path()),
            );
            assert!(
                stderr.contains(&format!("'{value}' for '{flag}")),
                "{flag}={value}:\n{stderr}"
            );
        }
    }
    // Every command that renders takes the same thread counts.
    for command in [
        vec!["bench", "--threads", "0"],
        vec!["accuracy", "scene.toml", "--threads", "5000"],
        vec![
            "peer",
            "--join",
            "127.0.0.1:1",
            "--certs",
            ".",
            "--threads",
            "0",
        ],
    ] {
        let stderr = usage_error(tessera().args(&command));
        assert!(stderr.contains("for '--threads"), "{command:?}:\n{stderr}");
    }
    assert!(started.elapsed() < std::time::Duration::from_secs(30));
    assert!(!dir.path().join("frame-0000.exr").exists());
}

/// Files written only once the render is over (statistics, the chart, the cost trace) are
/// checked before it starts: a folder where a file should be is refused naming the flag, and
/// nothing is rendered; a file in a folder not yet made is written, as `--out` is made.
#[test]
fn files_written_at_the_end_are_checked_at_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let out = dir.path().join("out");
    let small = [
        "--width", "8", "--height", "8", "--spp", "1", "--peers", "1",
    ];
    for flag in ["--stats", "--gantt", "--trace"] {
        let stderr = user_error(
            tessera()
                .arg("render")
                .arg(&scene)
                .args(small)
                .arg(flag)
                .arg(dir.path())
                .arg("--out")
                .arg(&out),
        );
        assert!(
            stderr.contains(&format!("{flag} {}", dir.path().display()))
                && stderr.contains("is a folder"),
            "{stderr}"
        );
        assert!(!out.join("frame-0000.exr").exists());
    }
    let stats = dir.path().join("new").join("folder").join("stats.json");
    let status = tessera()
        .arg("render")
        .arg(&scene)
        .args(small)
        .arg("--stats")
        .arg(&stats)
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    assert!(stats.exists() && out.join("frame-0000.exr").exists());
}

/// `tessera accuracy` refuses, as `render` does, an image whose buffers cannot fit in this
/// machine's memory, and a knob named twice.
#[test]
fn accuracy_refuses_images_past_memory_and_knobs_named_twice() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let started = std::time::Instant::now();
    let stderr = user_error(
        tessera()
            .arg("accuracy")
            .arg(&scene)
            .args(["--width", "200000", "--height", "200000", "--out"])
            .arg(dir.path()),
    );
    assert!(
        stderr.contains("--width 200000 --height 200000") && stderr.contains("MiB free"),
        "{stderr}"
    );
    assert!(started.elapsed() < std::time::Duration::from_secs(20));
    let stderr = user_error(
        tessera()
            .arg("accuracy")
            .arg(&scene)
            .args(["--knobs", "spp,depth,spp", "--out"])
            .arg(dir.path()),
    );
    assert!(stderr.contains("--knobs names `spp` twice"), "{stderr}");
}

/// The simulator, the bench and keygen refuse values that panicked, aborted or ran away, each
/// naming its flag: times too long for the simulator's clock (1e300 milliseconds panicked in
/// `Duration`), a bandwidth so small a transfer never ends, a crash at 1e300 seconds, zero
/// frames, a NaN doubt threshold, a trace of an image 4294967295 pixels a side (which aborted
/// allocating exabytes), 2^32 timed steal exchanges (32 GB), a hundred million simulated peers
/// (which aborted allocating), a bench image past this machine's memory, and a hundred million
/// certificates.
#[test]
fn simulator_bench_and_keygen_values_that_cannot_work_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let simulate = |flags: &[&str]| common::small_simulation(dir.path(), flags);
    let started = std::time::Instant::now();
    for flag in [
        "--latency",
        "--jitter",
        "--loss-detection",
        "--tile-overhead",
    ] {
        let stderr = user_error(&mut simulate(&[flag, "1e300"]));
        assert!(stderr.contains(&format!("{flag} must be")), "{stderr}");
    }
    // A hundred million simulated peers would keep state about each other past any memory.
    let stderr = user_error(
        tessera()
            .args([
                "simulate",
                "synthetic:16x12:2",
                "--peers",
                "2,100000000",
                "--tiles",
                "4",
                "--out",
            ])
            .arg(dir.path()),
    );
    assert!(
        stderr.contains("--peers 100000000") && stderr.contains("MiB free"),
        "{stderr}"
    );
    let stderr = user_error(&mut simulate(&["--bandwidth", "1e-300"]));
    assert!(stderr.contains("--bandwidth must be"), "{stderr}");
    let stderr = user_error(&mut simulate(&["--crash", "1@1e300"]));
    assert!(stderr.contains("--crash \"1@1e300\""), "{stderr}");
    let stderr = usage_error(&mut simulate(&["--frames", "0"]));
    assert!(stderr.contains("for '--frames"), "{stderr}");
    let stderr = usage_error(&mut simulate(&["--doubt-error", "nan"]));
    assert!(stderr.contains("for '--doubt-error"), "{stderr}");
    let trace = dir.path().join("huge.json");
    std::fs::write(
        &trace,
        "{\"format\":\"tessera-trace\",\"version\":1,\"width\":4294967295,\"height\":4294967295,\
         \"block_size\":4294967295,\"source\":\"x\"}\n{\"frame\":0,\"blocks\":[5]}\n",
    )
    .unwrap();
    let stderr = user_error(
        tessera()
            .arg("simulate")
            .arg(&trace)
            .args(["--peers", "1,2", "--tiles", "1,4", "--out"])
            .arg(dir.path()),
    );
    assert!(stderr.contains("at most 65536 pixels a side"), "{stderr}");
    let stderr = user_error(
        tessera()
            .args([
                "simulate",
                "synthetic:100000x100000:1",
                "--peers",
                "2",
                "--out",
            ])
            .arg(dir.path()),
    );
    assert!(stderr.contains("at most 65536 pixels a side"), "{stderr}");

    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let stderr = usage_error(
        tessera()
            .arg("bench")
            .arg(&scene)
            .args(["--steal-rtt", "4294967296"]),
    );
    assert!(stderr.contains("for '--steal-rtt"), "{stderr}");
    let stderr = user_error(tessera().arg("bench").arg(&scene).args([
        "--width",
        "100000000",
        "--height",
        "100000000",
        "--spp",
        "1",
    ]));
    assert!(
        stderr.contains("--width 100000000 --height 100000000") && stderr.contains("MiB free"),
        "{stderr}"
    );
    let stderr = user_error(
        tessera()
            .args(["keygen", "--peers", "100000000", "--out"])
            .arg(dir.path().join("keys")),
    );
    assert!(stderr.contains("--peers 100000000"), "{stderr}");
    assert!(started.elapsed() < std::time::Duration::from_secs(60));
}

/// A regular grid is k x k tiles: on an image smaller than the default grid it renders with a
/// grid that fits (it failed, naming neither flag), and a `--tiles` that cannot fit is refused
/// by name.
#[test]
fn a_regular_grid_fits_small_images_or_names_the_tiles_flag() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let small = [
        "--width",
        "16",
        "--height",
        "12",
        "--spp",
        "1",
        "--peers",
        "1",
        "--balancer",
        "regular",
    ];
    let status = tessera()
        .arg("render")
        .arg(&scene)
        .args(small)
        .arg("--out")
        .arg(dir.path())
        .status()
        .unwrap();
    assert!(status.success() && dir.path().join("frame-0000.exr").exists());
    let stderr = user_error(
        tessera()
            .arg("render")
            .arg(&scene)
            .args(small)
            .args(["--tiles", "192", "--out"])
            .arg(dir.path().join("other")),
    );
    assert!(stderr.contains("--tiles 192"), "{stderr}");
}

/// Where results cannot be written, the command says so before it works, naming the flag: a
/// simulated study, a validation and a render whose `--out` is a file (they failed only once
/// their work was done, losing it). And a scene file named to `bench` that does not exist is an
/// error, not a scene skipped as those of an absent `../shared` are.
#[test]
fn an_unwritable_out_and_a_missing_bench_scene_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "not a folder").unwrap();
    let scene = common::repo("scenes/point-in-sphere/point-in-sphere.toml");
    let stats = dir.path().join("no-stats.json");
    let commands: [Vec<std::ffi::OsString>; 3] = [
        common::SMALL_SIMULATION.map(Into::into).to_vec(),
        vec![
            "simulate".into(),
            "synthetic:16x12:2".into(),
            "--validate".into(),
            stats.clone().into(),
        ],
        vec![
            "render".into(),
            scene.clone().into(),
            "--width".into(),
            "8".into(),
            "--height".into(),
            "8".into(),
        ],
    ];
    for (command, shown) in commands.iter().zip(["simulate", "validate", "render"]) {
        for out in [file.clone(), file.join("below")] {
            let stderr = user_error(tessera().args(command).arg("--out").arg(&out));
            assert!(
                stderr.contains(&format!("--out {}", out.display())),
                "{shown}: {stderr}"
            );
        }
    }
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "not a folder");

    let missing = dir.path().join("missing.toml");
    let stderr = user_error(tessera().arg("bench").arg(&missing).args(["--spp", "1"]));
    assert!(stderr.contains("missing.toml"), "{stderr}");
}
