//! The lights of a scene and how next-event estimation samples them.
//!
//! Lights are emissive triangles (one-sided: they emit on the side of their winding normal), point
//! lights and the environment (constant, sampled uniformly over the sphere, or a map, sampled by
//! its luminance: [`crate::environment`]). One light is chosen per shading point: first its kind, each
//! present kind equally likely, then a light of that kind with probability proportional to its
//! power, so a large sky quad is not starved by a hundred tiny lamps. Kinds are not weighed by
//! power against each other because an environment's power depends on the scene's extent (a wide
//! floor would make it swamp a point light and turn the lamp's rare samples into fireflies). The
//! choice uses one random number, and the position on the light two more, whatever the light.
//!
//! How the list and its choice distribution are built: `build.rs`. Moving emitters are area
//! lights placed at the path's time: `moving.rs`. The environment's densities, and its second
//! sample through the scene's portals where it has them: `environment.rs`.
//!
//! A light without positive, finite power is never listed, whatever the effect set: it would be
//! chosen with probability zero anyway, and leaving it out in both a specialised render and one
//! with every effect forced on keeps the two choice distributions identical to the bit (see
//! [`crate::effects`]).

use crate::effects::Effects;
use crate::environment::{Environment, MapSampler, PortalSampler};
use crate::geometry::{Moment, SurfacePoint};
use crate::scene::Scene;
pub(crate) use build::TriangleShape;
use glam::{Vec2, Vec3};
use moving::{object_triangle, placed_shape};
use std::f32::consts::PI;

mod build;
mod environment;
mod moving;
pub(crate) use moving::placed_sample;

/// One light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// An emissive triangle: the index into `Scene::triangles`.
    Triangle(u32),
    /// An emissive triangle of a moving object: `triangle` of `Scene::moving[object]`, placed
    /// where the path's moment puts it.
    Moving {
        /// The moving object, an index into `Scene::moving`.
        object: u32,
        /// The triangle, an index into that object's triangles (in object space).
        triangle: u32,
    },
    /// A point light: where it is and its intensity (power per solid angle), which falls off
    /// with the squared distance.
    Point {
        /// Its position in world space.
        position: Vec3,
        /// Its radiant intensity per channel.
        intensity: Vec3,
    },
    /// The scene's environment, [`Scene::environment`].
    Environment,
}

/// A light as the paths in lanes sample it ([`Lights::lanes_choice`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum LanesLight<'a> {
    /// A still emissive triangle: its index among the scene's, and its shape.
    Triangle(u32, &'a TriangleShape),
    /// A point light: where it is, and its intensity.
    Point { position: Vec3, intensity: Vec3 },
    /// The environment.
    Environment,
    /// A triangle of a moving object: the object's index and the triangle's among its own.
    Moving { object: u32, triangle: u32 },
}

/// How next-event estimation samples the environment; every choice is unbiased, and they differ
/// in noise only. A comparison knob, like [`crate::geometry::Traversal`]: renders pick the default.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum EnvironmentSampling {
    /// A map by its luminance times sin(theta), combined with BSDF sampling by the power
    /// heuristic; a constant environment uniformly over the sphere (which is its importance).
    /// Where the scene declares portals, each sample is joined by a second through them (see
    /// [`Lights::portal_sample`]).
    #[default]
    Importance,
    /// As [`EnvironmentSampling::Importance`], with the scene's portals ignored.
    WithoutPortals,
    /// Uniformly over the sphere, map or not, combined with BSDF sampling.
    Uniform,
    /// Not at all: the environment is found only by BSDF sampling, with full weight (no MIS).
    Bsdf,
}

impl EnvironmentSampling {
    /// Every way, the default first: the ladder `tessera accuracy --knobs environment` walks.
    pub const ALL: [EnvironmentSampling; 4] = [
        EnvironmentSampling::Importance,
        EnvironmentSampling::WithoutPortals,
        EnvironmentSampling::Uniform,
        EnvironmentSampling::Bsdf,
    ];

    /// The name in reports.
    pub fn name(self) -> &'static str {
        match self {
            EnvironmentSampling::Importance => "importance",
            EnvironmentSampling::WithoutPortals => "without-portals",
            EnvironmentSampling::Uniform => "uniform",
            EnvironmentSampling::Bsdf => "bsdf-only",
        }
    }
}

