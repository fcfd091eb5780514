//! A tile's paths in lanes (`integrator/lanes/`, fed by `tile/lanes.rs`) render the same bits
//! as the same paths one by one, with the same counted work and cost map, whole frames and
//! tiles cut mid-row alike: across scales and distances from the origin (where the offsets of
//! both rays' origins are tested hardest), one sample per pixel, sample counts that leave a
//! pixel's last packet partly empty, tiles with fewer paths than lanes and tiles of no pixels,
//! depths from emitters alone to long paths, Russian roulette from the first bounce, and the
//! camera's rays found in packets or one by one; with textures, shading normals and a constant
//! sky beside an area light; with ideal mirrors, smooth glass and rough metals of every
//! roughness among the diffuse surfaces; with point lights beside area lights, skies and maps,
//! and alone; with Russian roulette off; with a moving box and a moving lamp (and the shipped
//! scenes of motion blur); with the sky through portals (one window or two, a constant sky or a
//! map, every kind of surface and light, things moving, at every scale and distance). Worlds
//! the lanes do not fit (fog, dispersive glass) render one by one whatever the knob says.

mod common;

use std::path::Path;
use tracer::scene::{CameraTrack, Scene};
use tracer::{CameraRays, PathLanes, Rect, World};

/// The shipped Cornell box (diffuse walls, one emissive quad), loaded.
fn cornell_box() -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/cornell-box.toml");
    tracer::scene::load(&path).expect("the shipped Cornell box loads")
}

/// `scene` with its tall box an ideal mirror and its short box smooth glass (both tinted, so
/// that their weights show in every channel): the lanes' delta bounces, reflected and
/// refracted, without a light sample, among the diffuse ones.
fn with_a_mirror_and_glass(mut scene: Scene) -> Scene {
    for (name, bsdf) in [
        (
            "tallBox",
            tracer::material::Bsdf::Mirror {
                reflectance: glam::Vec3::new(0.9, 0.8, 0.7),
            },
        ),
        (
            "shortBox",
            tracer::material::Bsdf::Dielectric {
                ior: 1.5,
                tint: glam::Vec3::new(0.95, 0.9, 1.0),
            },
        ),
    ] {
        let material = scene
            .materials
            .iter_mut()
            .find(|m| m.name == name)
            .expect("the Cornell box has both boxes");
        material.bsdf = bsdf;
    }
    scene
}

