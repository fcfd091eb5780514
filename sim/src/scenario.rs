//! One simulated run: a trace, a balancer, a cluster and a network, frame after frame.
//!
//! The frame owner's loop is the real owner's: the same [`Director`] the QUIC node drives deals
//! each frame to the live participants, the owner's core runs it, and when the core reports it
//! complete the director is given the frame's measured cost map (the trace's) and re-cuts the
//! partition for the next frame. Only time is virtual. The owner's control loop is charged per
//! tile dealt and per result received ([`OwnerCosts`]); its work between frames (writing the
//! image, re-cutting the tree) is not simulated: the next frame starts the instant the last one
//! completes.
//!
//! Time is counted work divided by a rate: a slot of a peer of speed 1 renders
//! [`Scenario::work_per_second`] units of counted work per second. The default,
//! [`DEFAULT_WORK_PER_SECOND`], was measured on the development machine (see its docs);
//! ratios such as efficiency do not depend on it, but latency and bandwidth effects do, since
//! they compare network time with render time.
//!
//! - `accounting`: what the owner plans for each frame when it deals it, and the frame's report,
//!   which sets that plan against what happened.

use std::collections::btree_map::Entry;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::{Duration, Instant};

use balancer::Partitioner;
use runtime_core::director::{self, Director};
use runtime_core::peer::Config;
use runtime_core::peer::testing::Cluster;
use runtime_core::wire::PeerId;

pub use crate::knobs::{Crash, CrashWhen, OwnerCosts};
use crate::network::Links;
use crate::report::RunReport;
use crate::sweep::Policy;
use crate::world::SimWorld;
use crate::{Error, Network, Trace};

mod accounting;

use accounting::{Plan, frame_report, plan};

/// The peer that owns every frame (and renders too, like any other).
pub const OWNER: PeerId = PeerId(0);

/// Counted work one rendering thread renders per second on the development machine (2 AMD
/// EPYC cores, otherwise idle, both rendering): `cargo run --release -p sim --example
/// record_trace` on the shipped glass-cluster-pan scene did 1.77e9 units in 15.0 to 15.3
/// thread-seconds, each tile timed alone (1.16e8 to 1.18e8 per thread-second). Pass `--rate`
/// for another machine or scene.
pub const DEFAULT_WORK_PER_SECOND: f64 = 1.17e8;

/// Memory one simulated run holds per pair of peers: each peer's core keeps what it knows of
/// every other (its queue as last heard, its round trip), so a run's memory grows as the square
/// of its peers. Measured (`/usr/bin/time -f %M`, `tessera simulate synthetic:16x12:2 --tiles
/// 4`): 60 MB at 1,024 peers, 732 MB at 4,096 (44 bytes a pair), rounded up.
pub const BYTES_PER_PEER_PAIR: u64 = 64;

/// About how much memory a run of `peers` peers holds at its peak (see
/// [`BYTES_PER_PEER_PAIR`]): what a caller checks against the machine's before starting one.
pub fn memory_estimate(peers: usize) -> u64 {
    let peers = peers as u64;
    peers
        .saturating_mul(peers)
        .saturating_mul(BYTES_PER_PEER_PAIR)
}