/// A sampled direction towards a light, as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point towards the light.
    pub wi: Vec3,
    /// Distance to the sampled point (infinite for the environment).
    pub distance: f32,
    /// The point on the light with its error bound and normal, for spawning the shadow ray
    /// towards it (on no surface for point lights; unused for the environment).
    pub at: SurfacePoint,
    /// Radiance (or, for a point light, intensity / distance^2) arriving along `wi`.
    pub radiance: Vec3,
    /// Solid-angle density including the probability of choosing this light; for a point light,
    /// just the choice probability (a delta in direction).
    pub pdf: f32,
    /// The density, choice included, with which the light's other sampling strategy would
    /// produce `wi`: for the environment with portals, the portals' for its own sample and its
    /// own for a portal sample; zero for every light sampled one way. Three strategies then
    /// weigh a sample, and the power heuristic over three, `f^2 / (f^2 + g^2 + h^2)`, is the
    /// two-strategy one against `sqrt(g^2 + h^2)`.
    pub other_pdf: f32,
    /// Whether the light is a delta in direction (a point light): BSDF sampling can never find
    /// it, so no multiple importance weight applies.
    pub delta: bool,
}

/// All lights of a scene with their power-proportional choice distribution.
#[derive(Clone, Debug)]
pub struct Lights {
    lights: Vec<Light>,
    /// Where each light's share of the choice's number starts and ends: light `i` takes
    /// `bounds[i]..bounds[i + 1]`; the first is 0 and the last 1, and there are none without
    /// lights. The leading 0 is kept so that where a share starts is a load for every light:
    /// as a branch on the first light, it was mispredicted as often as the number fell on
    /// either side of a two-triangle lamp, some 6 % of a Cornell render's mispredicted branches
    /// (docs/bench.md, issue 12, thirty-ninth round).
    bounds: Vec<f32>,
    /// For each scene triangle, its light's index, or `u32::MAX` when it does not emit; moving
    /// triangles follow the still ones, by the global index hits report.
    triangle_light: Vec<u32>,
    /// The probability of choosing the environment; zero when it is not a sampled light.
    environment_choice: f32,
    /// The environment's index in `lights`, when it is one.
    environment_index: usize,
    /// The map's importance sampler, when the environment is a map sampled by importance.
    map_sampler: Option<MapSampler>,
    /// The scene's portals, when the environment is sampled through them too: then each of its
    /// light samples is joined by one through a portal ([`Lights::portal_sample`]).
    portals: Vec<PortalSampler>,
    scene_radius: f32,
    /// For each light, its triangle's shape when it is a triangle (default otherwise): what
    /// [`Lights::sample`] and [`Lights::triangle_pdf`] would otherwise recompute per sample.
    shapes: Vec<TriangleShape>,
}

impl Lights {
    /// The lights of the kinds `effects` turns on that have positive, finite power.
    pub fn new(scene: &Scene, effects: &Effects) -> Self {
        Self::with_sampling(scene, effects, EnvironmentSampling::default())
    }

    /// Whether the scene has no light at all (then no light is sampled and no shadow ray cast).
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    /// How many lights there are, the environment counted as one.
    pub fn len(&self) -> usize {
        self.lights.len()
    }

    /// The radius of a sphere about the scene's still geometry, which the environment's power
    /// is reckoned over.
    pub fn scene_radius(&self) -> f32 {
        self.scene_radius
    }

    /// The probability that `sample` chooses light `index`.
    fn choice_pdf(&self, index: usize) -> f32 {
        self.bounds[index + 1] - self.bounds[index]
    }

    /// Whether every light is one the paths in lanes sample (`integrator/lanes/`): an emissive
    /// triangle, still or moving, a point light, or an environment that is constant (sampled
    /// uniformly over the sphere) or a map sampled by its importance, with portals or without.
    pub(crate) fn lanes_sample_all(&self, scene: &Scene) -> bool {
        let sky_in_lanes = match (&scene.environment, &self.map_sampler) {
            (None | Some(Environment::Constant(_)), None) => true,
            (Some(Environment::Map(_)), Some(_)) => true,
            // A map sampled uniformly (a comparison knob) is read at every direction drawn,
            // which the lanes' vector shading does not do.
            _ => false,
        };
        !self.lights.is_empty()
            && self.lights.iter().all(|light| match light {
                Light::Triangle(_) | Light::Point { .. } => true,
                Light::Environment => sky_in_lanes,
                Light::Moving { .. } => true,
            })
    }

    /// Whether some light is a point light.
    pub(crate) fn has_point_lights(&self) -> bool {
        self.lights
            .iter()
            .any(|light| matches!(light, Light::Point { .. }))
    }

