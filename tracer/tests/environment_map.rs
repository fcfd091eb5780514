//! Image-based lighting: an HDR lat-long map against answers computed here from its texels, not
//! against images of the renderer's own.
//!
//! The maps are written in the tests with the exr crate and loaded from memory, as a peer loads
//! the files an owner shipped. Checked: the orientation of the map (what a camera ray sees), the
//! density of the importance sampler (it integrates to one, and luminance over density has the
//! map's integral as its mean), direct light on a diffuse floor against the exact integral over
//! the map's cells with importance sampling, uniform sampling and BSDF sampling alone (no MIS),
//! a constant map against the constant environment and the white furnace, bit-identity of
//! specialised and `Effects::ALL` renders, and the loader's errors.

mod common;

use common::{assert_close, assert_same_bits, exr_bytes, load_with, mean_and_error, render_with};
use glam::Vec3;
use std::f64::consts::PI;
use tracer::Effects;
use tracer::environment::{Environment, EnvironmentMap, MapSampler};
use tracer::lights::{EnvironmentSampling, luminance, uniform_sphere};
use tracer::sampler::PixelSampler;

/// A sky for the tests: a gradient above the horizon, a small sun 200 times brighter, and a
/// bright ground below (which a floor must hide), `w` x `h` texels with `h` even.
fn sky(w: usize, h: usize) -> impl Fn(usize, usize) -> [f32; 3] {
    move |x, y| {
        if y >= h / 2 {
            [5.0, 4.0, 3.0]
        } else if (x, y) == (w * 5 / 8, h / 5) {
            [200.0, 180.0, 150.0]
        } else {
            let t = y as f32 / h as f32;
            [0.3 + t, 0.5 + t, 0.9 + 0.1 * (x % 3) as f32]
        }
    }
}

fn map_of(w: usize, h: usize, texel: &impl Fn(usize, usize) -> [f32; 3]) -> EnvironmentMap {
    let texels = (0..w * h)
        .map(|i| Vec3::from_array(texel(i % w, i / w)))
        .collect();
    EnvironmentMap::new(w as u32, h as u32, texels, 0.0)
}

#[test]
fn the_importance_sampler_density_integrates_to_one_and_matches_its_samples() {
    let (w, h) = (32, 16);
    let texel = sky(w, h);
    let map = map_of(w, h, &texel);
    let sampler = MapSampler::new(&map).expect("the sky is not black");
    // The exact integral of the luminance over the sphere: each cell covers
    // (2 pi / w) (cos theta_top - cos theta_bottom) steradians.
    let mut exact = 0.0f64;
    for y in 0..h {
        let band = (PI * y as f64 / h as f64).cos() - (PI * (y + 1) as f64 / h as f64).cos();
        for x in 0..w {
            exact +=
                f64::from(luminance(Vec3::from_array(texel(x, y)))) * 2.0 * PI / w as f64 * band;
        }
    }
    let n = 400_000u32;
    let (mut density_mean, mut estimate, mut estimate_sq) = (0.0f64, 0.0f64, 0.0f64);
    let mut disagreeing = 0;
    for i in 0..n {
        let mut s = PixelSampler::new(5, 0, i, 0, 0);
        // The density over uniform directions: its mean times 4 pi is its integral, one.
        density_mean += f64::from(sampler.pdf(&map, uniform_sphere(s.next_2d())));
        let Some(sample) = sampler.sample(&map, s.next_2d()) else {
            continue;
        };
        let value = f64::from(luminance(sample.radiance)) / f64::from(sample.pdf);
        estimate += value;
        estimate_sq += value * value;
        let again = sampler.pdf(&map, sample.wi);
        if (again - sample.pdf).abs() > 1e-4 * sample.pdf {
            disagreeing += 1;
        }
        assert_eq!(sample.radiance, map.radiance(sample.wi));
    }
    let n = f64::from(n);
    let integral = density_mean / n * 4.0 * PI;
    assert!(
        (integral - 1.0).abs() < 0.02,
        "density integrates to {integral}"
    );
    let mean = estimate / n;
    let se = ((estimate_sq / n - mean * mean).max(0.0) / n).sqrt();
    assert!(
        (mean - exact).abs() < 4.0 * se + 1e-4 * exact,
        "luminance / pdf has mean {mean} (se {se}), the map's integral is {exact}"
    );
    // Importance sampling by luminance: the estimate of the luminance itself varies only with
    // sin(theta) within a cell, far less than the map does.
    assert!(se < 0.01 * exact, "se {se} of {exact}");
    // A direction found again by its map coordinates lands in the same cell but at cell borders.
    assert!(
        f64::from(disagreeing) < 1e-3 * n,
        "{disagreeing} densities disagree"
    );
}

