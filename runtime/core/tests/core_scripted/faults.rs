//! Faults: peers that die, freeze or race, and results that disagree. Whatever happens, no
//! tile is lost.

use super::*;

#[test]
fn a_peer_lost_mid_frame_costs_time_not_tiles() {
    for config in [Config::default(), no_steal()] {
        let mut cluster = cluster(&config, 4, 2, 3);
        cluster
            .start_frame(OWNER, FrameId(1), contiguous(4, &uneven(48)))
            .unwrap();
        cluster.run(Duration::from_millis(20));
        cluster.kill(PeerId(2), true);
        finish(&mut cluster);
        let (_, results) = completion(&cluster, FrameId(1));
        assert_all_results(&results, FrameId(1), 48);
        let reissued: Vec<usize> = cluster
            .events()
            .filter_map(|(peer, event)| match event {
                Event::PeerFailed {
                    peer: PeerId(2),
                    reason: Failure::Lost,
                    reissued,
                    ..
                } if peer == OWNER => Some(*reissued),
                _ => None,
            })
            .collect();
        assert!(
            reissued.len() == 1 && reissued[0] > 0,
            "steal: {}: {reissued:?}",
            config.steal
        );
        // The frame's audit counts the same tiles and the one failure, and no backup: nobody
        // was overdue.
        let audit = audit(&cluster, FrameId(1));
        assert_eq!(
            (audit.reissued as usize, audit.backed_up, audit.failed),
            (reissued[0], 0, 1),
            "steal: {}",
            config.steal
        );
        assert_no_refusals_or_faults(&cluster);
    }
}

/// Runs until `stop` matches a processed happening, then returns it.
fn run_until(cluster: &mut Cluster, mut stop: impl FnMut(&Happening) -> bool) -> Happening {
    while let Some(happening) = cluster.step() {
        if stop(&happening) {
            return happening;
        }
    }
    panic!("the run ended before the awaited happening");
}

#[test]
fn a_thief_dying_with_its_grant_unannounced_costs_no_tile() {
    let mut cluster = cluster(&Config::default(), 3, 2, 1);
    cluster
        .start_frame(OWNER, FrameId(1), heavy_middle())
        .unwrap();
    let grant = run_until(&mut cluster, |h| {
        matches!(
            h,
            Happening::Deliver {
                to: PeerId(2),
                message: Message::StealGrant { .. },
                ..
            }
        )
    });
    // The thief's notice to the owner is still on the way: it dies with it.
    cluster.kill(PeerId(2), true);
    finish(&mut cluster);
    let (_, results) = completion(&cluster, FrameId(1));
    assert_all_results(&results, FrameId(1), 28);
    let Happening::Deliver {
        message: Message::StealGrant { tiles, .. },
        ..
    } = grant
    else {
        unreachable!()
    };
    for tile in tiles {
        assert!(results[tile.id.0 as usize].tile == tile.id);
    }
    assert_no_refusals_or_faults(&cluster);
}

#[test]
fn a_victim_dying_right_after_granting_costs_no_tile() {
    let mut cluster = cluster(&Config::default(), 4, 2, 5);
    let mut costs = vec![1.0; 4];
    costs.extend([10.0; 20]);
    costs.extend([1.0; 8]);
    let all = tiles(0, &costs);
    let assignments = BTreeMap::from([
        (PeerId(0), all[..4].to_vec()),
        (PeerId(1), all[4..24].to_vec()),
        (PeerId(2), all[24..28].to_vec()),
        (PeerId(3), all[28..].to_vec()),
    ]);
    cluster.start_frame(OWNER, FrameId(1), assignments).unwrap();
    run_until(&mut cluster, |h| {
        matches!(
            h,
            Happening::Deliver {
                to: PeerId(1),
                message: Message::StealRequest { .. },
                ..
            }
        )
    });
    assert!(matches!(
        cluster.trace().last(),
        Some(Record::Sent {
            message: Message::StealGrant { .. },
            ..
        })
    ));
    // The grant is already on the wire and arrives; the victim's other tiles are re-issued.
    cluster.kill(PeerId(1), false);
    finish(&mut cluster);
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 32);
    assert_no_refusals_or_faults(&cluster);
}

