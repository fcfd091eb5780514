//! The director driven over a virtual-time cluster of real cores (`peer::testing`), and alone.

use std::time::Duration;

use balancer::{CostMap, Grid, Kind, Partitioner};

use super::*;
use crate::peer::PeerStats;
use crate::peer::testing::{Cluster, Record, cost_renderer};

mod membership;
mod resumed;

const OWNER: PeerId = PeerId(0);
const SIDE: u32 = 32;

fn grid(columns: u32, rows: u32) -> Partitioner {
    let config = balancer::Config {
        kind: Kind::Regular,
        grid: Grid::Count { columns, rows },
        ..balancer::Config::default()
    };
    Partitioner::new(SIDE, SIDE, &config).expect("a valid grid")
}

fn pbt(leaves: usize) -> Partitioner {
    let config = balancer::Config {
        leaves,
        ..balancer::Config::default()
    };
    Partitioner::new(SIDE, SIDE, &config).expect("a valid PBT")
}

/// A cost map whose left half costs `left` per block and right half 1.
fn halves(left: u64) -> CostMap {
    let blocks = SIDE / 8;
    let counts: Vec<u64> = (0..blocks * blocks)
        .map(|i| if i % blocks < blocks / 2 { left } else { 1 })
        .collect();
    CostMap::from_counts(SIDE, SIDE, 8, &counts).expect("a valid map")
}

/// Drives `director` over `cluster` until it finishes, measuring every frame with `measure`.
/// Returns the deals, the director's events, and the owner core's events it was given.
fn drive(
    director: &mut Director,
    cluster: &mut Cluster,
    measure: &dyn Fn(FrameId) -> CostMap,
) -> (Vec<Deal>, Vec<Event>) {
    let mut deals = Vec::new();
    let mut events = Vec::new();
    let mut seen = 0;
    for _ in 0..100_000 {
        let now = cluster.now();
        while let Some(deal) = director.poll_deal(now).expect("the balancer deals") {
            cluster
                .start_frame(OWNER, deal.frame, deal.assignments.clone())
                .expect("the core starts the dealt frame");
            deals.push(deal);
        }
        let fresh: Vec<crate::peer::Event> = cluster.trace()[seen..]
            .iter()
            .filter_map(|record| match record {
                Record::Event { peer, event, .. } if *peer == OWNER => Some(event.clone()),
                _ => None,
            })
            .collect();
        seen = cluster.trace().len();
        for event in fresh {
            director
                .handle_core_event(now, event)
                .expect("no faults here");
        }
        let mut measured = false;
        while let Some(event) = director.poll_event() {
            if let Event::FrameComplete { frame, .. } = &event {
                director
                    .handle_measured(now, *frame, &measure(*frame))
                    .expect("the frame waits for its map");
                measured = true;
            }
            events.push(event);
        }
        if director.is_finished() {
            return (deals, events);
        }
        if measured {
            continue;
        }
        let due = [cluster.next_due(), director.poll_timeout()]
            .into_iter()
            .flatten()
            .min();
        match due {
            Some(at) if Some(at) == director.poll_timeout() && cluster.next_due() != Some(at) => {
                cluster.run(at);
                director.handle_timeout(at);
            }
            Some(_) => {
                cluster.step();
            }
            None => panic!("nothing left to happen and the director is not finished"),
        }
    }
    panic!("the director did not finish");
}

/// The owner core's completion of frame 0, without results (for the director alone).
fn empty_completion() -> crate::peer::Event {
    crate::peer::Event::FrameComplete {
        frame: FrameId(0),
        elapsed: Duration::ZERO,
        results: Vec::new(),
        rendered_by: Vec::new(),
        audit: crate::peer::Audit::default(),
    }
}

fn cluster(peers: u32) -> Cluster {
    let ids: Vec<(PeerId, usize)> = (0..peers).map(|p| (PeerId(p), 1)).collect();
    Cluster::new(
        &crate::peer::Config::default(),
        &ids,
        1,
        cost_renderer(1e-4),
    )
}

fn director(partitioner: Partitioner, peers: u32, frames: u32) -> Director {
    director_in_flight(
        partitioner,
        peers,
        frames,
        Config::default().frames_in_flight,
    )
}

/// A director dealing up to `in_flight` frames before they are measured.
fn director_in_flight(
    partitioner: Partitioner,
    peers: u32,
    frames: u32,
    in_flight: usize,
) -> Director {
    let config = Config {
        frames,
        frames_in_flight: in_flight,
        ..Config::default()
    };
    let mut director = Director::new(OWNER, partitioner, config);
    for p in 1..peers {
        director.handle_peer_joined(Duration::ZERO, PeerId(p));
    }
    director
}

