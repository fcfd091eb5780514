//! A scene's still triangles as tessera loaded them, written out for another renderer: one
//! binary PLY file per object and material, and an index (`meshes.json`) saying which is which
//! and what each material is.
//!
//! The Mitsuba 3 comparison (`scripts/mitsuba_scene.py`) builds its scenes from these, so that
//! what the two renderers trace is defined once, by tessera's loader: the OBJ reading (fans,
//! texture coordinates, relative indices, dropped zero-area triangles), the procedural shapes'
//! tessellation and normals, and the objects' transforms. A script that read the OBJ files and
//! tessellated the spheres again would be a second loader to keep in step with the first.
//!
//! The files hold exactly the loader's floats: a vertex is a corner's position, with its
//! shading normal and texture coordinates where the triangle has them, and corners with the
//! same bits share one vertex, so a closed mesh stays closed for the other renderer too.

use crate::LabError;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use tracer::material::Bsdf;
use tracer::scene::{Triangle, VertexAttributes};

/// The index file [`write_meshes`] writes beside the meshes.
pub const INDEX_FILE: &str = "meshes.json";

/// One mesh file: the triangles of one still object that share a material (and whether they
/// carry normals and texture coordinates, which a PLY file has for every vertex or none).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeshFile {
    /// The object's place among the scene's `[[object]]` tables, from 0.
    pub object: usize,
    /// The object's OBJ file or shape name, as the loader reports it.
    pub source: String,
    /// The PLY file's name, within the folder written to.
    pub file: String,
    /// How many triangles it holds.
    pub triangles: usize,
    /// Whether its vertices carry shading normals (`nx`, `ny`, `nz`).
    pub normals: bool,
    /// Whether its vertices carry texture coordinates (`u`, `v`, with v = 0 at the image's
    /// bottom row, as tessera reads them).
    pub texcoords: bool,
    /// What its triangles are made of.
    pub material: MaterialDescription,
}

/// A material as tessera resolved it (scene table over MTL, MTL defaults filled in).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MaterialDescription {
    /// The material's name (the MTL's, or the scene table's).
    pub name: String,
    /// Radiance emitted from the front face; zeros where it is not a light.
    pub emission: [f32; 3],
    /// How it scatters.
    pub bsdf: BsdfDescription,
}

/// The scattering model of a [`MaterialDescription`], one variant per [`Bsdf`] variant.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum BsdfDescription {
    /// Lambertian; `texture` (a file relative to the scene's folder) multiplies `albedo`.
    Diffuse {
        /// The reflected share per channel.
        albedo: [f32; 3],
        /// The texture's file, where the material has one.
        texture: Option<String>,
    },
    /// A perfect mirror.
    Mirror {
        /// The reflected share per channel.
        reflectance: [f32; 3],
    },
    /// A rough conductor (GGX, Schlick's Fresnel).
    Conductor {
        /// Reflectance at normal incidence.
        f0: [f32; 3],
        /// The GGX width.
        alpha: f32,
    },
    /// Smooth glass of relative index `ior`.
    Glass {
        /// Inside over outside.
        ior: f32,
        /// The factor of each refraction.
        tint: [f32; 3],
    },
    /// Smooth glass whose index depends on the wavelength; `ior_d` is its index at the d line.
    DispersiveGlass {
        /// The glass's own index at 587.6 nm.
        ior_d: f32,
        /// The index of what surrounds it.
        outside_ior: f32,
        /// The factor of each refraction.
        tint: [f32; 3],
    },
    /// An index-matched boundary of a medium.
    Interface,
}

/// A group of an object's triangles: their material, and whether they have normals and
/// texture coordinates.
type GroupKey = (u32, bool, bool);

