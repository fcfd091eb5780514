//! The driver: tokio + quinn around the sans-IO [`runtime_core`]. It moves bytes and timers and
//! renders on a rayon pool; every scheduling decision is the core's.
//!
//! - [`owner`]: the frame owner (`tessera serve`, and peer 0 of the in-process default).
//! - [`peer`]: any other peer (`tessera peer`).
//! - `session`: the event loop both share: link events, render results and the core's timer.
//! - [`bundle`]: the scene's files and tiles' pixels and costs as the wire carries them.
//! - [`checkpoint`]: the frame in progress kept on disk, for `--resume` within a frame.
//! - [`limits`]: the image sizes and tile counts refused before anything is rendered.
//! - [`run_local`]: several peers in one process over real QUIC on loopback, certificates made
//!   in memory: the default of `tessera render`.

pub mod bundle;
pub mod checkpoint;
pub mod limits;
pub mod owner;
pub mod peer;
mod session;

pub use owner::{Job, Owner, PeerReport};
pub use peer::{Leave, PeerRun, run_peer};

use crate::net::{BindError, ClusterCerts, ConnectError};
use runtime_core::stats::{FrameStats, LocalTile, TileStats};
use runtime_core::wire::{PeerId, TileId};
use std::net::{Ipv4Addr, SocketAddr};
use std::time::Duration;
use tracer::Film;

/// The longest a node waits for its goodbyes (and a leaving peer for its last results) to leave
/// before its endpoint closes every connection: a peer that stopped reading would hold a send
/// forever.
const GOODBYE_BOUND: Duration = Duration::from_secs(2);

/// How a node runs: its renderer, its policy and its transport's bounds.
#[derive(Clone, Debug)]
pub struct Options {
    /// Rendering threads, and so the tiles the core keeps in flight.
    pub threads: usize,
    /// The scheduling core's policy: prefetch, stealing, timeouts.
    pub core: runtime_core::peer::Config,
    /// The QUIC link's settings.
    pub net: crate::net::Config,
    /// The bounds every received message is decoded under.
    pub limits: runtime_core::wire::Limits,
    /// Seeds victim choice (mixed with the peer id by the core).
    pub seed: u64,
}

impl Default for Options {
    fn default() -> Self {
        // The scene travels in one message: allow scenes up to 64 MiB (the Stanford dragon's
        // OBJ is 32 MB). Chunked scene transfer would lift this; it is not written yet.
        let net = crate::net::Config {
            max_message_bytes: 64 << 20,
            ..crate::net::Config::default()
        };
        let limits = runtime_core::wire::Limits {
            max_message_bytes: 64 << 20,
            ..runtime_core::wire::Limits::default()
        };
        Self {
            threads: 1,
            core: runtime_core::peer::Config::default(),
            net,
            limits,
            seed: 0,
        }
    }
}

impl Options {
    /// Sets the one silence a user names (`--peer-timeout`) everywhere it applies: the owner's
    /// silence timeout for a peer that may hold work, and QUIC's idle timeout; heartbeats and
    /// keep-alives go out at a fifth of it, so that a live peer sends several within it.
    pub fn set_peer_timeout(&mut self, timeout: std::time::Duration) {
        self.core.peer_timeout = timeout;
        self.core.heartbeat_interval = timeout / 5;
        self.net.idle_timeout = timeout;
        self.net.keep_alive = timeout / 5;
    }
}

