//! Where secondary rays start: offsets from a conservative bound of each hit point's rounding
//! error, as pbrt-v4 does (Physically Based Rendering, 4th edition, section 6.8.6), and the fixed
//! ULP offset of Wachter and Binder (Ray Tracing Gems, chapter 6) for comparison only.
//!
//! Why: a hit point is computed with rounding error, so it lies slightly in front of or behind
//! its surface, and a ray leaving it may hit that surface again at a tiny `t` (shadow acne,
//! darkened glass) or, worse, start on the far side and leak out of a closed mesh. The error of
//! the computed point is bounded by one or two ULPs of the point itself plus a few of the
//! triangle's edges ([`SurfacePoint::on_triangle`]), so moving the origin along the normal by the
//! bound's projection, then one float further on every axis, puts it strictly on the side the
//! ray leaves to. The distance moved is as small as the rounding requires and no smaller:
//! nothing in it depends on the scene's scale. A point computed without error (on a plane
//! through the world's origin, such as a floor at `y = 0`) is already exactly on its plane and
//! is not moved ([`offset_ray_origin`]'s helper says why that is safe, and why stepping off
//! would be slow).
//!
//! The fixed offset moved every coordinate by 256 ULPs of *itself*, which grows with the
//! distance from the world's origin rather than with the geometry: at x = 1e5 an ULP is 0.0078,
//! so rays left a radius-1 sphere two units off its surface, outside it. It is kept as
//! [`OffsetMethod::FixedUlp`] so that `tessera accuracy` can show the difference; nothing renders
//! with it by default.
//!
//! The normal used for offsetting is the triangle's plane normal computed in f64 from its f32
//! vertices. The f32 cross product of a small triangle far from the origin can carry a relative
//! error large enough to flip the sign of a near-zero component, and the final one-float step
//! on that axis would then move the origin toward the surface; in f64 the direction is good to
//! about 1e-16 divided by the sine of the triangle's smallest angle.
//!
//! Scenes come into the tracer with their transforms already applied (the loader bakes them
//! into world-space vertices), so there is no transform between a hit and its offset: the
//! bound is on the world-space point, computed from the same vertices the ray was tested
//! against. Moving objects are the exception: rays meet them in object space, so a ray leaving
//! one must start off the surface *there*, and their points carry the two origins, one per
//! side, offset in object space and placed in the world (`SurfacePoint::spawn`,
//! `motion/bounds.rs`).

use super::triangle::gamma;
use super::{Hit, Ray};
use glam::{DVec3, Vec3};

/// How secondary rays leave surfaces. A closed set: the error-bound offset is the renderer's;
/// the fixed-ULP one exists for the accuracy comparison.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum OffsetMethod {
    /// Along the normal by the projection of the hit point's error bound, then one float
    /// further on each axis (pbrt-v4's `OffsetRayOrigin`).
    #[default]
    ErrorBound,
    /// 256 ULPs of each coordinate along the normal, a fixed 1/65536 within 1/32 of zero
    /// (Wachter and Binder). Loses light in small geometry far from the world's origin.
    FixedUlp,
}

impl OffsetMethod {
    /// Both methods, the default first: the ladder `tessera accuracy --knobs offset` walks.
    pub const ALL: [OffsetMethod; 2] = [OffsetMethod::ErrorBound, OffsetMethod::FixedUlp];

    /// The name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            OffsetMethod::ErrorBound => "error-bound",
            OffsetMethod::FixedUlp => "fixed-ulp",
        }
    }
}

/// A computed point and what is known about where it truly lies: within `error` of a point of
/// its surface on each axis, and the surface's unit normal there (winding side), zero for a
/// point on no surface (a point light).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// The computed point, in world space.
    pub p: Vec3,
    /// Per axis, a conservative bound of `|p - q|` for some point `q` exactly on the surface.
    pub error: Vec3,
    /// The unit plane normal `(v1 - v0) x (v2 - v0)` of the triangle, or zero.
    pub normal: Vec3,
    /// For a point on a moving object: where rays leaving it start, on the side `normal`
    /// points to and on the other, worked out in the object's space (see
    /// `crate::geometry::placed_point`); `None` elsewhere, where origins are offset here.
    pub spawn: Option<[Vec3; 2]>,
}

