//! The SIMD triangle test of `quad.rs` on eight triangles at once, in AVX's eight f32 lanes:
//! two consecutive groups of a leaf, the first in lanes 0 to 3, the second in lanes 4 to 7.
//! Used only where the processor has AVX (chosen at run time, with the 8-wide box test of
//! `node8.rs`), so that a leaf of five to eight triangles, obvhs's largest, costs one step
//! instead of two. The same lanes also take one triangle against the eight rays of a packet
//! (`packet.rs`), one ray per lane: the one body, [`watertight_lanes`], given its lanes either
//! way.
//!
//! Why it keeps the four-triangle layout rather than a leaf of eight in one block: most leaves
//! hold four triangles or fewer, and padding them all to eight would double the memory that the
//! traversal reads at random on large meshes, which is what it mostly waits on. Two groups are
//! joined in registers instead (`vinsertf128`, one instruction per coordinate).
//!
//! **Exactness.** Each lane computes exactly what [`QuadRay::intersect`] computes in the same
//! lane of its group: the same IEEE operations on the same operands in the same order, listed
//! below line for line with the four-lane code, and no fused multiply-add (only "avx" is
//! enabled, and Rust never contracts on its own). The four-lane code's comparisons are SSE's
//! ordered ones (false on NaN), and AVX's `_CMP_*_OQ` predicates are the same; its `abs` clears
//! the sign bit, as here; its `max` is `maxps` with the running value first, whose rule for NaN
//! and equal zeros (the second operand) `vmaxps` shares; its masks combine by bitwise and, or
//! and not, as here (`a & !b` is `andnot(b, a)`). So every lane's candidate bit and exact bit
//! are the four-lane test's bits, and so are the distance, error bound and barycentrics of
//! each lane with an exact bit (all that the traversal reads), which `quad.rs` holds to the
//! scalar test; `QuadRay::intersect_pair` is the reference the tests compare with. Where it
//! stops early (every lane outside its triangle, or missed by the next step: behind the ray or
//! edge on) each four-lane test stops at the same step or an earlier one, or goes on to find
//! every lane missed, so neither has a candidate.
//!
//! With a triangle against eight rays the same holds lane by lane with the roles swapped: lane
//! `r` gets the triangle's coordinates, as `Quad` stores them, and ray `r`'s own origin and
//! shear, the operands ray `r`'s four-lane test gives that triangle's lane; where every ray
//! misses the triangle by the second step, each ray's own test finds no candidate there
//! either.

use super::quad::{LaneHits, Quad, QuadRay};
use super::ray_setup::RayRows;
#[cfg(doc)]
use super::triangle::major_axis;
use super::triangle::{AXES, gamma};
use std::arch::x86_64::*;

/// [`QuadRay::intersect_pair`] in one step of eight lanes.
///
/// # Safety
/// The processor must support AVX.
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn intersect_pair_avx(ray: &QuadRay, a: &Quad, b: &Quad) -> LaneHits<8> {
    let axes = ray.axes();
    // Vertex `v`'s coordinate `j` (of the ray's permutation) of both groups: `a`'s lanes low,
    // `b`'s high.
    let load = |v: usize, j: usize| {
        let (low, high) = (&a.p[v][axes[j]], &b.p[v][axes[j]]);
        // SAFETY: each is four f32 in bounds of its group (`wide::f32x4` holds exactly four).
        unsafe {
            _mm256_loadu2_m128(
                (high as *const wide::f32x4).cast::<f32>(),
                (low as *const wide::f32x4).cast::<f32>(),
            )
        }
    };
    let ray = ray.scalars.map(|s| _mm256_set1_ps(s));
    // SAFETY: this function's own contract.
    unsafe { watertight_lanes(load, &ray, a.valid | b.valid << 4) }
}

