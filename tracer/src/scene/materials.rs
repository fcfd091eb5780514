//! The scene's material, texture and medium tables.
//!
//! Media (`[media.NAME]`) enter the same way, when a material's `medium` or `outside_medium`
//! key or the camera's `medium` first names them (`media.rs`), and a table that nothing uses is
//! an error.
//!
//! Materials come from two places: `[materials.NAME]` tables of the TOML and `newmtl` blocks of
//! MTL files. A TOML table replaces every MTL material of the same name, which is how a scene
//! fixes an exported material without editing the data. Each material and texture enters the
//! scene once, when first used, so the tables hold only what triangles reference, in first-use
//! order.
//!
//! Indices of refraction nest as media do: a glass's `outside_ior` is the index of what
//! surrounds it (the enclosing glass's `ior`; 1, vacuum or air, when left out), and its BSDF
//! works with the relative index, `ior / outside_ior`, since refraction and Fresnel reflection
//! depend on nothing else; a relative index outside [`crate::material::RELATIVE_IOR`] is
//! refused. Both outside keys, given or left out, are held against the geometry once the
//! objects are placed (`nesting.rs`): a glass whose outside contradicts what encloses it is
//! refused.

use super::Texture;
use super::error::{SceneError, line_of};
use super::files::FileLog;
use super::format::{MaterialKind, MaterialSpec, MediumSpec};
use super::media::MediumTable;
use super::mtl::MtlMaterial;
use super::nesting::Indices;
use crate::material::{Bsdf, Material, check_relative_ior};
use glam::Vec3;
use std::collections::{BTreeMap, BTreeSet};
use toml::Spanned;

pub(crate) struct MaterialTable<'a> {
    /// The TOML file's name and text, for the lines of its material tables.
    toml: &'a str,
    text: &'a str,
    defined: &'a BTreeMap<Spanned<String>, MaterialSpec>,
    used_defined: BTreeSet<String>,
    pub materials: Vec<Material>,
    /// Each material's indices of refraction on its two sides, where it is a boundary (glass
    /// or interface): what `nesting::check` holds against the geometry.
    pub indices: Vec<Option<Indices>>,
    ids: BTreeMap<MaterialKey, u32>,
    /// The materials whose `outside_medium` the TOML names; every other material's outside is
    /// the camera's medium ([`MaterialTable::place_outside`]).
    outside_named: BTreeSet<u32>,
    pub textures: Vec<Texture>,
    /// Decoded textures by path relative to the scene's folder.
    texture_ids: BTreeMap<String, u32>,
    /// The media that materials (and the camera) bind.
    pub media: MediumTable<'a>,
}

/// Materials are shared by identity: a TOML material by name, an MTL material by file and name.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum MaterialKey {
    Toml(String),
    Mtl { file: String, name: String },
}

impl<'a> MaterialTable<'a> {
    pub(crate) fn new(
        toml: &'a str,
        text: &'a str,
        defined: &'a BTreeMap<Spanned<String>, MaterialSpec>,
        media: &'a BTreeMap<Spanned<String>, MediumSpec>,
    ) -> Self {
        MaterialTable {
            media: MediumTable::new(toml, text, media),
            toml,
            text,
            defined,
            used_defined: BTreeSet::new(),
            materials: Vec::new(),
            indices: Vec::new(),
            ids: BTreeMap::new(),
            outside_named: BTreeSet::new(),
            textures: Vec::new(),
            texture_ids: BTreeMap::new(),
        }
    }

