//! Steal requests: what a victim refuses, how a thief's rounds are bounded and back off, whom a
//! ring thief asks.

use super::*;

#[test]
fn bad_inputs_are_refused_with_errors() {
    let mut core = Core::new(PeerId(1), 1, Config::default(), 1);
    core.handle_peer_connected(Duration::ZERO, PeerId(2));
    let hello = Message::Hello {
        version: 1,
        peer: PeerId(2),
        slots: 1,
    };
    assert!(matches!(
        core.handle_message(Duration::ZERO, PeerId(2), hello),
        Err(ProtocolError::NotForCore { .. })
    ));
    let result = synthetic_result(&runtime_core::peer::WorkItem {
        frame: FrameId(4),
        tile: tiles(0, &[1.0])[0],
    });
    assert!(matches!(
        core.handle_message(Duration::ZERO, PeerId(2), Message::TileDone(result)),
        Err(ProtocolError::NotOwner { .. })
    ));

    let start = |core: &mut Core, assignments| {
        core.start_frame(Duration::ZERO, FrameId(1), assignments, u64::MAX)
    };
    let one = tiles(0, &[1.0]);
    let stranger = BTreeMap::from([(PeerId(9), one.clone())]);
    assert!(matches!(
        start(&mut core, stranger),
        Err(FrameError::UnknownPeer(PeerId(9)))
    ));
    let twice = BTreeMap::from([(PeerId(1), one.clone()), (PeerId(2), one.clone())]);
    assert!(matches!(
        start(&mut core, twice),
        Err(FrameError::DuplicateTile(TileId(0)))
    ));
    let nan = vec![TileSpec {
        predicted: f64::NAN,
        ..one[0]
    }];
    assert!(matches!(
        start(&mut core, BTreeMap::from([(PeerId(1), nan)])),
        Err(FrameError::InvalidTile(_))
    ));
    assert!(matches!(
        start(&mut core, BTreeMap::new()),
        Err(FrameError::NoTiles)
    ));
    start(&mut core, BTreeMap::from([(PeerId(2), one.clone())])).unwrap();
    // Frames may overlap, but the same frame cannot start twice.
    assert!(matches!(
        start(&mut core, BTreeMap::from([(PeerId(2), one)])),
        Err(FrameError::NotNewer { .. })
    ));
}

/// `peers` peers of which peer 1 holds 300 ms of work and the others nothing, under `config`
/// with every steal refused (no grant could be worth `min_steal_cost`), run to the end.
fn refused_thieves(config: &Config, peers: u32) -> Cluster {
    let config = Config {
        min_steal_cost: 1e9,
        ..config.clone()
    };
    let mut cluster = cluster(&config, peers, 1, 5);
    let assignments: BTreeMap<PeerId, Vec<TileSpec>> = (0..peers)
        .map(|p| {
            let work = if p == 1 {
                tiles(0, &[10.0; 30])
            } else {
                Vec::new()
            };
            (PeerId(p), work)
        })
        .collect();
    cluster.start_frame(OWNER, FrameId(1), assignments).unwrap();
    finish(&mut cluster);
    let (_, results) = completion(&cluster, FrameId(1));
    assert_all_results(&results, FrameId(1), 30);
    cluster
}

/// The steal requests `thief` sent, as (when, to whom), grouped into rounds: requests less than
/// `gap` apart belong to one round.
fn rounds(cluster: &Cluster, thief: PeerId, gap: Duration) -> Vec<Vec<(Duration, PeerId)>> {
    let mut rounds: Vec<Vec<(Duration, PeerId)>> = Vec::new();
    for (at, to) in cluster.trace().iter().filter_map(|record| match record {
        Record::Sent {
            at,
            from,
            to,
            message: Message::StealRequest { .. },
        } if *from == thief => Some((*at, *to)),
        _ => None,
    }) {
        match rounds.last_mut() {
            Some(round) if at - round.last().unwrap().0 < gap => round.push((at, to)),
            _ => rounds.push(vec![(at, to)]),
        }
    }
    rounds
}

/// In a cluster larger than a round, an idle thief asks `victims_per_round` victims, then waits,
/// twice as long after each fruitless round in a row, up to the cap.
#[test]
fn rounds_are_bounded_and_backoffs_double_up_to_the_cap() {
    let config = Config {
        victims_per_round: 3,
        steal_backoff: Duration::from_millis(10),
        steal_backoff_max: Duration::from_millis(40),
        ..Config::default()
    };
    let cluster = refused_thieves(&config, 12);
    let rounds = rounds(&cluster, PeerId(5), config.steal_backoff);
    assert!(rounds.len() >= 6, "300 ms of waiting: {rounds:?}");
    let (last, full) = rounds.split_last().unwrap();
    assert!(full.iter().all(|round| round.len() == 3), "{rounds:?}");
    assert!(last.len() <= 3, "{rounds:?}");
    for (i, pair) in rounds.windows(2).enumerate() {
        let gap = pair[1][0].0 - pair[0].last().unwrap().0;
        let expected = (config.steal_backoff * (1 << i)).min(config.steal_backoff_max);
        assert!(
            gap >= expected && gap <= expected + Duration::from_millis(1),
            "backoff {i} lasted {gap:?}, expected {expected:?}"
        );
    }
}

/// With `VictimOrder::Ring` a thief asks the peers after it by id, wrapping around: all of them
/// in a small cluster, the nearest `victims_per_round` in a large one.
#[test]
fn a_ring_thief_asks_its_successors_by_id() {
    let victims = |peers: u32, thief: u32| -> Vec<u32> {
        let config = Config {
            victims: VictimOrder::Ring,
            victims_per_round: 3,
            ..Config::default()
        };
        let cluster = refused_thieves(&config, peers);
        let rounds = rounds(&cluster, PeerId(thief), config.steal_backoff);
        rounds[0].iter().map(|(_, to)| to.0).collect()
    };
    assert_eq!(victims(12, 5), vec![6, 7, 8]);
    assert_eq!(victims(12, 10), vec![11, 0, 1]);
    assert_eq!(victims(4, 2), vec![3, 0, 1]);
}
