//! The 8-wide node and the test of a ray against its eight boxes, written twice: with AVX's
//! eight f32 lanes, chosen at run time where the processor has them, and as two SSE steps of
//! four lanes (the `wide` crate: SSE2 on x86-64, plain code elsewhere) where it has not.
//!
//! Why both, and why at run time: building with `target-cpu` flags would make the binary's
//! instructions, and with them possibly its images, depend on the machine that built it. Here
//! every machine runs the same IEEE operations on the same values; only how many lanes one
//! instruction holds differs.
//!
//! **Exactness.** Each lane of the SSE test evaluates exactly the expressions of the binary
//! traversal's slab test (`SlabRay::enter` in `traverse.rs`) for its box: the same subtraction,
//! the same multiplications by the same reciprocal and by `FAR_SCALE`, the same NaN-dropping
//! selects, then a running maximum and minimum over the axes, in the same order, with the same
//! operand order (x86's `max`/`min` return their second operand on NaN and on equal zeros, and
//! what reaches them is NaN-free and never `-0.0` anyway), and the same ordered comparison at
//! the end. The AVX test computes the same subtraction and multiplications and folds each
//! select into the maximum or minimum that follows it (`enter_avx` says why that gives the
//! same entered boxes and the same entry distances, bit for bit, on every input). The two
//! paths therefore enter the same boxes at the same distances, and a traversal takes the same
//! steps and counts the same work on every machine.
//! `tracer/tests/wide_traversal.rs` renders through both and compares.

use super::Ray;
use super::collapse::reference_parts;
use super::packet_box::{PacketBound, PacketRays};
#[cfg(target_arch = "x86_64")]
use super::packet_box::{enter_bound_avx, enter_child_avx};
use super::packet_box::{enter_bound_portable, enter_child_portable};
use super::quad::{LaneHits, Quad, QuadRay};
#[cfg(target_arch = "x86_64")]
use super::quad_avx::RayLanes;
use super::ray_setup::{RayRows, WideRay};
use super::traverse::FAR_SCALE;
use wide::{CmpGt, CmpLe, CmpLt, f32x4};

/// Children per node: AVX's eight f32 lanes.
pub(super) const WIDTH: usize = 8;

/// A node of up to eight children: 256 bytes, four cache lines, aligned to them.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Node8 {
    /// The children's boxes, one lane per child: min x, y, z, then max x, y, z. Lanes past
    /// `children` hold an empty box (min +inf, max -inf) and are masked out anyway.
    pub(super) bounds: [[f32; WIDTH]; 6],
    /// Per child, its reference (`collapse::child_reference`): an inner node's index in
    /// `Bvh8::nodes` or a leaf's first group in `Bvh8::quads`, and the leaf's number of
    /// triangles (0 for an inner node), in one word, as the walks' stack entries carry them.
    pub(super) refs: [u32; WIDTH],
    /// Bit `i` set when lane `i` holds a child; children fill the lowest lanes.
    pub(super) valid: u8,
    /// The number of children, which the stats count as boxes tested (a stored count, since
    /// counting bits is a dozen instructions on x86-64 without `popcnt`).
    pub(super) children: u8,
}

const _: () = assert!(std::mem::size_of::<Node8>() == 256, "four cache lines");

impl Node8 {
    pub(super) const EMPTY: Node8 = Node8 {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        refs: [0; WIDTH],
        valid: 0,
        children: 0,
    };

    /// Lane `lane`'s child index.
    #[inline(always)]
    pub(super) fn index(&self, lane: usize) -> u32 {
        reference_parts(self.refs[lane]).0
    }

    /// Lane `lane`'s leaf's triangles, 0 for an inner node.
    #[inline(always)]
    pub(super) fn count(&self, lane: usize) -> u32 {
        reference_parts(self.refs[lane]).1
    }

    pub(super) fn set_bounds(&mut self, lane: usize, min: [f32; 3], max: [f32; 3]) {
        for axis in 0..3 {
            self.bounds[axis][lane] = min[axis];
            self.bounds[3 + axis][lane] = max[axis];
        }
    }
}

