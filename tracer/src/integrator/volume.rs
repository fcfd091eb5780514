//! The integrator's side of participating media: which medium a path is in, and what a shadow
//! ray lets through on its way to a light.
//!
//! A path starts in the camera's medium (`Scene::camera_medium`, vacuum when there is none) and
//! changes medium only where it crosses a surface: through glass (a refraction) or an
//! index-matched interface. Crossing against the surface's normal enters the material's
//! interior medium, crossing along it returns to the outside medium. Objects therefore hold one
//! medium each inside the outside one; a medium-filled object inside another is not modelled.

use super::World;
use crate::geometry::{Ray, SurfacePoint};
use crate::lights::LightSample;
use crate::material::{Bsdf, Material};
use crate::medium::Medium;
use glam::Vec3;

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

    /// The medium beyond a surface of `material` that a path crosses, entering the object when
    /// it arrived on the front side (`front_facing`).
    pub(super) fn medium_across(&self, material: &Material, front_facing: bool) -> Option<u32> {
        if front_facing {
            material.interior
        } else {
            self.scene.camera_medium
        }
    }

    /// What reaches `shadow`'s start from `light` through the media along it, per channel:
    /// zero when a surface other than an index-matched interface blocks it, else the product
    /// of each segment's transmittance between interfaces, starting in `medium`.
    ///
    /// Each segment asks for the closest *certain* blocker, so that with no interface in the
    /// way the answer is blocked exactly when [`crate::geometry::Accel::occluded_with`] would
    /// say so (that is what keeps `--effects all` bit-identical), and it pays what a renderer
    /// that always tracks media pays: a closest-hit query instead of an any-hit one.
    pub(super) fn transmittance(
        &self,
        shadow: Ray,
        light: &LightSample,
        medium: Option<u32>,
        stats: &mut super::PathStats,
    ) -> Vec3 {
        let mut shadow = shadow;
        let mut medium = medium;
        let mut transmittance = Vec3::ONE;
        loop {
            let blocker =
                self.accel
                    .intersect_certain_with(&shadow, self.traversal, &mut stats.traversal);
            let end = blocker.map_or(shadow.t_max, |h| h.t);
            let escapes = end == f32::INFINITY;
            transmittance *= self
                .flight_medium(medium, escapes)
                .transmittance(end * shadow.dir.length());
            let Some(hit) = blocker else {
                return transmittance;
            };
            let triangle = &self.scene.triangles[hit.triangle as usize];
            let material = &self.scene.materials[triangle.material as usize];
            if material.bsdf != Bsdf::Interface || transmittance == Vec3::ZERO {
                return Vec3::ZERO;
            }
            let front_facing = shadow.dir.dot(self.accel.unit_normal(hit.triangle)) < 0.0;
            medium = self.medium_across(material, front_facing);
            let at = SurfacePoint::on_triangle_with_normal(
                &triangle.p,
                hit.b1,
                hit.b2,
                self.accel.plane_normal(hit.triangle),
            );
            stats.shadow_rays += 1;
            shadow = self.shadow_ray(&at, light);
        }
    }
}
