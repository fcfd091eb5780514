//! Every way of sampling media ([`MediaSampling`], the `tessera accuracy --knobs media` ladder)
//! converges to the same mean, held to closed forms over families of densities, albedos and
//! phase asymmetries, grey and chromatic:
//!
//! - a white furnace (a sphere of a medium that only scatters, under a white sky) renders 1,
//!   whatever the flights and shadow rays meet;
//! - an emitter seen through a slab that absorbs and scatters, emitters only, arrives with
//!   `exp(-sigma_t d)`: the fraction of flights that cross without a real collision;
//! - ratio-tracked shadow rays through a slab average `exp(-sigma_t d)`;
//! - in a room with smoke, tinted glass and fog (no closed form) each choice's image mean agrees
//!   with the default's;
//! - and a scene without media keeps its bits under every choice with media forced on, which is
//!   what lets the knob live beside `--effects all`.

mod common;

use common::{
    assert_close, mean_and_error, ray_to_the_floor_under_the_light, render,
    slab_under_a_point_light,
};
use glam::Vec3;
use tracer::medium::MediaSampling;
use tracer::sampler::PixelSampler;
use tracer::scene::{Scene, load_str};
use tracer::{Effects, World};

/// `toml`'s scene, sampling its media as `media` says.
fn load(toml: &str, media: MediaSampling) -> Scene {
    let mut scene = load_str(toml).expect("test scene loads");
    scene.settings.media = media;
    scene
}

#[test]
fn every_choice_renders_one_in_a_white_furnace() {
    let media = [
        "albedo = 1\ndensity = 0.7",
        "albedo = 1\ndensity = 3\ng = 0.6",
        "sigma_s = [0.3, 1.5, 4]\ng = -0.3",
    ];
    for sampling in MediaSampling::LADDER {
        for medium in media {
            let toml = format!(
                r#"
                render = {{ width = 16, height = 16, spp = 32, max_depth = "unlimited", russian_roulette_depth = "off" }}
                camera = {{ position = [0, 0, -3], look_at = [0, 0, 0], vfov = 40 }}
                object = [{{ shape = "sphere", radius = 1, subdivisions = 3, material = "boundary" }}]
                environment = {{ radiance = 1 }}
                [materials.boundary]
                type = "interface"
                medium = "inside"
                [media.inside]
                {medium}
                "#
            );
            let out = render(&load(&toml, sampling), None, 0);
            assert!(out.stats.medium_scatters > 0, "nothing scattered");
            let what = format!("furnace, {}, {medium:?}", sampling.name());
            // Four standard errors and 0.5 % for the rounding of long paths.
            assert_close(&what, mean_and_error(&out), Vec3::ONE, 0.005);
        }
    }
}

#[test]
fn an_emitter_behind_a_scattering_slab_arrives_with_exp_of_minus_sigma_t_d() {
    // Emitters only: a flight that scatters ends its path, so what arrives is the fraction of
    // flights that cross the slab without a real collision, exp(-sigma_t d) per channel.
    let coefficients: [(&str, [f32; 3]); 4] = [
        ("albedo = 0.5\ndensity = 1.2", [1.2; 3]),
        ("albedo = 0.9\ndensity = 0.4\ng = 0.8", [0.4; 3]),
        (
            "sigma_a = [0.1, 0.4, 0.9]\nsigma_s = [0.6, 0.3, 0.05]",
            [0.7, 0.7, 0.95],
        ),
        (
            "sigma_a = [0.05, 0.5, 0]\nsigma_s = [0, 0.4, 1.6]",
            [0.05, 0.9, 1.6],
        ),
    ];
    for sampling in MediaSampling::LADDER {
        for thickness in [0.5f32, 1.5] {
            for (medium, sigma_t) in coefficients {
                let toml = format!(
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
                );
                let out = render(&load(&toml, sampling), None, 0);
                // Rays lie within 1.5 degrees of the axis: their paths are at most 1.0004 d.
                let expected = Vec3::from_array(sigma_t.map(|s| (-s * thickness).exp()));
                let what = format!("{}, {medium:?}, d = {thickness}", sampling.name());
                assert_close(&what, mean_and_error(&out), expected, 0.002);
            }
        }
    }
}

