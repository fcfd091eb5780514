//! The peer's side of a frame: its queues, its renderer's slots, and what it owes the owner.
//!
//! Every peer, the owner included, runs one worker. Its tiles wait in two queues. `queue` holds
//! the tiles the owner gave it, in partition order, and those it stole after them; it is rendered
//! from the front and given to thieves from the back, so stolen work can move on again to
//! whoever needs it most, as in rayon. `prefetch` holds the next `prefetch_depth` tiles, taken
//! from the front of `queue` and committed to this peer's renderer: never given away, so that a
//! victim cannot be robbed of the work that keeps its renderer busy during its own next steal.
//! Stealing itself lives in `steal.rs`.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use super::steal::{Estimates, Round, Thief};
use super::{Ctx, WorkItem};
use crate::peer::event::{Event, PeerStats};
use crate::wire::{FrameId, Message, PeerId, Piece, TileId, TileResult, TileSpec};

/// A piece of work in the renderer: its frame, tile and piece.
pub(super) type FlightKey = (FrameId, TileId, Piece);

pub(super) struct Worker {
    pub(super) me: PeerId,
    pub(super) slots: usize,
    pub(super) frame: Option<FrameState>,
    /// The newest frame this peer has been assigned, running or finished.
    newest: Option<FrameId>,
    /// Tiles handed to the renderer (or waiting in `ready` for the driver to hand over), of any
    /// frame: a tile of a finished frame still occupies its slot until the renderer returns it.
    pub(super) in_flight: BTreeMap<FlightKey, InFlight>,
    ready: VecDeque<WorkItem>,
    pub(super) estimates: Estimates,
    /// Counts since the last `FrameStats`, reported and reset when a frame ends.
    pub(super) stats: PeerStats,
}

pub(super) struct FrameState {
    pub(super) id: FrameId,
    pub(super) owner: PeerId,
    /// The frame's live participants, sorted; this peer steals only from them.
    pub(super) peers: Vec<PeerId>,
    pub(super) queue: VecDeque<TileSpec>,
    pub(super) queue_work: f64,
    pub(super) prefetch: VecDeque<TileSpec>,
    pub(super) prefetch_work: f64,
    /// The largest piece handed to the renderer at once, as the owner's newest `Assign` said.
    render_pixels: u64,
    started: Duration,
    /// `Assign`s and grants received and `TileDone`s sent this frame: the owner compares them
    /// with what it knows of, to tell a stale idle report from a current one.
    assigned: u32,
    pub(super) stolen: u32,
    done: u32,
    pub(super) thief: Thief,
    pub(super) round: Option<Round>,
    /// Rounds in a row in which every victim refused: the next backoff doubles with each.
    pub(super) fruitless_rounds: u32,
    /// The counts of the last idle report, so that it is sent once.
    idle_reported: Option<[u32; 3]>,
    last_to_owner: Duration,
}

pub(super) struct InFlight {
    pub(super) predicted: f64,
    pub(super) started: Duration,
    /// Busy time before this instant is already in `stats.busy`.
    accounted_from: Duration,
}

impl Worker {
    pub(super) fn new(me: PeerId, slots: usize, estimates: Estimates) -> Self {
        let stats = PeerStats {
            slots: slots as u32,
            ..PeerStats::default()
        };
        Self {
            me,
            slots,
            frame: None,
            newest: None,
            in_flight: BTreeMap::new(),
            ready: VecDeque::new(),
            estimates,
            stats,
        }
    }

    /// The newest frame this peer has been assigned; the owner never starts an older one.
    pub(super) fn newest(&self) -> Option<FrameId> {
        self.newest
    }

    pub(super) fn poll_work(&mut self) -> Option<WorkItem> {
        self.ready.pop_front()
    }

    pub(super) fn on_assign(
        &mut self,
        cx: &mut Ctx,
        from: PeerId,
        frame: FrameId,
        mut peers: Vec<PeerId>,
        tiles: Vec<TileSpec>,
        render_pixels: u64,
    ) {
        if self.newest.is_some_and(|newest| frame < newest)
            || (self.newest == Some(frame) && self.frame.is_none())
        {
            tracing::debug!(%frame, %from, "tiles of a finished frame: dropped");
            return;
        }
        let running = self
            .frame
            .as_ref()
            .map(|running| (running.id, running.owner));
        if running.is_some_and(|(id, owner)| id == frame && owner != from) {
            tracing::warn!(%frame, %from, "tiles from a peer that does not own the frame: dropped");
            return;
        }
        if running.is_some_and(|(id, _)| id < frame) {
            // The owner started a new frame, so the old one is complete even though its
            // `FrameDone` has not arrived (or was lost with a connection).
            self.finish_frame(cx);
        }
        peers.sort_unstable();
        peers.dedup();
        let now = cx.now;
        let state = self.frame.get_or_insert_with(|| {
            for flight in self.in_flight.values_mut() {
                flight.accounted_from = flight.accounted_from.max(now);
            }
            FrameState::new(frame, from, now)
        });
        state.peers = peers;
        state.render_pixels = render_pixels.max(1);
        state.queue_work += tiles.iter().map(|tile| tile.predicted).sum::<f64>();
        state.queue.extend(tiles);
        state.assigned += 1;
        // New work ends a backoff: the thief is not idle any more.
        if matches!(state.thief, Thief::Backoff { .. }) {
            state.thief = Thief::Ready;
            state.round = None;
        }
        state.fruitless_rounds = 0;
        self.newest = Some(frame);
    }

