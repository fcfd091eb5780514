//! `lab::meshes`: the files another renderer is given hold exactly the triangles tessera's loader
//! made, object by object and material by material, read back here by a PLY reader written from
//! the format's specification rather than from the writer.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use lab::meshes::{BsdfDescription, INDEX_FILE, write_meshes};
use std::path::Path;
use tracer::scene::{Triangle, VertexAttributes, load_file_with_report};

/// A perturbed smooth sphere (shared vertices, normals), an emitting quad, a box that moves (left
/// out of the files), an OBJ with two materials, one textured with texture coordinates, and a
/// transformed box after the moving one (so still objects' triangles are found past it).
const SCENE: &str = r#"
[camera]
position = [0, 0, -5]
look_at = [0, 0, 0]

[materials.white]
type = "diffuse"
albedo = 0.5

[materials.lamp]
type = "emissive"
emission = [30, 24, 16]

[[object]]
shape = "sphere"
center = [0.5, -0.25, 2]
radius = 0.75
subdivisions = 2
perturb = 0.1
seed = 3
material = "white"

[[object]]
shape = "quad"
corners = [[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]]
material = "lamp"

[[object]]
shape = "box"
min = [0, 0, 0]
max = [1, 1, 1]
material = "white"
[[object.keys]]
frame = 0
[[object.keys]]
frame = 1
translate = [0, 1, 0]

[[object]]
obj = "mesh/m.obj"

[[object]]
shape = "box"
min = [-3, -3, 4]
max = [3, -2.5, 5]
material = "white"
rotate_y = 30
scale = [1, 2, 1]
"#;

const OBJ: &str = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n\
                   usemtl tiles\nf 1/1 2/2 3/3\nf 2/2 4/1 3/3\nusemtl plain\nf 1 3 4\n";
const MTL: &str =
    "newmtl tiles\nKd 0.6 0.6 0.6\nmap_Kd ../tex/Tiles.png\n\nnewmtl plain\nKd 0.2 0.4 0.6\n";

#[test]
fn every_still_triangle_is_written_with_the_loaders_bits_by_object_and_material() {
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path());
    let out = dir.path().join("meshes");
    let index = write_meshes(&dir.path().join("scene.toml"), &out).unwrap();
    let (scene, report) = load_file_with_report(&dir.path().join("scene.toml")).unwrap();

    // Each still object's triangles, from the loader, grouped as the files should group them.
    let mut expected: Vec<(usize, Vec<(Triangle, VertexAttributes)>)> = Vec::new();
    let mut start = 0;
    for (object, range) in report.still_objects() {
        assert_eq!(
            range.start, start,
            "the still objects' ranges follow one another"
        );
        start = range.end;
        // Each triangle with its attributes, as the loader holds them.
        let triangles: Vec<_> = range
            .map(|i| {
                (
                    scene.triangles[i],
                    scene.attributes.get(i).copied().unwrap_or_default(),
                )
            })
            .collect();
        let key =
            |(t, a): &(Triangle, VertexAttributes)| (t.material, a.n.is_some(), a.uv.is_some());
        let mut keys: Vec<_> = triangles.iter().map(key).collect();
        keys.sort();
        keys.dedup();
        for group_key in keys {
            let group = triangles
                .iter()
                .filter(|t| key(t) == group_key)
                .copied()
                .collect();
            expected.push((object, group));
        }
    }
    assert_eq!(start, scene.triangles.len(), "every still triangle placed");
    assert_eq!(index.len(), expected.len(), "{index:#?}");
    // The moving box (object 2) has no file; the objects around it do.
    let objects: Vec<usize> = index.iter().map(|m| m.object).collect();
    assert_eq!(objects, [0, 1, 3, 3, 4], "{index:#?}");

    for (mesh, (object, triangles)) in index.iter().zip(&expected) {
        assert_eq!(mesh.object, *object);
        assert_eq!(mesh.triangles, triangles.len());
        let read = read_ply(&std::fs::read(out.join(&mesh.file)).unwrap());
        assert_eq!(read.faces.len(), triangles.len(), "{}", mesh.file);
        for (face, (t, a)) in read.faces.iter().zip(triangles) {
            for (corner, &vertex) in face.iter().enumerate() {
                let v = &read.vertices[vertex as usize];
                let bits = |x: &[f32]| x.iter().map(|c| c.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&v.p), bits(&t.p[corner].to_array()), "{}", mesh.file);
                match (&v.n, a.n) {
                    (Some(n), Some(tn)) => assert_eq!(bits(n), bits(&tn[corner].to_array())),
                    (None, None) => {}
                    _ => panic!(
                        "{}: normals where the loader has none, or none where it has",
                        mesh.file
                    ),
                }
                match (&v.uv, a.uv) {
                    (Some(uv), Some(tuv)) => assert_eq!(bits(uv), bits(&tuv[corner].to_array())),
                    (None, None) => {}
                    _ => panic!("{}: texture coordinates that differ in presence", mesh.file),
                }
            }
        }
        assert_eq!(
            (mesh.normals, mesh.texcoords),
            (read.normals, read.texcoords)
        );
        let material = &scene.materials[triangles[0].0.material as usize];
        assert_eq!(mesh.material.name, material.name);
        assert_eq!(mesh.material.emission, material.emission.to_array());
    }

    // Corners with the same bits are one vertex: the closed sphere keeps the icosphere's own
    // vertex count, 10 * 4^2 + 2, not three per triangle.
    let sphere = read_ply(&std::fs::read(out.join(&index[0].file)).unwrap());
    assert_eq!((sphere.vertices.len(), sphere.faces.len()), (162, 320));
    assert!(index[0].normals && !index[0].texcoords);
    assert_eq!(index[1].material.emission, [30.0, 24.0, 16.0]);
    // The textured material names its texture as the loader found it (case folded to the file
    // on disk), with the MTL's texture alone as the reflectance (albedo 1).
    let textured = index.iter().find(|m| m.material.name == "tiles").unwrap();
    assert!(textured.texcoords);
    assert_eq!(
        textured.material.bsdf,
        BsdfDescription::Diffuse {
            albedo: [1.0; 3],
            texture: Some("tex/tiles.png".into()),
        }
    );
    let plain = index.iter().find(|m| m.material.name == "plain").unwrap();
    assert_eq!(
        plain.material.bsdf,
        BsdfDescription::Diffuse {
            albedo: [0.2, 0.4, 0.6],
            texture: None,
        }
    );
    assert!(!plain.texcoords);

    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join(INDEX_FILE)).unwrap()).unwrap();
    assert_eq!(written.as_array().unwrap().len(), index.len());
    assert_eq!(written[4]["material"]["bsdf"]["type"], "diffuse");
}

