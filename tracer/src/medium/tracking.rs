//! How a render samples its media: the free-flight method and the shadow rays' transmittance,
//! a comparison knob ([`MediaSampling`], `RenderSettings::media`) that `tessera accuracy
//! --knobs media` measures in error against time.
//!
//! Every choice has the same mean (`tracer/tests/media_tracking.rs` holds each to closed forms);
//! they differ in noise and in work:
//!
//! - **Free flights.** `Hero` (the default) samples the distance to the first real collision in
//!   closed form by the path's hero channel, with spectral MIS over the whole path (the
//!   module comment of [`crate::medium`]). `Mixture` is what pbrt-v3's homogeneous medium does:
//!   each flight picks a channel anew and divides by the three channels' mean density, so no
//!   density ratios are kept, but per-flight weights of up to 3 multiply along a path. `Delta`
//!   is delta tracking with one grey majorant for the three channels (the largest channel's
//!   extinction times [`MediaSampling::majorant`]): tentative collisions at the majorant's rate,
//!   each taken as a scattering or a null collision by the hero channel's odds, with spectral
//!   MIS over those odds (Miller, Georgiev and Jarosz 2019; pbrt-v4's `SampleT_maj` with its
//!   `r_u`). That is what a tracker ready for heterogeneous media pays, where no closed form
//!   exists: a logarithm and a random number per tentative collision instead of one per flight.
//!   The grey majorant is the largest extinction, not the channels' mean: below any channel's
//!   extinction the null coefficient would go negative, and its weights with it (weighted delta
//!   tracking), with variance that has no bound.
//! - **Shadow rays.** `ClosedForm` (the default) multiplies `exp(-sigma_t d)` per channel.
//!   `RatioTracking` estimates it as a heterogeneous renderer must: tentative collisions at the
//!   majorant's rate, each multiplying the estimate by the null fraction `1 - sigma_t / majorant`.
//!   Unbiased, but with a majorant equal to the extinction it is 0 or 1 (the channel's estimate
//!   dies at the first collision); looser majorants trade collisions for less variance.
//!
//! **Why the default is `Hero` with `ClosedForm`:** for a homogeneous medium the closed forms are
//! exactly what the trackers estimate. The analytic flight is delta tracking's first real
//! collision without its null collisions (with a majorant equal to `sigma_t` they never happen,
//! and a looser one only adds work), for one logarithm; the closed-form transmittance is ratio
//! tracking's mean with no variance at all and no random number. The trackers only pay where
//! density varies in space, which this renderer does not model. Measured (`docs/accuracy/
//! README.md`, "Sampling participating media"): on the smoke box and the fog box no other choice
//! was more efficient beyond noise; ratio tracking with the tight majorant, a roulette on
//! transmittance, saved 6 % of the smoke box's work for 16 % more relMSE. And only the default
//! keeps the bits of every image rendered before the knob existed.
//!
//! **Random numbers.** The analytic choices need the two numbers of the bounce's medium stream
//! ([`crate::sampler::PixelSampler::medium`]); the trackers need one or two per tentative
//! collision, as many as they meet. They draw them from a [`Stream`] keyed by the numbers the
//! step already has (the flight's pair; a shadow ray's light-sample numbers), through the
//! SplitMix64 finaliser: still a pure function of (scene, frame, pixel, sample, seed), and no
//! other number moves.

use super::{Flight, Medium, ln};
use crate::sampler::{GOLDEN_GAMMA, splitmix_finalise, unit_f32};
use glam::{Vec2, Vec3};

/// How a render samples free flights and shadow-ray transmittance through media. The default
/// is the analytic pair, what every image of this renderer was made with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediaSampling {
    /// How a path samples the distance to its next scattering event in a medium.
    pub flights: FlightSampling,
    /// How a shadow ray estimates the transmittance of the media between a point and a light.
    pub shadows: ShadowTransmittance,
    /// The trackers' grey majorant, as a multiple (at least 1) of the medium's largest channel
    /// extinction: 1 is the tightest that keeps null coefficients non-negative.
    pub majorant: f32,
}

/// How a ray samples where it scatters in a medium.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FlightSampling {
    /// In closed form by the path's hero channel, with spectral MIS over the path.
    #[default]
    Hero,
    /// In closed form by a channel picked per flight, divided by the channels' mean density.
    Mixture,
    /// Delta tracking with a grey majorant, null collisions and spectral MIS.
    Delta,
}

