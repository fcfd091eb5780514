//! The transcendental functions of pixel math, computed the same on every machine.
//!
//! `f32::sin_cos`, `atan2`, `powf` and their kin call the platform's C library, and glibc picks
//! among implementations of some of them when the program starts, by the processor's features
//! (`__sincosf_fma` on a machine with fused multiply-add, another without), which need not round
//! alike: the same scene could then render different bits on two x86-64 machines. These call
//! `libm` instead, a pure-software port of musl's implementations that uses only IEEE basic
//! operations in a fixed order (built without its architecture-specific paths). Everything in
//! the tracer that decides a pixel goes through here; `tests/portable_math.rs` checks that no
//! other call creeps in.

pub(crate) mod branchless;

/// `(sin x, cos x)`.
pub fn sin_cos(x: f32) -> (f32, f32) {
    libm::sincosf(x)
}

/// `(sin x, cos x)` in double precision.
pub fn sin_cos_f64(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// `acos x` in double precision, in `[0, pi]`.
pub fn acos_f64(x: f64) -> f64 {
    libm::acos(x)
}

/// `sin x`.
pub fn sin(x: f32) -> f32 {
    libm::sinf(x)
}

/// `tan x`.
pub fn tan(x: f32) -> f32 {
    libm::tanf(x)
}

/// The angle of `(x, y)` from the positive x axis, in `[-pi, pi]`.
pub fn atan2(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}

/// `x` to the power `y`.
pub fn powf(x: f32, y: f32) -> f32 {
    libm::powf(x, y)
}

/// The hyperbolic tangent of `x`.
pub fn tanh(x: f32) -> f32 {
    libm::tanhf(x)
}

/// The inverse hyperbolic tangent of `x`, for `x` in (-1, 1).
pub fn atanh(x: f32) -> f32 {
    libm::atanhf(x)
}

/// The hyperbolic cosine of `x`.
pub fn cosh(x: f32) -> f32 {
    libm::coshf(x)
}

/// Shirley and Chiu's concentric map of the unit square onto the unit disk: uniform in area,
/// and it keeps neighbouring points neighbours (stratification survives). The one map of the
/// tracer's cosine-weighted directions and of its thin lens.
///
/// Written without branches (each choice is a select), so that a loop over paths in lanes
/// turns it into vector instructions (`integrator/lanes/`); a point's angle is taken from
/// the axis nearer to it, within an eighth of a turn, where [`sin_cos_quarter`] needs no
/// reduction: a point off the y axis by `phi` lies at `pi/2 - phi`, whose sine and cosine
/// are `phi`'s cosine and sine.
#[inline(always)]
pub fn concentric_disk(u: glam::Vec2) -> glam::Vec2 {
    use std::f32::consts::FRAC_PI_4;
    let o = 2.0 * u - glam::Vec2::ONE;
    let x_nearer = o.x.abs() > o.y.abs();
    let (r, ratio) = if x_nearer {
        (o.x, o.y / o.x)
    } else {
        (o.y, o.x / o.y)
    };
    let (sin, cos) = sin_cos_quarter(FRAC_PI_4 * ratio);
    let d = if x_nearer {
        glam::Vec2::new(cos, sin)
    } else {
        glam::Vec2::new(sin, cos)
    };
    // The centre, where both branches divided zero by zero.
    if o == glam::Vec2::ZERO {
        glam::Vec2::ZERO
    } else {
        r * d
    }
}

/// `(sin x, cos x)` for `|x| <= pi/4`: the two kernels `libm`'s `sincosf` evaluates over that
/// range (musl's, from FreeBSD: polynomials in f64, rounded once to f32), with no branch and
/// no reduction, so that it vectorises. Below `2^-12` `sincosf` returns `(x, 1)` without the
/// kernels, and so does this (the kernels round to the same but for `sin(-0)`); at `pi/4` itself (as an f32, just above the exact value)
/// `sincosf` reduces by `pi/2` first, and this keeps the kernels.
#[inline(always)]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let tiny = x.abs() < f32::from_bits(0x3980_0000);
    let (sin, cos) = quarter_kernels(f64::from(x));
    // Below 2^-12 the sine is `x` itself, as `sincosf` returns it: the kernel agrees but
    // for the sign of zero (`-0 + 0` is `+0`).
    (if tiny { x } else { sin }, cos)
}

