//! Procedural shapes and object transforms.
//!
//! Shapes let a scene (and a test) state analytic geometry without data files: a closed
//! tessellated sphere for furnace tests, a quad for a floor or an area light, a box for a room.
//! Closed shapes are watertight: neighbouring triangles share bit-identical vertices, also after
//! a transform or a perturbation, so no ray slips between them. The winding defines the outside
//! (the emitting side of a light); `inward` reverses it and the shading normals.

use super::format::{ObjectSpec, ShapeKind};
use super::{Mesh, Triangle, VertexAttributes};
use glam::{Mat3, Vec2, Vec3};
use std::collections::HashMap;

/// An icosphere: the icosahedron with every triangle split in four `subdivisions` times
/// (20 * 4^subdivisions triangles), vertices on the sphere. `perturb` moves each vertex radially
/// by a factor in [1 - perturb, 1 + perturb], pseudo-randomly from `seed`; shared vertices move
/// together, so the sphere stays closed. Smooth shading normals are the area-weighted averages of
/// the neighbouring face normals.
pub(crate) struct Sphere {
    pub center: Vec3,
    pub radius: f32,
    pub subdivisions: u32,
    pub inward: bool,
    pub perturb: f32,
    pub seed: u64,
    pub smooth: bool,
}

impl Sphere {
    pub(crate) fn mesh(&self, material: u32) -> Mesh {
        let (mut vertices, faces) = icosphere(self.subdivisions);
        for (i, v) in vertices.iter_mut().enumerate() {
            let jitter = 2.0 * unit_random(self.seed, i as u64) - 1.0;
            *v = self.center + *v * self.radius * (1.0 + self.perturb * jitter);
        }
        let faces: Vec<[u32; 3]> = faces
            .into_iter()
            .map(|[a, b, c]| if self.inward { [a, c, b] } else { [a, b, c] })
            .collect();
        let mut normals = vec![Vec3::ZERO; vertices.len()];
        for f in &faces {
            let area_vector = (vertices[f[1] as usize] - vertices[f[0] as usize])
                .cross(vertices[f[2] as usize] - vertices[f[0] as usize]);
            for &i in f {
                normals[i as usize] += area_vector;
            }
        }
        let at = |f: &[u32; 3], table: &[Vec3]| f.map(|i| table[i as usize]);
        let normals: Vec<Vec3> = normals.into_iter().map(Vec3::normalize).collect();
        let mut mesh = Mesh::default();
        for f in &faces {
            let attributes = VertexAttributes {
                n: self.smooth.then(|| at(f, &normals)),
                uv: None,
            };
            mesh.push(at(f, &vertices), material, attributes);
        }
        mesh
    }
}

/// Two triangles (0, 1, 2) and (0, 2, 3) with texture coordinates (0,0), (1,0), (1,1), (0,1).
pub(crate) fn quad(corners: [Vec3; 4], material: u32) -> Mesh {
    let mut mesh = Mesh::default();
    append_quad(&mut mesh, corners, material);
    mesh
}

/// [`quad`]'s two triangles, appended to `mesh`.
fn append_quad(mesh: &mut Mesh, corners: [Vec3; 4], material: u32) {
    let uv = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
    for i in [[0, 1, 2], [0, 2, 3]] {
        let attributes = VertexAttributes {
            n: None,
            uv: Some(i.map(|i| uv[i])),
        };
        mesh.push(i.map(|i| corners[i]), material, attributes);
    }
}

/// An axis-aligned box of 12 triangles facing outwards (inwards when `inward`).
pub(crate) fn cuboid(min: Vec3, max: Vec3, inward: bool, material: u32) -> Mesh {
    let mut out = Mesh::default();
    let corner = |x: usize, y: usize, z: usize| {
        Vec3::new([min.x, max.x][x], [min.y, max.y][y], [min.z, max.z][z])
    };
    for axis in 0..3 {
        for side in 0..2 {
            // The face's four corners in order around it; `u` and `v` are the other two axes.
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut corners = [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(a, b)| {
                let mut idx = [0; 3];
                (idx[axis], idx[u], idx[v]) = (side, a, b);
                corner(idx[0], idx[1], idx[2])
            });
            let mut outward = Vec3::ZERO;
            outward[axis] = if side == 1 { 1.0 } else { -1.0 };
            let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
            if (normal.dot(outward) > 0.0) == inward {
                corners.reverse();
            }
            append_quad(&mut out, corners, material);
        }
    }
    out
}

/// An affine placement: scale, then rotate about x, y and z (degrees), then translate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Transform {
    linear: Mat3,
    normal: Mat3,
    translation: Vec3,
}