/// Which instructions test a node's boxes, and a leaf's triangles eight at a time. The
/// traversal is written once, generic over this, and compiled once per implementation.
pub(super) trait BoxTest {
    /// Whether [`BoxTest::intersect_pair`] tests two groups of four triangles in one step, so
    /// that the traversal should hand it pairs. Where not, the traversal tests groups one by
    /// one; either way the results are the same bits.
    const PAIRS: bool;

    /// For each child of `node`, whether the ray enters its box within `(0, t_max]` (bit `i`)
    /// and the entry distance: lane by lane, the binary traversal's `SlabRay::enter`.
    fn enter(ray: &WideRay, node: &Node8, t_max: f32) -> (u32, [f32; WIDTH]);

    /// For each ray of `rays` (bit `r`), whether it enters the box of `node`'s child `child`
    /// within `(0, end[r]]`, and its entry distance: lane by lane, what [`BoxTest::enter`]
    /// computes for that box and that ray, to the bit (the same operations on the same values
    /// in the same order; only the lanes hold rays instead of boxes).
    fn enter_child(
        rays: &PacketRays,
        node: &Node8,
        child: usize,
        end: &[f32; WIDTH],
    ) -> (u32, [f32; WIDTH]);

    /// A superset of the children of `node` that some ray of the packet `bound` describes
    /// enters within `(0, end]`: bit `i` clear only where no such ray can enter child `i`'s
    /// box. Why it is conservative: rounding is monotonic, so each ray's entry distance on
    /// each axis, `(plane - origin) * inv_dir` rounded twice, is at least the same expression
    /// at the corner of the packet's interval that makes it least (and its exit distance at
    /// most the one at the corner that makes it greatest); with finite reciprocals, origins
    /// not NaN and finite planes (the valid children's) no NaN arises. A filter only.
    fn enter_bound(bound: &PacketBound, node: &Node8, end: f32) -> u32;

    /// The SIMD triangle test of two consecutive groups of a leaf, `a` in lanes 0 to 3 and `b`
    /// in lanes 4 to 7: [`QuadRay::intersect_pair`], lane for lane.
    fn intersect_pair(ray: &QuadRay, a: &Quad, b: &Quad) -> LaneHits<8>;

    /// A packet's rays in rows: [`RayRows::gather`], bit for bit.
    fn gather(rays: &[Ray]) -> RayRows;

    /// A packet's rays made into lanes for [`BoxTest::triangle_against_rays`].
    type RayLanes: Copy;

    /// A packet's rays as lanes, one a lane, where this test has a step for one triangle
    /// against eight rays and the rays permute the axes alike; else `None` (ray by ray).
    fn ray_lanes(rays: &RayRows) -> Option<Self::RayLanes>;

    /// Triangle `triangle` of `quad` against each ray of `rays` (lane `r` for ray `r`): for
    /// each, the SIMD test's lane for that triangle and that ray, to the bit. `valid` names the
    /// rays that need an answer.
    fn triangle_against_rays(
        rays: &Self::RayLanes,
        quad: &Quad,
        triangle: usize,
        valid: u32,
    ) -> LaneHits<8>;
}

/// Two SSE steps of four lanes (plain code off x86-64): every machine can run it.
pub(super) struct Portable;

impl BoxTest for Portable {
    const PAIRS: bool = false;

    #[inline(always)]
    fn intersect_pair(ray: &QuadRay, a: &Quad, b: &Quad) -> LaneHits<8> {
        ray.intersect_pair(a, b)
    }

    /// None (a type with no values): here a packet's leaves are tested ray by ray, four
    /// triangles a step, where eight lanes against eight rays would be two SSE steps per
    /// triangle; this test runs where the processor lacks AVX (or off x86-64), or where a test
    /// asks for it.
    type RayLanes = std::convert::Infallible;

    #[inline(always)]
    fn gather(rays: &[Ray]) -> RayRows {
        RayRows::gather(rays)
    }

    #[inline(always)]
    fn ray_lanes(_: &RayRows) -> Option<Self::RayLanes> {
        None
    }

    fn triangle_against_rays(rays: &Self::RayLanes, _: &Quad, _: usize, _: u32) -> LaneHits<8> {
        match *rays {}
    }

