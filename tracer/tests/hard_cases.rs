//! Hard cases: scenes written by the test to a folder, loaded and rendered whole through the
//! tracer's own frame layer ([`tracer::render_frame`], as every renderer of a whole frame does).
//!
//! Where a ray tracer leaks light, loses precision or divides by zero: a camera inside a closed
//! emitter (a ray slipping through an edge shows as a dark pixel), the Cornell box far from the
//! origin and at extreme scales, rays grazing a floor, rays exactly along the axes with signed
//! zeros, needle-thin and degenerate triangles. The expected answers come from the scenes'
//! construction (a closed emitter of radiance E with albedo 0 looks like E from every direction,
//! exactly), or from the unmodified scene, never from the code under test.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tracer::{Effects, FrameConfig, World, render_frame};

/// Emission of the closed emitters: dyadic, so any number of equal samples averages exactly.
const E: [f32; 3] = [1.5, 0.75, 3.0];

/// What a render changes from the scene as written.
#[derive(Clone, Copy, Default)]
struct Overrides {
    /// `Some(Effects::ALL)`: every effect on, as `tessera render --effects all` renders.
    effects: Option<Effects>,
    /// Another pixel-sampler seed, as `tessera render --seed` sets it.
    seed: Option<u64>,
}

/// A folder of the shipped scenes.
fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// Writes `toml` to `dir/name.toml`, renders frame 0 of it as `overrides` say and returns its
/// pixels, every one finite and not negative.
fn render(dir: &Path, name: &str, toml: &str, overrides: Overrides) -> Vec<[f32; 3]> {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, toml).unwrap();
    let mut scene = tracer::scene::load(&path).unwrap();
    if let Some(seed) = overrides.seed {
        scene.settings.seed = seed;
    }
    let world = World::prepare(scene, overrides.effects);
    let pool = rayon::ThreadPoolBuilder::new().build().unwrap();
    let image = render_frame(&world, 0, &pool, FrameConfig::default()).pixels;
    for p in &image {
        assert!(
            p.iter().all(|c| c.is_finite() && *c >= 0.0),
            "{name}: pixel {p:?}"
        );
    }
    image
}

/// Asserts every pixel is exactly `expected`, naming how many are not and the first of them.
fn assert_all_exactly(name: &str, image: &[[f32; 3]], expected: [f32; 3]) {
    let bad: Vec<(usize, [f32; 3])> = image
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, p)| *p != expected)
        .collect();
    assert!(
        bad.is_empty(),
        "{name}: {} of {} pixels are not {expected:?}, e.g. {:?}",
        bad.len(),
        image.len(),
        bad[0]
    );
}

fn emitter_material() -> String {
    format!(
        "[materials.lamp]\ntype = \"emissive\"\nemission = [{}, {}, {}]\n",
        E[0], E[1], E[2]
    )
}

#[test]
fn inside_a_closed_emissive_sphere_every_pixel_is_the_emission() {
    let dir = tempfile::tempdir().unwrap();
    // (sphere, camera): a coarse and a fine sphere, the icosahedron itself strongly perturbed
    // (valence-5 vertices right in view), one far from the origin and one tiny.
    let cases = [
        (
            "radius = 1\nsubdivisions = 3\nperturb = 0.3",
            "position = [0, 0, 0]\nlook_at = [0.3, 0.2, 1]\nvfov = 90",
        ),
        (
            "radius = 1\nsubdivisions = 5\nperturb = 0.2",
            "position = [0.3, -0.35, 0.2]\nlook_at = [1, -1, 0.5]\nvfov = 120",
        ),
        (
            "radius = 1\nsubdivisions = 0\nperturb = 0.45",
            "position = [0.1, 0.05, -0.1]\nlook_at = [0, 1, 0.1]\nvfov = 150",
        ),
        (
            "center = [1e5, -3e4, 7e3]\nradius = 20\nsubdivisions = 4\nperturb = 0.1",
            "position = [99996, -29998, 7006]\nlook_at = [99980, -29996, 7006]\nvfov = 100",
        ),
        (
            "radius = 1e-4\nsubdivisions = 2\nperturb = 0.4",
            "position = [2e-5, 1e-5, 0]\nlook_at = [0, 0, 1e-4]\nvfov = 100",
        ),
    ];
    for (i, (sphere, camera)) in cases.into_iter().enumerate() {
        let toml = format!(
            "[render]\nwidth = 96\nheight = 96\nspp = 2\n[camera]\n{camera}\n\
             [[object]]\nshape = \"sphere\"\n{sphere}\ninward = true\nseed = {i}\nmaterial = \"lamp\"\n{}",
            emitter_material()
        );
        let name = format!("sphere-{i}");
        assert_all_exactly(
            &name,
            &render(dir.path(), &name, &toml, Overrides::default()),
            E,
        );
        if i == 0 {
            let forced = render(
                dir.path(),
                "sphere-0-all",
                &toml,
                Overrides {
                    effects: Some(Effects::ALL),
                    ..Overrides::default()
                },
            );
            assert_all_exactly("sphere-0 with every effect on", &forced, E);
        }
    }
}

