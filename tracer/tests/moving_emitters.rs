//! Moving emitters against closed forms: a small emitting square moving above a diffuse floor
//! (translated, scaled, turned in its plane and tilted during the shutter) lights a point of the
//! floor with the time-average of the static irradiance, by Lambert's exact formula for a
//! polygon, averaged over the shutter by the midpoint rule. The same mean comes out of light
//! sampling alone, of direction (BSDF-like) sampling alone through the tracer's own
//! intersection of moving objects, and of the integrator's combination of the two; the density
//! a BSDF-sampled hit is weighed with equals the one light sampling gave the same point; and an
//! emitter seen directly streaks over exactly the distance it moves.

mod common;

use common::rng::Rng;
use common::{assert_close, assert_same_bits, mean_and_error, render};
use glam::{DVec3, Vec2, Vec3};
use tracer::World;
use tracer::geometry::{Ray, Traversal, TraversalStats};
use tracer::scene::{Scene, load_str};

/// Half the side of the emitting square, its emitted radiance, and the floor's albedo.
const HALF: f64 = 0.15;
const EMISSION: f64 = 4.0;
const ALBEDO: f64 = 0.5;

/// One key of the emitter: where it is (scale, then rotations about x and y, in degrees, then
/// translation), at frames 0 and 1; the shutter `[0, 1]` of frame 0 spans the two.
#[derive(Clone, Copy, Debug)]
struct Pose {
    scale: [f64; 3],
    rotate_x: f64,
    rotate_y: f64,
    translate: [f64; 3],
}

fn pose(translate: [f64; 3]) -> Pose {
    Pose {
        scale: [1.0; 3],
        rotate_x: 0.0,
        rotate_y: 0.0,
        translate,
    }
}

/// The families of motion: speeds and directions, a uniform and an anisotropic scaling key
/// (which change the area), a turn in the square's plane and a tilt (which turns its normal).
fn cases() -> Vec<(&'static str, Pose, Pose)> {
    vec![
        (
            "slow along x",
            pose([-0.2, 1.0, 0.0]),
            pose([0.2, 1.0, 0.0]),
        ),
        (
            "fast along x",
            pose([-1.0, 1.0, 0.1]),
            pose([1.0, 1.0, 0.1]),
        ),
        (
            "diagonal, rising",
            pose([-0.5, 0.7, -0.5]),
            pose([0.6, 1.2, 0.4]),
        ),
        (
            "growing",
            pose([0.3, 1.0, 0.0]),
            Pose {
                scale: [2.5; 3],
                ..pose([0.3, 1.0, 0.0])
            },
        ),
        (
            "stretching while moving",
            pose([0.0, 0.8, -0.4]),
            Pose {
                scale: [3.0, 1.0, 0.5],
                ..pose([0.2, 0.9, 0.3])
            },
        ),
        (
            "turning in its plane",
            pose([0.4, 1.0, 0.0]),
            Pose {
                scale: [2.0, 1.0, 1.0],
                rotate_y: 90.0,
                ..pose([0.4, 1.0, 0.0])
            },
        ),
        (
            "tilting",
            pose([0.0, 1.0, 0.2]),
            Pose {
                rotate_x: 50.0,
                ..pose([0.0, 1.0, 0.2])
            },
        ),
    ]
}

fn key_toml(frame: u32, p: &Pose) -> String {
    let [sx, sy, sz] = p.scale;
    let [tx, ty, tz] = p.translate;
    format!(
        "[[object.keys]]\nframe = {frame}\nscale = [{sx}, {sy}, {sz}]\nrotate_x = {}\n\
         rotate_y = {}\ntranslate = [{tx}, {ty}, {tz}]\n",
        p.rotate_x, p.rotate_y
    )
}

/// The floor `y = 0` seen at its origin through a narrow camera from the side, lit by the
/// moving square alone (`max_depth = 1`: direct light only), which faces down.
fn floor_toml(a: &Pose, b: &Pose, spp: u32) -> String {
    floor_toml_at([0.0; 3], a, b, spp)
}

