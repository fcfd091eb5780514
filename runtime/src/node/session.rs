//! The driver loop shared by the frame owner and every other peer: it moves bytes between the
//! QUIC [`Link`] and the scheduling [`Core`], hands tiles to the rayon renderer, and keeps the
//! core's timer. The core decides everything; this only carries.

use super::{NodeError, Options, bundle};
use crate::net::{
    CloseCode, CloseReason, ConnId, Event as NetEvent, Link, PeerCertificate, PeerIdentity,
};
use runtime_core::peer::{Core, Event as CoreEvent, WorkItem};
use runtime_core::stats::LocalTile;
use runtime_core::wire::{self, Message, PeerId};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tracer::World;

/// A decoded message and the size it had on the wire.
pub(crate) type Incoming = (Message, usize);

/// The decoder handed to the transport: pure, bounded (see [`wire::decode`]).
fn decoder(
    limits: wire::Limits,
) -> impl Fn(&[u8]) -> Result<Incoming, wire::WireError> + Send + Sync + 'static {
    move |bytes| wire::decode(bytes, &limits).map(|message| (message, bytes.len()))
}

/// A rendered tile as the renderer posts it back: what was asked, what came out, and when the
/// rendering thread began and ended it (the Gantt charts' bars: the loop takes a result some
/// time after its end, and the time between one tile's end and the next one's start is the
/// hand-over between the threads).
pub(crate) type Rendered = (WorkItem, tracer::TileOutput, std::ops::Range<Instant>);

/// Renders tiles on a rayon pool of its own and posts the results back to the async loop.
/// Rendering never runs on a tokio worker: a tile can take seconds.
pub(crate) struct Renderer {
    pool: rayon::ThreadPool,
    world: Arc<World>,
    done: mpsc::UnboundedSender<Rendered>,
}

impl Renderer {
    pub(crate) fn new(
        threads: usize,
        world: Arc<World>,
    ) -> std::io::Result<(Self, mpsc::UnboundedReceiver<Rendered>)> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .thread_name(|i| format!("render-{i}"))
            .build()
            .map_err(std::io::Error::other)?;
        let (done, results) = mpsc::unbounded_channel();
        Ok((Self { pool, world, done }, results))
    }

    /// Renders `item`.
    fn submit(&self, item: WorkItem) {
        let world = self.world.clone();
        let done = self.done.clone();
        self.pool.spawn(move || {
            let started = Instant::now();
            let rect = bundle::tracer_rect(item.tile.rect);
            let output = tracer::render_tile(&world, item.frame.0, rect);
            // The loop may be gone at shutdown; the tile is then simply not needed.
            let _ = done.send((item, output, started..Instant::now()));
        });
    }
}

/// Which connection is which peer. A connection is known by its peer only after the handshake.
#[derive(Default)]
pub(crate) struct Peers {
    by_conn: BTreeMap<ConnId, PeerId>,
    by_peer: BTreeMap<PeerId, ConnId>,
}

impl Peers {
    pub(crate) fn bind(&mut self, conn: ConnId, peer: PeerId) {
        self.by_conn.insert(conn, peer);
        self.by_peer.insert(peer, conn);
    }

    pub(crate) fn peer(&self, conn: ConnId) -> Option<PeerId> {
        self.by_conn.get(&conn).copied()
    }

    pub(crate) fn conn(&self, peer: PeerId) -> Option<ConnId> {
        self.by_peer.get(&peer).copied()
    }

    /// Forgets `conn`; returns its peer if that peer has no newer connection.
    pub(crate) fn forget(&mut self, conn: ConnId) -> Option<PeerId> {
        let peer = self.by_conn.remove(&conn)?;
        if self.by_peer.get(&peer) == Some(&conn) {
            self.by_peer.remove(&peer);
            return Some(peer);
        }
        None
    }

    pub(crate) fn ids(&self) -> impl Iterator<Item = PeerId> + '_ {
        self.by_peer.keys().copied()
    }
}

