//! The exponential and the logarithm the media need, in our own f64 arithmetic: basic IEEE
//! operations in a fixed order, so that images do not depend on which variant of glibc's
//! `expf`/`logf` a processor gets at run time (see the module above).
//!
//! A transmittance needs `exp(-x)` of three channels at once. [`exp_neg_each`] takes two of
//! them in the two f64 lanes of one SSE2 register (every x86-64 processor has SSE2) and the
//! third alone: both go through one generic body ([`exp_neg_lanes`]) over [`Lanes`], whose
//! lanes add, multiply and truncate exactly as one `f64` does, so each lane computes the very
//! operations [`exp_neg`] computes, in the same order, and rounds to the same bits. A test holds
//! the two to each other bit for bit. In the fog box the three calls of every transmittance had
//! been the largest single cost of the render (docs/bench.md, issue 16, "The exponential of
//! three channels in two lanes").

use std::ops::{Add, Mul, Neg, Sub};

/// `exp(-x)` for `x >= 0` (and `+inf`, giving 0), by range reduction to `x = k ln 2 + r` with
/// `|r| <= ln 2 / 2` and a degree-11 Taylor polynomial of `exp(-r)` in f64 (a tail below
/// 2^-47): within one f32 rounding of the exact value, and the same bits on every machine.
///
/// The polynomial multiplies by constant coefficients rather than dividing by `n` at each step,
/// as this function once did: a division cannot be turned into a multiplication without
/// changing its rounding, so the compiler kept thirteen dependent f64 divisions, about 200
/// cycles per call, and three calls per transmittance made it a third of a fog render's time.
pub fn exp_neg(x: f32) -> f32 {
    match special(x) {
        Some(value) => value,
        None => exp_neg_lanes(f64::from(x)) as f32,
    }
}

/// [`exp_neg`] of each component of `x` (each `>= 0`, `+inf` or NaN), the same bits as three
/// calls: the first two components in the lanes of one SSE2 register, the third alone.
#[inline]
pub fn exp_neg_each(x: glam::Vec3) -> glam::Vec3 {
    #[cfg(target_arch = "x86_64")]
    {
        let [a, b] = sse2::exp_neg_pair(x.x, x.y);
        glam::Vec3::new(
            special(x.x).unwrap_or(a),
            special(x.y).unwrap_or(b),
            special(x.z).unwrap_or_else(|| exp_neg_lanes(f64::from(x.z)) as f32),
        )
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        glam::Vec3::new(exp_neg(x.x), exp_neg(x.y), exp_neg(x.z))
    }
}

/// The natural logarithm of `y` in `(0, 1]`, in f64 by `ln(m 2^e) = e ln 2 + 2 atanh((m - 1) /
/// (m + 1))` with `m` in `[sqrt(1/2), sqrt(2))`: the same bits on every machine.
pub fn ln(y: f32) -> f32 {
    let y = f64::from(y);
    if y.is_nan() || y <= 0.0 {
        return if y == 0.0 {
            f32::NEG_INFINITY
        } else {
            f32::NAN
        };
    }
    // f32 inputs are normal in f64, so the exponent field is the binary exponent.
    let bits = y.to_bits();
    let mut e = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut m = f64::from_bits((bits & ((1u64 << 52) - 1)) | (1023u64 << 52));
    if m >= std::f64::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    // sum s^(2n+1) / (2n+1), n = 0..9; |s| <= 0.172 leaves a tail below 2^-55. By Estrin's
    // scheme, as in `exp_neg`: a free flight's distance waits on this.
    let p = estrin(&ATANH_SERIES, s2);
    (e as f64 * std::f64::consts::LN_2 + 2.0 * s * p) as f32
}

/// What [`exp_neg`] returns without its polynomial: NaN for NaN, 0 past 104 (`exp(-104)` is
/// below half the smallest f32 subnormal, and `+inf` is past it); `None` for the rest.
#[inline(always)]
fn special(x: f32) -> Option<f32> {
    if x.is_nan() {
        Some(f32::NAN)
    } else if x > 104.0 {
        Some(0.0)
    } else {
        None
    }
}

