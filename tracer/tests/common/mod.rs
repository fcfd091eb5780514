//! Helpers shared by the tracer's image tests (effects, analytic integrator checks, image-based
//! lighting, depth of field): rendering a scene whole, in either effect mode, and the image's
//! mean with its standard error.

#![allow(dead_code)]

pub mod rng;

use glam::Vec3;
use tracer::lights::EnvironmentSampling;
use tracer::scene::{MemoryFiles, Scene};
use tracer::{Effects, PathStats, Rect, TileOutput, World};

/// Renders frame `frame` of `scene` whole with `effects` (`None`: the scene's own) and the
/// environment sampled as `sampling` says; no sample may come out NaN or infinite.
pub fn render_with(
    scene: &Scene,
    effects: Option<Effects>,
    frame: u32,
    sampling: EnvironmentSampling,
) -> TileOutput {
    let world = World::prepare(scene.clone(), effects).with_environment_sampling(sampling);
    render_world(&world, frame)
}

/// Renders frame `frame` of `world` whole, as its settings say; no sample may come out NaN or
/// infinite.
pub fn render_world(world: &World, frame: u32) -> TileOutput {
    let (w, h) = (world.scene.settings.width, world.scene.settings.height);
    let out = tracer::render_tile(world, frame, Rect { x: 0, y: 0, w, h });
    assert_eq!(out.stats.invalid_samples, 0, "a sample was NaN or infinite");
    out
}

pub fn render(scene: &Scene, effects: Option<Effects>, frame: u32) -> TileOutput {
    render_with(scene, effects, frame, EnvironmentSampling::default())
}

/// Renders `scene` specialised and with every effect on, asserts the same bits, and returns the
/// specialised render and the forced one's counters.
pub fn assert_same_bits(what: &str, scene: &Scene, frame: u32) -> (TileOutput, PathStats) {
    let auto = render(scene, None, frame);
    let all = render(scene, Some(Effects::ALL), frame);
    let bits =
        |o: &TileOutput| -> Vec<u32> { o.pixels.iter().flatten().map(|c| c.to_bits()).collect() };
    let differing = bits(&auto)
        .iter()
        .zip(bits(&all))
        .filter(|(a, b)| **a != *b)
        .count();
    assert_eq!(
        differing,
        0,
        "{what}: {differing} channels differ between effects {} and all",
        Effects::of(scene)
    );
    assert!(
        auto.pixels.iter().flatten().any(|&c| c > 0.0),
        "{what}: a black image proves little"
    );
    (auto, all.stats)
}

/// Per-channel mean of an image and its standard error (pixels are independent).
pub fn mean_and_error(out: &TileOutput) -> (Vec3, Vec3) {
    let n = out.pixels.len() as f64;
    let mut sum = [0.0f64; 3];
    let mut sum_sq = [0.0f64; 3];
    for p in &out.pixels {
        for c in 0..3 {
            sum[c] += f64::from(p[c]);
            sum_sq[c] += f64::from(p[c]).powi(2);
        }
    }
    let mean = sum.map(|s| s / n);
    let se: [f64; 3] =
        std::array::from_fn(|c| ((sum_sq[c] / n - mean[c].powi(2)).max(0.0) / n).sqrt());
    (
        Vec3::from_array(mean.map(|m| m as f32)),
        Vec3::from_array(se.map(|s| s as f32)),
    )
}

/// Asserts `mean` lies within four standard errors (plus a relative `slack`) of `expected` in
/// every channel.
pub fn assert_close(what: &str, (mean, se): (Vec3, Vec3), expected: Vec3, slack: f32) {
    for c in 0..3 {
        let tolerance = 4.0 * se[c] + slack * expected[c].abs() + 1e-6;
        assert!(
            (mean[c] - expected[c]).abs() <= tolerance,
            "{what}: channel {c} mean {} expected {} (se {}, tolerance {tolerance})",
            mean[c],
            expected[c],
            se[c]
        );
    }
}

