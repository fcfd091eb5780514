//! The scene loader against bad input, the shipped scenes and the shared real-world scenes.
//!
//! Bad inputs are written into an in-memory file set (or a temporary folder, for the disk path)
//! and each test checks that the error names the file, the 1-based line and the problem.
//! Expected counts of the shared scenes come from their PROVENANCE.md files and an independent
//! count, not from the loader.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use glam::{Vec2, Vec3};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tracer::material::Bsdf;
use tracer::scene::{self, LoadReport, MemoryFiles, Scene, SceneError};

/// The shipped scenes and the shared real-world ones, loaded from disk.
#[path = "scene_loading/shipped.rs"]
mod shipped;

/// Where objects and the camera are placed: transforms and keyframes.
#[path = "scene_loading/placement.rs"]
mod placement;

type Loaded = Result<(Scene, LoadReport), SceneError>;

const CAMERA: &str = "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n";
/// [`CAMERA`] plus one object `m.obj`, whose table starts at line 5.
const SCENE: &str =
    "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\n[[object]]\nobj = \"m.obj\"\n";
const MTL: &str = "newmtl white\nKd 0.5 0.5 0.5\n\nnewmtl lamp\nKd 0 0 0\nKe 4 4 4\n";
/// A valid OBJ, one statement per line.
const GOOD: [&str; 6] = [
    "mtllib m.mtl",
    "v 0 0 0",
    "v 1 0 0",
    "v 0 1 0",
    "usemtl white",
    "f 1 2 3",
];

fn load(entries: &[(&str, &str)]) -> Loaded {
    let mut files = MemoryFiles::new();
    for (name, content) in entries {
        files.insert(name, *content);
    }
    scene::load_with_report(&files, "scene.toml")
}

/// The scene [`SCENE`] with the OBJ `lines` and the MTL `mtl`.
fn load_obj_with(lines: &[&str], mtl: &str) -> Loaded {
    load(&[
        ("scene.toml", SCENE),
        ("m.obj", &lines.join("\n")),
        ("m.mtl", mtl),
    ])
}

fn load_obj(lines: &[&str]) -> Loaded {
    load_obj_with(lines, MTL)
}

/// `GOOD` with `line` inserted as line 4.
fn good_with(line: &str) -> Vec<&str> {
    let mut lines = GOOD.to_vec();
    lines.insert(3, line);
    lines
}

/// Asserts the load failed at `place` ("file:line", or "file" when no line applies) saying `says`.
#[track_caller]
fn rejects(result: Loaded, place: &str, says: &str) {
    let Err(e) = result else {
        panic!("the input must be rejected")
    };
    let message = e.to_string();
    let (file, line) = match place.rsplit_once(':') {
        Some((file, line)) => (file, Some(line.parse().unwrap())),
        None => (place, None),
    };
    assert_eq!(
        (e.file(), e.line()),
        (file, line),
        "wrong place in: {message}"
    );
    assert!(message.contains(place), "`{message}` should name {place}");
    assert!(message.contains(says), "`{message}` should say `{says}`");
}

#[test]
fn a_good_obj_loads_and_lists_its_files() {
    let (scene, report) = load_obj(&GOOD).unwrap();
    assert_eq!((scene.triangles.len(), report.degenerate()), (1, 0));
    assert_eq!(scene.materials[0].name, "white");
    assert_eq!(scene.files, ["scene.toml", "m.obj", "m.mtl"]);
}

#[test]
fn non_finite_and_overflowing_vertices_are_rejected_at_their_line() {
    #[rustfmt::skip]
    let cases = [
        ("v nan 1 2", "`nan` is not a finite 32-bit number"),
        ("v inf 0 0", "`inf` is not a finite 32-bit number"),
        ("v 1e39 0 0", "`1e39` is not a finite 32-bit number"),
        ("v 0 -1e39 0", "`-1e39` is not a finite 32-bit number"),
        ("v 1 2 3 0", "vertex weight `w` is 0"),
        ("v 3e38 0 0 0.1", "coordinates overflow 32-bit floats"),
        ("v 1 2", "expected x y z"),
        ("v 1 x 2", "`x` is not a number"),
        ("vn 0 1", "expected 3 numbers"),
        ("vt 0 nan", "`nan` is not a finite"),
    ];
    for (bad, says) in cases {
        rejects(load_obj(&good_with(bad)), "m.obj:4", says);
    }
}

