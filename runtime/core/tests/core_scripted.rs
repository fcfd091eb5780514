//! The scheduling core driven directly: an owner and a few peers in virtual time
//! (`runtime_core::peer::testing::Cluster`), every message through the wire encoding, no sockets.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::time::Duration;

use balancer::Rect;
use proptest::prelude::*;
use runtime_core::peer::testing::{
    Cluster, Happening, Record, Rendered, cost_renderer, synthetic_result,
};
use runtime_core::peer::{
    Audit, Config, Core, Event, Failure, Fault, FrameError, PeerStats, ProtocolError, VictimOrder,
};
use runtime_core::wire::{FrameId, Message, PeerId, TileId, TileResult, TileSpec};

/// Peers dying, freezing and racing, and results that disagree.
#[path = "core_scripted/faults.rs"]
mod faults;

/// Far links: silence timeouts against round trips.
#[path = "core_scripted/links.rs"]
mod links;

/// Peers that join a running render, and peers that leave it when asked.
#[path = "core_scripted/elastic.rs"]
mod elastic;

/// The end of a frame: tiles cut on steal and rendered in pieces, stragglers backed up.
#[path = "core_scripted/tails.rs"]
mod tails;

/// Steal requests: what a victim refuses, a thief's rounds and backoffs, a ring thief's order.
#[path = "core_scripted/requests.rs"]
mod requests;

/// A frame resumed from the results an earlier run kept.
#[path = "core_scripted/resumed.rs"]
mod resumed;

const OWNER: PeerId = PeerId(0);
const LIMIT: Duration = Duration::from_secs(60);
/// One unit of predicted cost takes a millisecond of virtual time.
const MS_PER_UNIT: f64 = 1e-3;

/// Tiles `first..` with the given costs, laid out in a row of 4x4 rectangles.
fn tiles(first: u32, costs: &[f64]) -> Vec<TileSpec> {
    sized_tiles(first, costs, 4)
}

/// Tiles `first..` with the given costs, in a row of `side` x `side` squares.
fn sized_tiles(first: u32, costs: &[f64], side: u32) -> Vec<TileSpec> {
    (0..costs.len() as u32)
        .map(|i| {
            TileSpec::whole(
                TileId(first + i),
                Rect::new((first + i) * side, 0, side, side),
                costs[i as usize],
            )
        })
        .collect()
}

/// Splits `costs` into contiguous runs, one per peer `0..peers`.
fn contiguous(peers: u32, costs: &[f64]) -> BTreeMap<PeerId, Vec<TileSpec>> {
    contiguous_tiles(peers, tiles(0, costs))
}

/// Splits `all` into contiguous runs, one per peer `0..peers`.
fn contiguous_tiles(peers: u32, all: Vec<TileSpec>) -> BTreeMap<PeerId, Vec<TileSpec>> {
    let run = all.len().div_ceil(peers as usize);
    (0..peers)
        .map(|p| {
            (
                PeerId(p),
                all.iter()
                    .skip(p as usize * run)
                    .take(run)
                    .copied()
                    .collect(),
            )
        })
        .collect()
}

/// Runs until everything has settled (a minute of virtual time is far more than any test
/// needs).
fn finish(cluster: &mut Cluster) {
    cluster.run(cluster.now() + LIMIT);
}

fn cluster(config: &Config, peers: u32, slots: usize, seed: u64) -> Cluster {
    let peers: Vec<(PeerId, usize)> = (0..peers).map(|p| (PeerId(p), slots)).collect();
    Cluster::new(config, &peers, seed, cost_renderer(MS_PER_UNIT))
}

fn no_steal() -> Config {
    Config {
        steal: false,
        ..Config::default()
    }
}

/// The one `FrameComplete` of `frame`, with the time it took.
fn completion(cluster: &Cluster, frame: FrameId) -> (Duration, Vec<TileResult>) {
    let mut found = cluster.events().filter_map(|(_, event)| match event {
        Event::FrameComplete {
            frame: f,
            elapsed,
            results,
            ..
        } if *f == frame => Some((*elapsed, results.clone())),
        _ => None,
    });
    let first = found
        .next()
        .unwrap_or_else(|| panic!("{frame} did not complete"));
    assert!(found.next().is_none(), "{frame} completed twice");
    first
}

