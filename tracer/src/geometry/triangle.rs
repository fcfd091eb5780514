//! The watertight ray/triangle test of Woop, Benthin and Wald ("Watertight Ray/Triangle
//! Intersection", JCGT 2013), written as pbrt-v4's `IntersectTriangle`.
//!
//! Why this test and not Moller-Trumbore: a ray through an edge or vertex shared by several
//! triangles must hit at least one of them, or light leaks through closed meshes and shadow rays
//! slip through seams. The test moves every vertex into a frame where the ray is the +z axis
//! (translate by the origin, permute axes so the largest direction component becomes z, shear),
//! after which the question is 2D: does the origin lie inside the projected triangle? The edge
//! functions of an edge depend only on its two transformed vertices, so two triangles sharing an
//! edge compute exactly opposite values and cannot both reject a point on it. An edge function
//! that rounds to exactly zero is recomputed in double precision, where the products are exact, so
//! its sign is right (per edge, unlike pbrt: see [`edge_function`]). The hit distance is accepted only when it is conservatively positive, using
//! the error bounds of pbrt-v4 (Physically Based Rendering, 4th edition, section 6.8.4). Where
//! those bounds are inconclusive (for a ray almost in the triangle's plane that happens even at
//! large distances, and pbrt then drops the hit, leaving a hole) the distance is recomputed from
//! the plane equation in f64 and accepted if it is certainly positive.
//!
//! The per-ray part of the transform lives in [`ShearedRay`], a function of the ray alone
//! (made once per walk, or again where needed, always the same bits): every triangle sees
//! bit-identical shear factors, which the watertightness argument needs.

use super::Ray;
use glam::{Vec3, Vec3Swizzles};

/// Where a ray meets a triangle: the distance along the ray and the barycentric coordinates of
/// the hit point with respect to the triangle's vertices 0, 1 and 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    /// The distance along the ray, in units of its direction.
    pub t: f32,
    /// A bound on the rounding error of `t` (pbrt-v4's `deltaT`), for queries that must know
    /// whether a hit certainly lies before a given distance.
    pub t_error: f32,
    /// The barycentric coordinate of vertex 0.
    pub b0: f32,
    /// The barycentric coordinate of vertex 1.
    pub b1: f32,
    /// The barycentric coordinate of vertex 2.
    pub b2: f32,
}

/// Intersects `ray` with the triangle `p` over the open interval `(0, ray.t_max)`.
///
/// Degenerate triangles (see [`is_degenerate`]) are never hit, and no input produces a NaN
/// distance or barycentric: non-finite intermediate values fail every acceptance test.
pub fn intersect_triangle(ray: &Ray, p: &[Vec3; 3]) -> Option<TriangleHit> {
    if is_degenerate(p) {
        return None;
    }
    let hit = ShearedRay::new(ray).intersect(p, ray.t_max)?;
    (hit.t < ray.t_max).then_some(hit)
}

/// True when the triangle has zero area as computed in `f32` (all components of the cross
/// product of its edges are exactly zero: repeated vertices, collinear vertices) or a vertex
/// that is not finite. Such triangles can never be hit.
///
/// pbrt-v4 tests the squared length of the cross product against zero; testing the components
/// instead keeps tiny but valid triangles (edges near 1e-12) from underflowing into "degenerate".
pub fn is_degenerate(p: &[Vec3; 3]) -> bool {
    let finite = p.iter().all(|v| v.is_finite());
    !finite || (p[2] - p[0]).cross(p[1] - p[0]) == Vec3::ZERO
}

/// `gamma(n)` of pbrt: a bound on the relative error of `n` successive roundings, `n u / (1 - n u)`
/// with `u` the unit roundoff of `f32` (half its machine epsilon).
#[inline(always)]
pub(crate) const fn gamma(n: u32) -> f32 {
    let nu = n as f32 * (f32::EPSILON * 0.5);
    nu / (1.0 - nu)
}