/// `scene` with its tall box a rough metal of roughness `alpha` (tinted) and its short box
/// smooth glass, lit by a point light, beside its lamp where `lamp` and alone elsewhere: the
/// lanes' glossy light samples, weighed by the metal's lobe, and their point lights, whose
/// shadow rays end on no surface. The light hangs in the room's upper half, or where
/// `on_ceiling` lies exactly in the ceiling's plane (a fitting on the ceiling), where shadow
/// rays end on a surface that may block them. Its place and intensity follow the room's
/// bounds, so that the picture is the same at every scale.
fn with_metal_and_a_point_light(scene: Scene, alpha: f32, lamp: bool, on_ceiling: bool) -> Scene {
    let mut scene = with_a_mirror_and_glass(scene);
    let metal = scene
        .materials
        .iter_mut()
        .find(|m| m.name == "tallBox")
        .expect("the Cornell box has a tall box");
    metal.bsdf = tracer::material::Bsdf::Conductor {
        f0: glam::Vec3::new(0.95, 0.7, 0.5),
        alpha,
    };
    if !lamp {
        for material in &mut scene.materials {
            material.emission = glam::Vec3::ZERO;
        }
    }
    let corners = scene.triangles.iter().flat_map(|t| t.p);
    let (low, high) = corners.fold(
        (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
        |(low, high), p| (low.min(p), high.max(p)),
    );
    let extent = (high - low).max_element();
    let mut position = low + (high - low) * glam::Vec3::new(0.45, 0.8, 0.4);
    if on_ceiling {
        // The ceiling is the room's top: every corner of it has this height, to the bit.
        position.y = high.y;
    }
    scene.point_lights.push(tracer::scene::PointLight {
        position,
        intensity: glam::Vec3::new(1.0, 0.9, 0.7) * (0.5 * extent * extent),
    });
    scene
}

/// `scene` with its short box and its lamp (the triangles of `moved`, materials named) taken
/// out of the still triangles and keyed to move over frame 0 (the shutter open from 0 to 1),
/// each about its own centre: the box slides a tenth of the room, turns 50 degrees about the
/// vertical and stretches; the lamp slides and tilts. The lanes' hits on moving triangles and
/// their moving light's samples, both placed by the path's moment, and rays leaving from
/// origins worked out in the objects' space.
fn with_moving(scene: Scene, moved: &[&str]) -> Scene {
    with_moving_objects(scene, moved, false)
}

/// [`with_moving`], each triangle of the materials named its own object where `apart`: more
/// objects than a path places as it starts (sixteen) and than the motion's flat list holds
/// (eight), so that paths place them as they meet them, found through the tree over their
/// swept boxes.
fn with_moving_objects(mut scene: Scene, moved: &[&str], apart: bool) -> Scene {
    use tracer::scene::{MovingObject, TransformKey, TransformTrack, Triangle};
    let corners = scene.triangles.iter().flat_map(|t| t.p);
    let (low, high) = corners.fold(
        (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
        |(low, high), p| (low.min(p), high.max(p)),
    );
    let extent = (high - low).max_element();
    assert!(
        scene.attributes.is_empty(),
        "the box has no vertex attributes"
    );
    for name in moved {
        let material = scene
            .materials
            .iter()
            .position(|m| m.name == *name)
            .expect("the Cornell box has the material") as u32;
        let (ours, rest): (Vec<Triangle>, Vec<Triangle>) =
            scene.triangles.iter().partition(|t| t.material == material);
        assert!(!ours.is_empty(), "{name} has triangles");
        scene.triangles = rest;
        let groups = if apart {
            ours.iter().map(|t| vec![*t]).collect()
        } else {
            vec![ours]
        };
        for (k, group) in groups.into_iter().enumerate() {
            let centre =
                group.iter().flat_map(|t| t.p).sum::<glam::Vec3>() / (3 * group.len()) as f32;
            let key = |frame: u32, slide: f32, turn: glam::Vec3, scale: glam::Vec3| TransformKey {
                frame,
                scale,
                rotate_degrees: turn,
                translate: centre + glam::Vec3::new(slide, 0.0, -0.5 * slide) * extent,
            };
            let still = key(0, 0.0, glam::Vec3::ZERO, glam::Vec3::ONE);
            let moved = if *name == "light" {
                key(1, 0.08, glam::Vec3::new(0.0, 0.0, 12.0), glam::Vec3::ONE)
            } else {
                let turn = glam::Vec3::new(0.0, 50.0 * (1.0 + k as f32 * 0.37), 0.0);
                key(1, 0.1, turn, glam::Vec3::new(1.2, 0.8, 1.0))
            };
            scene.moving.push(MovingObject {
                triangles: group
                    .iter()
                    .map(|t| Triangle {
                        p: t.p.map(|p| p - centre),
                        material,
                    })
                    .collect(),
                attributes: Vec::new(),
                track: TransformTrack::new(vec![still, moved]).expect("two keys that differ"),
            });
        }
    }
    scene.shutter = tracer::scene::Shutter {
        open: 0.0,
        close: 1.0,
    };
    scene
}

/// `scene` scaled by `scale` about the origin, then moved by `shift`: every triangle, every
/// portal and the camera, so that the image is the same picture at another scale and distance.
fn placed(mut scene: Scene, scale: f32, shift: glam::Vec3) -> Scene {
    let place = |p: glam::Vec3| p * scale + shift;
    for triangle in &mut scene.triangles {
        triangle.p = triangle.p.map(place);
    }
    for portal in &mut scene.portals {
        portal.corner = place(portal.corner);
        portal.edge_u *= scale;
        portal.edge_v *= scale;
    }
    let mut camera = scene.camera.at_time(0.0);
    camera.position = place(camera.position);
    camera.look_at = place(camera.look_at);
    camera.focus_distance *= scale;
    scene.camera = CameraTrack::fixed(camera);
    scene
}

/// What a render both ways must agree on: the image's bits, the statistics and the cost map,
/// of the whole frame and of a tile away from its corner (whose pixels start mid-row, so that
/// the lanes' stream hands out and stores pixels of rows cut by the tile's edges).
#[derive(Debug, PartialEq)]
struct Rendered {
    bits: Vec<u32>,
    stats: tracer::PathStats,
    cost: tracer::TileCost,
    tile_bits: Vec<u32>,
    tile_cost: tracer::TileCost,
    tile_stats: tracer::PathStats,
    /// Tiles too small to fill the lanes: a pixel (fewer paths than lanes at the scene's
    /// sample counts below eight) and a row of two; and a tile of no pixels.
    small: Vec<(Vec<u32>, tracer::TileCost, tracer::PathStats)>,
}

/// The render with the paths advanced as `paths` says and the camera's rays found as
/// `camera_rays` says; and whether the lanes ran.
fn render(scene: Scene, paths: PathLanes, camera_rays: CameraRays) -> (Rendered, bool) {
    let mut world = World::prepare(scene, None);
    world.paths = paths;
    world.camera_rays = camera_rays;
    let fits = world.lanes_fit();
    let bits = |out: &tracer::TileOutput| -> Vec<u32> {
        out.pixels.iter().flatten().map(|c| c.to_bits()).collect()
    };
    let out = common::render_world(&world, 0);
    let (w, h) = (world.scene.settings.width, world.scene.settings.height);
    let rect = Rect {
        x: w / 3,
        y: h / 4,
        w: w / 2 + 1,
        h: h / 3 + 1,
    };
    let tile = tracer::render_tile(&world, 0, rect);
    let small = [(w / 2, h / 2, 1, 1), (w - 2, 0, 2, 1), (1, 1, 0, 3)]
        .into_iter()
        .map(|(x, y, w, h)| {
            let out = tracer::render_tile(&world, 0, Rect { x, y, w, h });
            (bits(&out), out.cost, out.stats)
        })
        .collect();
    let rendered = Rendered {
        bits: bits(&out),
        stats: out.stats,
        cost: out.cost,
        tile_bits: bits(&tile),
        tile_cost: tile.cost,
        tile_stats: tile.stats,
        small,
    };
    (rendered, fits)
}

/// Renders `scene` both ways and holds them to each other; returns whether the lanes ran.
fn same_both_ways(label: &str, scene: Scene, camera_rays: CameraRays) -> bool {
    let (lanes, fits) = render(scene.clone(), PathLanes::Lanes, camera_rays);
    let (one_by_one, _) = render(scene, PathLanes::OneByOne, camera_rays);
    assert!(
        lanes.bits.iter().any(|&b| f32::from_bits(b) > 0.0),
        "{label}: black"
    );
    let differing = lanes
        .bits
        .iter()
        .zip(&one_by_one.bits)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differing, 0, "{label}: {differing} channels differ");
    assert_eq!(lanes.stats, one_by_one.stats, "{label}: other work counted");
    assert_eq!(
        lanes, one_by_one,
        "{label}: the cost map or the tile differ"
    );
    fits
}

#[test]
fn lanes_render_the_same_bits_at_every_scale_distance_depth_and_sample_count() {
    let shifts = [
        (1.0, glam::Vec3::ZERO),
        (1e-3, glam::Vec3::ZERO),
        (1e3, glam::Vec3::ZERO),
        (1.0, glam::Vec3::new(1e4, -2e4, 5e3)),
        (0.01, glam::Vec3::new(-300.0, 40.0, 1e3)),
        (50.0, glam::Vec3::new(3e5, 0.0, -3e5)),
    ];
    // A rough metal's roughnesses, from below the least the lobe takes (clamped to it) to
    // the roughest, a different one at each place.
    let alphas = [1e-6, 1e-3, 0.05, 0.3, 0.7, 1.0];
    for (place, (scale, shift)) in shifts.into_iter().enumerate() {
        for (size, spp, depth, roulette) in [
            (24, 5, Some(7), Some(3)),
            (12, 1, Some(5), Some(2)),
            (16, 13, Some(1), Some(3)),
            (16, 8, Some(0), Some(3)),
            // Paths that end at their first surface: one lane takes every pixel of the tile
            // while the others hold the first pixel's first samples, whose later ones come
            // back early.
            (16, 13, Some(0), Some(3)),
            (16, 3, None, Some(1)),
            // No Russian roulette: paths end at the depth cap or where nothing comes back.
            (16, 4, Some(6), None),
        ] {
            let mut scene = placed(cornell_box(), scale, shift);
            scene.settings.width = size;
            scene.settings.height = size;
            scene.settings.samples_per_pixel = spp;
            scene.settings.max_depth = depth;
            scene.settings.russian_roulette_depth = roulette;
            let label = format!("scale {scale}, shift {shift}, {spp} spp, depth {depth:?}");
            let fits = same_both_ways(&label, scene.clone(), CameraRays::Packets);
            assert!(fits, "{label}: the lanes did not run");
            // The tall box a mirror and the short one glass, on paths long and unlimited.
            if depth.is_none_or(|depth| depth >= 5) {
                let mirrored = format!("{label}, a mirror and glass");
                let fits = same_both_ways(
                    &mirrored,
                    with_a_mirror_and_glass(scene.clone()),
                    CameraRays::Packets,
                );
                assert!(fits, "{mirrored}: the lanes did not run");
                // The mirror a rough metal, and a point light beside the lamp and alone, in
                // the room and on its ceiling.
                let metals = [
                    (alphas[place], true, false),
                    (alphas[(place + 3) % 6], false, false),
                    (alphas[(place + 1) % 6], true, true),
                ];
                // The short box (glass) and the lamp moving, the tall box a metal, a point
                // light beside them; and the box alone moving under the still lamp.
                for moved in [&["shortBox", "light"][..], &["shortBox"][..]] {
                    let label = format!("{label}, moving {moved:?}");
                    let metal = with_metal_and_a_point_light(scene.clone(), 0.3, true, false);
                    let scene = with_moving(metal, moved);
                    let fits = same_both_ways(&label, scene, CameraRays::Packets);
                    assert!(fits, "{label}: the lanes did not run");
                }
                // The motion shows: the box and the lamp moving change the picture.
                if place == 0 && spp == 5 {
                    let still = with_metal_and_a_point_light(scene.clone(), 0.3, true, false);
                    let moving = with_moving(still.clone(), &["shortBox", "light"]);
                    let image = |scene| common::render_world(&World::prepare(scene, None), 0);
                    assert_ne!(
                        image(still).pixels,
                        image(moving).pixels,
                        "the motion shows"
                    );
                }
                // Every triangle of both boxes and the lamp its own moving object: more than a
                // path places as it starts (sixteen); and of the short box and the lamp alone:
                // more than the flat list holds (eight), placed as each path starts (the
                // lanes' moments written over path after path) and found through the tree,
                // which asks the moment's time. The shutter opens half a frame before the
                // first key, so that the paths' times fall in two keyframe segments, the
                // objects held still in the first and moving in the second.
                if spp == 5 {
                    for (moved, many) in [
                        (&["shortBox", "tallBox", "light"][..], 17..usize::MAX),
                        (&["shortBox", "light"][..], 9..17),
                    ] {
                        let label = format!("{label}, {moved:?} moving apart");
                        let mut scene = with_moving_objects(scene.clone(), moved, true);
                        scene.shutter = tracer::scene::Shutter {
                            open: -0.5,
                            close: 0.5,
                        };
                        let count = scene.moving.len();
                        assert!(many.contains(&count), "{label}: {count} objects");
                        let fits = same_both_ways(&label, scene, CameraRays::Packets);
                        assert!(fits, "{label}: the lanes did not run");
                    }
                }
                for (alpha, lamp, on_ceiling) in metals {
                    let label = format!(
                        "{label}, metal of roughness {alpha}, lamp {lamp}, on the ceiling \
                         {on_ceiling}"
                    );
                    let scene =
                        with_metal_and_a_point_light(scene.clone(), alpha, lamp, on_ceiling);
                    let fits = same_both_ways(&label, scene, CameraRays::Packets);
                    assert!(fits, "{label}: the lanes did not run");
                }
            }
        }
    }
    let mut scene = cornell_box();
    scene.settings.width = 16;
    scene.settings.height = 16;
    scene.settings.samples_per_pixel = 6;
    assert!(same_both_ways(
        "camera rays one by one",
        scene,
        CameraRays::OneByOne
    ));
}

/// A floor with texture coordinates, shading normals and a checker texture, a box, a lamp
/// facing down and a constant sky, written into `dir`; the scene file's path.
fn textured_room_under_a_sky(dir: &Path) -> std::path::PathBuf {
    let checker = image::RgbImage::from_fn(4, 4, |x, y| {
        if (x + y) % 2 == 0 {
            image::Rgb([230, 200, 40])
        } else {
            image::Rgb([20, 60, 200])
        }
    });
    checker
        .save(dir.join("checker.png"))
        .expect("the texture is written");
    let obj = "mtllib room.mtl
v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2
vt 0 0\nvt 3 0\nvt 3 3\nvt 0 3
vn 0.2 1 0\nvn -0.2 1 0.1\nvn 0 1 -0.3\nvn 0.1 1 0.2
usemtl checker
f 1/1/1 4/4/4 3/3/3 2/2/2
v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0.5 0 0.5\nv -0.5 0 0.5
v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5
usemtl grey
f 9 10 11 12\nf 5 6 10 9\nf 6 7 11 10\nf 7 8 12 11\nf 8 5 9 12
v -0.5 2.5 -0.5\nv 0.5 2.5 -0.5\nv 0.5 2.5 0.5\nv -0.5 2.5 0.5
usemtl lamp
f 13 14 15 16
";
    let mtl = "newmtl checker\nKd 0.8 0.8 0.8\nmap_Kd checker.png\n\
               newmtl grey\nKd 0.5 0.4 0.3\n\
               newmtl lamp\nKd 0 0 0\nKe 6 6 6\n";
    let toml = "[render]\nwidth = 20\nheight = 20\nspp = 7\nmax_depth = 6\n\
                [camera]\nposition = [0.3, 2, 5]\nlook_at = [0, 0.5, 0]\nvfov = 50\n\
                [environment]\nradiance = 0.4\n\
                [[object]]\nobj = \"room.obj\"\n";
    for (name, text) in [("room.obj", obj), ("room.mtl", mtl), ("room.toml", toml)] {
        std::fs::write(dir.join(name), text).expect("the scene's files are written");
    }
    dir.join("room.toml")
}

/// The textured room's scene file `text` with the whole room moving (its textured floor with
/// its shading normals, its box and its lamp turning and sliding while the shutter is open), as
/// one object.
fn moving_room(text: &str) -> String {
    let moving = text.replace("vfov = 50\n", "vfov = 50\nshutter = [0, 1]\n")
        + "[[object.keys]]\nframe = 0\n\
           [[object.keys]]\nframe = 1\nrotate_y = 35\nrotate_z = 8\ntranslate = [0.4, 0.1, -0.3]\n";
    assert!(moving.contains("shutter"), "the shutter opened");
    moving
}

/// The MTL lines of a tinted mirror, of glass (index 1.33) and of a rough metal (roughness
/// 0.2), for [`box_as`].
const MIRROR: &str = "illum 5\nKs 0.9 0.8 0.7";
const GLASS: &str = "illum 4\nNi 1.33\nKd 0.5 0.4 0.3";
const METAL: &str = "Kd 0.1\nKs 0.9 0.6 0.2\nNs 48";

/// A point light's lines in a scene file, to follow the room's own.
const POINT_LIGHT: &str =
    "[[light]]\ntype = \"point\"\nposition = [0.8, 1.8, 1.2]\nintensity = 2\n";

/// The textured room's materials (`materials`, its MTL file's text) with its grey box's
/// lines replaced by `lines`.
fn box_as(materials: &str, lines: &str) -> String {
    let changed = materials.replace(
        "newmtl grey\nKd 0.5 0.4 0.3",
        &format!("newmtl grey\n{lines}"),
    );
    assert_ne!(changed, materials, "the box changed");
    changed
}

#[test]
fn lanes_render_the_same_bits_with_textures_shading_normals_and_a_sky() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = textured_room_under_a_sky(dir.path());
    let scene = tracer::scene::load(&path).expect("the textured room loads");
    assert!(
        !scene.textures.is_empty() && scene.has_shading_normals() && scene.environment.is_some()
    );
    for spp in [7, 16] {
        let mut scene = scene.clone();
        scene.settings.samples_per_pixel = spp;
        assert!(same_both_ways("textured room", scene, CameraRays::Packets));
    }
    // Its box a mirror, then glass, beside the textured floor.
    let mtl = dir.path().join("room.mtl");
    let materials = std::fs::read_to_string(&mtl).expect("the room's materials");
    let (mirrored, glass) = (box_as(&materials, MIRROR), box_as(&materials, GLASS));
    let metal = box_as(&materials, METAL);
    let text = std::fs::read_to_string(&path).expect("the room's scene file");
    let moving = moving_room(&text);
    let variants = [
        ("a mirror", mirrored, text.clone()),
        ("glass", glass, text.clone()),
        (
            "a rough metal and a point light",
            metal.clone(),
            format!("{text}{POINT_LIGHT}"),
        ),
        ("moving, a rough metal", metal, moving),
    ];
    for (label, materials, text) in variants {
        std::fs::write(&mtl, materials).expect("the materials are written");
        std::fs::write(&path, text).expect("the scene file is written");
        let scene = tracer::scene::load(&path).expect("the room with its box changed loads");
        let label = format!("textured room, {label}");
        assert!(
            same_both_ways(&label, scene, CameraRays::Packets),
            "{label}"
        );
    }
}

