//! Where one task of a SLURM step stands in the cluster it makes: its rank, how many tasks
//! there are, which host owns the frames and on which port. Pure: the environment comes in as a
//! map, so tests script any step and the binary passes its own variables.
//!
//! What this relies on (srun(1), "OUTPUT ENVIRONMENT VARIABLES" and `--distribution`; the
//! test `real_step_environments_read_as_runtime_slurm_expects` in `tests/slurm_real.rs` reads
//! the environments a real srun gives its tasks, under the block, cyclic and plane layouts):
//! - `SLURM_PROCID` is the task's global rank, 0 .. tasks; rank 0 owns the frames and rank K
//!   joins as peer K, so `tessera keygen --peers N` names every task's certificate.
//! - `SLURM_STEP_NUM_TASKS` (set by srun for its step) is the task count; `SLURM_NTASKS` (the
//!   job's, also what srun passes down) is the fallback for older releases.
//! - `SLURM_STEP_NODELIST` (`SLURM_JOB_NODELIST` as fallback) lists the step's nodes in the
//!   order of their relative node ids (`SLURM_NODEID` 0, 1, ...). Every distribution but
//!   `arbitrary` lays tasks out starting from relative node 0: `block` fills it first, `cyclic`
//!   deals task 0 to it, `plane` gives it the first plane. So rank 0 runs on the list's first
//!   node, and that, not "a host", is why the first host is the owner. With
//!   `--distribution=arbitrary` (`SLURM_DISTRIBUTION=arbitrary`) task 0 runs wherever
//!   `SLURM_HOSTFILE` put it, so we refuse unless the owner is named explicitly.
//! - Rank 0 checks the claim where it can: when `SLURMD_NODENAME` (the node it runs on) is set
//!   and is not the list's first node, it refuses instead of leaving its peers to dial a node
//!   where nobody listens. A layout we did not foresee is then an error, not a hang.
//! - Peers dial the owner by its SLURM node name, so that name must resolve to the node (true
//!   where `NodeName` is the host name, the common setup); elsewhere, name the owner.
//! - `SLURM_CPUS_PER_TASK` is set only when `--cpus-per-task` was given; it sizes the
//!   rendering pool. `SLURM_JOB_ID` (`SLURM_JOBID` on old releases) and `SLURM_STEP_ID`
//!   (`SLURM_STEPID`; absent, as in a batch script, counts as step 0) pick the default port, so
//!   that two jobs sharing a node do not collide, nor two steps of one job running at once.

pub mod hostlist;

pub use hostlist::{HostlistError, expand as expand_hostlist};

use std::collections::BTreeMap;

/// A process environment, or a test's script of one.
pub type Env = BTreeMap<String, String>;

/// What the command line says instead of the environment.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// The owner's host, for layouts where rank 0 is not on the step's first node.
    pub owner: Option<String>,
    /// The owner's port, instead of the one derived from the job id.
    pub port: Option<u16>,
}

/// One task's view of its step.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Step {
    /// This task's rank (`SLURM_PROCID`).
    pub rank: u32,
    /// Tasks in the step: the owner and `tasks - 1` peers.
    pub tasks: u32,
    /// The step's nodes, in relative node id order (empty when the owner was given).
    pub nodes: Vec<String>,
    /// The host that rank 0 runs on, where peers dial the owner.
    pub owner: String,
    /// The port the owner listens on.
    pub port: u16,
    /// Rendering threads per task, where SLURM says (`SLURM_CPUS_PER_TASK`).
    pub cpus_per_task: Option<usize>,
}

/// What this task does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Rank 0: own the frames, waiting for `peers` others.
    Owner {
        /// How many peers will join.
        peers: usize,
    },
    /// Rank K >= 1: join the owner as peer K.
    Peer {
        /// This task's peer index, its SLURM rank.
        index: u32,
    },
}

