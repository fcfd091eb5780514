//! `libm`'s `acos` and `sincos` written without branches, so that a loop over lanes of them
//! vectorises: the environment portals' draws in the lanes (`environment/portal.rs`,
//! `PortalDraws`). Each computes the arithmetic of every case `libm` (musl's `e_acos.c`, `__sin`,
//! `__cos` and `__rem_pio2`) might take, operation for operation, and selects the case `libm` would
//! have taken, so a lane's result is `libm`'s bit for bit: the tests below hold them to it over
//! every range and boundary. The tests on `libm`'s high words become comparisons of the floats
//! themselves (for non-negative numbers the orders agree), which vector instructions make without
//! integer lanes.
//!
//! [`sin_cos`] covers the angles of one turn and a little more, from zero to about
//! `9pi/4`: those up to about `pi/4`, which `sincos` takes as they are, and those `__rem_pio2`
//! reduces by its short path, a multiple of `pi/2` from one to four, but for the four narrow
//! bands about `pi/2`, `pi`, `3pi/2` and `2pi` where it takes its longer one. It says which
//! angles those are ([`sin_cos_covers`]); the caller computes the others with
//! [`super::sin_cos_f64`].

// The constants are musl's decimal literals verbatim, so that a reader can hold them to the
// source; they parse to the same doubles as the hexadecimal forms beside them there.
#![allow(clippy::excessive_precision)]

// musl's `pio2_hi` (0x3ff921fb54442d18) is the double nearest pi / 2.
const PIO2_HI: f64 = std::f64::consts::FRAC_PI_2;
const PIO2_LO: f64 = 6.12323399573676603587e-17;
const PS0: f64 = 1.66666666666666657415e-01;
const PS1: f64 = -3.25565818622400915405e-01;
const PS2: f64 = 2.01212532134862925881e-01;
const PS3: f64 = -4.00555345006794114027e-02;
const PS4: f64 = 7.91534994289814532176e-04;
const PS5: f64 = 3.47933107596021167570e-05;
const QS1: f64 = -2.40339491173441421878e+00;
const QS2: f64 = 2.02094576023350569471e+00;
const QS3: f64 = -6.88283971605453293030e-01;
const QS4: f64 = 7.70381505559019352791e-02;

/// `acos x`, [`super::acos_f64`]'s bits, for `x` in `[-1, 1]` (and NaN where `libm` gives
/// NaN, though not necessarily the same NaN).
#[inline(always)]
pub fn acos(x: f64) -> f64 {
    let tiny_correction = f64::from_bits(0x3870_0000_0000_0000); // 2^-120
    let ax = x.abs();
    // `r` of the case taken: of `x^2` below a half, else of `(1 - |x|) / 2` (for negative
    // `x`, `libm`'s `(1 + x) * 0.5` is the same operation on the same numbers).
    let below_half = ax < 0.5;
    let z = if below_half { x * x } else { (1.0 - ax) * 0.5 };
    let p = z * (PS0 + z * (PS1 + z * (PS2 + z * (PS3 + z * (PS4 + z * PS5)))));
    let q = 1.0 + z * (QS1 + z * (QS2 + z * (QS3 + z * QS4)));
    let r = p / q;
    let s = z.sqrt();
    // |x| < 1/2: beneath 2^-57 (a high word at most 0x3c600000) pi/2 itself.
    let small = PIO2_HI - (x - (PIO2_LO - x * r));
    let tiny = ax < f64::from_bits(0x3c60_0001_0000_0000);
    let small = if tiny {
        PIO2_HI + tiny_correction
    } else {
        small
    };
    // x < -1/2.
    let negative = 2.0 * (PIO2_HI - (s + (r * s - PIO2_LO)));
    // x > 1/2: `s` split into a high part with its low word cleared and a correction.
    let df = f64::from_bits(s.to_bits() & 0xffff_ffff_0000_0000);
    let c = (z - df * df) / (s + df);
    let positive = 2.0 * (df + (r * s + c));
    let inside = if below_half {
        small
    } else if x < 0.0 {
        negative
    } else {
        positive
    };
    // |x| >= 1 or NaN: the ends exactly, NaN beyond them.
    let end = if x == 1.0 {
        0.0
    } else if x == -1.0 {
        2.0 * PIO2_HI + tiny_correction
    } else {
        f64::NAN
    };
    if ax < 1.0 { inside } else { end }
}

