//! The simulator's side of the pump (`runtime_core::peer::testing::World`): renderers that take a
//! tile's time from the trace, the network model, and the running tally of each frame.
//!
//! The tally is kept as the run goes, never as a record of it: a run of a thousand peers over
//! a hundred frames sends tens of millions of messages, and keeping them would cost more than
//! simulating them. What the determinism tests need is a fingerprint: every output of every
//! core (message sent, tile started, event) is folded into one 64-bit hash with its time, and
//! every message's encoding with its arrival time as it leaves (once, for its size and its
//! hash alike).

use std::collections::BTreeMap;
use std::time::Duration;

use balancer::CostMap;
use runtime_core::peer::WorkItem;
use runtime_core::peer::testing::{Rendered, Seen, Transit, World};
use runtime_core::peer::{Audit, Event};
use runtime_core::wire::{self, Message, PeerId, TileId, TileResult};

use crate::network::Links;
use crate::plot::{BarKind, GanttBar};
use crate::scenario::{OWNER, OwnerCosts};

/// What the simulator knows and counts of one frame while it runs.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tally {
    pub(crate) started: Duration,
    /// The peer each tile started the frame with, by tile id (for the Gantt chart's colours).
    pub(crate) initial: Vec<PeerId>,
    pub(crate) tiles: usize,
    /// When the owner's core reported the frame complete, and in how long.
    pub(crate) completed: Option<(Duration, Duration)>,
    /// Whether the completion covered each tile of the frame exactly once.
    pub(crate) results_ok: bool,
    /// Results the completion held (more than `tiles` where tiles were cut).
    pub(crate) pieces: usize,
    pub(crate) audit: Audit,
    /// Tiles handed to renderers (more than `tiles` when some were rendered twice).
    pub(crate) renders: usize,
    /// Slot-seconds spent rendering this frame's tiles.
    pub(crate) busy: f64,
    pub(crate) messages: u64,
    pub(crate) bytes: u64,
    pub(crate) steal_requests: u64,
    pub(crate) grants: u64,
    pub(crate) stolen_tiles: u64,
    pub(crate) failures: u64,
    /// Faulty results and refused messages: both mean a bug, in the core or here.
    pub(crate) faults: u64,
    pub(crate) result_bytes: u64,
    /// Seconds of the owner's control loop spent on this frame.
    pub(crate) owner_busy: f64,
}

pub(crate) struct SimWorld {
    /// The trace's frames; frame `f` is costed by `maps[f % maps.len()]`.
    maps: Vec<CostMap>,
    /// Virtual seconds per unit of counted work, on a peer of speed 1.
    seconds_per_unit: f64,
    /// Virtual seconds each tile costs besides its work, on a peer of speed 1.
    tile_overhead: f64,
    /// Speed factor of each peer, indexed by peer id.
    speeds: Vec<f64>,
    links: Links,
    pub(crate) frames: BTreeMap<u32, Tally>,
    /// Tiles each peer has started over the run, indexed by peer id (for crashes on an event).
    pub(crate) starts: Vec<u64>,
    /// The frame whose renders become Gantt bars, with its neighbours' (drawn in grey where
    /// they overlap it).
    gantt_frame: Option<u32>,
    pub(crate) gantt: Vec<GanttBar>,
    /// Pixels begun by some peer, per charted frame: a render of pixels all begun already is a
    /// duplicate on the chart.
    begun: BTreeMap<u32, Vec<bool>>,
    pub(crate) fingerprint: Fingerprint,
    /// The owner core's events not yet handed to the director.
    owner_events: Vec<Event>,
    /// What the owner's control loop spends per tile, and when it is next free.
    pub(crate) owner_costs: OwnerCosts,
    owner_free: Duration,
    /// Block side of the cost maps tile results carry, for their size.
    block: u32,
}

