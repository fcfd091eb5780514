//! What the core reports to its driver: events, the errors of its `handle_*` and `start_frame`
//! calls, and the per-peer statistics behind `--stats`.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::wire::{FrameId, PeerId, TileId, TileResult};

/// Something the driver should know about or act on.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// (Owner) every tile of `frame` is in. `results` cover the image once, no two
    /// overlapping: by tile id, and within a tile its pieces in tree order (one whole-tile
    /// result for a tile that never was cut).
    FrameComplete {
        /// The frame that is complete.
        frame: FrameId,
        /// Time from the frame's start in this core to its last result.
        elapsed: Duration,
        /// The accepted results, in the order described above.
        results: Vec<TileResult>,
        /// Who sent each of `results`, in the same order (for statistics and Gantt charts).
        rendered_by: Vec<PeerId>,
        /// How the frame's duplicate results compared with the first.
        audit: Audit,
    },
    /// (Owner) `frame` is near its end: a participant has run out of its work, or at most
    /// [`Config::waning`](crate::peer::Config::waning) of its predicted cost is still missing.
    /// Reported once per frame, the director's cue to deal the next frame early.
    FrameWaning {
        /// The frame that wanes.
        frame: FrameId,
    },
    /// (Owner) `peer` made no progress on its work of `frame` for long past its prediction,
    /// and that work was backed up on idle peers. It is not declared failed (it may resume),
    /// but the director deals it nothing more until it is heard of again: a result
    /// ([`Event::PeerResumed`]) or its statistics.
    PeerOverdue {
        /// The frame whose work was backed up.
        frame: FrameId,
        /// The peer that stalled.
        peer: PeerId,
    },
    /// (Owner) a peer reported overdue in `frame` sent a result of it: it is progressing again
    /// (a peer slowed by a lossy link, not a frozen one), and the director may deal it work
    /// without waiting for the frame's end.
    PeerResumed {
        /// The frame it was overdue in.
        frame: FrameId,
        /// The peer heard of again.
        peer: PeerId,
    },
    /// (Owner) a participant's statistics for `frame`, its own included.
    PeerStats {
        /// The frame the statistics cover up to.
        frame: FrameId,
        /// The participant they are from.
        peer: PeerId,
        /// What it counted.
        stats: PeerStats,
    },
    /// (Owner) a participant is gone for the rest of `frame`; `reissued` of its tiles went to
    /// live peers. After a `Silent` failure the driver should close the connection.
    PeerFailed {
        /// The frame it is gone from.
        frame: FrameId,
        /// The participant that is gone.
        peer: PeerId,
        /// How it was found gone.
        reason: Failure,
        /// How many of its tiles were re-issued to live peers.
        reissued: usize,
    },
    /// (Owner) `peer` sent something that cannot be right. Its result was not used.
    FaultyPeer {
        /// The frame the result was for.
        frame: FrameId,
        /// The peer that sent it.
        peer: PeerId,
        /// The tile the result claimed to be.
        tile: TileId,
        /// What was wrong with it.
        fault: Fault,
    },
    /// (Peer) the owner of `frame` is gone; this peer dropped the frame.
    OwnerLost {
        /// The frame dropped.
        frame: FrameId,
    },
    /// (Owner) `peer` is leaving the render: it is dealt nothing more. Its connection closes
    /// once its last tiles are in; the driver reports that as usual.
    PeerLeaving {
        /// The peer that is leaving.
        peer: PeerId,
    },
    /// (Peer) this peer was leaving and has sent the last of its results: the driver may say
    /// goodbye and close.
    Left,
}

/// The owner's account of what it gave out twice in a frame, and a free audit of determinism:
/// every result that overlapped one already received (a backup of a straggler's work, a
/// re-issued tile) was compared with it pixel for pixel.
///
/// The counts of tiles given again are kept beside the comparisons because a duplicate that
/// arrives after its frame is done (a stopped peer's, once it resumes) is compared with
/// nothing: without them a frame that was rescued by backups would look untouched.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Audit {
    /// Duplicates whose pixels matched.
    pub agreed: u32,
    /// Duplicates whose pixels differed (each also reported as [`Fault::Mismatch`]).
    pub disagreed: u32,
    /// Tiles whose missing parts were given again because no live holder was rendering them
    /// (their holders were lost, or every peer was idle); a tile given again twice counts twice.
    pub reissued: u32,
    /// Tiles of overdue peers whose missing parts were copied to idle peers (speculation).
    pub backed_up: u32,
    /// Participants given up on during the frame: lost or silent (not those that left when
    /// asked). A live peer counted here was given up on wrongly.
    pub failed: u32,
}

