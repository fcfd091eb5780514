//! Scene values at the edges of what the format accepts, each family refused at its line with
//! its reason or loaded whole: cameras whose `up` is parallel to the view at every scale and
//! rounding, lists of corners that are not four, scales too small for their product, frames
//! past 2^24, emitters bright enough that a pixel's sum would overflow, and images that do not
//! decode.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

mod common;

use glam::Vec3;
use tracer::scene::{self, MAX_FRAMES, MAX_RADIANCE, MemoryFiles, Scene, SceneError};

/// A box to look at, so that a scene that loads has triangles.
const BOX: &str = "[[object]]\nshape = \"box\"\nmin = [-1, -1, -1]\nmax = [1, 1, 1]\n\
                   material = \"m\"\n[materials.m]\ntype = \"diffuse\"\n";

fn load(toml: &str) -> Result<Scene, SceneError> {
    let mut files = MemoryFiles::new();
    files.insert("scene.toml", toml);
    scene::load_from(&files, "scene.toml")
}

/// Asserts `toml` is refused at `line` of scene.toml, saying `says`.
#[track_caller]
fn refused(toml: &str, line: usize, says: &str) {
    let e = load(toml)
        .err()
        .unwrap_or_else(|| panic!("must be refused:\n{toml}"));
    let message = e.to_string();
    assert_eq!(e.line(), Some(line), "wrong line in `{message}`:\n{toml}");
    assert!(
        message.contains(says),
        "`{message}` should say `{says}`:\n{toml}"
    );
}

fn vector(v: Vec3) -> String {
    // `{:?}` prints the shortest digits that read back as the same f32.
    format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z)
}

fn camera(position: Vec3, look_at: Vec3, up: Vec3) -> String {
    format!(
        "[camera]\nposition = {}\nlook_at = {}\nup = {}\n{BOX}",
        vector(position),
        vector(look_at),
        vector(up)
    )
}

/// An `up` along the view direction, or within rounding of it, is refused at any length and
/// either sign, for views along an axis, along a diagonal and along the awkward direction of
/// `scenes/window-room`, from cameras near and far from the origin; an `up` a thousandth of a
/// radian away loads at ordinary lengths, and at lengths the camera's f32 basis cannot take is
/// refused for that reason, not as parallel.
#[test]
fn an_up_parallel_to_the_view_is_refused_at_every_length_and_rounding() {
    let views = [
        Vec3::Z,
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(-2.5, -0.6, 2.7),
        Vec3::new(1e-3, 7.0, -1e-4),
    ];
    let origins = [Vec3::ZERO, Vec3::new(3.0, -2.0, 1.0), Vec3::splat(1e6)];
    for view in views {
        for origin in origins {
            let look_at = origin + view;
            // The view as the loader sees it: the rounded difference of the two points.
            let forward = look_at - origin;
            for length in [1e-30f32, 1e-3, 1.0, 7.3, 1e3, 1e30] {
                for sign in [1.0f32, -1.0] {
                    let up = forward.normalize() * (length * sign);
                    refused(&camera(origin, look_at, up), 1, "`up` is parallel");
                    // A nudge of a part in a million is still parallel for a camera.
                    let nudged = up + forward.any_orthogonal_vector().normalize() * (length * 1e-6);
                    refused(&camera(origin, look_at, nudged), 1, "`up` is parallel");
                    let away = up + forward.any_orthogonal_vector().normalize() * (length * 1e-3);
                    if (1e-3..=1e3).contains(&length) {
                        let scene = load(&camera(origin, look_at, away)).unwrap();
                        assert_eq!(scene.camera.at(0).up, away);
                    } else {
                        // The camera's basis is worked out in f32, where the cross product of
                        // such an `up` with the view underflows or overflows: said so.
                        refused(&camera(origin, look_at, away), 1, "32-bit floats' range");
                    }
                }
            }
        }
    }
    refused(&camera(Vec3::ZERO, Vec3::Z, Vec3::ZERO), 1, "`up` is zero");
    // Not parallel, but too long for the camera's 32-bit basis: said so, not "parallel".
    let huge = camera(Vec3::ZERO, Vec3::Z * 5.0, Vec3::new(0.0, 3e38, 3e38));
    refused(&huge, 1, "out of 32-bit floats' range");
    let apart = camera(Vec3::splat(-3e38), Vec3::splat(3e38), Vec3::Y);
    refused(&apart, 1, "overflows 32-bit floats");
}

