//! `--resume` as users meet it: a render killed mid-animation (SIGKILL, no chance to tidy up) is
//! run again with `--resume`; it keeps the frames already written, renders the rest, and every
//! frame is bit for bit what an uninterrupted render writes. With other settings, `--resume`
//! re-renders from frame 0.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use common::{
    frames, free_port, keygen, repo, run_ok, spawn_reading, tessera, wait_for, wait_success,
};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, SystemTime};

const SCENE: &str = "scenes/glass-cluster-pan/glass-cluster-pan.toml";
const FRAMES: usize = 12;
/// The image; `--spp` and `--frames` are each call's, since the last render changes them.
const SIZE: [&str; 4] = ["--width", "64", "--height", "48"];

fn render(out: &Path, extra: &[&str]) -> Command {
    let mut command = tessera();
    command
        .arg("render")
        .arg(repo(SCENE))
        .args(SIZE)
        .args(["--threads", "2", "--out"])
        .arg(out)
        .args(extra)
        .env("NO_COLOR", "1");
    command
}

fn modified(path: &Path) -> SystemTime {
    std::fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn a_killed_render_resumes_from_its_first_missing_frame_with_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let reference_dir = dir.path().join("reference");
    run_ok(&mut render(
        &reference_dir,
        &["--spp", "8", "--frames", "12", "--peers", "1"],
    ));
    let reference = frames(&reference_dir);
    assert_eq!(reference.len(), FRAMES);

    // Killed once two frames are written: the owner gets no chance to finish anything.
    let out = dir.path().join("out");
    let (mut child, lines) = spawn_reading(
        render(&out, &["--spp", "8", "--frames", "12", "--peers", "2"]).stdout(Stdio::null()),
    );
    assert!(
        wait_for(&lines, "frame 1 done", Duration::from_secs(120)),
        "the render never finished frame 1"
    );
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let written = frames(&out).len();
    assert!(
        (2..FRAMES).contains(&written),
        "{written} frames were written before the kill; the test needs some but not all"
    );
    // What a writer killed midway leaves (the kill may or may not have hit one).
    std::fs::write(out.join("frame-0011.exr.partial"), b"half a frame").unwrap();
    let kept: Vec<SystemTime> = (0..written)
        .map(|f| modified(&out.join(format!("frame-{f:04}.exr"))))
        .collect();

    let resumed = run_ok(&mut render(
        &out,
        &["--spp", "8", "--frames", "12", "--peers", "2", "--resume"],
    ));
    let log = String::from_utf8_lossy(&resumed.stderr);
    let expected = format!("rendering frames {written}-{}", FRAMES - 1);
    assert!(log.contains(&expected), "no {expected:?} in:\n{log}");
    for (f, time) in kept.iter().enumerate() {
        let path = out.join(format!("frame-{f:04}.exr"));
        assert_eq!(modified(&path), *time, "frame {f} was written again");
    }
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().ends_with(".partial"))
        .collect();
    assert!(leftovers.is_empty(), "left half-written: {leftovers:?}");
    let got = frames(&out);
    assert_eq!(got.len(), reference.len());
    for ((name, a), (_, b)) in got.iter().zip(&reference) {
        assert!(a == b, "{name} differs from the uninterrupted render");
    }
    let stats = common::stats(&out);
    assert_eq!(stats["first_frame"], written);
    assert_eq!(stats["frames"][0]["frame"], written);
    assert_eq!(stats["render_hash"].as_str().map(str::len), Some(64));

    // Other settings: nothing is done, so it renders from frame 0 (two frames here, to be quick).
    let before = std::fs::read(out.join("frame-0000.exr")).unwrap();
    let changed = run_ok(&mut render(
        &out,
        &["--spp", "4", "--peers", "1", "--resume", "--frames", "2"],
    ));
    let log = String::from_utf8_lossy(&changed.stderr);
    assert!(
        log.contains("frame-0000.exr is of other scene files or settings")
            && log.contains("rendering frames 0-1"),
        "{log}"
    );
    assert!(std::fs::read(out.join("frame-0000.exr")).unwrap() != before);
}

