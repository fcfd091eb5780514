//! Specialisation by effect set: absent effects cost nothing, and skipping them changes no bit.
//!
//! Three kinds of test. Counters: per-render [`PathStats`] show zero shadow rays, light samples,
//! refractions or environment lookups exactly where the scene lacks the effect, and non-zero
//! where it has it (or where `Effects::ALL` forces the work on), so a counter that never moved
//! would fail. Bit-identity: every scene here, shipped or procedural, renders to the same bits
//! with its own effect set and with every effect forced on. Closed forms: the furnace, white
//! furnace and point-in-sphere answers hold for every material and every integrator setting
//! (depth limit, Russian roulette), in both effect modes.

mod common;

use common::{mean_and_error, render};
use std::path::Path;
use tracer::scene::{MemoryFiles, Scene};
use tracer::{Effects, PathStats, TileOutput};

/// Renders `scene` specialised and with every effect on, asserts the pixels are the same bits,
/// and returns the specialised render and the forced one's counters.
fn assert_same_bits(what: &str, scene: &Scene, frame: u32) -> (TileOutput, PathStats) {
    let auto = render(scene, None, frame);
    let all = render(scene, Some(Effects::ALL), frame);
    let bits =
        |o: &TileOutput| -> Vec<u32> { o.pixels.iter().flatten().map(|c| c.to_bits()).collect() };
    let (a, b) = (bits(&auto), bits(&all));
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(
        differing,
        0,
        "{what}: {differing} channels differ between effects {} and all",
        Effects::of(scene)
    );
    if Effects::of(scene).has_lights() {
        assert!(
            auto.pixels.iter().flatten().any(|&c| c > 0.0),
            "{what}: a black image proves little"
        );
    }
    (auto, all.stats)
}

fn load(toml: &str) -> Scene {
    tracer::scene::load_str(toml).expect("test scene loads")
}

/// A small open scene: a floor, a box and a sphere of `ball` under the given lights.
fn open_scene(ball: &str, lights: &str) -> String {
    format!(
        r#"
        render = {{ width = 20, height = 16, spp = 4, max_depth = 6, russian_roulette_depth = 2 }}
        camera = {{ position = [0, 1.5, -5], look_at = [0, 0.5, 0] }}
        object = [
            {{ shape = "quad", corners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]], material = "floor" }},
            {{ shape = "box", min = [-1.8, 0, -0.5], max = [-0.8, 1.2, 0.5], material = "floor" }},
            {{ shape = "sphere", center = [0.8, 0.7, 0], radius = 0.7, subdivisions = 2, material = "ball" }},
        ]
        [materials.floor]
        type = "diffuse"
        albedo = 0.7
        [materials.ball]
        {ball}
        {lights}
        "#
    )
}

const POINT: &str = "[[light]]\ntype = \"point\"\nposition = [1, 4, -2]\nintensity = 20";
const SKY: &str = "[environment]\nradiance = [0.4, 0.5, 0.7]";
const DIFFUSE: &str = "type = \"diffuse\"\nalbedo = 0.5";
const GLASS: &str = "type = \"glass\"\nior = 1.5";

/// What a counter must show: non-zero in the specialised render, zero there, or zero there but
/// non-zero with every effect forced on (work `--effects all` pays for and specialising skips).
#[derive(Clone, Copy, PartialEq)]
enum Work {
    Done,
    None,
    Skipped,
}

