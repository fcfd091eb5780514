//! A tile's paths in lanes: eight paths advanced a bounce at a time, their shading computed
//! together in vector instructions, for the worlds whose every path can be ([`World::lanes_fit`]):
//! worlds without media or dispersion, of diffuse surfaces (textured or not, with shading normals
//! or not), ideal mirrors, smooth glass and rough metals, still or moving, lit by emissive
//! triangles (still or moving), point lights and a constant sky or an environment map, seen through
//! portals or not. The Cornell scenes, Sponza, the README's scene and the shipped scenes of motion
//! blur are such worlds. Where objects move, each lane holds its path's moment (its objects placed
//! as the path starts), its walks ask the moving objects at it, and the first phase places the
//! points of hits on moving triangles and of moving lights' samples, as the scalar path does, for
//! the vector shading to take as they are (compiled apart, so that still worlds pay for none of
//! it). Where the scene has portals, both of the environment's samples, its own and the one
//! through a portal, are drawn after the first phase, every lane's draw through the portals at
//! once in vector instructions (`environment::PortalDraws`), and the vector shading weighs
//! both over the three strategies, each with its shadow ray.
//!
//! The paths come from a feed ([`PathFeed`]; the tile's, `tile/lanes.rs`, hands out its
//! pixels' samples in order, a camera packet at a time) and go back to it as they end, in any
//! order. A lane whose path ends takes the next path at once, so the lanes stay full: with a
//! pixel's eight samples alone in the lanes until the last one ended, two lanes in five did
//! the shading's work for nothing (docs/bench.md, issue 12, thirty-second round).
//!
//! Each bounce has three phases. The first, one lane at a time, in two passes: every lane's walk
//! through the tree (or, where its ray escapes, what the sky sends, and the lane's next path), then
//! every lane's surface: its numbers, side, shading normal and what it emits, and the light it
//! picks, and on a mirror, glass or a metal the direction `Bsdf::sample` draws (a mirror's or
//! glass's a delta, which samples no light); the texels of textured surfaces are asked for from
//! memory there and read once every lane has had its surface. These are the walks and the lookups,
//! whose branches and loads are each lane's own; in two passes and with the texels read last, the
//! misses of different lanes overlap. The second computes, for all lanes together, the hit's point
//! and error bound, the shading frame, the sampled direction, the throughput it leaves and Russian
//! roulette's verdict, the light sample, its weighed value and both rays' origins, in one loop over
//! the lanes whose body has no branch the compiler cannot make a select, so that it vectorises
//! (with AVX where the processor has it, chosen at run time), and then, as vectors again, the
//! walks' set-ups of every lane's shadow ray and next ray (`SetUpRows`: each lane exactly the
//! set-up the walk would make of its ray, so a walk starts without its divisions). The third, one
//! lane at a time again, traces the shadow rays and ends or continues each path.
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
//! or reorders float arithmetic). Each path's result depends only on its own numbers, never on
//! its lane or its neighbours, and the feed adds a pixel's samples in sample order, so an
//! image is the same bits either way, and so are the counted work and the statistics, each
//! lane's counted over its run of one block's paths and added to that block (integer sums).
//! `tracer/tests/path_lanes.rs` holds the two to each other image by image.
//!
//! Why this pays where a lockstep loop of scalar kernels did not (docs/bench.md, issue 12,
//! twenty-ninth and thirty-first rounds): the shading's divisions, square roots and
//! polynomials are latency chains the scalar path waits on; eight lanes run eight of them in
//! the time of one.

use super::scatter::{BounceNumbers, resolve};
use super::{AreaLightSampling, UNLIMITED_DEPTH, World};
use crate::environment::Environment;
use crate::geometry::{Moment, OffsetMethod, PACKET, Ray, SetUpRows, SurfacePoint, hit_point};
use crate::lights::{LanesLight, placed_sample, uniform_density, uniform_sphere};
use crate::material::{Bsdf, BsdfSample, Frame, Ggx};
use crate::scene::Texture;
use crate::spectrum::SpectralSampling;
use glam::{Vec2, Vec3};

/// The lanes: as many paths as a camera packet holds rays, eight f32 lanes of AVX.
const LANES: usize = PACKET;