/// What one step of the loop produced that the role above it must handle.
pub(crate) enum Step {
    /// A core event (frame complete, peer failed, ...).
    Core(CoreEvent),
    /// A message the core does not take (handshake, scene, goodbye), from a connection.
    Control { conn: ConnId, message: Message },
    /// A connection completed its TLS handshake.
    Connected {
        conn: ConnId,
        certificate: PeerCertificate,
        remote: std::net::SocketAddr,
        outbound: bool,
    },
    /// A connection is gone (the core has already been told if it was a known peer's).
    Closed { conn: ConnId, reason: CloseReason },
    /// The transport stopped.
    Stopped,
}

/// The machinery of one peer: core, link, renderer, timer.
pub(crate) struct Session {
    pub(crate) core: Core,
    pub(crate) link: Link<Incoming>,
    events: mpsc::Receiver<NetEvent<Incoming>>,
    pub(crate) peers: Peers,
    renderer: Option<Renderer>,
    results: Option<mpsc::UnboundedReceiver<Rendered>>,
    epoch: Instant,
    pending: std::collections::VecDeque<Step>,
    pub(crate) local_tiles: Vec<LocalTile>,
    /// Messages on their way out, each sent by a task of its own.
    sends: tokio::task::JoinSet<()>,
}

impl Session {
    /// Binds this peer's endpoint on `listen` and makes its core, as `identity` and `options`
    /// say. Must be called within a tokio runtime.
    pub(crate) fn bind(
        listen: SocketAddr,
        identity: &PeerIdentity,
        options: &Options,
    ) -> Result<Self, NodeError> {
        let (link, events) = Link::bind(
            listen,
            identity,
            options.net.clone(),
            decoder(options.limits.clone()),
        )?;
        let me = PeerId(identity.index());
        let core = Core::new(me, options.threads, options.core.clone(), options.seed);
        Ok(Self {
            core,
            link,
            events,
            peers: Peers::default(),
            renderer: None,
            results: None,
            epoch: Instant::now(),
            pending: Default::default(),
            local_tiles: Vec::new(),
            sends: tokio::task::JoinSet::new(),
        })
    }

    /// Time since the session started: the core's clock, read only here.
    pub(crate) fn now(&self) -> Duration {
        self.epoch.elapsed()
    }

    /// `peer` is connected on `conn`: the core learns of it with the round trip QUIC's handshake
    /// measured, so that an owner times the peer's first answer by it (a silence timeout
    /// shorter than the link's round trip would otherwise fail the peer at its first tiles).
    pub(crate) fn connected(&mut self, conn: ConnId, peer: PeerId) {
        let now = self.now();
        if let Some(rtt) = self.link.rtt(conn) {
            self.core.handle_rtt(peer, rtt);
        }
        self.core.handle_peer_connected(now, peer);
    }

    /// The instant [`Session::now`] counts from, to turn a state machine's deadline into a timer.
    pub(crate) fn epoch(&self) -> Instant {
        self.epoch
    }

    /// Waits until every message sent so far has been delivered (or failed to be).
    pub(crate) async fn drain_sends(&mut self) {
        while self.sends.join_next().await.is_some() {}
    }

    pub(crate) fn set_renderer(
        &mut self,
        renderer: Renderer,
        results: mpsc::UnboundedReceiver<Rendered>,
    ) {
        self.renderer = Some(renderer);
        self.results = Some(results);
    }

    /// Sends a message to a connection, without waiting: every message has its own stream, so
    /// order between messages is not kept anyway, and a slow peer must not stall the loop.
    pub(crate) fn send_conn(&mut self, conn: ConnId, message: &Message) {
        let bytes = wire::encode(message);
        self.core.record_bytes(bytes.len() as u64, 0);
        let link = self.link.clone();
        let kind = message.kind();
        // Reap the sends that are done, so the set holds only those in flight.
        while self.sends.try_join_next().is_some() {}
        self.sends.spawn(async move {
            // Delivered, not only handed to QUIC: `drain_sends` before a close then waits for
            // the peer to have every message (see `Link::send_delivered`).
            if let Err(error) = link.send_delivered(conn, &bytes).await {
                tracing::debug!(%error, kind, "a message was not sent");
            }
        });
    }

