//! Spawn offsets from moving objects: a ray spawned from a hit on a moving object, once taken
//! back into the object's space (where rays meet it), starts strictly on the side it leaves
//! to, at every scale, distance, rotation and scale of the placement; closed moving spheres
//! neither leak nor hit themselves nor shadow their inside.
//!
//! Sides are decided exactly by Shewchuk's `orient3d` (`exact/mod.rs`, see `offsets.rs` for
//! why that predicate), in object space, on the object's own f32 triangle.

mod common;
mod exact;

use common::rng::Rng;
use exact::side;
use glam::{DVec3, Vec3};
use tracer::geometry::{
    BuildQuality, MotionAccel, OffsetMethod, Ray, SurfacePoint, Traversal, TraversalStats,
    hit_point, is_degenerate, offset_ray_origin, placed_point, spawn_ray, spawn_ray_to,
};
use tracer::scene::{Placement, TransformKey, TransformTrack};

/// A random placement: scale per axis from 1e-2 to 1e2 (mirroring or not), any rotation, and a
/// translation of about `10^distance`.
fn placement(rng: &mut Rng, distance: i32) -> (TransformKey, Placement) {
    let scale = Vec3::from_array(std::array::from_fn(|_| {
        let magnitude = 10f32.powf(rng.range(-2.0, 2.0));
        if rng.index(4) == 0 {
            -magnitude
        } else {
            magnitude
        }
    }));
    let key = TransformKey {
        frame: 0,
        scale,
        rotate_degrees: Vec3::new(
            rng.range(-360.0, 360.0),
            rng.range(-360.0, 360.0),
            rng.range(-360.0, 360.0),
        ),
        translate: rng.direction() * 10f32.powi(distance),
    };
    (key, key.placement())
}

/// A triangle of size about `10^scale` at about `10^offset` from the object's origin.
fn triangle(rng: &mut Rng, scale: i32, offset: i32) -> [Vec3; 3] {
    let at = rng.direction() * 10f32.powi(offset) * rng.unit();
    let size = 10f32.powi(scale);
    [0, 1, 2].map(|_| at + rng.direction() * size)
}

/// The world origin spawned from `point` toward `toward`, taken into object space as the ray
/// transform takes it.
fn back(placement: &Placement, point: &SurfacePoint, toward: Vec3) -> Vec3 {
    let origin = offset_ray_origin(point, toward, OffsetMethod::ErrorBound);
    placement.unplace_point(origin.as_dvec3()).as_vec3()
}

