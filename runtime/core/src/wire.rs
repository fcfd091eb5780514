//! The wire protocol: every message peers exchange, and its byte encoding.
//!
//! Decoding is where a broken or hostile peer meets us, so it is a pure function over a byte slice
//! that a fuzzer can drive: no I/O, no panics, and every length a message claims is checked
//! against [`Limits`] and against the rest of the message (a tile's pixel buffer must hold exactly
//! its rectangle) before the scheduling core sees it.
//!
//! Messages are postcard-encoded: compact and fast, but not self-describing, so both ends must
//! agree on the layout. [`PROTOCOL_VERSION`] in the `Hello`/`Welcome` handshake is that agreement.
//! Those two variants keep their position and their leading `version` field in every future
//! version, so [`decode`] can name a version mismatch instead of reporting garbage. Byte buffers
//! use `serde_bytes`, which postcard copies in one piece instead of element by element.
//!
//! Allocation stays bounded even before validation: [`decode`] refuses input longer than
//! [`Limits::max_message_bytes`], postcard never pre-allocates more elements than there are input
//! bytes left (and serde caps pre-allocation at 1 MiB), and byte buffers are copied from the
//! input, so no claimed length can make us allocate more than a small multiple of the input.
//!
//! The items live in two files beside this one and are re-exported here, so every path is
//! `wire::X`: `wire/types.rs` holds the ids, pieces, tiles and other plain data the messages
//! carry, and `wire/codec.rs` the encoder, the bounded decoder and its checks.

use balancer::Rect;
use serde::{Deserialize, Serialize};

use crate::peer::PeerStats;

mod codec;
mod types;

#[cfg(test)]
mod tests;

pub use codec::{Limits, WireError, decode, encode, encoded_len, tile_result_len};
pub(crate) use codec::{check_buffers, check_cost, check_rect};
pub use types::{
    FrameId, PeerAddress, PeerId, Piece, RenderParams, SceneFile, TileId, TileResult, TileSpec,
    predicted_share,
};

/// The version of this protocol. Bump it on any change to [`Message`]'s layout.
pub const PROTOCOL_VERSION: u32 = 5;

/// The smallest piece worth cutting a tile into, in pixels: one 8x8 block, the unit the tracer
/// measures cost in. Below it a piece's transfer and per-piece overhead cost more than its work.
pub const MIN_PIECE_PIXELS: u64 = 64;

/// The most frames a render may have in flight at once (dealt and not yet measured), and so
/// the most a steal request names.
pub const MAX_FRAMES_IN_FLIGHT: usize = 64;

/// Pixels travel as linear RGB `f32` triples, little-endian: 12 bytes per pixel.
pub const BYTES_PER_PIXEL: u64 = 12;

/// A cost map holds at most one 8-byte value per pixel, plus a small header
/// ([`COST_HEADER_BYTES`]); anything longer is malformed.
pub const MAX_COST_BYTES_PER_PIXEL: u64 = 8;

/// Room for totals (rays, work) ahead of a cost map's per-block values: a 1x1 tile still
/// carries them.
pub const COST_HEADER_BYTES: u64 = 64;

/// A tile's cost map as it travels: its ray count and its counted work, then the work of each
/// block of `block` pixels the tile touches, row by row, every value a little-endian `u64`.
/// Returns its length in bytes. The encoder is the driver's (the tracer's cost type is opaque
/// here); this is the one statement of its size, which the simulator uses to size results.
pub fn cost_map_bytes(rect: Rect, block: u32) -> u64 {
    if rect.w == 0 || rect.h == 0 || block == 0 {
        return 16;
    }
    let across = (rect.x + rect.w - 1) / block - rect.x / block + 1;
    let down = (rect.y + rect.h - 1) / block - rect.y / block + 1;
    16 + 8 * u64::from(across) * u64::from(down)
}

