//! The wide tree the renderer traverses: obvhs's binary tree collapsed into nodes of up to eight
//! children (`collapse.rs` chooses which), whose eight boxes are tested against a ray at once
//! (`node8.rs`: one AVX step where the processor has AVX, two SSE steps where not, with the same
//! results bit for bit).
//!
//! Why 8 wide: on large meshes the traversal waits mostly on memory, one node after another, and
//! a tree of eight-child nodes is about two thirds as deep as one of four; on x86-64 with AVX its
//! eight boxes cost one step, as four did with SSE. Why the choice at run time rather than
//! `target-cpu` flags: those would make the binary's instructions depend on the machine that
//! built it (see `node8.rs`).
//!
//! **Exactness.** Each lane of the box test evaluates exactly the expressions of the binary
//! traversal's slab test (`SlabRay::enter` in `traverse.rs`) for its box, so a box is entered
//! exactly when the binary test enters it, at the same distance (`node8.rs` says why, for both
//! instruction sets). The tree only decides which leaves are opened, and in which order; since
//! culling is conservative and [`Closest::offer`] breaks ties in `t` by triangle index, the
//! closest hit (and whether a shadow ray is blocked) is the one brute force finds, whatever the
//! order. Tests render the same images through both trees, and through both box tests, bit for
//! bit.
//!
//! Leaves are the binary tree's leaves, the same runs of its leaf entries, packed four triangles
//! to a group for the SIMD triangle test of `quad.rs` (with AVX, a leaf's first two groups in one
//! step of eight lanes, `quad_avx.rs`); the scalar test, which settles what the SIMD one leaves,
//! reads its triangle from the group's lanes ([`Quad::triangle`]), so the wide walk needs no
//! other copy of the vertices, and the binary tree's can be freed
//! ([`Accel::release_binary_tree`]).

use super::bvh::Accel;
use super::closest::Closest;
use super::collapse::reference_parts;
use super::memory::prefetch;
#[cfg(target_arch = "x86_64")]
use super::node8::Avx;
use super::node8::{BoxTest, Node8, Portable, WIDTH, avx_available};
use super::packed_hit::PackedHit;
use super::quad::{LANES, Quad, QuadRay};
use super::ray_setup::{SetUpRows, WideRay};
use super::traverse::FAR_SCALE;
use super::{Hit, Ray, TraversalStats};
use std::mem::MaybeUninit;

/// The instructions that test a node's boxes and a leaf's triangles: AVX where the processor
/// has it (eight boxes, and two groups of four triangles, per step), else SSE (or plain code
/// off x86-64). Either gives the same results bit for bit; only speed differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BoxSimd {
    /// Two steps of four lanes: SSE2 on x86-64 (every x86-64 processor), plain code elsewhere.
    Sse,
    /// One step of eight lanes.
    Avx,
}

/// The collapsed tree. Node 0 is the root; an empty tree has no nodes.
#[derive(Clone, Debug)]
pub(super) struct Bvh8 {
    pub(super) nodes: Vec<Node8>,
    /// The leaves' triangles, four to a group, each leaf's groups in a run.
    pub(super) quads: Vec<Quad>,
    /// Levels of 8-wide nodes on the deepest path (0 when empty): bounds the traversal stack.
    pub(super) depth: usize,
    /// Whether every child's index fitted in its reference (`collapse::child_reference`);
    /// where not, the tree is left empty and never walked ([`Bvh8::walkable`]).
    pub(super) references_fit: bool,
    /// How boxes are tested: AVX where this processor has it.
    pub(super) simd: BoxSimd,
}

impl Default for Bvh8 {
    fn default() -> Self {
        Bvh8 {
            nodes: Vec::new(),
            quads: Vec::new(),
            depth: 0,
            references_fit: true,
            simd: best_simd(),
        }
    }
}

/// The fastest box test this processor runs.
pub(super) fn best_simd() -> BoxSimd {
    if avx_available() {
        BoxSimd::Avx
    } else {
        BoxSimd::Sse
    }
}

