//! The path tracer: next-event estimation with multiple importance sampling (power heuristic) for
//! area lights and the environment (constant or an importance-sampled map), point lights by next-event estimation alone, and Russian
//! roulette.
//!
//! Depth follows pbrt: `max_depth` counts scattering events, so 0 shows emitters only, 1 adds
//! direct lighting, and a path has at most `max_depth + 1` segments. Every bounce draws its random
//! numbers from a fixed block of dimensions ([`crate::sampler::DIMENSIONS_PER_BOUNCE`]), all of
//! them drawn whether used or not, so skipping an absent effect never shifts a later number.
//!
//! Participating media (`scatter.rs`, [`crate::medium`]): where the scene has them, every ray
//! first samples a free flight through the medium it is in; a scattering there is a bounce like
//! a surface's (next-event estimation through the phase function, then a phase-sampled
//! direction, from the same block of random numbers), and a path crosses index-matched
//! interfaces without counting a bounce. Contributions are divided by the mean of the path's
//! spectral density ratios (the balance heuristic over hero channels).
//!
//! Module map: `direct` (next-event estimation, and how it and BSDF sampling share the area
//! lights: [`AreaLightSampling`]); `scatter` (a BSDF or a phase function as next-event
//! estimation sees it, the bounce's random numbers, which medium a path is in, shadow-ray
//! transmittance, and the texel a textured BSDF reads); `hits` (where rays meet the static
//! and the moving geometry at the path's time, a pixel's camera rays walked together, and the
//! local geometry at a hit); `stats` (the per-sample counters, [`PathStats`]).
//!
//! Dispersion ([`crate::spectrum`]): a path is RGB until it meets dispersive glass, where it
//! turns spectral; from then on every RGB value it meets goes through its [`PathSpectrum`],
//! which is the identity, with no arithmetic, on an RGB path.
//!
//! Motion: a path has one time (`radiance`'s `time`, drawn per sample where the scene has
//! motion blur), and every ray of it meets the moving objects where they are then; light
//! sampling, and the density a BSDF-sampled hit on a moving emitter is weighed with, place
//! moving emitters at that time too (`lights/moving.rs`).
//!
//! Specialisation: every branch guarded by a flag of [`Effects`] is one whose work would add
//! exactly zero when the scene lacks the effect (see [`crate::effects`] for the argument, flag by
//! flag); the per-sample counters in [`PathStats`] let tests check that the skipped work is
//! really skipped, and bit-identity with [`Effects::ALL`] that it really was zero. The path
//! loop is compiled twice: once for plain worlds (no media, no moving objects, RGB
//! throughout: `World::is_plain`), where those effects' flags are constants and their steps
//! are not compiled in, and once for the rest, where the flags are read at run time.

/// The scattering events a path may have at most when `max_depth` is unlimited: Russian
/// roulette ends paths long before (its survival is below one), but without it a path in a
/// closed scene of white walls would never end (`russian_roulette_depth = "off"` with
/// `max_depth = "unlimited"` hung). Past 65536 events a path's weight in any lossy scene is
/// below every float, and in a lossless one the cap is what makes the render finish.
pub const UNLIMITED_DEPTH: u32 = 1 << 16;

use crate::effects::Effects;
use crate::geometry::{
    Accel, Hit, Moment, MotionAccel, OffsetMethod, Ray, SurfacePoint, Traversal, on_huge_pages,
    spawn_ray,
};
use crate::lights::{EnvironmentSampling, Lights};
use crate::material::{Bsdf, Frame};
use crate::medium::{Flight, hero_channel, mean_ratio, sample_henyey_greenstein};
use crate::sampler::PixelSampler;
use crate::scene::Scene;
use crate::spectrum::{PathSpectrum, SpectralSampling};
use direct::LightSamples;
use glam::Vec3;
use scatter::{BounceNumbers, Phase, SurfaceScatter, resolve};
use std::mem::ManuallyDrop;

mod direct;
mod hits;
mod lanes;
mod scatter;
mod stats;

pub use direct::AreaLightSampling;
pub use hits::CameraRays;
pub use lanes::PathLanes;
pub(crate) use lanes::{NOT_COUNTED, NewPath, PathFeed};
pub use stats::PathStats;

