//! What scatters light at a path's vertex and what a path travels through: a BSDF at a surface
//! or the phase function in a medium, as next-event estimation sees them; the random numbers
//! every bounce draws; which medium a path is in; what a shadow ray lets through; and the
//! texel a textured surface's BSDF reads.
//!
//! A path starts in the camera's medium (`Scene::camera_medium`, vacuum when there is none) and
//! changes medium only where it crosses a surface: through glass (a refraction) or an
//! index-matched interface. Crossing against the surface's normal enters the material's
//! interior medium, crossing along it its exterior one, which is the camera's medium unless the
//! scene names the medium of an enclosing object (`outside_medium`). So media nest as pbrt-v4's
//! `MediumInterface` nests them: each surface says what lies on its two sides, and the path
//! keeps no stack. Shadow rays follow the same rule: they start in the medium of the point they
//! leave and cross each interface on their way into the medium its side names, so every
//! segment's transmittance is taken in the medium that segment lies in.

use super::World;
use crate::geometry::{Moment, Ray};
use crate::lights::LightSample;
use crate::material::{Bsdf, Frame, Material};
use crate::medium::{Medium, Stream, henyey_greenstein};
use crate::sampler::{DIMENSIONS_PER_BOUNCE, PixelSampler};
use crate::scene::Texture;
use glam::{Vec2, Vec3};

/// A scatterer seen from a fixed outgoing direction: the value and the sampling density of an
/// incident world direction `wi`.
pub(super) trait Scatterer {
    /// `f * |cos|` for a surface, the phase function's value in a medium.
    fn f(&self, wi: Vec3) -> Vec3;
    /// The solid-angle density with which the scatterer's own sampling draws `wi`.
    fn pdf(&self, wi: Vec3) -> f32;
}

/// A BSDF in its shading frame, seen from `wo` (local).
pub(super) struct SurfaceScatter<'a> {
    pub bsdf: &'a Bsdf,
    pub frame: &'a Frame,
    pub wo: Vec3,
}

impl Scatterer for SurfaceScatter<'_> {
    fn f(&self, wi: Vec3) -> Vec3 {
        self.bsdf.eval(self.wo, self.frame.to_local(wi))
    }

    fn pdf(&self, wi: Vec3) -> f32 {
        self.bsdf.pdf(self.wo, self.frame.to_local(wi))
    }
}

/// A Henyey-Greenstein phase function of asymmetry `g`, seen from `wo` (world, unit length).
pub(super) struct Phase {
    pub wo: Vec3,
    pub g: f32,
}

impl Scatterer for Phase {
    fn f(&self, wi: Vec3) -> Vec3 {
        Vec3::splat(henyey_greenstein(self.wo.dot(wi), self.g))
    }

    fn pdf(&self, wi: Vec3) -> f32 {
        henyey_greenstein(self.wo.dot(wi), self.g)
    }
}

/// The random numbers of one bounce, all drawn whether used or not, in this fixed order (see
/// [`crate::sampler::DIMENSIONS_PER_BOUNCE`]). A scattering in a medium draws the same block:
/// its phase direction takes the BSDF's pair and leaves `choice` unused.
pub(super) struct BounceNumbers {
    pub light_choice: f32,
    pub light: Vec2,
    pub choice: f32,
    pub scatter: Vec2,
    pub roulette: f32,
}

impl BounceNumbers {
    /// Always inlined: out of line, in the lanes' AVX function, its seven hashes cost a
    /// tenth more instructions (the inliner's choice moved with unrelated changes).
    #[inline(always)]
    pub(super) fn draw(sampler: &mut PixelSampler) -> Self {
        let [
            light_choice,
            light_x,
            light_y,
            choice,
            scatter_x,
            scatter_y,
            roulette,
        ] = sampler.next_nd::<{ DIMENSIONS_PER_BOUNCE as usize }>();
        BounceNumbers {
            light_choice,
            light: Vec2::new(light_x, light_y),
            choice,
            scatter: Vec2::new(scatter_x, scatter_y),
            roulette,
        }
    }
}

impl World {
    /// The medium `medium` names: vacuum for `None`.
    pub(super) fn medium(&self, medium: Option<u32>) -> &Medium {
        medium.map_or(&Medium::VACUUM, |m| &self.scene.media[m as usize])
    }

    /// The medium a ray in `medium` flies through: `medium` itself, unless the ray escapes to
    /// infinity (`escapes`), which only the outside medium can hold. A closed object's interior
    /// is bounded, so a ray that escapes from "inside" one has leaked: a free flight sampled a
    /// scattering point a rounding error beyond the boundary. Left in the interior medium, such
    /// a path would scatter forever in an unbounded copy of it; in the outside medium it meets
    /// what any ray leaving the object would.
    pub(super) fn flight_medium(&self, medium: Option<u32>, escapes: bool) -> &Medium {
        self.medium(if escapes {
            self.scene.camera_medium
        } else {
            medium
        })
    }

