//! Strategies and independent reference computations shared by the property tests. The
//! references restate the specification directly (recursion over [`Rect::halves`], brute-force
//! sums) rather than calling the code under test.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(dead_code, clippy::unwrap_used)]

use balancer::{CostMap, Rect};
use proptest::prelude::*;

/// Image sizes: small squares-ish, 1xN and Nx1 strips, and images far wider than 2:1.
pub fn image() -> impl Strategy<Value = (u32, u32)> {
    prop_oneof![
        3 => (1u32..=96, 1u32..=96),
        1 => (1u32..=3, 1u32..=300),
        1 => (1u32..=300, 1u32..=3),
        2 => (50u32..=300, 1u32..=30),
    ]
}

/// One block cost: often zero, sometimes huge, usually ordinary.
pub fn cost_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        2 => Just(0.0),
        4 => 0.0f64..1000.0,
        3 => (0u32..100).prop_map(f64::from),
        1 => Just(1e30),
    ]
}

/// How a frame's cost is laid out.
#[derive(Clone, Debug)]
pub enum Layout {
    /// Independent block costs, row-major.
    Random(Vec<f64>),
    /// A hot disc over a uniform floor, like a bright object moving through a dim scene.
    Spot {
        cx: f64,
        cy: f64,
        radius: f64,
        peak: f64,
        floor: f64,
    },
}

impl Layout {
    pub fn map(&self, width: u32, height: u32, block: u32) -> CostMap {
        match self {
            Layout::Random(costs) => {
                CostMap::from_blocks(width, height, block, costs.clone()).unwrap()
            }
            Layout::Spot {
                cx,
                cy,
                radius,
                peak,
                floor,
            } => CostMap::from_fn(width, height, block, |c, r| {
                let (x, y) = (
                    f64::from(c * block) / f64::from(width),
                    f64::from(r * block) / f64::from(height),
                );
                if (x - cx).hypot(y - cy) < *radius {
                    *peak
                } else {
                    *floor
                }
            })
            .unwrap(),
        }
    }
}

/// Blocks in a `width` x `height` image.
pub fn block_count(width: u32, height: u32, block: u32) -> usize {
    (width.div_ceil(block) * height.div_ceil(block)) as usize
}

pub fn layout(blocks: usize) -> impl Strategy<Value = Layout> {
    prop_oneof![
        proptest::collection::vec(cost_value(), blocks).prop_map(Layout::Random),
        (
            0.0f64..1.0,
            0.0f64..1.0,
            0.02f64..0.5,
            cost_value(),
            prop_oneof![Just(0.0), 0.0f64..10.0]
        )
            .prop_map(|(cx, cy, radius, peak, floor)| Layout::Spot {
                cx,
                cy,
                radius,
                peak,
                floor
            }),
    ]
}

/// An image, a leaf count, a block size and a few frames of cost.
pub fn frames(max_leaves: usize) -> impl Strategy<Value = (u32, u32, usize, u32, Vec<Layout>)> {
    (image(), 1..=max_leaves, 1u32..=12, 1usize..=4).prop_flat_map(|((w, h), m, block, count)| {
        let blocks = block_count(w, h, block);
        (
            Just(w),
            Just(h),
            Just(m),
            Just(block),
            proptest::collection::vec(layout(blocks), count),
        )
    })
}

/// The leaf count of the tree made of forced cuts alone: rectangles breaking
/// `long <= 2 * short + 1` are halved until none does.
pub fn forced_leaves(rect: Rect) -> usize {
    if rect.w.max(rect.h) > 2 * rect.w.min(rect.h) + 1 {
        let (a, b) = rect.halves().unwrap();
        forced_leaves(a) + forced_leaves(b)
    } else {
        1
    }
}

/// The leaf count the PBT must have: `m`, but no fewer than the forced cuts make and no more
/// than the image has pixels.
pub fn expected_leaves(width: u32, height: u32, m: usize) -> usize {
    let image = Rect::image(width, height);
    m.max(forced_leaves(image)).min(image.area() as usize)
}

/// Population variance.
pub fn variance(values: &[f64]) -> f64 {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / values.len() as f64
}

/// `a` and `b` equal up to a relative `1e-9` (and an absolute `1e-9`).
pub fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-9
}