#[test]
fn bad_face_indices_are_rejected_at_their_line() {
    #[rustfmt::skip]
    let cases = [
        ("f 1 2 4", "vertex index 4 is out of range (3 defined"),
        ("f 0 1 2", "vertex index 0 (OBJ indices start at 1)"),
        ("f -1 -2 -4", "vertex index -4 is out of range"),
        ("f 1/1 2/1 3/1", "texture coordinate index 1 is out of range (0 defined"),
        ("f 1//2 2//2 3//2", "normal index 2 is out of range"),
        ("f 1 2", "at least 3 corners"),
        ("f 1 2/1 3", "form of the face's first corner"),
        ("f 1 2 x", "`x` is not an integer index"),
    ];
    for (face, says) in cases {
        let mut lines = GOOD.to_vec();
        lines[5] = face;
        rejects(load_obj(&lines), "m.obj:6", says);
    }
    // A face may only use what was defined before it.
    rejects(
        load_obj(&["f 1 2 3", "v 0 0 0", "v 1 0 0", "v 0 1 0"]),
        "m.obj:1",
        "(0 defined",
    );
}

#[test]
fn crlf_comments_relative_indices_and_polygons_are_understood() {
    let obj = [
        "# a comment line with \u{e9}",
        "mtllib m.mtl   # trailing comment",
        "v 0 0 0 # origin",
        "v 1 0 0",
        "v 1 1 0",
        "v 0 1 0",
        "v 0.5 1.5 0 1",
        "vt 0 0\r",
        "vt 1 0",
        "vt 1 1",
        "vn 0 0 1",
        "g group-names-do-not-matter",
        "usemtl white # Blue",
        "f -5/1/1 -4/2/1 -3/3/1 -2/3/1 -1/3/1",
        "usemtl lamp",
        "f 1//1 2//1 3//1",
        "l 1 2 3",
        "p 4",
    ];
    let crlf = obj.join("\r\n");
    let (scene, _) = load(&[("scene.toml", SCENE), ("m.obj", &crlf), ("m.mtl", MTL)]).unwrap();
    // The pentagon fans into 3 triangles; the `l` and `p` statements add none.
    let name = |t: &scene::Triangle| scene.materials[t.material as usize].name.clone();
    let names: Vec<String> = scene.triangles.iter().map(name).collect();
    assert_eq!(names, ["white", "white", "white", "lamp"]);
    // Counted before the array is made, polygons' fans included: counting faces came out
    // short, and the array doubled for the last triangles (the dragon's 94 MB held 188 MB).
    let quad_and_triangle = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl white\n\
                             f 1 2 3 4\nf 1 2 3\n";
    let (fans, _) = load(&[
        ("scene.toml", SCENE),
        ("m.obj", quad_and_triangle),
        ("m.mtl", MTL),
    ])
    .unwrap();
    assert_eq!((fans.triangles.len(), fans.triangles.capacity()), (3, 3));
    let first = scene.attributes[0];
    assert_eq!(first.uv.unwrap()[1], Vec2::new(1.0, 0.0));
    assert_eq!(first.n.unwrap()[0], Vec3::Z);
    assert_eq!(scene.materials[1].emission, Vec3::splat(4.0));
    // An error in a CRLF file is still reported at the right line.
    let bad = crlf.replace("v 1 1 0", "v 1 nan 0");
    rejects(
        load(&[("scene.toml", SCENE), ("m.obj", &bad), ("m.mtl", MTL)]),
        "m.obj:5",
        "nan",
    );
}

