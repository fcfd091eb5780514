//! Camera rays walked through the tree in packets against the same rays walked one by one: the
//! same hit for every ray, bit for bit, and the same images (`tracer/src/geometry/packet.rs`
//! says why they must be). Brute force over all triangles referees single rays. The families:
//! packets as a pixel's samples make them (one origin, directions a fraction of a degree
//! apart), through a lens (origins apart), grazing an axis (directions whose signs differ,
//! which are traced one by one), exactly along axes (infinite reciprocals, where the packet's
//! box filter stands aside), with ends short of infinity, of one to eight rays, at scales from
//! a millimetre to ten kilometres and far from the origin. Then both box tests (AVX and SSE)
//! against each other: the same hits and the same counted work.

mod common;

use common::rng::Rng;
use glam::Vec3;
use std::path::Path;
use tracer::geometry::{
    Accel, BoxSimd, BuildQuality, Hit, PACKET, Ray, TraversalStats, intersect_brute_force,
};
use tracer::scene::{CameraTrack, Triangle};
use tracer::{CameraRays, World};

fn triangle(p: [Vec3; 3]) -> Triangle {
    Triangle { p, material: 0 }
}

/// A closed box of `2 * half` around `centre` made of many small triangles (shared edges
/// everywhere), with a soup of loose triangles inside it, some of them exact copies (ties in
/// `t` that only the triangle index breaks).
fn scene(rng: &mut Rng, centre: Vec3, half: f32) -> Vec<Triangle> {
    let mut out = Vec::new();
    let cells = 6;
    for axis in 0..3 {
        for side in [-1.0f32, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for i in 0..cells {
                for j in 0..cells {
                    let corner = |a: usize, b: usize| {
                        let mut p = [0.0f32; 3];
                        p[axis] = side * half;
                        p[u] = half * (2.0 * a as f32 / cells as f32 - 1.0);
                        p[v] = half * (2.0 * b as f32 / cells as f32 - 1.0);
                        centre + Vec3::from_array(p)
                    };
                    out.push(triangle([
                        corner(i, j),
                        corner(i + 1, j),
                        corner(i + 1, j + 1),
                    ]));
                    out.push(triangle([
                        corner(i, j),
                        corner(i + 1, j + 1),
                        corner(i, j + 1),
                    ]));
                }
            }
        }
    }
    for _ in 0..300 {
        let v0 = centre
            + Vec3::new(
                rng.range(-0.8, 0.8),
                rng.range(-0.8, 0.8),
                rng.range(-0.8, 0.8),
            ) * half;
        let size = half * [0.01, 0.1, 0.4][rng.index(3)];
        let (v1, v2) = (v0 + rng.direction() * size, v0 + rng.direction() * size);
        out.push(triangle([v0, v1, v2]));
        if rng.index(5) == 0 {
            out.push(triangle([v0, v1, v2]));
        }
    }
    out
}

/// The ways a packet's rays may lie to each other.
#[derive(Clone, Copy, Debug)]
enum Family {
    /// A pixel's samples: one origin, directions within a small cone.
    Pixel,
    /// Through a lens: origins spread over a disc, directions converging.
    Lens,
    /// Around a direction with a zero component: the signs of the rays' directions differ.
    Grazing,
    /// Exactly along an axis, zeros of both signs: infinite reciprocal directions.
    AlongAxes,
    /// As `Pixel`, each ray ending at its own distance.
    Ends,
    /// Rays from a small region in directions that part ways (so that the packet's bound
    /// matters), one of them with a NaN in its origin or its direction: it hits nothing, and
    /// must not keep its companions from their hits.
    Broken,
}

const FAMILIES: [Family; 6] = [
    Family::Pixel,
    Family::Lens,
    Family::Grazing,
    Family::AlongAxes,
    Family::Ends,
    Family::Broken,
];