/// One long frame, checkpointed every 0.3 s, killed (SIGKILL) once a checkpoint is on disk and
/// before the frame is: `--resume` goes on from the checkpoint (it says what it kept), the frame
/// is bit for bit the uninterrupted render's, and the checkpoint is gone once the render is
/// done. A checkpoint of other settings is not used.
#[test]
fn a_render_killed_within_a_long_frame_resumes_from_its_checkpoint_with_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let long_at = |spp: &str, out: &Path, extra: &[&str]| {
        let mut command = tessera();
        command
            .arg("render")
            .arg(repo(SCENE))
            .args([
                "--width", "96", "--height", "80", "--spp", spp, "--frames", "1",
            ])
            .args([
                "--tiles",
                "64",
                "--threads",
                "2",
                "--checkpoint-every",
                "0.3",
            ])
            .arg("--out")
            .arg(out)
            .args(extra)
            .env("NO_COLOR", "1");
        command
    };
    let long = |out: &Path, extra: &[&str]| long_at("384", out, extra);
    let reference_dir = dir.path().join("reference");
    run_ok(&mut long(&reference_dir, &["--peers", "1"]));
    let reference = frames(&reference_dir);
    assert!(
        !reference_dir.join("checkpoint.bin").exists(),
        "a finished render left its checkpoint"
    );

    let out = dir.path().join("out");
    let checkpoint = out.join("checkpoint.bin");
    let mut child = long(&out, &["--peers", "2"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(120);
    while !checkpoint.is_file() {
        assert!(std::time::Instant::now() < deadline, "no checkpoint came");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the render ended first"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(
        frames(&out).is_empty(),
        "the frame was done before the kill: the test needs a frame in progress"
    );
    let kept = std::fs::read(&checkpoint).unwrap();

    let resumed = run_ok(&mut long(&out, &["--peers", "2", "--resume"]));
    let log = String::from_utf8_lossy(&resumed.stderr);
    let line = log
        .lines()
        .find(|l| l.contains("goes on from its checkpoint"))
        .unwrap_or_else(|| panic!("the checkpoint was not used:\n{log}"));
    let results: usize = line
        .split("checkpoint: ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!(results > 0, "{line}");
    let got = frames(&out);
    assert_eq!(got.len(), 1);
    assert!(got[0].1 == reference[0].1, "the resumed frame differs");
    assert!(
        !checkpoint.exists(),
        "the finished render left its checkpoint"
    );

    // The same checkpoint, resumed with other settings, is of another render: not used.
    std::fs::write(&checkpoint, kept).unwrap();
    let other = run_ok(&mut long_at("8", &out, &["--peers", "1", "--resume"]));
    let log = String::from_utf8_lossy(&other.stderr);
    assert!(
        log.contains("is of frame 0 or of other settings") && !log.contains("goes on from"),
        "{log}"
    );
}

#[test]
fn resume_and_trace_together_are_refused_naming_both_flags() {
    let dir = tempfile::tempdir().unwrap();
    let output = render(
        dir.path(),
        &[
            "--resume",
            "--trace",
            &dir.path().join("t").display().to_string(),
        ],
    )
    .output()
    .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("--trace cannot be combined with --resume"),
        "{stderr}"
    );
}

/// `serve --resume` with a peer process: it deals only the frames missing (a longer `--frames`
/// here), and when none is missing its peer is sent home and both exit with success.
#[test]
fn a_served_render_resumes_and_one_with_nothing_left_ends_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let reference_dir = dir.path().join("reference");
    run_ok(&mut render(
        &reference_dir,
        &["--spp", "4", "--frames", "5", "--peers", "1"],
    ));
    let out = dir.path().join("out");
    run_ok(&mut render(
        &out,
        &["--spp", "4", "--frames", "3", "--peers", "1"],
    ));
    let certs = dir.path().join("certs");
    keygen(&certs, 2);
    let serve_resumed = |expect_line: &str| {
        let port = free_port();
        let mut command = tessera();
        command
            .arg("serve")
            .arg(repo(SCENE))
            .args(SIZE)
            .args(["--spp", "4", "--frames", "5", "--resume", "--threads", "1"])
            .args(["--listen", &format!("127.0.0.1:{port}"), "--expect", "1"])
            .arg("--certs")
            .arg(&certs)
            .arg("--out")
            .arg(&out)
            .env("NO_COLOR", "1")
            .stdout(Stdio::null());
        let (server, lines) = spawn_reading(&mut command);
        let peer = tessera()
            .args(["peer", "--join", &format!("127.0.0.1:{port}")])
            .args(["--listen", "127.0.0.1:0", "--threads", "1", "--index", "1"])
            .arg("--certs")
            .arg(&certs)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        assert!(
            wait_for(&lines, expect_line, Duration::from_secs(60)),
            "serve never said {expect_line:?}"
        );
        wait_success(server, "serve", Duration::from_secs(120));
        wait_success(peer, "peer 1", Duration::from_secs(30));
    };
    serve_resumed("rendering frames 3-4");
    let got = frames(&out);
    let expected = frames(&reference_dir);
    assert_eq!(got.len(), 5);
    for ((name, a), (_, b)) in got.iter().zip(&expected) {
        assert!(a == b, "{name} differs from the uninterrupted render");
    }
    let stats = std::fs::read(out.join("stats.json")).unwrap();
    serve_resumed("all 5 frames are done; nothing to render");
    assert_eq!(frames(&out), got);
    assert!(
        std::fs::read(out.join("stats.json")).unwrap() == stats,
        "a render with nothing left rewrote stats.json"
    );
}
