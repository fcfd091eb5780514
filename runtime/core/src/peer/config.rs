//! The scheduling policy: every knob the core's mechanism consults, with defaults.
//!
//! Kept apart from the mechanism so that the simulator can sweep policies over the same core, and
//! so that a knob's meaning is written in one place.

use std::time::Duration;

/// Scheduling policy of one peer. All peers of a cluster should use the same policy.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// Whether peers steal from each other at all. Off, each peer renders its assignment plus
    /// whatever the owner re-issues to it, and refuses every steal request.
    pub steal: bool,
    /// Tiles a peer keeps committed to its renderer beyond those in its slots: never given to
    /// thieves, and with fewer than this waiting it steals even before it can estimate its work
    /// rate. With 0 it steals, before an estimate exists, only when a slot would otherwise idle.
    pub prefetch_depth: usize,
    /// The low-water mark, in round trips: a peer steals when the predicted work it holds would
    /// last less than this many round trips at its measured work rate, so that stolen tiles
    /// arrive before its renderer runs dry.
    pub low_water_rtts: f64,
    /// A victim refuses when the work it would give would take it less than this many round
    /// trips to render itself: the transfer would not pay.
    pub min_grant_rtts: f64,
    /// Smallest total predicted cost (in the predictor's units) worth giving in one grant.
    /// 0 leaves the decision to `min_grant_rtts` alone.
    pub min_steal_cost: f64,
    /// Most tiles in one grant.
    pub max_grant_tiles: usize,
    /// Which peers a thief asks, in which order.
    pub victims: VictimOrder,
    /// Most victims one round asks before the thief backs off. A cluster of at most this many
    /// other peers is asked in full, each once; a larger one by this many draws. Without a
    /// bound, every idle peer of `P` asks all `P - 1` others at the end of each frame: `P²`
    /// requests a round, most of them to peers as idle as the thief.
    pub victims_per_round: usize,
    /// Round-trip time assumed until one is measured (from steal exchanges or the driver).
    pub initial_rtt: Duration,
    /// A steal request unanswered for this long counts as refused; a grant arriving later is
    /// still kept, never dropped.
    pub steal_timeout: Duration,
    /// After every victim of a round refused, a thief waits this long before its next round,
    /// twice as long after two fruitless rounds in a row, and so on up to `steal_backoff_max`.
    /// A grant, new work or a new frame start again from `steal_backoff`.
    pub steal_backoff: Duration,
    /// The longest backoff (see `steal_backoff`).
    pub steal_backoff_max: Duration,
    /// A peer holding work tells the owner it is alive when it has sent the owner nothing for
    /// this long.
    pub heartbeat_interval: Duration,
    /// The owner declares a peer failed, and re-issues the tiles it holds, when the peer may hold
    /// work and has sent nothing for this long. Keep it several heartbeat intervals long.
    pub peer_timeout: Duration,
}

/// The order in which a thief tries its victims.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VictimOrder {
    /// As rayon does: a random first victim (from the core's seeded generator), then the
    /// others in turn; beyond `victims_per_round` others, that many victims drawn at random.
    /// Spreads thieves over victims.
    RandomStart,
    /// The peer after this one in id order first, then the others in turn (the nearest
    /// `victims_per_round` of them). No randomness; all thieves of a ring lean on their
    /// neighbours.
    Ring,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            steal: true,
            prefetch_depth: 1,
            low_water_rtts: 2.0,
            min_grant_rtts: 1.0,
            min_steal_cost: 0.0,
            max_grant_tiles: 64,
            victims: VictimOrder::RandomStart,
            victims_per_round: 8,
            initial_rtt: Duration::from_millis(1),
            steal_timeout: Duration::from_millis(250),
            steal_backoff: Duration::from_millis(10),
            steal_backoff_max: Duration::from_millis(80),
            heartbeat_interval: Duration::from_secs(1),
            peer_timeout: Duration::from_secs(10),
        }
    }
}
