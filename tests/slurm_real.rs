//! `tessera slurm` under a real SLURM: steps of three tasks on a one-machine cluster of three
//! nodes (`scripts/slurm_cluster.sh`, started by `common::slurm`), every frame compared bit for
//! bit with a one-peer render. `tests/slurm.rs` scripts SLURM's variables to test what each task
//! concludes from them; here SLURM itself sets them, places the tasks, and kills them.
//!
//! Each test skips, saying why, where no cluster can be set up, and fails instead in CI.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use common::slurm::Cluster;
use common::{frames, keygen, render_alone, repo, spawn_reading, tiles_of};
use runtime::slurm::{Env, Overrides, Role, Step, default_port};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{OnceLock, mpsc};
use std::time::{Duration, Instant};

/// The jobs, steps and tasks the tests drive, and the frames they compare with.
#[path = "slurm_real/steps.rs"]
mod steps;

use steps::*;

const SCENE: &str = "scenes/glass-cluster-pan/glass-cluster-pan.toml";
/// Frames of a few tenths of a second on three tasks: a task killed once frame 0 is done dies
/// in the middle of frame 1, not after the render, and a whole step still takes seconds.
const SIZE: [&str; 8] = [
    "--width", "96", "--height", "80", "--spp", "32", "--frames", "6",
];
const FRAMES: usize = 6;
/// Frames of about a second on two or three tasks: a peer started by a second `srun` once
/// frame 0 is done (which takes a second or two) joins with most of the render still to come.
const SLOW: [&str; 8] = [
    "--width", "96", "--height", "80", "--spp", "128", "--frames", "6",
];
/// srun as docs/cluster.md launches it: a task that dies neither takes the step down
/// (`--kill-on-bad-exit=0`) nor starts a clock on the others (`--wait=0`).
const SRUN: [&str; 4] = ["-N3", "-n3", "--kill-on-bad-exit=0", "--wait=0"];
/// How long a whole step may take before the test gives up on it.
const STEP_TIMEOUT: Duration = Duration::from_secs(120);

/// A plain step: SLURM puts one task on each node, task 0 on the first, and the frames are the
/// bytes one peer alone renders.
#[test]
fn a_three_node_step_renders_what_one_peer_renders() {
    let Some(cluster) = Cluster::start_or_skip("a_three_node_step_renders_what_one_peer_renders")
    else {
        return;
    };
    let job = Job::new(&cluster);
    let out = cluster.dir().join("plain");
    let (status, log) = finish(spawn(job.srun(&SRUN, &out, "")));
    assert!(status.success(), "srun failed: {status}\n{log}");
    assert_frames_match_reference(&out);
    let tasks: Vec<Task> = (0..3).map(|rank| job.task(0, rank)).collect();
    let nodes: Vec<&str> = tasks.iter().map(|t| t.node.as_str()).collect();
    assert_eq!(nodes, ["n1", "n2", "n3"], "srun's block layout");
    assert_eq!(tasks[0].job, cluster.first_job());
    let port = default_port(tasks[0].job, 0);
    assert!(
        log.contains(&format!("owning the frames on n1, port {port}"))
            && log.contains(&format!("joining n1 (127.0.0.1:{port})")),
        "{log}"
    );
    for peer in 0..3 {
        assert!(
            tiles_of(&out, peer).iter().any(|&n| n > 0),
            "task {peer} rendered no tile"
        );
    }
}

/// Task 2 killed with SIGKILL in the middle of frame 1: the owner gives its tiles to the
/// others, the step goes on without it, and every frame is still the one-peer render's.
#[test]
fn a_task_killed_mid_frame_costs_time_not_frames() {
    let Some(cluster) = Cluster::start_or_skip("a_task_killed_mid_frame_costs_time_not_frames")
    else {
        return;
    };
    let job = Job::new(&cluster);
    let out = cluster.dir().join("killed");
    let (child, lines) = spawn(job.srun_sized(&SRUN, &out, "", &SLOW));
    assert!(
        wait_for_frame(&out, 0, &lines),
        "the step never finished frame 0"
    );
    job.task(0, 2).kill();
    let (status, log) = finish((child, lines));
    // srun reports the lost task, and only that one.
    assert!(!status.success(), "srun hid the killed task\n{log}");
    assert!(log.contains("task 2: Killed"), "{log}");
    assert!(
        !log.contains("task 0:") && !log.contains("task 1:"),
        "{log}"
    );
    assert!(log.contains(&format!("rendered {FRAMES} frames")), "{log}");
    assert_frames_match(&out, reference_slow().to_vec());
    let tiles = tiles_of(&out, 2);
    assert!(
        tiles[0] > 0,
        "task 2 rendered nothing before it died: {tiles:?}"
    );
    assert_eq!(
        tiles[FRAMES - 1],
        0,
        "task 2 rendered after it was killed: {tiles:?}"
    );
}

