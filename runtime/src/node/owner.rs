//! The frame owner: admits peers, ships them the scene, and for each frame asks the balancer for
//! tiles and initial sets, starts the frame in its core, and assembles the results. It renders
//! tiles itself too: its own core is one of the participants.

use super::bundle;
use super::session::{Session, Step, check_hello};
use super::{CompletedFrame, FrameSink, NodeError, Options, TileRecord};
use crate::core::{Event as CoreEvent, PeerStats};
use crate::net::{CloseCode, PeerIdentity};
use crate::wire::{
    FrameId, GoodbyeReason, Message, PROTOCOL_VERSION, PeerAddress, PeerId, RenderParams,
    SceneFile, TileId, TileSpec,
};
use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;
use tracer::{Film, World};

/// What the owner renders.
pub struct Job {
    pub world: Arc<World>,
    /// The scene's files, hashed, shipped to every peer.
    pub files: Vec<SceneFile>,
    /// The settings every peer renders with (the scene's, after command-line overrides).
    pub params: RenderParams,
    pub frames: u32,
    pub partitioner: balancer::Partitioner,
}

/// The owner, bound and listening, before the render starts.
pub struct Owner {
    session: Session,
    options: Options,
}

/// Every peer's statistics for every frame, as the peers reported them.
pub type PeerReport = BTreeMap<(u64, PeerId), PeerStats>;

impl Owner {
    /// Binds the owner's endpoint. Must be called within a tokio runtime.
    pub fn bind(
        listen: SocketAddr,
        identity: &PeerIdentity,
        options: Options,
    ) -> Result<Self, NodeError> {
        Ok(Self {
            session: Session::bind(listen, identity, &options)?,
            options,
        })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.session.link.local_addr()
    }

    /// Waits for `expect` peers to join, then renders every frame of `job`, handing each finished
    /// frame to `sink`. Returns what the peers reported, and the tiles rendered here.
    pub async fn run(
        mut self,
        job: Job,
        expect: usize,
        sink: &mut dyn FrameSink,
    ) -> Result<(PeerReport, Vec<super::LocalTile>), NodeError> {
        let (renderer, results) =
            super::session::Renderer::new(self.options.threads, job.world.clone())?;
        self.session.set_renderer(renderer, results);
        let joined = self.admit(&job.files, job.params, expect).await?;
        let mut partitioner = job.partitioner;
        let mut report = PeerReport::new();
        for frame in 0..job.frames {
            let completed = self
                .render_frame(frame, &mut partitioner, &job.world, &mut report)
                .await?;
            sink.frame(completed).map_err(NodeError::Sink)?;
        }
        // Late statistics of the last frame arrive after its FrameDone: give them a moment.
        let deadline = Instant::now() + std::time::Duration::from_millis(200);
        while report
            .keys()
            .filter(|(f, _)| u64::from(job.frames.saturating_sub(1)) == *f)
            .count()
            < joined + 1
        {
            let remaining = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(remaining, self.session.step()).await {
                Ok(Step::Core(CoreEvent::PeerStats { frame, peer, stats })) => {
                    report.insert((frame.0, peer), stats);
                }
                Ok(Step::Stopped) | Err(_) => break,
                Ok(_) => {}
            }
        }
        let peers: Vec<PeerId> = self.session.peers.ids().collect();
        for peer in peers {
            self.session.send(
                peer,
                &Message::Goodbye {
                    reason: GoodbyeReason::Shutdown,
                },
            );
        }
        // Give the goodbyes a moment to leave before the endpoint closes.
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        self.session.link.shutdown().await;
        Ok((report, std::mem::take(&mut self.session.local_tiles)))
    }

