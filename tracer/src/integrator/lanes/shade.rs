//! The lanes' data, laid out a value of every lane at a time, and their second phase: the
//! shading of every lane in one loop that vectorises (see the parent module for why it is
//! exact).

use super::LANES;
use crate::environment::PortalDraws;
use crate::geometry::{SurfacePoint, gamma};
use crate::integrator::direct::{against_strategies, power_heuristic};
use crate::integrator::survival;
use crate::lights::{uniform_density, uniform_sphere};
use crate::material::{Frame, Ggx, sample_cosine_hemisphere};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Lane values: one per path.
pub(super) type Lanes<T> = [T; LANES];

/// Points and directions of every lane, a coordinate at a time (so that loads of a coordinate
/// for all lanes are one vector load).
#[derive(Clone, Copy, Default)]
pub(super) struct Points {
    pub(super) x: Lanes<f32>,
    pub(super) y: Lanes<f32>,
    pub(super) z: Lanes<f32>,
}

impl Points {
    #[inline(always)]
    pub(super) fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    #[inline(always)]
    pub(super) fn set(&mut self, i: usize, v: Vec3) {
        (self.x[i], self.y[i], self.z[i]) = (v.x, v.y, v.z);
    }

    /// The three coordinates' rows.
    #[inline(always)]
    pub(super) fn rows(&self) -> [&Lanes<f32>; 3] {
        [&self.x, &self.y, &self.z]
    }
}

/// Points placed in the first phase, with what the second needs of them: a moving
/// triangle's, whose point, error bound and normal come from its placement, and whose rays
/// leave from the origins worked out in its object's space (`SurfacePoint::spawn`), above
/// its plane and below.
#[derive(Clone, Copy, Default)]
pub(super) struct PlacedPoints {
    p: Points,
    error: Points,
    normal: Points,
    above: Points,
    below: Points,
}

impl PlacedPoints {
    /// Keeps lane `i`'s point, which is one placed on a moving triangle (its `spawn` given).
    #[inline(always)]
    pub(super) fn set(&mut self, i: usize, at: &SurfacePoint) {
        let [above, below] = at
            .spawn
            .expect("a point placed on a moving triangle carries its rays' origins");
        self.p.set(i, at.p);
        self.error.set(i, at.error);
        self.normal.set(i, at.normal);
        self.above.set(i, above);
        self.below.set(i, below);
    }

    /// Lane `i`'s point (its `spawn` left out) and its origins above and below.
    #[inline(always)]
    fn get(&self, i: usize) -> (SurfacePoint, [Vec3; 2]) {
        let at = SurfacePoint {
            p: self.p.get(i),
            error: self.error.get(i),
            normal: self.normal.get(i),
            spawn: None,
        };
        (at, [self.above.get(i), self.below.get(i)])
    }
}

