//! The 4-wide tree the renderer traverses: obvhs's binary tree collapsed into nodes of up to four
//! children, whose four boxes are tested against a ray at once, one SIMD lane per box.
//!
//! Why 4 wide: on x86-64 without `target-cpu` flags (which would make images depend on the
//! machine that built the binary) the SIMD width is SSE's four f32 lanes, so a node's four boxes
//! cost about what one box cost in the binary tree, and a ray visits fewer, shallower nodes.
//! Why the `wide` crate rather than `std::arch`: it is safe, works on stable Rust, compiles to
//! SSE2 on x86-64 and to plain scalar code elsewhere, and its lane operations are the IEEE
//! operations themselves (no fused multiply-add unless one asks for it).
//!
//! **Exactness.** Each lane of [`WideRay::enter`] evaluates exactly the expressions of the binary
//! traversal's slab test (`SlabRay::enter` in `traverse.rs`) for its box: the same subtraction,
//! multiplications by the same reciprocal and by `FAR_SCALE`, the same NaN-dropping selects; the
//! maximum and minimum that follow only see NaN-free values, for which every order of evaluation
//! gives the same result. So a box is entered exactly when the binary test enters it, at the same
//! distance. The tree only decides which leaves are opened, and in which order; since culling is
//! conservative and [`Closest::offer`] breaks ties in `t` by triangle index, the closest hit (and
//! whether a shadow ray is blocked) is the one brute force finds, whatever the order. Tests
//! render the same images through both trees, bit for bit.
//!
//! Leaves are the binary tree's leaves, the same runs of `Accel::vertices`, packed four triangles
//! to a group for the SIMD triangle test of `quad.rs`; `Accel::vertices` stays for the scalar
//! test, which settles what the SIMD one leaves.

use super::bvh::{Accel, Closest};
use super::quad::{LANES, Quad, QuadRay};
use super::traverse::FAR_SCALE;
use super::triangle::ShearedRay;
use super::{Hit, Ray, TraversalStats};
use glam::Vec3;
use obvhs::bvh2::Bvh2;
use std::mem::MaybeUninit;
use wide::{CmpGt, CmpLe, CmpLt, f32x4};

/// Children per node: SSE's four f32 lanes.
const WIDTH: usize = 4;

/// A node of up to four children. 128 bytes, two cache lines, aligned to 16 by `f32x4`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Node4 {
    /// The children's boxes, one lane per child: min x, y, z, then max x, y, z. Lanes past
    /// `children` hold an empty box (min +inf, max -inf) and are masked out anyway.
    bounds: [f32x4; 6],
    /// Per child: an inner node's index in [`Bvh4::nodes`], or a leaf's first group in
    /// [`Bvh4::quads`].
    index: [u32; WIDTH],
    /// Per child: the leaf's number of triangles (obvhs's leaves hold at most 255), or 0 for
    /// an inner node.
    count: [u8; WIDTH],
    /// Bit `i` set when lane `i` holds a child; children fill the lowest lanes.
    valid: u8,
    /// The number of children, which the stats count as boxes tested (a stored count, since
    /// counting bits is a dozen instructions on x86-64 without `popcnt`).
    children: u8,
}

/// The collapsed tree. Node 0 is the root; an empty tree has no nodes.
#[derive(Clone, Debug, Default)]
pub(super) struct Bvh4 {
    pub(super) nodes: Vec<Node4>,
    /// The leaves' triangles, four to a group, each leaf's groups in a run.
    pub(super) quads: Vec<Quad>,
    /// Levels of 4-wide nodes on the deepest path (0 when empty): bounds the traversal stack.
    pub(super) depth: usize,
}

