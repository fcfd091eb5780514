//! What the wide traversals make of their rays before the first box: one ray's box set-up
//! ([`WideRay`]), and a packet's rays gathered into rows ([`RayRows`]), from which its box and
//! triangle set-ups are computed lane by lane.
//!
//! The rows are gathered twice over: in plain code, a float at a time, which every machine
//! runs; and with AVX, where the box test has it, by loading each ray in two four-float pieces
//! and transposing them in registers. Both only move bits, so both give the same rows; a test
//! holds them to each other. The AVX gather is there for speed: the plain one's 48 narrow stores
//! were read back at once as whole rows, which the processor cannot forward from its store
//! buffer (a stall per packet; docs/bench.md, issue 12, twenty-sixth round).

use super::Ray;
use super::node8::WIDTH;
use super::quad::QuadRay;
use super::triangle::major_axis;

// What `RayRows::gather_avx`'s loads rely on: a ray is seven f32 with nothing between them.
const _: () = assert!(std::mem::size_of::<Ray>() == 7 * 4 && std::mem::align_of::<Ray>() == 4);

/// A ray prepared for 8-wide slab tests: the binary test's origin and reciprocal direction,
/// and for each axis which of a box's planes is near.
#[derive(Clone, Copy)]
pub(super) struct WideRay {
    pub(super) origin: [f32; 3],
    pub(super) inv_dir: [f32; 3],
    /// Per axis, the index in `Node8::bounds` of the near plane and of the far plane: the max
    /// when the reciprocal direction is negative (including -0.0's -inf), else the min.
    pub(super) near: [usize; 3],
    pub(super) far: [usize; 3],
}

impl WideRay {
    // Always inlined: once per ray, and a call would return the prepared ray through memory.
    // Left to the heuristics, it was inlined or not depending on unrelated code elsewhere in
    // the renderer (docs/bench.md, issue 12, twelfth round).
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        let inv = [1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z];
        Self::from_parts(ray.origin.to_array(), inv)
    }

    /// The set-up of a ray from `origin` whose reciprocal direction is `inv`.
    #[inline(always)]
    fn from_parts(origin: [f32; 3], inv: [f32; 3]) -> Self {
        let negative = |axis: usize| inv[axis] < 0.0;
        WideRay {
            origin,
            inv_dir: inv,
            near: [0, 1, 2].map(|a| if negative(a) { 3 + a } else { a }),
            far: [0, 1, 2].map(|a| if negative(a) { a } else { 3 + a }),
        }
    }
}

/// Eight rays' walk set-ups ([`WideRay`] and [`QuadRay`]), computed together, a row per value
/// and a lane per ray, by a caller that made the eight rays together (the path lanes: their
/// shadow rays and next rays). Made a ray at a time at the start of its walk, the set-up's
/// divisions and choices were a tenth of the walk's time on the small scenes (docs/bench.md,
/// issue 12, thirty-third round); made here, in loops of eight lanes the caller compiles to
/// vector instructions, they cost an eighth each, and they are ready before the walk starts.
///
/// **Exactness.** Lane `r` of each row is computed with exactly the operations
/// [`WideRay::new`] and [`QuadRay::for_ray`] apply to ray `r` (the reciprocals, the major
/// axis by the triangle test's own `major_axis`, the permutation as selects, the shear's
/// divisions), and
/// [`SetUpRows::lane`] assembles them as those do, so a walk from a lane's set-up is the walk
/// from its ray, bit for bit (a test holds the two to each other on every kind of value).
#[derive(Clone, Copy)]
#[repr(align(32))]
pub(crate) struct SetUpRows {
    origin: [[f32; WIDTH]; 3],
    inv_dir: [[f32; WIDTH]; 3],
    /// `ShearedRay::kz`: the axis each ray moves to z.
    kz: [u32; WIDTH],
    /// `QuadRay::scalars`: the permuted origin, then the shear.
    scalars: [[f32; WIDTH]; 6],
}

impl Default for SetUpRows {
    fn default() -> Self {
        SetUpRows {
            origin: [[0.0; WIDTH]; 3],
            inv_dir: [[0.0; WIDTH]; 3],
            kz: [2; WIDTH],
            scalars: [[0.0; WIDTH]; 6],
        }
    }
}

