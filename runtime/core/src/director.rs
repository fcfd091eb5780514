//! The frame owner's per-frame logic, once, for the QUIC node and the simulator alike.
//!
//! For each frame the director asks the balancer for its tiles, deals them to the participants
//! it knows (the owner included), and hands the driver a [`Deal`] to start in the owner's
//! [`Core`](crate::peer::Core). It follows the owner core's events; when the core reports a
//! frame complete, the director hands the driver the frame's pieces (each result with who
//! rendered it, whose share it started in, and what it was predicted to cost), frames always
//! in order. The driver measures them into a cost map (the node from the tiles' counted work,
//! assembled with the pixels; the simulator from its trace) and gives it back with
//! [`Director::handle_measured`], which re-cuts the partition for the frames after. After the
//! last frame it waits for every participant's statistics, or for the participant to leave,
//! or for [`Config::stats_grace`] at most, then reports [`Event::Finished`].
//!
//! Frames overlap: up to [`Config::frames_in_flight`] frames are dealt and not yet measured.
//! The next frame is dealt when the newest running one wanes (the owner's core reports
//! [`FrameWaning`](crate::peer::Event::FrameWaning): a participant ran out of its work, or
//! little of the frame is missing), so that peers finishing their part of a frame start on the
//! next instead of waiting for the frame's last tile, its measurement and a round trip. Every
//! peer renders the oldest frame's work first, and thieves take older work first, so the older
//! frame still ends first. A frame dealt early is cut from the costs measured last: those of
//! the frame two back rather than one.
//!
//! Why the director does not decode cost maps itself: a tile's block costs are the tracer's
//! encoding (opaque bytes to the scheduling code), and the simulator's costs come from a trace,
//! not from rendering; what both drivers share is everything around that measurement.
//!
//! Sans-IO like the core: `handle_*(now, ..)` in, `poll_*` out, no clock, no sockets.
//!
//! The director's knobs and what it hands its driver ([`Config`], [`Deal`], [`Piece`],
//! [`Event`], [`DirectorError`]) are in `director/types.rs`, re-exported here; this file is
//! the state machine.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use balancer::{CostMap, Partitioner, Update};

use crate::peer::Event as CoreEvent;
use crate::wire::{self, FrameId, PeerId, TileId, TileSpec};

mod types;

pub use types::{Config, Deal, DirectorError, Event, Piece};

/// The frame owner's state machine. See the module documentation.
pub struct Director {
    me: PeerId,
    config: Config,
    partitioner: Partitioner,
    /// Remote participants the owner deals to (connected, scene loaded).
    peers: BTreeSet<PeerId>,
    /// The tiles to cut the first frame into instead of the partitioner's: those of a
    /// checkpoint of it (see [`Director::resume_with`]).
    resumed: Option<Vec<balancer::Tile>>,
    /// Participants whose work was backed up as overdue and that have not been heard of since
    /// (a result, or their statistics): a frozen peer would hold up every frame dealt to it, so
    /// it is dealt nothing until it shows it is alive.
    overdue: BTreeSet<PeerId>,
    /// The next frame to deal.
    next: u32,
    /// Frames dealt and running in the owner's core, oldest first.
    running: BTreeMap<FrameId, Running>,
    /// Frames complete but not yet handed to the driver, because an older one is still
    /// running: frames are handed over in order.
    complete: BTreeMap<FrameId, (Event, Vec<balancer::Tile>)>,
    /// Frames handed to the driver and waiting for their measured cost maps, oldest first,
    /// with the tiles they were dealt (to tell how well they were predicted).
    measuring: VecDeque<(FrameId, Vec<balancer::Tile>)>,
    /// How far the last measured frame's tiles missed their predicted costs (see
    /// [`Config::doubt_error`]); `None` before any frame is measured.
    last_error: Option<f64>,
    /// The last frame whose measured costs the balancer took.
    last_measured: Option<u32>,
    /// Every frame is measured; waiting until this instant at most for the last statistics.
    closing: Option<Duration>,
    finished: bool,
    /// The participants of the frame dealt last that have not yet sent their statistics for it
    /// (statistics may arrive before the frame's measurement does).
    unreported: BTreeSet<PeerId>,
    events: VecDeque<Event>,
}