impl Bvh4 {
    /// Collapses `bvh`: each node takes its binary node's two children, then repeatedly
    /// replaces the inner child with the largest surface area by its two children, until it has
    /// four or only leaves. Deterministic: ties go to the first such child.
    /// Leaves are packed into groups of four triangles from `vertices` (`Accel::vertices`).
    pub(super) fn collapse(bvh: &Bvh2, vertices: &[[Vec3; 3]]) -> Bvh4 {
        if bvh.nodes.is_empty() {
            return Bvh4::default();
        }
        let mut nodes = vec![Node4::EMPTY];
        // A root that is a leaf becomes a root with that one leaf as its child.
        let root = &bvh.nodes[0];
        let root_children = if root.is_leaf() {
            vec![0]
        } else {
            let first = root.first_index as usize;
            vec![first, first + 1]
        };
        // (slot of the node being made, its binary children so far, its level)
        let mut pending = vec![(0usize, root_children, 1usize)];
        let mut depth = 0;
        let mut quads = Vec::with_capacity(vertices.len() / 2);
        while let Some((slot, mut children, level)) = pending.pop() {
            depth = depth.max(level);
            while children.len() < WIDTH {
                let widest = children
                    .iter()
                    .enumerate()
                    .filter(|&(_, &c)| !bvh.nodes[c].is_leaf())
                    .fold(None, |best: Option<(usize, f32)>, (i, &c)| {
                        let area = bvh.nodes[c].aabb().half_area();
                        match best {
                            Some((_, a)) if a >= area => best,
                            _ => Some((i, area)),
                        }
                    });
                let Some((i, _)) = widest else { break };
                let first = bvh.nodes[children[i]].first_index as usize;
                children[i] = first;
                children.insert(i + 1, first + 1);
            }
            let mut node = Node4::EMPTY;
            for (lane, &c) in children.iter().enumerate() {
                let child = &bvh.nodes[c];
                let aabb = child.aabb();
                node.set_bounds(lane, aabb.min.to_array(), aabb.max.to_array());
                node.valid |= 1 << lane;
                node.children += 1;
                if child.is_leaf() {
                    let first = child.first_index as usize;
                    node.index[lane] =
                        u32::try_from(quads.len()).expect("fewer groups than leaf entries");
                    node.count[lane] = u8::try_from(child.prim_count)
                        .expect("build.rs clamps leaves to 255 triangles");
                    let leaf = &vertices[first..first + child.prim_count as usize];
                    quads.extend(Quad::pack(leaf, child.first_index));
                } else {
                    let index = nodes.len();
                    nodes.push(Node4::EMPTY);
                    node.index[lane] =
                        u32::try_from(index).expect("fewer 4-wide nodes than binary ones");
                    let first = child.first_index as usize;
                    pending.push((index, vec![first, first + 1], level + 1));
                }
            }
            nodes[slot] = node;
        }
        Bvh4 {
            nodes,
            quads,
            depth,
        }
    }
}

const _: () = assert!(std::mem::size_of::<Node4>() == 128, "two cache lines");

impl Node4 {
    const EMPTY: Node4 = Node4 {
        bounds: [
            f32x4::new([f32::INFINITY; WIDTH]),
            f32x4::new([f32::INFINITY; WIDTH]),
            f32x4::new([f32::INFINITY; WIDTH]),
            f32x4::new([f32::NEG_INFINITY; WIDTH]),
            f32x4::new([f32::NEG_INFINITY; WIDTH]),
            f32x4::new([f32::NEG_INFINITY; WIDTH]),
        ],
        index: [0; WIDTH],
        count: [0; WIDTH],
        valid: 0,
        children: 0,
    };

    fn set_bounds(&mut self, lane: usize, min: [f32; 3], max: [f32; 3]) {
        for axis in 0..3 {
            let mut lo = self.bounds[axis].to_array();
            lo[lane] = min[axis];
            self.bounds[axis] = f32x4::new(lo);
            let mut hi = self.bounds[3 + axis].to_array();
            hi[lane] = max[axis];
            self.bounds[3 + axis] = f32x4::new(hi);
        }
    }
}

/// A ray prepared for 4-wide slab tests: the binary test's origin and reciprocal direction,
/// splatted, and for each axis which of a box's planes is near.
struct WideRay {
    origin: [f32x4; 3],
    inv_dir: [f32x4; 3],
    /// Per axis, the index in [`Node4::bounds`] of the near plane and of the far plane: the max
    /// when the reciprocal direction is negative (including -0.0's -inf), else the min.
    near: [usize; 3],
    far: [usize; 3],
}

impl WideRay {
    fn new(ray: &Ray) -> Self {
        let inv = [1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z];
        let o = ray.origin.to_array();
        let negative = |axis: usize| inv[axis] < 0.0;
        WideRay {
            origin: o.map(f32x4::splat),
            inv_dir: inv.map(f32x4::splat),
            near: [0, 1, 2].map(|a| if negative(a) { 3 + a } else { a }),
            far: [0, 1, 2].map(|a| if negative(a) { a } else { 3 + a }),
        }
    }

