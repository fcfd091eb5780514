//! What surrounds the cores of a virtual-time cluster: the [`World`] trait the pump drives
//! (renderers, the network beyond the cluster's own delay, and an observer), what a render and
//! a transit return, what the world is shown ([`Seen`]) and the happenings the pump schedules;
//! then the tests' world, [`Scripted`], which renders with a [`Renderer`] and keeps every
//! [`Record`] of the run, with [`Cluster::new`] to build a cluster around it, [`cost_renderer`]
//! to make a renderer, and [`synthetic_result`] for the results it produces, whose pixels are a
//! pure function of the frame and the pixel.
//!
//! One unit because it is everything on the far side of the pump (`testing.rs`): the interface
//! a world implements and the one world the core's own tests script races with. Nothing here
//! depends on how the pump orders its agenda; the simulator brings a world of its own through
//! [`Cluster::with_world`].

use std::time::Duration;

use super::Cluster;
use crate::peer::{Config, Event, ProtocolError, WorkItem};
use crate::wire::{BYTES_PER_PIXEL, Message, PeerId, TileResult};

/// What the simulated renderer of a peer makes of a tile, and how long it takes.
pub struct Rendered {
    /// How long the render takes in virtual time.
    pub duration: Duration,
    /// What the render sends to the owner.
    pub result: TileResult,
}

/// Renders a tile for a peer. Called once per tile a core hands out.
pub type Renderer = Box<dyn FnMut(PeerId, &WorkItem) -> Rendered>;

/// What surrounds the cores: their renderers, what the network does beyond the cluster's own
/// latency and jitter, and whoever watches the run.
pub trait World {
    /// `peer`'s renderer starts `item` at `now`: how long it takes and what it produces.
    fn render(&mut self, now: Duration, peer: PeerId, item: &WorkItem) -> Rendered;

    /// `message` leaves `from` for `to` at `now`; `delay` is what the cluster's own link model
    /// (`latency` plus jitter) gives it. Returns when it arrives and how many bytes it moves,
    /// which both cores count in their statistics. By default: the cluster's delay, no bytes.
    fn transit(
        &mut self,
        now: Duration,
        from: PeerId,
        to: PeerId,
        message: &Message,
        delay: Duration,
    ) -> Transit {
        let _ = (now, from, to, message);
        Transit { delay, bytes: 0 }
    }

    /// The round trip the driver of `a` would report for its link to `b` where the cluster
    /// reports round trips ([`Cluster::report_rtt`]): QUIC's smoothed estimate, the link's
    /// delay both ways without jitter, losses or queues. `base` is the cluster's own, twice its
    /// `latency`; by default the answer.
    fn round_trip(&self, a: PeerId, b: PeerId, base: Duration) -> Duration {
        let _ = (a, b);
        base
    }

    /// Sees what the cores do, in order, as it happens.
    fn observe(&mut self, at: Duration, seen: Seen<'_>);
}

/// How one message crosses the network.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Transit {
    /// How long the message takes to arrive.
    pub delay: Duration,
    /// Its size on the wire, counted in the peers' statistics.
    pub bytes: u64,
}

/// One output of a core, as a [`World`] sees it.
#[derive(Debug)]
pub enum Seen<'a> {
    /// A core sent a message.
    Sent {
        /// The sender.
        from: PeerId,
        /// The addressee.
        to: PeerId,
        /// The message as sent.
        message: &'a Message,
    },
    /// The core handed `item` to its renderer (just before [`World::render`] is asked).
    Started {
        /// The peer whose core handed out the work.
        peer: PeerId,
        /// The work handed out.
        item: &'a WorkItem,
    },
    /// A core reported an event.
    Event {
        /// The peer whose core reported it.
        peer: PeerId,
        /// The event.
        event: Event,
    },
    /// A core refused a message; a real driver would close the connection.
    Refused {
        /// The peer whose core refused it.
        peer: PeerId,
        /// The sender of the refused message.
        from: PeerId,
        /// Why it was refused.
        error: ProtocolError,
    },
}

/// One thing that happens to one peer at one instant.
#[derive(Clone, Debug, PartialEq)]
pub enum Happening {
    /// A message arrives.
    Deliver {
        /// The sender.
        from: PeerId,
        /// The addressee, whose core handles it.
        to: PeerId,
        /// The message, decoded from its encoding as a driver would.
        message: Message,
        /// Its size, as [`World::transit`] counted it.
        bytes: u64,
    },
    /// A peer's renderer finishes a tile.
    Rendered {
        /// The peer whose renderer finished.
        peer: PeerId,
        /// What it rendered.
        result: TileResult,
    },
    /// A peer learns that another is gone, as a closed connection tells a driver.
    Lost {
        /// The peer that learns it.
        peer: PeerId,
        /// The peer that is gone.
        lost: PeerId,
    },
    /// A peer's core reaches the time it asked to be woken at.
    Timeout {
        /// The peer woken.
        peer: PeerId,
    },
}

