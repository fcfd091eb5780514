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
//! **Arithmetic.** The exponential and logarithm here are our own (`arith.rs`: [`exp_neg`],
//! [`exp_neg_each`] for three channels at once in SIMD lanes, [`ln`]): basic IEEE operations in
//! f64 in a fixed order, so that images do not depend on which variant of glibc's
//! `expf`/`logf` a processor gets at run time (glibc picks FMA variants where the processor has
//! FMA). The phase function's azimuth uses [`crate::math::sin_cos`], as the BSDFs do, for the
//! same reason.
//!
//! The methods above are the default; `tracking.rs` holds the others a render can ask for
//! ([`MediaSampling`]: a per-flight channel mixture, delta tracking with null collisions, ratio
//! tracking for shadow rays), for `tessera accuracy` to measure, and says why the default is this.

mod arith;
mod tracking;

pub use arith::{exp_neg, exp_neg_each, ln};
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
        // A vacuum (the space around a closed object's medium) passes everything, with none
        // of the exponentials' work.
        if sigma_t == Vec3::ZERO {
            return Vec3::ONE;
        }
        // A grey medium (smoke, mist: the same extinction in every channel) has one
        // exponential for all three: the same argument in each, so the same bits.
        if sigma_t.x == sigma_t.y && sigma_t.y == sigma_t.z {
            return Vec3::splat(exp_neg(sigma_t.x * distance));
        }
        // The three exponentials at once (`exp_neg_each`: the same bits as one by one); a
        // channel without extinction is exactly 1 whatever the distance (`0 * inf` is NaN).
        let each = exp_neg_each(sigma_t * distance);
        let channel = |s: f32, value: f32| if s == 0.0 { 1.0 } else { value };
        Vec3::new(
            channel(sigma_t.x, each.x),
            channel(sigma_t.y, each.y),
            channel(sigma_t.z, each.z),
        )
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

#[cfg(test)]
mod tests {
    use super::*;

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