#[test]
fn missing_mtl_unknown_usemtl_and_empty_objs_are_rejected() {
    let mut missing = GOOD.to_vec();
    missing[0] = "mtllib gone.mtl";
    let e = load_obj(&missing).err().unwrap();
    assert!(matches!(e, SceneError::Read { .. }), "{e}");
    assert_eq!(e.file(), "gone.mtl");
    assert!(e.to_string().contains("referenced at m.obj:1"), "{e}");

    let mut unknown = GOOD.to_vec();
    unknown[4] = "usemtl whte";
    rejects(
        load_obj(&unknown),
        "m.obj:5",
        "`usemtl whte`: no material of that name in m.mtl or the scene",
    );
    rejects(
        load_obj(&["v 0 0 0", "usemtl x", "f 1 1 1"]),
        "m.obj:2",
        "no `mtllib`",
    );
    rejects(
        load_obj(&["mtllib m.mtl", "v 0 0 0", "v 1 0 0"]),
        "m.obj",
        "no faces",
    );
    let no_usemtl = ["v 0 0 0", "v 1 0 0", "v 0 1 0", "f 1 2 3"];
    rejects(load_obj(&no_usemtl), "m.obj:4", "face before any `usemtl`");
    // ... which a default material for the object fixes.
    let with_default = format!("{SCENE}material = \"d\"\n[materials.d]\ntype = \"diffuse\"\n");
    let obj = no_usemtl.join("\n");
    let (scene, _) = load(&[("scene.toml", &with_default), ("m.obj", &obj)]).unwrap();
    assert_eq!(scene.materials[0].name, "d");
    // A `usemtl` may name a material of the scene instead of an MTL one.
    let obj = ["v 0 0 0", "v 1 0 0", "v 0 1 0", "usemtl d", "f 1 2 3"].join("\n");
    let toml = format!("{SCENE}[materials.d]\ntype = \"mirror\"\n");
    let (scene, _) = load(&[("scene.toml", &toml), ("m.obj", &obj)]).unwrap();
    assert_eq!(
        scene.materials[0].bsdf,
        Bsdf::Mirror {
            reflectance: Vec3::ONE
        }
    );
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let obj = [
        "mtllib m.mtl",
        "v 0 0 0",
        "v 1 0 0",
        "v 0 1 0",
        "v 2 0 0",
        "usemtl white",
        "f 1 2 3",
        "f 1 2 4",
        "f 3 3 1",
        "f 1 2 3 4",
    ];
    let (scene, report) = load_obj(&obj).unwrap();
    // Of the 5 triangles, (1 2 4) is collinear and (3 3 1) repeats a vertex; the quad's two
    // halves (1 2 3) and (1 3 4) have area.
    assert_eq!((scene.triangles.len(), report.degenerate()), (3, 2));
    let object = &report.objects[0];
    assert_eq!(
        (object.source.as_str(), object.triangles, object.degenerate),
        ("m.obj", 3, 2)
    );
    let flat = [
        "mtllib m.mtl",
        "v 0 0 0",
        "v 1 0 0",
        "usemtl white",
        "f 1 2 2",
    ];
    rejects(load_obj(&flat), "m.obj", "every triangle has zero area");
}

