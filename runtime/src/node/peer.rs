//! A peer that is not the frame owner: joins the owner, loads the scene it is sent, connects to
//! the other peers so that it can steal from them, and renders until the owner says goodbye.

use super::session::{Renderer, Session, Step};
use super::{NodeError, Options, bundle};
use crate::net::{CloseCode, CloseReason, ConnId, Expect, PeerIdentity};
use runtime_core::membership::check_hello;
use runtime_core::peer::Event as CoreEvent;
use runtime_core::wire::{GoodbyeReason, Message, PROTOCOL_VERSION, PeerId};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::sync::watch;

/// Asks a running peer to leave the render, as SIGTERM asks a SLURM task or a preempted cloud
/// machine to stop: the peer hands back what it has not started, finishes the tiles in its
/// renderer, and goes (see the protocol's *Joining and leaving*). [`Leave::never`] for a peer
/// nobody will ask.
#[derive(Clone, Debug)]
pub struct Leave(Option<watch::Receiver<bool>>);

impl Leave {
    /// A request that never comes, for a peer nobody will ask to leave.
    pub fn never() -> Self {
        Self(None)
    }

    /// A request and the sender that makes it: send `true` to ask.
    pub fn channel() -> (watch::Sender<bool>, Self) {
        let (sender, receiver) = watch::channel(false);
        (sender, Self(Some(receiver)))
    }

    /// Resolves once asked; never, if the sender is gone without asking.
    async fn asked(&mut self) {
        if let Some(receiver) = &mut self.0
            && receiver.wait_for(|&asked| asked).await.is_ok()
        {
            return;
        }
        std::future::pending().await
    }
}

/// How a peer's part in a render ended.
#[derive(Debug)]
pub struct PeerRun {
    /// The tiles this peer rendered, with times since its own start (for the Gantt chart).
    pub tiles: Vec<runtime_core::stats::LocalTile>,
    /// Whether it left when asked ([`Leave`]) rather than at the render's end.
    pub left: bool,
}

