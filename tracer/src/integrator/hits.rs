//! Where a path's rays meet the scene, and the local geometry where they do.
//!
//! The static geometry answers first, through its tree, exactly as it did before anything could
//! move; moving objects are then asked at the path's time ([`Moment`]) for anything closer
//! (`crate::geometry::motion`). A scene without moving objects skips them with one test of an
//! empty list per query, so its rays trace the same way, to the bit and nearly to the cycle.
//! Hits on moving triangles are numbered after the static ones, so the tie rule (the lower
//! index wins) carries over, and the geometry of such a hit is placed in the world at the
//! path's time, with the error bound that spawning from it needs.
//!
//! A pixel's camera rays leave the same point (or the same lens) in nearly the same direction,
//! so their first hits in the still tree are found together, up to eight samples at a time
//! ([`World::camera_hits`], `crate::geometry`'s packets; each ray's moving objects are asked
//! after, at its own time): each ray is tested exactly as it would be alone, so the hits are
//! the same bits. Packets are made of one pixel's samples, never
//! of neighbouring pixels, so that what a pixel counts as work depends on the pixel alone, not
//! on the tile it falls in: the cost map stays the same for every partition.

use super::World;
use crate::geometry::{
    Accel, Hit, Moment, MovingTriangle, Ray, SetUp, SurfacePoint, Traversal, TraversalStats,
};
use crate::scene::{Placement, Scene, Triangle, VertexAttributes};
use glam::{Vec2, Vec3};

/// The geometry of a hit; both normals on the winding's side.
pub(super) struct Surface {
    /// The hit point, with what spawning rays from it needs: its error bound and plane normal.
    pub at: SurfacePoint,
    /// What the surface shows the ray: its side, shading normal and texture coordinates.
    pub seen: Shading,
    pub material: u32,
}

/// What a hit's surface shows the ray that found it ([`World::shading`]).
pub(super) struct Shading {
    /// Whether the ray arrives on the side the triangle's winding faces.
    pub front_facing: bool,
    /// The shading normal, on the side of the geometric one.
    pub normal: Vec3,
    /// The texture coordinates, where a texture will read them.
    pub uv: Option<Vec2>,
}

/// A hit's triangle and where it is: the point with its bound, the unit winding normal, and for
/// a moving triangle (in object space) its placement.
pub(super) struct Placed<'a> {
    pub triangle: &'a Triangle,
    /// The triangle's normals and texture coordinates, if it has any.
    pub attributes: Option<&'a VertexAttributes>,
    pub at: SurfacePoint,
    pub unit_normal: Vec3,
    pub placement: Option<&'a Placement>,
}

/// How a pixel's camera rays meet the BVH (a comparison knob: both find the same hits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum CameraRays {
    /// Up to eight of a pixel's samples walked through the tree together
    /// ([`crate::geometry::Accel::intersect_packet`]), where the default traversal is used and
    /// nothing moves; one by one otherwise.
    #[default]
    Packets,
    /// One by one, as every other ray.
    OneByOne,
}

impl World {
    /// The traversal rays take through the BVH ([`World::set_traversal`]).
    pub fn traversal(&self) -> Traversal {
        self.traversal
    }

    /// Makes rays take `traversal`: the renderer's own ([`Traversal::Robust`], the default)
    /// or a comparison one, which walks the binary tree. A world frees that tree when it is
    /// made ([`crate::geometry::Accel::release_binary_tree`]), so the first comparison
    /// traversal builds the still geometry's trees again, at the quality they were built
    /// with: the same trees, as the build is deterministic.
    pub fn set_traversal(&mut self, traversal: Traversal) {
        if traversal != Traversal::Robust && !self.accel.has_binary_tree() {
            let mut accel = Accel::build(&self.scene.triangles, self.accel.quality());
            accel.set_box_simd(self.accel.box_simd());
            make_ready(&mut accel, &self.scene, traversal);
            self.accel = accel;
        }
        self.traversal = traversal;
    }

    /// The still geometry's tree.
    pub fn accel(&self) -> &Accel {
        &self.accel
    }

    /// Replaces the still geometry's tree with `accel` (built from this world's triangles, at
    /// another quality, say), made ready as [`World::new`] makes its own: the hits' records
    /// prefetched, the binary tree freed unless the traversal walks it. Assigned as a bare
    /// field, a tree rendered without the prefetches its rivals had, which a comparison of
    /// trees must not do.
    pub fn set_accel(&mut self, mut accel: Accel) {
        make_ready(&mut accel, &self.scene, self.traversal);
        self.accel = accel;
        // A tree whose binary tree was already freed is built again for a comparison traversal.
        self.set_traversal(self.traversal);
    }