#[test]
fn grants_arriving_after_their_request_timed_out_are_kept() {
    let config = Config {
        steal_timeout: Duration::from_micros(200),
        ..Config::default()
    };
    let mut cluster = cluster(&config, 3, 2, 1);
    cluster
        .start_frame(OWNER, FrameId(1), heavy_middle())
        .unwrap();
    finish(&mut cluster);
    let stats = stats(&cluster, FrameId(1));
    let stolen: u32 = stats.values().map(|s| s.tiles_stolen).sum();
    assert!(stolen > 0);
    let given: u32 = stats.values().map(|s| s.tiles_given).sum();
    assert_eq!(stolen, given, "every granted tile was kept");
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 28);
    assert_no_refusals_or_faults(&cluster);
}

#[test]
fn a_silent_peer_is_declared_failed_and_its_tiles_reissued() {
    let config = Config {
        heartbeat_interval: Duration::from_millis(5),
        peer_timeout: Duration::from_millis(30),
        ..no_steal()
    };
    let mut cluster = cluster(&config, 3, 1, 1);
    cluster
        .start_frame(OWNER, FrameId(1), contiguous(3, &[10.0; 15]))
        .unwrap();
    cluster.run(Duration::from_millis(15));
    cluster.freeze(PeerId(2));
    finish(&mut cluster);
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 15);
    let silent = cluster.events().any(|(_, event)| {
        matches!(
            event,
            Event::PeerFailed {
                peer: PeerId(2),
                reason: Failure::Silent,
                ..
            }
        )
    });
    assert!(silent);
    assert!(audit(&cluster, FrameId(1)).reissued > 0);
    // It comes back after the frame: its late messages are dropped quietly.
    cluster.thaw(PeerId(2));
    finish(&mut cluster);
    assert_no_refusals_or_faults(&cluster);
}

#[test]
fn a_duplicate_result_is_accepted_only_if_bit_identical() {
    let mut owner = Core::new(OWNER, 1, Config::default(), 1);
    for peer in [PeerId(1), PeerId(2)] {
        owner.handle_peer_connected(Duration::ZERO, peer);
    }
    let all = tiles(0, &[1.0, 1.0]);
    let assignments = BTreeMap::from([(PeerId(1), vec![all[0]]), (OWNER, vec![all[1]])]);
    owner
        .start_frame(Duration::ZERO, FrameId(1), assignments, u64::MAX)
        .unwrap();
    let item = runtime_core::peer::WorkItem {
        frame: FrameId(1),
        tile: all[0],
    };
    let first = synthetic_result(&item);
    let at = Duration::from_millis(1);
    owner
        .handle_message(at, PeerId(1), Message::TileDone(first.clone()))
        .unwrap();
    owner
        .handle_message(at, PeerId(2), Message::TileDone(first.clone()))
        .unwrap();
    assert_eq!(
        next_event(&mut owner),
        None,
        "an identical duplicate is accepted silently"
    );
    let mut differing = first;
    differing.pixels[5] ^= 1;
    owner
        .handle_message(at, PeerId(2), Message::TileDone(differing))
        .unwrap();
    let expected = Event::FaultyPeer {
        frame: FrameId(1),
        peer: PeerId(2),
        tile: TileId(0),
        fault: Fault::Mismatch { first: PeerId(1) },
    };
    assert_eq!(next_event(&mut owner), Some(expected));
    // The owner's own tile completes the frame with the first result kept.
    let own = owner.poll_work().unwrap();
    owner.handle_tile_rendered(at, synthetic_result(&own));
    match next_event(&mut owner) {
        Some(Event::FrameComplete { results, audit, .. }) => {
            assert_eq!(results[0], synthetic_result(&item));
            let expected = runtime_core::peer::Audit {
                agreed: 1,
                disagreed: 1,
                reissued: 0,
                backed_up: 0,
                failed: 0,
            };
            assert_eq!(audit, expected, "both duplicates were compared and counted");
        }
        other => panic!("expected the frame to complete, got {other:?}"),
    }
}