/// Quads and portals take exactly four corners: three, five, or four followed by anything are
/// refused at their line (serde's fixed arrays used to drop what came after the fourth).
#[test]
fn corners_are_exactly_four() {
    let corner = "[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]";
    let quad = |corners: &str| {
        format!(
            "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n[[object]]\nshape = \"quad\"\n\
             corners = [{corners}]\nmaterial = \"m\"\n[materials.m]\ntype = \"diffuse\"\n"
        )
    };
    let portal = |corners: &str| {
        format!(
            "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n[environment]\nradiance = 1\n\
             portals = [[{corners}]]\n{BOX}"
        )
    };
    load(&quad(corner)).unwrap();
    load(&portal(corner)).unwrap();
    for bad in [
        "[0, 0, 0], [1, 0, 0], [1, 1, 0]".to_owned(),
        format!("{corner}, [0, 0, 0]"),
        format!("{corner}, \"junk\""),
        format!("{corner}, 7"),
    ] {
        refused(&quad(&bad), 6, "corners");
        refused(&portal(&bad), 6, "");
    }
    refused(
        &quad("[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1]"),
        6,
        "corners",
    );
}

/// An object's scale may be so small on both sides of a key that the product of the two
/// underflows to zero (a box 2e15 across, scaled by 1e-24 to 2e-9) without being taken for a
/// change of sign; a real change of sign, at any size, is still refused.
#[test]
fn tiny_scales_keep_their_sign() {
    let keys = |a: f32, b: f32| {
        format!(
            "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n[[object]]\nshape = \"box\"\n\
             min = [-1e15, -1e15, -1e15]\nmax = [1e15, 1e15, 1e15]\nmaterial = \"m\"\n\
             [[object.keys]]\nframe = 0\nscale = {a:?}\n[[object.keys]]\nframe = 4\n\
             scale = {b:?}\n[materials.m]\ntype = \"diffuse\"\n"
        )
    };
    for s in [1e-24f32, 1e-23, 1e-20, 1e-10] {
        for sign in [1.0f32, -1.0] {
            let scene = load(&keys(s * sign, s * sign * 2.0)).unwrap();
            assert_eq!(scene.settings.frames, 5);
            refused(&keys(s * sign, -s * sign), 12, "changes sign");
        }
    }
}

/// Frames are counted exactly up to 2^24: a render may have that many and a key may name the
/// last of them; past it, `frames` and keys are refused at their line rather than rendering an
/// animation whose times blur, or saturating at the largest frame number.
#[test]
fn frames_stop_at_two_to_the_twenty_four() {
    let key = |frame: u32| {
        format!(
            "[camera]\nlook_at = [0, 0, 0]\n[[camera.keys]]\nframe = 0\nposition = [0, 0, -5]\n\
             [[camera.keys]]\nframe = {frame}\nposition = [0, 1, -5]\n{BOX}"
        )
    };
    let scene = load(&key(MAX_FRAMES - 1)).unwrap();
    assert_eq!(scene.settings.frames, MAX_FRAMES);
    for frame in [MAX_FRAMES, MAX_FRAMES + 1, u32::MAX] {
        refused(&key(frame), 6, "past the last a render may have");
    }
    let frames = |n: u32| {
        format!(
            "[render]\nframes = {n}\n[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n{BOX}"
        )
    };
    assert_eq!(
        load(&frames(MAX_FRAMES)).unwrap().settings.frames,
        MAX_FRAMES
    );
    refused(&frames(MAX_FRAMES + 1), 2, "must be from 1 to 16777216");
    refused(&frames(0), 2, "must be from 1 to 16777216");
}