    /// For each child of `node`, whether the ray enters its box within `(0, t_max]` (bit `i`)
    /// and the entry distance: lane by lane, the binary traversal's `SlabRay::enter`.
    #[inline(always)]
    fn enter(&self, node: &Node4, t_max: f32) -> (u32, [f32; WIDTH]) {
        let zero = f32x4::ZERO;
        let end = f32x4::splat(t_max);
        let scale = f32x4::splat(FAR_SCALE);
        let mut t0 = zero;
        let mut t1 = end;
        for axis in 0..3 {
            let near = (node.bounds[self.near[axis]] - self.origin[axis]) * self.inv_dir[axis];
            let far =
                (node.bounds[self.far[axis]] - self.origin[axis]) * self.inv_dir[axis] * scale;
            // `a > b ? a : b` drops a NaN `a`, as in the binary test; what reaches the maximum
            // and minimum is never NaN, so their own NaN rules play no part.
            t0 = t0.fast_max(near.cmp_gt(zero).blend(near, zero));
            t1 = t1.fast_min(far.cmp_lt(end).blend(far, end));
        }
        let entered = t0.cmp_le(t1).move_mask() as u32 & u32::from(node.valid);
        (entered, t0.to_array())
    }
}

#[derive(Clone, Copy)]
struct StackEntry {
    node: u32,
    t_near: f32,
}

/// Stack entries held in place: a level pushes at most three, and obvhs's trees of real scenes
/// collapse to far fewer than 40 levels.
const INLINE_STACK: usize = 3 * 40;

impl Accel {
    /// Closest hit (or, with `ANY_HIT`, the first certain hit found) by the 4-wide traversal.
    pub(super) fn traverse_wide<const ANY_HIT: bool>(
        &self,
        ray: &Ray,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        if self.wide.nodes.is_empty() {
            return None;
        }
        let needed = WIDTH - 1;
        if self.wide.depth * needed <= INLINE_STACK {
            // Uninitialised: filling 120 entries per ray cost more than a node test.
            let mut stack = [MaybeUninit::<StackEntry>::uninit(); INLINE_STACK];
            self.wide_with_stack::<ANY_HIT>(ray, stats, &mut stack)
        } else {
            let mut stack = vec![MaybeUninit::uninit(); self.wide.depth * needed];
            self.wide_with_stack::<ANY_HIT>(ray, stats, &mut stack)
        }
    }

    /// The traversal proper. `stack` holds at least `3 * depth` entries: each level of the
    /// current path leaves at most three postponed siblings on it. Entries below `len` are
    /// always initialised: every push writes one before `len` grows past it.
    #[inline(always)]
    fn wide_with_stack<const ANY_HIT: bool>(
        &self,
        ray: &Ray,
        stats: &mut TraversalStats,
        stack: &mut [MaybeUninit<StackEntry>],
    ) -> Option<Hit> {
        let nodes = &self.wide.nodes;
        let wide = WideRay::new(ray);
        let sheared = ShearedRay::new(ray);
        let quad_ray = QuadRay::new(&sheared);
        let mut closest = Closest::new(ray, ANY_HIT);
        let cull = |closest: &Closest| closest.t_max() * FAR_SCALE;
        let mut node = &nodes[0];
        let mut len = 0usize;
        loop {
            stats.nodes += u64::from(node.children);
            let (mut entered, t_near) = wide.enter(node, cull(&closest));
            // The entered children, nearest first for closest-hit queries; an any-hit query
            // stops at any hit, so it skips the sort.
            let mut order = [(0usize, 0f32); WIDTH];
            let mut n = 0;
            while entered != 0 {
                let lane = entered.trailing_zeros() as usize;
                entered &= entered - 1;
                let mut k = n;
                if !ANY_HIT {
                    while k > 0 && order[k - 1].1 > t_near[lane] {
                        order[k] = order[k - 1];
                        k -= 1;
                    }
                }
                order[k] = (lane, t_near[lane]);
                n += 1;
            }
            // Leaves are tested at once, as in the binary traversal; the nearest inner child
            // is next, the others are postponed farthest first, so the nearest pops first.
            let mut next = None;
            let mut postponed = [(0u32, 0f32); WIDTH];
            let mut p = 0;
            for &(lane, t) in &order[..n] {
                let count = u32::from(node.count[lane]);
                if count > 0 {
                    // A nearer leaf may have moved the closest hit in front of this one.
                    if t <= cull(&closest)
                        && self.test_leaf::<ANY_HIT>(
                            node.index[lane],
                            count,
                            &sheared,
                            &quad_ray,
                            &mut closest,
                            stats,
                        )
                        && ANY_HIT
                    {
                        return closest.best;
                    }
                } else if next.is_none() {
                    next = Some(node.index[lane]);
                } else {
                    postponed[p] = (node.index[lane], t);
                    p += 1;
                }
            }
            for &(index, t_near) in postponed[..p].iter().rev() {
                stack[len].write(StackEntry {
                    node: index,
                    t_near,
                });
                len += 1;
            }
            if let Some(index) = next {
                node = &nodes[index as usize];
                continue;
            }
            // Resume at the nearest postponed box that may still hold a closer hit.
            loop {
                if len == 0 {
                    return closest.best;
                }
                len -= 1;
                // SAFETY: entries below the old `len` were written by the pushes above.
                let entry = unsafe { stack[len].assume_init() };
                if entry.t_near <= cull(&closest) {
                    node = &nodes[entry.node as usize];
                    break;
                }
            }
        }
    }

