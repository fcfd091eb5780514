//! Admission to a render, on the frame owner, as a state machine: which connections are peers.
//!
//! A connection that completed its TLS handshake says `Hello { version, peer, slots }`; the owner
//! checks the version and that the certificate vouches for the claimed id, answers `Welcome`
//! and ships the scene (`Scene { files, params }`); the peer answers `SceneReady` once it has
//! loaded it, and from then on it is a **member**. [`Membership::start`] starts the render:
//! every member is told where the others are (`Peers`) and is reported [`Action::Joined`].
//! Admission stays open: a peer that becomes a member later is told where every member is, every
//! other member is told where it is (so that each pair connects, the higher id dialing the
//! lower), and it is reported joined at once, to take part in the frames from then on. A member
//! whose connection closes is reported [`Action::Left`]; a new process with its identity may
//! join again.
//!
//! Races this settles (each has a scripted test): a connection that closes while loading the
//! scene is forgotten, not admitted; a second connection claiming a member's id, or the owner's,
//! is refused on identity; a peer that says `Goodbye` while joining is forgotten; anything else
//! out of turn closes that connection only.
//!
//! The connection key `C` is the driver's (the QUIC node's connection id; a number in tests).
//! Certificates stay in the driver: it passes what a certificate vouches for as a predicate.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::wire::{Message, PROTOCOL_VERSION, PeerAddress, PeerId, RenderParams, SceneFile};

/// What the driver must do.
#[derive(Clone, Debug, PartialEq)]
pub enum Action<C> {
    /// Send `message` to the other side of `conn`.
    Send {
        /// The connection to send on.
        conn: C,
        /// What to send.
        message: Message,
    },
    /// Close `conn` for `refusal`, telling the other side `reason`.
    Close {
        /// The connection to close.
        conn: C,
        /// Why it is refused, which the driver maps to a close code.
        refusal: Refusal,
        /// The text the other side is told.
        reason: String,
    },
    /// `peer` on `conn` is a member: bind the two, tell the core and the director.
    Joined {
        /// The new member's id.
        peer: PeerId,
        /// The connection it is reached on.
        conn: C,
    },
    /// Member `peer` is gone: tell the core and the director.
    Left {
        /// The member that left.
        peer: PeerId,
    },
}

/// Why a connection is refused; the driver maps these to its transport's close codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// The claimed identity is wrong: a version mismatch, a certificate that does not vouch for
    /// it, or an id already taken.
    Identity,
    /// A well-formed message out of turn.
    Protocol,
}

/// Where a connection stands.
#[derive(Clone, Debug, PartialEq)]
enum Stage {
    /// Handshake done; `Hello` expected.
    Connected { remote: String },
    /// Welcomed and sent the scene; `SceneReady` expected.
    Loading { peer: PeerId, remote: String },
    /// Admitted.
    Member { peer: PeerId },
}

/// The owner's admission state. See the module documentation.
pub struct Membership<C> {
    me: PeerId,
    files: Vec<SceneFile>,
    params: RenderParams,
    conns: BTreeMap<C, Stage>,
    /// Members by id, with their connection and address, in id order.
    members: BTreeMap<PeerId, (C, String)>,
    started: bool,
    out: VecDeque<Action<C>>,
}

/// The identity and slots a `Hello` claims, if it carries our protocol version and an id the
/// connection's certificate vouches for (`certifies`); otherwise the reason to refuse it. Every
/// peer checks the hellos it receives this way, the owner's admission and peers' mesh alike.
pub fn check_hello(
    message: &Message,
    certifies: &dyn Fn(u32) -> bool,
) -> Result<(PeerId, u32), String> {
    match *message {
        Message::Hello {
            version,
            peer,
            slots,
        } => {
            if version != PROTOCOL_VERSION {
                return Err(format!(
                    "protocol version {version}, we speak {PROTOCOL_VERSION}"
                ));
            }
            if !certifies(peer.0) {
                return Err(format!(
                    "claims to be {peer}, but its certificate does not say so"
                ));
            }
            Ok((peer, slots))
        }
        ref other => Err(format!("expected Hello, got {}", other.kind())),
    }
}

impl<C: Ord + Copy> Membership<C> {
    /// Owner `me` admits peers to a render of the scene `files` with `params`.
    pub fn new(me: PeerId, files: Vec<SceneFile>, params: RenderParams) -> Self {
        Self {
            me,
            files,
            params,
            conns: BTreeMap::new(),
            members: BTreeMap::new(),
            started: false,
            out: VecDeque::new(),
        }
    }

    /// Members that have loaded the scene.
    pub fn members(&self) -> usize {
        self.members.len()
    }

    /// True once [`Membership::start`] has run, after which members joining or leaving are
    /// reported.
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// A connection finished its handshake; `remote` is its address as the peers will dial it.
    pub fn handle_connected(&mut self, _now: Duration, conn: C, remote: String) {
        self.conns.insert(conn, Stage::Connected { remote });
    }

