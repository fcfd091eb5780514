//! The common surface: whichever balancer is configured, the runtime and the simulator see
//! [`Tile`]s with predicted costs, feed back measured [`CostMap`]s, and ask for an
//! [`Assignment`] of tiles to peers.
//!
//! A frame goes: `tiles()` (what to render, in a fixed order) -> `assign(peers, weights)` (who
//! starts with which tiles) -> render, measuring a [`CostMap`] -> `observe(&map)` (new
//! predictions, and for the PBT a re-cut tree) -> next frame.
//!
//! Both balancers predict the same way: a tile's predicted cost is the previous frame's
//! measured cost of its pixels, optionally smoothed over frames ([`Config::smoothing`]); before
//! any measurement it is the tile's area in pixels (a uniform guess: one unit of cost per pixel,
//! which only the ratios between tiles make meaningful).
//!
//! ```
//! use balancer::{Config, CostMap, Partitioner};
//!
//! let (width, height) = (640, 360);
//! let mut partitioner = Partitioner::new(width, height, &Config::default())?;
//! for _frame in 0..3 {
//!     let tiles = partitioner.tiles();
//!     let assignment = partitioner.assign(4, None)?;
//!     assert_eq!(assignment.runs.iter().map(Vec::len).sum::<usize>(), tiles.len());
//!     // Render; each tile reports counted work for its part of every 8x8 block it touches.
//!     let mut measured = CostMap::builder(width, height, 8)?;
//!     for tile in &tiles {
//!         let work = if tile.rect.x < 100 { 50.0 } else { 1.0 } * tile.rect.area() as f64;
//!         measured.add_rect(tile.rect, work)?;
//!     }
//!     partitioner.observe(&measured.build()?)?;
//! }
//! # Ok::<(), balancer::Error>(())
//! ```

use serde::{Deserialize, Serialize};

use crate::assign::{self, Assignment};
use crate::{CostMap, Error, Pbt, Rect, Regular};

/// One tile of the partition, with the cost predicted for the next frame. Why a type of its own:
/// it is all the balancer knows of a tile (no id, no peer, no pixels), so that the balancer stays
/// apart from the wire and the tracer; the director numbers it into a `wire::TileSpec`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tile {
    /// The pixels of the tile.
    pub rect: Rect,
    /// Its cost predicted for the frame being dealt, in the cost map's units.
    pub predicted: f64,
}

/// What an `observe` (or a change of leaf count) did to the partition.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Update {
    /// Leaves split into their two halves.
    pub splits: usize,
    /// Sibling leaf pairs merged into their parent.
    pub merges: usize,
    /// The greedy PBT update stopped at its safety cap on moves rather than at a local optimum
    /// (see [`crate::pbt`]). Never expected; reported so that tests and the simulator can tell.
    pub capped: bool,
}

/// Policy for building and dealing tiles. Every field has a documented default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Which partition to build. Default: [`Kind::Pbt`].
    pub kind: Kind,
    /// PBT target leaf count `m`. Default 256: about 16 tiles each for 16 peers, tiles of
    /// roughly 90x90 pixels at 1920x1080, enough slack for stealing to even out mispredictions.
    /// The tree never has fewer leaves than the cuts a very wide image forces, nor more than
    /// the image has pixels.
    pub leaves: usize,
    /// The regular baseline's grid. Default: 16 x 16 tiles.
    pub grid: Grid,
    /// How tiles are dealt to peers. Default: [`Order::Interleaved`], which the simulator found
    /// the most robust to motion for both balancers (`docs/results.md`).
    pub order: Order,
    /// Exponential smoothing of predictions: the weight the previous prediction keeps, in
    /// `[0, 1)`; a new prediction is `smoothing * old + (1 - smoothing) * measured`, block by
    /// block. Default 0: off, the prediction is the last frame's measurement, which is what
    /// temporal coherence of a moving scene calls for. Raise it for noisy cost measurements.
    /// The first measurement is taken as it is: there is nothing yet to blend it with.
    pub smoothing: f64,
    /// Motion-compensated prediction ([`crate::motion`]): the largest shift of the cost
    /// landscape searched, in blocks per frame, or `None` to predict each tile from where the
    /// costs were. Default 16 blocks (128 pixels a frame at the tracer's 8-pixel blocks): a
    /// camera pan or an object crossing the image is then predicted where it will be, frames
    /// ahead when frames are dealt before the last one is measured. A still scene predicts as
    /// without it (a shift must explain the newer frame clearly better than no motion).
    pub motion: Option<u32>,
}