#[test]
fn a_differing_duplicate_from_a_peer_that_comes_back_is_reported() {
    // Peer 2 renders differently: broken, or non-deterministic.
    let renderer = Box::new(|peer: PeerId, item: &runtime_core::peer::WorkItem| {
        let mut result = synthetic_result(item);
        if peer == PeerId(2) {
            result.pixels[0] ^= 0xff;
        }
        Rendered {
            duration: Duration::from_secs_f64(item.tile.predicted * MS_PER_UNIT),
            result,
        }
    });
    let config = Config {
        heartbeat_interval: Duration::from_millis(5),
        peer_timeout: Duration::from_millis(30),
        ..no_steal()
    };
    let peers = [(PeerId(0), 1), (PeerId(1), 1), (PeerId(2), 1)];
    let mut cluster = Cluster::new(&config, &peers, 1, renderer);
    cluster
        .start_frame(OWNER, FrameId(1), contiguous(3, &[10.0; 15]))
        .unwrap();
    cluster.run(Duration::from_millis(15));
    cluster.freeze(PeerId(2));
    let failed = |cluster: &Cluster| {
        cluster.events().any(|(_, event)| {
            matches!(
                event,
                Event::PeerFailed {
                    peer: PeerId(2),
                    ..
                }
            )
        })
    };
    while !failed(&cluster) {
        cluster
            .step()
            .expect("the owner declares peer 2 failed before the run ends");
    }
    // Peer 2 wakes up with the tile it was rendering, which others are about to render too.
    cluster.thaw(PeerId(2));
    finish(&mut cluster);
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 15);
    let mismatch = cluster.events().any(|(_, event)| match event {
        Event::FaultyPeer {
            peer,
            fault: Fault::Mismatch { first },
            ..
        } => *peer == PeerId(2) || *first == PeerId(2),
        _ => false,
    });
    assert!(mismatch);
}

#[test]
fn reports_overtaken_by_other_messages_do_not_count() {
    let config = Config {
        peer_timeout: Duration::from_millis(50),
        ..Config::default()
    };
    let mut owner = Core::new(OWNER, 1, config, 1);
    for peer in [PeerId(1), PeerId(2)] {
        owner.handle_peer_connected(Duration::ZERO, peer);
    }
    let all = tiles(0, &[1.0, 1.0, 1.0]);
    let assignments = BTreeMap::from([(PeerId(1), vec![all[0]]), (PeerId(2), all[1..].to_vec())]);
    owner
        .start_frame(Duration::ZERO, FrameId(1), assignments, u64::MAX)
        .unwrap();
    while owner.poll_transmit().is_some() {}
    let at = Duration::from_millis(1);
    let status = |idle, done| Message::Status {
        frame: FrameId(1),
        idle,
        assigned: 1,
        stolen: 0,
        done,
    };
    let result = |tile: &TileSpec| {
        Message::TileDone(synthetic_result(&runtime_core::peer::WorkItem {
            frame: FrameId(1),
            tile: *tile,
        }))
    };

    // Both peers' idle reports overtake their results: nobody is idle yet, nothing is re-issued.
    owner
        .handle_message(at, PeerId(1), status(true, 1))
        .unwrap();
    owner
        .handle_message(at, PeerId(2), status(true, 2))
        .unwrap();
    assert_eq!(owner.poll_transmit(), None);
    owner
        .handle_message(at, PeerId(1), result(&all[0]))
        .unwrap();
    owner
        .handle_message(at, PeerId(2), result(&all[1]))
        .unwrap();
    // An old heartbeat of peer 1 arrives last; it does not make peer 1 busy again.
    owner
        .handle_message(at, PeerId(1), status(false, 0))
        .unwrap();
    assert_eq!(owner.poll_transmit(), None);

    // Peer 2 still owes a result and goes quiet; idle peer 1 is not suspected and gets its tile.
    let mut failed = Vec::new();
    while failed.is_empty() {
        let later = owner
            .poll_timeout()
            .expect("the owner watches for silent peers");
        assert!(
            later < Duration::from_millis(60),
            "peer 2 is silent for 50 ms by {later:?}"
        );
        owner.handle_timeout(later);
        failed.extend(std::iter::from_fn(|| next_event(&mut owner)));
    }
    assert_eq!(
        failed,
        vec![Event::PeerFailed {
            frame: FrameId(1),
            peer: PeerId(2),
            reason: Failure::Silent,
            reissued: 1
        }]
    );
    let (to, message) = owner
        .poll_transmit()
        .expect("the silent peer's tile is re-issued");
    assert_eq!(to, PeerId(1));
    assert!(matches!(message, Message::Assign { tiles, .. } if tiles == vec![all[2]]));
}

