//! Motion blur in whole scenes: a spinning square against its closed-form profile, the same
//! bits whatever the tiles and threads, the same bits with every effect forced on, scenes
//! without motion unchanged, and the scene format's errors.

mod common;

use common::{assert_same_bits, render};
use tracer::scene::{Scene, load_str};
use tracer::{Effects, Film, FrameConfig, Rect, World, render_frame, render_tile};

fn bits(pixels: &[[f32; 3]]) -> Vec<u32> {
    pixels.iter().flatten().map(|c| c.to_bits()).collect()
}

/// A black square of half-side 0.25 turning about the view axis in front of a white sky, with
/// the given `[[object.keys]]` and shutter; the camera 1 away looking at its centre.
fn spinning(keys: &str, shutter: &str, size: u32, spp: u32) -> Scene {
    let toml = format!(
        "[render]\nwidth = {size}\nheight = {size}\nspp = {spp}\nmax_depth = 0\n\
         [camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nvfov = 40\nshutter = {shutter}\n\
         [environment]\nradiance = 1\n[materials.black]\ntype = \"diffuse\"\nalbedo = 0\n\
         [[object]]\nshape = \"quad\"\n\
         corners = [[-0.25, -0.25, 0], [-0.25, 0.25, 0], [0.25, 0.25, 0], [0.25, -0.25, 0]]\n\
         material = \"black\"\ntranslate = [0, 0, 1]\n{keys}"
    );
    load_str(&toml).expect("the spinning scene loads")
}

#[test]
fn a_square_spinning_a_quarter_turn_or_more_shows_the_closed_form_radial_profile() {
    // A square of half-side a, turned uniformly through any multiple of a quarter turn, covers
    // a point at radius r in (a, a sqrt 2) for a share 1 - (4 / pi) acos(a / r) of the time,
    // so the sky shows there for (4 / pi) acos(a / r); inside a it never does, beyond a sqrt 2
    // always. Three ways to a quarter turn: a quarter turn over the whole frame, one full turn
    // in a quarter of it, and a quarter of a frame that spins 720 degrees, half way through.
    let (size, spp) = (96u32, 64u32);
    let a = 0.25 * f64::from(size) / (2.0 * 20f64.to_radians().tan());
    let spins = [
        (
            "[[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 1\nrotate_z = 90\n",
            "[0, 1]",
        ),
        (
            "[[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 1\nrotate_z = 360\n",
            "[0, 0.25]",
        ),
        (
            "[[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 1\nrotate_z = -720\n",
            "[0.5, 0.625]",
        ),
    ];
    for (keys, shutter) in spins {
        let scene = spinning(keys, shutter, size, spp);
        assert!(Effects::of(&scene).motion_blur);
        let out = render(&scene, None, 0);
        // Rings one pixel wide, from just outside a to just inside a sqrt 2, where the profile
        // is smooth enough that a pixel's mean is its centre's value to about 1e-3.
        let rings = 8;
        let (lo, hi) = (a + 1.5, a * 2f64.sqrt() - 1.5);
        let mut sums = vec![(0.0f64, 0.0f64, 0u32); rings];
        for (i, p) in out.pixels.iter().enumerate() {
            let (x, y) = (
                (i as u32 % size) as f64 + 0.5,
                (i as u32 / size) as f64 + 0.5,
            );
            let r = (x - f64::from(size) / 2.0).hypot(y - f64::from(size) / 2.0);
            if r < lo || r >= hi {
                continue;
            }
            let ring = ((r - lo) / (hi - lo) * rings as f64) as usize;
            let exact = 4.0 / std::f64::consts::PI * (a / r).acos();
            let slot = &mut sums[ring];
            (slot.0, slot.1, slot.2) = (slot.0 + f64::from(p[1]), slot.1 + exact, slot.2 + 1);
        }
        for (ring, &(measured, exact, n)) in sums.iter().enumerate() {
            let (m, e) = (measured / f64::from(n), exact / f64::from(n));
            let sigma = (e * (1.0 - e) / f64::from(n * spp)).sqrt();
            eprintln!("{shutter}: ring {ring}: {m:.4} vs {e:.4} ({n} pixels)");
            assert!(
                (m - e).abs() < 5.0 * sigma + 0.01,
                "{keys} {shutter}: ring {ring} shows {m}, the closed form {e}"
            );
        }
        // Inside the square's inscribed circle the sky never shows, outside its corners always.
        let centre = (size / 2 * size + size / 2) as usize;
        assert_eq!(out.pixels[centre][1], 0.0);
        assert_eq!(out.pixels[0][1], 1.0);
    }
}

