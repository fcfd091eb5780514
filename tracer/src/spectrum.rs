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
//! drawn where the eye sees most (`visible`, pbrt's `SampleVisibleWavelengths`) at
//! `u`, `u + 1/3` and `u + 2/3` of that density's CDF (one uniform `u`, the others stratified
//! from it), so the
//! integrator's arithmetic, its Russian roulette and the media's hero-channel MIS
//! ([`crate::medium`]: there it becomes pbrt's spectral MIS over wavelengths) run unchanged on
//! them. pbrt carries four; three is what fits the integrator's colour type. A dispersive surface
//! bends each wavelength its own way but a path has one direction, so there the secondaries end
//! (pbrt's `TerminateSecondary`): the first wavelength goes on with three times its weight, the
//! others with none. The range is 380-780 nm, the CIE's own 5 nm tables': the observer outside it
//! holds under 0.01 % of its luminance, and sampling further would spend wavelengths on nothing.
//!
//! **The sensor is the CIE 1931 observer.** A spectral path's pixel value is
//! `sum_i S(l_i) L(l_i) / (3 p(l_i))`, `p` the wavelengths' density, with the sensor
//! `S(l) = M xyz_bar(l) D65(l) / Y_D65`: the 2-degree colour-matching functions, through the XYZ
//! to linear sRGB matrix `M`, weighted by D65 (sRGB's white) and normalised so that the constant
//! spectrum 1 is RGB (1, 1, 1). The weighting stands in the sensor rather than in the emitters:
//! emission multiplies the whole path, so it is the same thing, and nothing else changes. So a
//! prism spreads white into a spectrum's hues, violet through cyan to deep red.
//!
//! **From RGB to a spectrum and back: a partition of unity.** An RGB value `v` is the spectrum
//! `v . B(l)`, with `B = (red, green, blue)` the spectral primaries of Mallett and Yuksel 2019
//! (EGSR, "Spectral Primary Decomposition for Rendering with sRGB Reflectance"): the smoothest
//! three spectra with `B >= 0`, `B_r + B_g + B_b = 1` at every wavelength and
//! `integral S_c B_d dl = delta_cd`. So an RGB value turned into a spectrum and measured comes
//! back exactly, in expectation (a spectral render of an RGB scene has the RGB render's mean),
//! white stays exactly white, and an albedo in [0, 1] stays in [0, 1] at every wavelength, so
//! energy is conserved by construction. `scripts/fit_spectral_primaries.py` fits them and writes
//! both `B` and `S`, every 5 nm, into `primaries` (generated; its docstring gives the CIE data's
//! provenance); both are read by linear interpolation, and the fit's integrals are those of the
//! interpolants, so the identity holds for what the tracer reads, to about 1e-8.
//!
//! **Media** stay per RGB channel: a wavelength sees the coefficients of the band that weighs
//! most there (blue below about 490 nm, green to about 590 nm, red beyond; the red band's small
//! violet lobe never leads), which is a medium whose spectrum is piecewise constant, so a
//! spectral path through it is exact for that medium.
//!
//! Everything here is basic IEEE arithmetic, the same on every machine.

use crate::material::Bsdf;
use crate::medium::Medium;
use crate::sampler::PixelSampler;
use glam::Vec3;

mod primaries;
mod visible;

/// The shortest wavelength sampled, in nanometres: the first of the fitted table's.
pub const LAMBDA_MIN: f32 = primaries::FIRST_NM;
/// The longest wavelength sampled, in nanometres: the last of the fitted table's.
pub const LAMBDA_MAX: f32 =
    primaries::FIRST_NM + primaries::STEP_NM * (primaries::SAMPLES - 1) as f32;

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

/// The (red, green, blue) weights of the wavelength `nm`: the fitted spectral primaries, at
/// least 0 and summing to 1 (to within a rounding) at every wavelength.
pub fn basis(nm: f32) -> Vec3 {
    interpolate(&primaries::BANDS, nm)
}

/// The RGB a unit of spectral radiance at `nm` adds, per unit of wavelength: the CIE 1931
/// observer weighted by D65, in linear sRGB. Some channel is negative at every
/// wavelength: monochromatic light lies outside sRGB's gamut.
pub fn sensor(nm: f32) -> Vec3 {
    interpolate(&primaries::SENSOR, nm)
}

/// `table` read at `nm` by linear interpolation between its samples, clamped to its range.
fn interpolate(table: &[[f32; 3]; primaries::SAMPLES], nm: f32) -> Vec3 {
    let last = primaries::SAMPLES - 1;
    let x = ((nm - primaries::FIRST_NM) / primaries::STEP_NM).clamp(0.0, last as f32);
    // `x` is at least 0, so the cast truncates towards the sample below; at the range's end
    // that sample is the last but one, with `t` = 1.
    let i = (x as usize).min(last - 1);
    let t = x - i as f32;
    Vec3::from(table[i]) * (1.0 - t) + Vec3::from(table[i + 1]) * t
}

/// The band (0 red, 1 green, 2 blue) a wavelength falls in most, from its weights: which RGB
/// channel of a medium it sees. A tie goes to the redder band.
fn channel(weights: Vec3) -> usize {
    if weights.x >= weights.y && weights.x >= weights.z {
        0
    } else if weights.y >= weights.z {
        1
    } else {
        2
    }
}

