//! Depth of field: the thin lens against the thin-lens formula, and the pinhole it must stay.
//!
//! A small emitter on the axis at distance `d`, seen through a lens of radius `A` focused at `f`,
//! spreads into a disk whose radius on the focus plane is `A |d - f| / d`; the image shows that
//! plane at `(height / 2) / (f tan(vfov / 2))` pixels per unit. The spread is measured from the
//! image's second moment about its centroid: blurring by a uniform disk of radius `R` adds
//! `R^2 / 2` to the pinhole image's moment (moments of independent offsets add), whatever the
//! emitter's own size and the pixel filter, which the pinhole render of the same scene carries.

mod common;

use common::{assert_same_bits, render};
use tracer::Effects;
use tracer::scene::Scene;

/// The image's total, centroid and second moment about it, in pixels.
fn moments(pixels: &[[f32; 3]], width: u32) -> (f64, (f64, f64), f64) {
    let mut total = 0.0f64;
    let (mut sx, mut sy) = (0.0f64, 0.0f64);
    for (i, p) in pixels.iter().enumerate() {
        let value = f64::from(p[1]);
        let (x, y) = (
            (i as u32 % width) as f64 + 0.5,
            (i as u32 / width) as f64 + 0.5,
        );
        total += value;
        sx += value * x;
        sy += value * y;
    }
    let centre = (sx / total, sy / total);
    let mut second = 0.0f64;
    for (i, p) in pixels.iter().enumerate() {
        let (x, y) = (
            (i as u32 % width) as f64 + 0.5,
            (i as u32 / width) as f64 + 0.5,
        );
        second += f64::from(p[1]) * ((x - centre.0).powi(2) + (y - centre.1).powi(2));
    }
    (total, centre, second / total)
}

