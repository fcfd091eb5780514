//! Admission races, scripted: no sockets, no sleeps.

use std::time::Duration;

use super::*;
use crate::wire::{GoodbyeReason, RenderParams};

const T: Duration = Duration::ZERO;
const OWNER: PeerId = PeerId(0);

fn membership() -> Membership<u32> {
    Membership::new(OWNER, Vec::new(), RenderParams::default())
}

fn hello(peer: u32) -> Message {
    Message::Hello {
        version: PROTOCOL_VERSION,
        peer: PeerId(peer),
        slots: 1,
    }
}

/// Certificates that vouch for exactly the id they were issued to: connection `c` holds the
/// certificate of peer `c % 100`.
fn cert_of(conn: u32) -> impl Fn(u32) -> bool {
    move |id| id == conn % 100
}

fn actions(m: &mut Membership<u32>) -> Vec<Action<u32>> {
    std::iter::from_fn(|| m.poll_action()).collect()
}

/// Connects `conn` and walks it through hello and scene-ready.
fn join(m: &mut Membership<u32>, conn: u32) -> Vec<Action<u32>> {
    m.handle_connected(T, conn, format!("10.0.0.{conn}:1"));
    m.handle_message(T, conn, hello(conn % 100), &cert_of(conn));
    m.handle_message(T, conn, Message::SceneReady, &cert_of(conn));
    actions(m)
}

fn closes(actions: &[Action<u32>]) -> Vec<(u32, Refusal)> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Close { conn, refusal, .. } => Some((*conn, *refusal)),
            _ => None,
        })
        .collect()
}

#[test]
fn a_peer_is_welcomed_sent_the_scene_and_joins_when_the_render_starts() {
    let mut m = membership();
    let joined = join(&mut m, 1);
    assert!(matches!(
        &joined[..],
        [
            Action::Send {
                conn: 1,
                message: Message::Welcome { peer: OWNER, .. }
            },
            Action::Send {
                conn: 1,
                message: Message::Scene { .. }
            },
        ]
    ));
    join(&mut m, 2);
    assert_eq!(m.members(), 2);
    m.start(T);
    let started = actions(&mut m);
    let peers = Message::Peers {
        peers: vec![
            PeerAddress {
                peer: PeerId(1),
                addr: "10.0.0.1:1".into(),
            },
            PeerAddress {
                peer: PeerId(2),
                addr: "10.0.0.2:1".into(),
            },
        ],
    };
    assert_eq!(
        started,
        vec![
            Action::Send {
                conn: 1,
                message: peers.clone()
            },
            Action::Joined {
                peer: PeerId(1),
                conn: 1
            },
            Action::Send {
                conn: 2,
                message: peers
            },
            Action::Joined {
                peer: PeerId(2),
                conn: 2
            },
        ]
    );
    m.handle_closed(T, 2);
    assert_eq!(actions(&mut m), vec![Action::Left { peer: PeerId(2) }]);
}

#[test]
fn identities_are_checked_against_version_certificate_and_who_is_here() {
    let mut m = membership();
    join(&mut m, 1);
    // A second connection with peer 1's certificate (conn 101 holds id 1), while 1 is a member.
    m.handle_connected(T, 101, "x".into());
    m.handle_message(T, 101, hello(1), &cert_of(101));
    // Claiming an id the certificate does not vouch for.
    m.handle_connected(T, 3, "x".into());
    m.handle_message(T, 3, hello(4), &cert_of(3));
    // Claiming the owner's id with the owner's certificate.
    m.handle_connected(T, 100, "x".into());
    m.handle_message(T, 100, hello(0), &cert_of(100));
    // Another protocol version.
    m.handle_connected(T, 5, "x".into());
    let old = Message::Hello {
        version: PROTOCOL_VERSION + 1,
        peer: PeerId(5),
        slots: 1,
    };
    m.handle_message(T, 5, old, &cert_of(5));
    let refused = closes(&actions(&mut m));
    assert_eq!(
        refused,
        vec![
            (101, Refusal::Identity),
            (3, Refusal::Identity),
            (100, Refusal::Identity),
            (5, Refusal::Identity)
        ]
    );
    assert_eq!(m.members(), 1);
}

#[test]
fn two_connections_racing_for_one_id_while_loading_admit_one() {
    let mut m = membership();
    m.handle_connected(T, 1, "a".into());
    m.handle_connected(T, 101, "b".into());
    m.handle_message(T, 1, hello(1), &cert_of(1));
    m.handle_message(T, 101, hello(1), &cert_of(101));
    m.handle_message(T, 101, Message::SceneReady, &cert_of(101));
    m.handle_message(T, 1, Message::SceneReady, &cert_of(1));
    let all = actions(&mut m);
    assert_eq!(closes(&all), vec![(101, Refusal::Identity)]);
    assert_eq!(m.members(), 1);
}

