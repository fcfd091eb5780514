//! What a run yields, frame by frame, and the CSV and JSON files experiments write.
//!
//! Definitions (times in virtual seconds; "work" is counted work converted to the time one slot
//! of a speed-1 peer needs for it):
//! - **makespan**: the frame's interval, from when the frame before it was handed over (or from
//!   its own start, if later) to its own hand-over; frames are handed over in order. Without
//!   frames in flight that is from the owner starting the frame to its core reporting every
//!   tile in; with them, frames overlap and the intervals add up to the run, each moment once,
//!   so a frame whose work was partly done in the interval before can show an efficiency
//!   above 1.
//! - **capacity**: the frame's participants' speed factors times their slots (`P` for equal
//!   peers with one slot each).
//! - **efficiency** = work / (capacity x makespan): 1 when every slot renders from the first
//!   instant to the last and nothing is rendered twice.
//! - **lower bound** on the makespan = max(work / capacity, largest tile / fastest speed): no
//!   schedule of this partition can beat it. Where tiles can be cut on the way (rendered in
//!   pieces, or halved for thieves), the largest tile is no bound, and the lower bound is the
//!   fair share work / capacity alone. **bound efficiency** is the efficiency a run
//!   achieving it would have, so efficiency <= bound efficiency <= 1 always.
//! - **idle fraction** = 1 - busy slot time / (participant slots x makespan): slot time spent
//!   not rendering (waiting for work, for the network, or for the frame's last tile). The busy
//!   time is that of the frame's own tiles, wherever it fell, so with frames in flight it is a
//!   frame's share rather than its interval's (clamped at 0).
//!
//! A run's totals add frames up: efficiency = total work / sum of (capacity x makespan).

use std::fmt::Write as _;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::plot::GanttBar;
use crate::{Error, Policy, Scenario};

/// One frame of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameReport {
    /// The frame's number.
    pub frame: u32,
    /// Tiles the frame was cut into.
    pub tiles: usize,
    /// Peers the owner dealt tiles to.
    pub participants: usize,
    /// Their speed factors times their slots.
    pub capacity: f64,
    /// The frame's interval, in virtual seconds (see the module documentation).
    pub makespan: f64,
    /// The frame's work, in slot-seconds of a speed-1 peer.
    pub work: f64,
    /// The work of its most expensive tile.
    pub largest_tile: f64,
    /// No schedule of this partition can take less time than this.
    pub lower_bound: f64,
    /// Work over capacity times makespan: 1 is perfect.
    pub efficiency: f64,
    /// The efficiency a run reaching the lower bound would have.
    pub bound_efficiency: f64,
    /// The share of slot time spent not rendering.
    pub idle_fraction: f64,
    /// Pieces handed to renderers: `tiles`, plus the extra pieces of tiles cut on the way, plus
    /// any rendered twice (re-issued after a failure, or backed up).
    pub renders: usize,
    /// Results the frame was assembled from: one per tile, or more where tiles were cut.
    #[serde(default)]
    pub pieces: usize,
    /// Duplicate results the owner compared with the first and found bit-identical.
    #[serde(default)]
    pub duplicates_agreed: u32,
    /// Tiles the owner gave again because no live holder was rendering them.
    #[serde(default)]
    pub tiles_reissued: u32,
    /// Tiles of overdue peers the owner copied to idle peers.
    #[serde(default)]
    pub tiles_backed_up: u32,
    /// The owner's completion covered every tile exactly once, in tile order.
    pub results_ok: bool,
    /// Steal requests sent by all peers in the frame.
    pub steal_requests: u64,
    /// Steal requests answered with tiles, and the tiles they moved.
    pub grants: u64,
    /// Tiles moved by those grants.
    pub stolen_tiles: u64,
    /// Messages of this frame sent by all peers, and their bytes.
    pub messages: u64,
    /// Bytes of those messages.
    pub bytes: u64,
    /// Peers the owner declared failed during the frame.
    pub failures: u64,
    /// Results or messages a core refused; always 0 unless something is broken.
    pub faults: u64,
    /// What the balancer's update after this frame did (PBT leaves split and merged).
    pub splits: usize,
    /// PBT sibling pairs merged by the same update.
    pub merges: usize,
    /// Bytes of the tile results that reached the owner over the network (every result,
    /// duplicates included; not the owner's own).
    pub result_bytes: u64,
    /// Seconds the owner's control loop spent on the frame's deals and remote results.
    pub owner_busy: f64,
    /// Bytes of one result per tile of the frame, wherever rendered: `S` of the owner-link limit.
    pub frame_result_bytes: u64,
    /// The owner's seconds to deal every tile and receive one result per tile.
    pub frame_owner_time: f64,
}

