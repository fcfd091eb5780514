//! The renderer's side of a worker: handing tiles to free slots (and topping up the
//! prefetch), taking rendered tiles back and sending them to their owners, and relearning what
//! the rest of a tile will cost from how long a piece of it took.
//!
//! One unit because it is everything that moves work into and out of `in_flight`: the rest of
//! the worker (`worker.rs`) keeps the frames' queues and what the owners are told, and only
//! reads `in_flight` through [`Worker::frame_in_flight`].

use std::time::Duration;

use super::{InFlight, Worker, shrink};
use crate::peer::{Ctx, WorkItem};
use crate::wire::{FrameId, Message, Piece, TileId, TileResult};

/// The smallest piece a hot tile is rendered in ([`FrameState::hot`]), in pixels: below a
/// cost block (8x8), since a hot spot can be a single block; a pixel's value does not depend on
/// its piece, and the owner sums the blocks' counted work over the pieces that cover them.
///
/// [`FrameState::hot`]: super::FrameState::hot
const HOT_PIECE_PIXELS: u64 = 16;

/// How much costlier than predicted a piece must have been for the rest of its tile to be
/// rendered finer: smaller mispredictions are what every prediction has, and cutting for them
/// only adds pieces, each with its overhead.
const HOT_SCALE: f64 = 4.0;

impl Worker {
    pub(in crate::peer) fn on_tile_rendered(&mut self, cx: &mut Ctx, result: TileResult) {
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
        use crate::peer::config::RELEARN_BOUND;
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

    /// Hands tiles to free renderer slots (from the oldest frame with work waiting: its
    /// `prefetch`, then its `queue`), then tops the frames' prefetches up to `depth` tiles in
    /// all, again from the oldest frame's queue first.
    pub(in crate::peer) fn fill_slots(&mut self, now: Duration, depth: usize) {
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
    pub(in crate::peer) fn frame_in_flight(
        &self,
        frame: FrameId,
    ) -> impl Iterator<Item = &InFlight> {
        self.in_flight
            .range((frame, TileId(0), Piece(0))..=(frame, TileId(u32::MAX), Piece(u64::MAX)))
            .map(|(_, f)| f)
    }
}
