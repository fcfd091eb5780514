//! `tessera slurm` as srun would run it: one process per task, each told its place by the
//! SLURM_* variables srun sets, here scripted, on loopback. No SLURM is needed; what is tested
//! is everything after srun has started the tasks, on any machine. `tests/slurm_real.rs` runs
//! the same command under a real srun where SLURM can be set up.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use common::{frames, keygen, render_alone, repo, spawn_reading, tessera, wait_for, wait_success};
use runtime::slurm::default_port;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const SCENE: &str = "scenes/glass-cluster-pan/glass-cluster-pan.toml";
const SIZE: [&str; 8] = [
    "--width", "96", "--height", "80", "--spp", "8", "--frames", "6",
];

/// The step's node list: task 0's node first (the block layout), then two that are never dialed.
const NODES: &str = "localhost,node-b[1-2]";

/// A job id whose derived port for step 0 (the tasks set no SLURM_STEP_ID) is free for UDP
/// right now; the job ids tried start at one that depends on this process, so that two test
/// runs at once rarely try the same.
fn job_with_free_port() -> u64 {
    // Tests of this binary run at once: each call starts its search further on, so that two
    // tests never both find the same port free before either binds it.
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let start = 1_000_000 + (std::process::id() as u64 + 97 * call) % 2000;
    (start..start + 2000)
        .find(|&job| std::net::UdpSocket::bind(("0.0.0.0", default_port(job, 0))).is_ok())
        .expect("some port of step 0 in 20000..40000 is free")
}

/// `tessera slurm` as task `rank` of a `tasks`-task step of job `job`, with every SLURM
/// variable of the machine running the tests removed first.
fn task(certs: &Path, out: &Path, job: u64, rank: u32, tasks: u32) -> Command {
    let mut command = slurm_command();
    command
        .arg(repo(SCENE))
        .args(SIZE)
        .args(["--threads", "1", "--tiles", "64", "--certs"])
        .arg(certs)
        .arg("--out")
        .arg(out)
        .envs([
            ("SLURM_JOB_ID", job.to_string()),
            ("SLURM_PROCID", rank.to_string()),
            ("SLURM_STEP_NUM_TASKS", tasks.to_string()),
            ("SLURM_STEP_NODELIST", NODES.to_string()),
            ("SLURMD_NODENAME", "localhost".to_string()),
        ])
        .env("NO_COLOR", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    command
}

fn slurm_command() -> Command {
    let mut command = tessera();
    command.arg("slurm");
    for (name, _) in std::env::vars_os() {
        if name.to_string_lossy().starts_with("SLURM") {
            command.env_remove(name);
        }
    }
    command
}

fn failure(command: &mut Command) -> String {
    let Output { status, stderr, .. } = command.stderr(Stdio::piped()).output().unwrap();
    assert!(!status.success(), "{command:?} succeeded");
    String::from_utf8_lossy(&stderr).into_owned()
}

/// Three tasks, ranks 0..3, the peers started first: they knock until the owner listens (as
/// when task 0 is slow to load its scene), then all three render, and the frames are the
/// bytes one peer alone renders.
#[test]
fn a_three_task_step_renders_what_one_peer_renders() {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    keygen(&certs, 3);
    let job = job_with_free_port();
    let out = dir.path().join("step");
    let (first, lines) = spawn_reading(&mut task(&certs, &out, job, 1, 3));
    let second = task(&certs, &out, job, 2, 3).spawn().unwrap();
    // The first try of a peer gives up after the transport's 10 s handshake timeout.
    assert!(
        wait_for(&lines, "trying again", Duration::from_secs(40)),
        "a peer that found nobody listening did not try again"
    );
    let owner = task(&certs, &out, job, 0, 3).spawn().unwrap();
    wait_success(owner, "task 0", Duration::from_secs(180));
    wait_success(first, "task 1", Duration::from_secs(30));
    wait_success(second, "task 2", Duration::from_secs(30));

    let reference = dir.path().join("reference");
    render_alone(SCENE, &SIZE, &reference);
    let (got, expected) = (frames(&out), frames(&reference));
    assert_eq!(got.len(), 6);
    assert_eq!(got.len(), expected.len());
    for ((name, a), (_, b)) in got.iter().zip(&expected) {
        assert!(a == b, "{name} differs from the one-peer render");
    }
    // It was a cluster of three: every task rendered tiles.
    let stats = common::stats(&out);
    let tiles: Vec<&serde_json::Value> = stats["frames"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|frame| frame["tiles"].as_array().unwrap())
        .collect();
    for peer in 0..3 {
        assert!(
            tiles.iter().any(|tile| tile["peer"] == peer),
            "task {peer} rendered no tile"
        );
    }
}

/// `--expect 1` on a three-task step: task 0 starts with task 1 alone, and the render completes
/// without task 2, which never comes. An `--expect` above the step's other tasks is refused,
/// naming the flag.
#[test]
fn with_expect_task_zero_starts_without_the_tasks_that_never_come() {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    keygen(&certs, 3);
    let job = job_with_free_port();
    let out = dir.path().join("step");
    let first = task(&certs, &out, job, 1, 3).spawn().unwrap();
    let owner = task(&certs, &out, job, 0, 3)
        .args(["--expect", "1"])
        .spawn()
        .unwrap();
    wait_success(owner, "task 0", Duration::from_secs(180));
    wait_success(first, "task 1", Duration::from_secs(30));
    assert_eq!(frames(&out).len(), 6);
    let message = failure(task(&certs, &out, job, 0, 3).args(["--expect", "3"]));
    assert!(
        message.contains("--expect 3") && message.contains("only 2 tasks"),
        "{message}"
    );
}

/// Outside SLURM it says what is missing and renders nothing.
#[test]
fn outside_slurm_it_refuses_naming_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let message = failure(
        slurm_command()
            .arg(repo(SCENE))
            .arg("--certs")
            .arg(dir.path())
            .arg("--out")
            .arg(&out),
    );
    for name in [
        "SLURM_PROCID",
        "SLURM_STEP_NUM_TASKS",
        "SLURM_STEP_NODELIST",
        "srun",
    ] {
        assert!(message.contains(name), "{message}");
    }
    assert!(!out.exists(), "it created {}", out.display());
}

/// Task 0 on a node that is not the step's first refuses, naming both nodes, instead of
/// leaving its peers to dial where nobody listens.
#[test]
fn task_zero_on_the_wrong_node_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let message = failure(
        task(dir.path(), &out, 7, 0, 3)
            .env("SLURM_STEP_NODELIST", "n[1-3]")
            .env("SLURMD_NODENAME", "n2"),
    );
    assert!(
        message.contains("n2") && message.contains("n1") && message.contains("--owner"),
        "{message}"
    );
    assert!(!out.exists());
}

/// A task whose certificate the job's folder lacks (keygen made too few) fails at once,
/// naming it, rather than waiting for the owner.
#[test]
fn a_task_without_its_certificate_fails_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    keygen(&certs, 2);
    let started = Instant::now();
    let message = failure(&mut task(&certs, &dir.path().join("out"), 7, 2, 3));
    assert!(message.contains("peer 2's certificate"), "{message}");
    assert!(started.elapsed() < Duration::from_secs(5));
}

/// A malformed node list is refused with the variable and what is wrong with it.
#[test]
fn a_malformed_node_list_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let message = failure(
        task(dir.path(), &dir.path().join("out"), 7, 1, 3).env("SLURM_STEP_NODELIST", "n[1-3"),
    );
    assert!(
        message.contains("SLURM_STEP_NODELIST") && message.contains("never closed"),
        "{message}"
    );
}
