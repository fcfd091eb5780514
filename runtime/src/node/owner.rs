//! The frame owner: the QUIC driver of [`Membership`] (who may join) and [`Director`] (what each
//! frame deals and what it yields), beside its own scheduling core. It decides nothing itself:
//! it carries messages, timers and core events between those state machines, assembles each
//! completed frame's pixels into a film, and measures its cost map. It renders tiles itself
//! too: its own core is one of the participants.

use super::bundle;
use super::checkpoint::{self, Checkpoint, Checkpointing};
use super::session::{Session, Step};
use super::{CompletedFrame, FrameSink, GOODBYE_BOUND, NodeError, Options};
use crate::net::{CloseCode, PeerIdentity};
use runtime_core::director::{self, Director, Piece};
use runtime_core::membership::{Action, Membership, Refusal};
use runtime_core::peer::{Event as CoreEvent, Failure, PeerStats};
use runtime_core::stats::{LocalTile, TileStats};
use runtime_core::wire::{FrameId, GoodbyeReason, Message, PeerId, RenderParams, SceneFile};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tracer::{Film, World};

/// What the owner renders.
pub struct Job {
    /// The loaded scene, which the owner's own rendering threads trace.
    pub world: Arc<World>,
    /// The scene's files, hashed, shipped to every peer.
    pub files: Vec<SceneFile>,
    /// The settings every peer renders with (the scene's, after command-line overrides).
    pub params: RenderParams,
    /// The animation's frame count.
    pub frames: u32,
    /// The first frame to render: those before it are done already (`--resume`). Usually 0.
    pub first: u32,
    /// The balancer that cuts every frame, its tree carried from frame to frame.
    pub partitioner: balancer::Partitioner,
    /// Whether and where the frame in progress is checkpointed, and a checkpoint to resume
    /// the first frame from.
    pub checkpoint: Option<Checkpointing>,
}

/// The owner, bound and listening, before the render starts.
pub struct Owner {
    session: Session,
    options: Options,
    /// The certificate of each connection that has not closed, for membership's identity check.
    certificates: BTreeMap<crate::net::ConnId, crate::net::PeerCertificate>,
}

