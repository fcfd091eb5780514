//! Nested participating media against closed forms: an object whose boundary names the medium
//! on its outside (`outside_medium`) leads paths and shadow rays that leave it back into the
//! enclosing object's medium, not into the camera's.
//!
//! - Shadow rays through a box B of medium m2 inside a box A of medium m1 carry
//!   `exp(-sigma_t1 d1 - sigma_t2 d2)` (deterministic, to float rounding), for several
//!   coefficients and thicknesses. With B's outside left out (the camera's vacuum, which the
//!   geometry contradicts) the loader refuses the scene, naming `outside_medium`.
//! - Camera rays through the same nesting arrive with that transmittance on average (free-flight
//!   sampling, within Monte Carlo error).
//! - A white furnace of nested scattering media (albedo 1) inside each other, through glass or
//!   interfaces, still renders 1.
//! - Nested scenes render the same bits specialised or with every effect forced. (A medium
//!   named only as an outside cannot load any more: nothing encloses it.)

mod common;

use common::{
    assert_close, assert_same_bits, mean_and_error, radiance_under_the_light, render,
    under_a_point_light,
};
use glam::Vec3;
use tracer::Effects;
use tracer::scene::{Scene, load_str};

fn load(toml: &str) -> Scene {
    load_str(toml).expect("test scene loads")
}

/// Media, each with its extinction per channel: the table's body and `sigma_t`.
const MEDIA: [(&str, [f64; 3]); 4] = [
    ("sigma_a = 0.3", [0.3; 3]),
    ("sigma_a = 1\nsigma_s = 1", [2.0; 3]),
    ("albedo = 0.5\ndensity = 0.8", [0.8; 3]),
    ("sigma_a = [0.2, 1, 5]", [0.2, 1.0, 5.0]),
];

/// The two boxes' materials and media: `a` an interface around `m1`, `b` one around `m2`,
/// whose outside is `m1` when `nested` (else the camera's vacuum, as before media nested).
fn nested_boundaries(m1: &str, m2: &str, nested: bool) -> String {
    let outside = if nested {
        "outside_medium = \"m1\""
    } else {
        ""
    };
    format!(
        r#"
        [materials.a]
        type = "interface"
        medium = "m1"
        [materials.b]
        type = "interface"
        medium = "m2"
        {outside}
        [media.m1]
        {m1}
        [media.m2]
        {m2}
        "#
    )
}

/// A white diffuse floor at y = 0 under a point light of intensity 16 at height 4 above the
/// origin, with box A (`[-1, 1] x [1, 3] x [-1, 1]`, medium `m1`) around box B (`[-0.5, 0.5] x
/// [1.4, 1.4 + d2] x [-0.5, 0.5]`, medium `m2`); B's boundary names `m1` outside when
/// `nested`. Direct light only.
fn boxes_under_a_light(d2: f32, m1: &str, m2: &str, nested: bool) -> String {
    let top = 1.4 + d2;
    under_a_point_light(
        &format!(
            r#"{{ shape = "box", min = [-1, 1, -1], max = [1, 3, 1], material = "a" }},
            {{ shape = "box", min = [-0.5, 1.4, -0.5], max = [0.5, {top}, 0.5], material = "b" }},"#
        ),
        &nested_boundaries(m1, m2, nested),
    )
}

#[test]
fn shadow_rays_through_nested_boxes_carry_each_segments_own_medium() {
    // albedo / pi * I / r^2 with r = 4 and cos = 1, before any medium.
    let by_hand = 16.0 / (16.0 * std::f64::consts::PI);
    for d2 in [0.2f32, 0.6, 1.4] {
        let d2_f64 = f64::from(d2);
        for (m1, sigma_1) in MEDIA {
            for (m2, sigma_2) in MEDIA {
                let toml = boxes_under_a_light(d2, m1, m2, true);
                let (through, stats) = radiance_under_the_light(load(&toml));
                // One shadow ray and four more segments past the boxes' four faces.
                assert_eq!(stats.shadow_rays, 5, "{m1} / {m2}, d2 = {d2}");
                // A's medium is 0.4 thick below B and 1.6 - d2 above it.
                let d1 = 2.0 - d2_f64;
                for c in 0..3 {
                    let expected = by_hand * (-sigma_1[c] * d1 - sigma_2[c] * d2_f64).exp();
                    let got = f64::from(through[c]);
                    assert!(
                        (got - expected).abs() <= 2e-5 * expected,
                        "{m1} around {m2}, d2 = {d2}, channel {c}: {got}, expected {expected}"
                    );
                }
                refused_for_vacuum_around_b(&boxes_under_a_light(d2, m1, m2, false));
            }
        }
    }
}