    #[inline(always)]
    fn enter(ray: &WideRay, node: &Node8, t_max: f32) -> (u32, [f32; WIDTH]) {
        let half = |h: usize| {
            let zero = f32x4::ZERO;
            let end = f32x4::splat(t_max);
            let plane = |row: usize| {
                let lanes: &[f32; 4] = node.bounds[row][4 * h..4 * h + 4]
                    .try_into()
                    .expect("a half of eight lanes is four");
                f32x4::new(*lanes)
            };
            let mut t = (zero, end);
            for axis in 0..3 {
                let planes = (plane(ray.near[axis]), plane(ray.far[axis]));
                let (origin, inv_dir) = (
                    f32x4::splat(ray.origin[axis]),
                    f32x4::splat(ray.inv_dir[axis]),
                );
                t = slab_step_sse(t, planes, (origin, inv_dir), end);
            }
            (t.0.cmp_le(t.1).move_mask() as u32, t.0.to_array())
        };
        let (entered, t_near) = join_halves(half(0), half(1));
        (entered & u32::from(node.valid), t_near)
    }

    #[inline(always)]
    fn enter_child(
        rays: &PacketRays,
        node: &Node8,
        child: usize,
        end: &[f32; WIDTH],
    ) -> (u32, [f32; WIDTH]) {
        enter_child_portable(rays, node, child, end)
    }

    #[inline(always)]
    fn enter_bound(bound: &PacketBound, node: &Node8, end: f32) -> u32 {
        enter_bound_portable(bound, node, end)
    }
}

/// AVX's eight lanes. Only ever used where the processor was found to have AVX.
#[cfg(target_arch = "x86_64")]
pub(super) struct Avx;

#[cfg(target_arch = "x86_64")]
impl BoxTest for Avx {
    const PAIRS: bool = true;

    #[inline(always)]
    fn intersect_pair(ray: &QuadRay, a: &Quad, b: &Quad) -> LaneHits<8> {
        // SAFETY: as for `enter` below.
        unsafe { super::quad_avx::intersect_pair_avx(ray, a, b) }
    }

    #[inline(always)]
    fn gather(rays: &[Ray]) -> RayRows {
        // SAFETY: as for `enter` below.
        unsafe { RayRows::gather_avx(rays) }
    }

    type RayLanes = RayLanes;

    #[inline(always)]
    fn ray_lanes(rays: &RayRows) -> Option<RayLanes> {
        // SAFETY: as for `enter` below.
        unsafe { RayLanes::new(rays) }
    }

    #[inline(always)]
    fn triangle_against_rays(
        rays: &RayLanes,
        quad: &Quad,
        triangle: usize,
        valid: u32,
    ) -> LaneHits<8> {
        // SAFETY: as for `enter` below.
        unsafe { super::quad_avx::triangle_against_rays_avx(rays, quad, triangle, valid) }
    }

    #[inline(always)]
    fn enter(ray: &WideRay, node: &Node8, t_max: f32) -> (u32, [f32; WIDTH]) {
        // SAFETY: `Avx` is only used by `Accel::traverse_avx` and `Accel::packet_avx` (and by
        // tests that ask the processor first), which run only where
        // `is_x86_feature_detected!("avx")` said yes (`BoxSimd::Avx` is set nowhere else).
        unsafe { enter_avx(ray, node, t_max) }
    }

    #[inline(always)]
    fn enter_child(
        rays: &PacketRays,
        node: &Node8,
        child: usize,
        end: &[f32; WIDTH],
    ) -> (u32, [f32; WIDTH]) {
        // SAFETY: as for `enter` above (`Accel::packet_avx`).
        unsafe { enter_child_avx(rays, node, child, end) }
    }

    #[inline(always)]
    fn enter_bound(bound: &PacketBound, node: &Node8, end: f32) -> u32 {
        // SAFETY: as for `enter` above.
        unsafe { enter_bound_avx(bound, node, end) }
    }
}