/// [`floor_toml`] with the whole scene (floor, camera and the lamp's keys) moved by `origin`.
fn floor_toml_at(origin: [f64; 3], a: &Pose, b: &Pose, spp: u32) -> String {
    let h = HALF;
    let [ox, oy, oz] = origin;
    let moved = |p: &Pose| Pose {
        translate: [
            p.translate[0] + ox,
            p.translate[1] + oy,
            p.translate[2] + oz,
        ],
        ..*p
    };
    format!(
        "[render]\nwidth = 8\nheight = 8\nspp = {spp}\nmax_depth = 1\n\
         [camera]\nposition = [{}, {}, {oz}]\nlook_at = [{ox}, {oy}, {oz}]\nvfov = 0.05\n\
         shutter = [0, 1]\n\
         [materials.floor]\ntype = \"diffuse\"\nalbedo = {ALBEDO}\n\
         [materials.lamp]\ntype = \"diffuse\"\nalbedo = 0\nemission = {EMISSION}\n\
         [[object]]\nshape = \"quad\"\n\
         corners = [[{}, {oy}, {}], [{}, {oy}, {}], [{}, {oy}, {}], [{}, {oy}, {}]]\n\
         material = \"floor\"\n\
         [[object]]\nshape = \"quad\"\n\
         corners = [[{}, 0, {}], [{h}, 0, {}], [{h}, 0, {h}], [{}, 0, {h}]]\n\
         material = \"lamp\"\n{}{}",
        ox + 3.0,
        oy + 2.0,
        ox - 20.0,
        oz - 20.0,
        ox - 20.0,
        oz + 20.0,
        ox + 20.0,
        oz + 20.0,
        ox + 20.0,
        oz - 20.0,
        -h,
        -h,
        -h,
        -h,
        key_toml(0, &moved(a)),
        key_toml(1, &moved(b))
    )
}

/// `p` placed by the pose at fraction `s` of the way from `a` to `b`, as the tracer interpolates
/// keys (each value linearly; rotation about x, then y).
fn place(a: &Pose, b: &Pose, s: f64, p: DVec3) -> DVec3 {
    let lerp = |x: f64, y: f64| x + s * (y - x);
    let scale = DVec3::new(
        lerp(a.scale[0], b.scale[0]),
        lerp(a.scale[1], b.scale[1]),
        lerp(a.scale[2], b.scale[2]),
    );
    let q = p * scale;
    let (sx, cx) = lerp(a.rotate_x, b.rotate_x).to_radians().sin_cos();
    let q = DVec3::new(q.x, cx * q.y - sx * q.z, sx * q.y + cx * q.z);
    let (sy, cy) = lerp(a.rotate_y, b.rotate_y).to_radians().sin_cos();
    let q = DVec3::new(cy * q.x + sy * q.z, q.y, -sy * q.x + cy * q.z);
    q + DVec3::from(std::array::from_fn::<f64, 3, _>(|i| {
        lerp(a.translate[i], b.translate[i])
    }))
}

/// Irradiance at the floor's origin from the square placed at `s`, by Lambert's formula: half
/// the radiance times the sum over edges of the angle each subtends times the cosine of its
/// plane's normal with the floor's; zero when the square shows the floor its back.
fn irradiance(a: &Pose, b: &Pose, s: f64) -> f64 {
    let h = HALF;
    let corners =
        [[-h, -h], [h, -h], [h, h], [-h, h]].map(|[x, z]| place(a, b, s, DVec3::new(x, 0.0, z)));
    let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
    if corners[0].dot(normal) >= 0.0 {
        return 0.0;
    }
    let sum: f64 = (0..4)
        .map(|i| {
            let (u, v) = (corners[i].normalize(), corners[(i + 1) % 4].normalize());
            u.dot(v).clamp(-1.0, 1.0).acos() * u.cross(v).normalize().y
        })
        .sum();
    0.5 * EMISSION * sum.abs()
}

/// The irradiance averaged over the shutter, by the midpoint rule on 4096 steps.
fn mean_irradiance(a: &Pose, b: &Pose) -> f64 {
    let n = 4096;
    (0..n)
        .map(|k| irradiance(a, b, (f64::from(k) + 0.5) / f64::from(n)))
        .sum::<f64>()
        / f64::from(n)
}