    /// The environment's own sample for the numbers `u`, the environment being chosen among
    /// the lights with probability `choice`: the direction, what arrives along it, and the
    /// density of both choices; its map by importance, or the sphere uniformly. `None` where
    /// the map gives no direction. The scalar path's next-event estimation and the lanes'
    /// (for maps, `integrator/lanes/`) both sample it here.
    #[inline]
    pub(crate) fn environment_sample(
        &self,
        environment: &Environment,
        u: Vec2,
        choice: f32,
    ) -> Option<(Vec3, Vec3, f32)> {
        if let (Some(sampler), Environment::Map(map)) = (&self.map_sampler, environment) {
            let sample = sampler.sample(map, u)?;
            return Some((sample.wi, sample.radiance, choice * sample.pdf));
        }
        let wi = uniform_sphere(u);
        Some((wi, environment.radiance(wi), uniform_density(choice)))
    }

    /// Whether [`Lights::environment_sample`] draws `environment`'s directions uniformly over
    /// the sphere ([`uniform_sphere`], with density [`uniform_density`]): a constant one, or a
    /// map where the comparison knob samples it so.
    pub(crate) fn samples_sky_uniformly(&self, environment: &Environment) -> bool {
        !matches!(
            (&self.map_sampler, environment),
            (Some(_), Environment::Map(_))
        )
    }

    /// Whether the environment is one of the lights sampled.
    pub(crate) fn environment_is_light(&self) -> bool {
        self.lights
            .iter()
            .any(|light| matches!(light, Light::Environment))
    }

    /// The light `u_choice` picks, as [`Lights::sample`] picks it, with the probability of
    /// the choice, where every light is one the lanes sample ([`Lights::lanes_sample_all`]).
    #[inline(always)]
    pub(crate) fn lanes_choice(&self, u_choice: f32) -> (LanesLight<'_>, f32) {
        let index = self.pick(u_choice);
        let light = match self.lights[index] {
            Light::Triangle(triangle) => LanesLight::Triangle(triangle, &self.shapes[index]),
            Light::Point {
                position,
                intensity,
            } => LanesLight::Point {
                position,
                intensity,
            },
            Light::Environment => LanesLight::Environment,
            Light::Moving { object, triangle } => LanesLight::Moving { object, triangle },
        };
        (light, self.choice_pdf(index))
    }

    /// The index of the light `u_choice` picks from the choice distribution (there is one).
    #[inline(always)]
    fn pick(&self, u_choice: f32) -> usize {
        self.bounds[1..]
            .partition_point(|&c| c <= u_choice)
            .min(self.lights.len() - 1)
    }

    /// The cumulative probability of the lights before `index`: where its share of the choice's
    /// number starts.
    fn cdf_below(&self, index: usize) -> f32 {
        self.bounds[index]
    }

    /// Samples a light as seen from `p` at `moment` (where moving emitters are). `u_choice`
    /// picks the light, `u` the point on it.
    pub fn sample(
        &self,
        scene: &Scene,
        moment: &Moment,
        p: Vec3,
        u_choice: f32,
        u: Vec2,
    ) -> Option<LightSample> {
        let mut sample = None;
        self.sample_into(scene, moment, p, (u_choice, u), &mut sample);
        sample
    }

    /// [`Lights::sample`] into `out` (`None` before): how the renderer calls it.
    // Inlined where the renderer calls it, so that its sample need not go through memory
    // (a store-forwarding stall per shadow ray; docs/bench.md, issue 12, eighth round).
    // Always, with the still triangle's case alone: under a plain `#[inline]` the whole match
    // was left a call, and the sample came back through memory at every bounce (docs/bench.md,
    // issue 12, nineteenth round). The other lights are sampled out of line. Into a place the
    // caller names, by each case: where one value came out of both, the out-of-line call's
    // place was where the inline case built its sample too, which was then copied whole into
    // the caller's variable and read back across the narrow stores of its last fields, which
    // the processor cannot forward (issue 12, twenty-second round).
    #[inline(always)]
    pub fn sample_into(
        &self,
        scene: &Scene,
        moment: &Moment,
        p: Vec3,
        (u_choice, u): (f32, Vec2),
        out: &mut Option<LightSample>,
    ) {
        if self.lights.is_empty() {
            return;
        }
        let index = self.pick(u_choice);
        let choice = self.choice_pdf(index);
        if choice <= 0.0 {
            return;
        }
        if let Light::Triangle(t) = self.lights[index] {
            let triangle = &scene.triangles[t as usize];
            let shape = &self.shapes[index];
            let su = u.x.sqrt();
            let (b1, b2) = (su * (1.0 - u.y), su * u.y);
            let at = SurfacePoint::on_triangle_with_normal(&triangle.p, b1, b2, shape.plane_normal);
            let radiance = scene.materials[triangle.material as usize].emission;
            *out = area_sample(p, at, (shape.area, shape.normal), radiance, choice);
            return;
        }
        *out = self.sample_other(scene, moment, p, (index, choice), u);
    }

