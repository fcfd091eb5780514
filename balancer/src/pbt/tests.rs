//! Hand-worked cases of the PBT: every expected value below was computed by hand from the
//! module docs' rules, not by running the code.

use super::*;
use crate::check_partition;

fn config(leaves: usize) -> Config {
    Config {
        leaves,
        ..Config::default()
    }
}

/// An 8x4 image in 1-pixel blocks with the given pixel costs, zero elsewhere.
fn pixels(costs: &[((u32, u32), f64)]) -> CostMap {
    CostMap::from_fn(8, 4, 1, |x, y| {
        costs
            .iter()
            .find(|(at, _)| *at == (x, y))
            .map_or(0.0, |(_, cost)| *cost)
    })
    .unwrap()
}

fn summary(pbt: &Pbt) -> Vec<(Rect, f64)> {
    pbt.tiles()
        .iter()
        .map(|tile| (tile.rect, tile.predicted))
        .collect()
}

#[test]
fn uniform_start_cuts_the_image_evenly() {
    // 8x4 -> two 4x4 -> four 2x4 columns, all of area 8.
    let pbt = Pbt::new(8, 4, &config(4)).unwrap();
    let expected = [0, 2, 4, 6].map(|x| (Rect::new(x, 0, 2, 4), 8.0));
    assert_eq!(summary(&pbt), expected);
}

#[test]
fn one_profitable_pair_then_a_stop() {
    // Columns A, D (children of the left 4x4) and B, C (of the right 4x4). A = 8 with halves
    // top 6 and bottom 2; D = 5, B = 1, C = 3, each concentrated in one pixel.
    let mut pbt = Pbt::new(8, 4, &config(4)).unwrap();
    let map = pixels(&[
        ((0, 0), 3.0),
        ((1, 0), 3.0),
        ((0, 2), 2.0),
        ((2, 0), 5.0),
        ((4, 0), 1.0),
        ((6, 0), 3.0),
    ]);
    let update = pbt.observe(&map).unwrap();
    // Round 1: best split A (6 * 2 = 12); cheapest merge B, C (1 * 3 = 3), not A's parent;
    // 12 > 3, so A splits and B, C merge: sum of squares 64+25+1+9 = 99 -> 36+4+25+16 = 81,
    // down by 18 = 2 * (12 - 3).
    // Round 2: best split A's top (3 * 3 = 9), but the only merge is A itself (6 * 2 = 12),
    // A's top's own parent; the other pairing, split the right 4x4 (1 * 3 = 3) and merge A
    // (12), does not gain either. Stop.
    assert_eq!(
        update,
        Update {
            splits: 1,
            merges: 1,
            capped: false
        }
    );
    assert_eq!(
        summary(&pbt),
        vec![
            (Rect::new(0, 0, 2, 2), 6.0),
            (Rect::new(0, 2, 2, 2), 2.0),
            (Rect::new(2, 0, 2, 4), 5.0),
            (Rect::new(4, 0, 4, 4), 4.0),
        ]
    );
}

#[test]
fn the_cheapest_merge_is_skipped_when_it_is_the_split_leafs_parent() {
    // A = 8 with halves 4 and 4 (gain 16), its sibling D = 0, so the cheapest merge is A, D
    // (8 * 0 = 0): A's own parent. B = 2 with halves 1 and 1 (gain 1), C = 3 in one pixel.
    let mut pbt = Pbt::new(8, 4, &config(4)).unwrap();
    let map = pixels(&[
        ((0, 0), 4.0),
        ((0, 2), 4.0),
        ((4, 0), 1.0),
        ((4, 2), 1.0),
        ((6, 0), 3.0),
    ]);
    let update = pbt.observe(&map).unwrap();
    // Pairings: (split A, next merge B, C at 2 * 3 = 6) gains 16 - 6 = 10; (next split not
    // under A's parent, B at 1, merge A, D at 0) gains 1. Take the first: sum of squares
    // 64+0+4+9 = 77 -> 16+16+0+25 = 57, down by 20 = 2 * 10. Then the best split is the
    // right 4x4 (2 * 3 = 6) against the only merge, A (4 * 4 = 16): stop.
    assert_eq!(
        update,
        Update {
            splits: 1,
            merges: 1,
            capped: false
        }
    );
    assert_eq!(
        summary(&pbt),
        vec![
            (Rect::new(0, 0, 2, 2), 4.0),
            (Rect::new(0, 2, 2, 2), 4.0),
            (Rect::new(2, 0, 2, 4), 0.0),
            (Rect::new(4, 0, 4, 4), 5.0),
        ]
    );
}