/// Everything a run needs besides the trace and the balancer. Every effect is off by default.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Peers, the owner (peer 0) included.
    pub peers: usize,
    /// Tiles each peer renders at once (its rendering threads).
    pub slots: usize,
    /// The scheduling policy every core runs.
    pub core: Config,
    /// Latency, bandwidth, loss and failure detection between peers.
    pub network: Network,
    /// Speed factors, dealt to peers in turn: peer `p` renders at `speeds[p % len]` times the
    /// rate. Empty means all 1.
    pub speeds: Vec<f64>,
    /// Peers that crash, and when.
    pub crashes: Vec<Crash>,
    /// Seeds the cores' victim choice, the jitter, the links and the loss.
    pub seed: u64,
    /// Counted work per second of one slot of a speed-1 peer.
    pub work_per_second: f64,
    /// Time a slot of a speed-1 peer spends on each tile besides its counted work (setting up
    /// its camera rays, encoding and sending its result): what makes many small tiles cost
    /// more than a few big ones. Not work: efficiency counts it as lost time.
    pub tile_overhead: Duration,
    /// What the frame owner's CPU spends per tile besides rendering (default: measured).
    pub owner: OwnerCosts,
    /// Frames to simulate; `None`: as many as the trace has (more repeat it from the start).
    pub frames: Option<usize>,
    /// The frame whose renders are kept for a Gantt chart.
    pub gantt_frame: Option<u32>,
    /// Keep every frame's initial assignment (tile rectangles and their peers) in the report,
    /// to compare with a real render's.
    pub keep_assignments: bool,
    /// The director's bound on the pieces peers render at once, as a multiple of the frame's
    /// mean tile area (`runtime_core::director::Config::render_piece_factor`).
    pub render_piece_factor: Option<f64>,
    /// Frames dealt before the last is measured, at most
    /// (`runtime_core::director::Config::frames_in_flight`): 1 puts a barrier between frames.
    pub frames_in_flight: usize,
    /// When the director doubts its prediction (`director::Config::doubt_error`).
    pub doubt_error: f64,
    /// Pieces while the prediction is doubted (`director::Config::doubtful_piece_factor`).
    pub doubtful_piece_factor: Option<f64>,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            peers: 1,
            slots: 1,
            core: Config::default(),
            network: Network::default(),
            speeds: Vec::new(),
            crashes: Vec::new(),
            seed: 0,
            work_per_second: DEFAULT_WORK_PER_SECOND,
            tile_overhead: Duration::ZERO,
            owner: OwnerCosts::MEASURED,
            frames: None,
            gantt_frame: None,
            keep_assignments: false,
            render_piece_factor: director::Config::default().render_piece_factor,
            frames_in_flight: director::Config::default().frames_in_flight,
            doubt_error: director::Config::default().doubt_error,
            doubtful_piece_factor: director::Config::default().doubtful_piece_factor,
        }
    }
}

impl Scenario {
    fn validate(&self) -> Result<(), Error> {
        let bad = |message: &str| Err(Error::Scenario(message.to_string()));
        if self.peers == 0 || self.slots == 0 {
            return bad("a cluster needs at least one peer with one slot");
        }
        if self.peers > u32::MAX as usize {
            return bad("too many peers");
        }
        if self.speeds.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
            return bad("speed factors must be positive");
        }
        if !(self.work_per_second > 0.0 && self.work_per_second.is_finite()) {
            return bad("the work rate must be positive");
        }
        if let Some(crash) = self.crashes.iter().find(|c| c.peer as usize >= self.peers) {
            return Err(Error::Scenario(format!(
                "peer {} cannot crash: the cluster has peers 0 to {}",
                crash.peer,
                self.peers - 1
            )));
        }
        if self.crashes.iter().any(|c| PeerId(c.peer) == OWNER) {
            return bad("the owner (peer 0) cannot crash: its frame would die with it");
        }
        if self
            .crashes
            .iter()
            .any(|c| c.when == CrashWhen::Starting(0))
        {
            return bad("a crash on starting a tile counts tiles from 1");
        }
        self.network.validate().map_err(Error::Scenario)
    }

    /// Each peer's speed factor.
    fn peer_speeds(&self) -> Vec<f64> {
        (0..self.peers)
            .map(|p| match self.speeds.len() {
                0 => 1.0,
                n => self.speeds[p % n],
            })
            .collect()
    }
}

