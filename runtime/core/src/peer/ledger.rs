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

use std::collections::BTreeMap;
use std::time::Duration;

use super::Outbox;
use super::event::{Event, Failure, Fault};
use crate::wire::{self, FrameId, Message, PeerId, TileId, TileResult, TileSpec};

pub(super) struct Ledger {
    frame: FrameId,
    me: PeerId,
    started: Duration,
    tiles: BTreeMap<TileId, Entry>,
    missing: usize,
    peers: BTreeMap<PeerId, PeerView>,
    peer_timeout: Duration,
    /// No participant can have been silent too long before this instant: deadlines only move
    /// later as peers are heard from, so the owner scans for silent peers only when it passes.
    next_check: Option<Duration>,
}

struct Entry {
    spec: TileSpec,
    /// Live peers believed to hold the tile; empty once a result is in.
    holders: Vec<PeerId>,
    result: Option<(PeerId, TileResult)>,
}

struct PeerView {
    alive: bool,
    /// The counts `[assigned, stolen, done]` of the peer's newest idle report.
    idle_report: Option<[u32; 3]>,
    assigns_sent: u32,
    /// The highest grant count in the peer's steal notices.
    grants_seen: u32,
    results_received: u32,
    last_heard: Duration,
}

impl Ledger {
    /// Opens the ledger and sends every participant its tiles (this peer's own by local
    /// delivery).
    pub(super) fn start(
        now: Duration,
        me: PeerId,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
        peer_timeout: Duration,
        out: &mut Outbox,
    ) -> Self {
        let mut ledger = Self {
            frame,
            me,
            started: now,
            tiles: BTreeMap::new(),
            missing: 0,
            peers: BTreeMap::new(),
            peer_timeout,
            next_check: Some(now + peer_timeout),
        };
        for (&peer, tiles) in &assignments {
            ledger.peers.insert(peer, PeerView::new(now));
            for spec in tiles {
                let entry = Entry {
                    spec: *spec,
                    holders: vec![peer],
                    result: None,
                };
                ledger.tiles.insert(spec.id, entry);
            }
        }
        ledger.missing = ledger.tiles.len();
        let participants = ledger.live_peers();
        for (peer, tiles) in assignments {
            ledger.send_assign(now, peer, participants.clone(), tiles, out);
        }
        ledger
    }

    pub(super) fn frame(&self) -> FrameId {
        self.frame
    }

    pub(super) fn is_complete(&self) -> bool {
        self.missing == 0
    }

    /// Notes that `peer` is alive.
    pub(super) fn heard(&mut self, now: Duration, peer: PeerId) {
        if let Some(view) = self.peers.get_mut(&peer) {
            view.last_heard = now;
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
            view.idle()
        });
        if let Some(fault) = self.record(now, from, result, out) {
            out.events.push_back(fault);
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
        if result.rect != entry.spec.rect {
            return fault(Fault::WrongRect);
        }
        if wire::check_buffers(&result).is_err() {
            return fault(Fault::BadBuffers);
        }
        match &entry.result {
            // Rendering is deterministic, so an honest duplicate is bit-identical.
            Some((_, kept)) if kept.pixels == result.pixels => None,
            Some((first, _)) => fault(Fault::Mismatch { first: *first }),
            None => {
                entry.result = Some((from, result));
                entry.holders.clear();
                self.missing -= 1;
                if self.missing == 0 {
                    self.complete(now, out);
                }
                None
            }
        }
    }

    /// A thief took `tiles` from `victim`: it holds them now.
    pub(super) fn on_notice(
        &mut self,
        now: Duration,
        thief: PeerId,
        victim: PeerId,
        tiles: &[TileId],
        grants: u32,
        out: &mut Outbox,
    ) {
        let thief_alive = match self.peers.get_mut(&thief) {
            Some(view) => {
                view.grants_seen = view.grants_seen.max(grants);
                view.alive
            }
            None => false,
        };
        // The thief holds work again, so its silence matters again.
        self.watch(now + self.peer_timeout);
        let mut orphans = Vec::new();
        for id in tiles {
            let Some(entry) = self.tiles.get_mut(id).filter(|e| e.result.is_none()) else {
                continue;
            };
            entry.holders.retain(|&holder| holder != victim);
            if thief_alive && !entry.holders.contains(&thief) {
                entry.holders.push(thief);
            }
            if entry.holders.is_empty() {
                orphans.push(*id);
            }
        }
        self.reissue(now, orphans, out);
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
        let mut orphans = Vec::new();
        for (id, entry) in &mut self.tiles {
            let before = entry.holders.len();
            entry.holders.retain(|&holder| holder != peer);
            if before > 0 && entry.holders.is_empty() && entry.result.is_none() {
                orphans.push(*id);
            }
        }
        let reissued = orphans.len();
        self.reissue(now, orphans, out);
        let frame = self.frame;
        out.events.push_back(Event::PeerFailed {
            frame,
            peer,
            reason,
            reissued,
        });
        self.reissue_if_all_idle(now, out);
    }