/// Every peer's statistics for every frame, as the peers reported them.
pub type PeerReport = BTreeMap<(u32, PeerId), PeerStats>;

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
            certificates: BTreeMap::new(),
        })
    }

    /// The address the owner listens on, which peers dial.
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
    ) -> Result<(PeerReport, Vec<LocalTile>), NodeError> {
        let (renderer, results) =
            super::session::Renderer::new(self.options.threads, job.world.clone())?;
        self.session.set_renderer(renderer, results);
        let me = self.session.core.id();
        tracing::info!(
            "scene {}; waiting for {expect} peers",
            bundle::scene_digest(&job.files)
        );
        let mut membership = Membership::new(me, job.files, job.params);
        let config = director::Config {
            frames: job.frames,
            first: job.first,
            ..director::Config::default()
        };
        let mut director = Director::new(me, job.partitioner, config);
        let mut checkpoints = job.checkpoint.map(Checkpoints::new);
        // Results of the first frame kept by a stopped render, for its ledger. The director
        // deals `job.first` first, cut into the checkpoint's tiles, so the first deal takes them.
        let mut kept = checkpoints
            .as_mut()
            .and_then(|c| c.plan.resume.take())
            .filter(|kept| kept.frame.0 == job.first)
            .map(|kept| {
                director.resume_with(kept.tiles);
                kept.results
            });
        let mut report = PeerReport::new();
        while membership.members() < expect {
            let step = self.session.step().await;
            self.on_step(step, &mut membership, &mut director, &mut report)?;
        }
        membership.start(self.session.now());
        self.apply(&mut membership, &mut director);
        while !director.is_finished() {
            let now = self.session.now();
            while let Some(deal) = director.poll_deal(now)? {
                let done = kept.take().unwrap_or_default();
                self.session.core.resume_frame(
                    now,
                    deal.frame,
                    deal.assignments,
                    deal.render_pixels,
                    done,
                )?;
                self.session.flush();
            }
            while let Some(event) = director.poll_event() {
                if let director::Event::FrameComplete {
                    frame,
                    elapsed,
                    pieces,
                    audit,
                } = event
                {
                    let (mut completed, map) =
                        assemble(frame, pieces, &job.world, elapsed, self.session.now())?;
                    completed.audit = audit;
                    director.handle_measured(self.session.now(), frame, &map)?;
                    sink.frame(completed).map_err(NodeError::Sink)?;
                }
            }
            if director.is_finished() {
                break;
            }
            let deadline = [
                director.poll_timeout(),
                checkpoints.as_ref().and_then(|c| c.due),
            ]
            .into_iter()
            .flatten()
            .min()
            .map(|t| tokio::time::Instant::from_std(self.session.epoch() + t));
            let step = tokio::select! {
                step = self.session.step() => Some(step),
                () = sleep_until(deadline) => None,
            };
            match step {
                Some(step) => self.on_step(step, &mut membership, &mut director, &mut report)?,
                None => {
                    let now = self.session.now();
                    director.handle_timeout(now);
                    if let Some(checkpoints) = &mut checkpoints {
                        checkpoints.on_timeout(now, &self.session.core, &director);
                    }
                }
            }
        }
        if let Some(checkpoints) = checkpoints {
            checkpoints.finish().await;
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
        // The goodbyes must leave before the endpoint closes every connection. A peer that
        // stopped reading would hold its send forever; it gets no more than this.
        let _ = tokio::time::timeout(GOODBYE_BOUND, self.session.drain_sends()).await;
        self.session.link.shutdown().await;
        Ok((report, std::mem::take(&mut self.session.local_tiles)))
    }

    /// Hands one step of the loop to the state machine it is for.
    fn on_step(
        &mut self,
        step: Step,
        membership: &mut Membership<crate::net::ConnId>,
        director: &mut Director,
        report: &mut PeerReport,
    ) -> Result<(), NodeError> {
        let now = self.session.now();
        match step {
            Step::Core(event) => {
                let Some(event) = director.handle_core_event(now, event)? else {
                    return Ok(());
                };
                match event {
                    CoreEvent::PeerStats { frame, peer, stats } => {
                        report.insert((frame.0, peer), stats);
                    }
                    CoreEvent::PeerFailed {
                        peer,
                        reason: Failure::Left,
                        reissued,
                        frame,
                    } => {
                        tracing::info!(%peer, %frame, reissued, "peer leaving; the tiles it had not started were re-issued");
                    }
                    CoreEvent::PeerFailed {
                        peer,
                        reason,
                        reissued,
                        ..
                    } => {
                        tracing::warn!(%peer, ?reason, reissued, "peer failed; its tiles were re-issued");
                    }
                    CoreEvent::PeerLeaving { peer } => {
                        tracing::info!(%peer, "peer leaving the render");
                    }
                    CoreEvent::FaultyPeer {
                        peer, tile, fault, ..
                    } => tracing::error!(%peer, %tile, ?fault, "faulty result ignored"),
                    event => tracing::debug!(?event, "core event"),
                }
            }
            Step::Connected {
                conn,
                remote,
                certificate,
                ..
            } => {
                self.certificates.insert(conn, certificate);
                membership.handle_connected(now, conn, remote.to_string());
            }
            Step::Control { conn, message } => {
                let certificate = self.certificates.get(&conn);
                let certifies = |id: u32| certificate.is_some_and(|c| c.certifies(id));
                membership.handle_message(now, conn, message, &certifies);
            }
            Step::Closed { conn, .. } => {
                self.certificates.remove(&conn);
                membership.handle_closed(now, conn);
            }
            Step::Stopped => return Err(NodeError::Stopped),
        }
        self.apply(membership, director);
        Ok(())
    }

    /// Carries out what membership decided.
    fn apply(&mut self, membership: &mut Membership<crate::net::ConnId>, director: &mut Director) {
        let now = self.session.now();
        while let Some(action) = membership.poll_action() {
            match action {
                Action::Send { conn, message } => self.session.send_conn(conn, &message),
                Action::Close {
                    conn,
                    refusal,
                    reason,
                } => {
                    let code = match refusal {
                        Refusal::Identity => CloseCode::Identity,
                        Refusal::Protocol => CloseCode::Protocol,
                    };
                    self.session.close(conn, code, &reason);
                }
                Action::Joined { peer, conn } => {
                    tracing::info!(%peer, "peer joined the render");
                    self.session.peers.bind(conn, peer);
                    self.session.connected(conn, peer);
                    director.handle_peer_joined(now, peer);
                }
                Action::Left { peer } => director.handle_peer_left(now, peer),
            }
        }
        self.session.flush();
    }
}

