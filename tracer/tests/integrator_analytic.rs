//! The path tracer against answers known in closed form, not against images of its own.
//!
//! Each test renders a small image and compares its mean with the exact value, within a few
//! standard errors of the mean estimated from the pixels themselves (pixels are independent).

mod common;

use common::{assert_close, mean_and_error};
use glam::Vec3;
use tracer::geometry::{Accel, BuildQuality};
use tracer::{Effects, Rect, World, render_tile};

/// Renders the whole image of `toml` and returns the per-channel mean and its standard error.
fn render_mean(toml: &str) -> (Vec3, Vec3) {
    let scene = tracer::scene::load_str(toml).expect("test scene loads");
    let out = common::render(&scene, None, 0);
    assert!(out.pixels.iter().flatten().all(|c| c.is_finite()));
    mean_and_error(&out)
}

fn furnace(albedo: f32, emission: f32, depth: &str, roulette: &str, seed: u64) -> String {
    format!(
        r#"
        [render]
        width = 24
        height = 24
        spp = 16
        max_depth = {depth}
        russian_roulette_depth = {roulette}
        seed = {seed}
        [camera]
        position = [0.1, -0.2, 0.05]
        look_at = [1, 0.3, 0.2]
        vfov = 90
        [[object]]
        shape = "sphere"
        center = [0, 0, 0]
        radius = 1
        subdivisions = 3
        inward = true
        material = "wall"
        [materials.wall]
        type = "diffuse"
        albedo = [{albedo}, {albedo}, {albedo}]
        emission = [{emission}, {emission}, {emission}]
        "#
    )
}

#[test]
fn closed_emissive_diffuse_sphere_gives_the_geometric_series_at_each_depth() {
    let (rho, le) = (0.5f32, 1.5f32);
    for depth in [1u32, 2, 3, 5] {
        let expected: f32 = le * (0..=depth).map(|k| rho.powi(k as i32)).sum::<f32>();
        let result = render_mean(&furnace(rho, le, &depth.to_string(), "\"off\"", 1));
        assert_close(
            &format!("furnace depth {depth}"),
            result,
            Vec3::splat(expected),
            0.0,
        );
    }
}

#[test]
fn russian_roulette_is_unbiased_with_unlimited_depth() {
    let (rho, le) = (0.7f32, 1.0f32);
    for seed in [3, 4] {
        let result = render_mean(&furnace(rho, le, "\"unlimited\"", "2", seed));
        assert_close(
            "furnace with roulette",
            result,
            Vec3::splat(le / (1.0 - rho)),
            0.0,
        );
    }
}

#[test]
fn point_light_at_the_centre_of_a_diffuse_sphere_gives_radiance_one() {
    // Intensity pi at distance 1 gives irradiance pi; a Lambertian albedo 0.5 turns that into
    // radiance 0.5 after one bounce, and the bounces inside the closed sphere sum to 1. The
    // tessellated sphere's faces lie slightly inside the unit sphere, hence a 1% slack.
    let toml = r#"
        [render]
        width = 24
        height = 24
        spp = 16
        max_depth = "unlimited"
        russian_roulette_depth = 3
        [camera]
        position = [0, 0, 0]
        look_at = [0, 0, 1]
        vfov = 100
        [[object]]
        shape = "sphere"
        center = [0, 0, 0]
        radius = 1
        subdivisions = 4
        inward = true
        material = "wall"
        [materials.wall]
        type = "diffuse"
        albedo = [0.5, 0.5, 0.5]
        [[light]]
        type = "point"
        position = [0, 0, 0]
        intensity = [3.14159265, 3.14159265, 3.14159265]
    "#;
    assert_close("point in sphere", render_mean(toml), Vec3::ONE, 0.01);
}

fn convex_in_environment(material: &str) -> String {
    format!(
        r#"
        [render]
        width = 24
        height = 24
        spp = 16
        max_depth = "unlimited"
        russian_roulette_depth = 4
        [camera]
        position = [0, 0, -3]
        look_at = [0, 0, 0]
        vfov = 40
        [[object]]
        shape = "sphere"
        center = [0, 0, 0]
        radius = 1
        subdivisions = 3
        material = "ball"
        [materials.ball]
        {material}
        [environment]
        radiance = [0.8, 0.8, 0.8]
        "#
    )
}

#[test]
fn white_furnace_energy_conserving_materials_vanish_in_a_uniform_environment() {
    for material in [
        "type = \"diffuse\"\nalbedo = [1, 1, 1]",
        "type = \"mirror\"\nreflectance = [1, 1, 1]",
        "type = \"glass\"\nior = 1.5",
    ] {
        assert_close(
            material,
            render_mean(&convex_in_environment(material)),
            Vec3::splat(0.8),
            0.0,
        );
    }
}

#[test]
fn white_furnace_rough_metal_loses_energy_but_never_gains_it() {
    // Single-scattering microfacet models lose the energy of multiple scattering between
    // microfacets, more at higher roughness: the image may be darker than the environment, never
    // brighter.
    let (mean, se) = render_mean(&convex_in_environment(
        "type = \"metal\"\nreflectance = [1, 1, 1]\nroughness = 0.5",
    ));
    for c in 0..3 {
        assert!(
            mean[c] <= 0.8 + 4.0 * se[c],
            "metal brighter than its environment: {mean}"
        );
        assert!(mean[c] > 0.6, "metal lost implausibly much energy: {mean}");
    }
}

#[test]
fn one_sided_emitters_are_dark_from_behind() {
    // The furnace sphere emits inward only: seen from outside it is black (no environment).
    let toml = furnace(0.5, 1.0, "3", "\"off\"", 0)
        .replace("position = [0.1, -0.2, 0.05]", "position = [0, 0, -4]")
        .replace("look_at = [1, 0.3, 0.2]", "look_at = [0, 0, 0]");
    let (mean, _) = render_mean(&toml);
    assert_eq!(mean, Vec3::ZERO);
}

#[test]
fn the_shipped_furnace_scene_renders_its_known_mean() {
    // scenes/furnace: albedo 0.5, emission 1, max depth 8: mean = sum_{k=0..8} 0.5^k.
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/furnace/furnace.toml");
    let mut scene = tracer::scene::load(&path).expect("the shipped furnace loads");
    scene.settings.width = 24;
    scene.settings.height = 24;
    scene.settings.samples_per_pixel = 16;
    let accel = Accel::build(&scene.triangles, BuildQuality::default());
    let effects = Effects::of(&scene);
    let world = World::new(scene, accel, effects);
    let out = render_tile(
        &world,
        0,
        Rect {
            x: 0,
            y: 0,
            w: 24,
            h: 24,
        },
    );
    let n = out.pixels.len() as f64;
    let mean = out.pixels.iter().map(|p| f64::from(p[1])).sum::<f64>() / n;
    let var = out
        .pixels
        .iter()
        .map(|p| (f64::from(p[1]) - mean).powi(2))
        .sum::<f64>()
        / n;
    let expected: f64 = (0..=8).map(|k| 0.5f64.powi(k)).sum();
    assert!(
        (mean - expected).abs() <= 4.0 * (var / n).sqrt() + 1e-6,
        "mean {mean}, expected {expected}"
    );
}
