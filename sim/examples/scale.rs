//! How fast the simulator is at the issue's scale: 1024 peers, 100 frames of 16k tiles (a
//! synthetic 1024x1024 hot spot, PBT with stealing, links of 0.1 ms). Prints the wall time and the pump's
//! throughput. A measurement, not a test: speed targets live outside the test suite.
//!
//! ```text
//! cargo run --release -p sim --example scale -- [PEERS [FRAMES [TILES [POLICY [LATENCY_MS]]]]]
//! ```

use std::time::Instant;

use balancer::{Config, Grid, Partitioner};
use sim::Policy;
use sim::scenario::{self, Scenario};
use sim::synthetic::HotSpot;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or_else(|| default.to_string());
    let peers: usize = arg(0, "1024").parse()?;
    let frames: u32 = arg(1, "100").parse()?;
    let tiles: usize = arg(2, "16384").parse()?;
    let policy: Policy = arg(3, "pbt+steal").parse()?;
    let latency: f64 = arg(4, "0.1").parse()?;
    let started = Instant::now();
    let trace = HotSpot {
        frames,
        period: f64::from(frames),
        ..HotSpot::default()
    }
    .trace()?;
    let made = started.elapsed().as_secs_f64();
    let side = (tiles as f64).sqrt().round() as u32;
    let config = Config {
        kind: policy.kind,
        leaves: tiles,
        grid: Grid::Count {
            columns: side,
            rows: side,
        },
        ..Config::default()
    };
    let partitioner = Partitioner::new(trace.width(), trace.height(), &config)?;
    let mut scenario = Scenario {
        peers,
        ..Scenario::default()
    };
    scenario.network.latency = std::time::Duration::from_secs_f64(latency / 1e3);
    scenario.core.steal = policy.steal;
    let run = scenario::run(&trace, partitioner, &scenario)?;
    println!(
        "{peers} peers, {frames} frames, {} tiles, {policy}, {latency} ms: {:.2} s simulating ({:.2} s making the trace), {} happenings ({:.2} M/s), {} messages, efficiency {:.4} (bound {:.4})",
        run.tiles,
        run.wall_seconds,
        made,
        run.steps,
        run.steps as f64 / run.wall_seconds / 1e6,
        run.messages,
        run.efficiency,
        run.bound_efficiency
    );
    Ok(())
}
