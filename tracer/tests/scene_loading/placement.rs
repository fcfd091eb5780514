//! Where the loader puts objects and the camera: an object's transform, applied in its stated
//! order, and the camera's keyframes, which inherit what they leave out from the camera table.

use super::*;

#[test]
fn transforms_apply_scale_then_rotation_then_translation() {
    let toml = format!(
        "{CAMERA}[[object]]\nshape = \"quad\"\ncorners = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]\n\
         material = \"m\"\nscale = [2, 3, 1]\nrotate_z = 90\ntranslate = [10, 0, 0]\n\
         [materials.m]\ntype = \"emissive\"\nemission = 1\n"
    );
    let scene = scene::load_str(&toml).unwrap();
    // (1, 0, 0) -> scaled (2, 0, 0) -> rotated 90 degrees about z (0, 2, 0) -> moved (10, 2, 0);
    // (1, 1, 0) -> (2, 3, 0) -> (-3, 2, 0) -> (7, 2, 0).
    let [_, b, c] = scene.triangles[0].p;
    assert!((b - Vec3::new(10.0, 2.0, 0.0)).length() < 1e-5, "{b}");
    assert!((c - Vec3::new(7.0, 2.0, 0.0)).length() < 1e-5, "{c}");
    assert_eq!(
        scene.materials[0].bsdf,
        Bsdf::Diffuse {
            albedo: Vec3::ZERO,
            texture: None
        }
    );
}

#[test]
fn camera_keys_inherit_from_the_camera_table_and_set_the_frame_count() {
    let toml = "[camera]\nvfov = 50\nlook_at = [0, 0, 0]\n\
                [[camera.keys]]\nframe = 10\nposition = [0, 0, -4]\n\
                [[camera.keys]]\nframe = 0\nposition = [2, 0, -4]\nvfov = 30\n\
                [[object]]\nshape = \"box\"\nmin = [-1, -1, -1]\nmax = [1, 1, 1]\nmaterial = \"m\"\n\
                [materials.m]\ntype = \"diffuse\"\n";
    let scene = scene::load_str(toml).unwrap();
    assert_eq!(scene.settings.frames, 11);
    assert_eq!(
        (
            scene.camera.at(0).vfov_degrees,
            scene.camera.at(10).vfov_degrees
        ),
        (30.0, 50.0)
    );
    assert_eq!(scene.camera.at(5).position, Vec3::new(1.0, 0.0, -4.0));
    let twice = toml.replace("frame = 0", "frame = 10");
    rejects(
        load(&[("scene.toml", &twice)]),
        "scene.toml:7",
        "two keys at frame 10 (the other at line 4)",
    );
}

/// Each triangle's normals and texture coordinates (kept apart from it, in the scene's table)
/// are its own, whatever comes before it: a dropped degenerate triangle, other objects'
/// attributes, an object without any (a faceted sphere) before them all. The OBJ gives every vertex the texture coordinates `(x, y)`
/// and the normal `(x, y, 1)` (normalised) of its own object-space position, so the expected
/// attributes of a placed corner follow from where it lies, undone by its object's transform:
/// a rotated object's normals turn with it, and a mirrored one's corners keep theirs (the loader
/// swaps two corners to keep the front, and their attributes must follow).
#[test]
fn each_triangle_keeps_its_own_attributes_across_objects_and_transforms() {
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n\
               vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 2 0\n\
               vn 0 0 1\nvn 1 0 1\nvn 1 1 1\nvn 0 1 1\nvn 2 0 1\nusemtl m\n\
               f 1/1/1 5/5/5 2/2/2\nf 1/1/1 2/2/2 3/3/3\nf 1/1/1 3/3/3 4/4/4\n";
    let object = |extra: &str| format!("[[object]]\nobj = \"a.obj\"\n{extra}");
    let toml = format!(
        "{CAMERA}[[object]]\nshape = \"sphere\"\nsubdivisions = 0\nsmooth = false\n\
         material = \"m\"\n{}{}{}[[object]]\nshape = \"quad\"\n\
         corners = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]\nmaterial = \"m\"\n\
         translate = [0, 0, 5]\n{}[materials.m]\ntype = \"diffuse\"\n",
        object(""),
        object("rotate_z = 90\ntranslate = [10, 0, 0]\n"),
        object("scale = [-1, 1, 1]\ntranslate = [0, 10, 0]\n"),
        object("translate = [0, 0, -7]\n"),
    );
    let (scene, report) = load(&[("scene.toml", &toml), ("a.obj", obj)]).unwrap();
    // Each object's undoing of its transform, and its normals' turn, written out here.
    type Map = fn(Vec3) -> Vec3;
    let identity: (Map, Map) = (|p| p, |n| n);
    let rotated: (Map, Map) = (
        |p| Vec3::new(p.y, 10.0 - p.x, p.z),
        |n| Vec3::new(-n.y, n.x, n.z),
    );
    let mirrored: (Map, Map) = (
        |p| Vec3::new(-p.x, p.y - 10.0, p.z),
        |n| Vec3::new(-n.x, n.y, n.z),
    );
    let quad: (Map, Map) = (|p| p - Vec3::new(0.0, 0.0, 5.0), |n| n);
    let moved: (Map, Map) = (|p| p + Vec3::new(0.0, 0.0, 7.0), |n| n);
    let objects = [
        None,
        Some(identity),
        Some(rotated),
        Some(mirrored),
        Some(quad),
        Some(moved),
    ];
    // Once a triangle has attributes, every still triangle has an entry, those before it too.
    assert_eq!(scene.attributes.len(), scene.triangles.len());
    let ranges: Vec<_> = report.still_objects().collect();
    assert_eq!(ranges.len(), objects.len());
    for ((object, range), expected) in ranges.into_iter().zip(objects) {
        let triangles = &scene.triangles[range.clone()];
        // The degenerate first face of each OBJ is dropped; the sphere has 20, the quad 2.
        assert_eq!(
            triangles.len(),
            [20, 2, 2, 2, 2, 2][object],
            "object {object}"
        );
        for (t, i) in triangles.iter().zip(range) {
            let attributes = scene.attributes.get(i).filter(|a| !a.is_empty());
            let Some((local, turn)) = expected else {
                assert_eq!(attributes, None, "a faceted sphere has no attributes");
                continue;
            };
            let a = attributes.unwrap();
            for corner in 0..3 {
                let q = local(t.p[corner]);
                let uv = a.uv.unwrap()[corner];
                assert!(
                    (uv - Vec2::new(q.x, q.y)).length() < 1e-5,
                    "object {object}, corner at {q}: texture coordinates {uv}"
                );
                if object == 4 {
                    assert_eq!(a.n, None, "a quad has no normals");
                    continue;
                }
                let n = a.n.unwrap()[corner];
                let want = turn(Vec3::new(q.x, q.y, 1.0).normalize());
                assert!(
                    (n - want).length() < 1e-5,
                    "object {object}, corner at {q}: normal {n}, not {want}"
                );
            }
        }
    }
}
