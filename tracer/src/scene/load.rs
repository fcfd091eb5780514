//! Loading a scene: TOML, then each object's OBJ/MTL/texture files or procedural shape.
//!
//! Loading is sequential and ordered (objects in file order, materials in first-use order, files
//! in first-read order), so the same files always give the same [`Scene`], bit for bit, on every
//! peer. Everything a TOML names is checked against what exists (materials, files, shape keys)
//! with the TOML line of the reference.

use super::error::{SceneError, line_of};
use super::files::{DiskFiles, FileLog, MemoryFiles, SceneFiles};
use super::format::{self, MaterialKind, MaterialSpec, ObjectSpec, SceneSpec, ShapeKind};
use super::mtl::MtlMaterial;
use super::obj::{self, NO_MATERIAL};
use super::shapes::{self, Sphere, Transform};
use super::{Camera, CameraKey, CameraTrack, PointLight, RenderSettings, Scene, Texture, Triangle};
use crate::material::{Bsdf, Material};
use glam::Vec3;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use toml::Spanned;

/// What the loader noticed without rejecting the scene.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadReport {
    /// One entry per `[[object]]`, in file order.
    pub objects: Vec<ObjectReport>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjectReport {
    /// The OBJ file (relative to the scene's folder) or the shape's name (`"sphere"`, ...).
    pub source: String,
    /// Triangles kept.
    pub triangles: usize,
    /// Zero-area triangles dropped.
    pub degenerate: usize,
}

impl LoadReport {
    /// Zero-area triangles dropped over the whole scene.
    pub fn degenerate(&self) -> usize {
        self.objects.iter().map(|o| o.degenerate).sum()
    }
}

/// Loads the scene file at `path` and everything it references from the disk. Error messages
/// name files by their full path.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let root = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let files = DiskFiles { root: root.clone() };
    load_from(&files, &name).map_err(|e| e.rename_files(|f| root.join(f).display().to_string()))
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
pub fn load_with_report(files: &dyn SceneFiles, toml_name: &str) -> Result<(Scene, LoadReport), SceneError> {
    let mut log = FileLog::new(files, toml_name);
    let toml_file = toml_name.rsplit('/').next().unwrap_or(toml_name).to_owned();
    let (toml_path, bytes) = log.read(None, &toml_file)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| SceneError::at_line(&toml_path, line_of_utf8_error(&bytes, &e), "not valid UTF-8 text"))?;
    let spec = format::parse(&toml_path, text)?;
    let mut builder = Builder {
        log,
        toml: &toml_path,
        text,
        overrides: &spec.materials,
        used_overrides: BTreeSet::new(),
        materials: Vec::new(),
        material_ids: BTreeMap::new(),
        textures: Vec::new(),
        texture_ids: BTreeMap::new(),
        triangles: Vec::new(),
        report: LoadReport::default(),
    };
    for object in &spec.objects {
        builder.object(object)?;
    }
    if builder.triangles.is_empty() {
        return Err(SceneError::in_file(&toml_path, "the scene has no triangles"));
    }
    if let Some((name, _)) = spec.materials.iter().find(|(name, _)| !builder.used_overrides.contains(name.get_ref())) {
        let line = line_of(text, name.span().start);
        let detail = format!("[materials.{}] matches no MTL material and no object uses it", name.get_ref());
        return Err(SceneError::at_line(&toml_path, line, detail));
    }
    let camera = camera_track(&toml_path, text, &spec)?;
    let settings = render_settings(&spec, &camera);
    let Builder { log, materials, textures, triangles, report, .. } = builder;
    let scene = Scene {
        settings,
        camera,
        triangles,
        materials,
        textures,
        point_lights: spec.lights.iter().map(point_light).collect(),
        environment: spec.environment.map(|e| e.radiance.0),
        files: log.into_read(),
    };
    Ok((scene, report))
}

