//! The byte encoding of [`Message`] and its bounded decoder: the limits a decoded message must
//! keep, the errors it reports, and the checks behind them.
//!
//! One unit because this is where a broken or hostile peer meets us: everything here is a pure
//! function of its input, and every check the decoder makes is here too, so what a message may
//! contain is stated in one file (the scheduling core reuses a few of the checks for tiles that
//! did not come through the decoder).

use balancer::Rect;

use super::{
    BYTES_PER_PIXEL, COST_HEADER_BYTES, FrameId, MAX_COST_BYTES_PER_PIXEL, MAX_FRAMES_IN_FLIGHT,
    Message, PROTOCOL_VERSION, Piece, TileId, TileResult, TileSpec, cost_map_bytes,
};

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
