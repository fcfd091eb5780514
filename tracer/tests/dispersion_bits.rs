//! Dispersion and determinism: a pixel stays a pure function of (scene, frame, pixel, sample,
//! seed) when paths turn spectral, the specialised pipeline gives the forced one's bits, and
//! forcing the effect on never turns an RGB scene spectral.

mod common;

use common::{assert_same_bits, render};
use std::path::Path;
use tracer::spectrum::SpectralSampling;
use tracer::{Effects, FrameConfig, Rect, World};

/// The shipped prism scene, shrunk to `w` x `h` at `spp` samples.
fn prism(w: u32, h: u32, spp: u32) -> tracer::Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/prism/prism.toml");
    let mut scene = tracer::scene::load(&path).expect("the shipped prism loads");
    scene.settings.width = w;
    scene.settings.height = h;
    scene.settings.samples_per_pixel = spp;
    scene
}

fn bits(pixels: &[[f32; 3]]) -> Vec<u32> {
    pixels.iter().flatten().map(|c| c.to_bits()).collect()
}

#[test]
fn the_prism_renders_the_same_bits_specialised_or_forced() {
    let scene = prism(48, 36, 4);
    let effects = Effects::of(&scene);
    assert!(effects.dispersion && effects.refraction, "{effects}");
    assert_ne!(effects, Effects::ALL);
    let (auto, forced) = assert_same_bits("prism", &scene, 0);
    assert!(auto.stats.spectral_paths > 0 && forced.spectral_paths == auto.stats.spectral_paths);
    // Not every path meets the prism: the others stay RGB.
    assert!(auto.stats.spectral_paths < 48 * 36 * 4);
}

#[test]
fn spectral_pixels_do_not_depend_on_tiles_or_threads() {
    let scene = prism(40, 30, 4);
    let world = World::prepare(scene, None);
    let whole = tracer::render_tile(
        &world,
        0,
        Rect {
            x: 0,
            y: 0,
            w: 40,
            h: 30,
        },
    );
    for (threads, tile) in [(1, 7), (2, 16), (2, 3)] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool");
        let film = tracer::render_frame(&world, 0, &pool, FrameConfig { tile });
        assert_eq!(
            bits(&film.pixels),
            bits(&whole.pixels),
            "{threads} threads, tiles of {tile}"
        );
    }
    // The always-spectral sampling is as deterministic.
    let mut hero = World::prepare(prism(40, 30, 4), None);
    hero.spectral = SpectralSampling::Hero;
    let once = tracer::render_tile(
        &hero,
        0,
        Rect {
            x: 0,
            y: 0,
            w: 40,
            h: 30,
        },
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool");
    let tiled = tracer::render_frame(&hero, 0, &pool, FrameConfig { tile: 5 });
    assert_eq!(bits(&tiled.pixels), bits(&once.pixels));
    assert_ne!(
        bits(&once.pixels),
        bits(&whole.pixels),
        "the knob changes nothing"
    );
}

#[test]
fn forcing_dispersion_never_turns_an_rgb_scene_spectral() {
    let toml = r#"
        render = { width = 20, height = 16, spp = 4, max_depth = 6 }
        camera = { position = [0, 1.5, -5], look_at = [0, 0.5, 0] }
        object = [
            { shape = "quad", corners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]], material = "floor" },
            { shape = "sphere", center = [0.8, 0.7, 0], radius = 0.7, subdivisions = 2, material = "glass" },
        ]
        [materials.floor]
        type = "diffuse"
        albedo = [0.7, 0.5, 0.3]
        [materials.glass]
        type = "glass"
        ior = 1.5
        [environment]
        radiance = [0.4, 0.5, 0.7]
    "#;
    let scene = tracer::scene::load_str(toml).expect("test scene loads");
    assert!(!Effects::of(&scene).dispersion);
    let forced = render(&scene, Some(Effects::ALL), 0);
    assert!(forced.stats.refractions > 0, "the glass is seen");
    assert_eq!(forced.stats.spectral_paths, 0);
    assert_eq!(bits(&forced.pixels), bits(&render(&scene, None, 0).pixels));
}