/// The scene under construction.
struct Builder<'a> {
    log: FileLog<'a>,
    toml: &'a str,
    text: &'a str,
    overrides: &'a BTreeMap<Spanned<String>, MaterialSpec>,
    used_overrides: BTreeSet<String>,
    materials: Vec<Material>,
    material_ids: BTreeMap<MaterialKey, u32>,
    textures: Vec<Texture>,
    /// Decoded textures by path relative to the scene's folder.
    texture_ids: BTreeMap<String, u32>,
    triangles: Vec<Triangle>,
    report: LoadReport,
}

/// Materials are shared by identity: a TOML material by name, an MTL material by file and name.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum MaterialKey {
    Toml(String),
    Mtl { file: String, name: String },
}

const SPHERE_KEYS: &[&str] = &["center", "radius", "subdivisions", "inward", "perturb", "seed", "smooth"];
const QUAD_KEYS: &[&str] = &["corners"];
const BOX_KEYS: &[&str] = &["min", "max", "inward"];

impl Builder<'_> {
    fn object(&mut self, spanned: &Spanned<ObjectSpec>) -> Result<(), SceneError> {
        let o = spanned.get_ref();
        let line = line_of(self.text, spanned.span().start);
        let err = |detail: String| SceneError::at_line(self.toml, line, detail);
        let given = given_keys(o);
        let (allowed, source) = match (&o.obj, o.shape) {
            (Some(_), Some(_)) => return Err(err("[[object]] has both `obj` and `shape`; give one".into())),
            (None, None) => return Err(err("[[object]] needs `obj = \"file.obj\"` or `shape = ...`".into())),
            (Some(path), None) => (&[][..], path.get_ref().clone()),
            (None, Some(ShapeKind::Sphere)) => (SPHERE_KEYS, "sphere".to_owned()),
            (None, Some(ShapeKind::Quad)) => (QUAD_KEYS, "quad".to_owned()),
            (None, Some(ShapeKind::Box)) => (BOX_KEYS, "box".to_owned()),
        };
        if let Some(key) = given.iter().find(|k| !allowed.contains(k)) {
            return Err(err(format!("[[object]] key `{key}` does not apply to `{source}`")));
        }
        let default_material = match &o.material {
            Some(name) => Some(self.toml_material(name)?),
            None => None,
        };
        let local = match (&o.obj, o.shape) {
            (Some(path), _) => {
                let path_line = line_of(self.text, path.span().start);
                let (resolved, bytes) = self.log.read(Some((self.toml, path_line)), path.get_ref())?;
                let mesh = obj::load(&mut self.log, &resolved, &bytes)?;
                return self.place_obj(o, resolved, mesh, default_material);
            }
            (None, Some(kind)) => {
                let material = default_material.ok_or_else(|| err(format!("[[object]] `{source}` needs `material = \"name\"`")))?;
                shape_triangles(kind, o, material).map_err(err)?
            }
            (None, None) => unreachable!("checked above"),
        };
        self.place(o, source, local).map_err(err)
    }

    fn place_obj(
        &mut self,
        o: &ObjectSpec,
        path: String,
        mut mesh: obj::ObjMesh,
        default_material: Option<u32>,
    ) -> Result<(), SceneError> {
        if let (Some(line), None) = (mesh.first_face_without_material, default_material) {
            let detail = "face before any `usemtl`: add `material = \"name\"` to the scene's [[object]] for such faces";
            return Err(SceneError::at_line(&path, line, detail));
        }
        let used: BTreeSet<u32> = mesh.triangles.iter().map(|t| t.material).collect();
        let mut ids = BTreeMap::new();
        for local in used {
            let id = match local {
                NO_MATERIAL => default_material.expect("checked above: faces without usemtl have a default"),
                local => self.mtl_material(&mesh.materials[local as usize])?,
            };
            ids.insert(local, id);
        }
        for t in &mut mesh.triangles {
            t.material = ids[&t.material];
        }
        self.place(o, path.clone(), mesh.triangles).map_err(|detail| SceneError::in_file(&path, detail))
    }

    /// Transforms `local` triangles into the scene, dropping zero-area ones.
    fn place(&mut self, o: &ObjectSpec, source: String, local: Vec<Triangle>) -> Result<(), String> {
        let transform = Transform::new(
            o.scale.map_or(Vec3::ONE, |s| s.0),
            Vec3::new(o.rotate_x.map_or(0.0, |r| r.0), o.rotate_y.map_or(0.0, |r| r.0), o.rotate_z.map_or(0.0, |r| r.0)),
            o.translate.map_or(Vec3::ZERO, |t| t.0),
        );
        let before = self.triangles.len();
        let mut degenerate = 0;
        for t in &local {
            let t = if transform.is_identity() { *t } else { transform.apply(t) };
            let area = t.area_vector().length_squared();
            if !area.is_finite() {
                return Err("a triangle's area overflows 32-bit floats (coordinates too large)".into());
            }
            if area > 0.0 {
                self.triangles.push(t);
            } else {
                degenerate += 1;
            }
        }
        let kept = self.triangles.len() - before;
        if degenerate > 0 {
            tracing::warn!("{source}: dropped {degenerate} zero-area triangles of {}", local.len());
        }
        if kept == 0 {
            return Err(format!("{source}: every triangle has zero area"));
        }
        self.report.objects.push(ObjectReport { source, triangles: kept, degenerate });
        Ok(())
    }

    /// The scene id of the TOML material `name` (referenced at `name`'s span).
    fn toml_material(&mut self, name: &Spanned<String>) -> Result<u32, SceneError> {
        let key = MaterialKey::Toml(name.get_ref().clone());
        if let Some(&id) = self.material_ids.get(&key) {
            return Ok(id);
        }
        let overrides = self.overrides;
        let Some((_, spec)) = overrides.get_key_value(name.get_ref().as_str()) else {
            let line = line_of(self.text, name.span().start);
            let detail = format!("material `{}` is not defined: add a [materials.{}] table", name.get_ref(), name.get_ref());
            return Err(SceneError::at_line(self.toml, line, detail));
        };
        let material = self.from_spec(name, spec)?;
        Ok(self.add(key, material))
    }

    /// The scene id of an MTL material, or of the TOML material that replaces it.
    fn mtl_material(&mut self, m: &MtlMaterial) -> Result<u32, SceneError> {
        let overrides = self.overrides;
        if let Some((name, _)) = overrides.get_key_value(m.name.as_str()) {
            return self.toml_material(name);
        }
        let key = MaterialKey::Mtl { file: m.file.clone(), name: m.name.clone() };
        if let Some(&id) = self.material_ids.get(&key) {
            return Ok(id);
        }
        let material = m.to_material(|texture, line| self.texture((m.file.as_str(), line), texture))?;
        Ok(self.add(key, material))
    }

    fn add(&mut self, key: MaterialKey, material: Material) -> u32 {
        if let MaterialKey::Toml(name) = &key {
            self.used_overrides.insert(name.clone());
        }
        let id = self.materials.len() as u32;
        self.materials.push(material);
        self.material_ids.insert(key, id);
        id
    }

    fn from_spec(&mut self, name: &Spanned<String>, spec: &MaterialSpec) -> Result<Material, SceneError> {
        let line = line_of(self.text, name.span().start);
        let err = |detail: String| SceneError::at_line(self.toml, line, format!("[materials.{}]: {detail}", name.get_ref()));
        let Some(kind) = spec.kind else {
            return Err(err("needs `type` (diffuse, mirror, glass, metal or emissive)".into()));
        };
        let allowed: &[&str] = match kind {
            MaterialKind::Diffuse => &["albedo", "texture"],
            MaterialKind::Mirror => &["reflectance"],
            MaterialKind::Glass => &["ior", "tint"],
            MaterialKind::Metal => &["reflectance", "roughness"],
            MaterialKind::Emissive => &["albedo"],
        };
        let given = [
            ("albedo", spec.albedo.is_some()),
            ("texture", spec.texture.is_some()),
            ("reflectance", spec.reflectance.is_some()),
            ("ior", spec.ior.is_some()),
            ("tint", spec.tint.is_some()),
            ("roughness", spec.roughness.is_some()),
        ];
        if let Some((key, _)) = given.iter().find(|(key, given)| *given && !allowed.contains(key)) {
            return Err(err(format!("key `{key}` does not apply to type {kind:?}").to_lowercase()));
        }
        let emission = spec.emission.map_or(Vec3::ZERO, |e| e.0);
        let bsdf = match kind {
            MaterialKind::Diffuse => {
                let texture = match &spec.texture {
                    Some(t) => Some(self.texture((self.toml, line_of(self.text, t.span().start)), t.get_ref())?),
                    None => None,
                };
                Bsdf::Diffuse { albedo: spec.albedo.map_or(Vec3::splat(0.8), |a| a.0), texture }
            }
            MaterialKind::Mirror => Bsdf::Mirror { reflectance: spec.reflectance.map_or(Vec3::ONE, |r| r.0) },
            MaterialKind::Glass => Bsdf::Dielectric {
                ior: spec.ior.map_or(1.5, |i| i.0),
                tint: spec.tint.map_or(Vec3::ONE, |t| t.0),
            },
            MaterialKind::Metal => Bsdf::Conductor {
                f0: spec.reflectance.map_or(Vec3::splat(0.9), |r| r.0),
                alpha: spec.roughness.map_or(0.2, |r| r.0),
            },
            MaterialKind::Emissive => {
                if emission == Vec3::ZERO {
                    return Err(err("type emissive needs a non-zero `emission`".into()));
                }
                Bsdf::Diffuse { albedo: spec.albedo.map_or(Vec3::ZERO, |a| a.0), texture: None }
            }
        };
        Ok(Material { name: name.get_ref().clone(), bsdf, emission })
    }

    /// The scene index of the texture `reference`, named at `from` (file, line); decoded once.
    fn texture(&mut self, from: (&str, usize), reference: &str) -> Result<u32, SceneError> {
        let (path, bytes) = self.log.read(Some(from), reference)?;
        if let Some(&id) = self.texture_ids.get(&path) {
            return Ok(id);
        }
        let texture = decode_texture(&bytes).map_err(|e| SceneError::in_file(&path, format!("cannot decode the image: {e}")))?;
        let id = self.textures.len() as u32;
        self.textures.push(texture);
        self.texture_ids.insert(path, id);
        Ok(id)
    }
}