/// Slab A (`z in [0, 2]`) around slab B (`z in [0.5, 0.5 + d2]`), both wide enough to fill the
/// view, in front of an emitter of radiance 1 facing the camera; emitters only.
fn emitter_behind_nested_slabs(d2: f32, m1: &str, m2: &str, nested: bool) -> String {
    let back = 0.5 + d2;
    let boundaries = nested_boundaries(m1, m2, nested);
    format!(
        r#"
        render = {{ width = 32, height = 32, spp = 16, max_depth = 0 }}
        camera = {{ position = [0, 0, -5], look_at = [0, 0, 0], vfov = 2 }}
        object = [
            {{ shape = "box", min = [-3, -3, 0], max = [3, 3, 2], material = "a" }},
            {{ shape = "box", min = [-2, -2, 0.5], max = [2, 2, {back}], material = "b" }},
            {{ shape = "quad", corners = [[-3, -3, 5], [-3, 3, 5], [3, 3, 5], [3, -3, 5]], material = "lamp" }},
        ]
        [materials.lamp]
        type = "emissive"
        emission = 1
        {boundaries}
        "#
    )
}

#[test]
fn camera_rays_through_nested_slabs_arrive_with_the_product_of_transmittances() {
    let cases = [(0, 3, 0.5f32), (3, 1, 1.0), (1, 0, 1.25)];
    for (i, j, d2) in cases {
        let ((m1, sigma_1), (m2, sigma_2)) = (MEDIA[i], MEDIA[j]);
        let scene = load(&emitter_behind_nested_slabs(d2, m1, m2, true));
        let out = render(&scene, None, 0);
        let d1 = 2.0 - d2;
        // Rays lie within 1.5 degrees of the axis: their paths are at most 1.0004 times
        // the thicknesses.
        let expected = Vec3::from_array(std::array::from_fn(|c| {
            (-(sigma_1[c] as f32) * d1 - (sigma_2[c] as f32) * d2).exp()
        }));
        let what = format!("{m1} around {m2}, d2 = {d2}");
        assert_close(&what, mean_and_error(&out), expected, 0.002);
        refused_for_vacuum_around_b(&emitter_behind_nested_slabs(d2, m1, m2, false));
    }
}

/// A sphere of radius 1 bounded by an interface and filled with `outer`, around a sphere of
/// radius 0.5 bounded by `inner` (a material table's body) filled with `core` and naming the
/// outer medium outside, under a white sky.
fn nested_furnace(inner: &str, outer: &str, core: &str) -> String {
    format!(
        r#"
        render = {{ width = 16, height = 16, spp = 16, max_depth = "unlimited", russian_roulette_depth = "off" }}
        camera = {{ position = [0, 0, -3], look_at = [0, 0, 0], vfov = 40 }}
        object = [
            {{ shape = "sphere", radius = 1, subdivisions = 3, material = "shell" }},
            {{ shape = "sphere", radius = 0.5, subdivisions = 3, material = "core" }},
        ]
        environment = {{ radiance = 1 }}
        [materials.shell]
        type = "interface"
        medium = "outer"
        [materials.core]
        {inner}
        medium = "core"
        outside_medium = "outer"
        [media.outer]
        {outer}
        [media.core]
        {core}
        "#
    )
}

#[test]
fn nested_scattering_media_in_a_white_furnace_render_one() {
    let cases = [
        (
            "type = \"interface\"",
            "albedo = 1\ndensity = 0.7",
            "albedo = 1\ndensity = 4\ng = 0.6",
        ),
        (
            "type = \"glass\"\nior = 1.5",
            "albedo = 1\ndensity = 1.5\ng = -0.3",
            "albedo = 1\ndensity = 2",
        ),
        // Chromatic both: the spectral MIS weights differ from 1 in each medium.
        (
            "type = \"glass\"\nior = 1.33",
            "sigma_s = [0.2, 0.9, 2]",
            "sigma_s = [3, 1, 0.4]\ng = 0.4",
        ),
    ];
    for (inner, outer, core) in cases {
        let scene = load(&nested_furnace(inner, outer, core));
        let out = render(&scene, None, 0);
        assert!(out.stats.medium_scatters > 0, "nothing scattered");
        let what = format!("furnace: {inner:?} with {core:?} inside {outer:?}");
        // Four standard errors of the image mean and 0.5 % for the rounding of long paths.
        assert_close(&what, mean_and_error(&out), Vec3::ONE, 0.005);
    }
}