    /// A session message (not for the scheduling core) on `conn`. `certifies(id)` says whether
    /// the connection's certificate vouches for peer `id`.
    pub fn handle_message(
        &mut self,
        _now: Duration,
        conn: C,
        message: Message,
        certifies: &dyn Fn(u32) -> bool,
    ) {
        let Some(stage) = self.conns.get(&conn).cloned() else {
            // A connection the driver never reported, or one already refused: nothing to do.
            return;
        };
        match (stage, message) {
            // The connection closes next: a member leaves then, a joiner is forgotten now.
            (Stage::Member { .. }, Message::Goodbye { .. }) => {}
            // A joiner that goes before it is a member (a peer asked to leave while loading the
            // scene says `Leaving` first) is forgotten.
            (_, Message::Goodbye { .. } | Message::Leaving) => {
                self.conns.remove(&conn);
            }
            (Stage::Connected { remote }, hello @ Message::Hello { .. }) => {
                let peer = match check_hello(&hello, certifies) {
                    Ok((peer, _)) => peer,
                    Err(reason) => return self.refuse(conn, Refusal::Identity, &reason),
                };
                if peer == self.me || self.claimed(peer) {
                    return self.refuse(
                        conn,
                        Refusal::Identity,
                        &format!("{peer} is already here"),
                    );
                }
                self.out.push_back(Action::Send {
                    conn,
                    message: Message::Welcome {
                        version: PROTOCOL_VERSION,
                        peer: self.me,
                    },
                });
                self.out.push_back(Action::Send {
                    conn,
                    message: Message::Scene {
                        files: self.files.clone(),
                        params: self.params,
                    },
                });
                self.conns.insert(conn, Stage::Loading { peer, remote });
            }
            (Stage::Loading { peer, remote }, Message::SceneReady) => {
                self.conns.insert(conn, Stage::Member { peer });
                self.members.insert(peer, (conn, remote.clone()));
                if self.started {
                    self.admit_late(peer, conn, remote);
                }
            }
            (_, other) => {
                let reason = format!("unexpected {}", other.kind());
                self.refuse(conn, Refusal::Protocol, &reason);
            }
        }
    }

    /// `conn` is gone.
    pub fn handle_closed(&mut self, _now: Duration, conn: C) {
        if let Some(Stage::Member { peer }) = self.conns.remove(&conn) {
            self.members.remove(&peer);
            if self.started {
                self.out.push_back(Action::Left { peer });
            }
        }
    }

    /// Starts the render: tells every member where the others are and reports each joined.
    pub fn start(&mut self, _now: Duration) {
        if self.started {
            return;
        }
        self.started = true;
        let addresses = self.addresses();
        for (&peer, &(conn, _)) in &self.members {
            self.out.push_back(Action::Send {
                conn,
                message: Message::Peers {
                    peers: addresses.clone(),
                },
            });
            self.out.push_back(Action::Joined { peer, conn });
        }
    }

    /// `peer` became a member on `conn` after the render started: it learns where everyone
    /// is, everyone learns where it is, and it joins the frames.
    fn admit_late(&mut self, peer: PeerId, conn: C, remote: String) {
        let addresses = self.addresses();
        self.out.push_back(Action::Send {
            conn,
            message: Message::Peers { peers: addresses },
        });
        let newcomer = PeerAddress { peer, addr: remote };
        for (&other, &(other_conn, _)) in &self.members {
            if other != peer {
                self.out.push_back(Action::Send {
                    conn: other_conn,
                    message: Message::Peers {
                        peers: vec![newcomer.clone()],
                    },
                });
            }
        }
        self.out.push_back(Action::Joined { peer, conn });
    }

    /// The next thing the driver must do, if any; call until `None` after each `handle_*`.
    pub fn poll_action(&mut self) -> Option<Action<C>> {
        self.out.pop_front()
    }

    /// Where every member listens, in id order: what `Peers` tells.
    fn addresses(&self) -> Vec<PeerAddress> {
        self.members
            .iter()
            .map(|(&peer, (_, remote))| PeerAddress {
                peer,
                addr: remote.clone(),
            })
            .collect()
    }

    /// Whether `peer` is a member or is loading the scene on some connection.
    fn claimed(&self, peer: PeerId) -> bool {
        self.conns.values().any(|stage| match stage {
            Stage::Loading { peer: p, .. } | Stage::Member { peer: p } => *p == peer,
            Stage::Connected { .. } => false,
        })
    }

    fn refuse(&mut self, conn: C, refusal: Refusal, reason: &str) {
        self.conns.remove(&conn);
        self.out.push_back(Action::Close {
            conn,
            refusal,
            reason: reason.to_string(),
        });
    }
}

#[cfg(test)]
mod tests;
