//! The path tracer: next-event estimation with multiple importance sampling (power heuristic) for
//! area lights and the environment (constant or an importance-sampled map), point lights by next-event estimation alone, and Russian
//! roulette.
//!
//! Depth follows pbrt: `max_depth` counts scattering events, so 0 shows emitters only, 1 adds
//! direct lighting, and a path has at most `max_depth + 1` segments. Every bounce draws its random
//! numbers from a fixed block of dimensions ([`crate::sampler::DIMENSIONS_PER_BOUNCE`]), all of
//! them drawn whether used or not, so skipping an absent effect never shifts a later number.
//!
//! Specialisation: every branch guarded by a flag of [`Effects`] is one whose work would add
//! exactly zero when the scene lacks the effect (see [`crate::effects`] for the argument, flag by
//! flag); the per-sample counters in [`PathStats`] let tests check that the skipped work is
//! really skipped, and bit-identity with [`Effects::ALL`] that it really was zero.

use crate::effects::Effects;
use crate::geometry::{
    Accel, Hit, OffsetMethod, Ray, SurfacePoint, Traversal, TraversalStats, on_huge_pages,
    spawn_ray, spawn_ray_to,
};
use crate::lights::{EnvironmentSampling, Lights};
use crate::material::{Bsdf, Frame};
use crate::sampler::PixelSampler;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// A scene prepared for rendering: its acceleration structure, lights and effect set.
pub struct World {
    pub scene: Scene,
    pub accel: Accel,
    pub lights: Lights,
    pub effects: Effects,
    /// How rays meet the BVH: our robust traversal (the default), or obvhs's own for comparison.
    pub traversal: Traversal,
    /// Where secondary rays start: off the error bound of each hit point (the default), or the
    /// fixed-ULP offset for comparison.
    pub offset: OffsetMethod,
}

/// Per-sample counters: the counted work that becomes a tile's cost, and the effect counters the
/// tests read to check that absent effects cost nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PathStats {
    pub traversal: TraversalStats,
    /// Closest-hit rays (camera and bounce rays).
    pub rays: u64,
    /// Of those, the ones that hit a surface (and were shaded); the rest escaped.
    pub hits: u64,
    pub shadow_rays: u64,
    /// Lights sampled by next-event estimation (each may or may not need a shadow ray).
    pub light_samples: u64,
    /// BSDF samples that crossed a surface (refraction through glass).
    pub refractions: u64,
    /// Escaped rays that looked up the environment.
    pub environment_lookups: u64,
    /// Samples whose radiance came out non-finite and were dropped (a bug if ever non-zero).
    pub invalid_samples: u64,
}

impl PathStats {
    pub fn add(&mut self, other: &PathStats) {
        self.traversal.nodes += other.traversal.nodes;
        self.traversal.triangles += other.traversal.triangles;
        self.rays += other.rays;
        self.hits += other.hits;
        self.shadow_rays += other.shadow_rays;
        self.light_samples += other.light_samples;
        self.refractions += other.refractions;
        self.environment_lookups += other.environment_lookups;
        self.invalid_samples += other.invalid_samples;
    }

    /// The deterministic cost of the work counted here, in abstract units of about one BVH node
    /// visit: one per node visited and per triangle tested, 12 per ray that is shaded (a
    /// closest-hit ray that hits a surface: BSDF sampling and light choice) and per shadow ray
    /// (light sampling and the any-hit query's set-up), 4 per ray that escapes. The weights come
    /// from timing every 16x16 tile of the shipped and shared scenes alone
    /// (`cargo run --release -p sim --example fit_work`): a single charge of 16 for every ray
    /// priced escaping rays like shaded ones, and the 95th-percentile tile of scenes with much
    /// sky or background came out more than twice as slow as predicted; with these weights it is
    /// within about +30% in every scene.
    pub fn work(&self) -> u64 {
        const SHADED: u64 = 12;
        const ESCAPED: u64 = 4;
        let escaped = self.rays - self.hits;
        self.traversal.nodes
            + self.traversal.triangles
            + SHADED * (self.hits + self.shadow_rays)
            + ESCAPED * escaped
    }
}

