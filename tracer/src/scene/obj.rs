//! OBJ meshes: our validation pass, then tobj for the faces.
//!
//! tobj 4 accepts `v nan 1 2`, `v inf 0 0` and `v 1e39 0 0`, reads `v 1 2 3 # note` as a colour
//! error, turns `l` lines of three points into triangles, keeps `# comments` in `usemtl` names,
//! gives faces with an unknown `usemtl` no material, and reports no line numbers. So the raw text
//! is first checked line by line here (CRLF, `#` comments, relative indices, `v/vt/vn` forms,
//! polygons), every problem reported with the file and the 1-based line; the pass also writes a
//! canonical copy (comments stripped, `w` divided out, vertex colours, lines, points, groups and
//! smoothing dropped, every `mtllib` replaced by one at the top) which tobj then triangulates.
//! Materials are assigned by `usemtl` through tobj's per-mesh `material_id`, never by `g`/`o`
//! names (the Cornell box's `g` lines follow their faces; see its PROVENANCE.md).

use super::error::SceneError;
use super::files::FileLog;
use super::mtl::{self, MtlMaterial, parse_number};
use super::{Mesh, VertexAttributes};
use glam::{Vec2, Vec3};
use std::collections::{BTreeMap, HashMap};

/// An OBJ file's triangles in object space and the MTL materials they use.
pub(crate) struct ObjMesh {
    /// The triangles, whose `material` is an index into `materials`, or [`NO_MATERIAL`] for
    /// faces before any `usemtl`, with their normals and texture coordinates.
    pub mesh: Mesh,
    /// Every material of every `mtllib`, in file order.
    pub materials: Vec<MtlMaterial>,
    /// The first face line without a `usemtl`, if any.
    pub first_face_without_material: Option<usize>,
}

pub(crate) const NO_MATERIAL: u32 = u32::MAX;

/// Reads, validates and triangulates the OBJ file `path` (its content `bytes`) and its MTL
/// files. A `usemtl` name may also be one the scene defines (`defined`), which then needs no
/// MTL entry.
pub(crate) fn load(
    log: &mut FileLog,
    path: &str,
    bytes: Vec<u8>,
    defined: &dyn Fn(&str) -> bool,
) -> Result<ObjMesh, SceneError> {
    let scan = scan(path, &bytes)?;
    // tobj reads the canonical copy: the file's own text, freed here, would otherwise stay
    // beside it and beside tobj's arrays, the loading's peak memory (33 MB on the dragon).
    drop(bytes);
    let mut materials: Vec<MtlMaterial> = Vec::new();
    for (name, line) in &scan.mtllibs {
        let (mtl_path, mtl_bytes) = log.read(Some((path, *line)), name)?;
        materials.extend(mtl::parse(&mtl_path, &mtl_bytes)?);
    }
    // The last definition of a name wins, as in tobj (which resolves `usemtl` through this map).
    let mut by_name: HashMap<String, usize> = materials
        .iter()
        .enumerate()
        .map(|(i, m)| (m.name.clone(), i))
        .collect();
    for (name, line) in &scan.usemtls {
        if !by_name.contains_key(name) && defined(name) {
            by_name.insert(name.clone(), materials.len());
            materials.push(MtlMaterial::named(name, path, *line));
        }
        if !by_name.contains_key(name) {
            let libraries = scan
                .mtllibs
                .iter()
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>();
            let detail = if libraries.is_empty() {
                format!(
                    "`usemtl {name}`: the file has no `mtllib` and the scene no [materials.{name}]"
                )
            } else {
                format!(
                    "`usemtl {name}`: no material of that name in {} or the scene",
                    libraries.join(", ")
                )
            };
            return Err(SceneError::at_line(path, *line, detail));
        }
    }
    if scan.faces == 0 {
        return Err(SceneError::in_file(
            path,
            "no faces: the file defines no triangles",
        ));
    }
    let names: Vec<tobj::Material> = materials
        .iter()
        .map(|m| tobj::Material {
            name: m.name.clone(),
            ..Default::default()
        })
        .collect();
    // tobj's features (merging, reordering) add fields; the update keeps this valid with them.
    #[allow(clippy::needless_update)]
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj_buf(&mut scan.canonical.as_bytes(), &options, |_| {
        Ok((
            names.clone(),
            by_name.iter().map(|(name, &i)| (name.clone(), i)).collect(),
        ))
    })
    .map_err(|e| SceneError::in_file(path, format!("tobj rejected the validated file: {e}")))?;
    // Exactly the triangles the meshes make (a polygon of k corners makes k - 2): one short,
    // and the array doubled for the last few, which for the dragon was 94 MB more at the peak.
    let count = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    let mut mesh = Mesh {
        triangles: Vec::with_capacity(count),
        attributes: Vec::new(),
    };
    for model in &models {
        append_triangles(path, &model.mesh, &mut mesh);
    }
    Ok(ObjMesh {
        mesh,
        materials,
        first_face_without_material: scan.first_face_without_material,
    })
}

