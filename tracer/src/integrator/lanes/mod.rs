//! A pixel's paths in lanes: up to eight of its samples' paths advanced a bounce at a time,
//! their shading computed together in vector instructions, for the worlds whose every path
//! can be ([`World::lanes_fit`]): plain ones ([`World::is_plain`]) of diffuse surfaces
//! (textured or not, with shading normals or not), lit by still emissive triangles and a
//! constant sky. The Cornell scenes and Sponza are such worlds.
//!
//! Each bounce has three phases. The first, one lane at a time, draws the lane's numbers,
//! walks its ray through the tree, finds the surface's side, shading normal, texel and what
//! it emits (or what the sky sends, where the ray escapes), and picks a light: the walks and
//! the lookups, whose branches and loads are each lane's own. The second computes, for all
//! lanes together, the hit's point and error bound, the shading frame, the sampled
//! direction, the light sample, its weighed value and both rays' origins, in one loop over the lanes whose body
//! has no branch the compiler cannot make a select, so that it vectorises (with AVX where the
//! processor has it, chosen at run time). The third, one lane at a time again, traces the
//! shadow rays and ends or continues each path.
//!
//! **Exactness.** Every lane computes what the scalar path ([`World::radiance_from`])
//! computes for its sample, operation for operation and in the same order: the second phase
//! calls the scalar path's own functions where they are written without branches it cannot
//! make selects (`Frame`, the cosine-weighted direction, whose sine and cosine are `libm`'s
//! kernels without a branch, `math::sin_cos_quarter`; the points with their error bounds; the
//! power heuristic), and writes out lane by lane the decisions that return `Option`s there
//! (`Bsdf::sample`'s test of `wo`, `area_sample`, the light sample's value) and the rays'
//! offsets, whose one-float steps it takes with selects on the bits (`shade.rs` says why
//! the scalar path keeps its branches); vector instructions round each
//! lane as the scalar ones do (no fused multiply-add, no reassociation: Rust never contracts
//! or reorders float arithmetic). A pixel's samples are added in sample order, so an image is
//! the same bits either way, and so are the counted work and the statistics.
//! `tracer/tests/path_lanes.rs` holds the two to each other image by image.
//!
//! Why this pays where a lockstep loop of scalar kernels did not (docs/bench.md, issue 12,
//! twenty-ninth and thirty-first rounds): the shading's divisions, square roots and
//! polynomials are latency chains the scalar path waits on; eight lanes run eight of them in
//! the time of one.

use super::AreaLightSampling;
use super::scatter::{BounceNumbers, resolve};
use super::{PathStats, UNLIMITED_DEPTH, World};
use crate::environment::Environment;
use crate::geometry::{Hit, Moment, OffsetMethod, PACKET, Ray, hit_point};
use crate::material::Bsdf;
use crate::sampler::PixelSampler;
use crate::spectrum::SpectralSampling;
use glam::Vec3;

/// The lanes: a pixel's samples, as many as a camera packet holds.
const LANES: usize = PACKET;

mod shade;

use shade::{Gathered, Shaded, shade};

/// How a pixel's paths are advanced (a comparison knob: both give the same bits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PathLanes {
    /// Up to eight paths a bounce at a time, their shading in vector instructions, where the
    /// world allows it ([`World::lanes_fit`]); one by one elsewhere.
    #[default]
    Lanes,
    /// One path after another, each bounce by bounce.
    OneByOne,
}

impl PathLanes {
    /// Both ways, the default first.
    pub const ALL: [PathLanes; 2] = [PathLanes::Lanes, PathLanes::OneByOne];

    /// The name in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PathLanes::Lanes => "lanes",
            PathLanes::OneByOne => "one-by-one",
        }
    }
}