/// A scene prepared for rendering: its acceleration structure, lights and effect set.
pub struct World {
    /// The scene as loaded, its still triangles and textures moved onto huge pages.
    pub scene: Scene,
    /// The still geometry's tree (the moving objects have theirs in `motion`), made ready for
    /// this world ([`World::set_accel`]); read through [`World::accel`].
    accel: Accel,
    /// The moving objects' trees, built from [`Scene::moving`]; empty when nothing moves.
    pub motion: MotionAccel,
    /// Every light with its choice distribution, for next-event estimation.
    pub lights: Lights,
    /// The effects this world pays for: the scene's own, or more where a caller forces them.
    pub effects: Effects,
    /// Whether some material is an index-matched interface, the one surface shadow rays pass
    /// (`scatter.rs`); taken from the scene's materials when the world is made.
    pub interfaces: bool,
    /// How rays meet the BVH: ours (the default) or a comparison one ([`World::set_traversal`]).
    traversal: Traversal,
    /// Where secondary rays start: off the error bound of each hit point (the default), or the
    /// fixed-ULP offset for comparison.
    pub offset: OffsetMethod,
    /// Which wavelengths paths sample: RGB until dispersive glass (the default), or spectral
    /// from the camera on (comparison knobs, [`SpectralSampling`]).
    pub spectral: SpectralSampling,
    /// Which strategies find area lights: both, weighted (the default), or one alone
    /// (comparison knobs, [`AreaLightSampling`]).
    pub area_lights: AreaLightSampling,
    /// How a pixel's camera rays meet the BVH: walked together, up to eight samples at a time
    /// (the default), or one by one (for comparison); the same hits either way.
    pub camera_rays: CameraRays,
    /// How a tile's paths are advanced: eight at a time in lanes where the world allows
    /// it (the default, [`World::lanes_fit`]), or one by one (for comparison); the same bits
    /// either way.
    pub paths: PathLanes,
}

impl World {
    /// Prepares `scene` for rendering with the still geometry's tree `accel`: builds the moving
    /// objects' trees and the lights, moves the arrays every hit reads onto huge pages, and
    /// frees the binary tree, which only a comparison traversal walks ([`World::set_traversal`]).
    pub fn new(mut scene: Scene, mut accel: Accel, effects: Effects) -> Self {
        // Every hit reads its triangle, at random on large meshes: huge pages spare most of
        // those reads a page-table walk (`geometry/memory.rs`), and the traversal asks for it
        // as soon as it keeps a hit on it, so that the miss overlaps the rest of the query.
        scene.triangles = on_huge_pages(scene.triangles);
        scene.attributes = on_huge_pages(scene.attributes);
        hits::make_ready(&mut accel, &scene, Traversal::default());
        // So does every hit on a textured surface read a texel (`scene/texture.rs`).
        for texture in &mut scene.textures {
            texture.on_huge_pages();
        }
        let lights = Lights::new(&scene, &effects);
        let interfaces = scene.materials.iter().any(|m| m.bsdf == Bsdf::Interface);
        let first = u32::try_from(scene.triangles.len())
            .expect("fewer than 2^32 triangles: Hit::triangle is a u32");
        let motion = MotionAccel::build(
            &scene.moving,
            first,
            crate::geometry::BuildQuality::default(),
        );
        crate::geometry::release_freed_memory();
        Self {
            scene,
            accel,
            motion,
            lights,
            interfaces,
            effects,
            traversal: Traversal::Robust,
            offset: OffsetMethod::default(),
            spectral: SpectralSampling::default(),
            area_lights: AreaLightSampling::default(),
            camera_rays: CameraRays::default(),
            paths: PathLanes::default(),
        }
    }

    /// A world ready to render: the scene's BVH built (default quality) and its lights set
    /// up; `effects` forces an effect set, `None` derives it from the scene.
    pub fn prepare(scene: Scene, effects: Option<Effects>) -> Self {
        let effects = effects.unwrap_or_else(|| Effects::of(&scene));
        let accel =
            Accel::build_for_rendering(&scene.triangles, crate::geometry::BuildQuality::default());
        Self::new(scene, accel, effects)
    }

    /// This world with its environment sampled as `sampling` says (a comparison knob: every
    /// choice has the same mean, see [`EnvironmentSampling`]).
    pub fn with_environment_sampling(mut self, sampling: EnvironmentSampling) -> Self {
        self.lights = Lights::with_sampling(&self.scene, &self.effects, sampling);
        self
    }

    /// The radiance arriving along `ray` for one sample taken at `time` (in frames: where the
    /// moving objects are).
    pub fn radiance(
        &self,
        ray: Ray,
        time: f64,
        sampler: &mut PixelSampler,
        stats: &mut PathStats,
    ) -> Vec3 {
        self.radiance_from(&ray, None, time, sampler, stats)
    }

