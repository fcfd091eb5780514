//! Hard cases for the geometry module: the places where ray tracers leak light or crash.
//!
//! Each test states the property it checks. The expected answers come from geometry (a closed
//! mesh must be hit from inside, a zero-area triangle can't be hit) or from brute force over all
//! triangles, never from the code under test. Randomness is a local splitmix64 stream with fixed
//! seeds, so every run checks the same rays.

mod common;

use common::rng::Rng;
use glam::{Mat3, Vec3};
use proptest::prelude::*;
use tracer::geometry::{
    Accel, BuildQuality, Hit, OffsetMethod, Ray, TraversalStats, intersect_brute_force,
    intersect_triangle, is_degenerate, occluded_brute_force, offset_ray_origin, spawn_ray,
};
use tracer::scene::Triangle;

/// The BVH against a loop over every triangle.
#[path = "geometry_hard_cases/brute_force.rs"]
mod brute_force;

/// Triangles without area.
#[path = "geometry_hard_cases/degenerate.rs"]
mod degenerate;

fn ray(origin: Vec3, dir: Vec3) -> Ray {
    Ray {
        origin,
        dir,
        t_max: f32::INFINITY,
    }
}

/// An indexed mesh: vertices are shared exactly between the triangles that use them.
#[derive(Clone)]
struct Mesh {
    vertices: Vec<Vec3>,
    faces: Vec<[u32; 3]>,
}

impl Mesh {
    fn triangles(&self) -> Vec<Triangle> {
        let p = |f: &[u32; 3]| f.map(|i| self.vertices[i as usize]);
        let tri = |p| Triangle { p, material: 0 };
        self.faces.iter().map(|f| tri(p(f))).collect()
    }

    /// Applies `x -> rotation * (scale * x) + translation` to every vertex once.
    fn transformed(&self, rotation: Mat3, scale: f32, translation: Vec3) -> Mesh {
        let vertices = self
            .vertices
            .iter()
            .map(|&v| rotation * (v * scale) + translation);
        Mesh {
            vertices: vertices.collect(),
            faces: self.faces.clone(),
        }
    }
}

/// An `n * n` grid of unit quads in the plane z = 0, each split in two along alternating
/// diagonals so that both diagonal orientations occur.
fn quad_grid(n: u32) -> Mesh {
    let index = |i: u32, j: u32| i * (n + 1) + j;
    let vertices = (0..=n)
        .flat_map(|i| (0..=n).map(move |j| Vec3::new(i as f32, j as f32, 0.0)))
        .collect();
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (
                index(i, j),
                index(i + 1, j),
                index(i + 1, j + 1),
                index(i, j + 1),
            );
            if (i + j) % 2 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    Mesh { vertices, faces }
}

/// An icosphere of radius about 1 with `subdivisions` levels, every vertex then moved radially
/// by up to `jitter` (shared vertices move once, so the mesh stays closed).
fn perturbed_sphere(subdivisions: u32, jitter: f32, rng: &mut Rng) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    #[rustfmt::skip]
    let corners = [
        (-1.0, t, 0.0), (1.0, t, 0.0), (-1.0, -t, 0.0), (1.0, -t, 0.0),
        (0.0, -1.0, t), (0.0, 1.0, t), (0.0, -1.0, -t), (0.0, 1.0, -t),
        (t, 0.0, -1.0), (t, 0.0, 1.0), (-t, 0.0, -1.0), (-t, 0.0, 1.0),
    ];
    let mut vertices: Vec<Vec3> = corners
        .map(|(x, y, z)| Vec3::new(x, y, z).normalize())
        .to_vec();
    #[rustfmt::skip]
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints = std::collections::BTreeMap::new();
        let mut midpoint = |a: u32, b: u32, vertices: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let m = (vertices[a as usize] + vertices[b as usize]).normalize();
                vertices.push(m);
                vertices.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut vertices);
            let bc = midpoint(b, c, &mut vertices);
            let ca = midpoint(c, a, &mut vertices);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    for v in &mut vertices {
        *v *= 1.0 + rng.range(-jitter, jitter);
    }
    Mesh { vertices, faces }
}

fn closest(accel: &Accel, ray: &Ray) -> Option<Hit> {
    accel.intersect(ray, &mut TraversalStats::default())
}

