//! A minimal cluster of cores in virtual time: no sockets, no threads, no clock.
//!
//! Tests use it to script races (a peer dying the instant a grant reaches it, a peer frozen past
//! its timeout); the simulator can start from the same pattern. It is a discrete-event loop: an
//! agenda of deliveries ordered by (time, sequence number), plus each core's own timeout, one at
//! a time, so a run is a pure function of its inputs and seed. Every message can go through
//! [`wire::encode`] and [`wire::decode`] on the way, as it would on a real connection.

use std::collections::BTreeMap;
use std::time::Duration;

use super::steal::Rng;
use super::{Config, Core, Event, FrameError, WorkItem};
use crate::wire::{self, BYTES_PER_PIXEL, FrameId, Message, PeerId, TileResult, TileSpec};

/// What the simulated renderer of a peer makes of a tile, and how long it takes.
pub struct Rendered {
    pub duration: Duration,
    pub result: TileResult,
}

/// Renders a tile for a peer. Called once per tile a core hands out.
pub type Renderer = Box<dyn FnMut(PeerId, &WorkItem) -> Rendered>;

/// One thing that happens to one peer at one instant.
#[derive(Clone, Debug, PartialEq)]
pub enum Happening {
    Deliver {
        from: PeerId,
        to: PeerId,
        message: Message,
    },
    Rendered {
        peer: PeerId,
        result: TileResult,
    },
    Lost {
        peer: PeerId,
        lost: PeerId,
    },
    Timeout {
        peer: PeerId,
    },
}

/// The log of a run, in order.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    Sent {
        at: Duration,
        from: PeerId,
        to: PeerId,
        message: Message,
    },
    Started {
        at: Duration,
        peer: PeerId,
        item: WorkItem,
    },
    Event {
        at: Duration,
        peer: PeerId,
        event: Event,
    },
    /// A core refused a message with a `ProtocolError`; a real driver would close the connection.
    Refused {
        at: Duration,
        peer: PeerId,
        from: PeerId,
        error: String,
    },
}

/// Several cores, their renderers and the network between them.
pub struct Cluster {
    now: Duration,
    nodes: BTreeMap<PeerId, Node>,
    agenda: BTreeMap<(Duration, u64), Happening>,
    next_seq: u64,
    renderer: Renderer,
    trace: Vec<Record>,
    rng: Rng,
    /// One-way delay of every message.
    pub latency: Duration,
    /// Each message is delayed by up to this much more, uniformly at random (from the
    /// cluster's seed), so that messages overtake each other as they do on QUIC streams.
    pub jitter: Duration,
    /// How long after a peer dies the others learn of it.
    pub loss_detection: Duration,
    /// Pass every message through the wire encoding.
    pub encode: bool,
}

struct Node {
    core: Core,
    state: NodeState,
}

enum NodeState {
    Up,
    /// Receives nothing and does nothing; what reaches it waits here until it thaws.
    Frozen(Vec<Happening>),
    Dead,
}

impl Cluster {
    /// Peers `(id, renderer slots)`, all connected to each other at time zero.
    pub fn new(config: &Config, peers: &[(PeerId, usize)], seed: u64, renderer: Renderer) -> Self {
        let mut nodes = BTreeMap::new();
        for &(peer, slots) in peers {
            let mut core = Core::new(peer, slots, config.clone(), seed);
            for &(other, _) in peers {
                core.handle_peer_connected(Duration::ZERO, other);
            }
            nodes.insert(
                peer,
                Node {
                    core,
                    state: NodeState::Up,
                },
            );
        }
        Self {
            now: Duration::ZERO,
            nodes,
            agenda: BTreeMap::new(),
            next_seq: 0,
            renderer,
            trace: Vec::new(),
            rng: Rng(seed),
            latency: Duration::from_micros(500),
            jitter: Duration::ZERO,
            loss_detection: Duration::from_millis(20),
            encode: true,
        }
    }

    pub fn now(&self) -> Duration {
        self.now
    }

    pub fn core(&self, peer: PeerId) -> &Core {
        &self.nodes[&peer].core
    }

    pub fn trace(&self) -> &[Record] {
        &self.trace
    }

    /// Every event so far, with the peer that reported it.
    pub fn events(&self) -> impl Iterator<Item = (PeerId, &Event)> {
        self.trace.iter().filter_map(|record| match record {
            Record::Event { peer, event, .. } => Some((*peer, event)),
            _ => None,
        })
    }

    pub fn start_frame(
        &mut self,
        owner: PeerId,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
    ) -> Result<(), FrameError> {
        let now = self.now;
        self.node(owner).core.start_frame(now, frame, assignments)?;
        self.flush(owner);
        Ok(())
    }

    /// Processes everything that happens up to `until`, then moves the clock there.
    pub fn run(&mut self, until: Duration) {
        while self.next().is_some_and(|(at, _)| at <= until) {
            self.step();
        }
        self.now = self.now.max(until);
    }

    /// Processes the next happening and returns it; `None` when nothing is left.
    pub fn step(&mut self) -> Option<Happening> {
        let (at, timeout) = self.next()?;
        self.now = self.now.max(at);
        let happening = match timeout {
            Some(peer) => Happening::Timeout { peer },
            None => {
                self.agenda
                    .pop_first()
                    .expect("invariant: `next` saw an entry")
                    .1
            }
        };
        self.apply(happening.clone());
        Some(happening)
    }