/// [`Portable::enter`] in one step of eight lanes, with the select that drops a NaN or
/// negative distance folded into the running maximum (and likewise for the minimum).
///
/// Why the results are the same bits: the portable test keeps `t0 = max(t0, near > 0 ? near :
/// 0)` from `t0 = 0`; this one keeps `t0 = vmaxps(near, t0)`, which is `near` when `near > t0`
/// and `t0` otherwise (on a NaN `near`, on equality, and for any `near <= 0`, since `t0 >= 0`
/// throughout). Both are therefore the largest of 0 and the axes' non-NaN distances, and
/// neither is ever `-0.0` (a `-0.0` distance loses to the running `+0.0`, which is the second
/// operand on equality), so the stored entry distances are the same bits. Likewise `t1` is
/// the smallest of `t_max` and the non-NaN exit distances either way; it may differ only in
/// the sign of a zero, which the final ordered `t0 <= t1` does not see. So the entered mask
/// and the entry distances equal the portable test's (and the binary traversal's) on every
/// input; `tracer/tests/wide_traversal.rs` renders through both and compares. It saves a
/// compare and a blend per bound per axis, off the chain each node's test waits on.
///
/// # Safety
/// The processor must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn enter_avx(ray: &WideRay, node: &Node8, t_max: f32) -> (u32, [f32; WIDTH]) {
    use std::arch::x86_64::*;
    let mut t0 = _mm256_setzero_ps();
    let mut t1 = _mm256_set1_ps(t_max);
    for axis in 0..3 {
        let origin = _mm256_set1_ps(ray.origin[axis]);
        let inv_dir = _mm256_set1_ps(ray.inv_dir[axis]);
        // SAFETY: each row is eight f32 in bounds of `node`, 32-byte aligned (the node is
        // 64-byte aligned and rows are 32 bytes).
        let (near_plane, far_plane) = unsafe {
            (
                _mm256_load_ps(node.bounds[ray.near[axis]].as_ptr()),
                _mm256_load_ps(node.bounds[ray.far[axis]].as_ptr()),
            )
        };
        // SAFETY: this function runs only where AVX is (its own contract).
        (t0, t1) = unsafe { slab_step_avx((t0, t1), (near_plane, far_plane), (origin, inv_dir)) };
    }
    // SAFETY: as above.
    let (entered, t_near) = unsafe { slab_result_avx(t0, t1) };
    (entered & u32::from(node.valid), t_near)
}

/// The results of a slab test's two four-lane halves as one of eight lanes: the entered
/// bits of the low half, then the high's, and the entry distances in lane order.
#[inline(always)]
pub(super) fn join_halves(
    (low, t_low): (u32, [f32; 4]),
    (high, t_high): (u32, [f32; 4]),
) -> (u32, [f32; WIDTH]) {
    let mut t_near = [0.0; WIDTH];
    t_near[..4].copy_from_slice(&t_low);
    t_near[4..].copy_from_slice(&t_high);
    (low | (high << 4), t_near)
}

/// One axis of the slab test in four lanes, the one place its operations are written for SSE:
/// from the running entry and exit distances `t`, and the planes `(near, far)` of that axis,
/// the new ones, for a ray with `origin` and `inv_dir` on that axis (lane by lane: a ray's
/// eight boxes, or a box's eight rays). `a > b ? a : b` drops a NaN `a`, as in the binary test.
#[inline(always)]
pub(super) fn slab_step_sse(
    (t0, t1): (f32x4, f32x4),
    (near_plane, far_plane): (f32x4, f32x4),
    (origin, inv_dir): (f32x4, f32x4),
    end: f32x4,
) -> (f32x4, f32x4) {
    let zero = f32x4::ZERO;
    let near = (near_plane - origin) * inv_dir;
    let far = (far_plane - origin) * inv_dir * f32x4::splat(FAR_SCALE);
    (
        t0.fast_max(near.cmp_gt(zero).blend(near, zero)),
        t1.fast_min(far.cmp_lt(end).blend(far, end)),
    )
}