/// A small lit room: a diffuse box with a light in the ceiling, a glass sphere flying across
/// and turning, a box that grows, a camera that pans with a lens; shutter `shutter`.
fn room(shutter: &str, spp: u32) -> Scene {
    let toml = format!(
        r#"
        [render]
        width = 37
        height = 29
        spp = {spp}
        max_depth = 5
        [camera]
        look_at = [0, 1, 0]
        aperture_radius = 0.05
        shutter = {shutter}
        [[camera.keys]]
        frame = 0
        position = [-0.5, 1, -4]
        [[camera.keys]]
        frame = 4
        position = [0.5, 1.2, -4]
        [materials.wall]
        type = "diffuse"
        albedo = 0.7
        [materials.lamp]
        type = "emissive"
        emission = 8
        [materials.glass]
        type = "glass"
        [materials.red]
        type = "diffuse"
        albedo = [0.7, 0.2, 0.2]
        [[object]]
        shape = "box"
        min = [-2, 0, -5]
        max = [2, 3, 2]
        inward = true
        material = "wall"
        [[object]]
        shape = "quad"
        corners = [[-0.5, 2.99, -0.5], [0.5, 2.99, -0.5], [0.5, 2.99, 0.5], [-0.5, 2.99, 0.5]]
        material = "lamp"
        [[object]]
        shape = "sphere"
        radius = 0.4
        subdivisions = 2
        material = "glass"
        [[object.keys]]
        frame = 0
        translate = [-1.2, 0.6, 0]
        [[object.keys]]
        frame = 4
        translate = [1.2, 0.9, -0.5]
        rotate_y = 180
        [[object]]
        shape = "box"
        min = [-0.3, 0, -0.3]
        max = [0.3, 0.6, 0.3]
        material = "red"
        translate = [0.8, 0, 0.8]
        [[object.keys]]
        frame = 1
        [[object.keys]]
        frame = 3
        scale = [1, 2, 1]
        rotate_y = 45
        "#
    );
    load_str(&toml).expect("the room loads")
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a small rayon pool builds")
}

#[test]
fn a_blurred_frame_is_the_same_bits_whatever_the_tiles_and_threads() {
    let world = World::prepare(room("[-0.25, 0.25]", 2), None);
    assert!(world.effects.motion_blur && world.effects.depth_of_field);
    for frame in [0, 2] {
        let (w, h) = (world.scene.settings.width, world.scene.settings.height);
        let whole = render_tile(&world, frame, Rect { x: 0, y: 0, w, h });
        for (threads, tile) in [(1, 32), (3, 8), (2, 5)] {
            let film: Film = render_frame(&world, frame, &pool(threads), FrameConfig { tile });
            let what = format!("frame {frame}, {threads} threads, tiles of {tile}");
            assert_eq!(bits(&film.pixels), bits(&whole.pixels), "pixels of {what}");
            assert_eq!(film.stats, whole.stats, "counters of {what}");
        }
    }
}

#[test]
fn motion_renders_the_same_bits_specialised_and_with_every_effect_on() {
    // Blurred; animated without blur (an instant shutter, and one that opens late); a shutter
    // over a scene where nothing moves.
    for shutter in ["[-0.25, 0.25]", "[0, 0]", "[0.4, 0.4]"] {
        let scene = room(shutter, 2);
        assert_eq!(Effects::of(&scene).motion_blur, shutter == "[-0.25, 0.25]");
        for frame in [0, 2] {
            assert_same_bits(
                &format!("room, shutter {shutter}, frame {frame}"),
                &scene,
                frame,
            );
        }
    }
    let still = load_str(&still_room("shutter = [0, 0.5]", "")).expect("loads");
    assert!(!Effects::of(&still).motion_blur, "nothing moves");
    assert_same_bits("a still room with a shutter", &still, 0);
    // Guard: the blur does change the image, so equal bits above are not vacuous.
    let sharp = render(&room("[0, 0]", 2), None, 2);
    let blurred = render(&room("[-0.25, 0.25]", 2), None, 2);
    assert_ne!(bits(&sharp.pixels), bits(&blurred.pixels));
}

/// A room that does not move: a box, a lamp, a sphere placed by `sphere_keys` (keys that all
/// say the same, or none), the camera table's extra keys `camera`.
fn still_room(camera: &str, sphere_keys: &str) -> String {
    format!(
        r#"
        render = {{ width = 24, height = 20, spp = 4, max_depth = 4 }}
        [camera]
        position = [0, 1, -4]
        look_at = [0, 1, 0]
        {camera}
        [materials.wall]
        type = "diffuse"
        albedo = 0.7
        [materials.lamp]
        type = "emissive"
        emission = 8
        [[object]]
        shape = "box"
        min = [-2, 0, -5]
        max = [2, 3, 2]
        inward = true
        material = "wall"
        [[object]]
        shape = "quad"
        corners = [[-0.5, 2.99, -0.5], [0.5, 2.99, -0.5], [0.5, 2.99, 0.5], [-0.5, 2.99, 0.5]]
        material = "lamp"
        [[object]]
        shape = "sphere"
        radius = 0.5
        material = "wall"
        translate = [0.3, 0.5, 0]
        rotate_y = 30
        {sphere_keys}
        "#
    )
}