/// The farthest lit pixel centre from `centre`.
fn extent(pixels: &[[f32; 3]], width: u32, centre: (f64, f64)) -> f64 {
    pixels
        .iter()
        .enumerate()
        .filter(|(_, p)| p[1] > 0.0)
        .map(|(i, _)| {
            let (x, y) = (
                (i as u32 % width) as f64 + 0.5,
                (i as u32 / width) as f64 + 0.5,
            );
            ((x - centre.0).powi(2) + (y - centre.1).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

const SIZE: u32 = 64;
const VFOV: f64 = 40.0;

/// An emissive square facing the camera on the axis at distance `d` (flat, so all of it is at
/// that distance; its side 6 % of `d`), the camera at the origin with the lens keys `lens`;
/// emitters only.
fn emitter(d: f64, lens: &str, spp: u32) -> Scene {
    let s = 0.03 * d;
    let toml = format!(
        "render = {{ width = {SIZE}, height = {SIZE}, spp = {spp}, max_depth = 0 }}\n\
         camera = {{ position = [0, 0, 0], look_at = [0, 0, 1], vfov = {VFOV} {lens} }}\n\
         [[object]]\nshape = \"quad\"\n\
         corners = [[-{s}, -{s}, {d}], [-{s}, {s}, {d}], [{s}, {s}, {d}], [{s}, -{s}, {d}]]\n\
         material = \"lamp\"\n[materials.lamp]\ntype = \"emissive\"\nemission = 1\n"
    );
    tracer::scene::load_str(&toml).expect("scene loads")
}

#[test]
fn a_defocused_emitter_spreads_into_the_thin_lens_circle_of_confusion() {
    let (aperture, focus) = (0.25f64, 2.0f64);
    let pixels_per_unit = f64::from(SIZE) / 2.0 / (focus * (VFOV / 2.0).to_radians().tan());
    let lens = format!(", aperture_radius = {aperture}, focus_distance = {focus}");
    for d in [4.0, 1.2, 2.0] {
        let spp = 256;
        let pinhole = render(&emitter(d, "", spp), None, 0);
        let blurred_scene = emitter(d, &lens, spp);
        assert!(Effects::of(&blurred_scene).depth_of_field);
        let blurred = render(&blurred_scene, None, 0);
        let (pinhole_total, pinhole_centre, pinhole_second) = moments(&pinhole.pixels, SIZE);
        let (total, centre, second) = moments(&blurred.pixels, SIZE);
        let expected = aperture * (d - focus).abs() / d * pixels_per_unit;
        let measured = (2.0 * (second - pinhole_second)).max(0.0).sqrt();
        eprintln!(
            "d {d}: blur radius {measured:.3} px, thin lens {expected:.3} px; flux {total:.2} vs \
             pinhole {pinhole_total:.2}"
        );
        // The blur keeps the image centred and spends no light: the lens only moves rays.
        for (a, b) in [(centre.0, pinhole_centre.0), (centre.1, pinhole_centre.1)] {
            assert!(
                (a - b).abs() < 0.25,
                "d {d}: centre {centre:?} vs {pinhole_centre:?}"
            );
        }
        // About 7,000 samples hit the emitter: 1.2 % of noise in the flux, 4 sigma allowed.
        assert!(
            (total / pinhole_total - 1.0).abs() < 0.05,
            "d {d}: flux {total} vs pinhole {pinhole_total}"
        );
        if d == focus {
            // On the focus plane the lens is as sharp as the pinhole (to a hundredth of a pixel
            // squared, the noise of the moments).
            assert!(
                (second - pinhole_second).abs() < 0.05,
                "in focus: second moment {second} vs pinhole {pinhole_second}"
            );
        } else {
            assert!(
                (measured / expected - 1.0).abs() < 0.015,
                "d {d}: blur radius {measured} px, thin lens says {expected} px"
            );
            // And nothing lies beyond the disk: its radius plus the emitter's own image.
            let reach = extent(&blurred.pixels, SIZE, centre);
            let own = extent(&pinhole.pixels, SIZE, pinhole_centre);
            assert!(reach <= expected + own + 1.0, "d {d}: lit {reach} px out");
            assert!(reach >= expected, "d {d}: lit only {reach} px out");
        }
    }
}

/// A lit scene (floor, box, sphere, point light and sky) with the camera keys `camera`.
fn lit(camera: &str) -> Scene {
    let toml = format!(
        r#"
        render = {{ width = 20, height = 16, spp = 4, max_depth = 4 }}
        object = [
            {{ shape = "quad", corners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]], material = "floor" }},
            {{ shape = "box", min = [-1.8, 0, -0.5], max = [-0.8, 1.2, 0.5], material = "floor" }},
            {{ shape = "sphere", center = [0.8, 0.7, 0], radius = 0.7, subdivisions = 2, material = "glass" }},
        ]
        materials.floor = {{ type = "diffuse", albedo = 0.7 }}
        materials.glass = {{ type = "glass" }}
        {camera}
        [[light]]
        type = "point"
        position = [1, 4, -2]
        intensity = 20
        [environment]
        radiance = [0.4, 0.5, 0.7]
        "#
    );
    tracer::scene::load_str(&toml).expect("scene loads")
}

fn bits(pixels: &[[f32; 3]]) -> Vec<u32> {
    pixels.iter().flatten().map(|c| c.to_bits()).collect()
}

#[test]
fn aperture_zero_is_the_pinhole_to_the_bit_and_lenses_animate_by_keys() {
    let pose = "position = [0, 1.5, -5], look_at = [0, 0.5, 0]";
    let pinhole = lit(&format!("camera = {{ {pose} }}"));
    let closed = lit(&format!(
        "camera = {{ {pose}, aperture_radius = 0, focus_distance = 3 }}"
    ));
    assert!(!Effects::of(&closed).depth_of_field);
    let reference = render(&pinhole, None, 0);
    assert_eq!(
        bits(&render(&closed, None, 0).pixels),
        bits(&reference.pixels)
    );
    assert_eq!(
        bits(&render(&closed, Some(Effects::ALL), 0).pixels),
        bits(&reference.pixels),
        "forcing depth of field on changes no pinhole frame"
    );

    // The lens opens from a pinhole at frame 0 to radius 0.3 at frame 8, focusing nearer.
    let opening = lit("[camera]\nposition = [0, 1.5, -5]\nlook_at = [0, 0.5, 0]\n\
         [[camera.keys]]\nframe = 0\naperture_radius = 0\n\
         [[camera.keys]]\nframe = 8\naperture_radius = 0.3\nfocus_distance = 4\n");
    assert!(Effects::of(&opening).depth_of_field);
    let camera = opening.camera.at(4);
    // Unless a key says otherwise, it focuses on the point looked at.
    let focus_start = 26.0f32.sqrt();
    assert_eq!(opening.camera.at(0).focus_distance, focus_start);
    assert_eq!(camera.aperture_radius, 0.15);
    assert!((camera.focus_distance - 0.5 * (focus_start + 4.0)).abs() < 1e-5);
    let (first, _) = assert_same_bits("opening lens, frame 0", &opening, 0);
    assert_eq!(
        bits(&first.pixels),
        bits(&reference.pixels),
        "a key of aperture 0 is the pinhole"
    );
    for frame in [4, 8] {
        let (out, _) = assert_same_bits(&format!("opening lens, frame {frame}"), &opening, frame);
        assert_ne!(
            bits(&out.pixels),
            bits(&render(&pinhole, None, frame).pixels)
        );
    }
}

#[test]
fn lens_keys_are_checked_and_default_to_focus_on_the_point_looked_at() {
    let base =
        "[[object]]\nshape = \"sphere\"\nmaterial = \"m\"\n[materials.m]\ntype = \"diffuse\"\n";
    let scene = tracer::scene::load_str(&format!(
        "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\naperture_radius = 0.1\n{base}"
    ))
    .expect("scene loads");
    let camera = scene.camera.at(0);
    assert_eq!((camera.aperture_radius, camera.focus_distance), (0.1, 5.0));
    for (keys, words) in [
        ("aperture_radius = -0.1", "must not be negative"),
        ("focus_distance = 0", "must be greater than 0"),
        ("aperture_radius = inf", "must be a finite number"),
    ] {
        let toml = format!("[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n{keys}\n{base}");
        let error = tracer::scene::load_str(&toml).expect_err(keys).to_string();
        assert!(
            error.contains("scene.toml:4") && error.contains(words),
            "{keys}: {error}"
        );
    }
}
