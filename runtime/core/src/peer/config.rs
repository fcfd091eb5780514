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
    /// Round-trip time steals are planned with until one is measured: the driver's of a link
    /// (`Core::handle_rtt`), then this peer's own steal exchanges'.
    pub initial_rtt: Duration,
    /// A steal request unanswered for this long counts as refused; a grant arriving later is
    /// still kept, never dropped. The longest wait: see `steal_timeout_rtts`.
    pub steal_timeout: Duration,
    /// A request times out sooner, after this many measured round trips (but never under
    /// 2 ms), so that a victim that froze or died costs its thieves a few round trips, not
    /// `steal_timeout`. Giving up early is always safe: a late grant is still kept.
    pub steal_timeout_rtts: f64,
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
    /// work and has sent nothing for this long, and for at least three round trips of its link
    /// (`Core::handle_rtt`); after the owner sends it tiles, counted from a round trip later.
    /// Keep it several heartbeat intervals long.
    pub peer_timeout: Duration,
    /// Whether a victim whose farthest tile is worth more than it should give cuts it in half
    /// (again and again, down to `min_piece_pixels`) and gives the far half, rather than giving
    /// the whole tile or nothing. Off, tiles only ever move whole.
    pub split_on_steal: bool,
    /// The smallest piece a victim cuts a tile into, in pixels: below this a transfer costs more
    /// than the work it moves. One 8x8 block (the unit the tracer measures cost in) by default.
    pub min_piece_pixels: u64,
    /// When a piece of a tile has rendered, whether the rest of that tile still queued here is
    /// predicted anew from it: its predicted cost is scaled by what the piece took against what
    /// its prediction said at this peer's pace (within [`RELEARN_BOUND`] either way). A tile
    /// the prediction got wrong (all of them, on a frame cut blind) then shows its true weight
    /// to thieves, who take a fair share of it instead of judging it by its area. Off, pieces
    /// keep the tile's prediction shared by area.
    pub relearn_pieces: bool,
    /// (Owner) When to render again, elsewhere, work that is overdue on a peer; `None`: never
    /// (a peer that stops answering then costs its silence timeout, `peer_timeout` or more).
    pub speculation: Option<Speculation>,
    /// (Owner) The share of a frame's predicted cost still missing at which its ledger reports
    /// it waning ([`Event::FrameWaning`](crate::peer::Event::FrameWaning)), the director's cue
    /// to deal the next frame; it also reports it when the first participant runs out of work.
    /// Earlier hides more of the frame's end behind the next frame's work; the next frame is
    /// then predicted from older costs. Default 0.5.
    pub waning: f64,
}

/// How far one rendered piece may scale the prediction of the rest of its tile, either way
/// ([`Config::relearn_pieces`]): one piece's time is a noisy sample (a thread descheduled, a
/// cache cold), and a bound keeps a single outlier from making the rest look free or endless.
pub const RELEARN_BOUND: f64 = 16.0;

/// When the owner gives copies of a straggler's work to idle peers, as MapReduce's backup tasks
/// and Spark's speculation do. A missing tile is *overdue* when the participants believed to
/// hold it have made no progress (sent no result, received no work) for `factor` times its
/// predicted time, and at least `min_wait`; its predicted time is its predicted cost at the
/// frame's pace so far (the predicted cost of the results received, per participant-second).
/// While some participant is idle, the owner re-issues the unrendered pieces of overdue tiles to
/// the idle ones, each tile at most once. The first result wins; a second must be bit-identical
/// (checked, and counted in the frame's audit). The straggler itself is not declared failed: a
/// peer stalled for seconds that then resumes has only wasted its work, and `peer_timeout`
/// still decides when it is forgotten.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Speculation {
    /// How many times its predicted time a tile may go without progress before it is overdue.
    pub factor: f64,
    /// The least time without progress that makes a tile overdue, whatever its prediction.
    pub min_wait: Duration,
}

impl Default for Speculation {
    fn default() -> Self {
        Self {
            factor: 4.0,
            min_wait: Duration::from_millis(50),
        }
    }
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
            steal_timeout_rtts: 20.0,
            steal_backoff: Duration::from_millis(10),
            steal_backoff_max: Duration::from_millis(80),
            heartbeat_interval: Duration::from_secs(1),
            peer_timeout: Duration::from_secs(10),
            split_on_steal: true,
            min_piece_pixels: crate::wire::MIN_PIECE_PIXELS,
            relearn_pieces: true,
            speculation: Some(Speculation::default()),
            waning: 0.5,
        }
    }
}
