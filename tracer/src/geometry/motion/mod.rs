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
//! to (or exactly on its plane where its widened bound along the normal is zero, as still
//! geometry's points without error are): the argument is at [`placed_point`], and
//! `tracer/tests/motion_offsets.rs` checks it with an exact predicate at every scale, distance
//! and placement. Nothing here depends on the scene's size.

use super::offset::SurfacePoint;
use super::{Accel, BuildQuality, Hit, Ray, Traversal, TraversalStats};
use crate::scene::{MovingObject, Placement, TransformTrack};
pub use bounds::placed_point;
use bounds::{SweptBox, swept_bounds};
use glam::Vec3;

mod bounds;
#[cfg(test)]
mod tests;

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

/// The placements of every moving object at one time: what a path's rays share.
#[derive(Clone, Debug, Default)]
pub struct Moment {
    placements: Vec<(usize, Placement)>,
}

/// Where a ray met a moving object: which object and which of its triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MovingTriangle {
    /// The moving object, an index into `Scene::moving`.
    pub object: usize,
    /// The triangle, an index into that object's own triangles (in object space).
    pub triangle: usize,
}

impl Moment {
    /// The placement of moving object `object` (its index in `Scene::moving`) at this moment:
    /// where light sampling finds a moving emitter ([`crate::lights`]).
    pub fn placement(&self, object: usize) -> &Placement {
        &self.placements[object].1
    }
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
pub(super) fn to_object(placement: &Placement, ray: &Ray) -> Ray {
    Ray {
        origin: placement.unplace_point(ray.origin.as_dvec3()).as_vec3(),
        dir: (placement.inverse * ray.dir.as_dvec3()).as_vec3(),
        t_max: ray.t_max,
    }
}
