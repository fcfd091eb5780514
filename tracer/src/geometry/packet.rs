//! Closest hits of up to eight rays walked through the wide tree together: a packet. Meant for
//! rays that travel side by side, as the camera rays of one pixel's samples do, so that each
//! node on their common way is fetched from memory, tested and put on the stack once for all
//! of them: each of a node's boxes is tested against the eight rays in one step
//! ([`BoxTest::enter_child`]), where the single-ray traversal tests eight boxes against one.
//! Rays whose directions do not share their signs (whose boxes' near planes differ) are not
//! made into a packet: each is traced alone.
//!
//! A leaf reached by at least two thirds as many of the packet's rays as it has triangles is
//! tested a triangle at a time against all of them, one ray per lane (`quad_avx.rs`, with AVX,
//! where the rays permute the axes alike), rather than each ray against the leaf's triangles
//! four or eight at a time: a pixel's rays mostly reach the same leaves, and there one step
//! answers eight rays.
//!
//! **Exactness.** A packet changes only which nodes each ray is tested against and in which
//! order, never how: lane `r` of a packet's box test computes exactly what the single-ray box
//! test computes for ray `r` and that box, with the ray's own current end of search, and a
//! leaf is tested for each ray by the very leaf test ([`Accel::test_leaf`], with the ray's own
//! set-up and its own [`Closest`]), or by the lanes that compute, for each ray and
//! triangle, what that leaf test's lanes compute (`Accel::leaf_against_rays`). A ray goes down
//! to a child only if its own box test entered the child's box, and culling is conservative,
//! so the leaf holding its closest hit is always tested for it. Since [`Closest`] breaks ties
//! in `t` by triangle index, each ray's hit is the one the single-ray traversal (and brute
//! force) finds, to the bit, whatever its companions. `tracer/tests/packet_traversal.rs` holds
//! the two to each other ray by ray and image by image.
//!
//! Work is counted per ray, as done: a node's boxes for every ray that reached it, a leaf's
//! triangles for every ray tested against it. It depends on the companions (the order of the
//! walk is the packet's), so the renderer makes packets of one pixel's samples only.

use super::bvh::Accel;
use super::closest::Closest;
#[cfg(target_arch = "x86_64")]
use super::node8::Avx;
use super::node8::{BoxTest, Portable, WIDTH};
use super::packet_box::{PacketBound, PacketRays, within};
use super::quad::{LANES, QuadRay};
use super::traverse::FAR_SCALE;
use super::triangle::ShearedRay;
use super::wide::{BoxSimd, INLINE_STACK, WalkStack, push_sorted};
use super::{Hit, Ray, TraversalStats};
use std::mem::MaybeUninit;
use wide::f32x4;

/// The most rays in one packet: one bit each in a byte of ray masks.
pub const PACKET: usize = 8;

/// A child waiting on the packet's stack, or the one being visited.
#[derive(Clone, Copy)]
struct PacketEntry {
    /// An inner node's index in `Bvh8::nodes`, or a leaf's first group in `Bvh8::quads`.
    child: u32,
    /// The leaf's triangles; 0 for an inner node.
    count: u32,
    /// Bit `r` set when ray `r` entered the child's box.
    rays: u32,
    /// The entry distance of the lowest of those rays, by which the stack is ordered.
    order: f32,
    /// Each ray's entry distance (meaningful for the rays in `rays`).
    t_near: [f32; WIDTH],
}

impl Accel {
    /// The closest hit of each of `rays` (one to [`PACKET`] of them) into the same slot of
    /// `hits`, as [`Accel::intersect`] finds it, to the bit: by the wide traversal, the rays
    /// walked together where their directions share their signs, else one by one. Worth it
    /// for rays that travel side by side; any rays give the right hits.
    pub fn intersect_packet(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) {
        assert!(
            !rays.is_empty() && rays.len() <= PACKET && hits.len() == rays.len(),
            "a packet holds one to eight rays, with a slot for each one's hit"
        );
        // A tree the wide walks do not take (`Bvh8::walkable`) is walked ray by ray, through
        // the binary tree.
        if self.wide.walkable() && self.wide.nodes.is_empty() {
            hits.fill(None);
            return;
        }
        let together = self.wide.walkable() && self.packet_walk(rays, hits, stats);
        if !together {
            for (ray, hit) in rays.iter().zip(hits) {
                *hit = self.intersect(ray, stats);
            }
        }
    }

    /// The packet walk with the box test [`Bvh8::simd`](super::wide::Bvh8) names; `false`
    /// where the rays cannot be walked together.
    #[inline(always)]
    fn packet_walk(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.wide.simd == BoxSimd::Avx {
            // SAFETY: `simd` is `Avx` only where `is_x86_feature_detected!("avx")` said yes
            // (`best_simd`, `Accel::set_box_simd`).
            return unsafe { self.packet_avx(rays, hits, stats) };
        }
        self.packet_portable(rays, hits, stats)
    }