/// Checks that both brute force and the BVH hit something, and agree.
fn assert_hit(accel: &Accel, triangles: &[Triangle], r: &Ray, what: &str) {
    let brute = intersect_brute_force(triangles, r);
    assert!(brute.is_some(), "{what}: brute force missed {r:?}");
    assert_eq!(closest(accel, r), brute, "{what}: BVH disagrees on {r:?}");
    assert!(
        accel.occluded(r, &mut TraversalStats::default()),
        "{what}: {r:?}"
    );
}

#[test]
fn rays_at_shared_edges_and_vertices_of_split_quads_never_miss() {
    let mut rng = Rng(1);
    let grid = quad_grid(6);
    for frame in 0..40 {
        let scale = [1e-3, 1.0, 1e3][frame % 3];
        let translation = rng.direction() * scale * rng.range(0.0, 100.0);
        let mesh = grid.transformed(rng.rotation(), scale, translation);
        let normal =
            (mesh.vertices[1] - mesh.vertices[0]).cross(mesh.vertices[7] - mesh.vertices[0]);
        let normal = normal.normalize();
        let triangles = mesh.triangles();
        let accel = Accel::build(&triangles, BuildQuality::Medium);
        let at = |i: u32, j: u32| mesh.vertices[(i * 7 + j) as usize];
        let mut targets = Vec::new();
        for i in 1..6 {
            for j in 1..6 {
                targets.push(at(i, j)); // an interior vertex, shared by 4 to 8 triangles
            }
        }
        for face in &mesh.faces {
            // Points on each edge, the interior ones among them shared by two triangles.
            for k in 0..3 {
                let (a, b) = (
                    mesh.vertices[face[k] as usize],
                    mesh.vertices[face[(k + 1) % 3] as usize],
                );
                targets.push(a + (b - a) * 0.5);
                targets.push(a + (b - a) * rng.unit());
            }
        }
        let interior = |p: Vec3| {
            let local = p - at(0, 0);
            let (u, v) = (
                local.dot(at(6, 0) - at(0, 0)),
                local.dot(at(0, 6) - at(0, 0)),
            );
            let side = (at(6, 0) - at(0, 0)).length_squared();
            u > 1e-3 * side && u < 0.999 * side && v > 1e-3 * side && v < 0.999 * side
        };
        for target in targets.into_iter().filter(|&p| interior(p)) {
            for _ in 0..4 {
                let mut dir = rng.direction();
                if dir.dot(normal).abs() < 0.05 {
                    dir = (dir + normal * 0.2).normalize();
                }
                let origin = target - dir * scale * rng.range(0.5, 20.0);
                assert_hit(
                    &accel,
                    &triangles,
                    &ray(origin, target - origin),
                    "quad grid",
                );
            }
        }
    }
}

#[test]
fn rays_at_the_apex_of_a_triangle_fan_never_miss() {
    let mut rng = Rng(2);
    for fan in 0..120 {
        let n = 8 + (fan % 25) as u32;
        let mut vertices = vec![Vec3::ZERO];
        for k in 0..n {
            let angle = (k as f32 + rng.range(-0.3, 0.3)) * std::f32::consts::TAU / n as f32;
            let radius = rng.range(0.5, 2.0);
            // Small z jitter: the fan stays a graph over the plane with slopes under 10 degrees.
            let z = radius * rng.range(-0.01, 0.01);
            vertices.push(Vec3::new(radius * angle.cos(), radius * angle.sin(), z));
        }
        let faces = (0..n).map(|k| [0, 1 + k, 1 + (k + 1) % n]).collect();
        let scale = [1e-2, 1.0, 1e2, 1e4][fan % 4];
        let rotation = rng.rotation();
        let translation = rng.direction() * scale * rng.range(0.0, 50.0);
        let mesh = Mesh { vertices, faces }.transformed(rotation, scale, translation);
        let triangles = mesh.triangles();
        let accel = Accel::build(&triangles, BuildQuality::Fast);
        let apex = mesh.vertices[0];
        for _ in 0..200 {
            // Within 60 degrees of the fan's axis, from either side.
            let mut local = rng.direction();
            if local.z.abs() < 0.5 {
                local.z = local.z.signum() * 0.5 + local.z;
            }
            let dir = (rotation * local).normalize();
            let origin = apex - dir * scale * rng.range(0.1, 10.0);
            assert_hit(&accel, &triangles, &ray(origin, apex - origin), "fan apex");
        }
    }
}

