//! A cluster of scheduling cores in virtual time: no sockets, no threads, no clock.
//!
//! One pump serves two users, so that the simulator measures exactly the code the tests check.
//! The core's own tests script races with it (a peer dying the instant a grant reaches it, a
//! peer frozen past its timeout) through [`Cluster::new`], which keeps a full [`Record`] of the
//! run. The simulator (`sim`) runs thousands of peers over many frames through
//! [`Cluster::with_world`] and its own [`World`]: renderers that cost tiles from a trace, a
//! network with bandwidth and loss, and running statistics instead of a record.
//!
//! It is a discrete-event loop. Deliveries and finished renders wait in an agenda ordered by
//! (time, sequence number), first in first out on ties. Each core's own deadline
//! ([`Core::poll_timeout`]) waits beside them in a set ordered by (time, peer); a deadline due
//! at the same instant as an agenda entry goes first, as an event loop fires expired timers
//! before it reads its sockets. Each step jumps to the earliest of the two. A core's deadline
//! is re-read only after that core handled an input, so a step costs O(log n) whatever the
//! number of peers. A run is a pure function of its inputs and seed. Every message can go
//! through [`wire::encode`] and [`wire::decode`] on the way, as it would on a real connection.
//!
//! This file is the pump itself, [`Cluster`]. What surrounds the cores ([`World`], what the
//! pump shows it, and the tests' world [`Scripted`] with [`Cluster::new`] and the synthetic
//! renderers) is in `testing/world.rs`, re-exported here.

use std::cmp::Ordering;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap};
use std::time::Duration;

use super::{Config, Core, Event, FrameError};
use crate::rng::SplitMix;
use crate::wire::{self, FrameId, PeerId, TileSpec};

mod world;

pub use world::{
    Happening, Record, Rendered, Renderer, Scripted, Seen, Transit, World, cost_renderer,
    synthetic_result,
};

/// Several cores, their world and the network between them.
pub struct Cluster<W: World = Scripted> {
    now: Duration,
    nodes: BTreeMap<PeerId, Node>,
    agenda: BinaryHeap<Entry>,
    /// Every live, unfrozen core's next deadline.
    deadlines: BTreeSet<(Duration, PeerId)>,
    next_seq: u64,
    rng: SplitMix,
    world: W,
    /// One-way delay of every message.
    pub latency: Duration,
    /// Each message is delayed by up to this much more, uniformly at random (from the
    /// cluster's seed), so that messages overtake each other as they do on QUIC streams.
    pub jitter: Duration,
    /// Whether cores are told their links' round trips ([`World::round_trip`], by default
    /// twice `latency`; jitter left out, as QUIC reports a smoothed estimate) as the QUIC
    /// driver tells them (`Core::handle_rtt`): with each delivered message, when a peer joins,
    /// and (standing in for the connections made before) to an owner as it starts a frame. Off
    /// by default, for tests that script races at a fixed `initial_rtt`: the cores then plan
    /// with their own steal exchanges' samples. The simulator turns it on.
    pub report_rtt: bool,
    /// How long after a peer dies the others learn of it.
    pub loss_detection: Duration,
    /// Pass every message through the wire encoding.
    pub encode: bool,
}

struct Node {
    core: Core,
    state: NodeState,
    /// The deadline this core has in `Cluster::deadlines`, if any.
    deadline: Option<Duration>,
}

enum NodeState {
    Up,
    /// Receives nothing and does nothing; what reaches it waits here until it thaws.
    Frozen(Vec<Happening>),
    Dead,
}

/// An agenda entry; the heap's top is the earliest (time, sequence number). The happening is
/// boxed so that the heap moves 32-byte entries, not whole messages, as it sifts.
struct Entry {
    at: Duration,
    seq: u64,
    happening: Box<Happening>,
}