/// How a shadow ray takes the transmittance of the media it crosses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ShadowTransmittance {
    /// `exp(-sigma_t d)` per channel.
    #[default]
    ClosedForm,
    /// Ratio tracking with the grey majorant.
    RatioTracking,
}

impl Default for MediaSampling {
    fn default() -> Self {
        MediaSampling {
            flights: FlightSampling::Hero,
            shadows: ShadowTransmittance::ClosedForm,
            majorant: 1.0,
        }
    }
}

impl MediaSampling {
    /// The ladder `tessera accuracy --knobs media` measures, the default first: each flight
    /// method with closed-form shadows, ratio-tracked shadows behind analytic flights, and the
    /// trackers together, with the tightest majorant and with one four times looser.
    pub const LADDER: [MediaSampling; 6] = [
        Self::new(FlightSampling::Hero, ShadowTransmittance::ClosedForm, 1.0),
        Self::new(
            FlightSampling::Mixture,
            ShadowTransmittance::ClosedForm,
            1.0,
        ),
        Self::new(FlightSampling::Delta, ShadowTransmittance::ClosedForm, 1.0),
        Self::new(
            FlightSampling::Hero,
            ShadowTransmittance::RatioTracking,
            1.0,
        ),
        Self::new(
            FlightSampling::Delta,
            ShadowTransmittance::RatioTracking,
            1.0,
        ),
        Self::new(
            FlightSampling::Delta,
            ShadowTransmittance::RatioTracking,
            4.0,
        ),
    ];

    /// The sampling of these three choices; a `const fn` so that [`MediaSampling::LADDER`] can
    /// be a constant.
    pub const fn new(flights: FlightSampling, shadows: ShadowTransmittance, majorant: f32) -> Self {
        MediaSampling {
            flights,
            shadows,
            majorant,
        }
    }

    /// The name in reports, e.g. `delta+ratio x4`.
    pub fn name(&self) -> String {
        let flights = match self.flights {
            FlightSampling::Hero => "hero",
            FlightSampling::Mixture => "mixture",
            FlightSampling::Delta => "delta",
        };
        let shadows = match self.shadows {
            ShadowTransmittance::ClosedForm => "closed",
            ShadowTransmittance::RatioTracking => "ratio",
        };
        let tracks = self.flights == FlightSampling::Delta
            || self.shadows == ShadowTransmittance::RatioTracking;
        if tracks && self.majorant != 1.0 {
            format!("{flights}+{shadows} x{}", self.majorant)
        } else {
            format!("{flights}+{shadows}")
        }
    }
}

impl Medium {
    /// [`Medium::sample_flight`] as `sampling` says, from the bounce's medium pair `u` (`u.x`
    /// chose the hero); the default calls it with `u.y`, so its bits are the analytic ones.
    pub fn sample_flight_with(
        &self,
        sampling: &MediaSampling,
        t_end: f32,
        hero: usize,
        u: Vec2,
    ) -> Flight {
        match sampling.flights {
            FlightSampling::Hero => self.sample_flight(t_end, hero, u.y),
            FlightSampling::Mixture => self.sample_flight_mixture(t_end, u),
            FlightSampling::Delta => {
                let mut stream = Stream::new(&[u.x, u.y]);
                self.delta_track(t_end, hero, sampling.majorant, &mut stream)
            }
        }
    }

    /// [`Medium::transmittance`] as `sampling` says; ratio tracking draws from `stream`.
    pub fn transmittance_with(
        &self,
        sampling: &MediaSampling,
        distance: f32,
        stream: &mut Stream,
    ) -> Vec3 {
        match sampling.shadows {
            ShadowTransmittance::ClosedForm => self.transmittance(distance),
            ShadowTransmittance::RatioTracking => {
                self.ratio_track(distance, sampling.majorant, stream)
            }
        }
    }

    /// pbrt-v3's flight: a channel by `u.x`, the distance by its density from `u.y`, the weight
    /// over the three channels' mean density. No ratios: every flight is its own MIS.
    fn sample_flight_mixture(&self, t_end: f32, u: Vec2) -> Flight {
        let sigma_t = self.sigma_t();
        let s = sigma_t[super::hero_channel(u.x)];
        let distance = if s > 0.0 {
            -ln(1.0 - u.y) / s
        } else {
            f32::INFINITY
        };
        let mean = |v: Vec3| (v.x + v.y + v.z) / 3.0;
        if distance < t_end {
            let transmittance = self.transmittance(distance);
            // Positive: the channel drawn has `T` above 5e-8 there (see `sample_flight`).
            let pdf = mean(sigma_t * transmittance);
            return Flight::Scatter {
                distance,
                weight: self.sigma_s * transmittance / pdf,
                ratio: Vec3::ONE,
            };
        }
        let transmittance = self.transmittance(t_end);
        let pdf = mean(transmittance);
        Flight::Pass {
            // Zero only where every channel's transmittance underflowed: nothing gets through.
            weight: if pdf > 0.0 {
                transmittance / pdf
            } else {
                Vec3::ZERO
            },
            ratio: Vec3::ONE,
        }
    }

