//! The box tests of a packet (`packet.rs`): one box against up to eight rays at once, exactly
//! as the single-ray test computes each pair (`BoxTest::enter_child`), and a conservative
//! filter of a node's eight boxes against the interval the rays span
//! (`BoxTest::enter_bound`); each in two SSE steps of four lanes and in one AVX step of
//! eight, which `node8.rs`'s `Portable` and `Avx` call.

use super::node8::{Node8, WIDTH, join_halves, slab_step_sse};
#[cfg(target_arch = "x86_64")]
use super::node8::{slab_result_avx, slab_step_avx};
use super::ray_setup::RayRows;
use super::traverse::FAR_SCALE;
use wide::{CmpLe, f32x4};

/// Up to eight rays prepared for testing one box against all of them at once: lane `r` holds
/// ray `r`'s `WideRay` origin and reciprocal direction, and the near and far planes are the
/// same for all (a packet is made only of rays whose reciprocal directions have the same signs).
pub(super) struct PacketRays {
    pub(super) origin: [[f32; WIDTH]; 3],
    pub(super) inv_dir: [[f32; WIDTH]; 3],
    pub(super) near: [usize; 3],
    pub(super) far: [usize; 3],
}

impl PacketRays {
    /// The rays of `rows` prepared for the box tests: lane `r` holds what `WideRay::new`
    /// makes of ray `r`, computed with the same operations. `None` where their reciprocal
    /// directions do not all have the same signs (their boxes' near planes differ): such rays
    /// are traced one by one.
    #[inline(always)]
    pub(super) fn from_rows(rows: &RayRows) -> Option<Self> {
        let origin = rows.origin;
        let mut inv_dir = [[0.0; WIDTH]; 3];
        for (inv, dir) in inv_dir.iter_mut().zip(&rows.dir) {
            for (inv, &d) in inv.iter_mut().zip(dir) {
                *inv = 1.0 / d;
            }
        }
        let (mut near, mut far) = ([0; 3], [0; 3]);
        for axis in 0..3 {
            let negative = inv_dir[axis].iter().filter(|&&inv| inv < 0.0).count();
            if negative != 0 && negative != WIDTH {
                return None;
            }
            let negative = negative == WIDTH;
            near[axis] = if negative { 3 + axis } else { axis };
            far[axis] = if negative { axis } else { 3 + axis };
        }
        Some(PacketRays {
            origin,
            inv_dir,
            near,
            far,
        })
    }
}

/// The interval a packet's rays span on each axis, for a test that rejects at once the boxes
/// none of them can enter (`BoxTest::enter_bound`). For each axis: the origin coordinate
/// that makes the entry distance least and the one that makes the exit distance greatest
/// (which depends on the direction's sign, the same for all the packet's rays), and the least
/// and greatest reciprocal direction; and the near and far planes' rows, the packet's own.
/// Only ever made from finite reciprocal directions.
pub(super) struct PacketBound {
    pub(super) origin_near: [f32; 3],
    pub(super) origin_far: [f32; 3],
    pub(super) inv_low: [f32; 3],
    pub(super) inv_high: [f32; 3],
    pub(super) near: [usize; 3],
    pub(super) far: [usize; 3],
}

/// `BoxTest::enter_child` in two SSE steps of four lanes (plain code off x86-64).
#[inline(always)]
pub(super) fn enter_child_portable(
    rays: &PacketRays,
    node: &Node8,
    child: usize,
    end: &[f32; WIDTH],
) -> (u32, [f32; WIDTH]) {
    let half = |h: usize| {
        let lanes = |row: &[f32; WIDTH]| -> f32x4 {
            f32x4::new(
                row[4 * h..4 * h + 4]
                    .try_into()
                    .expect("a half of eight lanes is four"),
            )
        };
        let end = lanes(end);
        let mut t = (f32x4::ZERO, end);
        for axis in 0..3 {
            let planes = (
                f32x4::splat(node.bounds[rays.near[axis]][child]),
                f32x4::splat(node.bounds[rays.far[axis]][child]),
            );
            let ray = (lanes(&rays.origin[axis]), lanes(&rays.inv_dir[axis]));
            t = slab_step_sse(t, planes, ray, end);
        }
        (t.0.cmp_le(t.1).move_mask() as u32, t.0.to_array())
    };
    join_halves(half(0), half(1))
}