const PIO2_1: f64 = 1.57079632673412561417e+00;
const PIO2_1T: f64 = 6.07710050650619224932e-11;
const S1: f64 = -1.66666666666666324348e-01;
const S2: f64 = 8.33333333332248946124e-03;
const S3: f64 = -1.98412698298579493134e-04;
const S4: f64 = 2.75573137070700676789e-06;
const S5: f64 = -2.50507602534068634195e-08;
const S6: f64 = 1.58969099521155010221e-10;
const C1: f64 = 4.16666666666666019037e-02;
const C2: f64 = -1.38888888888741095749e-03;
const C3: f64 = 2.48015872894767294178e-05;
const C4: f64 = -2.75573143513906633035e-07;
const C5: f64 = 2.08757232129817482790e-09;
const C6: f64 = -1.13596475577881948265e-11;

/// A double whose high word is `high` and low word zero: where `libm`'s tests on high words
/// fall.
const fn at_high(high: u64) -> f64 {
    f64::from_bits(high << 32)
}

/// Whether [`sin_cos`] gives `libm`'s `sincos` of `x`: `x` from zero (either) to about
/// `9 pi / 4`, a high word at most `0x401c463b`, but for the four words where
/// `__rem_pio2` takes its longer reduction (`0x3ff921fb`, `0x400921fb`, `0x4012d97c`,
/// `0x401921fb`). Not NaN, nor negative.
#[inline(always)]
pub fn sin_cos_covers(x: f64) -> bool {
    let band = |high: u64| x >= at_high(high) && x < at_high(high + 1);
    let near_multiple =
        band(0x3ff9_21fb) | band(0x4009_21fb) | band(0x4012_d97c) | band(0x4019_21fb);
    (x >= 0.0) & (x < at_high(0x401c_463c)) & !near_multiple
}

