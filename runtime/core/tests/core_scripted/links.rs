//! Far links: a silence timeout shorter than a link's round trip gives up no live peer, and a
//! peer that really stops on such a link is still given up, when the owner's rule says.

use super::*;

/// Three peers, one slot each, on links of 150 ms each way (a 300 ms round trip, which the
/// cores are told, as the QUIC driver tells them), under a LAN's silence timeout of 0.1 s.
fn far_cluster(steal: bool, speculation: Option<runtime_core::peer::Speculation>) -> Cluster {
    let config = Config {
        steal,
        speculation,
        heartbeat_interval: Duration::from_millis(20),
        peer_timeout: Duration::from_millis(100),
        ..Config::default()
    };
    let mut cluster = cluster(&config, 3, 1, 4);
    cluster.latency = Duration::from_millis(150);
    cluster.report_rtt = true;
    cluster
}

/// A silence timeout shorter than a round trip (a LAN setting on a WAN: 0.1 s against 0.3 s)
/// declares no live peer failed: the owner's silence timeout is at least three round trips of
/// the peer's link, counted from when its answer to an assignment could first arrive. Without
/// that rule every peer it dealt tiles to was declared failed at the start of every frame and
/// its tiles re-issued (the frame completed, but as if every peer had died); the next test
/// pins each half of the rule.
#[test]
fn a_silence_timeout_shorter_than_the_round_trip_fails_no_live_peer() {
    for steal in [true, false] {
        let mut cluster = far_cluster(steal, Config::default().speculation);
        for frame in [FrameId(1), FrameId(2)] {
            cluster
                .start_frame(OWNER, frame, contiguous(3, &[20.0; 30]))
                .unwrap();
            finish(&mut cluster);
            assert_all_results(&completion(&cluster, frame).1, frame, 30);
        }
        let failed: Vec<&Event> = cluster
            .events()
            .map(|(_, event)| event)
            .filter(|event| matches!(event, Event::PeerFailed { .. }))
            .collect();
        assert!(failed.is_empty(), "steal {steal}: {failed:?}");
        for frame in [FrameId(1), FrameId(2)] {
            assert_eq!(audit(&cluster, frame).reissued, 0, "steal {steal}");
        }
        assert_no_refusals_or_faults(&cluster);
    }
}

/// Under that rule a far peer that really stops is still given up, when the rule says: a
/// round trip after its tiles were sent, plus the larger of `peer_timeout` and three round
/// trips (here 0.3 s + 0.9 s), neither before nor long after. Either half of the rule missing
/// moves the failure before 1.15 s.
#[test]
fn a_frozen_far_peer_is_given_up_once_its_silence_outlasts_three_round_trips() {
    let mut cluster = far_cluster(false, None);
    cluster.freeze(PeerId(2));
    cluster
        .start_frame(OWNER, FrameId(1), contiguous(3, &[20.0; 30]))
        .unwrap();
    let given_up = |cluster: &Cluster| {
        let failure = |event: &Event| {
            matches!(
                event,
                Event::PeerFailed {
                    peer: PeerId(2),
                    reason: Failure::Silent,
                    ..
                }
            )
        };
        cluster.events().any(|(_, event)| failure(event))
    };
    cluster.run(Duration::from_millis(1150));
    assert!(!given_up(&cluster), "given up before the rule allows");
    cluster.run(Duration::from_millis(1300));
    assert!(given_up(&cluster), "a frozen peer was never given up");
    finish(&mut cluster);
    assert_all_results(&completion(&cluster, FrameId(1)).1, FrameId(1), 30);
    assert_eq!(audit(&cluster, FrameId(1)).failed, 1);
}
