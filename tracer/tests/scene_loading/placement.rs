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