/// One f64, or several side by side in SIMD lanes: what [`exp_neg_lanes`] and [`estrin`]
/// compute with. Every lane of an implementation must round each operation exactly as `f64`
/// does (IEEE addition, subtraction and multiplication, a sign flip for negation, truncation
/// toward zero), which the basic SSE2 operations do.
trait Lanes:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Neg<Output = Self>
{
    /// Every lane `x`.
    fn splat(x: f64) -> Self;
    /// `k = trunc(t)` per lane (each in `0..=1023`, which [`exp_neg_lanes`]'s arguments keep
    /// it in), as a float, and `2^-k`, exact.
    fn truncate_with_scale(self) -> (Self, Self);
}

impl Lanes for f64 {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }

    #[inline(always)]
    fn truncate_with_scale(self) -> (Self, Self) {
        // Truncation is the floor here (the argument is at least 0.5), and unlike `floor` it
        // needs no call into libm on the baseline x86-64 target.
        let k = self as i64;
        (k as f64, f64::from_bits(((1023 - k) as u64) << 52))
    }
}

/// `exp(-x)` of every lane of `x` in `[0, 104]` (other lanes give unspecified values), rounded
/// to f32 by the caller: [`exp_neg`]'s body, for one f64 or for lanes.
#[inline(always)]
fn exp_neg_lanes<T: Lanes>(x: T) -> T {
    // The nearest integer to x / ln 2.
    let (k, scale) = (x * T::splat(std::f64::consts::LOG2_E) + T::splat(0.5)).truncate_with_scale();
    let r = x - k * T::splat(std::f64::consts::LN_2);
    // sum (-r)^n / n!, n = 0..11, by Estrin's scheme: pairs of terms, then pairs of pairs,
    // combined by r^2, r^4 and r^8. Horner's rule takes eleven dependent steps of a product and
    // a sum, about 90 cycles per call (most of a fog render's transmittance); this, four.
    // `scale` is 2^-k for k in [0, 150]: exact in f64.
    estrin(&EXP_NEG_TAYLOR, -r) * scale
}

/// `1 / n!` for n = 0..11, the Taylor coefficients [`exp_neg`] alternates the signs of;
/// evaluated by the compiler, the same constants on every machine.
const EXP_NEG_TAYLOR: [f64; 12] = {
    let mut c = [1.0f64; 12];
    let mut n = 1;
    while n < 12 {
        c[n] = c[n - 1] / n as f64;
        n += 1;
    }
    c
};

/// `1 / (2n + 1)` for n = 0..9, the series [`ln`] sums.
const ATANH_SERIES: [f64; 10] = {
    let mut c = [1.0f64; 10];
    let mut n = 0;
    while n < 10 {
        c[n] = 1.0 / (2 * n + 1) as f64;
        n += 1;
    }
    c
};

/// `sum c[n] x^n` by Estrin's scheme: the terms in pairs `c[2i] + c[2i+1] x`, then pairs of
/// those by `x^2`, of those by `x^4`, and so on (an odd one out carried up as it is), so that
/// the dependent chain is as long as the number of halvings rather than the number of terms.
/// Its f64 roundings differ from Horner's rule's by a few units of 2^-53 of the sum, far below
/// the f32 the callers round to.
#[inline(always)]
fn estrin<T: Lanes, const N: usize>(c: &[f64; N], x: T) -> T {
    let mut terms = c.map(T::splat);
    let mut len = N;
    let mut power = x;
    while len > 1 {
        // Pair `i` reads terms `2i` and `2i + 1` before anything writes them: writes stay
        // below `i + 1`.
        for i in 0..len / 2 {
            terms[i] = terms[2 * i] + power * terms[2 * i + 1];
        }
        if len % 2 == 1 {
            terms[len / 2] = terms[len - 1];
        }
        len = len.div_ceil(2);
        power = power * power;
    }
    terms[0]
}