impl SetUpRows {
    /// The set-ups of the rays from `origin` along `dir`, a row per axis and a lane per ray.
    /// Inlined, so that its loops take the caller's instruction set.
    #[inline(always)]
    pub(crate) fn new(origin: [&[f32; WIDTH]; 3], dir: [&[f32; WIDTH]; 3]) -> Self {
        let mut rows = SetUpRows::default();
        for axis in 0..3 {
            for r in 0..WIDTH {
                rows.origin[axis][r] = origin[axis][r];
                rows.inv_dir[axis][r] = 1.0 / dir[axis][r];
            }
        }
        for r in 0..WIDTH {
            let o = [origin[0][r], origin[1][r], origin[2][r]];
            let d = [dir[0][r], dir[1][r], dir[2][r]];
            // The triangle test's own major axis (its choices are selects), and `AXES[kz]`
            // as selects too: an index into a lane's array would keep the loop from
            // vectorising.
            let kz = major_axis(d) as u32;
            let pick = |v: [f32; 3], axis: u32| match axis {
                0 => v[0],
                1 => v[1],
                _ => v[2],
            };
            let (kx, ky) = (next_axis(kz), next_axis(next_axis(kz)));
            rows.kz[r] = kz;
            rows.scalars[0][r] = pick(o, kx);
            rows.scalars[1][r] = pick(o, ky);
            rows.scalars[2][r] = pick(o, kz);
            let dz = pick(d, kz);
            rows.scalars[3][r] = -pick(d, kx) / dz;
            rows.scalars[4][r] = -pick(d, ky) / dz;
            rows.scalars[5][r] = 1.0 / dz;
        }
        rows
    }

    /// Ray `r`'s set-up: what [`WideRay::new`] and [`QuadRay::for_ray`] make of it.
    #[inline(always)]
    pub(super) fn lane(&self, r: usize) -> (WideRay, QuadRay) {
        let column = |rows: &[[f32; WIDTH]; 3]| [rows[0][r], rows[1][r], rows[2][r]];
        let wide = WideRay::from_parts(column(&self.origin), column(&self.inv_dir));
        let scalars = std::array::from_fn(|k| self.scalars[k][r]);
        (wide, QuadRay::from_parts(self.kz[r] as usize, scalars))
    }
}

/// The axis after `axis`, cyclically: `AXES[kz]` is `[next(kz), next(next(kz)), kz]`.
#[inline(always)]
fn next_axis(axis: u32) -> u32 {
    match axis {
        0 => 1,
        1 => 2,
        _ => 0,
    }
}

/// Up to eight rays' origins and directions, a row per axis and a lane per ray (the lanes
/// past the last ray repeat it): what a packet's set-up is computed from, lane by lane.
/// Made per ray and transposed, that set-up was mostly copies (docs/bench.md, issue 12,
/// twenty-fifth round). Aligned so that each row is one whole cache-line-half store and load.
#[repr(align(32))]
pub(super) struct RayRows {
    pub(super) origin: [[f32; WIDTH]; 3],
    pub(super) dir: [[f32; WIDTH]; 3],
}

impl RayRows {
    /// `rays`, one to [`WIDTH`] of them, in rows.
    #[inline(always)]
    pub(super) fn gather(rays: &[Ray]) -> Self {
        let last = rays.len() - 1;
        let mut rows = RayRows {
            origin: [[0.0; WIDTH]; 3],
            dir: [[0.0; WIDTH]; 3],
        };
        for lane in 0..WIDTH {
            let ray = &rays[lane.min(last)];
            let (o, d) = (ray.origin.to_array(), ray.dir.to_array());
            for axis in 0..3 {
                rows.origin[axis][lane] = o[axis];
                rows.dir[axis][lane] = d[axis];
            }
        }
        rows
    }

