//! Validating a tiling: [`check_partition`], for tests, the simulator and anyone who receives
//! tiles from elsewhere.
//!
//! Exact cover is checked without touching pixels: every tile non-empty and inside the image,
//! no two tiles overlapping, and the tile areas adding up to the image's area. Together these
//! leave no pixel uncovered. Overlap is found by a sweep over x: at each column boundary the
//! tiles that end are removed from, and the tiles that start are inserted into, an ordered map
//! of the row spans currently crossed; a new span overlaps a live tile exactly when it overlaps
//! its neighbour above or below in the map. That is O(n log n) for n tiles, whatever the image
//! size: 16k tiles over a 4k image take milliseconds.

use std::collections::BTreeMap;

use crate::Rect;

/// Why a list of tiles is not a valid partition of an image. Tile numbers are indices into the
/// list given to [`check_partition`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PartitionError {
    /// A tile of zero width or height, which would render nothing and hide a gap.
    #[error("tile {index} ({rect:?}) has no pixels")]
    Empty {
        /// The tile's place in the list.
        index: usize,
        /// The empty rectangle.
        rect: Rect,
    },
    /// A tile with pixels beyond the image's right or bottom edge.
    #[error("tile {index} ({rect:?}) reaches outside the {width}x{height} image")]
    OutOfBounds {
        /// The tile's place in the list.
        index: usize,
        /// The offending rectangle.
        rect: Rect,
        /// The image's width in pixels.
        width: u32,
        /// The image's height in pixels.
        height: u32,
    },
    /// A tile more elongated than the halving tree allows, which would make its cost poorly
    /// predicted.
    #[error("tile {index} ({rect:?}) is longer than {max_aspect} times its width plus one pixel")]
    Aspect {
        /// The tile's place in the list.
        index: usize,
        /// The offending rectangle.
        rect: Rect,
        /// The largest ratio of long to short side the check was asked to allow.
        max_aspect: f64,
    },
    /// The list holds a different number of tiles than the caller asked for.
    #[error("{found} tiles where {expected} were expected")]
    Count {
        /// The number of tiles asked for.
        expected: usize,
        /// The number of tiles in the list.
        found: usize,
    },
    /// Two tiles share pixels, which would render them twice.
    #[error("tiles {first} ({first_rect:?}) and {second} ({second_rect:?}) overlap")]
    Overlap {
        /// The place of the earlier tile in the list.
        first: usize,
        /// The earlier tile's rectangle.
        first_rect: Rect,
        /// The place of the later tile in the list.
        second: usize,
        /// The later tile's rectangle.
        second_rect: Rect,
    },
    /// The tiles leave pixels of the image uncovered.
    #[error("the tiles cover {covered} of the image's {total} pixels")]
    Gap {
        /// Pixels the tiles cover.
        covered: u64,
        /// Pixels in the image.
        total: u64,
    },
}

/// Checks that `tiles` cover the `width` x `height` image exactly (no gap, no overlap), that
/// there are `expected_count` of them if given, and that each keeps its longer side within
/// `max_aspect` times its shorter side plus one pixel if given (see [`Rect::within_aspect`]; the
/// PBT's bound is `Some(2.0)`). Reports the first problem found, checking per-tile properties
/// first, then the count, then overlap, then coverage.
pub fn check_partition(
    width: u32,
    height: u32,
    tiles: &[Rect],
    expected_count: Option<usize>,
    max_aspect: Option<f64>,
) -> Result<(), PartitionError> {
    for (index, &rect) in tiles.iter().enumerate() {
        if rect.is_empty() {
            return Err(PartitionError::Empty { index, rect });
        }
        if !rect.inside(width, height) {
            return Err(PartitionError::OutOfBounds {
                index,
                rect,
                width,
                height,
            });
        }
        if let Some(max_aspect) = max_aspect.filter(|&bound| !rect.within_aspect(bound)) {
            return Err(PartitionError::Aspect {
                index,
                rect,
                max_aspect,
            });
        }
    }
    if let Some(expected) = expected_count.filter(|&expected| expected != tiles.len()) {
        return Err(PartitionError::Count {
            expected,
            found: tiles.len(),
        });
    }
    if let Some((first, second)) = first_overlap(tiles) {
        let (first_rect, second_rect) = (tiles[first], tiles[second]);
        return Err(PartitionError::Overlap {
            first,
            first_rect,
            second,
            second_rect,
        });
    }
    let covered: u64 = tiles.iter().map(Rect::area).sum();
    let total = Rect::image(width, height).area();
    if covered != total {
        return Err(PartitionError::Gap { covered, total });
    }
    Ok(())
}

