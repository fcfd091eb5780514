//! Building the tree with obvhs.
//!
//! We call obvhs's building blocks (PLOC, reinsertion, leaf collapse, spatial pre-splits) in the
//! order its `build_bvh2_from_tris` helper does, rather than calling the helper, for two reasons:
//! the helper reads the clock (the tracer has no clock of its own), and the boxes made by its
//! spatial pre-splits can fall short of their piece of triangle by a rounding error, which a
//! watertight traversal cannot afford ([`pad_split_boxes`]).
//!
//! Determinism: the tree is a pure function of the triangles and the parameters. obvhs builds on
//! one thread unless its `parallel` feature is on (it is off: nothing in the workspace enables
//! it); its builder draws no random numbers and uses only deterministic radix and unstable sorts,
//! so the same input gives the same tree. With `parallel` on, PLOC would split its search into
//! chunks by `rayon::current_num_threads()`, which a render must not depend on.

use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::{
    Bvh2, leaf_collapser::collapse, node::Bvh2Node, reinsertion::ReinsertionOptimizer,
};
use obvhs::ploc::{PlocBuilder, PlocSearchDistance};
use obvhs::splits::split_aabbs_preset;
use obvhs::triangle::Triangle;

/// obvhs's `build_bvh2_from_tris`, minus its clock and debug validation, plus padding of
/// split boxes. `shapes` must not be empty.
pub(super) fn build_bvh2(shapes: Vec<Triangle>, params: BvhBuildParams) -> Bvh2 {
    let (aabbs, indices) = primitive_boxes(&shapes, params.pre_split);
    // Each array freed as soon as the build is past it, not when the function returns: the
    // dragon's triangles, boxes and PLOC's own arrays together set the process's peak memory.
    drop(shapes);
    let mut bvh = ploc(aabbs, indices, &params);
    bvh.uses_spatial_splits = params.pre_split;
    let mut reinsertion = ReinsertionOptimizer::default();
    reinsertion.run(&mut bvh, params.reinsertion_batch_ratio, None);
    collapse(
        &mut bvh,
        params.max_prims_per_leaf.clamp(1, 255),
        params.collapse_traversal_cost,
    );
    let post_collapse =
        params.reinsertion_batch_ratio * params.post_collapse_reinsertion_batch_ratio_multiplier;
    reinsertion.run(&mut bvh, post_collapse, None);
    bvh
}

/// obvhs's `PlocBuilder::build`, with the boxes freed once PLOC has made its leaves of them,
/// before its passes: on the dragon the boxes are 28 MB, and PLOC's passes, with its arrays and
/// the tree it fills, are the process's peak memory. The same steps in the same order as
/// `PlocBuilder::build_ploc`, so the same tree.
fn ploc(aabbs: Vec<Aabb>, indices: Vec<u32>, params: &BvhBuildParams) -> Bvh2 {
    let count = aabbs.len();
    let mut builder = PlocBuilder::new();
    let mut bvh = Bvh2::zeroed(count);
    bvh.reset_for_reuse(count, Some(indices));
    let mut total = Aabb::empty();
    builder.current_nodes = aabbs
        .iter()
        .zip(&bvh.primitive_indices)
        .map(|(aabb, &index)| {
            total.extend(aabb.min);
            total.extend(aabb.max);
            Bvh2Node::new(*aabb, 1, index)
        })
        .collect();
    drop(aabbs);
    let (precision, threshold) = (params.sort_precision, params.search_depth_threshold);
    // obvhs's search distances are a const parameter of its passes; this is its own match.
    match params.ploc_search_distance {
        PlocSearchDistance::Minimum => {
            builder.build_ploc_from_leaves::<1, false>(&mut bvh, total, precision, threshold)
        }
        PlocSearchDistance::VeryLow => {
            builder.build_ploc_from_leaves::<2, false>(&mut bvh, total, precision, threshold)
        }
        PlocSearchDistance::Low => {
            builder.build_ploc_from_leaves::<6, false>(&mut bvh, total, precision, threshold)
        }
        PlocSearchDistance::Medium => {
            builder.build_ploc_from_leaves::<14, false>(&mut bvh, total, precision, threshold)
        }
        PlocSearchDistance::High => {
            builder.build_ploc_from_leaves::<24, false>(&mut bvh, total, precision, threshold)
        }
        PlocSearchDistance::VeryHigh => {
            builder.build_ploc_from_leaves::<32, false>(&mut bvh, total, precision, threshold)
        }
    }
    bvh
}

/// The boxes PLOC starts from and the triangle each bounds: one box per triangle, or with
/// `pre_split`, several boxes for large triangles whose box is a poor fit.
fn primitive_boxes(shapes: &[Triangle], pre_split: bool) -> (Vec<Aabb>, Vec<u32>) {
    let (mut aabbs, indices) = unpadded_primitive_boxes(shapes, pre_split);
    if pre_split {
        pad_split_boxes(&mut aabbs, &indices, shapes);
    }
    (aabbs, indices)
}

