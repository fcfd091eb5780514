//! Elastic membership: a peer that joins while a frame runs takes part in it (it steals, and is
//! given re-issues and backups), and a peer asked to leave hands back what it has not started,
//! sends what its renderer held, and goes. Either way every tile completes, with no timeout.

use super::*;

/// Whether the owner reported `peer` leaving, and which frames re-issued its tiles for it.
fn leaving_reports(cluster: &Cluster, peer: PeerId) -> (bool, Vec<(FrameId, usize)>) {
    let mut leaving = false;
    let mut reissued = Vec::new();
    for (at, event) in cluster.events() {
        match event {
            Event::PeerLeaving { peer: p } if at == OWNER && *p == peer => leaving = true,
            Event::PeerFailed {
                frame,
                peer: p,
                reason: Failure::Left,
                reissued: n,
            } if at == OWNER && *p == peer => reissued.push((*frame, *n)),
            _ => {}
        }
    }
    (leaving, reissued)
}

#[test]
fn a_peer_joining_mid_frame_steals_and_renders_part_of_it() {
    for seed in 0..6 {
        for joins_at in [5, 20, 60] {
            let mut cluster = cluster(&Config::default(), 2, 1, seed);
            cluster
                .start_frame(OWNER, FrameId(1), contiguous(2, &uneven(64)))
                .unwrap();
            cluster.run(Duration::from_millis(joins_at));
            cluster.join(PeerId(5), 2, seed);
            finish(&mut cluster);
            let (_, results) = completion(&cluster, FrameId(1));
            assert_all_results(&results, FrameId(1), 64);
            let by = rendered_by(&cluster, FrameId(1));
            assert!(
                by.contains(&PeerId(5)),
                "seed {seed}, joined at {joins_at} ms: the newcomer rendered nothing: {by:?}"
            );
            assert_no_refusals_or_faults(&cluster);
            // It was told of the frame and its participants, and reported its statistics.
            assert!(stats(&cluster, FrameId(1)).contains_key(&PeerId(5)));
        }
    }
}

#[test]
fn a_peer_joining_when_nothing_is_left_to_steal_costs_nothing() {
    let mut cluster = cluster(&no_steal(), 2, 1, 3);
    cluster
        .start_frame(OWNER, FrameId(1), contiguous(2, &uneven(16)))
        .unwrap();
    cluster.run(Duration::from_millis(10));
    cluster.join(PeerId(2), 1, 3);
    finish(&mut cluster);
    let (_, results) = completion(&cluster, FrameId(1));
    assert_all_results(&results, FrameId(1), 16);
    assert_no_refusals_or_faults(&cluster);
    // The next frame deals it work like anyone else.
    let next = contiguous_tiles(3, tiles(0, &uneven(24)));
    cluster.start_frame(OWNER, FrameId(2), next).unwrap();
    finish(&mut cluster);
    assert!(rendered_by(&cluster, FrameId(2)).contains(&PeerId(2)));
}

#[test]
fn a_peer_asked_to_leave_hands_back_its_queue_at_once_and_no_tile_is_lost() {
    let config = Config::default();
    for seed in 0..6 {
        for leaves_at in [1, 15, 40, 80] {
            for slots in [1, 3] {
                let mut cluster = cluster(&config, 4, slots, seed);
                cluster
                    .start_frame(OWNER, FrameId(1), contiguous(4, &uneven(96)))
                    .unwrap();
                cluster.run(Duration::from_millis(leaves_at));
                let asked = cluster.now();
                cluster.leave(PeerId(2), OWNER);
                finish(&mut cluster);
                let case = format!("seed {seed}, leaves at {leaves_at} ms, {slots} slots");
                let (elapsed, results) = completion(&cluster, FrameId(1));
                assert_all_results(&results, FrameId(1), 96);
                assert_no_refusals_or_faults(&cluster);
                let (leaving, reissued) = leaving_reports(&cluster, PeerId(2));
                assert!(leaving, "{case}: the owner never heard it leave");
                // The frame's ledger says it lost the peer if the frame was still running.
                let running = elapsed > asked;
                assert_eq!(reissued.len(), usize::from(running), "{case}: {reissued:?}");
                // Nothing waited for a timeout: the frame ends long before the owner would
                // have declared the peer silent.
                assert!(
                    elapsed < asked + config.peer_timeout / 2,
                    "{case}: took {elapsed:?}"
                );
                // Once it said it was leaving it started no new tile.
                let after: Vec<_> = cluster
                    .trace()
                    .iter()
                    .filter(
                        |r| matches!(r, Record::Started { peer: PeerId(2), at, .. } if *at > asked),
                    )
                    .collect();
                assert!(after.is_empty(), "{case}: {after:?}");
            }
        }
    }
}

