//! Property tests of the PBT over random images (including 1xN strips and images far wider
//! than 2:1), leaf counts and cost maps (including zero and 1e30 costs).

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::HashSet;

use balancer::{Config, CostMap, Error, Order, Pbt, Rect, check_partition};
use common::{Layout, close, expected_leaves, frames, variance};
use proptest::prelude::*;

fn rects(pbt: &Pbt) -> Vec<Rect> {
    pbt.tiles().iter().map(|tile| tile.rect).collect()
}

/// These properties are of the re-cut, with each leaf predicted exactly as the map costs it:
/// motion compensation, which predicts a moved map instead, is tested in `balancer::motion`.
fn config(leaves: usize) -> Config {
    Config {
        leaves,
        motion: None,
        ..Config::default()
    }
}

/// The parent of `leaf` in the full halving hierarchy of `image`: the tree a PBT's nodes are
/// drawn from, found by walking down from the root.
fn parent_of(image: Rect, leaf: Rect) -> Option<Rect> {
    let (mut node, mut parent) = (image, None);
    while node != leaf {
        let (a, b) = node.halves()?;
        parent = Some(node);
        node = if a.x <= leaf.x
            && a.y <= leaf.y
            && leaf.right() <= a.right()
            && leaf.bottom() <= a.bottom()
        {
            a
        } else {
            b
        };
    }
    parent
}

