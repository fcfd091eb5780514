//! The light-transport effects a scene calls for, derived from its materials, lights and settings.
//!
//! Why: most scenes use a few of the renderer's features, and a path tracer that asks at every
//! bounce whether the environment, a light or a texture is there still pays for the asking, and
//! worse, for work whose result is known to be zero (a light sample in a scene where nothing
//! emits). The integrator skips whole code paths for absent effects.
//!
//! The rule: an effect is left out only when the work it guards would contribute *exactly* zero,
//! bit for bit, and random dimensions are reserved per bounce whether used or not
//! ([`crate::sampler`]), so a specialised render is bit-identical to one with every effect forced
//! on ([`Effects::ALL`], `tessera render --effects all`). Flag by flag:
//! - `area_lights`, `point_lights`, `environment`: a kind of light is present when something of
//!   that kind emits a non-zero amount. [`crate::lights::Lights`] never lists a light without
//!   power in either mode, so the light choice is the same list with the same probabilities; an
//!   escaped ray adds `beta * 0` for a zero environment, which is `+0` since `beta` is finite.
//! - `shadows`: next-event estimation (a light sample, then a shadow ray) is done only when there
//!   is a light and a surface it can light: a non-delta lobe that reflects something (diffuse
//!   with a non-zero albedo, or a rough conductor). Elsewhere the light sample is either never
//!   taken (delta BSDFs) or its BSDF value is exactly zero (black diffuse), and the estimator
//!   returns zero before tracing.
//! - `textures`, `shading_normals`: without them the branches never match anyway (a texture on a
//!   zero albedo only multiplies zero by a finite texel); the flags also let the integrator skip
//!   interpolating texture coordinates, which only a texture lookup reads.
//! - `environment_map`: reported; which lookup and which sampler run is told by the closed enum
//!   [`Environment`], so a constant environment never touches map code in either mode. A map
//!   whose every texel is zero is no environment at all (the flag above).
//! - `depth_of_field`: rays start across the lens only at frames whose aperture is above zero,
//!   in either mode; a pinhole frame traces exactly the rays it traced before lenses existed,
//!   and the lens's random numbers come from a stream of their own ([`crate::sampler`]), so
//!   drawing them or not shifts no other number.
//! - `motion_blur`: the shutter stays open for a while and something moves (the camera between
//!   keys that differ, or an object with keys). Only then does each sample draw its time, from
//!   a stream of its own ([`crate::sampler`]), and take the camera and the moving objects where
//!   they are at that time. Without it every sample is taken at the frame's instant plus the
//!   shutter's opening (`frame + open`). Forced on in a scene without it, either the shutter is
//!   an instant, and every drawn time is `frame + open + u * 0`, that same instant to the bit;
//!   or nothing moves, and the camera at any time is its one pose (interpolating between equal
//!   keys gives `a + s * 0 = a`). Objects with keys move in every mode, between frames too,
//!   through their own trees (`crate::geometry::MotionAccel`); that is animation, not an
//!   effect, and scenes without them never touch that code.
//! - `specular_reflection`, `glossy_reflection`, `refraction`, `diffuse`: reported, and counted
//!   per sample (refractions); the BSDF is a closed enum, so no code of an absent material runs.
//! - `media`: a used material binds a medium that is not vacuum, inside or outside (the
//!   outside is the camera's medium unless the scene names an enclosing object's, so nested
//!   media need no rule of their own), the camera starts in one, or a used material is an
//!   index-matched interface. Only then does every ray sample a free flight
//!   through the medium it is in and every shadow ray take the transmittance
//!   ([`crate::medium`]), finding its closest blocker to pass interfaces where the scene has any
//!   (without one, the any-hit query answers the same). With media forced on in a scene
//!   without them, every ray is in [`crate::medium::Medium::VACUUM`]: its flights pass with
//!   weight exactly 1 (beta times 1 is beta; after a path's first flight, which picks its hero
//!   channel, a vacuum's flights are not even drawn), its transmittance is exactly 1, and the
//!   closest certain blocker exists exactly when the any-hit query finds one
//!   ([`crate::geometry::Accel::intersect_certain_with`]), so the bits do not move; the free
//!   flight's two random numbers come from a stream of their own ([`crate::sampler`]). That
//!   forced pipeline is what a renderer that always tracks media pays: a flight per ray, and,
//!   in scenes with an interface, closest-hit shadow rays instead of any-hit ones.
//! - `dispersion`: a used material is glass whose index depends on the wavelength. Paths are RGB
//!   until they meet such a surface, and only there turn spectral ([`crate::spectrum`]), drawing
//!   their wavelengths from a stream of their own. Forced on in a scene without it, the
//!   integrator asks each surface whether it is dispersive, none is, and no path turns: the
//!   same numbers, the same bits. The always-spectral pipeline that the specialisation saves is
//!   not this flag but [`crate::spectrum::SpectralSampling::Hero`], a knob of `tessera bench`
//!   and `tessera accuracy`.
//!
//! Not done, on purpose: "no shadow rays when nothing can block" beyond the case where nothing
//! emits. A shadow ray can be skipped exactly only if the occlusion test would certainly say
//! "unoccluded", and the obvious candidate, a camera and point lights inside one closed convex
//! mesh, needs more than it seems. With the old fixed-ULP spawn offset it failed outright (the
//! offset was not parallel to the normal and crossed neighbours' planes: an inward box falsely
//! occluded 4 of 2,400 rays at its edges, a radius-3 sphere at (1e5, 1e5, 0) 596 of 256,000).
//! With the error-bound offset `tracer/tests/offsets.rs` counts no false occlusion inside
//! spheres that are convex in f32, but the skip would have to establish that convexity exactly,
//! per mesh, and a scene's mesh far from the origin can stop being convex by rounding alone.

