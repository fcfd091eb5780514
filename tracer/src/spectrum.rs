//! Spectral rendering, paid for only where a path meets dispersive glass.
//!
//! **Paths are RGB until they meet a dispersive surface.** The renderer is an RGB renderer: a
//! path's throughput has one value per channel, and that is exact for every material whose
//! behaviour does not depend on the wavelength within a channel. Dispersive glass is the one that
//! does (its index, hence the direction a ray leaves it in, varies with the wavelength), so where a
//! path meets it ([`PathSpectrum::disperse`]) the path turns spectral: it draws wavelengths from a
//! sampler stream of their own (so paths that never meet one draw what they always drew, and
//! their pixels keep their bits), its RGB throughput becomes a spectrum, and from there on every
//! RGB quantity it meets (albedos, emission, lights, the environment, media) is read at its
//! wavelengths. Forcing the dispersion effect on in a scene without dispersive glass therefore
//! changes nothing: no path ever turns.
//!
//! **Hero wavelengths, three of them** (Wilkie et al. 2014; pbrt-v4's `SampledWavelengths`). A
//! spectral path carries three wavelengths in the slots where an RGB path carries its channels,
//! `l_i = 400 + 300 frac(u + i / 3)` nm (one uniform `u`, the others stratified from it), so the
//! integrator's arithmetic, its Russian roulette and the media's hero-channel MIS
//! ([`crate::medium`]: there it becomes pbrt's spectral MIS over wavelengths) run unchanged on
//! them. pbrt carries four; three is what fits the integrator's colour type, and the variance
//! difference is small next to what dispersion itself adds. A dispersive surface bends each
//! wavelength its own way but a path has one direction, so there the secondaries end (pbrt's
//! `TerminateSecondary`): the first wavelength goes on with three times its weight, the others
//! with none.
//!
//! **From RGB to a spectrum and back: a partition of unity.** An RGB value `v` is the spectrum
//! `v . B(l)`, with `B = (red, green, blue)` three smooth bands that sum to exactly 1 at every
//! wavelength (a spectral primary decomposition, as Mallett and Yuksel's 2019 upsampling of sRGB
//! reflectances, with bands of our own instead of their fitted primaries): white stays exactly
//! white, and an albedo in [0, 1] stays in [0, 1] at every wavelength, so energy is conserved by
//! construction. A spectrum goes back to RGB through the sensor `S(l) = M^-1 B(l) / |B|`, where
//! `|B|` is each band's integral and `M` the bands' overlap matrix, `M_cd = <B_c, B_d> / |B_c|`:
//! then `integral S(l) B(l)^T dl` is the identity, so an RGB value turned into a spectrum and
//! measured comes back exactly, in expectation. A spectral path's pixel value is
//! `sum_i S(l_i) L(l_i) / (3 p(l))`, `p` the uniform density over 400-700 nm.
//! This sensor is a three-band model, not the CIE 1931 observer; what it gives is an exact round
//! trip for RGB scenes, so that a spectral render of an RGB scene has the RGB render's mean.
//!
//! **Media** stay per RGB channel: a wavelength sees the coefficients of the band it falls in
//! most (red from 580 nm, green from 490 nm, blue below), which is a medium whose spectrum is
//! piecewise constant, so a spectral path through it is exact for that medium.
//!
//! Everything here is basic IEEE arithmetic, the same on every machine.

use crate::material::Bsdf;
use crate::medium::Medium;
use crate::sampler::PixelSampler;
use glam::{Mat3, Vec3};

/// The shortest wavelength sampled, in nanometres.
pub const LAMBDA_MIN: f32 = 400.0;
/// The longest wavelength sampled, in nanometres.
pub const LAMBDA_MAX: f32 = 700.0;
/// Where the blue band hands over to the green one, and the green to the red (nanometres).
const BLUE_GREEN: f32 = 490.0;
const GREEN_RED: f32 = 580.0;
/// The width of each hand-over, a smoothstep.
const BLEND: f32 = 40.0;

/// Which wavelengths a render samples: the sampling choice dispersion brings (a comparison knob
/// for `tessera accuracy` and `tessera bench`, like [`crate::lights::EnvironmentSampling`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum SpectralSampling {
    /// RGB, until a path meets dispersive glass, where it turns spectral (the default).
    #[default]
    Auto,
    /// Every path spectral from the camera, three hero wavelengths: the always-spectral
    /// pipeline a renderer without this specialisation runs.
    Hero,
    /// Every path spectral from the camera, one wavelength each.
    Single,
    /// Every path at this one wavelength (nanometres); every channel of the image is the
    /// spectral radiance there. For tests that follow one wavelength.
    Monochrome(f32),
}