/// Asserts that no split+merge pair would lower the variance of `map`'s costs over the leaves:
/// for every splittable leaf `a` and every unforced node `q` with two leaf children `b, c`,
/// other than `a`'s parent, `cost(a1) * cost(a2) <= cost(b) * cost(c)`.
fn assert_no_improving_pair(
    image: Rect,
    leaves: &[Rect],
    map: &CostMap,
) -> Result<(), TestCaseError> {
    let set: HashSet<Rect> = leaves.iter().copied().collect();
    // The two best split gains under distinct parents.
    let mut best: Vec<(f64, Option<Rect>)> = Vec::new();
    let mut merges: Vec<(f64, Rect)> = Vec::new();
    for &leaf in leaves {
        let parent = parent_of(image, leaf);
        if let Some((a1, a2)) = leaf.halves() {
            best.push((map.cost(a1) * map.cost(a2), parent));
        }
        if let Some(parent) = parent {
            let (b, c) = parent.halves().unwrap();
            let unforced = parent.long_side() <= 2 * parent.short_side() + 1;
            if leaf == b && set.contains(&c) && unforced {
                merges.push((map.cost(b) * map.cost(c), parent));
            }
        }
    }
    best.sort_by(|x, y| y.0.total_cmp(&x.0));
    let first = best.first().copied();
    let second = first.and_then(|(_, p)| best.iter().find(|(_, q)| *q != p).copied());
    for (loss, q) in merges {
        let gain = match first {
            Some((gain, parent)) if parent != Some(q) => gain,
            _ => second.map_or(0.0, |(gain, _)| gain),
        };
        prop_assert!(
            gain <= loss + 1e-9 * gain.max(loss),
            "split gaining {gain} beats merging {q:?} at {loss}"
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn updates_keep_an_exact_partition_and_improve_balance((w, h, m, block, layouts) in frames(80)) {
        let mut pbt = Pbt::new(w, h, &config(m)).unwrap();
        let expected = expected_leaves(w, h, m);
        prop_assert_eq!(check_partition(w, h, &rects(&pbt), Some(expected), Some(2.0)), Ok(()));
        for layout in &layouts {
            let map = layout.map(w, h, block);
            let before = rects(&pbt);
            let exact_before: Vec<f64> = before.iter().map(|&r| map.cost(r)).collect();
            let update = pbt.observe(&map).unwrap();
            prop_assert!(!update.capped);
            let tiles = pbt.tiles();
            let after: Vec<Rect> = tiles.iter().map(|t| t.rect).collect();
            let predicted: Vec<f64> = tiles.iter().map(|t| t.predicted).collect();
            // Exact cover, no overlap, 2:1 (plus a pixel), leaf count.
            prop_assert_eq!(check_partition(w, h, &after, Some(expected), Some(2.0)), Ok(()));
            prop_assert_eq!(update.splits, update.merges);
            // Predictions are the map's costs, finite, and their sum is what it was before the
            // re-cut: the map's total.
            prop_assert!(predicted.iter().all(|p| p.is_finite() && *p >= 0.0));
            for (tile, &p) in tiles.iter().zip(&predicted) {
                prop_assert_eq!(p, map.cost(tile.rect));
            }
            let (sum_before, sum_after) = (exact_before.iter().sum::<f64>(), predicted.iter().sum::<f64>());
            prop_assert!(close(sum_before, sum_after), "{} -> {}", sum_before, sum_after);
            prop_assert!(close(sum_after, map.total()));
            // With exact predictions the update never raises the variance.
            let scale = predicted.iter().map(|p| p * p).sum::<f64>() / predicted.len() as f64;
            let (v_before, v_after) = (variance(&exact_before), variance(&predicted));
            prop_assert!(v_after <= v_before + 1e-9 * scale + 1e-12, "variance {} -> {}", v_before, v_after);
            // And it stops only where no pair would help.
            assert_no_improving_pair(Rect::image(w, h), &after, &map)?;
        }
    }

    #[test]
    fn changing_the_leaf_count_keeps_an_exact_partition(
        (w, h, m, block, layouts) in frames(60),
        counts in proptest::collection::vec(1usize..=200, 1..4),
    ) {
        let mut pbt = Pbt::new(w, h, &config(m)).unwrap();
        for (layout, &count) in layouts.iter().zip(counts.iter().cycle()) {
            pbt.observe(&layout.map(w, h, block)).unwrap();
            let update = pbt.set_leaves(count).unwrap();
            prop_assert!(!update.capped);
            let expected = expected_leaves(w, h, count);
            prop_assert_eq!(pbt.leaf_count(), expected);
            prop_assert_eq!(check_partition(w, h, &rects(&pbt), Some(expected), Some(2.0)), Ok(()));
        }
    }

    #[test]
    fn contiguous_runs_and_interleaved_shares_are_balanced(
        (w, h, m, block, layouts) in frames(120),
        peers in 1usize..=24,
    ) {
        let contiguous = Config { order: Order::Contiguous, ..config(m) };
        let mut pbt = Pbt::new(w, h, &contiguous).unwrap();
        pbt.observe(&layouts[0].map(w, h, block)).unwrap();
        let costs: Vec<f64> = pbt.tiles().iter().map(|t| t.predicted).collect();
        let assignment = pbt.assign(peers, None).unwrap();
        prop_assert_eq!(assignment.peers(), peers);
        let order: Vec<usize> = assignment.runs.iter().flatten().copied().collect();
        prop_assert_eq!(order, (0..costs.len()).collect::<Vec<_>>());
        let run_costs = assignment.run_costs(&costs);
        let largest = costs.iter().fold(0.0f64, |a, &b| a.max(b));
        let (lo, hi) = run_costs.iter().fold((f64::MAX, 0.0f64), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        let total: f64 = costs.iter().sum();
        prop_assert!(hi - lo <= largest + 1e-9 * total, "runs {:?}, largest tile {}", run_costs, largest);

        // Interleaved (the default): every leaf dealt once, shares within the largest leaf too.
        let interleaved = Config { order: Order::Interleaved, ..config(m) };
        let mut pbt = Pbt::new(w, h, &interleaved).unwrap();
        pbt.observe(&layouts[0].map(w, h, block)).unwrap();
        let assignment = pbt.assign(peers, None).unwrap();
        let mut dealt: Vec<usize> = assignment.runs.iter().flatten().copied().collect();
        dealt.sort_unstable();
        prop_assert_eq!(dealt, (0..costs.len()).collect::<Vec<_>>());
        let run_costs = assignment.run_costs(&costs);
        let (lo, hi) = run_costs.iter().fold((f64::MAX, 0.0f64), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        prop_assert!(hi - lo <= largest + 1e-9 * total, "shares {:?}, largest tile {}", run_costs, largest);
    }

    #[test]
    fn a_nan_or_negative_cost_is_refused((w, h) in common::image(), block in 1u32..=8, at in any::<prop::sample::Index>(), bad in prop_oneof![Just(f64::NAN), Just(-1.0), Just(f64::NEG_INFINITY)]) {
        let blocks = common::block_count(w, h, block);
        let mut costs = vec![1.0; blocks];
        let index = at.index(blocks);
        costs[index] = bad;
        let result = CostMap::from_blocks(w, h, block, costs);
        let is_invalid_cost = matches!(result, Err(Error::InvalidCost { .. }));
        prop_assert!(is_invalid_cost);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn large_trees_follow_a_moving_spot(
        (w, h) in (64u32..=400, 64u32..=300),
        m in 200usize..=3000,
        spots in proptest::collection::vec((0.0f64..1.0, 0.0f64..1.0, 0.05f64..0.3, 2.0f64..100.0), 2..4),
    ) {
        let mut pbt = Pbt::new(w, h, &config(m)).unwrap();
        let expected = expected_leaves(w, h, m);
        for (cx, cy, radius, peak) in spots {
            let map = Layout::Spot { cx, cy, radius, peak, floor: 1.0 }.map(w, h, 8);
            let before: Vec<f64> = rects(&pbt).iter().map(|&r| map.cost(r)).collect();
            let update = pbt.observe(&map).unwrap();
            prop_assert!(!update.capped);
            let after = rects(&pbt);
            prop_assert_eq!(check_partition(w, h, &after, Some(expected), Some(2.0)), Ok(()));
            let predicted: Vec<f64> = pbt.tiles().iter().map(|t| t.predicted).collect();
            let scale = predicted.iter().map(|p| p * p).sum::<f64>() / predicted.len() as f64;
            prop_assert!(variance(&predicted) <= variance(&before) + 1e-9 * scale);
            assert_no_improving_pair(Rect::image(w, h), &after, &map)?;
        }
    }
}

#[test]
fn all_zero_and_all_huge_maps_leave_a_sane_tree() {
    for (w, h) in [(64, 48), (1, 40), (200, 5)] {
        let mut pbt = Pbt::new(w, h, &config(32)).unwrap();
        for layout in [
            Layout::Random(vec![0.0; common::block_count(w, h, 4)]),
            Layout::Random(vec![1e30; common::block_count(w, h, 4)]),
        ] {
            let map = layout.map(w, h, 4);
            let update = pbt.observe(&map).unwrap();
            assert!(!update.capped);
            let expected = expected_leaves(w, h, 32);
            assert_eq!(
                check_partition(w, h, &rects(&pbt), Some(expected), Some(2.0)),
                Ok(())
            );
            let sum: f64 = pbt.tiles().iter().map(|t| t.predicted).sum();
            assert!(close(sum, map.total()), "{sum} vs {}", map.total());
            let assignment = pbt.assign(5, None).unwrap();
            assert_eq!(
                assignment.runs.iter().map(Vec::len).sum::<usize>(),
                pbt.leaf_count()
            );
        }
    }
}