/// A room lit by a point light, with a box of fog around a glass ball (tinted inside) whose
/// outside is the fog when `nested`.
fn fog_box_room(nested: bool) -> String {
    let outside = if nested {
        "outside_medium = \"fog\""
    } else {
        ""
    };
    format!(
        r#"
        render = {{ width = 16, height = 12, spp = 4, max_depth = 6, russian_roulette_depth = 2 }}
        camera = {{ position = [0, 1, -3.5], look_at = [0, 1, 0] }}
        object = [
            {{ shape = "box", min = [-2, 0, -4], max = [2, 2.5, 2], inward = true, material = "wall" }},
            {{ shape = "box", min = [-1.5, 0.01, -1], max = [1.5, 2, 1.5], material = "fog-boundary" }},
            {{ shape = "sphere", center = [0.3, 0.7, 0.2], radius = 0.5, subdivisions = 2, material = "gem" }},
        ]
        [[light]]
        type = "point"
        position = [0, 2.2, -1]
        intensity = 8
        [materials.wall]
        type = "diffuse"
        albedo = [0.7, 0.6, 0.5]
        [materials.fog-boundary]
        type = "interface"
        medium = "fog"
        [materials.gem]
        type = "glass"
        medium = "tint"
        {outside}
        [media.fog]
        sigma_s = 0.4
        sigma_a = 0.05
        g = 0.3
        [media.tint]
        sigma_a = [0.2, 1, 2]
        "#
    )
}

#[test]
fn nested_media_render_the_same_bits_specialised_or_forced() {
    let nested = load(&fog_box_room(true));
    let (auto, _) = assert_same_bits("glass in a fog box", &nested, 0);
    assert!(auto.stats.flights > 0 && auto.stats.medium_scatters > 0);
    let refused = load_str(&fog_box_room(false)).expect_err("vacuum around glass in fog");
    let says = "[materials.gem]: the geometry puts medium `fog` around it, but its \
                `outside_medium` says vacuum";
    assert!(refused.to_string().contains(says), "{refused}");
}

#[test]
fn a_medium_named_only_outside_an_object_is_refused() {
    // A glass ball in a fog that only its outside names: nothing encloses the ball in the fog,
    // so a ray leaving it escapes to the camera's vacuum, and the loader says so. (Before the
    // nesting check this loaded, and the fog was a medium paths could enter only from the ball.)
    let toml = r#"
        render = { width = 8, height = 8, spp = 2 }
        camera = { position = [0, 0, -3], look_at = [0, 0, 0] }
        object = [{ shape = "sphere", radius = 1, material = "ball" }]
        environment = { radiance = 1 }
        [materials.ball]
        type = "glass"
        outside_medium = "fog"
        [media.fog]
        sigma_a = 0.5
        "#;
    let refused = load_str(toml).expect_err("nothing encloses the ball in fog");
    assert!(
        refused.to_string().contains("escapes to infinity"),
        "{refused}"
    );
    // Enclosed in a fog-filled interface, it loads and tracks media.
    let enclosed = toml
        .replace(
            "[materials.ball]",
            "[materials.around]\ntype = \"interface\"\nmedium = \"fog\"\n[materials.ball]",
        )
        .replace(
            "material = \"ball\" }]",
            "material = \"ball\" }, { shape = \"sphere\", radius = 2, material = \"around\" }]",
        );
    let scene = load(&enclosed);
    assert!(Effects::of(&scene).media);
    assert_same_bits("glass in fog", &scene, 0);
}

/// Asserts that `toml`, in which box B's outside is left out (the camera's vacuum) although
/// it lies inside A's medium, is refused naming `outside_medium` and the medium around B.
fn refused_for_vacuum_around_b(toml: &str) {
    let refused = load_str(toml).expect_err("vacuum around B contradicts the geometry");
    let says = "[materials.b]: the geometry puts medium `m1` around it, but its \
                `outside_medium` says vacuum";
    assert!(refused.to_string().contains(says), "{refused}");
}
