//! A real SLURM cluster of three nodes on this machine, for the tests that run `srun`: started
//! by `scripts/slurm_cluster.sh` in a temporary folder of its own and stopped when dropped.
//!
//! Where SLURM cannot be set up (not root, the packages missing, `n1` not resolving) a test
//! skips, saying why, unless the run must not skip: with `TESSERA_REQUIRE_SLURM=1` (which
//! `.ci/run` sets) or `CI` set, as CI services do, it fails with the reason instead.

use super::repo;
use runtime::slurm::default_port;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard};

/// One cluster at a time in a test binary: one step's three tasks already fill a small machine,
/// and clusters side by side would only make the moments the tests rely on (a task killed in
/// the middle of a frame) less certain.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A started cluster; dropping it stops every daemon and the steps still running.
pub struct Cluster {
    // Fields drop in declaration order once `drop` has stopped the daemons: the next test's
    // turn, then the folder with the cluster's logs.
    _turn: MutexGuard<'static, ()>,
    dir: tempfile::TempDir,
    first_job: u64,
}

/// Whether this run must not skip the SLURM tests.
pub fn required() -> bool {
    let set = |name| std::env::var(name).is_ok_and(|v| !v.is_empty() && v != "0" && v != "false");
    set("TESSERA_REQUIRE_SLURM") || set("CI")
}

impl Cluster {
    /// Starts a cluster for the test `test`, or says why it cannot: a panic where the run must
    /// not skip (see the module's notes), else a line on stderr and `None`.
    pub fn start_or_skip(test: &str) -> Option<Cluster> {
        // A test that failed with the lock held poisons it; the next one may still run.
        let turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        let dir = tempfile::tempdir().expect("a temporary folder");
        let base = free_base_port();
        let first_job = job_with_free_ports();
        let output = Command::new(script())
            .arg("start")
            .arg(dir.path())
            .arg(base.to_string())
            .arg(first_job.to_string())
            .output();
        let why = match output {
            Ok(output) if output.status.success() => {
                return Some(Cluster {
                    _turn: turn,
                    dir,
                    first_job,
                });
            }
            Ok(output) => String::from_utf8_lossy(&output.stderr).trim().to_owned(),
            Err(error) => format!("cannot run {}: {error}", script().display()),
        };
        if required() {
            panic!("{test}: SLURM must run here (TESSERA_REQUIRE_SLURM or CI is set): {why}");
        }
        // Written to the process's stderr itself, not through `eprintln!`, which the test
        // harness captures and shows only for failing tests: a skip must be seen.
        let _ = writeln!(
            std::io::stderr(),
            "{test}: SKIPPED, no SLURM cluster can be set up on this machine ({why}); \
             .ci/run shows what it needs"
        );
        None
    }

    /// The cluster's folder; tests put their certificates and outputs in it too.
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// The id of the cluster's first job (the first `srun` or `salloc`), whose first two steps'
    /// ports were free when it started.
    pub fn first_job(&self) -> u64 {
        self.first_job
    }

    /// `program` (srun, salloc, ...) talking to this cluster. Every SLURM variable of the
    /// environment the tests run in is removed first: inside a job of another cluster they
    /// would name its job and nodes.
    pub fn command(&self, program: &str) -> Command {
        let mut command = Command::new(program);
        for (name, _) in std::env::vars_os() {
            if name.to_string_lossy().starts_with("SLURM") {
                command.env_remove(name);
            }
        }
        command.env("SLURM_CONF", self.dir().join("slurm.conf"));
        command
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let stopped = Command::new(script()).arg("stop").arg(self.dir()).status();
        if !matches!(stopped, Ok(status) if status.success()) {
            eprintln!(
                "stopping the SLURM cluster in {} failed: {stopped:?}",
                self.dir().display()
            );
        }
    }
}

/// A job id whose steps 0 and 1 derive ports (`runtime::slurm::default_port`) free for UDP now,
/// so that a test's tessera owner does not find its port taken by another program. The ids
/// tried start at one that depends on this process, so that two test runs at once rarely try
/// the same.
fn job_with_free_ports() -> u64 {
    let free = |port| std::net::UdpSocket::bind(("0.0.0.0", port)).is_ok();
    let start = 1 + std::process::id() as u64 % 2000;
    (start..start + 2000)
        .find(|&job| free(default_port(job, 0)) && free(default_port(job, 1)))
        .expect("some job's ports in 20000..40000 are free")
}

fn script() -> PathBuf {
    repo("scripts/slurm_cluster.sh")
}

/// A port P such that P (slurmctld) and P+1 .. P+3 (the three slurmd) are free for TCP now,
/// from 17000 (the ports docs/cluster.md shows) up in steps of ten.
fn free_base_port() -> u16 {
    (17000..27000)
        .step_by(10)
        .find(|&base| {
            (base..base + 4).all(|port| std::net::TcpListener::bind(("0.0.0.0", port)).is_ok())
        })
        .expect("four free TCP ports in 17000..27000")
}