/// The triangles of a procedural shape in object space; an error names the problem.
fn shape_triangles(kind: ShapeKind, o: &ObjectSpec, material: u32) -> Result<Vec<Triangle>, String> {
    Ok(match kind {
        ShapeKind::Sphere => {
            let subdivisions = o.subdivisions.unwrap_or(3);
            if subdivisions > 8 {
                return Err(format!("sphere `subdivisions` {subdivisions} is above 8 (20 * 4^8 triangles)"));
            }
            Sphere {
                center: o.center.map_or(Vec3::ZERO, |c| c.0),
                radius: o.radius.map_or(1.0, |r| r.0),
                subdivisions,
                inward: o.inward.unwrap_or(false),
                perturb: o.perturb.map_or(0.0, |p| p.0),
                seed: o.seed.unwrap_or(0),
                smooth: o.smooth.unwrap_or(true),
            }
            .triangles(material)
        }
        ShapeKind::Quad => {
            let corners = o.corners.ok_or("quad needs `corners` (4 points, counter-clockwise seen from the front)")?;
            shapes::quad(corners.map(|c| c.0), material)
        }
        ShapeKind::Box => {
            let (Some(min), Some(max)) = (o.min, o.max) else {
                return Err("box needs `min` and `max`".into());
            };
            if !min.0.cmplt(max.0).all() {
                return Err("box `min` must be below `max` in x, y and z".into());
            }
            shapes::cuboid(min.0, max.0, o.inward.unwrap_or(false), material)
        }
    })
}