/// The closed set of balancers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// Adaptive subdivision by a Prediction Binary Tree ([`Pbt`]).
    #[default]
    Pbt,
    /// A fixed grid of nearly equal tiles ([`Regular`]).
    Regular,
}

/// The shape of a regular grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Grid {
    /// `columns x rows` tiles whose sides differ by at most one pixel.
    Count {
        /// Tiles across the image.
        columns: u32,
        /// Tiles down the image.
        rows: u32,
    },
    /// Tiles of `width x height` pixels from the top-left corner, partial at the right and
    /// bottom edges.
    Size {
        /// A tile's width in pixels.
        width: u32,
        /// A tile's height in pixels.
        height: u32,
    },
}

impl Default for Grid {
    fn default() -> Self {
        Grid::Count {
            columns: 16,
            rows: 16,
        }
    }
}

/// How an ordered list of tiles is dealt to peers. Serialised as the command line spells it
/// (`round-robin`), so that every file and flag names a deal one way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Order {
    /// Each peer gets one contiguous run of tiles, runs of nearly equal predicted cost
    /// (weighted by peer speed); spatially coherent for the PBT's depth-first order.
    Contiguous,
    /// Tiles dealt one at a time (smooth weighted round-robin), ignoring predicted cost.
    RoundRobin,
    /// Tiles dealt one at a time, in order, each to the peer with the least predicted work
    /// relative to its speed: every peer's share is spread over the image, so that a change of
    /// cost between frames lands on many peers instead of the few whose run covers it, and the
    /// shares stay balanced in predicted cost. On the PBT's equal-cost leaves it deals them
    /// round-robin.
    #[default]
    Interleaved,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            kind: Kind::Pbt,
            leaves: 256,
            grid: Grid::default(),
            order: Order::Interleaved,
            smoothing: 0.0,
            motion: Some(16),
        }
    }
}

impl Config {
    /// A partition of about `tiles` tiles of either kind: `tiles` PBT leaves, or for the regular
    /// grid the nearest k x k grid (k = round(sqrt(tiles)), at least 1), so that one tile count
    /// means comparable tiles whichever the kind (`--tiles` of `tessera render` and `simulate`).
    pub fn with_tiles(kind: Kind, tiles: usize, order: Order, motion: Option<u32>) -> Config {
        let side = ((tiles as f64).sqrt().round() as u32).max(1);
        Config {
            kind,
            leaves: tiles,
            grid: Grid::Count {
                columns: side,
                rows: side,
            },
            order,
            motion,
            ..Config::default()
        }
    }

    /// Checks the knobs the chosen [`Kind`] reads.
    pub fn validate(&self) -> Result<(), Error> {
        if !(0.0..1.0).contains(&self.smoothing) {
            return Err(Error::Config("smoothing must be in [0, 1)"));
        }
        match self.kind {
            Kind::Pbt if self.leaves == 0 => Err(Error::Config("a PBT needs at least one leaf")),
            Kind::Regular => match self.grid {
                Grid::Count { columns: 0, .. } | Grid::Count { rows: 0, .. } => Err(Error::Config(
                    "a grid needs at least one column and one row",
                )),
                Grid::Size { width: 0, .. } | Grid::Size { height: 0, .. } => {
                    Err(Error::Config("grid tiles need at least one pixel a side"))
                }
                _ => Ok(()),
            },
            Kind::Pbt => Ok(()),
        }
    }
}

