//! The peer's side of the frames it works on: its queues, its renderer's slots, and what it
//! owes each frame's owner.
//!
//! Every peer, the owner included, runs one worker. Several frames may be in flight at once
//! (the owner deals the next frame before the last has completed, so that no peer waits at the
//! end of a frame); each has its own queues, and the worker always renders the oldest frame's
//! work first, so frames still finish in order as far as it is concerned. Within a frame, tiles
//! wait in two queues. `queue` holds the tiles the owner gave it, in partition order, and those
//! it stole after them; it is rendered from the front and given to thieves from the back, so
//! stolen work can move on again to whoever needs it most, as in rayon. `prefetch` holds the
//! next tiles taken from the front of `queue` and committed to this peer's renderer (at most
//! `prefetch_depth` over all frames): never given away, so that a victim cannot be robbed of the
//! work that keeps its renderer busy during its own next steal. Stealing itself lives in
//! `steal.rs`; a peer has one thief, not one per frame.
//!
//! Filling the renderer's slots, taking its results back and relearning a hot tile's cost live
//! in `worker/render.rs`.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use super::estimates::Estimates;
use super::steal::{Round, Thief};
use super::{Ctx, WorkItem};
use crate::peer::event::{Event, PeerStats};
use crate::wire::{FrameId, Message, PeerId, Piece, TileId, TileSpec};

mod render;

/// A piece of work in the renderer: its frame, tile and piece.
pub(super) type FlightKey = (FrameId, TileId, Piece);

pub(super) struct Worker {
    pub(super) me: PeerId,
    pub(super) slots: usize,
    /// The frames this peer works on, oldest first.
    pub(super) frames: BTreeMap<FrameId, FrameState>,
    /// Frames that ended here (their `FrameDone` came, or their owner was lost): their late
    /// `Assign`s and grants are dropped. Frames are few (one per image), so this stays small.
    finished: BTreeSet<FrameId>,
    /// The newest frame this peer has been assigned or told of, running or finished.
    newest: Option<FrameId>,
    /// The live participants of the newest frame, sorted: this peer steals only from them.
    pub(super) peers: Vec<PeerId>,
    /// Tiles handed to the renderer (or waiting in `ready` for the driver to hand over), of any
    /// frame: a tile of a finished frame still occupies its slot until the renderer returns it.
    pub(super) in_flight: BTreeMap<FlightKey, InFlight>,
    ready: VecDeque<WorkItem>,
    pub(super) estimates: Estimates,
    pub(super) thief: Thief,
    pub(super) round: Option<Round>,
    /// Rounds in a row in which every victim refused: the next backoff doubles with each.
    pub(super) fruitless_rounds: u32,
    /// When this peer last sent a frame's owner anything (all frames of a render have one
    /// owner, and any message tells it the peer is alive).
    last_to_owner: Duration,
    /// Counts since the last `FrameStats`, reported and reset when a frame ends.
    pub(super) stats: PeerStats,
    /// Since when `stats` count: the last `FrameStats`, or the first `Assign` after a time with
    /// no frame.
    stats_since: Duration,
    /// This peer is leaving the render ([`super::Core::leave`]): it holds only what its
    /// renderer has, and takes and gives nothing more.
    pub(super) leaving: bool,
    /// Whether [`Event::Left`] was reported.
    left: bool,
}