/// Per-channel mean of an image.
fn mean(image: &[[f32; 3]]) -> [f64; 3] {
    let mut sum = [0.0f64; 3];
    for p in image {
        for c in 0..3 {
            sum[c] += f64::from(p[c]);
        }
    }
    sum.map(|s| s / image.len() as f64)
}

#[test]
fn the_cornell_box_far_away_tiny_or_huge_renders_like_the_original() {
    let dir = tempfile::tempdir().unwrap();
    for file in ["cornell-box.obj", "cornell-box.mtl"] {
        std::fs::copy(repo("scenes/cornell-box").join(file), dir.path().join(file)).unwrap();
    }
    // The shipped scene's camera and image, with the whole scene moved and scaled alike.
    let variant = |scale: f64, shift: f64| {
        let p = |x: f64, y: f64, z: f64| {
            format!(
                "[{}, {}, {}]",
                x * scale + shift,
                y * scale + shift,
                z * scale + shift
            )
        };
        format!(
            "[render]\nwidth = 64\nheight = 64\nspp = 32\nmax_depth = 8\n\
             [camera]\nposition = {}\nlook_at = {}\nvfov = 39.3077\n\
             [[object]]\nobj = \"cornell-box.obj\"\nscale = {scale}\ntranslate = [{shift}, {shift}, {shift}]\n",
            p(278.0, 273.0, -800.0),
            p(278.0, 273.0, 0.0)
        )
    };
    let original = render(
        dir.path(),
        "original",
        &variant(1.0, 0.0),
        Overrides::default(),
    );
    let reseeded = render(
        dir.path(),
        "reseeded",
        &variant(1.0, 0.0),
        Overrides {
            seed: Some(1),
            ..Overrides::default()
        },
    );
    // The Monte Carlo error of an image mean, from two independent renders: each pixel's
    // variance is estimated by half its squared difference.
    let n = original.len() as f64;
    let noise: [f64; 3] = std::array::from_fn(|c| {
        let sq: f64 = original
            .iter()
            .zip(&reseeded)
            .map(|(a, b)| (f64::from(a[c]) - f64::from(b[c])).powi(2))
            .sum();
        (sq / 2.0).sqrt() / n
    });
    let reference = mean(&original);
    assert!(
        noise.iter().all(|&s| s > 0.0),
        "two seeds gave the same image"
    );
    let lit = |p: &[f32; 3]| p.iter().any(|&c| c > 0.0);
    for (name, scale, shift) in [
        ("translated-1e5", 1.0, 1e5),
        ("scaled-1e-6", 1e-6, 0.0),
        ("scaled-1e4", 1e4, 0.0),
    ] {
        let image = render(
            dir.path(),
            name,
            &variant(scale, shift),
            Overrides::default(),
        );
        let m = mean(&image);
        for c in 0..3 {
            // The difference of two renders' means: sqrt(2) standard errors, four of them.
            let tolerance = 4.0 * std::f64::consts::SQRT_2 * noise[c];
            assert!(
                (m[c] - reference[c]).abs() <= tolerance,
                "{name}: channel {c} mean {} vs {} (tolerance {tolerance})",
                m[c],
                reference[c]
            );
        }
        // Dim pixels are black in some renders by chance (32 samples that all found nothing), so
        // black pixels are counted against the two originals, and a pixel both originals show
        // clearly lit must be lit.
        let black = |image: &[[f32; 3]]| image.iter().filter(|p| !lit(p)).count();
        let expected = black(&original).max(black(&reseeded));
        let allowed = expected + 3 * ((expected + 1) as f64).sqrt().ceil() as usize;
        assert!(
            black(&image) <= allowed,
            "{name}: {} black pixels, the original has {expected}",
            black(&image)
        );
        let clear = 0.05 * (reference[0] + reference[1] + reference[2]) as f32;
        for (i, p) in image.iter().enumerate() {
            let sum = |p: &[f32; 3]| p[0] + p[1] + p[2];
            if sum(&original[i]) > clear && sum(&reseeded[i]) > clear {
                assert!(
                    lit(p),
                    "{name}: pixel {i} is black, {:?} in the original",
                    original[i]
                );
            }
        }
    }
}