/// What the first phase hands the second: each lane's hit (its triangle's corners and plane
/// normal, the barycentric coordinates), shading normal, incoming direction, albedo and
/// numbers, and the light it picked. A lane without a surface keeps what it last held,
/// computes on it, and is ignored.
#[derive(Clone, Copy, Default)]
pub(super) struct Gathered {
    /// The corners of the triangle hit, and the hit's barycentric coordinates of corners 1
    /// and 2 (the point and its error bound are the second phase's).
    pub(super) hit: [Points; 3],
    pub(super) barycentric: [Lanes<f32>; 2],
    pub(super) plane: Points,
    /// Whether the hit is on a moving triangle, whose point the first phase placed (then
    /// the corners, barycentrics and plane above are stale).
    pub(super) moved: Lanes<bool>,
    pub(super) placed: PlacedPoints,
    pub(super) normal: Points,
    pub(super) dir: Points,
    /// The diffuse surface's albedo, or where `drawn` the sampled direction's weight.
    pub(super) albedo: Points,
    /// Whether the surface's direction was drawn in the first phase, by `Bsdf::sample` (a
    /// mirror, glass, a rough metal): `drawn_sampled` whether one was, `drawn_wi` it in the
    /// shading frame, `drawn_pdf` its density.
    pub(super) drawn: Lanes<bool>,
    pub(super) drawn_sampled: Lanes<bool>,
    pub(super) drawn_wi: Points,
    pub(super) drawn_pdf: Lanes<f32>,
    /// Whether the surface scatters by a delta (a mirror, glass): then its direction was drawn,
    /// its lane samples no light, and its light values are stale.
    pub(super) delta: Lanes<bool>,
    /// Whether the surface is a rough metal, a GGX lobe of colour `f0` at normal incidence and
    /// roughness `alpha` (clamped, as `Ggx::new` clamps it): its light sample is weighed by the
    /// lobe's value and density.
    pub(super) glossy: Lanes<bool>,
    pub(super) f0: Points,
    pub(super) alpha: Lanes<f32>,
    pub(super) scatter: [Lanes<f32>; 2],
    pub(super) light: [Lanes<f32>; 2],
    /// The light triangle's corners; for a point light the first is where it is.
    pub(super) corners: [Points; 3],
    pub(super) light_area: Lanes<f32>,
    pub(super) light_normal: Points,
    pub(super) light_plane: Points,
    /// Whether the light picked is a moving triangle, whose point the first phase drew and
    /// placed (then `corners` and `light_plane` are stale, and `light_area` and
    /// `light_normal` are the placed triangle's).
    pub(super) light_moved: Lanes<bool>,
    pub(super) light_placed: PlacedPoints,
    /// What the light emits: a triangle's radiance, a point light's intensity, or what the
    /// environment sends.
    pub(super) emission: Points,
    pub(super) choice: Lanes<f32>,
    /// Whether the light picked is a point light (then `corners[0]` is where it is, and the
    /// triangle's other values are stale).
    pub(super) point: Lanes<bool>,
    /// Whether the light picked is the environment (then `emission` is what it sends, and
    /// the triangle's values are stale).
    pub(super) sky: Lanes<bool>,
    /// The environment's own sample where the first phase drew it (a map's, or any sky's
    /// where the scene has portals): its direction and density (the choice's included; 0
    /// where the map gave no direction, whose `emission` is then zero), and where the scene
    /// has portals, the density with which they would have given the same direction.
    pub(super) sky_dir: Points,
    pub(super) sky_pdf: Lanes<f32>,
    pub(super) sky_other: Lanes<f32>,
    /// Where the scene has portals and the environment was sampled, its second sample, through
    /// them (`Lights::portal_sample`), drawn in the first phase: whether there is one, its
    /// direction, what arrives along it, its density (the environment's choice included) and
    /// the environment's own density of the same direction.
    pub(super) through: Lanes<bool>,
    pub(super) through_dir: Points,
    pub(super) through_emission: Points,
    pub(super) through_pdf: Lanes<f32>,
    pub(super) through_other: Lanes<f32>,
    /// The draws through the portals, set lane by lane in the first phase and drawn together
    /// after it, before the `through` values above are set from them.
    pub(super) portal_draws: PortalDraws,
    /// Russian roulette's number, and whether the game is played after this bounce.
    pub(super) roulette: Lanes<f32>,
    pub(super) playing: Lanes<bool>,
}

/// What the second phase hands the third, per lane.
#[derive(Clone, Copy, Default)]
pub(super) struct Shaded {
    /// The point hit, where the next ray leaves from.
    pub(super) p: Points,
    /// Whether the light sample brings anything (then `value` and the shadow ray's `origin`
    /// and `reach` hold it).
    pub(super) lit: Lanes<bool>,
    pub(super) value: Points,
    pub(super) origin: Points,
    pub(super) reach: Points,
    /// Where the scene has portals, the same for the sample through them: whether it brings
    /// anything, what, and where its shadow ray leaves from (along `Gathered::through_dir`).
    pub(super) through_lit: Lanes<bool>,
    pub(super) through_value: Points,
    pub(super) through_origin: Points,
    /// Whether the path goes on: a direction was sampled, the throughput it leaves is neither
    /// zero nor more than finite, and Russian roulette let it survive. Then `beta` is that
    /// throughput (raised by the roulette where played), `pdf` the direction's density, and
    /// the next ray's `next_origin` and `next_dir` hold it.
    pub(super) continues: Lanes<bool>,
    pub(super) beta: Points,
    pub(super) pdf: Lanes<f32>,
    pub(super) next_origin: Points,
    pub(super) next_dir: Points,
}

