//! Leaves packed four triangles to a group, and a SIMD filter that rejects, four at a time, the
//! triangles the watertight test would reject at its first step.
//!
//! Most triangle tests of a traversal fail the watertight test's inside test: the ray's origin
//! is outside the triangle as projected along the ray. That step is a few subtractions and
//! products per vertex, the same for every triangle, so four triangles' worth fit in SSE lanes.
//!
//! **Exactness.** Each lane of [`QuadRay::candidates`] computes, for its triangle, exactly the
//! f32 values the scalar test computes (`ShearedRay::intersect` in `triangle.rs`): the same
//! permutation of axes (by choosing coordinate arrays, which moves no value), the same
//! translation and shear, and the same edge functions `a.x * b.y - a.y * b.x`, with the IEEE
//! operations in the same order and no fused multiply-add. A lane is rejected only when two of
//! its edge functions are nonzero and of opposite signs. The scalar test recomputes an edge
//! function in f64 only when its f32 value is exactly zero, so those two values are the final
//! ones there too, and the scalar test rejects that triangle at the same step. Every lane not
//! rejected goes to the scalar test itself, whose answer is then the answer. So the filter
//! never changes a hit; it only skips work whose outcome is known.

use super::triangle::ShearedRay;
use glam::Vec3;
use wide::{CmpGt, CmpLt, f32x4};

/// Triangles per group: SSE's four f32 lanes.
pub(super) const LANES: usize = 4;

/// Four triangles of one leaf, coordinates in lanes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Quad {
    /// `p[vertex][axis]`: lane `i` holds triangle `entry + i`'s vertex. Unused lanes repeat
    /// the group's first triangle and are masked out by `valid`.
    p: [[f32x4; 3]; 3],
    /// The leaf entry (index into `Accel::vertices` and `Accel::original`) of lane 0.
    pub(super) entry: u32,
    /// Bit `i` set when lane `i` holds a triangle of the leaf.
    pub(super) valid: u32,
}

impl Quad {
    /// The groups of the leaf whose triangles are `vertices`, in order.
    pub(super) fn pack(vertices: &[[Vec3; 3]], first_entry: u32) -> impl Iterator<Item = Quad> {
        vertices.chunks(LANES).enumerate().map(move |(g, chunk)| {
            let lane = |i: usize| chunk.get(i).unwrap_or(&chunk[0]);
            let coordinate =
                |v: usize, axis: usize| f32x4::new([0, 1, 2, 3].map(|i| lane(i)[v][axis]));
            Quad {
                p: [0, 1, 2].map(|v| [0, 1, 2].map(|axis| coordinate(v, axis))),
                entry: first_entry + (g * LANES) as u32,
                valid: (1 << chunk.len()) - 1,
            }
        })
    }
}

/// The per-ray part of the filter: the scalar test's permutation, origin and shear, splatted.
pub(super) struct QuadRay {
    /// Which input axes become x, y and z.
    axes: [usize; 3],
    origin: [f32x4; 3],
    sx: f32x4,
    sy: f32x4,
}

impl QuadRay {
    pub(super) fn new(sheared: &ShearedRay) -> Self {
        let kz = sheared.kz;
        let o = sheared.origin;
        QuadRay {
            axes: [(kz + 1) % 3, (kz + 2) % 3, kz],
            origin: [o.x, o.y, o.z].map(f32x4::splat),
            sx: f32x4::splat(sheared.sx),
            sy: f32x4::splat(sheared.sy),
        }
    }

    /// The lanes of `quad` that the scalar test may accept: bit `i` clear only when the scalar
    /// test certainly rejects triangle `i` (see the module's comment).
    #[inline(always)]
    pub(super) fn candidates(&self, quad: &Quad) -> u32 {
        let [kx, ky, kz] = self.axes;
        // The scalar `transform` of each permuted vertex: `v = p - origin`, then
        // `(v.x + sx * v.z, v.y + sy * v.z)`.
        let sheared = |v: usize| {
            let x = quad.p[v][kx] - self.origin[0];
            let y = quad.p[v][ky] - self.origin[1];
            let z = quad.p[v][kz] - self.origin[2];
            (x + self.sx * z, y + self.sy * z)
        };
        let (p0, p1, p2) = (sheared(0), sheared(1), sheared(2));
        // The scalar `edge_function(a, b)`: `a.x * b.y - a.y * b.x`.
        let edge = |a: (f32x4, f32x4), b: (f32x4, f32x4)| a.0 * b.1 - a.1 * b.0;
        let (e0, e1, e2) = (edge(p1, p2), edge(p2, p0), edge(p0, p1));
        let zero = f32x4::ZERO;
        let negative = e0.cmp_lt(zero) | e1.cmp_lt(zero) | e2.cmp_lt(zero);
        let positive = e0.cmp_gt(zero) | e1.cmp_gt(zero) | e2.cmp_gt(zero);
        let rejected = (negative & positive).move_mask() as u32;
        !rejected & quad.valid
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;

    /// A splitmix64 step mapped to [-1, 1), for test cases.
    fn next(state: &mut u64) -> f32 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }

    #[test]
    fn the_filter_keeps_every_triangle_the_scalar_test_hits_and_rejects_most_misses() {
        let mut state = 7;
        let point = |s: &mut u64| Vec3::new(next(s), next(s), next(s));
        let (mut hits, mut kept, mut rejected) = (0, 0, 0);
        for _ in 0..20_000 {
            // Triangles around the origin, some sharing a vertex with the ray's aim point so
            // that edge functions round to zero or nearly.
            let aim = point(&mut state) * 0.5;
            let triangles: Vec<[Vec3; 3]> = (0..LANES)
                .map(|i| {
                    let a = if i % 2 == 0 { aim } else { point(&mut state) };
                    [a, point(&mut state), point(&mut state)]
                })
                .collect();
            let origin = point(&mut state) * 4.0;
            let dir = match state % 5 {
                0 => Vec3::new(0.0, -0.0, 1.0) * origin.z.signum() * -1.0,
                _ => aim - origin,
            };
            let ray = Ray {
                origin,
                dir,
                t_max: f32::INFINITY,
            };
            let sheared = ShearedRay::new(&ray);
            let quad = Quad::pack(&triangles, 0)
                .next()
                .expect("four triangles, one group");
            let mask = QuadRay::new(&sheared).candidates(&quad);
            for (i, p) in triangles.iter().enumerate() {
                let hit = sheared.intersect(p, f32::INFINITY).is_some();
                let candidate = mask & (1 << i) != 0;
                assert!(!hit || candidate, "lane {i} of {triangles:?} by {ray:?}");
                hits += hit as u32;
                kept += candidate as u32;
                rejected += !candidate as u32;
            }
        }
        assert!(
            hits > 10_000,
            "{hits} hits: the rays rarely meet the triangles"
        );
        assert!(rejected > 20_000, "only {rejected} rejected ({kept} kept)");
    }

    #[test]
    fn a_short_leaf_masks_its_unused_lanes() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let quads: Vec<Quad> = Quad::pack(&[t; 6], 10).collect();
        assert_eq!(quads.len(), 2);
        assert_eq!((quads[0].entry, quads[0].valid), (10, 0b1111));
        assert_eq!((quads[1].entry, quads[1].valid), (14, 0b0011));
        let ray = Ray {
            origin: Vec3::new(0.25, 0.25, 1.0),
            dir: -Vec3::Z,
            t_max: f32::INFINITY,
        };
        let quad_ray = QuadRay::new(&ShearedRay::new(&ray));
        assert_eq!(
            quad_ray.candidates(&quads[1]),
            0b0011,
            "the padding is never a candidate"
        );
    }
}
