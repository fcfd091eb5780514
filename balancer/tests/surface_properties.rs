//! Property tests of the pieces around the PBT: contiguous and round-robin assignment, cost-map
//! queries against brute force, the regular grid, and `check_partition` against painting pixels.

mod common;

use balancer::assign::{contiguous, round_robin};
use balancer::{Config, CostMap, Grid, Kind, Partitioner, Rect, Regular, check_partition};
use common::cost_value;
use proptest::prelude::*;

/// Whether some `lambda` has `lambda * u_k <= run_k <= lambda * u_k + largest` for every peer,
/// up to rounding: the band the contiguous cut promises.
fn within_band(runs: &[f64], weights: &[f64], largest: f64, total: f64) -> bool {
    let sum: f64 = weights.iter().sum();
    let tolerance = 1e-9 * total + 1e-12;
    let (mut low, mut high) = (0.0f64, f64::INFINITY);
    for (&run, &weight) in runs.iter().zip(weights) {
        let share = weight / sum;
        if share > 0.0 {
            low = low.max((run - largest - tolerance) / share);
            high = high.min((run + tolerance) / share);
        } else if run > largest + tolerance {
            return false;
        }
    }
    low <= high
}

fn costs() -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(cost_value(), 0..60)
}

fn weights() -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(prop_oneof![1 => Just(0.0), 6 => 0.1f64..4.0], 1..12)
        .prop_filter("some peer must have a positive weight", |w| {
            w.iter().any(|&x| x > 0.0)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn contiguous_runs_cover_in_order_within_one_largest_tile(costs in costs(), weights in weights()) {
        let runs = contiguous(&costs, &weights).unwrap();
        prop_assert_eq!(runs.len(), weights.len());
        let mut next = 0;
        for run in &runs {
            prop_assert_eq!(run.start, next);
            prop_assert!(run.end >= run.start);
            next = run.end;
        }
        prop_assert_eq!(next, costs.len());
        let run_costs: Vec<f64> = runs.iter().map(|r| costs[r.clone()].iter().sum()).collect();
        let total: f64 = costs.iter().sum();
        let largest = costs.iter().fold(0.0f64, |a, &b| a.max(b));
        if total > 0.0 {
            prop_assert!(within_band(&run_costs, &weights, largest, total), "{:?} for weights {:?}", run_costs, weights);
        } else {
            // Nothing predicted to cost anything: dealt by count, one tile each at most apart.
            let counts: Vec<f64> = runs.iter().map(|r| r.len() as f64).collect();
            prop_assert!(within_band(&counts, &weights, 1.0, costs.len() as f64));
        }
    }

    #[test]
    fn equal_weights_keep_every_run_near_its_share(costs in costs(), peers in 1usize..=16) {
        let runs = contiguous(&costs, &vec![1.0; peers]).unwrap();
        let total: f64 = costs.iter().sum();
        let largest = costs.iter().fold(0.0f64, |a, &b| a.max(b));
        for run in runs {
            let cost: f64 = costs[run].iter().sum();
            prop_assert!((cost - total / peers as f64).abs() <= largest + 1e-9 * total);
        }
    }

    #[test]
    fn round_robin_deals_every_tile_once_by_weight(tiles in 0usize..200, weights in weights()) {
        let runs = round_robin(tiles, &weights).unwrap();
        let mut dealt: Vec<usize> = runs.iter().flatten().copied().collect();
        dealt.sort();
        prop_assert_eq!(dealt, (0..tiles).collect::<Vec<_>>());
        let sum: f64 = weights.iter().sum();
        for (run, weight) in runs.iter().zip(&weights) {
            // A peer's credit is its share so far minus its tiles so far; a pick leaves the
            // picked credit at least -1 (it was the largest, so at least 0), and credits sum
            // to 0, so no credit exceeds P - 1: share - (P - 1) <= tiles <= share + 1.
            let share = tiles as f64 * weight / sum;
            let count = run.len() as f64;
            prop_assert!(count <= share + 1.0 + 1e-9, "{} tiles for a share of {}", count, share);
            prop_assert!(count >= share - (weights.len() as f64 - 1.0) - 1e-9, "{} tiles for a share of {}", count, share);
        }
    }

    #[test]
    fn rectangle_costs_match_brute_force(
        (w, h, block, blocks) in (1u32..=40, 1u32..=40, 1u32..=9).prop_flat_map(|(w, h, b)| {
            (Just(w), Just(h), Just(b), proptest::collection::vec(cost_value(), common::block_count(w, h, b)))
        }),
        corners in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
    ) {
        let integral = blocks.iter().all(|c| c.fract() == 0.0 && *c < 1e9);
        let map = CostMap::from_blocks(w, h, block, blocks).unwrap();
        let (x0, x1) = ordered(corners.0, corners.1, w);
        let (y0, y1) = ordered(corners.2, corners.3, h);
        let rect = Rect::new(x0, y0, x1 - x0, y1 - y0);
        // Each pixel carries its block's cost divided by the block's pixel count.
        let mut brute = 0.0;
        for y in y0..y1 {
            for x in x0..x1 {
                let (c, r) = (x / block, y / block);
                brute += map.block_cost(c, r).unwrap() / map.block_rect(c, r).unwrap().area() as f64;
            }
        }
        // Double-double prefix sums are good to about 2^-104 of the map's total.
        let slack = 1e-28 * map.total();
        prop_assert!((map.cost(rect) - brute).abs() <= slack + 1e-9 * brute + 1e-9, "{} vs {}", map.cost(rect), brute);
        // Snapped outwards to block boundaries: whole blocks, exact for integer costs.
        let snapped = Rect::new(x0 / block * block, y0 / block * block, 0, 0);
        let snapped = Rect { w: (x1.div_ceil(block) * block).min(w) - snapped.x, h: (y1.div_ceil(block) * block).min(h) - snapped.y, ..snapped };
        let mut exact = 0.0;
        for r in snapped.y / block..(snapped.bottom() as u32).div_ceil(block) {
            for c in snapped.x / block..(snapped.right() as u32).div_ceil(block) {
                exact += map.block_cost(c, r).unwrap();
            }
        }
        if integral {
            prop_assert_eq!(map.cost(snapped), exact);
        } else {
            let error = (map.cost(snapped) - exact).abs();
            prop_assert!(error <= slack + 1e-9 * exact + 1e-9, "{} vs {}", map.cost(snapped), exact);
        }
    }

    #[test]
    fn check_partition_agrees_with_painting_pixels(
        (w, h) in (1u32..=12, 1u32..=12),
        columns in 1u32..=4,
        rows in 1u32..=4,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), 0u8..6), 0..3),
    ) {
        let columns = columns.min(w);
        let rows = rows.min(h);
        let mut tiles: Vec<Rect> = Regular::grid(w, h, columns, rows).unwrap().tiles().iter().map(|t| t.rect).collect();
        for (at, edit) in edits {
            let i = at.index(tiles.len());
            let t = &mut tiles[i];
            match edit {
                0 => t.w = t.w.saturating_sub(1),
                1 => t.w += 1,
                2 => t.h += 1,
                3 => t.x = t.x.saturating_sub(1),
                4 => { let copy = *t; tiles.push(copy); }
                _ => { tiles.remove(i); }
            }
            if tiles.is_empty() { break; }
        }
        let mut painted = vec![0u32; (w * h) as usize];
        let mut valid = true;
        for t in &tiles {
            if t.is_empty() || !t.inside(w, h) { valid = false; continue; }
            for y in t.y..t.y + t.h {
                for x in t.x..t.x + t.w {
                    painted[(y * w + x) as usize] += 1;
                }
            }
        }
        valid &= painted.iter().all(|&n| n == 1);
        prop_assert_eq!(check_partition(w, h, &tiles, None, None).is_ok(), valid);
    }

    #[test]
    fn regular_grids_partition_any_image((w, h) in common::image(), columns in 1u32..=20, rows in 1u32..=20, size in (1u32..=50, 1u32..=50)) {
        let (columns, rows) = (columns.min(w), rows.min(h));
        let counted = Regular::grid(w, h, columns, rows).unwrap();
        let rects: Vec<Rect> = counted.tiles().iter().map(|t| t.rect).collect();
        prop_assert_eq!(check_partition(w, h, &rects, Some((columns * rows) as usize), None), Ok(()));
        let widths: Vec<u32> = rects.iter().map(|r| r.w).collect();
        prop_assert!(widths.iter().max().unwrap() - widths.iter().min().unwrap() <= 1);
        let sized = Regular::tile_size(w, h, size.0, size.1).unwrap();
        let rects: Vec<Rect> = sized.tiles().iter().map(|t| t.rect).collect();
        let count = (w.div_ceil(size.0) * h.div_ceil(size.1)) as usize;
        prop_assert_eq!(check_partition(w, h, &rects, Some(count), None), Ok(()));
    }
}