#[test]
fn ratio_tracked_shadow_rays_through_a_slab_average_exp_of_minus_sigma_t_d() {
    // A floor point under a point light seen through a slab `[2, 2 + d]` high; the camera ray
    // misses the slab, so only the shadow ray's transmittance is random (`tests/media.rs` has
    // the same scene in closed form).
    let by_hand = 16.0 / (16.0 * std::f64::consts::PI);
    let coefficients: [(&str, [f64; 3]); 3] = [
        ("albedo = 0.5\ndensity = 1.5", [1.5; 3]),
        ("sigma_a = 0.2\nsigma_s = [0.1, 0.8, 2]", [0.3, 1.0, 2.2]),
        ("sigma_a = [0, 0.5, 3]", [0.0, 0.5, 3.0]),
    ];
    let ratio = MediaSampling::LADDER
        .into_iter()
        .filter(|m| m.shadows == tracer::medium::ShadowTransmittance::RatioTracking);
    for sampling in ratio {
        for thickness in [0.3f32, 1.2] {
            for (medium, sigma_t) in coefficients {
                let toml = slab_under_a_point_light(
                    thickness,
                    &format!("medium = \"m\"\n[media.m]\n{medium}"),
                );
                let world = World::prepare(load(&toml, sampling), None);
                let ray = ray_to_the_floor_under_the_light();
                let n = 20_000u32;
                let mut sum = [0.0f64; 3];
                for sample in 0..n {
                    let mut sampler = PixelSampler::new(0, 0, 0, 0, sample);
                    let mut stats = tracer::PathStats::default();
                    let radiance = world.radiance(ray, 0.0, &mut sampler, &mut stats);
                    for c in 0..3 {
                        sum[c] += f64::from(radiance[c]);
                    }
                }
                for c in 0..3 {
                    let mean = sum[c] / f64::from(n);
                    let expected = by_hand * (-sigma_t[c] * f64::from(thickness)).exp();
                    // Each estimate lies in [0, by_hand]: its standard error is at most half that
                    // over sqrt(n).
                    let tolerance = 4.0 * 0.5 * by_hand / f64::from(n).sqrt() + 1e-6;
                    assert!(
                        (mean - expected).abs() <= tolerance,
                        "{}, {medium:?}, d = {thickness}, channel {c}: {mean}, expected {expected}",
                        sampling.name()
                    );
                }
            }
        }
    }
}

/// A diffuse room lit by a point light, with a smoke ball, a tinted glass and thin fog.
const ROOM: &str = r#"
    render = { width = 24, height = 18, spp = 64, max_depth = 6, russian_roulette_depth = 2 }
    camera = { position = [0, 1, -3.5], look_at = [0, 1, 0], medium = "fog" }
    object = [
        { shape = "box", min = [-2, 0, -4], max = [2, 2.5, 2], inward = true, material = "wall" },
        { shape = "sphere", center = [-0.7, 0.8, 0], radius = 0.6, subdivisions = 2, material = "ball" },
        { shape = "sphere", center = [0.8, 0.6, 0.3], radius = 0.5, subdivisions = 2, material = "gem" },
    ]
    [[light]]
    type = "point"
    position = [0, 2.2, -1]
    intensity = 8
    [materials.wall]
    type = "diffuse"
    albedo = [0.7, 0.6, 0.5]
    [materials.ball]
    type = "interface"
    medium = "smoke"
    [media.smoke]
    albedo = [0.9, 0.8, 0.6]
    density = [2, 3, 4]
    g = 0.4
    [materials.gem]
    type = "glass"
    medium = "tint"
    [media.tint]
    sigma_a = [0.2, 1, 2]
    [media.fog]
    sigma_s = 0.15
    sigma_a = 0.02
    g = -0.2
"#;

#[test]
fn in_a_room_with_every_kind_of_medium_each_choice_agrees_with_the_default() {
    let default = render(&load(ROOM, MediaSampling::default()), None, 0);
    let (mean, se) = mean_and_error(&default);
    for sampling in &MediaSampling::LADDER[1..] {
        let out = render(&load(ROOM, *sampling), None, 0);
        assert_ne!(
            out.pixels,
            default.pixels,
            "{}: a different estimator",
            sampling.name()
        );
        let (other, other_se) = mean_and_error(&out);
        for c in 0..3 {
            // Both renders' errors (they share the main random stream, so this is generous).
            let tolerance = 4.0 * (se[c].powi(2) + other_se[c].powi(2)).sqrt() + 0.005 * mean[c];
            assert!(
                (other[c] - mean[c]).abs() <= tolerance,
                "{}: channel {c} mean {} against the default's {} (tolerance {tolerance})",
                sampling.name(),
                other[c],
                mean[c]
            );
        }
    }
}

#[test]
fn without_media_every_choice_keeps_the_bits_with_media_forced_on() {
    // The room's walls and light, with a diffuse ball and a plain glass: no medium anywhere.
    let walls = &ROOM[..ROOM.find("[materials.ball]").expect("the room has a ball")];
    let plain = walls.replace(", medium = \"fog\"", "")
        + "[materials.ball]\ntype = \"diffuse\"\n[materials.gem]\ntype = \"glass\"\n";
    let auto = render(&load(&plain, MediaSampling::default()), None, 0);
    assert!(!Effects::of(&load(&plain, MediaSampling::default())).media);
    for sampling in MediaSampling::LADDER {
        let forced = render(&load(&plain, sampling), Some(Effects::ALL), 0);
        assert!(
            forced.stats.flights > 0,
            "media forced on: a flight per ray"
        );
        assert_eq!(forced.pixels, auto.pixels, "{}", sampling.name());
    }
}
