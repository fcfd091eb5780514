//! The commands of a real cluster: `tessera serve` (the frame owner), `tessera peer`, `tessera
//! slurm` (one task of a SLURM step: task 0 serves, the others are peers) and `tessera keygen`.

use crate::cli::{KeygenArgs, PeerArgs, ServeArgs, SlurmArgs};
use crate::job;
use anyhow::Context;
use runtime::net::{ClusterCerts, PeerIdentity};
use runtime::node;
use runtime::slurm::{self, Role};
use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::time::{Duration, Instant};
use tokio::signal::unix::SignalKind;

/// `tessera serve`: this process owns the frames (peer 0) and renders too; peers join it from
/// other processes or machines: `--expect` of them before the first frame, any more later.
pub fn serve(args: &ServeArgs) -> anyhow::Result<()> {
    let identity = PeerIdentity::load(&args.certs, 0)
        .with_context(|| format!("loading peer 0's certificate from {}", args.certs.display()))?;
    let threads = args.job.threads.unwrap_or_else(job::available_threads);
    let options = job::options(&args.job, threads);
    anyhow::ensure!(
        args.expect <= options.net.max_connections,
        "--expect {}: a node accepts at most {} connections",
        args.expect,
        options.net.max_connections
    );
    job::execute(&args.job, args.expect + 1, threads, |job, sink| {
        let tokio = job::tokio_runtime()?;
        tokio.block_on(async {
            let owner = node::Owner::bind(args.listen, &identity, options)?;
            tracing::info!(
                "listening on {}; waiting for {} peers",
                owner.local_addr()?,
                args.expect
            );
            let (peers, own) = owner.run(job, args.expect, sink).await?;
            Ok(node::LocalRun {
                peers,
                timelines: vec![(runtime_core::wire::PeerId(0), own)],
            })
        })
    })
}

pub fn keygen(args: &KeygenArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.peers >= 2,
        "a cluster needs the owner (peer 0) and at least one peer"
    );
    let most = node::Options::default().net.max_connections as u32 + 1;
    anyhow::ensure!(
        args.peers <= most,
        "--peers {}: an owner accepts at most {} peers, so a cluster has at most {most} \
         certificates",
        args.peers,
        most - 1
    );
    let certs = ClusterCerts::generate(args.peers)?;
    certs
        .write_pem(&args.out)
        .with_context(|| format!("writing certificates to {}", args.out.display()))?;
    println!(
        "wrote a cluster CA and {} peer certificates to {}: give peer 0 to `tessera serve`, peer K to the K-th `tessera peer --index K`; keep ca-key.pem private",
        args.peers,
        args.out.display()
    );
    Ok(())
}

pub fn peer(args: &PeerArgs) -> anyhow::Result<()> {
    let index = match args.index {
        Some(index) => index,
        None => PeerIdentity::only_index(&args.certs)?,
    };
    // A plain peer is started by hand after the owner: one try, as it always was.
    join(
        args.join,
        args.listen,
        &args.certs,
        index,
        args.threads,
        Duration::ZERO,
    )
}