/// Why a task cannot place itself in its step.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SlurmError {
    /// Variables every SLURM step sets are unset: this is not a task of a step.
    #[error(
        "not inside a SLURM step: {} not set (run it as a task of `srun`)",
        missing_list(.0)
    )]
    Missing(Vec<&'static str>),
    /// A variable's value does not parse.
    #[error("{name}={value:?}: {reason}")]
    Invalid {
        /// The variable.
        name: &'static str,
        /// Its value.
        value: String,
        /// What was wrong with it.
        reason: &'static str,
    },
    /// A variable's host list does not expand.
    #[error("{name}={value:?}: {source}")]
    Hostlist {
        /// The variable.
        name: &'static str,
        /// Its value.
        value: String,
        /// Why it does not expand.
        source: HostlistError,
    },
    /// This task's rank is not below the step's task count.
    #[error("SLURM_PROCID={rank} but the step has only {tasks} tasks")]
    RankOutOfRange {
        /// This task's rank.
        rank: u32,
        /// The step's task count.
        tasks: u32,
    },
    /// A step of one task cannot hold an owner and a peer.
    #[error(
        "the step has {0} task: a cluster needs the owner and at least one peer (srun -n 2 or \
         more); `tessera render` renders on one node"
    )]
    TooFewTasks(u32),
    /// With an arbitrary task layout the owner's host cannot be known from the environment.
    #[error(
        "SLURM_DISTRIBUTION={0:?}: with an arbitrary layout task 0 may run on any node; name \
         its host with --owner"
    )]
    ArbitraryLayout(String),
    /// Task 0 is not on the step's first node, which the other tasks would dial.
    #[error(
        "task 0 runs on {here} but the step's first node is {first}: peers would dial the wrong \
         node; name the owner's host with --owner"
    )]
    OwnerElsewhere {
        /// The host task 0 runs on.
        here: String,
        /// The step's first node.
        first: String,
    },
}

fn missing_list(names: &[&'static str]) -> String {
    let verb = if names.len() == 1 { "is" } else { "are" };
    format!("{} {verb}", names.join(", "))
}

/// How many consecutive steps of one job get ports of their own: the job's block of ports.
pub const STEPS_PER_JOB: u64 = 10;

/// The owner's port for a step: 20000 .. 39999, the same in every task of the step without
/// talking. Each job has a block of [`STEPS_PER_JOB`] ports, `20000 + 10 * (job mod 2000)`
/// onwards, and step S takes the block's port `S mod 10`. So jobs whose ids are less than
/// 2000 apart never collide, whatever their steps, and neither do up to ten steps of one job
/// running at once (`srun ... & srun ... & wait` in one batch script), which a port from the
/// job id alone could not tell apart.
pub fn default_port(job_id: u64, step_id: u64) -> u16 {
    const FIRST: u16 = 20000;
    const PORTS: u64 = 20000;
    let block = job_id % (PORTS / STEPS_PER_JOB) * STEPS_PER_JOB;
    FIRST + (block + step_id % STEPS_PER_JOB) as u16
}

impl Step {
    /// Reads a task's place from its environment. Every required variable that is absent (or
    /// empty) is named at once, so a user outside SLURM sees the whole list.
    pub fn from_env(env: &Env, overrides: &Overrides) -> Result<Step, SlurmError> {
        let var = |name: &str| env.get(name).map(String::as_str).filter(|v| !v.is_empty());
        let first_of = |names: &[&'static str]| {
            names
                .iter()
                .find_map(|&name| var(name).map(|value| (name, value)))
        };
        let rank = var("SLURM_PROCID");
        let tasks = first_of(&["SLURM_STEP_NUM_TASKS", "SLURM_NTASKS"]);
        let nodes = first_of(&["SLURM_STEP_NODELIST", "SLURM_JOB_NODELIST"]);
        let job = first_of(&["SLURM_JOB_ID", "SLURM_JOBID"]);
        let mut missing = Vec::new();
        if rank.is_none() {
            missing.push("SLURM_PROCID");
        }
        if tasks.is_none() {
            missing.push("SLURM_STEP_NUM_TASKS (or SLURM_NTASKS)");
        }
        if nodes.is_none() && overrides.owner.is_none() {
            missing.push("SLURM_STEP_NODELIST (or SLURM_JOB_NODELIST)");
        }
        if job.is_none() && overrides.port.is_none() {
            missing.push("SLURM_JOB_ID");
        }
        let (Some(rank), Some((tasks_name, tasks))) = (rank, tasks) else {
            return Err(SlurmError::Missing(missing));
        };
        if !missing.is_empty() {
            return Err(SlurmError::Missing(missing));
        }
        let rank: u32 = parse("SLURM_PROCID", rank, "not a task rank")?;
        let tasks: u32 = parse(tasks_name, tasks, "not a task count")?;
        if tasks < 2 {
            return Err(SlurmError::TooFewTasks(tasks));
        }
        if rank >= tasks {
            return Err(SlurmError::RankOutOfRange { rank, tasks });
        }
        let cpus_per_task = match var("SLURM_CPUS_PER_TASK") {
            Some(value) => match parse::<usize>("SLURM_CPUS_PER_TASK", value, "not a CPU count")? {
                0 => return Err(invalid("SLURM_CPUS_PER_TASK", value, "zero CPUs")),
                n => Some(n),
            },
            None => None,
        };
        let port = match (overrides.port, job) {
            (Some(port), _) => port,
            (None, Some((name, job))) => {
                let step = match first_of(&["SLURM_STEP_ID", "SLURM_STEPID"]) {
                    Some((name, step)) => parse(name, step, "not a step id")?,
                    None => 0,
                };
                default_port(parse(name, job, "not a job id")?, step)
            }
            (None, None) => unreachable!("a missing job id without --port was reported above"),
        };
        let (nodes, owner) = match (&overrides.owner, nodes) {
            (Some(owner), _) => (Vec::new(), owner.clone()),
            (None, Some((name, list))) => {
                let nodes = expand_hostlist(list).map_err(|source| SlurmError::Hostlist {
                    name,
                    value: list.to_owned(),
                    source,
                })?;
                let owner = owner_node(env, rank, &nodes)?;
                (nodes, owner)
            }
            (None, None) => unreachable!("a missing node list without --owner was reported above"),
        };
        Ok(Step {
            rank,
            tasks,
            nodes,
            owner,
            port,
            cpus_per_task,
        })
    }

    /// What this task is in the cluster: the owner (rank 0) or peer K (rank K).
    pub fn role(&self) -> Role {
        match self.rank {
            0 => Role::Owner {
                peers: self.tasks as usize - 1,
            },
            index => Role::Peer { index },
        }
    }
}

/// The node rank 0 runs on: the step's first (see the module's notes for why), checked by
/// rank 0 itself against the node it is on.
fn owner_node(env: &Env, rank: u32, nodes: &[String]) -> Result<String, SlurmError> {
    if let Some(layout) = env.get("SLURM_DISTRIBUTION") {
        // `arbitrary`, or `arbitrary:...` with a second-level distribution.
        if layout.split([':', ',']).next() == Some("arbitrary") {
            return Err(SlurmError::ArbitraryLayout(layout.clone()));
        }
    }
    let first = nodes[0].clone(); // expand_hostlist never returns an empty list.
    if rank == 0
        && let Some(here) = env.get("SLURMD_NODENAME").filter(|n| !n.is_empty())
        && *here != first
    {
        return Err(SlurmError::OwnerElsewhere {
            here: here.clone(),
            first,
        });
    }
    Ok(first)
}

fn parse<T: std::str::FromStr>(
    name: &'static str,
    value: &str,
    reason: &'static str,
) -> Result<T, SlurmError> {
    value
        .trim()
        .parse()
        .map_err(|_| invalid(name, value, reason))
}

fn invalid(name: &'static str, value: &str, reason: &'static str) -> SlurmError {
    SlurmError::Invalid {
        name,
        value: value.to_owned(),
        reason,
    }
}

/// Why a peer cannot dial the owner's host.
#[derive(Debug, thiserror::Error)]
pub enum OwnerAddressError {
    /// The host name does not resolve here.
    #[error("cannot resolve the owner's host {host:?}; name a host peers can reach with --owner")]
    Unresolved {
        /// The owner's host, as the step or `--owner` named it.
        host: String,
        /// What the resolver said.
        #[source]
        source: std::io::Error,
    },
    /// The host resolves, to IPv6 addresses only.
    #[error(
        "the owner's host {host:?} has no IPv4 address ({addresses:?}); name another with --owner"
    )]
    NoIpv4 {
        /// The owner's host.
        host: String,
        /// What it resolved to.
        addresses: Vec<std::net::SocketAddr>,
    },
}

