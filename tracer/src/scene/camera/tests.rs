//! The camera's rays: the track's poses, the lens, and the rays made eight at a time held
//! to the rays made alone.

use super::*;

fn cam(x: f32) -> Camera {
    Camera {
        position: Vec3::new(x, 0.0, 0.0),
        look_at: Vec3::new(x, 0.0, 1.0),
        up: Vec3::Y,
        vfov_degrees: 40.0,
        aperture_radius: 0.0,
        focus_distance: 1.0,
    }
}

#[test]
fn track_interpolates_and_holds() {
    let track = CameraTrack::new(vec![
        CameraKey {
            frame: 10,
            camera: cam(1.0),
        },
        CameraKey {
            frame: 0,
            camera: cam(0.0),
        },
    ])
    .unwrap();
    assert_eq!(track.at(5).position.x, 0.5);
    assert_eq!(track.at(20).position.x, 1.0);
    assert!(CameraTrack::new(vec![]).is_none());
}

#[test]
fn centre_ray_looks_forward_and_corners_span_the_fov() {
    let rays = cam(0.0).rays(100, 50);
    assert!((rays.ray(50.0, 25.0).dir - Vec3::Z).length() < 1e-6);
    let top = rays.ray(50.0, 0.0).dir;
    assert!((top.y.atan2(top.z).to_degrees() - 20.0).abs() < 1e-4);
    // Image x grows to the right of the view: with up +y and forward +z, right is -x.
    assert!(rays.ray(100.0, 25.0).dir.x < 0.0);
}

#[test]
fn lens_rays_start_on_the_disk_and_meet_on_the_focus_plane() {
    let camera = Camera {
        aperture_radius: 0.5,
        focus_distance: 3.0,
        ..cam(0.0)
    };
    let rays = camera.rays(100, 50);
    let pinhole = rays.ray(30.0, 10.0);
    let on_plane = pinhole.dir * (3.0 / pinhole.dir.z);
    for lens in [
        Vec2::new(0.1, 0.9),
        Vec2::new(0.7, 0.2),
        Vec2::new(0.5, 0.5),
    ] {
        let ray = rays.ray_through_lens(30.0, 10.0, lens);
        assert!(ray.origin.z == 0.0 && ray.origin.length() <= 0.5 + 1e-6);
        let t = (3.0 - ray.origin.z) / ray.dir.z;
        let hit = ray.origin + ray.dir * t;
        assert!(
            (hit - on_plane).length() < 1e-5,
            "{lens}: {hit} vs {on_plane}"
        );
    }
    // The map fills the disk uniformly: a quarter of the area lies within half the radius.
    let n = 64;
    let inner = (0..n * n)
        .filter(|i| {
            let u = Vec2::new((i % n) as f32 + 0.5, (i / n) as f32 + 0.5) / n as f32;
            crate::math::concentric_disk(u).length() < 0.5
        })
        .count();
    assert!(
        (inner as f32 / (n * n) as f32 - 0.25).abs() < 0.01,
        "{inner}"
    );
    let pinhole_camera = cam(0.0).rays(100, 50);
    assert!(!pinhole_camera.has_lens());
    assert_eq!(
        pinhole_camera
            .ray_through_lens(30.0, 10.0, Vec2::new(0.1, 0.9))
            .dir,
        pinhole.dir
    );
}

/// Eight rays made at once are each the ray made alone, to the bit: cameras far from the
/// origin and at it, narrow and wide, looking along an axis and askew, upright and rolled
/// (so that every axis of the view has every coordinate), square images and long ones;
/// positions at the image's corners, its centre, outside it and scattered.
#[test]
fn rays_made_eight_at_a_time_are_the_rays_made_alone() {
    // Position, target, up, vertical field of view, image size.
    let cameras = [
        (Vec3::ZERO, Vec3::Z, Vec3::Y, 40.0, (256, 256)),
        (
            Vec3::new(3e5, -2e4, 7e3),
            Vec3::new(3e5 + 1.0, -2e4 + 0.3, 7e3 - 2.0),
            Vec3::new(0.3, 1.0, -0.2),
            90.0,
            (640, 90),
        ),
        (
            Vec3::new(1e-3, 2e-3, -5e-4),
            Vec3::new(-1.0, 0.5, 0.25),
            Vec3::new(-0.7, 0.1, 1.0),
            5.0,
            (17, 4093),
        ),
        (
            Vec3::new(278.0, 273.0, -800.0),
            Vec3::new(278.0, 273.0, 0.0),
            Vec3::Y,
            39.3,
            (512, 512),
        ),
    ];
    let mut next = uniform_stream(0x9e37_79b9);
    for (position, look_at, up, vfov_degrees, (w, h)) in cameras {
        let rays = pinhole(position, look_at, up, vfov_degrees).rays(w, h);
        let (w, h) = (w as f32, h as f32);
        let mut positions = vec![
            [0.0, 0.0],
            [w, h],
            [w, 0.0],
            [0.0, h],
            [0.5 * w, 0.5 * h],
            [-3.0, h + 7.5],
            [w * 40.0, -h],
            [1e-30, 0.999_999_9],
        ];
        positions.extend((0..400).map(|_| [next() * w, next() * h]));
        for eight in positions.chunks_exact(PACKET) {
            let x: [f32; PACKET] = std::array::from_fn(|k| eight[k][0]);
            let y: [f32; PACKET] = std::array::from_fn(|k| eight[k][1]);
            let mut together = [crate::geometry::UNUSED_RAY; PACKET];
            rays.rays_into(&x, &y, &mut together);
            for k in 0..PACKET {
                let alone = rays.ray(x[k], y[k]);
                assert_eq!(
                    ray_bits(&together[k]),
                    ray_bits(&alone),
                    "({}, {})",
                    x[k],
                    y[k]
                );
            }
        }
    }
}