impl SurfacePoint {
    /// A point given exactly and on no surface: spawning from or to it moves nothing.
    pub fn exact(p: Vec3) -> Self {
        SurfacePoint {
            p,
            error: Vec3::ZERO,
            normal: Vec3::ZERO,
            spawn: None,
        }
    }

    /// The point with barycentrics `(1 - b1 - b2, b1, b2)` on the triangle `v` ([`hit_point`]),
    /// with its error bound and the triangle's normal.
    ///
    /// The bound, per axis: with the edges `E1 = fl(v1 - v0)`, `E2 = fl(v2 - v0)`, the computed
    /// `p = fl(v0 + fl(fl(b1 E1) + fl(b2 E2)))` lies within `gamma(1) |p|` (the last addition)
    /// plus `gamma(3) (|b1 E1| + |b2 E2|)` (the sum, the products and the edges' own rounding)
    /// of `q = v0 + b1 (v1 - v0) + b2 (v2 - v0)`, which is exactly a point of the triangle's
    /// plane whatever the values of `b1` and `b2`. `gamma(2)` and `gamma(4)` leave room for the
    /// roundings in computing the bound itself. For a triangle small beside its distance from
    /// the origin the bound is one to two ULPs of `p`, and the offset about two to three.
    ///
    /// Why not the tightest bound, half an ULP of `p`: the point may be off by as much within
    /// the plane too, beyond an edge, and near a sharp crease only an offset along the normal
    /// that exceeds that in-plane error keeps the origin inside the neighbour's plane. With
    /// half an ULP, a unit sphere rounded to a grid of 1/8 (2e6 from the origin) leaked 19 of
    /// 3,000 bounces in `tests/offsets.rs`; with this bound, none.
    pub fn on_triangle(v: &[Vec3; 3], b1: f32, b2: f32) -> Self {
        Self::on_triangle_with_normal(v, b1, b2, plane_normal(v))
    }

    /// [`SurfacePoint::on_triangle`] with the triangle's [`plane_normal`] computed beforehand.
    /// Renderers cache the normal per triangle: its f64 cross product and square root cost about
    /// as much as the rest of the point, and the cached value is the same bits.
    // Always inlined: the lanes' shading loop (`integrator/lanes/shade.rs`) calls it, and one
    // call left in that loop's body keeps the whole loop from vectorising.
    #[inline(always)]
    pub fn on_triangle_with_normal(v: &[Vec3; 3], b1: f32, b2: f32, normal: Vec3) -> Self {
        let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
        let p = hit_point(v, b1, b2);
        let along = (b1 * e1).abs() + (b2 * e2).abs();
        SurfacePoint {
            p,
            error: gamma(2) * p.abs() + gamma(4) * along,
            normal,
            spawn: None,
        }
    }
}

impl Hit {
    /// The hit point on the triangle `p` that was hit, from the barycentrics ([`hit_point`]).
    pub fn point(&self, p: &[Vec3; 3]) -> Vec3 {
        hit_point(p, self.b1, self.b2)
    }

    /// The hit point with its error bound and normal, for spawning rays from it.
    pub fn surface_point(&self, p: &[Vec3; 3]) -> SurfacePoint {
        SurfacePoint::on_triangle(p, self.b1, self.b2)
    }
}

/// The point with barycentrics `(1 - b1 - b2, b1, b2)` on the triangle `p`, computed as
/// `p0 + (b1 (p1 - p0) + b2 (p2 - p0))`, whose error is about one ULP of the point plus a few
/// of the edges (whereas `origin + t * dir` carries the error of `t`, which grows with the
/// distance travelled). Why this form and not `b0 p0 + b1 p1 + b2 p2`: far from the origin
/// each of the three products rounds by an ULP of the coordinates, and `b0 = 1 - b1 - b2`
/// rounds too, so the bound on the error (and the offset) came to about 15 ULPs of the point.
#[inline(always)]
pub fn hit_point(p: &[Vec3; 3], b1: f32, b2: f32) -> Vec3 {
    p[0] + (b1 * (p[1] - p[0]) + b2 * (p[2] - p[0]))
}