/// The textured room under the shipped sky map (`scenes/fog-window/sky.exr`, turned and
/// tinted), with its lamp (the choice between the lamp and the map) and without it (the map
/// alone, and so with its box a mirror): each a world the lanes take, drawing the map's
/// samples lane by lane, with the scalar path's bits; a portal over the room takes the map
/// out of the lanes, whose shading has no second sample through it.
#[test]
fn lanes_render_the_same_bits_under_an_environment_map_with_a_lamp_and_without() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = textured_room_under_a_sky(dir.path());
    // Beside the scene file: a scene names its files inside its own tree.
    let sky = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/fog-window/sky.exr");
    std::fs::copy(&sky, dir.path().join("sky.exr")).expect("the sky map is copied");
    let text = std::fs::read_to_string(&path).expect("the room's scene file");
    let mapped = text.replace(
        "radiance = 0.4",
        "map = \"sky.exr\"\nrotate = 30\nscale = [1.0, 0.9, 0.8]",
    );
    assert_ne!(mapped, text, "the room's sky became the map");
    let mapped_moving = moving_room(&mapped);
    let portal = mapped.replace(
        "scale = [1.0, 0.9, 0.8]",
        "scale = [1.0, 0.9, 0.8]\nportals = [[[-3, 3, -3], [3, 3, -3], [3, 3, 3], [-3, 3, 3]]]",
    );
    let two_portals = mapped.replace(
        "scale = [1.0, 0.9, 0.8]",
        "scale = [1.0, 0.9, 0.8]\nportals = [[[-3, 3, -3], [0, 3, -3], [0, 3, 3], [-3, 3, 3]], \
         [[0, 3, -3], [3, 3, -3], [3, 3, 3], [0, 3, 3]]]",
    );
    let two_portals_moving = moving_room(&two_portals);
    let mtl = dir.path().join("room.mtl");
    let lit = std::fs::read_to_string(&mtl).expect("the room's materials");
    // The lamp's emission is in the materials: left out, the map is the one light.
    let dark = lit.replace("Ke 6 6 6", "Ke 0 0 0");
    assert_ne!(dark, lit, "the lamp went dark");
    let mirrored = box_as(&dark, MIRROR);
    let metal = box_as(&dark, METAL);
    let with_point = format!("{mapped}{POINT_LIGHT}");
    let variants = [
        ("map and lamp", &mapped, &lit, true),
        ("map and lamp, the room moving", &mapped_moving, &lit, true),
        ("map alone", &mapped, &dark, true),
        ("map alone, a mirror", &mapped, &mirrored, true),
        (
            "map, a point light, a rough metal",
            &with_point,
            &metal,
            true,
        ),
        ("map through a portal", &portal, &lit, true),
        ("map through two portals", &two_portals, &lit, true),
        (
            "map through two portals, the room moving",
            &two_portals_moving,
            &lit,
            true,
        ),
    ];
    for (label, text, materials, in_lanes) in variants {
        std::fs::write(&path, text).expect("the scene file is written");
        std::fs::write(&mtl, materials).expect("the materials are written");
        let scene = tracer::scene::load(&path).expect("the room under the map loads");
        assert!(
            matches!(
                scene.environment,
                Some(tracer::environment::Environment::Map(_))
            ),
            "{label}: a map"
        );
        let portals = ["two portals", "a portal"]
            .iter()
            .zip([2, 1])
            .find_map(|(name, n)| label.contains(name).then_some(n))
            .unwrap_or(0);
        assert_eq!(scene.portals.len(), portals, "{label}: its portals");
        for spp in [5, 16] {
            let mut scene = scene.clone();
            scene.settings.samples_per_pixel = spp;
            assert_eq!(
                same_both_ways(label, scene, CameraRays::Packets),
                in_lanes,
                "{label}: the lanes ran or not"
            );
        }
    }
}

