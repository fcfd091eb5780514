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

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use super::steal::{Estimates, Round, Thief};
use super::{Ctx, WorkItem};
use crate::peer::event::{Event, PeerStats};
use crate::wire::{FrameId, Message, PeerId, Piece, TileId, TileResult, TileSpec};

/// The smallest piece a hot tile is rendered in ([`FrameState::hot`]), in pixels: below a
/// cost block (8x8), since a hot spot can be a single block; a pixel's value does not depend on
/// its piece, and the owner sums the blocks' counted work over the pieces that cover them.
const HOT_PIECE_PIXELS: u64 = 16;

/// How much costlier than predicted a piece must have been for the rest of its tile to be
/// rendered finer: smaller mispredictions are what every prediction has, and cutting for them
/// only adds pieces, each with its overhead.
const HOT_SCALE: f64 = 4.0;

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

    pub(super) fn on_tile_rendered(&mut self, cx: &mut Ctx, result: TileResult) {
        let Some(flight) = self
            .in_flight
            .remove(&(result.frame, result.tile, result.piece))
        else {
            tracing::warn!(frame = %result.frame, tile = %result.tile, "result of a tile not in flight: dropped");
            return;
        };
        let now = cx.now;
        let took = now.saturating_sub(flight.started);
        self.stats.busy += now.saturating_sub(flight.accounted_from);
        self.stats.tiles_rendered += 1;
        if cx.config.relearn_pieces {
            self.relearn(result.frame, result.tile, flight.predicted, took);
        }
        self.estimates.sample_rate(flight.predicted, took);
        match self.frames.get_mut(&result.frame) {
            Some(state) => {
                state.done += 1;
                let owner = state.owner;
                self.send_to_owner(cx, owner, Message::TileDone(result));
            }
            None => {
                tracing::debug!(frame = %result.frame, tile = %result.tile, "result of a finished frame: dropped")
            }
        }
    }

    /// A piece of `tile` predicted at `predicted` took `took`: the rest of the tile still waiting
    /// here is likely to cost alike, so its prediction is scaled by the piece's actual over its
    /// expected time at this peer's measured pace (before this piece is folded into the pace).
    fn relearn(&mut self, frame: FrameId, tile: TileId, predicted: f64, took: Duration) {
        use super::config::RELEARN_BOUND;
        let Some(expected) = self.estimates.seconds_for(predicted, 1) else {
            return;
        };
        let Some(state) = self.frames.get_mut(&frame) else {
            return;
        };
        if expected <= 0.0 || took.is_zero() {
            return;
        }
        let scale = (took.as_secs_f64() / expected).clamp(1.0 / RELEARN_BOUND, RELEARN_BOUND);
        if scale >= HOT_SCALE {
            let finer = (state.render_pixels as f64 / scale).max(HOT_PIECE_PIXELS as f64) as u64;
            let limit = state.hot.entry(tile).or_insert(state.render_pixels);
            *limit = (*limit).min(finer);
            // A prefetched piece of the tile, cut before it was known to be hot, goes back to
            // the front of the queue to be cut finer: the renderer has not started it.
            let limit = *limit;
            let mut index = state.prefetch.len();
            while index > 0 {
                index -= 1;
                if state.prefetch[index].id == tile && state.prefetch[index].rect.area() > limit {
                    let spec = state
                        .prefetch
                        .remove(index)
                        .expect("invariant: the index is within the prefetch");
                    state.prefetch_work = shrink(
                        state.prefetch_work,
                        spec.predicted,
                        state.prefetch.is_empty(),
                    );
                    state.queue_work += spec.predicted;
                    state.queue.push_front(spec);
                }
            }
        }
        for (queue, work) in [
            (&mut state.queue, &mut state.queue_work),
            (&mut state.prefetch, &mut state.prefetch_work),
        ] {
            for spec in queue.iter_mut().filter(|spec| spec.id == tile) {
                let relearned = spec.predicted * scale;
                *work = (*work + relearned - spec.predicted).max(0.0);
                spec.predicted = relearned;
            }
        }
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

    /// Hands tiles to free renderer slots (from the oldest frame with work waiting: its
    /// `prefetch`, then its `queue`), then tops the frames' prefetches up to `depth` tiles in
    /// all, again from the oldest frame's queue first.
    pub(super) fn fill_slots(&mut self, now: Duration, depth: usize) {
        while self.in_flight.len() < self.slots {
            let Some(state) = self
                .frames
                .values_mut()
                .find(|state| !state.prefetch.is_empty() || !state.queue.is_empty())
            else {
                break;
            };
            let tile = match state.prefetch.pop_front() {
                Some(tile) => {
                    let empty = state.prefetch.is_empty();
                    state.prefetch_work = shrink(state.prefetch_work, tile.predicted, empty);
                    tile
                }
                None => state
                    .pop_queue()
                    .expect("invariant: the frame was chosen for waiting work"),
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
        let mut prefetched: usize = self.frames.values().map(|s| s.prefetch.len()).sum();
        while prefetched < depth {
            let Some(state) = self
                .frames
                .values_mut()
                .find(|state| !state.queue.is_empty())
            else {
                break;
            };
            let tile = state
                .pop_queue()
                .expect("invariant: the frame was chosen for its queue");
            state.prefetch_work += tile.predicted;
            state.prefetch.push_back(tile);
            prefetched += 1;
        }
    }

    /// Tiles of `frame` in the renderer.
    pub(super) fn frame_in_flight(&self, frame: FrameId) -> impl Iterator<Item = &InFlight> {
        self.in_flight
            .range((frame, TileId(0), Piece(0))..=(frame, TileId(u32::MAX), Piece(u64::MAX)))
            .map(|(_, f)| f)
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