/// [`slab_step_sse`] in eight AVX lanes, the one place its operations are written for AVX,
/// with the select folded into the maximum and the minimum ([`enter_avx`] says why that gives
/// the same bits): `vmaxps(a, b)` returns its second operand when either is NaN, so with the
/// running value second a NaN distance is dropped, as the select drops it.
///
/// # Safety
/// The processor must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn slab_step_avx(
    (t0, t1): (std::arch::x86_64::__m256, std::arch::x86_64::__m256),
    (near_plane, far_plane): (std::arch::x86_64::__m256, std::arch::x86_64::__m256),
    (origin, inv_dir): (std::arch::x86_64::__m256, std::arch::x86_64::__m256),
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    let near = _mm256_mul_ps(_mm256_sub_ps(near_plane, origin), inv_dir);
    let far = _mm256_mul_ps(
        _mm256_mul_ps(_mm256_sub_ps(far_plane, origin), inv_dir),
        _mm256_set1_ps(FAR_SCALE),
    );
    (_mm256_max_ps(near, t0), _mm256_min_ps(far, t1))
}

/// The end of an eight-lane slab test: which lanes are entered (`t0 <= t1`, ordered) and
/// their entry distances.
///
/// # Safety
/// The processor must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn slab_result_avx(
    t0: std::arch::x86_64::__m256,
    t1: std::arch::x86_64::__m256,
) -> (u32, [f32; WIDTH]) {
    use std::arch::x86_64::*;
    let entered = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
    let mut t_near = [0.0f32; WIDTH];
    // SAFETY: `t_near` holds eight f32; the store is unaligned.
    unsafe { _mm256_storeu_ps(t_near.as_mut_ptr(), t0) };
    (entered, t_near)
}

/// Whether this processor runs the AVX box test. Asked once per tree (`Bvh8::collapse`); the
/// answer changes speed only, never a result (see the module's comment).
pub(super) fn avx_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// The values that make a slab test hard: zeros of both signs (a reciprocal of +-inf, and
    /// `0 * inf = NaN` where the origin lies on a plane), infinities, the extremes of the
    /// normal range, subnormals, and plain values on both sides.
    const HARD: [f32; 14] = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.5,
        -3.0,
        1e-30,
        -1e-30,
        1e30,
        -1e30,
        f32::MIN_POSITIVE / 4.0,
        f32::INFINITY,
        f32::NEG_INFINITY,
        2.0,
    ];

    /// A deterministic stream of hard values (a linear congruential walk over `HARD`).
    fn hard(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        HARD[(*state >> 33) as usize % HARD.len()]
    }

    #[test]
    fn the_avx_box_test_enters_the_same_boxes_at_the_same_distances_as_the_portable_one() {
        if !avx_available() {
            eprintln!("this processor has no AVX: only the portable test runs here");
            return;
        }
        let mut state = 7u64;
        let mut entered_any = 0;
        for case in 0..20_000 {
            let mut node = Node8::EMPTY;
            // Seven of eight lanes hold a box whose corners are hard values (not sorted, so
            // some boxes are inverted or flat), one is left empty.
            for lane in 0..WIDTH - 1 {
                let min = [hard(&mut state), hard(&mut state), hard(&mut state)];
                let max = [hard(&mut state), hard(&mut state), hard(&mut state)];
                node.set_bounds(lane, min, max);
                node.valid |= 1 << lane;
            }
            let ray = Ray {
                origin: Vec3::new(hard(&mut state), hard(&mut state), hard(&mut state)),
                dir: Vec3::new(hard(&mut state), hard(&mut state), hard(&mut state)),
                t_max: f32::INFINITY,
            };
            let wide = WideRay::new(&ray);
            for t_max in [f32::INFINITY, 1.0, 0.0, 1e-30] {
                let (mask, t) = Portable::enter(&wide, &node, t_max);
                let (mask_avx, t_avx) = Avx::enter(&wide, &node, t_max);
                assert_eq!(mask, mask_avx, "case {case}, t_max {t_max}: {ray:?}");
                for lane in (0..WIDTH).filter(|&l| mask & (1 << l) != 0) {
                    assert_eq!(
                        t[lane].to_bits(),
                        t_avx[lane].to_bits(),
                        "case {case}, lane {lane}, t_max {t_max}: {ray:?}"
                    );
                }
                entered_any += mask.count_ones();
            }
        }
        // The walk must reach boxes that are entered, or the comparison says little.
        assert!(entered_any > 10_000, "only {entered_any} boxes entered");
    }
}
