//! The wide tree's shape: obvhs's binary tree collapsed into nodes of up to eight children
//! over the same leaves, choosing which binary nodes become wide nodes by the surface area
//! heuristic (Ylitie, Karras and Laine 2017), the leaves packed into groups of four triangles
//! for the SIMD tests, and each child named by one word, its [`child_reference`].
//!
//! **Exactness.** The shape decides only which boxes a ray tests, and in which order it opens
//! leaves; every leaf is still reached by every ray whose path crosses its box, and
//! [`Closest::offer`](super::closest::Closest)'s tie rule makes the closest hit independent of the
//! order. So the collapse changes speed, never a hit or a pixel (`scripts/same_bits.sh`).

use super::node8::{Node8, WIDTH};
use super::quad::Quad;
use super::wide::{Bvh8, best_simd};
use glam::Vec3;
use obvhs::bvh2::Bvh2;

impl Bvh8 {
    /// Collapses `bvh` into nodes of up to eight children over the same leaves, choosing which
    /// binary nodes become wide nodes so that the summed surface area of the wide nodes, the
    /// surface area heuristic's measure of how often rays open them, is least ([`Plan`]).
    /// Deterministic: ties go to the first choice considered.
    /// Leaves are packed into groups of four triangles, their input triangles from `original`
    /// (the binary tree's leaf entries, `BinaryTree`) and each one's vertices
    /// `vertices_of(input triangle)`.
    pub(super) fn collapse(
        bvh: &Bvh2,
        original: &[u32],
        vertices_of: impl Fn(u32) -> [Vec3; 3] + Copy,
    ) -> Bvh8 {
        if bvh.nodes.is_empty() {
            return Bvh8::default();
        }
        let plan = Plan::new(bvh);
        let mut nodes = vec![Node8::EMPTY];
        // (slot of the node being made, the binary node it stands for, its level)
        let mut pending = vec![(0usize, 0usize, 1usize)];
        let mut depth = 0;
        let mut quads = Vec::with_capacity(original.len() / 2);
        let mut children = Vec::with_capacity(WIDTH);
        while let Some((slot, binary, level)) = pending.pop() {
            depth = depth.max(level);
            children.clear();
            plan.children(bvh, binary, &mut children);
            let mut node = Node8::EMPTY;
            for (lane, &c) in children.iter().enumerate() {
                let child = &bvh.nodes[c];
                let aabb = child.aabb();
                node.set_bounds(lane, aabb.min.to_array(), aabb.max.to_array());
                node.valid |= 1 << lane;
                node.children += 1;
                if child.is_leaf() {
                    let first = child.first_index as usize;
                    let count = u8::try_from(child.prim_count)
                        .expect("build.rs clamps leaves to 255 triangles");
                    let Some(reference) = child_reference(quads.len(), count) else {
                        return Bvh8::unwalkable();
                    };
                    node.refs[lane] = reference;
                    let end = first + child.prim_count as usize;
                    quads.extend(Quad::pack(
                        &original[first..end],
                        child.first_index,
                        vertices_of,
                    ));
                } else {
                    let index = nodes.len();
                    nodes.push(Node8::EMPTY);
                    let Some(reference) = child_reference(index, 0) else {
                        return Bvh8::unwalkable();
                    };
                    node.refs[lane] = reference;
                    pending.push((index, c, level + 1));
                }
            }
            nodes[slot] = node;
        }
        Bvh8 {
            nodes,
            quads,
            depth,
            references_fit: true,
            simd: best_simd(),
        }
    }

    /// The tree of a collapse whose indices outgrew the references: empty, and never walked.
    pub(super) fn unwalkable() -> Bvh8 {
        Bvh8 {
            references_fit: false,
            ..Bvh8::default()
        }
    }
}

/// The index's bits of a child's [`child_reference`]; the leaf's triangles take the eight above.
const INDEX_MASK: u32 = (1 << 24) - 1;