#[test]
fn a_scene_that_does_not_load_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let error = write_meshes(&dir.path().join("absent.toml"), &dir.path().join("out"))
        .unwrap_err()
        .to_string();
    let path = dir.path().join("absent.toml");
    assert!(error.contains(&path.display().to_string()), "{error}");
    assert!(!dir.path().join("out").exists(), "nothing written");
}

fn write_scene(dir: &Path) {
    std::fs::write(dir.join("scene.toml"), SCENE).unwrap();
    for folder in ["mesh", "mat", "tex"] {
        std::fs::create_dir(dir.join(folder)).unwrap();
    }
    std::fs::write(
        dir.join("mesh/m.obj"),
        OBJ.replace("mtllib m.mtl", "mtllib ../mat/m.mtl"),
    )
    .unwrap();
    std::fs::write(dir.join("mat/m.mtl"), MTL).unwrap();
    let mut png = Vec::new();
    image::RgbImage::from_pixel(2, 2, image::Rgb([200, 100, 50]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    std::fs::write(dir.join("tex/tiles.png"), png).unwrap();
}

struct Ply {
    vertices: Vec<Vertex>,
    faces: Vec<[u32; 3]>,
    normals: bool,
    texcoords: bool,
}

struct Vertex {
    p: [f32; 3],
    n: Option<[f32; 3]>,
    uv: Option<[f32; 2]>,
}

/// A reader for what the PLY specification allows of binary little-endian files with float
/// vertex properties (by name, in any order) and faces as lists of `uchar` counts and `uint`
/// or `int` indices.
fn read_ply(bytes: &[u8]) -> Ply {
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..body]).unwrap();
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"));
    assert_eq!(lines.next(), Some("format binary_little_endian 1.0"));
    let (mut vertices, mut faces, mut names) = (0, 0, Vec::new());
    let mut element = "";
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", name, count] => {
                element = if *name == "vertex" { "vertex" } else { "face" };
                let count: usize = count.parse().unwrap();
                if element == "vertex" {
                    vertices = count
                } else {
                    faces = count
                }
            }
            ["property", "float", name] if element == "vertex" => names.push(name.to_string()),
            [
                "property",
                "list",
                "uchar",
                "uint" | "int",
                "vertex_indices",
            ] => {}
            ["end_header"] | ["comment", ..] => {}
            other => panic!("unexpected header line {other:?}"),
        }
    }
    let mut at = body;
    let mut float = || {
        let value = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        at += 4;
        value
    };
    let column = |name: &str| names.iter().position(|n| n == name);
    let normals = column("nx").is_some();
    let texcoords = column("u").is_some();
    let mut read = Vec::new();
    for _ in 0..vertices {
        let values: Vec<f32> = names.iter().map(|_| float()).collect();
        let get = |name: &str| values[column(name).unwrap()];
        read.push(Vertex {
            p: [get("x"), get("y"), get("z")],
            n: normals.then(|| [get("nx"), get("ny"), get("nz")]),
            uv: texcoords.then(|| [get("u"), get("v")]),
        });
    }
    let mut list = Vec::new();
    for _ in 0..faces {
        assert_eq!(bytes[at], 3, "a triangle");
        at += 1;
        let index =
            |k: usize| u32::from_le_bytes(bytes[at + 4 * k..at + 4 * k + 4].try_into().unwrap());
        list.push([index(0), index(1), index(2)]);
        at += 12;
    }
    assert_eq!(at, bytes.len(), "nothing after the faces");
    Ply {
        vertices: read,
        faces: list,
        normals,
        texcoords,
    }
}