impl Transform {
    pub(crate) fn new(scale: Vec3, rotate_degrees: Vec3, translation: Vec3) -> Self {
        let r = rotate_degrees * (std::f32::consts::PI / 180.0);
        let linear = Mat3::from_rotation_z(r.z)
            * Mat3::from_rotation_y(r.y)
            * Mat3::from_rotation_x(r.x)
            * Mat3::from_diagonal(scale);
        // Normals transform by the inverse transpose; for scale * rotation that is the rotation
        // times the reciprocal scale, computed directly to stay exact for the identity.
        let normal = Mat3::from_rotation_z(r.z)
            * Mat3::from_rotation_y(r.y)
            * Mat3::from_rotation_x(r.x)
            * Mat3::from_diagonal(scale.recip());
        Transform {
            linear,
            normal,
            translation,
        }
    }

    pub(crate) fn is_identity(&self) -> bool {
        self.linear == Mat3::IDENTITY && self.translation == Vec3::ZERO
    }

    /// The placed triangle. A mirroring transform (negative determinant) would turn the winding
    /// inside out, so two vertices are swapped to keep the front side in front; its attributes
    /// are placed by [`Transform::apply_to_attributes`], which swaps theirs alike.
    pub(crate) fn apply(&self, t: &Triangle) -> Triangle {
        let mut out = Triangle {
            p: t.p.map(|p| self.linear * p + self.translation),
            ..*t
        };
        if self.mirrors() {
            out.p.swap(1, 2);
        }
        out
    }

    /// The placed attributes of a triangle that [`Transform::apply`] places.
    pub(crate) fn apply_to_attributes(&self, a: &VertexAttributes) -> VertexAttributes {
        let mut out = VertexAttributes {
            // A normal that a near-zero scale sends to infinity has no direction left; such a
            // triangle is shaded with its geometric normal.
            n: a.n
                .map(|n| n.map(|n| (self.normal * n).normalize_or_zero()))
                .filter(|n| n.iter().all(|n| *n != Vec3::ZERO)),
            uv: a.uv,
        };
        if self.mirrors() {
            if let Some(n) = &mut out.n {
                n.swap(1, 2);
            }
            if let Some(uv) = &mut out.uv {
                uv.swap(1, 2);
            }
        }
        out
    }

    /// Whether the transform mirrors (a negative determinant), turning windings inside out.
    fn mirrors(&self) -> bool {
        self.linear.determinant() < 0.0
    }
}

/// The triangles of a procedural shape in object space; an error names the problem.
pub(crate) fn shape_mesh(kind: ShapeKind, o: &ObjectSpec, material: u32) -> Result<Mesh, String> {
    Ok(match kind {
        ShapeKind::Sphere => {
            let subdivisions = o.subdivisions.unwrap_or(3);
            if subdivisions > 8 {
                return Err(format!(
                    "sphere `subdivisions` {subdivisions} is above 8 (20 * 4^8 triangles)"
                ));
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
            .mesh(material)
        }
        ShapeKind::Quad => {
            let corners = o
                .corners
                .ok_or("quad needs `corners` (4 points, counter-clockwise seen from the front)")?;
            quad(corners.0, material)
        }
        ShapeKind::Box => {
            let (Some(min), Some(max)) = (o.min, o.max) else {
                return Err("box needs `min` and `max`".into());
            };
            if !min.0.cmplt(max.0).all() {
                return Err("box `min` must be below `max` in x, y and z".into());
            }
            cuboid(min.0, max.0, o.inward.unwrap_or(false), material)
        }
    })
}

/// The keys a sphere takes besides the transform's and `material`.
pub(crate) const SPHERE_KEYS: &[&str] = &[
    "center",
    "radius",
    "subdivisions",
    "inward",
    "perturb",
    "seed",
    "smooth",
];
/// A quad's.
pub(crate) const QUAD_KEYS: &[&str] = &["corners"];
/// A box's.
pub(crate) const BOX_KEYS: &[&str] = &["min", "max", "inward"];

/// The shape-specific keys an `[[object]]` table gives (transform keys and `material` apply to all).
pub(crate) fn given_keys(o: &ObjectSpec) -> Vec<&'static str> {
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
    keys.into_iter()
        .filter(|(_, given)| *given)
        .map(|(key, _)| key)
        .collect()
}