/// The second phase: each lane's shading, in one loop that vectorises. Its body is the scalar
/// path's arithmetic, in the scalar path's order, with every choice a select: `Frame`,
/// `sample_cosine_hemisphere`, `SurfacePoint::on_triangle_with_normal` and `power_heuristic`
/// are called as they are; what `Bsdf::sample`, `area_sample`, the light sample's value and
/// the spawns (`offset` below) do for a diffuse surface is written out here lane by lane,
/// because their `Option`s and branches kept the compiler from vectorising the loop
/// (docs/bench.md, issue 12, thirty-first round). So is what the scalar path does with the
/// sampled direction's weight: `beta`, the lanes' throughputs, times the weight, the path's
/// end where that is zero or not finite, and Russian roulette (`World::roulette`), whose
/// division by one where the game is not yet played is exact (`x / 1` is `x`): played
/// lane by lane in the third phase, its branch on the depth was mispredicted as often as the
/// lanes' depths differed (docs/bench.md, issue 12, thirty-ninth round).
/// `tracer/tests/path_lanes.rs` holds every image to the scalar path's, bit for bit.
///
/// `SKY` where the environment is a light, `SKY_DRAWN` where the first phase drew its sample
/// (a map's, whose inversions search tables, each lane its own way, or any sky's where the
/// scene has portals); a constant one's is drawn here otherwise. `PORTALS` where the scene has
/// portals: the environment's sample is weighed against them as well, and the second sample,
/// through them, which the first phase drew, is weighed and given its shadow ray's origin
/// here. `DRAWN` where some surfaces' directions are drawn in the first phase (mirrors, glass,
/// rough metals): their lanes take that direction, and the deltas among them no light sample.
/// `GLOSSY` where some surfaces are rough metals, whose light samples the GGX lobe weighs;
/// `POINT` where some lights are point lights; `MOVING` where some objects move, whose hits'
/// points and lights' samples the first phase placed. Each is compiled only for the worlds that
/// have what it names (`Surfaces`, the parent module's dispatch).
#[inline(always)]
pub(super) fn shade<
    const SKY: bool,
    const SKY_DRAWN: bool,
    const DRAWN: bool,
    const GLOSSY: bool,
    const POINT: bool,
    const MOVING: bool,
    const PORTALS: bool,
