//! Next-event estimation (a point sampled on a light, then a shadow ray) and how it combines
//! with the other strategy that can find an area light, BSDF sampling (a direction drawn from
//! the surface that happens to hit an emitter).
//!
//! Both are unbiased for the light a path gathers from an emissive triangle, so a renderer may
//! use either alone or both, weighted. The default weighs them by the power heuristic (Veach's
//! multiple importance sampling, exponent 2), which keeps each where it is good: light sampling
//! for small or distant lights seen from rough surfaces, BSDF sampling for large lights seen
//! from glossy ones. The two single strategies exist as a comparison knob ([`AreaLightSampling`],
//! `tessera accuracy --knobs lights`): they show what the weighting buys in noise, and what it
//! costs in time (the light's density at every BSDF-sampled emitter hit, the BSDF's at every
//! light sample). Only area lights follow the knob: a point light is a delta that only light
//! sampling can find, and the environment has its own knob
//! ([`crate::lights::EnvironmentSampling`]).

use super::scatter::Scatterer;
use super::{PathStats, World};
use crate::geometry::{Moment, Ray, SurfacePoint, spawn_ray, spawn_ray_to};
use crate::lights::LightSample;
use crate::spectrum::PathSpectrum;
use glam::{Vec2, Vec3};

/// Which strategies find area lights (emissive triangles, still or moving); every choice is
/// unbiased, and they differ in noise and time only. A comparison knob, like
/// [`crate::lights::EnvironmentSampling`]: renders pick the default.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum AreaLightSampling {
    /// Both, weighted by the power heuristic.
    #[default]
    Mis,
    /// Next-event estimation alone: a BSDF-sampled ray that hits an emitter adds nothing,
    /// except after a specular bounce or from the camera, where no light sample could have
    /// found it.
    Light,
    /// BSDF sampling alone: light samples that land on an area light are dropped, before their
    /// shadow ray.
    Bsdf,
}

impl AreaLightSampling {
    /// Every way, the default first: the ladder `tessera accuracy --knobs lights` walks.
    pub const ALL: [AreaLightSampling; 3] = [
        AreaLightSampling::Mis,
        AreaLightSampling::Light,
        AreaLightSampling::Bsdf,
    ];

    /// The name in reports.
    pub fn name(self) -> &'static str {
        match self {
            AreaLightSampling::Mis => "mis",
            AreaLightSampling::Light => "light-only",
            AreaLightSampling::Bsdf => "bsdf-only",
        }
    }

    /// The weight of an emitter found by BSDF sampling with density `bsdf_pdf` after a
    /// non-specular bounce; `light_pdf` gives light sampling's density of the same point,
    /// asked only where the weighting needs it.
    pub(super) fn bsdf_hit_weight(self, bsdf_pdf: f32, light_pdf: impl FnOnce() -> f32) -> f32 {
        match self {
            AreaLightSampling::Mis => power_heuristic(bsdf_pdf, light_pdf()),
            AreaLightSampling::Light => 0.0,
            AreaLightSampling::Bsdf => 1.0,
        }
    }

    /// Whether this choice drops the light sample `light` before its shadow ray: BSDF sampling
    /// alone drops those on area lights.
    pub(super) fn drops(self, light: &LightSample) -> bool {
        self == AreaLightSampling::Bsdf && on_area_light(light)
    }

    /// The weight of the light sample `light` (one [`AreaLightSampling::drops`] kept), whose
    /// direction the scatterer would sample with density `scatter_pdf` (asked only where the
    /// weighting needs it). Delta lights take all the weight whatever the choice; the
    /// environment is weighed by the power heuristic, as its own knob decides how it is sampled.
    pub(super) fn light_weight(
        self,
        light: &LightSample,
        scatter_pdf: impl FnOnce() -> f32,
    ) -> f32 {
        if light.delta || (self == AreaLightSampling::Light && on_area_light(light)) {
            1.0
        } else {
            power_heuristic(
                light.pdf,
                against_strategies(scatter_pdf(), light.other_pdf),
            )
        }
    }
}