#[test]
fn mtl_values_are_checked_at_their_line_unless_the_scene_replaces_the_material() {
    let bright = "newmtl white\nKd 1.5 0.5 0.5\n";
    rejects(load_obj_with(&GOOD, bright), "m.mtl:2", "exceeds 1");
    rejects(
        load_obj_with(&GOOD, "newmtl white\nKe 1 -1 1\n"),
        "m.mtl:2",
        "not be negative",
    );
    rejects(
        load_obj_with(&GOOD, "newmtl white\nillum 7\nNi 0.5\n"),
        "m.mtl:3",
        "at least 1",
    );
    let obj = GOOD.join("\n");
    let replaced = format!("{SCENE}\n[materials.white]\ntype = \"mirror\"\n");
    let (scene, _) = load(&[
        ("scene.toml", &replaced),
        ("m.obj", &obj),
        ("m.mtl", bright),
    ])
    .unwrap();
    assert_eq!(
        scene.materials[0].bsdf,
        Bsdf::Mirror {
            reflectance: Vec3::ONE
        }
    );
    // tobj would panic on the one-component `Kd 0.5`, which the MTL format allows.
    let (scene, _) = load_obj_with(&GOOD, "newmtl white\nKd 0.5\n").unwrap();
    let grey = Bsdf::Diffuse {
        albedo: Vec3::splat(0.5),
        texture: None,
    };
    assert_eq!(scene.materials[0].bsdf, grey);
    let unused = format!("{SCENE}\n[materials.whiet]\ntype = \"mirror\"\n");
    let result = load(&[("scene.toml", &unused), ("m.obj", &obj), ("m.mtl", MTL)]);
    rejects(
        result,
        "scene.toml:8",
        "[materials.whiet] matches no MTL material",
    );
}

#[test]
fn toml_errors_name_the_line_and_the_key() {
    #[rustfmt::skip]
    let cases = [
        ("[render]\nwidth = \"big\"\n", 2, "key `render.width`"),
        ("[render]\nwidht = 4\n", 2, "unknown field `widht`"),
        ("[render]\n\nspp = 0\n", 3, "must be at least 1 (key `render.spp`)"),
        ("[render]\nmax_depth = \"forever\"\n", 2, "\"unlimited\""),
        ("[render]\nrussian_roulette_depth = -1\n", 2, "\"off\""),
        ("[camera.keys]\n", 1, "invalid type"),
        ("[environment]\nradiance = [1, 1]\n", 2, "array of 3 numbers"),
        ("[[object]]\nshape = \"cone\"\n", 2, "unknown variant `cone`"),
        ("[[light]]\ntype = \"point\"\nposition = [0, nan, 0]\nintensity = 1\n", 3, "finite"),
        ("[materials.a]\ntype = \"diffuse\"\nalbedo = [2, 0, 0]\n", 3, "[0, 1]"),
        ("[render\n", 1, ""),
    ];
    for (toml, line, says) in cases {
        // The camera goes last, so that `line` counts from the case's first line.
        let toml = format!("{toml}\n{CAMERA}");
        rejects(
            load(&[("scene.toml", &toml)]),
            &format!("scene.toml:{line}"),
            says,
        );
    }
    let vfov = format!("{CAMERA}vfov = 200\n");
    rejects(
        load(&[("scene.toml", &vfov)]),
        "scene.toml:4",
        "200 must be in (0, 180) degrees",
    );
}

#[test]
fn toml_references_are_checked_with_their_line() {
    let sphere = |extra: &str| format!("{CAMERA}\n[[object]]\nshape = \"sphere\"\n{extra}\n");
    let m = "[materials.m]\ntype = \"diffuse\"";
    #[rustfmt::skip]
    let cases = [
        (sphere("material = \"nope\""), 7, "material `nope` is not defined"),
        (sphere(""), 5, "`sphere` needs `material"),
        (sphere(&format!("material = \"m\"\nmin = [0, 0, 0]\n{m}")), 5, "key `min` does not apply"),
        (sphere("material = \"m\"\n[materials.m]\ntype = \"glass\"\nalbedo = 0.5"), 8, "type glass"),
        (sphere("material = \"m\"\n[materials.m]\ntype = \"emissive\""), 8, "non-zero `emission`"),
        (sphere("material = \"m\"\nsubdivisions = 9\n[materials.m]\ntype = \"mirror\""), 5, "above 8"),
        (format!("{CAMERA}\n[[object]]\nshape = \"box\"\nmin = [0, 0, 0]\nmax = [1, 0, 1]\nmaterial = \"m\"\n{m}"), 5, "below `max`"),
        (format!("{CAMERA}\n[[object]]\nobj = \"a.obj\"\nshape = \"box\"\n"), 5, "both `obj` and `shape`"),
        (sphere(&format!("material = \"m\"\n{m}")).replace("[0, 0, 0]", "[0, 0, -5]"), 1, "`look_at` equals"),
        (format!("{CAMERA}up = [0, 0, 2]\n"), 1, "`up` is parallel"),
    ];
    for (toml, line, says) in cases {
        rejects(
            load(&[("scene.toml", &toml)]),
            &format!("scene.toml:{line}"),
            says,
        );
    }
    rejects(
        load(&[("scene.toml", CAMERA)]),
        "scene.toml",
        "the scene has no triangles",
    );
    let missing = format!("{CAMERA}\n[[object]]\nobj = \"meshes/missing.obj\"\n");
    let e = load(&[("scene.toml", &missing)]).err().unwrap();
    assert_eq!(e.file(), "meshes/missing.obj");
    assert!(e.to_string().contains("referenced at scene.toml:6"), "{e}");
}