#[cfg(target_arch = "x86_64")]
mod sse2 {
    //! Two f64 lanes in an SSE2 register. SSE2 is part of x86-64 itself, so these need no
    //! check of the processor; its packed operations round each lane as the scalar ones do.
    //! Every `unsafe` block below holds SSE2 intrinsics alone, which are sound to call on any
    //! x86-64 processor (the `SAFETY` notes say so once each).

    use super::{Lanes, exp_neg_lanes};
    use std::arch::x86_64::{
        __m128d, _mm_add_pd, _mm_castsi128_pd, _mm_cvtepi32_pd, _mm_cvtpd_ps, _mm_cvttpd_epi32,
        _mm_mul_pd, _mm_set_pd, _mm_set1_epi32, _mm_set1_pd, _mm_setzero_si128, _mm_slli_epi64,
        _mm_storeu_ps, _mm_sub_epi32, _mm_sub_pd, _mm_unpacklo_epi32, _mm_xor_pd,
    };
    use std::ops::{Add, Mul, Neg, Sub};

    /// [`exp_neg_lanes`] of `a` and `b` at once, rounded to f32 (unspecified where
    /// [`super::special`] decides).
    #[inline(always)]
    pub(super) fn exp_neg_pair(a: f32, b: f32) -> [f32; 2] {
        // SAFETY: SSE2, on x86-64.
        let x = F64x2(unsafe { _mm_set_pd(f64::from(b), f64::from(a)) });
        let mut out = [0.0f32; 4];
        // SAFETY: SSE2, on x86-64; `out` holds the four floats the unaligned store writes (the
        // conversion's upper two are zero).
        unsafe { _mm_storeu_ps(out.as_mut_ptr(), _mm_cvtpd_ps(exp_neg_lanes(x).0)) };
        [out[0], out[1]]
    }

    #[derive(Clone, Copy)]
    struct F64x2(__m128d);

    /// `impl $Trait for F64x2` by the packed instruction `$packed`, lane by lane.
    macro_rules! lanewise {
        ($($Trait:ident $method:ident $packed:ident),*) => {$(
            impl $Trait for F64x2 {
                type Output = Self;
                #[inline(always)]
                fn $method(self, other: Self) -> Self {
                    // SAFETY: SSE2, on x86-64.
                    F64x2(unsafe { $packed(self.0, other.0) })
                }
            }
        )*};
    }

    lanewise!(Add add _mm_add_pd, Sub sub _mm_sub_pd, Mul mul _mm_mul_pd);

    impl Neg for F64x2 {
        type Output = Self;
        /// The sign bit flipped, as `-x` of an f64 does (not `0 - x`, which turns -0 into +0).
        #[inline(always)]
        fn neg(self) -> Self {
            // SAFETY: SSE2, on x86-64.
            F64x2(unsafe { _mm_xor_pd(self.0, _mm_set1_pd(-0.0)) })
        }
    }

    impl Lanes for F64x2 {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            // SAFETY: SSE2, on x86-64.
            F64x2(unsafe { _mm_set1_pd(x) })
        }