/// A ray prepared for [`ShearedRay::intersect`]: the axis permutation and shear that make it the
/// +z axis, a function of the ray alone, so that every triangle sees bit-identical factors.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShearedRay {
    /// The axis that becomes z; x and y follow cyclically (`kx = kz + 1`, `ky = kz + 2`).
    pub(super) kz: usize,
    /// The ray origin and direction, permuted.
    pub(super) origin: Vec3,
    dir: Vec3,
    /// The shear of x and y by z, and the scale of z.
    pub(super) sx: f32,
    pub(super) sy: f32,
    pub(super) sz: f32,
}

impl ShearedRay {
    pub(crate) fn new(ray: &Ray) -> Self {
        let kz = major_axis(ray.dir.to_array());
        // Indexing arrays by a table, rather than `permute`'s match and glam's checked
        // indexing, keeps this per-ray set-up free of branches; the values are the same.
        let [kx, ky, _] = AXES[kz];
        let (o, d) = (ray.origin.to_array(), ray.dir.to_array());
        ShearedRay {
            kz,
            origin: Vec3::new(o[kx], o[ky], o[kz]),
            dir: Vec3::new(d[kx], d[ky], d[kz]),
            sx: -d[kx] / d[kz],
            sy: -d[ky] / d[kz],
            sz: 1.0 / d[kz],
        }
    }

    /// Moves a vertex, already permuted, into the ray's frame: translated and sheared in x and
    /// y. The z shear (scaling by `sz`) is applied later, only when the edge tests pass, as in
    /// pbrt. Permuting before translating gives the same values as pbrt's order.
    #[inline(always)]
    fn transform(&self, p: Vec3) -> Vec3 {
        let v = p - self.origin;
        Vec3::new(v.x + self.sx * v.z, v.y + self.sy * v.z, v.z)
    }

    /// The test itself, for a triangle already known not to be degenerate. Accepts hits in the
    /// half-open interval `(0, t_max]`: closed at `t_max` so that a BVH traversal can pass its
    /// current closest distance and still see exact ties, which it breaks by triangle index.
    #[inline(always)]
    pub(crate) fn intersect(&self, p: &[Vec3; 3], t_max: f32) -> Option<TriangleHit> {
        // Permuting whole vertices (a branch taken the same way for every triangle of a ray)
        // rather than indexing each coordinate by kx, ky, kz.
        let [p0, p1, p2] = p.map(|v| permute(v, self.kz));
        let p0t = self.transform(p0);
        let p1t = self.transform(p1);
        let p2t = self.transform(p2);

        let e0 = edge_function(p1t, p2t);
        let e1 = edge_function(p2t, p0t);
        let e2 = edge_function(p0t, p1t);
        if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
            return None;
        }
        let det = e0 + e1 + e2;
        if det == 0.0 {
            return None;
        }

        let z0 = p0t.z * self.sz;
        let z1 = p1t.z * self.sz;
        let z2 = p2t.z * self.sz;
        let t_scaled = e0 * z0 + e1 * z1 + e2 * z2;
        // A hit behind the origin has t_scaled of the opposite sign to det; rejecting it here
        // saves the division. Unlike pbrt we do not compare against t_max * det here: the
        // rounded product could reject a hit whose computed t is within t_max, and a closest-hit
        // query must see every triangle's t exactly as brute force would.
        if (det < 0.0 && t_scaled >= 0.0) || (det > 0.0 && t_scaled <= 0.0) {
            return None;
        }
        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;

