//! The accelerator for moving objects, and where a ray meets them at a given time.
//!
//! Design: static geometry stays in the scene's [`Accel`], built once and untouched. Each moving
//! object keeps its triangles in object space with an [`Accel`] of its own, built once by the
//! same code; a ray at time `t` is taken into the object's space by the inverse of its placement
//! at `t` and traced there through [`Accel`]'s own queries, used as they are. Affine maps keep
//! a ray's parameter, so a hit's `t` in object space is its `t` in the world and hits of
//! different objects compare directly. Why not rebuild or refit a world-space tree per time: a
//! sample's time is its own, so every sample would need its own tree; and why not bounds
//! swept over the whole frame around world-space triangles: a fast object's triangles would
//! sweep boxes the length of its path, and every ray crossing the path would test them all.
//!
//! Above the objects sits a flat list, one world-space box per object and keyframe segment
//! holding the object wherever the segment's interpolation puts it (see [`swept_bounds`]). A ray
//! tests the box of its time's segment before it pays for the transform, so rays far from an
//! object cost one box test. The list is flat rather than a tree: scenes move a few objects,
//! and a tree over them would pay off only with tens; it is not done.
//!
//! Numerics. A hit on a moving object is computed in object space, exactly as on static
//! geometry, with its error bound there, and [`placed_point`] offsets it there too, by that
//! bound widened by the roundings still to come (placing the origin in the world, and taking
//! the next ray back), before placing the two origins (one per side) in the world. Once back
//! in object space the origin is strictly on the side of the object-space triangle it leaves
//! to: the argument is at [`placed_point`], and `tracer/tests/motion_offsets.rs` checks it with
//! an exact predicate at every scale, distance and placement. Nothing here depends on the
//! scene's size.

use super::offset::{OffsetMethod, SurfacePoint, offset_ray_origin};
use super::triangle::gamma;
use super::{Accel, BuildQuality, Hit, Ray, Traversal, TraversalStats};
use crate::scene::{MovingObject, Placement, TransformTrack};
use glam::{DMat3, DVec3, Vec3};

/// The moving objects of a scene, each with its own tree, and their swept bounds.
#[derive(Clone, Debug, Default)]
pub struct MotionAccel {
    objects: Vec<Mover>,
    /// The global index of the first moving triangle: hits on moving objects report
    /// `first + ` the triangle's index among all moving objects' triangles, in object order,
    /// so that they follow the static triangles and never share an index with one.
    first: u32,
}

#[derive(Clone, Debug)]
struct Mover {
    accel: Accel,
    track: TransformTrack,
    /// Object-space vertices, by the object's own triangle index.
    vertices: Vec<[Vec3; 3]>,
    /// Per keyframe segment: the world box holding the object anywhere in the segment.
    bounds: Vec<SweptBox>,
    /// This object's first triangle among all moving triangles.
    offset: u32,
}

/// A box in world space and what a ray's rounding into object space can add to it.
#[derive(Clone, Copy, Debug)]
struct SweptBox {
    min: Vec3,
    max: Vec3,
    /// The largest condition number `|L| |L^-1|` (infinity norms) of the segment's placements.
    condition: f32,
    /// Three times the largest translation plus the box's own extent (infinity norms): with the
    /// ray's origin, what bounds the object-space ray's coordinates near the object.
    reach: f32,
}

/// The placements of every moving object at one time: what a path's rays share.
#[derive(Clone, Debug, Default)]
pub struct Moment {
    placements: Vec<(usize, Placement)>,
}

/// Where a ray met a moving object: which object and which of its triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MovingTriangle {
    pub object: usize,
    pub triangle: usize,
}

impl MotionAccel {
    /// Trees for `objects`, whose hits will be numbered from `first`.
    pub fn build(objects: &[MovingObject], first: u32, quality: BuildQuality) -> Self {
        let mut offset = 0u32;
        let objects = objects
            .iter()
            .map(|object| {
                let vertices: Vec<[Vec3; 3]> = object.triangles.iter().map(|t| t.p).collect();
                let mover = Mover {
                    accel: Accel::build(&object.triangles, quality),
                    bounds: swept_bounds(&object.track, &vertices),
                    track: object.track.clone(),
                    vertices,
                    offset,
                };
                offset += u32::try_from(object.triangles.len())
                    .expect("fewer than 2^32 triangles: Hit::triangle is a u32");
                mover
            })
            .collect();
        MotionAccel { objects, first }
    }

    /// Whether there is anything that moves.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// Every object's placement at `time` (frames), for the rays of one path.
    pub fn moment(&self, time: f64) -> Moment {
        Moment {
            placements: self
                .objects
                .iter()
                .map(|o| (o.track.segment(time), o.track.at(time)))
                .collect(),
        }
    }

    /// Which moving object and triangle the global index `triangle` names, or `None` for a
    /// static triangle.
    pub fn locate(&self, triangle: u32) -> Option<MovingTriangle> {
        if self.objects.is_empty() {
            return None;
        }
        let index = triangle.checked_sub(self.first)?;
        let object = self.objects.partition_point(|o| o.offset <= index) - 1;
        Some(MovingTriangle {
            object,
            triangle: (index - self.objects[object].offset) as usize,
        })
    }

