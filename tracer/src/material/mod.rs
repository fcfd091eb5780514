//! Materials: the closed set of BSDFs ([`Bsdf`]) plus emission.
//!
//! BSDFs are evaluated in a local shading frame ([`Frame`]) where the normal is +z; `wo` and `wi`
//! are unit vectors that both point away from the surface, `wo` towards where the light goes (the
//! camera side of the path), `wi` towards where it comes from. `wo.z < 0` means the path arrives
//! from the back of the surface (from inside, for glass). Working in this frame, as pbrt-v4 and
//! Mitsuba 3 do, makes every cosine a coordinate and keeps the models free of world geometry.
//!
//! Conventions that the integrator relies on:
//! - **Sides.** Diffuse, mirror and conductor surfaces are *two-sided reflectors*: seen from the
//!   back, they behave as seen from the front with the normal flipped, and they never transmit
//!   (`eval` is zero when `wo` and `wi` are on opposite sides). Meshes in scenes are often not
//!   closed or consistently wound, and a one-sided diffuse wall would render black from behind.
//!   The dielectric is the one material where the side matters: the normal points outside, and
//!   `ior` is the index inside relative to the index outside (Mitsuba 3's `int_ior / ext_ior`).
//!   Outside is vacuum unless the scene says otherwise: glass inside another glass, such as a
//!   glass ball in water, refracts by the ratio of the two indices, which the loader works out
//!   (or, for a dispersive glass, [`Bsdf::DispersiveGlass`] keeps the outside index).
//! - **Radiance.** The renderer transports radiance, so refraction scales throughput by 1/eta^2
//!   (the `dielectric` module says which eta).
//! - **Random numbers.** [`Bsdf::sample`] takes its random numbers as arguments (one for a
//!   discrete choice, two for a direction) and the integrator always draws all three, whatever
//!   the material, so the number of random dimensions per bounce is fixed and pixel values stay a
//!   pure function of the sample index. A material without a discrete choice ignores `u_choice`.
//! - **Grazing.** A direction exactly in the tangent plane (`z == 0`) scatters nothing: `eval`
//!   and `pdf` are zero and `sample` returns `None`. No input direction produces NaN or infinity.
//!
//! Module map: `frame` (the shading basis), `microfacet` (GGX conductors), `dielectric` (Fresnel
//! equations and smooth glass), `dispersion` (indices that depend on the wavelength: Cauchy,
//! Sellmeier, named glasses); Lambertian diffuse and the perfect mirror are short enough to
//! live here.

mod dielectric;
mod dispersion;
mod frame;
mod microfacet;
// In a `tests` folder, as unit tests that may call the platform's `sin` and `asin` for their
// expected values (tests/portable_math.rs reads every other file as the renderer's code).
#[cfg(test)]
#[path = "tests/nested_ior.rs"]
mod nested_ior_tests;

pub use dielectric::{RELATIVE_IOR, check_relative_ior, fresnel_dielectric, fresnel_schlick};
pub use dispersion::{Dispersion, GLASSES};
pub use frame::Frame;
pub use microfacet::MIN_ALPHA;

use dielectric::{reflect_local, sample_dielectric};
use glam::{Vec2, Vec3};
pub(crate) use microfacet::Ggx;
use std::f32::consts::FRAC_1_PI;

/// A surface material: how it scatters and what it emits.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The MTL name (or the override's name), for messages and statistics.
    pub name: String,
    /// How the surface scatters light that reaches it.
    pub bsdf: Bsdf,
    /// Emitted radiance from the front face (the winding normal's side); zero when not a light.
    pub emission: Vec3,
    /// The medium filling the closed object this material bounds (an index into
    /// `Scene::media`), for glass and interfaces; `None` is vacuum. A path that crosses the
    /// surface against its normal enters this medium.
    pub interior: Option<u32>,
    /// The medium around the closed object this material bounds (an index into
    /// `Scene::media`; `None` is vacuum): a path that crosses the surface along its normal
    /// enters it. A scene's loader makes it the camera's medium (`Scene::camera_medium`) unless
    /// the scene names another, the medium of an object that encloses this one (pbrt-v4's
    /// `MediumInterface`, Mitsuba 3's `exterior`).
    pub exterior: Option<u32>,
}