        // Ensure t is conservatively greater than zero (pbrt-v4, section 6.8.4).
        let max_zt = z0.abs().max(z1.abs()).max(z2.abs());
        let delta_z = gamma(3) * max_zt;
        let max_xt = p0t.x.abs().max(p1t.x.abs()).max(p2t.x.abs());
        let max_yt = p0t.y.abs().max(p1t.y.abs()).max(p2t.y.abs());
        let delta_x = gamma(5) * (max_xt + max_zt);
        let delta_y = gamma(5) * (max_yt + max_zt);
        let delta_e = 2.0 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t =
            3.0 * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv_det.abs();
        let (t, t_error, b) = if t > delta_t && t.is_finite() {
            (t, delta_t, [e0 * inv_det, e1 * inv_det, e2 * inv_det])
        } else {
            // The bound grows as 1 / det, so for a ray nearly in the triangle's plane it can
            // exceed a t that is plainly positive (seen: t = 1, bound 2.6, on a facet of a closed
            // sphere crossed at 4e-5 radians), and the ray would leak out of the mesh. pbrt
            // rejects such hits; we settle them from the plane equation in f64, which is just as
            // conservative. Dividing (rather than multiplying by inv_det, which may overflow when
            // det is tiny) keeps the barycentrics in [0, 1].
            // The f64 value is good to far better than f32's rounding of it.
            let t = self.plane_distance_f64(&[p0, p1, p2])?;
            (t, t * f32::EPSILON, [e0 / det, e1 / det, e2 / det])
        };
        // Only the final t is compared with t_max, so that whether a triangle is hit does not
        // depend on the t_max a traversal happens to pass.
        (t <= t_max).then_some(TriangleHit {
            t,
            t_error,
            b0: b[0],
            b1: b[1],
            b2: b[2],
        })
    }
}

impl ShearedRay {
    /// The ray's `t` at the plane of the (permuted) triangle `p`, if it is certainly positive
    /// and finite, computed in f64 from `t = (p0 - o) . n / (d . n)`.
    ///
    /// Differences of f32 values are exact or nearly so in f64, and the few products and sums
    /// that follow add relative errors near 1e-16 of the magnitudes involved; a sign is trusted
    /// only when the value exceeds 1e-12 of those magnitudes, which leaves a margin of 10^4.
    #[inline(never)]
    fn plane_distance_f64(&self, p: &[Vec3; 3]) -> Option<f32> {
        let [p0, p1, p2] = p.map(|v| v.as_dvec3());
        let (o, d) = (self.origin.as_dvec3(), self.dir.as_dvec3());
        let (e1, e2, w) = (p1 - p0, p2 - p0, p0 - o);
        let n = e1.cross(e2);
        let (num, den) = (w.dot(n), d.dot(n));
        let scale = 1e-12 * e1.length() * e2.length();
        if num.abs() <= scale * w.length() || den.abs() <= scale * d.length() {
            return None;
        }
        let t = (num / den) as f32;
        (t > 0.0 && t.is_finite()).then_some(t)
    }
}

/// The axis a ray along `dir` moves to z: pbrt's MaxComponentIndex of `|dir|`, ties
/// included, so that our choice of axis matches pbrt's.
#[inline(always)]
pub(super) fn major_axis(dir: [f32; 3]) -> usize {
    let a = dir.map(f32::abs);
    if a[0] > a[1] {
        if a[0] > a[2] { 0 } else { 2 }
    } else if a[1] > a[2] {
        1
    } else {
        2
    }
}

/// The axes that become x, y and z for each `ShearedRay::kz`: x and y follow z cyclically,
/// as [`permute`] moves them.
pub(super) const AXES: [[usize; 3]; 3] = [[1, 2, 0], [2, 0, 1], [0, 1, 2]];

/// `v` with axis `kz` moved to z and the others following cyclically.
fn permute(v: Vec3, kz: usize) -> Vec3 {
    match kz {
        0 => v.yzx(),
        1 => v.zxy(),
        _ => v,
    }
}