/// A moving pinhole's eight rays, each from its own pose, are the rays its pose makes
/// alone, to the bit: tracks that dolly far from the origin and near it, roll (`up`
/// turning, so every coordinate's sums matter), narrow and widen the field of view or
/// keep it (the tangent then shared), at times before the first key, between keys, on
/// them and after the last, and positions in and out of the image.
#[test]
fn a_moving_pinholes_rays_made_eight_at_a_time_are_each_poses_rays() {
    let key = |frame, position, look_at, up, vfov_degrees| CameraKey {
        frame,
        camera: pinhole(position, look_at, up, vfov_degrees),
    };
    let tracks = [
        // Looking straight along +z with a target's x of -0.0: the forward axis's x is then
        // -0.0 and the up axis's +0.0, whose signs reach the ray through the image's middle
        // column (its x offset exactly zero).
        vec![
            key(0, Vec3::ZERO, Vec3::new(-0.0, 0.0, 5.0), Vec3::Y, 45.0),
            key(
                4,
                Vec3::new(0.0, 2.0, 0.0),
                Vec3::new(-0.0, 2.0, 5.0),
                Vec3::Y,
                45.0,
            ),
        ],
        vec![
            key(
                0,
                Vec3::new(2.5, 2.73, -8.0),
                Vec3::new(2.5, 2.73, 0.0),
                Vec3::Y,
                39.3,
            ),
            key(
                23,
                Vec3::new(3.06, 2.73, -8.0),
                Vec3::new(3.06, 2.73, 0.0),
                Vec3::Y,
                39.3,
            ),
        ],
        vec![
            key(
                2,
                Vec3::new(3e5, -2e4, 7e3),
                Vec3::new(3e5 + 1.0, -2e4, 7e3),
                Vec3::Y,
                90.0,
            ),
            key(
                3,
                Vec3::new(3e5, -2e4 + 5.0, 7e3),
                Vec3::ZERO,
                Vec3::new(0.3, 1.0, -0.2),
                20.0,
            ),
            key(
                9,
                Vec3::new(1e-3, 2e-3, -5e-4),
                Vec3::X,
                Vec3::new(-0.7, 0.1, 1.0),
                5.0,
            ),
        ],
    ];
    let mut next = uniform_stream(0x2545_f491);
    let mut compared = 0;
    for keys in tracks {
        let track = CameraTrack::new(keys).expect("keys at distinct frames");
        let last = f64::from(track.keys().last().expect("a key").frame);
        for (w, h) in [(256, 256), (640, 90), (17, 4093)] {
            for round in 0..60 {
                let times: [f64; PACKET] = std::array::from_fn(|k| match (round + k) % 5 {
                    0 => f64::from((next() * (last as f32 + 1.0)) as u32),
                    1 => -0.5,
                    2 => last + 0.25,
                    _ => f64::from(next()) * (last + 1.0) - 0.5,
                });
                let (wf, hf) = (w as f32, h as f32);
                let x: [f32; PACKET] = std::array::from_fn(|k| match k {
                    0 => 0.0,
                    1 => wf * 3.0,
                    2 => wf * 0.5,
                    _ => next() * wf,
                });
                let y: [f32; PACKET] = std::array::from_fn(|k| match k {
                    0 => hf,
                    1 => -7.5,
                    _ => next() * hf,
                });
                let mut together = [crate::geometry::UNUSED_RAY; PACKET];
                track.pinhole_rays_into(&times, (w, h), (&x, &y), &mut together);
                for k in 0..PACKET {
                    let alone = track.at_time(times[k]).rays(w, h).ray(x[k], y[k]);
                    let at = (times[k], x[k], y[k]);
                    assert_eq!(
                        ray_bits(&together[k]),
                        ray_bits(&alone),
                        "{w}x{h} at {at:?}"
                    );
                    compared += 1;
                }
            }
        }
    }
    assert_eq!(compared, 3 * 3 * 60 * PACKET);
}

/// Numbers in [0, 1] from a xorshift stream, so that every run checks the same cases.
fn uniform_stream(mut state: u32) -> impl FnMut() -> f32 {
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    }
}

/// A ray's every bit: origin, direction and end.
fn ray_bits(r: &Ray) -> [u32; 7] {
    let [a, b, c] = r.origin.to_array();
    let [d, e, f] = r.dir.to_array();
    [a, b, c, d, e, f, r.t_max].map(f32::to_bits)
}

/// A pinhole camera (no lens).
fn pinhole(position: Vec3, look_at: Vec3, up: Vec3, vfov_degrees: f32) -> Camera {
    Camera {
        position,
        look_at,
        up,
        vfov_degrees,
        aperture_radius: 0.0,
        focus_distance: 1.0,
    }
}