    /// Delta tracking by the grey majorant `scale * max(sigma_t)`, the hero's odds choosing
    /// between scattering and a null collision at each tentative one (absorption is carried as
    /// weight, as in the analytic flight, never sampled as an event).
    fn delta_track(&self, t_end: f32, hero: usize, scale: f32, stream: &mut Stream) -> Flight {
        let sigma_t = self.sigma_t();
        let majorant = sigma_t.max_element() * scale;
        if majorant == 0.0 {
            // A vacuum: exactly the analytic flight's pass, so forced media keep their bits.
            return Flight::Pass {
                weight: Vec3::ONE,
                ratio: Vec3::ONE,
            };
        }
        let sigma_n = (Vec3::splat(majorant) - sigma_t).max(Vec3::ZERO);
        // Each channel's probability, as hero, of taking a collision as a scattering. Where a
        // channel has neither scattering nor null collisions (it only absorbs, at the majorant)
        // either call gives it weight 0, so any fixed odds are a valid strategy.
        let odds = |s: f32, n: f32| if s + n > 0.0 { s / (s + n) } else { 0.5 };
        let p_scatter = Vec3::new(
            odds(self.sigma_s.x, sigma_n.x),
            odds(self.sigma_s.y, sigma_n.y),
            odds(self.sigma_s.z, sigma_n.z),
        );
        let p = p_scatter[hero];
        let (mut weight, mut ratio) = (Vec3::ONE, Vec3::ONE);
        if p == 0.0 && t_end == f32::INFINITY {
            // Only null collisions, forever: their product is the closed form's limit, 1 where a
            // channel has no extinction (and no chance to scatter) and 0 elsewhere, and walking
            // there would never end.
            let limit = |keep: bool| if keep { 1.0 } else { 0.0 };
            return Flight::Pass {
                weight: Vec3::new(
                    limit(sigma_t.x == 0.0),
                    limit(sigma_t.y == 0.0),
                    limit(sigma_t.z == 0.0),
                ),
                ratio: Vec3::new(
                    limit(p_scatter.x == 0.0),
                    limit(p_scatter.y == 0.0),
                    limit(p_scatter.z == 0.0),
                ),
            };
        }
        let mut t = 0.0f32;
        loop {
            t += -ln(1.0 - stream.next_1d()) / majorant;
            if t >= t_end {
                return Flight::Pass { weight, ratio };
            }
            if stream.next_1d() < p {
                return Flight::Scatter {
                    distance: t,
                    weight: weight * self.sigma_s / (majorant * p),
                    ratio: ratio * p_scatter / p,
                };
            }
            weight *= sigma_n / (majorant * (1.0 - p));
            ratio *= (Vec3::ONE - p_scatter) / (1.0 - p);
            if weight == Vec3::ZERO {
                return Flight::Pass { weight, ratio };
            }
        }
    }

    /// Ratio tracking over `distance` by the grey majorant `scale * max(sigma_t)`.
    fn ratio_track(&self, distance: f32, scale: f32, stream: &mut Stream) -> Vec3 {
        let sigma_t = self.sigma_t();
        let majorant = sigma_t.max_element() * scale;
        if majorant == 0.0 || distance == f32::INFINITY {
            // A vacuum lets exactly 1 through; over an infinite distance the estimate's limit
            // is the closed form's (1 without extinction, else 0), which tracking never reaches.
            return self.transmittance(distance);
        }
        let null = (Vec3::ONE - sigma_t / majorant).max(Vec3::ZERO);
        let mut transmittance = Vec3::ONE;
        let mut t = 0.0f32;
        loop {
            t += -ln(1.0 - stream.next_1d()) / majorant;
            if t >= distance {
                return transmittance;
            }
            transmittance *= null;
            if transmittance == Vec3::ZERO {
                return transmittance;
            }
        }
    }
}