impl SimWorld {
    pub(crate) fn new(
        maps: Vec<CostMap>,
        (seconds_per_unit, tile_overhead): (f64, f64),
        speeds: Vec<f64>,
        links: Links,
        gantt_frame: Option<u32>,
    ) -> Self {
        let peers = speeds.len();
        let block = maps.first().map_or(8, CostMap::block);
        Self {
            maps,
            seconds_per_unit,
            tile_overhead,
            speeds,
            links,
            frames: BTreeMap::new(),
            starts: vec![0; peers],
            gantt_frame,
            gantt: Vec::new(),
            begun: BTreeMap::new(),
            fingerprint: Fingerprint::default(),
            owner_events: Vec::new(),
            owner_costs: OwnerCosts::NONE,
            owner_free: Duration::ZERO,
            block,
        }
    }

    /// The cost map that measures frame `frame`.
    pub(crate) fn map(&self, frame: u32) -> &CostMap {
        &self.maps[frame as usize % self.maps.len()]
    }

    pub(crate) fn begin_frame(&mut self, frame: u32, now: Duration, initial: Vec<PeerId>) {
        let tally = Tally {
            started: now,
            tiles: initial.len(),
            initial,
            ..Tally::default()
        };
        self.frames.insert(frame, tally);
    }

    /// The owner core's events since the last call, in order, for the director.
    pub(crate) fn take_owner_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.owner_events)
    }

    fn tally(&mut self, frame: u32) -> Option<&mut Tally> {
        self.frames.get_mut(&frame)
    }
}

impl World for SimWorld {
    fn round_trip(&self, a: PeerId, b: PeerId, _base: Duration) -> Duration {
        self.links.round_trip(a, b)
    }

    fn render(&mut self, now: Duration, peer: PeerId, item: &WorkItem) -> Rendered {
        let frame = item.frame.0;
        let map = self.map(frame);
        let (cost, width, height) = (map.cost(item.tile.rect), map.width(), map.height());
        let speed = self.speeds[peer.0 as usize];
        self.starts[peer.0 as usize] += 1;
        let seconds = (cost * self.seconds_per_unit + self.tile_overhead) / speed;
        // Rounded up to whole nanoseconds: truncating would make every tile a little cheaper
        // than its work, and a run's efficiency could then exceed its bound.
        let duration = Duration::from_nanos((seconds * 1e9).ceil() as u64);
        if let Some(tally) = self.frames.get_mut(&frame) {
            tally.renders += 1;
            tally.busy += duration.as_secs_f64();
            let charted = self
                .gantt_frame
                .is_some_and(|g| frame + 1 >= g && frame <= g + 1);
            if charted {
                let taken = tally.initial.get(item.tile.id.0 as usize).copied() != Some(peer);
                let start = now.as_secs_f64();
                let begun = self
                    .begun
                    .entry(frame)
                    .or_insert_with(|| vec![false; width as usize * height as usize]);
                let kind = match mark_begun(begun, width, item.tile.rect) {
                    false => BarKind::Duplicate,
                    true if item.tile.piece != wire::Piece::WHOLE => BarKind::Piece,
                    true if taken => BarKind::Taken,
                    true => BarKind::Own,
                };
                self.gantt.push(GanttBar {
                    row: peer.0,
                    start,
                    end: start + duration.as_secs_f64(),
                    frame,
                    kind,
                });
            }
        }
        // Pixels are opaque to the core, which only checks their length and compares
        // duplicates; zeros are as deterministic as any. The cost map a real peer would add is
        // counted in the message's size instead.
        let rect = item.tile.rect;
        let pixels = vec![0; (rect.area() * wire::BYTES_PER_PIXEL) as usize];
        let result = TileResult {
            frame: item.frame,
            tile: item.tile.id,
            piece: item.tile.piece,
            rect,
            pixels,
            costs: vec![0; wire::cost_map_bytes(rect, self.block) as usize],
        };
        Rendered { duration, result }
    }