fn packet(rng: &mut Rng, family: Family, centre: Vec3, half: f32, n: usize) -> Vec<Ray> {
    let origin = centre
        + Vec3::new(
            rng.range(-0.7, 0.7),
            rng.range(-0.7, 0.7),
            rng.range(-0.7, 0.7),
        ) * half;
    let axis = rng.direction();
    let spread = [1e-4, 1e-3, 2e-2][rng.index(3)];
    // In the upper half of the packet's lanes, whose NaN a careless reduction would let take
    // a lower lane's place.
    let broken = n / 2 + rng.index(n - n / 2);
    (0..n)
        .map(|r| {
            let jitter = rng.direction() * spread;
            match family {
                Family::Broken if r == broken => {
                    let mut ray = Ray {
                        origin,
                        dir: axis + jitter,
                        t_max: f32::INFINITY,
                    };
                    match rng.index(4) {
                        0 => ray.origin.x = f32::NAN,
                        1 => ray.origin.z = f32::NAN,
                        2 => ray.dir.y = f32::NAN,
                        _ => ray.dir = Vec3::NAN,
                    }
                    ray
                }
                Family::Pixel => Ray {
                    origin,
                    dir: axis + jitter,
                    t_max: f32::INFINITY,
                },
                Family::Ends => Ray {
                    origin,
                    dir: axis + jitter,
                    t_max: rng.range(0.1, 2.0) * half,
                },
                Family::Broken => Ray {
                    origin: origin + rng.direction() * (0.2 * half),
                    dir: axis + rng.direction() * 0.3,
                    t_max: f32::INFINITY,
                },
                Family::Lens => {
                    let lens = rng.direction() * (0.05 * half);
                    let focus = origin + axis * half;
                    Ray {
                        origin: origin + lens,
                        dir: focus - origin - lens,
                        t_max: f32::INFINITY,
                    }
                }
                Family::Grazing => {
                    let mut dir = axis + jitter;
                    dir.x = rng.range(-1e-3, 1e-3);
                    Ray {
                        origin,
                        dir,
                        t_max: f32::INFINITY,
                    }
                }
                Family::AlongAxes => {
                    let dirs = [
                        Vec3::X,
                        -Vec3::Y,
                        Vec3::new(-0.0, 0.0, 1.0),
                        Vec3::new(0.0, -0.0, -1.0),
                    ];
                    Ray {
                        origin,
                        dir: dirs[rng.index(dirs.len())],
                        t_max: f32::INFINITY,
                    }
                }
            }
        })
        .collect()
}

fn bits(hit: &Option<Hit>) -> Option<(u32, u32, u32, u32)> {
    hit.map(|h| (h.t.to_bits(), h.triangle, h.b1.to_bits(), h.b2.to_bits()))
}

#[test]
fn packets_find_each_rays_own_hit_at_every_scale_distance_and_spread() {
    let mut rng = Rng(0x9ac4_e700);
    let mut hits = 0;
    for (half, centre) in [
        (1e-3, Vec3::ZERO),
        (1.0, Vec3::ZERO),
        (1.0, Vec3::new(1e4, -3e4, 2e4)),
        (1e4, Vec3::new(-1e5, 0.0, 5e4)),
    ] {
        let triangles = scene(&mut rng, centre, half);
        for quality in [BuildQuality::Fastest, BuildQuality::Medium] {
            let accel = Accel::build(&triangles, quality);
            for family in FAMILIES {
                for round in 0..60 {
                    let n = 1 + round % PACKET;
                    let rays = packet(&mut rng, family, centre, half, n);
                    let mut found = vec![None; n];
                    accel.intersect_packet(&rays, &mut found, &mut TraversalStats::default());
                    for (ray, hit) in rays.iter().zip(&found) {
                        let alone = accel.intersect(ray, &mut TraversalStats::default());
                        assert_eq!(
                            bits(hit),
                            bits(&alone),
                            "{family:?}, {half} at {centre}: {ray:?}"
                        );
                        let brute = intersect_brute_force(&triangles, ray);
                        assert_eq!(
                            bits(hit),
                            bits(&brute),
                            "{family:?}, {half} at {centre}: {ray:?}"
                        );
                        hits += hit.is_some() as u32;
                    }
                }
            }
        }
    }
    // Inside a closed box nearly every ray hits something; far fewer would mean the rays
    // missed the scene and the comparison said little.
    assert!(hits > 9000, "only {hits} hits");
}