#[test]
fn every_ray_from_inside_a_closed_perturbed_sphere_hits_it() {
    let mut rng = Rng(3);
    let mesh = perturbed_sphere(4, 0.05, &mut rng);
    let triangles = mesh.triangles();
    let centroid = |i: usize| triangles[i].p.iter().sum::<Vec3>() / 3.0;
    // The mesh is star-shaped around the centre (vertices only move radially), so every point
    // on a segment from the centre to a face is inside.
    let mut origins = vec![Vec3::ZERO, Vec3::new(0.3, -0.2, 0.1)];
    for s in [0.9, 0.999, 0.99999] {
        origins.push(centroid(rng.index(triangles.len())) * s);
    }
    // Random directions, and directions aimed at a vertex or a point on an edge of a random
    // triangle: the rays a non-watertight test lets through (obvhs's Moller-Trumbore test lets
    // about half of the vertex-aimed ones escape).
    let direction = |origin: Vec3, k: usize, rng: &mut Rng| {
        let p = triangles[rng.index(triangles.len())].p;
        match k % 4 {
            0 | 1 => rng.direction(),
            2 => p[rng.index(3)] - origin,
            _ => p[0] + (p[1] - p[0]) * rng.unit() - origin,
        }
    };
    let accel = Accel::build(&triangles, BuildQuality::Medium);
    let mut stats = TraversalStats::default();
    for &origin in &origins {
        for k in 0..100_000 {
            let r = ray(origin, direction(origin, k, &mut rng));
            assert!(accel.intersect(&r, &mut stats).is_some(), "{r:?} escaped");
            assert!(accel.occluded(&r, &mut stats));
            if k % 50 == 0 {
                assert_eq!(
                    accel.intersect(&r, &mut stats),
                    intersect_brute_force(&triangles, &r)
                );
            }
        }
    }
    // Every build quality, including the ones with spatial pre-splits.
    for quality in BuildQuality::ALL {
        let accel = Accel::build(&triangles, quality);
        for &origin in &origins {
            for k in 0..5_000 {
                let r = ray(origin, direction(origin, k, &mut rng));
                assert!(
                    accel.intersect(&r, &mut stats).is_some(),
                    "{quality:?}: {r:?}"
                );
            }
        }
    }
}

/// Axis-aligned unit squares (two triangles each) on integer planes in all three orientations,
/// plus a closed axis-aligned box: boxes, planes and edges coincide everywhere.
fn axis_aligned_lattice(rng: &mut Rng) -> Vec<Triangle> {
    let mut mesh = Mesh {
        vertices: Vec::new(),
        faces: Vec::new(),
    };
    let mut square = |corner: Vec3, u: Vec3, v: Vec3| {
        let base = mesh.vertices.len() as u32;
        mesh.vertices
            .extend([corner, corner + u, corner + u + v, corner + v]);
        mesh.faces
            .extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
    };
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..4 {
                let corner = Vec3::new(i as f32, j as f32, k as f32);
                let normal = rng.index(3);
                if rng.unit() < 0.4 {
                    square(corner, axes[(normal + 1) % 3], axes[(normal + 2) % 3]);
                }
            }
        }
    }
    // The closed box [-1, 5]^3, each face a 2x2 grid of squares of side 3.
    for axis in 0..3 {
        let (u, v) = (axes[(axis + 1) % 3] * 3.0, axes[(axis + 2) % 3] * 3.0);
        for side in [-1.0, 5.0] {
            for (a, b) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                let corner = Vec3::splat(-1.0) + u * a + v * b;
                let corner = corner + axes[axis] * (side - corner[axis]);
                square(corner, u, v);
            }
        }
    }
    mesh.triangles()
}