/// Every way a scene emits (a material's emission, a point light's intensity, a constant
/// environment, an environment map's texels times its scale) takes values up to `MAX_RADIANCE`
/// and refuses more at its line: from 3e38 a render summed its samples to infinite pixels.
#[test]
fn emitters_stop_where_a_pixel_sum_could_overflow() {
    let camera = "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n";
    let emission = |v: f32| {
        format!(
            "{camera}[[object]]\nshape = \"box\"\nmin = [-1, -1, -1]\nmax = [1, 1, 1]\n\
             material = \"m\"\n[materials.m]\ntype = \"emissive\"\nemission = {v:e}\n"
        )
    };
    let point = |v: f32| {
        format!(
            "{camera}{BOX}[[light]]\ntype = \"point\"\nposition = [0, 3, 0]\nintensity = {v:e}\n"
        )
    };
    let sky = |v: f32| format!("{camera}{BOX}[environment]\nradiance = {v:e}\n");
    let cases: [(&dyn Fn(f32) -> String, usize); 3] = [(&emission, 11), (&point, 14), (&sky, 12)];
    for (toml, line) in cases {
        load(&toml(MAX_RADIANCE)).unwrap();
        for v in [2e30f32, 3e38] {
            refused(&toml(v), line, "must be at most 1e30");
        }
    }
    // A map: its brightest texel times the scale, against the same bound.
    let map = |texel: f32, scale: f32| {
        let exr = common::exr_bytes(4, 2, |x, _| if x == 1 { [texel; 3] } else { [0.5; 3] });
        let toml = format!("{camera}{BOX}[environment]\nmap = \"sky.exr\"\nscale = {scale:e}\n");
        let mut files = MemoryFiles::new();
        files.insert("scene.toml", toml.as_str());
        files.insert("sky.exr", exr);
        scene::load_from(&files, "scene.toml")
    };
    map(1e10, 1e20).unwrap();
    map(3e38, 1.0).err().unwrap();
    let e = map(1e10, 1e21).err().unwrap();
    assert!(e.to_string().contains("must be at most 1e30"), "{e}");
}

/// "Unlimited" depth without Russian roulette in a closed box of white walls: every path would
/// bounce forever (the render hung); it now ends at `UNLIMITED_DEPTH` scattering events, so the
/// render finishes with finite pixels, each path having cast exactly that many rays after its
/// camera ray.
#[test]
fn an_unlimited_depth_without_roulette_ends_in_a_lossless_closed_box() {
    let toml = "[render]\nwidth = 2\nheight = 2\nspp = 1\nmax_depth = \"unlimited\"\n\
                russian_roulette_depth = \"off\"\n[[light]]\ntype = \"point\"\n\
                position = [0, 0, 0]\nintensity = 10\n[camera]\nposition = [0, 0, 4]\n\
                look_at = [0, 0, 0]\n[[object]]\nshape = \"box\"\nmin = [-3, -3, -3]\n\
                max = [3, 3, 8]\ninward = true\nmaterial = \"m\"\n[materials.m]\n\
                type = \"diffuse\"\nalbedo = 1\n";
    let scene = load(toml).unwrap();
    let effects = tracer::Effects::of(&scene);
    let accel = tracer::geometry::Accel::build(&scene.triangles, Default::default());
    let world = tracer::World::new(scene, accel, effects);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let film = tracer::render_frame(&world, 0, &pool, tracer::FrameConfig { tile: 8 });
    let depth = u64::from(tracer::integrator::UNLIMITED_DEPTH);
    assert_eq!(film.stats.rays, 4 * (depth + 1));
    for pixel in &film.pixels {
        assert!(pixel.iter().all(|c| c.is_finite() && *c > 0.0), "{pixel:?}");
    }
}

/// An image that does not decode is named with the MTL line that asked for it, as a missing one
/// is: the texture may be shared, and the fix is often in the MTL file.
#[test]
fn an_image_that_does_not_decode_names_the_line_that_asked_for_it() {
    let camera = camera(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, Vec3::Y);
    let scene = format!("{camera}[[object]]\nobj = \"m.obj\"\n");
    let set: [(&str, &str); 4] = [
        ("scene.toml", &scene),
        (
            "m.obj",
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl t\nf 1/1 2/1 3/1\n",
        ),
        ("m.mtl", "newmtl t\nKd 0.5 0.5 0.5\n\nmap_Kd wall.png\n"),
        ("wall.png", "\u{89}PNG but not an image"),
    ];
    let mut files = MemoryFiles::new();
    for (name, text) in set {
        files.insert(name, text);
    }
    let e = scene::load_from(&files, "scene.toml").err().unwrap();
    let message = e.to_string();
    assert_eq!(e.file(), "wall.png", "{message}");
    assert!(
        message.starts_with("wall.png (referenced at m.mtl:4): cannot decode the image"),
        "{message}"
    );

    // From disk, both the image and the line that asked for it are full paths.
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in set {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    let e = scene::load(&dir.path().join("scene.toml")).err().unwrap();
    let message = e.to_string();
    let (image, mtl) = (dir.path().join("wall.png"), dir.path().join("m.mtl"));
    assert_eq!(e.file(), image.to_str().unwrap(), "{message}");
    let at = format!("{} (referenced at {}:4)", image.display(), mtl.display());
    assert!(message.starts_with(&at), "{message}");
}