/// The owner's checkpoints of the frame in progress: every `plan.every`, the oldest running
/// frame's accepted results, if more came in since the last, written by a blocking task while
/// the loop goes on (a checkpoint of a large frame is tens of megabytes). One write at a time:
/// a checkpoint due while the last is still being written waits for the next turn.
struct Checkpoints {
    plan: Checkpointing,
    /// When the next checkpoint is due; never without `plan.every`.
    due: Option<Duration>,
    /// The frame and result count of the last checkpoint written.
    last: Option<(FrameId, usize)>,
    writing: Option<tokio::task::JoinHandle<()>>,
}

impl Checkpoints {
    fn new(plan: Checkpointing) -> Self {
        Self {
            due: plan.every,
            plan,
            last: None,
            writing: None,
        }
    }

    fn on_timeout(&mut self, now: Duration, core: &runtime_core::peer::Core, director: &Director) {
        let (Some(due), Some(every)) = (self.due, self.plan.every) else {
            return;
        };
        if now < due {
            return;
        }
        self.due = Some(now + every);
        if self
            .writing
            .as_ref()
            .is_some_and(|task| !task.is_finished())
        {
            return;
        }
        let Some(frame) = core.running_frames().next() else {
            return;
        };
        let (Some(results), Some(deal)) = (core.accepted(frame), director.running_deal(frame))
        else {
            return;
        };
        if results.is_empty() || self.last == Some((frame, results.len())) {
            return;
        }
        self.last = Some((frame, results.len()));
        let checkpoint = Checkpoint {
            render_hash: self.plan.render_hash.clone(),
            frame,
            tiles: deal.tiles.clone(),
            results,
        };
        let path = self.plan.path.clone();
        self.writing = Some(tokio::task::spawn_blocking(move || {
            match checkpoint.write(&path) {
                Ok(()) => tracing::debug!(%frame, "checkpoint written"),
                // A checkpoint is insurance: failing to write one costs nothing now.
                Err(error) => {
                    tracing::warn!(%error, "cannot write the checkpoint {}", path.display())
                }
            }
        }));
    }

    /// The render is done: no checkpoint is needed any more.
    async fn finish(self) {
        if let Some(task) = self.writing {
            let _ = task.await;
        }
        if let Err(error) = checkpoint::remove(&self.plan.path) {
            tracing::warn!(%error, "cannot remove the checkpoint {}", self.plan.path.display());
        }
    }
}

/// Sleeps until `deadline`, or forever without one.
async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(deadline) => tokio::time::sleep_until(deadline).await,
        None => std::future::pending().await,
    }
}

/// Puts a completed frame's pieces together: pixels into a film, counted work into the cost map
/// the director learns from, and a record per tile.
fn assemble(
    frame: FrameId,
    pieces: Vec<Piece>,
    world: &World,
    elapsed: Duration,
    now: Duration,
) -> Result<(CompletedFrame, balancer::CostMap), NodeError> {
    let settings = &world.scene.settings;
    let mut film = Film::new(settings.width, settings.height);
    let mut records = Vec::with_capacity(pieces.len());
    let mut rays = 0u64;
    for piece in pieces {
        let result = piece.result;
        let rect = bundle::tracer_rect(result.rect);
        let pixels =
            bundle::decode_pixels(&result.pixels).ok_or(NodeError::BadTile(result.tile))?;
        let cost = bundle::decode_cost(&result.costs).ok_or(NodeError::BadTile(result.tile))?;
        let (_, _, bw, bh) = rect.blocks();
        if pixels.len() as u64 != rect.area() || cost.blocks.len() != (bw * bh) as usize {
            return Err(NodeError::BadTile(result.tile));
        }
        film.insert(rect, &pixels, &cost);
        rays += cost.rays;
        records.push(TileStats::piece(
            result.tile.0,
            result.rect,
            piece.predicted,
            cost.work,
            piece.peer.0,
            piece.initial.0,
        ));
    }
    let map = balancer::CostMap::from_counts(
        film.width,
        film.height,
        tracer::BLOCK_SIZE,
        &film.block_work,
    )?;
    let completed = CompletedFrame {
        frame: frame.0,
        film,
        tiles: records,
        seconds: elapsed.as_secs_f64(),
        completed_at: now.as_secs_f64(),
        rays,
        audit: runtime_core::peer::Audit::default(),
    };
    Ok((completed, map))
}