    pub(super) fn on_frame_done(&mut self, cx: &mut Ctx, from: PeerId, frame: FrameId) {
        let running = self.frame.as_ref().map(|state| (state.id, state.owner));
        match running {
            Some((id, owner)) if id == frame && owner == from => self.finish_frame(cx),
            // A later frame is done, so this one is too; its own `FrameDone` was lost.
            Some((id, _)) if id < frame => self.finish_frame(cx),
            _ => {}
        }
        if self.newest.is_none_or(|newest| frame > newest) {
            // Messages may arrive in any order: this `FrameDone` overtook our `Assign`, which
            // must now be dropped when it comes.
            self.newest = Some(frame);
        }
    }

    /// Ends the running frame: reports its statistics to its owner and drops its leftovers.
    fn finish_frame(&mut self, cx: &mut Ctx) {
        let Some(state) = self.frame.take() else {
            return;
        };
        let now = cx.now;
        for flight in self.in_flight.values_mut() {
            self.stats.busy += now.saturating_sub(flight.accounted_from);
            flight.accounted_from = now;
        }
        self.drop_unstarted(state.id);
        let mut stats = std::mem::take(&mut self.stats);
        stats.slots = self.slots as u32;
        stats.wall = now.saturating_sub(state.started);
        stats.idle = (stats.wall * stats.slots).saturating_sub(stats.busy);
        self.stats.slots = self.slots as u32;
        cx.out.send(
            state.owner,
            Message::FrameStats {
                frame: state.id,
                stats,
            },
        );
    }

    /// Forgets tiles of `frame` the driver has not yet taken with `poll_work`.
    fn drop_unstarted(&mut self, frame: FrameId) {
        let in_flight = &mut self.in_flight;
        self.ready.retain(|item| {
            let keep = item.frame != frame;
            if !keep {
                in_flight.remove(&(item.frame, item.tile.id, item.tile.piece));
            }
            keep
        });
    }

    pub(super) fn on_tile_rendered(&mut self, cx: &mut Ctx, result: TileResult) {
        let Some(flight) = self
            .in_flight
            .remove(&(result.frame, result.tile, result.piece))
        else {
            tracing::warn!(frame = %result.frame, tile = %result.tile, "result of a tile not in flight: dropped");
            return;
        };
        let now = cx.now;
        self.stats.busy += now.saturating_sub(flight.accounted_from);
        self.stats.tiles_rendered += 1;
        self.estimates
            .sample_rate(flight.predicted, now.saturating_sub(flight.started));
        match &mut self.frame {
            Some(state) if state.id == result.frame => {
                state.done += 1;
                state.send_to_owner(cx, Message::TileDone(result));
            }
            _ => {
                tracing::debug!(frame = %result.frame, tile = %result.tile, "result of a finished frame: dropped")
            }
        }
    }

    /// Drops the running frame if `peer` owned it, else stops stealing from `peer`.
    pub(super) fn on_peer_lost(&mut self, cx: &mut Ctx, peer: PeerId) {
        let Some(state) = &mut self.frame else { return };
        if state.owner == peer {
            let frame = state.id;
            self.frame = None;
            self.drop_unstarted(frame);
            cx.out.events.push_back(Event::OwnerLost { frame });
            return;
        }
        state.peers.retain(|&other| other != peer);
        if matches!(state.thief, Thief::Asking { victim, .. } if victim == peer) {
            state.give_up_on_victim();
        }
    }

