//! The owner's ledger of a frame: which tiles are done, who is believed to hold the rest, and
//! which participants are alive and idle.
//!
//! The ledger is the safety net under stealing. Peers move tiles among themselves without asking
//! the owner, and tell it afterwards (`StealNotice`); messages can be lost with a connection, so
//! the ledger's view of who holds a tile may be stale. It is therefore only used to decide what
//! to re-issue, and re-issuing is always safe: a tile rendered twice costs time, and the second
//! result is checked against the first. Three rules re-issue a tile: its last known holder is
//! lost, its holder stops answering, or every live participant says it is idle while the tile
//! is still missing (which catches any tile whose whereabouts the ledger got wrong).
//!
//! The recovery rules (watching for silence, re-issuing, and backing up overdue tiles) live in
//! `ledger/recovery.rs`; this file keeps the ledger's state and what it learns from messages.

use std::collections::BTreeMap;
use std::time::Duration;

use super::Outbox;
use super::config::{Config, Speculation};
use super::event::{Audit, Event, Failure, Fault};
use super::pieces::{self, Pieces};
use crate::wire::{self, FrameId, Message, PeerId, Piece, TileId, TileResult, TileSpec};

mod recovery;

pub(super) struct Ledger {
    frame: FrameId,
    me: PeerId,
    started: Duration,
    tiles: BTreeMap<TileId, Entry>,
    missing: usize,
    peers: BTreeMap<PeerId, PeerView>,
    peer_timeout: Duration,
    /// The round trip to each peer, as the transport last measured it ([`PeerView::silent_since`]).
    round_trips: BTreeMap<PeerId, Duration>,
    /// The largest piece a participant hands its renderer at once (sent with every `Assign`).
    render_pixels: u64,
    speculation: Option<Speculation>,
    /// Predicted cost of the results accepted this frame: the frame's pace, for speculation.
    predicted_received: f64,
    /// When the first result was accepted: the pace counts from then, since a frame dealt
    /// while an older one runs is rendered only once peers are done with the older one.
    first_result: Option<Duration>,
    /// The predicted cost of all the frame's tiles.
    predicted_total: f64,
    /// The missing share at which the frame is reported waning (`Config::waning`), and
    /// whether it has been.
    waning: f64,
    waned: bool,
    audit: Audit,
    /// No participant can have been silent too long before this instant: deadlines move later
    /// as peers are heard from, and where one moves earlier (a shorter round trip measured) the
    /// check is brought forward, so the owner scans for silent peers only when it passes.
    next_check: Option<Duration>,
    /// When to look for overdue peers next; armed while some participant is idle.
    next_speculation: Option<Duration>,
}

struct Entry {
    spec: TileSpec,
    /// Live peers believed to hold some part of the tile; empty once it is complete.
    holders: Vec<PeerId>,
    pieces: Pieces,
    complete: bool,
    /// Whether its missing parts were already given to idle peers as backups.
    speculated: bool,
}

struct PeerView {
    alive: bool,
    /// The counts `[assigned, stolen, done]` of the peer's newest idle report.
    idle_report: Option<[u32; 3]>,
    assigns_sent: u32,
    /// The highest grant count in the peer's steal notices.
    grants_seen: u32,
    results_received: u32,
    /// When the peer's silence starts to count: its last message, or the earliest its answer to
    /// the owner's last `Assign` could arrive (a round trip after it was sent), if later.
    silent_since: Duration,
    /// When the peer last sent a result or was given work (an `Assign`, a grant it told of):
    /// how long it has gone without progress, for speculation.
    last_progress: Duration,
    /// Whether the peer was reported overdue ([`Event::PeerOverdue`]) and has sent no result
    /// since: its next result is reported as [`Event::PeerResumed`].
    overdue: bool,
}