    /// When the next happening is due, and whose timeout it is if it is one.
    fn next(&self) -> Option<(Duration, Option<PeerId>)> {
        let timeout = self
            .nodes
            .iter()
            .filter(|(_, node)| matches!(node.state, NodeState::Up))
            .filter_map(|(peer, node)| Some((node.core.poll_timeout()?, *peer)))
            .min();
        let next = self.agenda.first_key_value().map(|(key, _)| key.0);
        match (timeout, next) {
            (Some((at, peer)), next) if next.is_none_or(|next| at <= next) => {
                Some((at, Some(peer)))
            }
            (_, next) => Some((next?, None)),
        }
    }

    /// Kills `peer`: everything addressed to it is lost, and so is everything it sent that is
    /// still on the way if `drop_outgoing`. The others learn of it after `loss_detection`.
    pub fn kill(&mut self, peer: PeerId, drop_outgoing: bool) {
        self.node(peer).state = NodeState::Dead;
        self.agenda.retain(|_, happening| match happening {
            Happening::Deliver { from, to, .. } => *to != peer && !(drop_outgoing && *from == peer),
            Happening::Rendered { peer: at, .. }
            | Happening::Lost { peer: at, .. }
            | Happening::Timeout { peer: at } => *at != peer,
        });
        let others: Vec<PeerId> = self.live_peers().filter(|&other| other != peer).collect();
        for other in others {
            self.schedule(
                self.loss_detection,
                Happening::Lost {
                    peer: other,
                    lost: peer,
                },
            );
        }
    }

    /// Stops `peer` without closing its connections, as a long pause or a partition would.
    pub fn freeze(&mut self, peer: PeerId) {
        self.node(peer).state = NodeState::Frozen(Vec::new());
    }

    /// Resumes a frozen peer; what reached it meanwhile arrives now, in order.
    pub fn thaw(&mut self, peer: PeerId) {
        let state = std::mem::replace(&mut self.node(peer).state, NodeState::Up);
        if let NodeState::Frozen(held) = state {
            for happening in held {
                self.schedule(Duration::ZERO, happening);
            }
        }
    }

    fn apply(&mut self, happening: Happening) {
        let peer = match &happening {
            Happening::Deliver { to, .. } => *to,
            Happening::Rendered { peer, .. }
            | Happening::Lost { peer, .. }
            | Happening::Timeout { peer } => *peer,
        };
        let (now, encode) = (self.now, self.encode);
        let node = self.node(peer);
        match &mut node.state {
            NodeState::Dead => return,
            NodeState::Frozen(held) => {
                if !matches!(happening, Happening::Timeout { .. }) {
                    held.push(happening);
                }
                return;
            }
            NodeState::Up => {}
        }
        match happening {
            Happening::Deliver { from, message, .. } => {
                let message = if encode {
                    wire::decode(&wire::encode(&message), &wire::Limits::default())
                        .expect("invariant: what the core sends decodes")
                } else {
                    message
                };
                if let Err(error) = node.core.handle_message(now, from, message) {
                    let error = error.to_string();
                    self.trace.push(Record::Refused {
                        at: now,
                        peer,
                        from,
                        error,
                    });
                }
            }
            Happening::Rendered { result, .. } => node.core.handle_tile_rendered(now, result),
            Happening::Lost { lost, .. } => node.core.handle_peer_lost(now, lost),
            Happening::Timeout { .. } => node.core.handle_timeout(now),
        }
        self.flush(peer);
    }

    /// Moves a core's outputs into the agenda and the trace.
    fn flush(&mut self, peer: PeerId) {
        let now = self.now;
        while let Some(item) = self.node(peer).core.poll_work() {
            self.trace.push(Record::Started {
                at: now,
                peer,
                item,
            });
            let Rendered { duration, result } = (self.renderer)(peer, &item);
            self.schedule(duration, Happening::Rendered { peer, result });
        }
        while let Some((to, message)) = self.node(peer).core.poll_transmit() {
            let record = Record::Sent {
                at: now,
                from: peer,
                to,
                message: message.clone(),
            };
            self.trace.push(record);
            if self
                .nodes
                .get(&to)
                .is_some_and(|node| !matches!(node.state, NodeState::Dead))
            {
                let jitter = self.rng.below(self.jitter.as_nanos() as usize + 1);
                let delay = self.latency + Duration::from_nanos(jitter as u64);
                self.schedule(
                    delay,
                    Happening::Deliver {
                        from: peer,
                        to,
                        message,
                    },
                );
            }
        }
        while let Some(event) = self.node(peer).core.poll_event() {
            self.trace.push(Record::Event {
                at: now,
                peer,
                event,
            });
        }
    }

    fn schedule(&mut self, after: Duration, happening: Happening) {
        self.agenda
            .insert((self.now + after, self.next_seq), happening);
        self.next_seq += 1;
    }

    fn node(&mut self, peer: PeerId) -> &mut Node {
        self.nodes
            .get_mut(&peer)
            .expect("invariant: tests name peers of the cluster")
    }

    fn live_peers(&self) -> impl Iterator<Item = PeerId> + '_ {
        let alive = |(_, node): &(&PeerId, &Node)| !matches!(node.state, NodeState::Dead);
        self.nodes.iter().filter(alive).map(|(peer, _)| *peer)
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

/// A result whose pixels are a pure function of (frame, tile, pixel), as a real render's are.
pub fn synthetic_result(item: &WorkItem) -> TileResult {
    let len = item.tile.rect.area() * BYTES_PER_PIXEL;
    let seed = item.frame.0.wrapping_mul(31) ^ u64::from(item.tile.id.0).wrapping_mul(131);
    let pixels = (0..len)
        .map(|i| (seed.wrapping_add(i) % 251) as u8)
        .collect();
    TileResult {
        frame: item.frame,
        tile: item.tile.id,
        rect: item.tile.rect,
        pixels,
        costs: vec![1; item.tile.rect.area() as usize],
    }
}
