//! The three ways area lights are found (`tracer::integrator::AreaLightSampling`): both
//! strategies weighted by the power heuristic, next-event estimation alone, BSDF sampling alone.
//! All three must estimate the same image (an emitting room whose radiance is known in closed
//! form), each must be the better one where the other fails (so the weighting is worth its
//! time), and the knob must leave every light that is not an area light alone.

mod common;

use common::{assert_close, load_with, mean_and_error, render_world};
use glam::Vec3;
use tracer::integrator::AreaLightSampling;
use tracer::{TileOutput, World};

fn render(toml: &str, sampling: AreaLightSampling) -> TileOutput {
    let scene = load_with(toml, &[]).expect("the scene loads");
    let mut world = World::prepare(scene, None);
    world.area_lights = sampling;
    render_world(&world, 0)
}

/// A closed room whose every wall emits `emission` and reflects diffusely with `albedo`, seen
/// from inside: every path sees `emission (1 + albedo + albedo^2 + ...)`, so every pixel's
/// expectation is `emission / (1 - albedo)`, whatever strategy finds the walls.
fn emitting_room(shape: &str, emission: Vec3, albedo: Vec3) -> String {
    format!(
        "render = {{ width = 24, height = 24, spp = 8, max_depth = \"unlimited\", russian_roulette_depth = 3 }}\n\
         camera = {{ position = [0.1, 0.2, -0.3], look_at = [0.4, -0.1, 1], vfov = 70 }}\n\
         [[object]]\n{shape}\nmaterial = \"wall\"\n\
         [materials.wall]\ntype = \"emissive\"\nemission = [{}, {}, {}]\nalbedo = [{}, {}, {}]\n",
        emission.x, emission.y, emission.z, albedo.x, albedo.y, albedo.z
    )
}

#[test]
fn every_choice_keeps_an_emitting_room_at_its_closed_form_radiance() {
    let rooms = [
        "shape = \"box\"\nmin = [-1, -1, -1]\nmax = [1, 1, 1]\ninward = true",
        "shape = \"box\"\nmin = [-3, -0.5, -2]\nmax = [0.5, 4, 6]\ninward = true",
        "shape = \"sphere\"\nradius = 2\nsubdivisions = 2\ninward = true\nsmooth = false",
    ];
    let cases = [
        (Vec3::splat(0.5), Vec3::splat(0.5)),
        (Vec3::new(1.0, 0.25, 2.0), Vec3::new(0.2, 0.5, 0.7)),
        (Vec3::splat(3.0), Vec3::ZERO),
    ];
    for room in rooms {
        for (emission, albedo) in cases {
            let expected = emission / (Vec3::ONE - albedo);
            let toml = emitting_room(room, emission, albedo);
            for sampling in AreaLightSampling::ALL {
                let out = render(&toml, sampling);
                let what = format!("{sampling:?}, {room:?}, albedo {albedo}");
                assert_close(&what, mean_and_error(&out), expected, 0.0);
                // Where the walls reflect, next-event estimation runs at every bounce.
                assert_eq!(out.stats.light_samples > 0, albedo.x > 0.0, "{what}");
            }
        }
    }
}

/// A diffuse or glossy floor under one square lamp of side `lamp` at height 2, seen from above,
/// rendered with the pixel streams' `seed`.
fn floor_under_lamp(floor: &str, lamp: f32, seed: u32) -> String {
    let h = lamp / 2.0;
    format!(
        "render = {{ width = 16, height = 16, spp = 32, max_depth = 1, seed = {seed} }}\n\
         camera = {{ position = [0, 1.5, -3], look_at = [0, 0, 0.5], vfov = 40 }}\n\
         [[object]]\nshape = \"quad\"\ncorners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]]\nmaterial = \"floor\"\n\
         [[object]]\nshape = \"quad\"\ncorners = [[-{h}, 2, -{h}], [{h}, 2, -{h}], [{h}, 2, {h}], [-{h}, 2, {h}]]\nmaterial = \"lamp\"\n\
         [materials.floor]\n{floor}\n\
         [materials.lamp]\ntype = \"emissive\"\nemission = {}\n",
        4.0 / (lamp * lamp)
    )
}