/// Work `peer` handed its renderer after `since`, and grants it gave after `since`.
fn after(cluster: &Cluster, peer: PeerId, since: Duration) -> (usize, usize) {
    let mut started = 0;
    let mut granted = 0;
    for record in cluster.trace() {
        match record {
            Record::Started { at, peer: p, .. } if *p == peer && *at > since => started += 1,
            Record::Sent {
                at,
                from,
                message: Message::StealGrant { .. },
                ..
            } if *from == peer && *at > since => granted += 1,
            _ => {}
        }
    }
    (started, granted)
}

#[test]
fn a_leaving_peer_gives_nothing_and_keeps_no_grant_that_reaches_it_late() {
    // Peer 2 asks peer 1 for work and is asked to leave while the answer is on its way.
    for seed in 0..4 {
        let mut cluster = cluster(&Config::default(), 3, 1, seed);
        cluster
            .start_frame(OWNER, FrameId(1), heavy_middle())
            .unwrap();
        let mut asked = None;
        while let Some(happening) = cluster.step() {
            if matches!(
                happening,
                Happening::Deliver {
                    from: PeerId(2),
                    message: Message::StealRequest { .. },
                    ..
                }
            ) {
                asked = Some(cluster.now());
                cluster.leave(PeerId(2), OWNER);
                break;
            }
        }
        let asked = asked.expect("peer 2 never stole");
        finish(&mut cluster);
        let (_, results) = completion(&cluster, FrameId(1));
        assert_all_results(&results, FrameId(1), 28);
        assert_no_refusals_or_faults(&cluster);
        assert_eq!(after(&cluster, PeerId(2), asked), (0, 0), "seed {seed}");
        // A grant that reached it after it left was told to the owner, which re-issued it.
        let late_grant = cluster.trace().iter().any(|r| {
            matches!(r, Record::Sent { at, to: PeerId(2), message: Message::StealGrant { .. }, .. } if *at >= asked)
        });
        if late_grant {
            let noticed = sent(&cluster).any(|(from, to, m)| {
                from == PeerId(2) && to == OWNER && matches!(m, Message::StealNotice { .. })
            });
            assert!(noticed, "seed {seed}: a late grant went unannounced");
        }
    }
}

#[test]
fn a_peer_that_left_may_join_again_as_a_new_process() {
    let mut cluster = cluster(&Config::default(), 3, 1, 4);
    cluster
        .start_frame(OWNER, FrameId(1), contiguous(3, &uneven(48)))
        .unwrap();
    cluster.run(Duration::from_millis(10));
    cluster.leave(PeerId(1), OWNER);
    cluster.run(cluster.now() + Duration::from_millis(60));
    assert!(
        cluster
            .events()
            .any(|(peer, event)| peer == PeerId(1) && *event == Event::Left),
        "peer 1 never finished leaving"
    );
    cluster.join(PeerId(1), 2, 9);
    finish(&mut cluster);
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 48);
    let next = contiguous_tiles(3, tiles(0, &uneven(24)));
    cluster.start_frame(OWNER, FrameId(2), next).unwrap();
    finish(&mut cluster);
    assert_all_results(&completion(&cluster, FrameId(2)).1, FrameId(2), 24);
    assert!(rendered_by(&cluster, FrameId(2)).contains(&PeerId(1)));
    assert_no_refusals_or_faults(&cluster);
}