/// One run: its configuration, its frames and its totals.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// How frames were cut, and whether peers stole.
    pub policy: Policy,
    /// Peers, the owner included.
    pub peers: usize,
    /// Tiles each peer renders at once.
    pub slots: usize,
    /// Tiles of the first frame (the PBT's leaf count, or the grid's cells).
    pub tiles: usize,
    /// The seed of the run's randomness (victims, jitter, loss).
    pub seed: u64,
    /// The network's one-way latency, in milliseconds.
    pub latency_ms: f64,
    /// Each link's bandwidth; `None` for unlimited.
    pub bandwidth_bytes_per_second: Option<f64>,
    /// The probability that a transmission is lost and resent.
    pub loss: f64,
    /// Counted work a speed-1 slot renders per second, which turns work into time.
    pub work_per_second: f64,
    /// The fixed cost of rendering one tile, in milliseconds.
    pub tile_overhead_ms: f64,
    /// Totals over all frames (see the module documentation).
    pub makespan: f64,
    /// Work of all frames.
    pub work: f64,
    /// Total work over the sum of capacity times makespan.
    pub efficiency: f64,
    /// The efficiency a run reaching every frame's lower bound would have.
    pub bound_efficiency: f64,
    /// The share of slot time spent not rendering, over all frames.
    pub idle_fraction: f64,
    /// Steal requests answered with tiles, over all frames.
    pub steals: u64,
    /// Messages sent, over all frames.
    pub messages: u64,
    /// Bytes sent, over all frames.
    pub bytes: u64,
    /// A hash of every output of every core in order, with its time: equal for equal runs.
    pub fingerprint: String,
    /// Happenings the pump processed (messages delivered, tiles rendered, timeouts).
    pub steps: u64,
    /// Real seconds the simulation took (not part of the fingerprint).
    pub wall_seconds: f64,
    /// The owner-link limit P = T1 x B / S: one peer's frame time (T1, work over one peer's
    /// slots) times the link's bandwidth (B) over the bytes of a frame's results (S), averaged
    /// over frames. Beyond this many peers the owner's downlink, not rendering, sets the pace.
    /// `None` on unlimited links.
    pub owner_link_limit: Option<f64>,
    /// The owner-CPU limit: T1 over the owner's control-loop seconds to deal and receive a whole
    /// frame. `None` for a free owner.
    pub owner_cpu_limit: Option<f64>,
    /// Each frame's report, in order.
    pub frames: Vec<FrameReport>,
    /// The frame the scenario asked to draw, and every render of it.
    pub gantt_frame: Option<u32>,
    /// The bars of the Gantt chart of `gantt_frame`, for drawing only (not saved).
    #[serde(skip)]
    pub gantt: Vec<GanttBar>,
    /// Each frame's tiles in partition order with the peer that started with each, if the
    /// scenario asked to keep them.
    #[serde(skip)]
    pub assignments: Vec<Vec<(balancer::Rect, u32)>>,
}

impl RunReport {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        policy: Policy,
        scenario: &Scenario,
        tiles: usize,
        frames: Vec<FrameReport>,
        fingerprint: u64,
        steps: u64,
        gantt: Vec<GanttBar>,
        wall_seconds: f64,
    ) -> Self {
        let sum = |f: &dyn Fn(&FrameReport) -> f64| frames.iter().map(f).sum::<f64>();
        let slots = scenario.slots as f64;
        let work = sum(&|f| f.work);
        let capacity_time = sum(&|f| f.capacity * f.makespan);
        let bound_time = sum(&|f| f.capacity * f.lower_bound);
        let slot_time = sum(&|f| f.participants as f64 * slots * f.makespan);
        let idle_time = sum(&|f| f.idle_fraction * f.participants as f64 * slots * f.makespan);
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 1.0 };
        let one_peer = work / slots;
        let result_bytes = frames.iter().map(|f| f.frame_result_bytes).sum::<u64>() as f64;
        let owner_busy = sum(&|f| f.frame_owner_time);
        let owner_link_limit = scenario
            .network
            .bandwidth
            .filter(|_| result_bytes > 0.0)
            .map(|bandwidth| one_peer * bandwidth / result_bytes);
        let owner_cpu_limit = (owner_busy > 0.0).then(|| one_peer / owner_busy);
        Self {
            policy,
            peers: scenario.peers,
            slots: scenario.slots,
            tiles,
            seed: scenario.seed,
            latency_ms: scenario.network.latency.as_secs_f64() * 1e3,
            bandwidth_bytes_per_second: scenario.network.bandwidth,
            loss: scenario.network.loss,
            work_per_second: scenario.work_per_second,
            tile_overhead_ms: scenario.tile_overhead.as_secs_f64() * 1e3,
            makespan: sum(&|f| f.makespan),
            work,
            efficiency: ratio(work, capacity_time),
            bound_efficiency: ratio(work, bound_time),
            idle_fraction: ratio(idle_time, slot_time),
            steals: frames.iter().map(|f| f.grants).sum(),
            messages: frames.iter().map(|f| f.messages).sum(),
            bytes: frames.iter().map(|f| f.bytes).sum(),
            fingerprint: format!("{fingerprint:016x}"),
            steps,
            wall_seconds,
            owner_link_limit,
            owner_cpu_limit,
            frames,
            gantt_frame: scenario.gantt_frame,
            gantt,
            assignments: Vec::new(),
        }
    }

    /// Whether every frame completed with exactly one result per tile and nothing refused.
    pub fn all_tiles_once(&self) -> bool {
        self.frames.iter().all(|f| f.results_ok && f.faults == 0)
    }
}