/// `tessera slurm`: one task of a SLURM step. Rank 0 is `tessera serve` listening on every
/// interface for the other tasks; rank K is `tessera peer --index K` dialing rank 0's node.
/// Where each stands comes from the environment, read by `runtime::slurm`.
pub fn slurm(mut args: SlurmArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.port != Some(0),
        "--port 0: every task must know the owner's port; give a fixed one or leave it to the \
         job id"
    );
    let patience = Duration::try_from_secs_f64(args.join_timeout).map_err(|_| {
        anyhow::anyhow!(
            "--join-timeout {:?}: must be a number of seconds, 0 or more and not absurdly large",
            args.join_timeout
        )
    })?;
    // Variables that are not Unicode are none of SLURM's, which writes ASCII.
    let env: slurm::Env = std::env::vars_os()
        .filter_map(|(k, v)| Some((k.into_string().ok()?, v.into_string().ok()?)))
        .collect();
    let overrides = slurm::Overrides {
        owner: args.owner.clone(),
        port: args.port,
    };
    let step = slurm::Step::from_env(&env, &overrides)?;
    let threads = args.job.threads.or(step.cpus_per_task);
    match step.role() {
        Role::Owner { peers } => {
            let most = node::Options::default().net.max_connections;
            anyhow::ensure!(
                peers <= most,
                "the step has {} tasks: an owner accepts at most {most} peers",
                step.tasks
            );
            tracing::info!(
                "SLURM task 0 of {}: owning the frames on {}, port {}",
                step.tasks,
                step.owner,
                step.port
            );
            let expect = args.expect.unwrap_or(peers);
            anyhow::ensure!(
                expect <= peers,
                "--expect {expect}: the step has only {peers} tasks besides task 0"
            );
            args.job.threads = threads;
            serve(&ServeArgs {
                job: args.job,
                listen: SocketAddr::from((Ipv4Addr::UNSPECIFIED, step.port)),
                certs: args.certs,
                expect,
            })
        }
        Role::Peer { index } => {
            let owner = slurm::owner_address(&step.owner, step.port)?;
            tracing::info!(
                "SLURM task {index} of {}: joining {} ({owner})",
                step.tasks,
                step.owner
            );
            let listen = SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0));
            join(owner, listen, &args.certs, index, threads, patience)
        }
    }
}

/// Joins the owner at `owner` as peer `index` and renders until the render is over. While
/// nobody answers and `patience` lasts, it tries again: tasks started together find an owner
/// still loading its scene. A refusal ends it at once.
fn join(
    owner: SocketAddr,
    listen: SocketAddr,
    certs: &Path,
    index: u32,
    threads: Option<usize>,
    patience: Duration,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        index >= 1,
        "peer 0 is the frame owner's certificate; peers use 1 and up"
    );
    let identity = PeerIdentity::load(certs, index).with_context(|| {
        format!(
            "loading peer {index}'s certificate from {}",
            certs.display()
        )
    })?;
    let threads = threads.unwrap_or_else(job::available_threads);
    let options = node::Options {
        threads,
        ..node::Options::default()
    };
    let tokio = job::tokio_runtime()?;
    // SIGTERM is how SLURM (preemption, `scancel`, the end of a time limit) and cloud
    // machines about to be taken back ask a process to stop: the peer hands back what it
    // has not started and leaves, so the render loses nothing and waits for no timeout.
    let (asked, leave) = node::Leave::channel();
    let mut terminate = tokio
        .block_on(async { tokio::signal::unix::signal(SignalKind::terminate()) })
        .context("listening for SIGTERM")?;
    tokio.spawn(async move {
        if terminate.recv().await.is_some() {
            tracing::info!("SIGTERM: leaving the render");
            let _ = asked.send(true);
        }
    });
    tracing::info!("peer {index} joining {owner} with {threads} threads");
    let started = Instant::now();
    let run = loop {
        let attempt = node::run_peer(owner, listen, &identity, options.clone(), leave.clone());
        match tokio.block_on(attempt) {
            Err(error) if slurm::nobody_answered(&error) && started.elapsed() < patience => {
                tracing::info!("nobody answers at {owner} yet: trying again");
            }
            Err(error) if slurm::nobody_answered(&error) => {
                let waited = if patience.is_zero() {
                    String::new()
                } else {
                    format!(" within {:.0} s", patience.as_secs_f64())
                };
                return Err(error).with_context(|| {
                    format!("nobody answered at {owner}{waited}: is the owner running there?")
                });
            }
            result => break result?,
        }
    };
    let ending = if run.left {
        "left the render when asked (SIGTERM), having handed back the rest"
    } else {
        "the render is over"
    };
    println!("peer {index}: rendered {} tiles; {ending}", run.tiles.len());
    Ok(())
}
