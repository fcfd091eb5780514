//! Loading a scene: TOML, then each object's OBJ/MTL/texture files or procedural shape.
//!
//! Loading is sequential and ordered (objects in file order, materials and textures in first-use
//! order, files in first-read order), so the same files always give the same [`Scene`], bit for
//! bit, on every peer. Everything a TOML names is checked against what exists (materials, files,
//! shape keys) and reported with the TOML line of the reference.

use super::error::{SceneError, line_of};
use super::files::{DiskFiles, FileLog, MemoryFiles, SceneFiles};
use super::format::{self, ObjectSpec, SceneSpec};
use super::keys::{camera_track, key_pose, object_track, shutter};
use super::materials::MaterialTable;
use super::motion::{MovingObject, TransformTrack};
use super::nesting;
use super::obj::{self, NO_MATERIAL};
use super::report::{LoadReport, ObjectReport};
use super::shapes::{BOX_KEYS, QUAD_KEYS, SPHERE_KEYS, Transform, given_keys, shape_mesh};
use super::{CameraTrack, Mesh, PointLight, RenderSettings, Scene, Triangle, VertexAttributes};
use crate::environment::{Environment, EnvironmentMap, Portal, decode_exr};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use toml::Spanned;

/// Loads the scene file at `path` and everything it references from the disk. Error messages
/// name files by their full path.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_file_with_report(path).map(|(scene, _)| scene)
}

/// [`load`], also returning what the loader noticed ([`LoadReport`]).
pub fn load_file_with_report(path: &Path) -> Result<(Scene, LoadReport), SceneError> {
    let root = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let files = DiskFiles { root: root.clone() };
    load_with_report(&files, &name)
        .map_err(|e| e.rename_files(|f| root.join(f).display().to_string()))
}

/// Loads the scene file `toml_name` (a path within `files`) and everything it references.
pub fn load_from(files: &dyn SceneFiles, toml_name: &str) -> Result<Scene, SceneError> {
    load_with_report(files, toml_name).map(|(scene, _)| scene)
}

/// Loads a scene from TOML text alone (procedural shapes only), named `scene.toml` in errors.
pub fn load_str(toml: &str) -> Result<Scene, SceneError> {
    let mut files = MemoryFiles::new();
    files.insert("scene.toml", toml);
    load_from(&files, "scene.toml")
}

/// [`load_from`], also returning what was dropped.
pub fn load_with_report(
    files: &dyn SceneFiles,
    toml_name: &str,
) -> Result<(Scene, LoadReport), SceneError> {
    let mut log = FileLog::new(files, toml_name);
    let toml_file = toml_name.rsplit('/').next().unwrap_or(toml_name).to_owned();
    let (toml, bytes) = log.read(None, &toml_file)?;
    let text = std::str::from_utf8(&bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        SceneError::at_line(&toml, line, "not valid UTF-8 text")
    })?;
    let spec = format::parse(&toml, text)?;
    let camera = camera_track(&toml, text, &spec)?;
    let mut builder = Builder {
        log,
        toml: &toml,
        text,
        table: MaterialTable::new(&toml, text, &spec.materials, &spec.media),
        still: Mesh::default(),
        moving: Vec::new(),
        report: LoadReport::default(),
    };
    for object in &spec.objects {
        builder.object(object)?;
    }
    if builder.still.triangles.is_empty() && builder.moving.is_empty() {
        return Err(SceneError::in_file(&toml, "the scene has no triangles"));
    }
    if let Some(unused) = builder.table.unused_definition() {
        return Err(unused);
    }
    let camera_medium = match &spec.camera.get_ref().medium {
        Some(name) => Some(builder.table.media.medium("[camera] `medium`", name)?),
        None => None,
    };
    builder.table.place_outside(camera_medium);
    let table = &builder.table;
    if let Some(c) = nesting::check(
        &builder.still.triangles,
        &table.materials,
        &table.indices,
        camera_medium,
    ) {
        return Err(nesting::refusal(table, &c));
    }
    if let Some(unused) = builder.table.media.unused_definition() {
        return Err(unused);
    }
    let environment = environment(&mut builder.log, &toml, text, spec.environment.as_ref())?;
    let portals = portals(&toml, text, spec.environment.as_ref())?;
    let Builder {
        log,
        table,
        still,
        moving,
        mut report,
        ..
    } = builder;
    report.textures = table.texture_files();
    let scene = Scene {
        settings: render_settings(&spec, &camera, &moving),
        camera,
        shutter: shutter(&spec),
        triangles: still.triangles,
        attributes: still.attributes,
        moving,
        materials: table.materials,
        textures: table.textures,
        point_lights: spec.lights.iter().map(point_light).collect(),
        environment,
        portals,
        media: table.media.media,
        camera_medium,
        files: log.into_read(),
    };
    Ok((scene, report))
}

