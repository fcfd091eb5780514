//! The SIMD triangle test of `quad.rs` on eight triangles at once, in AVX's eight f32 lanes:
//! two consecutive groups of a leaf, the first in lanes 0 to 3, the second in lanes 4 to 7.
//! Used only where the processor has AVX (chosen at run time, with the 8-wide box test of
//! `node8.rs`), so that a leaf of five to eight triangles, obvhs's largest, costs one step
//! instead of two.
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
//! and not, as here (`a & !b` is `andnot(b, a)`). So every lane's candidate bit, exact bit,
//! distance, error bound and barycentrics are the four-lane test's bits, which `quad.rs` holds
//! to the scalar test; `QuadRay::intersect_pair` is the reference the tests compare with. Where
//! it stops early (every lane outside its triangle) the two four-lane tests stop there too or
//! find every lane outside, so neither has a candidate.

use super::quad::{LaneHits, Quad, QuadRay};
use super::triangle::gamma;
use std::arch::x86_64::*;

/// [`QuadRay::intersect_pair`] in one step of eight lanes.
///
/// # Safety
/// The processor must support AVX.
#[target_feature(enable = "avx")]
#[inline]
pub(super) unsafe fn intersect_pair_avx(ray: &QuadRay, a: &Quad, b: &Quad) -> LaneHits<8> {
    let [kx, ky, kz] = ray.axes();
    let [ox, oy, oz, sx, sy, sz] = ray.scalars.map(|s| _mm256_set1_ps(s));
    // Vertex `v`'s coordinate `axis` of both groups: `a`'s lanes low, `b`'s high.
    let load = |v: usize, axis: usize| {
        let (low, high) = (&a.p[v][axis], &b.p[v][axis]);
        // SAFETY: each is four f32 in bounds of its group (`wide::f32x4` holds exactly four).
        unsafe {
            _mm256_loadu2_m128(
                (high as *const wide::f32x4).cast::<f32>(),
                (low as *const wide::f32x4).cast::<f32>(),
            )
        }
    };
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
        let x = sub(load(v, kx), ox);
        let y = sub(load(v, ky), oy);
        let z = sub(load(v, kz), oz);
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
    let valid = a.valid | b.valid << 4;
    // As in the four-lane test: where every lane is missed at the first step, nothing else
    // decides anything (both groups' tests stop there too, or find no candidate).
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
    let candidates = !(_mm256_movemask_ps(missed) as u32) & valid;
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
