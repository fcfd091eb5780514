//! Where secondary rays start: the spawn offset of Wachter and Binder ("A Fast and Robust Method
//! for Avoiding Self-Intersection", Ray Tracing Gems, chapter 6).
//!
//! Why: a hit point is computed with rounding error, so it lies slightly in front of or behind
//! the surface, and a ray leaving it may hit the same surface again at a tiny `t` (shadow acne,
//! darkened glass). Moving the origin by a scene-scale epsilon fails on scenes of another scale;
//! this method moves it along the geometric normal by a fixed number of units in the last place
//! (ULPs) of each coordinate, which grows with the coordinate's magnitude exactly as its error
//! does. Near zero, where ULPs become vanishingly small but the error of a computed point does
//! not (it is relative to the triangle's vertices), a small fixed offset is used instead.
//!
//! The hit point itself is computed from barycentrics as `b0 p0 + b1 p1 + b2 p2` ([`hit_point`]):
//! its error is bounded by a few ULPs of the vertex coordinates, whereas `origin + t * dir`
//! carries the error of `t`, which grows with the distance travelled.
//!
//! Limitation (inherent to the constants): within 1/32 of zero on an axis the offset is the
//! fixed `1/65536 * n`, about 1.5e-5, so a scene much smaller than that, centred on the origin,
//! sees rays start farther from the surface than its own size.

use super::{Hit, Ray};
use glam::Vec3;

/// Coordinates closer to zero than this get the fixed offset `FLOAT_SCALE * n`.
const ORIGIN: f32 = 1.0 / 32.0;
/// The fixed offset near zero, as a fraction of the unit normal.
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// The ULP offset elsewhere: a unit normal component moves a coordinate by up to 256 ULPs.
const INT_SCALE: f32 = 256.0;

/// Offsets the point `p` off its surface along `n`, which must point to the side the new ray
/// leaves on (the geometric normal, flipped if needed; see [`spawn_ray`]). `n` need not be unit
/// length; a zero `n` leaves `p` unchanged.
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    let n = n.normalize_or_zero();
    Vec3::new(
        offset_coordinate(p.x, n.x),
        offset_coordinate(p.y, n.y),
        offset_coordinate(p.z, n.z),
    )
}

/// One coordinate of [`offset_ray_origin`]. Adding to the bit pattern of a float moves it by
/// that many ULPs away from zero, so negative coordinates subtract to move toward +n.
fn offset_coordinate(p: f32, n: f32) -> f32 {
    if p.abs() < ORIGIN {
        return p + FLOAT_SCALE * n;
    }
    // Truncation toward zero, as the C cast in the original.
    let ulps = (INT_SCALE * n) as i32;
    let ulps = if p < 0.0 { -ulps } else { ulps };
    // Wrapping: for |p| >= 1/32 the bit pattern is far from the ends of the i32 range.
    f32::from_bits((p.to_bits() as i32).wrapping_add(ulps) as u32)
}

/// The point with barycentrics `(1 - b1 - b2, b1, b2)` on the triangle `p`, computed as
/// `b0 p0 + b1 p1 + b2 p2`, whose error is a few ULPs of the vertex coordinates.
pub fn hit_point(p: &[Vec3; 3], b1: f32, b2: f32) -> Vec3 {
    let b0 = 1.0 - b1 - b2;
    b0 * p[0] + b1 * p[1] + b2 * p[2]
}

impl Hit {
    /// The hit point on the triangle `p` that was hit, from the barycentrics ([`hit_point`]).
    pub fn point(&self, p: &[Vec3; 3]) -> Vec3 {
        hit_point(p, self.b1, self.b2)
    }
}

/// A ray leaving the surface point `p` (with geometric normal `ng`, either orientation) in
/// direction `dir`. The origin is offset to the side `dir` points to.
pub fn spawn_ray(p: Vec3, ng: Vec3, dir: Vec3) -> Ray {
    Ray {
        origin: offset_ray_origin(p, toward(ng, dir)),
        dir,
        t_max: f32::INFINITY,
    }
}

/// A shadow ray from the surface point `p` (geometric normal `ng`) to `target`, covering the
/// open segment between them (`t` in `(0, 1)`). When `target` lies on a surface, pass its
/// geometric normal: the target is then offset toward `p` too, so that its own surface lies
/// beyond `t = 1` rather than within rounding of it.
pub fn spawn_ray_to(p: Vec3, ng: Vec3, target: Vec3, target_ng: Option<Vec3>) -> Ray {
    let origin = offset_ray_origin(p, toward(ng, target - p));
    let target = match target_ng {
        Some(n) => offset_ray_origin(target, toward(n, p - target)),
        None => target,
    };
    Ray {
        origin,
        dir: target - origin,
        t_max: 1.0,
    }
}

/// `n` flipped, if needed, to the side of its plane that `dir` points to.
fn toward(n: Vec3, dir: Vec3) -> Vec3 {
    if n.dot(dir) < 0.0 { -n } else { n }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn far_from_zero_the_offset_is_256_ulps_per_unit_normal_component() {
        for x in [1.0f32, -1.0, 1e5, -3.5e-2, 7e20] {
            let moved = offset_ray_origin(Vec3::new(x, 5.0, -5.0), Vec3::X).x;
            let ulps = moved.to_bits() as i64 - x.to_bits() as i64;
            assert_eq!(ulps.abs(), 256, "{x}");
            assert!(moved > x, "{x} moved to {moved}: must move toward +x");
            let back = offset_ray_origin(Vec3::new(x, 5.0, -5.0), -Vec3::X).x;
            assert!(back < x);
        }
    }

    #[test]
    fn near_zero_the_offset_is_fixed_and_crosses_zero_cleanly() {
        for x in [0.0f32, -0.0, 1e-30, -1e-30, 0.03, -0.03] {
            let moved = offset_ray_origin(Vec3::new(x, 1.0, 1.0), Vec3::X).x;
            assert_eq!(moved, x + FLOAT_SCALE, "{x}");
        }
    }

    #[test]
    fn the_normal_is_normalised_and_a_zero_normal_does_nothing() {
        let p = Vec3::new(2.0, 3.0, 4.0);
        assert_eq!(
            offset_ray_origin(p, Vec3::Z * 1e-20),
            offset_ray_origin(p, Vec3::Z)
        );
        assert_eq!(offset_ray_origin(p, Vec3::ZERO), p);
    }

    #[test]
    fn spawned_rays_start_on_the_side_they_leave_on() {
        let p = Vec3::new(0.5, 0.25, 3.0);
        let up = spawn_ray(p, -Vec3::Z, Vec3::new(0.1, 0.2, 1.0));
        assert!(up.origin.z > p.z);
        let down = spawn_ray(p, Vec3::Z, Vec3::new(0.1, 0.2, -1.0));
        assert!(down.origin.z < p.z);
    }

    #[test]
    fn a_shadow_ray_to_a_surface_stops_short_of_it() {
        let p = Vec3::new(0.0, 0.0, 1.0);
        let light = Vec3::new(0.0, 0.0, 5.0);
        let r = spawn_ray_to(p, Vec3::Z, light, Some(-Vec3::Z));
        assert!(r.origin.z > 1.0);
        let end = r.origin + r.dir * r.t_max;
        assert!(end.z < 5.0, "the offset target is on p's side of the light");
        let r = spawn_ray_to(p, Vec3::Z, light, None);
        assert_eq!(r.origin + r.dir, light);
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
