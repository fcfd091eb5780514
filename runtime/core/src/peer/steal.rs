//! Work stealing between peers: when a peer asks, whom it asks, and what a victim gives.
//!
//! A peer steals before it runs dry, not after: when the work it holds would last less than a
//! few round trips (the low-water mark, from its measured work rate and round-trip time), so the
//! grant lands while its renderer is still busy with its prefetched tiles. A victim gives from the
//! far end of its queue, which its own renderer would reach last, about half the difference
//! between its work and the thief's, and refuses when that would not pay for the transfer. The
//! rules are written out in `core/README.md`.

use std::time::Duration;

use super::Ctx;
use super::config::{Config, VictimOrder};
use super::worker::{Worker, shrink};
use crate::rng::SplitMix;
use crate::wire::{FrameId, Message, PeerId, TileSpec};

/// Where a peer's stealing stands within a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Thief {
    /// Not asking anyone; asks as soon as it wants work.
    Ready,
    /// Waiting for `victim`'s answer to a request sent at `sent`.
    Asking { victim: PeerId, sent: Duration },
    /// Every victim of the last round refused; asks again at `until`.
    Backoff { until: Duration },
}

/// A round of requests: over a few peers, victim `start` first, then the others in turn; over
/// many, `victims_per_round` draws (see [`pick_victim`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Round {
    start: usize,
    tried: usize,
}

/// What the thief does next within its round.
enum Pick {
    Victim(PeerId),
    /// The round has asked all it may: back off.
    RoundOver,
    /// No live participant to ask.
    Nobody,
}

/// The next victim of the running round, starting a round if none runs. Costs `O(log P)` per
/// request in a large cluster (no list of candidates is built), so that the simulator's
/// thousands of peers stay cheap.
fn pick_victim(
    round: &mut Option<Round>,
    peers: &[PeerId],
    me: PeerId,
    rng: &mut SplitMix,
    cx: &Ctx,
) -> Pick {
    let eligible = |peer: &PeerId| *peer != me && cx.connected.contains(peer);
    let limit = cx.config.victims_per_round.max(1);
    let few = peers.len() <= limit + 1;
    match cx.config.victims {
        // The live peers after this one by id, wrapping around: all of them when few, the
        // nearest `limit` when many.
        VictimOrder::Ring => {
            let round = *round.get_or_insert(Round { start: 0, tried: 0 });
            if round.tried >= limit {
                return Pick::RoundOver;
            }
            let after = peers.partition_point(|p| *p <= me);
            let ring = peers[after..].iter().chain(&peers[..after]);
            match ring.filter(|p| eligible(p)).nth(round.tried) {
                Some(&peer) => Pick::Victim(peer),
                None if round.tried == 0 => Pick::Nobody,
                None => Pick::RoundOver,
            }
        }
        // Few enough to ask every one, each once, from a random first.
        VictimOrder::RandomStart if few => {
            let victims: Vec<PeerId> = peers.iter().copied().filter(eligible).collect();
            if victims.is_empty() {
                return Pick::Nobody;
            }
            let round = *round.get_or_insert_with(|| Round {
                start: rng.below(victims.len()),
                tried: 0,
            });
            match round.tried < victims.len() {
                true => Pick::Victim(victims[(round.start + round.tried) % victims.len()]),
                false => Pick::RoundOver,
            }
        }
        // Many: `limit` draws. Nearly every participant is a candidate, so a few draws find one;
        // the scan behind them only runs when most have been lost.
        VictimOrder::RandomStart => {
            let round = *round.get_or_insert(Round { start: 0, tried: 0 });
            if round.tried >= limit {
                return Pick::RoundOver;
            }
            for _ in 0..32 {
                let peer = peers[rng.below(peers.len())];
                if eligible(&peer) {
                    return Pick::Victim(peer);
                }
            }
            let victims: Vec<PeerId> = peers.iter().copied().filter(eligible).collect();
            match victims.len() {
                0 => Pick::Nobody,
                n => Pick::Victim(victims[rng.below(n)]),
            }
        }
    }
}

impl Worker {
    /// Predicted work this peer still holds over all its frames: its queues plus what is left
    /// of the tiles in its renderer (assuming they progress at the measured rate).
    pub(super) fn remaining_work(&self, now: Duration) -> f64 {
        self.remaining_by_frame(now).map(|(_, work)| work).sum()
    }