/// `scene` under a constant sky seen through `portals`, rectangles given by three corners
/// (the fourth where they put it).
fn through_portals(mut scene: Scene, portals: &[[[f32; 3]; 3]]) -> Scene {
    use tracer::environment::{Environment, Portal};
    scene.environment = Some(Environment::Constant(glam::Vec3::new(0.5, 0.7, 1.0)));
    scene.portals = portals
        .iter()
        .map(|&[a, b, d]| {
            let [a, b, d] = [a, b, d].map(glam::Vec3::from);
            Portal::from_corners([a, b, b + d - a, d]).expect("a rectangle")
        })
        .collect();
    scene
}

/// The sky through portals: the room the shipped `window-room` is (a constant sky through its
/// window), the same room with its window as two portals side by side (their densities
/// averaged) and with a second portal where the wall has no opening (whose samples the wall
/// blocks), and the Cornell box open to the sky on its front, through a portal there, beside
/// its lamp: with a mirror and glass, a rough metal and a point light, its boxes and lamp
/// moving; at every scale and distance. The map through a portal is the environment map
/// test's.
#[test]
fn lanes_render_the_same_bits_through_portals_at_every_scale_and_distance() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let room = tracer::scene::load(&root.join("window-room/window-room.toml"))
        .expect("the shipped window room loads");
    assert_eq!(room.portals.len(), 1, "the window room has one portal");
    let window = [[0.0, 0.9, 2.0], [0.0, 2.6, 2.0], [0.0, 0.9, 4.2]];
    let halves = [
        [[0.0, 0.9, 2.0], [0.0, 2.6, 2.0], [0.0, 0.9, 3.1]],
        [[0.0, 0.9, 3.1], [0.0, 2.6, 3.1], [0.0, 0.9, 4.2]],
    ];
    let blind = [[4.0, 1.0, 1.0], [4.0, 2.0, 1.0], [4.0, 1.0, 3.0]];
    let front = [[0.0, 0.0, 0.0], [556.0, 0.0, 0.0], [0.0, 548.8, 0.0]];
    let open_box = || through_portals(cornell_box(), &[front]);
    let worlds = [
        ("the window room", through_portals(room.clone(), &[window])),
        (
            "the window as two portals",
            through_portals(room.clone(), &halves),
        ),
        (
            "a window and a blind portal",
            through_portals(room, &[window, blind]),
        ),
        (
            "the open box, a mirror and glass",
            with_a_mirror_and_glass(open_box()),
        ),
        (
            "the open box, a rough metal and a point light",
            with_metal_and_a_point_light(open_box(), 0.3, true, false),
        ),
        (
            "the open box, its boxes and lamp moving",
            with_moving(open_box(), &["shortBox", "tallBox", "light"]),
        ),
    ];
    let shifts = [
        (1.0, glam::Vec3::ZERO),
        (1e-3, glam::Vec3::new(0.5, -0.2, 0.1)),
        (1e3, glam::Vec3::ZERO),
        (0.01, glam::Vec3::new(-300.0, 40.0, 1e3)),
        (50.0, glam::Vec3::new(3e5, 0.0, -3e5)),
    ];
    for (name, world) in worlds {
        for (scale, shift) in shifts {
            let mut scene = placed(world.clone(), scale, shift);
            scene.settings.width = 16;
            scene.settings.height = 12;
            scene.settings.samples_per_pixel = 5;
            let label = format!("{name}, scale {scale}, shift {shift}");
            assert!(
                same_both_ways(&label, scene, CameraRays::Packets),
                "{label}: the lanes did not run"
            );
        }
    }
}