    /// The packet walk with the portable box test (SSE on x86-64).
    #[inline(never)]
    fn packet_portable(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) -> bool {
        self.packet_with::<Portable>(rays, hits, stats)
    }

    /// The packet walk compiled with AVX, as `Accel::traverse_avx` is and for the same reasons.
    ///
    /// # Safety
    /// The processor must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline(never)]
    unsafe fn packet_avx(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) -> bool {
        self.packet_with::<Avx>(rays, hits, stats)
    }

    #[inline(always)]
    fn packet_with<B: BoxTest>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) -> bool {
        // The stack as `Accel::traverse_with` takes it, from a `WalkStack` rather than through
        // a closure: a closure is compiled without the AVX target feature of the function it
        // sits in, so the AVX box and triangle tests inside it became calls (the box's rays,
        // 769 to 910 instructions each, when tried).
        let mut counted = *stats;
        let mut stack: WalkStack<PacketEntry> = [MaybeUninit::uninit(); INLINE_STACK];
        let together = self.packet_with_stack::<B>(rays, hits, &mut counted, &mut stack);
        *stats = counted;
        together
    }

    /// The walk proper, in the single-ray traversal's order (`Accel::wide_with_stack`): a
    /// node's entered children onto the stack sorted by entry distance, the nearest on top,
    /// then on at the top. `stack` holds at least `7 * depth + 1` entries, as there. Returns
    /// `false`, having done nothing, where the rays' directions do not share their signs.
    #[inline(always)]
    fn packet_with_stack<B: BoxTest>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
        stack: &mut [MaybeUninit<PacketEntry>],
    ) -> bool {
        let last = rays.len() - 1;
        let ray = |r: usize| &rays[r.min(last)];
        let rows = B::gather(rays);
        let Some(packet) = PacketRays::from_rows(&rows) else {
            return false;
        };
        let bound = packet_bound(&packet);
        // The rays in lanes, for leaves tested a triangle against all of them at once: where
        // the box test has that step (AVX) and the rays permute the axes alike, as a pixel's
        // camera rays nearly always do.
        let lanes = B::ray_lanes(&rows);
        // Each ray's own triangle set-up, for the leaves tested ray by ray: made once per ray
        // where the packet has no lanes (no AVX, or rays permuting the axes differently) and
        // every leaf comes here; where it has lanes, made again at each of the few leaves
        // that reach here (few of its rays reach them). The same bits either way: a function
        // of the ray alone.
        let quad_rays: Option<[QuadRay; PACKET]> = lanes
            .is_none()
            .then(|| per_ray(|r| QuadRay::for_ray(ray(r))));
        let mut closest: [Closest; PACKET] = per_ray(|r| Closest::new(ray(r), false));
        let cull = |closest: &Closest| closest.t_max() * FAR_SCALE;
        // Each ray's current end of search for the box tests.
        let mut end: [f32; PACKET] = per_ray(|r| cull(&closest[r]));
        // The farthest of those ends, for the filter; kept, and taken again only when a leaf
        // has moved an end (ends only ever come nearer).
        let farthest_of =
            |end: &[f32; PACKET]| end.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        let mut farthest = farthest_of(&end);
        let nodes = &self.wide.nodes;
        let mut current = PacketEntry {
            child: 0,
            count: 0,
            rays: (1u32 << rays.len()) - 1,
            order: 0.0,
            t_near: [0.0; WIDTH],
        };
        let mut len = 0usize;
        loop {
            if current.count > 0 {
                // The lanes take a step per triangle whatever the rays, the leaf test a step
                // per ray and group of four (or pair of groups), so the lanes pay where the
                // rays that reached the leaf are not few against its triangles. Two thirds or
                // more: of the thresholds tried (a half, two thirds, one, five quarters),
                // cachegrind counted the fewest instructions there on the box and on Sponza,
                // whose packets part ways more often (docs/bench.md, issue 12, twenty-fourth
                // round).
                let mut moved = if let Some(lanes) = lanes
                    .as_ref()
                    .filter(|_| current.rays.count_ones() * 3 >= current.count * 2)
                {
                    self.leaf_against_rays::<B>(&current, lanes, rays, &mut closest, stats)
                } else {
                    let (mut waiting, mut moved) = (current.rays, 0u32);
                    while waiting != 0 {
                        let r = waiting.trailing_zeros() as usize;
                        waiting &= waiting - 1;
                        let quad_ray = match &quad_rays {
                            Some(quad_rays) => quad_rays[r],
                            None => QuadRay::for_ray(&rays[r]),
                        };
                        // SAFETY: as for the single-ray walk: a leaf entry of this tree.
                        if unsafe {
                            self.test_leaf::<false, B>(
                                current.child,
                                current.count,
                                &rays[r],
                                &quad_ray,
                                &mut closest[r],
                                stats,
                            )
                        } {
                            moved |= 1 << r;
                        }
                    }
                    moved
                };
                if moved != 0 {
                    while moved != 0 {
                        let r = moved.trailing_zeros() as usize;
                        moved &= moved - 1;
                        end[r] = cull(&closest[r]);
                    }
                    farthest = farthest_of(&end);
                }
            } else {
                // SAFETY: `current.child` of an entry with no triangles is an inner node's
                // index, which `Bvh8::collapse` set to a slot of `nodes` it had pushed.
                let node = unsafe { nodes.get_unchecked(current.child as usize) };
                stats.nodes += u64::from(node.children) * u64::from(current.rays.count_ones());
                let base = len;
                let mut children = match &bound {
                    Some(bound) => B::enter_bound(bound, node, farthest),
                    None => u32::from(node.valid),
                };
                while children != 0 {
                    let lane = children.trailing_zeros() as usize;
                    children &= children - 1;
                    let (entered, t_near) = B::enter_child(&packet, node, lane, &end);
                    let entered = entered & current.rays;
                    if entered == 0 {
                        continue;
                    }
                    let entry = PacketEntry {
                        child: node.index(lane),
                        count: node.count(lane),
                        rays: entered,
                        order: t_near[entered.trailing_zeros() as usize],
                        t_near,
                    };
                    self.prefetch_child(entry.child, entry.count);
                    // SAFETY: `base <= len`, entries below `len` are written, and `len <
                    // stack.len()`, as in `Accel::wide_with_stack`: each level of the current
                    // path leaves at most seven entries.
                    unsafe { push_sorted(stack, base, len, entry, |e| e.order) };
                    len += 1;
                }
            }
            // On at the nearest waiting child that may still hold a closer hit for one of
            // the rays that entered it; the others leave the entry.
            loop {
                if len == 0 {
                    for (hit, closest) in hits.iter_mut().zip(&closest) {
                        *hit = closest.best;
                    }
                    return true;
                }
                len -= 1;
                // SAFETY: entries below the old `len` were written by the pushes above.
                let mut entry = unsafe { stack.get_unchecked(len).assume_init() };
                entry.rays &= within(&entry.t_near, &end);
                if entry.rays != 0 {
                    current = entry;
                    break;
                }
            }
        }
    }
}

