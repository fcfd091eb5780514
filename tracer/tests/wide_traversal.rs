//! The 8-wide traversal the renderer uses against the binary one it replaced: the same hits for
//! every ray, bit for bit, and the same images, since the wide one only changes which nodes are
//! opened and in which order (`tracer/src/geometry/wide.rs`). Brute force over all triangles is
//! the referee for single rays; for images the binary traversal is, which earlier tests held to
//! brute force in turn. And the wide traversal's two box tests (AVX, chosen at run time, and
//! SSE) against each other: the same hits, the same counted work and the same image bits.

mod common;

use common::rng::Rng;
use glam::Vec3;
use std::path::Path;
use tracer::World;
use tracer::geometry::{
    Accel, BoxSimd, BuildQuality, Ray, Traversal, TraversalStats, intersect_brute_force,
    occluded_brute_force,
};
use tracer::scene::Triangle;

fn triangle(p: [Vec3; 3]) -> Triangle {
    Triangle { p, material: 0 }
}

/// Triangles of many sizes in a 10-wide cube, with an exact copy of some (a tie in `t` that
/// only the triangle index breaks) and a shared edge between pairs (where watertightness
/// matters).
/// Ray `i` of a probe: from a random point of the soup's box, in a random direction or, when
/// `axes` are given, along one of them; every third ray ends at a random distance. The draws
/// are made in one order, so a seed gives the same rays.
fn probe_ray(rng: &mut Rng, i: usize, axes: Option<[Vec3; 3]>) -> Ray {
    let origin = Vec3::new(
        rng.range(-7.0, 7.0),
        rng.range(-7.0, 7.0),
        rng.range(-7.0, 7.0),
    );
    let mut dir = rng.direction();
    if let Some(axes) = axes {
        dir = axes[rng.index(3)];
    }
    let t_max = if i.is_multiple_of(3) {
        rng.range(0.5, 12.0)
    } else {
        f32::INFINITY
    };
    Ray { origin, dir, t_max }
}

fn soup(rng: &mut Rng, n: usize) -> Vec<Triangle> {
    let mut out = Vec::new();
    for _ in 0..n {
        let v0 = Vec3::new(
            rng.range(-5.0, 5.0),
            rng.range(-5.0, 5.0),
            rng.range(-5.0, 5.0),
        );
        let size = [0.05, 0.5, 3.0][rng.index(3)];
        let v1 = v0 + rng.direction() * size;
        let v2 = v0 + rng.direction() * size;
        out.push(triangle([v0, v1, v2]));
        match rng.index(4) {
            0 => out.push(triangle([v0, v1, v2])),
            1 => out.push(triangle([v1, v0, v0 + rng.direction() * size])),
            _ => {}
        }
    }
    out
}

#[test]
fn wide_binary_and_brute_force_agree_on_every_ray_at_every_build_quality() {
    let mut rng = Rng(0x5eed_0012);
    let triangles = soup(&mut rng, 700);
    for quality in BuildQuality::ALL {
        let accel = Accel::build(&triangles, quality);
        let (mut wide_stats, mut binary_stats) =
            (TraversalStats::default(), TraversalStats::default());
        let mut hits = 0;
        for i in 0..4000 {
            // Axis-aligned directions, zeros of both signs included: the slab test's NaN cases.
            let axes = [Vec3::X, -Vec3::Y, Vec3::new(-0.0, 0.0, 1.0)];
            let ray = probe_ray(&mut rng, i, (i % 7 == 0).then_some(axes));
            let expected = intersect_brute_force(&triangles, &ray);
            let wide = accel.intersect_with(&ray, Traversal::Robust, &mut wide_stats);
            let binary = accel.intersect_with(&ray, Traversal::RobustBinary, &mut binary_stats);
            assert_eq!(wide, expected, "{quality:?} {ray:?}");
            assert_eq!(binary, expected, "{quality:?} {ray:?}");
            hits += expected.is_some() as u32;
            let blocked = occluded_brute_force(&triangles, &ray);
            assert_eq!(
                accel.occluded_with(&ray, Traversal::Robust, &mut wide_stats),
                blocked
            );
            assert_eq!(
                accel.occluded_with(&ray, Traversal::RobustBinary, &mut binary_stats),
                blocked
            );
        }
        assert!(
            hits > 1000,
            "{quality:?}: only {hits} hits, the soup is too thin"
        );
        // An 8-wide node tests all its children's boxes in one step, so the wide tree tests
        // somewhat more boxes than the binary one (a tenth more with the Fastest tree here) in far
        // fewer steps; a collapse that left nodes mostly empty would test many more.
        assert!(
            wide_stats.nodes < binary_stats.nodes * 3 / 2,
            "{quality:?}: the wide tree tested {} boxes, the binary {}",
            wide_stats.nodes,
            binary_stats.nodes
        );
    }
}