/// A stream of numbers in [0, 1) for the trackers, keyed by numbers the step already drew (the
/// module comment says why): SplitMix64 over the key, 24 bits a number like the pixel sampler's,
/// so `1 - u` is exact and never 0.
#[derive(Clone, Debug)]
pub struct Stream {
    state: u64,
}

impl Stream {
    /// The stream keyed by `numbers` (each in [0, 1)).
    pub fn new(numbers: &[f32]) -> Self {
        let mut state = 0x7ac4_0000_0000_0005u64;
        for x in numbers {
            state = splitmix_finalise(state ^ u64::from(x.to_bits()));
        }
        Stream { state }
    }

    /// The next number, uniform in [0, 1) with spacing 2^-24.
    pub fn next_1d(&mut self) -> f32 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        unit_f32(splitmix_finalise(self.state))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chromatic() -> Medium {
        Medium {
            sigma_a: Vec3::new(0.1, 0.6, 1.5),
            sigma_s: Vec3::new(1.2, 0.8, 0.2),
            g: 0.3,
        }
    }

    #[test]
    fn ratio_tracking_averages_to_the_closed_form() {
        let medium = chromatic();
        for scale in [1.0f32, 2.0, 4.0] {
            for distance in [0.1f32, 0.7, 2.0] {
                let n = 200_000;
                let mut sum = [0.0f64; 3];
                let mut stream = Stream::new(&[scale, distance]);
                for _ in 0..n {
                    let t = medium.ratio_track(distance, scale, &mut stream);
                    for (sum, t) in sum.iter_mut().zip(t.to_array()) {
                        *sum += f64::from(t);
                    }
                }
                for (c, sum) in sum.into_iter().enumerate() {
                    let mean = sum / f64::from(n);
                    let exact = (-f64::from(medium.sigma_t()[c] * distance)).exp();
                    // Each estimate is in [0, 1]: its standard error is at most 0.5 / sqrt(n).
                    assert!(
                        (mean - exact).abs() < 4.0 * 0.5 / f64::from(n).sqrt(),
                        "x{scale}, d {distance}, channel {c}: {mean} vs {exact}"
                    );
                }
            }
        }
    }

    /// The integrator leaves out a vacuum's flights once a path has its hero
    /// (`World::radiance`), which is exact only because every method passes any vacuum, of
    /// any phase asymmetry, over any length, by any hero and numbers, with weights of 1.
    #[test]
    fn every_method_passes_a_vacuum_with_weight_exactly_one() {
        let vacua = [
            Medium::VACUUM,
            Medium {
                g: 0.8,
                ..Medium::VACUUM
            },
        ];
        let numbers = [0.0f32, 0.4, 0.7, 1.0 - f32::EPSILON / 2.0];
        for sampling in MediaSampling::LADDER {
            for vacuum in vacua {
                assert!(vacuum.is_vacuum());
                for t_end in [1e-30f32, 0.5, 1e30, f32::MAX, f32::INFINITY] {
                    for hero in 0..3 {
                        for (ux, uy) in numbers.iter().flat_map(|&x| numbers.map(|y| (x, y))) {
                            assert_eq!(
                                vacuum.sample_flight_with(
                                    &sampling,
                                    t_end,
                                    hero,
                                    Vec2::new(ux, uy)
                                ),
                                Flight::Pass {
                                    weight: Vec3::ONE,
                                    ratio: Vec3::ONE
                                },
                                "{}, length {t_end}, hero {hero}, u ({ux}, {uy})",
                                sampling.name()
                            );
                        }
                    }
                    let mut stream = Stream::new(&[0.25]);
                    let t = vacuum.transmittance_with(&sampling, t_end, &mut stream);
                    assert_eq!(t, Vec3::ONE, "{}", sampling.name());
                }
            }
        }
    }

    #[test]
    fn a_pure_absorber_hero_walking_to_infinity_ends() {
        // The hero (red) only absorbs below a looser majorant: every collision is null, forever.
        let medium = Medium {
            sigma_a: Vec3::new(0.5, 0.0, 0.0),
            sigma_s: Vec3::new(0.0, 0.0, 0.0),
            g: 0.0,
        };
        let mut stream = Stream::new(&[0.5]);
        let flight = medium.delta_track(f32::INFINITY, 0, 2.0, &mut stream);
        assert_eq!(
            flight,
            Flight::Pass {
                weight: Vec3::new(0.0, 1.0, 1.0),
                ratio: Vec3::ONE
            }
        );
        assert_eq!(
            medium.ratio_track(f32::INFINITY, 2.0, &mut stream),
            Vec3::new(0.0, 1.0, 1.0)
        );
    }
}