/// `BoxTest::enter_bound` in two SSE steps of four lanes (plain code off x86-64).
#[inline(always)]
pub(super) fn enter_bound_portable(bound: &PacketBound, node: &Node8, end: f32) -> u32 {
    let half = |h: usize| {
        let plane = |row: usize| -> f32x4 {
            f32x4::new(
                node.bounds[row][4 * h..4 * h + 4]
                    .try_into()
                    .expect("a half of eight lanes is four"),
            )
        };
        let scale = f32x4::splat(FAR_SCALE);
        let mut t0 = f32x4::ZERO;
        let mut t1 = f32x4::splat(end);
        for axis in 0..3 {
            let (near_row, far_row) = (bound.near[axis], bound.far[axis]);
            let (low, high) = (
                f32x4::splat(bound.inv_low[axis]),
                f32x4::splat(bound.inv_high[axis]),
            );
            let near = plane(near_row) - f32x4::splat(bound.origin_near[axis]);
            let far = plane(far_row) - f32x4::splat(bound.origin_far[axis]);
            t0 = t0.fast_max((near * low).fast_min(near * high));
            t1 = t1.fast_min((far * low).fast_max(far * high) * scale);
        }
        t0.cmp_le(t1).move_mask() as u32
    };
    (half(0) | (half(1) << 4)) & u32::from(node.valid)
}

/// [`enter_bound_portable`] in one step of eight lanes.
///
/// # Safety
/// The processor must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn enter_bound_avx(bound: &PacketBound, node: &Node8, end: f32) -> u32 {
    use std::arch::x86_64::*;
    let scale = _mm256_set1_ps(FAR_SCALE);
    let mut t0 = _mm256_setzero_ps();
    let mut t1 = _mm256_set1_ps(end);
    for axis in 0..3 {
        let (near_row, far_row) = (bound.near[axis], bound.far[axis]);
        let low = _mm256_set1_ps(bound.inv_low[axis]);
        let high = _mm256_set1_ps(bound.inv_high[axis]);
        // SAFETY: each row is eight f32 in bounds of `node`, 32-byte aligned.
        let (near_plane, far_plane) = unsafe {
            (
                _mm256_load_ps(node.bounds[near_row].as_ptr()),
                _mm256_load_ps(node.bounds[far_row].as_ptr()),
            )
        };
        let near = _mm256_sub_ps(near_plane, _mm256_set1_ps(bound.origin_near[axis]));
        let far = _mm256_sub_ps(far_plane, _mm256_set1_ps(bound.origin_far[axis]));
        let least = _mm256_min_ps(_mm256_mul_ps(near, low), _mm256_mul_ps(near, high));
        let greatest = _mm256_max_ps(_mm256_mul_ps(far, low), _mm256_mul_ps(far, high));
        t0 = _mm256_max_ps(least, t0);
        t1 = _mm256_min_ps(_mm256_mul_ps(greatest, scale), t1);
    }
    let entered = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
    entered & u32::from(node.valid)
}

/// `BoxTest::enter_child` in one step of eight lanes: `node8::enter_avx`'s operations, in its order, on one box and eight rays.
///
/// # Safety
/// The processor must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn enter_child_avx(
    rays: &PacketRays,
    node: &Node8,
    child: usize,
    end: &[f32; WIDTH],
) -> (u32, [f32; WIDTH]) {
    use std::arch::x86_64::*;
    // SAFETY (the loads and the store): every row is eight f32 in bounds; unaligned access.
    let mut t0 = _mm256_setzero_ps();
    let mut t1 = unsafe { _mm256_loadu_ps(end.as_ptr()) };
    for axis in 0..3 {
        let (origin, inv_dir) = unsafe {
            (
                _mm256_loadu_ps(rays.origin[axis].as_ptr()),
                _mm256_loadu_ps(rays.inv_dir[axis].as_ptr()),
            )
        };
        let planes = (
            _mm256_set1_ps(node.bounds[rays.near[axis]][child]),
            _mm256_set1_ps(node.bounds[rays.far[axis]][child]),
        );
        // SAFETY: this function runs only where AVX is (its own contract).
        (t0, t1) = unsafe { slab_step_avx((t0, t1), planes, (origin, inv_dir)) };
    }
    // SAFETY: as above.
    unsafe { slab_result_avx(t0, t1) }
}