/// `point` moved off its surface to the side of its normal that `toward` points to. A point on
/// no surface (zero normal) is returned unchanged. A point on a moving object gives the origin
/// it carries for that side, whatever `method` (the comparison offset is for still geometry).
// Inlined into the spawns, so that the origin stays in registers (docs/bench.md, issue 12,
// eighth round: a store-forwarding stall per ray when it was returned through memory). Always:
// under a plain `#[inline]` it was left a call, whose direction was read back through memory.
#[inline(always)]
pub fn offset_ray_origin(point: &SurfacePoint, toward: Vec3, method: OffsetMethod) -> Vec3 {
    let below = point.normal.dot(toward) < 0.0;
    if let Some([above_origin, below_origin]) = point.spawn {
        return if below { below_origin } else { above_origin };
    }
    let n = if below { -point.normal } else { point.normal };
    match method {
        OffsetMethod::ErrorBound => offset_by_error(point.p, point.error, n),
        OffsetMethod::FixedUlp => offset_by_ulps(point.p, n),
    }
}

/// A ray leaving `from` in direction `dir`, from the side of the surface `dir` points to.
// Always inlined: as a call, the path loop read the returned ray back from memory in two
// overlapping 16-byte loads across the narrower stores that wrote it, which the processor
// cannot forward (a stall per bounce; docs/bench.md, issue 12, twenty-sixth round).
#[inline(always)]
pub fn spawn_ray(from: &SurfacePoint, dir: Vec3, method: OffsetMethod) -> Ray {
    Ray {
        origin: offset_ray_origin(from, dir, method),
        dir,
        t_max: f32::INFINITY,
    }
}

/// A shadow ray from `from` to `to`, covering the open segment between them (`t` in `(0, 1)`).
/// Both ends are offset off their surfaces toward each other, so that neither surface lies
/// within the segment; a `to` on no surface (a point light) stays where it is.
///
/// The ray's end `origin + 1 * dir` is not the offset target itself: `dir = target - origin`
/// rounds by up to half an ULP of each component. So the target's error bound is widened by
/// `gamma(2) |target - origin|` before offsetting, which keeps the exact end of the segment
/// off the target's surface too; [`crate::geometry::Accel::occluded`] then counts only hits
/// certainly before `t = 1`, so that the rounding of `t` cannot report the light as blocking.
///
/// Limitation: a segment that runs within rounding of the plane it leaves (both ends on an
/// edge two triangles share) has no side that is certainly right, and may be reported blocked
/// by the surface it runs along. Light arriving along a surface carries a cosine of zero.
pub fn spawn_ray_to(from: &SurfacePoint, to: &SurfacePoint, method: OffsetMethod) -> Ray {
    let origin = offset_ray_origin(from, to.p - from.p, method);
    let widened = SurfacePoint {
        error: to.error + gamma(2) * (to.p - origin).abs(),
        ..*to
    };
    let target = offset_ray_origin(&widened, origin - to.p, method);
    Ray {
        origin,
        dir: target - origin,
        t_max: 1.0,
    }
}

/// The unit normal of the plane of `v`, from the cross product of its edges in f64 (see the
/// module's comment); zero for a triangle without area.
pub fn plane_normal(v: &[Vec3; 3]) -> Vec3 {
    let [a, b, c] = v.map(|v| v.as_dvec3());
    let n: DVec3 = (b - a).cross(c - a);
    n.normalize_or_zero().as_vec3()
}