#[test]
fn counters_are_zero_exactly_where_an_effect_is_absent() {
    use Work::{Done, None, Skipped};
    let closed_black_emitter = "[render]\nwidth = 16\nheight = 16\nspp = 2\n\
        [camera]\nposition = [0.1, 0.2, -0.3]\nlook_at = [1, 0, 0]\nvfov = 90\n\
        [[object]]\nshape = \"sphere\"\nsubdivisions = 2\ninward = true\nmaterial = \"lamp\"\n\
        [materials.lamp]\ntype = \"emissive\"\nemission = 2\n";
    let zero_sky = "[environment]\nradiance = 0";
    let dark_lamp = "[[light]]\ntype = \"point\"\nposition = [1, 4, -2]\nintensity = 0";
    // Light samples, shadow rays, refractions, environment lookups.
    let cases: [(&str, String, [Work; 4]); 7] = [
        (
            "diffuse under a point light",
            open_scene(DIFFUSE, POINT),
            [Done, Done, None, None],
        ),
        (
            "diffuse under sky",
            open_scene(DIFFUSE, SKY),
            [Done, Done, None, Done],
        ),
        (
            "glass under a point light",
            open_scene(GLASS, POINT),
            [Done, Done, Done, None],
        ),
        (
            "nothing emits",
            open_scene(GLASS, ""),
            [Skipped, None, Done, None],
        ),
        (
            "zero sky, a lamp",
            open_scene(DIFFUSE, &format!("{POINT}\n{zero_sky}")),
            [Done, Done, None, Skipped],
        ),
        (
            "a dark lamp, sky",
            open_scene(DIFFUSE, &format!("{dark_lamp}\n{SKY}")),
            [Done, Done, None, Done],
        ),
        (
            "inside a black emitter",
            closed_black_emitter.to_owned(),
            [Skipped, None, None, None],
        ),
    ];
    for (what, toml, expect) in cases {
        let scene = load(&toml);
        let (auto, all) = assert_same_bits(what, &scene, 0);
        let auto = auto.stats;
        let counters = |s: &PathStats| {
            [
                s.light_samples,
                s.shadow_rays,
                s.refractions,
                s.environment_lookups,
            ]
        };
        let names = [
            "light samples",
            "shadow rays",
            "refractions",
            "environment lookups",
        ];
        for (((name, a), b), expect) in names
            .iter()
            .zip(counters(&auto))
            .zip(counters(&all))
            .zip(expect)
        {
            let ok = match expect {
                Done => a > 0,
                None => a == 0,
                Skipped => a == 0 && b > 0,
            };
            assert!(
                ok,
                "{what}: {name} = {a} specialised, {b} with every effect on"
            );
        }
        let effects = Effects::of(&scene);
        assert_eq!(effects.shadows, expect[1] == Done, "{what}: {effects}");
        assert_eq!(effects.refraction, expect[2] == Done, "{what}: {effects}");
        assert_eq!(effects.environment, expect[3] == Done, "{what}: {effects}");
        assert!(auto.work() <= all.work(), "{what}: specialising cost work");
    }
}

#[test]
fn mirrors_and_glass_alone_take_no_light_samples_even_when_forced() {
    // Delta BSDFs never sample lights, whatever the effect set: both counters stay at zero,
    // while the light still arrives (the image is not black) by the BSDF's own sampling.
    let scene =
        load(&open_scene(GLASS, &format!("{POINT}\n{SKY}")).replace("albedo = 0.7", "albedo = 0"));
    let effects = Effects::of(&scene);
    assert!(
        !effects.shadows && !effects.diffuse && effects.refraction,
        "{effects}"
    );
    let (auto, all) = assert_same_bits("glass on black", &scene, 0);
    let auto = auto.stats;
    assert_eq!((auto.light_samples, auto.shadow_rays), (0, 0));
    assert!(
        all.light_samples > 0,
        "black diffuse surfaces still sample lights when forced"
    );
    assert_eq!(
        all.shadow_rays, 0,
        "a black surface never needs a shadow ray"
    );
}

/// `scenes/NAME`, shrunk to `w` x `h` at `spp` samples.
fn shipped(name: &str, w: u32, h: u32, spp: u32) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name);
    let mut scene = tracer::scene::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
    scene.settings.width = w;
    scene.settings.height = h;
    scene.settings.samples_per_pixel = spp;
    scene
}

#[test]
fn shipped_scenes_render_the_same_bits_specialised_or_forced() {
    for (name, frame) in [
        ("cornell-box/cornell-box.toml", 0),
        ("furnace/furnace.toml", 0),
        ("point-in-sphere/point-in-sphere.toml", 0),
        ("glass-cluster-pan/glass-cluster-pan.toml", 0),
        ("glass-cluster-pan/glass-cluster-pan.toml", 13),
        ("cornell-blur/cornell-blur.toml", 0),
        ("cornell-blur/cornell-blur.toml", 12),
        ("prism/prism.toml", 0),
        ("fog-window/fog-window.toml", 0),
        ("fog-window/fog-window.toml", 11),
        ("swinging-lamp/swinging-lamp.toml", 6),
    ] {
        let scene = shipped(name, 24, 20, 4);
        assert_ne!(
            Effects::of(&scene),
            Effects::ALL,
            "{name} would not test specialisation"
        );
        assert_same_bits(name, &scene, frame);
    }
}

#[test]
fn shared_scenes_render_the_same_bits_specialised_or_forced() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes");
    if !shared.is_dir() {
        eprintln!(
            "SKIPPED: {} is absent; the shared scenes were not checked",
            shared.display()
        );
        return;
    }
    // Small images: the point is the many materials (dark glass, water, textures, sky).
    for name in [
        "cornell-box-original",
        "cornell-box-mirror",
        "cornell-box-sphere",
        "cornell-box-water",
        "sponza-skylight",
    ] {
        let scene = shipped(&format!("shared/{name}.toml"), 12, 12, 2);
        assert_same_bits(name, &scene, 0);
    }
}

