//! Participating media: homogeneous absorption and scattering with a Henyey-Greenstein phase
//! function, and how a path samples its distance through them.
//!
//! A medium fills the interior of a closed object (bound through the object's glass or an
//! index-matched `interface` boundary) or, as global fog, the space outside every object, which
//! is where the camera starts ([`crate::scene::Scene::camera_medium`]). Objects nest: each
//! boundary names the media on its two sides ([`crate::material::Material::interior`] and
//! [`crate::material::Material::exterior`], the outside being the camera's medium unless the
//! scene names an enclosing object's), so a glass inside a smoke-filled box leads paths back
//! into the smoke. Coefficients are per unit length of the scene and per RGB channel.
//!
//! **Tracking method: analytic distance sampling by a hero channel, with spectral MIS over the
//! three channels at the level of the whole path.** A homogeneous medium's majorant is its own
//! extinction `sigma_t`, so delta tracking would never see a null collision: sampling the
//! free-flight distance in closed form, `t = -ln(1 - u) / sigma_t`, is exactly delta tracking's
//! first real collision, at the cost of one logarithm. The channels differ (a tinted glass
//! absorbs red less than blue), so one channel's density cannot serve the others: a path sampled
//! by red that reaches a point where blue has long died carries blue weight `T_b / T_r`,
//! unbounded. So each path picks a *hero* channel once, uniformly, samples every flight by that
//! channel's `sigma_t`, and keeps beside its throughput the ratios `r[c] = p_c(path) /
//! p_hero(path)` of every channel's path density to the hero's; a contribution is divided by the
//! mean of `r`, which makes it the one-sample balance heuristic over the three hero choices
//! (Miller, Georgiev and Jarosz's null-scattering path integral; pbrt-v4's `VolPathIntegrator`
//! keeps the same ratios as `r_u` over its four wavelengths). A channel's contribution is then
//! at most 3 times what its own hero would give, which for a medium that does not amplify is at
//! most 3, however many times the path scatters. (A first version chose the channel anew at
//! every flight and divided by the channels' mean density per flight: also unbiased, but the
//! per-flight weights, each up to 3, multiply along a path, and a glass sphere full of a
//! chromatic medium rendered 25 % dark at 16 samples, the mean carried by rare huge weights.)
//! Absorption is not sampled as an event: the scattering weight carries `sigma_s`, not
//! `sigma_t`, which spares the noise of killing paths at random and needs no random number.
//!
//! **Shadow rays** carry the medium's transmittance `exp(-sigma_t d)` in closed form, channel
//! by channel: for a homogeneous medium ratio tracking with the majorant `sigma_t` would
//! estimate exactly this value, with no variance, so evaluating it needs no random numbers.
//!
//! **Arithmetic.** The exponential and logarithm here are our own ([`exp_neg`], [`ln`]): basic
//! IEEE operations in f64 in a fixed order, so that images do not depend on which variant of
//! glibc's `expf`/`logf` a processor gets at run time (glibc picks FMA variants where the
//! processor has FMA). The phase function's azimuth uses [`crate::math::sin_cos`], as the BSDFs
//! do, for the same reason.
//!
//! The methods above are the default; `tracking.rs` holds the others a render can ask for
//! ([`MediaSampling`]: a per-flight channel mixture, delta tracking with null collisions, ratio
//! tracking for shadow rays), for `tessera accuracy` to measure, and says why the default is this.

mod tracking;

pub use tracking::{FlightSampling, MediaSampling, ShadowTransmittance, Stream};

use crate::material::Frame;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A homogeneous medium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Medium {
    /// Absorption coefficient per unit length, per channel; never negative.
    pub sigma_a: Vec3,
    /// Scattering coefficient per unit length, per channel; never negative.
    pub sigma_s: Vec3,
    /// The Henyey-Greenstein asymmetry, in (-1, 1): positive scatters forward.
    pub g: f32,
}

/// What a path meets along one segment through a medium. `weight` multiplies the path's
/// throughput (each channel's value over the hero's density) and `ratio` its density ratios
/// (each channel's density over the hero's), as the module's comment explains.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Flight {
    /// It scatters at `distance` from the segment's start.
    Scatter {
        /// How far along the segment it scatters, in the scene's units of length.
        distance: f32,
        /// The factor of the path's throughput, per channel: `sigma_s T` of the channel over the
        /// hero's density of scattering here (absorption is carried, never sampled).
        weight: Vec3,
        /// The factor of the path's density ratios, per channel: the channel's density of
        /// this flight over the hero's.
        ratio: Vec3,
    },
    /// It reaches the segment's end (the surface hit, or infinity).
    Pass {
        /// The factor of the path's throughput, per channel: the channel's transmittance over
        /// the hero's probability of passing.
        weight: Vec3,
        /// The factor of the path's density ratios, per channel: the channel's probability of
        /// passing over the hero's.
        ratio: Vec3,
    },
}