/// The owner's audit of `frame`: what it gave out twice, and how the duplicates compared.
fn audit(cluster: &Cluster, frame: FrameId) -> Audit {
    cluster
        .events()
        .find_map(|(_, event)| match event {
            Event::FrameComplete {
                frame: f, audit, ..
            } if *f == frame => Some(*audit),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{frame} did not complete"))
}

/// Who the owner says rendered each tile of `frame`, by tile id.
fn rendered_by(cluster: &Cluster, frame: FrameId) -> Vec<PeerId> {
    cluster
        .events()
        .find_map(|(_, event)| match event {
            Event::FrameComplete {
                frame: f,
                rendered_by,
                ..
            } if *f == frame => Some(rendered_by.clone()),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{frame} did not complete"))
}

fn stats(cluster: &Cluster, frame: FrameId) -> BTreeMap<PeerId, PeerStats> {
    cluster
        .events()
        .filter_map(|(_, event)| match event {
            Event::PeerStats {
                frame: f,
                peer,
                stats,
            } if *f == frame => Some((*peer, stats.clone())),
            _ => None,
        })
        .collect()
}

/// How many times each tile was handed to a renderer, and by whom last.
fn renders(cluster: &Cluster) -> BTreeMap<(FrameId, TileId), Vec<PeerId>> {
    let mut renders: BTreeMap<_, Vec<PeerId>> = BTreeMap::new();
    for record in cluster.trace() {
        if let Record::Started { peer, item, .. } = record {
            renders
                .entry((item.frame, item.tile.id))
                .or_default()
                .push(*peer);
        }
    }
    renders
}

fn sent(cluster: &Cluster) -> impl Iterator<Item = (PeerId, PeerId, &Message)> {
    cluster.trace().iter().filter_map(|record| match record {
        Record::Sent {
            from, to, message, ..
        } => Some((*from, *to, message)),
        _ => None,
    })
}

/// Every tile `0..count` is in `results`, in tile order: once, or as pieces of it (which the
/// owner's cover never lets overlap).
fn assert_all_results(results: &[TileResult], frame: FrameId, count: u32) {
    let mut ids: Vec<TileId> = results.iter().map(|result| result.tile).collect();
    assert!(ids.is_sorted(), "{ids:?}");
    ids.dedup();
    assert_eq!(ids, (0..count).map(TileId).collect::<Vec<_>>());
    for result in results {
        assert_eq!(result.frame, frame);
    }
}

fn assert_no_refusals_or_faults(cluster: &Cluster) {
    for record in cluster.trace() {
        assert!(!matches!(record, Record::Refused { .. }), "{record:?}");
    }
    for (_, event) in cluster.events() {
        assert!(!matches!(event, Event::FaultyPeer { .. }), "{event:?}");
    }
}

/// Uneven, deterministic costs.
fn uneven(count: usize) -> Vec<f64> {
    (0..count).map(|i| 1.0 + ((i * 7919) % 13) as f64).collect()
}

#[test]
fn every_tile_completes_exactly_once_over_two_frames() {
    for peers in 2..=5 {
        let mut cluster = cluster(&Config::default(), peers, 2, 1);
        let costs = uneven(40);
        for frame in [FrameId(1), FrameId(2)] {
            cluster
                .start_frame(OWNER, frame, contiguous(peers, &costs))
                .unwrap();
            finish(&mut cluster);
            let (_, results) = completion(&cluster, frame);
            assert_all_results(&results, frame, 40);
            let stats = stats(&cluster, frame);
            assert_eq!(
                stats.len(),
                peers as usize,
                "every peer reports its statistics"
            );
            let rendered: u32 = stats.values().map(|s| s.tiles_rendered).sum();
            assert_eq!(rendered, 40, "{peers} peers, {frame}");
            for s in stats.values() {
                assert_eq!(s.busy + s.idle, s.wall * s.slots);
            }
        }
        let renders = renders(&cluster);
        assert_eq!(renders.len(), 80);
        assert!(
            renders.values().all(|by| by.len() == 1),
            "a tile was rendered twice"
        );
        for frame in [FrameId(1), FrameId(2)] {
            let by: Vec<PeerId> = (0..40).map(|t| renders[&(frame, TileId(t))][0]).collect();
            assert_eq!(rendered_by(&cluster, frame), by);
        }
        assert_no_refusals_or_faults(&cluster);
    }
}

/// Peer 1 gets 24 heavy tiles; peers 0 and 2 get two light ones each.
fn heavy_middle() -> BTreeMap<PeerId, Vec<TileSpec>> {
    let mut costs = vec![1.0, 1.0];
    costs.extend([10.0; 24]);
    costs.extend([1.0, 1.0]);
    let all = tiles(0, &costs);
    BTreeMap::from([
        (PeerId(0), all[..2].to_vec()),
        (PeerId(1), all[2..26].to_vec()),
        (PeerId(2), all[26..].to_vec()),
    ])
}

#[test]
fn a_heavy_assignment_is_stolen_from_and_only_when_stealing_is_on() {
    let mut stealing = cluster(&Config::default(), 3, 2, 1);
    stealing
        .start_frame(OWNER, FrameId(1), heavy_middle())
        .unwrap();
    finish(&mut stealing);
    let (with, results) = completion(&stealing, FrameId(1));
    assert_all_results(&results, FrameId(1), 28);
    let stats_on = stats(&stealing, FrameId(1));
    assert!(stats_on[&PeerId(1)].tiles_given > 0);
    assert!(stats_on[&PeerId(0)].tiles_stolen + stats_on[&PeerId(2)].tiles_stolen > 0);
    assert_no_refusals_or_faults(&stealing);

    let mut alone = cluster(&no_steal(), 3, 2, 1);
    alone
        .start_frame(OWNER, FrameId(1), heavy_middle())
        .unwrap();
    finish(&mut alone);
    let (without, _) = completion(&alone, FrameId(1));
    let stats_off = stats(&alone, FrameId(1));
    assert!(
        stats_off
            .values()
            .all(|s| s.steal_requests_sent == 0 && s.tiles_stolen == 0)
    );
    let assignee: BTreeMap<TileId, PeerId> = heavy_middle()
        .into_iter()
        .flat_map(|(p, ts)| ts.into_iter().map(move |t| (t.id, p)))
        .collect();
    for ((_, tile), by) in renders(&alone) {
        assert_eq!(
            by,
            vec![assignee[&tile]],
            "without stealing {tile} stays with its assignee"
        );
    }
    // 24 tiles of 10 ms on 2 slots take 120 ms alone; shared by 6 slots, about 40 ms.
    assert!(
        with < without,
        "stealing took {with:?}, not stealing {without:?}"
    );
}

#[test]
fn steals_come_from_the_far_end_of_the_victims_queue() {
    let mut cluster = cluster(&Config::default(), 3, 2, 1);
    cluster
        .start_frame(OWNER, FrameId(1), heavy_middle())
        .unwrap();
    finish(&mut cluster);
    let grants: Vec<Vec<u32>> = sent(&cluster)
        .filter(|(from, _, _)| *from == PeerId(1))
        .filter_map(|(_, _, message)| match message {
            Message::StealGrant { tiles, .. } => Some(tiles.iter().map(|t| t.id.0).collect()),
            _ => None,
        })
        .collect();
    assert!(grants.len() >= 2, "{grants:?}");
    // The first grant ends with the assignment's last tile; each later one ends right before
    // where the previous one began, and every grant is a contiguous run.
    let mut end = 25;
    for grant in &grants {
        assert_eq!(*grant.last().unwrap(), end, "{grants:?}");
        assert!(
            grant.windows(2).all(|pair| pair[1] == pair[0] + 1),
            "{grants:?}"
        );
        end = grant[0] - 1;
    }
}

/// Peer 0 holds a long tile in flight and a tiny one queued; peer 1 runs dry and asks it.
/// Without a prefetch, the tiny tile is the victim's to give.
fn tiny_leftover(config: Config) -> Cluster {
    let config = Config {
        prefetch_depth: 0,
        ..config
    };
    let mut cluster = Cluster::new(
        &config,
        &[(PeerId(0), 1), (PeerId(1), 1)],
        1,
        cost_renderer(MS_PER_UNIT),
    );
    let all = tiles(0, &[1.0, 50.0, 0.01, 1.0]);
    let assignments = BTreeMap::from([
        (PeerId(0), all[..3].to_vec()),
        (PeerId(1), all[3..].to_vec()),
    ]);
    cluster.start_frame(OWNER, FrameId(1), assignments).unwrap();
    finish(&mut cluster);
    cluster
}

#[test]
fn a_victim_refuses_when_the_gain_would_not_pay_for_the_transfer() {
    let cluster = tiny_leftover(Config::default());
    let from_victim: Vec<&Message> = sent(&cluster)
        .filter(|(from, to, _)| (*from, *to) == (PeerId(0), PeerId(1)))
        .map(|m| m.2)
        .collect();
    assert!(
        from_victim
            .iter()
            .any(|m| matches!(m, Message::StealRefuse { .. }))
    );
    assert!(
        !from_victim
            .iter()
            .any(|m| matches!(m, Message::StealGrant { .. }))
    );
    assert!(stats(&cluster, FrameId(1))[&PeerId(1)].steal_requests_refused > 0);
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 4);

    // The same situation with the rule off: the tiny tile is given. So the refusal above was
    // the gain rule's doing.
    let cluster = tiny_leftover(Config {
        min_grant_rtts: 0.0,
        ..Config::default()
    });
    let granted = sent(&cluster).any(|(from, _, message)| {
        from == PeerId(0)
            && matches!(message, Message::StealGrant { tiles, .. } if tiles[0].id == TileId(2))
    });
    assert!(granted);
}

/// A run with stealing between randomly chosen victims.
fn traced_run(seed: u64) -> Vec<Record> {
    let mut cluster = cluster(&Config::default(), 5, 2, seed);
    let mut costs = uneven(30);
    costs.extend([12.0; 30]);
    cluster
        .start_frame(OWNER, FrameId(1), contiguous(5, &costs))
        .unwrap();
    finish(&mut cluster);
    cluster.trace().to_vec()
}

#[test]
fn the_same_seed_gives_the_same_trace() {
    let first = traced_run(7);
    assert!(first.iter().any(|r| matches!(
        r,
        Record::Sent {
            message: Message::StealGrant { .. },
            ..
        }
    )));
    assert_eq!(first, traced_run(7));
    // And the seed is what chooses the victims: another one asks in another order.
    let victims = |trace: &[Record]| -> Vec<(PeerId, PeerId)> {
        trace
            .iter()
            .filter_map(|r| match r {
                Record::Sent {
                    from,
                    to,
                    message: Message::StealRequest { .. },
                    ..
                } => Some((*from, *to)),
                _ => None,
            })
            .collect()
    };
    assert_ne!(victims(&first), victims(&traced_run(8)));
}