/// A 4 x 4 RGB checkerboard as PNG bytes.
fn checker_png() -> Vec<u8> {
    let image = image::RgbImage::from_fn(4, 4, |x, y| {
        if (x + y) % 2 == 0 {
            image::Rgb([230, 40, 40])
        } else {
            image::Rgb([20, 20, 200])
        }
    });
    let mut bytes = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, image::ImageFormat::Png)
        .expect("PNG encodes");
    bytes.into_inner()
}

#[test]
fn textures_and_shading_normals_render_the_same_bits_specialised_or_forced() {
    // A floor quad with texture coordinates and shading normals tilted away from its geometric
    // normal, so both code paths change the image.
    let obj = "v -3 0 -3\nv 3 0 -3\nv 3 0 3\nv -3 0 3\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
               vn 0.3 1 0\nvn -0.3 1 0.2\nvn 0 1 -0.4\nvn 0.1 1 0.1\nf 1/1/1 4/4/4 3/3/3 2/2/2\n";
    let toml = r#"
        [render]
        width = 20
        height = 16
        spp = 4
        [camera]
        position = [0, 2, -5]
        look_at = [0, 0, 0]
        [[object]]
        obj = "floor.obj"
        material = "checker"
        [[object]]
        shape = "sphere"
        center = [0, 1, 0]
        radius = 0.8
        subdivisions = 2
        material = "metal"
        [materials.checker]
        type = "diffuse"
        albedo = 1
        texture = "checker.png"
        [materials.metal]
        type = "metal"
        roughness = 0.3
        [[light]]
        type = "point"
        position = [2, 5, -3]
        intensity = 30
        [environment]
        radiance = 0.2
    "#;
    let mut files = MemoryFiles::new();
    files.insert("scene.toml", toml);
    files.insert("floor.obj", obj);
    files.insert("checker.png", checker_png());
    let scene = tracer::scene::load_from(&files, "scene.toml").expect("test scene loads");
    let effects = Effects::of(&scene);
    assert!(
        effects.textures && effects.shading_normals && effects.glossy_reflection,
        "{effects}"
    );
    assert_same_bits("textures and shading normals", &scene, 0);
    // Guard: the texture and the normals do change the image, so equal bits are not vacuous.
    let plain = render(
        &scene,
        Some(Effects {
            textures: false,
            shading_normals: false,
            ..Effects::ALL
        }),
        0,
    );
    assert_ne!(plain.pixels, render(&scene, None, 0).pixels);
}

// The closed forms, for every material and integrator setting.

/// The integrator settings every material is run under: (`max_depth`, `russian_roulette_depth`).
const SETTINGS: [(Option<u32>, Option<u32>); 6] = [
    (Some(1), None),
    (Some(3), None),
    (Some(3), Some(1)),
    (Some(6), Some(2)),
    (None, Some(1)),
    (None, Some(3)),
];

/// `max_depth` as TOML, and the sum of `r^k` for k in 0..=depth (infinite depth: 1 / (1 - r)).
fn depth_toml(depth: Option<u32>) -> String {
    depth.map_or("\"unlimited\"".to_owned(), |d| d.to_string())
}
fn series(r: f32, depth: Option<u32>) -> f32 {
    depth.map_or(1.0 / (1.0 - r), |d| (0..=d).map(|k| r.powi(k as i32)).sum())
}

/// Camera inside a closed inward sphere of `material` (which emits 1.5 inward).
fn furnace(material: &str, depth: Option<u32>, roulette: Option<u32>) -> String {
    let roulette = roulette.map_or("\"off\"".to_owned(), |r| r.to_string());
    format!(
        "[render]\nwidth = 16\nheight = 16\nspp = 8\nmax_depth = {}\nrussian_roulette_depth = {roulette}\n\
         [camera]\nposition = [0.1, -0.2, 0.05]\nlook_at = [1, 0.3, 0.2]\nvfov = 90\n\
         [[object]]\nshape = \"sphere\"\nsubdivisions = 3\ninward = true\nmaterial = \"wall\"\n\
         [materials.wall]\n{material}\nemission = 1.5\n",
        depth_toml(depth)
    )
}