/// Some pair of overlapping tiles (all non-empty and inside the image), by the sweep of the
/// module docs.
fn first_overlap(tiles: &[Rect]) -> Option<(usize, usize)> {
    // (x, starts, tile): at equal x, tiles that end (false) leave before tiles that start.
    let mut events: Vec<(u32, bool, usize)> = Vec::with_capacity(2 * tiles.len());
    for (index, rect) in tiles.iter().enumerate() {
        events.push((rect.x, true, index));
        events.push((rect.x + rect.w, false, index));
    }
    events.sort_unstable();
    // Live row spans crossed at the sweep position: top row -> (bottom row, tile).
    let mut live: BTreeMap<u32, (u32, usize)> = BTreeMap::new();
    for (_, starts, index) in events {
        let rect = tiles[index];
        let (top, bottom) = (rect.y, rect.y + rect.h);
        if !starts {
            live.remove(&top);
            continue;
        }
        if let Some((_, &(above_bottom, above))) = live.range(..=top).next_back()
            && above_bottom > top
        {
            return Some((above.min(index), above.max(index)));
        }
        if let Some((&below_top, &(_, below))) = live.range(top..).next()
            && below_top < bottom
        {
            return Some((below.min(index), below.max(index)));
        }
        live.insert(top, (bottom, index));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quadrants() -> Vec<Rect> {
        vec![
            Rect::new(0, 0, 2, 2),
            Rect::new(2, 0, 2, 2),
            Rect::new(0, 2, 2, 2),
            Rect::new(2, 2, 2, 2),
        ]
    }

    #[test]
    fn accepts_an_exact_cover() {
        assert_eq!(
            check_partition(4, 4, &quadrants(), Some(4), Some(2.0)),
            Ok(())
        );
        assert_eq!(
            check_partition(1, 1, &[Rect::new(0, 0, 1, 1)], Some(1), Some(2.0)),
            Ok(())
        );
    }

    #[test]
    fn reports_overlap_even_when_areas_add_up() {
        // The first tile grows into the second's place; the fourth shrinks to keep the area.
        let mut tiles = quadrants();
        tiles[0] = Rect::new(0, 0, 3, 2);
        tiles[3] = Rect::new(3, 2, 1, 2);
        assert_eq!(
            check_partition(4, 4, &tiles, None, None),
            Err(PartitionError::Overlap {
                first: 0,
                first_rect: tiles[0],
                second: 1,
                second_rect: tiles[1]
            })
        );
        // A tile nested inside another.
        let nested = [Rect::new(0, 0, 4, 4), Rect::new(1, 1, 1, 1)];
        assert!(matches!(
            check_partition(4, 4, &nested, None, None),
            Err(PartitionError::Overlap { .. })
        ));
    }

    #[test]
    fn reports_gaps_bounds_counts_and_aspect() {
        let mut tiles = quadrants();
        tiles[3] = Rect::new(2, 2, 1, 2);
        assert_eq!(
            check_partition(4, 4, &tiles, None, None),
            Err(PartitionError::Gap {
                covered: 14,
                total: 16
            })
        );
        let out = [Rect::new(0, 0, 5, 4)];
        assert!(matches!(
            check_partition(4, 4, &out, None, None),
            Err(PartitionError::OutOfBounds { index: 0, .. })
        ));
        let empty = [Rect::new(0, 0, 0, 4)];
        assert!(matches!(
            check_partition(4, 4, &empty, None, None),
            Err(PartitionError::Empty { .. })
        ));
        assert_eq!(
            check_partition(4, 4, &quadrants(), Some(5), None),
            Err(PartitionError::Count {
                expected: 5,
                found: 4
            })
        );
        let strips = [Rect::new(0, 0, 1, 4), Rect::new(1, 0, 3, 4)];
        assert!(matches!(
            check_partition(4, 4, &strips, None, Some(2.0)),
            Err(PartitionError::Aspect { index: 0, .. })
        ));
        assert_eq!(check_partition(4, 4, &strips, None, Some(3.0)), Ok(()));
    }
}