/// Simulates `scenario` on `trace`, the owner cutting frames with `partitioner` (which must
/// cover the trace's image).
pub fn run(
    trace: &Trace,
    partitioner: Partitioner,
    scenario: &Scenario,
) -> Result<RunReport, Error> {
    scenario.validate()?;
    if (partitioner.width(), partitioner.height()) != (trace.width(), trace.height()) {
        return Err(Error::Scenario(format!(
            "the balancer cuts {}x{} images but the trace is {}x{}",
            partitioner.width(),
            partitioner.height(),
            trace.width(),
            trace.height()
        )));
    }
    let wall = Instant::now();
    let maps = trace.cost_maps()?;
    let frames = scenario.frames.unwrap_or(maps.len());
    // Frames are numbered in a `u32` everywhere (the wire, the tracer, the trace's files).
    let frames = u32::try_from(frames)
        .map_err(|_| Error::Scenario(format!("{frames} frames: at most {} fit", u32::MAX)))?;
    let speeds = scenario.peer_speeds();
    let seconds_per_unit = 1.0 / scenario.work_per_second;
    let network = &scenario.network;
    let links = Links::new(network.clone(), scenario.peers, scenario.seed);
    let overhead = scenario.tile_overhead.as_secs_f64();
    let mut world = SimWorld::new(
        maps,
        (seconds_per_unit, overhead),
        speeds.clone(),
        links,
        scenario.gantt_frame,
    );
    world.owner_costs = scenario.owner;
    let peers: Vec<(PeerId, usize)> = (0..scenario.peers)
        .map(|p| (PeerId(p as u32), scenario.slots))
        .collect();
    let mut cluster = Cluster::with_world(&scenario.core, &peers, scenario.seed, world);
    cluster.latency = network.latency;
    cluster.jitter = network.jitter;
    cluster.loss_detection = network.loss_detection;
    cluster.encode = false;
    // The cores learn each link's round trip as the QUIC driver tells them (`Core::handle_rtt`):
    // an owner times a peer's silence by it (told none, it timed silence as if links had no
    // delay), and a peer seeds its steal plans with it until it has timed an exchange.
    cluster.report_rtt = true;

    let mut crashes: Vec<(Duration, u32)> = Vec::new();
    let mut on_start: Vec<(u32, u64)> = Vec::new();
    for crash in &scenario.crashes {
        match crash.when {
            CrashWhen::At(at) => crashes.push((at, crash.peer)),
            CrashWhen::Starting(tile) => on_start.push((crash.peer, tile)),
        }
    }
    crashes.sort();
    let mut crashes = VecDeque::from(crashes);
    let mut crashed: BTreeMap<PeerId, Duration> = BTreeMap::new();
    // The crashed peers the director has been told have left.
    let mut left: BTreeSet<PeerId> = BTreeSet::new();
    let mut plans: BTreeMap<u32, Plan> = BTreeMap::new();
    let mut assignments = Vec::new();
    let mut steps = 0u64;
    let policy = Policy::of(&partitioner, &scenario.core);
    let first_tiles = partitioner.tiles().len();
    let block = trace.header.block_size;
    let config = director::Config {
        frames,
        render_piece_factor: scenario.render_piece_factor,
        frames_in_flight: scenario.frames_in_flight,
        doubt_error: scenario.doubt_error,
        doubtful_piece_factor: scenario.doubtful_piece_factor,
        ..director::Config::default()
    };
    let mut director = Director::new(OWNER, partitioner, config);
    for &(peer, _) in &peers {
        director.handle_peer_joined(Duration::ZERO, peer);
    }
    // One loop over the cluster's events: the director deals a frame whenever it is ready
    // (the first at once, each next one when the running frame wanes or is measured), and
    // measures each frame as it is handed over, in order.
    while !director.is_finished() {
        let now = cluster.now();
        // The owner deals to the peers it is connected to: a crashed peer until its
        // connection times out. Each is reported once (this loop runs at every happening).
        for (&peer, &at) in &crashed {
            if now >= at + network.loss_detection && left.insert(peer) {
                director.handle_peer_left(now, peer);
            }
        }
        while let Some(deal) = director.poll_deal(now)? {
            let frame = deal.frame.0;
            plans.insert(
                frame,
                plan(&deal, cluster.world().map(frame), &speeds, scenario, block),
            );
            if scenario.keep_assignments {
                let dealt = deal
                    .tiles
                    .iter()
                    .zip(&deal.initial)
                    .map(|(t, p)| (t.rect, p.0));
                assignments.push(dealt.collect());
            }
            cluster
                .world_mut()
                .begin_frame(frame, now, deal.initial.clone());
            cluster.start_frame_in_pieces(
                OWNER,
                deal.frame,
                deal.assignments,
                deal.render_pixels,
            )?;
        }
        feed(&mut director, &mut cluster)?;
        let mut handed = false;
        while let Some(event) = director.poll_event() {
            if let director::Event::FrameComplete { frame: done, .. } = event {
                let update = director.handle_measured(now, done, cluster.world().map(done.0))?;
                let plan = plans
                    .get_mut(&done.0)
                    .expect("invariant: every completed frame was planned when dealt");
                (plan.splits, plan.merges) = (update.splits, update.merges);
                handed = true;
            }
        }
        if handed || director.is_finished() {
            // A measured frame may let the next be dealt at this same instant.
            continue;
        }
        let due = cluster.next_due();
        if let Some(&(at, peer)) = crashes.front().filter(|c| due.is_none_or(|d| c.0 <= d)) {
            crashes.pop_front();
            cluster.run(at);
            if let Entry::Vacant(entry) = crashed.entry(PeerId(peer)) {
                cluster.kill(*entry.key(), false);
                entry.insert(cluster.now());
            }
            continue;
        }
        let grace = director.poll_timeout();
        if due.is_none() || grace.is_some_and(|g| due.is_some_and(|d| g < d)) {
            if let Some(deadline) = grace {
                // Only statistics are awaited: the grace period decides.
                cluster.run(deadline.max(cluster.now()));
                director.handle_timeout(deadline.max(cluster.now()));
                continue;
            }
            return Err(stalled(&cluster));
        }
        cluster.advance();
        steps += 1;
        if !on_start.is_empty() {
            let started = &cluster.world().starts;
            let (due, waiting) = on_start
                .iter()
                .partition(|(peer, tile)| started[*peer as usize] >= *tile);
            on_start = waiting;
            for (peer, _) in due {
                if let Entry::Vacant(entry) = crashed.entry(PeerId(peer)) {
                    cluster.kill(*entry.key(), false);
                    entry.insert(cluster.now());
                }
            }
        }
        feed(&mut director, &mut cluster)?;
    }
    // Let the last messages travel, for the message counts.
    while cluster.advance().is_some() {
        steps += 1;
        feed(&mut director, &mut cluster)?;
    }
    let plans: Vec<Plan> = plans.into_values().collect();
    let world = cluster.into_world();
    // Frames overlap, so a frame's time is its interval: from when the frame before it was
    // handed over (or from its own start, if later) to its own hand-over, frames being handed
    // over in order. The intervals add up to the run, each moment counted once.
    let mut handed_over = Duration::ZERO;
    let frame_reports = plans
        .iter()
        .enumerate()
        .map(|(frame, plan)| {
            let tally = &world.frames[&(frame as u32)];
            let (completed, _) = tally
                .completed
                .expect("invariant: the run loop waits for every frame to complete");
            let from = handed_over.max(tally.started);
            handed_over = handed_over.max(completed);
            let interval = handed_over.saturating_sub(from);
            frame_report(frame as u32, plan, interval, &world, scenario)
        })
        .collect();
    let mut report = RunReport::new(
        policy,
        scenario,
        first_tiles,
        frame_reports,
        world.fingerprint.0,
        steps,
        world.gantt,
        wall.elapsed().as_secs_f64(),
    );
    report.assignments = assignments;
    Ok(report)
}

/// The error of a run with nothing left to happen: the oldest incomplete frame stalled.
fn stalled(cluster: &Cluster<SimWorld>) -> Error {
    let world = cluster.world();
    let (frame, tally) = world
        .frames
        .iter()
        .find(|(_, tally)| tally.completed.is_none())
        .map_or((0, None), |(frame, tally)| (*frame, Some(tally)));
    Error::Stalled {
        frame,
        at: cluster.now(),
        missing: tally.map_or(0, |t| t.tiles.saturating_sub(t.renders)),
    }
}

/// Hands the owner core's events since the last call to the director.
fn feed(director: &mut Director, cluster: &mut Cluster<SimWorld>) -> Result<(), Error> {
    let now = cluster.now();
    for event in cluster.world_mut().take_owner_events() {
        director.handle_core_event(now, event)?;
    }
    Ok(())
}
