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