#[test]
fn a_camera_ray_sees_the_texel_the_documented_orientation_names() {
    // 9 x 5 texels, each its own value; a narrow camera looks at the middle of one texel.
    let (w, h) = (9, 5);
    let value = |x: usize, y: usize| (1 + x + w * y) as f32;
    let exr = exr_bytes(w, h, |x, y| [value(x, y), 0.0, 1.0]);
    for (rotate, look_at, texel) in [
        (0.0, [0.0, 0.0, 1.0], (4, 2)),
        (0.0, [1.0, 0.0, 0.0], (6, 2)),
        (0.0, [-0.1, 0.0, -1.0], (0, 2)),
        (90.0, [1.0, 0.0, 0.0], (4, 2)),
        (90.0, [0.0, 0.0, 1.0], (2, 2)),
        (0.0, [0.0, 0.8, 1.0], (4, 1)),
    ] {
        let toml = format!(
            "render = {{ width = 1, height = 1, spp = 4, max_depth = 0 }}\n\
             camera = {{ position = [0, 0, 0], look_at = {look_at:?}, vfov = 1 }}\n\
             [[object]]\nshape = \"sphere\"\ncenter = [0, -100, 0]\nradius = 0.1\nmaterial = \"m\"\n\
             [materials.m]\ntype = \"diffuse\"\n\
             [environment]\nmap = \"sky.exr\"\nrotate = {rotate}\n"
        );
        let scene = load_with(&toml, &[("sky.exr", exr.clone())]).expect("scene loads");
        let out = render_with(&scene, None, 0, EnvironmentSampling::default());
        assert_eq!(
            out.pixels[0],
            [value(texel.0, texel.1), 0.0, 1.0],
            "rotate {rotate}, looking at {look_at:?}"
        );
    }
}

/// A diffuse floor of albedo 0.5 seen from above, lit by the environment alone with one
/// scattering event: direct light only.
fn floor_toml(environment: &str, spp: u32) -> String {
    format!(
        r#"
        render = {{ width = 16, height = 16, spp = {spp}, max_depth = 1, russian_roulette_depth = "off" }}
        camera = {{ position = [0, 1, 0], look_at = [0, 0, 0], up = [0, 0, 1], vfov = 20 }}
        [[object]]
        shape = "quad"
        corners = [[-1000, 0, -1000], [-1000, 0, 1000], [1000, 0, 1000], [1000, 0, -1000]]
        material = "floor"
        [materials.floor]
        type = "diffuse"
        albedo = 0.5
        [environment]
        {environment}
        "#
    )
}