impl<W: World> Cluster<W> {
    /// Peers `(id, renderer slots)`, all connected to each other at time zero, in `world`.
    /// Messages take 0.5 ms, with no jitter, through the wire encoding; change the public
    /// fields to taste.
    pub fn with_world(config: &Config, peers: &[(PeerId, usize)], seed: u64, world: W) -> Self {
        let mut nodes = BTreeMap::new();
        for &(peer, slots) in peers {
            let mut core = Core::new(peer, slots, config.clone(), seed);
            for &(other, _) in peers {
                core.handle_peer_connected(Duration::ZERO, other);
            }
            let node = Node {
                core,
                state: NodeState::Up,
                deadline: None,
            };
            nodes.insert(peer, node);
        }
        let mut cluster = Self {
            now: Duration::ZERO,
            nodes,
            agenda: BinaryHeap::new(),
            deadlines: BTreeSet::new(),
            next_seq: 0,
            rng: SplitMix(seed),
            world,
            latency: Duration::from_micros(500),
            jitter: Duration::ZERO,
            report_rtt: false,
            loss_detection: Duration::from_millis(20),
            encode: true,
        };
        let ids: Vec<PeerId> = cluster.nodes.keys().copied().collect();
        for peer in ids {
            cluster.rearm(peer);
        }
        cluster
    }

    /// The round trip reported to `a`'s core for its link to `b` where `report_rtt` is on: the
    /// world's ([`World::round_trip`]), by default twice `latency`.
    fn round_trip(&self, a: PeerId, b: PeerId) -> Duration {
        self.world.round_trip(a, b, self.latency * 2)
    }

    /// The current virtual time.
    pub fn now(&self) -> Duration {
        self.now
    }

    /// Peer `peer`'s core, for tests that inspect its state; panics for an unknown peer.
    pub fn core(&self, peer: PeerId) -> &Core {
        &self.nodes[&peer].core
    }

    /// The world the cluster runs in.
    pub fn world(&self) -> &W {
        &self.world
    }

    /// The world the cluster runs in, for tests that change it mid-run.
    pub fn world_mut(&mut self) -> &mut W {
        &mut self.world
    }

    /// Gives up the cluster, keeping its world (and whatever it gathered).
    pub fn into_world(self) -> W {
        self.world
    }

    /// Starts `frame` at `owner`, every tile rendered whole.
    pub fn start_frame(
        &mut self,
        owner: PeerId,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
    ) -> Result<(), FrameError> {
        self.start_frame_in_pieces(owner, frame, assignments, u64::MAX)
    }

    /// Starts `frame` at `owner`, renderers taking pieces of at most `render_pixels` pixels.
    pub fn start_frame_in_pieces(
        &mut self,
        owner: PeerId,
        frame: FrameId,
        assignments: BTreeMap<PeerId, Vec<TileSpec>>,
        render_pixels: u64,
    ) -> Result<(), FrameError> {
        let now = self.now;
        if self.report_rtt {
            // As the driver reports each connection's round trip when it comes up.
            let links: Vec<(PeerId, Duration)> = (self.nodes.keys())
                .filter(|&&peer| peer != owner)
                .map(|&peer| (peer, self.round_trip(owner, peer)))
                .collect();
            for (peer, round_trip) in links {
                self.node(owner).core.handle_rtt(peer, round_trip);
            }
        }
        self.node(owner)
            .core
            .start_frame(now, frame, assignments, render_pixels)?;
        self.flush(owner);
        Ok(())
    }

    /// Processes everything that happens up to `until`, then moves the clock there.
    pub fn run(&mut self, until: Duration) {
        while self.next_due().is_some_and(|at| at <= until) {
            self.advance();
        }
        self.now = self.now.max(until);
    }

    /// Processes the next happening and returns (a copy of) it; `None` when nothing is left.
    pub fn step(&mut self) -> Option<Happening> {
        let happening = self.take_next()?;
        self.apply(happening.clone());
        Some(happening)
    }

    /// Processes the next happening, as [`Cluster::step`] does without copying it, and
    /// returns the time it happened; `None` when nothing is left.
    pub fn advance(&mut self) -> Option<Duration> {
        let happening = self.take_next()?;
        self.apply(happening);
        Some(self.now)
    }

