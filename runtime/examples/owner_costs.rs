//! Measures what the frame owner's CPU spends per tile besides rendering, with the real code:
//! per tile result received (the wire decoder, the owner core's ledger, decoding its pixels and
//! costs, copying them into the frame) and per tile dealt (the director's cut and deal, the core's
//! `start_frame`, encoding the `Assign`s). The simulator's `OwnerCosts` defaults come from this.
//!
//! `cargo run --release -p runtime --example owner_costs`
//!
//! Prints, for tiles of several sizes, the time per result, and a least-squares line
//! `per result + per pixel x pixels`; and the time per dealt tile at several tile counts.

use std::time::{Duration, Instant};

use balancer::{Grid, Kind, Partitioner};
use runtime::node::bundle;
use runtime_core::director::{self, Director};
use runtime_core::peer::{Config, Core};
use runtime_core::wire::{self, FrameId, Message, PeerId, TileResult};

const OWNER: PeerId = PeerId(0);
const PEERS: u32 = 8;

fn grid(side: u32, columns: u32) -> Partitioner {
    let config = balancer::Config {
        kind: Kind::Regular,
        grid: Grid::Count {
            columns,
            rows: columns,
        },
        ..balancer::Config::default()
    };
    Partitioner::new(side, side, &config).expect("a valid grid")
}

/// An owner core with `PEERS - 1` remote peers, its director's first frame started.
fn started(partitioner: Partitioner) -> (Core, director::Deal) {
    let mut core = Core::new(OWNER, 1, Config::default(), 1);
    let mut director = Director::new(OWNER, partitioner, director::Config::default());
    for p in 1..PEERS {
        core.handle_peer_connected(Duration::ZERO, PeerId(p));
        director.handle_peer_joined(Duration::ZERO, PeerId(p));
    }
    let deal = director
        .poll_deal(Duration::ZERO)
        .expect("the grid deals")
        .expect("a first frame");
    core.start_frame(
        Duration::ZERO,
        deal.frame,
        deal.assignments.clone(),
        deal.render_pixels,
    )
    .expect("the core starts it");
    while core.poll_transmit().is_some() {}
    (core, deal)
}

/// Seconds per result received, for tiles of `tile` pixels a side on a `side`-pixel image.
fn per_result(side: u32, tile: u32) -> (f64, u64) {
    let (mut core, deal) = started(grid(side, side / tile));
    let mut film = tracer::Film::new(side, side);
    // The encoded results, as they would arrive, made before the clock starts.
    let arriving: Vec<(PeerId, Vec<u8>)> = deal
        .assignments
        .iter()
        .filter(|(peer, _)| **peer != OWNER)
        .flat_map(|(&peer, specs)| {
            specs.iter().map(move |spec| {
                let rect = bundle::tracer_rect(spec.rect);
                let (_, _, bw, bh) = rect.blocks();
                let pixels = vec![[0.5f32, 0.25, 0.125]; rect.area() as usize];
                let cost = tracer::TileCost {
                    rays: 1,
                    work: 1,
                    blocks: vec![1; (bw * bh) as usize],
                };
                let result = TileResult {
                    frame: FrameId(0),
                    tile: spec.id,
                    piece: spec.piece,
                    rect: spec.rect,
                    pixels: bundle::encode_pixels(&pixels),
                    costs: bundle::encode_cost(&cost),
                };
                (peer, wire::encode(&Message::TileDone(result)))
            })
        })
        .collect();
    let limits = wire::Limits {
        max_message_bytes: usize::MAX,
        ..wire::Limits::default()
    };
    let count = arriving.len();
    let clock = Instant::now();
    for (peer, bytes) in arriving {
        let message = wire::decode(&bytes, &limits).expect("our own encoding");
        let Message::TileDone(result) = &message else {
            unreachable!("encoded as a TileDone")
        };
        let rect = bundle::tracer_rect(result.rect);
        let pixels = bundle::decode_pixels(&result.pixels).expect("our own pixels");
        let cost = bundle::decode_cost(&result.costs).expect("our own costs");
        film.insert(rect, &pixels, &cost);
        core.handle_message(Duration::ZERO, peer, message)
            .expect("a result of the running frame");
        while core.poll_transmit().is_some() {}
    }
    let seconds = clock.elapsed().as_secs_f64() / count as f64;
    std::hint::black_box(&film);
    (seconds, u64::from(tile) * u64::from(tile))
}

/// Seconds per dealt tile, for `columns x columns` tiles.
fn per_dealt(columns: u32) -> f64 {
    let repeats = 20;
    let clock = Instant::now();
    for _ in 0..repeats {
        let (mut core, deal) = started(grid(2048, columns));
        let mut bytes = 0;
        while let Some((_, message)) = core.poll_transmit() {
            bytes += wire::encode(&message).len();
        }
        std::hint::black_box((bytes, deal));
    }
    clock.elapsed().as_secs_f64() / f64::from(repeats * columns * columns)
}

fn main() {
    println!("per tile result received (decode, ledger, pixels into the frame):");
    let mut points = Vec::new();
    for tile in [8, 16, 32, 64, 128] {
        // Take the fastest of five runs: the machine is shared, and slower runs measure others.
        let best = (0..5)
            .map(|_| per_result(1024, tile))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("five runs");
        println!("  {tile:>4}x{tile:<4} {:>9.2} us", best.0 * 1e6);
        points.push((best.1 as f64, best.0));
    }
    let n = points.len() as f64;
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |(sx, sy), (x, y)| (sx + x, sy + y));
    let sxx: f64 = points.iter().map(|(x, _)| x * x).sum();
    let sxy: f64 = points.iter().map(|(x, y)| x * y).sum();
    let slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    let intercept = (sy - slope * sx) / n;
    println!(
        "  fit: {:.2} us per result + {:.2} ns per pixel",
        intercept * 1e6,
        slope * 1e9
    );
    println!("per tile dealt (cut, deal, start_frame, encode the Assigns):");
    for columns in [16, 32, 64] {
        let best = (0..5)
            .map(|_| per_dealt(columns))
            .fold(f64::INFINITY, f64::min);
        println!("  {:>6} tiles {:>9.2} us", columns * columns, best * 1e6);
    }
}