/// Any balancer, behind one surface.
#[derive(Clone, Debug)]
pub enum Partitioner {
    /// The Prediction Binary Tree, cutting by predicted cost.
    Pbt(Pbt),
    /// The fixed grid, the baseline the PBT is measured against.
    Regular(Regular),
}

impl Partitioner {
    /// The balancer `config.kind` names, over a `width` x `height` image.
    pub fn new(width: u32, height: u32, config: &Config) -> Result<Self, Error> {
        Ok(match config.kind {
            Kind::Pbt => Partitioner::Pbt(Pbt::new(width, height, config)?),
            Kind::Regular => Partitioner::Regular(Regular::new(width, height, config)?),
        })
    }

    /// The width in pixels of the image being partitioned.
    pub fn width(&self) -> u32 {
        match self {
            Partitioner::Pbt(pbt) => pbt.width(),
            Partitioner::Regular(regular) => regular.width(),
        }
    }

    /// The height in pixels of the image being partitioned.
    pub fn height(&self) -> u32 {
        match self {
            Partitioner::Pbt(pbt) => pbt.height(),
            Partitioner::Regular(regular) => regular.height(),
        }
    }

    /// The tiles, in their fixed order (depth-first for the PBT, row-major for the grid).
    pub fn tiles(&self) -> Vec<Tile> {
        match self {
            Partitioner::Pbt(pbt) => pbt.tiles(),
            Partitioner::Regular(regular) => regular.tiles(),
        }
    }

    /// Takes the measured costs of the frame just rendered: updates predictions for the next
    /// frame, and re-cuts the PBT.
    pub fn observe(&mut self, map: &CostMap) -> Result<Update, Error> {
        self.observe_ahead(map, 1)
    }

    /// Aims the prediction at the frame `ahead` frames after the last measured one, re-cutting
    /// the PBT if that moved it: call before dealing a frame whose distance from the last
    /// measurement differs from the one [`Self::observe_ahead`] assumed. A no-op without motion.
    pub fn aim(&mut self, ahead: u32) -> Result<Update, Error> {
        match self {
            Partitioner::Pbt(pbt) => pbt.aim(ahead),
            Partitioner::Regular(regular) => regular.aim(ahead),
        }
    }

    /// The motion of the cost landscape found at the last observation, if any was.
    pub fn motion(&self) -> Option<crate::motion::Motion> {
        match self {
            Partitioner::Pbt(pbt) => pbt.motion(),
            Partitioner::Regular(regular) => regular.motion(),
        }
    }

    /// As [`Self::observe`], predicting for the frame `ahead` frames after the measured one
    /// (2 when the frame after it was dealt before it was measured): motion is carried on that
    /// far.
    pub fn observe_ahead(&mut self, map: &CostMap, ahead: u32) -> Result<Update, Error> {
        match self {
            Partitioner::Pbt(pbt) => pbt.observe_ahead(map, ahead),
            Partitioner::Regular(regular) => regular.observe_ahead(map, ahead),
        }
    }

    /// How this partitioner deals its tiles.
    pub fn order(&self) -> Order {
        match self {
            Partitioner::Pbt(pbt) => pbt.order,
            Partitioner::Regular(regular) => regular.order,
        }
    }

    /// Deals `tiles` (not necessarily this partitioner's: a checkpoint's) to `peers` peers in
    /// this partitioner's deal order, as [`Self::assign`] deals its own.
    pub fn assign_tiles(
        &self,
        tiles: &[Tile],
        peers: usize,
        weights: Option<&[f64]>,
    ) -> Result<Assignment, Error> {
        deal(
            tiles.iter().map(|tile| tile.predicted),
            self.order(),
            peers,
            weights,
        )
    }

    /// Deals the tiles to `peers` peers, optionally weighted by peer speed (`None`: equal).
    /// Run `p` lists the indices into [`Self::tiles`] that peer `p` starts with.
    pub fn assign(&self, peers: usize, weights: Option<&[f64]>) -> Result<Assignment, Error> {
        match self {
            Partitioner::Pbt(pbt) => pbt.assign(peers, weights),
            Partitioner::Regular(regular) => regular.assign(peers, weights),
        }
    }
}