    /// Admits peers until `expect` have loaded the scene; then tells each where the others are.
    async fn admit(
        &mut self,
        files: &[SceneFile],
        params: RenderParams,
        expect: usize,
    ) -> Result<usize, NodeError> {
        let mut pending: BTreeMap<crate::net::ConnId, (crate::net::PeerCertificate, SocketAddr)> =
            BTreeMap::new();
        let mut ready: BTreeMap<PeerId, SocketAddr> = BTreeMap::new();
        let mut loading: BTreeMap<crate::net::ConnId, (PeerId, SocketAddr)> = BTreeMap::new();
        let digest = bundle::scene_digest(files);
        while ready.len() < expect {
            match self.session.step().await {
                Step::Connected {
                    conn,
                    certificate,
                    remote,
                    ..
                } => {
                    pending.insert(conn, (certificate, remote));
                }
                Step::Control { conn, message } => {
                    if let Some((certificate, remote)) = pending.remove(&conn) {
                        match check_hello(&message, &certificate) {
                            Ok((peer, _))
                                if peer == self.session.core.id() || ready.contains_key(&peer) =>
                            {
                                self.session.close(
                                    conn,
                                    CloseCode::Identity,
                                    &format!("{peer} is already here"),
                                );
                            }
                            Ok((peer, slots)) => {
                                tracing::info!(%peer, %remote, slots, "peer joined; sending scene {digest}");
                                self.session.send_conn(
                                    conn,
                                    &Message::Welcome {
                                        version: PROTOCOL_VERSION,
                                        peer: self.session.core.id(),
                                    },
                                );
                                self.session.send_conn(
                                    conn,
                                    &Message::Scene {
                                        files: files.to_vec(),
                                        params,
                                    },
                                );
                                loading.insert(conn, (peer, remote));
                            }
                            Err(reason) => self.session.close(conn, CloseCode::Identity, &reason),
                        }
                    } else if let (Some(&(peer, remote)), Message::SceneReady) =
                        (loading.get(&conn), &message)
                    {
                        loading.remove(&conn);
                        self.session.peers.bind(conn, peer);
                        ready.insert(peer, remote);
                        tracing::info!(%peer, "peer ready ({}/{expect})", ready.len());
                    } else if let Message::Goodbye { reason } = message {
                        tracing::warn!(?conn, ?reason, "a joining peer gave up");
                    } else {
                        self.session.close(
                            conn,
                            CloseCode::Protocol,
                            &format!("unexpected {} while joining", message.kind()),
                        );
                    }
                }
                Step::Closed { conn, peer } => {
                    pending.remove(&conn);
                    loading.remove(&conn);
                    if let Some(peer) = peer {
                        ready.remove(&peer);
                    }
                }
                Step::Core(event) => tracing::debug!(?event, "core event while admitting"),
                Step::Stopped => return Err(NodeError::Stopped),
            }
        }
        let addresses: Vec<PeerAddress> = ready
            .iter()
            .map(|(&peer, addr)| PeerAddress {
                peer,
                addr: addr.to_string(),
            })
            .collect();
        let now = self.session.now();
        for &peer in ready.keys() {
            self.session.send(
                peer,
                &Message::Peers {
                    peers: addresses.clone(),
                },
            );
            self.session.core.handle_peer_connected(now, peer);
        }
        self.session.flush();
        Ok(ready.len())
    }