/// Something done to a peer (never the owner) at some instant of a random run.
#[derive(Clone, Debug)]
enum Mishap {
    Kill {
        drop_outgoing: bool,
    },
    /// Frozen for a while, or for good.
    Freeze {
        for_ms: Option<u64>,
    },
}

fn mishap() -> impl Strategy<Value = (u64, u32, Mishap)> {
    let what = prop_oneof![
        any::<bool>().prop_map(|drop_outgoing| Mishap::Kill { drop_outgoing }),
        proptest::option::of(1..200u64).prop_map(|for_ms| Mishap::Freeze { for_ms }),
    ];
    (0..120u64, 1..6u32, what)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Whatever dies, freezes, races or overtakes, however tiles are cut or backed up, every
    /// frame completes with every pixel once, and nothing is reported faulty (the renderer is
    /// deterministic, so every duplicate is identical).
    #[test]
    fn no_tile_is_ever_lost(
        peers in 2..7u32,
        slots in 1..4usize,
        costs in proptest::collection::vec(prop_oneof![Just(0.0), 0.1..20.0f64], 1..60),
        seed in any::<u64>(),
        steal in any::<bool>(),
        latency_us in 50..5000u64,
        jitter_us in prop_oneof![Just(0u64), 1..5000u64],
        short_steal_timeout in any::<bool>(),
        mishaps in proptest::collection::vec(mishap(), 0..4),
        side in prop_oneof![Just(4u32), Just(16u32), Just(23u32)],
        render_pixels in prop_oneof![Just(u64::MAX), 8..300u64],
        split_on_steal in any::<bool>(),
        backups in any::<bool>(),
    ) {
        let config = Config {
            steal,
            steal_timeout: if short_steal_timeout { Duration::from_micros(300) } else { Duration::from_millis(250) },
            heartbeat_interval: Duration::from_millis(10),
            peer_timeout: Duration::from_millis(60),
            split_on_steal,
            min_piece_pixels: 16,
            speculation: backups.then(|| runtime_core::peer::Speculation {
                factor: 2.0,
                min_wait: Duration::from_millis(5),
            }),
            ..Config::default()
        };
        let mut cluster = cluster(&config, peers, slots, seed);
        cluster.latency = Duration::from_micros(latency_us);
        cluster.jitter = Duration::from_micros(jitter_us);
        let deal = contiguous_tiles(peers, sized_tiles(0, &costs, side));
        cluster.start_frame_in_pieces(OWNER, FrameId(1), deal, render_pixels).unwrap();
        let mut mishaps: Vec<_> = mishaps.into_iter().filter(|(_, peer, _)| *peer < peers).collect();
        mishaps.sort_by_key(|(at, _, _)| *at);
        let calm = mishaps.is_empty();
        let mut thaws = Vec::new();
        let mut gone = std::collections::BTreeSet::new();
        for (at_ms, peer, what) in mishaps {
            cluster.run(Duration::from_millis(at_ms));
            if !gone.insert(peer) {
                continue;
            }
            match what {
                Mishap::Kill { drop_outgoing } => cluster.kill(PeerId(peer), drop_outgoing),
                Mishap::Freeze { for_ms } => {
                    cluster.freeze(PeerId(peer));
                    if let Some(ms) = for_ms {
                        thaws.push((at_ms + ms, peer));
                    }
                }
            }
        }
        thaws.sort();
        for (at_ms, peer) in thaws {
            cluster.run(Duration::from_millis(at_ms));
            cluster.thaw(PeerId(peer));
        }
        finish(&mut cluster);
        let (_, results) = completion(&cluster, FrameId(1));
        assert_all_results(&results, FrameId(1), costs.len() as u32);
        let area: u64 = results.iter().map(|r| r.rect.area()).sum();
        prop_assert_eq!(area, costs.len() as u64 * u64::from(side * side));
        assert_no_refusals_or_faults(&cluster);
        if calm {
            let failed = cluster.events().find(|(_, e)| matches!(e, Event::PeerFailed { .. }));
            prop_assert!(failed.is_none(), "nobody died, yet {:?}", failed);
        }
    }
}

/// The core's next event other than a frame's waning (the director's cue, not what these
/// tests are about).
fn next_event(core: &mut Core) -> Option<Event> {
    std::iter::from_fn(|| core.poll_event())
        .find(|event| !matches!(event, Event::FrameWaning { .. }))
}