fn ordered(a: f64, b: f64, extent: u32) -> (u32, u32) {
    let (a, b) = (
        (a * f64::from(extent)) as u32,
        (b * f64::from(extent)) as u32,
    );
    let (lo, hi) = (a.min(b), a.max(b));
    (lo.min(extent - 1), (hi + 1).min(extent))
}

#[test]
fn a_band_exists_for_every_small_integer_case() {
    // Exhaustive over all cost sequences of up to 5 tiles with costs 0..=4, for 2 to 4 peers:
    // the banded cut must never need its fallback.
    for n in 0..=5u32 {
        for code in 0..5u32.pow(n) {
            let costs: Vec<f64> = (0..n).map(|i| f64::from(code / 5u32.pow(i) % 5)).collect();
            let total: f64 = costs.iter().sum();
            let largest = costs.iter().fold(0.0f64, |a, &b| a.max(b));
            for peers in 2..=4 {
                for weights in [vec![1.0; peers], (1..=peers).map(|p| p as f64).collect()] {
                    let runs = contiguous(&costs, &weights).unwrap();
                    let run_costs: Vec<f64> =
                        runs.iter().map(|r| costs[r.clone()].iter().sum()).collect();
                    if total > 0.0 {
                        assert!(
                            within_band(&run_costs, &weights, largest, total),
                            "{costs:?} {weights:?} -> {run_costs:?}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn the_common_surface_drives_either_balancer() {
    let map = CostMap::from_fn(64, 32, 8, |c, r| if c < 2 && r < 2 { 100.0 } else { 1.0 }).unwrap();
    for kind in [Kind::Pbt, Kind::Regular] {
        let config = Config {
            kind,
            leaves: 16,
            grid: Grid::Count {
                columns: 4,
                rows: 4,
            },
            ..Config::default()
        };
        let mut partitioner = Partitioner::new(64, 32, &config).unwrap();
        partitioner.observe(&map).unwrap();
        let tiles = partitioner.tiles();
        let rects: Vec<Rect> = tiles.iter().map(|t| t.rect).collect();
        assert_eq!(check_partition(64, 32, &rects, Some(16), None), Ok(()));
        let assignment = partitioner.assign(4, Some(&[1.0, 1.0, 2.0, 0.5])).unwrap();
        assert_eq!(assignment.peers(), 4);
        let dealt: usize = assignment.runs.iter().map(Vec::len).sum();
        assert_eq!(dealt, 16);
    }
}