    /// The id of the TOML material `name`, referenced where `name`'s span says.
    pub(crate) fn toml_material(
        &mut self,
        log: &mut FileLog,
        name: &Spanned<String>,
    ) -> Result<u32, SceneError> {
        let key = MaterialKey::Toml(name.get_ref().clone());
        if let Some(&id) = self.ids.get(&key) {
            return Ok(id);
        }
        let defined = self.defined;
        let Some((definition, spec)) = defined.get_key_value(name.get_ref().as_str()) else {
            let line = line_of(self.text, name.span().start);
            let name = name.get_ref();
            let detail =
                format!("material `{name}` is not defined: add a [materials.{name}] table");
            return Err(SceneError::at_line(self.toml, line, detail));
        };
        let (material, indices) = self.define(log, definition, spec)?;
        self.used_defined.insert(name.get_ref().clone());
        let id = self.add(key, material, indices);
        if spec.outside_medium.is_some() {
            self.outside_named.insert(id);
        }
        Ok(id)
    }

    /// The id of an MTL material, or of the TOML material that replaces it.
    pub(crate) fn mtl_material(
        &mut self,
        log: &mut FileLog,
        m: &MtlMaterial,
    ) -> Result<u32, SceneError> {
        let defined = self.defined;
        if let Some((name, _)) = defined.get_key_value(m.name.as_str()) {
            return self.toml_material(log, name);
        }
        let key = MaterialKey::Mtl {
            file: m.file.clone(),
            name: m.name.clone(),
        };
        if let Some(&id) = self.ids.get(&key) {
            return Ok(id);
        }
        let material =
            m.to_material(|texture, line| self.texture(log, (&m.file, line), texture))?;
        // MTL glass has air outside, so its relative index is its own.
        let indices = Indices::of(&material.bsdf);
        Ok(self.add(key, material, indices))
    }

    /// Whether the TOML defines a material `name`.
    pub(crate) fn defines(&self, name: &str) -> bool {
        self.defined.contains_key(name)
    }

    /// A TOML material table that nothing used: most likely a misspelt name.
    pub(crate) fn unused_definition(&self) -> Option<SceneError> {
        unused_table(
            self.toml,
            self.text,
            self.defined,
            &self.used_defined,
            |name| format!("[materials.{name}] matches no MTL material and no object uses it"),
        )
    }

    /// Gives every material whose TOML does not name its `outside_medium` (MTL materials
    /// among them) the camera's medium `camera_medium` outside: the one outside medium that
    /// objects held before media could nest, so scenes without the key keep their meaning.
    pub(crate) fn place_outside(&mut self, camera_medium: Option<u32>) {
        for (id, material) in (0u32..).zip(&mut self.materials) {
            if !self.outside_named.contains(&id) {
                material.exterior = camera_medium;
            }
        }
    }

    /// Where material `id` is defined, for messages about it: its `[materials.NAME]` table's
    /// file and line, or the MTL file it came from.
    pub(crate) fn place(&self, id: u32) -> (&str, Option<usize>) {
        let name = self.materials[id as usize].name.as_str();
        if let Some((table, _)) = self.defined.get_key_value(name) {
            return (self.toml, Some(line_of(self.text, table.span().start)));
        }
        let file = self.ids.iter().find_map(|(key, &i)| match key {
            MaterialKey::Mtl { file, .. } if i == id => Some(file.as_str()),
            _ => None,
        });
        (file.unwrap_or(self.toml), None)
    }

    fn add(&mut self, key: MaterialKey, material: Material, indices: Option<Indices>) -> u32 {
        let id = self.materials.len() as u32;
        self.materials.push(material);
        self.indices.push(indices);
        self.ids.insert(key, id);
        id
    }

