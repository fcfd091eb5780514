//! The numerics of moving objects: where a ray leaving one starts (the hit placed in the world,
//! its origins offset in the object's space: [`placed_point`]), a world ray taken into an
//! object's space ([`to_object`]), and the world boxes that hold an object over each keyframe
//! segment, with the conservative test of a ray against them (the still trees' slab test,
//! through [`SweptRay`]).

use crate::geometry::Ray;
use crate::geometry::offset::{OffsetMethod, SurfacePoint, offset_ray_origin};
use crate::geometry::traverse::SlabRay;
use crate::geometry::triangle::gamma;
use crate::scene::{Placement, TransformTrack};
use glam::{DMat3, DVec3, Vec3};

/// The point with barycentrics `(b1, b2)` on the object-space triangle `v`, placed in the world
/// by `placement`, with the two origins rays leaving it start from ([`SurfacePoint::spawn`]).
///
/// Why the offset is made in object space: that is where the ray will meet the surface again,
/// and a world offset along the world normal, taken back through an anisotropic placement,
/// moves the origin along the plane too, as far as the condition number times its height,
/// across the crease with a neighbouring facet (a flattened sphere leaked so). So the
/// object-space point is offset as still geometry is ([`offset_ray_origin`]), by its own
/// bound `e` widened by what is still to come: placing the origin in the world rounds it to
/// within `gamma(1) |o_w|`, which is `|M'| gamma(1) |o_w|` in object space, and taking a ray's
/// origin back rounds it to within `gamma(1) |x|` (both `gamma(3)` here, for the origin's
/// distance from the point and the roundings of the bound itself). The origin ends at least
/// the widened reach beyond the plane, so what the two roundings add leaves it on its side,
/// and, as for still geometry, further along the normal than its error reaches along the
/// plane. What f64 rounds (the products, `M M'` differing from the identity by about 1e-16)
/// is covered by a term of 1e-13 relative, far above it and far below a 32-bit float's 6e-8.
///
/// The point's `error` is the bound of `p` in the world: the object-space bound mapped by
/// `|M|`, plus the rounding of placing it. Its `normal` is the world plane's, `M'^T n`
/// normalised: a direction's side of it is its side of the object's plane in object space.
///
/// Limitation: the direction of the next ray is rounded too on its way into object space, by
/// about 6e-8 times the placement's condition number relative to its length, so a direction
/// more grazing than that (a cosine with the surface below it) may point to the other side
/// there and meet the surface it leaves. Still geometry has the same limit without the
/// condition number; light arriving that flat carries a cosine of almost zero.
pub fn placed_point(placement: &Placement, v: &[Vec3; 3], b1: f32, b2: f32) -> SurfacePoint {
    placed_point_with_normal(placement, v, object_normal(v), b1, b2)
}

/// The unit plane normal `(v1 - v0) x (v2 - v0)` of the object-space triangle `v`, in f64, or
/// zero where it has no area: the normal [`placed_point`] places.
pub fn object_normal(v: &[Vec3; 3]) -> DVec3 {
    let [a, b, c] = v.map(|p| p.as_dvec3());
    (b - a).cross(c - a).normalize_or_zero()
}

/// The unit normal in the world of a triangle whose [`object_normal`] is `object_normal`,
/// placed by `placement`: `M'^T n` normalised, the side a direction is on being its side of
/// the object's plane. The one rule for a placed point's normal and a moving emitter's.
#[inline(always)]
pub fn placed_normal(placement: &Placement, object_normal: DVec3) -> Vec3 {
    (placement.normal * object_normal)
        .normalize_or_zero()
        .as_vec3()
}

