//! The scheduling core of a peer: queues, prefetch, stealing and frame completion, as a state
//! machine with no I/O and no clock.
//!
//! As quinn-proto is to quinn: the driver feeds it inputs (`handle_*`, each with the current
//! time) and drains its outputs (`poll_*`); the core never blocks, sleeps, reads a clock or
//! touches a socket. That is what lets the simulator run thousands of cores in virtual time and
//! tests script every race, and it makes a core's behaviour a pure function of its seed and
//! its inputs: maps are ordered, randomness comes from a seeded generator.
//!
//! Every peer runs a worker (`worker.rs`, `steal.rs`, and what it has measured in
//! `estimates.rs`); the peer that starts a frame also keeps its ledger (`ledger.rs`). The
//! owner's worker and ledger talk through the same messages as remote peers do, delivered
//! locally, so the owner needs no special cases. The protocol is described in `README.md`
//! beside this file.

mod config;
mod estimates;
mod event;
mod ledger;
mod pieces;
mod steal;
pub mod testing;
mod worker;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

pub use config::{Config, RELEARN_BOUND, Speculation, VictimOrder};
pub use event::{Audit, Event, Failure, Fault, FrameError, PeerStats, ProtocolError};

use crate::rng::SplitMix;
use crate::wire::{self, FrameId, Message, PeerId, TileResult, TileSpec};
use estimates::Estimates;
use ledger::Ledger;
use worker::Worker;

/// A tile for the local renderer. Render it and give the result to
/// [`Core::handle_tile_rendered`]. Why a type of its own: a [`TileSpec`] travels inside a message
/// that names its frame, but work handed to a renderer stands alone, so it carries the frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkItem {
    /// The frame the tile belongs to.
    pub frame: FrameId,
    /// The tile or piece to render.
    pub tile: TileSpec,
}

/// One peer's scheduling state. See the module documentation and `README.md`.
pub struct Core {
    config: Config,
    connected: BTreeSet<PeerId>,
    /// The round trip to each peer, as the transport last measured it (`handle_rtt`).
    round_trips: BTreeMap<PeerId, Duration>,
    worker: Worker,
    /// The ledgers of the frames this peer owns that are still running, oldest first.
    ledgers: BTreeMap<FrameId, Ledger>,
    /// The newest frame this peer has started as owner, running or complete.
    newest_owned: Option<FrameId>,
    out: Outbox,
}

impl Core {
    /// A core for peer `me`, whose renderer works on `slots` tiles at once. `seed` drives victim
    /// choice; the core mixes `me` into it, so a cluster may give every peer the same seed.
    pub fn new(me: PeerId, slots: usize, config: Config, seed: u64) -> Self {
        let estimates = Estimates::new(&config, SplitMix::stream(seed, u64::from(me.0)));
        Self {
            config,
            connected: BTreeSet::new(),
            round_trips: BTreeMap::new(),
            worker: Worker::new(me, slots, estimates),
            ledgers: BTreeMap::new(),
            newest_owned: None,
            out: Outbox::new(me),
        }
    }

    /// The id of the peer this core schedules for.
    pub fn id(&self) -> PeerId {
        self.worker.me
    }

    /// The policy the core was built with.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The oldest frame this peer is working on, if any.
    pub fn frame(&self) -> Option<FrameId> {
        self.worker.oldest()
    }

