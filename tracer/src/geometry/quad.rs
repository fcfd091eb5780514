//! Leaves packed four triangles to a group, and the watertight test run on the four at once,
//! one SIMD lane per triangle, as far as it goes in f32.
//!
//! Most triangle tests of a traversal fail the watertight test's inside test (the ray's origin
//! is outside the triangle as projected along the ray), and those that pass mostly end in f32
//! arithmetic: both are the same few subtractions, products and comparisons for every triangle,
//! so four triangles' worth fit in SSE lanes.
//!
//! **Exactness.** Each lane of [`QuadRay::intersect`] computes, for its triangle, exactly the f32
//! values of the scalar test (`ShearedRay::intersect` in `triangle.rs`): the same permutation of
//! axes (by choosing coordinate arrays, which moves no value), translation, shear, edge
//! functions, determinant, scaled distance, division and error bound, with the IEEE operations
//! in the same order and no fused multiply-add. Where the scalar test leaves f32 (an edge
//! function exactly zero, recomputed in f64; a distance its error bound cannot call positive,
//! settled from the plane equation in f64), the lane is handed to the scalar test itself.
//! Otherwise:
//! - a lane with two nonzero edge functions of opposite signs is rejected; the scalar test
//!   recomputes only zero ones, so it rejects it too, at the same step;
//! - a lane without a zero edge function that has a zero determinant or a distance behind the
//!   origin is rejected, as the scalar test rejects it;
//! - a lane whose distance passes the error bound gets the scalar test's very hit (`t`, bound,
//!   barycentrics); only the final `t <= t_max` is left, made by `Closest::offer_hit` against
//!   the `t_max` the scalar call would have been given.
//!
//! The maxima in the error bound are the one place where SIMD and scalar could disagree (on
//! NaN); a NaN in any of their inputs makes the lane's `t` NaN, which goes to the scalar test.
//! So no hit changes: tests compare every lane with the scalar test.

use super::Ray;
use super::triangle::{AXES, ShearedRay, TriangleHit, gamma};
use glam::Vec3;
use wide::{CmpEq, CmpGe, CmpGt, CmpLe, CmpLt, f32x4};

/// Triangles per group: SSE's four f32 lanes.
pub(super) const LANES: usize = 4;

/// Four triangles of one leaf, coordinates in lanes: 192 bytes, three cache lines, aligned to
/// them, so that a group never straddles a fourth line.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Quad {
    /// `p[vertex][axis]`: lane `i` holds triangle `entry + i`'s vertex. Unused lanes repeat
    /// the group's first triangle and are masked out by `valid`.
    pub(super) p: [[f32x4; 3]; 3],
    /// The leaf entry of lane 0 (its place in the binary tree's leaf order, `BinaryTree`): no
    /// walk reads it (an undecided lane's triangle comes from `p`, [`Quad::triangle`]); the
    /// collapse's test does, to see every leaf entry packed once.
    pub(super) entry: u32,
    /// Each lane's input triangle (the binary tree's `original` of its leaf entry), which hits
    /// report: kept here, in the cache lines the test has just read, rather than read from a
    /// separate array at every candidate (on the dragon a cache miss of its own).
    pub(super) original: [u32; LANES],
    /// Bit `i` set when lane `i` holds a triangle of the leaf; triangles fill the lowest lanes.
    pub(super) valid: u32,
    /// The number of triangles in the group (stored: counting bits is slow without `popcnt`).
    pub(super) len: u32,
}

const _: () = assert!(std::mem::size_of::<Quad>() == 192, "three cache lines");

impl Quad {
    /// The groups of the leaf whose input triangles are `original`, in order, each one's
    /// vertices `vertices_of(original)`.
    pub(super) fn pack<'a>(
        original: &'a [u32],
        first_entry: u32,
        vertices_of: impl Fn(u32) -> [Vec3; 3] + 'a,
    ) -> impl Iterator<Item = Quad> + 'a {
        original.chunks(LANES).enumerate().map(move |(g, ids)| {
            // Each lane's triangle, looked up once: unused lanes repeat the group's first.
            let original = [0, 1, 2, 3].map(|i| ids.get(i).copied().unwrap_or(ids[0]));
            let lanes = original.map(&vertices_of);
            let coordinate =
                |v: usize, axis: usize| f32x4::new(lanes.map(|vertices| vertices[v][axis]));
            Quad {
                p: [0, 1, 2].map(|v| [0, 1, 2].map(|axis| coordinate(v, axis))),
                entry: first_entry + (g * LANES) as u32,
                original,
                valid: (1 << ids.len()) - 1,
                len: ids.len() as u32,
            }
        })
    }

    /// Lane `i`'s triangle, its vertices as [`Quad::pack`] was given them (the same bits):
    /// what the scalar test reads for a lane the SIMD test leaves undecided, from the lines
    /// the SIMD test has just read.
    #[inline(always)]
    pub(super) fn triangle(&self, i: usize) -> [Vec3; 3] {
        self.p.map(|[x, y, z]| {
            Vec3::new(
                x.as_array_ref()[i],
                y.as_array_ref()[i],
                z.as_array_ref()[i],
            )
        })
    }
}