/// A packet whose rays part ways on one axis, the ray that bounds them there in a lower lane
/// and a ray with a NaN in that axis's origin or direction four lanes above it: the NaN must
/// not take the bounding ray's place in the packet's bound (a reduction that let it did, and
/// the filter then dropped boxes the bounding ray enters), so every ray finds its own hit.
#[test]
fn a_nan_four_lanes_above_the_ray_that_bounds_a_packet_leaves_it_its_hit() {
    let mut rng = Rng(0x9ac4_e702);
    let half = 1.0;
    let triangles = scene(&mut rng, Vec3::ZERO, half);
    let accel = Accel::build(&triangles, BuildQuality::Medium);
    let mut hits = 0;
    for round in 0..800 {
        let origin = Vec3::new(
            rng.range(-0.5, 0.5),
            rng.range(-0.5, 0.5),
            rng.range(-0.5, 0.5),
        );
        let signs = Vec3::new(
            if round % 2 == 0 { 1.0 } else { -1.0 },
            if round % 4 < 2 { 1.0 } else { -1.0 },
            if round % 8 < 4 { 1.0 } else { -1.0 },
        );
        let lane = round % 4;
        let rays: Vec<Ray> = (0..PACKET)
            .map(|r| {
                let mut ray = Ray {
                    origin,
                    dir: Vec3::new(rng.range(0.01, 0.02), rng.range(0.01, 0.02), 1.0) * signs,
                    t_max: f32::INFINITY,
                };
                if r == lane {
                    // The bounding ray: the least origin and reciprocal along x.
                    ray.origin.x -= 0.3 * half;
                    ray.dir.x = rng.range(0.5, 1.5) * signs.x;
                } else if r == lane + 4 {
                    match round % 8 / 4 {
                        0 => ray.origin.x = f32::NAN,
                        _ => ray.dir.x = f32::NAN,
                    }
                }
                ray
            })
            .collect();
        let mut found = vec![None; PACKET];
        accel.intersect_packet(&rays, &mut found, &mut TraversalStats::default());
        for (ray, hit) in rays.iter().zip(&found) {
            let alone = accel.intersect(ray, &mut TraversalStats::default());
            assert_eq!(bits(hit), bits(&alone), "round {round}: {ray:?}");
            hits += hit.is_some() as u32;
        }
    }
    // Seven good rays a packet inside a closed box: nearly all hit.
    assert!(hits > 5000, "only {hits} hits");
}

#[test]
fn the_avx_and_sse_packets_find_the_same_hits_with_the_same_work() {
    let mut rng = Rng(0x9ac4_e701);
    let triangles = scene(&mut rng, Vec3::new(3.0, -2.0, 1.0), 2.0);
    let mut avx = Accel::build(&triangles, BuildQuality::Medium);
    if !avx.set_box_simd(BoxSimd::Avx) {
        eprintln!("skipped: this processor has no AVX, so there is one box test only");
        return;
    }
    let mut sse = avx.clone();
    assert!(sse.set_box_simd(BoxSimd::Sse));
    let (mut avx_work, mut sse_work) = (TraversalStats::default(), TraversalStats::default());
    for round in 0..400 {
        let family = FAMILIES[round % FAMILIES.len()];
        let rays = packet(&mut rng, family, Vec3::new(3.0, -2.0, 1.0), 2.0, PACKET);
        let (mut a, mut b) = (vec![None; PACKET], vec![None; PACKET]);
        avx.intersect_packet(&rays, &mut a, &mut avx_work);
        sse.intersect_packet(&rays, &mut b, &mut sse_work);
        assert_eq!(
            a.iter().map(bits).collect::<Vec<_>>(),
            b.iter().map(bits).collect::<Vec<_>>()
        );
    }
    assert_eq!(avx_work, sse_work);
    assert!(avx_work.nodes > 0 && avx_work.triangles > 0);
}