#[test]
fn every_frame_deals_each_tile_once_and_completes_with_one_piece_per_tile() {
    for peers in [1, 2, 5] {
        let mut cluster = cluster(peers);
        let mut director = director(grid(4, 4), peers, 3);
        let (deals, events) = drive(&mut director, &mut cluster, &|_| halves(5));
        assert_eq!(deals.len(), 3);
        for deal in &deals {
            assert_eq!(deal.participants().count(), peers as usize);
            let mut dealt: Vec<u32> = deal
                .assignments
                .values()
                .flatten()
                .map(|spec| spec.id.0)
                .collect();
            dealt.sort_unstable();
            assert_eq!(dealt, (0..16).collect::<Vec<_>>());
            for (peer, specs) in &deal.assignments {
                for spec in specs {
                    assert_eq!(deal.initial[spec.id.0 as usize], *peer);
                    assert_eq!(deal.tiles[spec.id.0 as usize].rect, spec.rect);
                }
            }
        }
        let completed: Vec<&Event> = events
            .iter()
            .filter(|e| matches!(e, Event::FrameComplete { .. }))
            .collect();
        assert_eq!(completed.len(), 3);
        for (frame, event) in completed.iter().enumerate() {
            let Event::FrameComplete {
                frame: id, pieces, ..
            } = event
            else {
                unreachable!("filtered above")
            };
            assert_eq!(id.0, frame as u32);
            let ids: Vec<u32> = pieces.iter().map(|p| p.result.tile.0).collect();
            assert_eq!(ids, (0..16).collect::<Vec<_>>());
            for piece in pieces.iter() {
                let deal = &deals[frame];
                assert_eq!(piece.initial, deal.initial[piece.result.tile.0 as usize]);
                assert_eq!(
                    piece.predicted,
                    deal.tiles[piece.result.tile.0 as usize].predicted
                );
            }
        }
        assert_eq!(events.last(), Some(&Event::Finished));
    }
}

#[test]
fn the_next_frame_is_cut_from_the_measured_map() {
    // Frame 0 knows nothing: equal leaves. A frame cut from a map whose left half costs 15
    // times the right has smaller leaves on the left, and all predicted nearly equal. Frame 1
    // waits for frame 0's measurement even with two frames in flight: dealt earlier, it would
    // be cut blind as well.
    let left = |deal: &Deal| {
        deal.tiles
            .iter()
            .filter(|t| t.rect.right() <= u64::from(SIDE / 2))
            .count()
    };
    for (in_flight, first_measured) in [(1, 1), (2, 1)] {
        let mut cluster = cluster(3);
        let mut director = director_in_flight(pbt(16), 3, 3, in_flight);
        let (deals, _) = drive(&mut director, &mut cluster, &|_| halves(15));
        for deal in &deals[..first_measured] {
            assert_eq!(left(deal) * 2, deal.tiles.len(), "{in_flight} in flight");
        }
        for deal in &deals[first_measured..] {
            assert!(
                left(deal) > deal.tiles.len() * 3 / 4,
                "{in_flight} in flight: {} of {} leaves on the costly half",
                left(deal),
                deal.tiles.len()
            );
        }
    }
}

#[test]
fn with_one_frame_in_flight_nothing_is_dealt_while_a_frame_runs_or_waits_for_its_measure() {
    let mut director = director_in_flight(grid(2, 2), 1, 2, 1);
    let deal = director
        .poll_deal(Duration::ZERO)
        .unwrap()
        .expect("frame 0");
    assert_eq!(deal.frame, FrameId(0));
    assert!(director.poll_deal(Duration::ZERO).unwrap().is_none());
    assert!(matches!(
        director.handle_measured(Duration::ZERO, FrameId(0), &halves(1)),
        Err(DirectorError::NotWaiting { .. })
    ));
    let complete = empty_completion();
    director
        .handle_core_event(Duration::ZERO, complete)
        .unwrap();
    assert!(director.poll_deal(Duration::ZERO).unwrap().is_none());
    assert!(matches!(
        director.handle_measured(Duration::ZERO, FrameId(1), &halves(1)),
        Err(DirectorError::NotWaiting { .. })
    ));
    director
        .handle_measured(Duration::ZERO, FrameId(0), &halves(1))
        .unwrap();
    let next = director
        .poll_deal(Duration::ZERO)
        .unwrap()
        .expect("frame 1");
    assert_eq!(next.frame, FrameId(1));
}

/// The owner core's completion of `frame`, without results (for the director alone).
fn completion(frame: u32) -> crate::peer::Event {
    match empty_completion() {
        crate::peer::Event::FrameComplete {
            elapsed,
            results,
            rendered_by,
            audit,
            ..
        } => crate::peer::Event::FrameComplete {
            frame: FrameId(frame),
            elapsed,
            results,
            rendered_by,
            audit,
        },
        _ => unreachable!("empty_completion is a completion"),
    }
}