/// What docs/cluster.md warns of: with `srun -K` (`--kill-on-bad-exit`) one task killed
/// ends the whole step, the owner with it, and the render stops short.
#[test]
fn with_kill_on_bad_exit_one_killed_task_ends_the_step() {
    let Some(cluster) =
        Cluster::start_or_skip("with_kill_on_bad_exit_one_killed_task_ends_the_step")
    else {
        return;
    };
    let job = Job::new(&cluster);
    let out = cluster.dir().join("kill-on-bad-exit");
    let on_bad_exit = ["-N3", "-n3", "--kill-on-bad-exit=1"];
    let (child, lines) = spawn(job.srun_sized(&on_bad_exit, &out, "", &SLOW));
    assert!(
        wait_for_frame(&out, 0, &lines),
        "the step never finished frame 0"
    );
    job.task(0, 2).kill();
    let (status, log) = finish((child, lines));
    assert!(!status.success(), "{log}");
    assert!(
        log.contains("task 0: Terminated") || log.contains("task 0: Killed"),
        "srun did not end the owner\n{log}"
    );
    let written = frames(&out).len();
    assert!(
        written < FRAMES,
        "the owner wrote all {written} frames: srun did not end the step"
    );
}

/// A task that starts three seconds after the others (a slow node) is waited for: the owner
/// starts frame 0 only once every task of the step has joined, so task 2 renders in it.
///
/// A task that comes only after the render started is `a_peer_joining_a_running_step_...`.
#[test]
fn a_task_that_starts_late_is_waited_for() {
    let Some(cluster) = Cluster::start_or_skip("a_task_that_starts_late_is_waited_for") else {
        return;
    };
    let job = Job::new(&cluster);
    let out = cluster.dir().join("late");
    let started = Instant::now();
    let late = r#"[ "$SLURM_PROCID" != 2 ] || sleep 3"#;
    let (status, log) = finish(spawn(job.srun(&SRUN, &out, late)));
    assert!(status.success(), "srun failed: {status}\n{log}");
    assert!(started.elapsed() >= Duration::from_secs(3));
    assert_frames_match_reference(&out);
    assert!(tiles_of(&out, 2)[0] > 0, "frame 0 started without task 2");
}

/// Elastic membership under SLURM: a step of two tasks renders; once frame 0 is done, a job
/// of its own puts a third peer on node n3 (`tessera peer --join`, as a later allocation
/// would), which joins the running render, renders in the frames after, and changes no pixel.
///
/// The late job is allocated while frame 0 renders and its task waits for the owner's address,
/// which the test writes once frame 0 is on disk: a join then takes a process start and a
/// handshake, not an allocation, which under a loaded CI took longer than the five frames left
/// (seen once: the render over before the peer came).
#[test]
fn a_peer_joining_a_running_step_takes_part_and_changes_no_pixel() {
    let Some(cluster) =
        Cluster::start_or_skip("a_peer_joining_a_running_step_takes_part_and_changes_no_pixel")
    else {
        return;
    };
    let job = Job::new(&cluster);
    let out = cluster.dir().join("joined");
    // n3 is kept for the late job, so that neither allocation waits on the other.
    let two = ["-N2", "-n2", "-x", "n3", "--kill-on-bad-exit=0", "--wait=0"];
    let (child, lines) = spawn(job.srun_sized(&two, &out, "", &SLOW));
    // The step's job first, as in use, and as the cluster checked its first job's ports.
    assert!(wait_for_task(&job, 0, &lines), "the step never started");
    let address = cluster.dir().join("owner-address");
    let wait_then_join = format!(
        r#"while [ ! -e "{0}" ]; do sleep 0.01; done; exec "$0" peer --join "$(cat "{0}")" "$@""#,
        address.display()
    );
    let mut late = cluster.command("srun");
    late.args(["-N1", "-n1", "-w", "n3", "sh", "-c", &wait_then_join])
        .arg(env!("CARGO_BIN_EXE_tessera"))
        .args(["--index", "2", "--threads", "1", "--certs"])
        .arg(&job.certs)
        .env("NO_COLOR", "1");
    let late = spawn(late);
    assert!(
        wait_for_frame(&out, 0, &lines),
        "the step never finished frame 0"
    );
    let port = default_port(job.task(0, 0).job, 0);
    // Written whole, then renamed, so the waiting task never reads half an address.
    let partial = address.with_extension("partial");
    std::fs::write(&partial, format!("127.0.0.1:{port}")).unwrap();
    std::fs::rename(&partial, &address).unwrap();
    let (status, log) = finish((child, lines));
    assert!(status.success(), "the first step failed: {status}\n{log}");
    let (late_status, late_log) = finish(late);
    assert!(
        late_status.success(),
        "the late peer failed: {late_status}\n{late_log}"
    );
    assert!(log.contains("peer joined the render"), "{log}");
    assert_frames_match(&out, reference_slow().to_vec());
    let tiles = tiles_of(&out, 2);
    assert_eq!(tiles[0], 0, "the late peer rendered in frame 0");
    // Taking part is rendering in some frame after it joined. Not necessarily the last: under
    // the full suite's load a one-thread peer measured slow may be predicted less than a tile
    // there and find nothing left to steal (seen once in CI: tiles [0, 6, 24, 2, 0, 0]).
    assert!(
        tiles[1..].iter().sum::<usize>() > 0,
        "the late peer took no part: {tiles:?}"
    );
}