/// The scene under construction.
struct Builder<'a> {
    log: FileLog<'a>,
    toml: &'a str,
    text: &'a str,
    table: MaterialTable<'a>,
    /// The still objects' triangles and attributes, in world space.
    still: Mesh,
    moving: Vec<MovingObject>,
    report: LoadReport,
}

impl Builder<'_> {
    fn object(&mut self, spanned: &Spanned<ObjectSpec>) -> Result<(), SceneError> {
        let o = spanned.get_ref();
        let line = line_of(self.text, spanned.span().start);
        let err = |detail: String| SceneError::at_line(self.toml, line, detail);
        let (allowed, source) = match (&o.obj, o.shape) {
            (Some(_), Some(_)) => return Err(err("[[object]] has both `obj` and `shape`".into())),
            (None, None) => {
                return Err(err(
                    "[[object]] needs `obj = \"file.obj\"` or `shape = ...`".into(),
                ));
            }
            (Some(path), None) => (&[][..], path.get_ref().clone()),
            (None, Some(format::ShapeKind::Sphere)) => (SPHERE_KEYS, "sphere".to_owned()),
            (None, Some(format::ShapeKind::Quad)) => (QUAD_KEYS, "quad".to_owned()),
            (None, Some(format::ShapeKind::Box)) => (BOX_KEYS, "box".to_owned()),
        };
        if let Some(key) = given_keys(o).iter().find(|k| !allowed.contains(k)) {
            return Err(err(format!(
                "[[object]] key `{key}` does not apply to `{source}`"
            )));
        }
        let track = object_track(self.toml, self.text, o)?;
        let default_material = match &o.material {
            Some(name) => Some(self.table.toml_material(&mut self.log, name)?),
            None => None,
        };
        if let Some(path) = &o.obj {
            let at = (self.toml, line_of(self.text, path.span().start));
            let (resolved, bytes) = self.log.read(Some(at), path.get_ref())?;
            let defined = |name: &str| self.table.defines(name);
            let mesh = obj::load(&mut self.log, &resolved, bytes, &defined)?;
            return self.place_obj(o, track, resolved, mesh, default_material);
        }
        let kind = o
            .shape
            .expect("an object without `obj` has a `shape`: checked above");
        let Some(material) = default_material else {
            return Err(err(format!(
                "[[object]] `{source}` needs `material = \"name\"`"
            )));
        };
        let local = shape_mesh(kind, o, material).map_err(err)?;
        self.place(o, track, source, local).map_err(err)
    }

    fn place_obj(
        &mut self,
        o: &ObjectSpec,
        track: Option<TransformTrack>,
        path: String,
        mut mesh: obj::ObjMesh,
        default_material: Option<u32>,
    ) -> Result<(), SceneError> {
        if let (Some(line), None) = (mesh.first_face_without_material, default_material) {
            let detail = "face before any `usemtl`: give the scene's [[object]] a `material` for \
                          such faces";
            return Err(SceneError::at_line(&path, line, detail));
        }
        let used: BTreeSet<u32> = mesh.mesh.triangles.iter().map(|t| t.material).collect();
        let mut ids = BTreeMap::new();
        for local in used {
            let id = match local {
                // Faces before any `usemtl` were checked above to have a default.
                NO_MATERIAL => default_material
                    .ok_or_else(|| SceneError::in_file(&path, "faces without a material"))?,
                local => self
                    .table
                    .mtl_material(&mut self.log, &mesh.materials[local as usize])?,
            };
            ids.insert(local, id);
        }
        for t in &mut mesh.mesh.triangles {
            t.material = ids[&t.material];
        }
        self.place(o, track, path.clone(), mesh.mesh)
            .map_err(|detail| SceneError::in_file(&path, detail))
    }

    /// Transforms `local` triangles (and their attributes) into the scene, dropping zero-area
    /// ones; or, for an object that moves by `track`, keeps them in object space with it.
    fn place(
        &mut self,
        o: &ObjectSpec,
        track: Option<TransformTrack>,
        source: String,
        local: Mesh,
    ) -> Result<(), String> {
        // A still object with keys that all say the same stands at that pose, as if it had no
        // keys; a moving one is checked, and warned about, where its first key places it.
        let pose = match &track {
            Some(track) => track.keys()[0],
            None => key_pose(o, o.keys.first().map(|k| k.get_ref())),
        };
        let transform = Transform::new(pose.scale, pose.rotate_degrees, pose.translate);
        let moving = track.is_some();
        // The triangles kept, where they lie in `local`: a still object's moved into the world
        // in place, a moving one's left in object space, with its world copies (where the
        // first key places them) in `placed` for the distance check alone. A still mesh is then
        // never held twice: the dragon's 94 MB of triangles set the process's peak while
        // loading when each still object was copied into `kept` and again into `placed`.
        let Mesh {
            triangles: mut kept,
            mut attributes,
        } = local;
        let total = kept.len();
        let mut placed = Vec::new();
        let mut overflows = false;
        // Kept triangles move down to `next`, and their attributes (if any) beside them.
        let mut next = 0;
        for i in 0..total {
            let t = kept[i];
            let world = if transform.is_identity() {
                t
            } else {
                transform.apply(&t)
            };
            let area = world.area_vector().length_squared();
            overflows |= !area.is_finite();
            // A moving triangle must have area where it is modelled too: that is where rays
            // meet it.
            let keep = area > 0.0 && (!moving || t.area_vector().length_squared() > 0.0);
            if !keep {
                continue;
            }
            // `next <= i`: what is written there has been read already.
            if moving {
                placed.push(world);
                kept[next] = t;
            } else {
                kept[next] = world;
            }
            if let Some(&a) = attributes.get(i) {
                attributes[next] = if moving || transform.is_identity() {
                    a
                } else {
                    transform.apply_to_attributes(&a)
                };
            }
            next += 1;
        }
        kept.truncate(next);
        attributes.truncate(next);
        // Where no kept triangle has any (those that had were dropped, or a transform left
        // their normals no direction), the object has none: nothing to hold or prefetch.
        if attributes.iter().all(VertexAttributes::is_empty) {
            attributes = Vec::new();
        }
        if overflows {
            return Err("a triangle's area overflows 32-bit floats (coordinates too large)".into());
        }
        let degenerate = total - kept.len();
        let too_far = warn_if_too_far(&source, if moving { &placed } else { &kept });
        if degenerate > 0 {
            tracing::warn!("{source}: dropped {degenerate} zero-area triangles of {total}");
        }
        if kept.is_empty() {
            return Err(format!("{source}: every triangle has zero area"));
        }
        self.report.objects.push(ObjectReport {
            source,
            triangles: kept.len(),
            degenerate,
            moving,
            too_far,
        });
        match track {
            // A moving object may emit: light sampling places it at each path's time
            // (`lights.rs`).
            Some(track) => {
                self.moving.push(MovingObject {
                    triangles: kept,
                    attributes,
                    track,
                });
            }
            None => self.still.append(Mesh {
                triangles: kept,
                attributes,
            }),
        }
        Ok(())
    }
}