    /// When the next happening is due, if anything is left to happen.
    pub fn next_due(&self) -> Option<Duration> {
        let deadline = self.deadlines.first().map(|(at, _)| *at);
        let entry = self.agenda.peek().map(|entry| entry.at);
        match (deadline, entry) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Kills `peer`: everything addressed to it is lost, and so is everything it sent that is
    /// still on the way if `drop_outgoing`. The others learn of it after `loss_detection`.
    pub fn kill(&mut self, peer: PeerId, drop_outgoing: bool) {
        self.node(peer).state = NodeState::Dead;
        self.rearm(peer);
        self.agenda.retain(|entry| match &*entry.happening {
            Happening::Deliver { from, to, .. } => *to != peer && !(drop_outgoing && *from == peer),
            Happening::Rendered { peer: at, .. }
            | Happening::Lost { peer: at, .. }
            | Happening::Timeout { peer: at } => *at != peer,
        });
        let others: Vec<PeerId> = self.live_peers().filter(|&other| other != peer).collect();
        for other in others {
            let lost = Happening::Lost {
                peer: other,
                lost: peer,
            };
            self.schedule(self.loss_detection, lost);
        }
    }

    /// Adds `peer`, with `slots` and the cluster's first core's policy, to the running cluster
    /// (a dead peer comes back as a new process): it connects to every live peer and every live
    /// peer to it, now (the owner's core then admits it to the frames it runs, as a late join
    /// over the network does).
    pub fn join(&mut self, peer: PeerId, slots: usize, seed: u64) {
        assert!(
            self.nodes
                .get(&peer)
                .is_none_or(|node| matches!(node.state, NodeState::Dead)),
            "{peer} is already in the cluster"
        );
        let config = self
            .nodes
            .values()
            .next()
            .map(|node| node.core.config().clone())
            .unwrap_or_default();
        let now = self.now;
        let mut core = Core::new(peer, slots, config, seed);
        let others: Vec<PeerId> = self.live_peers().collect();
        for &other in &others {
            core.handle_peer_connected(now, other);
        }
        let node = Node {
            core,
            state: NodeState::Up,
            deadline: None,
        };
        self.nodes.insert(peer, node);
        self.flush(peer);
        for other in others {
            if self.report_rtt {
                let round_trip = self.round_trip(other, peer);
                self.node(other).core.handle_rtt(peer, round_trip);
                let round_trip = self.round_trip(peer, other);
                self.node(peer).core.handle_rtt(other, round_trip);
            }
            self.node(other).core.handle_peer_connected(now, peer);
            self.flush(other);
        }
    }

    /// Asks `peer` to leave the render `owner` owns ([`Core::leave`]). Once it reports
    /// [`Event::Left`] it goes as a closed connection does: what it sent still arrives, and the
    /// others learn of it after `loss_detection`.
    pub fn leave(&mut self, peer: PeerId, owner: PeerId) {
        let now = self.now;
        self.node(peer).core.leave(now, owner);
        self.flush(peer);
    }

    /// Stops `peer` without closing its connections, as a long pause or a partition would.
    pub fn freeze(&mut self, peer: PeerId) {
        self.node(peer).state = NodeState::Frozen(Vec::new());
        self.rearm(peer);
    }

    /// Resumes a frozen peer; what reached it meanwhile arrives now, in order.
    pub fn thaw(&mut self, peer: PeerId) {
        let state = std::mem::replace(&mut self.node(peer).state, NodeState::Up);
        if let NodeState::Frozen(held) = state {
            for happening in held {
                self.schedule(Duration::ZERO, happening);
            }
        }
        self.rearm(peer);
    }

    /// Removes the next happening (a deadline first on a tie) and moves the clock to it.
    fn take_next(&mut self) -> Option<Happening> {
        let deadline = self.deadlines.first().copied();
        let entry = self.agenda.peek().map(|entry| entry.at);
        let happening = match (deadline, entry) {
            (Some((at, peer)), entry) if entry.is_none_or(|entry| at <= entry) => {
                self.now = self.now.max(at);
                Happening::Timeout { peer }
            }
            (_, Some(_)) => {
                let entry = self.agenda.pop().expect("invariant: peeked just above");
                self.now = self.now.max(entry.at);
                *entry.happening
            }
            (_, None) => return None,
        };
        Some(happening)
    }

    fn apply(&mut self, happening: Happening) {
        let peer = match &happening {
            Happening::Deliver { to, .. } => *to,
            Happening::Rendered { peer, .. }
            | Happening::Lost { peer, .. }
            | Happening::Timeout { peer } => *peer,
        };
        let (now, encode) = (self.now, self.encode);
        // The round trip the receiver's driver reports with a delivered message.
        let reported = match &happening {
            Happening::Deliver { from, .. } if self.report_rtt => {
                Some(self.round_trip(peer, *from))
            }
            _ => None,
        };
        let node = self
            .nodes
            .get_mut(&peer)
            .expect("invariant: only peers of the cluster are scheduled");
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
            Happening::Deliver {
                from,
                message,
                bytes,
                ..
            } => {
                let message = if encode {
                    wire::decode(&wire::encode(&message), &wire::Limits::default())
                        .expect("invariant: what the core sends decodes")
                } else {
                    message
                };
                node.core.record_bytes(0, bytes);
                if let Some(round_trip) = reported {
                    node.core.handle_rtt(from, round_trip);
                }
                if let Err(error) = node.core.handle_message(now, from, message) {
                    let seen = Seen::Refused { peer, from, error };
                    self.world.observe(now, seen);
                }
            }
            Happening::Rendered { result, .. } => node.core.handle_tile_rendered(now, result),
            Happening::Lost { lost, .. } => node.core.handle_peer_lost(now, lost),
            Happening::Timeout { .. } => node.core.handle_timeout(now),
        }
        self.flush(peer);
    }

