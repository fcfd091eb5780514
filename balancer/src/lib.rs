//! The Prediction Binary Tree and its baselines: measured costs in, tiles out. Pure: std, serde
//! and thiserror only; never a clock, never I/O, nothing of the tracer or the network.
//!
//! Module map:
//! - [`rect`]: [`Rect`], a rectangle of pixels, and [`Rect::halves`], the one cut every tree
//!   here makes (across the longer side, at the middle; tiles stay within 2:1 up to a pixel).
//! - [`cost`]: [`CostMap`], measured cost per block of pixels over a whole image, with a
//!   summed-area table so that the cost of any pixel rectangle is O(1).
//! - [`pbt`]: [`Pbt`], the Prediction Binary Tree: leaves are tiles, re-cut between frames by
//!   greedy split+merge pairs to minimise the variance of the predicted leaf costs.
//! - [`regular`]: [`Regular`], the baseline: a fixed grid of (nearly) equal tiles.
//! - [`assign`]: dealing an ordered list of tiles into one [`Assignment`] share per peer, either
//!   interleaved or contiguous with balanced predicted cost, or round-robin.
//! - [`motion`]: motion-compensated prediction: the global shift of the cost landscape between
//!   the last two measured frames, and the last one carried on by it to the frame predicted.
//! - [`partition`]: the common surface the runtime and the simulator use: [`Partitioner`],
//!   [`Tile`], [`Config`], and the predictor shared by every partition.
//! - [`check`]: [`check_partition`], the O(n log n) validator of a tiling (exact cover, no
//!   overlap, aspect, count), public for tests and the simulator.
//!
//! Everything is deterministic: the same image, config and sequence of observed cost maps give
//! the same tiles in the same order.

pub mod assign;
pub mod check;
pub mod cost;
pub mod motion;
pub mod partition;
pub mod pbt;
pub mod rect;
pub mod regular;

pub use assign::Assignment;
pub use check::{PartitionError, check_partition};
pub use cost::{CostMap, CostMapBuilder};
pub use partition::{Config, Grid, Kind, Order, Partitioner, Tile, Update};
pub use pbt::Pbt;
pub use rect::Rect;
pub use regular::Regular;

/// What can go wrong building a cost map, a partition or an assignment. (A tiling that fails
/// [`check_partition`] is a [`PartitionError`] instead: that is a verdict, not a failure.)
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// The image to partition has zero width or height.
    #[error("a {width}x{height} image has no pixels to partition")]
    EmptyImage {
        /// The requested width in pixels.
        width: u32,
        /// The requested height in pixels.
        height: u32,
    },
    /// A cost map was asked for with blocks of zero pixels, which could never cover an image.
    #[error("the block size of a cost map must be at least one pixel")]
    ZeroBlock,
    /// The costs given do not match the number of blocks the map's grid has.
    #[error("{found} block costs given, but the block grid has {expected} blocks")]
    BlockCount {
        /// Blocks in the grid.
        expected: usize,
        /// Costs given.
        found: usize,
    },
    /// A measured cost is NaN, infinite or negative, which no prediction could use.
    #[error("cost {value} for pixels {rect:?}: costs must be finite and non-negative")]
    InvalidCost {
        /// The cost given.
        value: f64,
        /// The pixels it was given for.
        rect: Rect,
    },
    /// A tile's predicted cost is NaN, infinite or negative, so it cannot be dealt fairly.
    #[error("predicted cost {value} of tile {index}: costs must be finite and non-negative")]
    InvalidTileCost {
        /// The tile's index in the partition.
        index: usize,
        /// The predicted cost.
        value: f64,
    },
    /// The sum of all costs is not a finite f64, so summed-area tables would be meaningless.
    #[error("the costs add up to more than the largest finite f64")]
    Overflow,
    /// A rectangle asked about reaches beyond the image.
    #[error("{rect:?} lies outside the {width}x{height} image")]
    OutOfBounds {
        /// The rectangle asked about.
        rect: Rect,
        /// The image's width in pixels.
        width: u32,
        /// The image's height in pixels.
        height: u32,
    },
    /// A cost map measured for one image size was given to a partition of another.
    #[error("the cost map covers {found:?} pixels but the partition covers {expected:?}")]
    MapSize {
        /// The partition's image size, width by height.
        expected: (u32, u32),
        /// The cost map's image size, width by height.
        found: (u32, u32),
    },
    /// A configuration value outside its range; the text names the field and the rule.
    #[error("invalid config: {0}")]
    Config(&'static str),
    /// Tiles were to be dealt among no peers at all.
    #[error("cannot assign tiles to zero peers")]
    NoPeers,
    /// Peer weights that cannot share out work (not one per peer, negative or not finite, or
    /// summing to zero); the text says which.
    #[error("invalid peer weights: {0}")]
    Weights(&'static str),
}