        #[inline(always)]
        fn truncate_with_scale(self) -> (Self, Self) {
            // Truncation toward zero into 32-bit integers, as `as i64` truncates (every `k` a
            // lane of ours can hold fits); then `1023 - k` into each 64-bit lane's exponent.
            // SAFETY: SSE2, on x86-64.
            unsafe {
                let k = _mm_cvttpd_epi32(self.0);
                let biased = _mm_sub_epi32(_mm_set1_epi32(1023), k);
                let wide = _mm_unpacklo_epi32(biased, _mm_setzero_si128());
                (
                    F64x2(_mm_cvtepi32_pd(k)),
                    F64x2(_mm_castsi128_pd(_mm_slli_epi64::<52>(wide))),
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estrin_sums_every_term_of_polynomials_of_every_length() {
        // Integer coefficients at x = 3: every product and sum is exact in f64, so any other
        // order of the same terms gives the same value, and a term left out or taken twice
        // (an odd one out dropped, a pair misaligned) shows.
        fn check<const N: usize>() {
            let c: [f64; N] = std::array::from_fn(|n| (n + 1) as f64);
            let horner = c.iter().rev().fold(0.0, |p, &c| c + 3.0 * p);
            assert_eq!(estrin(&c, 3.0), horner, "{N} terms");
        }
        macro_rules! check_lengths {
            ($($n:literal)*) => { $(check::<$n>();)* };
        }
        check_lengths!(1 2 3 4 5 6 7 8 9 10 11 12 13);
    }

    #[test]
    fn exp_and_ln_match_the_f64_library_across_their_ranges() {
        // A grid over [0, 100], and a geometric sweep from 1e-30 to 104 that reaches the
        // smallest arguments and the subnormal results.
        let grid = (0..=20_000).map(|i| i as f32 * 0.005);
        let sweep = (0..=3_000).map(|i| 1e-30f32 * 104e30f32.powf(i as f32 / 3_000.0));
        for x in grid.chain(sweep) {
            let ours = f64::from(exp_neg(x));
            let exact = (-f64::from(x)).exp();
            let tolerance = exact * 2.0f64.powi(-23) + f64::from(f32::from_bits(1));
            assert!(
                (ours - exact).abs() <= tolerance,
                "exp(-{x}): {ours} vs {exact}"
            );
        }
        assert_eq!(exp_neg(0.0), 1.0);
        assert_eq!(exp_neg(f32::INFINITY), 0.0);
        for i in 1..=(1 << 12) {
            let y = i as f32 / (1 << 12) as f32;
            for y in [y, y * 1e-6] {
                let ours = f64::from(ln(y));
                let exact = f64::from(y).ln();
                let tolerance = exact.abs() * 2.0f64.powi(-23) + 1e-9;
                assert!(
                    (ours - exact).abs() <= tolerance,
                    "ln({y}): {ours} vs {exact}"
                );
            }
        }
        assert_eq!(ln(1.0), 0.0);
    }

    #[test]
    fn exp_of_each_channel_is_exp_of_each_channel_alone_bit_for_bit() {
        // Every 4099th float from 0 up to past 104 (subnormals, the range reduction's every
        // `k`, the cut-off), the edges themselves, and random bit patterns of every exponent.
        let strided = (0..=104f32.next_up().to_bits())
            .step_by(4099)
            .map(f32::from_bits);
        let edges = [
            0.0,
            -0.0,
            f32::from_bits(1),
            f32::MIN_POSITIVE,
            0.5 * std::f32::consts::LN_2,
            std::f32::consts::LN_2,
            104.0f32.next_down(),
            104.0,
            104.0f32.next_up(),
            f32::MAX,
            f32::INFINITY,
            f32::NAN,
        ];
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let random = std::iter::repeat_with(move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            f32::from_bits((state >> 33) as u32 & 0x7fff_ffff)
        })
        .take(100_000);
        let xs: Vec<f32> = strided.chain(edges).chain(random).collect();
        // Each argument in each of the three places, beside different neighbours.
        for (i, &x) in xs.iter().enumerate() {
            let (y, z) = (xs[(i + 1) % xs.len()], xs[(i * 7 + 3) % xs.len()]);
            for v in [
                glam::Vec3::new(x, y, z),
                glam::Vec3::new(y, x, z),
                glam::Vec3::new(z, y, x),
            ] {
                for (got, arg) in exp_neg_each(v).to_array().into_iter().zip(v.to_array()) {
                    assert_eq!(got.to_bits(), exp_neg(arg).to_bits(), "exp(-{arg:e})");
                }
            }
        }
    }
}