/// The hero channel a number `u` in [0, 1) picks, each with probability 1/3.
pub fn hero_channel(u: f32) -> usize {
    ((u * 3.0) as usize).min(2)
}

/// The one-sample balance heuristic's divisor: the mean of a path's density ratios.
pub fn mean_ratio(ratio: Vec3) -> f32 {
    (ratio.x + ratio.y + ratio.z) / 3.0
}

impl Medium {
    /// The medium of every ray in a pipeline that tracks media in scenes without any: nothing
    /// absorbs or scatters, so every flight passes with weight exactly 1.
    pub const VACUUM: Medium = Medium {
        sigma_a: Vec3::ZERO,
        sigma_s: Vec3::ZERO,
        g: 0.0,
    };

    /// The extinction coefficient `sigma_a + sigma_s`.
    pub fn sigma_t(&self) -> Vec3 {
        self.sigma_a + self.sigma_s
    }

    /// Whether light crosses the medium unchanged (every channel's extinction is zero).
    pub fn is_vacuum(&self) -> bool {
        self.sigma_t() == Vec3::ZERO
    }

    /// The fraction of light per channel that crosses `distance` (which may be infinite):
    /// exactly 1 in a channel without extinction.
    pub fn transmittance(&self, distance: f32) -> Vec3 {
        let sigma_t = self.sigma_t();
        let channel = |s: f32| {
            if s == 0.0 { 1.0 } else { exp_neg(s * distance) }
        };
        Vec3::new(channel(sigma_t.x), channel(sigma_t.y), channel(sigma_t.z))
    }

    /// Samples where a path starting into the medium scatters before `t_end` (the distance to
    /// the surface it would hit, infinite when it escapes), by the density of channel `hero`,
    /// with `u_distance` in [0, 1).
    pub fn sample_flight(&self, t_end: f32, hero: usize, u_distance: f32) -> Flight {
        let sigma_t = self.sigma_t();
        if sigma_t == Vec3::ZERO {
            // A vacuum: what the general case below computes (transmittance 1 over density 1),
            // without its divisions; every ray of a forced pipeline in a scene without media.
            return Flight::Pass {
                weight: Vec3::ONE,
                ratio: Vec3::ONE,
            };
        }
        let s = sigma_t[hero];
        // `1 - u` is exact for the sampler's 24-bit numbers and never 0, so `ln` is finite.
        let distance = if s > 0.0 {
            -ln(1.0 - u_distance) / s
        } else {
            f32::INFINITY
        };
        if distance < t_end {
            let transmittance = self.transmittance(distance);
            let density = sigma_t * transmittance;
            // Positive: the sampler's numbers keep `s * distance` below 16.7, so `T` is above 5e-8.
            let pdf = density[hero];
            Flight::Scatter {
                distance,
                weight: self.sigma_s * transmittance / pdf,
                ratio: density / pdf,
            }
        } else {
            let transmittance = self.transmittance(t_end);
            let pdf = transmittance[hero];
            if pdf > 0.0 {
                Flight::Pass {
                    weight: transmittance / pdf,
                    ratio: transmittance / pdf,
                }
            } else {
                // Only where the hero's transmittance underflowed: the path carries nothing.
                Flight::Pass {
                    weight: Vec3::ZERO,
                    ratio: Vec3::ONE,
                }
            }
        }
    }
}

/// The Henyey-Greenstein phase function of asymmetry `g` at `cos_theta = wo . wi`, with `wo`
/// towards the camera and `wi` towards the light (pbrt-v4's convention: forward scattering,
/// `g > 0`, peaks at `wi = -wo`).
pub fn henyey_greenstein(cos_theta: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g + 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * PI * denom * denom.max(0.0).sqrt())
}

/// Samples `wi` from the Henyey-Greenstein phase function around `wo` (pbrt-v4's inversion);
/// returns `wi` and its density, which equals the phase function's value, so the sample's
/// weight is exactly 1.
pub fn sample_henyey_greenstein(wo: Vec3, g: f32, u: Vec2) -> (Vec3, f32) {
    let cos_theta = if g.abs() < 1e-3 {
        1.0 - 2.0 * u.x
    } else {
        let square = (1.0 - g * g) / (1.0 + g - 2.0 * g * u.x);
        -1.0 / (2.0 * g) * (1.0 + g * g - square * square)
    }
    .clamp(-1.0, 1.0);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (sin_phi, cos_phi) = crate::math::sin_cos(2.0 * PI * u.y);
    let local = Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta);
    let wi = Frame::from_normal(wo).to_world(local);
    (wi, henyey_greenstein(cos_theta, g))
}

