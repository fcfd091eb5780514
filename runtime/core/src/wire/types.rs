//! The plain data messages carry: the ids of peers, tiles and frames, a tile's pieces, work to
//! render and its result, a scene's files and settings, and where a peer listens.
//!
//! They are one unit because they are what the protocol is *about*, apart from how it is framed
//! and checked (`codec.rs`): the scheduling core, the drivers and the simulator all pass these
//! values around, and the few rules they carry (how a piece halves, how a prediction is shared
//! out) must be the same everywhere.

use std::fmt;

use balancer::Rect;
use serde::{Deserialize, Serialize};

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
///
/// [`BYTES_PER_PIXEL`]: super::BYTES_PER_PIXEL
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
    ///
    /// [`BYTES_PER_PIXEL`]: super::BYTES_PER_PIXEL
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