/// Loads `scene` and writes its still objects' triangles into the folder `out` (made if
/// missing), one PLY file per object and material, with the index [`INDEX_FILE`]; returns the
/// index. Moving objects are left out (their triangles are in object space, placed per time):
/// the index says so only by their absence, and a caller that needs them must refuse the scene.
pub fn write_meshes(scene: &Path, out: &Path) -> Result<Vec<MeshFile>, LabError> {
    let (loaded, report) = tracer::scene::load_file_with_report(scene)?;
    std::fs::create_dir_all(out).map_err(LabError::io("create", out))?;
    let mut index = Vec::new();
    for (object, range) in report.still_objects() {
        let source = &report.objects[object].source;
        // The object's triangles by material, then by the attributes they carry, each group
        // in the loader's order.
        let mut groups: BTreeMap<GroupKey, Vec<(&Triangle, VertexAttributes)>> = BTreeMap::new();
        for i in range {
            let t = &loaded.triangles[i];
            let a = loaded.attributes.get(i).copied().unwrap_or_default();
            let key = (t.material, a.n.is_some(), a.uv.is_some());
            groups.entry(key).or_default().push((t, a));
        }
        for ((material, normals, texcoords), group) in groups {
            let file = format!("object-{object}-{}.ply", index.len());
            let path = out.join(&file);
            let bytes = ply(&group, normals, texcoords);
            std::fs::write(&path, bytes).map_err(LabError::io("write", &path))?;
            let material = &loaded.materials[material as usize];
            index.push(MeshFile {
                object,
                source: source.clone(),
                file,
                triangles: group.len(),
                normals,
                texcoords,
                material: describe(material, &report.textures),
            });
        }
    }
    let path = out.join(INDEX_FILE);
    let json = serde_json::to_vec_pretty(&index)?;
    std::fs::write(&path, json).map_err(LabError::io("write", &path))?;
    Ok(index)
}

/// `material` as the index describes it; `textures` are the scene's texture files.
fn describe(material: &tracer::material::Material, textures: &[String]) -> MaterialDescription {
    let bsdf = match material.bsdf {
        Bsdf::Diffuse { albedo, texture } => BsdfDescription::Diffuse {
            albedo: albedo.into(),
            texture: texture.map(|t| textures[t as usize].clone()),
        },
        Bsdf::Mirror { reflectance } => BsdfDescription::Mirror {
            reflectance: reflectance.into(),
        },
        Bsdf::Conductor { f0, alpha } => BsdfDescription::Conductor {
            f0: f0.into(),
            alpha,
        },
        Bsdf::Dielectric { ior, tint } => BsdfDescription::Glass {
            ior,
            tint: tint.into(),
        },
        Bsdf::DispersiveGlass {
            dispersion,
            outside_ior,
            tint,
        } => BsdfDescription::DispersiveGlass {
            ior_d: dispersion.ior_d(),
            outside_ior,
            tint: tint.into(),
        },
        Bsdf::Interface => BsdfDescription::Interface,
    };
    MaterialDescription {
        name: material.name.clone(),
        emission: material.emission.into(),
        bsdf,
    }
}

/// The binary little-endian PLY file of `triangles`: vertices `x y z` (then `nx ny nz` where
/// `normals`, `u v` where `texcoords`) as 32-bit floats, corners with the same bits shared, and
/// faces as lists of three 32-bit indices, in order.
fn ply(triangles: &[(&Triangle, VertexAttributes)], normals: bool, texcoords: bool) -> Vec<u8> {
    let mut vertices: Vec<[f32; 8]> = Vec::new();
    let mut ids: HashMap<[u32; 8], u32> = HashMap::new();
    let mut faces = Vec::with_capacity(triangles.len());
    for (t, a) in triangles {
        let face: [u32; 3] = std::array::from_fn(|corner| {
            let n = a.n.map_or([0.0; 3], |n| n[corner].into());
            let uv = a.uv.map_or([0.0; 2], |uv| uv[corner].into());
            let p = t.p[corner];
            let vertex = [p.x, p.y, p.z, n[0], n[1], n[2], uv[0], uv[1]];
            *ids.entry(vertex.map(f32::to_bits)).or_insert_with(|| {
                vertices.push(vertex);
                u32::try_from(vertices.len() - 1).expect("a scene holds fewer than 2^32 vertices")
            })
        });
        faces.push(face);
    }
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n",
        vertices.len()
    );
    if normals {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if texcoords {
        header += "property float u\nproperty float v\n";
    }
    header += &format!(
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        faces.len()
    );
    let mut bytes = header.into_bytes();
    let kept = [
        true, true, true, normals, normals, normals, texcoords, texcoords,
    ];
    for vertex in &vertices {
        for (value, _) in vertex.iter().zip(kept).filter(|(_, keep)| *keep) {
            bytes.extend_from_slice(&value.to_le_bytes());
        }
    }
    for face in &faces {
        bytes.push(3);
        for index in face {
            bytes.extend_from_slice(&index.to_le_bytes());
        }
    }
    bytes
}