/// With two frames in flight: while the prediction is doubted (no frame measured, or the last
/// measured missed) a frame runs alone in small pieces; once trusted, the next frame is dealt
/// when the running one wanes, never more than two are dealt and unmeasured, and frames reach
/// the driver in order even when a later one completes first.
#[test]
fn the_next_frame_is_dealt_when_the_running_one_wanes_and_frames_are_handed_over_in_order() {
    let t = Duration::ZERO;
    let mut director = director_in_flight(grid(2, 2), 1, 7, 2);
    let wane = |frame| crate::peer::Event::FrameWaning {
        frame: FrameId(frame),
    };
    let frame_of = |deal: Option<Deal>| deal.map(|deal| deal.frame.0);
    let config = Config::default();
    let mean_area = 32.0 * 32.0 / 4.0;
    let pieces = |factor: Option<f64>| {
        ((factor.expect("pieces by default") * mean_area) as u64).max(wire::MIN_PIECE_PIXELS)
    };
    // Frames 0 and 1 are doubted: frame 0 is cut by area alone, and its tiles miss the
    // measured costs, which frame 1 is then cut from; frame 1 meets them exactly.
    for frame in 0..2 {
        let deal = director.poll_deal(t).unwrap().expect("a doubted frame");
        assert_eq!(deal.frame, FrameId(frame));
        assert_eq!(deal.render_pixels, pieces(config.doubtful_piece_factor));
        director.handle_core_event(t, wane(frame)).unwrap();
        assert!(
            director.poll_deal(t).unwrap().is_none(),
            "frame {frame} is doubted"
        );
        director.handle_core_event(t, completion(frame)).unwrap();
        assert!(matches!(
            director.poll_event(),
            Some(Event::FrameComplete { .. })
        ));
        director
            .handle_measured(t, FrameId(frame), &halves(3))
            .unwrap();
    }
    let trusted = director.poll_deal(t).unwrap().expect("frame 2");
    assert_eq!(trusted.frame, FrameId(2));
    assert_eq!(trusted.render_pixels, pieces(config.render_piece_factor));
    assert_eq!(
        frame_of(director.poll_deal(t).unwrap()),
        None,
        "frame 2 has not waned"
    );
    assert!(director.handle_core_event(t, wane(2)).unwrap().is_none());
    assert_eq!(frame_of(director.poll_deal(t).unwrap()), Some(3));
    // Frame 3 wanes too, but two frames are already unmeasured.
    director.handle_core_event(t, wane(3)).unwrap();
    assert_eq!(
        frame_of(director.poll_deal(t).unwrap()),
        None,
        "two in flight"
    );
    // Frame 3 completes first: it is held until frame 2 is in.
    director.handle_core_event(t, completion(3)).unwrap();
    assert!(director.poll_event().is_none());
    assert_eq!(frame_of(director.poll_deal(t).unwrap()), None);
    director.handle_core_event(t, completion(2)).unwrap();
    let handed: Vec<u32> = std::iter::from_fn(|| director.poll_event())
        .map(|event| match event {
            Event::FrameComplete { frame, .. } => frame.0,
            Event::Finished => u32::MAX,
        })
        .collect();
    assert_eq!(handed, [2, 3]);
    assert!(matches!(
        director.handle_measured(t, FrameId(3), &halves(3)),
        Err(DirectorError::NotWaiting { .. })
    ));
    director.handle_measured(t, FrameId(2), &halves(3)).unwrap();
    // Frame 3 is complete but unmeasured, and nothing runs: frame 4 may go.
    assert_eq!(frame_of(director.poll_deal(t).unwrap()), Some(4));
    assert_eq!(
        frame_of(director.poll_deal(t).unwrap()),
        None,
        "two in flight"
    );
    // Frame 3 missed: its costs moved (the costly half is now the right one).
    let moved = {
        let blocks = SIDE / 8;
        let counts: Vec<u64> = (0..blocks * blocks)
            .map(|i| if i % blocks < blocks / 2 { 1 } else { 3 })
            .collect();
        CostMap::from_counts(SIDE, SIDE, 8, &counts).expect("a valid map")
    };
    director.handle_measured(t, FrameId(3), &moved).unwrap();
    // So frame 5 waits for frame 4's measurement, however early frame 4 wanes.
    director.handle_core_event(t, wane(4)).unwrap();
    assert_eq!(
        frame_of(director.poll_deal(t).unwrap()),
        None,
        "the prediction is doubted"
    );
    director.handle_core_event(t, completion(4)).unwrap();
    assert!(matches!(
        director.poll_event(),
        Some(Event::FrameComplete { .. })
    ));
    // Frame 4 was cut before frame 3's costs were known: it missed as well.
    director.handle_measured(t, FrameId(4), &moved).unwrap();
    let doubted = director.poll_deal(t).unwrap().expect("frame 5");
    assert_eq!(doubted.render_pixels, pieces(config.doubtful_piece_factor));
    director.handle_core_event(t, wane(5)).unwrap();
    assert_eq!(
        frame_of(director.poll_deal(t).unwrap()),
        None,
        "frame 5 runs alone"
    );
    director.handle_core_event(t, completion(5)).unwrap();
    assert!(director.poll_event().is_some());
    director.handle_measured(t, FrameId(5), &moved).unwrap();
    let next = director.poll_deal(t).unwrap().expect("frame 6");
    assert_eq!(
        next.render_pixels,
        pieces(config.render_piece_factor),
        "trusted again"
    );
}

