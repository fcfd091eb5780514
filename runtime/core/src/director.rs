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

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use balancer::{CostMap, Partitioner, Update};

use crate::peer::{Audit, Event as CoreEvent};
use crate::wire::{self, FrameId, PeerId, TileId, TileResult, TileSpec};

/// The director's policy knobs.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The frame count of the animation: frames are numbered from 0 to `frames - 1`.
    pub frames: u32,
    /// The first frame to deal. The frames before it are done already (a resumed render), so
    /// the director deals `first..frames`. Default 0. The balancer has then no costs of frame
    /// `first - 1` and cuts `first` as it would cut frame 0; pixels do not depend on tiles.
    pub first: u32,
    /// How long after the last frame completes the director waits for participants'
    /// statistics before it finishes without them. Default 1 s: statistics are sent the moment
    /// a peer learns the frame is done, so this only matters for a peer that is dying.
    pub stats_grace: Duration,
    /// Faulty results (a duplicate whose pixels differ, a wrong rectangle) tolerated per frame,
    /// besides two per tile. A renderer that keeps producing results the ledger refuses would
    /// have its tiles re-issued forever; past this the render stops with an error.
    pub fault_allowance: usize,
    /// Peers hand their renderers pieces of at most this many times the frame's mean tile
    /// area; larger tiles are rendered half by half, so that the unrendered part of a tile
    /// stays in a queue a thief can take from. The partition makes large tiles where it
    /// predicts cheap pixels, which is exactly where a misprediction leaves one peer with a
    /// long tile. `None` renders every tile whole.
    pub render_piece_factor: Option<f64>,
    /// Frames dealt and not yet measured, at most. 1 deals each frame once the last is
    /// measured (a barrier between frames); 2, the default, deals the next frame when the
    /// running one wanes. From 1 to [`wire::MAX_FRAMES_IN_FLIGHT`]. Frames overlap only while
    /// the prediction is trusted (see `doubt_error`): a frame dealt early is cut from costs one
    /// frame older, which pays only when costs move slowly.
    pub frames_in_flight: usize,
    /// The prediction is doubted before any frame is measured (tiles cut by area alone: the
    /// first frame, or a resumed render's first), and when the last measured frame's tiles
    /// missed their predicted costs by more than this share of the frame's cost (the sum over
    /// tiles of |predicted - measured|, over the sum measured; 0 is a perfect prediction, 2
    /// the worst). A frame dealt while the prediction is doubted is not overlapped with the
    /// next, and renders in pieces of `doubtful_piece_factor`. Default 0.5: above the error of a
    /// prediction two frames old where costs move slowly (the synthetic orbit's 0.34), below
    /// that of one whose costs move by more than their size each frame (the fast orbit's 0.78).
    pub doubt_error: f64,
    /// A frame dealt while the prediction is doubted renders in pieces of at most this many
    /// times its mean tile area (never below [`wire::MIN_PIECE_PIXELS`]), instead of
    /// `render_piece_factor`: nothing then bounds what one
    /// tile costs, and smaller pieces let thieves share out a costly region the prediction did
    /// not see. `None` uses `render_piece_factor`.
    pub doubtful_piece_factor: Option<f64>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            frames: 1,
            first: 0,
            stats_grace: Duration::from_secs(1),
            fault_allowance: 8,
            render_piece_factor: Some(2.0),
            frames_in_flight: 2,
            doubt_error: 0.5,
            doubtful_piece_factor: Some(0.125),
        }
    }
}

/// One frame as dealt: what the driver starts in the owner's core.
#[derive(Clone, Debug, PartialEq)]
pub struct Deal {
    /// The frame these tiles belong to.
    pub frame: FrameId,
    /// The partition's tiles, by tile id.
    pub tiles: Vec<balancer::Tile>,
    /// The participant each tile was dealt to, by tile id.
    pub initial: Vec<PeerId>,
    /// Each participant's initial tiles, for [`Core::start_frame`](crate::peer::Core::start_frame).
    pub assignments: BTreeMap<PeerId, Vec<TileSpec>>,
    /// The largest piece a participant renders at once (see [`Config::render_piece_factor`]).
    pub render_pixels: u64,
}

impl Deal {
    /// The participants dealt to, in id order.
    pub fn participants(&self) -> impl Iterator<Item = PeerId> + '_ {
        self.assignments.keys().copied()
    }
}

/// One finished tile of a completed frame. Why a type of its own: it is the result the owner
/// kept, still encoded, with who rendered it and what was predicted; the driver decodes and
/// measures it into a `stats::TileStats`.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    /// The accepted result, still as the wire carries it.
    pub result: TileResult,
    /// Who rendered it (sent the accepted result).
    pub peer: PeerId,
    /// Whose initial share it was in; differs from `peer` when it was stolen or re-issued.
    pub initial: PeerId,
    /// The cost the balancer predicted for it.
    pub predicted: f64,
}

/// What the director tells its driver.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Every tile of `frame` is in, `elapsed` after it was dealt; `pieces` cover the image once,
    /// in tile order (a tile that was cut on the way by its pieces, in tree order). The driver
    /// measures them and calls [`Director::handle_measured`].
    FrameComplete {
        /// The frame that is complete.
        frame: FrameId,
        /// Time from the frame's deal to its last piece, on the driver's clock.
        elapsed: Duration,
        /// Every piece of the frame, in the order described above.
        pieces: Vec<Piece>,
        /// How the frame's duplicate results compared with the first.
        audit: Audit,
    },
    /// Every frame is measured and every participant's statistics are in (or it left, or
    /// [`Config::stats_grace`] ran out): the driver may say goodbye and close.
    Finished,
}

/// Why the director stopped the render.
#[derive(Debug, thiserror::Error)]
pub enum DirectorError {
    /// The balancer refused to cut or learn, e.g. a cost map of the wrong size.
    #[error(transparent)]
    Balancer(#[from] balancer::Error),
    /// Too many results of one frame failed their checks to go on trusting the cluster.
    #[error(
        "frame {frame}: {faults} faulty results; a peer keeps sending results that cannot be right"
    )]
    Faulty {
        /// The frame the faults arrived in.
        frame: FrameId,
        /// How many faulty results it had.
        faults: usize,
    },
    /// The driver measured a frame the director was not waiting on, a bug in the driver.
    #[error("{frame} was measured, but it is not the frame waiting for its measurement")]
    NotWaiting {
        /// The frame measured.
        frame: FrameId,
    },
    /// The driver started a frame's deal a second time, a bug in the driver.
    #[error("{frame} was dealt twice")]
    DealtTwice {
        /// The frame dealt twice.
        frame: FrameId,
    },
}

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
    /// (by their statistics): a frozen peer would hold up every frame dealt to it, so it is
    /// dealt nothing until it shows it is alive.
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