fn load(toml: &str) -> Scene {
    let scene = load_str(toml).expect("the moving-lamp scene loads");
    let lamp = &scene.moving[0].triangles[0].p;
    let n = (lamp[1] - lamp[0]).cross(lamp[2] - lamp[0]);
    assert!(n.y < 0.0, "the lamp faces down, onto the floor: {n}");
    scene
}

#[test]
fn a_moving_lamp_lights_the_floor_with_the_time_average_of_the_static_closed_form() {
    for (what, a, b) in cases() {
        let scene = load(&floor_toml(&a, &b, 64));
        let out = render(&scene, None, 0);
        let expected = (ALBEDO / std::f64::consts::PI * mean_irradiance(&a, &b)) as f32;
        assert!(expected > 1e-3, "{what}: the case lights the floor");
        assert_close(what, mean_and_error(&out), Vec3::splat(expected), 0.01);
    }
}

#[test]
fn a_moving_lamp_far_from_the_origin_lights_the_floor_the_same() {
    // Spawn offsets and the shadow ray's end near the lamp grow with the coordinates; light
    // that reaches the floor must not be lost to the lamp occluding its own samples there.
    for origin in [[1000.0, 500.0, -700.0], [-30000.0, 0.0, 20000.0]] {
        for (what, a, b) in cases() {
            let scene = load(&floor_toml_at(origin, &a, &b, 64));
            let out = render(&scene, None, 0);
            let expected = (ALBEDO / std::f64::consts::PI * mean_irradiance(&a, &b)) as f32;
            let what = format!("{what} at {origin:?}");
            assert_close(&what, mean_and_error(&out), Vec3::splat(expected), 0.01);
        }
    }
}

#[test]
fn light_sampling_alone_and_bsdf_sampling_alone_give_the_same_mean_with_consistent_densities() {
    let n = 200_000;
    for (what, a, b) in cases() {
        let scene = load(&floor_toml(&a, &b, 1));
        let world = World::prepare(scene, None);
        let first = world.scene.triangles.len() as u32;
        let expected = mean_irradiance(&a, &b);
        let x = Vec3::ZERO;
        let mut rng = Rng(0x5eed_0000 + what.len() as u64);
        let (mut nee, mut nee_sq, mut bsdf, mut bsdf_sq) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            // The time of a path in frame 0 with the shutter [0, 1]: the fraction itself.
            let moment = world.motion.moment(f64::from(rng.unit()));
            // Light sampling: E = L cos / pdf, the density including the choice of light.
            let u = Vec2::new(rng.unit(), rng.unit());
            if let Some(light) = world.lights.sample(&world.scene, &moment, x, rng.unit(), u) {
                let cos = f64::from(light.wi.y.max(0.0));
                let e = f64::from(light.radiance.x) * cos / f64::from(light.pdf);
                (nee, nee_sq) = (nee + e, nee_sq + e * e);
                // What a BSDF-sampled ray finding the same point would be weighed with. The
                // square's two triangles share their area and normal, so either names it.
                let pdf = world.lights.triangle_pdf(&moment, first, x, light.at.p);
                let relative = (pdf - light.pdf).abs() / light.pdf;
                assert!(relative < 1e-4, "{what}: pdf {pdf} vs {}", light.pdf);
            }
            // Sampling directions instead, uniformly over the floor's hemisphere (as a BSDF
            // sampling would, with a known density): E = 2 pi L cos where the ray meets the
            // lamp's front, found by the tracer's intersection of moving objects.
            let dir = rng.hemisphere(Vec3::Y);
            let ray = Ray {
                origin: Vec3::new(0.0, 1e-4, 0.0),
                dir,
                t_max: f32::INFINITY,
            };
            let mut stats = TraversalStats::default();
            let hit =
                world
                    .motion
                    .closest::<false>(&moment, &ray, None, Traversal::Robust, &mut stats);
            if let Some(hit) = hit {
                let at = world
                    .motion
                    .locate(hit.triangle)
                    .expect("a moving triangle");
                let normal = world.motion.surface(&moment, at, &hit).normal;
                if dir.dot(normal) < 0.0 {
                    let e = std::f64::consts::TAU * EMISSION * f64::from(dir.y);
                    (bsdf, bsdf_sq) = (bsdf + e, bsdf_sq + e * e);
                }
            }
        }
        let n = f64::from(n);
        for (name, sum, sq) in [("light", nee, nee_sq), ("bsdf", bsdf, bsdf_sq)] {
            let mean = sum / n;
            let se = ((sq / n - mean * mean).max(0.0) / n).sqrt();
            assert!(
                (mean - expected).abs() <= 4.0 * se + 0.01 * expected,
                "{what}: {name} sampling gives {mean}, expected {expected} (se {se})"
            );
        }
    }
}