impl Accel {
    /// The leaf `entry` names tested for each of its rays, a triangle against all of them at
    /// once ([`BoxTest::triangle_against_rays`]); returns the rays whose closest hit it moved.
    ///
    /// For each ray this offers exactly what [`Accel::test_leaf`] offers it, in the same order:
    /// every candidate triangle of the leaf, group by group and lane by lane, with the SIMD
    /// test's own hit where that lane is exact and through the scalar test where not (the
    /// order would not matter anyway: [`Closest::offer`]'s tie rule). It counts what
    /// `test_leaf` counts for a closest-hit query, the leaf's triangles once per ray.
    #[inline(always)]
    fn leaf_against_rays<B: BoxTest>(
        &self,
        entry: &PacketEntry,
        lanes: &B::RayLanes,
        rays: &[Ray],
        closest: &mut [Closest; PACKET],
        stats: &mut TraversalStats,
    ) -> u32 {
        let groups = (entry.count as usize).div_ceil(LANES);
        let first = entry.child as usize;
        let mut moved = 0u32;
        for quad in &self.wide.quads[first..first + groups] {
            for i in 0..quad.len as usize {
                let hits = B::triangle_against_rays(lanes, quad, i, entry.rays);
                let original = quad.original[i];
                // Only rays of `entry.rays` can be candidates: it is the test's `valid`.
                let mut candidates = hits.candidates;
                while candidates != 0 {
                    let r = candidates.trailing_zeros() as usize;
                    candidates &= candidates - 1;
                    let kept = if hits.exact & (1 << r) != 0 {
                        closest[r].offer_hit(hits.hit(r), original)
                    } else {
                        closest[r].offer(&ShearedRay::new(&rays[r]), &quad.triangle(i), original)
                    };
                    if kept {
                        moved |= 1 << r;
                        self.prefetch_hit(original);
                    }
                }
            }
        }
        stats.triangles += u64::from(entry.count) * u64::from(entry.rays.count_ones());
        moved
    }
}