/// The shape-specific keys an [[object]] table gives (transform keys and `material` apply to all).
fn given_keys(o: &ObjectSpec) -> Vec<&'static str> {
    let keys = [
        ("center", o.center.is_some()),
        ("radius", o.radius.is_some()),
        ("subdivisions", o.subdivisions.is_some()),
        ("inward", o.inward.is_some()),
        ("perturb", o.perturb.is_some()),
        ("seed", o.seed.is_some()),
        ("smooth", o.smooth.is_some()),
        ("corners", o.corners.is_some()),
        ("min", o.min.is_some()),
        ("max", o.max.is_some()),
    ];
    keys.into_iter().filter(|(_, given)| *given).map(|(key, _)| key).collect()
}

fn camera_track(file: &str, text: &str, spec: &SceneSpec) -> Result<CameraTrack, SceneError> {
    let c = spec.camera.get_ref();
    let camera_line = line_of(text, spec.camera.span().start);
    let pose = |line: usize, position: Option<format::Point>, look_at: Option<format::Point>, up: Option<format::Point>, vfov: Option<format::Fov>| {
        let err = |detail: &str| SceneError::at_line(file, line, format!("camera: {detail}"));
        let position = position.or(c.position).ok_or_else(|| err("needs `position`"))?.0;
        let look_at = look_at.or(c.look_at).ok_or_else(|| err("needs `look_at`"))?.0;
        let up = up.or(c.up).map_or(Vec3::Y, |u| u.0);
        let forward = look_at - position;
        if forward == Vec3::ZERO {
            return Err(err("`look_at` equals `position`"));
        }
        if forward.cross(up).length_squared() <= f32::MIN_POSITIVE || !forward.cross(up).is_finite() {
            return Err(err("`up` is zero or parallel to the view direction"));
        }
        let vfov_degrees = vfov.or(c.vfov).map_or(40.0, |v| v.0);
        Ok(Camera { position, look_at, up, vfov_degrees })
    };
    if c.keys.is_empty() {
        return Ok(CameraTrack::fixed(pose(camera_line, None, None, None, None)?));
    }
    let mut keys = Vec::with_capacity(c.keys.len());
    let mut frames = BTreeMap::new();
    for key in &c.keys {
        let k = key.get_ref();
        let line = line_of(text, key.span().start);
        if let Some(first) = frames.insert(k.frame, line) {
            let detail = format!("camera: two keys at frame {} (the other at line {first})", k.frame);
            return Err(SceneError::at_line(file, line, detail));
        }
        keys.push(CameraKey { frame: k.frame, camera: pose(line, k.position, k.look_at, k.up, k.vfov)? });
    }
    Ok(CameraTrack::new(keys).expect("keys are non-empty and their frames distinct: checked above"))
}