/// Joins the owner at `owner` and renders until the render is over, or until asked to `leave`
/// and done handing back.
pub async fn run_peer(
    owner: SocketAddr,
    listen: SocketAddr,
    identity: &PeerIdentity,
    options: Options,
    mut leave: Leave,
) -> Result<PeerRun, NodeError> {
    let me = PeerId(identity.index());
    let mut session = Session::bind(listen, identity, &options)?;
    let owner_conn = session.link.connect(owner, Expect::Peer(0)).await?;
    session.send_conn(
        owner_conn,
        &Message::Hello {
            version: PROTOCOL_VERSION,
            peer: me,
            slots: options.threads as u32,
        },
    );

    // Connections whose handshake is under way: inbound ones wait for Hello, outbound for Welcome.
    let mut inbound: BTreeMap<ConnId, crate::net::PeerCertificate> = BTreeMap::new();
    let mut outbound: BTreeMap<ConnId, PeerId> = BTreeMap::new();
    // Where the peers we dial listen: their certificates were required at connect time.
    let mut dialing: BTreeMap<SocketAddr, PeerId> = BTreeMap::new();
    // Why the owner's connection ended, if not as a finished render's does.
    let mut lost = None;
    let mut left = false;
    loop {
        let step = tokio::select! {
            step = session.step() => step,
            () = leave.asked(), if !session.core.is_leaving() => {
                tracing::info!(%me, "asked to leave: handing back the tiles not being rendered");
                let now = session.now();
                session.core.leave(now, PeerId(0));
                session.flush();
                continue;
            }
        };
        match step {
            Step::Connected {
                conn,
                remote,
                outbound: true,
                ..
            } => {
                // TLS already checked the certificate we asked for (`Expect::Peer`), so the
                // connection is bound to its peer at once: a message overtaking the Welcome
                // (every message has its own stream) still finds its sender.
                let peer = if conn == owner_conn {
                    Some(PeerId(0))
                } else {
                    dialing.get(&remote).copied()
                };
                match peer {
                    Some(peer) => {
                        session.peers.bind(conn, peer);
                        if conn != owner_conn {
                            session.send_conn(
                                conn,
                                &Message::Hello {
                                    version: PROTOCOL_VERSION,
                                    peer: me,
                                    slots: options.threads as u32,
                                },
                            );
                        }
                        outbound.insert(conn, peer);
                    }
                    None => session.close(conn, CloseCode::Protocol, "a connection nobody dialed"),
                }
            }
            Step::Connected {
                conn, certificate, ..
            } => {
                inbound.insert(conn, certificate);
            }
            Step::Control { conn, message } => {
                if let Some(certificate) = inbound.remove(&conn) {
                    match check_hello(&message, &|id| certificate.certifies(id)) {
                        Ok((peer, _)) if peer > me => {
                            session.send_conn(
                                conn,
                                &Message::Welcome {
                                    version: PROTOCOL_VERSION,
                                    peer: me,
                                },
                            );
                            session.peers.bind(conn, peer);
                            session.connected(conn, peer);
                            session.flush();
                        }
                        Ok((peer, _)) => session.close(
                            conn,
                            CloseCode::Protocol,
                            &format!("{peer} should not dial {me}"),
                        ),
                        Err(reason) => session.close(conn, CloseCode::Identity, &reason),
                    }
                    continue;
                }
                match message {
                    Message::Welcome { version, peer } if outbound.get(&conn) == Some(&peer) => {
                        outbound.remove(&conn);
                        if version != PROTOCOL_VERSION {
                            session.close(conn, CloseCode::Protocol, "another protocol version");
                            continue;
                        }
                        if conn != owner_conn {
                            session.connected(conn, peer);
                            session.flush();
                        }
                    }
                    Message::Scene { files, params } if conn == owner_conn => {
                        let digest = bundle::scene_digest(&files);
                        let loaded =
                            tokio::task::spawn_blocking(move || bundle::load_scene(files, &params))
                                .await;
                        let scene = match loaded {
                            Ok(Ok(scene)) => scene,
                            Ok(Err(error)) => {
                                session.send_conn(
                                    conn,
                                    &Message::Goodbye {
                                        reason: GoodbyeReason::BadScene,
                                    },
                                );
                                return Err(error.into());
                            }
                            Err(join) => return Err(NodeError::Io(std::io::Error::other(join))),
                        };
                        let effects = params.all_effects.then_some(tracer::Effects::ALL);
                        let world = tokio::task::spawn_blocking(move || {
                            Arc::new(tracer::World::prepare(scene, effects))
                        })
                        .await
                        .map_err(|e| NodeError::Io(std::io::Error::other(e)))?;
                        let (renderer, results) = Renderer::new(options.threads, world)?;
                        session.set_renderer(renderer, results);
                        tracing::info!(%me, "scene {digest} loaded");
                        session.send_conn(conn, &Message::SceneReady);
                        session.connected(conn, PeerId(0));
                        session.flush();
                    }
                    Message::Peers { peers } if conn == owner_conn => {
                        // The first list names every member; later ones name a peer that
                        // joined since. Of each pair, the higher id dials the lower.
                        let known: Vec<PeerId> = session.peers.ids().collect();
                        for address in peers.into_iter().filter(|a| {
                            a.peer < me && a.peer != PeerId(0) && !known.contains(&a.peer)
                        }) {
                            let Ok(addr) = address.addr.parse::<SocketAddr>() else {
                                tracing::warn!(addr = address.addr, "unusable peer address");
                                continue;
                            };
                            dialing.insert(addr, address.peer);
                            let link = session.link.clone();
                            tokio::spawn(async move {
                                if let Err(error) =
                                    link.connect(addr, Expect::Peer(address.peer.0)).await
                                {
                                    tracing::warn!(peer = %address.peer, %error, "cannot reach peer; stealing from the others");
                                }
                            });
                        }
                    }
                    Message::Goodbye { .. } if conn == owner_conn => break,
                    Message::Goodbye { .. } => {}
                    other => session.close(
                        conn,
                        CloseCode::Protocol,
                        &format!("unexpected {}", other.kind()),
                    ),
                }
            }
            Step::Closed { conn, reason } if conn == owner_conn => {
                // An owner that finished says goodbye (which ends the loop above) or closes with
                // `Shutdown`; anything else (silence past the idle timeout, a reset, a crash, a
                // refusal) leaves the render incomplete, and the user must hear of it.
                let finished = matches!(
                    reason,
                    CloseReason::Remote { code, .. } if code == CloseCode::Shutdown as u64
                );
                if !finished {
                    lost = Some(reason);
                }
                break;
            }
            Step::Closed { conn, .. } => {
                inbound.remove(&conn);
                outbound.remove(&conn);
            }
            Step::Core(CoreEvent::OwnerLost { frame }) => {
                tracing::warn!(%frame, "the owner is gone")
            }
            Step::Core(CoreEvent::Left) => {
                tracing::info!(%me, "the last results are sent: leaving the render");
                session.send_conn(
                    owner_conn,
                    &Message::Goodbye {
                        reason: GoodbyeReason::Shutdown,
                    },
                );
                left = true;
                break;
            }
            Step::Core(event) => tracing::debug!(?event, "core event"),
            Step::Stopped => break,
        }
    }
    if left {
        // The last results and the goodbye must leave before the endpoint closes.
        let _ = tokio::time::timeout(super::GOODBYE_BOUND, session.drain_sends()).await;
    }
    session.link.shutdown().await;
    match lost {
        Some(reason) => Err(NodeError::OwnerLost(reason)),
        None => Ok(PeerRun {
            tiles: std::mem::take(&mut session.local_tiles),
            left,
        }),
    }
}
