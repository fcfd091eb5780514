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

use std::fmt;

use balancer::Rect;
use serde::{Deserialize, Serialize};

use crate::peer::PeerStats;

#[cfg(test)]
mod tests;

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
/// distribution, orderly close); the rest are the scheduling core's (see `core/README.md`).
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

/// A peer, numbered by whoever sets up the cluster.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct PeerId(pub u32);

/// A tile, unique within its frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct TileId(pub u32);

/// A frame of an animation; frames are numbered upwards and never reused. A `u32`, as the
/// tracer, the scene's frame count and every file number frames: one integer end to end, so
/// no driver converts (protocol version 5; 4 carried a `u64`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct FrameId(pub u32);

macro_rules! display_id {
    ($($ty:ident => $prefix:literal),*) => {$(
        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, concat!($prefix, "{}"), self.0)
            }
        }
    )*};
}
display_id!(PeerId => "peer ", TileId => "tile ", FrameId => "frame ", Piece => "piece ");

/// Which part of its tile a piece is: a node of the tile's halving tree, numbered as in a
/// binary heap. [`Piece::WHOLE`] (1) is the tile itself; node `n`'s halves are `2n` and
/// `2n + 1`, cut as [`Rect::halves`] cuts (across the longer side, the first half the left or
/// top one). Because the cut is a pure function of the rectangle, a piece's number and its
/// tile's rectangle determine its rectangle, and any two peers that split the same tile agree
/// on what every piece is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Piece(pub u64);

impl Piece {
    /// The whole tile.
    pub const WHOLE: Piece = Piece(1);
    /// The deepest piece the decoder accepts: a tile halved this many times is far below one
    /// pixel for any tile the limits allow, so no honest peer gets near it.
    pub const MAX_DEPTH: u32 = 48;

    /// How many halvings from the whole tile; `None` for the invalid number 0.
    pub fn depth(self) -> Option<u32> {
        (self.0 != 0).then(|| 63 - self.0.leading_zeros())
    }

    /// The two halves of this piece.
    pub fn halves(self) -> (Piece, Piece) {
        (Piece(self.0 << 1), Piece((self.0 << 1) | 1))
    }

    /// Whether `self` is `ancestor` or lies inside it.
    pub fn is_within(self, ancestor: Piece) -> bool {
        match (self.depth(), ancestor.depth()) {
            (Some(mine), Some(theirs)) if mine >= theirs => self.0 >> (mine - theirs) == ancestor.0,
            _ => false,
        }
    }

    /// This piece's rectangle within a tile of rectangle `tile`; `None` if the piece number is
    /// invalid or the tile cannot be halved that often.
    pub fn rect(self, tile: Rect) -> Option<Rect> {
        let depth = self.depth()?;
        let mut rect = tile;
        for level in (0..depth).rev() {
            let (first, second) = rect.halves()?;
            rect = if (self.0 >> level) & 1 == 0 {
                first
            } else {
                second
            };
        }
        Some(rect)
    }
}

/// Work to render: a leaf of the partition, or a piece of one, with the predictor's cost
/// estimate (in the predictor's units; only ratios between estimates matter to the core).
/// `rect` is the piece's own rectangle; `id` names the partition's tile it belongs to. Why a type
/// of its own: it is a `balancer::Tile` named for the wire (id, and which piece), the unit every
/// queue, steal and re-issue moves.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileSpec {
    /// The tile's id in its frame.
    pub id: TileId,
    /// Which part of the tile this is: the whole, or a node of its halving tree.
    pub piece: Piece,
    /// The pixels of this tile or piece.
    pub rect: Rect,
    /// Its share of the tile's predicted cost (see [`predicted_share`]).
    pub predicted: f64,
}

impl TileSpec {
    /// A whole tile of the partition.
    pub fn whole(id: TileId, rect: Rect, predicted: f64) -> Self {
        Self {
            id,
            piece: Piece::WHOLE,
            rect,
            predicted,
        }
    }

    /// Its two halves, each predicted in proportion to its area; `None` for a single pixel.
    pub fn halves(&self) -> Option<(TileSpec, TileSpec)> {
        let (first_rect, second_rect) = self.rect.halves()?;
        let (first_piece, second_piece) = self.piece.halves();
        let first_cost = predicted_share(self.predicted, self.rect, first_rect);
        let first = TileSpec {
            id: self.id,
            piece: first_piece,
            rect: first_rect,
            predicted: first_cost,
        };
        let second = TileSpec {
            id: self.id,
            piece: second_piece,
            rect: second_rect,
            predicted: (self.predicted - first_cost).max(0.0),
        };
        Some((first, second))
    }
}