use crate::environment::Environment;
use crate::material::Bsdf;
use crate::scene::Scene;
use glam::Vec3;
use std::fmt;

/// The set of effects a render pays for. Each flag guards one code path of the integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Effects {
    /// Emissive triangles exist: emission is added on hits and area lights are sampled.
    pub area_lights: bool,
    /// Point lights with non-zero intensity exist: they are sampled by next-event estimation.
    pub point_lights: bool,
    /// A non-zero environment (constant or a map) surrounds the scene: escaped rays pick it up,
    /// and it is sampled.
    pub environment: bool,
    /// The environment is a lat-long map (with a texel other than zero), importance-sampled.
    pub environment_map: bool,
    /// The camera has a lens (an aperture above zero) at some frame: rays start across it.
    pub depth_of_field: bool,
    /// Next-event estimation: a light is sampled and a shadow ray traced at non-delta surfaces.
    pub shadows: bool,
    /// Some surface scatters diffusely (a Lambertian albedo other than zero).
    pub diffuse: bool,
    /// Some surface is a perfect mirror.
    pub specular_reflection: bool,
    /// Some surface is a rough conductor.
    pub glossy_reflection: bool,
    /// Some surface is glass.
    pub refraction: bool,
    /// Some material reads a texture (and its albedo is not zero).
    pub textures: bool,
    /// Some triangle carries shading normals.
    pub shading_normals: bool,
    /// Participating media (or index-matched boundaries) exist: rays are tracked through them.
    pub media: bool,
    /// The shutter is open for a while and something moves: each sample has a time of its own.
    pub motion_blur: bool,
    /// Some glass disperses (its index depends on the wavelength): paths that meet it turn
    /// spectral.
    pub dispersion: bool,
}

impl Effects {
    /// Every effect on: the reference against which specialised renders are checked.
    pub const ALL: Effects = Effects {
        area_lights: true,
        point_lights: true,
        environment: true,
        environment_map: true,
        depth_of_field: true,
        shadows: true,
        diffuse: true,
        specular_reflection: true,
        glossy_reflection: true,
        refraction: true,
        textures: true,
        shading_normals: true,
        media: true,
        motion_blur: true,
        dispersion: true,
    };

    /// The effects `scene` needs. Only materials that some triangle uses count.
    pub fn of(scene: &Scene) -> Effects {
        let used = |pred: fn(&Bsdf) -> bool| {
            scene
                .all_triangles()
                .any(|t| pred(&scene.materials[t.material as usize].bsdf))
        };
        let area_lights = scene.emissive_triangles().next().is_some();
        let point_lights = scene.point_lights.iter().any(|l| l.intensity != Vec3::ZERO);
        let environment = scene.environment.as_ref().is_some_and(|e| !e.is_black());
        let environment_map = environment && matches!(scene.environment, Some(Environment::Map(_)));
        let depth_of_field = scene
            .camera
            .keys()
            .iter()
            .any(|k| k.camera.aperture_radius > 0.0);
        let diffuse = used(|b| matches!(b, Bsdf::Diffuse { albedo, .. } if *albedo != Vec3::ZERO));
        let glossy_reflection = used(|b| matches!(b, Bsdf::Conductor { .. }));
        let not_vacuum = |m: Option<u32>| m.is_some_and(|m| !scene.media[m as usize].is_vacuum());
        let media = not_vacuum(scene.camera_medium)
            || scene.all_triangles().any(|t| {
                let material = &scene.materials[t.material as usize];
                matches!(material.bsdf, Bsdf::Interface)
                    || not_vacuum(material.interior)
                    || not_vacuum(material.exterior)
            });
        Effects {
            area_lights,
            point_lights,
            environment,
            environment_map,
            depth_of_field,
            // A light sample pays off only where a non-delta lobe reflects something.
            shadows: (area_lights || point_lights || environment) && (diffuse || glossy_reflection),
            diffuse,
            specular_reflection: used(|b| matches!(b, Bsdf::Mirror { .. })),
            glossy_reflection,
            refraction: used(|b| {
                matches!(b, Bsdf::Dielectric { .. } | Bsdf::DispersiveGlass { .. })
            }),
            textures: used(
                |b| matches!(b, Bsdf::Diffuse { albedo, texture: Some(_) } if *albedo != Vec3::ZERO),
            ),
            shading_normals: scene.has_shading_normals(),
            media,
            motion_blur: scene.shutter.is_open() && scene.moves(),
            dispersion: used(Bsdf::is_dispersive),
        }
    }

    /// Any light that next-event estimation can sample.
    pub fn has_lights(&self) -> bool {
        self.area_lights || self.point_lights || self.environment
    }

    /// The names of the effects that are on, in a fixed order (as printed and in stats.json).
    pub fn names(&self) -> Vec<&'static str> {
        let flags = [
            (self.area_lights, "area-lights"),
            (self.point_lights, "point-lights"),
            (self.environment, "environment"),
            (self.environment_map, "environment-map"),
            (self.depth_of_field, "depth-of-field"),
            (self.shadows, "shadows"),
            (self.diffuse, "diffuse"),
            (self.specular_reflection, "specular-reflection"),
            (self.glossy_reflection, "glossy-reflection"),
            (self.refraction, "refraction"),
            (self.textures, "textures"),
            (self.shading_normals, "shading-normals"),
            (self.media, "media"),
            (self.motion_blur, "motion-blur"),
            (self.dispersion, "dispersion"),
        ];
        flags
            .into_iter()
            .filter(|(on, _)| *on)
            .map(|(_, name)| name)
            .collect()
    }
}

impl fmt::Display for Effects {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = self.names();
        if names.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&names.join(","))
        }
    }
}