/// The end of a render waits for every participant's statistics, for a participant that
/// leaves, or for the grace period, whichever comes first; never longer.
#[test]
fn the_last_frame_waits_for_statistics_leavers_or_the_grace_period() {
    let stats = |peer: u32| crate::peer::Event::PeerStats {
        frame: FrameId(0),
        peer: PeerId(peer),
        stats: PeerStats::default(),
    };
    let complete = empty_completion();
    let t0 = Duration::from_secs(5);
    let ended = |leave: bool, report: &[u32], wait: Duration| {
        let mut director = director(grid(2, 2), 3, 1);
        director.poll_deal(Duration::ZERO).unwrap();
        director.handle_core_event(t0, complete.clone()).unwrap();
        director
            .handle_measured(t0, FrameId(0), &halves(1))
            .unwrap();
        for &peer in report {
            director.handle_core_event(t0, stats(peer)).unwrap();
        }
        if leave {
            director.handle_peer_left(t0, PeerId(2));
        }
        director.handle_timeout(t0 + wait);
        director.is_finished()
    };
    let grace = Config::default().stats_grace;
    assert!(ended(false, &[0, 1, 2], Duration::ZERO), "all reported");
    assert!(
        !ended(false, &[0, 1], Duration::ZERO),
        "peer 2 has not reported"
    );
    assert!(ended(true, &[0, 1], Duration::ZERO), "peer 2 left");
    assert!(!ended(false, &[0], grace - Duration::from_millis(1)));
    assert!(ended(false, &[0], grace), "the grace period ran out");
}

#[test]
fn frames_dealt_ahead_are_predicted_where_a_moving_spot_will_be() {
    // A spot crossing a 256-pixel image by 3 blocks a frame, on a grid of 8 x 8 tiles of 4 x 4
    // blocks. From frame 2 on (two measurements show the motion), the tile predicted costliest
    // is the one the spot is in at the frame dealt, whether that frame is one after the last
    // measured (one in flight) or two (two in flight: the prediction is aimed further when the
    // frame is dealt). Without motion compensation it lags behind.
    const SIDE: u32 = 256;
    let centre = |frame: u32| 4.0 + 3.0 * f64::from(frame);
    let measure = |frame: FrameId| {
        CostMap::from_fn(SIDE, SIDE, 8, |c, r| {
            let (dx, dy) = (f64::from(c) - centre(frame.0), f64::from(r) - 16.0);
            1.0 + 1000.0 * (-(dx * dx + dy * dy) / 4.5).exp()
        })
        .expect("a valid map")
    };
    let hottest_holds_the_spot = |motion: Option<u32>, in_flight: usize| {
        let config = balancer::Config {
            kind: Kind::Regular,
            grid: Grid::Count {
                columns: 8,
                rows: 8,
            },
            motion,
            ..balancer::Config::default()
        };
        let partitioner = Partitioner::new(SIDE, SIDE, &config).expect("a valid grid");
        let mut cluster = cluster(3);
        let mut director = director_in_flight(partitioner, 3, 7, in_flight);
        let (deals, _) = drive(&mut director, &mut cluster, &measure);
        assert_eq!(deals.len(), 7);
        deals[2..].iter().all(|deal| {
            let hottest = deal
                .tiles
                .iter()
                .max_by(|a, b| a.predicted.total_cmp(&b.predicted))
                .expect("a deal has tiles");
            let x = (centre(deal.frame.0) * 8.0 + 4.0) as u64;
            hottest.rect.x as u64 <= x && x < hottest.rect.right()
        })
    };
    for in_flight in [1, 2] {
        assert!(
            hottest_holds_the_spot(Some(16), in_flight),
            "{in_flight} in flight"
        );
        assert!(
            !hottest_holds_the_spot(None, in_flight),
            "{in_flight} in flight, no motion"
        );
    }
}