    fn transit(
        &mut self,
        now: Duration,
        from: PeerId,
        to: PeerId,
        message: &Message,
        delay: Duration,
    ) -> Transit {
        // The message's content enters the fingerprint here rather than in `observe`, so that
        // it is encoded once for both its size and its hash.
        let bytes = self.fingerprint.message(message);
        if let Some(tally) = message_frame(message).and_then(|f| self.tally(f)) {
            tally.bytes += bytes;
        }
        // The owner encodes its part of an Assign before the message can leave.
        let mut leave = now;
        let frame = message_frame(message);
        if let (OWNER, Message::Assign { tiles, .. }) = (from, message) {
            let busy = self.owner_costs.per_dealt_tile * tiles.len() as u32;
            leave = self.owner_free.max(now) + busy;
            self.owner_free = leave;
            if let Some(tally) = frame.and_then(|f| self.frames.get_mut(&f)) {
                tally.owner_busy += busy.as_secs_f64();
            }
        }
        let mut delay = (leave - now) + self.links.transit(leave, from, to, bytes, delay);
        // A result is handled once the owner's control loop is done with those before it.
        if let (OWNER, Message::TileDone(result)) = (to, message) {
            let busy = self.owner_costs.result(result.rect.area());
            let handled = self.owner_free.max(now + delay) + busy;
            self.owner_free = handled;
            delay = handled - now;
            if let Some(tally) = frame.and_then(|f| self.frames.get_mut(&f)) {
                tally.owner_busy += busy.as_secs_f64();
                tally.result_bytes += bytes;
            }
        }
        self.fingerprint.word(delay.as_nanos() as u64);
        Transit { delay, bytes }
    }

    fn observe(&mut self, at: Duration, seen: Seen<'_>) {
        let print = &mut self.fingerprint;
        print.word(at.as_nanos() as u64);
        match seen {
            Seen::Sent { from, to, message } => {
                print.words(&[1, u64::from(from.0), u64::from(to.0)]);
                print.bytes(message.kind().as_bytes());
                let Some(tally) = message_frame(message).and_then(|f| self.frames.get_mut(&f))
                else {
                    return;
                };
                tally.messages += 1;
                match message {
                    Message::StealRequest { .. } => tally.steal_requests += 1,
                    Message::StealGrant { tiles, .. } => {
                        tally.grants += 1;
                        tally.stolen_tiles += tiles.len() as u64;
                    }
                    _ => {}
                }
            }
            Seen::Started { peer, item } => {
                print.words(&[
                    2,
                    u64::from(peer.0),
                    u64::from(item.frame.0),
                    u64::from(item.tile.id.0),
                ]);
            }
            Seen::Event { peer, event } => {
                print.words(&[3, u64::from(peer.0)]);
                self.event(&event);
                if peer == crate::scenario::OWNER {
                    self.owner_events.push(event);
                }
            }
            Seen::Refused { peer, from, error } => {
                print.words(&[4, u64::from(peer.0), u64::from(from.0)]);
                tracing::error!(%peer, %from, %error, "a simulated core refused a message");
                if let Some(tally) = self.frames.values_mut().next_back() {
                    tally.faults += 1;
                }
            }
        }
    }
}