/// An OBJ of an `n` x `n` grid of quads (two triangles each) over [-size, size]^2 at y = 0,
/// facing up, with shared vertices.
fn floor_grid(n: usize, size: f64) -> String {
    let mut obj = String::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, z) = (
                -size + 2.0 * size * i as f64 / n as f64,
                -size + 2.0 * size * j as f64 / n as f64,
            );
            writeln!(obj, "v {x} 0 {z}").unwrap();
        }
    }
    let v = |i: usize, j: usize| j * (n + 1) + i + 1;
    for j in 0..n {
        for i in 0..n {
            writeln!(
                obj,
                "f {} {} {}\nf {} {} {}",
                v(i, j),
                v(i, j + 1),
                v(i + 1, j + 1),
                v(i, j),
                v(i + 1, j + 1),
                v(i + 1, j)
            )
            .unwrap();
        }
    }
    obj
}

#[test]
fn grazing_rays_along_a_floor_find_no_hole() {
    // An emitting floor under a sky of another radiance, one sample per pixel: every pixel is
    // exactly the floor's or the sky's radiance, and down each column the sky gives way to the
    // floor once, at the horizon; a sky pixel below the floor's first row would be a hole.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("floor.obj"), floor_grid(60, 1000.0)).unwrap();
    let sky = [0.25f32, 0.25, 0.25];
    // Straight ahead over a grid line's neighbourhood, exactly above a grid line, and from a
    // corner exactly along the triangles' diagonal edges.
    let views = [
        (1e-3, [0.3, -1000.0], [0.3, 0.0]),
        (1e-6, [0.0, -1000.0], [0.0, 0.0]),
        (1e-4, [-1000.0, -1000.0], [1000.0, 1000.0]),
    ];
    for (i, (height, from, to)) in views.into_iter().enumerate() {
        let toml = format!(
            "[render]\nwidth = 200\nheight = 100\nspp = 1\n\
             [camera]\nposition = [{}, {height}, {}]\nlook_at = [{}, {height}, {}]\nvfov = 40\n\
             [[object]]\nobj = \"floor.obj\"\nmaterial = \"lamp\"\n{}[environment]\nradiance = 0.25\n",
            from[0],
            from[1],
            to[0],
            to[1],
            emitter_material()
        );
        let name = format!("grazing-{i}");
        let image = render(dir.path(), &name, &toml, Overrides::default());
        let (w, h) = (200usize, 100usize);
        for x in 0..w {
            let column: Vec<[f32; 3]> = (0..h).map(|y| image[y * w + x]).collect();
            assert!(
                column.iter().all(|p| *p == sky || *p == E),
                "{name}: column {x} has a pixel that is neither sky nor floor"
            );
            let first_floor = column.iter().position(|p| *p == E).unwrap_or(h);
            assert!(
                column[first_floor..].iter().all(|p| *p == E),
                "{name}: column {x} has a hole below row {first_floor}"
            );
            assert!(
                (h / 2..=h / 2 + 1).contains(&first_floor),
                "{name}: column {x}'s horizon at row {first_floor}"
            );
        }
    }
}