    /// The closest hit among the moving objects at `moment` that is closer than `best` (the
    /// static geometry's, say), or `best` itself. With `CERTAIN`, a first hit must be certain
    /// as [`Accel::occluded_with`] counts it; once one is found, closer ones need not be.
    pub fn closest<const CERTAIN: bool>(
        &self,
        moment: &Moment,
        ray: &Ray,
        mut best: Option<Hit>,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        for (mover, (segment, placement)) in self.objects.iter().zip(&moment.placements) {
            let t_max = best.map_or(ray.t_max, |h| h.t);
            // The swept box counts as one node of work, as a box of the tree would.
            stats.nodes += 1;
            if !mover.bounds[*segment].may_hit(ray, t_max) {
                continue;
            }
            let local = Ray {
                t_max,
                ..to_object(placement, ray)
            };
            let found = if CERTAIN && best.is_none() {
                mover.accel.intersect_certain_with(&local, traversal, stats)
            } else {
                mover.accel.intersect_with(&local, traversal, stats)
            };
            // The object's t_max is exclusive, so an equally close hit stays with the lower
            // index, as within one tree.
            if let Some(hit) = found {
                best = Some(Hit {
                    triangle: self.first + mover.offset + hit.triangle,
                    ..hit
                });
            }
        }
        best
    }

    /// Whether any moving object at `moment` is certainly hit in `(0, ray.t_max)`.
    pub fn occluded(
        &self,
        moment: &Moment,
        ray: &Ray,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> bool {
        self.objects
            .iter()
            .zip(&moment.placements)
            .any(|(mover, (segment, placement))| {
                stats.nodes += 1;
                mover.bounds[*segment].may_hit(ray, ray.t_max)
                    && mover
                        .accel
                        .occluded_with(&to_object(placement, ray), traversal, stats)
            })
    }

    /// The world-space hit point of `hit` on moving triangle `at`, with its bound and the
    /// origins rays leaving it start from ([`placed_point`]); its `normal` is the triangle's
    /// unit winding normal in the world (the side it faces, as [`Accel::unit_normal`] gives for
    /// still triangles).
    pub fn surface(&self, moment: &Moment, at: MovingTriangle, hit: &Hit) -> SurfacePoint {
        let mover = &self.objects[at.object];
        let placement = &moment.placements[at.object].1;
        placed_point(placement, &mover.vertices[at.triangle], hit.b1, hit.b2)
    }

    /// The placement of object `object` at `moment`: for shading normals.
    pub fn placement<'a>(&self, moment: &'a Moment, object: usize) -> &'a Placement {
        &moment.placements[object].1
    }
}

/// `ray` in the object space of `placement`: its origin and direction taken through the
/// inverse in f64 and rounded once to f32. Its parameter is the world ray's.
fn to_object(placement: &Placement, ray: &Ray) -> Ray {
    Ray {
        origin: placement.unplace_point(ray.origin.as_dvec3()).as_vec3(),
        dir: (placement.inverse * ray.dir.as_dvec3()).as_vec3(),
        t_max: ray.t_max,
    }
}

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
pub fn placed_point(placement: &Placement, v: &[Vec3; 3], b1: f32, b2: f32) -> SurfacePoint {
    let [a, b, c] = v.map(|p| p.as_dvec3());
    let object_normal = (b - a).cross(c - a).normalize_or_zero();
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
    let origin = |side: Vec3| {
        let o = offset_ray_origin(&widened, side, OffsetMethod::ErrorBound);
        placement.point(o.as_dvec3()).as_vec3()
    };
    let world_noise = 1e-13 * (abs(&placement.linear) * p_object.abs() + translation);
    SurfacePoint {
        p,
        error: round_up(abs(&placement.linear) * e_object + g * p.as_dvec3().abs() + world_noise),
        normal: (placement.normal * object_normal)
            .normalize_or_zero()
            .as_vec3(),
        spawn: Some([local.normal, -local.normal].map(origin)),
    }
}

/// The world boxes, one per keyframe segment of `track`, that hold the triangles `v` wherever
/// the segment's interpolation places them. Where a segment keeps its rotation, every vertex
/// moves on a straight line between its places at the segment's ends (scale and translation are
/// linear in time), so the two ends' boxes hold it all. Where it turns, a vertex stays within
/// `|S p|` of the translation, for the scale `S` at that time, which is largest at one of the
/// ends, so balls of that radius around both ends' translations hold it. Both are padded by
/// the f64 rounding of the interpolation and rounded outwards to f32.
fn swept_bounds(track: &TransformTrack, v: &[[Vec3; 3]]) -> Vec<SweptBox> {
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
    /// Whether `ray` may meet, in `(0, t_max)`, something this box holds, once the ray is taken
    /// into object space with its rounding. The rounding moves the object-space ray by a few
    /// ULPs of its origin and of the distance it travels, which the world sees multiplied by
    /// the placement's condition number; the box is widened by that before a slab test whose
    /// far distances are widened by `1 + 2 gamma(3)` (pbrt-v4's conservative test).
    fn may_hit(&self, ray: &Ray, t_max: f32) -> bool {
        let origin = ray.origin.abs().max_element();
        let pad = gamma(4) * self.condition * (2.0 * origin + self.reach);
        let (min, max) = (self.min - Vec3::splat(pad), self.max + Vec3::splat(pad));
        let (mut t0, mut t1) = (0.0f32, t_max);
        for axis in 0..3 {
            let (o, d) = (ray.origin[axis], ray.dir[axis]);
            if d == 0.0 {
                if o < min[axis] || o > max[axis] {
                    return false;
                }
                continue;
            }
            let (mut near, mut far) = ((min[axis] - o) / d, (max[axis] - o) / d);
            if near > far {
                std::mem::swap(&mut near, &mut far);
            }
            far *= 1.0 + 2.0 * gamma(3);
            t0 = t0.max(near);
            t1 = t1.min(far);
            if t0 > t1 {
                return false;
            }
        }
        true
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