/// Why a node stopped before the render was done.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The node's endpoint could not be bound.
    #[error(transparent)]
    Bind(#[from] BindError),
    /// A peer could not connect to the owner or to another peer.
    #[error(transparent)]
    Connect(#[from] ConnectError),
    /// The cluster's certificates could not be made or read.
    #[error(transparent)]
    Certs(#[from] crate::net::CertError),
    /// A file or socket operation failed.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The scene could not be bundled, or a received one could not be loaded.
    #[error(transparent)]
    Bundle(#[from] bundle::BundleError),
    /// The core refused a frame the owner started.
    #[error(transparent)]
    Frame(#[from] runtime_core::peer::FrameError),
    /// The balancer refused to cut or learn.
    #[error(transparent)]
    Balancer(#[from] balancer::Error),
    /// The director refused a step.
    #[error(transparent)]
    Director(#[from] runtime_core::director::DirectorError),
    /// A result's pixels or costs do not decode, so the frame cannot be assembled.
    #[error("{0} came back with malformed pixels or costs")]
    BadTile(TileId),
    /// The link's endpoint stopped before the render was done.
    #[error("the transport stopped")]
    Stopped,
    /// A peer lost the frame owner before the render was done.
    #[error("the frame owner was lost ({0}); the render is incomplete")]
    OwnerLost(crate::net::CloseReason),
    /// The [`FrameSink`] refused a frame; the text is its error.
    #[error("writing a frame: {0}")]
    Sink(String),
    /// A peer of an in-process cluster failed; the text is its error.
    #[error("a peer task failed: {0}")]
    Peer(String),
}

/// One finished frame, as the owner assembled it.
#[derive(Debug)]
pub struct CompletedFrame {
    /// The frame's number.
    pub frame: u32,
    /// The assembled pixels.
    pub film: Film,
    /// Its pieces as the owner accepted them, in tile order (one per piece, `pieces` 1).
    pub tiles: Vec<TileStats>,
    /// From starting the frame to its last tile, in seconds.
    pub seconds: f64,
    /// When the frame was handed over, in seconds since the owner started: frames overlap, so
    /// the time between two frames' hand-overs is what each adds to the render.
    pub completed_at: f64,
    /// Rays traced for the frame, of every kind.
    pub rays: u64,
    /// How duplicate results (backups of stragglers, re-issued tiles) compared with the first.
    pub audit: runtime_core::peer::Audit,
}

impl CompletedFrame {
    /// The frame's entry of `stats.json`: its times, rays and counted work, one record per
    /// tile of the partition (its pieces summed), how the duplicates compared, and the spread
    /// of the tiles' measured costs. The peers' own accounts are added when the render ends
    /// ([`runtime_core::stats::StatsFile::add_peer_accounts`]).
    pub fn stats(&self) -> FrameStats {
        let mut stats = FrameStats {
            frame: self.frame,
            seconds: self.seconds,
            completed_at: self.completed_at,
            rays: self.rays,
            work: self.tiles.iter().map(|t| t.measured).sum(),
            tiles: TileStats::per_tile(&self.tiles),
            duplicates_agreed: self.audit.agreed,
            duplicates_disagreed: self.audit.disagreed,
            tiles_reissued: self.audit.reissued,
            tiles_backed_up: self.audit.backed_up,
            peers_failed: self.audit.failed,
            ..FrameStats::default()
        };
        stats.summarise_leaves();
        stats
    }
}

/// Where finished frames go (the CLI writes them to disk).
pub trait FrameSink: Send {
    /// Takes one finished frame, in frame order; an error stops the render with
    /// [`NodeError::Sink`].
    fn frame(&mut self, frame: CompletedFrame) -> Result<(), String>;
}

/// What an in-process cluster run reports.
pub struct LocalRun {
    /// Every peer's statistics for every frame.
    pub peers: PeerReport,
    /// Tiles each peer rendered, with times since its own start (for the Gantt chart).
    pub timelines: Vec<(PeerId, Vec<LocalTile>)>,
}

/// Renders `job` with `peers` peers in this process (peer 0 is the owner), each with
/// `options.threads` rendering threads, over QUIC on 127.0.0.1 with certificates made in memory.
pub async fn run_local(
    job: Job,
    peers: usize,
    options: Options,
    sink: &mut dyn FrameSink,
) -> Result<LocalRun, NodeError> {
    let peers = peers.max(1);
    let certs = ClusterCerts::generate(peers as u32)?;
    let loopback = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    let owner = Owner::bind(loopback, &certs.peers()[0], options.clone())?;
    let owner_addr = owner.local_addr()?;
    let mut tasks = Vec::new();
    for identity in &certs.peers()[1..] {
        let (identity, options) = (identity.clone(), options.clone());
        tasks.push(tokio::spawn(async move {
            let id = PeerId(identity.index());
            run_peer(owner_addr, loopback, &identity, options, Leave::never())
                .await
                .map(|run| (id, run.tiles))
        }));
    }
    let (report, own_tiles) = owner.run(job, peers - 1, sink).await?;
    let mut timelines = vec![(PeerId(0), own_tiles)];
    for task in tasks {
        match tokio::time::timeout(Duration::from_secs(10), task).await {
            Ok(Ok(Ok(timeline))) => timelines.push(timeline),
            Ok(Ok(Err(error))) => return Err(NodeError::Peer(error.to_string())),
            Ok(Err(join)) => return Err(NodeError::Peer(join.to_string())),
            Err(_) => {
                return Err(NodeError::Peer(
                    "a peer did not stop after the render".into(),
                ));
            }
        }
    }
    Ok(LocalRun {
        peers: report,
        timelines,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use balancer::Rect;

    /// A frame's entry sums its pieces' work, folds them into their tiles, keeps the audit and
    /// states the spread of the tiles' costs.
    #[test]
    fn a_completed_frame_states_its_tiles_work_and_duplicates() {
        let done = CompletedFrame {
            frame: 7,
            film: Film::new(8, 4),
            tiles: vec![
                TileStats::piece(0, Rect::new(0, 0, 4, 4), 10.0, 12, 0, 0),
                TileStats::piece(1, Rect::new(4, 0, 4, 2), 2.0, 2, 1, 0),
                TileStats::piece(1, Rect::new(4, 2, 4, 2), 2.0, 2, 1, 0),
            ],
            seconds: 1.5,
            completed_at: 2.5,
            rays: 1000,
            audit: runtime_core::peer::Audit {
                agreed: 2,
                disagreed: 0,
                reissued: 3,
                backed_up: 1,
                failed: 1,
            },
        };
        let stats = done.stats();
        assert_eq!(
            (stats.frame, stats.seconds, stats.completed_at),
            (7, 1.5, 2.5)
        );
        assert_eq!((stats.rays, stats.work), (1000, 16));
        assert_eq!(stats.tiles.len(), 2);
        assert_eq!((stats.tiles[1].measured, stats.tiles[1].pieces), (4, 2));
        assert_eq!(
            (stats.duplicates_agreed, stats.duplicates_disagreed),
            (2, 0)
        );
        assert_eq!(
            (
                stats.tiles_reissued,
                stats.tiles_backed_up,
                stats.peers_failed
            ),
            (3, 1, 1)
        );
        // Tiles of 12 and 4: mean 8, variance 16, the largest 1.5 times the mean.
        assert_eq!(stats.leaf_cost_variance, 16.0);
        assert_eq!(stats.leaf_cost_max_over_mean, 1.5);
        assert!(stats.peers.is_empty());
    }
}