/// The edge function of the edge from `a` to `b` (transformed vertices): twice the signed area of
/// the triangle (ray, a, b) in the sheared plane, `a.x * b.y - a.y * b.x`.
///
/// When the f32 value is exactly zero (the ray passes, to within rounding, through the edge) it
/// is recomputed in f64, where the sign is exact. pbrt recomputes all three edges of a triangle
/// when any one is zero; we decide per edge, so that the value of an edge depends on its two
/// vertices alone and two triangles sharing it always see exactly opposite values:
/// `edge_function(b, a) == -edge_function(a, b)` in both precisions, which is what makes the test
/// watertight. (With pbrt's rule a triangle could use the f64 sign of a shared edge while its
/// neighbour uses an f32 value of the other sign, and both reject a ray near their vertex.)
#[inline(always)]
fn edge_function(a: Vec3, b: Vec3) -> f32 {
    let e = a.x * b.y - a.y * b.x;
    if e == 0.0 { edge_function_f64(a, b) } else { e }
}

/// `a.x * b.y - a.y * b.x` with exact products: two 24-bit significands multiply into at most
/// 48 bits, which fit in an f64, so only the subtraction rounds and a zero result is a true zero.
#[inline(never)]
fn edge_function_f64(a: Vec3, b: Vec3) -> f32 {
    let (ax, ay, bx, by) = (a.x as f64, a.y as f64, b.x as f64, b.y as f64);
    (ax * by - ay * bx) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axes_table_moves_coordinates_as_permute_does() {
        // Two owners of one permutation: the table the per-ray set-up and the SIMD tests index
        // by, and the match the scalar test permutes whole vertices with.
        let v = Vec3::new(1.0, 2.0, 3.0);
        for (kz, [x, y, z]) in AXES.into_iter().enumerate() {
            let a = v.to_array();
            assert_eq!(Vec3::new(a[x], a[y], a[z]), permute(v, kz), "kz {kz}");
            assert_eq!(z, kz, "z is the axis kz names");
        }
    }

    fn ray(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir,
            t_max: f32::INFINITY,
        }
    }

    const UNIT: [Vec3; 3] = [Vec3::ZERO, Vec3::X, Vec3::Y];

    #[test]
    fn hits_the_interior_with_the_right_distance_and_barycentrics() {
        let hit = intersect_triangle(&ray(Vec3::new(0.25, 0.5, 2.0), -Vec3::Z), &UNIT)
            .expect("the ray passes through the interior");
        assert_eq!(hit.t, 2.0);
        assert_eq!((hit.b0, hit.b1, hit.b2), (0.25, 0.25, 0.5));
    }

    #[test]
    fn respects_both_ends_of_the_interval() {
        let r = Ray {
            t_max: 2.0,
            ..ray(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z)
        };
        assert!(
            intersect_triangle(&r, &UNIT).is_none(),
            "t_max is exclusive"
        );
        let behind = ray(Vec3::new(0.25, 0.25, 2.0), Vec3::Z);
        assert!(intersect_triangle(&behind, &UNIT).is_none());
        let on_plane = ray(Vec3::new(0.25, 0.25, 0.0), Vec3::Z);
        assert!(
            intersect_triangle(&on_plane, &UNIT).is_none(),
            "t = 0 is not a hit"
        );
    }

    #[test]
    fn a_vertex_is_hit_from_either_side() {
        for dir in [Vec3::Z, -Vec3::Z] {
            let hit = intersect_triangle(&ray(Vec3::X - 3.0 * dir, dir), &UNIT);
            let hit = hit.expect("a ray through a vertex hits the triangle");
            assert_eq!((hit.t, hit.b1), (3.0, 1.0));
        }
    }

    #[test]
    fn the_f64_fallback_gives_the_sign_that_f32_rounds_away() {
        // a.x * b.y = 1 + 2e exactly, a.y * b.x = (1 + e)^2 = 1 + 2e + e^2, which f32 rounds to
        // 1 + 2e: in f32 the edge function is zero, in truth it is -e^2.
        let e = f32::EPSILON;
        let a = Vec3::new(1.0, 1.0 + e, 0.0);
        let b = Vec3::new(1.0 + e, 1.0 + 2.0 * e, 0.0);
        assert_eq!(a.x * b.y - a.y * b.x, 0.0);
        assert_eq!(edge_function_f64(a, b), -(e * e));
        assert_eq!(
            edge_function_f64(b, a),
            e * e,
            "swapping the edge flips the sign exactly"
        );
    }

    #[test]
    fn a_grazing_hit_beyond_pbrts_error_bound_is_kept() {
        // A facet of a jittered sphere, crossed from inside at 4e-5 radians from its plane.
        // pbrt's bound on the error of t is 2.6 here, so pbrt rejects this hit at t = 0.9987
        // and the ray leaks out of the closed mesh. An f64 Moller-Trumbore gives t = 0.99874.
        let v = |b: [u32; 3]| Vec3::from_array(b.map(f32::from_bits));
        let p = [
            v([1062413947, 1057128321, 3198242291]),
            v([1061894962, 1058252550, 3199631914]),
            v([1061108544, 1057424381, 3196402555]),
        ];
        let r = ray(
            v([3189289118, 1065311373, 1035495222]),
            v([1064749202, 3203316160, 3201709144]),
        );
        let hit = intersect_triangle(&r, &p).expect("the ray crosses the facet");
        assert!((hit.t - 0.99874).abs() < 1e-5, "{hit:?}");
        let reversed = Ray { dir: -r.dir, ..r };
        assert_eq!(
            intersect_triangle(&reversed, &p),
            None,
            "the plane is behind"
        );
    }

    #[test]
    fn edge_functions_are_exactly_antisymmetric_even_near_zero() {
        // Nearly collinear with the ray, so that f32 rounding decides the sign or gives zero.
        let mut state = 1u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1 << 24) as f32
        };
        let mut zeros = 0;
        for _ in 0..100_000 {
            let a = Vec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, 0.0);
            let k = 1.0 + (next() - 0.5) * 1e-6;
            let b = Vec3::new(a.x * k, a.y * (1.0 + (next() - 0.5) * 1e-6), 0.0);
            let e = edge_function(a, b);
            // == rather than bits: +0 and -0 are the same to the inside test.
            assert!(edge_function(b, a) == -e, "{a} {b}");
            zeros += (a.x * b.y - a.y * b.x == 0.0) as u32;
        }
        assert!(
            zeros > 100,
            "only {zeros} f32 zeros: the f64 path went untested"
        );
    }

    #[test]
    fn degenerate_triangles_are_recognised() {
        let line = [Vec3::ZERO, Vec3::ONE, Vec3::splat(2.0)];
        let point = [Vec3::ONE; 3];
        let nan = [Vec3::ZERO, Vec3::X, Vec3::new(f32::NAN, 1.0, 0.0)];
        for p in [line, point, nan] {
            assert!(is_degenerate(&p), "{p:?}");
            assert!(intersect_triangle(&ray(Vec3::new(0.5, 0.5, 3.0), -Vec3::Z), &p).is_none());
        }
        // Seen from a distance of its own size; from much farther away the error bound on t,
        // which grows with the distance, would (rightly, for f32) refuse to call t positive.
        let tiny = UNIT.map(|v| v * 1e-12);
        assert!(!is_degenerate(&tiny), "a 1e-12 triangle has area");
        let r = ray(Vec3::new(2.5e-13, 2.5e-13, 1e-12), -Vec3::Z);
        assert!(intersect_triangle(&r, &tiny).is_some());
    }

    #[test]
    fn a_zero_or_nan_direction_never_hits_and_never_gives_nan() {
        for dir in [
            Vec3::ZERO,
            Vec3::new(f32::NAN, 0.0, -1.0),
            Vec3::splat(f32::INFINITY),
        ] {
            let hit = intersect_triangle(&ray(Vec3::new(0.25, 0.25, 1.0), dir), &UNIT);
            assert!(hit.is_none(), "{dir:?} gave {hit:?}");
        }
    }

    #[test]
    fn gamma_matches_its_definition() {
        let u = f32::EPSILON as f64 * 0.5;
        let expected = 3.0 * u / (1.0 - 3.0 * u);
        assert!(((gamma(3) as f64) - expected).abs() < expected * 1e-6);
    }
}
