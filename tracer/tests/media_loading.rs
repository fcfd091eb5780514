//! The scene format's media: `[media.NAME]` tables, `medium` on glass, interfaces and the
//! camera, and the errors that name the offending key and line.

use glam::Vec3;
use tracer::Material;
use tracer::material::Bsdf;
use tracer::medium::Medium;
use tracer::scene::load_str;

/// A scene with one sphere of material `ball`, the given `[materials.ball]` body, media tables
/// and `[camera]` extra keys.
fn scene(ball: &str, media: &str, camera: &str) -> String {
    format!(
        "[camera]\nposition = [0, 0, -3]\nlook_at = [0, 0, 0]\n{camera}\n\
         [[object]]\nshape = \"sphere\"\nmaterial = \"ball\"\n\
         [materials.ball]\n{ball}\n{media}"
    )
}

/// [`scene`] with the ball inside a larger sphere bounded by an interface around medium
/// `fog` (which `media` defines): where a ball whose outside is the fog must be for the
/// loader's nesting check.
fn scene_in_fog(ball: &str, media: &str, camera: &str) -> String {
    format!(
        "{}\n[[object]]\nshape = \"sphere\"\nradius = 2\nmaterial = \"around\"\n\
         [materials.around]\ntype = \"interface\"\nmedium = \"fog\"\n",
        scene(ball, media, camera)
    )
}

/// Asserts that loading fails with a message containing `says` and naming the line of
/// scene.toml that holds `at` (the first such line).
fn rejects(toml: &str, at: &str, says: &str) {
    let line = 1 + toml
        .lines()
        .position(|l| l.contains(at))
        .expect("the test names a line of its scene");
    let message = match load_str(toml) {
        Ok(_) => panic!("loaded, but should say `{says}`:\n{toml}"),
        Err(e) => e.to_string(),
    };
    let place = format!("scene.toml:{line}");
    assert!(message.contains(&place), "`{message}` should name {place}");
    assert!(message.contains(says), "`{message}` should say `{says}`");
}

#[test]
fn both_forms_of_coefficients_give_the_same_medium_and_bind_where_used() {
    let by_coefficients =
        "[media.smoke]\nsigma_a = [0.1, 0.2, 0.3]\nsigma_s = [0.9, 1.8, 2.7]\ng = 0.5";
    let by_albedo = "[media.smoke]\nalbedo = 0.9\ndensity = [1, 2, 3]\ng = 0.5";
    let mut loaded = Vec::new();
    for media in [by_coefficients, by_albedo] {
        let s = load_str(&scene(
            "type = \"interface\"\nmedium = \"smoke\"",
            media,
            "",
        ))
        .expect("loads");
        assert_eq!(s.media.len(), 1);
        assert_eq!(s.camera_medium, None);
        let Material { bsdf, interior, .. } = &s.materials[0];
        assert_eq!(*bsdf, Bsdf::Interface);
        assert_eq!(*interior, Some(0));
        loaded.push(s.media[0]);
    }
    for m in &loaded {
        assert!(
            (m.sigma_a - Vec3::new(0.1, 0.2, 0.3)).abs().max_element() < 1e-6,
            "{m:?}"
        );
        assert!(
            (m.sigma_s - Vec3::new(0.9, 1.8, 2.7)).abs().max_element() < 1e-6,
            "{m:?}"
        );
        assert_eq!(m.g, 0.5);
    }
    // Fog: the camera's medium; glass binds one too; one table may serve both.
    let s = load_str(&scene(
        "type = \"glass\"\nmedium = \"fog\"",
        "[media.fog]\nsigma_s = 0.1",
        "medium = \"fog\"",
    ))
    .expect("loads");
    assert_eq!(s.camera_medium, Some(0));
    assert_eq!(s.materials[0].interior, Some(0));
    assert_eq!(
        s.media,
        vec![Medium {
            sigma_a: Vec3::ZERO,
            sigma_s: Vec3::splat(0.1),
            g: 0.0
        }]
    );
    // Albedo 1: no absorption, exactly.
    let s = load_str(&scene(
        "type = \"interface\"\nmedium = \"m\"",
        "[media.m]\nalbedo = 1\ndensity = 7.3",
        "",
    ))
    .expect("loads");
    assert_eq!(s.media[0].sigma_a, Vec3::ZERO);
}