    /// (Owner) the frames this peer started that have not completed yet, oldest first.
    pub fn running_frames(&self) -> impl Iterator<Item = FrameId> + '_ {
        self.ledgers.keys().copied()
    }

    /// (Owner) every result of running `frame` accepted so far, in tile order (`None` if the
    /// frame is not running here): what a checkpoint keeps, for [`Core::resume_frame`].
    pub fn accepted(&self, frame: FrameId) -> Option<Vec<TileResult>> {
        self.ledgers.get(&frame).map(Ledger::accepted)
    }

    /// Tiles handed to the renderer (or ready to be) and not yet returned.
    pub fn in_flight(&self) -> usize {
        self.worker.in_flight.len()
    }

    /// (Owner) starts `frame`: `assignments` maps each participant (this peer included, if it
    /// renders) to its initial tiles, typically a contiguous run of partition leaves in order.
    /// Every participant hands its renderer pieces of at most `render_pixels` pixels (larger
    /// tiles half by half); `u64::MAX` renders tiles whole. Earlier frames may still be running:
    /// every peer renders the oldest frame's work first.
    pub fn start_frame(
        &mut self,
        now: Duration,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
        render_pixels: u64,
    ) -> Result<(), FrameError> {
        self.resume_frame(now, frame, assignments, render_pixels, Vec::new())
    }

    /// (Owner) [`Core::start_frame`], with `done`: results of the frame kept from a render
    /// that was stopped (a checkpoint of [`Core::accepted`]). They count as received; tiles
    /// they cover are given to nobody, and the frame completes at once if they cover it all.
    pub fn resume_frame(
        &mut self,
        now: Duration,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
        render_pixels: u64,
        done: Vec<TileResult>,
    ) -> Result<(), FrameError> {
        let newest = self.worker.newest().max(self.newest_owned);
        if let Some(newest) = newest.filter(|&newest| frame <= newest) {
            return Err(FrameError::NotNewer { frame, newest });
        }
        let mut seen = BTreeSet::new();
        for (peer, tiles) in &assignments {
            if *peer != self.id() && !self.connected.contains(peer) {
                return Err(FrameError::UnknownPeer(*peer));
            }
            for tile in tiles {
                let limits = wire::Limits {
                    max_tile_pixels: u64::MAX,
                    ..wire::Limits::default()
                };
                let valid = wire::check_rect(tile.rect, &limits).is_ok()
                    && wire::check_cost(tile.predicted).is_ok()
                    && tile.piece == wire::Piece::WHOLE;
                if !valid {
                    return Err(FrameError::InvalidTile(tile.id));
                }
                if !seen.insert(tile.id) {
                    return Err(FrameError::DuplicateTile(tile.id));
                }
            }
        }
        if seen.is_empty() {
            return Err(FrameError::NoTiles);
        }
        let ledger = Ledger::start(
            now,
            self.id(),
            frame,
            assignments,
            render_pixels.max(1),
            &self.config,
            &self.round_trips,
            done,
            &mut self.out,
        );
        self.ledgers.insert(frame, ledger);
        self.newest_owned = Some(frame);
        self.settle(now);
        Ok(())
    }

    /// A message from `from`. On error the message was ignored, and the driver should close the
    /// connection (then report it with [`Core::handle_peer_lost`]).
    pub fn handle_message(
        &mut self,
        now: Duration,
        from: PeerId,
        message: Message,
    ) -> Result<(), ProtocolError> {
        self.worker.stats.messages_received += 1;
        for ledger in self.ledgers.values_mut() {
            ledger.heard(now, from);
        }
        let result = self.dispatch(now, from, message);
        self.settle(now);
        result
    }

    /// The local renderer finished a tile that [`Core::poll_work`] handed out.
    pub fn handle_tile_rendered(&mut self, now: Duration, result: TileResult) {
        let (worker, mut cx) = self.split(now);
        worker.on_tile_rendered(&mut cx, result);
        self.settle(now);
    }

    /// Call when `now` reaches [`Core::poll_timeout`] (calling it earlier is harmless).
    pub fn handle_timeout(&mut self, now: Duration) {
        let (worker, mut cx) = self.split(now);
        worker.thief_timeout(&mut cx);
        worker.heartbeat(&mut cx);
        for ledger in self.ledgers.values_mut() {
            ledger.on_timeout(now, &mut self.out);
        }
        self.settle(now);
    }

    /// A connection to `peer` is up (after the driver's handshake and scene transfer). On the
    /// owner, a peer that joins while frames run takes part in them from now on (see the
    /// protocol's *Joining and leaving*).
    pub fn handle_peer_connected(&mut self, now: Duration, peer: PeerId) {
        if peer != self.id() {
            self.connected.insert(peer);
            for ledger in self.ledgers.values_mut() {
                ledger.admit(now, peer, &mut self.out);
            }
        }
        self.settle(now);
    }

    /// (Peer) leaves the render `owner` owns, as a peer asked to stop (SIGTERM) does: it tells
    /// the owner ([`Message::Leaving`]), drops every tile it has not handed its renderer (the
    /// owner re-issues them), takes and gives no more work, and reports [`Event::Left`] once
    /// the tiles in its renderer are rendered and their results sent.
    pub fn leave(&mut self, now: Duration, owner: PeerId) {
        let (worker, mut cx) = self.split(now);
        worker.leave(&mut cx, owner);
        self.settle(now);
    }

    /// Whether [`Core::leave`] was called.
    pub fn is_leaving(&self) -> bool {
        self.worker.leaving
    }

    /// The connection to `peer` is gone: closed, timed out, or said `Goodbye`.
    pub fn handle_peer_lost(&mut self, now: Duration, peer: PeerId) {
        if peer == self.id() || !self.connected.remove(&peer) {
            return;
        }
        let (worker, mut cx) = self.split(now);
        worker.on_peer_lost(&mut cx, peer);
        for ledger in self.ledgers.values_mut() {
            ledger.on_peer_lost(now, peer, Failure::Lost, &mut self.out);
        }
        self.settle(now);
    }

    /// A round-trip measurement of the link to `peer` from the transport (quinn's path RTT,
    /// for instance): an owner counts `peer`'s silence from a round trip after each assignment
    /// it sends it, and this peer plans its steals with it until it has timed a steal exchange
    /// of its own (which includes the victim's time to answer, as the link's does not).
    pub fn handle_rtt(&mut self, peer: PeerId, rtt: Duration) {
        self.worker.estimates.seed_rtt(rtt);
        // The driver reports a round trip with every message, mostly the one it reported last:
        // the ledgers, which took the table when they opened, need only the changes.
        if self.round_trips.insert(peer, rtt) == Some(rtt) {
            return;
        }
        for ledger in self.ledgers.values_mut() {
            ledger.set_round_trip(peer, rtt);
        }
    }

    /// Bytes the driver moved for this peer since its last report, for the frame's statistics.
    pub fn record_bytes(&mut self, sent: u64, received: u64) {
        self.worker.stats.bytes_sent += sent;
        self.worker.stats.bytes_received += received;
    }

    /// The next message to send, and to whom.
    pub fn poll_transmit(&mut self) -> Option<(PeerId, Message)> {
        let transmit = self.out.transmits.pop_front()?;
        self.worker.stats.messages_sent += 1;
        Some(transmit)
    }

    /// The next tile for the local renderer. The core hands out at most `slots` at a time.
    pub fn poll_work(&mut self) -> Option<WorkItem> {
        self.worker.poll_work()
    }

    /// The next event for the driver, if any; call until `None` after each `handle_*`.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.out.events.pop_front()
    }

    /// When to call [`Core::handle_timeout`], if ever.
    pub fn poll_timeout(&self) -> Option<Duration> {
        let thief = self.worker.thief_deadline(&self.config);
        let heartbeat = self.worker.heartbeat_due(self.config.heartbeat_interval);
        let owner = self.ledgers.values().filter_map(Ledger::poll_timeout).min();
        [thief, heartbeat, owner].into_iter().flatten().min()
    }

    fn split(&mut self, now: Duration) -> (&mut Worker, Ctx<'_>) {
        let cx = Ctx {
            now,
            config: &self.config,
            connected: &self.connected,
            out: &mut self.out,
        };
        (&mut self.worker, cx)
    }

    fn dispatch(
        &mut self,
        now: Duration,
        from: PeerId,
        message: Message,
    ) -> Result<(), ProtocolError> {
        let kind = message.kind();
        if message.is_session() {
            return Err(ProtocolError::NotForCore { kind });
        }
        let (worker, mut cx) = self.split(now);
        match message {
            Message::Hello { .. }
            | Message::Welcome { .. }
            | Message::Peers { .. }
            | Message::Scene { .. }
            | Message::SceneReady
            | Message::Goodbye { .. } => unreachable!("session messages were refused above"),
            Message::Assign {
                frame,
                peers,
                tiles,
                render_pixels,
            } => worker.on_assign(&mut cx, from, frame, peers, tiles, render_pixels),
            Message::StealRequest { frame, remaining } => {
                worker.on_steal_request(&mut cx, from, frame, &remaining)
            }
            Message::StealGrant { frame, tiles } => worker.on_grant(&mut cx, from, frame, tiles),
            Message::StealRefuse { frame } => worker.on_refuse(&mut cx, from, frame),
            Message::FrameDone { frame } => worker.on_frame_done(&mut cx, from, frame),
            Message::Leaving => {
                // Harmless on a peer that owns nothing: it only stops stealing from `from`.
                worker.forget_victim(from);
                for ledger in self.ledgers.values_mut() {
                    ledger.on_peer_lost(now, from, Failure::Left, &mut self.out);
                }
                self.out.events.push_back(Event::PeerLeaving { peer: from });
            }
            Message::StealNotice {
                frame,
                victim,
                tiles,
                stolen,
            } => {
                if let Some(ledger) = ledger_for(&mut self.ledgers, self.newest_owned, frame, kind)?
                {
                    ledger.on_notice(now, from, victim, &tiles, stolen, &mut self.out);
                }
            }
            Message::Status {
                frame,
                idle,
                assigned,
                stolen,
                done,
            } => {
                if let Some(ledger) = ledger_for(&mut self.ledgers, self.newest_owned, frame, kind)?
                {
                    ledger.on_status(now, from, idle, [assigned, stolen, done], &mut self.out);
                }
            }
            Message::TileDone(result) => {
                if let Some(ledger) =
                    ledger_for(&mut self.ledgers, self.newest_owned, result.frame, kind)?
                {
                    ledger.on_result(now, from, result, &mut self.out);
                }
            }
            Message::FrameStats { frame, stats } => {
                ledger_for(&mut self.ledgers, self.newest_owned, frame, kind)?;
                self.out.events.push_back(Event::PeerStats {
                    frame,
                    peer: from,
                    stats,
                });
            }
        }
        Ok(())
    }

    /// Runs the core to a resting state after an input: delivers messages to itself, fills
    /// renderer slots, steals, reports idleness, retires a completed ledger.
    fn settle(&mut self, now: Duration) {
        loop {
            while let Some(message) = self.out.local.pop_front() {
                let me = self.id();
                if let Err(error) = self.dispatch(now, me, message) {
                    debug_assert!(false, "a message to oneself was refused: {error}");
                    tracing::error!(%error, "a message to oneself was refused");
                }
            }
            self.ledgers.retain(|_, ledger| !ledger.is_complete());
            if self.worker.leaving {
                // Grants and `Assign`s that were on their way when it left: the owner knows it
                // left and re-issues them.
                self.worker.shed();
            }
            self.worker.fill_slots(now, self.config.prefetch_depth);
            let (worker, mut cx) = self.split(now);
            worker.maybe_steal(&mut cx);
            worker.report_idle(&mut cx);
            worker.report_left(&mut cx);
            if self.out.local.is_empty() {
                break;
            }
        }
    }
}

