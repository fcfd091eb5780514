//! Participating media against closed forms, and the effect set's promise for them.
//!
//! - A furnace: a closed sphere whose boundary is index-matched (or glass) filled with a medium
//!   that scatters and never absorbs, under a uniform white environment, shows exactly 1 in
//!   every pixel, for grey and chromatic media, several densities and phase asymmetries. Light
//!   that enters leaves, whatever it met; the test passes only if free flights, their spectral
//!   MIS weights, the phase function's sampling, next-event estimation through the boundary and
//!   its MIS against phase sampling are right together.
//! - Transmittance through a slab of medium equals `exp(-sigma_t d)` per channel, for a family
//!   of coefficients and thicknesses: along shadow rays (deterministic, to float rounding) and
//!   along camera rays (free-flight sampling: within Monte Carlo error); global fog attenuates
//!   what the camera sees the same way.
//! - Media scenes render the same bits specialised and with every effect forced on, and a
//!   scene without media counts no free flight unless media are forced on.

mod common;

use common::{
    assert_close, assert_same_bits, mean_and_error, radiance_under_the_light, render,
    slab_under_a_point_light,
};
use glam::Vec3;
use tracer::Effects;
use tracer::scene::{Scene, load_str};

fn load(toml: &str) -> Scene {
    load_str(toml).expect("test scene loads")
}

/// A sphere of radius 1 at the origin bounded by `boundary` (a material table's body) and filled
/// with `medium` (a medium table's body), under a white sky, seen from outside.
fn furnace(boundary: &str, medium: &str) -> String {
    format!(
        r#"
        render = {{ width = 16, height = 16, spp = 16, max_depth = "unlimited", russian_roulette_depth = "off" }}
        camera = {{ position = [0, 0, -3], look_at = [0, 0, 0], vfov = 40 }}
        object = [{{ shape = "sphere", radius = 1, subdivisions = 3, material = "boundary" }}]
        environment = {{ radiance = 1 }}
        [materials.boundary]
        {boundary}
        medium = "inside"
        [media.inside]
        {medium}
        "#
    )
}

#[test]
fn a_scattering_medium_in_a_white_furnace_renders_one() {
    let interface = "type = \"interface\"";
    let glass = "type = \"glass\"\nior = 1.5";
    let media = [
        "albedo = 1\ndensity = 0.5",
        "albedo = 1\ndensity = 3\ng = 0.7",
        "albedo = 1\ndensity = 2\ng = -0.5",
        // Chromatic: each channel has its own mean free path, so the spectral MIS weights differ
        // from 1 at every flight, and only their expectation is 1.
        "sigma_s = [0.3, 1.5, 4]\ng = 0.3",
    ];
    for boundary in [interface, glass] {
        for medium in media {
            let scene = load(&furnace(boundary, medium));
            assert!(Effects::of(&scene).media);
            let out = render(&scene, None, 0);
            assert!(out.stats.medium_scatters > 0, "nothing scattered");
            let what = format!("furnace {boundary:?} with {medium:?}");
            let (mean, se) = mean_and_error(&out);
            eprintln!("{what}: mean {mean}, standard error {se}");
            // Four standard errors of the image mean (pixels are independent) and 0.5 % for
            // the float rounding of long paths.
            assert_close(&what, mean_and_error(&out), Vec3::ONE, 0.005);
        }
    }
}

#[test]
fn an_absorbing_medium_loses_energy_in_the_furnace() {
    // The guard on the test above: a medium with absorption must not render 1.
    let scene = load(&furnace(
        "type = \"interface\"",
        "sigma_a = 0.5\nsigma_s = 1",
    ));
    let (mean, _) = mean_and_error(&render(&scene, None, 0));
    assert!(mean.max_element() < 0.9, "mean {mean}");
}