>(
    g: &Gathered,
    beta: &Points,
    out: &mut Shaded,
) {
    for i in 0..LANES {
        let hit = [g.hit[0].get(i), g.hit[1].get(i), g.hit[2].get(i)];
        let plane = g.plane.get(i);
        let on_triangle = SurfacePoint::on_triangle_with_normal(
            &hit,
            g.barycentric[0][i],
            g.barycentric[1][i],
            plane,
        );
        let moved = MOVING && g.moved[i];
        let (placed, spawn) = g.placed.get(i);
        let at = point_where(moved, placed, on_triangle);
        let p = at.p;
        out.p.set(i, p);
        let frame = Frame::from_normal(g.normal.get(i));
        let wo = frame.to_local(-g.dir.get(i));
        // `Bsdf::sample`, diffuse: a cosine-weighted direction on `wo`'s side; a mirror's, a
        // glass's or a metal's, as the first phase drew it.
        let drawn = DRAWN && g.drawn[i];
        let delta = DRAWN && g.delta[i];
        // Read whatever the lane holds, then selected: read only where `drawn`, these loads
        // kept the loop from vectorising (the Cornell box with a mirror took half again as
        // long as with no lanes at all; its instructions 341 M to 437 M at 64x64, 16 spp).
        let (drawn_sampled, drawn_pdf, drawn_wi) =
            (g.drawn_sampled[i], g.drawn_pdf[i], g.drawn_wi.get(i));
        let flip = wo.z < 0.0;
        let local = sample_cosine_hemisphere(Vec2::new(g.scatter[0][i], g.scatter[1][i]));
        let diffuse_sampled = (wo.z != 0.0) & !wo.z.is_nan() & (local.z > 0.0);
        let sampled = if drawn {
            drawn_sampled
        } else {
            diffuse_sampled
        };
        out.pdf[i] = if drawn {
            drawn_pdf
        } else {
            local.z * FRAC_1_PI
        };
        // Either sample's weight is in `albedo`.
        let next = beta.get(i) * g.albedo.get(i);
        let survive = survival(next);
        let playing = g.playing[i];
        // `&`, not `&&`: short-circuits are branches, and with them this loop no longer
        // vectorised (the box's instructions 774 M to 973 M, 96x96, 16 spp).
        out.continues[i] = sampled
            & (next != Vec3::ZERO)
            & next.is_finite()
            & !(playing & (g.roulette[i] >= survive));
        out.beta.set(i, next / if playing { survive } else { 1.0 });
        let z = if flip { -local.z } else { local.z };
        let scattered = if drawn {
            drawn_wi
        } else {
            Vec3::new(local.x, local.y, z)
        };
        let wi = frame.to_world(scattered);
        out.next_dir.set(i, wi);
        out.next_origin
            .set(i, origin_leaving(&at, (moved, spawn), wi));
        // `triangle_sample`: a point uniform on the light's triangle, as seen from `p`; or
        // where a point light is (`SurfacePoint::exact`: no error, on no surface).
        let su = g.light[0][i].sqrt();
        let (b1, b2) = (su * (1.0 - g.light[1][i]), su * g.light[1][i]);
        let corners = [
            g.corners[0].get(i),
            g.corners[1].get(i),
            g.corners[2].get(i),
        ];
        let on_triangle =
            SurfacePoint::on_triangle_with_normal(&corners, b1, b2, g.light_plane.get(i));
        let point = POINT && g.point[i];
        let light_at = point_where(point, SurfacePoint::exact(corners[0]), on_triangle);
        let light_moved = MOVING && g.light_moved[i];
        let (light_placed, light_spawn) = g.light_placed.get(i);
        let light_at = point_where(light_moved, light_placed, light_at);
        let to_light = light_at.p - p;
        let distance_squared = to_light.length_squared();
        let distance = distance_squared.sqrt();
        let cos_light = -(to_light / distance).dot(g.light_normal.get(i));
        let area = g.light_area[i];
        // Or the environment's: as drawn, or a constant one's uniform over the sphere
        // (`Lights::environment_sample`).
        let sky = SKY && g.sky[i];
        let sky_way = if SKY_DRAWN {
            g.sky_dir.get(i)
        } else {
            uniform_sphere(Vec2::new(g.light[0][i], g.light[1][i]))
        };
        let toward = if sky { sky_way } else { to_light / distance };
        // A point light's density is its choice's alone (a delta in direction).
        let light_pdf = if sky {
            if SKY_DRAWN {
                g.sky_pdf[i]
            } else {
                uniform_density(g.choice[i])
            }
        } else if point {
            g.choice[i]
        } else {
            g.choice[i] * distance_squared / (cos_light * area)
        };
        let sampled_light = sky
            || if point {
                distance_squared != 0.0
            } else {
                distance_squared != 0.0 && area != 0.0 && cos_light > 0.0
            };
        // `unshadowed`: the BSDF towards it, weighed against BSDF sampling.
        let surface = Response {
            frame,
            wo,
            flip,
            glossy: GLOSSY && g.glossy[i],
            lobe: Ggx {
                f0: g.f0.get(i),
                alpha: g.alpha[i],
            },
            albedo: g.albedo.get(i),
        };
        let (f, density) = surface.toward(toward);
        // A point light's intensity falls off with the squared distance.
        let emission = if point {
            g.emission.get(i) / distance_squared
        } else {
            g.emission.get(i)
        };
        // A delta light takes all the weight (`AreaLightSampling::light_weight`); the sky is
        // weighed against the portals too where the scene has them.
        let against = if PORTALS {
            against_strategies(density, if sky { g.sky_other[i] } else { 0.0 })
        } else {
            density
        };
        let weight = if point {
            1.0
        } else {
            power_heuristic(light_pdf, against)
        };
        let (value, brings) = light_value(f, emission, weight, light_pdf);
        out.value.set(i, value);
        out.lit[i] = sampled_light & !delta & brings;
        // `shadow_ray`: towards the sky (`spawn_ray`), or with both ends off their surfaces
        // (`spawn_ray_to`; a point light's end, on no surface, stays where it is).
        let origin = origin_leaving(&at, (moved, spawn), if sky { sky_way } else { to_light });
        let widened = SurfacePoint {
            error: light_at.error + gamma(2) * (light_at.p - origin).abs(),
            ..light_at
        };
        let target = origin_leaving(&widened, (light_moved, light_spawn), origin - light_at.p);
        out.origin.set(i, origin);
        out.reach
            .set(i, if sky { sky_way } else { target - origin });
        if PORTALS {
            // The sample through the portals, as `World::light_contribution` weighs it.
            let (through_dir, through_pdf) = (g.through_dir.get(i), g.through_pdf[i]);
            let (f, density) = surface.toward(through_dir);
            let weight =
                power_heuristic(through_pdf, against_strategies(density, g.through_other[i]));
            let (value, brings) = light_value(f, g.through_emission.get(i), weight, through_pdf);
            out.through_value.set(i, value);
            out.through_lit[i] = g.through[i] & !delta & brings;
            out.through_origin
                .set(i, origin_leaving(&at, (moved, spawn), through_dir));
        }
    }
}