/// What a lane whose direction the first phase draws holds where `Bsdf::sample` drew nothing
/// (the path ends there).
const NO_SAMPLE: BsdfSample = BsdfSample {
    wi: Vec3::Z,
    weight: Vec3::ZERO,
    pdf: 0.0,
    delta: true,
    transmission: false,
};

mod paths;
mod shade;

pub use paths::PathLanes;
use paths::Paths;
pub(crate) use paths::{NOT_COUNTED, NewPath, PathFeed};

use shade::{Gathered, Points, Shaded, shade};

impl World {
    /// Whether every path of this world can run in lanes: a world without media or dispersion
    /// (RGB throughout; its objects still or moving) whose materials are all diffuse, ideal
    /// mirrors, smooth glass (a delta bounce: no light sample, the direction drawn by
    /// `Bsdf::sample`) or rough metals (the direction drawn by `Bsdf::sample`, the light sample
    /// weighed by the lobe), every light an emissive triangle (still or moving), a point light
    /// or an environment, constant or a map sampled by its importance, with portals or not
    /// (`Lights::lanes_sample_all`), lights found both ways and weighed (the default), the
    /// default offsets and RGB sampling, and shadow rays on. Each condition names a step the
    /// lanes leave out; a world that fails one renders one path at a time, as every world can.
    /// Russian roulette may be off: its game is then never played, in the lanes as in the
    /// scalar path.
    pub fn lanes_fit(&self) -> bool {
        self.paths == PathLanes::Lanes
            && !self.effects.media
            && !self.effects.dispersion
            && self.lights.lanes_sample_all(&self.scene)
            && self.area_lights == AreaLightSampling::Mis
            && self.offset == OffsetMethod::ErrorBound
            && self.spectral == SpectralSampling::Auto
            && self.effects.shadows
            && self.scene.materials.iter().all(|m| {
                matches!(
                    m.bsdf,
                    Bsdf::Diffuse { .. }
                        | Bsdf::Mirror { .. }
                        | Bsdf::Dielectric { .. }
                        | Bsdf::Conductor { .. }
                )
            })
    }