    /// Moves a core's outputs into the agenda and the world, and re-reads its deadline.
    fn flush(&mut self, peer: PeerId) {
        let now = self.now;
        while let Some(item) = self.node(peer).core.poll_work() {
            self.world.observe(now, Seen::Started { peer, item: &item });
            let Rendered { duration, result } = self.world.render(now, peer, &item);
            self.schedule(duration, Happening::Rendered { peer, result });
        }
        while let Some((to, message)) = self.node(peer).core.poll_transmit() {
            let seen = Seen::Sent {
                from: peer,
                to,
                message: &message,
            };
            self.world.observe(now, seen);
            if self
                .nodes
                .get(&to)
                .is_some_and(|node| !matches!(node.state, NodeState::Dead))
            {
                let jitter = self.rng.below(self.jitter.as_nanos() as usize + 1);
                let delay = self.latency + Duration::from_nanos(jitter as u64);
                let transit = self.world.transit(now, peer, to, &message, delay);
                self.node(peer).core.record_bytes(transit.bytes, 0);
                let deliver = Happening::Deliver {
                    from: peer,
                    to,
                    message,
                    bytes: transit.bytes,
                };
                self.schedule(transit.delay, deliver);
            }
        }
        let mut left = false;
        while let Some(event) = self.node(peer).core.poll_event() {
            left |= event == Event::Left;
            self.world.observe(now, Seen::Event { peer, event });
        }
        if left {
            self.kill(peer, false);
        }
        self.rearm(peer);
    }

    /// Brings `peer`'s entry in `deadlines` up to date: its core's deadline if it is up.
    fn rearm(&mut self, peer: PeerId) {
        let node = self
            .nodes
            .get_mut(&peer)
            .expect("invariant: only peers of the cluster are rearmed");
        let due = match node.state {
            NodeState::Up => node.core.poll_timeout(),
            NodeState::Frozen(_) | NodeState::Dead => None,
        };
        if due != node.deadline {
            if let Some(old) = node.deadline {
                self.deadlines.remove(&(old, peer));
            }
            if let Some(new) = due {
                self.deadlines.insert((new, peer));
            }
            node.deadline = due;
        }
    }

    fn schedule(&mut self, after: Duration, happening: Happening) {
        let entry = Entry {
            at: self.now + after,
            seq: self.next_seq,
            happening: Box::new(happening),
        };
        self.agenda.push(entry);
        self.next_seq += 1;
    }

    fn node(&mut self, peer: PeerId) -> &mut Node {
        self.nodes
            .get_mut(&peer)
            .expect("invariant: callers name peers of the cluster")
    }

    fn live_peers(&self) -> impl Iterator<Item = PeerId> + '_ {
        let alive = |(_, node): &(&PeerId, &Node)| !matches!(node.state, NodeState::Dead);
        self.nodes.iter().filter(alive).map(|(peer, _)| *peer)
    }
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        (self.at, self.seq) == (other.at, other.seq)
    }
}

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    /// Reversed, so that the max-heap's top is the earliest entry.
    fn cmp(&self, other: &Self) -> Ordering {
        (other.at, other.seq).cmp(&(self.at, self.seq))
    }
}