/// Splits a Wavefront (OBJ or MTL) file into statements: `(1-based line, text)` with the line
/// ending (LF or CRLF), `#` comments and surrounding white space removed; blank lines skipped.
/// Only the statement text must be UTF-8, so Latin-1 comments are harmless.
pub(crate) fn statements<'a>(
    file: &'a str,
    bytes: &'a [u8],
) -> impl Iterator<Item = Result<(usize, &'a str), SceneError>> + 'a {
    bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .filter_map(move |(i, raw)| {
            let code = raw
                .iter()
                .position(|&b| b == b'#')
                .map_or(raw, |hash| &raw[..hash]);
            match std::str::from_utf8(code) {
                Ok(text) => {
                    let text = text.trim();
                    (!text.is_empty()).then_some(Ok((i + 1, text)))
                }
                Err(_) => Some(Err(SceneError::at_line(
                    file,
                    i + 1,
                    "not valid UTF-8 text",
                ))),
            }
        })
}

/// What the validation pass learns and the canonical text it writes for tobj.
struct Scan {
    canonical: String,
    mtllibs: Vec<(String, usize)>,
    /// Distinct `usemtl` names with their first line.
    usemtls: Vec<(String, usize)>,
    faces: usize,
    first_face_without_material: Option<usize>,
}

fn scan(file: &str, bytes: &[u8]) -> Result<Scan, SceneError> {
    // tobj resolves `usemtl` against the libraries loaded so far, so one library, holding every
    // material the faces may name, goes first. Written first into the one copy, rather than
    // the body copied after it: on the dragon that second copy was 33 MB.
    let mut canonical = String::with_capacity(bytes.len() + 16);
    canonical.push_str("mtllib all\n");
    let mut mtllibs = Vec::new();
    let mut usemtls: BTreeMap<String, usize> = BTreeMap::new();
    let (mut positions, mut texcoords, mut normals, mut faces) = (0usize, 0usize, 0usize, 0usize);
    let mut in_material = false;
    let mut first_face_without_material = None;
    let mut warned_free_form = false;
    for statement in statements(file, bytes) {
        let (line, text) = statement?;
        let err = |detail: String| SceneError::at_line(file, line, detail);
        let (keyword, rest) = text.split_once(char::is_whitespace).unwrap_or((text, ""));
        let rest = rest.trim();
        match keyword {
            "v" => {
                let v = numbers(rest).map_err(err)?;
                let p = match v[..] {
                    [x, y, z] | [x, y, z, _, _, _] => Vec3::new(x, y, z),
                    [x, y, z, w] if w != 0.0 => Vec3::new(x, y, z) / w,
                    [_, _, _, _] => return Err(err("vertex weight `w` is 0".into())),
                    _ => {
                        return Err(err(format!(
                            "`v {rest}`: expected x y z, x y z w or x y z r g b"
                        )));
                    }
                };
                if !p.is_finite() {
                    return Err(err(format!(
                        "`v {rest}`: coordinates overflow 32-bit floats"
                    )));
                }
                if v.len() == 3 {
                    push_line(&mut canonical, format_args!("v {rest}"));
                } else {
                    push_line(&mut canonical, format_args!("v {} {} {}", p.x, p.y, p.z));
                }
                positions += 1;
            }
            "vt" => {
                let t = numbers(rest).map_err(err)?;
                let uv = match t[..] {
                    [u] => Vec2::new(u, 0.0),
                    [u, v] | [u, v, _] => Vec2::new(u, v),
                    _ => return Err(err(format!("`vt {rest}`: expected 1 to 3 numbers"))),
                };
                if t.len() == 2 {
                    push_line(&mut canonical, format_args!("vt {rest}"));
                } else {
                    push_line(&mut canonical, format_args!("vt {} {}", uv.x, uv.y));
                }
                texcoords += 1;
            }
            "vn" => {
                if numbers(rest).map_err(err)?.len() != 3 {
                    return Err(err(format!("`vn {rest}`: expected 3 numbers")));
                }
                push_line(&mut canonical, format_args!("vn {rest}"));
                normals += 1;
            }
            "f" => {
                check_face(rest, [positions, texcoords, normals]).map_err(err)?;
                push_line(&mut canonical, format_args!("f {rest}"));
                faces += 1;
                if !in_material && first_face_without_material.is_none() {
                    first_face_without_material = Some(line);
                }
            }
            "usemtl" => {
                if rest.is_empty() {
                    return Err(err("`usemtl` without a name".into()));
                }
                usemtls.entry(rest.to_owned()).or_insert(line);
                in_material = true;
                push_line(&mut canonical, format_args!("usemtl {rest}"));
            }
            "mtllib" if rest.is_empty() => return Err(err("`mtllib` without a file name".into())),
            "mtllib" => mtllibs.push((rest.to_owned(), line)),
            "curv" | "curv2" | "surf" if !warned_free_form => {
                tracing::warn!(
                    "{file}:{line}: free-form geometry (`{keyword}`) is not supported; ignored"
                );
                warned_free_form = true;
            }
            // Groups, objects, smoothing, lines, points and the rest do not affect triangles.
            _ => {}
        }
    }
    let mut usemtls: Vec<(String, usize)> = usemtls.into_iter().collect();
    usemtls.sort_by_key(|(_, line)| *line);
    Ok(Scan {
        canonical,
        mtllibs,
        usemtls,
        faces,
        first_face_without_material,
    })
}

fn push_line(out: &mut String, line: std::fmt::Arguments) {
    use std::fmt::Write;
    out.write_fmt(line)
        .expect("writing to a String cannot fail");
    out.push('\n');
}

fn numbers(rest: &str) -> Result<Vec<f32>, String> {
    rest.split_whitespace().map(parse_number).collect()
}

/// Checks a face's corners (`v`, `v/vt`, `v//vn`, `v/vt/vn`): at least three, the same form at
/// every corner, and every index (1-based, or negative = relative to the end) in range of the
/// `counts` of positions, texture coordinates and normals defined so far.
fn check_face(rest: &str, counts: [usize; 3]) -> Result<(), String> {
    const KINDS: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    let mut form = None;
    let mut corners = 0;
    for corner in rest.split_whitespace() {
        corners += 1;
        let mut parts = [""; 3];
        let mut split = corner.split('/');
        for part in &mut parts {
            *part = split.next().unwrap_or_default();
        }
        if split.next().is_some() || parts[0].is_empty() {
            return Err(format!(
                "face corner `{corner}`: expected v, v/vt, v//vn or v/vt/vn"
            ));
        }
        let present = parts.map(|p| !p.is_empty());
        if *form.get_or_insert(present) != present {
            return Err(format!(
                "face corner `{corner}` does not have the form of the face's first corner"
            ));
        }
        for (k, part) in parts.iter().enumerate().filter(|(_, p)| !p.is_empty()) {
            let index: i64 = part
                .parse()
                .map_err(|_| format!("face corner `{corner}`: `{part}` is not an integer index"))?;
            let count = counts[k] as i64;
            let resolved = if index < 0 { count + index } else { index - 1 };
            if index == 0 {
                return Err(format!(
                    "face corner `{corner}`: {} index 0 (OBJ indices start at 1)",
                    KINDS[k]
                ));
            }
            if !(0..count).contains(&resolved) {
                return Err(format!(
                    "face corner `{corner}`: {} index {index} is out of range ({count} defined before this line)",
                    KINDS[k]
                ));
            }
        }
    }
    if corners < 3 {
        return Err(format!(
            "a face needs at least 3 corners, this one has {corners}"
        ));
    }
    Ok(())
}

/// Appends the triangles of one tobj mesh. Normals and texture coordinates are kept only when
/// every vertex of the mesh has them: with `single_index`, tobj's arrays fall out of step when
/// some faces of a mesh have them and others do not.
fn append_triangles(file: &str, mesh: &tobj::Mesh, out: &mut Mesh) {
    let vertices = mesh.positions.len() / 3;
    let has_normals = mesh.normals.len() == 3 * vertices && vertices > 0;
    let has_uvs = mesh.texcoords.len() == 2 * vertices && vertices > 0;
    if (!mesh.normals.is_empty() && !has_normals) || (!mesh.texcoords.is_empty() && !has_uvs) {
        tracing::warn!(
            "{file}: faces mix corners with and without normals or texture coordinates; those are dropped for the mesh"
        );
    }
    let p = |i: u32| Vec3::from_slice(&mesh.positions[3 * i as usize..]);
    let n = |i: u32| Vec3::from_slice(&mesh.normals[3 * i as usize..]).normalize_or_zero();
    let uv = |i: u32| Vec2::from_slice(&mesh.texcoords[2 * i as usize..]);
    let material = mesh.material_id.map_or(NO_MATERIAL, |id| id as u32);
    for c in mesh.indices.chunks_exact(3) {
        // A zero `vn` has no direction; such a triangle is shaded with its geometric normal.
        let normals = has_normals.then(|| [n(c[0]), n(c[1]), n(c[2])]);
        let attributes = VertexAttributes {
            n: normals.filter(|n| n.iter().all(|n| *n != Vec3::ZERO)),
            uv: has_uvs.then(|| [uv(c[0]), uv(c[1]), uv(c[2])]),
        };
        out.push([p(c[0]), p(c[1]), p(c[2])], material, attributes);
    }
}