/// One triangle of `quad` (its lane `triangle`) against the eight rays of `rays`, lane `r`
/// for ray `r`: what [`intersect_pair_avx`] computes for that triangle in its lane, with each
/// ray's own origin and shear in place of the one ray's. The rays must share their
/// permutation (`axes`), which the triangle's coordinates are taken in.
///
/// Why the results are the scalar test's: lane `r` takes the operations of the eight-lane
/// test on the operands the four-lane test of ray `r` (`QuadRay::intersect`) would give that
/// triangle's lane (its coordinates as `Quad` stores them, the ray's `QuadRay::scalars`), in
/// the same order; `quad.rs` holds those to the scalar test, lane by lane. Only `valid`
/// differs: it names the rays to be answered, and a ray outside it gets no candidate bit (its
/// lane's values are left as they come).
///
/// # Safety
/// The processor must support AVX.
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn triangle_against_rays_avx(
    rays: &RayLanes,
    quad: &Quad,
    triangle: usize,
    valid: u32,
) -> LaneHits<8> {
    let axes = rays.axes;
    let load =
        |v: usize, j: usize| _mm256_broadcast_ss(&quad.p[v][axes[j]].as_array_ref()[triangle]);
    // SAFETY: this function's own contract.
    unsafe { watertight_lanes(load, &rays.lanes, valid) }
}

/// Eight rays of a packet that share their permutation, for [`triangle_against_rays_avx`]:
/// row `k` holds, lane `r` for ray `r`, the `k`-th of ray `r`'s [`QuadRay::scalars`] (the
/// permuted origin, then the shear).
#[derive(Clone, Copy)]
pub(super) struct RayLanes {
    pub(super) axes: [usize; 3],
    pub(super) lanes: [__m256; 6],
}

impl RayLanes {
    /// The lanes of the rays in `rows`, or `None` where two of them permute the axes
    /// differently (a triangle's coordinates are then not the same lanes for all). Lane `r`
    /// of each row is what `ShearedRay::new` computes for ray `r`, with the same operations
    /// (a test holds them to it, bit for bit): its axis choice ([`major_axis`]: `z` is `x`
    /// where `|x| > |y|` and `|x| > |z|`, else `y` where `|y| > |z|`, else `z`), its permuted
    /// origin, and its shear, `-d[kx] / d[kz]`, `-d[ky] / d[kz]` and `1 / d[kz]`.
    ///
    /// Written in AVX instructions: in plain loops the compiler took the rows apart into
    /// scalars and put them together again.
    ///
    /// # Safety
    /// The processor must support AVX.
    #[target_feature(enable = "avx")]
    #[inline]
    pub(super) unsafe fn new(rows: &RayRows) -> Option<RayLanes> {
        // SAFETY: each row holds eight f32; the loads are unaligned.
        let load = |row: &[f32; 8]| unsafe { _mm256_loadu_ps(row.as_ptr()) };
        let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX));
        let [ax, ay, az] = [0, 1, 2].map(|axis| _mm256_and_ps(load(&rows.dir[axis]), magnitude));
        let greater = |a, b| _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(a, b)) as u32;
        let x_over_y = greater(ax, ay);
        let x_major = x_over_y & greater(ax, az);
        let y_major = !x_over_y & greater(ay, az) & 0xff;
        let kz = match (x_major, y_major) {
            (0xff, _) => 0,
            (_, 0xff) => 1,
            (0, 0) => 2,
            _ => return None,
        };
        let [kx, ky, _] = AXES[kz];
        let (dx, dy, dz) = (
            load(&rows.dir[kx]),
            load(&rows.dir[ky]),
            load(&rows.dir[kz]),
        );
        let negate = |x| _mm256_xor_ps(x, _mm256_set1_ps(-0.0));
        Some(RayLanes {
            axes: AXES[kz],
            lanes: [
                load(&rows.origin[kx]),
                load(&rows.origin[ky]),
                load(&rows.origin[kz]),
                _mm256_div_ps(negate(dx), dz),
                _mm256_div_ps(negate(dy), dz),
                _mm256_div_ps(_mm256_set1_ps(1.0), dz),
            ],
        })
    }
}