fn unpadded_primitive_boxes(shapes: &[Triangle], pre_split: bool) -> (Vec<Aabb>, Vec<u32>) {
    let mut aabbs: Vec<Aabb> = shapes.iter().map(|t| t.aabb()).collect();
    let mut indices: Vec<u32> = (0..shapes.len() as u32).collect();
    if pre_split {
        let largest = aabbs.iter().map(Aabb::half_area).fold(0.0, f32::max);
        let average = aabbs.iter().map(Aabb::half_area).sum::<f32>() / aabbs.len() as f32;
        split_aabbs_preset(&mut aabbs, &mut indices, shapes, average, largest);
        // The splits push their boxes, so one split doubles the arrays' room: the dragon's
        // 28 MB of boxes held 56 MB through PLOC, at the process's peak.
        aabbs.shrink_to_fit();
        indices.shrink_to_fit();
    }
    (aabbs, indices)
}

/// Widens boxes made by obvhs's spatial pre-splits so that they cover their piece of triangle.
///
/// A split box's extent on the other axes comes from points where the triangle's edges cross the
/// split plane, computed in `f32` with an error of about 13 units of roundoff of the largest
/// vertex coordinate `m`. A box short by that much leaves a crack between the two halves that a
/// ray can pass through. Widening by `16 * EPSILON * m` (32 units of roundoff), clamped to the
/// whole triangle's box, which is exact, closes the crack and keeps boxes conservative.
fn pad_split_boxes(aabbs: &mut [Aabb], indices: &[u32], shapes: &[Triangle]) {
    for (aabb, &index) in aabbs.iter_mut().zip(indices) {
        let whole = shapes[index as usize].aabb();
        if *aabb != whole {
            let m = whole.min.abs().max(whole.max.abs()).max_element();
            let pad = Vec3A::splat(16.0 * f32::EPSILON * m);
            aabb.min = (aabb.min - pad).max(whole.min);
            aabb.max = (aabb.max + pad).min(whole.max);
        }
    }
}

