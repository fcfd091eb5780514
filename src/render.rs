//! `tessera render`: load a scene, start peers in this process (peer 0 owns the frames), and let
//! them render every frame: the PBT (or a grid) deals initial tile sets, peers steal from each
//! other over QUIC, and the owner writes each frame and feeds its measured costs back to the
//! balancer.

use crate::cli::RenderArgs;
use crate::job;
use runtime::node;

/// `tessera render`: every peer in this process.
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let peers = args.peers;
    let threads = args.job.threads.unwrap_or_else(job::available_threads);
    let options = job::options(&args.job, (threads / peers).max(1));
    // Every peer keeps a connection to every other: past the transport's limit some would be
    // refused and the render would wait for them forever.
    let most = options.net.max_connections + 1;
    anyhow::ensure!(
        peers <= most,
        "--peers {peers}: at most {most} peers fit in one process (each keeps a QUIC connection \
         to every other, and a node accepts at most {})",
        options.net.max_connections
    );
    job::execute(&args.job, peers, threads, |job, sink| {
        let tokio = job::tokio_runtime()?;
        Ok(tokio.block_on(node::run_local(job, peers, options, sink))?)
    })
}