/// The part of a tile's `predicted` cost a piece of rectangle `part` carries: its share of the
/// tile's area. The one rule by which a prediction is shared out, wherever a tile is cut.
pub fn predicted_share(predicted: f64, whole: Rect, part: Rect) -> f64 {
    predicted * (part.area() as f64 / whole.area() as f64)
}

/// A rendered tile: its pixels (see [`BYTES_PER_PIXEL`]) and its measured block cost map, both
/// opaque to the scheduling core. Why a type of its own: it is a tracer's `TileOutput` as bytes
/// on the wire, which the core routes and compares without decoding.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileResult {
    /// The frame the tile belongs to.
    pub frame: FrameId,
    /// The tile's id in that frame.
    pub tile: TileId,
    /// Which part of the tile `rect` is.
    pub piece: Piece,
    /// The pixels rendered.
    pub rect: Rect,
    /// The pixels as the tracer encodes them, [`BYTES_PER_PIXEL`] bytes each.
    #[serde(with = "serde_bytes")]
    pub pixels: Vec<u8>,
    /// The measured cost of each block of the rectangle, encoded by the tracer.
    #[serde(with = "serde_bytes")]
    pub costs: Vec<u8>,
}

/// One file of a scene. `name` is a relative path with `/` separators; `hash` is the content
/// hash of `bytes`, computed and checked by the drivers (blake3 by convention).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneFile {
    /// The file's path relative to the scene, with `/` separators.
    pub name: String,
    /// The content hash of `bytes`.
    pub hash: [u8; 32],
    /// The file's contents.
    #[serde(with = "serde_bytes")]
    pub bytes: Vec<u8>,
}

/// The render settings the owner uses, which may differ from the scene file's (command-line
/// overrides): every peer must render with exactly these, or its pixels would differ.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RenderParams {
    /// The image's width in pixels.
    pub width: u32,
    /// The image's height in pixels.
    pub height: u32,
    /// Samples traced per pixel.
    pub samples_per_pixel: u32,
    /// The longest path, if overridden; `None` keeps the scene's.
    pub max_depth: Option<u32>,
    /// The bounce after which paths may end by Russian roulette, if overridden.
    pub russian_roulette_depth: Option<u32>,
    /// The seed of every pixel's sample stream.
    pub seed: u64,
    /// Every light-transport effect forced on (`--effects all`) rather than the scene's set.
    pub all_effects: bool,
}

/// Where a peer listens, as a socket address string (`"10.0.0.7:4433"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PeerAddress {
    /// The peer listening.
    pub peer: PeerId,
    /// Its socket address, as text.
    pub addr: String,
}

/// Bounds on what one decoded message may contain.
#[derive(Clone, Debug, PartialEq)]
pub struct Limits {
    /// Longest encoded message. Scenes travel in one message, so this bounds the scene too.
    pub max_message_bytes: usize,
    /// Most tiles (or tile ids) in one message.
    pub max_tiles_per_message: usize,
    /// Most peers named in one message.
    pub max_peers: usize,
    /// Most files in a scene.
    pub max_scene_files: usize,
    /// Largest scene file.
    pub max_file_bytes: usize,
    /// Longest file name or address, in bytes.
    pub max_name_bytes: usize,
    /// Largest tile, in pixels.
    pub max_tile_pixels: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_message_bytes: 256 << 20,
            max_tiles_per_message: 1 << 16,
            max_peers: 1 << 16,
            max_scene_files: 4096,
            max_file_bytes: 256 << 20,
            max_name_bytes: 1024,
            max_tile_pixels: 1 << 24,
        }
    }
}

