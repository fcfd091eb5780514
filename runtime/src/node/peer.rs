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

/// Joins the owner at `owner`, renders until the render is over, and returns this peer's tiles
/// rendered (for the Gantt chart) when the owner says goodbye.
pub async fn run_peer(
    owner: SocketAddr,
    listen: SocketAddr,
    identity: &PeerIdentity,
    options: Options,
) -> Result<Vec<super::LocalTile>, NodeError> {
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
    loop {
        match session.step().await {
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
                            let now = session.now();
                            session.core.handle_peer_connected(now, peer);
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
                            let now = session.now();
                            session.core.handle_peer_connected(now, peer);
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
                        let now = session.now();
                        session.core.handle_peer_connected(now, PeerId(0));
                        session.flush();
                    }
                    Message::Peers { peers } if conn == owner_conn => {
                        for address in peers
                            .into_iter()
                            .filter(|a| a.peer < me && a.peer != PeerId(0))
                        {
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
            Step::Core(event) => tracing::debug!(?event, "core event"),
            Step::Stopped => break,
            Step::Failed(error) => {
                session.link.shutdown().await;
                return Err(error);
            }
        }
    }
    session.link.shutdown().await;
    match lost {
        Some(reason) => Err(NodeError::OwnerLost(reason)),
        None => Ok(std::mem::take(&mut session.local_tiles)),
    }
}