    /// Tests the `count` triangles of the leaf whose groups start at `first`: the SIMD filter
    /// four at a time, then the scalar test on the lanes it leaves. Returns whether any became
    /// the closest hit (with `ANY_HIT`, stops at the first). Every triangle up to where it
    /// stops counts as tested, filtered out or not.
    #[inline(always)]
    fn test_leaf<const ANY_HIT: bool>(
        &self,
        first: u32,
        count: u32,
        sheared: &ShearedRay,
        quad_ray: &QuadRay,
        closest: &mut Closest,
        stats: &mut TraversalStats,
    ) -> bool {
        let groups = (count as usize).div_ceil(LANES);
        let first = first as usize;
        let mut found = false;
        for quad in &self.wide.quads[first..first + groups] {
            let quad_hits = quad_ray.intersect(quad);
            let mut candidates = quad_hits.candidates;
            while candidates != 0 {
                let lane = candidates.trailing_zeros();
                candidates &= candidates - 1;
                let k = (quad.entry + lane) as usize;
                let kept = if quad_hits.exact & (1 << lane) != 0 {
                    closest.offer_hit(quad_hits.hit(lane as usize), self.original[k])
                } else {
                    closest.offer(sheared, &self.vertices[k], self.original[k])
                };
                if kept {
                    found = true;
                    if ANY_HIT {
                        stats.triangles += u64::from(lane + 1);
                        return true;
                    }
                }
            }
            stats.triangles += u64::from(quad.len);
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::BuildQuality;
    use crate::scene::Triangle;

    /// A grid of `n * n` bumpy quads, two triangles each.
    fn grid(n: usize) -> Vec<Triangle> {
        let v = |i: usize, j: usize| Vec3::new(i as f32, j as f32, ((i * 7 + j * 13) % 5) as f32);
        let mut out = Vec::new();
        for i in 0..n {
            for j in 0..n {
                for p in [
                    [v(i, j), v(i + 1, j), v(i + 1, j + 1)],
                    [v(i, j), v(i + 1, j + 1), v(i, j + 1)],
                ] {
                    out.push(Triangle {
                        p,
                        n: None,
                        uv: None,
                        material: 0,
                    });
                }
            }
        }
        out
    }

    #[test]
    fn the_wide_tree_holds_every_leaf_entry_once_in_nodes_of_up_to_four() {
        for n in [1, 3, 40] {
            let triangles = grid(n);
            let accel = Accel::build(&triangles, BuildQuality::Medium);
            let wide = &accel.wide;
            let mut seen = vec![0u32; accel.leaf_entries()];
            for node in &wide.nodes {
                assert!(node.valid != 0 && node.valid.count_ones() as usize <= WIDTH);
                assert_eq!(u32::from(node.children), node.valid.count_ones());
                for lane in (0..WIDTH).filter(|&l| node.valid & (1 << l) != 0) {
                    if node.count[lane] == 0 {
                        continue;
                    }
                    let groups = (node.count[lane] as usize).div_ceil(LANES);
                    let first = node.index[lane] as usize;
                    for quad in &wide.quads[first..first + groups] {
                        for i in 0..LANES as u32 {
                            if quad.valid & (1 << i) != 0 {
                                seen[(quad.entry + i) as usize] += 1;
                            }
                        }
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "n = {n}: {seen:?}");
            assert!(wide.depth <= accel.depth());
            if n == 40 {
                // A full 4-wide node replaces three binary inner nodes; leaves in the way of
                // the collapse leave some with fewer children, but not most.
                let inner = accel.node_count() / 2;
                assert!(
                    wide.nodes.len() * 3 < inner * 2,
                    "{} wide nodes for {inner} binary inner ones",
                    wide.nodes.len(),
                );
            }
        }
    }
}