/// The closed set of scattering models.
// Aligned to 16 bytes, so that its size (44 bytes unaligned) is three whole vector registers:
// a copy of 44 bytes is three overlapping 16-byte moves, and a later read of the last one
// spans two stores, which the processor cannot forward; the shading point's BSDF is copied
// and read back at every bounce (docs/bench.md, issue 12, nineteenth round).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(16))]
pub enum Bsdf {
    /// Lambertian reflection; `texture` (an index into `Scene::textures`) multiplies `albedo`.
    /// The BSDF methods ignore `texture`: the integrator resolves it first with
    /// [`Bsdf::with_texture_value`].
    Diffuse {
        /// The share of light reflected per RGB channel, each in [0, 1] for energy to be kept.
        albedo: Vec3,
        /// The texture whose value multiplies `albedo` at the hit's texture coordinates.
        texture: Option<u32>,
    },
    /// A perfect specular reflector.
    Mirror {
        /// The share of light reflected per RGB channel, the same at every angle.
        reflectance: Vec3,
    },
    /// A rough conductor: GGX microfacets with Schlick Fresnel from `f0`, roughness `alpha` in (0, 1].
    /// `alpha` is clamped to [[`MIN_ALPHA`], 1]; the lobe stays a (very narrow) GGX lobe, never a
    /// delta, so use [`Bsdf::Mirror`] for an ideal mirror.
    Conductor {
        /// Reflectance at normal incidence per RGB channel, Schlick's Fresnel term's start.
        f0: Vec3,
        /// The GGX width: near 0 polished, 1 very rough (a scene's `roughness` as given; from
        /// an MTL's `Ns`, `sqrt(2 / (Ns + 2))`).
        alpha: f32,
    },
    /// Smooth glass: Fresnel reflection and refraction with the relative index `ior`, and a
    /// transmission `tint`.
    Dielectric {
        /// The index of refraction inside the glass over the index outside it: the glass's own
        /// index when vacuum (or air) surrounds it, above 1 for glass in air, below 1 for an
        /// air bubble in water.
        ior: f32,
        /// The factor per RGB channel of each refraction through the surface, each in [0, 1];
        /// reflection is not tinted.
        tint: Vec3,
    },
    /// Smooth glass whose index depends on the wavelength (`dispersion`), with a transmission
    /// `tint`. A path that meets it turns spectral (`crate::spectrum`), which resolves it into
    /// the [`Bsdf::Dielectric`] of its wavelength; unresolved, it samples as the glass of its
    /// index at the d line ([`Dispersion::ior_d`]). Either way the relative index is the
    /// glass's index at the wavelength over `outside_ior`.
    DispersiveGlass {
        /// How the index of refraction depends on the wavelength.
        dispersion: Dispersion,
        /// The index of what surrounds the glass, the same at every wavelength (1 for vacuum or
        /// air); kept apart from `dispersion` because the ratio changes with the wavelength.
        outside_ior: f32,
        /// The factor per RGB channel of each refraction through the surface, each in [0, 1];
        /// reflection is not tinted.
        tint: Vec3,
    },
    /// An index-matched boundary: light passes straight through, unchanged. It only marks
    /// where a medium begins ([`Material::interior`]); the integrator crosses it without
    /// counting a scattering event, and shadow rays pass it too.
    Interface,
}