/// The eight-lane watertight test, as far as it goes in f32, on the permuted coordinate
/// lanes `coordinate(v, j)` of vertex `v` and the ray lanes `ray` (the permuted origin, then
/// the shear): the one body of [`intersect_pair_avx`] and [`triangle_against_rays_avx`].
///
/// # Safety
/// The processor must support AVX.
#[target_feature(enable = "avx")]
#[inline]
unsafe fn watertight_lanes(
    coordinate: impl Fn(usize, usize) -> __m256,
    ray: &[__m256; 6],
    valid: u32,
) -> LaneHits<8> {
    let [ox, oy, oz, sx, sy, sz] = *ray;
    let zero = _mm256_setzero_ps();
    let lt = |x, y| _mm256_cmp_ps::<_CMP_LT_OQ>(x, y);
    let gt = |x, y| _mm256_cmp_ps::<_CMP_GT_OQ>(x, y);
    let le = |x, y| _mm256_cmp_ps::<_CMP_LE_OQ>(x, y);
    let ge = |x, y| _mm256_cmp_ps::<_CMP_GE_OQ>(x, y);
    let eq = |x, y| _mm256_cmp_ps::<_CMP_EQ_OQ>(x, y);
    let or = |x, y| _mm256_or_ps(x, y);
    let and = |x, y| _mm256_and_ps(x, y);
    let mul = |x, y| _mm256_mul_ps(x, y);
    let add = |x, y| _mm256_add_ps(x, y);
    let sub = |x, y| _mm256_sub_ps(x, y);
    let abs = |x| _mm256_and_ps(x, _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX)));
    let splat = |x: f32| _mm256_set1_ps(x);

    // `sheared(v)`: `(x + sx * z, y + sy * z, z)` of `p - origin`, permuted.
    let sheared = |v: usize| {
        let x = sub(coordinate(v, 0), ox);
        let y = sub(coordinate(v, 1), oy);
        let z = sub(coordinate(v, 2), oz);
        (add(x, mul(sx, z)), add(y, mul(sy, z)), z)
    };
    let (p0, p1, p2) = (sheared(0), sheared(1), sheared(2));
    // `edge(a, b)`: `a.x * b.y - a.y * b.x`.
    let edge = |a: (__m256, __m256, __m256), b: (__m256, __m256, __m256)| {
        sub(mul(a.0, b.1), mul(a.1, b.0))
    };
    let (e0, e1, e2) = (edge(p1, p2), edge(p2, p0), edge(p0, p1));
    let negative = or(or(lt(e0, zero), lt(e1, zero)), lt(e2, zero));
    let positive = or(or(gt(e0, zero), gt(e1, zero)), gt(e2, zero));
    let outside = and(negative, positive);
    // As in the four-lane test: where every lane is missed at the first step, nothing else
    // decides anything (the four-lane tests of those triangles, or of those rays, stop there
    // too, or find no candidate).
    if !(_mm256_movemask_ps(outside) as u32) & valid == 0 {
        return LaneHits::NONE;
    }
    let zero_edge = or(or(eq(e0, zero), eq(e1, zero)), eq(e2, zero));

    let det = add(add(e0, e1), e2);
    let z0 = mul(p0.2, sz);
    let z1 = mul(p1.2, sz);
    let z2 = mul(p2.2, sz);
    let t_scaled = add(add(mul(e0, z0), mul(e1, z1)), mul(e2, z2));
    let behind = or(
        and(lt(det, zero), ge(t_scaled, zero)),
        and(gt(det, zero), le(t_scaled, zero)),
    );
    // `outside | ((det == 0 | behind) & !zero_edge)`.
    let missed = or(
        outside,
        _mm256_andnot_ps(zero_edge, or(eq(det, zero), behind)),
    );
    // And where every lane is missed by the second step (outside, or a triangle behind the
    // ray or seen edge on), the division and the error bound decide nothing either.
    let candidates = !(_mm256_movemask_ps(missed) as u32) & valid;
    if candidates == 0 {
        return LaneHits::NONE;
    }
    let inv_det = _mm256_div_ps(splat(1.0), det);
    let t = mul(t_scaled, inv_det);

    let max3 = |a, b, c| _mm256_max_ps(_mm256_max_ps(abs(a), abs(b)), abs(c));
    let max_zt = max3(z0, z1, z2);
    let delta_z = mul(splat(gamma(3)), max_zt);
    let max_xt = max3(p0.0, p1.0, p2.0);
    let max_yt = max3(p0.1, p1.1, p2.1);
    let delta_x = mul(splat(gamma(5)), add(max_xt, max_zt));
    let delta_y = mul(splat(gamma(5)), add(max_yt, max_zt));
    // `2 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt)`.
    let delta_e = mul(
        splat(2.0),
        add(
            add(
                mul(mul(splat(gamma(2)), max_xt), max_yt),
                mul(delta_y, max_xt),
            ),
            mul(delta_x, max_yt),
        ),
    );
    let max_e = max3(e0, e1, e2);
    // `3 * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * |inv_det|`.
    let delta_t = mul(
        mul(
            splat(3.0),
            add(
                add(
                    mul(mul(splat(gamma(3)), max_e), max_zt),
                    mul(delta_e, max_zt),
                ),
                mul(delta_z, max_e),
            ),
        ),
        abs(inv_det),
    );
    let bounded = and(gt(t, delta_t), lt(abs(t), splat(f32::INFINITY)));
    let exact = _mm256_movemask_ps(_mm256_andnot_ps(zero_edge, bounded)) as u32 & candidates;
    let store = |x: __m256| {
        let mut out = [0.0f32; 8];
        // SAFETY: `out` holds eight f32; the store is unaligned.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), x) };
        out
    };
    LaneHits {
        candidates,
        exact,
        t: store(t),
        t_error: store(delta_t),
        b: [
            store(mul(e0, inv_det)),
            store(mul(e1, inv_det)),
            store(mul(e2, inv_det)),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;
    use crate::geometry::build::tests::next_signed as next;
    use crate::geometry::quad::LANES;
    use crate::geometry::triangle::ShearedRay;
    use glam::Vec3;

    /// Eight rays against four triangles, at scales from a millimetre to ten kilometres and
    /// far from the origin, the rays from one point (a pixel's) or from a disc (a lens's),
    /// aimed at a point that half the triangles have as a vertex (so that edge functions are
    /// exactly zero and lanes go to the scalar test) or nearby: each ray's lane of
    /// `triangle_against_rays_avx`, for each triangle, is that triangle's lane of the
    /// four-lane test of that ray alone, in everything the packet walk reads.
    #[test]
    fn a_triangle_against_eight_rays_is_each_rays_own_four_lane_test_bit_for_bit() {
        if !crate::geometry::node8::avx_available() {
            eprintln!("skipped: this processor has no AVX, so there is no such step to run");
            return;
        }
        let mut state = 23;
        let point = |s: &mut u64| Vec3::new(next(s), next(s), next(s));
        let (mut compared, mut exact, mut scalar, mut mixed) = (0, 0, 0, 0);
        for round in 0..6_000 {
            let scale = [1e-3, 1.0, 1e4][round % 3];
            let centre = [Vec3::ZERO, Vec3::new(3e4, -1e4, 2e4)][round / 3 % 2] * scale;
            let aim = centre + point(&mut state) * (0.5 * scale);
            let triangles: Vec<[Vec3; 3]> = (0..LANES)
                .map(|i| {
                    let a = if i % 2 == 0 {
                        aim
                    } else {
                        centre + point(&mut state) * scale
                    };
                    let mut other = || centre + point(&mut state) * scale;
                    [a, other(), other()]
                })
                .collect();
            let eye = centre + point(&mut state) * (4.0 * scale);
            // Independent of the scale (`round % 3`) and the place (`round / 3 % 2`).
            let spread = [0.0, 1e-3, 0.05][round / 6 % 3];
            let rays: Vec<Ray> = (0..8)
                .map(|r| {
                    let origin = if round % 2 == 0 {
                        eye
                    } else {
                        eye + point(&mut state) * (spread * scale)
                    };
                    let target = if r % 3 == 0 {
                        aim
                    } else {
                        aim + point(&mut state) * (spread * scale)
                    };
                    Ray {
                        origin,
                        dir: target - origin,
                        t_max: f32::INFINITY,
                    }
                })
                .collect();
            let quad_rays: [QuadRay; 8] = std::array::from_fn(|r| QuadRay::for_ray(&rays[r]));
            // SAFETY: this processor has AVX (checked above).
            let Some(lanes) = (unsafe { RayLanes::new(&RayRows::gather(&rays)) }) else {
                // Rays that permute the axes differently are not put in lanes.
                let kz = quad_rays[0].axes()[2];
                assert!(quad_rays.iter().any(|q| q.axes()[2] != kz));
                mixed += 1;
                continue;
            };
            let quad = Quad::pack(&[0, 1, 2, 3], 0, |i| triangles[i as usize])
                .next()
                .expect("four triangles, one group");
            let alone: Vec<LaneHits<LANES>> =
                quad_rays.iter().map(|q| q.intersect(&quad)).collect();
            for (i, triangle) in triangles.iter().enumerate() {
                for valid in [0xff, 0b1010_0110] {
                    // SAFETY: this processor has AVX (checked above).
                    let together = unsafe { triangle_against_rays_avx(&lanes, &quad, i, valid) };
                    for r in (0..8).filter(|r| valid & (1 << r) != 0) {
                        let one = &alone[r];
                        let candidate = one.candidates & (1 << i) != 0;
                        assert_eq!(
                            together.candidates & (1 << r) != 0,
                            candidate,
                            "ray {r}, triangle {i}: {triangle:?} by {:?}",
                            rays[r]
                        );
                        let settled = one.exact & (1 << i) != 0;
                        assert_eq!(
                            together.exact & (1 << r) != 0,
                            settled,
                            "ray {r}, triangle {i}"
                        );
                        if settled {
                            let bits = |h: crate::geometry::TriangleHit| {
                                [h.t, h.t_error, h.b0, h.b1, h.b2].map(f32::to_bits)
                            };
                            assert_eq!(bits(together.hit(r)), bits(one.hit(i)));
                            exact += 1;
                        } else if candidate {
                            scalar += 1;
                        }
                        compared += 1;
                    }
                }
            }
        }
        // Sanity checks that the comparison is not vacuous: many lanes settled in SIMD, many
        // left to the scalar test (the zero edge functions), and most packets in lanes.
        assert!(compared > 200_000, "{compared} lanes compared");
        assert!(exact > 10_000, "only {exact} lanes settled in SIMD");
        assert!(
            scalar > 5_000,
            "only {scalar} candidates left to the scalar test"
        );
        assert!(
            mixed < 600,
            "{mixed} of 6000 packets permuted their axes differently"
        );
    }

    /// The rays' lanes made in rows are, lane for lane and bit for bit, what each ray's own
    /// `ShearedRay` holds, over directions that make the set-up hard: zeros of both signs,
    /// subnormals, the extremes of the normal range, infinities, NaN, and components of equal
    /// magnitude, where the axis choice breaks ties; and they are refused exactly where the
    /// rays' axes differ.
    #[test]
    fn ray_lanes_made_in_rows_are_each_rays_own_set_up_bit_for_bit() {
        if !crate::geometry::node8::avx_available() {
            eprintln!("skipped: this processor has no AVX, so the lanes are never made");
            return;
        }
        const HARD: [f32; 15] = [
            0.0,
            -0.0,
            1e-40,
            -1e-40,
            f32::MIN_POSITIVE,
            1.0,
            -1.0,
            0.75,
            -3.0,
            1e20,
            -1e20,
            f32::MAX,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        let mut state = 0x07a9_e5e7_u64;
        let pick = |state: &mut u64| {
            let i = (next(state).to_bits() as usize) % HARD.len();
            HARD[i]
        };
        let (mut together, mut refused) = (0, 0);
        for round in 0..4000 {
            // A shared direction most of the time, so that the lanes are made at all.
            let shared = Vec3::new(pick(&mut state), pick(&mut state), pick(&mut state));
            let rays: Vec<Ray> = (0..1 + round % 8)
                .map(|r| Ray {
                    origin: Vec3::new(next(&mut state), next(&mut state), 1e3 * next(&mut state)),
                    dir: if round % 3 == 0 && r > 0 {
                        Vec3::new(pick(&mut state), pick(&mut state), pick(&mut state))
                    } else {
                        shared
                    },
                    t_max: f32::INFINITY,
                })
                .collect();
            let alone: Vec<ShearedRay> = rays.iter().map(ShearedRay::new).collect();
            let lane_of = |r: usize| &alone[r.min(rays.len() - 1)];
            // SAFETY: this processor has AVX (checked above).
            let Some(lanes) = (unsafe { RayLanes::new(&RayRows::gather(&rays)) }) else {
                assert!(alone.iter().any(|s| s.kz != alone[0].kz), "{rays:?}");
                refused += 1;
                continue;
            };
            assert!(alone.iter().all(|s| s.kz == alone[0].kz), "{rays:?}");
            assert_eq!(lanes.axes, AXES[alone[0].kz]);
            for r in 0..8 {
                let own = QuadRay::scalars_of(lane_of(r));
                for (row, value) in lanes.lanes.iter().zip(own) {
                    let mut row_values = [0.0f32; 8];
                    // SAFETY: eight f32 of room; the store is unaligned.
                    unsafe { _mm256_storeu_ps(row_values.as_mut_ptr(), *row) };
                    let lane = row_values[r];
                    assert_eq!(lane.to_bits(), value.to_bits(), "lane {r} of {rays:?}");
                }
            }
            together += 1;
        }
        assert!(
            together > 2000 && refused > 300,
            "{together} made, {refused} refused"
        );
    }
}