    /// [`Lights::sample`] of light `index`, chosen with probability `choice`, where it is not a
    /// still triangle.
    #[inline(never)]
    fn sample_other(
        &self,
        scene: &Scene,
        moment: &Moment,
        p: Vec3,
        (index, choice): (usize, f32),
        u: Vec2,
    ) -> Option<LightSample> {
        match self.lights[index] {
            Light::Triangle(_) => {
                unreachable!("still triangles are sampled inline by `sample_into`")
            }
            Light::Moving { object, triangle } => {
                moving::sample(scene, moment, (object, triangle), p, u, choice)
            }
            Light::Point {
                position,
                intensity,
            } => {
                let to_light = position - p;
                let distance_squared = to_light.length_squared();
                if distance_squared == 0.0 {
                    return None;
                }
                let distance = distance_squared.sqrt();
                Some(LightSample {
                    wi: to_light / distance,
                    distance,
                    at: SurfacePoint::exact(position),
                    radiance: intensity / distance_squared,
                    pdf: choice,
                    other_pdf: 0.0,
                    delta: true,
                })
            }
            Light::Environment => self.environment_light_sample(scene, p, u, choice),
        }
    }

    /// The density with which `sample` would have produced the hit of emissive triangle `t` (a
    /// global index, as hits report it) from `p` at `moment`, for multiple importance sampling;
    /// zero if the triangle is not a sampled light.
    pub fn triangle_pdf(&self, moment: &Moment, t: u32, p: Vec3, hit_point: Vec3) -> f32 {
        let Some(&index) = self.triangle_light.get(t as usize) else {
            return 0.0;
        };
        if index == u32::MAX {
            return 0.0;
        }
        // A moving emitter's area and normal are where the path's moment places it, as
        // `moving::sample` computed them for the same point.
        let (area, normal) = match self.lights[index as usize] {
            Light::Moving { object, triangle } => {
                let (v, normal) = object_triangle(moment, (object, triangle));
                placed_shape(moment.placement(object as usize), v, normal)
            }
            _ => {
                let shape = &self.shapes[index as usize];
                (shape.area, shape.normal)
            }
        };
        let to_light = hit_point - p;
        let distance_squared = to_light.length_squared();
        let cos_light = (to_light.normalize_or_zero().dot(normal)).abs();
        if cos_light == 0.0 || area == 0.0 {
            return 0.0;
        }
        self.choice_pdf(index as usize) * distance_squared / (cos_light * area)
    }
}

/// The light sample of point `at` on an area emitter of `area` whose emitting side faces
/// `normal`, seen from `p`, chosen with probability `choice`: the one conversion of an area
/// density into a solid-angle one, for still and moving triangles alike. `None` where the point
/// shows its back (which does not emit) or the emitter has no area.
fn area_sample(
    p: Vec3,
    at: SurfacePoint,
    (area, normal): (f32, Vec3),
    radiance: Vec3,
    choice: f32,
) -> Option<LightSample> {
    let to_light = at.p - p;
    let distance_squared = to_light.length_squared();
    if distance_squared == 0.0 || area == 0.0 {
        return None;
    }
    let distance = distance_squared.sqrt();
    let wi = to_light / distance;
    let cos_light = -wi.dot(normal);
    if cos_light <= 0.0 {
        // The sampled point shows us its back, which does not emit.
        return None;
    }
    Some(LightSample {
        wi,
        distance,
        at,
        radiance,
        pdf: choice * distance_squared / (cos_light * area),
        other_pdf: 0.0,
        delta: false,
    })
}

/// The luminance of linear sRGB (Rec. 709 weights): how lights and environment texels are
/// weighed against each other.
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// A direction uniformly distributed on the unit sphere.
// Always inlined: the lanes' shading loop (`integrator/lanes/shade.rs`) calls it for sky-lit
// worlds, and a call left in that loop's body keeps the whole loop from vectorising (a build
// where the compiler's heuristics left it a call ran Sponza's lanes slower than one path at a
// time).
#[inline(always)]
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (sin, cos) = crate::math::sin_cos_turn(u.y);
    Vec3::new(r * cos, r * sin, z)
}

/// The density of a direction [`uniform_sphere`] draws, with the light's choice `choice`:
/// written `choice / 4 pi`, as before maps existed, so that constant environments keep their
/// bits. For the scalar paths and the lanes alike.
#[inline(always)]
pub(crate) fn uniform_density(choice: f32) -> f32 {
    choice / (4.0 * PI)
}