/// The unit icosahedron subdivided `n` times: vertices on the unit sphere and outward-wound
/// faces. Midpoints are cached per edge so that neighbouring faces share vertices exactly.
fn icosphere(n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let t = (1.0 + 5.0f32.sqrt()) / 2.0;
    let mut vertices: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .into_iter()
    .map(|(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..n {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, vertices: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                vertices.push((vertices[a as usize] + vertices[b as usize]).normalize());
                vertices.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut vertices);
            let bc = midpoint(b, c, &mut vertices);
            let ca = midpoint(c, a, &mut vertices);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (vertices, faces)
}

/// A pseudo-random number in [0, 1) from (seed, index): SplitMix64's finaliser.
fn unit_random(seed: u64, index: u64) -> f32 {
    let mut z = seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// Every directed edge must appear once and its reverse once: closed, consistently wound.
    fn assert_closed(tris: &[Triangle]) {
        let key = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut edges: BTreeMap<([u32; 3], [u32; 3]), i32> = BTreeMap::new();
        for t in tris {
            for i in 0..3 {
                let (a, b) = (key(t.p[i]), key(t.p[(i + 1) % 3]));
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1, "directed edge used {count} times");
            assert_eq!(
                edges.get(&(b, a)),
                Some(&1),
                "edge without its twin: not closed"
            );
        }
    }

    fn sphere(inward: bool, perturb: f32) -> Sphere {
        let center = Vec3::new(1.0, 2.0, 3.0);
        Sphere {
            center,
            radius: 2.0,
            subdivisions: 2,
            inward,
            perturb,
            seed: 9,
            smooth: true,
        }
    }

    #[test]
    fn spheres_are_closed_and_face_the_requested_way() {
        for (inward, perturb) in [(false, 0.0), (true, 0.0), (true, 0.2)] {
            let s = sphere(inward, perturb);
            let mesh = s.mesh(0);
            let tris = &mesh.triangles;
            assert_eq!(tris.len(), 20 * 16);
            assert_closed(tris);
            assert_eq!(
                mesh.attributes.len(),
                tris.len(),
                "every triangle has normals"
            );
            for (t, a) in tris.iter().zip(&mesh.attributes) {
                let centroid = (t.p[0] + t.p[1] + t.p[2]) / 3.0 - s.center;
                let outward = t.area_vector().dot(centroid) > 0.0;
                assert_eq!(outward, !inward);
                let shading = a.n.unwrap()[0].dot(centroid) > 0.0;
                assert_eq!(shading, !inward);
                if perturb == 0.0 {
                    assert!(
                        t.p.iter()
                            .all(|p| ((*p - s.center).length() - 2.0).abs() < 1e-5)
                    );
                }
            }
        }
        let bumpy = sphere(false, 0.2).mesh(0);
        let radii = bumpy
            .triangles
            .iter()
            .flat_map(|t| t.p)
            .map(|p| (p - Vec3::new(1.0, 2.0, 3.0)).length());
        let (lo, hi) = radii.fold((f32::MAX, 0.0f32), |(lo, hi), r| (lo.min(r), hi.max(r)));
        assert!(
            lo >= 2.0 * 0.8 - 1e-5 && hi <= 2.0 * 1.2 + 1e-5 && hi - lo > 0.3,
            "{lo} {hi}"
        );
    }

    #[test]
    fn boxes_are_closed_and_face_outwards_unless_inward() {
        for inward in [false, true] {
            let tris = cuboid(
                Vec3::new(-1.0, 0.0, 2.0),
                Vec3::new(3.0, 1.0, 5.0),
                inward,
                0,
            )
            .triangles;
            assert_eq!(tris.len(), 12);
            assert_closed(&tris);
            let center = Vec3::new(1.0, 0.5, 3.5);
            for t in &tris {
                let c = (t.p[0] + t.p[1] + t.p[2]) / 3.0 - center;
                assert_eq!(t.area_vector().dot(c) > 0.0, !inward);
            }
        }
    }

    #[test]
    fn transforms_scale_rotate_translate_in_that_order_and_keep_the_front() {
        let t = Transform::new(
            Vec3::new(2.0, 1.0, 1.0),
            Vec3::new(0.0, 90.0, 0.0),
            Vec3::new(0.0, 0.0, 10.0),
        );
        let tri = Triangle::new([Vec3::X, Vec3::Y, Vec3::ZERO], 0);
        let attributes = VertexAttributes {
            n: Some([Vec3::X, Vec3::Y, Vec3::Z]),
            uv: Some([Vec2::ZERO, Vec2::X, Vec2::Y]),
        };
        let placed = t.apply(&tri);
        // x scaled to 2, then rotated 90 degrees about y (x -> -z), then moved 10 along z.
        assert!(
            (placed.p[0] - Vec3::new(0.0, 0.0, 8.0)).length() < 1e-5,
            "{:?}",
            placed.p
        );
        let mirror = Transform::new(Vec3::new(-1.0, 1.0, 1.0), Vec3::ZERO, Vec3::ZERO);
        let mirrored = mirror.apply(&tri);
        let before = tri.area_vector().normalize();
        let after = mirrored.area_vector().normalize();
        // The mirror maps the normal (0, 0, 1) to itself; the front must stay where it was.
        assert!((before - after).length() < 1e-6);
        // The attributes follow their vertices: vertex 0 stays, 1 and 2 swap places.
        assert_eq!(mirrored.p, [-Vec3::X, Vec3::ZERO, Vec3::Y]);
        let placed = mirror.apply_to_attributes(&attributes);
        assert_eq!(placed.n, Some([-Vec3::X, Vec3::Z, Vec3::Y]));
        assert_eq!(placed.uv, Some([Vec2::ZERO, Vec2::Y, Vec2::X]));
    }
}