impl World {
    pub fn new(mut scene: Scene, accel: Accel, effects: Effects) -> Self {
        // Every hit reads its triangle, at random on large meshes: huge pages spare most of
        // those reads a page-table walk (`geometry/memory.rs`).
        scene.triangles = on_huge_pages(scene.triangles);
        let lights = Lights::new(&scene, &effects);
        Self {
            scene,
            accel,
            lights,
            effects,
            traversal: Traversal::Robust,
            offset: OffsetMethod::default(),
        }
    }

    /// A world ready to render: the scene's BVH built (default quality) and its lights set
    /// up; `effects` forces an effect set, `None` derives it from the scene.
    pub fn prepare(scene: Scene, effects: Option<Effects>) -> Self {
        let effects = effects.unwrap_or_else(|| Effects::of(&scene));
        let accel = Accel::build(&scene.triangles, crate::geometry::BuildQuality::default());
        Self::new(scene, accel, effects)
    }

    /// This world with its environment sampled as `sampling` says (a comparison knob: every
    /// choice has the same mean, see [`EnvironmentSampling`]).
    pub fn with_environment_sampling(mut self, sampling: EnvironmentSampling) -> Self {
        self.lights = Lights::with_sampling(&self.scene, &self.effects, sampling);
        self
    }

    /// The radiance arriving along `ray` for one sample.
    pub fn radiance(&self, ray: Ray, sampler: &mut PixelSampler, stats: &mut PathStats) -> Vec3 {
        let settings = &self.scene.settings;
        let effects = &self.effects;
        let mut ray = ray;
        let mut radiance = Vec3::ZERO;
        let mut beta = Vec3::ONE;
        // The density of the direction the last bounce sampled, and whether it was a delta lobe;
        // the camera ray counts as specular (nothing else could have found what it hits).
        let mut last_pdf = 0.0f32;
        let mut last_delta = true;
        let mut last_point = ray.origin;
        let mut depth = 0u32;
        loop {
            sampler.start_bounce(depth);
            stats.rays += 1;
            let Some(hit) = self
                .accel
                .intersect_with(&ray, self.traversal, &mut stats.traversal)
            else {
                if effects.environment
                    && let Some(environment) = &self.scene.environment
                {
                    stats.environment_lookups += 1;
                    let weight = if last_delta {
                        1.0
                    } else {
                        let light_pdf = self.lights.environment_pdf(&self.scene, ray.dir);
                        power_heuristic(last_pdf, light_pdf)
                    };
                    radiance += beta * environment.radiance(ray.dir) * weight;
                }
                break;
            };
            stats.hits += 1;
            let surface = self.surface(&ray, &hit);
            let material = &self.scene.materials[surface.material as usize];

            if effects.area_lights && material.emission != Vec3::ZERO && surface.front_facing {
                let weight = if last_delta {
                    1.0
                } else {
                    let light_pdf =
                        self.lights
                            .triangle_pdf(hit.triangle, last_point, surface.at.p);
                    power_heuristic(last_pdf, light_pdf)
                };
                radiance += beta * material.emission * weight;
            }
            if settings.max_depth.is_some_and(|max| depth >= max) {
                break;
            }

            let bsdf = self.resolve(&material.bsdf, &surface);
            let frame = Frame::from_normal(surface.shading_normal);
            let wo = frame.to_local(-ray.dir);
            // The bounce's random numbers, all drawn, in a fixed order.
            let u_light_choice = sampler.next_1d();
            let u_light = sampler.next_2d();
            let u_bsdf_choice = sampler.next_1d();
            let u_bsdf = sampler.next_2d();
            let u_roulette = sampler.next_1d();

            if effects.shadows && !bsdf.is_delta() {
                radiance += beta
                    * self.direct_light(
                        &bsdf,
                        &frame,
                        wo,
                        &surface,
                        u_light_choice,
                        u_light,
                        stats,
                    );
            }

            let Some(sample) = bsdf.sample(wo, u_bsdf_choice, u_bsdf) else {
                break;
            };
            if sample.transmission {
                stats.refractions += 1;
            }
            let wi = frame.to_world(sample.wi);
            beta *= sample.weight;
            if beta == Vec3::ZERO || !beta.is_finite() {
                break;
            }
            last_pdf = sample.pdf;
            last_delta = sample.delta;
            last_point = surface.at.p;
            depth += 1;

            if let Some(start) = settings.russian_roulette_depth
                && depth >= start
            {
                let survive = beta.max_element().min(0.95);
                if u_roulette >= survive {
                    break;
                }
                beta /= survive;
            }
            ray = spawn_ray(&surface.at, wi, self.offset);
        }
        radiance
    }