    /// Makes the still tree test its boxes and triangles with `simd`, where this processor
    /// runs it ([`Accel::set_box_simd`]); `false`, changing nothing, where it does not.
    pub fn set_box_simd(&mut self, simd: crate::geometry::BoxSimd) -> bool {
        self.accel.set_box_simd(simd)
    }

    /// The closest hits of a pixel's camera rays `rays` (at most [`crate::geometry::PACKET`])
    /// in the still tree, found together into `hits`, their work counted in `stats`; `false`,
    /// with nothing done, where this world traces them one by one instead (then
    /// [`World::radiance`] finds each). Moving objects are not asked here: each ray's path asks
    /// them after, at the ray's own time (`World::with_moving`).
    pub fn camera_hits(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) -> bool {
        // The traversals kept for comparison walk one ray at a time.
        let together =
            self.camera_rays == CameraRays::Packets && self.traversal == Traversal::Robust;
        if together {
            self.accel.intersect_packet(rays, hits, stats);
        }
        together
    }

    /// The closest hit of `ray` at `moment`, from `still`, its closest hit in the still tree:
    /// the moving objects asked after it, with `CERTAIN` as [`World::closest_certain`] asks
    /// them. Every closest-hit query finishes so, whoever walked the still tree: a single ray's
    /// walk ([`World::closest_from`] with these steps written out), or a camera packet's
    /// ([`World::camera_hits`]), so the hit is the same.
    #[inline(always)]
    pub(super) fn with_moving<const CERTAIN: bool>(
        &self,
        ray: &Ray,
        still: Option<Hit>,
        moment: &Moment,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        if self.motion.is_empty() {
            return still;
        }
        self.motion
            .closest::<CERTAIN>(moment, ray, still, self.traversal, stats)
    }

    /// The closest hit of `ray` at `moment`.
    #[inline(always)]
    pub(super) fn closest(
        &self,
        ray: &Ray,
        moment: &Moment,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        self.closest_from(ray, None, moment, stats)
    }

    /// [`World::closest`], with the still tree's walk set up ahead where `set_up` says so
    /// ([`Accel::intersect_from`](crate::geometry::Accel::intersect_from)).
    #[inline(always)]
    pub(super) fn closest_from(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        moment: &Moment,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        let hit = self
            .accel
            .intersect_from(ray, set_up, self.traversal, stats);
        // `World::with_moving`'s steps written out: called here, in the lanes' and the scalar
        // path's hottest query, it compiled to 0.15 % more instructions on the Cornell box.
        if self.motion.is_empty() {
            return hit;
        }
        self.motion
            .closest::<false>(moment, ray, hit, self.traversal, stats)
    }

    /// The closest hit of `ray` among those a shadow ray must respect (see
    /// [`crate::geometry::Accel::intersect_certain_with`]): `Some` exactly when
    /// [`World::occluded`] says blocked.
    pub(super) fn closest_certain(
        &self,
        ray: &Ray,
        moment: &Moment,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        let hit = self
            .accel
            .intersect_certain_with(ray, self.traversal, stats);
        self.with_moving::<true>(ray, hit, moment, stats)
    }

    /// Whether anything certainly blocks `ray` at `moment`.
    #[inline(always)]
    pub(super) fn occluded(&self, ray: &Ray, moment: &Moment, stats: &mut TraversalStats) -> bool {
        self.occluded_from(ray, None, moment, stats)
    }

    /// [`World::occluded`], with the still tree's walk set up ahead where `set_up` says so.
    #[inline(always)]
    pub(super) fn occluded_from(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        moment: &Moment,
        stats: &mut TraversalStats,
    ) -> bool {
        self.accel.occluded_from(ray, set_up, self.traversal, stats)
            || (!self.motion.is_empty() && self.motion.occluded(moment, ray, self.traversal, stats))
    }

