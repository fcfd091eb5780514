//! The Prediction Binary Tree (PBT): adaptive subdivision of the image into tiles of nearly equal
//! predicted cost, re-cut between frames using the previous frame's measured costs (temporal
//! coherence). The idea is from B. Cosenza, G. Cordasco, R. De Chiara, U. Erra and V. Scarano,
//! *On Estimating the Effectiveness of Temporal and Spatial Coherence in Parallel Ray Tracing*,
//! Eurographics Italian Chapter Conference 2008, pp. 97-104,
//! doi:10.2312/LocalChapterEvents/ItalChap/ItalianChapConf2008/097-104.
//!
//! **The tree.** A full binary tree over the image: the root is the whole image, and each
//! internal node's children are the halves of its rectangle ([`Rect::halves`]: across the longer
//! side, floor first). The leaves partition the image exactly and are the tiles, listed
//! depth-first, which keeps neighbours in the list close on screen. Every leaf keeps
//! `long <= 2 * short + 1` (2:1 up to one pixel of integer rounding; see [`crate::rect`]).
//! An image outside that bound (wider than about 2:1) first gets the *forced* cuts it needs:
//! nodes whose rectangle breaks the bound are always cut and never merged, so the tree never has
//! fewer leaves than those cuts make (a 1x1000 image keeps at least 488 tiles of 1x2 and 1x3).
//! A single pixel cannot be cut, so the tree never has more leaves than pixels. Within those
//! limits it has exactly the configured `m` leaves.
//!
//! **The predictor.** A leaf's estimate for the next frame is the measured cost of its rectangle
//! in the last frame, from the [`CostMap`]'s summed-area table: exact whatever the tree looks
//! like, because the map is per block of pixels and not per tile. Optional exponential smoothing
//! blends successive maps ([`Config::smoothing`]). Before the first measurement, a leaf's
//! estimate is its area.
//!
//! **The objective.** With leaf estimates `e_l`, `m` leaves and total `W = sum e_l`, we minimise
//! the variance `sigma^2 = (1/m) sum (e_l - mu)^2 = (1/m) sum e_l^2 - mu^2`, `mu = W / m`. A
//! move that keeps `m` and `W` fixed therefore changes `sigma^2` only through `sum e_l^2`. The
//! estimate is additive (a rectangle's cost is its halves' costs added), so splitting leaf `a`
//! into `a1 + a2` changes `sum e^2` by `a1^2 + a2^2 - a^2 = -2 a1 a2`, and merging sibling leaves
//! `b, c` changes it by `(b + c)^2 - b^2 - c^2 = +2 bc`. One split plus one merge keeps `m` and
//! lowers the variance exactly when
//!
//! ```text
//! a^2 - a1^2 - a2^2 > 2 bc,   that is   a1 a2 > b c.
//! ```
//!
//! The pair must be disjoint: `{b, c}` may not contain `a` (after the split `a` is no longer a
//! leaf), so the merge may not be `a`'s own parent. Merging `a1, a2` straight back is never
//! chosen, since it would gain nothing.
//!
//! **The greedy update.** Repeatedly take the pair with the largest `a1 a2 - b c`: the split of
//! largest `a1 a2` with the merge of smallest `b c`, or, when that merge is the split leaf's own
//! parent, the better of (that split, the next merge) and (the next split that is not under that
//! parent, that merge); stop when no pair gains. So when it stops, no single split+merge pair
//! lowers the variance. (Keying on the products rather than on the plain estimates, "split the
//! largest, merge the cheapest pair", ranks moves by what they actually gain: a leaf whose cost
//! sits in one half gains nothing from a split however large it is, and a pair `b, c` with
//! `c = 0` costs nothing to merge.) Candidates live in two heaps with lazy deletion by
//! generation counters, so a move is O(log m) (details in the private `greedy` module).
//!
//! **Termination.** Since `sum e^2 = e_root^2 - 2 * sum over internal nodes n of P(n)` with
//! `P(n)` the product of `n`'s halves' estimates, minimising the variance is maximising
//! `sum P(n)` over the internal nodes. Within one update every `P(n)` is a fixed floating-point
//! number (the estimates are pure functions of the rectangles), and a move replaces internal
//! node `q` by `a` only if `P(a) > P(q)`: the sum strictly increases, exactly and not merely up
//! to rounding, so no tree repeats and the loop ends. A cap on moves per update is kept as a
//! safety net against bugs, reported in [`Update::capped`].
//!
//! **Changing m.** [`Pbt::set_leaves`] grows the tree by splitting the leaf of largest
//! `a1 a2` or shrinks it by merging the pair of smallest `b c` (the moves that lower the
//! variance most, or raise it least), then runs the greedy update.
//!
//! **Assignment.** The leaves in depth-first order are cut into contiguous runs, one per peer,
//! of nearly equal predicted cost ([`crate::assign`]).

mod greedy;
mod tree;

use crate::partition::{Predictor, deal};
use crate::{Assignment, Config, CostMap, Error, Rect, Tile, Update};
use crate::{Order, Partitioner};
use tree::Tree;