    /// [`World::radiance`], with the closest hit of `ray` in the still tree already found where
    /// `first` is `Some` (by [`World::camera_hits`], which counted its work; moving objects are
    /// asked here).
    ///
    /// The ray is taken by reference: passed by value, the caller copied it into a temporary
    /// just before the call, in two overlapping 16-byte stores, and the path's first read of
    /// its direction spanned both, which the processor cannot forward from the store buffer (a
    /// stall per camera ray; docs/bench.md, issue 12, twenty-sixth round).
    pub fn radiance_from(
        &self,
        ray: &Ray,
        first: Option<Option<Hit>>,
        time: f64,
        sampler: &mut PixelSampler,
        stats: &mut PathStats,
    ) -> Vec3 {
        if self.is_plain() {
            self.radiance_with::<true>(ray, first, time, sampler, stats)
        } else {
            self.radiance_with::<false>(ray, first, time, sampler, stats)
        }
    }

    /// Whether every path of this world is a plain one: no media to track, no moving object
    /// to place, and RGB throughout (the dispersion effect off, so that no glass turns a path
    /// spectral, and RGB sampling asked for). Such paths run [`World::radiance_with`] compiled
    /// for them (`PLAIN`), where the loop's steps for those effects are not there at all
    /// rather than skipped at run time: the loop is then small enough that the compiler keeps
    /// more of its state in registers (1.7 % fewer instructions on the Cornell box). Both
    /// compile the same source, so they compute the same bits; [`Effects::ALL`] is never
    /// plain, so the tests that hold a scene's own effect set to it compare the two loops.
    /// Next-event estimation's own test of the media flag stays a run-time branch.
    fn is_plain(&self) -> bool {
        !self.effects.media
            && !self.effects.dispersion
            && self.motion.is_empty()
            && matches!(self.spectral, SpectralSampling::Auto)
    }

