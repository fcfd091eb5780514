//! What the tests drive: a SLURM job on the cluster, its `srun` steps and their tasks (killed or
//! signalled by name), the environments SLURM gives a step's tasks, and the frames one peer alone
//! renders, which every step's frames must equal.

use super::*;

/// Runs `srun FLAGS` of a task that saves its environment, and reads each task's back with the
/// step `runtime::slurm` makes of it, in rank order; `name` names the step's folder.
pub(super) fn step_environments(cluster: &Cluster, name: &str, flags: &[&str]) -> Vec<(Env, Step)> {
    let dir = cluster.dir().join("envs").join(name);
    std::fs::create_dir_all(&dir).unwrap();
    let dump = format!(r#"env -0 > "{}/$SLURM_PROCID""#, dir.display());
    let output = cluster
        .command("srun")
        .args(flags)
        .args(["sh", "-c", &dump])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{name}: {stderr}");
    let tasks = std::fs::read_dir(&dir).unwrap().count();
    (0..tasks)
        .map(|rank| {
            let bytes = std::fs::read(dir.join(rank.to_string())).unwrap();
            // `env -0` ends each NAME=value with a NUL; values may hold newlines.
            let env: Env = bytes
                .split(|&b| b == 0)
                .filter_map(|entry| {
                    let (name, value) = std::str::from_utf8(entry).ok()?.split_once('=')?;
                    Some((name.to_owned(), value.to_owned()))
                })
                .collect();
            let step = Step::from_env(&env, &Overrides::default())
                .unwrap_or_else(|e| panic!("{name}, task {rank}: {e}"));
            (env, step)
        })
        .collect()
}

/// One render's certificates and the command its tasks run, on one cluster.
pub(super) struct Job<'a> {
    cluster: &'a Cluster,
    pub(super) certs: PathBuf,
    tasks: PathBuf,
}

/// Where one task ran, as it wrote it before starting tessera.
pub(super) struct Task {
    pid: u32,
    pub(super) node: String,
    pub(super) job: u64,
}

impl Job<'_> {
    pub(super) fn new(cluster: &Cluster) -> Job<'_> {
        let certs = cluster.dir().join("certs");
        keygen(&certs, 3);
        let tasks = cluster.dir().join("tasks");
        std::fs::create_dir_all(&tasks).unwrap();
        Job {
            cluster,
            certs,
            tasks,
        }
    }

    /// `srun FLAGS` of `tessera slurm` rendering into `out`. Each task first writes its pid,
    /// node and job id to `tasks/STEP.RANK`, then runs `before` (a shell command), then
    /// becomes tessera with the same pid: srun starts tasks under SLURM's daemons, not as
    /// children of the test, and this is how a test finds one to kill.
    pub(super) fn srun(&self, flags: &[&str], out: &Path, before: &str) -> Command {
        self.srun_sized(flags, out, before, &SIZE)
    }

    /// [`Job::srun`] with frames of another size.
    pub(super) fn srun_sized(
        &self,
        flags: &[&str],
        out: &Path,
        before: &str,
        size: &[&str],
    ) -> Command {
        let record = format!(
            r#"echo "$$ $SLURMD_NODENAME $SLURM_JOB_ID" > "{}/$SLURM_STEP_ID.$SLURM_PROCID"; {before}
exec "$0" "$@""#,
            self.tasks.display()
        );
        let mut command = self.cluster.command("srun");
        command.args(flags).args(["sh", "-c", &record]);
        command.arg(env!("CARGO_BIN_EXE_tessera")).arg("slurm");
        command.arg(repo(SCENE)).args(size);
        command.args(["--threads", "1", "--tiles", "64", "--peer-timeout", "2"]);
        command
            .arg("--certs")
            .arg(&self.certs)
            .arg("--out")
            .arg(out);
        command.env("NO_COLOR", "1");
        command
    }

    /// What task `rank` of step `step` wrote.
    pub(super) fn task(&self, step: u32, rank: u32) -> Task {
        let path = self.tasks.join(format!("{step}.{rank}"));
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let fields: Vec<&str> = text.split_whitespace().collect();
        let [pid, node, job] = fields[..] else {
            panic!("{}: {text:?}", path.display());
        };
        Task {
            pid: pid.parse().unwrap(),
            node: node.to_owned(),
            job: job.parse().unwrap(),
        }
    }
}

impl Task {
    /// SIGKILL: no goodbye, no connection closed, as when a node dies.
    pub(super) fn kill(&self) {
        self.signal("-KILL");
    }