#[test]
fn worlds_the_lanes_do_not_fit_render_one_by_one() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let load = |name: &str| {
        tracer::scene::load(&root.join(format!("{name}/{name}.toml")))
            .expect("a shipped scene loads")
    };
    for (label, mut scene) in [
        ("fog", load("fog-window")),
        ("a dispersive prism", load("prism")),
    ] {
        scene.settings.width = 12;
        scene.settings.height = 12;
        scene.settings.samples_per_pixel = 4;
        assert!(
            !same_both_ways(label, scene, CameraRays::Packets),
            "{label}: the lanes ran"
        );
    }
    let mut world = World::prepare(cornell_box(), None);
    assert!(world.lanes_fit());
    world.paths = PathLanes::OneByOne;
    assert!(!world.lanes_fit(), "the knob turns the lanes off");
}

/// The shipped scenes with rough metal, point lights or no Russian roulette: the README's
/// scene (glass, mirrors and a metal under a sky and a point light), a point light at the
/// camera inside a sphere (every shading point a unit from it), and the furnace (paths to
/// their depth cap).
#[test]
fn shipped_scenes_with_metal_point_lights_or_no_roulette_render_the_same_bits_in_lanes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for name in [
        "glass-cluster-pan",
        "point-in-sphere",
        "furnace",
        "cornell-blur",
        "swinging-lamp",
    ] {
        let path = root.join(format!("{name}/{name}.toml"));
        let mut scene = tracer::scene::load(&path).expect("a shipped scene loads");
        scene.settings.width = 24;
        scene.settings.height = 24;
        scene.settings.samples_per_pixel = 5;
        assert!(
            same_both_ways(name, scene, CameraRays::Packets),
            "{name}: the lanes did not run"
        );
    }
}

#[test]
fn shared_scenes_render_the_same_bits_in_lanes_when_present() {
    // The Cornell bunny (69k triangles, diffuse, one light), Sponza (textures, the sky
    // alone), the Stanford bunny under a sky map, and the Cornell box with a mirror, with
    // water and with a glass sphere. Their files live in ../shared/scenes, outside the
    // repository; without them there is nothing to render.
    for name in [
        "cornell-bunny",
        "sponza",
        "stanford-bunny-sky",
        "cornell-box-mirror",
        "cornell-box-water",
        "cornell-box-sphere",
    ] {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/shared/{name}.toml"));
        let Ok(mut scene) = tracer::scene::load(&path) else {
            eprintln!("skipped: {} or its files are absent", path.display());
            continue;
        };
        scene.settings.width = 32;
        scene.settings.height = 32;
        scene.settings.samples_per_pixel = 9;
        assert!(same_both_ways(name, scene, CameraRays::Packets));
    }
}