/// The per-ray part of the test: the scalar test's permutation, origin and shear. Kept as
/// scalars and splatted where a test uses them: a splat from memory is one instruction, as
/// loading a splat kept here would be, and a ray that tests few triangles (most of them, on
/// small scenes) does not pay for splats it never uses.
#[derive(Clone, Copy)]
pub(super) struct QuadRay {
    /// Which input axes become x, y and z.
    axes: [usize; 3],
    /// The permuted origin, then the shear (`sx`, `sy`, `sz`), as `ShearedRay` has them.
    pub(super) scalars: [f32; 6],
}

impl QuadRay {
    #[inline(always)]
    pub(super) fn new(sheared: &ShearedRay) -> Self {
        Self::from_parts(sheared.kz, Self::scalars_of(sheared))
    }

    /// The set-up of a ray that moves axis `kz` to z, with these [`QuadRay::scalars`].
    #[inline(always)]
    pub(super) fn from_parts(kz: usize, scalars: [f32; 6]) -> Self {
        QuadRay {
            axes: AXES[kz],
            scalars,
        }
    }

    /// The set-up of `ray` itself: what `new` makes of its `ShearedRay`, which the SIMD
    /// tests do not otherwise need.
    #[inline(always)]
    pub(super) fn for_ray(ray: &Ray) -> Self {
        Self::new(&ShearedRay::new(ray))
    }

    /// What [`QuadRay::scalars`] holds for `sheared`: the permuted origin, then the shear.
    #[inline(always)]
    pub(super) fn scalars_of(sheared: &ShearedRay) -> [f32; 6] {
        let o = sheared.origin;
        [o.x, o.y, o.z, sheared.sx, sheared.sy, sheared.sz]
    }

    /// Which input axes become x, y and z: the scalar test's permutation.
    pub(super) fn axes(&self) -> [usize; 3] {
        self.axes
    }

