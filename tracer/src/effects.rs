//! The light-transport effects a scene calls for, derived from its materials, lights and settings.
//!
//! The integrator skips whole code paths for absent effects (no shadow rays when nothing emits, no
//! environment lookups without an environment, ...). Skipping is only ever done where the skipped
//! work would contribute exactly zero, and random dimensions are reserved per bounce whether used
//! or not, so a specialised render is bit-identical to one with every effect forced on.

use crate::material::Bsdf;
use crate::scene::Scene;
use std::fmt;

/// The set of effects a render pays for. Each flag guards one code path of the integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Effects {
    /// Emissive triangles exist: emission is added on hits and area lights are sampled.
    pub area_lights: bool,
    /// Point lights exist: they are sampled by next-event estimation.
    pub point_lights: bool,
    /// A constant environment surrounds the scene: escaped rays pick it up, and it is sampled.
    pub environment: bool,
    /// Shadow rays are traced for next-event estimation (needs something to sample).
    pub shadows: bool,
    /// Some surface scatters diffusely.
    pub diffuse: bool,
    /// Some surface is a perfect mirror.
    pub specular_reflection: bool,
    /// Some surface is a rough conductor.
    pub glossy_reflection: bool,
    /// Some surface is glass.
    pub refraction: bool,
    /// Some material reads a texture.
    pub textures: bool,
    /// Some triangle carries shading normals.
    pub shading_normals: bool,
}

impl Effects {
    /// Every effect on: the reference against which specialised renders are checked.
    pub const ALL: Effects = Effects {
        area_lights: true,
        point_lights: true,
        environment: true,
        shadows: true,
        diffuse: true,
        specular_reflection: true,
        glossy_reflection: true,
        refraction: true,
        textures: true,
        shading_normals: true,
    };

    /// The effects `scene` needs.
    pub fn of(scene: &Scene) -> Effects {
        let used = |pred: fn(&Bsdf) -> bool| {
            scene.triangles.iter().any(|t| pred(&scene.materials[t.material as usize].bsdf))
        };
        let area_lights = scene.emissive_triangles().next().is_some();
        let point_lights = !scene.point_lights.is_empty();
        let environment = scene.environment.is_some_and(|e| e != glam::Vec3::ZERO);
        Effects {
            area_lights,
            point_lights,
            environment,
            // Next-event estimation needs a shadow ray exactly when there is a light to sample and
            // something that could stand in its way.
            shadows: (area_lights || point_lights || environment) && !scene.triangles.is_empty(),
            diffuse: used(|b| matches!(b, Bsdf::Diffuse { .. })),
            specular_reflection: used(|b| matches!(b, Bsdf::Mirror { .. })),
            glossy_reflection: used(|b| matches!(b, Bsdf::Conductor { .. })),
            refraction: used(|b| matches!(b, Bsdf::Dielectric { .. })),
            textures: used(|b| matches!(b, Bsdf::Diffuse { texture: Some(_), .. })),
            shading_normals: scene.triangles.iter().any(|t| t.n.is_some()),
        }
    }

    /// Any light that next-event estimation can sample.
    pub fn has_lights(&self) -> bool {
        self.area_lights || self.point_lights || self.environment
    }

    fn names(&self) -> Vec<&'static str> {
        let flags = [
            (self.area_lights, "area-lights"),
            (self.point_lights, "point-lights"),
            (self.environment, "environment"),
            (self.shadows, "shadows"),
            (self.diffuse, "diffuse"),
            (self.specular_reflection, "specular-reflection"),
            (self.glossy_reflection, "glossy-reflection"),
            (self.refraction, "refraction"),
            (self.textures, "textures"),
            (self.shading_normals, "shading-normals"),
        ];
        flags.into_iter().filter(|(on, _)| *on).map(|(_, name)| name).collect()
    }
}

impl fmt::Display for Effects {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = self.names();
        if names.is_empty() { f.write_str("none") } else { f.write_str(&names.join(",")) }
    }
}