    /// Renders every path `feed` hands out, up to eight at a time, and hands each one's
    /// radiance back to `feed` as it ends (and each lane's counted work as `feed` asks for it,
    /// [`PathFeed::next_path`]): each path's, bit for bit, what
    /// [`World::radiance_from`] finds for it. A lane whose path ends takes the feed's next
    /// one at once, so that the shading's vector instructions work on eight paths for as
    /// long as the feed has paths, not on a pixel's dwindling few (at a pixel's last bounces
    /// only two in five lanes were still busy). Only for worlds that [`World::lanes_fit`].
    pub(crate) fn radiance_stream(&self, feed: &mut impl PathFeed) {
        // Compiled apart for worlds without textures, which then carry no texels (where the
        // world pays for no textures, `texel_ahead` finds none anyway), and for worlds whose
        // objects move, whose paths place them (a still world's lanes never ask where a hit's
        // triangle lies; asked at run time, that cost the Cornell box 3 % more instructions).
        let (textured, moves) = (self.effects.textures, !self.motion.is_empty());
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: the processor has AVX, just checked.
            return unsafe {
                match (textured, moves) {
                    (false, false) => self.lanes_avx::<false, false>(feed),
                    (true, false) => self.lanes_avx::<true, false>(feed),
                    (false, true) => self.lanes_avx::<false, true>(feed),
                    (true, true) => self.lanes_avx::<true, true>(feed),
                }
            };
        }
        match (textured, moves) {
            (false, false) => self.lanes_with::<false, false>(feed),
            (true, false) => self.lanes_with::<true, false>(feed),
            (false, true) => self.lanes_with::<false, true>(feed),
            (true, true) => self.lanes_with::<true, true>(feed),
        }
    }

    /// [`World::lanes_with`] compiled with AVX: the second phase's loops eight lanes wide.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn lanes_avx<const TEXTURED: bool, const MOVES: bool>(&self, feed: &mut impl PathFeed) {
        self.lanes_with::<TEXTURED, MOVES>(feed)
    }

    /// The paths' loop, a bounce of every busy lane at a time; with `TEXTURED`, reading the
    /// texels of textured surfaces.
    #[inline(always)]
    fn lanes_with<const TEXTURED: bool, const MOVES: bool>(&self, feed: &mut impl PathFeed) {
        // Each lane's path's moment: where its moving objects are, placed as the path starts.
        // In a still world every ray is asked at the one moment, and the lanes keep theirs.
        let mut moments: [Moment; LANES] = Default::default();
        let mut paths = Paths::default();
        let mut gathered = Gathered::default();
        let mut shaded = Shaded::default();
        let mut texels: [Texel; LANES] = [None; LANES];
        // Which lanes found a surface to shade this bounce.
        let mut shading = [false; LANES];
        let sky = SkyLight::of(self);
        // What the shading is compiled for: the kinds of surface and of light the world has.
        let kinds = (
            sky,
            Surfaces::of(self),
            self.lights.has_point_lights(),
            MOVES,
        );
        loop {
            // First phase, in two passes: every lane's walk, then every lane's surface, so
            // that the hit triangles' records, which the walks ask for from memory as they
            // keep a hit, arrive while the other lanes walk. A lane whose path ends in either
            // takes the next one, until it has a surface to shade or the feed is dry.
            let mut walked = [false; LANES];
            for (i, walked) in walked.iter_mut().enumerate() {
                *walked = self.next_hit::<MOVES>(&mut moments, &mut paths, i, feed);
            }
            for (i, shading) in shading.iter_mut().enumerate() {
                // A path that ends at its surface (the depth cap) hands the lane on to the
                // next path, walked and seen at once.
                *shading = walked[i]
                    && loop {
                        let lane = (&mut gathered, &mut texels[i]);
                        let moment = &moments[moment_index::<MOVES>(i)];
                        let phase = Self::surface_phase::<TEXTURED, MOVES>;
                        if phase(self, moment, &mut paths, i, lane, sky) {
                            break true;
                        }
                        paths.end(i, feed);
                        if !self.next_hit::<MOVES>(&mut moments, &mut paths, i, feed) {
                            break false;
                        }
                    };
            }
            if !shading.iter().any(|&s| s) {
                // Every lane's last call found the feed dry, which took its counted work.
                debug_assert!(
                    paths.counted_for.iter().all(|&c| c == NOT_COUNTED),
                    "a lane's counted work was left behind"
                );
                return;
            }
            let portals = matches!(sky, SkyLight::Portals);
            if portals && gathered.portal_draws.pending.contains(&true) {
                self.draw_through_portals(&mut gathered, &mut paths);
            }
            for (i, texel) in texels.iter_mut().enumerate().filter(|_| TEXTURED) {
                if let Some((bsdf, texel)) = texel.take() {
                    let Bsdf::Diffuse { albedo, .. } = resolve(bsdf, texel) else {
                        unreachable!("only a textured diffuse surface asks for a texel")
                    };
                    gathered.albedo.set(i, albedo);
                }
            }
            // Second phase: every lane's shading at once, then the walks' set-ups of every
            // lane's shadow ray and next ray, eight at a time.
            // Compiled apart for each kind of sky, surface and light the world has.
            shade_for(kinds, &gathered, &paths.beta, &mut shaded);
            let shadows = SetUpRows::new(shaded.origin.rows(), shaded.reach.rows());
            paths.set_up = SetUpRows::new(shaded.next_origin.rows(), shaded.next_dir.rows());
            // Third phase: shadow rays, then each path's next ray or its end.
            for (i, &shading) in shading.iter().enumerate() {
                let lane = (&gathered, &shaded, &shadows, portals);
                let moment = &moments[moment_index::<MOVES>(i)];
                if shading && !self.third_phase(moment, &mut paths, i, lane) {
                    paths.end(i, feed);
                }
            }
        }
    }

    /// Lane `i`'s walk to its next hit: the ray of its path, or where that path ends (the ray
    /// escapes), of the feed's next ones. `true` with the hit kept in the lane, `false` when
    /// the feed is dry.
    #[inline(always)]
    fn next_hit<'w, const MOVES: bool>(
        &'w self,
        moments: &mut [Moment<'w>; LANES],
        paths: &mut Paths,
        i: usize,
        feed: &mut impl PathFeed,
    ) -> bool {
        loop {
            if !paths.alive[i] {
                if !paths.admit(i, feed) {
                    return false;
                }
                if MOVES {
                    // The last path's placements written over in place: no allocation per
                    // path.
                    self.motion.move_to(&mut moments[i], paths.time[i]);
                }
            }
            let moment = &moments[moment_index::<MOVES>(i)];
            let stats = &mut paths.stats[i];
            stats.rays += 1;
            let ray = &paths.ray[i];
            let found = match paths.first[i].take() {
                Some(still) if MOVES => {
                    self.with_moving::<false>(ray, still, moment, &mut stats.traversal)
                }
                Some(hit) => hit,
                None => {
                    let set_up = paths.set_up_ready[i].then_some((&paths.set_up, i));
                    self.closest_from(ray, set_up, moment, &mut stats.traversal)
                }
            };
            if let Some(hit) = &found {
                // Read apart: the walk's hit was just written as two halves.
                paths.hit[i] = hit.read_apart();
                return true;
            }
            let (dir, last) = (paths.ray[i].dir, paths.last(i));
            let stats = &mut paths.stats[i];
            if let Some((arriving, weight)) = self.environment_seen(dir, last, stats) {
                paths.radiance[i] += paths.beta.get(i) * arriving * weight;
            }
            paths.end(i, feed);
        }
    }

    /// Lane `i`'s surface, after its walk: its numbers, the surface's side, shading normal,
    /// texel and emission, and its light. `true` where the lane has a surface to shade (its
    /// values gathered), `false` where its path ends.
    #[inline(always)]
    fn surface_phase<'w, const TEXTURED: bool, const MOVES: bool>(
        &'w self,
        moment: &Moment,
        paths: &mut Paths,
        i: usize,
        (g, texel): (&mut Gathered, &mut Texel<'w>),
        sky: SkyLight,
    ) -> bool {
        let max_depth = self.scene.settings.max_depth.unwrap_or(UNLIMITED_DEPTH);
        let depth = paths.depth[i];
        let sampler = &mut paths.sampler[i];
        sampler.start_bounce(depth);
        let u = BounceNumbers::draw(sampler);
        let ray = &paths.ray[i];
        let hit = paths.hit[i];
        paths.stats[i].hits += 1;
        // `World::surface`, but for a still triangle's point and its error bound, which the
        // second phase computes from the corners gathered below; a moving triangle's point is
        // placed here, as the scalar path places it.
        let moving = if MOVES {
            self.motion.locate(hit.triangle)
        } else {
            None
        };
        let placed = moving.map(|moving| self.placed_moving(moving, &hit, moment));
        let (triangle, attributes, geometric, placement) = match &placed {
            None => (
                &self.scene.triangles[hit.triangle as usize],
                self.scene.attributes.get(hit.triangle as usize),
                self.accel.unit_normal(hit.triangle),
                None,
            ),
            Some(placed) => (
                placed.triangle,
                placed.attributes,
                placed.unit_normal,
                placed.placement,
            ),
        };
        let seen = self.shading(ray.dir, &hit, attributes, placement, geometric);
        let material = &self.scene.materials[triangle.material as usize];
        if self.effects.area_lights && material.emission != Vec3::ZERO && seen.front_facing {
            let at = match &placed {
                None => hit_point(&triangle.p, hit.b1, hit.b2),
                Some(placed) => placed.at.p,
            };
            // The last scattering, read only here, where a light is hit.
            let last = paths.last(i);
            let weight = self.hit_emitter_weight(moment, hit.triangle, at, last);
            paths.radiance[i] += paths.beta.get(i) * material.emission * weight;
        }
        if depth >= max_depth {
            return false;
        }
        // A texture's texel is asked for from memory here and read after every lane's first
        // phase, so that the lanes' misses overlap each other and the other lanes' surfaces;
        // read at once, the wait was a third of this function's time on
        // Sponza (docs/bench.md, issue 12, thirty-second round).
        if TEXTURED {
            *texel = match material.bsdf {
                Bsdf::Diffuse {
                    texture: Some(_), ..
                } => Some((&material.bsdf, self.texel_ahead(&material.bsdf, seen.uv))),
                _ => None,
            };
        }
        // Counted as the third phase will count it, once this bounce is done.
        (g.roulette[i], g.playing[i]) = (u.roulette, self.roulette_plays(depth + 1));
        match &placed {
            None => {
                for (corner, p) in g.hit.iter_mut().zip(triangle.p) {
                    corner.set(i, p);
                }
                (g.barycentric[0][i], g.barycentric[1][i]) = (hit.b1, hit.b2);
                g.plane.set(i, self.accel.plane_normal(hit.triangle));
            }
            Some(placed) => g.placed.set(i, &placed.at),
        }
        if MOVES {
            g.moved[i] = placed.is_some();
        }
        g.normal.set(i, seen.normal);
        g.dir.set(i, ray.dir);
        (g.scatter[0][i], g.scatter[1][i]) = (u.scatter.x, u.scatter.y);
        if let Bsdf::Diffuse { albedo, .. } = material.bsdf {
            (g.drawn[i], g.delta[i], g.glossy[i]) = (false, false, false);
            g.albedo.set(i, albedo);
        } else {
            // A mirror's, a glass's or a rough metal's bounce: its direction drawn here, lane
            // by lane, by the scalar path's own `Bsdf::sample` in the scalar path's frame (the
            // vector shading makes the same frame again), its weight where a diffuse surface's
            // albedo goes. A delta samples no light, as the scalar path samples none on a
            // delta BSDF: the lane's light values stay as they were, and the shading leaves it
            // unlit. A metal samples its light as a diffuse surface does, and the shading
            // weighs it by the metal's lobe.
            let frame = Frame::from_normal(seen.normal);
            let sample = material
                .bsdf
                .sample(frame.to_local(-ray.dir), u.choice, u.scatter);
            if sample.is_some_and(|s| s.transmission) {
                paths.stats[i].refractions += 1;
            }
            g.drawn[i] = true;
            g.drawn_sampled[i] = sample.is_some();
            let sample = sample.unwrap_or(NO_SAMPLE);
            g.drawn_wi.set(i, sample.wi);
            g.drawn_pdf[i] = sample.pdf;
            g.albedo.set(i, sample.weight);
            let Bsdf::Conductor { f0, alpha } = material.bsdf else {
                (g.delta[i], g.glossy[i]) = (true, false);
                return true;
            };
            let lobe = Ggx::new(f0, alpha);
            (g.delta[i], g.glossy[i]) = (false, true);
            g.f0.set(i, lobe.f0);
            g.alpha[i] = lobe.alpha;
        }
        paths.stats[i].light_samples += 1;
        let (light, choice) = self.lights.lanes_choice(u.light_choice);
        if matches!(sky, SkyLight::Portals) {
            g.through[i] = false;
        }
        (g.light[0][i], g.light[1][i]) = (u.light.x, u.light.y);
        g.choice[i] = choice;
        g.sky[i] = matches!(light, LanesLight::Environment);
        g.point[i] = matches!(light, LanesLight::Point { .. });
        match light {
            LanesLight::Triangle(triangle, shape) => {
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
            LanesLight::Point {
                position,
                intensity,
            } => {
                g.corners[0].set(i, position);
                g.emission.set(i, intensity);
            }
            // Where the scene has portals, both of the environment's samples are drawn here,
            // lane by lane, as `World::sample_lights` draws them, from the point the vector
            // shading will find (the same expressions: `SurfacePoint::on_triangle_with_normal`
            // of the corners gathered above, or the placed point).
            LanesLight::Environment if matches!(sky, SkyLight::Portals) => {
                let p = match &placed {
                    None => {
                        SurfacePoint::on_triangle_with_normal(
                            &triangle.p,
                            hit.b1,
                            hit.b2,
                            self.accel.plane_normal(hit.triangle),
                        )
                        .p
                    }
                    Some(placed) => placed.at.p,
                };
                self.environment_with_portals(p, (u.light_choice, u.light), choice, g, i);
            }
            // An environment map's sample is drawn here, lane by lane, where a constant
            // environment's is drawn in the vector shading.
            LanesLight::Environment if matches!(sky, SkyLight::Map) => {
                let environment = self.scene.environment.as_ref();
                let sample =
                    environment.and_then(|e| self.lights.environment_sample(e, u.light, choice));
                let (dir, arriving, pdf) = sample.unwrap_or((Vec3::Z, Vec3::ZERO, 0.0));
                g.sky_dir.set(i, dir);
                g.emission.set(i, arriving);
                g.sky_pdf[i] = pdf;
            }
            LanesLight::Environment => g.emission.set(i, sky.constant()),
            // A moving triangle's point is drawn and placed here, lane by lane
            // (`lights::placed_sample`), and weighed as seen from the surface in the vector
            // shading, as a still triangle's is.
            LanesLight::Moving { object, triangle } => {
                let (at, area, radiance) =
                    placed_sample(&self.scene, moment, (object, triangle), u.light);
                g.light_placed.set(i, &at);
                g.light_area[i] = area;
                g.light_normal.set(i, at.normal);
                g.emission.set(i, radiance);
            }
        }
        if MOVES {
            g.light_moved[i] = matches!(light, LanesLight::Moving { .. });
        }
        true
    }

    /// The environment's own sample from `p` where the scene has portals, into lane `i` of
    /// `g`, as `World::sample_lights` draws it (`Lights::environment_light_sample`), and
    /// where it takes one, the second sample's draw through a portal (`Lights::portal_pick`)
    /// set in the lane, for every lane's to be drawn together after the first phase
    /// ([`World::draw_through_portals`]). With one portal, the own sample's density through it
    /// is found with that draw, from the same view of the portal. Out of line: inlined into
    /// the lanes' first phase, its code cost every other world's lanes 0.7 % more instructions
    /// (the Cornell box).
    #[inline(never)]
    fn environment_with_portals(
        &self,
        p: Vec3,
        (u_choice, u): (f32, Vec2),
        choice: f32,
        g: &mut Gathered,
        i: usize,
    ) {
        let environment = (self.scene.environment.as_ref())
            .expect("the environment is a light only where the scene has one");
        let pick = self.lights.portal_pick(&self.scene, u_choice, u);
        // The own sample's density through the portals is set with the draw through them
        // ([`World::draw_through_portals`]), where the lane takes one.
        g.sky_other[i] = 0.0;
        if let Some((k, u)) = pick.filter(|_| self.lights.samples_sky_uniformly(environment)) {
            // A sky sampled uniformly over the sphere: its own sample is drawn with the draws
            // through the portals, every lane's together.
            g.portal_draws.set(i, (k, self.lights.portal(k)), p, u);
            return;
        }
        let own = self.lights.environment_sample(environment, u, choice);
        let (dir, arriving, pdf) = own.unwrap_or((Vec3::Z, Vec3::ZERO, 0.0));
        g.sky_dir.set(i, dir);
        g.emission.set(i, arriving);
        g.sky_pdf[i] = pdf;
        if own.is_some()
            && let Some((k, u)) = pick
        {
            g.portal_draws.set(i, (k, self.lights.portal(k)), p, u);
            g.portal_draws.set_other(i, dir);
        }
    }

    /// Every lane's draw through the portals that its first phase set, drawn together
    /// (`PortalDraws`), then each lane's second light sample made of it, as
    /// `Lights::portal_sample` makes it, into `g`; counted in the lane's statistics. Out of
    /// line, for the reason [`World::environment_with_portals`] is.
    #[inline(never)]
    fn draw_through_portals(&self, g: &mut Gathered, paths: &mut Paths) {
        let environment = (self.scene.environment.as_ref())
            .expect("the environment is a light only where the scene has one");
        if self.lights.samples_sky_uniformly(environment) {
            // The sky's own samples, as `Lights::environment_sample` draws them, uniform over
            // the sphere for the lanes' light numbers: every lane's at once, in a loop that
            // vectorises, then set lane by lane.
            let mut own = Points::default();
            for i in 0..LANES {
                own.set(i, uniform_sphere(Vec2::new(g.light[0][i], g.light[1][i])));
            }
            let pending = g.portal_draws.pending;
            for i in (0..LANES).filter(|&i| pending[i]) {
                let wi = own.get(i);
                g.portal_draws.set_other(i, wi);
                g.sky_dir.set(i, wi);
                g.emission.set(i, environment.radiance(wi));
                g.sky_pdf[i] = uniform_density(g.choice[i]);
            }
        }
        g.portal_draws.draw();
        for i in 0..LANES {
            if !g.portal_draws.pending[i] {
                continue;
            }
            let k = g.portal_draws.portal[i];
            let p = g.portal_draws.point(i);
            // `Lights::environment_light_sample`'s other density: the portals' mean density of
            // the own sample's direction; with one portal that portal's, found by the draw
            // from its view.
            let own = g.sky_dir.get(i);
            let drawn = || g.portal_draws.other_density(i);
            let portals = self.lights.portals_density(p, own, drawn);
            g.sky_other[i] = g.choice[i] * portals;
            let through = g
                .portal_draws
                .checked(i, self.lights.portal(k))
                .and_then(|drawn| self.lights.through_portals(&self.scene, p, drawn));
            g.through[i] = through.is_some();
            if let Some(through) = through {
                paths.stats[i].light_samples += 1;
                g.through_dir.set(i, through.wi);
                g.through_emission.set(i, through.radiance);
                g.through_pdf[i] = through.pdf;
                g.through_other[i] = through.other_pdf;
            }
        }
    }

    /// Lane `i`'s third phase: its shadow ray, then its next ray; `false` where its path
    /// ends.
    #[inline(always)]
    fn third_phase(
        &self,
        moment: &Moment,
        paths: &mut Paths,
        i: usize,
        (g, shaded, shadows, portals): (&Gathered, &Shaded, &SetUpRows, bool),
    ) -> bool {
        let stats = &mut paths.stats[i];
        // Where the environment took its sample through the portals too, both are summed
        // before they are weighed by the throughput, as `World::direct_from` sums them.
        let both = portals && g.through[i] && !g.delta[i];
        let mut own = Vec3::ZERO;
        if shaded.lit[i] {
            stats.shadow_rays += 1;
            let shadow = Ray {
                origin: shaded.origin.get(i),
                dir: shaded.reach.get(i),
                t_max: if g.sky[i] { f32::INFINITY } else { 1.0 },
            };
            if !self.occluded_from(&shadow, Some((shadows, i)), moment, &mut stats.traversal) {
                if both {
                    own = shaded.value.get(i);
                } else {
                    paths.radiance[i] += paths.beta.get(i) * shaded.value.get(i);
                }
            }
        }
        if both {
            let mut through = Vec3::ZERO;
            if shaded.through_lit[i] {
                stats.shadow_rays += 1;
                let shadow = Ray {
                    origin: shaded.through_origin.get(i),
                    dir: g.through_dir.get(i),
                    t_max: f32::INFINITY,
                };
                if !self.occluded_from(&shadow, None, moment, &mut stats.traversal) {
                    through = shaded.through_value.get(i);
                }
            }
            paths.radiance[i] += paths.beta.get(i) * (own + through);
        }
        // Counted before the path may end here, where the scalar path counts it after: a path
        // that ends takes its depth with it, so no number changes.
        paths.depth[i] += 1;
        // The throughput, its checks and Russian roulette were the second phase's.
        if !shaded.continues[i] {
            return false;
        }
        paths.beta.set(i, shaded.beta.get(i));
        (paths.last_pdf[i], paths.last_delta[i], paths.last_point[i]) =
            (shaded.pdf[i], g.delta[i], shaded.p.get(i));
        paths.ray[i] = Ray {
            origin: shaded.next_origin.get(i),
            dir: shaded.next_dir.get(i),
            t_max: f32::INFINITY,
        };
        paths.set_up_ready[i] = true;
        true
    }
}

