//! The accounting of each frame of a run: what the owner planned when it dealt the frame (its
//! capacity, work, largest tile, result bytes and control-loop time), and the frame's report,
//! which sets that plan against what the world tallied. It is one unit because it is the run's
//! arithmetic; the run loop in the parent module only decides when frames are dealt and measured.

use std::time::Duration;

use runtime_core::director;
use runtime_core::wire::PeerId;

use super::Scenario;
use crate::report::FrameReport;
use crate::world::SimWorld;

/// What the owner planned for one frame, to set against what happened.
pub(super) struct Plan {
    capacity: f64,
    fastest: f64,
    participants: usize,
    work: f64,
    largest: f64,
    pub(super) splits: usize,
    pub(super) merges: usize,
    /// Bytes of one result per tile, as the wire encodes them, wherever they are rendered.
    results: u64,
    /// The owner's control-loop seconds to deal every tile and receive one result per tile.
    owner_time: f64,
}

/// What the owner plans for the frame of `deal`, costed by `map`.
pub(super) fn plan(
    deal: &director::Deal,
    map: &balancer::CostMap,
    speeds: &[f64],
    scenario: &Scenario,
    block: u32,
) -> Plan {
    let seconds_per_unit = 1.0 / scenario.work_per_second;
    let speed = |p: PeerId| speeds[p.0 as usize];
    Plan {
        capacity: deal.participants().map(speed).sum::<f64>() * scenario.slots as f64,
        fastest: deal.participants().map(speed).fold(0.0, f64::max),
        participants: deal.participants().count(),
        work: map.total() * seconds_per_unit,
        largest: deal
            .tiles
            .iter()
            .map(|t| map.cost(t.rect))
            .fold(0.0, f64::max)
            * seconds_per_unit,
        splits: 0,
        merges: 0,
        results: deal.tiles.iter().map(|t| result_bytes(t.rect, block)).sum(),
        owner_time: deal
            .tiles
            .iter()
            .map(|t| {
                (scenario.owner.result(t.rect.area()) + scenario.owner.per_dealt_tile).as_secs_f64()
            })
            .sum(),
    }
}

/// The encoded size of a tile result covering `rect`, with its pixels and a cost map of `block`
/// pixels a side, as the wire format counts it without building the buffers (which, for a
/// trace of a 4294967295-pixel-wide image, could not be allocated).
fn result_bytes(rect: balancer::Rect, block: u32) -> u64 {
    runtime_core::wire::tile_result_len(rect, block)
}

pub(super) fn frame_report(
    frame: u32,
    plan: &Plan,
    interval: Duration,
    world: &SimWorld,
    scenario: &Scenario,
) -> FrameReport {
    let slots = scenario.slots;
    let tally = &world.frames[&frame];
    let makespan = interval.as_secs_f64();
    // A tile that can be cut on the way (rendered in pieces, or halved for a thief) no longer
    // bounds its frame: then the fair share alone does.
    let cuttable = scenario.render_piece_factor.is_some()
        || (scenario.core.steal && scenario.core.split_on_steal);
    let fair_share = plan.work / plan.capacity;
    let lower_bound = if cuttable {
        fair_share
    } else {
        fair_share.max(plan.largest / plan.fastest)
    };
    let slot_time = (plan.participants * slots) as f64 * makespan;
    FrameReport {
        frame,
        tiles: tally.tiles,
        participants: plan.participants,
        capacity: plan.capacity,
        makespan,
        work: plan.work,
        largest_tile: plan.largest,
        lower_bound,
        efficiency: if makespan > 0.0 {
            plan.work / (plan.capacity * makespan)
        } else {
            1.0
        },
        bound_efficiency: if lower_bound > 0.0 {
            plan.work / (plan.capacity * lower_bound)
        } else {
            1.0
        },
        idle_fraction: if slot_time > 0.0 {
            (1.0 - tally.busy / slot_time).max(0.0)
        } else {
            0.0
        },
        renders: tally.renders,
        pieces: tally.pieces,
        duplicates_agreed: tally.audit.agreed,
        tiles_reissued: tally.audit.reissued,
        tiles_backed_up: tally.audit.backed_up,
        results_ok: tally.results_ok,
        steal_requests: tally.steal_requests,
        grants: tally.grants,
        stolen_tiles: tally.stolen_tiles,
        messages: tally.messages,
        bytes: tally.bytes,
        failures: tally.failures,
        faults: tally.faults,
        splits: plan.splits,
        merges: plan.merges,
        result_bytes: tally.result_bytes,
        owner_busy: tally.owner_busy,
        frame_result_bytes: plan.results,
        frame_owner_time: plan.owner_time,
    }
}