/// The density a light sample's own is weighed against by the power heuristic: the
/// scatterer's, `scatter_pdf`, where the light is sampled one way; where it is sampled two
/// ways (the environment with portals: its `other_pdf` positive), the root of the sum of both
/// other strategies' squared densities, which makes the two-strategy heuristic the one over
/// three, `f^2 / (f^2 + g^2 + h^2)` (see `LightSample::other_pdf`). For the scalar paths and
/// the lanes' vector shading alike (whose loop makes the branch a select).
#[inline(always)]
pub(super) fn against_strategies(scatter_pdf: f32, other_pdf: f32) -> f32 {
    if other_pdf > 0.0 {
        let (g, h) = (f64::from(scatter_pdf), f64::from(other_pdf));
        (g * g + h * h).sqrt() as f32
    } else {
        scatter_pdf
    }
}

impl World {
    /// One light sample seen from `at` in `medium` through `scatter` (a BSDF or a phase
    /// function), weighted by multiple importance sampling against the scatterer's own sampling,
    /// at the wavelengths of `spectrum`.
    pub(super) fn direct_light(
        &self,
        scatter: &impl Scatterer,
        at: &SurfacePoint,
        media: (Option<u32>, &PathSpectrum),
        moment: &Moment,
        numbers: (f32, Vec2),
        stats: &mut PathStats,
    ) -> Vec3 {
        let mut samples = LightSamples::default();
        self.sample_lights(at, moment, numbers, stats, &mut samples);
        self.direct_from(&samples, scatter, at, media, moment, numbers, stats)
    }

    /// The first half of [`World::direct_light`]: where its light samples land, into
    /// `samples` (none before), which does not depend on the scatterer, so that a surface's
    /// texel can be on its way from memory meanwhile (`World::radiance`). Inlined, as
    /// `direct_light` was: returned through a call the samples were copied through memory, two
    /// percent of a Cornell box's instructions. Written in place: returned as a value, the
    /// sample was taken out of its `Option` and copied whole into a new one, read back across
    /// the narrow stores that had just written its last fields, which the processor cannot
    /// forward (5 % of `radiance_from`'s samples on the Cornell box; docs/bench.md, issue 12,
    /// twenty-second round).
    #[inline(always)]
    pub(super) fn sample_lights(
        &self,
        at: &SurfacePoint,
        moment: &Moment,
        (u_choice, u): (f32, Vec2),
        stats: &mut PathStats,
        samples: &mut LightSamples,
    ) {
        stats.light_samples += 1;
        self.lights
            .sample_into(&self.scene, moment, at.p, (u_choice, u), &mut samples.own);
        // The environment with portals takes a second sample, through them (`Lights::
        // portal_sample`); both are weighed by the power heuristic over the three strategies.
        if let Some(own) = &samples.own
            && own.distance.is_infinite()
            && self.lights.has_portals()
        {
            samples.through = self.lights.portal_sample(&self.scene, at.p, u_choice, u);
            if samples.through.is_some() {
                stats.light_samples += 1;
            }
        }
    }