/// A unit sphere of `material` seen from outside in a uniform environment of radiance 0.8.
fn white_furnace(material: &str, depth: Option<u32>, roulette: Option<u32>) -> String {
    furnace(material, depth, roulette)
        .replace(
            "position = [0.1, -0.2, 0.05]\nlook_at = [1, 0.3, 0.2]\nvfov = 90",
            "position = [0, 0, -3]\nlook_at = [0, 0, 0]\nvfov = 40",
        )
        .replace("inward = true", "inward = false")
        .replace("emission = 1.5\n", "[environment]\nradiance = 0.8\n")
}

/// Renders `toml` in both effect modes (asserting the same bits) and asserts the image mean
/// lies in `[lo, hi]` up to four standard errors in every channel.
fn assert_closed_form(what: &str, toml: &str, lo: f32, hi: f32) {
    let (auto, _) = assert_same_bits(what, &load(toml), 0);
    let (mean, se) = mean_and_error(&auto);
    for c in 0..3 {
        let slack = 4.0 * se[c] + 1e-5 * hi.abs();
        assert!(
            mean[c] >= lo - slack && mean[c] <= hi + slack,
            "{what}: channel {c} mean {} not in [{lo}, {hi}] (se {})",
            mean[c],
            se[c]
        );
    }
}

#[test]
fn furnaces_hold_for_every_material_and_integrator_setting_in_both_effect_modes() {
    const METAL: &str = "type = \"metal\"\nreflectance = 1\nroughness = 0.5";
    for (depth, roulette) in SETTINGS {
        let setting = format!("max_depth {depth:?}, roulette {roulette:?}");
        // Emitting walls inside a closed sphere: every hit adds 1.5, every bounce keeps r.
        for material in [
            "type = \"diffuse\"\nalbedo = 0.5",
            "type = \"mirror\"\nreflectance = 0.5",
        ] {
            let expected = 1.5 * series(0.5, depth);
            let what = format!("furnace {material:?}, {setting}");
            assert_closed_form(
                &what,
                &furnace(material, depth, roulette),
                expected,
                expected,
            );
        }
        // A rough metal with f0 = 1 reflects at most everything, and single-scattering GGX at
        // alpha 0.5 loses what its microfacets send below the surface: its albedo is 0.68 to 0.92
        // by angle (numerical integration), so the mean lies between the series for 0.6 and for 1
        // (unlimited depth would make the latter infinite, so only limited depths are run).
        if let Some(d) = depth {
            let (lo, hi) = (1.5 * series(0.6, depth), 1.5 * (d + 1) as f32);
            assert_closed_form(
                &format!("metal furnace, {setting}"),
                &furnace(METAL, depth, roulette),
                lo,
                hi,
            );
        }
        // Energy-conserving materials vanish in a uniform environment. Glass needs the depth to
        // follow its internal reflections, so it runs only where paths are not cut short, and six
        // bounces inside it leave at most a few 1e-3 of the light behind.
        for material in [
            "type = \"diffuse\"\nalbedo = 1",
            "type = \"mirror\"\nreflectance = 1",
            "type = \"glass\"\nior = 1.5",
        ] {
            let glass = material.contains("glass");
            if glass && depth.is_some_and(|d| d < 6) {
                continue;
            }
            let lo = if glass && depth.is_some() { 0.79 } else { 0.8 };
            let what = format!("white furnace {material:?}, {setting}");
            assert_closed_form(&what, &white_furnace(material, depth, roulette), lo, 0.8);
        }
        // Seen from outside, one bounce: 0.8 times an albedo of at least 0.68, and never brighter
        // than the environment.
        let what = format!("white furnace metal, {setting}");
        assert_closed_form(
            &what,
            &white_furnace(METAL, depth, roulette),
            0.8 * 0.68,
            0.8,
        );
    }
}

#[test]
fn point_in_sphere_holds_for_every_integrator_setting_in_both_effect_modes() {
    // Intensity pi at the centre of a unit sphere, diffuse 0.5 inside: the k-th scattering adds
    // 0.5^k, so max_depth D gives 1 - 0.5^D and no limit gives 1. The tessellated sphere lies
    // just inside the true one (1% slack).
    let lamp = "[[light]]\ntype = \"point\"\nposition = [0, 0, 0]\nintensity = 3.14159265\n";
    for (depth, roulette) in SETTINGS {
        let toml = furnace("type = \"diffuse\"\nalbedo = 0.5", depth, roulette)
            .replace("emission = 1.5\n", lamp)
            .replace("subdivisions = 3", "subdivisions = 4");
        let what = format!("point in sphere, max_depth {depth:?}, roulette {roulette:?}");
        let expected = depth.map_or(1.0, |d| 1.0 - 0.5f32.powi(d as i32));
        assert_closed_form(&what, &toml, 0.99 * expected, 1.01 * expected);
    }
}