    async fn render_frame(
        &mut self,
        frame: u32,
        partitioner: &mut balancer::Partitioner,
        world: &World,
        report: &mut PeerReport,
    ) -> Result<CompletedFrame, NodeError> {
        let tiles = partitioner.tiles();
        let mut participants: BTreeSet<PeerId> = self.session.peers.ids().collect();
        participants.insert(self.session.core.id());
        let participants: Vec<PeerId> = participants.into_iter().collect();
        let assignment = partitioner.assign(participants.len(), None)?;
        let mut initial: BTreeMap<PeerId, Vec<TileSpec>> = BTreeMap::new();
        for (peer, run) in participants.iter().zip(assignment.runs.iter()) {
            let specs = run
                .iter()
                .map(|&index| TileSpec {
                    id: TileId(index as u32),
                    rect: tiles[index].rect,
                    predicted: tiles[index].predicted,
                })
                .collect();
            initial.insert(*peer, specs);
        }
        let owners: BTreeMap<TileId, PeerId> = initial
            .iter()
            .flat_map(|(&peer, specs)| specs.iter().map(move |spec| (spec.id, peer)))
            .collect();
        let now = self.session.now();
        let started = Instant::now();
        self.session
            .core
            .start_frame(now, FrameId(u64::from(frame)), initial)?;
        self.session.flush();
        // A renderer that keeps producing results the ledger refuses would have its tiles
        // re-issued forever; past this many refusals the render stops with an error instead.
        let mut faults = 0usize;
        let max_faults = 2 * tiles.len() + 8;
        loop {
            match self.session.step().await {
                Step::Core(CoreEvent::FrameComplete {
                    frame: done,
                    results,
                    rendered_by,
                    ..
                }) if done.0 == u64::from(frame) => {
                    let seconds = started.elapsed().as_secs_f64();
                    let results = rendered_by.into_iter().zip(results).collect();
                    return self.assemble(
                        frame,
                        &tiles,
                        &owners,
                        results,
                        world,
                        seconds,
                        partitioner,
                    );
                }
                Step::Core(CoreEvent::PeerStats { frame, peer, stats }) => {
                    report.insert((frame.0, peer), stats);
                }
                Step::Core(CoreEvent::PeerFailed {
                    peer,
                    reason,
                    reissued,
                    ..
                }) => {
                    tracing::warn!(%peer, ?reason, reissued, "peer failed; its tiles were re-issued");
                }
                Step::Core(CoreEvent::FaultyPeer {
                    peer, tile, fault, ..
                }) => {
                    tracing::error!(%peer, %tile, ?fault, "faulty result ignored");
                    faults += 1;
                    if faults > max_faults {
                        return Err(NodeError::Faulty { frame, faults });
                    }
                }
                Step::Core(event) => tracing::debug!(?event, "core event"),
                Step::Connected { conn, .. } => {
                    self.session.close(
                        conn,
                        CloseCode::Protocol,
                        "the render has started; no new peers",
                    );
                }
                Step::Control { conn, message } => {
                    if !matches!(message, Message::Goodbye { .. }) {
                        self.session.close(
                            conn,
                            CloseCode::Protocol,
                            &format!("unexpected {}", message.kind()),
                        );
                    }
                }
                Step::Closed { .. } => {}
                Step::Stopped => return Err(NodeError::Stopped),
            }
        }
    }

    fn assemble(
        &mut self,
        frame: u32,
        tiles: &[balancer::Tile],
        owners: &BTreeMap<TileId, PeerId>,
        results: Vec<(PeerId, crate::wire::TileResult)>,
        world: &World,
        seconds: f64,
        partitioner: &mut balancer::Partitioner,
    ) -> Result<CompletedFrame, NodeError> {
        let settings = &world.scene.settings;
        let mut film = Film::new(settings.width, settings.height);
        let mut records = Vec::with_capacity(results.len());
        let mut rays = 0u64;
        for (peer, result) in results {
            let rect = tracer::Rect {
                x: result.rect.x,
                y: result.rect.y,
                w: result.rect.w,
                h: result.rect.h,
            };
            let pixels =
                bundle::decode_pixels(&result.pixels).ok_or(NodeError::BadTile(result.tile))?;
            let cost = bundle::decode_cost(&result.costs).ok_or(NodeError::BadTile(result.tile))?;
            let (_, _, bw, bh) = rect.blocks();
            if pixels.len() as u64 != rect.area() || cost.blocks.len() != (bw * bh) as usize {
                return Err(NodeError::BadTile(result.tile));
            }
            film.insert(rect, &pixels, &cost);
            rays += cost.rays;
            let predicted = tiles
                .get(result.tile.0 as usize)
                .map_or(0.0, |t| t.predicted);
            let initial = owners.get(&result.tile).copied().unwrap_or(peer);
            records.push(TileRecord {
                tile: result.tile,
                rect: result.rect,
                predicted,
                measured: cost.work,
                peer,
                initial,
            });
        }
        let map = balancer::CostMap::from_counts(
            film.width,
            film.height,
            tracer::BLOCK_SIZE,
            &film.block_work,
        )?;
        partitioner.observe(&map)?;
        Ok(CompletedFrame {
            frame,
            film,
            tiles: records,
            seconds,
            rays,
        })
    }
}