/// Renders `scene` at its own settings, shrunk to `size` square, through `traversal`.
fn render_bits(path: &Path, size: u32, spp: u32, traversal: Traversal) -> Vec<u32> {
    render_with(path, size, spp, traversal, None).0
}

/// [`render_bits`] with the wide traversal's box test forced to `simd` (when given and this
/// processor runs it; `None` in the result when it does not), and the counted work.
fn render_with(
    path: &Path,
    size: u32,
    spp: u32,
    traversal: Traversal,
    simd: Option<BoxSimd>,
) -> (Vec<u32>, Option<tracer::PathStats>) {
    let mut scene = tracer::scene::load(path).expect("the shipped scene loads");
    scene.settings.width = size;
    scene.settings.height = size;
    scene.settings.samples_per_pixel = spp;
    let mut world = World::prepare(scene, None);
    // A world frees the binary tree, and the wide walk answers alone (with the leaves'
    // triangles read from their groups); a comparison traversal builds the tree again.
    assert!(
        !world.accel().has_binary_tree(),
        "a world keeps the wide tree alone"
    );
    world.set_traversal(traversal);
    assert_eq!(
        world.accel().has_binary_tree(),
        traversal != Traversal::Robust,
        "{traversal:?}"
    );
    if let Some(simd) = simd
        && !world.set_box_simd(simd)
    {
        return (Vec::new(), None);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of two threads builds");
    let out = tracer::render_frame(&world, 0, &pool, tracer::FrameConfig::default());
    let bits = out.pixels.iter().flatten().map(|c| c.to_bits()).collect();
    (bits, Some(out.stats))
}

#[test]
fn shipped_scenes_render_the_same_bits_through_the_wide_and_the_binary_tree() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for (scene, size, spp) in [
        ("cornell-box/cornell-box.toml", 48, 4),
        ("glass-cluster-pan/glass-cluster-pan.toml", 48, 4),
        ("point-in-sphere/point-in-sphere.toml", 32, 4),
    ] {
        let path = root.join(scene);
        let wide = render_bits(&path, size, spp, Traversal::Robust);
        let binary = render_bits(&path, size, spp, Traversal::RobustBinary);
        assert!(
            wide.iter().any(|&b| f32::from_bits(b) > 0.0),
            "{scene}: black"
        );
        let differing = wide.iter().zip(&binary).filter(|(a, b)| a != b).count();
        assert_eq!(differing, 0, "{scene}: {differing} channels differ");
    }
}

#[test]
fn a_shared_scene_renders_the_same_bits_through_both_trees_when_present() {
    // The Stanford bunny in the Cornell box: 69k triangles, a deep tree. Its files live in
    // ../shared/scenes, outside the repository; without them there is nothing to render.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/shared/cornell-bunny.toml");
    let Ok(scene) = tracer::scene::load(&path) else {
        eprintln!("skipped: {} or its OBJ is absent", path.display());
        return;
    };
    drop(scene);
    let wide = render_bits(&path, 40, 2, Traversal::Robust);
    let binary = render_bits(&path, 40, 2, Traversal::RobustBinary);
    assert_eq!(wide, binary);
}

/// Whether this processor runs the AVX box test, said once per test that needs it: without it
/// there is only one box test, and nothing to compare it with.
fn avx_present(test: &str) -> bool {
    let mut accel = Accel::build(&[], BuildQuality::Medium);
    let present = accel.set_box_simd(BoxSimd::Avx);
    if !present {
        eprintln!("{test}: skipped, this processor has no AVX");
    }
    present
}