impl Ledger {
    /// Opens the ledger and sends every participant its tiles (this peer's own by local
    /// delivery). `done` are results of the frame kept from before (a checkpoint of a render
    /// that was stopped): they are recorded first, as this peer's own, and a tile they cover is
    /// given to nobody; a tile they cover in part is given whole, its duplicate parts audited.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn start(
        now: Duration,
        me: PeerId,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
        render_pixels: u64,
        config: &Config,
        round_trips: &BTreeMap<PeerId, Duration>,
        done: Vec<TileResult>,
        out: &mut Outbox,
    ) -> Self {
        let mut ledger = Self {
            frame,
            me,
            started: now,
            tiles: BTreeMap::new(),
            missing: 0,
            peers: BTreeMap::new(),
            peer_timeout: config.peer_timeout,
            round_trips: round_trips.clone(),
            render_pixels,
            speculation: config.speculation,
            predicted_received: 0.0,
            first_result: None,
            predicted_total: 0.0,
            waning: config.waning,
            waned: false,
            audit: Audit::default(),
            next_check: Some(now + config.peer_timeout),
            next_speculation: None,
        };
        for (&peer, tiles) in &assignments {
            ledger.peers.insert(peer, PeerView::new(now));
            for spec in tiles {
                let entry = Entry {
                    spec: *spec,
                    holders: vec![peer],
                    pieces: Pieces::default(),
                    complete: false,
                    speculated: false,
                };
                ledger.tiles.insert(spec.id, entry);
            }
        }
        ledger.missing = ledger.tiles.len();
        ledger.predicted_total = ledger.tiles.values().map(|e| e.spec.predicted).sum();
        for result in done {
            if let Some(fault) = ledger.record(now, me, result, out) {
                // A checkpoint that does not fit its own partition: its result is not used.
                out.events.push_back(fault);
            }
        }
        if ledger.missing == 0 {
            // The kept results cover the frame: it completed above, and nobody needs tiles.
            return ledger;
        }
        let participants = ledger.live_peers();
        for (peer, mut tiles) in assignments {
            tiles.retain(|spec| ledger.tiles.get(&spec.id).is_some_and(|e| !e.complete));
            ledger.send_assign(now, peer, participants.clone(), tiles, out);
        }
        ledger
    }

    /// Every result accepted so far, in tile order: what a checkpoint of the frame keeps.
    pub(super) fn accepted(&self) -> Vec<TileResult> {
        self.tiles
            .values()
            .flat_map(|entry| entry.pieces.results())
            .cloned()
            .collect()
    }

    /// `peer` joined the render while this frame runs. It takes part from now on with no
    /// tiles of its own (an empty `Assign` names the frame and its participants): it steals
    /// from them, and takes re-issues and backups once it reports itself idle. A peer that was
    /// lost and comes back (a new process with the same identity) starts afresh.
    pub(super) fn admit(&mut self, now: Duration, peer: PeerId, out: &mut Outbox) {
        if peer == self.me || self.peers.get(&peer).is_some_and(|view| view.alive) {
            return;
        }
        self.peers.insert(peer, PeerView::new(now));
        let participants = self.live_peers();
        self.send_assign(now, peer, participants, Vec::new(), out);
    }

    pub(super) fn is_complete(&self) -> bool {
        self.missing == 0
    }

    /// Notes that `peer` is alive.
    pub(super) fn heard(&mut self, now: Duration, peer: PeerId) {
        if let Some(view) = self.peers.get_mut(&peer) {
            view.silent_since = view.silent_since.max(now);
        }
    }

    pub(super) fn on_result(
        &mut self,
        now: Duration,
        from: PeerId,
        result: TileResult,
        out: &mut Outbox,
    ) {
        let counted = self.peers.get_mut(&from).map(|view| {
            view.results_received += 1;
            view.last_progress = now;
            view.idle()
        });
        match self.record(now, from, result, out) {
            Some(fault) => out.events.push_back(fault),
            None => self.resume_if_overdue(from, out),
        }
        // The result may have been what kept the sender's idle report from counting.
        if counted == Some(true) {
            self.reissue_if_all_idle(now, out);
        }
    }

    /// Records a result; returns the fault if it is not acceptable.
    fn record(
        &mut self,
        now: Duration,
        from: PeerId,
        result: TileResult,
        out: &mut Outbox,
    ) -> Option<Event> {
        let (frame, tile) = (self.frame, result.tile);
        let fault = |fault| {
            Some(Event::FaultyPeer {
                frame,
                peer: from,
                tile,
                fault,
            })
        };
        let Some(entry) = self.tiles.get_mut(&tile) else {
            return fault(Fault::UnknownTile);
        };
        if result.piece.rect(entry.spec.rect) != Some(result.rect) {
            return fault(Fault::WrongRect);
        }
        if wire::check_buffers(&result).is_err() {
            return fault(Fault::BadBuffers);
        }
        // Rendering is deterministic, so an honest duplicate is bit-identical wherever it
        // overlaps what is already in.
        let mut duplicate = false;
        for (first, kept) in entry.pieces.overlapping(result.piece) {
            if !pieces::agree(kept, &result) {
                self.audit.disagreed += 1;
                return fault(Fault::Mismatch { first });
            }
            duplicate = true;
        }
        if duplicate {
            self.audit.agreed += 1;
        }
        if entry.complete {
            return None;
        }
        self.predicted_received +=
            wire::predicted_share(entry.spec.predicted, entry.spec.rect, result.rect);
        self.first_result.get_or_insert(now);
        entry.pieces.insert(from, result);
        if self.predicted_received >= (1.0 - self.waning) * self.predicted_total {
            wane(self.frame, &mut self.waned, out);
        }
        if entry.pieces.complete() {
            entry.complete = true;
            entry.holders.clear();
            self.missing -= 1;
            if self.missing == 0 {
                self.complete(now, out);
            }
        }
        None
    }

    /// A thief took `tiles` from `victim`: it holds them now.
    ///
    /// A whole tile moved from the victim to the thief. A piece moved to the thief, but the
    /// victim may still hold other parts of its tile, so it stays a holder: believing a peer
    /// holds a part it does not costs at most a late re-issue (when all are idle, or the
    /// victim is lost or overdue), never a lost tile.
    pub(super) fn on_notice(
        &mut self,
        now: Duration,
        thief: PeerId,
        victim: PeerId,
        tiles: &[(TileId, Piece)],
        grants: u32,
        out: &mut Outbox,
    ) {
        let thief_alive = match self.peers.get_mut(&thief) {
            Some(view) => {
                view.grants_seen = view.grants_seen.max(grants);
                view.last_progress = view.last_progress.max(now);
                view.alive
            }
            None => false,
        };
        // The thief holds work again, so its silence matters again.
        self.watch(now.saturating_add(self.silence_timeout(thief)));
        let mut orphans = Vec::new();
        for (id, piece) in tiles {
            let Some(entry) = self.tiles.get_mut(id).filter(|e| !e.complete) else {
                continue;
            };
            if *piece == Piece::WHOLE {
                entry.holders.retain(|&holder| holder != victim);
            }
            if thief_alive && !entry.holders.contains(&thief) {
                entry.holders.push(thief);
            }
            if entry.holders.is_empty() {
                orphans.push(*id);
            }
        }
        self.audit.reissued += self.reissue(now, orphans, out);
    }

    /// A liveness report, and an idle report if `idle`. Reports may arrive in any order; the
    /// counts only grow, so the newest report is the one with the highest counts.
    pub(super) fn on_status(
        &mut self,
        now: Duration,
        from: PeerId,
        idle: bool,
        counts: [u32; 3],
        out: &mut Outbox,
    ) {
        let Some(view) = self.peers.get_mut(&from) else {
            return;
        };
        if idle {
            let newest = view
                .idle_report
                .map_or(counts, |old| [0, 1, 2].map(|i| old[i].max(counts[i])));
            view.idle_report = Some(newest);
        }
        if view.idle() {
            wane(self.frame, &mut self.waned, out);
            self.arm_speculation(now);
            self.reissue_if_all_idle(now, out);
        }
    }

    pub(super) fn on_peer_lost(
        &mut self,
        now: Duration,
        peer: PeerId,
        reason: Failure,
        out: &mut Outbox,
    ) {
        let Some(view) = self.peers.get_mut(&peer).filter(|view| view.alive) else {
            return;
        };
        view.alive = false;
        if reason != Failure::Left {
            self.audit.failed += 1;
        }
        let mut orphans = Vec::new();
        for (id, entry) in &mut self.tiles {
            let before = entry.holders.len();
            entry.holders.retain(|&holder| holder != peer);
            if before > 0 && entry.holders.is_empty() && !entry.complete {
                orphans.push(*id);
            }
        }
        let reissued = orphans.len();
        self.audit.reissued += self.reissue(now, orphans, out);
        let frame = self.frame;
        out.events.push_back(Event::PeerFailed {
            frame,
            peer,
            reason,
            reissued,
        });
        self.reissue_if_all_idle(now, out);
    }

    /// Declares failed every participant that may hold work and has been silent too long, and
    /// backs up the work of overdue ones.
    pub(super) fn on_timeout(&mut self, now: Duration, out: &mut Outbox) {
        if self.next_speculation.is_some_and(|due| now >= due) {
            self.next_speculation = None;
            self.speculate(now, out);
        }
        if self.next_check.is_none_or(|check| now < check) {
            return;
        }
        let silent: Vec<PeerId> = self
            .suspects()
            .filter(|(_, deadline)| now >= *deadline)
            .map(|(peer, _)| peer)
            .collect();
        for peer in silent {
            self.on_peer_lost(now, peer, Failure::Silent, out);
        }
        self.next_check = self.suspects().map(|(_, deadline)| deadline).min();
    }

    pub(super) fn poll_timeout(&self) -> Option<Duration> {
        [self.next_check, self.next_speculation]
            .into_iter()
            .flatten()
            .min()
    }

    /// Sends `peer` tiles. Its silence counts from a round trip later, when its answer could
    /// first arrive: an idle peer sends no heartbeats.
    fn send_assign(
        &mut self,
        now: Duration,
        peer: PeerId,
        peers: Vec<PeerId>,
        tiles: Vec<TileSpec>,
        out: &mut Outbox,
    ) {
        let round_trip = self.round_trip(peer);
        let view = self
            .peers
            .get_mut(&peer)
            .expect("invariant: tiles go to participants");
        view.assigns_sent += 1;
        let answer = now.saturating_add(round_trip);
        view.silent_since = view.silent_since.max(answer);
        view.last_progress = view.last_progress.max(now);
        self.watch(answer.saturating_add(self.silence_timeout(peer)));
        out.send(
            peer,
            Message::Assign {
                frame: self.frame,
                peers,
                tiles,
                render_pixels: self.render_pixels,
            },
        );
    }

    fn live_peers(&self) -> Vec<PeerId> {
        self.peers
            .iter()
            .filter(|(_, view)| view.alive)
            .map(|(peer, _)| *peer)
            .collect()
    }

    /// Reports the frame and tells every live participant that it is over.
    fn complete(&mut self, now: Duration, out: &mut Outbox) {
        let (rendered_by, results) = std::mem::take(&mut self.tiles)
            .into_values()
            .flat_map(|entry| entry.pieces.into_cover())
            .unzip();
        let elapsed = now.saturating_sub(self.started);
        out.events.push_back(Event::FrameComplete {
            frame: self.frame,
            elapsed,
            results,
            rendered_by,
            audit: self.audit,
        });
        for peer in self.live_peers() {
            out.send(peer, Message::FrameDone { frame: self.frame });
        }
    }
}

/// Reports `frame` waning, once.
fn wane(frame: FrameId, waned: &mut bool, out: &mut Outbox) {
    if !*waned {
        *waned = true;
        out.events.push_back(Event::FrameWaning { frame });
    }
}

impl PeerView {
    fn new(now: Duration) -> Self {
        Self {
            alive: true,
            idle_report: None,
            assigns_sent: 0,
            grants_seen: 0,
            results_received: 0,
            silent_since: now,
            last_progress: now,
            overdue: false,
        }
    }

    /// Whether the peer holds no work, as far as the owner can tell: its newest idle report was
    /// sent after it had received every `Assign` sent to it and every grant the owner has heard
    /// of, and every result it had sent then has arrived. A peer goes from idle to busy only by
    /// receiving one of those, so no explicit "busy" report is needed.
    fn idle(&self) -> bool {
        self.alive
            && self.idle_report.is_some_and(|[assigned, stolen, done]| {
                assigned >= self.assigns_sent
                    && stolen >= self.grants_seen
                    && done <= self.results_received
            })
    }
}