/// pbrt-v4's `OffsetRayOrigin`: `p` moved along the unit normal `n` by `d = |n| . error`, the
/// largest distance from the plane that the error box around `p` reaches, then one float
/// further on every axis along which that offset moves it. The last step is what makes the
/// result strictly off the plane: the addition rounds to nearest, possibly back toward the
/// plane, and the step away is larger than that rounding.
///
/// A point with no error along the normal (`d = 0`) is exactly on its plane, which then passes
/// through the world's origin along every axis the normal has (the floor `y = 0` of the
/// Cornell scenes, a vertex at the origin): it stays there, as in pbrt-v4. Rays from it find
/// that plane at `t = 0` exactly, which the triangle test rejects (for a grazing ray, through
/// its f64 plane distance, which is not certainly positive), so nothing hits the surface it
/// leaves; `tests/offsets.rs` probes closed boxes with faces on those planes at every scale.
/// Stepping one float off it anyway, as we once did, gave a coordinate of 1.4e-45, a
/// subnormal: every triangle and box test reading that origin then took a microcode assist
/// per operation, and the Cornell box rendered 18 % slower (docs/bench.md, issue 12,
/// eighteenth round).
// Inlined, as `offset_ray_origin` is: called through memory, the normal and the direction
// were read back from the caller's stores at every spawn.
#[inline(always)]
fn offset_by_error(p: Vec3, error: Vec3, n: Vec3) -> Vec3 {
    let d = n.abs().dot(error);
    let offset = d * n;
    let moved = p + offset;
    let step = |x: f32, along: f32| {
        if along > 0.0 {
            x.next_up()
        } else if along < 0.0 {
            x.next_down()
        } else {
            x
        }
    };
    Vec3::new(
        step(moved.x, offset.x),
        step(moved.y, offset.y),
        step(moved.z, offset.z),
    )
}

/// Coordinates closer to zero than this get the fixed offset `FLOAT_SCALE * n` (Wachter-Binder).
const ORIGIN: f32 = 1.0 / 32.0;
/// The fixed offset near zero, as a fraction of the unit normal.
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// The ULP offset elsewhere: a unit normal component moves a coordinate by up to 256 ULPs.
const INT_SCALE: f32 = 256.0;

/// Wachter and Binder's offset along the unit normal `n`: 256 ULPs per unit of normal component.
fn offset_by_ulps(p: Vec3, n: Vec3) -> Vec3 {
    Vec3::new(
        ulp_coordinate(p.x, n.x),
        ulp_coordinate(p.y, n.y),
        ulp_coordinate(p.z, n.z),
    )
}

