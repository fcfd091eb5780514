//! The frame owner's per-frame logic, once, for the QUIC node and the simulator alike.
//!
//! For each frame the director asks the balancer for its tiles, deals them to the participants
//! it knows (the owner included), and hands the driver a [`Deal`] to start in the owner's
//! [`Core`](crate::peer::Core). It follows the owner core's events; when the core reports the
//! frame complete, the director hands the driver the frame's pieces (each result with who
//! rendered it, whose share it started in, and what it was predicted to cost). The driver
//! measures them into a cost map (the node from the tiles' counted work, assembled with the
//! pixels; the simulator from its trace) and gives it back with
//! [`Director::handle_measured`], which re-cuts the partition for the next frame. After the
//! last frame it waits for every participant's statistics, or for the participant to leave,
//! or for [`Config::stats_grace`] at most, then reports [`Event::Finished`].
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
    pub frames: u64,
    /// The first frame to deal. The frames before it are done already (a resumed render), so
    /// the director deals `first..frames`. Default 0. The balancer has then no costs of frame
    /// `first - 1` and cuts `first` as it would cut frame 0; pixels do not depend on tiles.
    pub first: u64,
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
}

impl Default for Config {
    fn default() -> Self {
        Self {
            frames: 1,
            first: 0,
            stats_grace: Duration::from_secs(1),
            fault_allowance: 8,
            render_piece_factor: Some(2.0),
        }
    }
}

/// One frame as dealt: what the driver starts in the owner's core.
#[derive(Clone, Debug, PartialEq)]
pub struct Deal {
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

/// One finished tile of a completed frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
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
        frame: FrameId,
        elapsed: Duration,
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
    #[error(transparent)]
    Balancer(#[from] balancer::Error),
    #[error(
        "frame {frame}: {faults} faulty results; a peer keeps sending results that cannot be right"
    )]
    Faulty { frame: FrameId, faults: usize },
    #[error("{frame} was measured, but it is not the frame waiting for its measurement")]
    NotWaiting { frame: FrameId },
}

/// The frame owner's state machine. See the module documentation.
pub struct Director {
    me: PeerId,
    config: Config,
    partitioner: Partitioner,
    /// Remote participants the owner deals to (connected, scene loaded).
    peers: BTreeSet<PeerId>,
    next: u64,
    state: State,
    /// The participants of the frame dealt last that have not yet sent their statistics for it
    /// (statistics may arrive before the frame's measurement does).
    unreported: BTreeSet<PeerId>,
    events: VecDeque<Event>,
}

enum State {
    /// Ready to deal frame `next`.
    Idle,
    /// `deal` is running in the owner's core since `started`.
    Running {
        deal: Deal,
        started: Duration,
        faults: usize,
    },
    /// `frame` is complete and waits for its measured cost map.
    Measuring {
        frame: FrameId,
    },
    /// Every frame is measured; waiting until `deadline` at most for the last statistics.
    Closing {
        deadline: Duration,
    },
    Finished,
}

impl Director {
    /// The director of owner `me`, cutting frames with `partitioner`.
    pub fn new(me: PeerId, partitioner: Partitioner, config: Config) -> Self {
        let mut director = Self {
            me,
            partitioner,
            peers: BTreeSet::new(),
            next: config.first,
            state: State::Idle,
            unreported: BTreeSet::new(),
            events: VecDeque::new(),
            config,
        };
        if director.next >= director.config.frames {
            director.finish();
        }
        director
    }

    pub fn partitioner(&self) -> &Partitioner {
        &self.partitioner
    }