    pub(crate) fn send(&mut self, peer: PeerId, message: &Message) {
        match self.peers.conn(peer) {
            Some(conn) => self.send_conn(conn, message),
            None => tracing::debug!(%peer, kind = message.kind(), "no connection to send on"),
        }
    }

    pub(crate) fn close(&mut self, conn: ConnId, code: CloseCode, reason: &str) {
        tracing::warn!(?conn, ?code, "closing a connection: {reason}");
        self.link.close(conn, code, reason);
    }

    /// Drains the core's outputs: messages out, tiles to the renderer, events up.
    pub(crate) fn flush(&mut self) {
        while let Some((peer, message)) = self.core.poll_transmit() {
            self.send(peer, &message);
        }
        while let Some(item) = self.core.poll_work() {
            match &self.renderer {
                Some(renderer) => renderer.submit(item),
                None => tracing::error!("the core handed out work before the scene was loaded"),
            }
        }
        while let Some(event) = self.core.poll_event() {
            self.pending.push_back(Step::Core(event));
        }
    }

    /// Waits for the next thing that happens and returns what the role must handle.
    pub(crate) async fn step(&mut self) -> Step {
        loop {
            if let Some(step) = self.pending.pop_front() {
                return step;
            }
            let deadline = self
                .core
                .poll_timeout()
                .map(|t| tokio::time::Instant::from_std(self.epoch + t));
            let sleep = async {
                match deadline {
                    Some(deadline) => tokio::time::sleep_until(deadline).await,
                    None => std::future::pending().await,
                }
            };
            let results = async {
                match &mut self.results {
                    Some(results) => results.recv().await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                event = self.events.recv() => match event {
                    None => return Step::Stopped,
                    Some(event) => if let Some(step) = self.on_net(event) { return step; },
                },
                Some((item, output, took)) = results => {
                    let since_epoch = |at: Instant| at.saturating_duration_since(self.epoch);
                    let now = self.now();
                    self.local_tiles.push(LocalTile {
                        frame: item.frame.0,
                        tile: item.tile.id.0,
                        rect: item.tile.rect,
                        piece: item.tile.piece != runtime_core::wire::Piece::WHOLE,
                        start: since_epoch(took.start),
                        end: since_epoch(took.end),
                    });
                    let result = bundle::tile_result(item.frame, &item.tile, &output);
                    self.core.handle_tile_rendered(now, result);
                }
                () = sleep => {
                    let now = self.now();
                    self.core.handle_timeout(now);
                }
            }
            self.flush();
        }
    }

    fn on_net(&mut self, event: NetEvent<Incoming>) -> Option<Step> {
        match event {
            NetEvent::Connected {
                conn,
                remote,
                direction,
                certificate,
            } => Some(Step::Connected {
                conn,
                certificate,
                remote,
                outbound: direction == crate::net::Direction::Outbound,
            }),
            NetEvent::Closed { conn, reason } => {
                let peer = self.peers.forget(conn);
                if let Some(peer) = peer {
                    tracing::info!(%peer, ?reason, "peer left");
                    let now = self.now();
                    self.core.handle_peer_lost(now, peer);
                    self.flush();
                }
                Some(Step::Closed { conn, reason })
            }
            NetEvent::Message {
                conn,
                message: (message, len),
            } => {
                self.core.record_bytes(0, len as u64);
                let Some(peer) = self.peers.peer(conn) else {
                    return Some(Step::Control { conn, message });
                };
                // QUIC measures the path on every packet; the core's own samples come only from
                // steal exchanges, so without this it would plan with `initial_rtt` for a while.
                // Before the session check, so that an owner knows a new peer's round trip by
                // the time it deals it its first tiles.
                if let Some(rtt) = self.link.rtt(conn) {
                    self.core.handle_rtt(peer, rtt);
                }
                if message.is_session() {
                    return Some(Step::Control { conn, message });
                }
                let now = self.now();
                if let Err(error) = self.core.handle_message(now, peer, message) {
                    self.close(conn, CloseCode::Protocol, &error.to_string());
                }
                None
            }
        }
    }
}