/// What a light sample brings through a surface whose value towards it is `f`: `World::
/// light_contribution`'s weighed value (in a world without media, whose transmittance of one
/// changes no bit), and whether it brings anything, that function's test before its shadow
/// ray; for the lanes' own samples and their samples through portals alike.
#[inline(always)]
fn light_value(f: Vec3, emission: Vec3, weight: f32, pdf: f32) -> (Vec3, bool) {
    let brings = (f != Vec3::ZERO) & (emission != Vec3::ZERO) & (pdf > 0.0);
    (f * emission * (weight / pdf), brings)
}

/// A lane's surface as a light sample sees it: `Bsdf::eval` and `Bsdf::pdf` of a diffuse
/// surface or a rough metal, written out for the vector shading.
struct Response {
    frame: Frame,
    wo: Vec3,
    /// Whether `wo` is below the shading frame's plane (both directions are then mirrored).
    flip: bool,
    glossy: bool,
    lobe: Ggx,
    albedo: Vec3,
}

impl Response {
    /// The surface's value and density towards `toward` (world space, unit length).
    #[inline(always)]
    fn toward(&self, toward: Vec3) -> (Vec3, f32) {
        let (frame, wo) = (&self.frame, self.wo);
        let local = frame.to_local(toward);
        let (wo_z, wi_z) = if self.flip {
            (-wo.z, -local.z)
        } else {
            (wo.z, local.z)
        };
        let diffuse_density = if wo_z > 0.0 && wi_z > 0.0 {
            wi_z * FRAC_1_PI
        } else {
            0.0
        };
        // A rough metal's: its lobe's value and density, both directions mirrored to the upper
        // hemisphere as `Bsdf::eval` mirrors them (where they are not both above it, the
        // lobe's own test gives zero, as the scalar path's `same_side_upper` does).
        let (wo_upper, wi_upper) = (
            Vec3::new(wo.x, wo.y, wo_z),
            Vec3::new(local.x, local.y, wi_z),
        );
        if self.glossy {
            (
                self.lobe.eval(wo_upper, wi_upper),
                self.lobe.pdf(wo_upper, wi_upper),
            )
        } else {
            (self.albedo * diffuse_density, diffuse_density)
        }
    }
}