impl SpectralSampling {
    /// The choices compared by `tessera accuracy` (`Monochrome` is not an estimate of the image).
    pub const ALL: [SpectralSampling; 3] = [
        SpectralSampling::Auto,
        SpectralSampling::Hero,
        SpectralSampling::Single,
    ];

    /// The choice's name in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            SpectralSampling::Auto => "rgb",
            SpectralSampling::Hero => "spectral-hero",
            SpectralSampling::Single => "spectral-single",
            SpectralSampling::Monochrome(_) => "monochrome",
        }
    }
}

/// The (red, green, blue) weights of the wavelength `nm`: three smooth bands summing to 1.
pub fn basis(nm: f32) -> Vec3 {
    let smoothstep = |t: f32| {
        let t = t.clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    let blue = 1.0 - smoothstep((nm - (BLUE_GREEN - 0.5 * BLEND)) / BLEND);
    let red = smoothstep((nm - (GREEN_RED - 0.5 * BLEND)) / BLEND);
    // The hand-overs do not overlap, so at most one of `red` and `blue` is above zero.
    Vec3::new(red, 1.0 - red - blue, blue)
}

/// The RGB a unit of spectral radiance at `nm` adds, per unit of wavelength.
pub fn sensor(nm: f32) -> Vec3 {
    let (overlap_inverse, band) = sensor_matrix();
    overlap_inverse * (basis(nm) / band)
}

/// `M^-1` and the bands' integrals `|B|`, in closed form: each hand-over is a smoothstep `s`
/// over [`BLEND`], and `integral s (1 - s) = 9 / 70` of its width.
fn sensor_matrix() -> (Mat3, Vec3) {
    let band = Vec3::new(
        LAMBDA_MAX - GREEN_RED,
        GREEN_RED - BLUE_GREEN,
        BLUE_GREEN - LAMBDA_MIN,
    );
    let o = BLEND * 9.0 / 70.0;
    let rows = [
        Vec3::new(band.x - o, o, 0.0) / band.x,
        Vec3::new(o, band.y - 2.0 * o, o) / band.y,
        Vec3::new(0.0, o, band.z - o) / band.z,
    ];
    let overlap = Mat3::from_cols(rows[0], rows[1], rows[2]).transpose();
    (overlap.inverse(), band)
}

/// The band (0 red, 1 green, 2 blue) a wavelength falls in most: which RGB channel of a medium
/// it sees.
fn channel(nm: f32) -> usize {
    if nm >= GREEN_RED {
        0
    } else if nm >= BLUE_GREEN {
        1
    } else {
        2
    }
}

/// The wavelengths of a spectral path, one per colour slot.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Wavelengths {
    nm: [f32; 3],
    basis: [Vec3; 3],
    channel: [usize; 3],
    /// Only slot 0 carries weight: the secondaries were ended, or never carried.
    single: bool,
}

impl Wavelengths {
    /// Three stratified wavelengths from one uniform `u`.
    fn sample(u: f32) -> Self {
        let range = LAMBDA_MAX - LAMBDA_MIN;
        let nm = [0.0f32, 1.0 / 3.0, 2.0 / 3.0].map(|offset| {
            let x = u + offset;
            LAMBDA_MIN + range * if x >= 1.0 { x - 1.0 } else { x }
        });
        Self::at(nm)
    }

    fn at(nm: [f32; 3]) -> Self {
        Wavelengths {
            nm,
            basis: nm.map(basis),
            channel: nm.map(channel),
            single: false,
        }
    }

    /// The spectrum of the RGB value `rgb`, read at each slot's wavelength.
    fn project(&self, rgb: Vec3) -> Vec3 {
        Vec3::new(
            self.basis[0].dot(rgb),
            self.basis[1].dot(rgb),
            self.basis[2].dot(rgb),
        )
    }

    /// Each slot's value of a per-channel quantity of a medium: its wavelength's channel's.
    fn pick(&self, per_channel: Vec3) -> Vec3 {
        Vec3::new(
            per_channel[self.channel[0]],
            per_channel[self.channel[1]],
            per_channel[self.channel[2]],
        )
    }
}