#[test]
fn a_peer_that_leaves_while_loading_is_forgotten_not_admitted() {
    for goodbye in [false, true] {
        let mut m = membership();
        m.handle_connected(T, 1, "a".into());
        m.handle_message(T, 1, hello(1), &cert_of(1));
        if goodbye {
            let bye = Message::Goodbye {
                reason: GoodbyeReason::Shutdown,
            };
            m.handle_message(T, 1, bye, &cert_of(1));
        }
        m.handle_closed(T, 1);
        // A late SceneReady from the dead connection changes nothing.
        m.handle_message(T, 1, Message::SceneReady, &cert_of(1));
        m.start(T);
        let all = actions(&mut m);
        assert!(
            !all.iter()
                .any(|a| matches!(a, Action::Joined { .. } | Action::Left { .. })),
            "{all:?}"
        );
        assert_eq!(m.members(), 0);
        // The id is free again: the peer may come back on a new connection.
        let mut m2 = m;
        m2.started = false;
        join(&mut m2, 201);
        assert_eq!(m2.members(), 1);
    }
}

#[test]
fn messages_out_of_turn_close_that_connection_only() {
    let mut m = membership();
    join(&mut m, 1);
    m.handle_connected(T, 2, "b".into());
    m.handle_message(T, 2, Message::SceneReady, &cert_of(2));
    m.handle_connected(T, 3, "c".into());
    m.handle_message(T, 3, hello(3), &cert_of(3));
    m.handle_message(T, 3, hello(3), &cert_of(3));
    let all = actions(&mut m);
    assert_eq!(
        closes(&all),
        vec![(2, Refusal::Protocol), (3, Refusal::Protocol)]
    );
    assert_eq!(m.members(), 1);
}

fn address(peer: u32) -> PeerAddress {
    PeerAddress {
        peer: PeerId(peer),
        addr: format!("10.0.0.{peer}:1"),
    }
}

#[test]
fn after_the_start_a_newcomer_joins_at_once_and_every_pair_learns_of_each_other() {
    let mut m = membership();
    join(&mut m, 1);
    join(&mut m, 3);
    // Peer 2 is half way through joining when the render starts: it finishes later.
    m.handle_connected(T, 2, address(2).addr);
    m.handle_message(T, 2, hello(2), &cert_of(2));
    m.start(T);
    let started = actions(&mut m);
    assert!(closes(&started).is_empty(), "{started:?}");
    m.handle_message(T, 2, Message::SceneReady, &cert_of(2));
    let late = actions(&mut m);
    assert_eq!(
        late,
        vec![
            Action::Send {
                conn: 2,
                message: Message::Peers {
                    peers: vec![address(1), address(2), address(3)]
                }
            },
            Action::Send {
                conn: 1,
                message: Message::Peers {
                    peers: vec![address(2)]
                }
            },
            Action::Send {
                conn: 3,
                message: Message::Peers {
                    peers: vec![address(2)]
                }
            },
            Action::Joined {
                peer: PeerId(2),
                conn: 2
            },
        ]
    );
    assert_eq!(m.members(), 3);
    // One that connects from scratch after the start is welcomed and joins the same way.
    let fourth = join(&mut m, 4);
    assert!(
        matches!(
            &fourth[..],
            [
                Action::Send {
                    message: Message::Welcome { .. },
                    ..
                },
                Action::Send {
                    message: Message::Scene { .. },
                    ..
                },
                Action::Send { conn: 4, .. },
                Action::Send { conn: 1, .. },
                Action::Send { conn: 2, .. },
                Action::Send { conn: 3, .. },
                Action::Joined {
                    peer: PeerId(4),
                    conn: 4
                },
            ]
        ),
        "{fourth:?}"
    );
}

#[test]
fn a_member_that_left_may_come_back_under_its_identity_and_rejoin() {
    let mut m = membership();
    join(&mut m, 1);
    m.start(T);
    actions(&mut m);
    // A member's goodbye is not a protocol error; its close then reports it gone.
    let bye = Message::Goodbye {
        reason: GoodbyeReason::Shutdown,
    };
    m.handle_message(T, 1, bye, &cert_of(1));
    m.handle_closed(T, 1);
    assert_eq!(actions(&mut m), vec![Action::Left { peer: PeerId(1) }]);
    assert_eq!(m.members(), 0);
    let again = join(&mut m, 101);
    assert!(
        again.contains(&Action::Joined {
            peer: PeerId(1),
            conn: 101
        }),
        "{again:?}"
    );
    // While it is a member, its identity stays taken after the start too.
    m.handle_connected(T, 201, "x".into());
    m.handle_message(T, 201, hello(1), &cert_of(201));
    assert_eq!(closes(&actions(&mut m)), vec![(201, Refusal::Identity)]);
}