/// `exp(-x)` for `x >= 0` (and `+inf`, giving 0), by range reduction to `x = k ln 2 + r` with
/// `|r| <= ln 2 / 2` and a degree-11 Taylor polynomial of `exp(-r)` in f64 (a tail below
/// 2^-47): within one f32 rounding of the exact value, and the same bits on every machine.
///
/// The polynomial multiplies by constant coefficients rather than dividing by `n` at each step,
/// as this function once did: a division cannot be turned into a multiplication without
/// changing its rounding, so the compiler kept thirteen dependent f64 divisions, about 200
/// cycles per call, and three calls per transmittance made it a third of a fog render's time.
pub fn exp_neg(x: f32) -> f32 {
    // exp(-104) is below half the smallest f32 subnormal.
    if x.is_nan() || x > 104.0 {
        return if x.is_nan() { f32::NAN } else { 0.0 };
    }
    let x = f64::from(x);
    // The nearest integer to x / ln 2. Truncation is the floor here (the argument is at least
    // 0.5), and unlike `floor` it needs no call into libm on the baseline x86-64 target.
    let k = (x * std::f64::consts::LOG2_E + 0.5) as i64;
    let r = x - k as f64 * std::f64::consts::LN_2;
    // sum (-r)^n / n!, n = 0..11, by Estrin's scheme: pairs of terms, then pairs of pairs,
    // combined by r^2, r^4 and r^8. Horner's rule takes eleven dependent steps of a product and
    // a sum, about 90 cycles per call (most of a fog render's transmittance); this, four.
    let p = estrin(&EXP_NEG_TAYLOR, -r);
    // 2^-k for k in [-1, 150]: exact in f64.
    let scale = f64::from_bits(((1023 - k) as u64) << 52);
    (p * scale) as f32
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

/// `sum c[n] x^n` by Estrin's scheme: the terms in pairs `c[2i] + c[2i+1] x`, then pairs of
/// those by `x^2`, of those by `x^4`, and so on (an odd one out carried up as it is), so that
/// the dependent chain is as long as the number of halvings rather than the number of terms.
/// Its f64 roundings differ from Horner's rule's by a few units of 2^-53 of the sum, far below
/// the f32 the callers round to.
#[inline(always)]
fn estrin<const N: usize>(c: &[f64; N], x: f64) -> f64 {
    let mut terms = *c;
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
        power *= power;
    }
    terms[0]
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
    fn henyey_greenstein_is_normalised_sampled_by_its_own_density_with_mean_cosine_minus_g() {
        for g in [-0.9f32, -0.5, 0.0, 0.0005, 0.3, 0.8, 0.95] {
            // Integral over the sphere by the midpoint rule in cos theta.
            let n = 200_000;
            let integral: f64 = (0..n)
                .map(|i| {
                    let c = -1.0 + (2.0 * i as f64 + 1.0) / n as f64;
                    f64::from(henyey_greenstein(c as f32, g)) * 2.0 * std::f64::consts::PI
                })
                .sum::<f64>()
                * 2.0
                / n as f64;
            assert!((integral - 1.0).abs() < 2e-3, "g {g}: integral {integral}");
            let wo = Vec3::new(0.3, -0.5, 0.8).normalize();
            let mut mean_cos = 0.0f64;
            let m = 64 * 64;
            for i in 0..m {
                // A stratified grid: its error is far below the Monte Carlo one.
                let u = Vec2::new(
                    ((i % 64) as f32 + 0.5) / 64.0,
                    ((i / 64) as f32 + 0.5) / 64.0,
                );
                let (wi, pdf) = sample_henyey_greenstein(wo, g, u);
                assert!((wi.length() - 1.0).abs() < 1e-5);
                let c = wo.dot(wi);
                let expected = henyey_greenstein(c, g);
                assert!(
                    (pdf - expected).abs() <= 1e-3 * expected.max(1.0),
                    "g {g}: pdf {pdf} vs value {expected}"
                );
                mean_cos += f64::from(c);
            }
            mean_cos /= f64::from(m);
            assert!(
                (mean_cos + f64::from(g)).abs() < 0.01,
                "g {g}: mean cosine {mean_cos}"
            );
        }
    }

    #[test]
    fn a_vacuum_passes_every_flight_with_weight_exactly_one() {
        for t_end in [0.0f32, 1e-3, 1.0, 1e30, f32::INFINITY] {
            for u in [0.0f32, 0.3, 0.999_999] {
                assert_eq!(
                    Medium::VACUUM.sample_flight(t_end, hero_channel(u), u),
                    Flight::Pass {
                        weight: Vec3::ONE,
                        ratio: Vec3::ONE
                    }
                );
            }
            assert_eq!(Medium::VACUUM.transmittance(t_end), Vec3::ONE);
        }
    }
}