/// One coordinate of [`offset_by_ulps`]. Adding to the bit pattern of a float moves it by that
/// many ULPs away from zero, so negative coordinates subtract to move toward +n.
fn ulp_coordinate(p: f32, n: f32) -> f32 {
    if p.abs() < ORIGIN {
        return p + FLOAT_SCALE * n;
    }
    // Truncation toward zero, as the C cast in the original.
    let ulps = (INT_SCALE * n) as i32;
    let ulps = if p < 0.0 { -ulps } else { ulps };
    // Wrapping: for |p| >= 1/32 the bit pattern is far from the ends of the i32 range.
    f32::from_bits((p.to_bits() as i32).wrapping_add(ulps) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The triangle z = `z` spanned by `(x, 0)`, `(x + 1, 0)`, `(x, 1)`, normal +z.
    fn flat(x: f32, z: f32) -> [Vec3; 3] {
        [
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 1.0, 0.0, z),
            Vec3::new(x, 1.0, z),
        ]
    }

    #[test]
    fn the_error_bound_offset_grows_with_the_vertices_not_beyond() {
        // At 1e5 an ULP of x is 0.0078, but the plane z = 1 is where the error along z is:
        // the offset is a few ULPs of 1, not of 1e5.
        let point = SurfacePoint::on_triangle(&flat(1e5, 1.0), 0.25, 0.25);
        let up = offset_ray_origin(&point, Vec3::Z, OffsetMethod::ErrorBound);
        assert!(up.z > 1.0 && up.z < 1.0 + 1e-5, "{up}");
        assert_eq!((up.x, up.y), (point.p.x, point.p.y), "n has no x or y");
        let down = offset_ray_origin(&point, -Vec3::Z, OffsetMethod::ErrorBound);
        assert!(down.z < 1.0 && down.z > 1.0 - 1e-5, "{down}");
    }

    #[test]
    fn a_point_without_error_stays_exactly_on_its_plane_and_never_turns_subnormal() {
        // On the plane z = 0 every computed point is exact along z: its error there is zero,
        // so the offset is zero, and the origin stays on the plane, where the triangle test's
        // distance to that plane is exactly zero and is rejected. One float up from zero
        // would have been 1.4e-45, a subnormal that slows every operation reading it.
        for (b1, b2) in [(0.0, 0.0), (0.25, 0.5), (1.0, 0.0), (0.3, 0.7)] {
            let point = SurfacePoint::on_triangle(&flat(0.0, 0.0), b1, b2);
            assert_eq!((point.p.z, point.error.z), (0.0, 0.0));
            for toward in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.2, 1e-6)] {
                let origin = offset_ray_origin(&point, toward, OffsetMethod::ErrorBound);
                assert_eq!(origin, point.p, "({b1}, {b2}) toward {toward}");
                assert!(origin.to_array().iter().all(|c| !c.is_subnormal()));
            }
        }
        // A plane beside zero has an error along its normal, and the origin moves off it.
        let point = SurfacePoint::on_triangle(&flat(0.0, 1e-3), 0.25, 0.25);
        let up = offset_ray_origin(&point, Vec3::Z, OffsetMethod::ErrorBound);
        assert!(up.z > 1e-3 && up.z < 1e-3 + 1e-9, "{up}");
    }

    #[test]
    fn the_fixed_ulp_offset_is_256_ulps_per_unit_normal_component() {
        for x in [1.0f32, -1.0, 1e5, -3.5e-2, 7e20] {
            let moved = offset_by_ulps(Vec3::new(x, 5.0, -5.0), Vec3::X).x;
            let ulps = moved.to_bits() as i64 - x.to_bits() as i64;
            assert_eq!(ulps.abs(), 256, "{x}");
            assert!(moved > x, "{x} moved to {moved}: must move toward +x");
            assert!(offset_by_ulps(Vec3::new(x, 5.0, -5.0), -Vec3::X).x < x);
        }
        for x in [0.0f32, -0.0, 1e-30, -0.03] {
            let moved = offset_by_ulps(Vec3::new(x, 1.0, 1.0), Vec3::X).x;
            assert_eq!(moved, x + FLOAT_SCALE, "{x}: the fixed offset near zero");
        }
    }

    #[test]
    fn a_point_on_no_surface_stays_where_it_is() {
        let p = SurfacePoint::exact(Vec3::new(2.0, 3.0, 4.0));
        for method in OffsetMethod::ALL {
            assert_eq!(offset_ray_origin(&p, Vec3::Z, method), p.p);
        }
    }

    #[test]
    fn spawned_rays_start_on_the_side_they_leave_on() {
        let point = SurfacePoint::on_triangle(&flat(0.0, 3.0), 0.5, 0.25);
        for method in OffsetMethod::ALL {
            let up = spawn_ray(&point, Vec3::new(0.1, 0.2, 1.0), method);
            assert!(up.origin.z > 3.0, "{method:?}");
            let down = spawn_ray(&point, Vec3::new(0.1, 0.2, -1.0), method);
            assert!(down.origin.z < 3.0, "{method:?}");
        }
    }

    #[test]
    fn a_shadow_ray_to_a_surface_stops_short_of_it() {
        let from = SurfacePoint::on_triangle(&flat(0.0, 1.0), 0.25, 0.25);
        let light = SurfacePoint::on_triangle(&flat(0.0, 5.0), 0.25, 0.25);
        for method in OffsetMethod::ALL {
            let r = spawn_ray_to(&from, &light, method);
            assert!(r.origin.z > 1.0);
            let end = r.origin + r.dir * r.t_max;
            assert!(
                end.z < 5.0,
                "{method:?}: the end is on the near side of the light"
            );
        }
        let point_light = SurfacePoint::exact(Vec3::new(0.25, 0.25, 5.0));
        let r = spawn_ray_to(&from, &point_light, OffsetMethod::ErrorBound);
        assert_eq!(r.origin + r.dir, point_light.p);
    }

    #[test]
    fn hit_point_interpolates_the_vertices() {
        let p = [
            Vec3::ZERO,
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(0.0, 8.0, 0.0),
        ];
        assert_eq!(hit_point(&p, 0.25, 0.5), Vec3::new(1.0, 4.0, 0.0));
        assert_eq!(hit_point(&p, 0.0, 0.0), p[0]);
    }
}