fn point_light(l: &format::LightSpec) -> PointLight {
    match l.kind {
        format::LightKind::Point => PointLight { position: l.position.0, intensity: l.intensity.0 },
    }
}

fn render_settings(spec: &SceneSpec, camera: &CameraTrack) -> RenderSettings {
    let r = &spec.render;
    let last_key = camera.keys().last().map_or(0, |k| k.frame);
    RenderSettings {
        width: r.width.0,
        height: r.height.0,
        samples_per_pixel: r.spp.0,
        max_depth: r.max_depth.value,
        russian_roulette_depth: r.russian_roulette_depth.value,
        seed: r.seed,
        frames: r.frames.map_or(last_key.saturating_add(1), |f| f.0),
    }
}

/// Decodes a PNG or JPEG to linear RGB (the files store sRGB-encoded values).
fn decode_texture(bytes: &[u8]) -> Result<Texture, image::ImageError> {
    let image = image::load_from_memory(bytes)?.into_rgb8();
    let to_linear: Vec<f32> = (0..=255u8)
        .map(|v| {
            let c = v as f32 / 255.0;
            if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
        })
        .collect();
    let texels = image.pixels().map(|p| Vec3::from(p.0.map(|c| to_linear[c as usize]))).collect();
    Ok(Texture { width: image.width(), height: image.height(), texels })
}

fn line_of_utf8_error(bytes: &[u8], e: &std::str::Utf8Error) -> usize {
    1 + bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count()
}