/// A child waiting on the traversal's stack, or the one being visited: an inner node, or a
/// leaf's run of triangle groups.
#[derive(Clone, Copy)]
struct StackEntry {
    /// The child's reference (`Node8::refs`): its index and its leaf's triangles.
    reference: u32,
    /// Where the ray enters the child's box.
    t_near: f32,
}

/// Stack entries held in place: a node pushes its entered children (at most eight) and pops
/// the nearest at once, so each level of the current path leaves at most seven, and the
/// deepest node briefly eight; obvhs's trees of real scenes collapse to far fewer than 30
/// levels.
pub(super) const INLINE_STACK: usize = (WIDTH - 1) * 30 + 1;

/// The stack a walk of the wide tree takes, for the single-ray walk and the packet walk alike:
/// [`INLINE_STACK`] entries in place, uninitialised (filling 211 entries per ray would cost
/// more than a node test). A tree too deep for it is never walked wide
/// ([`Bvh8::walkable`]), so the walks carry no heap fallback: no allocator's state
/// to set up per ray, and no release of it at every return.
pub(super) type WalkStack<E> = [MaybeUninit<E>; INLINE_STACK];

impl Bvh8 {
    /// Whether the wide walks take this tree: every walk's pushes fit in a [`WalkStack`] (at
    /// most `7 * depth + 1` entries, see [`INLINE_STACK`]) and every child's index fitted in
    /// its reference (`collapse::child_reference`). Where not (trees no real scene has come
    /// near: thirty levels of wide nodes, or 2^24 nodes or groups, some 67 million
    /// triangles), the rays are walked through the binary tree instead, which finds the same
    /// hits, bit for bit.
    #[inline(always)]
    pub(super) fn walkable(&self) -> bool {
        self.references_fit && (WIDTH - 1) * self.depth < INLINE_STACK
    }
}

/// A walk's set-up made ahead of it: lane `r` of rows made with the ray's own eight (see
/// [`SetUpRows`]); `None` where the walk makes its own.
pub(crate) type SetUp<'a> = Option<(&'a SetUpRows, usize)>;