/// `(sin x, cos x)`, `libm`'s `sincos` bit for bit where [`sin_cos_covers`] `x`
/// (elsewhere a number of no meaning): up to `pi / 4`, `__sin(x, 0, 0)` and `__cos(x, 0)`
/// (below `2^-27 sqrt 2`, `x` and one); beyond, `__rem_pio2`'s short reduction by `n` times
/// `pi / 2`, `n` from one to four as its bands decide, then `__sin` and `__cos` of the
/// remainder and the quadrant's signs.
#[inline(always)]
pub fn sin_cos(x: f64) -> (f64, f64) {
    let reduced = x >= at_high(0x3fe9_21fc);
    let tiny = x < at_high(0x3e46_a09e);
    // n: 1 up to 3 pi / 4, 2 up to 5 pi / 4, 3 up to 7 pi / 4, 4 beyond.
    let two = x >= at_high(0x4002_d97d);
    let three = x >= at_high(0x400f_6a7b);
    let four = x >= at_high(0x4015_fdbd);
    let n = if four {
        4.0
    } else if three {
        3.0
    } else if two {
        2.0
    } else {
        1.0
    };
    let z = x - n * PIO2_1;
    let (y0, y1) = if reduced {
        let y0 = z - n * PIO2_1T;
        (y0, (z - y0) - n * PIO2_1T)
    } else {
        (x, 0.0)
    };
    // `__sin(y0, y1, 1)`.
    let zz = y0 * y0;
    let w = zz * zz;
    let r = S2 + zz * (S3 + zz * S4) + zz * w * (S5 + zz * S6);
    let v = zz * y0;
    let sin = y0 - ((zz * (0.5 * y1 - v * r) - y1) - v * S1);
    // `__sin(x, 0, 0)`, unreduced.
    let sin_small = y0 + v * (S1 + zz * r);
    // `__cos(y0, y1)`.
    let r = zz * (C1 + zz * (C2 + zz * C3)) + w * w * (C4 + zz * (C5 + zz * C6));
    let hz = 0.5 * zz;
    let w = 1.0 - hz;
    let cos = w + (((1.0 - w) - hz) + (zz * r - y0 * y1));
    // The quadrant, `n & 3`: 1 (c, -s), 2 (-s, -c), 3 (-c, s), 0 (s, c).
    if tiny {
        (x, 1.0)
    } else if !reduced {
        (sin_small, cos)
    } else if four {
        (sin, cos)
    } else if three {
        (-cos, sin)
    } else if two {
        (-sin, -cos)
    } else {
        (cos, -sin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Numbers from a small generator, the same every run.
    fn numbers(seed: u64, count: usize) -> impl Iterator<Item = f64> {
        let mut state = seed;
        (0..count).map(move |_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        })
    }

    /// Every double within `steps` of each of `points`, both ways.
    fn around(points: &[f64], steps: u64) -> Vec<f64> {
        let mut out = Vec::new();
        for &p in points {
            let bits = p.to_bits();
            for k in 0..=steps {
                out.push(f64::from_bits(bits + k));
                out.push(f64::from_bits(bits.saturating_sub(k)));
            }
        }
        out
    }

    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn acos_is_libms_over_the_whole_domain_and_its_boundaries() {
        let mut inputs: Vec<f64> = numbers(1, 200_000).map(|u| 2.0 * u - 1.0).collect();
        // Near the ends, near the halves, near zero and beneath 2^-57, and at the boundaries
        // of each case, both signs.
        let edges = [
            1.0,
            0.5,
            f64::from_bits(0x3c60_0000_0000_0000),
            f64::from_bits(0x3c60_0001_0000_0000),
            1e-300,
            f64::MIN_POSITIVE,
        ];
        for x in around(&edges, 3000) {
            inputs.push(x);
            inputs.push(-x);
        }
        inputs.extend(numbers(2, 50_000).map(|u| 1.0 - u * 1e-6));
        inputs.extend(numbers(3, 50_000).map(|u| u * 1e-12));
        inputs.extend([0.0, -0.0, 1.0, -1.0, f64::NAN, 1.5, -2.0, f64::INFINITY]);
        for x in inputs {
            let (ours, theirs) = (acos(x), libm::acos(x));
            assert!(same(ours, theirs), "acos({x:e}): {ours:e}, libm {theirs:e}");
        }
    }

    #[test]
    fn sin_cos_is_libms_wherever_it_covers_and_says_where_it_does_not() {
        use std::f64::consts::PI;
        let mut inputs: Vec<f64> = numbers(4, 300_000).map(|u| u * 2.5 * PI).collect();
        inputs.extend(numbers(5, 50_000).map(|u| u * PI / 4.0));
        inputs.extend(numbers(6, 20_000).map(|u| u * 1e-7));
        inputs.extend([
            0.0,
            -0.0,
            -1e-9,
            -1.0,
            f64::NAN,
            1e-300,
            f64::MIN_POSITIVE * 0.5,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ]);
        // Each band's ends and the four longer reductions' bands, at their high words.
        let highs: [u64; 14] = [
            0x3e46_a09e,
            0x3e46_a09d,
            0x3fe9_21fb,
            0x3fe9_21fc,
            0x3ff9_21fb,
            0x3ff9_21fc,
            0x4002_d97c,
            0x4002_d97d,
            0x4009_21fb,
            0x4009_21fc,
            0x400f_6a7a,
            0x400f_6a7b,
            0x4012_d97c,
            0x4015_fdbd,
        ];
        let mut edges: Vec<f64> = highs.iter().map(|&h| at_high(h)).collect();
        edges.extend([
            at_high(0x4012_d97d),
            at_high(0x4015_fdbc),
            at_high(0x4019_21fb),
            at_high(0x4019_21fc),
            at_high(0x401c_463b),
            at_high(0x401c_463c),
            PI / 4.0,
            PI / 2.0,
            PI,
            1.5 * PI,
            2.0 * PI,
            2.25 * PI,
        ]);
        inputs.extend(around(&edges, 3000));
        let mut covered = 0;
        for x in inputs {
            let theirs = libm::sincos(x);
            if sin_cos_covers(x) {
                covered += 1;
                let ours = sin_cos(x);
                assert!(
                    same(ours.0, theirs.0) && same(ours.1, theirs.1),
                    "sincos({x:e}): {ours:?}, libm {theirs:?}"
                );
            } else {
                // Outside: negative or NaN, above 9 pi / 4, or in the four narrow bands.
                let high = x.to_bits() >> 32;
                assert!(
                    x.is_nan()
                        || x < 0.0
                        || high > 0x401c_463b
                        || [0x3ff9_21fb, 0x4009_21fb, 0x4012_d97c, 0x4019_21fb].contains(&high),
                    "{x:e} (high word {high:x}) is left out"
                );
            }
        }
        assert!(covered > 250_000, "only {covered} angles were covered");
    }
}