/// A child's reference: `index` (an inner node's in `Bvh8::nodes`, or a leaf's first group's
/// in `Bvh8::quads`) in the low 24 bits, the leaf's triangles (obvhs's leaves hold at most 255,
/// `build.rs` clamps them; 0 for an inner node) in the high 8; `None` where the index needs
/// more bits (a tree of some 67 million triangles or more, which is then walked through the
/// binary tree, `Bvh8::walkable`). Why one word: a walk's stack entry is then the reference and
/// the entry distance, eight bytes a push and a pop where the index and the count were twelve
/// (docs/bench.md, issue 12, thirty-eighth round).
pub(super) fn child_reference(index: usize, triangles: u8) -> Option<u32> {
    let index = u32::try_from(index).ok().filter(|&i| i <= INDEX_MASK)?;
    Some(index | u32::from(triangles) << 24)
}

/// A [`child_reference`]'s index and triangles.
#[inline(always)]
pub(super) fn reference_parts(reference: u32) -> (u32, u32) {
    (reference & INDEX_MASK, reference >> 24)
}

/// Which binary nodes become wide nodes: the collapse of Ylitie, Karras and Laine ("Efficient
/// incoherent ray traversal on GPUs through compressed wide BVHs", 2017) over fixed leaves.
///
/// Why not the greedy rule (open the child of largest area until a node has eight): it fills
/// the nodes near the root and starves the ones near the leaves. A full node whose child holds
/// a binary subtree of three leaves gives that child a wide node of three; on Sponza the greedy
/// tree's nodes held 4.5 children on average, and each opened node costs a full eight-lane box
/// test and a dependent memory access whatever it holds.
///
/// The cost of a wide tree whose leaves are given is the sum over its wide nodes of their box's
/// surface area (a node's box is opened with a probability proportional to it; each opening
/// costs one box test); the leaves' own cost is the same for every collapse. `cost[n][i - 1]`
/// is the least cost of binary node `n`'s subtree when it may take up to `i` of its wide
/// parent's eight slots: either one slot for a wide node of its own, or its two children
/// share the `i` slots (`n` itself then tested by nobody). A leaf takes one slot at no cost.
struct Plan {
    /// Per binary node: `0` where, given `i` slots, it is best a wide node of its own (always
    /// for one slot); else how many of the `i` slots go to its first child.
    split: Vec<[u8; WIDTH]>,
    /// Per inner binary node: how many of a wide node's eight slots go to its first child.
    split_own: Vec<u8>,
}

impl Plan {
    fn new(bvh: &Bvh2) -> Plan {
        let count = bvh.nodes.len();
        let mut cost = vec![[0.0f64; WIDTH]; count];
        let mut split = vec![[0u8; WIDTH]; count];
        let mut split_own = vec![0u8; count];
        for n in post_order(bvh) {
            let node = &bvh.nodes[n];
            if node.is_leaf() {
                continue;
            }
            let (first, second) = (node.first_index as usize, node.first_index as usize + 1);
            // `shared[j]`: the least cost of the two children in `j` slots, and the first's share.
            let mut shared = [(f64::INFINITY, 0u8); WIDTH + 1];
            for (j, best) in shared.iter_mut().enumerate().skip(2) {
                for k in 1..j {
                    let c = cost[first][k - 1] + cost[second][j - k - 1];
                    if c < best.0 {
                        *best = (c, k as u8);
                    }
                }
            }
            let own = f64::from(node.aabb().half_area()) + shared[WIDTH].0;
            split_own[n] = shared[WIDTH].1;
            cost[n][0] = own;
            for i in 2..=WIDTH {
                if shared[i].0 < own {
                    cost[n][i - 1] = shared[i].0;
                    split[n][i - 1] = shared[i].1;
                } else {
                    cost[n][i - 1] = own;
                }
            }
        }
        Plan { split, split_own }
    }