impl Accel {
    /// Closest hit (or, with `ANY_HIT`, the first certain hit found) by the wide traversal,
    /// with the box test [`Bvh8::simd`] names.
    ///
    /// Inlined into its callers, so that the hit comes back from the traversal proper (never
    /// inlined: AVX code cannot be, and it is large) in two registers ([`PackedHit`]) and is
    /// unpacked in the caller's registers.
    #[inline(always)]
    pub(super) fn traverse_wide<const ANY_HIT: bool, const CERTAIN: bool>(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        if !self.wide.walkable() {
            return self.traverse_robust::<ANY_HIT, CERTAIN>(ray, stats);
        }
        if self.wide.nodes.is_empty() {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        if self.wide.simd == BoxSimd::Avx {
            // SAFETY: `simd` is `Avx` only where `is_x86_feature_detected!("avx")` said yes
            // (`best_simd`, `Accel::set_box_simd`).
            return unsafe { self.traverse_avx::<ANY_HIT, CERTAIN>(ray, set_up, stats) }.unpack();
        }
        self.traverse_portable::<ANY_HIT, CERTAIN>(ray, set_up, stats)
            .unpack()
    }

    /// The traversal with the portable box test (SSE on x86-64).
    #[inline(never)]
    fn traverse_portable<const ANY_HIT: bool, const CERTAIN: bool>(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        stats: &mut TraversalStats,
    ) -> PackedHit {
        PackedHit::pack(self.traverse_with::<ANY_HIT, CERTAIN, Portable>(ray, set_up, stats))
    }

    /// The traversal compiled with AVX enabled: its box test and its test of two triangle
    /// groups inlined as AVX instructions, and the rest of it (the four-lane triangle test of a
    /// leaf's last odd group, the scalar code) VEX-encoded, which runs the same IEEE operations. No fused multiply-add: that is a separate feature, not enabled, and Rust
    /// never contracts a multiplication and an addition on its own.
    ///
    /// # Safety
    /// The processor must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline(never)]
    unsafe fn traverse_avx<const ANY_HIT: bool, const CERTAIN: bool>(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        stats: &mut TraversalStats,
    ) -> PackedHit {
        PackedHit::pack(self.traverse_with::<ANY_HIT, CERTAIN, Avx>(ray, set_up, stats))
    }

    #[inline(always)]
    fn traverse_with<const ANY_HIT: bool, const CERTAIN: bool, B: BoxTest>(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        // Counted in a local copy, written back once: through `stats` itself, every node's
        // count was a store to the caller's memory, which LLVM may not keep in a register.
        let mut counted = *stats;
        let mut stack: WalkStack<StackEntry> = [MaybeUninit::uninit(); INLINE_STACK];
        let copy;
        let (ray, wide, quad_ray) = match set_up {
            Some((rows, lane)) => {
                let (wide, quad_ray) = rows.lane(lane);
                (ray, wide, quad_ray)
            }
            None => {
                copy = ray.read_apart();
                (&copy, WideRay::new(&copy), QuadRay::for_ray(&copy))
            }
        };
        let hit = self.wide_with_stack::<ANY_HIT, CERTAIN, B>(
            (ray, &wide, &quad_ray),
            &mut counted,
            &mut stack,
        );
        *stats = counted;
        hit
    }

    /// The traversal proper: Embree's order. A node's entered children go onto the stack
    /// sorted by entry distance, the nearest on top, and the walk goes on at the top: an inner
    /// node is tested, a leaf's triangles are, then the next nearest child that may still hold
    /// a closer hit. Leaves are children like the others, so a leaf behind a nearer subtree
    /// waits until that subtree has had its chance to move the closest hit in front of it.
    /// An any-hit query stops at any hit, so it tests a node's leaves at once and leaves the
    /// rest unsorted.
    ///
    /// `stack` holds at least `7 * depth + 1` entries (see [`Bvh8::walkable`]).
    /// Entries below `len` are always initialised: every push writes one before `len` grows
    /// past it.
    #[inline(always)]
    fn wide_with_stack<const ANY_HIT: bool, const CERTAIN: bool, B: BoxTest>(
        &self,
        (ray, wide, quad_ray): (&Ray, &WideRay, &QuadRay),
        stats: &mut TraversalStats,
        stack: &mut [MaybeUninit<StackEntry>],
    ) -> Option<Hit> {
        let nodes = &self.wide.nodes;
        let mut closest = Closest::new(ray, CERTAIN);
        let cull = |closest: &Closest| closest.t_max() * FAR_SCALE;
        let mut current = StackEntry {
            reference: 0,
            t_near: 0.0,
        };
        let mut len = 0usize;
        loop {
            let (child, count) = reference_parts(current.reference);
            if count > 0 {
                // SAFETY: every entry with triangles is a lane of a node of this tree (pushed
                // below from `node.refs`), and this one has some.
                if unsafe {
                    self.test_leaf::<ANY_HIT, B>(child, count, ray, quad_ray, &mut closest, stats)
                } && ANY_HIT
                {
                    return closest.best;
                }
            } else {
                // SAFETY: the `child` of an entry with no triangles is an inner node's
                // index, which `Bvh8::collapse` set to a slot of `nodes` it had pushed (a leaf
                // never has 0 triangles: obvhs's leaves hold at least one), or the root's 0,
                // which exists since the empty tree returned above.
                let node = unsafe { nodes.get_unchecked(child as usize) };
                stats.nodes += u64::from(node.children);
                let (mut entered, t_near) = B::enter(wide, node, cull(&closest));
                let base = len;
                while entered != 0 {
                    let lane = entered.trailing_zeros() as usize;
                    entered &= entered - 1;
                    let entry = StackEntry {
                        reference: node.refs[lane],
                        t_near: t_near[lane],
                    };
                    let (child, count) = reference_parts(entry.reference);
                    self.prefetch_child(child, count);
                    if ANY_HIT && count > 0 {
                        // SAFETY: a lane of this node, with triangles.
                        if unsafe {
                            self.test_leaf::<ANY_HIT, B>(
                                child,
                                count,
                                ray,
                                quad_ray,
                                &mut closest,
                                stats,
                            )
                        } {
                            return closest.best;
                        }
                        continue;
                    }
                    // Keeping this node's run of the stack farthest first; an any-hit query
                    // leaves it unsorted (a run that starts at the top sorts nothing).
                    let run = if ANY_HIT { len } else { base };
                    // SAFETY: `run <= len`, entries below `len` are written, and `len <
                    // stack.len()`: each level of the current path leaves at most seven
                    // entries and the deepest pushes eight, so `len` never passes
                    // `7 * depth + 1`, which the stack holds.
                    unsafe { push_sorted(stack, run, len, entry, |e| e.t_near) };
                    len += 1;
                }
                if len > base {
                    // The nearest entered child, entered within the current search interval.
                    len -= 1;
                    // SAFETY: written by the pushes above.
                    current = unsafe { stack.get_unchecked(len).assume_init() };
                    continue;
                }
            }
            // Resume at the nearest postponed child that may still hold a closer hit.
            loop {
                if len == 0 {
                    return closest.best;
                }
                len -= 1;
                // SAFETY: entries below the old `len` were written by the pushes above.
                let entry = unsafe { stack.get_unchecked(len).assume_init() };
                if entry.t_near <= cull(&closest) {
                    current = entry;
                    break;
                }
            }
        }
    }

    /// Asks for the memory of a child the ray entered (an inner node's four cache lines, a
    /// leaf's first two groups) before any of it is read. On large meshes the traversal waits
    /// mostly on cache misses: the next node's address is known only once its parent is
    /// tested, and a leaf's triangles only once its box is. Asking for all of a node's entered
    /// children at once lets their misses overlap. A prefetch reads nothing into the
    /// computation, so it cannot change a result.
    #[inline(always)]
    pub(super) fn prefetch_child(&self, child: u32, count: u32) {
        // Written out line by line: a loop over a count costs more instructions than the
        // prefetches themselves, once per entered child.
        if count > 0 {
            // A group is three whole lines (`Quad` is aligned to them); a leaf of five or more
            // triangles has a second group, tested in the same step with AVX.
            let start = address_of(&self.wide.quads, child);
            prefetch(start);
            prefetch(start.wrapping_add(64));
            prefetch(start.wrapping_add(128));
            if count as usize > LANES {
                prefetch(start.wrapping_add(192));
                prefetch(start.wrapping_add(256));
                prefetch(start.wrapping_add(320));
            }
        } else {
            let start = address_of(&self.wide.nodes, child);
            prefetch(start);
            prefetch(start.wrapping_add(64));
            prefetch(start.wrapping_add(128));
            prefetch(start.wrapping_add(192));
        }
    }
}

/// Pushes `entry` onto `stack` above its `len` entries, keeping the run from `run` (a node's
/// entered children) ordered farthest first by `distance`, so that the nearest is on top: an
/// insertion, which for the few children of a node beats any sort. The single-ray and the
/// packet traversals both push through it.
///
/// # Safety
/// `run <= len < stack.len()`, and the entries below `len` are initialised.
#[inline(always)]
pub(super) unsafe fn push_sorted<E: Copy>(
    stack: &mut [MaybeUninit<E>],
    run: usize,
    len: usize,
    entry: E,
    distance: impl Fn(&E) -> f32,
) {
    let mut k = len;
    while k > run {
        // SAFETY: `run <= k - 1 < len`: initialised (the contract).
        let below = unsafe { stack.get_unchecked(k - 1).assume_init() };
        if distance(&below) >= distance(&entry) {
            break;
        }
        // SAFETY: `k <= len < stack.len()` (the contract).
        unsafe { stack.get_unchecked_mut(k) }.write(below);
        k -= 1;
    }
    // SAFETY: as above.
    unsafe { stack.get_unchecked_mut(k) }.write(entry);
}

/// Where `items[index]` starts, for a prefetch: computed without a bounds check, since a hint
/// never reads (and never faults, even past the end).
#[inline(always)]
fn address_of<T>(items: &[T], index: u32) -> *const u8 {
    items.as_ptr().wrapping_add(index as usize).cast()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{BuildQuality, PACKET, intersect_brute_force, occluded_brute_force};
    use crate::scene::Triangle;
    use glam::Vec3;

    /// Triangles along the x axis at geometrically shrinking distances from the origin, each
    /// half as large as the one before: a tree over them is many levels deep.
    fn chain(n: usize) -> Vec<Triangle> {
        (0..n)
            .map(|k| {
                let s = 0.5f32.powi(k as i32);
                Triangle {
                    p: [
                        Vec3::new(s, -s, -s),
                        Vec3::new(s, s, -s),
                        Vec3::new(s, 0.0, s),
                    ],
                    material: 0,
                }
            })
            .collect()
    }

    #[test]
    fn trees_the_wide_walks_do_not_take_are_walked_through_the_binary_tree_with_the_same_hits() {
        let triangles = chain(120);
        // No tree of real scenes outgrows the inline stack (thirty levels of wide nodes) or the
        // references (2^24 nodes or groups), so each is made so: the depth the walks check
        // raised past the stack, and the tree the collapse leaves where its indices outgrow
        // the references. Single rays and packets alike are then walked through the binary
        // tree, as such a tree's would be.
        for too_large in [false, true] {
            let mut accel = Accel::build(&triangles, BuildQuality::default());
            assert!(accel.wide.walkable());
            if too_large {
                accel.wide = Bvh8::unwalkable();
            } else {
                accel.wide.depth = accel.wide.depth.max(INLINE_STACK / (WIDTH - 1) + 1);
            }
            assert!(!accel.wide.walkable());
            assert!(!accel.release_binary_tree(), "the binary tree is kept");
            same_hits_as_brute_force(accel, &triangles);
        }
    }

    /// Rays through `chain` triangles find the brute-force hits through `accel`, alone and in
    /// packets, with either box test.
    fn same_hits_as_brute_force(mut accel: Accel, triangles: &[Triangle]) {
        // Rays from beyond the largest triangle back toward the origin, through the
        // triangles' planes at several slants, and segments ending between triangles.
        let rays: Vec<Ray> = (0..200)
            .map(|i| {
                let a = i as f32 * 0.031;
                Ray {
                    origin: Vec3::new(2.0, 0.01 * a.cos(), 0.0),
                    dir: Vec3::new(-1.0, 0.3 * a.sin(), 0.3 * a.cos() - 0.1),
                    t_max: if i % 2 == 0 {
                        f32::INFINITY
                    } else {
                        1.0 + 0.005 * i as f32
                    },
                }
            })
            .collect();
        let mut hits = 0;
        for simd in [BoxSimd::Sse, BoxSimd::Avx] {
            if !accel.set_box_simd(simd) {
                continue;
            }
            let mut stats = TraversalStats::default();
            for ray in &rays {
                let hit = accel.intersect(ray, &mut stats);
                assert_eq!(
                    hit,
                    intersect_brute_force(triangles, ray),
                    "{simd:?} {ray:?}"
                );
                hits += usize::from(hit.is_some());
                assert_eq!(
                    accel.occluded(ray, &mut stats),
                    occluded_brute_force(triangles, ray),
                    "{simd:?} {ray:?}"
                );
            }
            // The packet walk checks the same.
            for packet in rays.chunks(PACKET) {
                let mut found = [None; PACKET];
                accel.intersect_packet(packet, &mut found[..packet.len()], &mut stats);
                for (ray, hit) in packet.iter().zip(found) {
                    assert_eq!(
                        hit,
                        intersect_brute_force(triangles, ray),
                        "{simd:?} packet"
                    );
                }
            }
        }
        assert!(hits > 100, "the rays must find triangles: {hits} hits");
    }
}