    /// The peers frames are dealt to besides the owner.
    pub fn peers(&self) -> impl Iterator<Item = PeerId> + '_ {
        self.peers.iter().copied()
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
        self.unreported.remove(&peer);
        self.settle();
    }

    /// The next frame to start, if the director is ready for one. The driver starts it with
    /// `core.start_frame(now, deal.frame, deal.assignments, deal.render_pixels)`.
    pub fn poll_deal(&mut self, now: Duration) -> Result<Option<Deal>, DirectorError> {
        if !matches!(self.state, State::Idle) {
            return Ok(None);
        }
        let tiles = self.partitioner.tiles();
        let mut participants: Vec<PeerId> = self.peers.iter().copied().collect();
        participants.push(self.me);
        participants.sort_unstable();
        let assignment = self.partitioner.assign(participants.len(), None)?;
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
        let render_pixels = match self.config.render_piece_factor {
            Some(factor) if !tiles.is_empty() => ((area as f64 / tiles.len() as f64) * factor)
                .ceil()
                .max(1.0) as u64,
            _ => u64::MAX,
        };
        let deal = Deal {
            frame: FrameId(self.next),
            tiles,
            initial,
            assignments,
            render_pixels,
        };
        self.next += 1;
        self.state = State::Running {
            deal: deal.clone(),
            started: now,
            faults: 0,
        };
        Ok(Some(deal))
    }

    /// An event of the owner's core. The director takes a completion of the running frame
    /// (its results become the pieces of [`Event::FrameComplete`]) and returns every other
    /// event, having noted faults and statistics, for the driver to log or keep.
    pub fn handle_core_event(
        &mut self,
        now: Duration,
        event: CoreEvent,
    ) -> Result<Option<CoreEvent>, DirectorError> {
        match (event, &mut self.state) {
            (
                CoreEvent::FrameComplete {
                    frame,
                    results,
                    rendered_by,
                    audit,
                    ..
                },
                State::Running { deal, started, .. },
            ) if frame == deal.frame => {
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
                self.events.push_back(Event::FrameComplete {
                    frame,
                    elapsed: now.saturating_sub(*started),
                    pieces,
                    audit,
                });
                self.state = State::Measuring { frame };
                Ok(None)
            }
            (event @ CoreEvent::FaultyPeer { .. }, State::Running { deal, faults, .. }) => {
                let CoreEvent::FaultyPeer { frame, .. } = event else {
                    unreachable!("matched just above")
                };
                if frame == deal.frame {
                    *faults += 1;
                    if *faults > 2 * deal.tiles.len() + self.config.fault_allowance {
                        return Err(DirectorError::Faulty {
                            frame,
                            faults: *faults,
                        });
                    }
                }
                Ok(Some(event))
            }
            (event @ CoreEvent::PeerStats { .. }, _) => {
                if let CoreEvent::PeerStats { frame, peer, .. } = &event
                    && frame.0 + 1 == self.next
                {
                    self.unreported.remove(peer);
                    self.settle();
                }
                Ok(Some(event))
            }
            (event, _) => Ok(Some(event)),
        }
    }

    /// The measured cost map of the frame that waits for it: the balancer learns from it and
    /// the next frame may be dealt.
    pub fn handle_measured(
        &mut self,
        now: Duration,
        frame: FrameId,
        map: &CostMap,
    ) -> Result<Update, DirectorError> {
        if !matches!(self.state, State::Measuring { frame: waiting } if waiting == frame) {
            return Err(DirectorError::NotWaiting { frame });
        }
        let update = self.partitioner.observe(map)?;
        self.state = if self.next < self.config.frames {
            State::Idle
        } else {
            State::Closing {
                deadline: now + self.config.stats_grace,
            }
        };
        self.settle();
        Ok(update)
    }

    /// Call when `now` reaches [`Director::poll_timeout`].
    pub fn handle_timeout(&mut self, now: Duration) {
        if let State::Closing { deadline, .. } = self.state
            && now >= deadline
        {
            self.finish();
        }
    }

    /// When to call [`Director::handle_timeout`], if ever.
    pub fn poll_timeout(&self) -> Option<Duration> {
        match self.state {
            State::Closing { deadline, .. } => Some(deadline),
            _ => None,
        }
    }

    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    pub fn is_finished(&self) -> bool {
        matches!(self.state, State::Finished)
    }

    fn settle(&mut self) {
        if matches!(self.state, State::Closing { .. }) && self.unreported.is_empty() {
            self.finish();
        }
    }

    fn finish(&mut self) {
        if !self.is_finished() {
            self.state = State::Finished;
            self.events.push_back(Event::Finished);
        }
    }
}

#[cfg(test)]
mod tests;