    /// The watertight test on the four triangles of `quad`, lane by lane, as far as it can be
    /// taken without the scalar test's f64 steps (see the module's comment).
    #[inline(always)]
    pub(super) fn intersect(&self, quad: &Quad) -> QuadHits {
        let [kx, ky, kz] = self.axes;
        // Splatted one by one: through an array's `map` they were a call (its `try_map`, left
        // out of line in the AVX traversal), one per group tested.
        let [ox, oy, oz, sx, sy, sz] = self.scalars;
        let (ox, oy, oz) = (f32x4::splat(ox), f32x4::splat(oy), f32x4::splat(oz));
        let (sx, sy, sz) = (f32x4::splat(sx), f32x4::splat(sy), f32x4::splat(sz));
        // The scalar `transform` of each permuted vertex: `v = p - origin`, then
        // `(v.x + sx * v.z, v.y + sy * v.z, v.z)`.
        let sheared = |v: usize| {
            let x = quad.p[v][kx] - ox;
            let y = quad.p[v][ky] - oy;
            let z = quad.p[v][kz] - oz;
            (x + sx * z, y + sy * z, z)
        };
        let (p0, p1, p2) = (sheared(0), sheared(1), sheared(2));
        // The scalar `edge_function(a, b)` in f32: `a.x * b.y - a.y * b.x`.
        let edge = |a: (f32x4, f32x4, f32x4), b: (f32x4, f32x4, f32x4)| a.0 * b.1 - a.1 * b.0;
        let (e0, e1, e2) = (edge(p1, p2), edge(p2, p0), edge(p0, p1));
        let zero = f32x4::ZERO;
        let negative = e0.cmp_lt(zero) | e1.cmp_lt(zero) | e2.cmp_lt(zero);
        let positive = e0.cmp_gt(zero) | e1.cmp_gt(zero) | e2.cmp_gt(zero);
        let outside = negative & positive;
        // Most tests end here: every triangle of the group is missed at the first step, and
        // the rest (the division, the error bound) would decide nothing.
        if !(outside.move_mask() as u32) & quad.valid == 0 {
            return LaneHits::NONE;
        }
        // Where an edge function is exactly zero the scalar test recomputes it in f64: those
        // lanes, unless already outside, are the scalar test's to decide.
        let zero_edge = e0.cmp_eq(zero) | e1.cmp_eq(zero) | e2.cmp_eq(zero);

        let det = e0 + e1 + e2;
        let z0 = p0.2 * sz;
        let z1 = p1.2 * sz;
        let z2 = p2.2 * sz;
        let t_scaled = e0 * z0 + e1 * z1 + e2 * z2;
        let behind =
            (det.cmp_lt(zero) & t_scaled.cmp_ge(zero)) | (det.cmp_gt(zero) & t_scaled.cmp_le(zero));
        let missed = outside | ((det.cmp_eq(zero) | behind) & !zero_edge);
        // And where every lane is missed by the second step (outside, or a triangle behind
        // the ray or seen edge on), the division and the error bound decide nothing either.
        let candidates = !(missed.move_mask() as u32) & quad.valid;
        if candidates == 0 {
            return LaneHits::NONE;
        }
        let inv_det = f32x4::ONE / det;
        let t = t_scaled * inv_det;

        // The scalar error bound of t (pbrt-v4, section 6.8.4), term for term. Its maxima see
        // NaN only in lanes where t is NaN too, and those are never `bounded`.
        let max3 = |a: f32x4, b: f32x4, c: f32x4| a.abs().fast_max(b.abs()).fast_max(c.abs());
        let max_zt = max3(z0, z1, z2);
        let delta_z = f32x4::splat(gamma(3)) * max_zt;
        let max_xt = max3(p0.0, p1.0, p2.0);
        let max_yt = max3(p0.1, p1.1, p2.1);
        let delta_x = f32x4::splat(gamma(5)) * (max_xt + max_zt);
        let delta_y = f32x4::splat(gamma(5)) * (max_yt + max_zt);
        let delta_e = f32x4::splat(2.0)
            * (f32x4::splat(gamma(2)) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = max3(e0, e1, e2);
        let delta_t = f32x4::splat(3.0)
            * (f32x4::splat(gamma(3)) * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
            * inv_det.abs();
        let bounded = t.cmp_gt(delta_t) & t.abs().cmp_lt(f32x4::splat(f32::INFINITY));
        let exact = (bounded & !zero_edge).move_mask() as u32 & candidates;
        QuadHits {
            candidates,
            exact,
            t: t.to_array(),
            t_error: delta_t.to_array(),
            b: [e0 * inv_det, e1 * inv_det, e2 * inv_det].map(f32x4::to_array),
        }
    }

    /// [`QuadRay::intersect`] on two groups at once, `a` in lanes 0 to 3 and `b` in lanes 4
    /// to 7: what the eight-lane test of `quad_avx.rs` computes, written as two four-lane
    /// tests. Every machine can run it; the tests hold the AVX test to it, bit for bit.
    pub(super) fn intersect_pair(&self, a: &Quad, b: &Quad) -> LaneHits<8> {
        let (low, high) = (self.intersect(a), self.intersect(b));
        let join = |x: [f32; LANES], y: [f32; LANES]| {
            let mut out = [0.0; 8];
            out[..LANES].copy_from_slice(&x);
            out[LANES..].copy_from_slice(&y);
            out
        };
        LaneHits {
            candidates: low.candidates | high.candidates << LANES,
            exact: low.exact | high.exact << LANES,
            t: join(low.t, high.t),
            t_error: join(low.t_error, high.t_error),
            b: [0, 1, 2].map(|i| join(low.b[i], high.b[i])),
        }
    }
}

/// What [`QuadRay::intersect`] found out about four triangles.
pub(super) type QuadHits = LaneHits<LANES>;

/// What a SIMD triangle test found out about `N` triangles, lane `i` for triangle `i`.
pub(super) struct LaneHits<const N: usize> {
    /// Lanes the scalar test would not reject: bit `i` clear only when it certainly would.
    pub(super) candidates: u32,
    /// Of those, the lanes whose hit below is the scalar test's own result, up to its final
    /// `t <= t_max`; the other candidates need the scalar test.
    pub(super) exact: u32,
    pub(super) t: [f32; N],
    pub(super) t_error: [f32; N],
    pub(super) b: [[f32; N]; 3],
}

impl<const N: usize> LaneHits<N> {
    /// No candidate: every triangle certainly missed.
    pub(super) const NONE: Self = LaneHits {
        candidates: 0,
        exact: 0,
        t: [0.0; N],
        t_error: [0.0; N],
        b: [[0.0; N]; 3],
    };

    /// Lane `lane`'s hit, valid when its bit of `exact` is set.
    #[inline(always)]
    pub(super) fn hit(&self, lane: usize) -> TriangleHit {
        TriangleHit {
            t: self.t[lane],
            t_error: self.t_error[lane],
            b0: self.b[0][lane],
            b1: self.b[1][lane],
            b2: self.b[2][lane],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;
    use crate::geometry::build::tests::next_signed as next;

    #[test]
    fn simd_lanes_reject_only_misses_and_their_hits_are_the_scalar_ones() {
        let mut state = 7;
        let point = |s: &mut u64| Vec3::new(next(s), next(s), next(s));
        let (mut hits, mut kept, mut rejected, mut exact) = (0, 0, 0, 0);
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
            let quad = Quad::pack(&[0, 1, 2, 3], 0, |i| triangles[i as usize])
                .next()
                .expect("four triangles, one group");
            let found = QuadRay::new(&sheared).intersect(&quad);
            let mask = found.candidates;
            for (i, p) in triangles.iter().enumerate() {
                let scalar = sheared.intersect(p, f32::INFINITY);
                let hit = scalar.is_some();
                let candidate = mask & (1 << i) != 0;
                assert!(!hit || candidate, "lane {i} of {triangles:?} by {ray:?}");
                if found.exact & (1 << i) != 0 {
                    assert_eq!(
                        scalar,
                        Some(found.hit(i)),
                        "lane {i}: the SIMD hit is the scalar one"
                    );
                    exact += 1;
                }
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
        // Half the triangles have a vertex exactly where the ray aims, so their edge functions
        // are zero and the scalar test settles them; the SIMD hits must still be many.
        assert!(exact > hits / 8, "{exact} of {hits} hits settled in SIMD");
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_avx_pair_test_is_the_four_lane_test_bit_for_bit() {
        if !crate::geometry::node8::avx_available() {
            eprintln!("skipped: this processor has no AVX, so there is no eight-lane test to run");
            return;
        }
        let mut state = 11;
        let point = |s: &mut u64| Vec3::new(next(s), next(s), next(s));
        // The masks, and the hits of the lanes settled in SIMD: all that the traversal reads.
        let bits = |h: &LaneHits<8>| {
            let lanes = (0..8).filter(|&i| h.exact & (1 << i) != 0);
            let hits = lanes
                .map(|i| h.hit(i))
                .map(|h| [h.t, h.t_error, h.b0, h.b1, h.b2]);
            let hits: Vec<u32> = hits.flatten().map(f32::to_bits).collect();
            (h.candidates, h.exact, hits)
        };
        let mut exact = 0;
        for round in 0..20_000 {
            // Eight triangles (a second group of one to four), half of them through the ray's
            // aim point, so that edge functions round to zero and lanes go to the scalar test.
            let aim = point(&mut state) * 0.5;
            let count = 5 + round % 4;
            let triangles: Vec<[Vec3; 3]> = (0..count)
                .map(|i| {
                    let a = if i % 2 == 0 { aim } else { point(&mut state) };
                    [a, point(&mut state), point(&mut state)]
                })
                .collect();
            let origin = point(&mut state) * 4.0;
            let dir = match state % 5 {
                0 => Vec3::new(0.0, -0.0, 1.0) * origin.z.signum() * -1.0,
                1 => Vec3::new(f32::MIN_POSITIVE, 1.0, -0.0),
                _ => aim - origin,
            };
            let ray = Ray {
                origin,
                dir,
                t_max: f32::INFINITY,
            };
            let quad_ray = QuadRay::for_ray(&ray);
            let ids: Vec<u32> = (0..count as u32).collect();
            let quads: Vec<Quad> = Quad::pack(&ids, 0, |i| triangles[i as usize]).collect();
            let four = quad_ray.intersect_pair(&quads[0], &quads[1]);
            // SAFETY: this processor has AVX (checked above).
            let eight = unsafe {
                super::super::quad_avx::intersect_pair_avx(&quad_ray, &quads[0], &quads[1])
            };
            assert_eq!(bits(&eight), bits(&four), "{triangles:?} by {ray:?}");
            exact += four.exact.count_ones();
        }
        // About 7,700 here: a sanity check that the comparison is not vacuous.
        assert!(exact > 5_000, "only {exact} lanes settled in SIMD");
    }

    #[test]
    fn a_short_leaf_masks_its_unused_lanes() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let quads: Vec<Quad> = Quad::pack(&[20, 21, 22, 23, 24, 25], 10, |_| t).collect();
        assert_eq!(quads.len(), 2);
        assert_eq!((quads[0].entry, quads[0].valid), (10, 0b1111));
        assert_eq!((quads[1].entry, quads[1].valid), (14, 0b0011));
        assert_eq!(
            (quads[0].original, quads[1].original),
            ([20, 21, 22, 23], [24, 25, 24, 24])
        );
        let ray = Ray {
            origin: Vec3::new(0.25, 0.25, 1.0),
            dir: -Vec3::Z,
            t_max: f32::INFINITY,
        };
        let quad_ray = QuadRay::for_ray(&ray);
        let found = quad_ray.intersect(&quads[1]);
        assert_eq!(found.candidates, 0b0011, "the padding is never a candidate");
        assert_eq!(found.exact, 0b0011);
    }
}