/// One direction drawn by [`Bsdf::sample`], in the local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// The sampled incident direction (unit length, pointing away from the surface).
    pub wi: Vec3,
    /// The path throughput factor: `f * |cos theta_i| / pdf` for a non-delta lobe, the lobe's
    /// throughput divided by its selection probability for a delta lobe.
    pub weight: Vec3,
    /// The solid-angle density of `wi` for a non-delta lobe (equal to [`Bsdf::pdf`]); for a delta
    /// lobe, the discrete probability with which that lobe was chosen (1 for a mirror).
    pub pdf: f32,
    /// Whether `wi` came from a delta lobe, which multiple importance sampling must skip.
    pub delta: bool,
    /// Whether `wi` is on the other side of the surface from `wo` (the path crossed it).
    pub transmission: bool,
}

impl Bsdf {
    /// `f(wo, wi) * |cos theta_i|`: the BSDF times the foreshortening of `wi`. Zero for delta
    /// BSDFs, whose value is a distribution that only [`Bsdf::sample`] can produce.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        match *self {
            Bsdf::Diffuse { albedo, .. } => match same_side_upper(wo, wi) {
                Some((_, wi)) => albedo * (wi.z * FRAC_1_PI),
                None => Vec3::ZERO,
            },
            Bsdf::Conductor { f0, alpha } => match same_side_upper(wo, wi) {
                Some((wo, wi)) => Ggx::new(f0, alpha).eval(wo, wi),
                None => Vec3::ZERO,
            },
            Bsdf::Mirror { .. }
            | Bsdf::Dielectric { .. }
            | Bsdf::DispersiveGlass { .. }
            | Bsdf::Interface => Vec3::ZERO,
        }
    }

    /// The solid-angle density with which [`Bsdf::sample`] draws `wi` given `wo`; zero for delta
    /// BSDFs. For the conductor it integrates to less than 1: the rest is the probability that a
    /// sample fails because the reflection went below the surface.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match *self {
            Bsdf::Diffuse { .. } => match same_side_upper(wo, wi) {
                Some((_, wi)) => wi.z * FRAC_1_PI,
                None => 0.0,
            },
            Bsdf::Conductor { f0, alpha } => match same_side_upper(wo, wi) {
                Some((wo, wi)) => Ggx::new(f0, alpha).pdf(wo, wi),
                None => 0.0,
            },
            Bsdf::Mirror { .. }
            | Bsdf::Dielectric { .. }
            | Bsdf::DispersiveGlass { .. }
            | Bsdf::Interface => 0.0,
        }
    }

    /// Draws `wi` given `wo`, using exactly `u_choice` for the discrete choice between lobes (the
    /// dielectric's reflect-or-refract; ignored by the other materials) and `u` for the
    /// direction, all in [0, 1). `None` means the path ends here: `wo` is in the tangent plane,
    /// or a microfacet reflection went below the surface.
    pub fn sample(&self, wo: Vec3, u_choice: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z == 0.0 || wo.z.is_nan() {
            return None;
        }
        let flip = wo.z < 0.0;
        match *self {
            Bsdf::Diffuse { albedo, .. } => {
                let wi = sample_cosine_hemisphere(u);
                (wi.z > 0.0).then(|| BsdfSample {
                    wi: flip_z(wi, flip),
                    weight: albedo,
                    pdf: wi.z * FRAC_1_PI,
                    delta: false,
                    transmission: false,
                })
            }
            Bsdf::Mirror { reflectance } => Some(BsdfSample {
                wi: reflect_local(wo),
                weight: reflectance,
                pdf: 1.0,
                delta: true,
                transmission: false,
            }),
            Bsdf::Conductor { f0, alpha } => {
                let (wi, weight, pdf) = Ggx::new(f0, alpha).sample(flip_z(wo, flip), u)?;
                Some(BsdfSample {
                    wi: flip_z(wi, flip),
                    weight,
                    pdf,
                    delta: false,
                    transmission: false,
                })
            }
            Bsdf::Dielectric { ior, tint } => sample_dielectric(ior, tint, wo, u_choice),
            Bsdf::DispersiveGlass {
                dispersion,
                outside_ior,
                tint,
            } => sample_dielectric(dispersion.ior_d() / outside_ior, tint, wo, u_choice),
            Bsdf::Interface => Some(BsdfSample {
                wi: -wo,
                weight: Vec3::ONE,
                pdf: 1.0,
                delta: true,
                transmission: true,
            }),
        }
    }

    /// Whether every direction the BSDF scatters into comes from a delta lobe, so that `eval`
    /// and `pdf` are zero everywhere and light sampling is useless.
    pub fn is_delta(&self) -> bool {
        matches!(
            self,
            Bsdf::Mirror { .. }
                | Bsdf::Dielectric { .. }
                | Bsdf::DispersiveGlass { .. }
                | Bsdf::Interface
        )
    }

    /// Whether light can pass through the surface (the path may change sides).
    pub fn has_transmission(&self) -> bool {
        matches!(
            self,
            Bsdf::Dielectric { .. } | Bsdf::DispersiveGlass { .. } | Bsdf::Interface
        )
    }

    /// Whether the index depends on the wavelength: a path that meets it must turn spectral.
    pub fn is_dispersive(&self) -> bool {
        matches!(self, Bsdf::DispersiveGlass { .. })
    }

    /// The texture that still has to be resolved into the albedo, if any.
    pub fn texture(&self) -> Option<u32> {
        match *self {
            Bsdf::Diffuse { texture, .. } => texture,
            _ => None,
        }
    }

    /// The BSDF at one shading point: a textured diffuse's albedo multiplied by the texture's
    /// `value` there, with the texture cleared. Other BSDFs are returned unchanged.
    pub fn with_texture_value(self, value: Vec3) -> Bsdf {
        match self {
            Bsdf::Diffuse {
                albedo,
                texture: Some(_),
            } => Bsdf::Diffuse {
                albedo: albedo * value,
                texture: None,
            },
            other => other,
        }
    }
}