#[test]
fn direct_light_from_a_map_matches_the_integral_over_its_cells_by_every_sampling() {
    let (w, h) = (32, 16);
    let texel = sky(w, h);
    let exr = exr_bytes(w, h, &texel);
    // Radiance off a Lambertian floor: albedo / pi times the integral of L cos(theta) over the
    // upper hemisphere; a cell spans (2 pi / w) (sin^2 theta_bottom - sin^2 theta_top) / 2 of
    // projected solid angle. The ground below the horizon must not count.
    let mut expected = [0.0f64; 3];
    for y in 0..h / 2 {
        let (top, bottom) = (PI * y as f64 / h as f64, PI * (y + 1) as f64 / h as f64);
        let projected = 2.0 * PI / w as f64 * 0.5 * (bottom.sin().powi(2) - top.sin().powi(2));
        for x in 0..w {
            for (c, e) in expected.iter_mut().enumerate() {
                *e += 0.5 / PI * f64::from(texel(x, y)[c]) * projected;
            }
        }
    }
    let expected = Vec3::from_array(expected.map(|e| e as f32));
    let mut errors = Vec::new();
    for rotate in [0.0, 123.0] {
        for (sampling, spp) in [
            (EnvironmentSampling::Importance, 16),
            (EnvironmentSampling::Uniform, 64),
            (EnvironmentSampling::Bsdf, 64),
        ] {
            let toml = floor_toml(&format!("map = \"sky.exr\"\nrotate = {rotate}"), spp);
            let scene = load_with(&toml, &[("sky.exr", exr.clone())]).expect("scene loads");
            let out = render_with(&scene, None, 0, sampling);
            let result = mean_and_error(&out);
            assert_close(
                &format!("{sampling:?}, rotate {rotate}"),
                result,
                expected,
                0.0,
            );
            if rotate == 0.0 {
                errors.push((sampling, result.1.x * (spp as f32).sqrt()));
            }
        }
    }
    // Per sample, importance sampling the sun beats sampling the sphere blindly.
    let (importance, uniform) = (errors[0].1, errors[1].1);
    assert!(importance < uniform, "{errors:?}");
}

#[test]
fn a_constant_map_renders_like_the_constant_environment_and_keeps_the_white_furnace() {
    let exr = exr_bytes(12, 6, |_, _| [0.8, 0.8, 0.8]);
    let sphere = |albedo: f32, environment: &str| {
        format!(
            "render = {{ width = 24, height = 24, spp = 16, max_depth = \"unlimited\", russian_roulette_depth = 4 }}\n\
             camera = {{ position = [0, 0, -3], look_at = [0, 0, 0], vfov = 40 }}\n\
             [[object]]\nshape = \"sphere\"\nsubdivisions = 3\nmaterial = \"ball\"\n\
             [materials.ball]\ntype = \"diffuse\"\nalbedo = {albedo}\n[environment]\n{environment}\n"
        )
    };
    let files = [("sky.exr", exr)];
    for albedo in [1.0, 0.5] {
        let constant = load_with(&sphere(albedo, "radiance = 0.8"), &[]).unwrap();
        let map = load_with(&sphere(albedo, "map = \"sky.exr\"\nrotate = 10"), &files).unwrap();
        assert!(matches!(map.environment, Some(Environment::Map(_))));
        let (a, a_se) = mean_and_error(&render_with(&constant, None, 0, Default::default()));
        let (b, b_se) = mean_and_error(&render_with(&map, None, 0, Default::default()));
        let se = (a_se * a_se + b_se * b_se).x.sqrt();
        assert!(
            (a.x - b.x).abs() < 4.0 * se + 1e-6,
            "albedo {albedo}: {a} vs {b}"
        );
        if albedo == 1.0 {
            // The white furnace: a white diffuse sphere vanishes into a uniform environment.
            assert_close(
                "white furnace under a map",
                (b, b_se),
                Vec3::splat(0.8),
                0.0,
            );
        }
    }
}