/// The interval the rays of `packet` span (all its lanes: slots past its rays repeat its last
/// one), for the test that rejects at once the boxes none of them enters; `None` where a
/// reciprocal direction is infinite, zero or NaN, or an origin NaN, for which that test's
/// argument (no NaN arises) does not hold.
#[inline(always)]
pub(super) fn packet_bound(packet: &PacketRays) -> Option<PacketBound> {
    let mut bound = PacketBound {
        origin_near: [0.0; 3],
        origin_far: [0.0; 3],
        inv_low: [0.0; 3],
        inv_high: [0.0; 3],
        near: packet.near,
        far: packet.far,
    };
    let mut usable = true;
    for axis in 0..3 {
        let (origin_low, origin_high) = least_and_greatest(&packet.origin[axis]);
        let (inv_low, inv_high) = least_and_greatest(&packet.inv_dir[axis]);
        usable &= inv_low.is_finite() && inv_high.is_finite() && inv_low != 0.0 && inv_high != 0.0;
        usable &= !origin_low.is_nan() && !origin_high.is_nan();
        // With positive reciprocals (the near plane the min, row `axis`) the entry distance is
        // least from the greatest origin and the exit distance greatest from the least; with
        // negative ones the other way round.
        let positive = packet.near[axis] == axis;
        bound.origin_near[axis] = if positive { origin_high } else { origin_low };
        bound.origin_far[axis] = if positive { origin_low } else { origin_high };
        bound.inv_low[axis] = inv_low;
        bound.inv_high[axis] = inv_high;
    }
    usable.then_some(bound)
}

/// The least and the greatest of `row`'s lanes, four lanes at a time and then in pairs (the
/// reduction one lane after another was 150 instructions a packet); both NaN where any lane
/// is NaN, which `packet_bound` refuses. The vector steps alone would not say so: where one
/// operand is NaN they take the other, or give NaN, depending on which lane it is in, and
/// could leave out a ray that is not NaN (a review found the case; a test now covers every
/// pattern of NaN lanes).
#[inline(always)]
fn least_and_greatest(row: &[f32; PACKET]) -> (f32, f32) {
    let half = |start: usize| f32x4::new([0, 1, 2, 3].map(|i| row[start + i]));
    let (a, b) = (half(0), half(4));
    if (a.is_nan() | b.is_nan()).any() {
        return (f32::NAN, f32::NAN);
    }
    let (low, high) = (a.fast_min(b).to_array(), a.fast_max(b).to_array());
    let min = |x: f32, y: f32| if x < y { x } else { y };
    let max = |x: f32, y: f32| if x > y { x } else { y };
    (
        min(min(low[0], low[1]), min(low[2], low[3])),
        max(max(high[0], high[1]), max(high[2], high[3])),
    )
}

/// `[f(0), .., f(PACKET - 1)]`, built in place. `std::array::from_fn` was compiled out of line
/// (its drop guard kept it from being inlined into the AVX traversal), in SSE code, and its
/// result copied into place by `memcpy`: 2 % of the Cornell box's time went to that copy and
/// the call (`docs/bench.md`, issue 12, twenty-second round). Slots 1 on briefly hold a copy
/// of `f(0)` and are overwritten: `f` is called once per index, in order, as `from_fn` did.
/// (Slots left uninitialised and written once, then read out as the array, cost more: the
/// read-out is a copy.)
#[inline(always)]
fn per_ray<T: Copy>(f: impl Fn(usize) -> T) -> [T; PACKET] {
    let mut out = [f(0); PACKET];
    for (r, slot) in out.iter_mut().enumerate().skip(1) {
        *slot = f(r);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pattern of NaN lanes, with the least and the greatest of the others in every
    /// lane: the pair is exactly the least and greatest of a row without NaN, and NaN for a
    /// row with any, which `packet_bound` then refuses. (A reduction that let a NaN lane take
    /// its partner's place left a ray out of the bound, and its boxes were filtered away.)
    #[test]
    fn a_rows_least_and_greatest_are_exact_or_refused_for_every_pattern_of_nans() {
        for nans in 0u32..256 {
            for least in 0..PACKET {
                for greatest in (0..PACKET).filter(|&g| g != least) {
                    let mut row: [f32; PACKET] = std::array::from_fn(|i| 1.0 + i as f32 * 0.25);
                    row[least] = -3.0;
                    row[greatest] = 7.0;
                    for (i, value) in row.iter_mut().enumerate() {
                        if nans & (1 << i) != 0 {
                            *value = f32::NAN;
                        }
                    }
                    let (low, high) = least_and_greatest(&row);
                    if nans == 0 {
                        assert_eq!((low, high), (-3.0, 7.0));
                    } else {
                        assert!(low.is_nan() && high.is_nan(), "{row:?}: {low}, {high}");
                    }
                }
            }
        }
    }
}