/// [`placed_point`] with the triangle's [`object_normal`] computed beforehand: the moving
/// objects keep it per triangle, since its square root and division were a fifth of the time of
/// placing a point (`swinging-lamp` places one for every light sample). `object_normal` must be
/// `object_normal(v)` itself: the offsets' argument is made for that plane.
#[inline]
pub fn placed_point_with_normal(
    placement: &Placement,
    v: &[Vec3; 3],
    object_normal: DVec3,
    b1: f32,
    b2: f32,
) -> SurfacePoint {
    debug_assert!(
        object_normal.to_array().map(f64::to_bits)
            == self::object_normal(v).to_array().map(f64::to_bits),
        "the normal given is the triangle's own"
    );
    let local = SurfacePoint::on_triangle_with_normal(v, b1, b2, object_normal.as_vec3());
    let (p_object, e_object) = (local.p.as_dvec3(), local.error.as_dvec3());
    let p_world = placement.point(p_object);
    let p = p_world.as_vec3();
    let g = f64::from(gamma(3));
    let abs_inverse = abs(&placement.inverse);
    let translation = placement.translation.abs();
    let noise = 1e-13
        * (abs_inverse * (p_world.abs() + translation)
            + DVec3::splat(condition(placement)) * p_object.abs());
    let after = abs_inverse * (g * p.as_dvec3().abs()) + g * (p_object.abs() + e_object) + noise;
    let widened = SurfacePoint {
        error: round_up(e_object + after),
        ..local
    };
    // Two calls, not an array's `map`: the map's closure was left out of line, and its
    // arguments went through memory (a tenth of `swinging-lamp`'s render in that closure).
    #[inline(always)]
    fn origin(placement: &Placement, widened: &SurfacePoint, side: Vec3) -> Vec3 {
        let o = offset_ray_origin(widened, side, OffsetMethod::ErrorBound);
        placement.point(o.as_dvec3()).as_vec3()
    }
    let world_noise = 1e-13 * (abs(&placement.linear) * p_object.abs() + translation);
    SurfacePoint {
        p,
        error: round_up(abs(&placement.linear) * e_object + g * p.as_dvec3().abs() + world_noise),
        normal: placed_normal(placement, object_normal),
        spawn: Some([
            origin(placement, &widened, local.normal),
            origin(placement, &widened, -local.normal),
        ]),
    }
}

#[derive(Clone, Copy, Debug)]
pub(super) struct SweptBox {
    pub(super) min: Vec3,
    pub(super) max: Vec3,
    /// The largest condition number `|L| |L^-1|` (infinity norms) of the segment's placements.
    condition: f32,
    /// Three times the largest translation plus the box's own extent (infinity norms): with the
    /// ray's origin, what bounds the object-space ray's coordinates near the object.
    reach: f32,
}