impl SimWorld {
    fn event(&mut self, event: &Event) {
        let print = &mut self.fingerprint;
        match event {
            Event::FrameComplete {
                frame,
                elapsed,
                results,
                rendered_by,
                audit,
            } => {
                print.words(&[10, u64::from(frame.0), elapsed.as_nanos() as u64]);
                for peer in rendered_by {
                    print.word(u64::from(peer.0));
                }
                let Some(tally) = self.frames.get_mut(&frame.0) else {
                    return;
                };
                let at = tally.started + *elapsed;
                // The ledger's cover has no two overlapping pieces, so it covers every tile
                // exactly once when the ids run through every tile in order and the areas add
                // up to the image.
                let mut ids: Vec<TileId> = results.iter().map(|r| r.tile).collect();
                let sorted = ids.is_sorted();
                ids.dedup();
                let area: u64 = results.iter().map(|r| r.rect.area()).sum();
                let image = self
                    .maps
                    .first()
                    .map_or(0, |m| u64::from(m.width()) * u64::from(m.height()));
                tally.results_ok = sorted
                    && ids.iter().copied().eq((0..tally.tiles as u32).map(TileId))
                    && area == image
                    && results.iter().all(|r| r.frame == *frame);
                tally.pieces = results.len();
                tally.audit = *audit;
                tally.completed = Some((at, *elapsed));
            }
            // The director's cue to deal: what it changes shows in the messages that follow.
            Event::FrameWaning { .. } => {}
            Event::PeerOverdue { frame, peer } => {
                print.words(&[16, u64::from(frame.0), u64::from(peer.0)]);
            }
            Event::PeerResumed { frame, peer } => {
                print.words(&[19, u64::from(frame.0), u64::from(peer.0)]);
            }
            Event::PeerStats { frame, peer, stats } => {
                print.words(&[
                    11,
                    u64::from(frame.0),
                    u64::from(peer.0),
                    stats.busy.as_nanos() as u64,
                ]);
            }
            Event::PeerFailed {
                frame,
                peer,
                reissued,
                ..
            } => {
                print.words(&[12, u64::from(frame.0), u64::from(peer.0), *reissued as u64]);
                if let Some(tally) = self.frames.get_mut(&frame.0) {
                    tally.failures += 1;
                }
            }
            Event::FaultyPeer {
                frame, peer, tile, ..
            } => {
                print.words(&[13, u64::from(frame.0), u64::from(peer.0), u64::from(tile.0)]);
                tracing::error!(%frame, %peer, %tile, "a simulated peer's result was refused");
                if let Some(tally) = self.frames.get_mut(&frame.0) {
                    tally.faults += 1;
                }
            }
            Event::OwnerLost { frame } => print.words(&[14, u64::from(frame.0)]),
            Event::PeerLeaving { peer } => print.words(&[17, u64::from(peer.0)]),
            Event::Left => print.word(18),
        }
    }
}

/// The frame a message belongs to, if it names one.
fn message_frame(message: &Message) -> Option<u32> {
    match message {
        Message::Assign { frame, .. }
        | Message::StealRequest { frame, .. }
        | Message::StealGrant { frame, .. }
        | Message::StealRefuse { frame }
        | Message::StealNotice { frame, .. }
        | Message::Status { frame, .. }
        | Message::FrameDone { frame }
        | Message::FrameStats { frame, .. } => Some(frame.0),
        Message::TileDone(result) => Some(result.frame.0),
        Message::Hello { .. }
        | Message::Welcome { .. }
        | Message::Peers { .. }
        | Message::Scene { .. }
        | Message::SceneReady
        | Message::Goodbye { .. }
        | Message::Leaving => None,
    }
}

/// A 64-bit hash of a run's outputs, word by word (a multiply-rotate mix: fast, and any
/// difference in any word changes the result with overwhelming probability).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Fingerprint(pub(crate) u64);

impl Fingerprint {
    fn word(&mut self, word: u64) {
        self.0 = (self.0 ^ word)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(29);
    }

    fn words(&mut self, words: &[u64]) {
        for &word in words {
            self.word(word);
        }
    }

    /// Folds in a message's full encoding (a tile result's: its frame, tile and rectangle, not
    /// its pixels and costs, which are all zeros here) and returns its size on the wire.
    fn message(&mut self, message: &Message) -> u64 {
        if let Message::TileDone(r) = message {
            let rect = r.rect;
            let words = [
                20,
                u64::from(r.frame.0),
                u64::from(r.tile.0),
                u64::from(rect.x),
                u64::from(rect.y),
            ];
            self.words(&words);
            self.words(&[u64::from(rect.w), u64::from(rect.h)]);
            return wire::encoded_len(message) as u64;
        }
        let bytes = wire::encode(message);
        self.bytes(&bytes);
        bytes.len() as u64
    }

    fn bytes(&mut self, bytes: &[u8]) {
        self.word(bytes.len() as u64);
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.word(u64::from_le_bytes(word));
        }
    }
}

/// Marks `rect`'s pixels begun in a frame's map of `width` columns; whether any was new.
fn mark_begun(begun: &mut [bool], width: u32, rect: balancer::Rect) -> bool {
    let mut new = false;
    for y in rect.y..rect.y + rect.h {
        let row = (y * width) as usize;
        for pixel in &mut begun[row + rect.x as usize..row + (rect.x + rect.w) as usize] {
            new |= !*pixel;
            *pixel = true;
        }
    }
    new
}