    /// The second half of [`World::direct_light`]: what `samples` bring through `scatter`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) fn direct_from(
        &self,
        samples: &LightSamples,
        scatter: &impl Scatterer,
        at: &SurfacePoint,
        media: (Option<u32>, &PathSpectrum),
        moment: &Moment,
        (u_choice, u): (f32, Vec2),
        stats: &mut PathStats,
    ) -> Vec3 {
        let Some(own) = &samples.own else {
            return Vec3::ZERO;
        };
        let numbers = [u_choice, u.x, u.y];
        let own = self.light_contribution(scatter, at, own, media, moment, &numbers, stats);
        match &samples.through {
            Some(through) => {
                own + self.light_contribution(scatter, at, through, media, moment, &numbers, stats)
            }
            None => own,
        }
    }

    /// What the light sample `light` brings to `at` through `scatter`, weighed; `numbers` drive
    /// the shadow ray's tracking through media.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn light_contribution(
        &self,
        scatter: &impl Scatterer,
        at: &SurfacePoint,
        light: &LightSample,
        (medium, spectrum): (Option<u32>, &PathSpectrum),
        moment: &Moment,
        numbers: &[f32; 3],
        stats: &mut PathStats,
    ) -> Vec3 {
        if self.area_lights.drops(light) {
            return Vec3::ZERO;
        }
        let f = scatter.f(light.wi);
        if f == Vec3::ZERO || light.radiance == Vec3::ZERO || light.pdf <= 0.0 {
            return Vec3::ZERO;
        }
        stats.shadow_rays += 1;
        let shadow = self.shadow_ray(at, light);
        // Without media a shadow ray is blocked or not; with them it carries what the media let
        // through, and passes index-matched interfaces (`scatter.rs`). A vacuum lets exactly 1
        // through, and `x * 1` is `x`, so the product below keeps its bits either way.
        let transmittance = if self.effects.media {
            let transmittance = self.transmittance(&shadow, light, medium, moment, numbers, stats);
            if transmittance == Vec3::ZERO {
                return Vec3::ZERO;
            }
            spectrum.channels(transmittance)
        } else if self.occluded(&shadow, moment, &mut stats.traversal) {
            return Vec3::ZERO;
        } else {
            Vec3::ONE
        };
        let weight = self
            .area_lights
            .light_weight(light, || scatter.pdf(light.wi));
        f * spectrum.of(light.radiance) * (weight / light.pdf) * transmittance
    }

    /// The shadow ray from `at` towards the sampled light: to its point, or along its direction
    /// when it is infinitely far (the environment).
    pub(super) fn shadow_ray(&self, at: &SurfacePoint, light: &LightSample) -> Ray {
        if light.distance.is_finite() {
            spawn_ray_to(at, &light.at, self.offset)
        } else {
            spawn_ray(at, light.wi, self.offset)
        }
    }

    /// What the environment sends along `dir`, the direction of a path's ray that met
    /// nothing, and its weight by multiple importance sampling against light sampling after
    /// the last scattering (`last`: its density, whether it was a delta, where it was);
    /// `None` where the world has no environment. For the scalar paths and the lanes alike.
    #[inline(always)]
    pub(super) fn environment_seen(
        &self,
        dir: Vec3,
        (last_pdf, last_delta, last_point): (f32, bool, Vec3),
        stats: &mut PathStats,
    ) -> Option<(Vec3, f32)> {
        if !self.effects.environment {
            return None;
        }
        let look = self.scene.environment.as_ref()?.look(dir);
        stats.environment_lookups += 1;
        let weight = if last_delta {
            1.0
        } else {
            let light_pdf = self.lights.environment_pdf(last_point, dir, &look);
            power_heuristic(last_pdf, light_pdf)
        };
        Some((look.radiance, weight))
    }

    /// The weight of an emitter that a path's ray found at `at` (on triangle `triangle`),
    /// after a scattering at `last_point` that sampled the ray with density `last_pdf`, or a
    /// delta (or the camera) where `last_delta`: multiple importance sampling against light
    /// sampling, for the scalar paths and the paths in lanes alike.
    #[inline(always)]
    pub(super) fn hit_emitter_weight(
        &self,
        moment: &Moment,
        triangle: u32,
        at: Vec3,
        (last_pdf, last_delta, last_point): (f32, bool, Vec3),
    ) -> f32 {
        if last_delta {
            1.0
        } else {
            self.area_lights.bsdf_hit_weight(last_pdf, || {
                self.lights.triangle_pdf(moment, triangle, last_point, at)
            })
        }
    }
}

/// The light samples of one next-event estimation ([`World::sample_lights`]): none where no
/// light could be sampled; a second, through the environment's portals, where the first is the
/// environment and the scene declares portals.
#[derive(Default)]
pub(super) struct LightSamples {
    own: Option<LightSample>,
    through: Option<LightSample>,
}

/// Whether `light` lies on an area light: of the lights that are not deltas, every one but the
/// environment (the only one infinitely far) is an emissive triangle.
fn on_area_light(light: &LightSample) -> bool {
    !light.delta && light.distance.is_finite()
}

/// Veach's power heuristic with exponent 2: the weight of a sample drawn with density `f`
/// against another strategy's density `g` of the same sample.
#[inline(always)]
pub(super) fn power_heuristic(f: f32, g: f32) -> f32 {
    let (f2, g2) = (f * f, g * g);
    if f2 + g2 == 0.0 || !(f2 + g2).is_finite() {
        // One density is infinite (a delta) or both vanish: the finite one takes all the weight.
        return if f.is_finite() && f > g {
            1.0
        } else if g.is_finite() && g > f {
            0.0
        } else {
            1.0
        };
    }
    f2 / (f2 + g2)
}