#[test]
fn zero_tiny_and_subnormal_direction_components_agree_with_brute_force() {
    let mut rng = Rng(4);
    let triangles = axis_aligned_lattice(&mut rng);
    let components = [
        0.0,
        -0.0,
        1e-8,
        -1e-8,
        1e-40, // subnormal: 1 / 1e-40 overflows to infinity
        -1e-40,
        f32::MIN_POSITIVE,
        1.0,
        -1.0,
        0.5,
    ];
    let coordinates = [0.0, 1.0, 2.0, 0.5, 4.0, -1.0, 5.0];
    let accels = [
        BuildQuality::Fastest,
        BuildQuality::Medium,
        BuildQuality::Slow,
    ]
    .map(|quality| Accel::build(&triangles, quality));
    let mut checked = 0;
    let mut hits = 0;
    for _ in 0..150 {
        // Origins on lattice planes, edges and corners, with an occasional random coordinate.
        let mut coordinate = || match rng.index(8) {
            7 => rng.range(-0.5, 4.5),
            i => coordinates[i],
        };
        let origin = Vec3::new(coordinate(), coordinate(), coordinate());
        for &x in &components {
            for &y in &components {
                for &z in &components {
                    let dir = Vec3::new(x, y, z);
                    if dir == Vec3::ZERO {
                        continue;
                    }
                    let t_max = [f32::INFINITY, 1.0, 2.5][rng.index(3)];
                    let r = Ray { origin, dir, t_max };
                    let brute = intersect_brute_force(&triangles, &r);
                    for accel in &accels {
                        assert_eq!(closest(accel, &r), brute, "{r:?} ({accel:?})");
                        // Occlusion counts only hits certainly before t_max: a subset.
                        let occluded = accel.occluded(&r, &mut TraversalStats::default());
                        assert_eq!(occluded, occluded_brute_force(&triangles, &r), "{r:?}");
                        assert!(!occluded || brute.is_some(), "{r:?}");
                    }
                    checked += 1;
                    hits += brute.is_some() as u32;
                }
            }
        }
    }
    // Many rays cannot reach anything: tiny directions with a finite t_max barely move, and
    // with only subnormal components the hit distance would exceed f32's range.
    assert!(
        hits > checked / 8,
        "the rays must meet the lattice: {hits} of {checked}"
    );
}

#[test]
fn secondary_rays_never_rehit_their_own_triangle_at_any_scale() {
    let mut rng = Rng(5);
    let sphere = perturbed_sphere(3, 0.05, &mut rng);
    let mut scene = sphere.clone();
    let floor = quad_grid(4).transformed(Mat3::IDENTITY, 1.0, Vec3::new(-2.0, -2.0, -1.5));
    let base = scene.vertices.len() as u32;
    scene.vertices.extend(&floor.vertices);
    scene
        .faces
        .extend(floor.faces.iter().map(|f| f.map(|i| i + base)));

    let mut configs = Vec::new();
    for scale in [1e-6, 1.0, 1e3, 1e5] {
        configs.push((scale, Vec3::ZERO));
        configs.push((scale, Vec3::new(3e3, -1e3, 2e3) * scale));
    }
    configs.push((1.0, Vec3::new(1e5, -5e4, 7e4)));

    let (mut secondary, mut wrong_side_rehits) = (0, 0);
    for (scale, translation) in configs {
        let mesh = scene.transformed(rng.rotation(), scale, translation);
        let triangles = mesh.triangles();
        let accel = Accel::build(&triangles, BuildQuality::Medium);
        let mut stats = TraversalStats::default();
        for _ in 0..3_000 {
            // Primary rays from outside toward the sphere, and from its centre outward.
            let r = if rng.unit() < 0.5 {
                let target = translation + rng.direction() * scale * 0.8;
                let origin = translation + rng.direction() * scale * 6.0;
                ray(origin, target - origin)
            } else {
                ray(translation, rng.direction())
            };
            let Some(hit) = accel.intersect(&r, &mut stats) else {
                continue;
            };
            let tri = &triangles[hit.triangle as usize];
            let p = hit.surface_point(&tri.p);
            let ng = tri.area_vector().normalize();
            let facing = if ng.dot(r.dir) < 0.0 { ng } else { -ng };
            for side in [facing, -facing] {
                // Reflection (back toward the primary ray's side) and transmission.
                let dir = rng.hemisphere(side);
                let next = spawn_ray(&p, dir, OffsetMethod::ErrorBound);
                if let Some(again) = accel.intersect(&next, &mut stats) {
                    assert_ne!(
                        again.triangle, hit.triangle,
                        "scale {scale}, translation {translation}: {next:?} re-hit at t = {}",
                        again.t
                    );
                }
                secondary += 1;
                // The same ray offset to the wrong side must cross its own triangle: this shows
                // the check above can fail.
                let wrong = Ray {
                    origin: offset_ray_origin(&p, -side, OffsetMethod::ErrorBound),
                    ..next
                };
                let rehit = accel.intersect(&wrong, &mut stats);
                wrong_side_rehits += rehit.is_some_and(|h| h.triangle == hit.triangle) as u32;
            }
        }
    }
    assert!(secondary > 20_000, "{secondary} secondary rays");
    assert!(
        wrong_side_rehits > secondary / 10,
        "offsetting to the wrong side re-hit only {wrong_side_rehits} of {secondary}"
    );
}