#[test]
fn shadow_rays_through_a_slab_carry_exp_of_minus_sigma_t_d() {
    // albedo / pi * I / r^2 with r = 4, cos = 1, through a vacuum-filled interface.
    let (clear, _) = radiance_under_the_light(load(&slab_under_a_point_light(1.0, "")));
    let by_hand = 16.0 / (16.0 * std::f64::consts::PI);
    for c in 0..3 {
        assert!(
            (f64::from(clear[c]) - by_hand).abs() < 1e-5 * by_hand,
            "without a medium {clear}, expected {by_hand}"
        );
    }
    let coefficients: [(&str, [f64; 3]); 4] = [
        ("sigma_a = 0.3", [0.3; 3]),
        ("sigma_a = 1\nsigma_s = 1", [2.0; 3]),
        ("albedo = 0.5\ndensity = 4", [4.0; 3]),
        ("sigma_a = [0.2, 1, 5]", [0.2, 1.0, 5.0]),
    ];
    for thickness in [0.1f32, 0.5, 1.0, 1.75] {
        for (medium, sigma_t) in coefficients {
            let toml = slab_under_a_point_light(
                thickness,
                &format!("medium = \"m\"\n[media.m]\n{medium}"),
            );
            let (through, stats) = radiance_under_the_light(load(&toml));
            // One shadow ray and two more segments past the slab's two faces.
            assert_eq!(stats.shadow_rays, 3, "{medium}, d = {thickness}");
            for c in 0..3 {
                let expected = by_hand * (-sigma_t[c] * f64::from(thickness)).exp();
                let got = f64::from(through[c]);
                assert!(
                    (got - expected).abs() <= 2e-5 * expected,
                    "{medium}, d = {thickness}, channel {c}: {got}, expected {expected}"
                );
            }
        }
    }
}

/// A slab `z in [0, d]` wide enough to fill the view, bounded by an interface and filled with
/// `medium`, in front of an emitter of radiance 1 facing the camera; emitters only.
fn emitter_behind_slab(thickness: f32, medium: &str) -> String {
    format!(
        r#"
        render = {{ width = 32, height = 32, spp = 16, max_depth = 0 }}
        camera = {{ position = [0, 0, -5], look_at = [0, 0, 0], vfov = 2 }}
        object = [
            {{ shape = "box", min = [-3, -3, 0], max = [3, 3, {thickness}], material = "slab" }},
            {{ shape = "quad", corners = [[-3, -3, 5], [-3, 3, 5], [3, 3, 5], [3, -3, 5]], material = "lamp" }},
        ]
        [materials.lamp]
        type = "emissive"
        emission = 1
        [materials.slab]
        type = "interface"
        medium = "m"
        [media.m]
        {medium}
        "#
    )
}

#[test]
fn camera_rays_through_a_slab_arrive_with_exp_of_minus_sigma_t_d_on_average() {
    // The quad's winding must face the camera for it to emit; the clear case checks that.
    let coefficients: [(&str, [f32; 3]); 3] = [
        ("sigma_a = 0.7", [0.7; 3]),
        ("sigma_a = 0.5\nsigma_s = 0.5\ng = 0.8", [1.0; 3]),
        ("sigma_a = [0.1, 0.8, 2.5]", [0.1, 0.8, 2.5]),
    ];
    for thickness in [0.25f32, 1.0, 2.0] {
        for (medium, sigma_t) in coefficients {
            let scene = load(&emitter_behind_slab(thickness, medium));
            let out = render(&scene, None, 0);
            // Rays lie within 1.5 degrees of the axis: their paths are at most 1.0004 d.
            let expected = Vec3::from_array(sigma_t.map(|s| (-s * thickness).exp()));
            let what = format!("{medium}, d = {thickness}");
            assert_close(&what, mean_and_error(&out), expected, 0.002);
        }
    }
    let clear = load(&emitter_behind_slab(1.0, "sigma_a = 0"));
    let (mean, _) = mean_and_error(&render(&clear, None, 0));
    assert_eq!(mean, Vec3::ONE, "a vacuum slab passes everything");
}

#[test]
fn fog_attenuates_what_the_camera_sees_by_exp_of_minus_sigma_t_distance() {
    // The camera starts in the fog; an emitter 10 away faces it; emitters only.
    let coefficients: [(&str, [f32; 3]); 3] = [
        ("sigma_a = 0.05", [0.05; 3]),
        ("sigma_a = 0.1\nsigma_s = 0.1", [0.2; 3]),
        ("sigma_a = [0.02, 0.1, 0.3]", [0.02, 0.1, 0.3]),
    ];
    for (medium, sigma_t) in coefficients {
        let toml = format!(
            r#"
            render = {{ width = 32, height = 32, spp = 16, max_depth = 0 }}
            camera = {{ position = [0, 0, -5], look_at = [0, 0, 0], vfov = 2, medium = "fog" }}
            object = [{{ shape = "quad", corners = [[-3, -3, 5], [-3, 3, 5], [3, 3, 5], [3, -3, 5]], material = "lamp" }}]
            [materials.lamp]
            type = "emissive"
            emission = 1
            [media.fog]
            {medium}
            "#
        );
        let scene = load(&toml);
        assert!(Effects::of(&scene).media);
        let out = render(&scene, None, 0);
        // Rays lie within 1.5 degrees of the axis: their paths are at most 1.0004 times 10.
        let expected = Vec3::from_array(sigma_t.map(|s| (-s * 10.0).exp()));
        assert_close(
            &format!("fog {medium}"),
            mean_and_error(&out),
            expected,
            0.002,
        );
    }
}