#[test]
fn a_spawned_origin_taken_back_into_object_space_is_strictly_on_its_side() {
    let mut rng = Rng(16);
    let mut checked = 0;
    for scale in -4..=4 {
        for offset in [-3, 0, 3, 5] {
            for distance in [-2, 0, 3, 6] {
                for _ in 0..60 {
                    let v = triangle(&mut rng, scale, offset.max(scale));
                    if is_degenerate(&v) {
                        continue;
                    }
                    let (_, placement) = placement(&mut rng, distance);
                    let (b1, b2) = rng.barycentrics();
                    let point = placed_point(&placement, &v, b1, b2);
                    assert!(point.error.is_finite() && point.normal != Vec3::ZERO);
                    let (up, down) = (
                        back(&placement, &point, point.normal),
                        back(&placement, &point, -point.normal),
                    );
                    let what = format!("{v:?} at ({b1}, {b2}) placed by {placement:?}");
                    assert!(side(&v, up) > 0.0, "{what}: {up} not above");
                    assert!(side(&v, down) < 0.0, "{what}: {down} not below");
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 7_000, "{checked}");
}

#[test]
fn without_the_bound_the_origins_taken_back_fall_on_either_side() {
    // The predicate has work to do: offset in the world by one float alone, some origins taken
    // back land on the wrong side (a few in a thousand), so the test above could fail.
    let mut rng = Rng(61);
    let (mut wrong, mut total) = (0, 0);
    for _ in 0..4_000 {
        let scale = rng.index(5) as i32 - 2;
        let v = triangle(&mut rng, scale, 1);
        if is_degenerate(&v) {
            continue;
        }
        let (_, placement) = placement(&mut rng, 2);
        let (b1, b2) = rng.barycentrics();
        let bare = SurfacePoint {
            error: Vec3::ZERO,
            spawn: None,
            ..placed_point(&placement, &v, b1, b2)
        };
        total += 1;
        wrong += (side(&v, back(&placement, &bare, bare.normal)) <= 0.0) as u32;
    }
    eprintln!("{wrong} of {total} on the wrong side");
    assert!(wrong > 0, "{wrong} of {total} on the wrong side");
}

/// What probing one closed moving sphere counted.
#[derive(Debug, Default)]
struct Counts {
    probes: u32,
    primary_leaks: u32,
    bounce_leaks: u32,
    self_hits: u32,
    false_occlusions: u32,
}

/// Probes a closed icosphere of `radius` (level 2, centred on its object's origin) moving
/// between two random placements `distance` from the world's origin, at random times.
fn probe(radius: f32, distance: i32, seed: u64, n: u32) -> Counts {
    let mut rng = Rng(seed);
    let toml = format!(
        "[camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\n[materials.m]\ntype = \"diffuse\"\n\
         [[object]]\nshape = \"sphere\"\nmaterial = \"m\"\nradius = {radius:e}\nsubdivisions = 2\n\
         [[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 1\ntranslate = [1, 0, 0]\n"
    );
    let mut scene = tracer::scene::load_str(&toml).expect("the sphere loads");
    let mut object = scene.moving.pop().expect("the sphere moves");
    let (mut a, _) = placement(&mut rng, distance);
    let (mut b, _) = placement(&mut rng, distance);
    // The same signs at both keys (a scale through zero is refused at load), 1 frame apart.
    b.scale = b.scale.abs() * a.scale.signum();
    (a.frame, b.frame) = (0, 1);
    object.track = TransformTrack::new(vec![a, b]).expect("two keys that differ");
    let v: Vec<[Vec3; 3]> = object.triangles.iter().map(|t| t.p).collect();
    let motion = MotionAccel::build(std::slice::from_ref(&object), 0, BuildQuality::Medium);
    let mut stats = TraversalStats::default();
    let mut counts = Counts::default();
    for _ in 0..n {
        counts.probes += 1;
        let time = f64::from(rng.unit());
        let moment = motion.moment(time);
        let placement = object.track.at(time);
        let world = |p: Vec3| placement.point(p.as_dvec3()).as_vec3();
        let inside = |rng: &mut Rng| world(rng.direction() * (0.3 * radius * rng.unit()));
        let origin = inside(&mut rng);
        let (b1, b2) = rng.barycentrics();
        let target = world(hit_point(&v[rng.index(v.len())], b1, b2));
        let primary = Ray {
            origin,
            dir: target - origin,
            t_max: f32::INFINITY,
        };
        let closest = |ray: &Ray, stats: &mut TraversalStats| {
            motion.closest::<false>(&moment, ray, None, Traversal::Robust, stats)
        };
        let Some(hit) = closest(&primary, &mut stats) else {
            counts.primary_leaks += 1;
            continue;
        };
        let at = motion.locate(hit.triangle).expect("a moving triangle");
        let surface = motion.surface(&moment, at, &hit);
        let normal = surface.normal;
        let inward = if normal.dot(primary.dir) < 0.0 {
            normal
        } else {
            -normal
        };
        let d = rng.direction();
        let dir = if rng.index(2) == 0 {
            if d.dot(inward) < 0.0 { -d } else { d }
        } else {
            // Grazing, but far above the rounding of a direction (see `offsets.rs`).
            d.cross(inward).normalize() + inward * [1e-2, 1e-4][rng.index(2)]
        };
        match closest(
            &spawn_ray(&surface, dir, OffsetMethod::ErrorBound),
            &mut stats,
        ) {
            None => counts.bounce_leaks += 1,
            Some(h) if h.triangle == hit.triangle => counts.self_hits += 1,
            Some(_) => {}
        }
        let lamp = SurfacePoint::exact(inside(&mut rng));
        let shadow = spawn_ray_to(&surface, &lamp, OffsetMethod::ErrorBound);
        counts.false_occlusions +=
            motion.occluded(&moment, &shadow, Traversal::Robust, &mut stats) as u32;
    }
    counts
}

#[test]
fn closed_moving_spheres_neither_leak_nor_self_hit_nor_shadow_their_inside() {
    for exponent in [-4, -2, 0, 2, 4] {
        let radius = 10f32.powi(exponent);
        for distance in [exponent - 1, exponent + 2, exponent + 4] {
            for seed in 0..3 {
                let counts = probe(radius, distance, seed, 400);
                let failures = [
                    counts.primary_leaks,
                    counts.bounce_leaks,
                    counts.self_hits,
                    counts.false_occlusions,
                ];
                assert_eq!(
                    failures, [0; 4],
                    "radius {radius}, 10^{distance} away: {counts:?}"
                );
            }
        }
    }
}

#[test]
fn the_placed_normal_is_the_placed_triangles_and_the_point_lies_on_it() {
    let mut rng = Rng(5);
    for _ in 0..500 {
        let v = triangle(&mut rng, 0, 1);
        let (_, placement) = placement(&mut rng, 1);
        let (b1, b2) = rng.barycentrics();
        let point = placed_point(&placement, &v, b1, b2);
        let w: Vec<DVec3> = v.iter().map(|p| placement.point(p.as_dvec3())).collect();
        let mut normal = (w[1] - w[0]).cross(w[2] - w[0]).normalize();
        // A mirroring placement turns the winding; the front side stays the mapped normal's.
        if placement.linear.determinant() < 0.0 {
            normal = -normal;
        }
        assert!(
            (point.normal.as_dvec3() - normal).length() < 1e-5,
            "{} vs {normal}",
            point.normal
        );
        let exact = w[0] + b1 as f64 * (w[1] - w[0]) + b2 as f64 * (w[2] - w[0]);
        let off = (point.p.as_dvec3() - exact).abs();
        assert!(
            off.cmple(point.error.as_dvec3()).all(),
            "{off} beyond {}",
            point.error
        );
    }
}