/// Maps a pair of directions on the same side of the surface to the upper hemisphere, mirroring
/// both through the tangent plane when `wo` is below it: the two-sided reflection convention.
/// `None` when they are on opposite sides or either is in the tangent plane.
fn same_side_upper(wo: Vec3, wi: Vec3) -> Option<(Vec3, Vec3)> {
    let flip = wo.z < 0.0;
    let (wo, wi) = (flip_z(wo, flip), flip_z(wi, flip));
    (wo.z > 0.0 && wi.z > 0.0).then_some((wo, wi))
}

fn flip_z(v: Vec3, flip: bool) -> Vec3 {
    if flip { Vec3::new(v.x, v.y, -v.z) } else { v }
}

/// A cosine-weighted direction in the upper hemisphere (density `cos theta / pi`), by Malley's
/// method: a uniform point on the unit disk lifted onto the hemisphere.
#[inline(always)]
pub(crate) fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = crate::math::concentric_disk(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    const WHITE: Vec3 = Vec3::ONE;

    fn all_materials() -> [Bsdf; 4] {
        [
            Bsdf::Diffuse {
                albedo: WHITE,
                texture: None,
            },
            Bsdf::Mirror { reflectance: WHITE },
            Bsdf::Conductor {
                f0: WHITE,
                alpha: 0.3,
            },
            Bsdf::Dielectric {
                ior: 1.5,
                tint: WHITE,
            },
        ]
    }

    #[test]
    fn flags_describe_the_lobes() {
        let [diffuse, mirror, conductor, glass] = all_materials();
        assert!(!diffuse.is_delta() && !conductor.is_delta());
        assert!(mirror.is_delta() && glass.is_delta());
        assert!(glass.has_transmission());
        assert!(!diffuse.has_transmission() && !mirror.has_transmission());
        assert!(!conductor.has_transmission());
    }

    #[test]
    fn texture_value_multiplies_the_albedo_once() {
        let textured = Bsdf::Diffuse {
            albedo: Vec3::new(0.5, 1.0, 0.2),
            texture: Some(3),
        };
        assert_eq!(textured.texture(), Some(3));
        let resolved = textured.with_texture_value(Vec3::new(0.5, 0.25, 1.0));
        assert_eq!(
            resolved,
            Bsdf::Diffuse {
                albedo: Vec3::new(0.25, 0.25, 0.2),
                texture: None
            }
        );
        assert_eq!(resolved.texture(), None);
        assert_eq!(resolved.with_texture_value(Vec3::ZERO), resolved);
        let mirror = Bsdf::Mirror { reflectance: WHITE };
        assert_eq!(mirror.with_texture_value(Vec3::ZERO), mirror);
    }

    #[test]
    fn reflectors_are_two_sided_and_never_transmit() {
        let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
        let wi = Vec3::new(-0.5, 0.1, 0.6).normalize();
        let (wo_back, wi_back) = (flip_z(wo, true), flip_z(wi, true));
        for bsdf in [all_materials()[0], all_materials()[2]] {
            let front = bsdf.eval(wo, wi);
            assert!(front.min_element() > 0.0, "{bsdf:?} front");
            assert_eq!(bsdf.eval(wo_back, wi_back), front, "{bsdf:?} from the back");
            assert_eq!(
                bsdf.pdf(wo_back, wi_back),
                bsdf.pdf(wo, wi),
                "{bsdf:?} pdf from the back"
            );
            assert_eq!(bsdf.eval(wo, wi_back), Vec3::ZERO, "{bsdf:?} transmits");
            assert_eq!(bsdf.pdf(wo_back, wi), 0.0, "{bsdf:?} transmits");
            let s = bsdf
                .sample(wo_back, 0.5, Vec2::new(0.3, 0.6))
                .expect("a diffuse or rough sample");
            assert!(
                s.wi.z < 0.0 && !s.transmission,
                "{bsdf:?} sampled {s:?} from the back"
            );
        }
    }

    #[test]
    fn mirror_reflects_about_the_normal() {
        let bsdf = Bsdf::Mirror {
            reflectance: Vec3::new(0.9, 0.5, 0.1),
        };
        for wo in [Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.0, -0.6, -0.8)] {
            let s = bsdf
                .sample(wo, 0.7, Vec2::new(0.1, 0.2))
                .expect("mirrors always reflect");
            assert_eq!(s.wi, Vec3::new(-wo.x, -wo.y, wo.z));
            assert_eq!(s.weight, Vec3::new(0.9, 0.5, 0.1));
            assert!(s.delta && !s.transmission);
            assert_eq!(bsdf.eval(wo, s.wi), Vec3::ZERO);
            assert_eq!(bsdf.pdf(wo, s.wi), 0.0);
        }
    }

    #[test]
    fn tangent_plane_scatters_nothing() {
        let wo = Vec3::X;
        for bsdf in all_materials() {
            assert!(bsdf.sample(wo, 0.5, Vec2::splat(0.5)).is_none(), "{bsdf:?}");
            assert_eq!(bsdf.eval(wo, Vec3::Z), Vec3::ZERO, "{bsdf:?}");
            assert_eq!(bsdf.eval(Vec3::Z, wo), Vec3::ZERO, "{bsdf:?}");
            assert_eq!(bsdf.pdf(wo, Vec3::Z), 0.0, "{bsdf:?}");
        }
    }

    #[test]
    fn concentric_map_stays_in_the_disk_and_covers_its_rim() {
        let mut max_r = 0.0f32;
        for i in 0..=64 {
            for j in 0..=64 {
                let u = Vec2::new(i as f32 / 64.0, j as f32 / 64.0);
                let r = crate::math::concentric_disk(u).length();
                assert!(r <= 1.0 + 1e-6, "u = {u} maps outside the disk (r = {r})");
                max_r = max_r.max(r);
            }
        }
        assert!(max_r > 0.999, "the rim is never reached: max r = {max_r}");
        assert_eq!(crate::math::concentric_disk(Vec2::splat(0.5)), Vec2::ZERO);
    }
}