/// An OpenEXR file of `width` x `height` float RGB texels, `texel(x, y)` each, row 0 the top,
/// written by the exr crate into memory.
pub fn exr_bytes(
    width: usize,
    height: usize,
    texel: impl Fn(usize, usize) -> [f32; 3] + Sync,
) -> Vec<u8> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let [r, g, b] = texel(p.x(), p.y());
        (r, g, b)
    });
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_channels((width, height), channels)
        .write()
        .non_parallel()
        .to_buffered(&mut bytes)
        .expect("the EXR encodes");
    bytes.into_inner()
}

/// Asserts that `toml`, loaded as `scene.toml`, is refused at its line `line` with a message
/// that says `says`; returns the message, for further checks.
pub fn assert_refused(toml: &str, line: usize, says: &str) -> String {
    let error = load_with(toml, &[])
        .err()
        .unwrap_or_else(|| panic!("must be refused, saying `{says}`:\n{toml}"));
    let message = error.to_string();
    assert_eq!(
        (error.file(), error.line()),
        ("scene.toml", Some(line)),
        "{message}\n{toml}"
    );
    assert!(
        message.contains(says),
        "`{message}` should say `{says}`\n{toml}"
    );
    message
}

/// Loads `toml` as `scene.toml` beside the given files.
pub fn load_with(toml: &str, files: &[(&str, Vec<u8>)]) -> Result<Scene, tracer::SceneError> {
    let mut set = MemoryFiles::new();
    set.insert("scene.toml", toml);
    for (name, bytes) in files {
        set.insert(name, bytes.clone());
    }
    tracer::scene::load_from(&set, "scene.toml")
}

/// The media tests' scene: a white diffuse floor at y = 0, the rays' eye at `(3, 1, 0)` (see
/// [`ray_to_the_floor_under_the_light`]), a point light of intensity 16 at height 4 above the
/// origin, and `objects` (TOML inline tables, each with its trailing comma) with their
/// `materials` (TOML tables) between; direct light only.
pub fn under_a_point_light(objects: &str, materials: &str) -> String {
    format!(
        r#"
        render = {{ width = 8, height = 8, spp = 1, max_depth = 1, russian_roulette_depth = "off" }}
        camera = {{ position = [3, 1, 0], look_at = [0, 0, 0] }}
        object = [
            {{ shape = "quad", corners = [[-4, 0, -4], [-4, 0, 4], [4, 0, 4], [4, 0, -4]], material = "floor" }},
            {objects}
        ]
        [[light]]
        type = "point"
        position = [0, 4, 0]
        intensity = 16
        [materials.floor]
        type = "diffuse"
        albedo = 1
        {materials}
        "#
    )
}

/// [`under_a_point_light`] with a horizontal slab `[-0.5, 0.5] x [2, 2 + d] x [-0.5, 0.5]`
/// between the floor and the light, bounded by an interface whose table's further lines are
/// `medium` (for instance `medium = "m"` and the medium's own table).
pub fn slab_under_a_point_light(thickness: f32, medium: &str) -> String {
    let top = 2.0 + thickness;
    under_a_point_light(
        &format!(
            r#"{{ shape = "box", min = [-0.5, 2, -0.5], max = [0.5, {top}, 0.5], material = "slab" }},"#
        ),
        &format!("[materials.slab]\ntype = \"interface\"\n{medium}"),
    )
}

/// The ray from the media tests' eye to the floor point under their light (the origin). The
/// scenes keep it clear of their media, so next-event estimation alone reaches the light, along
/// a vertical shadow ray.
pub fn ray_to_the_floor_under_the_light() -> tracer::geometry::Ray {
    let origin = Vec3::new(3.0, 1.0, 0.0);
    tracer::geometry::Ray {
        origin,
        dir: (Vec3::ZERO - origin).normalize(),
        t_max: f32::INFINITY,
    }
}

/// The radiance of the one path along [`ray_to_the_floor_under_the_light`] (with the first
/// pixel sampler, deterministic here) and what it did.
pub fn radiance_under_the_light(scene: Scene) -> (Vec3, PathStats) {
    let world = World::prepare(scene, None);
    let mut stats = PathStats::default();
    let mut sampler = tracer::sampler::PixelSampler::new(0, 0, 0, 0, 0);
    let ray = ray_to_the_floor_under_the_light();
    let radiance = world.radiance(ray, 0.0, &mut sampler, &mut stats);
    (radiance, stats)
}