/// Task 2 sent SIGTERM in frame 1, as SLURM preempts a task or ends a time limit: it hands back
/// what it has not started and exits 0; the owner re-issues that at once (no silence
/// timeout), srun reports no failed task, and every frame is the one-peer render's.
#[test]
fn a_task_sent_sigterm_hands_back_its_work_and_the_step_succeeds() {
    let Some(cluster) =
        Cluster::start_or_skip("a_task_sent_sigterm_hands_back_its_work_and_the_step_succeeds")
    else {
        return;
    };
    let job = Job::new(&cluster);
    let out = cluster.dir().join("terminated");
    let (child, lines) = spawn(job.srun_sized(&SRUN, &out, "", &SLOW));
    assert!(
        wait_for_frame(&out, 0, &lines),
        "the step never finished frame 0"
    );
    job.task(0, 2).signal("-TERM");
    let (status, log) = finish((child, lines));
    assert!(status.success(), "srun failed: {status}\n{log}");
    assert!(log.contains("left the render when asked"), "{log}");
    assert!(log.contains("peer leaving the render"), "{log}");
    assert!(!log.contains("peer failed"), "{log}");
    assert_frames_match(&out, reference_slow().to_vec());
    let tiles = tiles_of(&out, 2);
    assert!(tiles[0] > 0, "task 2 rendered nothing before it left");
    assert_eq!(tiles[FRAMES - 1], 0, "task 2 rendered after it left");
}

/// The sbatch example of docs/cluster.md, as written there, submitted with `sbatch --wait`
/// (the command line sizes it for this cluster: three nodes, one CPU a task; it overrides the
/// script's `#SBATCH` lines): certificates made for the job, the shipped scene rendered at its
/// own settings by three tasks, and the certificates gone when the job ends.
#[test]
fn the_sbatch_example_of_the_cluster_guide_renders() {
    let Some(cluster) = Cluster::start_or_skip("the_sbatch_example_of_the_cluster_guide_renders")
    else {
        return;
    };
    let guide = std::fs::read_to_string(repo("docs/cluster.md")).unwrap();
    let start = guide
        .find("```sh\n#!/bin/bash")
        .expect("docs/cluster.md has an sbatch example")
        + "```sh\n".len();
    let script = &guide[start..start + guide[start..].find("```").unwrap()];
    let dir = cluster.dir().join("sbatch");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("render.sbatch");
    std::fs::write(&path, script).unwrap();
    let tessera = Path::new(env!("CARGO_BIN_EXE_tessera"));
    let search = format!(
        "{}:{}",
        tessera.parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut sbatch = cluster.command("sbatch");
    sbatch
        .args(["--wait", "-N3", "-n3", "-c1", "-o"])
        .arg(dir.join("job-%j.log"))
        .arg("--chdir")
        .arg(repo(""))
        .arg(&path)
        .current_dir(&dir)
        .env("PATH", search)
        .env("NO_COLOR", "1");
    let (status, log) = finish(spawn(sbatch));
    let job_log: String = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("job-"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
        .collect();
    assert!(
        status.success(),
        "sbatch failed: {status}\n{log}\n{job_log}"
    );
    let folders: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("tessera-")
        })
        .collect();
    let [folder] = &folders[..] else {
        panic!("expected one tessera-JOBID folder: {folders:?}\n{job_log}");
    };
    assert_eq!(frames(&folder.join("out")).len(), 24, "{job_log}");
    assert!(
        !folder.join("certs").exists(),
        "the job left its keys behind"
    );
    for peer in 0..3 {
        let tiles = tiles_of(&folder.join("out"), peer);
        assert!(
            tiles.iter().sum::<usize>() > 0,
            "task {peer} rendered nothing\n{job_log}"
        );
    }
}