    /// The predicted work this peer still holds of each frame it works on, oldest first.
    pub(super) fn remaining_by_frame(
        &self,
        now: Duration,
    ) -> impl Iterator<Item = (FrameId, f64)> + '_ {
        let rate = self.estimates.slot_rate.unwrap_or(0.0);
        self.frames.values().map(move |state| {
            let in_flight: f64 = self
                .frame_in_flight(state.id)
                .map(|f| {
                    (f.predicted - now.saturating_sub(f.started).as_secs_f64() * rate).max(0.0)
                })
                .sum();
            (state.id, state.queue_work + state.prefetch_work + in_flight)
        })
    }

    /// Whether this peer is below its low-water mark.
    fn wants_work(&self, config: &Config, now: Duration) -> bool {
        if self.frames.is_empty() {
            return false;
        }
        let waiting: usize = self
            .frames
            .values()
            .map(|state| state.queue.len() + state.prefetch.len())
            .sum();
        if (waiting == 0 && self.in_flight.len() < self.slots) || waiting < config.prefetch_depth {
            return true;
        }
        // Out of work of its oldest frame while newer frames keep it busy: that frame's end
        // is still being rendered by others, and taking part of their share ends it sooner.
        if self.frames.len() > 1
            && let Some(oldest) = self.frames.values().next()
            && oldest.queue.is_empty()
            && oldest.prefetch.is_empty()
            && self.frame_in_flight(oldest.id).next().is_none()
        {
            return true;
        }
        let low_water = config.low_water_rtts * self.estimates.rtt.as_secs_f64();
        self.estimates
            .seconds_for(self.remaining_work(now), self.slots)
            .is_some_and(|seconds| seconds < low_water)
    }

    /// Sends a steal request if this peer wants work and may ask. The request names the newest
    /// frame this peer works on: a victim gives from its oldest frame up to that one, so the
    /// older frame's work moves first and a thief is never given a frame it has not been
    /// dealt.
    pub(super) fn maybe_steal(&mut self, cx: &mut Ctx) {
        let Some(newest) = self.frames.keys().next_back().copied() else {
            return;
        };
        match self.thief {
            Thief::Asking { .. } => return,
            Thief::Backoff { until } if cx.now < until => return,
            Thief::Backoff { .. } | Thief::Ready => self.thief = Thief::Ready,
        }
        if self.leaving || !cx.config.steal || !self.wants_work(cx.config, cx.now) {
            return;
        }
        let victim = match pick_victim(
            &mut self.round,
            &self.peers,
            self.me,
            &mut self.estimates.rng,
            cx,
        ) {
            Pick::Victim(victim) => victim,
            Pick::Nobody => return,
            Pick::RoundOver => {
                // Each fruitless round in a row doubles the wait, up to the cap.
                let doublings = self.fruitless_rounds.min(16);
                let backoff = cx
                    .config
                    .steal_backoff
                    .saturating_mul(1 << doublings)
                    .min(cx.config.steal_backoff_max.max(cx.config.steal_backoff));
                self.fruitless_rounds += 1;
                self.thief = Thief::Backoff {
                    until: cx.now + backoff,
                };
                self.round = None;
                return;
            }
        };
        let remaining: Vec<(FrameId, f64)> = self
            .remaining_by_frame(cx.now)
            .take(crate::wire::MAX_FRAMES_IN_FLIGHT)
            .collect();
        self.thief = Thief::Asking {
            victim,
            sent: cx.now,
        };
        self.stats.steal_requests_sent += 1;
        cx.out.send(
            victim,
            Message::StealRequest {
                frame: newest,
                remaining,
            },
        );
    }

    /// Answers a thief working on frames up to `frame`: a grant from the far end of the queue
    /// of the oldest of those frames that has something to give, or a refusal. What a frame
    /// `g` may give is judged by the work the two peers hold of frames up to `g`, which each
    /// renders before it reaches `g`'s end: so a thief that has finished its share of the
    /// oldest frame takes part of the victim's, however much newer work it holds.
    pub(super) fn on_steal_request(
        &mut self,
        cx: &mut Ctx,
        thief: PeerId,
        frame: FrameId,
        thief_remaining: &[(FrameId, f64)],
    ) {
        self.stats.steal_requests_received += 1;
        let mut grant = None;
        if cx.config.steal {
            let mine: Vec<(FrameId, f64)> = self
                .remaining_by_frame(cx.now)
                .take_while(|(id, _)| *id <= frame)
                .collect();
            let mut victim_before = 0.0;
            for (id, work) in mine {
                victim_before += work;
                let thief_before: f64 = thief_remaining
                    .iter()
                    .filter(|(theirs, _)| *theirs <= id)
                    .map(|(_, work)| work)
                    .sum();
                let tiles = self.take_grant(cx.config, id, victim_before - thief_before);
                if !tiles.is_empty() {
                    grant = Some((id, tiles));
                    break;
                }
            }
        }
        let Some((granted, tiles)) = grant else {
            cx.out.send(thief, Message::StealRefuse { frame });
            return;
        };
        self.stats.tiles_given += tiles.len() as u32;
        cx.out.send(
            thief,
            Message::StealGrant {
                frame: granted,
                tiles,
            },
        );
    }

    /// Takes from the back of `frame`'s queue what to give a thief holding `difference` less
    /// work than this peer: as much as fits in half the difference (at most half the queue's
    /// pieces), or nothing when that is worth less than the transfer. A piece too large
    /// to fit is cut in half, and its far half considered, while `split_on_steal` allows and
    /// the halves stay above `min_piece_pixels`. A first piece larger than half the difference
    /// that cannot be cut is still given if it is smaller than the whole difference: the pair
    /// then finishes sooner, and it cannot come back (the thief would hold the lesser share).
    fn take_grant(&mut self, config: &Config, frame: FrameId, difference: f64) -> Vec<TileSpec> {
        let Some(state) = self.frames.get_mut(&frame) else {
            return Vec::new();
        };
        let mut taken: Vec<TileSpec> = Vec::new();
        let mut given = 0.0;
        loop {
            let most = config
                .max_grant_tiles
                .min((state.queue.len() + taken.len()).div_ceil(2));
            if taken.len() >= most {
                break;
            }
            let Some(&tile) = state.queue.back() else {
                break;
            };
            if given + tile.predicted <= difference / 2.0 {
                taken.push(tile);
                given += tile.predicted;
                state.queue.pop_back();
                continue;
            }
            let cuttable = config.split_on_steal
                && tile.rect.area() >= 2 * config.min_piece_pixels.max(1)
                && tile
                    .piece
                    .depth()
                    .is_some_and(|d| d < crate::wire::Piece::MAX_DEPTH);
            if cuttable && let Some((near, far)) = tile.halves() {
                state.queue.pop_back();
                state.queue.push_back(near);
                state.queue.push_back(far);
                continue;
            }
            if taken.is_empty() && tile.predicted < difference {
                taken.push(tile);
                given += tile.predicted;
                state.queue.pop_back();
            }
            break;
        }
        let worth_time = self
            .estimates
            .seconds_for(given, self.slots)
            .is_none_or(|seconds| {
                seconds >= config.min_grant_rtts * self.estimates.rtt.as_secs_f64()
            });
        let state = self
            .frames
            .get_mut(&frame)
            .expect("invariant: matched Some above");
        // Back to front as taken; the queue's order is front to back.
        taken.reverse();
        if given > 0.0 && given >= config.min_steal_cost && worth_time {
            state.queue_work = shrink(state.queue_work, given, state.queue.is_empty());
            taken
        } else {
            state.queue.extend(taken);
            Vec::new()
        }
    }

    /// Keeps granted tiles, however late they come: the victim has already let go of them.
    /// A grant is of a frame this peer was dealt (the victim gives none newer than the request
    /// named); it is dropped only if that frame has ended here.
    pub(super) fn on_grant(
        &mut self,
        cx: &mut Ctx,
        victim: PeerId,
        frame: FrameId,
        tiles: Vec<TileSpec>,
    ) {
        if let Thief::Asking {
            victim: asked,
            sent,
        } = self.thief
            && asked == victim
        {
            self.estimates.sample_rtt(cx.now.saturating_sub(sent));
            if tiles.is_empty() {
                self.stats.steal_requests_refused += 1;
                self.give_up_on_victim();
                return;
            }
            self.thief = Thief::Ready;
            self.round = None;
        }
        if tiles.is_empty() {
            return;
        }
        let Some(state) = self.frames.get_mut(&frame) else {
            tracing::debug!(%frame, %victim, "grant for a finished frame: dropped");
            return;
        };
        state.stolen += 1;
        state.queue_work += tiles.iter().map(|tile| tile.predicted).sum::<f64>();
        let ids = tiles.iter().map(|tile| (tile.id, tile.piece)).collect();
        let count = tiles.len() as u32;
        state.queue.extend(tiles);
        let notice = Message::StealNotice {
            frame,
            victim,
            tiles: ids,
            stolen: state.stolen,
        };
        let owner = state.owner;
        self.fruitless_rounds = 0;
        self.stats.tiles_stolen += count;
        self.send_to_owner(cx, owner, notice);
    }

    pub(super) fn on_refuse(&mut self, cx: &mut Ctx, victim: PeerId, _frame: FrameId) {
        if let Thief::Asking {
            victim: asked,
            sent,
        } = self.thief
            && asked == victim
        {
            self.estimates.sample_rtt(cx.now.saturating_sub(sent));
            self.stats.steal_requests_refused += 1;
            self.give_up_on_victim();
        }
    }

    /// When the pending request times out, or the backoff ends.
    pub(super) fn thief_deadline(&self, config: &Config) -> Option<Duration> {
        if self.frames.is_empty() {
            return None;
        }
        match self.thief {
            Thief::Ready => None,
            Thief::Asking { sent, .. } => Some(sent + self.estimates.steal_timeout(config)),
            Thief::Backoff { until } => Some(until),
        }
    }

    /// Counts an unanswered request as refused. A backoff needs no action here: the next
    /// `maybe_steal` sees that it is over.
    pub(super) fn thief_timeout(&mut self, cx: &mut Ctx) {
        if let Thief::Asking { sent, .. } = self.thief
            && cx.now >= sent + self.estimates.steal_timeout(cx.config)
        {
            self.stats.steal_requests_refused += 1;
            self.give_up_on_victim();
        }
    }

    /// Moves on to the round's next victim.
    pub(super) fn give_up_on_victim(&mut self) {
        self.thief = Thief::Ready;
        if let Some(round) = &mut self.round {
            round.tried += 1;
        }
    }
}