    /// The triangle `hit` names and where it is at `moment`.
    // Inlined: its result, returned through memory, stalled on store forwarding at every
    // hit (docs/bench.md, issue 12, eighth round).
    #[inline(always)]
    pub(super) fn placed<'a>(&'a self, hit: &Hit, moment: &'a Moment) -> Placed<'a> {
        match self.motion.locate(hit.triangle) {
            None => {
                let triangle = &self.scene.triangles[hit.triangle as usize];
                Placed {
                    triangle,
                    attributes: self.scene.attributes.get(hit.triangle as usize),
                    at: SurfacePoint::on_triangle_with_normal(
                        &triangle.p,
                        hit.b1,
                        hit.b2,
                        self.accel.plane_normal(hit.triangle),
                    ),
                    unit_normal: self.accel.unit_normal(hit.triangle),
                    placement: None,
                }
            }
            Some(moving) => self.placed_moving(moving, hit, moment),
        }
    }

    /// [`World::placed`] for a hit on moving triangle `moving`: the lanes' too, which place
    /// only these in their first phase (a still triangle's point is their vector shading's).
    #[inline(always)]
    pub(super) fn placed_moving<'a>(
        &'a self,
        moving: MovingTriangle,
        hit: &Hit,
        moment: &'a Moment,
    ) -> Placed<'a> {
        let at = self.motion.surface(moment, moving, hit);
        let object = &self.scene.moving[moving.object];
        Placed {
            triangle: &object.triangles[moving.triangle],
            attributes: object.attributes.get(moving.triangle),
            at,
            unit_normal: at.normal,
            placement: Some(self.motion.placement(moment, moving.object)),
        }
    }

    /// The local geometry at a hit.
    pub(super) fn surface(&self, ray: &Ray, hit: &Hit, moment: &Moment) -> Surface {
        let Placed {
            triangle,
            attributes,
            at,
            unit_normal: geometric,
            placement,
        } = self.placed(hit, moment);
        Surface {
            at,
            seen: self.shading(ray.dir, hit, attributes, placement, geometric),
            material: triangle.material,
        }
    }

    /// What the surface a ray along `dir` hit (`hit`, on a triangle of unit normal `geometric`
    /// with `attributes`, placed by `placement` where it moves) shows it: its side, its
    /// shading normal and its texture coordinates. [`World::surface`]'s, and the lanes' for
    /// the hits they gather (`lanes/`).
    #[inline(always)]
    pub(super) fn shading(
        &self,
        dir: Vec3,
        hit: &Hit,
        attributes: Option<&VertexAttributes>,
        placement: Option<&Placement>,
        geometric: Vec3,
    ) -> Shading {
        // Normals keep the winding's orientation: the side a ray arrives from is what tells a
        // dielectric whether it is entering or leaving, and an emitter whether it is seen from
        // the front. Reflection-only BSDFs are two-sided by themselves.
        let front_facing = dir.dot(geometric) < 0.0;
        let b0 = 1.0 - hit.b1 - hit.b2;
        let normal = match attributes.and_then(|a| a.n) {
            Some(n) if self.effects.shading_normals => {
                let mut interpolated = b0 * n[0] + hit.b1 * n[1] + hit.b2 * n[2];
                // A moving triangle's normals are in object space; they turn with it.
                if let Some(placement) = placement {
                    interpolated = (placement.normal * interpolated.as_dvec3()).as_vec3();
                }
                let interpolated = interpolated.normalize_or_zero();
                if interpolated == Vec3::ZERO {
                    geometric
                } else if interpolated.dot(geometric) < 0.0 {
                    -interpolated
                } else {
                    interpolated
                }
            }
            _ => geometric,
        };
        // Texture coordinates are only ever read by a texture lookup.
        let uv = attributes
            .and_then(|a| a.uv)
            .filter(|_| self.effects.textures)
            .map(|uv| b0 * uv[0] + hit.b1 * uv[1] + hit.b2 * uv[2]);
        Shading {
            front_facing,
            normal,
            uv,
        }
    }
}

/// Makes `accel`, built from `scene`'s still triangles, ready for a world that walks it by
/// `traversal`: the records every hit reads asked for as the walk keeps a hit
/// ([`Accel::prefetch_at_hits`]); the binary tree freed where only the wide walk runs, else
/// moved onto huge pages. The one preparation every tree a world holds gets.
pub(super) fn make_ready(accel: &mut Accel, scene: &Scene, traversal: Traversal) {
    accel.prefetch_at_hits(&scene.triangles, &scene.attributes);
    if traversal == Traversal::Robust {
        accel.release_binary_tree();
    } else {
        accel.binary_tree_on_huge_pages();
    }
}