    /// The material a `[materials.NAME]` table defines, with its indices of refraction on
    /// both sides where it is a boundary.
    fn define(
        &mut self,
        log: &mut FileLog,
        name: &Spanned<String>,
        spec: &MaterialSpec,
    ) -> Result<(Material, Option<Indices>), SceneError> {
        let line = line_of(self.text, name.span().start);
        let err = |detail: &str| {
            let detail = format!("[materials.{}]: {detail}", name.get_ref());
            SceneError::at_line(self.toml, line, detail)
        };
        let Some(kind) = spec.kind else {
            return Err(err(
                "needs `type` (diffuse, mirror, glass, metal, emissive or interface)",
            ));
        };
        let (type_name, allowed): (&str, &[&str]) = match kind {
            MaterialKind::Diffuse => ("diffuse", &["albedo", "texture", "emission"]),
            MaterialKind::Mirror => ("mirror", &["reflectance", "emission"]),
            MaterialKind::Glass => (
                "glass",
                &[
                    "ior",
                    "outside_ior",
                    "cauchy",
                    "sellmeier",
                    "glass",
                    "tint",
                    "medium",
                    "outside_medium",
                    "emission",
                ],
            ),
            MaterialKind::Metal => ("metal", &["reflectance", "roughness", "emission"]),
            MaterialKind::Emissive => ("emissive", &["albedo", "emission"]),
            MaterialKind::Interface => ("interface", &["medium", "outside_medium"]),
        };
        let given = [
            ("albedo", spec.albedo.is_some()),
            ("texture", spec.texture.is_some()),
            ("reflectance", spec.reflectance.is_some()),
            ("ior", spec.ior.is_some()),
            ("outside_ior", spec.outside_ior.is_some()),
            ("cauchy", spec.cauchy.is_some()),
            ("sellmeier", spec.sellmeier.is_some()),
            ("glass", spec.glass.is_some()),
            ("tint", spec.tint.is_some()),
            ("roughness", spec.roughness.is_some()),
            ("medium", spec.medium.is_some()),
            ("outside_medium", spec.outside_medium.is_some()),
            ("emission", spec.emission.is_some()),
        ];
        if let Some((key, _)) = given
            .iter()
            .find(|(key, given)| *given && !allowed.contains(key))
        {
            return Err(err(&format!(
                "key `{key}` does not apply to type {type_name}"
            )));
        }
        let emission = spec.emission.map_or(Vec3::ZERO, |e| e.0);
        // A plain glass's indices on both sides, where its BSDF keeps only their ratio.
        let mut own_indices = None;
        let bsdf = match kind {
            MaterialKind::Diffuse => {
                let texture = match &spec.texture {
                    Some(t) => {
                        let at = (self.toml, line_of(self.text, t.span().start));
                        Some(self.texture(log, at, t.get_ref())?)
                    }
                    None => None,
                };
                Bsdf::Diffuse {
                    albedo: spec.albedo.map_or(Vec3::splat(0.8), |a| a.0),
                    texture,
                }
            }
            MaterialKind::Mirror => Bsdf::Mirror {
                reflectance: spec.reflectance.map_or(Vec3::ONE, |r| r.0),
            },
            MaterialKind::Glass => {
                let tint = spec.tint.map_or(Vec3::ONE, |t| t.0);
                // Vacuum (or air) outside when the key is left out.
                let outside_ior = spec.outside_ior.map_or(1.0, |i| i.0);
                let indices = [
                    ("ior", spec.ior.map(|_| None)),
                    ("cauchy", spec.cauchy.map(|c| Some(c.0))),
                    ("sellmeier", spec.sellmeier.map(|s| Some(s.0))),
                    ("glass", spec.glass.map(|g| Some(g.0))),
                ];
                let mut given = indices.iter().filter(|(_, v)| v.is_some());
                match (given.next(), given.next()) {
                    (Some((a, _)), Some((b, _))) => {
                        return Err(err(&format!(
                            "give one index (`ior`, `cauchy`, `sellmeier` or `glass`), not both `{a}` and `{b}`"
                        )));
                    }
                    (Some((key, Some(Some(dispersion)))), None) => {
                        let (low, high) = dispersion.index_range();
                        for n in [low, high] {
                            check_relative_ior(n / outside_ior).map_err(|e| {
                                err(&format!("`{key}` over `outside_ior` {e} (index {n})"))
                            })?;
                        }
                        Bsdf::DispersiveGlass {
                            dispersion: *dispersion,
                            outside_ior,
                            tint,
                        }
                    }
                    // The relative index, worked out once here so that the renderer divides
                    // nothing; over the default 1 it is `ior` itself, bit for bit. The glass's
                    // own index is kept for the nesting check, which the BSDF's would not serve.
                    _ => {
                        let ior = spec.ior.map_or(1.5, |i| i.0);
                        own_indices = Some(Indices {
                            inside: Some(ior),
                            outside: Some(outside_ior),
                        });
                        Bsdf::Dielectric {
                            ior: check_relative_ior(ior / outside_ior)
                                .map_err(|e| err(&format!("`ior` over `outside_ior` {e}")))?,
                            tint,
                        }
                    }
                }
            }
            MaterialKind::Metal => Bsdf::Conductor {
                f0: spec.reflectance.map_or(Vec3::splat(0.9), |r| r.0),
                alpha: spec.roughness.map_or(0.2, |r| r.0),
            },
            MaterialKind::Emissive if emission == Vec3::ZERO => {
                return Err(err("type emissive needs a non-zero `emission`"));
            }
            MaterialKind::Emissive => Bsdf::Diffuse {
                albedo: spec.albedo.map_or(Vec3::ZERO, |a| a.0),
                texture: None,
            },
            MaterialKind::Interface => Bsdf::Interface,
        };
        let mut medium = |key: &str, given: &Option<Spanned<String>>| match given {
            Some(medium) => {
                let key = format!("[materials.{}] `{key}`", name.get_ref());
                self.media.medium(&key, medium).map(Some)
            }
            None => Ok(None),
        };
        let interior = medium("medium", &spec.medium)?;
        // Left out, the outside is the camera's medium, which is resolved after the objects:
        // `MaterialTable::place_outside` fills it in then.
        let exterior = medium("outside_medium", &spec.outside_medium)?;
        let indices = own_indices.or_else(|| Indices::of(&bsdf));
        let material = Material {
            name: name.get_ref().clone(),
            bsdf,
            emission,
            interior,
            exterior,
        };
        Ok((material, indices))
    }