#[test]
fn forced_effects_give_the_specialised_bits_with_a_moving_lamp() {
    for (what, a, b) in cases().into_iter().take(4) {
        let scene = load(&floor_toml(&a, &b, 4));
        assert_same_bits(what, &scene, 0);
    }
}

/// A vertical emitting strip, `2 HALF_STRIP` wide, seen straight on against black, moving along
/// x by `shift` over the shutter: each column's expected value is the emission times the share
/// of the column's width and of the exposure the strip covers.
const HALF_STRIP: f64 = 0.1;
const STRIP_VFOV: f64 = 10.0;

fn strip_toml(shift: f64, spp: u32) -> String {
    let (h, l) = (HALF_STRIP, 4.0);
    format!(
        "[render]\nwidth = 160\nheight = 8\nspp = {spp}\nmax_depth = 0\n\
         [camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nvfov = {STRIP_VFOV}\n\
         shutter = [0, 1]\n\
         [materials.lamp]\ntype = \"diffuse\"\nalbedo = 0\nemission = 1\n\
         [[object]]\nshape = \"quad\"\n\
         corners = [[{}, {}, 0], [{}, {l}, 0], [{h}, {l}, 0], [{h}, {}, 0]]\n\
         material = \"lamp\"\n\
         [[object.keys]]\nframe = 0\ntranslate = [{}, 0, 1]\n\
         [[object.keys]]\nframe = 1\ntranslate = [{}, 0, 1]\n",
        -h,
        -l,
        -h,
        -l,
        -shift / 2.0,
        shift / 2.0
    )
}

#[test]
fn a_moving_emitter_seen_directly_streaks_over_the_distance_it_moved() {
    for shift in [0.0, 0.15, 0.4] {
        let (width, height, spp) = (160u32, 8u32, 64u32);
        let scene = load_str(&strip_toml(shift, spp)).expect("the strip scene loads");
        let out = render(&scene, None, 0);
        // Pixels per unit on the strip's plane, one unit from the camera; the motion is
        // symmetric about the image's centre, so the image's mirroring does not matter.
        let ppu = f64::from(height) / (2.0 * (STRIP_VFOV / 2.0).to_radians().tan());
        let mut total = 0.0f64;
        for column in 0..width {
            let x0 = (f64::from(column) - f64::from(width) / 2.0) / ppu;
            let x1 = x0 + 1.0 / ppu;
            let steps = 2048;
            let expected = (0..steps)
                .map(|k| {
                    let c = shift * ((f64::from(k) + 0.5) / f64::from(steps) - 0.5);
                    let overlap = (x1.min(c + HALF_STRIP) - x0.max(c - HALF_STRIP)).max(0.0);
                    overlap / (x1 - x0)
                })
                .sum::<f64>()
                / f64::from(steps);
            let values: Vec<f64> = (0..height)
                .map(|row| f64::from(out.pixels[(row * width + column) as usize][0]))
                .collect();
            let mean = values.iter().sum::<f64>() / f64::from(height);
            total += mean;
            // A sample is 0 or 1: the binomial error of the column's samples, and a little for
            // the midpoint rule.
            let n = f64::from(height * spp);
            let se = (expected * (1.0 - expected) / n).sqrt();
            assert!(
                (mean - expected).abs() <= 4.0 * se + 0.01,
                "shift {shift}: column {column} is {mean}, expected {expected}"
            );
        }
        // The streak holds the strip's light, spread over its width plus the distance moved.
        let strip = 2.0 * HALF_STRIP * ppu;
        assert!(
            (total - strip).abs() <= 0.01 * strip + 0.5,
            "shift {shift}: the streak sums to {total} columns, the strip is {strip}"
        );
    }
}