    /// One light sample, weighted by multiple importance sampling against the BSDF.
    #[allow(clippy::too_many_arguments)]
    fn direct_light(
        &self,
        bsdf: &Bsdf,
        frame: &Frame,
        wo: Vec3,
        surface: &Surface,
        u_choice: f32,
        u: Vec2,
        stats: &mut PathStats,
    ) -> Vec3 {
        stats.light_samples += 1;
        let Some(light) = self.lights.sample(&self.scene, surface.at.p, u_choice, u) else {
            return Vec3::ZERO;
        };
        let wi_local = frame.to_local(light.wi);
        let f = bsdf.eval(wo, wi_local);
        if f == Vec3::ZERO || light.radiance == Vec3::ZERO || light.pdf <= 0.0 {
            return Vec3::ZERO;
        }
        stats.shadow_rays += 1;
        let shadow = if light.distance.is_finite() {
            spawn_ray_to(&surface.at, &light.at, self.offset)
        } else {
            spawn_ray(&surface.at, light.wi, self.offset)
        };
        if self
            .accel
            .occluded_with(&shadow, self.traversal, &mut stats.traversal)
        {
            return Vec3::ZERO;
        }
        let weight = if light.delta {
            1.0
        } else {
            power_heuristic(light.pdf, bsdf.pdf(wo, wi_local))
        };
        f * light.radiance * (weight / light.pdf)
    }

    fn resolve(&self, bsdf: &Bsdf, surface: &Surface) -> Bsdf {
        match *bsdf {
            Bsdf::Diffuse {
                texture: Some(texture),
                ..
            } if self.effects.textures => {
                let texel = surface.uv.map_or(Vec3::ONE, |uv| {
                    self.scene.textures[texture as usize].lookup(uv)
                });
                bsdf.with_texture_value(texel)
            }
            other => other,
        }
    }

    /// The local geometry at a hit.
    fn surface(&self, ray: &Ray, hit: &Hit) -> Surface {
        let triangle = &self.scene.triangles[hit.triangle as usize];
        let at = SurfacePoint::on_triangle_with_normal(
            &triangle.p,
            hit.b1,
            hit.b2,
            self.accel.plane_normal(hit.triangle),
        );
        // Normals keep the winding's orientation: the side a ray arrives from is what tells a
        // dielectric whether it is entering or leaving, and an emitter whether it is seen from
        // the front. Reflection-only BSDFs are two-sided by themselves.
        let geometric = self.accel.unit_normal(hit.triangle);
        let front_facing = ray.dir.dot(geometric) < 0.0;
        let b0 = 1.0 - hit.b1 - hit.b2;
        let shading_normal = match triangle.n {
            Some(n) if self.effects.shading_normals => {
                let interpolated = (b0 * n[0] + hit.b1 * n[1] + hit.b2 * n[2]).normalize_or_zero();
                if interpolated == Vec3::ZERO {
                    geometric
                } else if interpolated.dot(geometric) < 0.0 {
                    -interpolated
                } else {
                    interpolated
                }
            }
            _ => geometric,
        };
        // Texture coordinates are only ever read by a texture lookup.
        let uv = triangle
            .uv
            .filter(|_| self.effects.textures)
            .map(|uv| b0 * uv[0] + hit.b1 * uv[1] + hit.b2 * uv[2]);
        Surface {
            at,
            shading_normal,
            uv,
            material: triangle.material,
            front_facing,
        }
    }
}

/// The geometry of a hit; both normals on the winding's side.
struct Surface {
    /// The hit point, with what spawning rays from it needs: its error bound and plane normal.
    at: SurfacePoint,
    shading_normal: Vec3,
    uv: Option<Vec2>,
    material: u32,
    front_facing: bool,
}

fn power_heuristic(f: f32, g: f32) -> f32 {
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
