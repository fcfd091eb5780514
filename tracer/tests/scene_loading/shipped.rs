//! The scenes we ship and the shared real-world scenes of `../shared/scenes`, loaded from disk:
//! their geometry, materials and textures against their published descriptions.

use super::*;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn load_disk(relative: &str) -> (Scene, LoadReport) {
    let path = repo().join(relative);
    let files = scene::DiskFiles {
        root: path.parent().unwrap().to_path_buf(),
    };
    let name = path.file_name().unwrap().to_str().unwrap();
    scene::load_with_report(&files, name).unwrap_or_else(|e| panic!("{relative}: {e}"))
}

#[test]
fn the_shipped_cornell_box_has_the_published_geometry() {
    let (scene, report) = load_disk("scenes/cornell-box/cornell-box.toml");
    // 23 quads: floor, 8 ceiling pieces around the light, 3 walls, the light, 5 + 5 block faces.
    assert_eq!((scene.triangles.len(), report.degenerate()), (46, 0));
    let lights: Vec<_> = scene.emissive_triangles().collect();
    let area: f32 = lights.iter().map(|(_, t)| t.area()).sum();
    assert_eq!(lights.len(), 2);
    assert!((area - 130.0 * 105.0).abs() < 0.01, "{area}");
    let camera = scene.camera.at(0);
    assert_eq!(
        (camera.position, camera.vfov_degrees),
        (Vec3::new(278.0, 273.0, -800.0), 39.3077)
    );
    // Every surface faces the room's centre (walls) or away from its block's centre; the light
    // faces down.
    let room = Vec3::new(278.0, 274.4, 279.6);
    for t in &scene.triangles {
        let name = &scene.materials[t.material as usize].name;
        let c = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
        let front = match name.as_str() {
            "shortBox" => c - Vec3::new(186.0, 82.5, 168.5),
            "tallBox" => c - Vec3::new(368.5, 165.0, 351.25),
            "light" => Vec3::NEG_Y,
            _ => room - c,
        };
        assert!(
            t.area_vector().dot(front) > 0.0,
            "{name} faces the wrong way"
        );
    }
}

#[test]
fn the_analytic_scenes_are_closed_spheres_facing_inwards() {
    let furnace = load_disk("scenes/furnace/furnace.toml").0;
    let point = load_disk("scenes/point-in-sphere/point-in-sphere.toml").0;
    for (scene, triangles) in [(&furnace, 1280), (&point, 20480)] {
        assert_eq!(scene.triangles.len(), triangles);
        assert!(
            scene
                .triangles
                .iter()
                .all(|t| t.area_vector().dot(t.p[0]) < 0.0),
            "not inward"
        );
    }
    assert_eq!(
        (furnace.materials[0].emission, furnace.settings.max_depth),
        (Vec3::ONE, Some(8))
    );
    let light = point.point_lights[0];
    assert_eq!(
        (light.position, point.settings.max_depth),
        (Vec3::ZERO, None)
    );
    assert!(
        (light.intensity - Vec3::splat(std::f32::consts::PI))
            .abs()
            .max_element()
            < 1e-6
    );
    // The README's claim: the tessellation's area is within 0.03 % of the sphere's.
    let area: f32 = point.triangles.iter().map(|t| t.area()).sum();
    assert!(
        (area / (4.0 * std::f32::consts::PI) - 1.0).abs() < 0.0004,
        "{area}"
    );
}

#[test]
fn the_uneven_scene_pans_over_a_crowded_cluster() {
    let (scene, _) = load_disk("scenes/glass-cluster-pan/glass-cluster-pan.toml");
    let s = &scene.settings;
    assert_eq!(
        (s.width, s.height, s.samples_per_pixel, s.frames),
        (256, 256, 16, 24)
    );
    assert!(scene.camera.at(0).position.x < -3.0 && scene.camera.at(23).position.x > 3.0);
    let specular = |t: &&scene::Triangle| {
        let bsdf = &scene.materials[t.material as usize].bsdf;
        matches!(
            bsdf,
            Bsdf::Dielectric { .. } | Bsdf::Mirror { .. } | Bsdf::Conductor { .. }
        )
    };
    assert_eq!(scene.triangles.iter().filter(specular).count(), 9 * 1280);
}

/// The scenes of ../shared/scenes: the TOML in scenes/shared, the triangle count its
/// PROVENANCE.md gives, and how many of those have exactly zero area (counted independently of
/// the loader, with exact rational arithmetic on the f32-rounded vertices of the fan-triangulated
/// faces).
const SHARED: [(&str, usize, usize); 9] = [
    ("cornell-box-original", 36, 0),
    ("cornell-box-mirror", 36, 0),
    ("cornell-box-sphere", 2188, 0),
    ("cornell-box-water", 7088, 0),
    ("stanford-bunny", 69451, 0),
    ("cornell-bunny", 69463, 0),
    ("cornell-dragon", 871426, 110),
    ("sponza", 66450, 6),
    ("sponza-skylight", 66452, 6),
];