/// The ledger of `frame` if it is running here; `None` for a frame this peer owned and
/// finished (late messages are expected); an error for a frame it never owned. Frames are
/// started in order, so every frame up to the newest started that has no ledger is finished.
fn ledger_for<'a>(
    ledgers: &'a mut BTreeMap<FrameId, Ledger>,
    newest_owned: Option<FrameId>,
    frame: FrameId,
    kind: &'static str,
) -> Result<Option<&'a mut Ledger>, ProtocolError> {
    match ledgers.get_mut(&frame) {
        Some(ledger) => Ok(Some(ledger)),
        None if newest_owned.is_some_and(|newest| frame <= newest) => Ok(None),
        None => Err(ProtocolError::NotOwner { kind, frame }),
    }
}

/// What a handler needs besides the worker: the time, the policy, the connections and the
/// outputs.
struct Ctx<'a> {
    now: Duration,
    config: &'a Config,
    connected: &'a BTreeSet<PeerId>,
    out: &'a mut Outbox,
}

/// The core's outputs. Messages to this peer itself are delivered locally, never transmitted.
struct Outbox {
    me: PeerId,
    transmits: VecDeque<(PeerId, Message)>,
    local: VecDeque<Message>,
    events: VecDeque<Event>,
}

impl Outbox {
    fn new(me: PeerId) -> Self {
        Self {
            me,
            transmits: VecDeque::new(),
            local: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    fn send(&mut self, to: PeerId, message: Message) {
        if to == self.me {
            self.local.push_back(message);
        } else {
            self.transmits.push_back((to, message));
        }
    }
}
