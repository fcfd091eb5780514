//! The loader's nesting check: what a glass or interface says surrounds it (`outside_medium`,
//! `outside_ior`, or the camera's medium and index 1 when left out) must be what the geometry
//! puts there, or the scene is refused at the material's line, naming the key.
//!
//! - A ball in a fog-filled box, in a water-filled glass tank, or in the open, with each
//!   combination of keys: the right ones load, each wrong one is refused naming exactly the
//!   keys that are wrong, at scales from a millimetre to a kilometre and far from the origin.
//! - Probes pass through surfaces that do not bound media (a diffuse wall between the ball and
//!   the tank), a sibling ball beside the first does not count as enclosing it, and probes that
//!   meet different objects agree when those put the same medium there.
//! - Where the geometry says no one thing (a ball crossing the tank's wall), nothing is refused.
//! - An MTL glass, which cannot name its outside, is refused at its MTL file with the fix.

mod common;

use common::load_with;
use glam::Vec3;

/// Where the ball sits: nothing around it, a box of fog (an interface), or a tank of water
/// (a glass of index 1.33 filled with the medium `water`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Around {
    Open,
    Fog,
    Water,
}

/// A scene at `scale` around `centre`: a glass ball of radius 0.5 (of material `ball`, whose
/// table's extra keys are `keys`) at the centre, inside `around` (a cube of side 4), with
/// `extra` objects appended.
fn scene(around: Around, keys: &str, scale: f32, centre: Vec3, extra: &str) -> String {
    let at = |p: Vec3| {
        let p = centre + p * scale;
        format!("[{}, {}, {}]", p.x, p.y, p.z)
    };
    let container = match around {
        Around::Open => String::new(),
        Around::Fog | Around::Water => format!(
            "{{ shape = \"box\", min = {}, max = {}, material = \"container\" }},",
            at(Vec3::splat(-2.0)),
            at(Vec3::splat(2.0))
        ),
    };
    let container_material = match around {
        Around::Open => "",
        Around::Fog => "[materials.container]\ntype = \"interface\"\nmedium = \"fog\"",
        Around::Water => "[materials.container]\ntype = \"glass\"\nior = 1.33\nmedium = \"water\"",
    };
    let camera = at(Vec3::new(0.0, 0.0, -8.0));
    format!(
        "camera = {{ position = {camera}, look_at = {} }}\n\
         object = [\n\
           {{ shape = \"sphere\", center = {}, radius = {}, subdivisions = 2, material = \"ball\" }},\n\
           {container}\n{extra}\n]\n\
         [materials.ball]\ntype = \"glass\"\nior = 1.5\n{keys}\n\
         {container_material}\n\
         [media.fog]\nsigma_s = 0.2\n[media.water]\nsigma_a = 0.1\n[media.other]\nsigma_a = 1\n\
         [materials.unused-media-binder]\ntype = \"interface\"\nmedium = \"other\"\n",
        at(Vec3::ZERO),
        at(Vec3::ZERO),
        0.5 * scale,
    )
}