    /// Hands tiles to free renderer slots (from `prefetch`, then `queue`), then tops `prefetch`
    /// up to `depth` from the front of `queue`.
    pub(super) fn fill_slots(&mut self, now: Duration, depth: usize) {
        let Some(state) = &mut self.frame else { return };
        while self.in_flight.len() < self.slots {
            let tile = if let Some(tile) = state.prefetch.pop_front() {
                let empty = state.prefetch.is_empty();
                state.prefetch_work = shrink(state.prefetch_work, tile.predicted, empty);
                tile
            } else if let Some(tile) = state.pop_queue() {
                tile
            } else {
                break;
            };
            let flight = InFlight {
                predicted: tile.predicted,
                started: now,
                accounted_from: now,
            };
            self.in_flight
                .insert((state.id, tile.id, tile.piece), flight);
            self.ready.push_back(WorkItem {
                frame: state.id,
                tile,
            });
        }
        while state.prefetch.len() < depth
            && let Some(tile) = state.pop_queue()
        {
            state.prefetch_work += tile.predicted;
            state.prefetch.push_back(tile);
        }
    }

    /// Tiles of the running frame in the renderer.
    pub(super) fn frame_in_flight(&self, frame: FrameId) -> impl Iterator<Item = &InFlight> {
        self.in_flight
            .range((frame, TileId(0), Piece(0))..=(frame, TileId(u32::MAX), Piece(u64::MAX)))
            .map(|(_, f)| f)
    }

    /// Tells the owner, once per change, that this peer holds no work of the frame.
    pub(super) fn report_idle(&mut self, cx: &mut Ctx) {
        let Some(state) = &self.frame else { return };
        let holds_work = !state.queue.is_empty()
            || !state.prefetch.is_empty()
            || self.frame_in_flight(state.id).next().is_some()
            || matches!(state.thief, Thief::Asking { .. });
        let counts = state.counts();
        if holds_work || state.idle_reported == Some(counts) {
            return;
        }
        let state = self.frame.as_mut().expect("invariant: checked just above");
        state.idle_reported = Some(counts);
        let status = state.status(true);
        state.send_to_owner(cx, status);
    }

    /// Sends a heartbeat if the owner has heard nothing from this peer for a while.
    pub(super) fn heartbeat(&mut self, cx: &mut Ctx) {
        let Some(due) = self.heartbeat_due(cx.config.heartbeat_interval) else {
            return;
        };
        if cx.now >= due {
            let state = self
                .frame
                .as_mut()
                .expect("invariant: a heartbeat is due only in a frame");
            let status = state.status(false);
            state.send_to_owner(cx, status);
        }
    }

    pub(super) fn heartbeat_due(&self, interval: Duration) -> Option<Duration> {
        let state = self.frame.as_ref()?;
        let idle = state.idle_reported == Some(state.counts());
        (state.owner != self.me && !idle).then(|| state.last_to_owner + interval)
    }
}

impl FrameState {
    fn new(id: FrameId, owner: PeerId, now: Duration) -> Self {
        Self {
            id,
            owner,
            peers: Vec::new(),
            queue: VecDeque::new(),
            queue_work: 0.0,
            prefetch: VecDeque::new(),
            prefetch_work: 0.0,
            render_pixels: u64::MAX,
            started: now,
            assigned: 0,
            stolen: 0,
            done: 0,
            thief: Thief::Ready,
            round: None,
            fruitless_rounds: 0,
            idle_reported: None,
            last_to_owner: now,
        }
    }

    /// The next piece for the renderer (or the prefetch), from the front of the queue. A tile
    /// larger than `render_pixels` is rendered half by half: its first half is taken (halved
    /// again while still too large) and the rest stays at the front of the queue, where it is
    /// rendered next unless a thief takes it first. That is how the unrendered part of the tile
    /// a peer is busy with can still move.
    fn pop_queue(&mut self) -> Option<TileSpec> {
        let mut tile = self.queue.pop_front()?;
        while tile.rect.area() > self.render_pixels
            && let Some((first, second)) = tile.halves()
        {
            self.queue.push_front(second);
            tile = first;
        }
        self.queue_work = shrink(self.queue_work, tile.predicted, self.queue.is_empty());
        Some(tile)
    }

    pub(super) fn send_to_owner(&mut self, cx: &mut Ctx, message: Message) {
        self.last_to_owner = cx.now;
        cx.out.send(self.owner, message);
    }

    fn counts(&self) -> [u32; 3] {
        [self.assigned, self.stolen, self.done]
    }

    fn status(&self, idle: bool) -> Message {
        let [assigned, stolen, done] = self.counts();
        Message::Status {
            frame: self.id,
            idle,
            assigned,
            stolen,
            done,
        }
    }
}

/// Subtracts a tile's cost from a running sum, resetting it to exactly zero when its queue
/// empties so that rounding errors cannot accumulate over a frame.
pub(super) fn shrink(sum: f64, cost: f64, now_empty: bool) -> f64 {
    if now_empty {
        0.0
    } else {
        (sum - cost).max(0.0)
    }
}