    /// Sends the task `signal` (`-TERM`, `-KILL`).
    pub(super) fn signal(&self, signal: &str) {
        common::signal(self.pid, signal);
    }
}

/// Starts `command` (srun or salloc); its stderr lines, where srun forwards every task's log,
/// arrive on the channel.
pub(super) fn spawn(mut command: Command) -> (Child, mpsc::Receiver<String>) {
    spawn_reading(command.stdout(Stdio::piped()))
}

/// Waits for a spawned srun or salloc to end; its status, and its stdout and the stderr lines
/// not yet read, as one text for assertions and failure messages.
pub(super) fn finish((mut child, lines): (Child, mpsc::Receiver<String>)) -> (ExitStatus, String) {
    let status = common::wait_exit(&mut child, "the step", STEP_TIMEOUT);
    let mut log = String::new();
    child
        .stdout
        .take()
        .expect("spawn pipes stdout")
        .read_to_string(&mut log)
        .unwrap();
    // The reader thread ends when srun's stderr closes, which it has.
    for line in lines.iter() {
        log.push('\n');
        log.push_str(&line);
    }
    (status, log)
}

/// A command as one line of `sh`, every word quoted.
pub(super) fn shell_line(command: &Command) -> String {
    let quote =
        |word: &std::ffi::OsStr| format!("'{}'", word.to_string_lossy().replace('\'', r"'\''"));
    std::iter::once(command.get_program())
        .chain(command.get_args())
        .map(quote)
        .collect::<Vec<_>>()
        .join(" ")
}

/// The frames of one peer alone, rendered once per test binary.
pub(super) fn reference() -> &'static [(String, Vec<u8>)] {
    static REFERENCE: OnceLock<Vec<(String, Vec<u8>)>> = OnceLock::new();
    REFERENCE.get_or_init(|| reference_sized(&SIZE))
}

/// The frames of one peer alone at the [`SLOW`] size, rendered once per test binary.
pub(super) fn reference_slow() -> &'static [(String, Vec<u8>)] {
    static REFERENCE: OnceLock<Vec<(String, Vec<u8>)>> = OnceLock::new();
    REFERENCE.get_or_init(|| reference_sized(&SLOW))
}

fn reference_sized(size: &[&str]) -> Vec<(String, Vec<u8>)> {
    let dir = tempfile::tempdir().unwrap();
    render_alone(SCENE, size, dir.path());
    frames(dir.path())
}

pub(super) fn assert_frames_match_reference(out: &Path) {
    assert_frames_match(out, reference().to_vec());
}

pub(super) fn assert_frames_match(out: &Path, expected: Vec<(String, Vec<u8>)>) {
    let got = frames(out);
    assert_eq!(got.len(), FRAMES, "{}", out.display());
    assert_eq!(expected.len(), FRAMES);
    for ((name, a), (_, b)) in got.iter().zip(&expected) {
        assert!(
            a == b,
            "{name} in {} differs from the one-peer render",
            out.display()
        );
    }
}

/// Waits until frame `frame`'s image is in `out`, where the owner renames it once whole, or
/// [`STEP_TIMEOUT`] has passed; `false` also when the step ended first (`lines` closed). The
/// file, not the owner's "frame N done" that srun forwards: that line can arrive a second or
/// more late on a loaded machine, and a test that kills a task "after frame 0" must not kill
/// it after the render (seen once in CI: a task killed once the line came had rendered 11
/// tiles of the last frame).
pub(super) fn wait_for_frame(out: &Path, frame: u32, lines: &mpsc::Receiver<String>) -> bool {
    wait_for_file(
        &runtime::frames::resume::frame_path(out, frame, "exr"),
        lines,
    )
}

/// Waits until a step's task `rank` has written where it runs (see [`Job::srun`]): its job
/// is allocated and the task started. `false` as [`wait_for_frame`].
pub(super) fn wait_for_task(job: &Job, rank: u32, lines: &mpsc::Receiver<String>) -> bool {
    wait_for_file(&job.tasks.join(format!("0.{rank}")), lines)
}

fn wait_for_file(path: &Path, lines: &mpsc::Receiver<String>) -> bool {
    let deadline = Instant::now() + STEP_TIMEOUT;
    while Instant::now() < deadline {
        if path.exists() {
            return true;
        }
        if let Err(mpsc::RecvTimeoutError::Disconnected) =
            lines.recv_timeout(Duration::from_millis(10))
        {
            return path.exists();
        }
    }
    false
}
