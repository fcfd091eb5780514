//! Hand-worked cost-map queries: every expected value is computed by hand in the comments.

use super::*;

/// A 10x6 image in 4-pixel blocks: block columns 4, 4, 2 wide; block rows 4, 2 tall.
fn hand_map() -> CostMap {
    CostMap::from_blocks(10, 6, 4, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap()
}

#[test]
fn aligned_rectangles_sum_whole_blocks() {
    let map = hand_map();
    assert_eq!((map.columns(), map.rows()), (3, 2));
    assert_eq!(map.total(), 21.0);
    assert_eq!(map.cost(Rect::image(10, 6)), 21.0);
    assert_eq!(map.cost(Rect::new(0, 0, 8, 4)), 1.0 + 2.0);
    // Columns 1..3 of row 1, the last ones partial blocks covered entirely.
    assert_eq!(map.cost(Rect::new(4, 4, 6, 2)), 5.0 + 6.0);
    assert_eq!(map.block_rect(2, 1), Some(Rect::new(8, 4, 2, 2)));
}

#[test]
fn cut_blocks_are_charged_by_area() {
    let map = hand_map();
    // Half of block 0 (2 of its 4 columns) and half of block 1.
    assert_eq!(map.cost(Rect::new(2, 0, 4, 4)), 0.5 * 1.0 + 0.5 * 2.0);
    // Half of the 2-pixel-wide edge block 2.
    assert_eq!(map.cost(Rect::new(8, 0, 1, 4)), 0.5 * 3.0);
    // One pixel of the 2x2 corner block 5.
    assert_eq!(map.cost(Rect::new(9, 5, 1, 1)), 6.0 / 4.0);
    // x 3..9 covers 1/4 of block column 0, all of column 1 and 1/2 of the 2-pixel column 2;
    // y 2..5 covers 2/4 of block row 0 and 1/2 of the 2-pixel row 1.
    let expected = 0.5 * (0.25 * 1.0 + 2.0 + 0.5 * 3.0) + 0.5 * (0.25 * 4.0 + 5.0 + 0.5 * 6.0);
    assert_eq!(map.cost(Rect::new(3, 2, 6, 3)), expected);
}

#[test]
fn the_part_outside_the_image_costs_nothing() {
    let map = hand_map();
    assert_eq!(map.cost(Rect::new(8, 4, 100, 100)), 6.0);
    assert_eq!(map.cost(Rect::new(10, 0, 5, 5)), 0.0);
    assert_eq!(map.cost(Rect::new(0, 0, 0, 5)), 0.0);
}

#[test]
fn small_costs_survive_next_to_huge_ones() {
    // Without double-double prefix sums every rectangle whose corners see the 1e30 block
    // would lose its ones to cancellation.
    let map =
        CostMap::from_fn(16, 16, 1, |c, r| if (c, r) == (7, 7) { 1e30 } else { 1.0 }).unwrap();
    for (x0, x1) in (0..16).flat_map(|a| (a + 1..=16).map(move |b| (a, b))) {
        for (y0, y1) in (0..16).flat_map(|a| (a + 1..=16).map(move |b| (a, b))) {
            let rect = Rect::new(x0, y0, x1 - x0, y1 - y0);
            let ones = rect.area() as f64;
            let expected = if rect.overlaps(&Rect::new(7, 7, 1, 1)) {
                1e30 + (ones - 1.0)
            } else {
                ones
            };
            assert_eq!(map.cost(rect), expected, "{rect:?}");
        }
    }
}

#[test]
fn bad_costs_and_shapes_are_errors() {
    let nan = CostMap::from_blocks(4, 4, 2, vec![0.0, f64::NAN, 0.0, 0.0]);
    assert!(matches!(
        nan,
        Err(Error::InvalidCost {
            rect: Rect { x: 2, y: 0, .. },
            ..
        })
    ));
    let negative = CostMap::from_blocks(4, 4, 2, vec![0.0, 0.0, -1.0, 0.0]);
    assert!(matches!(
        negative,
        Err(Error::InvalidCost { value: -1.0, .. })
    ));
    let infinite = CostMap::from_blocks(4, 4, 2, vec![f64::INFINITY, 0.0, 0.0, 0.0]);
    assert!(matches!(infinite, Err(Error::InvalidCost { .. })));
    assert_eq!(
        CostMap::from_blocks(4, 4, 2, vec![0.0; 3]).unwrap_err(),
        Error::BlockCount {
            expected: 4,
            found: 3
        }
    );
    assert_eq!(CostMap::builder(4, 4, 0).unwrap_err(), Error::ZeroBlock);
    assert_eq!(
        CostMap::builder(0, 4, 2).unwrap_err(),
        Error::EmptyImage {
            width: 0,
            height: 4
        }
    );
    let overflow = CostMap::from_blocks(2, 1, 1, vec![f64::MAX, f64::MAX]);
    assert_eq!(overflow.unwrap_err(), Error::Overflow);
}

#[test]
fn zero_and_huge_costs_are_fine() {
    let zero = CostMap::from_blocks(5, 3, 2, vec![0.0; 6]).unwrap();
    assert_eq!(zero.cost(Rect::new(1, 1, 3, 2)), 0.0);
    let huge = CostMap::from_blocks(4, 4, 2, vec![1e30; 4]).unwrap();
    assert_eq!(huge.total(), 4e30);
    assert_eq!(huge.cost(Rect::new(1, 0, 2, 2)), 1e30);
}

#[test]
fn builder_spreads_a_rectangle_over_the_blocks_it_touches() {
    let mut builder = CostMap::builder(10, 6, 4).unwrap();
    // x 2..6 is half in block column 0 and half in column 1; y 0..4 is block row 0.
    builder.add_rect(Rect::new(2, 0, 4, 4), 8.0).unwrap();
    // Two tiles sharing edge block 5: their shares add up.
    builder.add_rect(Rect::new(8, 4, 1, 2), 3.0).unwrap();
    builder.add_rect(Rect::new(9, 4, 1, 2), 4.0).unwrap();
    builder.add_block(0, 1, 0.5).unwrap();
    let map = builder.build().unwrap();
    let blocks: Vec<_> = (0..2).flat_map(|r| (0..3).map(move |c| (c, r))).collect();
    let costs: Vec<_> = blocks
        .iter()
        .map(|&(c, r)| map.block_cost(c, r).unwrap())
        .collect();
    assert_eq!(costs, vec![4.0, 4.0, 0.0, 0.5, 0.0, 7.0]);
    let mut builder = CostMap::builder(10, 6, 4).unwrap();
    assert!(matches!(
        builder.add_block(3, 0, 1.0),
        Err(Error::OutOfBounds { .. })
    ));
    assert!(matches!(
        builder.add_rect(Rect::new(8, 0, 3, 1), 1.0),
        Err(Error::OutOfBounds { .. })
    ));
    assert!(matches!(
        builder.add_rect(Rect::new(0, 0, 1, 1), f64::NAN),
        Err(Error::InvalidCost { .. })
    ));
}

#[test]
fn counts_are_exact() {
    let counts = [3u64, 1 << 40, 7, 0];
    let map = CostMap::from_counts(4, 4, 2, &counts).unwrap();
    assert_eq!(map.total(), (3 + (1u64 << 40) + 7) as f64);
    assert_eq!(map.cost(Rect::new(0, 2, 4, 2)), 7.0);
}