/// Which of the lanes' moments lane `i` asks: its own where objects move, else the first, the
/// one moment of a still world (one address for every lane, which the walks then need not
/// compute lane by lane).
#[inline(always)]
fn moment_index<const MOVES: bool>(i: usize) -> usize {
    if MOVES { i } else { 0 }
}

/// The kinds of surface a world's lanes shade, each kind's shading compiled apart (`shade`'s
/// `DRAWN` and `GLOSSY`): a world of diffuse surfaces pays for none of the others' selects.
#[derive(Clone, Copy)]
enum Surfaces {
    /// Diffuse surfaces alone.
    Diffuse,
    /// Mirrors or glass among them, whose directions the first phase draws.
    Deltas,
    /// Rough metals among them (and perhaps mirrors or glass), whose light samples the GGX
    /// lobe weighs.
    Glossy,
}

impl Surfaces {
    /// The kinds of surface `world` has.
    fn of(world: &World) -> Self {
        let effects = &world.effects;
        if effects.glossy_reflection {
            Surfaces::Glossy
        } else if effects.specular_reflection || effects.refraction {
            Surfaces::Deltas
        } else {
            Surfaces::Diffuse
        }
    }
}

/// The second phase, `shade`, compiled for the world's sky, its surfaces, whether it has
/// point lights and whether objects move: a constant's choice at each step, so that the
/// instance the world runs is chosen once per bounce.
#[inline(always)]
fn shade_for(
    (sky, surfaces, point, moves): (SkyLight, Surfaces, bool, bool),
    g: &Gathered,
    beta: &Points,
    out: &mut Shaded,
) {
    let kinds = (surfaces, point, moves);
    match sky {
        // A world with portals runs the shading compiled for every kind of surface and light
        // (its portals' samples cost far more than the selects): one more instance.
        SkyLight::Portals => shade::<true, true, true, true, true, true, true>(g, beta, out),
        SkyLight::Map => shade_with_sky::<true, true>(kinds, g, beta, out),
        SkyLight::Constant(_) => shade_with_sky::<true, false>(kinds, g, beta, out),
        SkyLight::Absent => shade_with_sky::<false, false>(kinds, g, beta, out),
    }
}