/// The most leaves a tree may have (and need for its forced cuts): node indices are u32, and a
/// tree this size already takes tens of gigabytes.
pub const MAX_LEAVES: usize = 1 << 30;

/// The Prediction Binary Tree over one image (see the module docs).
#[derive(Clone, Debug)]
pub struct Pbt {
    width: u32,
    height: u32,
    target: usize,
    pub(crate) order: Order,
    tree: Tree,
    predictor: Predictor,
    /// The leaves, depth-first: the tile order.
    leaves: Vec<u32>,
    scratch: greedy::Scratch,
}

impl Pbt {
    /// A tree over a `width` x `height` image with `config.leaves` leaves of area-proportional
    /// estimates, predicting with `config.smoothing`, dealing tiles in `config.order`.
    pub fn new(width: u32, height: u32, config: &Config) -> Result<Self, Error> {
        if width == 0 || height == 0 {
            return Err(Error::EmptyImage { width, height });
        }
        let config = Config {
            kind: crate::Kind::Pbt,
            ..config.clone()
        };
        config.validate()?;
        // Forced leaves keep the short side and are longer than it, so there are fewer of them
        // than long side / short side.
        let elongation = (width.max(height) / width.min(height)) as usize;
        if config.leaves > MAX_LEAVES || elongation > MAX_LEAVES {
            return Err(Error::Config("a PBT can have at most 2^30 leaves"));
        }
        let image = Rect::image(width, height);
        let mut pbt = Pbt {
            width,
            height,
            target: config.leaves,
            order: config.order,
            tree: Tree::new(image),
            predictor: Predictor::new(width, height, &config),
            leaves: Vec::new(),
            scratch: greedy::Scratch::default(),
        };
        pbt.leaves = pbt.tree.leaves();
        pbt.refresh_estimates();
        pbt.restructure();
        Ok(pbt)
    }

    /// The width in pixels of the image the tree covers.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// The height in pixels of the image the tree covers.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The configured leaf count `m`.
    pub fn target_leaves(&self) -> usize {
        self.target
    }

    /// The actual leaf count: `m`, unless forced cuts need more or the image has fewer pixels.
    pub fn leaf_count(&self) -> usize {
        self.leaves.len()
    }

    /// The leaves, depth-first, with their predicted costs.
    pub fn tiles(&self) -> Vec<Tile> {
        let tile = |&leaf: &u32| {
            let node = self.tree.node(leaf);
            Tile {
                rect: node.rect,
                predicted: node.estimate,
            }
        };
        self.leaves.iter().map(tile).collect()
    }

    /// Takes the measured costs of the frame just rendered: every leaf's estimate becomes its
    /// predicted cost, then the tree is re-cut greedily.
    pub fn observe(&mut self, map: &CostMap) -> Result<Update, Error> {
        self.observe_ahead(map, 1)
    }

    /// Aims the prediction at `ahead` frames after the last measured one (see
    /// [`crate::Partitioner::aim`]).
    pub fn aim(&mut self, ahead: u32) -> Result<Update, Error> {
        if !self.predictor.aim(ahead)? {
            return Ok(Update::default());
        }
        self.refresh_estimates();
        Ok(self.restructure())
    }

    /// The motion of the cost landscape found at the last observation, if any was.
    pub fn motion(&self) -> Option<crate::motion::Motion> {
        self.predictor.motion()
    }

    /// As [`Self::observe`], predicting for `ahead` frames after the measured one (see
    /// [`crate::Partitioner::observe_ahead`]).
    pub fn observe_ahead(&mut self, map: &CostMap, ahead: u32) -> Result<Update, Error> {
        self.predictor.observe(map, ahead)?;
        self.refresh_estimates();
        Ok(self.restructure())
    }

    /// Changes the leaf count `m` (grow by splitting, shrink by merging; see the module docs).
    pub fn set_leaves(&mut self, leaves: usize) -> Result<Update, Error> {
        if leaves == 0 || leaves > MAX_LEAVES {
            return Err(Error::Config("a PBT has between 1 and 2^30 leaves"));
        }
        self.target = leaves;
        Ok(self.restructure())
    }

    /// Deals the tiles to `peers` peers (contiguous runs by default), optionally weighted by
    /// peer speed.
    pub fn assign(&self, peers: usize, weights: Option<&[f64]>) -> Result<Assignment, Error> {
        let costs = self
            .leaves
            .iter()
            .map(|&leaf| self.tree.node(leaf).estimate);
        deal(costs, self.order, peers, weights)
    }

    fn refresh_estimates(&mut self) {
        for &leaf in &self.leaves {
            let estimate = self.predictor.estimate(self.tree.node(leaf).rect);
            self.tree.set_estimate(leaf, estimate);
        }
    }

    fn restructure(&mut self) -> Update {
        let update = greedy::restructure(
            &mut self.tree,
            &self.predictor,
            self.target,
            &mut self.scratch,
        );
        self.leaves = self.tree.leaves();
        update
    }
}

impl From<Pbt> for Partitioner {
    fn from(pbt: Pbt) -> Self {
        Partitioner::Pbt(pbt)
    }
}

#[cfg(test)]
mod tests;