/// Two steps of one job at once (`srun ... & srun ... & wait` in an allocation) listen on
/// ports of their own, derived from the job and step ids, and both render the right frames.
/// With a port from the job id alone the second owner could not bind it.
#[test]
fn two_steps_of_one_job_at_once_get_ports_of_their_own() {
    let Some(cluster) =
        Cluster::start_or_skip("two_steps_of_one_job_at_once_get_ports_of_their_own")
    else {
        return;
    };
    let job = Job::new(&cluster);
    let outs = [cluster.dir().join("step-0"), cluster.dir().join("step-1")];
    // `--exact`: each step takes only the CPU per task it asks for, so both fit at once in
    // an allocation of two CPUs on each node.
    let steps: Vec<String> = outs
        .iter()
        .map(|out| shell_line(&job.srun(&["--exact", "-N3", "-n3"], out, "")))
        .collect();
    let script = cluster.dir().join("two-steps.sh");
    // The script fails if either step does (a bare `wait` would succeed whatever they did).
    let both = format!(
        "{} &\nfirst=$!\n{} &\nsecond=$!\nwait $first; a=$?\nwait $second; b=$?\n\
         [ $a = 0 ] && [ $b = 0 ]\n",
        steps[0], steps[1]
    );
    std::fs::write(&script, both).unwrap();
    let mut salloc = cluster.command("salloc");
    salloc
        .args(["-N3", "-n6", "sh"])
        .arg(&script)
        .env("NO_COLOR", "1");
    let (status, log) = finish(spawn(salloc));
    assert!(status.success(), "salloc failed: {status}\n{log}");
    for out in &outs {
        assert_frames_match_reference(out);
    }
    let (first, second) = (job.task(0, 0), job.task(1, 0));
    assert_eq!(first.job, second.job, "the steps belong to one job");
    for port in [default_port(first.job, 0), default_port(first.job, 1)] {
        assert!(
            log.contains(&format!("listening on 0.0.0.0:{port};")),
            "no owner listened on {port}\n{log}"
        );
    }
}

/// What `runtime::slurm` assumes of srun, checked on the environments srun really gives its
/// tasks: under each layout (block, cyclic, plane; two tasks per node, so that block and cyclic
/// differ) task 0 runs on the step's first node and owns, every task reads the same owner `n1`
/// and the same port, and `--cpus-per-task` sizes the rendering pool.
#[test]
fn real_step_environments_read_as_runtime_slurm_expects() {
    let Some(cluster) =
        Cluster::start_or_skip("real_step_environments_read_as_runtime_slurm_expects")
    else {
        return;
    };
    let layouts = [
        ("block", ["n1", "n1", "n2", "n2", "n3", "n3"]),
        ("cyclic", ["n1", "n2", "n3", "n1", "n2", "n3"]),
        // Planes of two tasks per node, two tasks per node: laid out as block.
        ("plane=2", ["n1", "n1", "n2", "n2", "n3", "n3"]),
    ];
    for (layout, expected) in layouts {
        let layout_flag = format!("--distribution={layout}");
        let steps = step_environments(&cluster, layout, &["-N3", "-n6", &layout_flag]);
        let nodes: Vec<&str> = steps
            .iter()
            .map(|(env, _)| env["SLURMD_NODENAME"].as_str())
            .collect();
        assert_eq!(nodes, expected, "{layout}");
        let (env0, step0) = &steps[0];
        assert_eq!(step0.role(), Role::Owner { peers: 5 }, "{layout}");
        let job: u64 = env0["SLURM_JOB_ID"].parse().unwrap();
        assert_eq!(step0.port, default_port(job, 0), "{layout}");
        for (rank, (_, step)) in steps.iter().enumerate() {
            if rank > 0 {
                let index = rank as u32;
                assert_eq!(step.role(), Role::Peer { index }, "{layout}");
            }
            assert_eq!(step.owner, "n1", "{layout}, task {rank}");
            assert_eq!(step.port, step0.port, "{layout}, task {rank}");
            assert_eq!(step.nodes, ["n1", "n2", "n3"], "{layout}, task {rank}");
            assert_eq!(step.cpus_per_task, None, "{layout}: no --cpus-per-task");
        }
    }
    // SLURM_CPUS_PER_TASK, set only with -c, becomes the pool's size in every task.
    let steps = step_environments(&cluster, "cpus", &["-N3", "-n3", "-c2"]);
    for (rank, (_, step)) in steps.iter().enumerate() {
        assert_eq!(step.cpus_per_task, Some(2), "task {rank}");
    }
}