/// Why bytes did not decode to an acceptable [`Message`].
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    /// A message longer than the decoder accepts, refused before decoding.
    #[error("message of {len} bytes exceeds the limit of {max}")]
    TooLong {
        /// The message's length in bytes.
        len: usize,
        /// The longest accepted.
        max: usize,
    },
    /// The bytes are not a message postcard can decode.
    #[error("malformed message: {0}")]
    Malformed(#[from] postcard::Error),
    /// Bytes left over after a whole message, which a well-formed sender never leaves.
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
    /// The other side speaks another protocol version.
    #[error("peer speaks protocol version {theirs}, we speak {ours}")]
    VersionMismatch {
        /// The version it speaks.
        theirs: u32,
        /// The version this build speaks.
        ours: u32,
    },
    /// A list or buffer in the message exceeds its bound.
    #[error("{what}: {len} exceeds the limit of {max}")]
    Limit {
        /// What exceeded its bound.
        what: &'static str,
        /// Its length.
        len: u64,
        /// The bound.
        max: u64,
    },
    /// A value in the message breaks a rule of the protocol.
    #[error("invalid {what}")]
    Invalid {
        /// What broke it.
        what: &'static str,
    },
}

/// Encodes a message. Pure; never fails.
pub fn encode(message: &Message) -> Vec<u8> {
    postcard::to_stdvec(message)
        .expect("invariant: every Message field has a known length, so postcard cannot fail")
}

/// The length of [`encode`]'s output, computed by the same encoder without writing it.
pub fn encoded_len(message: &Message) -> usize {
    postcard::serialize_with_flavor(message, postcard::ser_flavors::Size::default())
        .expect("invariant: every Message field has a known length, so postcard cannot fail")
}

/// The length of [`encode`]'s output for a [`TileResult`] covering `rect` with a cost map of
/// `block`-pixel blocks, without building its buffers (the simulator sizes every transfer by
/// it, for tiles of any size): the encoding of the result with empty buffers, plus each
/// buffer's bytes and what its length prefix takes beyond the empty one's byte (postcard writes
/// a length as a varint, seven bits a byte).
pub fn tile_result_len(rect: Rect, block: u32) -> u64 {
    let empty = TileResult {
        frame: FrameId(0),
        tile: TileId(0),
        piece: Piece::WHOLE,
        rect,
        pixels: Vec::new(),
        costs: Vec::new(),
    };
    let base = encoded_len(&Message::TileDone(empty)) as u64;
    let buffer = |n: u64| n + u64::from((64 - (n | 1).leading_zeros()).div_ceil(7)) - 1;
    base + buffer(rect.area() * BYTES_PER_PIXEL) + buffer(cost_map_bytes(rect, block))
}

/// Decodes and validates one message. Pure and total: any input gives a message or an error.
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<Message, WireError> {
    if bytes.len() > limits.max_message_bytes {
        return Err(WireError::TooLong {
            len: bytes.len(),
            max: limits.max_message_bytes,
        });
    }
    check_handshake_version(bytes)?;
    let (message, rest) = postcard::take_from_bytes::<Message>(bytes)?;
    if !rest.is_empty() {
        return Err(WireError::Trailing(rest.len()));
    }
    validate(&message, limits)?;
    Ok(message)
}

/// Reads the version of a `Hello` or `Welcome` before decoding the rest, whose layout may
/// differ in another version.
fn check_handshake_version(bytes: &[u8]) -> Result<(), WireError> {
    // Both are postcard varints: the variant index, then the leading `version` field.
    let Ok(((variant, theirs), _)) = postcard::take_from_bytes::<(u32, u32)>(bytes) else {
        return Ok(());
    };
    if variant <= 1 && theirs != PROTOCOL_VERSION {
        return Err(WireError::VersionMismatch {
            theirs,
            ours: PROTOCOL_VERSION,
        });
    }
    Ok(())
}

fn validate(message: &Message, limits: &Limits) -> Result<(), WireError> {
    match message {
        Message::Hello { .. } | Message::Welcome { .. } | Message::SceneReady => Ok(()),
        Message::Peers { peers } => {
            bound("peers", peers.len(), limits.max_peers)?;
            for entry in peers {
                bound("address length", entry.addr.len(), limits.max_name_bytes)?;
            }
            Ok(())
        }
        Message::Scene { files, .. } => {
            bound("scene files", files.len(), limits.max_scene_files)?;
            for file in files {
                bound("scene file size", file.bytes.len(), limits.max_file_bytes)?;
                bound("file name length", file.name.len(), limits.max_name_bytes)?;
                check_file_name(&file.name)?;
            }
            Ok(())
        }
        Message::Assign { peers, tiles, .. } => {
            bound("peers", peers.len(), limits.max_peers)?;
            check_tiles(tiles, limits)
        }
        Message::StealRequest { remaining, .. } => {
            bound("frames", remaining.len(), MAX_FRAMES_IN_FLIGHT)?;
            remaining.iter().try_for_each(|(_, work)| check_cost(*work))
        }
        Message::StealGrant { tiles, .. } => check_tiles(tiles, limits),
        Message::StealNotice { tiles, .. } => {
            bound("tiles", tiles.len(), limits.max_tiles_per_message)?;
            tiles.iter().try_for_each(|(_, piece)| check_piece(*piece))
        }
        Message::TileDone(result) => check_result(result, limits),
        Message::StealRefuse { .. }
        | Message::Status { .. }
        | Message::FrameDone { .. }
        | Message::FrameStats { .. }
        | Message::Goodbye { .. }
        | Message::Leaving => Ok(()),
    }
}