#[test]
fn disk_errors_give_full_paths() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.toml"), SCENE).unwrap();
    std::fs::write(
        dir.path().join("m.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n",
    )
    .unwrap();
    let e = scene::load(&dir.path().join("scene.toml")).unwrap_err();
    assert_eq!(
        (e.file(), e.line()),
        (dir.path().join("m.obj").to_str().unwrap(), Some(4))
    );
    std::fs::remove_file(dir.path().join("m.obj")).unwrap();
    let e = scene::load(&dir.path().join("scene.toml"))
        .unwrap_err()
        .to_string();
    let toml = dir.path().join("scene.toml");
    assert!(
        e.contains("m.obj") && e.contains(&format!("{}:6", toml.display())),
        "{e}"
    );
}

#[test]
fn textures_match_case_insensitively_decode_to_linear_and_are_listed() {
    let mut png = Vec::new();
    let image = image::RgbImage::from_fn(2, 1, |x, _| {
        image::Rgb([0, 128, if x == 0 { 255 } else { 0 }])
    });
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let obj = "mtllib ../mat/m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl t\nf 1/1 2/1 3/1\n";
    let mut set = MemoryFiles::new();
    set.insert(
        "s/scene.toml",
        format!("{CAMERA}[[object]]\nobj = \"mesh/m.obj\"\n"),
    );
    set.insert("s/mesh/m.obj", obj);
    set.insert(
        "s/mat/m.mtl",
        "newmtl t\nKd 0.6 0.6 0.6\nmap_Kd ..\\tex\\WALL.PNG\n",
    );
    set.insert("s/tex/wall.png", png);
    let (scene, _) = scene::load_with_report(&set, "s/scene.toml").unwrap();
    assert_eq!(
        scene.files,
        ["scene.toml", "mesh/m.obj", "mat/m.mtl", "tex/wall.png"]
    );
    // sRGB 128/255 is 0.21586 in linear light (IEC 61966-2-1).
    let texel = scene.textures[0].texel(0);
    assert!(
        texel.x == 0.0 && (texel.y - 0.21586).abs() < 1e-4 && texel.z == 1.0,
        "{texel}"
    );
    assert_eq!(
        scene.materials[0].bsdf,
        Bsdf::Diffuse {
            albedo: Vec3::ONE,
            texture: Some(0)
        }
    );
    // The files, shipped to a peer as Scene::files lists them, load into the same scene.
    let mut shipped = MemoryFiles::new();
    for name in &scene.files {
        shipped.insert(name, set.0[&format!("s/{name}")].clone());
    }
    let again = scene::load_from(&shipped, &scene.files[0]).unwrap();
    assert_eq!(
        (&again.triangles, &again.textures),
        (&scene.triangles, &scene.textures)
    );
    assert_eq!(
        (&again.materials, &again.files),
        (&scene.materials, &scene.files)
    );
    set.insert("s/tex/wall.png", "not a png");
    rejects(
        scene::load_with_report(&set, "s/scene.toml"),
        "tex/wall.png",
        "cannot decode",
    );
}