impl World {
    /// Whether every path of this world can run in lanes: a plain world (no media, no
    /// moving objects, RGB throughout) whose materials are all diffuse, every light a still emissive
    /// triangle or a constant environment without portals (`Lights::lanes_sample_all`), lights found both ways and weighed (the default), the
    /// default offsets and RGB sampling, shadow rays on, and Russian roulette on. Each
    /// condition names a step the lanes leave out; a world that fails one renders one path
    /// at a time, as every world can.
    pub fn lanes_fit(&self) -> bool {
        self.paths == PathLanes::Lanes
            && self.is_plain()
            && self.scene.settings.russian_roulette_depth.is_some()
            && self.lights.lanes_sample_all(&self.scene)
            && self.area_lights == AreaLightSampling::Mis
            && self.offset == OffsetMethod::ErrorBound
            && self.spectral == SpectralSampling::Auto
            && self.effects.shadows
            && self
                .scene
                .materials
                .iter()
                .all(|m| matches!(m.bsdf, Bsdf::Diffuse { .. }))
    }

    /// The radiance of `rays.len()` (one to eight) paths of a pixel, from their camera rays,
    /// as [`World::radiance_from`] finds each one's; `first` holds their closest hits where
    /// the camera packet found them. Only for worlds that [`World::lanes_fit`].
    pub fn radiance_lanes(
        &self,
        rays: &[Ray],
        first: Option<&[Option<Hit>]>,
        samplers: &mut [PixelSampler],
        stats: &mut PathStats,
    ) -> [Vec3; LANES] {
        assert!(
            !rays.is_empty() && rays.len() <= LANES && samplers.len() >= rays.len(),
            "one to eight paths, each with its sampler"
        );
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: the processor has AVX, just checked.
            return unsafe { self.lanes_avx(rays, first, samplers, stats) };
        }
        self.lanes_with(rays, first, samplers, stats)
    }

    /// [`World::lanes_with`] compiled with AVX: the second phase's loops eight lanes wide.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn lanes_avx(
        &self,
        rays: &[Ray],
        first: Option<&[Option<Hit>]>,
        samplers: &mut [PixelSampler],
        stats: &mut PathStats,
    ) -> [Vec3; LANES] {
        self.lanes_with(rays, first, samplers, stats)
    }

    /// The paths' loop, a bounce of every live lane at a time.
    #[inline(always)]
    fn lanes_with(
        &self,
        rays: &[Ray],
        mut first: Option<&[Option<Hit>]>,
        samplers: &mut [PixelSampler],
        stats: &mut PathStats,
    ) -> [Vec3; LANES] {
        let moment = Moment::default();
        let settings = &self.scene.settings;
        let max_depth = settings.max_depth.unwrap_or(UNLIMITED_DEPTH);
        let mut ray = [rays[0]; LANES];
        ray[..rays.len()].copy_from_slice(rays);
        let mut alive = [false; LANES];
        alive[..rays.len()].fill(true);
        let mut beta = [Vec3::ONE; LANES];
        let mut radiance = [Vec3::ZERO; LANES];
        // The last scattering's density, whether it was a delta, and where it was; the camera
        // counts as a delta, as in the scalar path.
        let mut last: [(f32, bool, Vec3); LANES] =
            std::array::from_fn(|i| (0.0, true, ray[i].origin));
        let mut roulette = [0.0f32; LANES];
        let mut gathered = Gathered::default();
        let mut shaded = Shaded::default();
        // Which lanes found a surface to shade this bounce.
        let mut shading = [false; LANES];
        let mut depth = 0u32;
        // What the constant environment sends every way, where it is a light; where it is
        // not, the shading is compiled without its sampling.
        let sky = match &self.scene.environment {
            Some(Environment::Constant(radiance)) => *radiance,
            _ => Vec3::ZERO,
        };
        let sky_is_light = self.lights.environment_is_light();
        while alive.iter().any(|&a| a) {
            // First phase: numbers, walk, surface, emission, the light's choice.
            for i in 0..LANES {
                shading[i] = false;
                if !alive[i] {
                    continue;
                }
                let sampler = &mut samplers[i];
                sampler.start_bounce(depth);
                let u = BounceNumbers::draw(sampler);
                stats.rays += 1;
                let found = match first {
                    Some(hits) => hits[i],
                    None => self.closest(&ray[i], &moment, &mut stats.traversal),
                };
                let Some(hit) = found else {
                    if let Some((arriving, weight)) =
                        self.environment_seen(ray[i].dir, last[i], stats)
                    {
                        radiance[i] += beta[i] * arriving * weight;
                    }
                    alive[i] = false;
                    continue;
                };
                stats.hits += 1;
                // `World::surface`, but for the point and its error bound, which the second
                // phase computes from the corners gathered below.
                let triangle = &self.scene.triangles[hit.triangle as usize];
                let geometric = self.accel.unit_normal(hit.triangle);
                let attributes = self.scene.attributes.get(hit.triangle as usize);
                let seen = self.shading(ray[i].dir, &hit, attributes, None, geometric);
                let material = &self.scene.materials[triangle.material as usize];
                if self.effects.area_lights && material.emission != Vec3::ZERO && seen.front_facing
                {
                    let at = hit_point(&triangle.p, hit.b1, hit.b2);
                    let weight = self.hit_emitter_weight(&moment, hit.triangle, at, last[i]);
                    radiance[i] += beta[i] * material.emission * weight;
                }
                if depth >= max_depth {
                    alive[i] = false;
                    continue;
                }
                let albedo = match material.bsdf {
                    Bsdf::Diffuse {
                        albedo,
                        texture: None,
                    } => albedo,
                    _ => {
                        let texel = self.texel_ahead(&material.bsdf, seen.uv);
                        let Bsdf::Diffuse { albedo, .. } = resolve(&material.bsdf, texel) else {
                            unreachable!("lanes_fit: every material is diffuse")
                        };
                        albedo
                    }
                };
                stats.light_samples += 1;
                let (light, choice) = self.lights.lanes_choice(u.light_choice);
                roulette[i] = u.roulette;
                shading[i] = true;
                let g = &mut gathered;
                for (corner, p) in g.hit.iter_mut().zip(triangle.p) {
                    corner.set(i, p);
                }
                (g.barycentric[0][i], g.barycentric[1][i]) = (hit.b1, hit.b2);
                g.plane.set(i, self.accel.plane_normal(hit.triangle));
                g.normal.set(i, seen.normal);
                g.dir.set(i, ray[i].dir);
                g.albedo.set(i, albedo);
                (g.scatter[0][i], g.scatter[1][i]) = (u.scatter.x, u.scatter.y);
                (g.light[0][i], g.light[1][i]) = (u.light.x, u.light.y);
                g.choice[i] = choice;
                g.sky[i] = light.is_none();
                match light {
                    Some((triangle, shape)) => {
                        let triangle = &self.scene.triangles[triangle as usize];
                        for (corner, p) in g.corners.iter_mut().zip(triangle.p) {
                            corner.set(i, p);
                        }
                        g.light_area[i] = shape.area;
                        g.light_normal.set(i, shape.normal);
                        g.light_plane.set(i, shape.plane_normal);
                        let emission = self.scene.materials[triangle.material as usize].emission;
                        g.emission.set(i, emission);
                    }
                    None => g.emission.set(i, sky),
                }
            }
            first = None;
            // Second phase: every lane's shading at once.
            if sky_is_light {
                shade::<true>(&gathered, &mut shaded);
            } else {
                shade::<false>(&gathered, &mut shaded);
            }
            // Third phase: shadow rays, then each path's next ray or its end.
            depth += 1;
            for i in 0..LANES {
                if !shading[i] {
                    continue;
                }
                if shaded.lit[i] {
                    stats.shadow_rays += 1;
                    let shadow = Ray {
                        origin: shaded.origin.get(i),
                        dir: shaded.reach.get(i),
                        t_max: if gathered.sky[i] { f32::INFINITY } else { 1.0 },
                    };
                    if !self.occluded(&shadow, &moment, &mut stats.traversal) {
                        radiance[i] += beta[i] * shaded.value.get(i);
                    }
                }
                if !shaded.sampled[i] {
                    alive[i] = false;
                    continue;
                }
                beta[i] *= shaded.weight.get(i);
                if beta[i] == Vec3::ZERO || !beta[i].is_finite() {
                    alive[i] = false;
                    continue;
                }
                last[i] = (shaded.pdf[i], false, shaded.p.get(i));
                if !self.roulette(false, depth, roulette[i], Vec3::ONE, &mut beta[i]) {
                    alive[i] = false;
                    continue;
                }
                ray[i] = Ray {
                    origin: shaded.next_origin.get(i),
                    dir: shaded.next_dir.get(i),
                    t_max: f32::INFINITY,
                };
            }
        }
        radiance
    }
}
