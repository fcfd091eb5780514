//! Helpers shared by the end-to-end tests: run the real binary, read its EXR output; `slurm`
//! starts a real SLURM cluster on this machine.

#![allow(dead_code, clippy::unwrap_used)]

pub mod slurm;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

pub fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// Runs the command and returns its output, failing the test with stderr if it failed.
pub fn run_ok(command: &mut Command) -> Output {
    let output = command.output().expect("the tessera binary runs");
    assert!(
        output.status.success(),
        "{command:?} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// The bytes of every `frame-NNNN.exr` in `dir`, in frame order.
/// Renders `scene` with `size` flags on one peer and one thread into `out`, 64 tiles: the
/// reference every distributed render of these tests is compared with, bit for bit.
pub fn render_alone(scene: &str, size: &[&str], out: &Path) {
    run_ok(
        tessera()
            .arg("render")
            .arg(repo(scene))
            .args(size)
            .args(["--peers", "1", "--threads", "1", "--tiles", "64", "--out"])
            .arg(out),
    );
}

pub fn frames(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("frame-") && n.ends_with(".exr"))
        .collect();
    names.sort();
    names
        .into_iter()
        .map(|n| {
            let bytes = std::fs::read(dir.join(&n)).unwrap();
            (n, bytes)
        })
        .collect()
}

/// Every pixel of an EXR file as linear RGB.
pub fn pixels(path: &Path) -> Vec<[f32; 3]> {
    tracer::output::read_exr(path)
        .expect("our EXR files read back")
        .pixels
}

/// `../shared/scenes` beside the repository, if present.
pub fn shared_scenes() -> Option<PathBuf> {
    let dir = repo("../shared/scenes");
    dir.is_dir().then_some(dir)
}

/// A free UDP port on 127.0.0.1 (released before use; tests run few enough servers for this).
pub fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A cluster CA and certificates for `peers` peers in `dir` (`tessera keygen`).
pub fn keygen(dir: &Path, peers: u32) {
    run_ok(
        tessera()
            .args(["keygen", "--peers", &peers.to_string(), "--out"])
            .arg(dir),
    );
}

/// Spawns `command` with its stderr lines sent to the returned channel.
pub fn spawn_reading(command: &mut Command) -> (Child, mpsc::Receiver<String>) {
    let mut child = command.stderr(Stdio::piped()).spawn().unwrap();
    let (lines, receiver) = mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    (child, receiver)
}

/// Waits for a line containing `needle`, up to `timeout`.
pub fn wait_for(lines: &mpsc::Receiver<String>, needle: &str, timeout: Duration) -> bool {
    let deadline = Instant::now() + timeout;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match lines.recv_timeout(left) {
            Ok(line) if line.contains(needle) => return true,
            Ok(_) => {}
            Err(_) => return false,
        }
    }
    false
}

/// Sends process `pid` the signal `name` (`-STOP`, `-CONT`, `-TERM`, `-KILL`) with kill(1):
/// for processes started elsewhere too (srun's tasks), which `Child::kill` cannot reach.
pub fn signal(pid: u32, name: &str) {
    let status = Command::new("kill")
        .args([name, &pid.to_string()])
        .status()
        .unwrap();
    assert!(status.success(), "kill {name} {pid} failed");
}

/// Waits for `child` (called `what` in failures) to exit successfully within `timeout`.
pub fn wait_success(mut child: Child, what: &str, timeout: Duration) {
    let status = wait_exit(&mut child, what, timeout);
    assert!(status.success(), "{what} failed: {status}");
}

/// Waits for `child` (called `what` in failures) to exit within `timeout`, and says how it did.
pub fn wait_exit(child: &mut Child, what: &str, timeout: Duration) -> ExitStatus {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if Instant::now() > deadline {
            child.kill().ok();
            panic!("{what} did not finish within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The owner's stats.json in `out`, parsed.
pub fn stats(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("stats.json")).unwrap()).unwrap()
}

/// How many tiles peer `peer` rendered in each frame, from the owner's stats.json.
pub fn tiles_of(out: &Path, peer: u64) -> Vec<usize> {
    let stats = stats(out);
    stats["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|frame| {
            frame["tiles"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|tile| tile["peer"] == peer)
                .count()
        })
        .collect()
}

/// A small simulation's command line: a synthetic trace on 2 peers and 4 tiles.
pub const SMALL_SIMULATION: [&str; 6] = [
    "simulate",
    "synthetic:16x12:2",
    "--peers",
    "2",
    "--tiles",
    "4",
];

/// `tessera simulate` of [`SMALL_SIMULATION`] with `flags`, writing into `out`.
pub fn small_simulation(out: &std::path::Path, flags: &[&str]) -> std::process::Command {
    let mut command = tessera();
    command
        .args(SMALL_SIMULATION)
        .args(flags)
        .arg("--out")
        .arg(out);
    command
}