    /// Declares failed every participant that may hold work and has been silent too long.
    pub(super) fn on_timeout(&mut self, now: Duration, out: &mut Outbox) {
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
        self.next_check
    }

    /// Makes sure the owner looks for silent peers by `deadline`.
    fn watch(&mut self, deadline: Duration) {
        self.next_check = Some(
            self.next_check
                .map_or(deadline, |check| check.min(deadline)),
        );
    }

    /// Participants that may hold work, with the instant their silence becomes a failure.
    fn suspects(&self) -> impl Iterator<Item = (PeerId, Duration)> + '_ {
        self.peers
            .iter()
            .filter(|(peer, view)| **peer != self.me && view.alive && !view.idle())
            .map(|(peer, view)| (*peer, view.last_heard + self.peer_timeout))
    }

    fn reissue_if_all_idle(&mut self, now: Duration, out: &mut Outbox) {
        let all_idle = self
            .peers
            .values()
            .filter(|view| view.alive)
            .all(PeerView::idle);
        if self.missing > 0 && all_idle {
            let missing: Vec<TileId> = self
                .tiles
                .iter()
                .filter(|(_, entry)| entry.result.is_none())
                .map(|(id, _)| *id)
                .collect();
            tracing::info!(frame = %self.frame, tiles = missing.len(), "every peer is idle: re-issuing missing tiles");
            self.reissue(now, missing, out);
        }
    }

    /// Gives `tiles` (in id order) to live participants in contiguous runs: to the idle ones
    /// if any, else to all. With none left alive, the owner takes them itself.
    fn reissue(&mut self, now: Duration, tiles: Vec<TileId>, out: &mut Outbox) {
        if tiles.is_empty() {
            return;
        }
        let live = self.live_peers();
        let idle: Vec<PeerId> = live
            .iter()
            .copied()
            .filter(|p| self.peers[p].idle())
            .collect();
        let targets = match (idle.is_empty(), live.is_empty()) {
            (false, _) => idle,
            (true, false) => live.clone(),
            (true, true) => {
                self.peers.insert(self.me, PeerView::new(now));
                vec![self.me]
            }
        };
        let participants = self.live_peers();
        let run = tiles.len().div_ceil(targets.len());
        for (chunk, &target) in tiles.chunks(run).zip(&targets) {
            let specs = chunk
                .iter()
                .map(|id| {
                    let entry = self
                        .tiles
                        .get_mut(id)
                        .expect("invariant: re-issued ids exist");
                    if !entry.holders.contains(&target) {
                        entry.holders.push(target);
                    }
                    entry.spec
                })
                .collect();
            self.send_assign(now, target, participants.clone(), specs, out);
        }
    }

    /// Sends `peer` tiles. Its silence counts from now: an idle peer sends no heartbeats.
    fn send_assign(
        &mut self,
        now: Duration,
        peer: PeerId,
        peers: Vec<PeerId>,
        tiles: Vec<TileSpec>,
        out: &mut Outbox,
    ) {
        let view = self
            .peers
            .get_mut(&peer)
            .expect("invariant: tiles go to participants");
        view.assigns_sent += 1;
        view.last_heard = view.last_heard.max(now);
        self.watch(now + self.peer_timeout);
        out.send(
            peer,
            Message::Assign {
                frame: self.frame,
                peers,
                tiles,
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
            .map(|entry| {
                entry
                    .result
                    .expect("invariant: complete only when no tile is missing")
            })
            .unzip();
        let elapsed = now.saturating_sub(self.started);
        out.events.push_back(Event::FrameComplete {
            frame: self.frame,
            elapsed,
            results,
            rendered_by,
        });
        for peer in self.live_peers() {
            out.send(peer, Message::FrameDone { frame: self.frame });
        }
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
            last_heard: now,
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