/// One message between two peers.
///
/// `Hello` to `SceneReady` and `Goodbye` belong to the connection's driver (handshake, scene
/// distribution, orderly close); the rest are the scheduling core's (see `peer/README.md`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// First message of the dialing side. Must stay variant 0 with `version` first.
    Hello {
        /// The protocol version the sender speaks ([`PROTOCOL_VERSION`]).
        version: u32,
        /// The id the sender claims, checked against its certificate by the driver.
        peer: PeerId,
        /// How many tiles the sender renders at once.
        slots: u32,
    },
    /// Reply to `Hello`. Must stay variant 1 with `version` first.
    Welcome {
        /// The protocol version the replier speaks.
        version: u32,
        /// The replier's own id, which the dialler checks is the peer it meant to reach.
        peer: PeerId,
    },
    /// Where the other peers listen, so that peers can steal from each other directly.
    Peers {
        /// Every member's listening address.
        peers: Vec<PeerAddress>,
    },
    /// The scene's files; the receiver checks each file's hash before loading it.
    Scene {
        /// Every file the scene needs, with its hash.
        files: Vec<SceneFile>,
        /// The settings every peer renders with.
        params: RenderParams,
    },
    /// The receiver has loaded the scene and can take tiles.
    SceneReady,
    /// The owner gives tiles of `frame` to the receiver (its initial set, or re-issued tiles).
    /// `peers` are the frame's live participants: the receiver steals only from them.
    /// `render_pixels` is the largest piece the receiver hands its renderer at once: larger
    /// tiles are rendered half by half, so that what is not yet rendered can still be stolen.
    Assign {
        /// The frame dealt.
        frame: FrameId,
        /// Every participant of the frame, whom the receiver may steal from.
        peers: Vec<PeerId>,
        /// The receiver's initial tiles.
        tiles: Vec<TileSpec>,
        /// The largest piece, in pixels, the receiver renders at once.
        render_pixels: u64,
    },
    /// A thief asks for work of frames up to `frame`, the newest it works on; `remaining` is
    /// the predicted work it still holds of each frame it works on, oldest first (at most
    /// [`MAX_FRAMES_IN_FLIGHT`]), so that a victim can even out the oldest frame first.
    StealRequest {
        /// The frame the thief asks for work of.
        frame: FrameId,
        /// The thief's remaining predicted work per frame, oldest first.
        remaining: Vec<(FrameId, f64)>,
    },
    /// The victim's answer: tiles from the far end of its queue.
    StealGrant {
        /// The frame the tiles belong to.
        frame: FrameId,
        /// The tiles or pieces given.
        tiles: Vec<TileSpec>,
    },
    /// The victim's answer when giving would not pay for the transfer.
    StealRefuse {
        /// The frame asked about.
        frame: FrameId,
    },
    /// A thief tells the owner which tiles it took from `victim`, so the owner's ledger knows
    /// who holds them. `stolen` counts the grants the thief has received this frame.
    StealNotice {
        /// The frame the tiles belong to.
        frame: FrameId,
        /// The peer the tiles were taken from.
        victim: PeerId,
        /// The tiles or pieces taken.
        tiles: Vec<(TileId, Piece)>,
        /// The grants the thief has received this frame.
        stolen: u32,
    },
    /// A peer's report to the owner: alive, and idle (holding no work of the frame) or not.
    /// `assigned`, `stolen` and `done` count the `Assign`s and grants the peer has received and
    /// the `TileDone`s it has sent this frame, so that the owner, whose messages may arrive in
    /// any order, can tell a current idle report from one overtaken by events.
    Status {
        /// The frame reported on.
        frame: FrameId,
        /// True when the sender has no work of the frame left.
        idle: bool,
        /// Tiles of the frame the sender was assigned.
        assigned: u32,
        /// Steal grants of the frame the sender received.
        stolen: u32,
        /// `TileDone`s of the frame the sender sent.
        done: u32,
    },
    /// A finished tile, sent to the owner by whoever rendered it.
    TileDone(TileResult),
    /// The owner has every tile of `frame`; peers drop what is left of it.
    FrameDone {
        /// The frame complete.
        frame: FrameId,
    },
    /// A peer's statistics for `frame`, sent to the owner after `FrameDone`.
    FrameStats {
        /// The frame the statistics cover up to.
        frame: FrameId,
        /// What the peer counted.
        stats: PeerStats,
    },
    /// The sender is closing the connection.
    Goodbye {
        /// Why it is closing.
        reason: GoodbyeReason,
    },
    /// A peer tells the owner that it is leaving the render (it was asked to stop, as SLURM and
    /// cloud preemption ask, with SIGTERM): it takes no more work, gives away none, and closes
    /// once the tiles in its renderer are rendered and sent. The owner re-issues everything else
    /// it held at once and deals it nothing more.
    Leaving,
}

impl Message {
    /// Whether the message belongs to the connection's driver (handshake, scene distribution,
    /// orderly close) rather than to the scheduling core.
    pub fn is_session(&self) -> bool {
        matches!(
            self,
            Message::Hello { .. }
                | Message::Welcome { .. }
                | Message::Peers { .. }
                | Message::Scene { .. }
                | Message::SceneReady
                | Message::Goodbye { .. }
        )
    }

    /// The variant's name, for errors and logs.
    pub fn kind(&self) -> &'static str {
        match self {
            Message::Hello { .. } => "Hello",
            Message::Welcome { .. } => "Welcome",
            Message::Peers { .. } => "Peers",
            Message::Scene { .. } => "Scene",
            Message::SceneReady => "SceneReady",
            Message::Assign { .. } => "Assign",
            Message::StealRequest { .. } => "StealRequest",
            Message::StealGrant { .. } => "StealGrant",
            Message::StealRefuse { .. } => "StealRefuse",
            Message::StealNotice { .. } => "StealNotice",
            Message::Status { .. } => "Status",
            Message::TileDone(_) => "TileDone",
            Message::FrameDone { .. } => "FrameDone",
            Message::FrameStats { .. } => "FrameStats",
            Message::Goodbye { .. } => "Goodbye",
            Message::Leaving => "Leaving",
        }
    }
}

/// Why a peer closes a connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum GoodbyeReason {
    /// The render is over or the user stopped it.
    Shutdown,
    /// The other side speaks another [`PROTOCOL_VERSION`].
    VersionMismatch,
    /// A scene file did not match its hash or did not load.
    BadScene,
    /// The other side sent a malformed or unexpected message.
    ProtocolViolation,
}