/// A path's colour state: RGB, or spectral at some wavelengths. Every method is the identity,
/// with no arithmetic, on an RGB path, so paths that never turn compute what they always did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSpectrum {
    wavelengths: Option<Wavelengths>,
    /// Monochrome: the slots hold one wavelength, and the image shows its radiance.
    monochrome: bool,
    /// What the path gathered while it was RGB, before it turned spectral.
    gathered_rgb: Vec3,
}

impl PathSpectrum {
    /// The state a path of `sampling` starts in, and its starting throughput.
    pub fn start(sampling: SpectralSampling, sampler: &PixelSampler) -> (Self, Vec3) {
        let mut spectrum = PathSpectrum {
            wavelengths: None,
            monochrome: false,
            gathered_rgb: Vec3::ZERO,
        };
        let mut beta = Vec3::ONE;
        match sampling {
            SpectralSampling::Auto => {}
            SpectralSampling::Hero => {
                spectrum.wavelengths = Some(Wavelengths::sample(sampler.wavelength()));
            }
            SpectralSampling::Single => {
                spectrum.wavelengths = Some(Wavelengths::sample(sampler.wavelength()));
                spectrum.terminate_secondary(&mut beta);
            }
            SpectralSampling::Monochrome(nm) => {
                spectrum.wavelengths = Some(Wavelengths::at([nm; 3]));
                spectrum.monochrome = true;
            }
        }
        (spectrum, beta)
    }

    /// Whether the path is spectral.
    pub fn is_spectral(&self) -> bool {
        self.wavelengths.is_some()
    }

    /// An RGB quantity (an emission, a light's radiance, a colour) as the path sees it.
    #[inline]
    pub fn of(&self, rgb: Vec3) -> Vec3 {
        match &self.wavelengths {
            None => rgb,
            Some(w) => w.project(rgb),
        }
    }

    /// A per-channel quantity of a medium (a transmittance) as the path sees it.
    #[inline]
    pub fn channels(&self, per_channel: Vec3) -> Vec3 {
        match &self.wavelengths {
            None => per_channel,
            Some(w) => w.pick(per_channel),
        }
    }

    /// A medium as the path sees it.
    pub fn medium(&self, medium: &Medium) -> Medium {
        match &self.wavelengths {
            None => *medium,
            Some(w) => Medium {
                sigma_a: w.pick(medium.sigma_a),
                sigma_s: w.pick(medium.sigma_s),
                g: medium.g,
            },
        }
    }

    /// A BSDF as the path sees it: colours read at its wavelengths, and a dispersive glass as
    /// the plain glass of its index at the first wavelength (the only one that goes on through
    /// it, [`PathSpectrum::disperse`]). Unchanged on an RGB path.
    pub fn bsdf(&self, bsdf: Bsdf) -> Bsdf {
        let Some(w) = &self.wavelengths else {
            return bsdf;
        };
        match bsdf {
            Bsdf::Diffuse { albedo, texture } => Bsdf::Diffuse {
                albedo: w.project(albedo),
                texture,
            },
            Bsdf::Mirror { reflectance } => Bsdf::Mirror {
                reflectance: w.project(reflectance),
            },
            Bsdf::Conductor { f0, alpha } => Bsdf::Conductor {
                f0: w.project(f0),
                alpha,
            },
            Bsdf::Dielectric { ior, tint } => Bsdf::Dielectric {
                ior,
                tint: w.project(tint),
            },
            Bsdf::DispersiveGlass { dispersion, tint } => Bsdf::Dielectric {
                ior: dispersion.ior(w.nm[0]),
                tint: w.project(tint),
            },
            Bsdf::Interface => Bsdf::Interface,
        }
    }

    /// The path meets a dispersive surface: an RGB path turns spectral, drawing its wavelengths
    /// from `sampler`'s wavelength stream (its throughput `beta` read at them, and what it has
    /// gathered so far in `radiance` kept aside in RGB), and the secondary wavelengths end.
    pub fn disperse(&mut self, sampler: &PixelSampler, beta: &mut Vec3, radiance: &mut Vec3) {
        if self.wavelengths.is_none() {
            let w = Wavelengths::sample(sampler.wavelength());
            *beta = w.project(*beta);
            self.gathered_rgb = *radiance;
            *radiance = Vec3::ZERO;
            self.wavelengths = Some(w);
        }
        self.terminate_secondary(beta);
    }