/// Every combination of outside keys a user might write for the ball, and the keys among
/// `outside_medium` and `outside_ior` that are wrong for each place.
fn key_cases() -> Vec<(&'static str, [&'static [&'static str]; 3])> {
    // [wrong keys when Open, when Fog, when Water]
    vec![
        (
            "",
            [&[], &["outside_medium"], &["outside_medium", "outside_ior"]],
        ),
        (
            "outside_medium = \"fog\"",
            [&["outside_medium"], &[], &["outside_medium", "outside_ior"]],
        ),
        (
            "outside_medium = \"water\"",
            [&["outside_medium"], &["outside_medium"], &["outside_ior"]],
        ),
        (
            "outside_ior = 1.33",
            [&["outside_ior"], &["outside_medium"], &["outside_medium"]],
        ),
        (
            "outside_medium = \"water\"\noutside_ior = 1.33",
            [&["outside_medium", "outside_ior"], &["outside_medium"], &[]],
        ),
        (
            "outside_medium = \"other\"",
            [
                &["outside_medium"],
                &["outside_medium"],
                &["outside_medium", "outside_ior"],
            ],
        ),
    ]
}

/// The `[materials.ball]` table's line in `toml`.
fn ball_line(toml: &str) -> usize {
    1 + toml
        .lines()
        .position(|l| l == "[materials.ball]")
        .expect("the scene has the ball's table")
}

/// Loads `toml` (which binds the otherwise unused media through an extra object) and checks
/// it loads when `wrong` is empty, else that it is refused at the ball's line naming exactly
/// the keys in `wrong`.
fn expect(toml: &str, wrong: &[&str], what: &str) {
    match (load_with(toml, &[]), wrong.is_empty()) {
        (Ok(_), true) => {}
        (Ok(_), false) => panic!("{what}: loaded, but {wrong:?} contradict the geometry\n{toml}"),
        (Err(e), true) => panic!("{what}: refused: {e}\n{toml}"),
        (Err(e), false) => {
            let message = e.to_string();
            assert_eq!(
                (e.file(), e.line()),
                ("scene.toml", Some(ball_line(toml))),
                "{what}: {message}"
            );
            let head = message
                .split(" (left out")
                .next()
                .expect("split yields at least one piece");
            for key in ["outside_medium", "outside_ior"] {
                assert_eq!(
                    head.contains(&format!("`{key}`")),
                    wrong.contains(&key),
                    "{what}: `{message}` should name exactly {wrong:?}"
                );
            }
        }
    }
}

/// A small object of the unused-media binder, far from everything, so that each scene binds
/// every medium it defines (the loader refuses unused media tables) without enclosing the ball.
fn binder(scale: f32, centre: Vec3) -> String {
    let c = centre + Vec3::new(40.0, 0.0, 0.0) * scale;
    format!(
        "{{ shape = \"sphere\", center = [{}, {}, {}], radius = {}, subdivisions = 1, material = \"unused-media-binder\" }},\n\
         {{ shape = \"sphere\", center = [{}, {}, {}], radius = {}, subdivisions = 1, material = \"fog-binder\" }},\n\
         {{ shape = \"sphere\", center = [{}, {}, {}], radius = {}, subdivisions = 1, material = \"water-binder\" }},",
        c.x,
        c.y,
        c.z,
        0.5 * scale,
        c.x,
        c.y + 3.0 * scale,
        c.z,
        0.5 * scale,
        c.x,
        c.y + 6.0 * scale,
        c.z,
        0.5 * scale,
    )
}

/// `scene` with every medium bound by a far-away object.
fn full_scene(around: Around, keys: &str, scale: f32, centre: Vec3, extra: &str) -> String {
    let extra = format!("{extra}\n{}", binder(scale, centre));
    scene(around, keys, scale, centre, &extra)
        + "[materials.fog-binder]\ntype = \"interface\"\nmedium = \"fog\"\n\
           [materials.water-binder]\ntype = \"interface\"\nmedium = \"water\"\n"
}

#[test]
fn outside_keys_must_match_what_encloses_the_ball_at_every_scale_and_distance() {
    let places = [Around::Open, Around::Fog, Around::Water];
    for scale in [1e-3f32, 1.0, 1e3] {
        for centre in [Vec3::ZERO, Vec3::new(300.0, -200.0, 500.0) * scale] {
            for (keys, wrong) in key_cases() {
                for (around, wrong) in places.iter().zip(wrong) {
                    let toml = full_scene(*around, keys, scale, centre, "");
                    let what = format!("{keys:?} in {around:?} at scale {scale}, centre {centre}");
                    expect(&toml, wrong, &what);
                }
            }
        }
    }
}

#[test]
fn probes_pass_walls_and_siblings_but_not_ambiguous_geometry() {
    // A diffuse slab between the ball and the tank's side, and a second glass ball of the same
    // material beside the first: the right keys still load, wrong ones are still refused.
    let wall = "{ shape = \"box\", min = [0.7, -1.5, -1.5], max = [0.9, 1.5, 1.5], material = \"slab\" },\n\
                { shape = \"sphere\", center = [-1.2, 0, 0], radius = 0.5, subdivisions = 2, material = \"ball\" },";
    let slab = "[materials.slab]\ntype = \"diffuse\"\n";
    for (keys, wrong) in [
        ("outside_medium = \"water\"\noutside_ior = 1.33", &[][..]),
        ("outside_medium = \"water\"", &["outside_ior"][..]),
        ("", &["outside_medium", "outside_ior"][..]),
    ] {
        let toml = full_scene(Around::Water, keys, 1.0, Vec3::ZERO, wall) + slab;
        expect(
            &toml,
            wrong,
            &format!("{keys:?} behind a wall beside a sibling"),
        );
    }
    // In the fog box among six balls of another medium whose outside is the fog, one on each
    // side: probes that meet those balls from outside and probes that pass between them to
    // the box's inside both find fog, so they agree, and the ball's missing `outside_medium`
    // is still refused.
    let neighbour: String = [
        [1.1, 0.0, 0.0],
        [-1.1, 0.0, 0.0],
        [0.0, 1.1, 0.0],
        [0.0, -1.1, 0.0],
        [0.0, 0.0, 1.1],
        [0.0, 0.0, -1.1],
    ]
    .iter()
    .map(|[x, y, z]| {
        format!("{{ shape = \"sphere\", center = [{x}, {y}, {z}], radius = 0.5, subdivisions = 2, material = \"smoke-ball\" }},\n")
    })
    .collect();
    let smoke = "[materials.smoke-ball]\ntype = \"interface\"\nmedium = \"smoke\"\noutside_medium = \"fog\"\n\
                 [media.smoke]\nsigma_s = 3\n";
    for (keys, wrong) in [
        ("outside_medium = \"fog\"", &[][..]),
        ("", &["outside_medium"][..]),
    ] {
        let toml = full_scene(Around::Fog, keys, 1.0, Vec3::ZERO, &neighbour) + smoke;
        expect(&toml, wrong, &format!("{keys:?} in fog among smoke balls"));
    }
    // A ball crossing the tank's wall is partly in water and partly outside: its probes
    // disagree, so the check says nothing, whatever the keys.
    for keys in ["", "outside_medium = \"water\"\noutside_ior = 1.33"] {
        let toml = full_scene(Around::Water, keys, 1.0, Vec3::ZERO, "").replace(
            "center = [0, 0, 0], radius = 0.5",
            "center = [2, 0, 0], radius = 0.5",
        );
        assert!(
            toml.contains("center = [2, 0, 0]"),
            "the ball moved onto the wall"
        );
        load_with(&toml, &[]).unwrap_or_else(|e| panic!("{keys:?} across the wall: {e}"));
    }
}

#[test]
fn an_mtl_glass_in_fog_is_refused_at_its_file_with_the_fix() {
    // A tetrahedron wound outward, of MTL glass, inside a fog-filled box.
    let obj = b"mtllib g.mtl\nv 1 1 1\nv 1 -1 -1\nv -1 1 -1\nv -1 -1 1\nusemtl crystal\n\
                f 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\n"
        .to_vec();
    let mtl = b"newmtl crystal\nillum 7\nNi 1.5\n".to_vec();
    let toml = "camera = { position = [0, 0, -8], look_at = [0, 0, 0] }\n\
                object = [{ obj = \"g.obj\" },\n\
                { shape = \"box\", min = [-3, -3, -3], max = [3, 3, 3], material = \"fog-box\" }]\n\
                [materials.fog-box]\ntype = \"interface\"\nmedium = \"fog\"\n\
                [media.fog]\nsigma_s = 0.2\n";
    let files = [("g.obj", obj), ("g.mtl", mtl)];
    let e = load_with(toml, &files).expect_err("MTL glass with vacuum outside, in fog");
    let message = e.to_string();
    assert_eq!((e.file(), e.line()), ("g.mtl", None), "{message}");
    assert!(
        message.contains(
            "MTL cannot say it: add a [materials.crystal] table setting `outside_medium`"
        ),
        "{message}"
    );
    // The table the message asks for fixes it.
    let fixed = format!(
        "{toml}[materials.crystal]\ntype = \"glass\"\nior = 1.5\noutside_medium = \"fog\"\n"
    );
    load_with(&fixed, &files).unwrap_or_else(|e| panic!("the suggested table: {e}"));
}