#[test]
fn scenes_that_do_not_move_render_the_bits_they_rendered_without_motion() {
    let plain = load_str(&still_room("", "")).expect("loads");
    let reference = bits(&render(&plain, None, 0).pixels);
    let same_keys =
        "[[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 5\ntranslate = [0.3, 0.5, 0]\n";
    for (camera, keys) in [
        ("shutter = [0, 0.5]", ""),
        ("shutter = [0, 0]", ""),
        ("", same_keys),
        ("shutter = [-1, 0]", same_keys),
    ] {
        let scene = load_str(&still_room(camera, keys)).expect("loads");
        assert!(
            scene.moving.is_empty(),
            "{camera} {keys}: keys that all agree stand still"
        );
        for effects in [None, Some(Effects::ALL)] {
            assert_eq!(
                bits(&render(&scene, effects, 0).pixels),
                reference,
                "{camera} {keys} with {effects:?}"
            );
        }
    }
}

/// The loader's message for `toml`, which must not load.
fn error_of(toml: &str) -> String {
    match load_str(toml) {
        Ok(_) => panic!("loaded, but must not:\n{toml}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_shutters_and_keys_are_errors_that_name_the_line() {
    let with_camera = |extra: &str| still_room(extra, "");
    for (extra, words) in [
        ("shutter = [0.5, 0.2]", "closes before it opens"),
        ("shutter = [0, 1.5]", "within one frame"),
        ("shutter = [-1, 0.5]", "more than one"),
        ("shutter = [0, nan]", "must be a finite number"),
        ("shutter = [0, 0.5, 1]", "two numbers"),
        ("shutter = 0.5", "invalid type"),
    ] {
        let error = error_of(&with_camera(extra));
        assert!(
            error.contains("scene.toml:6") && error.contains(words) && error.contains("shutter"),
            "{extra}: {error}"
        );
    }
    let key = |frame: u32, rest: &str| format!("[[object.keys]]\nframe = {frame}\n{rest}\n");
    for (keys, line, words) in [
        (
            key(4, "") + &key(2, "translate = [1, 0, 0]"),
            32,
            "out of order: frame 2 comes after frame 4",
        ),
        (
            key(3, "") + &key(3, "translate = [1, 0, 0]"),
            32,
            "two keys at frame 3",
        ),
        (
            key(0, "scale = 1") + &key(2, "scale = [1, -1, 1]"),
            32,
            "changes sign",
        ),
        (key(0, "colour = 1"), 31, "unknown field `colour`"),
    ] {
        let error = error_of(&still_room("", &keys));
        assert!(
            error.contains(&format!("scene.toml:{line}")) && error.contains(words),
            "{keys}: {error}"
        );
    }
    // A moving light is no error: it loads as a moving object whose triangles emit (what it
    // renders to is checked in `moving_emitters.rs`).
    let moving_lamp = still_room("", "").replace(
        "material = \"lamp\"",
        "material = \"lamp\"\n[[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 1\ntranslate = [0, -1, 0]",
    );
    let scene = load_str(&moving_lamp).expect("a moving lamp loads");
    assert!(
        scene
            .emissive_triangles()
            .any(|(i, _)| i as usize >= scene.triangles.len())
    );
}

#[test]
fn object_keys_set_the_default_frame_count_and_interpolate_between_them() {
    let keys =
        "[[object.keys]]\nframe = 2\n[[object.keys]]\nframe = 9\ntranslate = [1.7, 0.5, 0]\n";
    let scene = load_str(&still_room("", keys)).expect("loads");
    assert_eq!(scene.settings.frames, 10);
    let track = &scene.moving[0].track;
    // Keys inherit the object's transform: frame 2 stands where the object says.
    assert_eq!(track.keys()[0].translate, glam::Vec3::new(0.3, 0.5, 0.0));
    assert_eq!(track.keys()[1].rotate_degrees.y, 30.0);
    let mid = track.at(5.5).translation;
    assert!(
        (mid - glam::DVec3::new(1.0, 0.5, 0.0)).length() < 1e-6,
        "{mid}"
    );
}

#[test]
fn a_moving_ball_of_smoke_renders_the_same_bits_specialised_and_forced() {
    // Shadow rays pass a moving interface (the transmittance's closest certain blocker comes
    // from the moving object's tree), and paths enter and leave its medium while it moves.
    let toml = still_room("shutter = [0, 1]", "")
        .replace(
            "radius = 0.5\n        material = \"wall\"",
            "radius = 0.6\n        material = \"smoke\"",
        )
        .replace(
            "rotate_y = 30\n",
            "rotate_y = 30\n[[object.keys]]\nframe = 0\n[[object.keys]]\nframe = 1\n\
             translate = [-0.6, 1.4, 0.2]\n[materials.smoke]\ntype = \"interface\"\n\
             medium = \"fog\"\n[media.fog]\nsigma_s = 2\nsigma_a = 0.5\n",
        );
    let scene = load_str(&toml).expect("the smoke room loads");
    let effects = Effects::of(&scene);
    assert!(effects.media && effects.motion_blur, "{effects}");
    assert_eq!(scene.moving.len(), 1);
    let (out, forced) = assert_same_bits("a moving ball of smoke", &scene, 0);
    assert!(out.stats.medium_scatters > 0 && forced.medium_scatters > 0);
    // Guard: the smoke is seen, so the bits above are not those of an empty room.
    let empty = load_str(&still_room("shutter = [0, 1]", "")).expect("loads");
    assert_ne!(bits(&out.pixels), bits(&render(&empty, None, 0).pixels));
}