/// Red channels of `a` minus `b`, pixel by pixel, as f64.
fn differences(a: &TileOutput, b: &TileOutput) -> Vec<f64> {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(a, b)| f64::from(a[0]) - f64::from(b[0]))
        .collect()
}

/// The mean of `d` and its standard error.
fn mean_and_se(d: &[f64]) -> (f64, f64) {
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let variance = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (variance / n).sqrt())
}

#[test]
fn each_strategy_alone_fails_where_the_weighting_does_not() {
    // A small lamp over a diffuse floor: BSDF sampling rarely finds it, light sampling always.
    // A large lamp over a glossy metal: light sampling draws points the lobe ignores, BSDF
    // sampling follows the lobe.
    let diffuse = "type = \"diffuse\"\nalbedo = 0.7";
    let glossy = "type = \"metal\"\nreflectance = 0.9\nroughness = 0.1";
    for (what, floor, lamp, worse) in [
        (
            "small lamp, diffuse floor",
            diffuse,
            0.1,
            AreaLightSampling::Bsdf,
        ),
        (
            "large lamp, glossy floor",
            glossy,
            6.0,
            AreaLightSampling::Light,
        ),
    ] {
        let renders =
            |seed| AreaLightSampling::ALL.map(|s| render(&floor_under_lamp(floor, lamp, seed), s));
        let [mis, light, bsdf] = renders(1);
        let [mis_again, light_again, bsdf_again] = renders(2);
        assert!(
            mis.pixels.iter().any(|p| p[0] > 0.0),
            "{what}: a black image proves little"
        );
        // All three estimate the same image: pixel by pixel, their differences average to zero
        // within four standard errors of that average.
        for (other, out) in [("light-only", &light), ("bsdf-only", &bsdf)] {
            let (mean, se) = mean_and_se(&differences(&mis_again, out));
            assert!(
                mean.abs() <= 4.0 * se,
                "{what}: mis and {other} differ by {mean} per pixel (se {se})"
            );
        }
        // Noise: the spread of the difference between two independent renders of one choice.
        let noise = |a, b| mean_and_se(&differences(a, b)).1;
        let mis_noise = noise(&mis, &mis_again);
        let worse_noise = match worse {
            AreaLightSampling::Bsdf => noise(&bsdf, &bsdf_again),
            _ => noise(&light, &light_again),
        };
        assert!(
            mis_noise * 2.0 < worse_noise,
            "{what}: mis noise {mis_noise} against {worse:?}'s {worse_noise}"
        );
    }
}

#[test]
fn lights_that_are_not_area_lights_render_the_same_bits_whatever_the_choice() {
    // A point light and a constant sky over a diffuse floor: no emissive triangle, so the knob
    // must change nothing, neither the delta light's weight nor the environment's MIS.
    let toml = "render = { width = 16, height = 16, spp = 4, max_depth = 3 }\n\
        camera = { position = [0, 1.5, -3], look_at = [0, 0, 0.5], vfov = 40 }\n\
        [[object]]\nshape = \"quad\"\ncorners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]]\nmaterial = \"floor\"\n\
        [[object]]\nshape = \"sphere\"\ncenter = [0.5, 0.6, 0.5]\nradius = 0.6\nmaterial = \"floor\"\n\
        [materials.floor]\ntype = \"diffuse\"\nalbedo = 0.6\n\
        [[light]]\ntype = \"point\"\nposition = [1, 3, -1]\nintensity = 5\n\
        [environment]\nradiance = [0.3, 0.4, 0.5]\n";
    let bits = |out: &TileOutput| -> Vec<u32> {
        out.pixels.iter().flatten().map(|c| c.to_bits()).collect()
    };
    let [mis, light, bsdf] = AreaLightSampling::ALL.map(|s| render(toml, s));
    assert!(mis.pixels.iter().flatten().any(|&c| c > 0.0));
    assert_eq!(bits(&mis), bits(&light), "light-only moved a pixel");
    assert_eq!(bits(&mis), bits(&bsdf), "bsdf-only moved a pixel");
}