/// Why the owner gave up on a peer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Failure {
    /// The driver reported the connection lost.
    Lost,
    /// The peer may hold work but sent nothing for `Config::peer_timeout` and at least three
    /// round trips of its link, counted from a round trip after it was last dealt tiles.
    Silent,
    /// The peer said it is leaving ([`Message::Leaving`](crate::wire::Message::Leaving)): what it
    /// held went to others at once, and the tiles in its renderer may still come.
    Left,
}

/// What was wrong with a peer's result.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// A second result of the tile whose pixels differ from the accepted one (from `first`).
    /// Rendering is deterministic, so one of the two peers is broken; the first is kept.
    Mismatch {
        /// The peer whose result was accepted first.
        first: PeerId,
    },
    /// The tile is not part of the frame.
    UnknownTile,
    /// The result's rectangle is not the tile's.
    WrongRect,
    /// The buffers do not fit the rectangle.
    BadBuffers,
}

/// One peer's account of one frame. Times are slot-time: a peer with 4 slots busy for 1 s
/// reports 4 s busy. Frames may overlap, so the counts cover the time since the peer's previous
/// report (or since its first `Assign` after a time without frames) up to the frame's
/// `FrameDone`: a peer's reports add up to its whole run, each moment counted once.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PeerStats {
    /// Tiles the peer renders at once (its rendering threads), the factor of every slot-time.
    pub slots: u32,
    /// From the peer's previous report (or first `Assign`) to the frame's `FrameDone`.
    pub wall: Duration,
    /// Slot-time spent rendering.
    pub busy: Duration,
    /// Slot-time not rendering: `wall * slots - busy`.
    pub idle: Duration,
    /// Tiles and pieces the peer rendered, stolen or not.
    pub tiles_rendered: u32,
    /// Tiles received in steal grants.
    pub tiles_stolen: u32,
    /// Tiles given away in steal grants.
    pub tiles_given: u32,
    /// Steal requests the peer sent as a thief.
    pub steal_requests_sent: u32,
    /// Of the requests sent: refused, or unanswered in time.
    pub steal_requests_refused: u32,
    /// Steal requests the peer answered as a victim.
    pub steal_requests_received: u32,
    /// Protocol messages the core sent, of any kind.
    pub messages_sent: u64,
    /// Protocol messages the core received, of any kind.
    pub messages_received: u64,
    /// Reported by the driver, which sees the bytes (see `Core::record_bytes`).
    pub bytes_sent: u64,
    /// Reported by the driver, like `bytes_sent`.
    pub bytes_received: u64,
}

/// A message the core cannot accept. The driver should close the connection it came on.
#[derive(Debug, thiserror::Error)]
pub enum ProtocolError {
    /// A message the driver should have handled itself (handshake, scene, goodbye) reached the
    /// core.
    #[error("{kind} belongs to the connection's driver, not the scheduling core")]
    NotForCore {
        /// The message's kind.
        kind: &'static str,
    },
    /// A message only a frame's owner may receive came for a frame this peer does not own.
    #[error("{kind} for {frame}, which this peer does not own")]
    NotOwner {
        /// The message's kind.
        kind: &'static str,
        /// The frame it named.
        frame: FrameId,
    },
}

/// Why the owner could not start a frame.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// Frames are started in increasing order; this one is not.
    #[error("{frame} is not newer than {newest}, which this peer has already seen")]
    NotNewer {
        /// The frame asked for.
        frame: FrameId,
        /// The newest frame already started.
        newest: FrameId,
    },
    /// The deal names a peer this core has no connection to.
    #[error("{0} is not connected")]
    UnknownPeer(PeerId),
    /// The deal gives one tile id twice.
    #[error("{0} is assigned twice")]
    DuplicateTile(TileId),
    /// A tile with an empty rectangle or a predicted cost that is not finite and non-negative.
    #[error("{0} has an invalid rectangle or predicted cost")]
    InvalidTile(TileId),
    /// The deal has no tiles, so the frame could never complete.
    #[error("a frame needs at least one tile")]
    NoTiles,
}
