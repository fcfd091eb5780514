//! The baseline: a fixed grid of tiles, the partition every adaptive scheme must beat.
//!
//! The grid never changes; observing a frame only updates each tile's predicted cost (with the
//! same predictor as the PBT), which the contiguous assignment uses. With [`Order::RoundRobin`]
//! predictions are not used at all: the classic static interleaving.

use crate::partition::{Predictor, deal};
use crate::{Assignment, Config, CostMap, Error, Grid, Order, Partitioner, Rect, Tile, Update};

/// A regular grid of tiles in row-major order.
#[derive(Clone, Debug)]
pub struct Regular {
    width: u32,
    height: u32,
    pub(crate) order: Order,
    rects: Vec<Rect>,
    predicted: Vec<f64>,
    predictor: Predictor,
}

impl Regular {
    /// The grid `config.grid` over a `width` x `height` image, predicting with
    /// `config.smoothing` and dealing tiles in `config.order`.
    pub fn new(width: u32, height: u32, config: &Config) -> Result<Self, Error> {
        if width == 0 || height == 0 {
            return Err(Error::EmptyImage { width, height });
        }
        let config = Config {
            kind: crate::Kind::Regular,
            ..config.clone()
        };
        config.validate()?;
        let (xs, ys) = match config.grid {
            Grid::Count { columns, rows } => {
                if columns > width || rows > height {
                    return Err(Error::Config(
                        "a grid cannot have more columns or rows than pixels",
                    ));
                }
                (even_cuts(width, columns), even_cuts(height, rows))
            }
            Grid::Size {
                width: tile_width,
                height: tile_height,
            } => (
                sized_cuts(width, tile_width),
                sized_cuts(height, tile_height),
            ),
        };
        let rects: Vec<Rect> = ys
            .windows(2)
            .flat_map(|y| {
                xs.windows(2)
                    .map(move |x| Rect::new(x[0], y[0], x[1] - x[0], y[1] - y[0]))
            })
            .collect();
        let predictor = Predictor::new(width, height, &config);
        let predicted = rects.iter().map(|&rect| predictor.estimate(rect)).collect();
        Ok(Regular {
            width,
            height,
            order: config.order,
            rects,
            predicted,
            predictor,
        })
    }

    /// `columns` x `rows` tiles whose sides differ by at most a pixel, dealt in contiguous runs.
    pub fn grid(width: u32, height: u32, columns: u32, rows: u32) -> Result<Self, Error> {
        let grid = Grid::Count { columns, rows };
        Regular::new(
            width,
            height,
            &Config {
                grid,
                ..Config::default()
            },
        )
    }

    /// Tiles of `tile_width` x `tile_height` pixels from the top-left corner (partial at the
    /// right and bottom edges), dealt in contiguous runs.
    pub fn tile_size(
        width: u32,
        height: u32,
        tile_width: u32,
        tile_height: u32,
    ) -> Result<Self, Error> {
        let grid = Grid::Size {
            width: tile_width,
            height: tile_height,
        };
        Regular::new(
            width,
            height,
            &Config {
                grid,
                ..Config::default()
            },
        )
    }

    /// The same grid, dealt in `order`.
    pub fn with_order(self, order: Order) -> Self {
        Regular { order, ..self }
    }

    /// The width in pixels of the image the grid covers.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// The height in pixels of the image the grid covers.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The tiles, row-major, with their predicted costs.
    pub fn tiles(&self) -> Vec<Tile> {
        let tiles = self.rects.iter().zip(&self.predicted);
        tiles
            .map(|(&rect, &predicted)| Tile { rect, predicted })
            .collect()
    }

    /// Takes the measured costs of the frame just rendered: new predictions, same grid.
    pub fn observe(&mut self, map: &CostMap) -> Result<Update, Error> {
        self.observe_ahead(map, 1)
    }

    /// Aims the prediction at `ahead` frames after the last measured one (see
    /// [`crate::Partitioner::aim`]).
    pub fn aim(&mut self, ahead: u32) -> Result<Update, Error> {
        if self.predictor.aim(ahead)? {
            for (predicted, &rect) in self.predicted.iter_mut().zip(&self.rects) {
                *predicted = self.predictor.estimate(rect);
            }
        }
        Ok(Update::default())
    }

    /// The motion of the cost landscape found at the last observation, if any was.
    pub fn motion(&self) -> Option<crate::motion::Motion> {
        self.predictor.motion()
    }

    /// As [`Self::observe`], predicting for `ahead` frames after the measured one (see
    /// [`crate::Partitioner::observe_ahead`]).
    pub fn observe_ahead(&mut self, map: &CostMap, ahead: u32) -> Result<Update, Error> {
        self.predictor.observe(map, ahead)?;
        for (predicted, &rect) in self.predicted.iter_mut().zip(&self.rects) {
            *predicted = self.predictor.estimate(rect);
        }
        Ok(Update::default())
    }