/// [`shade_for`], its sky chosen.
#[inline(always)]
fn shade_with_sky<const SKY: bool, const SKY_DRAWN: bool>(
    (surfaces, point, moves): (Surfaces, bool, bool),
    g: &Gathered,
    beta: &Points,
    out: &mut Shaded,
) {
    if moves {
        // A world whose objects move runs the shading compiled for every kind of surface and
        // light: one instance per sky rather than six more (its selects cost little beside
        // placing its objects).
        return shade::<SKY, SKY_DRAWN, true, true, true, true, false>(g, beta, out);
    }
    match (surfaces, point) {
        (Surfaces::Diffuse, false) => {
            shade::<SKY, SKY_DRAWN, false, false, false, false, false>(g, beta, out)
        }
        (Surfaces::Diffuse, true) => {
            shade::<SKY, SKY_DRAWN, false, false, true, false, false>(g, beta, out)
        }
        (Surfaces::Deltas, false) => {
            shade::<SKY, SKY_DRAWN, true, false, false, false, false>(g, beta, out)
        }
        (Surfaces::Deltas, true) => {
            shade::<SKY, SKY_DRAWN, true, false, true, false, false>(g, beta, out)
        }
        (Surfaces::Glossy, false) => {
            shade::<SKY, SKY_DRAWN, true, true, false, false, false>(g, beta, out)
        }
        (Surfaces::Glossy, true) => {
            shade::<SKY, SKY_DRAWN, true, true, true, false, false>(g, beta, out)
        }
    }
}