/// How far beyond its feature size an object may lie from the origin: 2^20, where a typical
/// edge spans 8 ULPs of its coordinates (an ULP at distance `d` is at most `2^-23 d`). Past it
/// rounding starts to fold the mesh, and spawn offsets (two or three ULPs) cross its sharp
/// creases; see `scenes/README.md` for what was measured.
pub const MAX_DISTANCE_PER_FEATURE: f32 = 1_048_576.0;

/// Warns, naming the object, when its median edge (each triangle's longest) is smaller than
/// `1 / MAX_DISTANCE_PER_FEATURE` of its farthest coordinate from the origin. The median rather
/// than the smallest: a few slivers do not make a mesh unrepresentable, most of it small does.
/// Returns the ratio when it warned.
fn warn_if_too_far(source: &str, triangles: &[Triangle]) -> Option<u64> {
    let distance = triangles
        .iter()
        .flat_map(|t| t.p)
        .map(|p| p.abs().max_element())
        .fold(0.0f32, f32::max);
    let mut edges: Vec<f32> = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.p;
            (b - a).length().max((c - b).length()).max((a - c).length())
        })
        .collect();
    if edges.is_empty() {
        return None;
    }
    let middle = edges.len() / 2;
    let (_, &mut median, _) = edges.select_nth_unstable_by(middle, f32::total_cmp);
    if median * MAX_DISTANCE_PER_FEATURE < distance {
        tracing::warn!(
            "{source}: its median edge ({median:e}) is {:.1e} times smaller than its distance from \
             the origin ({distance:e}), past the 2^20 that 32-bit floats keep closed meshes \
             representable at: expect light to leak (move the scene nearer the origin)",
            distance / median
        );
        return Some((distance / median).round() as u64);
    }
    None
}