    /// The binary nodes that become the children of the wide node standing for `binary` (the
    /// root, or a node the plan made wide): leaves, and nodes that are wide nodes of their own.
    fn children(&self, bvh: &Bvh2, binary: usize, out: &mut Vec<usize>) {
        let node = &bvh.nodes[binary];
        if node.is_leaf() {
            // Only the root can be a leaf here: it becomes a node with that one leaf.
            out.push(binary);
            return;
        }
        let first = node.first_index as usize;
        let k = usize::from(self.split_own[binary]);
        self.frontier(bvh, first, k, out);
        self.frontier(bvh, first + 1, WIDTH - k, out);
    }

    /// The children that binary node `n`'s subtree gives its wide parent in `slots` slots.
    fn frontier(&self, bvh: &Bvh2, n: usize, slots: usize, out: &mut Vec<usize>) {
        let node = &bvh.nodes[n];
        let k = usize::from(self.split[n][slots - 1]);
        if node.is_leaf() || k == 0 {
            out.push(n);
        } else {
            let first = node.first_index as usize;
            self.frontier(bvh, first, k, out);
            self.frontier(bvh, first + 1, slots - k, out);
        }
    }
}

/// The binary tree's nodes, every node after its children.
fn post_order(bvh: &Bvh2) -> Vec<usize> {
    let mut order = Vec::with_capacity(bvh.nodes.len());
    // (node, whether its children are already listed)
    let mut stack = vec![(0usize, false)];
    while let Some((n, expanded)) = stack.pop() {
        let node = &bvh.nodes[n];
        if expanded || node.is_leaf() {
            order.push(n);
        } else {
            stack.push((n, true));
            let first = node.first_index as usize;
            stack.push((first + 1, false));
            stack.push((first, false));
        }
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Accel;
    use crate::geometry::BuildQuality;
    use crate::geometry::quad::LANES;
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
                    out.push(Triangle { p, material: 0 });
                }
            }
        }
        out
    }

    #[test]
    fn references_hold_indices_below_two_to_the_24_and_refuse_the_rest() {
        for (index, triangles) in [(0, 0), (1, 255), ((1 << 24) - 1, 7), (123_456, 4)] {
            let r = child_reference(index, triangles).expect("fits");
            let mut node = Node8::EMPTY;
            node.refs[3] = r;
            assert_eq!(
                (node.index(3), node.count(3)),
                (index as u32, u32::from(triangles))
            );
        }
        for index in [1 << 24, (1 << 24) + 5, u32::MAX as usize, usize::MAX] {
            assert_eq!(child_reference(index, 1), None, "{index}");
        }
    }

    #[test]
    fn the_wide_tree_holds_every_leaf_entry_once_in_nodes_of_up_to_eight() {
        for n in [1, 3, 40] {
            let triangles = grid(n);
            let accel = Accel::build(&triangles, BuildQuality::Medium);
            let wide = &accel.wide;
            let mut seen = vec![0u32; accel.leaf_entries()];
            for node in &wide.nodes {
                assert!(node.valid != 0 && node.valid.count_ones() as usize <= WIDTH);
                assert_eq!(u32::from(node.children), node.valid.count_ones());
                for lane in (0..WIDTH).filter(|&l| node.valid & (1 << l) != 0) {
                    if node.count(lane) == 0 {
                        continue;
                    }
                    let groups = (node.count(lane) as usize).div_ceil(LANES);
                    let first = node.index(lane) as usize;
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
                // A full 8-wide node replaces seven binary inner nodes. Near the leaves the
                // binary tree has too few levels left to fill one (a node above two leaf pairs
                // gets four children), so on this grid each replaces about 2.8 (a full 4-wide
                // node, three).
                let inner = accel.node_count() / 2;
                assert!(
                    wide.nodes.len() * 5 < inner * 2,
                    "{} wide nodes for {inner} binary inner ones",
                    wide.nodes.len(),
                );
            }
        }
    }

    /// The binary nodes the plan makes wide nodes: the root, then every inner node that a wide
    /// node takes as a child.
    fn wide_nodes(plan: &Plan, bvh: &Bvh2) -> Vec<usize> {
        let (mut wide, mut pending) = (Vec::new(), vec![0]);
        while let Some(n) = pending.pop() {
            wide.push(n);
            let mut children = Vec::new();
            plan.children(bvh, n, &mut children);
            pending.extend(children.into_iter().filter(|&c| !bvh.nodes[c].is_leaf()));
        }
        wide
    }

    /// The least summed area of a valid choice of wide nodes, by trying every subset of the
    /// inner nodes below the root: valid when each chosen node, the root included, reaches at
    /// most eight leaves or chosen nodes without passing another chosen one.
    fn brute_force_least_area(bvh: &Bvh2) -> f64 {
        let inner: Vec<usize> = (1..bvh.nodes.len())
            .filter(|&n| !bvh.nodes[n].is_leaf())
            .collect();
        let area = |n: usize| f64::from(bvh.nodes[n].aabb().half_area());
        let mut best = f64::INFINITY;
        for subset in 0u32..1 << inner.len() {
            let chosen = |n: usize| {
                n == 0
                    || inner
                        .iter()
                        .position(|&i| i == n)
                        .is_some_and(|k| subset & 1 << k != 0)
            };
            // The slots below a chosen node: its children, opened down to leaves and chosen nodes.
            let slots = |n: usize| {
                let first = bvh.nodes[n].first_index as usize;
                let (mut count, mut open) = (0, vec![first, first + 1]);
                while let Some(c) = open.pop() {
                    if bvh.nodes[c].is_leaf() || chosen(c) {
                        count += 1;
                    } else {
                        let f = bvh.nodes[c].first_index as usize;
                        open.extend([f, f + 1]);
                    }
                }
                count
            };
            let wide: Vec<usize> = std::iter::once(0)
                .chain(inner.iter().copied().filter(|&n| chosen(n)))
                .collect();
            if wide.iter().all(|&n| slots(n) <= WIDTH) {
                best = best.min(wide.iter().map(|&n| area(n)).sum());
            }
        }
        best
    }

    #[test]
    fn the_collapse_chooses_the_wide_nodes_of_least_summed_area_that_brute_force_finds() {
        // Random triangle soups of many sizes and shapes (a cube of small triangles, long
        // slivers among them, a flat sheet): each tree small enough to try every choice.
        let mut compared = 0;
        let mut state = 0x00c0_11a9;
        for case in 0..60 {
            let mut next = || crate::geometry::build::tests::next(&mut state);
            let count = 6 + case % 40;
            let triangles: Vec<Triangle> = (0..count)
                .map(|i| {
                    let a =
                        Vec3::new(next(), next(), if case % 3 == 0 { 0.0 } else { next() }) * 10.0;
                    let reach = if i % 5 == 0 { 4.0 } else { 0.6 };
                    let d = Vec3::new(next(), next(), next()) * reach;
                    let e = Vec3::new(next(), next(), next()) * 0.6;
                    Triangle {
                        p: [a, a + d, a + e],
                        material: 0,
                    }
                })
                .collect();
            let accel = Accel::build(
                &triangles,
                BuildQuality::ALL[case % BuildQuality::ALL.len()],
            );
            let bvh = &accel.binary_tree().bvh;
            let inner = bvh.nodes.iter().skip(1).filter(|n| !n.is_leaf()).count();
            if bvh.nodes[0].is_leaf() || inner > 14 {
                continue;
            }
            let plan = Plan::new(bvh);
            let wide = wide_nodes(&plan, bvh);
            let ours: f64 = wide
                .iter()
                .map(|&n| f64::from(bvh.nodes[n].aabb().half_area()))
                .sum();
            let least = brute_force_least_area(bvh);
            assert!(
                (ours - least).abs() <= 1e-9 * least,
                "case {case}: {} wide nodes of summed area {ours}, brute force {least}",
                wide.len()
            );
            // And the wide tree built from the plan is that choice.
            assert_eq!(accel.wide.nodes.len(), wide.len(), "case {case}");
            compared += 1;
        }
        assert!(
            compared >= 30,
            "only {compared} trees small enough to compare"
        );
    }
}
