//! How the owner's ledger gets missing work rendered after all: it watches for silent
//! participants, re-issues tiles whose holders are gone or all idle, backs up overdue tiles on
//! idle peers (speculation), and reports an overdue peer resumed once a result of it is accepted.
//!
//! One unit because these are the ledger's recovery rules, the part that acts on what it
//! believes rather than keeping it up to date: who counts as silent, and where the missing
//! parts of tiles go (`reissue`). `ledger.rs` records results, notices and reports and calls
//! in here.

use std::time::Duration;

use super::{Ledger, PeerView};
use crate::peer::Outbox;
use crate::peer::event::Event;
use crate::wire::{PeerId, TileId, TileSpec};

/// The fewest round trips a peer's silence may last before the owner declares it failed,
/// whatever `Config::peer_timeout` says. On a link of long round trips a live peer falls
/// silent for about one whenever its messages wait on QUIC's congestion window (a burst of
/// results beyond it waits for acknowledgements), so a timeout of a LAN's length there failed
/// live peers at every frame. Three, after QUIC's rule for its own idle timeout, at least
/// three probe timeouts (RFC 9000, section 10.1; a probe timeout is a little longer than a
/// round trip, so this floor is a little shorter than QUIC's).
const SILENCE_ROUND_TRIPS: u32 = 3;

impl Ledger {
    /// Makes sure the owner looks for silent peers by `deadline`.
    pub(super) fn watch(&mut self, deadline: Duration) {
        self.next_check = Some(
            self.next_check
                .map_or(deadline, |check| check.min(deadline)),
        );
    }

    /// The transport's latest measurement of the round trip to `peer`. A shorter one brings
    /// the peer's deadline forward, so the next scan for silent peers comes no later than it.
    pub(in crate::peer) fn set_round_trip(&mut self, peer: PeerId, rtt: Duration) {
        self.round_trips.insert(peer, rtt);
        if let Some(view) = self.peers.get(&peer).filter(|v| v.alive && !v.idle()) {
            let deadline = view.silent_since.saturating_add(self.silence_timeout(peer));
            self.watch(deadline);
        }
    }

    /// The round trip to `peer` as last measured; zero before any measurement, which counts
    /// silence from the instant work was given, as the owner did before it knew round trips.
    pub(super) fn round_trip(&self, peer: PeerId) -> Duration {
        self.round_trips.get(&peer).copied().unwrap_or_default()
    }

    /// How long `peer` may stay silent while it may hold work: `Config::peer_timeout`, and at
    /// least [`SILENCE_ROUND_TRIPS`] round trips of its link.
    pub(super) fn silence_timeout(&self, peer: PeerId) -> Duration {
        self.peer_timeout
            .max(self.round_trip(peer).saturating_mul(SILENCE_ROUND_TRIPS))
    }