/// The environment as the lanes sample it where it is one of the lights: a constant one (what
/// it sends every way), drawn in the vector shading, or a map, drawn lane by lane before it;
/// or either where the scene has portals, whose samples, the environment's own and the one
/// through the portals, are drawn before it: every lane's draw through the portals (and a
/// uniform sky's own sample) together, in vector instructions, a map's own sample lane by
/// lane.
#[derive(Clone, Copy)]
enum SkyLight {
    Absent,
    Constant(Vec3),
    Map,
    Portals,
}

impl SkyLight {
    /// The sky `world`'s lanes sample.
    fn of(world: &World) -> Self {
        if !world.lights.environment_is_light() {
            return SkyLight::Absent;
        }
        if world.lights.has_portals() {
            return SkyLight::Portals;
        }
        match &world.scene.environment {
            Some(Environment::Constant(radiance)) => SkyLight::Constant(*radiance),
            Some(Environment::Map(_)) => SkyLight::Map,
            None => SkyLight::Absent,
        }
    }

    /// What a constant sky sends every way; zero for the others, whose light is never picked
    /// as a constant one.
    #[inline(always)]
    fn constant(self) -> Vec3 {
        match self {
            SkyLight::Constant(radiance) => radiance,
            SkyLight::Absent | SkyLight::Map | SkyLight::Portals => Vec3::ZERO,
        }
    }
}

/// A textured surface's BSDF and the texel it reads, asked for from memory in a lane's first
/// phase and read after every lane's ([`World::texel_ahead`]).
type Texel<'w> = Option<(&'w Bsdf, Option<(&'w Texture, Option<usize>)>)>;