/// The number of levels of the tree, without recursion (obvhs's `depth` recurses).
pub(super) fn tree_depth(bvh: &Bvh2) -> usize {
    let mut deepest = 0;
    let mut stack = vec![(0usize, 1usize)];
    while let Some((index, depth)) = stack.pop() {
        deepest = deepest.max(depth);
        let node = &bvh.nodes[index];
        if !node.is_leaf() {
            let first = node.first_index as usize;
            stack.push((first, depth + 1));
            stack.push((first + 1, depth + 1));
        }
    }
    deepest
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::DVec3;
    use obvhs::ploc::SortPrecision;

    /// A splitmix64 step mapped to [0, 1), for test scenes and the SIMD triangle tests.
    pub(crate) fn next(state: &mut u64) -> f32 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// [`next`] mapped to [-1, 1), for the SIMD triangle tests' points (doubling and the
    /// subtraction are exact, so the draws are `next`'s own).
    pub(crate) fn next_signed(state: &mut u64) -> f32 {
        2.0 * next(state) - 1.0
    }

    /// Small triangles in a 20-wide cube plus long diagonal slivers, whose boxes are mostly empty
    /// so that pre-splits cut them.
    fn scene() -> Vec<Triangle> {
        let mut state = 11;
        let mut point =
            |scale: f32| Vec3A::new(next(&mut state), next(&mut state), next(&mut state)) * scale;
        let mut shapes = Vec::new();
        for _ in 0..400 {
            let v0 = point(20.0);
            shapes.push(Triangle {
                v0,
                v1: v0 + point(0.5),
                v2: v0 + point(0.5),
            });
        }
        for _ in 0..60 {
            let (v0, v1) = (point(20.0), point(20.0));
            shapes.push(Triangle {
                v0,
                v1,
                v2: v1 + point(0.3),
            });
        }
        shapes
    }

    /// Points where a triangle's edges cross the planes of its own split boxes, computed in f64
    /// (the exact crossing, up to 1e-16), that none of the triangle's boxes contains. Those are
    /// the places where rounding in the split leaves a crack.
    fn uncovered_crossings(aabbs: &[Aabb], indices: &[u32], shapes: &[Triangle]) -> usize {
        let mut boxes = std::collections::BTreeMap::<u32, Vec<Aabb>>::new();
        for (aabb, &i) in aabbs.iter().zip(indices) {
            boxes.entry(i).or_default().push(*aabb);
        }
        let contains =
            |b: &Aabb, x: DVec3| x.cmpge(b.min.as_dvec3()).all() && x.cmple(b.max.as_dvec3()).all();
        let mut uncovered = 0;
        for (i, pieces) in boxes.iter().filter(|(_, pieces)| pieces.len() > 1) {
            let t = &shapes[*i as usize];
            let v = [t.v0, t.v1, t.v2].map(|v| v.as_dvec3());
            for piece in pieces {
                for axis in 0..3 {
                    for plane in [piece.min[axis] as f64, piece.max[axis] as f64] {
                        for (p, q) in [(v[0], v[1]), (v[1], v[2]), (v[2], v[0])] {
                            let (a, b) = (p[axis].min(q[axis]), p[axis].max(q[axis]));
                            if !(a < plane && plane < b) {
                                continue;
                            }
                            let mut x = p + (q - p) * ((plane - p[axis]) / (q[axis] - p[axis]));
                            x[axis] = plane;
                            uncovered += !pieces.iter().any(|b| contains(b, x)) as usize;
                        }
                    }
                }
            }
        }
        uncovered
    }

    #[test]
    fn padded_split_boxes_cover_their_triangles_where_unpadded_ones_leave_cracks() {
        let shapes = scene();
        let (aabbs, indices) = unpadded_primitive_boxes(&shapes, true);
        assert!(aabbs.len() > shapes.len() + 50, "the slivers were split");
        let cracks = uncovered_crossings(&aabbs, &indices, &shapes);
        assert!(
            cracks > 0,
            "obvhs's split boxes fall short somewhere (else the fix is moot)"
        );
        let (padded, padded_indices) = primitive_boxes(&shapes, true);
        assert_eq!(padded_indices, indices);
        assert_eq!(uncovered_crossings(&padded, &indices, &shapes), 0);
    }

    #[test]
    fn padding_only_widens_and_stays_within_the_whole_triangle() {
        let shapes = scene();
        let (before, indices) = unpadded_primitive_boxes(&shapes, true);
        let (after, _) = primitive_boxes(&shapes, true);
        for ((padded, old), &i) in after.iter().zip(&before).zip(&indices) {
            let whole = shapes[i as usize].aabb();
            assert!(padded.min.cmple(old.min).all() && padded.max.cmpge(old.max).all());
            assert!(padded.min.cmpge(whole.min).all() && padded.max.cmple(whole.max).all());
        }
        assert!(after.iter().zip(&before).any(|(a, b)| a != b));
    }

    #[test]
    fn our_ploc_builds_obvhs_own_tree_at_every_search_distance() {
        // `ploc` repeats `PlocBuilder::build`'s steps to free the boxes early: held to it node
        // for node (boxes, counts, indices) and in its primitive order, so an upgrade of obvhs
        // that changes those steps fails here rather than changing the trees unnoticed.
        let shapes = scene();
        let (aabbs, indices) = primitive_boxes(&shapes, true);
        let distances = [
            PlocSearchDistance::Minimum,
            PlocSearchDistance::VeryLow,
            PlocSearchDistance::Low,
            PlocSearchDistance::Medium,
            PlocSearchDistance::High,
            PlocSearchDistance::VeryHigh,
        ];
        let nodes = |bvh: &Bvh2| -> Vec<[u32; 8]> {
            bvh.nodes
                .iter()
                .map(|n| {
                    let (min, max) = (n.aabb().min, n.aabb().max);
                    let [a, b, c] = min.to_array().map(f32::to_bits);
                    let [d, e, f] = max.to_array().map(f32::to_bits);
                    [a, b, c, d, e, f, n.prim_count, n.first_index]
                })
                .collect()
        };
        for precision in [SortPrecision::U64, SortPrecision::U128] {
            for (k, &distance) in distances.iter().enumerate() {
                let params = BvhBuildParams {
                    ploc_search_distance: distance,
                    sort_precision: precision,
                    search_depth_threshold: k % 3,
                    ..BvhBuildParams::medium_build()
                };
                let ours = ploc(aabbs.clone(), indices.clone(), &params);
                let theirs = PlocBuilder::with_capacity(aabbs.len()).build(
                    distance,
                    &aabbs,
                    indices.clone(),
                    precision,
                    params.search_depth_threshold,
                );
                assert!(
                    ours.nodes.len() > 2 * shapes.len() - 1,
                    "split boxes are leaves too"
                );
                assert_eq!(nodes(&ours), nodes(&theirs), "{distance:?} {precision:?}");
                assert_eq!(ours.primitive_indices, theirs.primitive_indices);
            }
        }
    }

    #[test]
    fn tree_depth_counts_levels() {
        let shapes = scene();
        let one = build_bvh2(shapes[..1].to_vec(), BvhBuildParams::medium_build());
        let bvh = build_bvh2(shapes, BvhBuildParams::medium_build());
        assert_eq!(tree_depth(&bvh), bvh.depth(0));
        assert_eq!(tree_depth(&one), 1);
    }
}