    /// Each texture's file (as the loader resolved it), in the order of `textures`.
    pub(super) fn texture_files(&self) -> Vec<String> {
        let mut files = vec![String::new(); self.textures.len()];
        for (path, &id) in &self.texture_ids {
            files[id as usize] = path.clone();
        }
        files
    }

    /// The index of the texture `reference`, named at `from` (file, line); decoded once.
    fn texture(
        &mut self,
        log: &mut FileLog,
        from: (&str, usize),
        reference: &str,
    ) -> Result<u32, SceneError> {
        let (path, bytes) = log.read(Some(from), reference)?;
        if let Some(&id) = self.texture_ids.get(&path) {
            return Ok(id);
        }
        let texture = decode_texture(&bytes)
            .map_err(|e| SceneError::image(&path, from, format!("cannot decode the image: {e}")))?;
        let id = self.textures.len() as u32;
        self.textures.push(texture);
        self.texture_ids.insert(path, id);
        Ok(id)
    }
}

/// Decodes a PNG or JPEG to its sRGB bytes, which [`Texture`] reads as linear RGB: colour
/// images store sRGB-encoded values, and shading needs linear reflectances. Alpha is ignored.
fn decode_texture(bytes: &[u8]) -> Result<Texture, image::ImageError> {
    let image = image::load_from_memory(bytes)?.into_rgb8();
    let (width, height) = (image.width(), image.height());
    Ok(Texture::from_srgb8(width, height, image.into_raw()))
}

/// The first table of `defined` whose name `used` lacks, as an error at its line saying
/// `message(name)`: a table nothing uses is most likely a misspelt name.
pub(super) fn unused_table<T>(
    toml: &str,
    text: &str,
    defined: &BTreeMap<Spanned<String>, T>,
    used: &BTreeSet<String>,
    message: impl Fn(&str) -> String,
) -> Option<SceneError> {
    let (name, _) = defined.iter().find(|(n, _)| !used.contains(n.get_ref()))?;
    let line = line_of(text, name.span().start);
    Some(SceneError::at_line(toml, line, message(name.get_ref())))
}
