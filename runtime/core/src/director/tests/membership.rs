//! Peers that misbehave, come, go or fall silent: a peer that keeps sending faulty results stops
//! the render; joiners and leavers are dealt from the next frame on; an overdue peer is dealt
//! nothing until it is heard from again.

use super::*;

#[test]
fn a_peer_that_keeps_sending_faulty_results_stops_the_render() {
    let mut director = director(grid(2, 2), 2, 1);
    director.poll_deal(Duration::ZERO).unwrap();
    let faulty = crate::peer::Event::FaultyPeer {
        frame: FrameId(0),
        peer: PeerId(1),
        tile: TileId(0),
        fault: crate::peer::Fault::UnknownTile,
    };
    let allowed = 2 * 4 + Config::default().fault_allowance;
    for _ in 0..allowed {
        director
            .handle_core_event(Duration::ZERO, faulty.clone())
            .unwrap();
    }
    assert!(matches!(
        director.handle_core_event(Duration::ZERO, faulty.clone()),
        Err(DirectorError::Faulty { .. })
    ));
}

#[test]
fn peers_that_join_or_leave_are_dealt_from_the_next_frame() {
    let mut director = director(grid(4, 4), 2, 3);
    let first = director.poll_deal(Duration::ZERO).unwrap().unwrap();
    assert_eq!(
        first.participants().collect::<Vec<_>>(),
        [PeerId(0), PeerId(1)]
    );
    director.handle_peer_joined(Duration::ZERO, PeerId(7));
    director.handle_peer_left(Duration::ZERO, PeerId(1));
    let complete = empty_completion();
    director
        .handle_core_event(Duration::ZERO, complete)
        .unwrap();
    director
        .handle_measured(Duration::ZERO, FrameId(0), &halves(1))
        .unwrap();
    let second = director.poll_deal(Duration::ZERO).unwrap().unwrap();
    assert_eq!(
        second.participants().collect::<Vec<_>>(),
        [PeerId(0), PeerId(7)]
    );
}

/// A peer whose work was backed up as overdue is dealt nothing until its statistics show it
/// alive again (or a result does: the next test): a frozen peer would hold up every frame
/// dealt to it.
#[test]
fn an_overdue_peer_is_dealt_nothing_until_it_is_heard_of() {
    let t = Duration::ZERO;
    let mut director = director_in_flight(grid(4, 4), 3, 3, 1);
    let participants = |deal: &Deal| deal.participants().map(|p| p.0).collect::<Vec<_>>();
    let first = director.poll_deal(t).unwrap().unwrap();
    assert_eq!(participants(&first), [0, 1, 2]);
    let overdue = crate::peer::Event::PeerOverdue {
        frame: FrameId(0),
        peer: PeerId(2),
    };
    assert!(director.handle_core_event(t, overdue).unwrap().is_none());
    director.handle_core_event(t, completion(0)).unwrap();
    director.handle_measured(t, FrameId(0), &halves(1)).unwrap();
    let second = director.poll_deal(t).unwrap().unwrap();
    assert_eq!(participants(&second), [0, 1], "peer 2 is overdue");
    let alive = crate::peer::Event::PeerStats {
        frame: FrameId(0),
        peer: PeerId(2),
        stats: PeerStats::default(),
    };
    director.handle_core_event(t, alive).unwrap();
    director.handle_core_event(t, completion(1)).unwrap();
    director.handle_measured(t, FrameId(1), &halves(1)).unwrap();
    let third = director.poll_deal(t).unwrap().unwrap();
    assert_eq!(participants(&third), [0, 1, 2], "peer 2 was heard of");
}

/// An overdue peer that delivers a result again ([`crate::peer::Event::PeerResumed`]) is
/// dealt the next frame, without waiting for its statistics of the frame it was overdue in.
#[test]
fn an_overdue_peer_that_resumes_is_dealt_again() {
    let t = Duration::ZERO;
    let mut director = director_in_flight(grid(4, 4), 3, 3, 1);
    let participants = |deal: &Deal| deal.participants().map(|p| p.0).collect::<Vec<_>>();
    let first = director.poll_deal(t).unwrap().unwrap();
    assert_eq!(participants(&first), [0, 1, 2]);
    for event in [
        crate::peer::Event::PeerOverdue {
            frame: FrameId(0),
            peer: PeerId(2),
        },
        crate::peer::Event::PeerResumed {
            frame: FrameId(0),
            peer: PeerId(2),
        },
    ] {
        assert!(director.handle_core_event(t, event).unwrap().is_none());
    }
    director.handle_core_event(t, completion(0)).unwrap();
    director.handle_measured(t, FrameId(0), &halves(1)).unwrap();
    let second = director.poll_deal(t).unwrap().unwrap();
    assert_eq!(participants(&second), [0, 1, 2], "peer 2 resumed");
}