#[test]
fn invalid_media_are_refused_naming_the_key() {
    let ball = "type = \"interface\"\nmedium = \"m\"";
    // (the table's body, the line the error names, what it says)
    let cases: [(&str, &str, &str); 9] = [
        (
            "sigma_a = -0.1",
            "sigma_a",
            "must not be negative (key `media.m.sigma_a`)",
        ),
        (
            "sigma_s = [1, -2, 1]",
            "sigma_s",
            "must not be negative (key `media.m.sigma_s`)",
        ),
        (
            "albedo = 0.5\ndensity = -1",
            "density",
            "must not be negative (key `media.m.density`)",
        ),
        (
            "albedo = 1.5\ndensity = 1",
            "albedo",
            "[0, 1] (key `media.m.albedo`)",
        ),
        ("sigma_s = 1\ng = 1", "g =", "must be in (-1, 1)"),
        ("sigma_s = 1\ng = -1.2", "g =", "(key `media.m.g`)"),
        ("sigma_s = 1\ndensity = 1", "[media.m]", "not keys of both"),
        (
            "albedo = 0.5",
            "[media.m]",
            "`albedo` and `density` go together",
        ),
        (
            "g = 0.3",
            "[media.m]",
            "needs `sigma_a` and `sigma_s`, or `albedo` and `density`",
        ),
    ];
    for (body, at, says) in cases {
        rejects(&scene(ball, &format!("[media.m]\n{body}"), ""), at, says);
    }
    rejects(
        &scene(ball, "[media.m]\nsigma_s = 1\nsigma_t = 2", ""),
        "sigma_t",
        "unknown field `sigma_t`",
    );
}

#[test]
fn media_references_are_checked() {
    let media = "[media.m]\nsigma_s = 1";
    // A medium nothing defines, from a material and from the camera.
    rejects(
        &scene("type = \"interface\"\nmedium = \"n\"", media, ""),
        "medium = \"n\"",
        "[materials.ball] `medium`: medium `n` is not defined",
    );
    rejects(
        &scene("type = \"diffuse\"", media, "medium = \"n\""),
        "medium = \"n\"",
        "[camera] `medium`: medium `n` is not defined",
    );
    // A medium nothing uses.
    rejects(
        &scene("type = \"glass\"", media, ""),
        "[media.m]",
        "[media.m] is used by no material's `medium` or `outside_medium` and not by the camera's `medium`",
    );
    // `medium` applies to glass and interfaces only; interfaces take nothing else.
    rejects(
        &scene("type = \"diffuse\"\nmedium = \"m\"", media, ""),
        "[materials.ball]",
        "key `medium` does not apply to type diffuse",
    );
    rejects(
        &scene(
            "type = \"interface\"\nmedium = \"m\"\nemission = 1",
            media,
            "",
        ),
        "[materials.ball]",
        "key `emission` does not apply to type interface",
    );
    rejects(
        &scene("type = \"interface\"\nior = 1.3", "", ""),
        "[materials.ball]",
        "key `ior` does not apply to type interface",
    ); // `outside_medium` likewise: a medium it names must be defined, and only glass and
    // interfaces bound a medium.
    rejects(
        &scene("type = \"glass\"\noutside_medium = \"n\"", media, ""),
        "outside_medium = \"n\"",
        "[materials.ball] `outside_medium`: medium `n` is not defined",
    );
    for kind in ["diffuse", "mirror", "metal"] {
        rejects(
            &scene(
                &format!("type = \"{kind}\"\noutside_medium = \"m\""),
                media,
                "",
            ),
            "[materials.ball]",
            &format!("key `outside_medium` does not apply to type {kind}"),
        );
    }
}

#[test]
fn an_objects_outside_is_the_camera_medium_unless_named() {
    let two = "[media.fog]\nsigma_s = 0.1\n[media.smoke]\nsigma_s = 2";
    // Named: the enclosing medium, with or without one inside, whatever the camera is in.
    for (ball, camera) in [
        (
            "type = \"interface\"\nmedium = \"smoke\"\noutside_medium = \"fog\"",
            "",
        ),
        (
            "type = \"glass\"\nmedium = \"smoke\"\noutside_medium = \"fog\"",
            "medium = \"smoke\"",
        ),
    ] {
        let s = load_str(&scene_in_fog(ball, two, camera)).expect("loads");
        let m = &s.materials[0];
        let (fog, smoke) = (
            m.exterior.expect("fog outside"),
            m.interior.expect("smoke inside"),
        );
        assert_eq!(s.media[fog as usize].sigma_s, Vec3::splat(0.1), "{ball}");
        assert_eq!(s.media[smoke as usize].sigma_s, Vec3::splat(2.0), "{ball}");
    }
    // Left out: the camera's medium, vacuum without one, as before media nested.
    let s = load_str(&scene(
        "type = \"glass\"\nmedium = \"smoke\"",
        two,
        "medium = \"fog\"",
    ))
    .expect("loads");
    assert!(s.camera_medium.is_some());
    assert_eq!(s.materials[0].exterior, s.camera_medium);
    assert_ne!(s.materials[0].exterior, s.materials[0].interior);
    let s = load_str(&scene_in_fog(
        "type = \"glass\"\noutside_medium = \"fog\"",
        "[media.fog]\nsigma_s = 0.1",
        "",
    ))
    .expect("loads");
    assert_eq!(
        (s.materials[0].interior, s.materials[0].exterior),
        (None, Some(0))
    );
    let s = load_str(&scene("type = \"glass\"", "", "")).expect("loads");
    assert_eq!(s.materials[0].exterior, None);
}