/// `libm`'s `sincosf` kernels (musl's `__sindf` and `__cosdf`): the sine and cosine of `y`,
/// `|y| <= pi/4`, by polynomials in f64, each rounded once to f32.
#[inline(always)]
// The constants are musl's decimal literals verbatim, so that a reader can hold them to the
// source; they parse to the same doubles as the hexadecimal forms beside them there.
#[allow(clippy::excessive_precision)]
fn quarter_kernels(y: f64) -> (f32, f32) {
    const S1: f64 = -0.166666666416265235595;
    const S2: f64 = 0.0083333293858894631756;
    const S3: f64 = -0.000198393348360966317347;
    const S4: f64 = 0.0000027183114939898219064;
    const C0: f64 = -0.499999997251031003120;
    const C1: f64 = 0.0416666233237390631894;
    const C2: f64 = -0.00138867637746099294692;
    const C3: f64 = 0.0000243904487962774090654;
    let z = y * y;
    let w = z * z;
    let s = z * y;
    let sin = (y + s * (S1 + z * S2)) + s * w * (S3 + z * S4);
    let cos = ((1.0 + z * C0) + w * C1) + (w * z) * (C2 + z * C3);
    (sin as f32, cos as f32)
}

/// `(sin 2 pi u, cos 2 pi u)` for `u` in [0, 1], without a branch, so that it vectorises: the
/// turn is split, exactly, into the nearest quarter turn `k/4` and the rest `t = u - k/4`
/// (within an eighth of a turn; the subtraction is exact by Sterbenz's lemma), the rest's
/// angle `2 pi t` is taken in f64 by the kernels [`sin_cos_quarter`] uses, and the quarter
/// turns rotate the pair by selects. More accurate than `sin_cos(2 pi u)` in f32, whose angle
/// rounds by up to half an ulp of `2 pi` before the sine sees it.
#[inline(always)]
pub fn sin_cos_turn(u: f32) -> (f32, f32) {
    let quarters = u32::from(u >= 0.125)
        + u32::from(u >= 0.375)
        + u32::from(u >= 0.625)
        + u32::from(u >= 0.875);
    let t = u - 0.25 * quarters as f32;
    let (sin, cos) = quarter_kernels(std::f64::consts::TAU * f64::from(t));
    // A quarter turn on, the sine is the cosine and the cosine minus the sine.
    let (sin, cos) = if quarters % 2 == 1 {
        (cos, sin)
    } else {
        (sin, cos)
    };
    let sine_negated = quarters == 2 || quarters == 3;
    let cosine_negated = quarters == 1 || quarters == 2;
    (
        if sine_negated { -sin } else { sin },
        if cosine_negated { -cos } else { cos },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The concentric map at points whose angle is any eighth of a turn (both signs of each
    /// coordinate, either one the larger): on the unit circle's radius, in the right quadrant,
    /// and through `sin_cos`'s own angle, as the map's definition states it.
    #[test]
    fn the_concentric_map_is_shirley_and_chius() {
        for i in 0..=200 {
            for j in 0..=200 {
                let u = glam::Vec2::new(i as f32 / 200.0, j as f32 / 200.0);
                let o = 2.0 * u - glam::Vec2::ONE;
                let d = concentric_disk(u);
                if o == glam::Vec2::ZERO {
                    assert_eq!(d, glam::Vec2::ZERO);
                    continue;
                }
                let (r, theta) = if o.x.abs() > o.y.abs() {
                    (o.x, std::f64::consts::FRAC_PI_4 * f64::from(o.y / o.x))
                } else {
                    (
                        o.y,
                        std::f64::consts::FRAC_PI_2
                            - std::f64::consts::FRAC_PI_4 * f64::from(o.x / o.y),
                    )
                };
                let expected = (f64::from(r) * theta.cos(), f64::from(r) * theta.sin());
                let close = |a: f32, b: f64| (f64::from(a) - b).abs() < 4e-7;
                assert!(
                    close(d.x, expected.0) && close(d.y, expected.1),
                    "{u}: {d} against {expected:?}"
                );
            }
        }
    }

    /// `sin_cos_quarter` is `libm`'s `sincosf` wherever `sincosf` evaluates the same kernels
    /// (below `pi/4` in magnitude), to the bit: every 31st float of that range, both signs,
    /// and every float around `2^-12`, where `sincosf` stops calling them.
    #[test]
    fn the_quarter_kernels_are_libms() {
        let check = |bits: u32| {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                let (s, c) = sin_cos_quarter(x);
                let (ls, lc) = libm::sincosf(x);
                assert!(
                    s.to_bits() == ls.to_bits() && c.to_bits() == lc.to_bits(),
                    "sin_cos_quarter({x:e}) = ({s:e}, {c:e}), sincosf ({ls:e}, {lc:e})"
                );
            }
        };
        let last = std::f32::consts::FRAC_PI_4.to_bits() - 1;
        (0..=last).step_by(31).chain([last]).for_each(check);
        (0x3980_0000 - 20_000..0x3980_0000 + 20_000).for_each(check);
        // At pi/4 itself, the kernels against the true values.
        let (s, c) = sin_cos_quarter(std::f32::consts::FRAC_PI_4);
        let exact = f64::from(std::f32::consts::FRAC_PI_4);
        assert!((f64::from(s) - exact.sin()).abs() < 1e-7);
        assert!((f64::from(c) - exact.cos()).abs() < 1e-7);
    }

    /// `sin_cos_turn` within an ulp of the sine and cosine (f64's) of the turn, over
    /// every 1021st float of [0, 1) and the quarter and eighth turns themselves, where it
    /// changes quarter.
    #[test]
    fn the_turn_is_within_an_ulp() {
        let ulp = |x: f32| (f32::from_bits(x.abs().to_bits() + 1) - x.abs()) as f64;
        let check = |u: f32| {
            let (s, c) = sin_cos_turn(u);
            let angle = std::f64::consts::TAU * f64::from(u);
            for (got, exact) in [(s, angle.sin()), (c, angle.cos())] {
                let error = (f64::from(got) - exact).abs();
                // Near a zero of either, the f64 reference's own angle is off by 1e-16.
                assert!(
                    error <= ulp(exact as f32).max(1e-15),
                    "sin_cos_turn({u:e}) = ({s:e}, {c:e}), off by {error:e}"
                );
            }
        };
        (0..1.0f32.to_bits())
            .step_by(1021)
            .map(f32::from_bits)
            .for_each(check);
        for eighth in 0..=8 {
            let u = eighth as f32 / 8.0;
            for bits in u.to_bits().saturating_sub(3)..=u.to_bits() + 3 {
                let u = f32::from_bits(bits);
                if (0.0..=1.0).contains(&u) {
                    check(u);
                }
            }
        }
    }

    /// Against the standard library's (the platform's) functions, which are within an ulp or
    /// two of the exact value: the two may differ in the last bits, never by more.
    #[test]
    fn agrees_with_the_platform_within_a_few_ulps() {
        let close = |a: f32, b: f32| (a - b).abs() <= 4.0 * f32::EPSILON * b.abs().max(1e-30);
        for i in 0..20_000 {
            let x = -40.0 + 80.0 * (i as f32) / 20_000.0;
            let (s, c) = sin_cos(x);
            assert!(close(s, x.sin()) && close(c, x.cos()), "sin_cos({x})");
            assert!(close(sin(x), x.sin()), "sin({x})");
            let (s, c) = sin_cos_f64(f64::from(x));
            assert!(
                (s - f64::from(x).sin()).abs() < 1e-15 && (c - f64::from(x).cos()).abs() < 1e-15
            );
            let y = 3.0 * (i as f32 / 20_000.0) - 1.5;
            assert!(close(atan2(y, x), y.atan2(x)), "atan2({y}, {x})");
            let t = 1.5 * (i as f32 / 20_000.0) - 0.75;
            assert!(close(tan(t), t.tan()), "tan({t})");
            let p = i as f32 / 20_000.0;
            for e in [1.0 / 2.4, 2.4, 0.5, 3.0] {
                assert!(close(powf(p, e), p.powf(e)), "powf({p}, {e})");
            }
        }
    }

    /// A few values known exactly (or to the last bit of their correctly rounded value).
    #[test]
    fn exact_values() {
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        assert_eq!(atan2(0.0, 1.0), 0.0);
        assert_eq!(atan2(1.0, 0.0), std::f32::consts::FRAC_PI_2);
        assert_eq!(powf(2.0, 10.0), 1024.0);
        assert_eq!(powf(1.0, 2.4), 1.0);
        assert_eq!(tan(0.0), 0.0);
    }
}