    /// Ends the secondary wavelengths: the first goes on for all three (pbrt's
    /// `TerminateSecondary`). Nothing to end at a single wavelength or a monochrome one.
    fn terminate_secondary(&mut self, beta: &mut Vec3) {
        if let Some(w) = &mut self.wavelengths
            && !w.single
            && !self.monochrome
        {
            *beta = Vec3::new(3.0 * beta.x, 0.0, 0.0);
            w.single = true;
        }
    }

    /// The path's RGB value from what it gathered, `radiance` (in its slots since it turned).
    pub fn finish(&self, radiance: Vec3) -> Vec3 {
        match &self.wavelengths {
            None => radiance,
            Some(_) if self.monochrome => radiance,
            Some(w) => {
                let per_slot = (LAMBDA_MAX - LAMBDA_MIN) / 3.0;
                let rgb = sensor(w.nm[0]) * radiance.x
                    + sensor(w.nm[1]) * radiance.y
                    + sensor(w.nm[2]) * radiance.z;
                self.gathered_rgb + rgb * per_slot
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The integral over the sampled range of `f`, by the midpoint rule on a fine grid.
    fn integrate(f: impl Fn(f32) -> Vec3) -> Vec3 {
        let steps = 30_000;
        let h = (LAMBDA_MAX - LAMBDA_MIN) / steps as f32;
        (0..steps)
            .map(|i| f(LAMBDA_MIN + (i as f32 + 0.5) * h) * h)
            .fold(Vec3::ZERO, |a, b| a + b)
    }

    #[test]
    fn the_bands_are_a_partition_of_unity_in_zero_one() {
        for i in 0..=3000 {
            let b = basis(LAMBDA_MIN + i as f32 * 0.1);
            assert_eq!(
                b.x + b.y + b.z,
                1.0,
                "at {} nm",
                LAMBDA_MIN + i as f32 * 0.1
            );
            assert!(b.min_element() >= 0.0 && b.max_element() <= 1.0);
        }
        assert_eq!(basis(450.0), Vec3::Z);
        assert_eq!(basis(530.0), Vec3::Y);
        assert_eq!(basis(650.0), Vec3::X);
    }

    #[test]
    fn rgb_to_spectrum_and_back_is_the_identity() {
        // The closed-form overlap matrix against numerical integration of S(l) B(l)^T.
        for (c, unit) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
            let measured = integrate(|nm| sensor(nm) * basis(nm).dot(unit));
            assert!(
                (measured - unit).abs().max_element() < 1e-3,
                "channel {c}: {measured}"
            );
        }
        // A flat spectrum is white.
        let white = integrate(sensor);
        assert!((white - Vec3::ONE).abs().max_element() < 1e-3, "{white}");
    }

    #[test]
    fn hero_wavelengths_are_stratified_and_cover_the_range() {
        for u in [0.0f32, 0.2, 0.5, 0.999] {
            let w = Wavelengths::sample(u);
            let mut nm = w.nm;
            nm.sort_by(f32::total_cmp);
            assert!(nm[0] >= LAMBDA_MIN && nm[2] < LAMBDA_MAX, "{nm:?}");
            assert!((nm[1] - nm[0] - 100.0).abs() < 1e-3 && (nm[2] - nm[1] - 100.0).abs() < 1e-3);
        }
    }

    #[test]
    fn an_rgb_path_is_left_alone() {
        let sampler = PixelSampler::new(1, 0, 2, 3, 4);
        let (rgb, beta) = PathSpectrum::start(SpectralSampling::Auto, &sampler);
        assert_eq!(beta, Vec3::ONE);
        let v = Vec3::new(0.3, 0.7, 0.1);
        assert_eq!(rgb.of(v), v);
        assert_eq!(rgb.channels(v), v);
        assert_eq!(rgb.finish(v), v);
        let glass = Bsdf::Dielectric { ior: 1.5, tint: v };
        assert_eq!(rgb.bsdf(glass), glass);
    }

    #[test]
    fn dispersing_keeps_the_first_wavelength_three_times() {
        let sampler = PixelSampler::new(1, 0, 2, 3, 4);
        let (mut spectrum, mut beta) = PathSpectrum::start(SpectralSampling::Hero, &sampler);
        let mut radiance = Vec3::ZERO;
        beta *= 0.5;
        spectrum.disperse(&sampler, &mut beta, &mut radiance);
        assert_eq!(beta, Vec3::new(1.5, 0.0, 0.0));
        spectrum.disperse(&sampler, &mut beta, &mut radiance);
        assert_eq!(beta, Vec3::new(1.5, 0.0, 0.0), "ended once only");
    }
}