/// Deals tiles of predicted `costs` by `order`: the one assignment path both balancers share.
pub(crate) fn deal(
    costs: impl Iterator<Item = f64>,
    order: Order,
    peers: usize,
    weights: Option<&[f64]>,
) -> Result<Assignment, Error> {
    assign::assign(&costs.collect::<Vec<f64>>(), order, peers, weights)
}

/// Predicts the cost of any rectangle in a coming frame from the frames observed so far.
#[derive(Clone, Debug)]
pub(crate) struct Predictor {
    width: u32,
    height: u32,
    smoothing: f64,
    /// The largest shift searched for motion, in blocks; `None`: no motion compensation.
    motion: Option<u32>,
    /// The predicted cost map; `None` before the first observation.
    map: Option<CostMap>,
    /// The prediction before the last observation, which smoothing blends the new one with.
    before: Option<CostMap>,
    /// The last measurement as it was: what motion carries on, and what the next measurement
    /// is compared with for motion.
    last: Option<CostMap>,
    /// The motions found between successive measurements, oldest first (the last three; empty
    /// once a measurement showed none).
    history: Vec<crate::motion::Motion>,
    /// How many frames after the last measured one the prediction is for.
    ahead: u32,
}

impl Predictor {
    pub(crate) fn new(width: u32, height: u32, config: &Config) -> Self {
        Predictor {
            width,
            height,
            smoothing: config.smoothing,
            motion: config.motion,
            map: None,
            before: None,
            last: None,
            history: Vec::new(),
            ahead: 1,
        }
    }

    /// Predicted cost of `rect`: the (smoothed, motion-compensated) measured cost, or before any
    /// measurement its area in pixels.
    pub(crate) fn estimate(&self, rect: Rect) -> f64 {
        match &self.map {
            Some(map) => map.cost(rect),
            None => rect.area() as f64,
        }
    }

    /// The motion found between the last two measurements, if any was.
    pub(crate) fn motion(&self) -> Option<crate::motion::Motion> {
        self.history.last().copied()
    }

    /// Folds in one frame's measurement, predicting for `ahead` frames after it. A map in a
    /// different block size than the previous one cannot be blended block by block, so it
    /// replaces the prediction outright.
    pub(crate) fn observe(&mut self, measured: &CostMap, ahead: u32) -> Result<(), Error> {
        if (measured.width(), measured.height()) != (self.width, self.height) {
            return Err(Error::MapSize {
                expected: (self.width, self.height),
                found: (measured.width(), measured.height()),
            });
        }
        let found = match (self.motion, &self.last) {
            (Some(max_shift), Some(last)) => crate::motion::estimate(last, measured, max_shift),
            _ => None,
        };
        match found {
            Some(motion) => {
                if self.history.len() == 3 {
                    self.history.remove(0);
                }
                self.history.push(motion);
            }
            None => self.history.clear(),
        }
        self.before = self.map.take();
        self.last = Some(measured.clone());
        self.predict(ahead.max(1))
    }

    /// Predicts for `ahead` frames after the last measured one instead; whether that changed
    /// the prediction (it does only where motion was found).
    pub(crate) fn aim(&mut self, ahead: u32) -> Result<bool, Error> {
        let ahead = ahead.max(1);
        if ahead == self.ahead || self.history.is_empty() || self.last.is_none() {
            self.ahead = ahead;
            return Ok(false);
        }
        self.predict(ahead)?;
        Ok(true)
    }

    fn predict(&mut self, ahead: u32) -> Result<(), Error> {
        self.ahead = ahead;
        let Some(last) = &self.last else {
            return Ok(());
        };
        let carried = match self.history.is_empty() {
            false => {
                let shift = crate::motion::ahead(&self.history, ahead);
                crate::motion::extrapolate(last, shift)?
            }
            true => last.clone(),
        };
        self.map = Some(match &self.before {
            Some(old) if self.smoothing > 0.0 && old.block() == carried.block() => {
                old.blend(&carried, self.smoothing)
            }
            _ => carried,
        });
        Ok(())
    }
}