    /// [`RayRows::gather`] with AVX: each ray loaded as `(ox, oy, oz, dx)` and `(dx, dy, dz,
    /// t_max)`, rays `r` and `r + 4` side by side in one register, and the eight registers
    /// transposed by unpacks and shuffles within their halves; each row is then one whole
    /// store. The same bits as the plain gather: nothing but moves.
    ///
    /// # Safety
    /// The processor must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub(super) unsafe fn gather_avx(rays: &[Ray]) -> Self {
        use std::arch::x86_64::*;
        let last = rays.len() - 1;
        // Ray `lane`'s first float (the last ray's past the end).
        let at = |lane: usize| -> *const f32 { (&rays[lane.min(last)] as *const Ray).cast() };
        // SAFETY: `Ray` is `repr(C)`, seven f32 (origin, dir, t_max), so floats 0 to 3 and 3 to
        // 6 of a ray lie within the one ray each pointer was made from; the loads are
        // unaligned. Written out rather than mapped over lanes: through closures LLVM left
        // some loads as calls.
        let (a0, a1, a2, a3, b0, b1, b2, b3) = unsafe {
            let low = |lane: usize| _mm_loadu_ps(at(lane));
            let high = |lane: usize| _mm_loadu_ps(at(lane).add(3));
            (
                _mm256_set_m128(low(4), low(0)),
                _mm256_set_m128(low(5), low(1)),
                _mm256_set_m128(low(6), low(2)),
                _mm256_set_m128(low(7), low(3)),
                _mm256_set_m128(high(4), high(0)),
                _mm256_set_m128(high(5), high(1)),
                _mm256_set_m128(high(6), high(2)),
                _mm256_set_m128(high(7), high(3)),
            )
        };
        // The first three columns of four registers `(x, y, z, w)` (ray `k` in the low half of
        // register `k`, ray `k + 4` in the high): within each half, lanes `(x0, x1, y0, y1)`
        // and `(z0, z1, w0, w1)`, then the first or second pair of two such side by side.
        let columns = |r0, r1, r2, r3| {
            let (low01, high01) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
            let (low23, high23) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
            [
                _mm256_shuffle_ps::<0x44>(low01, low23),
                _mm256_shuffle_ps::<0xee>(low01, low23),
                _mm256_shuffle_ps::<0x44>(high01, high23),
            ]
        };
        let origin = columns(a0, a1, a2, a3);
        let dir = columns(b0, b1, b2, b3);
        let row = |v: __m256| {
            let mut out = [0.0f32; WIDTH];
            // SAFETY: `out` holds eight f32; the store is unaligned.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
            out
        };
        RayRows {
            origin: [row(origin[0]), row(origin[1]), row(origin[2])],
            dir: [row(dir[0]), row(dir[1]), row(dir[2])],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::build::tests::next_signed as next;
    use glam::Vec3;

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_avx_gather_gives_the_plain_rows_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx") {
            eprintln!("skipped: this processor has no AVX, where the AVX gather never runs");
            return;
        }
        let mut state = 11;
        let value = |s: &mut u64| test_value(100.0, s);
        for round in 0..4_000 {
            let count = 1 + round % WIDTH;
            let rays: Vec<Ray> = (0..count)
                .map(|_| Ray {
                    origin: Vec3::new(value(&mut state), value(&mut state), value(&mut state)),
                    dir: Vec3::new(value(&mut state), value(&mut state), value(&mut state)),
                    t_max: value(&mut state),
                })
                .collect();
            let plain = RayRows::gather(&rays);
            // SAFETY: the processor has AVX, asked above.
            let avx = unsafe { RayRows::gather_avx(&rays) };
            let bits = |rows: &RayRows| {
                [rows.origin, rows.dir].map(|rows| rows.map(|row| row.map(f32::to_bits)))
            };
            assert_eq!(bits(&avx), bits(&plain), "{rays:?}");
        }
    }

    /// Values whose bits a conversion or an arithmetic step would change, or that a set-up
    /// must treat alike: zeros of both signs (infinite reciprocals, ties between axes), a
    /// subnormal (an infinite reciprocal from a nonzero value), infinities, a NaN with a
    /// payload, the extremes, and equal magnitudes of either sign (the major axis's ties).
    const HARD: [f32; 10] = [
        0.0,
        -0.0,
        1.0e-40,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::from_bits(0x7fc0_1234),
        f32::MAX,
        -f32::MIN_POSITIVE,
        0.5,
        -0.5,
    ];

    /// One of [`HARD`] a third of the time, else an ordinary value within `scale` of zero.
    fn test_value(scale: f32, state: &mut u64) -> f32 {
        let pick = (next(state).abs() * 3.0 * HARD.len() as f32) as usize;
        HARD.get(pick)
            .copied()
            .unwrap_or_else(|| next(state) * scale)
    }

    /// `SetUpRows::new` compiled with AVX, as the path lanes compile it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn set_up_rows_avx(origin: [&[f32; WIDTH]; 3], dir: [&[f32; WIDTH]; 3]) -> SetUpRows {
        SetUpRows::new(origin, dir)
    }

    #[test]
    fn a_lanes_set_up_is_its_rays_own_bit_for_bit() {
        let mut state = 5;
        let value = |s: &mut u64| test_value(10.0, s);
        let bits = |(wide, quad): (WideRay, QuadRay)| {
            (
                [wide.origin, wide.inv_dir].map(|v| v.map(f32::to_bits)),
                [wide.near, wide.far],
                quad.axes(),
                quad.scalars.map(f32::to_bits),
            )
        };
        for _ in 0..20_000 {
            let mut origin = [[0.0f32; WIDTH]; 3];
            let mut dir = [[0.0f32; WIDTH]; 3];
            for axis in 0..3 {
                for r in 0..WIDTH {
                    origin[axis][r] = value(&mut state);
                    dir[axis][r] = value(&mut state);
                }
            }
            let [o, d] = [&origin, &dir].map(|rows| [&rows[0], &rows[1], &rows[2]]);
            let mut made = vec![SetUpRows::new(o, d)];
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the processor has AVX, asked just above.
                made.push(unsafe { set_up_rows_avx(o, d) });
            }
            for r in 0..WIDTH {
                let ray = Ray {
                    origin: Vec3::new(origin[0][r], origin[1][r], origin[2][r]),
                    dir: Vec3::new(dir[0][r], dir[1][r], dir[2][r]),
                    t_max: f32::INFINITY,
                };
                let own = bits((WideRay::new(&ray), QuadRay::for_ray(&ray)));
                for rows in &made {
                    assert_eq!(bits(rows.lane(r)), own, "{ray:?}");
                }
            }
        }
    }
}