fn bound(what: &'static str, len: usize, max: usize) -> Result<(), WireError> {
    if len > max {
        return Err(WireError::Limit {
            what,
            len: len as u64,
            max: max as u64,
        });
    }
    Ok(())
}

fn check_tiles(tiles: &[TileSpec], limits: &Limits) -> Result<(), WireError> {
    bound("tiles", tiles.len(), limits.max_tiles_per_message)?;
    for tile in tiles {
        check_rect(tile.rect, limits)?;
        check_cost(tile.predicted)?;
        check_piece(tile.piece)?;
    }
    Ok(())
}

/// A piece number is a node of a halving tree no deeper than [`Piece::MAX_DEPTH`].
pub(crate) fn check_piece(piece: Piece) -> Result<(), WireError> {
    match piece.depth() {
        Some(depth) if depth <= Piece::MAX_DEPTH => Ok(()),
        _ => Err(WireError::Invalid { what: "piece" }),
    }
}

/// A predicted cost is a finite, non-negative number: anything else would poison the steal
/// arithmetic.
pub(crate) fn check_cost(cost: f64) -> Result<(), WireError> {
    if cost.is_finite() && cost >= 0.0 {
        Ok(())
    } else {
        Err(WireError::Invalid {
            what: "predicted cost",
        })
    }
}

/// A tile is non-empty, within `u32` coordinates and no larger than the limit.
pub(crate) fn check_rect(rect: Rect, limits: &Limits) -> Result<(), WireError> {
    let inside = rect.x.checked_add(rect.w).is_some() && rect.y.checked_add(rect.h).is_some();
    if rect.w == 0 || rect.h == 0 || !inside {
        return Err(WireError::Invalid {
            what: "tile rectangle",
        });
    }
    if rect.area() > limits.max_tile_pixels {
        return Err(WireError::Limit {
            what: "tile pixels",
            len: rect.area(),
            max: limits.max_tile_pixels,
        });
    }
    Ok(())
}

/// A result's buffers must fit its rectangle: exactly [`BYTES_PER_PIXEL`] bytes per pixel, and
/// at most [`MAX_COST_BYTES_PER_PIXEL`] bytes of cost map per pixel plus [`COST_HEADER_BYTES`].
pub(crate) fn check_result(result: &TileResult, limits: &Limits) -> Result<(), WireError> {
    check_rect(result.rect, limits)?;
    check_piece(result.piece)?;
    check_buffers(result)
}

/// The buffer half of [`check_result`], for results that did not come through [`decode`].
pub(crate) fn check_buffers(result: &TileResult) -> Result<(), WireError> {
    let area = result.rect.area();
    if result.pixels.len() as u64 != area * BYTES_PER_PIXEL {
        return Err(WireError::Invalid {
            what: "pixel buffer length for the tile's rectangle",
        });
    }
    let max_costs = area * MAX_COST_BYTES_PER_PIXEL + COST_HEADER_BYTES;
    if result.costs.len() as u64 > max_costs {
        return Err(WireError::Limit {
            what: "cost map bytes",
            len: result.costs.len() as u64,
            max: max_costs,
        });
    }
    Ok(())
}

/// A file name must stay inside the directory the receiver unpacks the scene into.
fn check_file_name(name: &str) -> Result<(), WireError> {
    let bad_component = |part: &str| part.is_empty() || part == "." || part == "..";
    let bad = name.is_empty()
        || name.contains(['\0', '\\', ':'])
        || name.starts_with('/')
        || name.split('/').any(bad_component);
    if bad {
        return Err(WireError::Invalid {
            what: "scene file name",
        });
    }
    Ok(())
}