    /// Participants that may hold work, with the instant their silence becomes a failure.
    pub(super) fn suspects(&self) -> impl Iterator<Item = (PeerId, Duration)> + '_ {
        self.peers
            .iter()
            .filter(|(peer, view)| **peer != self.me && view.alive && !view.idle())
            .map(|(peer, view)| {
                let deadline = view
                    .silent_since
                    .saturating_add(self.silence_timeout(*peer));
                (*peer, deadline)
            })
    }

    pub(super) fn reissue_if_all_idle(&mut self, now: Duration, out: &mut Outbox) {
        let all_idle = self
            .peers
            .values()
            .filter(|view| view.alive)
            .all(PeerView::idle);
        if self.missing > 0 && all_idle {
            let missing: Vec<TileId> = self
                .tiles
                .iter()
                .filter(|(_, entry)| !entry.complete)
                .map(|(id, _)| *id)
                .collect();
            tracing::info!(frame = %self.frame, tiles = missing.len(), "every peer is idle: re-issuing missing tiles");
            self.audit.reissued += self.reissue(now, missing, out);
        }
    }

    /// Gives the missing parts of `tiles` (in id order) to live participants in contiguous
    /// runs: to the idle ones if any, else to all. With none left alive, the owner takes them
    /// itself. Returns how many of `tiles` had parts to give, for the frame's [`Audit`].
    ///
    /// [`Audit`]: crate::peer::Audit
    pub(super) fn reissue(&mut self, now: Duration, tiles: Vec<TileId>, out: &mut Outbox) -> u32 {
        let mut given = 0;
        let mut parts: Vec<TileSpec> = Vec::new();
        for entry in tiles.iter().filter_map(|id| self.tiles.get(id)) {
            let missing = entry.pieces.missing(&entry.spec);
            given += u32::from(!missing.is_empty());
            parts.extend(missing);
        }
        if parts.is_empty() {
            return 0;
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
        let run = parts.len().div_ceil(targets.len());
        for (chunk, &target) in parts.chunks(run).zip(&targets) {
            for part in chunk {
                let entry = self
                    .tiles
                    .get_mut(&part.id)
                    .expect("invariant: re-issued parts are of the frame's tiles");
                if !entry.holders.contains(&target) {
                    entry.holders.push(target);
                }
            }
            self.send_assign(now, target, participants.clone(), chunk.to_vec(), out);
        }
        given
    }

    /// A live peer reported overdue whose result was just accepted is progressing again:
    /// reported resumed, once. A result it sent before it stalled that arrives only now resumes
    /// it too (the owner cannot tell when a result was sent); if it is still stalled, its work
    /// in the next frame is backed up in turn.
    pub(super) fn resume_if_overdue(&mut self, peer: PeerId, out: &mut Outbox) {
        if let Some(view) = self.peers.get_mut(&peer)
            && view.alive
            && std::mem::take(&mut view.overdue)
        {
            out.events.push_back(Event::PeerResumed {
                frame: self.frame,
                peer,
            });
        }
    }

    /// Looks for overdue participants once some participant is idle (see [`Speculation`]).
    ///
    /// [`Speculation`]: crate::peer::Speculation
    pub(super) fn arm_speculation(&mut self, now: Duration) {
        let Some(speculation) = self.speculation else {
            return;
        };
        if self.next_speculation.is_none() && self.missing > 0 {
            self.next_speculation = Some(now + speculation.min_wait);
        }
    }

    /// Gives idle participants copies of the missing parts of overdue tiles, and looks again
    /// when the next would become overdue. A tile is overdue when its busy holders have made no
    /// progress for `factor` times its predicted time, at the frame's pace so far (predicted
    /// cost received per participant-second), and at least `min_wait`.
    pub(super) fn speculate(&mut self, now: Duration, out: &mut Outbox) {
        let Some(speculation) = self.speculation else {
            return;
        };
        if self.missing == 0 || !self.peers.values().any(PeerView::idle) {
            return;
        }
        let participants = self.peers.values().filter(|view| view.alive).count().max(1);
        let since = self.first_result.unwrap_or(self.started);
        let elapsed = now.saturating_sub(since).as_secs_f64();
        let pace = self.predicted_received / (elapsed * participants as f64);
        if !(pace > 0.0 && pace.is_finite()) {
            // Nothing measured yet: look again once results have set the pace.
            self.next_speculation = Some(now + speculation.min_wait);
            return;
        }
        let mut backups = Vec::new();
        let mut next: Option<Duration> = None;
        let mut overdue = std::collections::BTreeSet::new();
        for (id, entry) in &mut self.tiles {
            if entry.complete || entry.speculated {
                continue;
            }
            // Only tiles some busy holder has are candidates: the rest cost no walk of pieces.
            let busy = entry
                .holders
                .iter()
                .filter_map(|holder| self.peers.get(holder))
                .filter(|view| view.alive && !view.idle());
            let Some(last_progress) = busy.map(|view| view.last_progress).min() else {
                continue;
            };
            let predicted: f64 = entry
                .pieces
                .missing(&entry.spec)
                .iter()
                .map(|p| p.predicted)
                .sum();
            let patience = Duration::try_from_secs_f64(speculation.factor * predicted / pace)
                .unwrap_or(Duration::MAX)
                .max(speculation.min_wait);
            let due = last_progress.saturating_add(patience);
            if now >= due {
                entry.speculated = true;
                backups.push(*id);
                let stalled = entry.holders.iter().filter(|holder| {
                    self.peers.get(holder).is_some_and(|view| {
                        view.alive && !view.idle() && now >= view.last_progress + patience
                    })
                });
                overdue.extend(stalled);
            } else {
                next = Some(next.map_or(due, |n| n.min(due)));
            }
        }
        if !backups.is_empty() {
            tracing::info!(frame = %self.frame, tiles = backups.len(), "backing up overdue tiles on idle peers");
            self.audit.backed_up += self.reissue(now, backups, out);
        }
        for peer in overdue {
            if let Some(view) = self.peers.get_mut(&peer) {
                view.overdue = true;
            }
            out.events.push_back(Event::PeerOverdue {
                frame: self.frame,
                peer,
            });
        }
        self.next_speculation = next.map(|due| due.max(now + speculation.min_wait));
    }
}