/// Renders `path` at `size` square and `spp` through `camera_rays`, after `adjust`.
fn render(
    path: &Path,
    size: u32,
    spp: u32,
    camera_rays: CameraRays,
    adjust: &dyn Fn(&mut tracer::scene::Scene),
) -> (Vec<u32>, tracer::PathStats) {
    let mut scene = tracer::scene::load(path).expect("the scene loads");
    scene.settings.width = size;
    scene.settings.height = size;
    scene.settings.samples_per_pixel = spp;
    adjust(&mut scene);
    let mut world = World::prepare(scene, None);
    world.camera_rays = camera_rays;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of two threads builds");
    let out = tracer::render_frame(&world, 0, &pool, tracer::FrameConfig::default());
    (
        out.pixels.iter().flatten().map(|c| c.to_bits()).collect(),
        out.stats,
    )
}

#[test]
fn scenes_render_the_same_bits_with_camera_packets_and_without() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let pinhole: &dyn Fn(&mut tracer::scene::Scene) = &|_| {};
    // A lens on the Cornell box: the packet's origins spread over the aperture.
    let lens: &dyn Fn(&mut tracer::scene::Scene) = &|scene| {
        let mut camera = scene.camera.at_time(0.0);
        camera.aperture_radius = 0.05;
        scene.camera = CameraTrack::fixed(camera);
    };
    for (scene, size, spp, adjust) in [
        ("cornell-box/cornell-box.toml", 32, 11, pinhole),
        ("cornell-box/cornell-box.toml", 32, 9, lens),
        ("glass-cluster-pan/glass-cluster-pan.toml", 32, 8, pinhole),
        ("prism/prism.toml", 24, 3, pinhole),
        ("window-room/window-room.toml", 24, 5, pinhole),
        // Moving objects, asked by each ray after its packet's walk of the still tree: a ball
        // and a turning box under a moving camera; a swinging lamp; fog through a window
        // with a moving object.
        ("cornell-blur/cornell-blur.toml", 24, 5, pinhole),
        ("swinging-lamp/swinging-lamp.toml", 24, 5, pinhole),
        ("fog-window/fog-window.toml", 16, 3, pinhole),
    ] {
        let path = root.join(scene);
        let (packets, work) = render(&path, size, spp, CameraRays::Packets, adjust);
        let (one_by_one, _) = render(&path, size, spp, CameraRays::OneByOne, adjust);
        assert!(
            packets.iter().any(|&b| f32::from_bits(b) > 0.0),
            "{scene}: black"
        );
        let differing = packets
            .iter()
            .zip(&one_by_one)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differing, 0, "{scene}: {differing} channels differ");
        assert!(work.rays > 0);
    }
}

#[test]
fn a_shared_scene_renders_the_same_bits_with_camera_packets_and_without_when_present() {
    // Sponza: 66k triangles, a deep tree, camera rays that pass many nodes. Its files live in
    // ../shared/scenes, outside the repository; without them there is nothing to render.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/shared/sponza.toml");
    if tracer::scene::load(&path).is_err() {
        eprintln!("skipped: {} or its files are absent", path.display());
        return;
    }
    let (packets, _) = render(&path, 40, 8, CameraRays::Packets, &|_| {});
    let (one_by_one, _) = render(&path, 40, 8, CameraRays::OneByOne, &|_| {});
    assert_eq!(packets, one_by_one);
}