#[test]
fn rays_exactly_along_the_axes_with_signed_zeros_stay_inside_a_closed_room() {
    // A field of view of 1e-44 degrees is 0 radians in f32: every camera ray is exactly the
    // view direction, whose other components are +0.0 or -0.0 as the look-at point's signed
    // zeros make them. At 1e-40 degrees the components are subnormal instead, and their
    // reciprocals overflow. The camera sits on planes of the inner box's faces, so these rays
    // run along its edges and through its corners. Both boxes emit E towards the camera.
    let dir = tempfile::tempdir().unwrap();
    let room = format!(
        "[[object]]\nshape = \"box\"\nmin = [-1, -1, -1]\nmax = [1, 1, 1]\ninward = true\nmaterial = \"lamp\"\n\
         [[object]]\nshape = \"box\"\nmin = [0, 0, 0.25]\nmax = [0.5, 0.5, 0.75]\nmaterial = \"lamp\"\n{}",
        emitter_material()
    );
    let views = [
        ("[0, 0, -0.5]", "[0, 0, 0.5]", "[0, 1, 0]"),
        ("[-0.0, -0.0, 0.9]", "[0, 0, 0]", "[0, 1, 0]"),
        ("[0, 0, 0.9]", "[-0.0, -0.0, 0]", "[0, 1, 0]"),
        ("[-0.5, 0, 0.25]", "[0.5, -0.0, 0.25]", "[0, 1, 0]"),
        ("[0.9, 0.5, 0.5]", "[0, 0.5, 0.5]", "[0, 1, 0]"),
        ("[0, -0.9, 0.75]", "[-0.0, 0, 0.75]", "[0, 0, 1]"),
        ("[0.5, 0.9, 0.25]", "[0.5, 0, 0.25]", "[0, 0, -1]"),
    ];
    for (i, (position, look_at, up)) in views.into_iter().enumerate() {
        for vfov in ["1e-44", "1e-40"] {
            let toml = format!(
                "[render]\nwidth = 4\nheight = 4\nspp = 2\n\
                 [camera]\nposition = {position}\nlook_at = {look_at}\nup = {up}\nvfov = {vfov}\n{room}"
            );
            let name = format!("axis-{i}-{vfov}");
            assert_all_exactly(
                &name,
                &render(dir.path(), &name, &toml, Overrides::default()),
                E,
            );
        }
    }
}

/// A closed cylinder (axis z, radius 1, z in [-1, 1]) of `n` needle-thin side quads and two fans
/// of `n` needles meeting at the caps' centres, facing inward, plus triangles of zero area (a
/// repeated corner, three points on the axis) that the loader must drop.
fn needle_cylinder(n: usize) -> String {
    let mut obj = String::new();
    for k in 0..n {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        writeln!(
            obj,
            "v {} {} -1\nv {} {} 1",
            a.cos(),
            a.sin(),
            a.cos(),
            a.sin()
        )
        .unwrap();
    }
    writeln!(obj, "v 0 0 -1\nv 0 0 1\nv 0 0 -0.5\nv 0 0 0\nv 0 0 0.5").unwrap();
    let (bottom, top) = (|k: usize| 2 * (k % n) + 1, |k: usize| 2 * (k % n) + 2);
    let (cb, ct) = (2 * n + 1, 2 * n + 2);
    for k in 0..n {
        writeln!(
            obj,
            "f {} {} {}\nf {} {} {}",
            bottom(k),
            top(k),
            top(k + 1),
            bottom(k),
            top(k + 1),
            bottom(k + 1)
        )
        .unwrap();
        writeln!(
            obj,
            "f {cb} {} {}\nf {ct} {} {}",
            bottom(k),
            bottom(k + 1),
            top(k + 1),
            top(k)
        )
        .unwrap();
    }
    writeln!(obj, "f 1 1 2\nf {} {} {}", 2 * n + 3, 2 * n + 4, 2 * n + 5).unwrap();
    obj
}

#[test]
fn needle_and_degenerate_triangles_leave_no_hole() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("needles.obj"), needle_cylinder(3000)).unwrap();
    // Towards a cap's centre where 3000 needles meet, across the side, and grazing along it.
    for (i, (position, look_at)) in [
        ("[0.1, 0.2, -0.3]", "[0, 0, 1]"),
        ("[0.1, 0.2, 0.3]", "[-1, 0.4, 0.1]"),
        ("[0.95, 0, -0.9]", "[0.95, 0.01, 1]"),
    ]
    .into_iter()
    .enumerate()
    {
        let toml = format!(
            "[render]\nwidth = 96\nheight = 96\nspp = 1\n\
             [camera]\nposition = {position}\nlook_at = {look_at}\nvfov = 120\n\
             [[object]]\nobj = \"needles.obj\"\nmaterial = \"lamp\"\n{}",
            emitter_material()
        );
        let name = format!("needles-{i}");
        assert_all_exactly(
            &name,
            &render(dir.path(), &name, &toml, Overrides::default()),
            E,
        );
    }
}