pub(super) struct FrameState {
    pub(super) id: FrameId,
    pub(super) owner: PeerId,
    pub(super) queue: VecDeque<TileSpec>,
    pub(super) queue_work: f64,
    pub(super) prefetch: VecDeque<TileSpec>,
    pub(super) prefetch_work: f64,
    /// The largest piece handed to the renderer at once, as the owner's newest `Assign` said.
    render_pixels: u64,
    /// Tiles re-predicted costlier than their share of `render_pixels` pays for
    /// ([`Config::relearn_pieces`](super::Config::relearn_pieces)), with the smaller pieces
    /// they are rendered in: a piece that costs `s` times its prediction is cut `s` times finer,
    /// so that its cost is what a normal piece's is and thieves can share a hot spot out.
    hot: BTreeMap<TileId, u64>,
    /// `Assign`s and grants received and `TileDone`s sent this frame: the owner compares them
    /// with what it knows of, to tell a stale idle report from a current one.
    assigned: u32,
    pub(super) stolen: u32,
    done: u32,
    /// The counts of the last idle report, so that it is sent once.
    idle_reported: Option<[u32; 3]>,
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
            frames: BTreeMap::new(),
            finished: BTreeSet::new(),
            newest: None,
            peers: Vec::new(),
            in_flight: BTreeMap::new(),
            ready: VecDeque::new(),
            estimates,
            thief: Thief::Ready,
            round: None,
            fruitless_rounds: 0,
            last_to_owner: Duration::ZERO,
            stats,
            stats_since: Duration::ZERO,
            leaving: false,
            left: false,
        }
    }

    /// Starts leaving: tells `owner`, and drops whatever the renderer has not taken.
    pub(super) fn leave(&mut self, cx: &mut Ctx, owner: PeerId) {
        if self.leaving {
            return;
        }
        self.leaving = true;
        self.send_to_owner(cx, owner, Message::Leaving);
        self.shed();
        self.report_left(cx);
    }

    /// Drops every tile not in the renderer, of every frame: queued, prefetched, and ready but
    /// not yet taken by the driver. Only for a leaving peer, whose owner re-issues them.
    pub(super) fn shed(&mut self) {
        for state in self.frames.values_mut() {
            state.queue.clear();
            state.queue_work = 0.0;
            state.prefetch.clear();
            state.prefetch_work = 0.0;
        }
        for item in std::mem::take(&mut self.ready) {
            self.in_flight
                .remove(&(item.frame, item.tile.id, item.tile.piece));
        }
    }

    /// Reports [`Event::Left`] once a leaving peer's renderer is empty and the answer to a steal
    /// request it sent before leaving is in: a grant must not reach a closed connection, where
    /// only the owner's last safety net would find its tiles; this peer tells the owner of it
    /// instead (the notice), and the owner re-issues it.
    pub(super) fn report_left(&mut self, cx: &mut Ctx) {
        let waiting = matches!(self.thief, Thief::Asking { .. });
        if self.leaving && !self.left && !waiting && self.in_flight.is_empty() {
            self.left = true;
            cx.out.events.push_back(Event::Left);
        }
    }

    /// Stops stealing from `peer`, which is leaving the render.
    pub(super) fn forget_victim(&mut self, peer: PeerId) {
        self.peers.retain(|&other| other != peer);
        if matches!(self.thief, Thief::Asking { victim, .. } if victim == peer) {
            self.give_up_on_victim();
        }
    }

    /// The newest frame this peer has been assigned; the owner never starts an older one.
    pub(super) fn newest(&self) -> Option<FrameId> {
        self.newest
    }

    /// The oldest frame this peer works on.
    pub(super) fn oldest(&self) -> Option<FrameId> {
        self.frames.keys().next().copied()
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
        if self.finished.contains(&frame) {
            tracing::debug!(%frame, %from, "tiles of a finished frame: dropped");
            return;
        }
        if self
            .frames
            .get(&frame)
            .is_some_and(|state| state.owner != from)
        {
            tracing::warn!(%frame, %from, "tiles from a peer that does not own the frame: dropped");
            return;
        }
        let now = cx.now;
        if self.frames.is_empty() {
            // Work after a time with none: the statistics and the busy time count from now.
            self.stats_since = now;
            self.last_to_owner = now;
            self.thief = Thief::Ready;
            self.round = None;
            for flight in self.in_flight.values_mut() {
                flight.accounted_from = flight.accounted_from.max(now);
            }
        }
        if self.newest.is_none_or(|newest| frame >= newest) {
            peers.sort_unstable();
            peers.dedup();
            self.peers = peers;
            self.newest = Some(frame);
        }
        let state = self
            .frames
            .entry(frame)
            .or_insert_with(|| FrameState::new(frame, from));
        state.render_pixels = render_pixels.max(1);
        state.queue_work += tiles.iter().map(|tile| tile.predicted).sum::<f64>();
        state.queue.extend(tiles);
        state.assigned += 1;
        self.new_work();
    }

    /// New work ends a backoff: the thief is not idle any more.
    pub(super) fn new_work(&mut self) {
        if matches!(self.thief, Thief::Backoff { .. }) {
            self.thief = Thief::Ready;
            self.round = None;
        }
        self.fruitless_rounds = 0;
    }

    pub(super) fn on_frame_done(&mut self, cx: &mut Ctx, from: PeerId, frame: FrameId) {
        if self
            .frames
            .get(&frame)
            .is_some_and(|state| state.owner == from)
        {
            self.finish_frame(cx, frame);
        } else if !self.frames.contains_key(&frame) {
            // Messages may arrive in any order: this `FrameDone` overtook our `Assign`, which
            // must now be dropped when it comes.
            self.finished.insert(frame);
        }
        if self.newest.is_none_or(|newest| frame > newest) {
            self.newest = Some(frame);
        }
    }

    /// Ends `frame`: reports the statistics since the last report to its owner and drops its
    /// leftovers.
    fn finish_frame(&mut self, cx: &mut Ctx, frame: FrameId) {
        let Some(state) = self.frames.remove(&frame) else {
            return;
        };
        self.finished.insert(frame);
        let now = cx.now;
        for flight in self.in_flight.values_mut() {
            self.stats.busy += now.saturating_sub(flight.accounted_from);
            flight.accounted_from = now;
        }
        self.drop_unstarted(frame);
        let mut stats = std::mem::take(&mut self.stats);
        stats.slots = self.slots as u32;
        stats.wall = now.saturating_sub(self.stats_since);
        stats.idle = (stats.wall * stats.slots).saturating_sub(stats.busy);
        self.stats.slots = self.slots as u32;
        self.stats_since = now;
        self.last_to_owner = now;
        cx.out
            .send(state.owner, Message::FrameStats { frame, stats });
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

    /// Drops the frames `peer` owned, else stops stealing from `peer`.
    pub(super) fn on_peer_lost(&mut self, cx: &mut Ctx, peer: PeerId) {
        let orphaned: Vec<FrameId> = self
            .frames
            .values()
            .filter(|state| state.owner == peer)
            .map(|state| state.id)
            .collect();
        for frame in orphaned {
            self.frames.remove(&frame);
            self.finished.insert(frame);
            self.drop_unstarted(frame);
            cx.out.events.push_back(Event::OwnerLost { frame });
        }
        self.forget_victim(peer);
    }

    /// Tells each frame's owner, once per change, that this peer holds no work of that frame.
    /// A peer busy with a newer frame is idle in an older one it has finished its part of: the
    /// older frame's owner may then give it backups and re-issues, which it renders first.
    pub(super) fn report_idle(&mut self, cx: &mut Ctx) {
        if self.leaving || matches!(self.thief, Thief::Asking { .. }) {
            // A leaving peer's owner knows it holds nothing for it; a grant on its way may
            // hold work of any frame.
            return;
        }
        let idle: Vec<FrameId> = self
            .frames
            .values()
            .filter(|state| {
                state.queue.is_empty()
                    && state.prefetch.is_empty()
                    && state.idle_reported != Some(state.counts())
            })
            .map(|state| state.id)
            .filter(|&frame| self.frame_in_flight(frame).next().is_none())
            .collect();
        for frame in idle {
            let state = self
                .frames
                .get_mut(&frame)
                .expect("invariant: chosen from the frames just above");
            state.idle_reported = Some(state.counts());
            let (owner, status) = (state.owner, state.status(true));
            self.send_to_owner(cx, owner, status);
        }
    }

    /// Sends a heartbeat if the owner has heard nothing from this peer for a while.
    pub(super) fn heartbeat(&mut self, cx: &mut Ctx) {
        let Some(due) = self.heartbeat_due(cx.config.heartbeat_interval) else {
            return;
        };
        if cx.now >= due {
            let state = self
                .busy_frame()
                .expect("invariant: a heartbeat is due only while some frame holds work");
            let (owner, status) = (state.owner, state.status(false));
            self.send_to_owner(cx, owner, status);
        }
    }

    pub(super) fn heartbeat_due(&self, interval: Duration) -> Option<Duration> {
        self.busy_frame()
            .filter(|state| state.owner != self.me)
            .map(|_| self.last_to_owner + interval)
    }

    /// The oldest frame this peer has not told its owner it is idle in.
    fn busy_frame(&self) -> Option<&FrameState> {
        self.frames
            .values()
            .find(|state| state.idle_reported != Some(state.counts()))
    }

    pub(super) fn send_to_owner(&mut self, cx: &mut Ctx, owner: PeerId, message: Message) {
        self.last_to_owner = cx.now;
        cx.out.send(owner, message);
    }
}

impl FrameState {
    fn new(id: FrameId, owner: PeerId) -> Self {
        Self {
            id,
            owner,
            queue: VecDeque::new(),
            queue_work: 0.0,
            prefetch: VecDeque::new(),
            prefetch_work: 0.0,
            render_pixels: u64::MAX,
            hot: BTreeMap::new(),
            assigned: 0,
            stolen: 0,
            done: 0,
            idle_reported: None,
        }
    }

    /// The next piece for the renderer (or the prefetch), from the front of the queue. A tile
    /// larger than `render_pixels` is rendered half by half: its first half is taken (halved
    /// again while still too large) and the rest stays at the front of the queue, where it is
    /// rendered next unless a thief takes it first. That is how the unrendered part of the tile
    /// a peer is busy with can still move.
    fn pop_queue(&mut self) -> Option<TileSpec> {
        let mut tile = self.queue.pop_front()?;
        let limit = self
            .hot
            .get(&tile.id)
            .copied()
            .unwrap_or(self.render_pixels);
        while tile.rect.area() > limit
            && let Some((first, second)) = tile.halves()
        {
            self.queue.push_front(second);
            tile = first;
        }
        self.queue_work = shrink(self.queue_work, tile.predicted, self.queue.is_empty());
        Some(tile)
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