    /// The medium beyond a surface of `material` that a path crosses: the object's inside when
    /// it arrived on the front side (`front_facing`), else the object's outside.
    pub(super) fn medium_across(&self, material: &Material, front_facing: bool) -> Option<u32> {
        if front_facing {
            material.interior
        } else {
            material.exterior
        }
    }

    /// What reaches `shadow`'s start from `light` through the media along it, per channel:
    /// zero when a surface other than an index-matched interface blocks it, else the product
    /// of each segment's transmittance between interfaces, starting in `medium`. Ratio
    /// tracking ([`crate::medium::MediaSampling`]) draws from a stream keyed by the light
    /// sample's `numbers`; the closed form draws nothing.
    ///
    /// Each segment asks for the closest *certain* blocker, so that with no interface in the
    /// way the answer is blocked exactly when [`crate::geometry::Accel::occluded_with`] would
    /// say so (that is what keeps `--effects all` bit-identical), and it pays what a renderer
    /// that always tracks media pays: a closest-hit query instead of an any-hit one.
    ///
    /// `shadow` is taken by reference: passed by value, it was copied just after
    /// [`World::shadow_ray`] wrote it, in wide loads across that function's narrower stores,
    /// which the processor cannot forward (docs/bench.md, issue 12, twenty-sixth round).
    pub(super) fn transmittance(
        &self,
        shadow: &Ray,
        light: &LightSample,
        medium: Option<u32>,
        moment: &Moment,
        numbers: &[f32],
        stats: &mut super::PathStats,
    ) -> Vec3 {
        let sampling = &self.scene.settings.media;
        let mut stream = Stream::new(numbers);
        if !self.interfaces {
            // No surface lets the ray through, so the loop below would stop at its first
            // blocker with zero, or cross one medium to the end: the any-hit query tells which,
            // for less than the closest certain blocker costs, and the same bits come out (the
            // loop's product starts at exactly 1). What `--effects all` saves in a scene without
            // media, and a scene of fog or tinted glass alone.
            if self.occluded(shadow, moment, &mut stats.traversal) {
                return Vec3::ZERO;
            }
            let escapes = shadow.t_max == f32::INFINITY;
            let length = shadow.t_max * shadow.dir.length();
            return self.flight_medium(medium, escapes).transmittance_with(
                sampling,
                length,
                &mut stream,
            );
        }
        let mut shadow = *shadow;
        let mut medium = medium;
        let mut transmittance = Vec3::ONE;
        loop {
            let blocker = self.closest_certain(&shadow, moment, &mut stats.traversal);
            let end = blocker.map_or(shadow.t_max, |h| h.t);
            let escapes = end == f32::INFINITY;
            transmittance *= self.flight_medium(medium, escapes).transmittance_with(
                sampling,
                end * shadow.dir.length(),
                &mut stream,
            );
            let Some(hit) = blocker else {
                return transmittance;
            };
            let placed = self.placed(&hit, moment);
            let material = &self.scene.materials[placed.triangle.material as usize];
            if material.bsdf != Bsdf::Interface || transmittance == Vec3::ZERO {
                return Vec3::ZERO;
            }
            let front_facing = shadow.dir.dot(placed.unit_normal) < 0.0;
            medium = self.medium_across(material, front_facing);
            stats.shadow_rays += 1;
            shadow = self.shadow_ray(&placed.at, light);
        }
    }

    /// The texel a textured `bsdf` reads at texture coordinates `uv`, where textures are
    /// simulated: its texture and index (none for a surface without coordinates, which reads white), found
    /// once here and asked for from memory now, so that [`resolve`] reads it after other work
    /// has overlapped the wait.
    pub(super) fn texel_ahead(
        &self,
        bsdf: &Bsdf,
        uv: Option<Vec2>,
    ) -> Option<(&Texture, Option<usize>)> {
        let texture = match *bsdf {
            Bsdf::Diffuse {
                texture: Some(texture),
                ..
            } if self.effects.textures => &self.scene.textures[texture as usize],
            _ => return None,
        };
        let index = uv.map(|uv| texture.nearest(uv));
        if let Some(index) = index {
            texture.prefetch(index);
        }
        Some((texture, index))
    }
}

/// `bsdf` with the texel [`World::texel_ahead`] found for it, if any.
pub(super) fn resolve(bsdf: &Bsdf, texel: Option<(&Texture, Option<usize>)>) -> Bsdf {
    match texel {
        Some((texture, index)) => {
            bsdf.with_texture_value(index.map_or(Vec3::ONE, |index| texture.texel(index)))
        }
        None => *bsdf,
    }
}