#[test]
fn scenes_with_a_map_render_the_same_bits_specialised_or_forced() {
    let (w, h) = (32, 16);
    let exr = exr_bytes(w, h, sky(w, h));
    let black = exr_bytes(4, 2, |_, _| [0.0; 3]);
    let toml = |environment: &str| {
        format!(
            r#"
            render = {{ width = 20, height = 16, spp = 4, max_depth = 6, russian_roulette_depth = 2 }}
            camera = {{ position = [0, 1.5, -5], look_at = [0, 0.5, 0] }}
            object = [
                {{ shape = "quad", corners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]], material = "floor" }},
                {{ shape = "sphere", center = [-1, 0.7, 0], radius = 0.7, subdivisions = 2, material = "glass" }},
                {{ shape = "sphere", center = [1, 0.7, 0], radius = 0.7, subdivisions = 2, material = "metal" }},
            ]
            materials.floor = {{ type = "diffuse", albedo = 0.7 }}
            materials.glass = {{ type = "glass" }}
            materials.metal = {{ type = "metal", roughness = 0.3 }}
            [[light]]
            type = "point"
            position = [1, 4, -2]
            intensity = 20
            [environment]
            {environment}
            "#
        )
    };
    let files = [("sky.exr", exr), ("black.exr", black)];
    let lit = load_with(
        &toml("map = \"sky.exr\"\nrotate = 30\nscale = [1, 0.5, 2]"),
        &files,
    )
    .expect("scene loads");
    let effects = Effects::of(&lit);
    assert!(effects.environment && effects.environment_map, "{effects}");
    assert_eq!(
        lit.files,
        ["scene.toml", "sky.exr"],
        "the map ships with the scene"
    );
    let (auto, _) = assert_same_bits("map", &lit, 0);
    assert!(auto.stats.environment_lookups > 0);
    // A black map is no environment: nothing looked up specialised, the same bits forced.
    let dark = load_with(&toml("map = \"black.exr\""), &files).expect("scene loads");
    let effects = Effects::of(&dark);
    assert!(
        !effects.environment && !effects.environment_map,
        "{effects}"
    );
    let (auto, all) = assert_same_bits("black map", &dark, 0);
    assert_eq!(auto.stats.environment_lookups, 0);
    assert!(all.environment_lookups > 0);
}

#[test]
fn bad_maps_are_errors_that_name_the_file_and_line() {
    let toml = |environment: &str| {
        format!(
            "camera = {{ position = [0, 0, -3], look_at = [0, 0, 0] }}\n\
             [[object]]\nshape = \"sphere\"\nmaterial = \"m\"\n[materials.m]\ntype = \"diffuse\"\n\
             [environment]\n{environment}\n"
        )
    };
    let good = exr_bytes(4, 2, |_, _| [1.0; 3]);
    let nan = exr_bytes(4, 2, |x, _| [if x == 3 { f32::NAN } else { 1.0 }; 3]);
    let files = [
        ("good.exr", good),
        ("nan.exr", nan),
        ("text.exr", b"not an image".to_vec()),
    ];
    for (environment, file, words) in [
        (
            "map = \"missing.exr\"",
            "missing.exr",
            "cannot read missing.exr (referenced at scene.toml:8)",
        ),
        (
            "map = \"text.exr\"",
            "text.exr",
            "text.exr (referenced at scene.toml:8): not a readable OpenEXR",
        ),
        (
            "map = \"nan.exr\"",
            "nan.exr",
            "nan.exr (referenced at scene.toml:8): texel (3, 0)",
        ),
        ("map = \"good.exr\"\nradiance = 1", "scene.toml", "not both"),
        (
            "radiance = 1\nrotate = 3",
            "scene.toml",
            "apply to a `map` only",
        ),
        ("scale = 2", "scene.toml", "needs `radiance"),
        (
            "map = \"good.exr\"\nscale = -1",
            "scene.toml",
            "must not be negative",
        ),
        (
            "map = \"/etc/sky.exr\"",
            "scene.toml",
            "not a relative path",
        ),
    ] {
        let error = load_with(&toml(environment), &files).expect_err(environment);
        let message = error.to_string();
        assert!(
            error.file() == file && message.contains(words),
            "{environment}: {message}"
        );
    }
    let scene = load_with(&toml("map = \"good.exr\"\nscale = 3"), &files).unwrap();
    let Some(Environment::Map(map)) = &scene.environment else {
        panic!("a map");
    };
    assert_eq!((map.width, map.height), (4, 2));
    assert_eq!(map.radiance(Vec3::Y), Vec3::splat(3.0), "scaled at load");
}