/// Whether ../shared/scenes exists; says what goes untested when it does not.
fn shared_scenes_present(test: &str) -> bool {
    let folder = repo().join("../shared/scenes");
    if !folder.is_dir() {
        println!(
            "NOT TESTED ({test}): {} is absent, so the shared scenes were not loaded",
            folder.display()
        );
    }
    folder.is_dir()
}

#[test]
fn every_shared_scene_loads_with_its_documented_triangle_count() {
    if !shared_scenes_present("every shared scene loads") {
        return;
    }
    for (name, expected, degenerate) in SHARED {
        let start = Instant::now();
        let (scene, report) = load_disk(&format!("scenes/shared/{name}.toml"));
        let (kept, dropped) = (scene.triangles.len(), report.degenerate());
        println!(
            "{name}: {kept} triangles kept, {dropped} zero-area dropped, loaded in {:.2?}",
            start.elapsed()
        );
        assert_eq!((kept + dropped, dropped), (expected, degenerate), "{name}");
        assert_eq!(scene.files[0], format!("{name}.toml"));
        assert!(
            scene.emissive_triangles().next().is_some() || scene.environment.is_some(),
            "{name}: no light"
        );
    }
}

#[test]
fn shared_cornell_boxes_get_materials_by_usemtl_and_map_mirror_and_glass() {
    if !shared_scenes_present("shared Cornell box materials") {
        return;
    }
    let (scene, _) = load_disk("scenes/shared/cornell-box-original.toml");
    // The boxes' `g` lines follow their faces; materials must still come from `usemtl`.
    let top = |name: &str| {
        let tris = scene
            .triangles
            .iter()
            .filter(|t| scene.materials[t.material as usize].name == name);
        tris.flat_map(|t| t.p).map(|p| p.y).fold(0.0f32, f32::max)
    };
    assert_eq!(
        (top("shortBox"), top("tallBox"), top("leftWall")),
        (0.6, 1.2, 1.99)
    );
    let material = |scene: &Scene, name: &str| {
        scene
            .materials
            .iter()
            .find(|m| m.name == name)
            .cloned()
            .unwrap()
    };
    assert_eq!(
        material(&scene, "light").emission,
        Vec3::new(17.0, 12.0, 4.0)
    );
    let (mirror, _) = load_disk("scenes/shared/cornell-box-mirror.toml");
    // The MTL says `newmtl tallBox ` with a trailing space.
    assert_eq!(
        material(&mirror, "tallBox").bsdf,
        Bsdf::Mirror {
            reflectance: Vec3::splat(0.95)
        }
    );
    let (sphere, _) = load_disk("scenes/shared/cornell-box-sphere.toml");
    let glass = Bsdf::Dielectric {
        ior: 2.5,
        tint: Vec3::splat(0.1),
    };
    assert_eq!(material(&sphere, "rightSphere").bsdf, glass);
    // `Kd 0.161 0.133 0.427 # Blue` is read without its comment.
    let blue = Bsdf::Diffuse {
        albedo: Vec3::new(0.161, 0.133, 0.427),
        texture: None,
    };
    assert_eq!(material(&sphere, "rightWall").bsdf, blue);
    assert!(
        sphere
            .attributes
            .iter()
            .any(|a| a.n.is_some() && a.uv.is_some())
    );
}

#[test]
fn shared_sponza_reads_its_textures_despite_the_case_of_their_names() {
    if !shared_scenes_present("Sponza textures") {
        return;
    }
    let (scene, _) = load_disk("scenes/shared/sponza.toml");
    let textured = scene.materials.iter().filter(|m| {
        matches!(
            m.bsdf,
            Bsdf::Diffuse {
                texture: Some(_),
                ..
            }
        )
    });
    // All 20 materials are used; 19 have a `map_Kd`, naming 12 distinct files (counted with grep).
    assert_eq!((textured.count(), scene.textures.len()), (19, 12));
    assert!(
        scene
            .files
            .iter()
            .any(|f| f.ends_with("dabrovic-sponza/00_skap.JPG")),
        "{:?}",
        scene.files
    );
    assert!(
        scene
            .textures
            .iter()
            .all(|t| t.texels().all(|c| c.is_finite() && c.max_element() <= 1.0))
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Scene files may come from other peers: no OBJ text, however wrong, may panic the loader.
    #[test]
    fn arbitrary_obj_statements_give_a_scene_or_an_error(
        words in prop::collection::vec(prop::sample::select(&[
            "v", "vt", "vn", "f", "l", "usemtl white", "usemtl lamp", "usemtl x", "mtllib m.mtl",
            "g a", "0", "1", "2", "3", "-1", "-3", "0.5", "1e39", "nan", "1/1", "2/1/1", "3//1",
            "-1/-1/-1", "#", "\r", "\n", "\n", "\n", " ", "\t",
        ][..]), 0..60)
    ) {
        let obj = words.join(" ");
        let _ = load(&[("scene.toml", SCENE), ("m.obj", &obj), ("m.mtl", MTL)]);
    }
}