/// A frame running in the owner's core.
struct Running {
    deal: Deal,
    started: Duration,
    faults: usize,
    /// Whether the core reported it waning: then the next frame may be dealt.
    waned: bool,
}

impl Director {
    /// The director of owner `me`, cutting frames with `partitioner`.
    pub fn new(me: PeerId, partitioner: Partitioner, config: Config) -> Self {
        let mut director = Self {
            me,
            partitioner,
            peers: BTreeSet::new(),
            resumed: None,
            overdue: BTreeSet::new(),
            next: config.first,
            running: BTreeMap::new(),
            complete: BTreeMap::new(),
            measuring: VecDeque::new(),
            last_error: None,
            last_measured: None,
            closing: None,
            finished: false,
            unreported: BTreeSet::new(),
            events: VecDeque::new(),
            config,
        };
        if director.next >= director.config.frames {
            director.finish();
        }
        director
    }

    /// The balancer that cuts the frames, for drivers that report its tree or grid.
    pub fn partitioner(&self) -> &Partitioner {
        &self.partitioner
    }

    /// The peers frames are dealt to besides the owner.
    pub fn peers(&self) -> impl Iterator<Item = PeerId> + '_ {
        self.peers.iter().copied()
    }

    /// The first frame ([`Config::first`]) is cut into `tiles`, those of a checkpoint of it
    /// taken by a render that was stopped, so that the checkpoint's results fit its tiles
    /// (the driver hands them to `Core::resume_frame`). The balancer learns from the frame as
    /// from any other.
    pub fn resume_with(&mut self, tiles: Vec<balancer::Tile>) {
        self.resumed = Some(tiles);
    }

    /// The deal of `frame` while it runs: its tiles, for a checkpoint.
    pub fn running_deal(&self, frame: FrameId) -> Option<&Deal> {
        self.running.get(&frame).map(|running| &running.deal)
    }

    /// `peer` is connected and ready to render: it is dealt work from the next frame on.
    pub fn handle_peer_joined(&mut self, _now: Duration, peer: PeerId) {
        if peer != self.me {
            self.peers.insert(peer);
        }
    }

    /// `peer` is gone. The owner's core re-issues whatever it held; the director deals it
    /// nothing more and stops waiting for its statistics.
    pub fn handle_peer_left(&mut self, _now: Duration, peer: PeerId) {
        self.peers.remove(&peer);
        self.overdue.remove(&peer);
        self.unreported.remove(&peer);
        self.settle();
    }

    /// The next frame to start, if the director is ready for one: no frame is running, or the
    /// newest running frame has waned, and fewer than [`Config::frames_in_flight`] frames are
    /// dealt and not measured. The driver starts it with
    /// `core.start_frame(now, deal.frame, deal.assignments, deal.render_pixels)`.
    pub fn poll_deal(&mut self, now: Duration) -> Result<Option<Deal>, DirectorError> {
        if !self.ready_to_deal() {
            return Ok(None);
        }
        // The prediction was aimed, when the last frame was measured, at the frame to be dealt
        // next then; a frame dealt later, before another is measured, lies further ahead.
        if let Some(measured) = self.last_measured {
            self.partitioner.aim(self.ahead_of(measured))?;
        }
        let resumed = self
            .resumed
            .take()
            .filter(|_| self.next == self.config.first);
        let tiles = resumed.clone().unwrap_or_else(|| self.partitioner.tiles());
        let mut participants: Vec<PeerId> = self.peers.difference(&self.overdue).copied().collect();
        participants.push(self.me);
        participants.sort_unstable();
        let assignment = match &resumed {
            Some(tiles) => self
                .partitioner
                .assign_tiles(tiles, participants.len(), None)?,
            None => self.partitioner.assign(participants.len(), None)?,
        };
        let mut initial = vec![self.me; tiles.len()];
        let mut assignments = BTreeMap::new();
        for (&peer, run) in participants.iter().zip(&assignment.runs) {
            let specs = run
                .iter()
                .map(|&index| {
                    initial[index] = peer;
                    TileSpec::whole(
                        TileId(index as u32),
                        tiles[index].rect,
                        tiles[index].predicted,
                    )
                })
                .collect();
            assignments.insert(peer, specs);
        }
        self.unreported = participants.iter().copied().collect();
        let area: u64 = tiles.iter().map(|tile| tile.rect.area()).sum();
        let factor = match self.doubtful() {
            false => self.config.render_piece_factor,
            true => self
                .config
                .doubtful_piece_factor
                .or(self.config.render_piece_factor),
        };
        let render_pixels = match factor {
            Some(factor) if !tiles.is_empty() => ((area as f64 / tiles.len() as f64) * factor)
                .ceil()
                .max(wire::MIN_PIECE_PIXELS as f64)
                as u64,
            _ => u64::MAX,
        };
        let frame = FrameId(self.next);
        let deal = Deal {
            frame,
            tiles,
            initial,
            assignments,
            render_pixels,
        };
        self.next += 1;
        let running = Running {
            deal: deal.clone(),
            started: now,
            faults: 0,
            waned: false,
        };
        if self.running.insert(frame, running).is_some() {
            return Err(DirectorError::DealtTwice { frame });
        }
        Ok(Some(deal))
    }

    /// How many frames after the measured frame `measured` the next one dealt is (at least 1).
    fn ahead_of(&self, measured: u32) -> u32 {
        self.next.saturating_sub(measured).max(1)
    }

    /// Whether the next frame's prediction is doubted (see [`Config::doubt_error`]).
    fn doubtful(&self) -> bool {
        self.last_error
            // A NaN error (a frame of no predicted cost) is doubted too.
            .is_none_or(|error| error.is_nan() || error > self.config.doubt_error)
    }

    fn ready_to_deal(&self) -> bool {
        let unmeasured = self.running.len() + self.complete.len() + self.measuring.len();
        let in_flight = match self.doubtful() {
            false => self
                .config
                .frames_in_flight
                .clamp(1, wire::MAX_FRAMES_IN_FLIGHT),
            true => 1,
        };
        let newest_waned = self
            .running
            .values()
            .next_back()
            .is_none_or(|running| running.waned);
        !self.finished && self.next < self.config.frames && unmeasured < in_flight && newest_waned
    }

    /// An event of the owner's core. The director takes a completion of a running frame
    /// (its results become the pieces of [`Event::FrameComplete`]) and a frame's waning, and
    /// returns every other event, having noted faults and statistics, for the driver to log or
    /// keep.
    pub fn handle_core_event(
        &mut self,
        now: Duration,
        event: CoreEvent,
    ) -> Result<Option<CoreEvent>, DirectorError> {
        match event {
            CoreEvent::FrameComplete {
                frame,
                results,
                rendered_by,
                audit,
                ..
            } if self.running.contains_key(&frame) => {
                let Running { deal, started, .. } = self
                    .running
                    .remove(&frame)
                    .expect("invariant: checked just above");
                let pieces = results
                    .into_iter()
                    .zip(rendered_by)
                    .map(|(result, peer)| {
                        let index = result.tile.0 as usize;
                        // A piece's prediction is its tile's, shared out by area as the
                        // worker that cut it shared it.
                        let predicted = deal.tiles.get(index).map_or(0.0, |tile| {
                            wire::predicted_share(tile.predicted, tile.rect, result.rect)
                        });
                        Piece {
                            initial: deal.initial.get(index).copied().unwrap_or(peer),
                            predicted,
                            result,
                            peer,
                        }
                    })
                    .collect();
                let complete = Event::FrameComplete {
                    frame,
                    elapsed: now.saturating_sub(started),
                    pieces,
                    audit,
                };
                self.complete.insert(frame, (complete, deal.tiles));
                self.hand_over_in_order();
                Ok(None)
            }
            CoreEvent::PeerOverdue { peer, .. } => {
                if peer != self.me {
                    self.overdue.insert(peer);
                }
                Ok(None)
            }
            CoreEvent::PeerResumed { peer, .. } => {
                self.overdue.remove(&peer);
                Ok(None)
            }
            CoreEvent::PeerLeaving { peer } => {
                // Its connection closes once its last results are in; until then it is dealt
                // nothing.
                self.peers.remove(&peer);
                self.overdue.remove(&peer);
                Ok(Some(event))
            }
            CoreEvent::FrameWaning { frame } => {
                if let Some(running) = self.running.get_mut(&frame) {
                    running.waned = true;
                }
                Ok(None)
            }
            event @ CoreEvent::FaultyPeer { .. } => {
                let CoreEvent::FaultyPeer { frame, .. } = event else {
                    unreachable!("matched just above")
                };
                if let Some(running) = self.running.get_mut(&frame) {
                    running.faults += 1;
                    let allowed = 2 * running.deal.tiles.len() + self.config.fault_allowance;
                    if running.faults > allowed {
                        return Err(DirectorError::Faulty {
                            frame,
                            faults: running.faults,
                        });
                    }
                }
                Ok(Some(event))
            }
            CoreEvent::PeerStats { frame, peer, .. } => {
                // Statistics come once the peer has handled a frame's end: it is alive.
                self.overdue.remove(&peer);
                if frame.0 + 1 == self.next {
                    self.unreported.remove(&peer);
                    self.settle();
                }
                Ok(Some(event))
            }
            event => Ok(Some(event)),
        }
    }

    /// Hands completed frames to the driver, oldest first, as long as no older frame runs.
    fn hand_over_in_order(&mut self) {
        while let Some(entry) = self.complete.first_entry() {
            let frame = *entry.key();
            if self
                .running
                .keys()
                .next()
                .is_some_and(|&older| older < frame)
            {
                break;
            }
            let (event, tiles) = entry.remove();
            self.events.push_back(event);
            self.measuring.push_back((frame, tiles));
        }
    }

    /// The measured cost map of the oldest frame that waits for it: the balancer learns from
    /// it, and the frames after may be dealt.
    pub fn handle_measured(
        &mut self,
        now: Duration,
        frame: FrameId,
        map: &CostMap,
    ) -> Result<Update, DirectorError> {
        if self.measuring.front().map(|(waiting, _)| *waiting) != Some(frame) {
            return Err(DirectorError::NotWaiting { frame });
        }
        // The next frame dealt is the first not yet dealt: with a frame in flight it is two
        // after the one measured, and the prediction carries motion on that far.
        let ahead = self.ahead_of(frame.0);
        let update = self.partitioner.observe_ahead(map, ahead)?;
        self.last_measured = Some(frame.0);
        if let Some(motion) = self.partitioner.motion() {
            tracing::debug!(%frame, ahead, dx = motion.dx, dy = motion.dy, "the costs moved");
        }
        let (_, tiles) = self
            .measuring
            .pop_front()
            .expect("invariant: checked just above");
        // A frame cut blind misses by nearly 1, so the frame after it is doubted too: the PBT
        // moves a bounded number of leaves per frame and is still far from the costs after
        // one measurement (on the fast orbit, trusting it loses a tenth of the efficiency).
        let error = prediction_error(&tiles, map);
        tracing::debug!(%frame, error, "how far the frame's tiles missed their predicted costs");
        self.last_error = Some(error);
        let all_measured =
            self.running.is_empty() && self.complete.is_empty() && self.measuring.is_empty();
        if self.next >= self.config.frames && all_measured {
            self.closing = Some(now + self.config.stats_grace);
        }
        self.settle();
        Ok(update)
    }

    /// Call when `now` reaches [`Director::poll_timeout`].
    pub fn handle_timeout(&mut self, now: Duration) {
        if self.closing.is_some_and(|deadline| now >= deadline) {
            self.finish();
        }
    }

    /// When to call [`Director::handle_timeout`], if ever.
    pub fn poll_timeout(&self) -> Option<Duration> {
        self.closing.filter(|_| !self.finished)
    }

    /// The next thing the driver must act on, if any; call until `None` after each `handle_*`.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// True once the director has reported [`Event::Finished`]: every frame handed over, or closing
    /// done.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    fn settle(&mut self) {
        if self.closing.is_some() && self.unreported.is_empty() {
            self.finish();
        }
    }

    fn finish(&mut self) {
        if !self.finished {
            self.finished = true;
            self.events.push_back(Event::Finished);
        }
    }
}

/// How far `tiles` missed their predicted costs on the measured `map`: the sum of
/// |predicted - measured| over the sum measured (0 for a frame that cost nothing).
fn prediction_error(tiles: &[balancer::Tile], map: &CostMap) -> f64 {
    let (missed, measured) = tiles.iter().fold((0.0, 0.0), |(missed, measured), tile| {
        let cost = map.cost(tile.rect);
        (missed + (tile.predicted - cost).abs(), measured + cost)
    });
    if measured > 0.0 {
        missed / measured
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests;