#[test]
fn the_avx_and_sse_box_tests_find_the_same_hits_with_the_same_work() {
    if !avx_present("the_avx_and_sse_box_tests_find_the_same_hits_with_the_same_work") {
        return;
    }
    let mut rng = Rng(0x5eed_0a5c);
    let triangles = soup(&mut rng, 700);
    let mut avx = Accel::build(&triangles, BuildQuality::Medium);
    let mut sse = avx.clone();
    assert!(avx.set_box_simd(BoxSimd::Avx) && sse.set_box_simd(BoxSimd::Sse));
    let (mut avx_stats, mut sse_stats) = (TraversalStats::default(), TraversalStats::default());
    let mut hits = 0;
    for i in 0..4000 {
        // Axis-aligned directions, zeros of both signs included: the slab test's NaN cases,
        // where the two instruction sets' NaN rules would show if the code leaned on them.
        let axes = [Vec3::X, -Vec3::Z, Vec3::new(0.0, -0.0, 1.0)];
        let ray = probe_ray(&mut rng, i, (i % 5 == 0).then_some(axes));
        let a = avx.intersect(&ray, &mut avx_stats);
        assert_eq!(a, sse.intersect(&ray, &mut sse_stats), "{ray:?}");
        assert_eq!(
            avx.occluded(&ray, &mut avx_stats),
            sse.occluded(&ray, &mut sse_stats),
            "{ray:?}"
        );
        assert_eq!(avx_stats, sse_stats, "the same steps, ray {i}");
        hits += a.is_some() as u32;
    }
    assert!(hits > 1000, "only {hits} hits, the soup is too thin");
}

#[test]
fn scenes_render_the_same_bits_and_work_through_the_avx_and_sse_box_tests() {
    if !avx_present("scenes_render_the_same_bits_and_work_through_the_avx_and_sse_box_tests") {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut scenes = vec![
        ("cornell-box/cornell-box.toml", 48, 4),
        ("glass-cluster-pan/glass-cluster-pan.toml", 48, 4),
    ];
    // The bunny's 69k triangles make a deep tree; its files live outside the repository.
    if tracer::scene::load(&root.join("shared/cornell-bunny.toml")).is_ok() {
        scenes.push(("shared/cornell-bunny.toml", 32, 2));
    } else {
        eprintln!("the bunny is skipped: ../shared/scenes is absent");
    }
    for (scene, size, spp) in scenes {
        let path = root.join(scene);
        let avx = render_with(&path, size, spp, Traversal::Robust, Some(BoxSimd::Avx));
        let sse = render_with(&path, size, spp, Traversal::Robust, Some(BoxSimd::Sse));
        assert!(avx.1.is_some() && sse.1.is_some(), "{scene}: both ran");
        assert!(
            avx.0.iter().any(|&b| f32::from_bits(b) > 0.0),
            "{scene}: black"
        );
        assert_eq!(avx.0, sse.0, "{scene}: the image bits");
        assert_eq!(avx.1, sse.1, "{scene}: the counted work");
    }
}

#[test]
fn a_tree_set_on_a_world_is_made_ready_as_the_worlds_own_and_renders_the_same_bits() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/cornell-box.toml");
    let mut scene = tracer::scene::load(&path).expect("the shipped scene loads");
    scene.settings.width = 32;
    scene.settings.height = 32;
    scene.settings.samples_per_pixel = 2;
    let mut world = World::prepare(scene, None);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of two threads builds");
    let render = |world: &World| {
        let film = tracer::render_frame(world, 0, &pool, tracer::FrameConfig::default());
        film.pixels
            .iter()
            .flatten()
            .map(|c| c.to_bits())
            .collect::<Vec<u32>>()
    };
    let own = render(&world);
    for (quality, traversal) in [
        (BuildQuality::Fastest, Traversal::Robust),
        (BuildQuality::VerySlow, Traversal::RobustBinary),
        (BuildQuality::Medium, Traversal::Robust),
    ] {
        world.set_traversal(traversal);
        // A fresh tree keeps its binary tree; the world frees it where only the wide walk
        // runs, as it frees its own, and keeps it for a comparison traversal.
        world.set_accel(Accel::build(&world.scene.triangles, quality));
        assert_eq!(
            world.accel().has_binary_tree(),
            traversal != Traversal::Robust,
            "{quality:?}, {traversal:?}"
        );
        assert!(
            render(&world) == own,
            "{quality:?}, {traversal:?}: the image changed"
        );
    }
}