    /// Deals the tiles to `peers` peers, optionally weighted by peer speed.
    pub fn assign(&self, peers: usize, weights: Option<&[f64]>) -> Result<Assignment, Error> {
        deal(self.predicted.iter().copied(), self.order, peers, weights)
    }
}

impl From<Regular> for Partitioner {
    fn from(regular: Regular) -> Self {
        Partitioner::Regular(regular)
    }
}

/// `parts + 1` cut positions `floor(extent * i / parts)`: `parts` spans of `floor` or `ceil` of
/// `extent / parts` pixels.
fn even_cuts(extent: u32, parts: u32) -> Vec<u32> {
    (0..=parts)
        .map(|i| (u64::from(extent) * u64::from(i) / u64::from(parts)) as u32)
        .collect()
}

/// Cut positions every `size` pixels, the last span partial.
fn sized_cuts(extent: u32, size: u32) -> Vec<u32> {
    let mut cuts: Vec<u32> = (0..extent.div_ceil(size)).map(|i| i * size).collect();
    cuts.push(extent);
    cuts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check_partition;

    fn rects(regular: &Regular) -> Vec<Rect> {
        regular.tiles().iter().map(|tile| tile.rect).collect()
    }

    #[test]
    fn counted_grid_spreads_the_remainder() {
        // 10 = 3 + 3 + 4 (cuts at floor(10 i / 3) = 0, 3, 6, 10); 5 = 2 + 3.
        let regular = Regular::grid(10, 5, 3, 2).unwrap();
        let expected = vec![
            Rect::new(0, 0, 3, 2),
            Rect::new(3, 0, 3, 2),
            Rect::new(6, 0, 4, 2),
            Rect::new(0, 2, 3, 3),
            Rect::new(3, 2, 3, 3),
            Rect::new(6, 2, 4, 3),
        ];
        assert_eq!(rects(&regular), expected);
        let predicted: Vec<f64> = regular.tiles().iter().map(|tile| tile.predicted).collect();
        assert_eq!(predicted, vec![6.0, 6.0, 8.0, 9.0, 9.0, 12.0]);
    }

    #[test]
    fn sized_grid_has_partial_edge_tiles() {
        let regular = Regular::tile_size(10, 5, 4, 4).unwrap();
        let widths: Vec<(u32, u32)> = rects(&regular).iter().map(|r| (r.w, r.h)).collect();
        assert_eq!(widths, vec![(4, 4), (4, 4), (2, 4), (4, 1), (4, 1), (2, 1)]);
        assert_eq!(
            check_partition(10, 5, &rects(&regular), Some(6), None),
            Ok(())
        );
    }

    #[test]
    fn observing_changes_predictions_not_tiles() {
        let mut regular = Regular::grid(8, 8, 2, 2).unwrap();
        let before = rects(&regular);
        let map = CostMap::from_fn(8, 8, 4, |c, r| f64::from(c + 2 * r)).unwrap();
        assert_eq!(regular.observe(&map).unwrap(), Update::default());
        assert_eq!(rects(&regular), before);
        let predicted: Vec<f64> = regular.tiles().iter().map(|tile| tile.predicted).collect();
        assert_eq!(predicted, vec![0.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn the_three_deals_differ() {
        let mut regular = Regular::grid(8, 8, 4, 1).unwrap();
        // Columns of cost 3, 1, 1, 1 (before any measurement every tile costs its area).
        let map = CostMap::from_fn(8, 8, 2, |c, _| if c == 0 { 3.0 } else { 1.0 }).unwrap();
        regular.observe(&map).unwrap();
        let contiguous = regular.clone().with_order(Order::Contiguous);
        assert_eq!(
            contiguous.assign(2, None).unwrap().runs,
            vec![vec![0], vec![1, 2, 3]]
        );
        let round_robin = regular.clone().with_order(Order::RoundRobin);
        assert_eq!(
            round_robin.assign(2, None).unwrap().runs,
            vec![vec![0, 2], vec![1, 3]]
        );
        // Each tile to the less loaded peer: 0 to peer 0, then peer 1 until it catches up.
        let interleaved = regular.with_order(Order::Interleaved);
        assert_eq!(
            interleaved.assign(2, None).unwrap().runs,
            vec![vec![0], vec![1, 2, 3]]
        );
    }

    #[test]
    fn impossible_grids_are_errors() {
        assert!(matches!(Regular::grid(4, 4, 5, 1), Err(Error::Config(_))));
        assert!(matches!(Regular::grid(4, 4, 0, 1), Err(Error::Config(_))));
        assert!(matches!(
            Regular::tile_size(4, 4, 0, 1),
            Err(Error::Config(_))
        ));
        assert!(matches!(
            Regular::grid(0, 4, 1, 1),
            Err(Error::EmptyImage { .. })
        ));
    }
}