const RUN_COLUMNS: &str = "policy,peers,slots,tiles,frames,latency_ms,bandwidth_bytes_per_second,loss,tile_overhead_ms,makespan_s,work_s,efficiency,bound_efficiency,idle_fraction,steals,messages,bytes,steps,wall_s,fingerprint";

const FRAME_COLUMNS: &str = "policy,peers,tiles,frame,frame_tiles,participants,capacity,makespan_s,work_s,largest_tile_s,lower_bound_s,efficiency,bound_efficiency,idle_fraction,renders,steal_requests,grants,stolen_tiles,messages,bytes,failures,splits,merges";

/// Writes `runs.csv` (one row per run), `frames.csv` (one row per run and frame) and
/// `runs.json` (everything) into `dir`.
pub fn write_runs(dir: &Path, runs: &[RunReport]) -> Result<(), Error> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut csv = format!("{RUN_COLUMNS}\n");
    for r in runs {
        let bandwidth = r
            .bandwidth_bytes_per_second
            .map_or(String::new(), |b| b.to_string());
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{:.9},{:.9},{:.6},{:.6},{:.6},{},{},{},{},{:.3},{}",
            r.policy,
            r.peers,
            r.slots,
            r.tiles,
            r.frames.len(),
            r.latency_ms,
            bandwidth,
            r.loss,
            r.tile_overhead_ms,
            r.makespan,
            r.work,
            r.efficiency,
            r.bound_efficiency,
            r.idle_fraction,
            r.steals,
            r.messages,
            r.bytes,
            r.steps,
            r.wall_seconds,
            r.fingerprint,
        );
    }
    write(&dir.join("runs.csv"), &csv)?;
    let mut csv = format!("{FRAME_COLUMNS}\n");
    for r in runs {
        for f in &r.frames {
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{},{},{:.9},{:.9},{:.9},{:.9},{:.6},{:.6},{:.6},{},{},{},{},{},{},{},{},{}",
                r.policy,
                r.peers,
                r.tiles,
                f.frame,
                f.tiles,
                f.participants,
                f.capacity,
                f.makespan,
                f.work,
                f.largest_tile,
                f.lower_bound,
                f.efficiency,
                f.bound_efficiency,
                f.idle_fraction,
                f.renders,
                f.steal_requests,
                f.grants,
                f.stolen_tiles,
                f.messages,
                f.bytes,
                f.failures,
                f.splits,
                f.merges,
            );
        }
    }
    write(&dir.join("frames.csv"), &csv)?;
    let json = serde_json::to_string_pretty(runs).expect("reports always serialise");
    write(&dir.join("runs.json"), &json)
}

pub(crate) fn write(path: &Path, text: &str) -> Result<(), Error> {
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}

/// The table `tessera simulate` prints: a line per run. Its last two columns are the owner
/// limits, the peer counts beyond which the owner's downlink (T1 x B / S) or its control loop,
/// not rendering, sets the pace (`-` where there is none).
pub fn table(runs: &[RunReport]) -> String {
    let mut text = format!(
        "{:>14} {:>6} {:>6} {:>10} {:>8} {:>8} {:>11} {:>8} {:>10} {:>8} {:>9} {:>9}\n",
        "policy",
        "peers",
        "tiles",
        "efficiency",
        "bound",
        "idle",
        "makespan s",
        "steals",
        "messages",
        "wall s",
        "link P",
        "owner P"
    );
    let limit = |p: Option<f64>| p.map_or("-".to_string(), |p| format!("{p:.0}"));
    for r in runs {
        let _ = writeln!(
            text,
            "{:>14} {:>6} {:>6} {:>10.4} {:>8.4} {:>8.4} {:>11.4} {:>8} {:>10} {:>8.2} {:>9} {:>9}",
            r.policy.to_string(),
            r.peers,
            r.tiles,
            r.efficiency,
            r.bound_efficiency,
            r.idle_fraction,
            r.makespan,
            r.steals,
            r.messages,
            r.wall_seconds,
            limit(r.owner_link_limit),
            limit(r.owner_cpu_limit)
        );
    }
    text
}