/// The world boxes, one per keyframe segment of `track`, that hold the triangles `v` wherever
/// the segment's interpolation places them. Where a segment keeps its rotation, every vertex
/// moves on a straight line between its places at the segment's ends (scale and translation are
/// linear in time), so the two ends' boxes hold it all. Where it turns, a vertex stays within
/// `|S p|` of the translation, for the scale `S` at that time, which is largest at one of the
/// ends, so balls of that radius around both ends' translations hold it. Both are padded by
/// the f64 rounding of the interpolation and rounded outwards to f32.
pub(super) fn swept_bounds(track: &TransformTrack, v: &[[Vec3; 3]]) -> Vec<SweptBox> {
    let (lo, hi) = v.iter().flatten().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
    );
    let corners: Vec<DVec3> = (0..8)
        .map(|i| {
            DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    (0..track.segments())
        .map(|segment| {
            let (a, b) = track.segment_keys(segment);
            let ends = [a.placement(), b.placement()];
            let (mut min, mut max) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            if a.rotate_degrees == b.rotate_degrees {
                for end in &ends {
                    for &corner in &corners {
                        let p = end.point(corner);
                        (min, max) = (min.min(p), max.max(p));
                    }
                }
            } else {
                // The largest radius at either end holds at every time between them.
                let radius = [a, b]
                    .iter()
                    .flat_map(|key| corners.iter().map(|&c| (key.scale.as_dvec3() * c).length()))
                    .fold(0.0, f64::max);
                for end in &ends {
                    min = min.min(end.translation - DVec3::splat(radius));
                    max = max.max(end.translation + DVec3::splat(radius));
                }
            }
            let size = min.abs().max(max.abs()).max_element();
            let pad = DVec3::splat(1e-9 * size);
            let condition = ends.iter().map(condition).fold(0.0, f64::max);
            let translation = ends
                .iter()
                .map(|e| e.translation.abs().max_element())
                .fold(0.0, f64::max);
            SweptBox {
                min: round_down(min - pad),
                max: round_up(max + pad),
                condition: condition as f32,
                reach: (3.0 * translation + size) as f32,
            }
        })
        .collect()
}

impl SweptBox {
    /// The box from `min` to `max` with no padding (no rotation or scale to round through):
    /// its test is the slab test alone.
    #[cfg(test)]
    pub(super) fn unpadded(min: Vec3, max: Vec3) -> Self {
        SweptBox {
            min,
            max,
            condition: 0.0,
            reach: 0.0,
        }
    }

    /// Half the box's surface area: what the tree's build weighs the chance of entering it by.
    pub(super) fn area(&self) -> f32 {
        let d = self.max - self.min;
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    /// The smallest box holding both, with the larger of each padding term: a test against it
    /// passes wherever a test against either does (see `tree.rs`).
    pub(super) fn union(&self, other: &SweptBox) -> SweptBox {
        SweptBox {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
            condition: self.condition.max(other.condition),
            reach: self.reach.max(other.reach),
        }
    }

    /// Whether `ray` may meet, in `(0, t_max]`, something this box holds, once the ray is taken
    /// into object space with its rounding. The rounding moves the object-space ray by a few
    /// ULPs of its origin and of the distance it travels, which the world sees multiplied by
    /// the placement's condition number; the box is widened by that before the still trees'
    /// robust slab test (`SlabRay`: far distances widened by `1 + 2 gamma(3)`, pbrt-v4's
    /// conservative test, Ize's argument).
    #[inline]
    pub(super) fn may_hit(&self, ray: &SweptRay, t_max: f32) -> bool {
        let pad = gamma(4) * self.condition * (2.0 * ray.origin_size + self.reach);
        let (min, max) = (self.min - Vec3::splat(pad), self.max + Vec3::splat(pad));
        ray.slab.enter_box(min.into(), max.into(), t_max).is_some()
    }
}

/// A world ray made ready for the swept boxes' tests, once for every box a query tests: its
/// slab test's reciprocal direction (one vector division, where each box's test divided six
/// times) and the size of its origin, which each box's padding takes.
pub(super) struct SweptRay {
    slab: SlabRay,
    /// The largest coordinate of the ray's origin, in magnitude.
    origin_size: f32,
    dir: Vec3,
}

impl SweptRay {
    pub(super) fn new(ray: &Ray) -> Self {
        SweptRay {
            slab: SlabRay::new(ray),
            origin_size: ray.origin.abs().max_element(),
            dir: ray.dir,
        }
    }

    /// Whether the ray goes down `axis` (its direction below zero there: not at `-0.0`).
    pub(super) fn goes_down(&self, axis: usize) -> bool {
        self.dir[axis] < 0.0
    }
}

/// `|L| |L^-1|` in the infinity norm: how much the placement can magnify a relative error.
fn condition(placement: &Placement) -> f64 {
    let norm = |m: &DMat3| {
        let a = abs(m).transpose();
        [a.x_axis, a.y_axis, a.z_axis]
            .iter()
            .map(|row| row.element_sum())
            .fold(0.0, f64::max)
    };
    norm(&placement.linear) * norm(&placement.inverse)
}

fn abs(m: &DMat3) -> DMat3 {
    DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs())
}

/// The smallest f32 vector at least `v` on every axis.
fn round_up(v: DVec3) -> Vec3 {
    let up = |x: f64| {
        let f = x as f32;
        if f64::from(f) < x { f.next_up() } else { f }
    };
    Vec3::new(up(v.x), up(v.y), up(v.z))
}

/// The largest f32 vector at most `v` on every axis.
fn round_down(v: DVec3) -> Vec3 {
    let down = |x: f64| {
        let f = x as f32;
        if f64::from(f) > x { f.next_down() } else { f }
    };
    Vec3::new(down(v.x), down(v.y), down(v.z))
}

/// `ray` in the object space of `placement`: its origin and direction taken through the
/// inverse in f64 and rounded once to f32. Its parameter is the world ray's.
pub(super) fn to_object(placement: &Placement, ray: &Ray) -> Ray {
    Ray {
        origin: placement.unplace_point(ray.origin.as_dvec3()).as_vec3(),
        dir: (placement.inverse * ray.dir.as_dvec3()).as_vec3(),
        t_max: ray.t_max,
    }
}