/// The environment of `[environment]`: a constant radiance, or a map read through `log` (so it is
/// among the scene's files and ships to peers) and multiplied by its scale.
fn environment(
    log: &mut FileLog,
    file: &str,
    text: &str,
    spec: Option<&Spanned<format::EnvironmentSpec>>,
) -> Result<Option<Environment>, SceneError> {
    let Some(spanned) = spec else {
        return Ok(None);
    };
    let e = spanned.get_ref();
    let line = line_of(text, spanned.span().start);
    let err = |detail: &str| SceneError::at_line(file, line, format!("[environment]: {detail}"));
    let map = match (&e.radiance, &e.map) {
        (Some(radiance), None) => {
            if e.scale.is_some() || e.rotate.is_some() {
                return Err(err("`scale` and `rotate` apply to a `map` only"));
            }
            return Ok(Some(Environment::Constant(radiance.0)));
        }
        (None, Some(map)) => map,
        (Some(_), Some(_)) => return Err(err("give `radiance` or `map`, not both")),
        (None, None) => return Err(err("needs `radiance = ...` or `map = \"file.exr\"`")),
    };
    let at = (file, line_of(text, map.span().start));
    let (resolved, bytes) = log.read(Some(at), map.get_ref())?;
    let (width, height, mut texels) =
        decode_exr(&bytes).map_err(|detail| SceneError::image(&resolved, at, detail))?;
    if width == 0 || height == 0 {
        return Err(SceneError::image(&resolved, at, "the image has no texels"));
    }
    if let Some(scale) = e.scale {
        for t in &mut texels {
            *t *= scale.0;
        }
    }
    if texels
        .iter()
        .any(|t| !t.is_finite() || t.max_element() > super::MAX_RADIANCE)
    {
        return Err(err(&format!(
            "the map's texels (times `scale`) must be at most {:e}",
            super::MAX_RADIANCE
        )));
    }
    let rotate = e.rotate.map_or(0.0, |r| r.0);
    let map = EnvironmentMap::new(width, height, texels, rotate);
    Ok(Some(Environment::Map(map)))
}

/// The rectangles of `[environment] portals`; an error names the key's line and the portal.
fn portals(
    file: &str,
    text: &str,
    spec: Option<&Spanned<format::EnvironmentSpec>>,
) -> Result<Vec<Portal>, SceneError> {
    let Some(portals) = spec.and_then(|e| e.get_ref().portals.as_ref()) else {
        return Ok(Vec::new());
    };
    let line = line_of(text, portals.span().start);
    portals
        .get_ref()
        .iter()
        .enumerate()
        .map(|(i, corners)| {
            Portal::from_corners(corners.0).map_err(|detail| {
                let detail = format!("[environment] portals: portal {}: {detail}", i + 1);
                SceneError::at_line(file, line, detail)
            })
        })
        .collect()
}

fn point_light(l: &format::LightSpec) -> PointLight {
    match l.kind {
        format::LightKind::Point => PointLight {
            position: l.position.0,
            intensity: l.intensity.0,
        },
    }
}

fn render_settings(
    spec: &SceneSpec,
    camera: &CameraTrack,
    moving: &[MovingObject],
) -> RenderSettings {
    let r = &spec.render;
    let objects = moving.iter().filter_map(|o| o.track.keys().last());
    let last_key = camera
        .keys()
        .iter()
        .map(|k| k.frame)
        .chain(objects.map(|k| k.frame))
        .max()
        .unwrap_or(0);
    RenderSettings {
        width: r.width.0,
        height: r.height.0,
        samples_per_pixel: r.spp.0,
        max_depth: r.max_depth.value,
        russian_roulette_depth: r.russian_roulette_depth.value,
        seed: r.seed,
        frames: r.frames.map_or(last_key.saturating_add(1), |f| f.0),
        media: crate::medium::MediaSampling::default(),
    }
}