/// `given` where `take` holds, else `otherwise`, field by field as selects (which the loop
/// vectorises, where a choice of the whole point was a branch); neither's `spawn`, which the
/// shading keeps apart.
#[inline(always)]
fn point_where(take: bool, given: SurfacePoint, otherwise: SurfacePoint) -> SurfacePoint {
    SurfacePoint {
        p: if take { given.p } else { otherwise.p },
        error: if take { given.error } else { otherwise.error },
        normal: if take { given.normal } else { otherwise.normal },
        spawn: None,
    }
}

/// `offset_ray_origin` with the error-bound method: where `at` was placed on a moving
/// triangle (`moved`), the origin worked out in its object's space for the side of its
/// normal `toward` points to (`spawn`, above and below), else [`offset`]'s.
#[inline(always)]
fn origin_leaving(
    at: &SurfacePoint,
    (moved, [above, below]): (bool, [Vec3; 2]),
    toward: Vec3,
) -> Vec3 {
    let offset = offset(at, toward);
    let spawned = if at.normal.dot(toward) < 0.0 {
        below
    } else {
        above
    };
    if moved { spawned } else { offset }
}

/// `offset_ray_origin` with the error-bound method, for a still surface: `at` moved off its
/// plane to the side `toward` points to, then one float further along each axis it moved, by
/// integer steps on the bits. The scalar path's own (`offset_by_error`) steps with
/// `next_up`/`next_down`, whose branches predict well there: written with these selects, it
/// made the scalar path 7 % slower on the Cornell box (docs/bench.md, thirty-first round), so
/// the lanes keep this twin, held to it bit for bit by `tracer/tests/path_lanes.rs` and
/// `step`'s own test.
#[inline(always)]
fn offset(at: &SurfacePoint, toward: Vec3) -> Vec3 {
    let n = if at.normal.dot(toward) < 0.0 {
        -at.normal
    } else {
        at.normal
    };
    let d = n.abs().dot(at.error);
    let offset = d * n;
    let moved = at.p + offset;
    Vec3::new(
        step(moved.x, offset.x),
        step(moved.y, offset.y),
        step(moved.z, offset.z),
    )
}

/// `x.next_up()` where `along > 0`, `x.next_down()` where `along < 0`, `x` elsewhere, with
/// selects rather than branches: a float's neighbour is the next integer on its bits, up or
/// down by its sign; zero's are the least subnormals; an infinity away from zero and NaN stay.
#[inline(always)]
fn step(x: f32, along: f32) -> f32 {
    let bits = x.to_bits();
    let magnitude = bits & 0x7fff_ffff;
    let up = if magnitude == 0 {
        1
    } else if x > 0.0 {
        bits + 1
    } else {
        bits - 1
    };
    let down = if magnitude == 0 {
        0x8000_0001
    } else if x > 0.0 {
        bits - 1
    } else {
        bits + 1
    };
    let stays_up = x.is_nan() || x == f32::INFINITY;
    let stays_down = x.is_nan() || x == f32::NEG_INFINITY;
    if along > 0.0 && !stays_up {
        f32::from_bits(up)
    } else if along < 0.0 && !stays_down {
        f32::from_bits(down)
    } else {
        x
    }
}

/// The neighbours [`step`] finds are the standard library's, for every kind of float.
#[cfg(test)]
#[test]
fn steps_are_next_up_and_next_down() {
    let values = [
        0.0f32,
        -0.0,
        1.0,
        -1.0,
        1.5e-45,
        -1.5e-45,
        1.0e-40,
        f32::MAX,
        -f32::MAX,
        f32::MIN_POSITIVE,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        3.7e12,
        -2.5e-7,
    ];
    for x in values {
        for (along, expected) in [(1.0, x.next_up()), (-1.0, x.next_down()), (0.0, x)] {
            let stepped = step(x, along);
            assert!(
                stepped.to_bits() == expected.to_bits() || (x.is_nan() && stepped.is_nan()),
                "step({x:e}, {along}) = {stepped:e}, expected {expected:e}"
            );
        }
    }
}