/// The address a peer dials to reach the owner on `host`: its first IPv4 address. IPv4 only,
/// because the owner listens on 0.0.0.0 and a peer's endpoint, bound the same way, can only
/// dial IPv4.
pub fn owner_address(host: &str, port: u16) -> Result<std::net::SocketAddr, OwnerAddressError> {
    use std::net::ToSocketAddrs;
    let addresses: Vec<_> = (host, port)
        .to_socket_addrs()
        .map_err(|source| OwnerAddressError::Unresolved {
            host: host.to_owned(),
            source,
        })?
        .collect();
    match addresses.iter().find(|a| a.is_ipv4()) {
        Some(address) => Ok(*address),
        None => Err(OwnerAddressError::NoIpv4 {
            host: host.to_owned(),
            addresses,
        }),
    }
}

/// Whether a peer's join failed because nobody answered, as opposed to being refused: srun
/// starts every task at once and the owner loads its scene before it listens, so a peer may
/// knock first. Worth trying again; a refusal (another cluster's certificate) is not.
pub fn nobody_answered(error: &crate::node::NodeError) -> bool {
    matches!(
        error,
        crate::node::NodeError::Connect(crate::net::ConnectError::Handshake(
            quinn::ConnectionError::TimedOut
        ))
    )
}

#[cfg(test)]
mod tests;