    /// The path loop, compiled twice: for plain worlds ([`World::is_plain`]), where the
    /// absent effects' flags are the constant `false` and their code folds away, and for
    /// the rest, where the flags are read at run time. Where `PLAIN`, the path's colour state
    /// is never changed from [`PathSpectrum::RGB`] (its changes are the spectral start and
    /// dispersion, both absent), so every reading of it folds to the identity too.
    fn radiance_with<const PLAIN: bool>(
        &self,
        ray: &Ray,
        mut first: Option<Option<Hit>>,
        time: f64,
        sampler: &mut PixelSampler,
        stats: &mut PathStats,
    ) -> Vec3 {
        // Held undropped, and dropped below only where it placed moving objects: a still
        // world's moment holds nothing to release, and its drop was a call per path (the drop
        // glue, which the compiler leaves out of line for the moving case's sake).
        let still = PLAIN || self.motion.is_empty();
        let owned_moment = ManuallyDrop::new(if still {
            Moment::default()
        } else {
            self.motion.moment(time)
        });
        let moment: &Moment = &owned_moment;
        let settings = &self.scene.settings;
        let effects = &self.effects;
        // Where `PLAIN`, the flags of the effects it leaves out, as constants.
        let media = !PLAIN && effects.media;
        let dispersion = !PLAIN && effects.dispersion;
        let mut ray = *ray;
        let mut radiance = Vec3::ZERO;
        let (mut spectrum, mut beta) = (PathSpectrum::RGB, Vec3::ONE);
        if !PLAIN {
            spectrum.begin(self.spectral, sampler, &mut beta);
        }
        // The density of the direction the last bounce sampled, and whether it was a delta lobe;
        // the camera ray counts as specular (nothing else could have found what it hits).
        let mut last_pdf = 0.0f32;
        let mut last_delta = true;
        let mut last_point = ray.origin;
        let mut depth = 0u32;
        // The block of random numbers the next ray draws from: one per ray, so it runs ahead of
        // `depth` only where a path crosses an index-matched interface, which scatters nothing.
        // Without interfaces it is `depth`, as before media existed.
        let mut segment = 0u32;
        let mut medium = self.scene.camera_medium;
        // Spectral MIS through media (`crate::medium`): the channel that samples every flight,
        // picked at the path's first, and each channel's path density over the hero's. Without
        // media the ratios stay exactly 1, and dividing by their mean (1) moves no bit.
        let mut hero = None;
        let mut ratio = Vec3::ONE;
        loop {
            sampler.start_bounce(segment);
            // The bounce's numbers, drawn before its ray is traced though used after: they
            // depend on nothing the ray finds, so their hashing overlaps the traversal (1 to
            // 2 % faster renders, though a path that escapes now draws a block it never uses;
            // docs/bench.md, issue 12, eighteenth round). One block serves a surface's bounce
            // and a medium's scattering alike, as before.
            let u = BounceNumbers::draw(sampler);
            segment += 1;
            stats.rays += 1;
            let found = match first.take() {
                Some(still) if PLAIN => still,
                Some(still) => self.with_moving::<false>(&ray, still, moment, &mut stats.traversal),
                None => self.closest(&ray, moment, &mut stats.traversal),
            };
            if media {
                stats.flights += 1;
            }
            // Once the path has its hero channel, a flight through a vacuum is left out: every
            // way of sampling flights passes a vacuum with weights of exactly 1 (`x * 1` is
            // `x`), and its two numbers come from a stream of their own, so not drawing them
            // moves no other. The first flight is always taken, as it picks the hero.
            let flight_medium = media
                .then(|| self.flight_medium(medium, found.is_none()))
                .filter(|m| hero.is_none() || !m.is_vacuum());
            if let Some(flight_medium) = flight_medium {
                let length = ray.dir.length();
                let t_end = found.map_or(f32::INFINITY, |h| h.t * length);
                let flight = sampler.medium();
                let hero = *hero.get_or_insert_with(|| hero_channel(flight.x));
                let in_medium = &spectrum.medium(flight_medium);
                match in_medium.sample_flight_with(&settings.media, t_end, hero, flight) {
                    Flight::Pass {
                        weight,
                        ratio: flight_ratio,
                    } => {
                        beta *= weight;
                        ratio *= flight_ratio;
                    }
                    Flight::Scatter {
                        distance,
                        weight,
                        ratio: flight_ratio,
                    } => {
                        beta *= weight;
                        ratio *= flight_ratio;
                        stats.medium_scatters += 1;
                        // A medium that only absorbs gives a scattering weight of zero: the
                        // path carries nothing further.
                        if beta == Vec3::ZERO
                            || !beta.is_finite()
                            || depth >= settings.max_depth.unwrap_or(UNLIMITED_DEPTH)
                        {
                            break;
                        }
                        let at = SurfacePoint::exact(ray.origin + ray.dir * (distance / length));
                        let phase = Phase {
                            wo: -ray.dir / length,
                            g: in_medium.g,
                        };
                        if effects.has_lights() {
                            radiance += weighed(media, beta, ratio)
                                * self.direct_light(
                                    &phase,
                                    &at,
                                    (medium, &spectrum),
                                    moment,
                                    (u.light_choice, u.light),
                                    stats,
                                );
                        }
                        let (wi, pdf) = sample_henyey_greenstein(phase.wo, phase.g, u.scatter);
                        last_pdf = pdf;
                        last_delta = false;
                        last_point = at.p;
                        depth += 1;
                        if !self.roulette(media, depth, u.roulette, ratio, &mut beta) {
                            break;
                        }
                        ray = spawn_ray(&at, wi, self.offset);
                        continue;
                    }
                }
                if beta == Vec3::ZERO || !beta.is_finite() {
                    break;
                }
            }
            let Some(hit) = found else {
                let last = (last_pdf, last_delta, last_point);
                if let Some((arriving, weight)) = self.environment_seen(ray.dir, last, stats) {
                    radiance += weighed(media, beta, ratio) * spectrum.of(arriving) * weight;
                }
                break;
            };
            stats.hits += 1;
            let surface = self.surface(&ray, &hit, moment);
            let material = &self.scene.materials[surface.material as usize];
            if media && material.bsdf == Bsdf::Interface {
                // Straight on into the medium beyond, as if nothing were there: no scattering
                // event, so neither the depth nor the last scattering's densities change.
                medium = self.medium_across(material, surface.seen.front_facing);
                ray = spawn_ray(&surface.at, ray.dir, self.offset);
                continue;
            }

            if effects.area_lights && material.emission != Vec3::ZERO && surface.seen.front_facing {
                let last = (last_pdf, last_delta, last_point);
                let weight = self.hit_emitter_weight(moment, hit.triangle, surface.at.p, last);
                radiance += weighed(media, beta, ratio) * spectrum.of(material.emission) * weight;
            }
            if depth >= settings.max_depth.unwrap_or(UNLIMITED_DEPTH) {
                break;
            }

            if dispersion && material.bsdf.is_dispersive() {
                spectrum.disperse(sampler, &mut beta, &mut radiance);
            }
            // A textured surface's texel is, on scenes whose textures outgrow a core's caches,
            // a long wait on memory. Ask for it now, and read it only after what does not need
            // it: the frame, the bounce's numbers, and where the light samples land.
            let texel = self.texel_ahead(&material.bsdf, surface.seen.uv);
            let frame = Frame::from_normal(surface.seen.normal);
            let wo = frame.to_local(-ray.dir);
            let shadows = effects.shadows && !material.bsdf.is_delta();
            let mut lights = LightSamples::default();
            if shadows {
                let numbers = (u.light_choice, u.light);
                self.sample_lights(&surface.at, moment, numbers, stats, &mut lights);
            }
            let mut bsdf = resolve(&material.bsdf, texel);
            spectrum.see_bsdf(&mut bsdf);
            // The next direction is drawn before the shadow ray is traced, though used after:
            // it needs neither, and its chain of square roots and sines then overlaps the
            // light sample's instead of waiting for the traversal between them (the box 5 %
            // faster; spawning the next ray here as well made it 11 % slower: docs/bench.md,
            // issue 12, eighteenth round). The numbers were drawn already: no bit moves.
            let scattered = bsdf.sample(wo, u.choice, u.scatter);

            if shadows {
                let scatter = SurfaceScatter {
                    bsdf: &bsdf,
                    frame: &frame,
                    wo,
                };
                radiance += weighed(media, beta, ratio)
                    * self.direct_from(
                        &lights,
                        &scatter,
                        &surface.at,
                        (medium, &spectrum),
                        moment,
                        (u.light_choice, u.light),
                        stats,
                    );
            }

            let Some(sample) = scattered else {
                break;
            };
            if sample.transmission {
                stats.refractions += 1;
                if media {
                    medium = self.medium_across(material, surface.seen.front_facing);
                }
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
            if !self.roulette(media, depth, u.roulette, ratio, &mut beta) {
                break;
            }
            ray = spawn_ray(&surface.at, wi, self.offset);
        }
        if spectrum.is_spectral() {
            stats.spectral_paths += 1;
        }
        if !still {
            // Hands the placements' buffer back to the thread (`Moment`'s `Drop`).
            drop(ManuallyDrop::into_inner(owned_moment));
        }
        spectrum.finish(radiance)
    }

    /// Russian roulette at `depth`: whether the path survives `u`, with `beta` raised to make
    /// up for the paths ended. Paths survive unconditionally before the settings' start depth.
    /// The survival probability follows what the path would contribute ([`weighed`], with
    /// `media` whether the path's media are tracked).
    fn roulette(&self, media: bool, depth: u32, u: f32, ratio: Vec3, beta: &mut Vec3) -> bool {
        if self.roulette_plays(depth) {
            let survive = survival(weighed(media, *beta, ratio));
            if u >= survive {
                return false;
            }
            *beta /= survive;
        }
        true
    }

    /// Whether Russian roulette is played at `depth` ([`World::roulette`]'s count): from the
    /// settings' start depth on, where they have one.
    #[inline(always)]
    fn roulette_plays(&self, depth: u32) -> bool {
        self.scene
            .settings
            .russian_roulette_depth
            .is_some_and(|start| depth >= start)
    }
}

/// The probability that Russian roulette lets a path of (weighed) throughput `beta` go on:
/// its largest channel, at most 0.95. The scalar path's game and the lanes', which plays it
/// for every lane at once (`lanes/shade.rs`), both take it from here.
#[inline(always)]
fn survival(beta: Vec3) -> f32 {
    beta.max_element().min(0.95)
}

/// What a path of throughput `beta` and spectral ratios `ratio` contributes per unit of what it
/// finds: `beta` over the mean ratio where media are tracked (`media`: the balance heuristic
/// over hero channels, `crate::medium`), `beta` itself elsewhere, with no arithmetic, so that
/// paths without media compute what they computed before media. A parameter rather than the
/// world's flag, so that the plain path loop ([`World::is_plain`]) passes its constant.
fn weighed(media: bool, beta: Vec3, ratio: Vec3) -> Vec3 {
    if media {
        beta / mean_ratio(ratio)
    } else {
        beta
    }
}