#[test]
fn a_wide_image_keeps_its_forced_cuts() {
    // 100x10 breaks 2:1, so does 50x10, so does 25x10; 12x10 and 13x10 keep it: 8 leaves.
    let mut pbt = Pbt::new(100, 10, &config(1)).unwrap();
    let xs: Vec<u32> = pbt.tiles().iter().map(|tile| tile.rect.x).collect();
    assert_eq!(xs, vec![0, 12, 25, 37, 50, 62, 75, 87]);
    pbt.set_leaves(3).unwrap();
    assert_eq!(pbt.leaf_count(), 8);
    pbt.set_leaves(20).unwrap();
    assert_eq!(pbt.leaf_count(), 20);
    let rects: Vec<Rect> = pbt.tiles().iter().map(|tile| tile.rect).collect();
    assert_eq!(
        check_partition(100, 10, &rects, Some(20), Some(2.0)),
        Ok(())
    );
}

#[test]
fn tiny_images_stop_at_single_pixels() {
    let one = Pbt::new(1, 1, &config(50)).unwrap();
    assert_eq!(summary(&one), vec![(Rect::new(0, 0, 1, 1), 1.0)]);
    assert_eq!(Pbt::new(1, 2, &config(5)).unwrap().leaf_count(), 2);
    let nine = Pbt::new(3, 3, &config(100)).unwrap();
    assert!(nine.tiles().iter().all(|tile| tile.rect.area() == 1));
    assert_eq!(nine.leaf_count(), 9);
    // 1x10: 10 -> 5, 5 -> each 5 (over 3) -> 2 and 3: four leaves at least.
    let column = Pbt::new(1, 10, &config(1)).unwrap();
    let heights: Vec<u32> = column.tiles().iter().map(|tile| tile.rect.h).collect();
    assert_eq!(heights, vec![2, 3, 2, 3]);
}

#[test]
fn growing_and_shrinking_keep_a_partition() {
    let mut pbt = Pbt::new(64, 48, &config(16)).unwrap();
    for leaves in [4, 1, 37, 3072, 3073, 5] {
        pbt.set_leaves(leaves).unwrap();
        let rects: Vec<Rect> = pbt.tiles().iter().map(|tile| tile.rect).collect();
        let expected = leaves.min(64 * 48);
        assert_eq!(
            check_partition(64, 48, &rects, Some(expected), Some(2.0)),
            Ok(())
        );
    }
    assert!(pbt.set_leaves(0).is_err());
}

#[test]
fn smoothing_blends_successive_measurements() {
    let smooth = Config {
        smoothing: 0.25,
        ..config(8)
    };
    let mut pbt = Pbt::new(16, 8, &smooth).unwrap();
    let first = CostMap::from_fn(16, 8, 4, |c, _| f64::from(c)).unwrap();
    let second = CostMap::from_fn(16, 8, 4, |_, r| 10.0 * f64::from(r)).unwrap();
    pbt.observe(&first).unwrap();
    // The first measurement is taken as it is: columns 0..3 cost 0+1+2+3 per block row.
    let total = |pbt: &Pbt| pbt.tiles().iter().map(|tile| tile.predicted).sum::<f64>();
    assert_eq!(total(&pbt), 2.0 * 6.0);
    pbt.observe(&second).unwrap();
    // 0.25 * 12 + 0.75 * (4 blocks * 0 + 4 blocks * 10).
    assert_eq!(total(&pbt), 0.25 * 12.0 + 0.75 * 40.0);
}

#[test]
fn a_map_of_another_size_is_refused() {
    let mut pbt = Pbt::new(16, 8, &config(8)).unwrap();
    let map = CostMap::from_fn(8, 16, 4, |_, _| 1.0).unwrap();
    assert_eq!(
        pbt.observe(&map).unwrap_err(),
        Error::MapSize {
            expected: (16, 8),
            found: (8, 16)
        }
    );
    assert_eq!(
        Pbt::new(0, 8, &config(8)).unwrap_err(),
        Error::EmptyImage {
            width: 0,
            height: 8
        }
    );
}

#[test]
fn the_same_inputs_give_the_same_tiles() {
    let maps: Vec<CostMap> = (0..4)
        .map(|frame| {
            CostMap::from_fn(96, 64, 8, |c, r| {
                if (c + frame) % 5 == 0 && r % 3 == 1 {
                    50.0
                } else {
                    1.0
                }
            })
            .unwrap()
        })
        .collect();
    let run = || {
        let mut pbt = Pbt::new(96, 64, &config(40)).unwrap();
        for map in &maps {
            pbt.observe(map).unwrap();
        }
        pbt.tiles()
    };
    assert_eq!(run(), run());
}

#[test]
fn absurd_sizes_are_refused() {
    // A 1 x 2^32-1 strip would need over 2^30 forced leaves of at most 3 pixels.
    assert!(matches!(
        Pbt::new(1, u32::MAX, &config(1)),
        Err(Error::Config(_))
    ));
    assert!(matches!(
        Pbt::new(8, 8, &config(MAX_LEAVES + 1)),
        Err(Error::Config(_))
    ));
    let mut pbt = Pbt::new(8, 8, &config(4)).unwrap();
    assert!(matches!(
        pbt.set_leaves(MAX_LEAVES + 1),
        Err(Error::Config(_))
    ));
    assert_eq!(pbt.leaf_count(), 4);
}