/// A diffuse room lit by a point light, with `extra` objects, materials and media.
fn room(extra: &str) -> String {
    format!(
        r#"
        render = {{ width = 16, height = 12, spp = 4, max_depth = 6, russian_roulette_depth = 2 }}
        camera = {{ position = [0, 1, -3.5], look_at = [0, 1, 0] {camera} }}
        object = [
            {{ shape = "box", min = [-2, 0, -4], max = [2, 2.5, 2], inward = true, material = "wall" }},
            {{ shape = "sphere", center = [-0.7, 0.8, 0], radius = 0.6, subdivisions = 2, material = "ball" }},
            {{ shape = "sphere", center = [0.8, 0.6, 0.3], radius = 0.5, subdivisions = 2, material = "gem" }},
        ]
        [[light]]
        type = "point"
        position = [0, 2.2, -1]
        intensity = 8
        [materials.wall]
        type = "diffuse"
        albedo = [0.7, 0.6, 0.5]
        {extra}
        "#,
        camera = if extra.contains("[media.fog]") {
            ", medium = \"fog\""
        } else {
            ""
        },
    )
}

const SMOKE: &str = "[materials.ball]\ntype = \"interface\"\nmedium = \"smoke\"\n\
    [media.smoke]\nalbedo = [0.9, 0.8, 0.6]\ndensity = 3\ng = 0.4\n";
const TINTED: &str = "[materials.gem]\ntype = \"glass\"\nmedium = \"tint\"\n\
    [media.tint]\nsigma_a = [0.2, 1, 2]\n";
const PLAIN_GLASS: &str = "[materials.gem]\ntype = \"glass\"\n";
const PLAIN_BALL: &str = "[materials.ball]\ntype = \"diffuse\"\n";
const FOG: &str = "[media.fog]\nsigma_s = 0.15\nsigma_a = 0.02\ng = -0.2\n";

#[test]
fn media_scenes_render_the_same_bits_specialised_or_forced() {
    let cases = [
        ("smoke sphere", format!("{SMOKE}{PLAIN_GLASS}")),
        ("tinted glass", format!("{PLAIN_BALL}{TINTED}")),
        ("fog", format!("{PLAIN_BALL}{PLAIN_GLASS}{FOG}")),
        ("fog, smoke, tinted glass", format!("{SMOKE}{TINTED}{FOG}")),
    ];
    for (what, extra) in cases {
        let scene = load(&room(&extra));
        assert!(Effects::of(&scene).media, "{what}");
        let (auto, _) = assert_same_bits(what, &scene, 0);
        assert!(auto.stats.flights > 0, "{what}");
        // Guard: the media do change the image, so equal bits are not vacuous.
        let without = load(&room(&format!("{PLAIN_BALL}{PLAIN_GLASS}")));
        assert_ne!(auto.pixels, render(&without, None, 0).pixels, "{what}");
    }
}

#[test]
fn without_media_no_flight_is_sampled_unless_media_are_forced() {
    let scene = load(&room(&format!("{PLAIN_BALL}{PLAIN_GLASS}")));
    assert!(!Effects::of(&scene).media);
    let (auto, all) = assert_same_bits("no media", &scene, 0);
    assert_eq!(auto.stats.flights, 0);
    assert_eq!(auto.stats.medium_scatters, 0);
    assert_eq!(all.flights, all.rays, "forced: one flight per ray");
    assert_eq!(all.medium_scatters, 0, "a vacuum scatters nothing");
    assert_eq!(all.shadow_rays, auto.stats.shadow_rays);
    // A vacuum medium bound to glass is no medium at all.
    let vacuum = load(&room(&format!(
        "{PLAIN_BALL}[materials.gem]\ntype = \"glass\"\nmedium = \"v\"\n[media.v]\nsigma_s = 0\n"
    )));
    assert!(!Effects::of(&vacuum).media);
    assert_eq!(render(&vacuum, None, 0).pixels, auto.pixels);
}