/// The rays (bit `r`) whose entry distance `t_near[r]` is within their end of search
/// `end[r]`: the ordered comparison `t_near <= end` of every lane, false on NaN as the scalar
/// one is, in two four-lane steps (compared one by one, with the shifts that gather the bits,
/// it was 24 instructions per ray on Sponza's camera rays). A comparison computes nothing, so
/// no lane's answer can differ.
#[inline(always)]
pub(super) fn within(t_near: &[f32; WIDTH], end: &[f32; WIDTH]) -> u32 {
    let half = |h: usize| {
        let lanes = |x: &[f32; WIDTH]| {
            let four: &[f32; 4] = x[4 * h..4 * h + 4]
                .try_into()
                .expect("a half of eight lanes is four");
            f32x4::new(*four)
        };
        lanes(t_near).cmp_le(lanes(end)).move_mask() as u32
    };
    half(0) | half(1) << 4
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;
    #[cfg(target_arch = "x86_64")]
    use crate::geometry::node8::Avx;
    use crate::geometry::node8::{BoxTest, Portable, avx_available};
    use crate::geometry::ray_setup::WideRay;
    use glam::Vec3;

    /// A small fixed stream (splitmix64), so every run checks the same cases.
    struct Stream(u64);

    impl Stream {
        fn unit(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let z = crate::sampler::splitmix_finalise(self.0);
            (z >> 40) as f32 / (1u64 << 24) as f32
        }

        fn range(&mut self, low: f32, high: f32) -> f32 {
            low + (high - low) * self.unit()
        }
    }

    #[test]
    fn within_is_the_scalar_comparison_of_every_lane_on_every_kind_of_float() {
        let kinds = [
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            1e-40,
            1.0,
            1.0 + f32::EPSILON,
            -3.0,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let mut stream = Stream(41);
        let mut pick = || kinds[(stream.unit() * kinds.len() as f32) as usize];
        for _ in 0..20_000 {
            let t_near: [f32; WIDTH] = std::array::from_fn(|_| pick());
            let end: [f32; WIDTH] = std::array::from_fn(|_| pick());
            let scalar = (0..WIDTH).fold(0, |bits, r| bits | u32::from(t_near[r] <= end[r]) << r);
            assert_eq!(within(&t_near, &end), scalar, "{t_near:?} against {end:?}");
        }
    }

    /// A node of eight random boxes near `centre` at `scale`: some flat on an axis, some
    /// holding the packet's origin, some with a face through it.
    fn node(stream: &mut Stream, centre: Vec3, scale: f32, origin: Vec3) -> Node8 {
        let mut node = Node8::EMPTY;
        for lane in 0..WIDTH {
            let mut min = [0.0; 3];
            let mut max = [0.0; 3];
            for axis in 0..3 {
                let a = centre[axis] + scale * stream.range(-1.0, 1.0);
                let b = centre[axis] + scale * stream.range(-1.0, 1.0);
                (min[axis], max[axis]) = (a.min(b), a.max(b));
                match (lane + axis) % 5 {
                    0 => max[axis] = min[axis],
                    1 => min[axis] = origin[axis],
                    _ => {}
                }
                if lane == 7 {
                    (min[axis], max[axis]) = (origin[axis] - scale, origin[axis] + scale);
                }
            }
            node.set_bounds(lane, min, max);
        }
        node.valid = 0xff;
        node.children = 8;
        node
    }

    /// Eight rays from about `origin` towards about `target`: a pixel's samples or a lens's.
    fn packet(stream: &mut Stream, origin: Vec3, target: Vec3, spread: f32) -> [Ray; WIDTH] {
        std::array::from_fn(|_| {
            let jitter = |s: &mut Stream| {
                Vec3::new(s.range(-1.0, 1.0), s.range(-1.0, 1.0), s.range(-1.0, 1.0))
            };
            let from = origin + jitter(stream) * spread;
            let to = target + jitter(stream) * spread;
            Ray {
                origin: from,
                dir: to - from,
                t_max: f32::INFINITY,
            }
        })
    }

    /// For each box test: lane `r` of the packet test is ray `r`'s own test of that box, to
    /// the bit, and the filter never drops a box some ray enters.
    fn check<B: BoxTest>(what: &str) {
        let mut stream = Stream(0x9ac4_b0c5);
        let mut checked = (0, 0);
        for round in 0..3000 {
            let scale = [1e-3, 1.0, 1e3][round % 3];
            let far = [0.0, 1e4][round / 3 % 2];
            let origin = Vec3::new(far, -far, far * 0.5) + Vec3::splat(scale * 0.3);
            let target = origin
                + Vec3::new(
                    stream.range(-1.0, 1.0),
                    stream.range(-1.0, 1.0),
                    stream.range(0.2, 1.0),
                ) * (4.0 * scale);
            let spread = scale * [1e-5, 1e-3, 0.1][round / 6 % 3];
            let mut rays = packet(&mut stream, origin, target, spread);
            if round % 5 == 4 {
                // Along a plane: a zero of either sign, an infinite reciprocal of that sign,
                // whose near plane the packet's must be.
                let zero = if round % 10 == 4 { 0.0 } else { -0.0 };
                rays.iter_mut().for_each(|ray| ray.dir.y = zero);
            }
            let wide: [WideRay; WIDTH] = std::array::from_fn(|r| WideRay::new(&rays[r]));
            let Some(packet) = PacketRays::from_rows(&RayRows::gather(&rays)) else {
                // Only rays whose near planes differ are refused.
                assert!(wide.iter().any(|w| w.near != wide[0].near), "{what}");
                continue;
            };
            for (r, alone) in wide.iter().enumerate() {
                for axis in 0..3 {
                    assert_eq!(
                        packet.origin[axis][r].to_bits(),
                        alone.origin[axis].to_bits()
                    );
                    assert_eq!(
                        packet.inv_dir[axis][r].to_bits(),
                        alone.inv_dir[axis].to_bits()
                    );
                }
                assert_eq!((packet.near, packet.far), (alone.near, alone.far), "{what}");
            }
            let Some(bound) = crate::geometry::packet::packet_bound(&packet) else {
                continue;
            };
            let node = node(&mut stream, target, 2.0 * scale, origin);
            let end: [f32; WIDTH] = std::array::from_fn(|r| {
                if r % 3 == 0 {
                    f32::INFINITY
                } else {
                    scale * stream.range(0.5, 8.0)
                }
            });
            let farthest = end.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            let filter = B::enter_bound(&bound, &node, farthest);
            for child in 0..WIDTH {
                let (entered, t_near) = B::enter_child(&packet, &node, child, &end);
                for r in 0..WIDTH {
                    let (alone, alone_t) = B::enter(&wide[r], &node, end[r]);
                    let by_itself = alone & (1 << child) != 0;
                    assert_eq!(
                        entered & (1 << r) != 0,
                        by_itself,
                        "{what}: ray {r}, box {child}"
                    );
                    if by_itself {
                        assert_eq!(t_near[r].to_bits(), alone_t[child].to_bits(), "{what}");
                        assert!(
                            filter & (1 << child) != 0,
                            "{what}: the filter dropped box {child}, which ray {r} enters"
                        );
                        checked.0 += 1;
                    }
                }
                checked.1 += (entered == 0 && filter & (1 << child) == 0) as u32;
            }
        }
        // Enough boxes entered to test the filter on, and enough it rightly dropped to show it
        // filters at all.
        assert!(
            checked.0 > 10_000 && checked.1 > 1_000,
            "{what}: {checked:?}"
        );
    }

    #[test]
    fn a_packets_box_tests_are_each_rays_own_and_its_filter_drops_no_box_a_ray_enters() {
        check::<Portable>("SSE");
        #[cfg(target_arch = "x86_64")]
        if avx_available() {
            check::<Avx>("AVX");
        }
    }
}