/// The log of a run, in order.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    /// A message was sent.
    Sent {
        /// When, in virtual time.
        at: Duration,
        /// The sender.
        from: PeerId,
        /// The addressee.
        to: PeerId,
        /// The message.
        message: Message,
    },
    /// A core handed work to its renderer.
    Started {
        /// When, in virtual time.
        at: Duration,
        /// The peer whose core handed it out.
        peer: PeerId,
        /// The work.
        item: WorkItem,
    },
    /// A core reported an event.
    Event {
        /// When, in virtual time.
        at: Duration,
        /// The peer whose core reported it.
        peer: PeerId,
        /// The event.
        event: Event,
    },
    /// A core refused a message with a `ProtocolError`; a real driver would close the connection.
    Refused {
        /// When, in virtual time.
        at: Duration,
        /// The peer whose core refused it.
        peer: PeerId,
        /// The sender of the refused message.
        from: PeerId,
        /// The error's text, so that records compare equal across runs.
        error: String,
    },
}

/// The tests' world: renders with a [`Renderer`] and keeps every [`Record`].
pub struct Scripted {
    renderer: Renderer,
    trace: Vec<Record>,
}

impl World for Scripted {
    fn render(&mut self, _now: Duration, peer: PeerId, item: &WorkItem) -> Rendered {
        (self.renderer)(peer, item)
    }

    fn observe(&mut self, at: Duration, seen: Seen<'_>) {
        self.trace.push(match seen {
            Seen::Sent { from, to, message } => Record::Sent {
                at,
                from,
                to,
                message: message.clone(),
            },
            Seen::Started { peer, item } => Record::Started {
                at,
                peer,
                item: *item,
            },
            Seen::Event { peer, event } => Record::Event { at, peer, event },
            Seen::Refused { peer, from, error } => Record::Refused {
                at,
                peer,
                from,
                error: error.to_string(),
            },
        });
    }
}

impl Cluster<Scripted> {
    /// Peers `(id, renderer slots)`, all connected to each other at time zero, rendering with
    /// `renderer` and keeping a full record.
    pub fn new(config: &Config, peers: &[(PeerId, usize)], seed: u64, renderer: Renderer) -> Self {
        let world = Scripted {
            renderer,
            trace: Vec::new(),
        };
        Self::with_world(config, peers, seed, world)
    }

    /// Everything that happened so far, in order, for tests to read.
    pub fn trace(&self) -> &[Record] {
        &self.world.trace
    }

    /// Every event so far, with the peer that reported it.
    pub fn events(&self) -> impl Iterator<Item = (PeerId, &Event)> {
        self.world.trace.iter().filter_map(|record| match record {
            Record::Event { peer, event, .. } => Some((*peer, event)),
            _ => None,
        })
    }
}

/// A renderer that takes `seconds_per_unit` of virtual time per unit of predicted cost and
/// produces [`synthetic_result`]s.
pub fn cost_renderer(seconds_per_unit: f64) -> Renderer {
    Box::new(move |_, item| Rendered {
        duration: Duration::from_secs_f64(item.tile.predicted * seconds_per_unit),
        result: synthetic_result(item),
    })
}

/// A result whose pixels are a pure function of (frame, pixel), as a real render's are: the
/// same whichever tile or piece the pixel was rendered in.
pub fn synthetic_result(item: &WorkItem) -> TileResult {
    let rect = item.tile.rect;
    let mut pixels = Vec::with_capacity((rect.area() * BYTES_PER_PIXEL) as usize);
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let seed = u64::from(item.frame.0).wrapping_mul(31)
                ^ u64::from(x).wrapping_mul(131)
                ^ u64::from(y).wrapping_mul(1_000_003);
            pixels.extend((0..BYTES_PER_PIXEL).map(|c| (seed.wrapping_add(c) % 251) as u8));
        }
    }
    TileResult {
        frame: item.frame,
        tile: item.tile.id,
        piece: item.tile.piece,
        rect,
        pixels,
        costs: vec![1; rect.area() as usize],
    }
}