/// The wavelengths of a spectral path, one per colour slot.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Wavelengths {
    nm: [f32; 3],
    /// Each wavelength's density per nanometre ([`visible`]; 1 for a monochrome path, which
    /// does not estimate an integral over wavelengths).
    pdf: [f32; 3],
    basis: [Vec3; 3],
    channel: [usize; 3],
    /// Only slot 0 carries weight: the secondaries were ended, or never carried.
    single: bool,
}

impl Wavelengths {
    /// Three wavelengths from one uniform `u`, stratified in the density's CDF: at
    /// `u`, `u + 1/3` and `u + 2/3` (modulo 1) of it.
    fn sample(u: f32) -> Self {
        let visible = &*visible::VISIBLE;
        let nm = [0.0f32, 1.0 / 3.0, 2.0 / 3.0].map(|offset| {
            let x = u + offset;
            visible.sample(if x >= 1.0 { x - 1.0 } else { x })
        });
        Self::at(nm, nm.map(|nm| visible.pdf(nm)))
    }

    fn at(nm: [f32; 3], pdf: [f32; 3]) -> Self {
        let basis = nm.map(basis);
        Wavelengths {
            nm,
            pdf,
            basis,
            channel: basis.map(channel),
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
    /// The state every path starts in: RGB, nothing gathered aside.
    pub const RGB: PathSpectrum = PathSpectrum {
        wavelengths: None,
        monochrome: false,
        gathered_rgb: Vec3::ZERO,
    };

    /// The state a path of `sampling` starts in, and its starting throughput.
    pub fn start(sampling: SpectralSampling, sampler: &PixelSampler) -> (Self, Vec3) {
        let (mut spectrum, mut beta) = (Self::RGB, Vec3::ONE);
        spectrum.begin(sampling, sampler, &mut beta);
        (spectrum, beta)
    }

    /// Turns a path that starts in [`PathSpectrum::RGB`] with throughput `beta` into the state
    /// a path of `sampling` starts in. In place, rather than [`PathSpectrum::start`]'s value:
    /// an RGB start writes only a few of the state's bytes, and the value, copied whole into
    /// the path's variable, was read back across those narrow stores, which the processor
    /// cannot forward (a stall at every path's start: 7 % of `radiance_from`'s samples on the
    /// Cornell box; docs/bench.md, issue 12, twenty-second round).
    #[inline(always)]
    pub fn begin(&mut self, sampling: SpectralSampling, sampler: &PixelSampler, beta: &mut Vec3) {
        match sampling {
            SpectralSampling::Auto => {}
            SpectralSampling::Hero => {
                self.wavelengths = Some(Wavelengths::sample(sampler.wavelength()));
            }
            SpectralSampling::Single => {
                self.wavelengths = Some(Wavelengths::sample(sampler.wavelength()));
                self.terminate_secondary(beta);
            }
            SpectralSampling::Monochrome(nm) => {
                self.wavelengths = Some(Wavelengths::at([nm; 3], [1.0; 3]));
                self.monochrome = true;
            }
        }
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

    /// `bsdf` made what the path sees: colours read at its wavelengths, and a dispersive glass
    /// as the plain glass of its index at the first wavelength (the only one that goes on
    /// through it, [`PathSpectrum::disperse`]). Untouched on an RGB path.
    // Inlined, with the spectral reading kept out of line, so that an RGB path (every path of
    // a scene without dispersive glass) pays no call and no copy of the BSDF at each hit. In
    // place: returned as a value, a textured BSDF just written field by field was copied whole
    // and read back across those narrow stores, which the processor cannot forward (a stall at
    // every textured hit; docs/bench.md, issue 12, twenty-second round).
    #[inline(always)]
    pub fn see_bsdf(&self, bsdf: &mut Bsdf) {
        if let Some(w) = &self.wavelengths {
            *bsdf = Self::spectral_bsdf(w, *bsdf);
        }
    }

    #[inline(never)]
    fn spectral_bsdf(w: &Wavelengths, bsdf: Bsdf) -> Bsdf {
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
            // The outside index does not depend on the wavelength (`Bsdf::DispersiveGlass`);
            // dividing by 1, as without `outside_ior`, leaves the index's bits alone.
            Bsdf::DispersiveGlass {
                dispersion,
                outside_ior,
                tint,
            } => Bsdf::Dielectric {
                ior: dispersion.ior(w.nm[0]) / outside_ior,
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
    // Inlined for the RGB path's identity, as `bsdf`.
    #[inline(always)]
    pub fn finish(&self, radiance: Vec3) -> Vec3 {
        match &self.wavelengths {
            None => radiance,
            Some(_) if self.monochrome => radiance,
            Some(w) => self.spectral_finish(w, radiance),
        }
    }

    #[inline(never)]
    fn spectral_finish(&self, w: &Wavelengths, radiance: Vec3) -> Vec3 {
        // Each slot estimates the integral over wavelengths by itself; the three estimates are
        // averaged.
        let slot = |i: usize, l: f32| sensor(w.nm[i]) * (l / (3.0 * w.pdf[i]));
        self.gathered_rgb + slot(0, radiance.x) + slot(1, radiance.y) + slot(2, radiance.z)
    }
}

#[cfg(test)]
mod tests;
