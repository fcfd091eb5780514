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
//! Above the objects sit world-space boxes, one per object and keyframe segment, each holding
//! the object wherever the segment's interpolation puts it (see [`swept_bounds`]). A ray tests
//! the box of its time's segment before it pays for the transform. Up to eight objects it
//! tests each object's in turn; beyond, a tree over the boxes (`tree.rs`) finds those it may
//! meet, so rays far from the moving objects cost a few box tests however many there are, and
//! beyond sixteen a path places an object only when one of its rays or light samples needs it
//! ([`Moment`]).
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
use bounds::{SweptBox, SweptRay, swept_bounds, to_object};
pub use bounds::{object_normal, placed_normal, placed_point, placed_point_with_normal};
use elsa::FrozenMap;
use glam::{DVec3, Vec3};
use std::cell::Cell;
use std::collections::hash_map::DefaultHasher;
use std::hash::BuildHasherDefault;
use tree::{Candidates, ObjectTree};

mod bounds;
#[cfg(test)]
mod tests;
mod tree;

/// The moving objects of a scene, each with its own tree, and their swept bounds.
#[derive(Clone, Debug, Default)]
pub struct MotionAccel {
    objects: Vec<Mover>,
    /// Over every object's swept boxes: which objects a ray may meet.
    tree: ObjectTree,
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
    /// Their unit plane normals ([`object_normal`]), by the same index.
    normals: Vec<DVec3>,
    /// Per keyframe segment: the world box holding the object anywhere in the segment.
    bounds: Vec<SweptBox>,
    /// This object's first triangle among all moving triangles.
    offset: u32,
}

/// The moving objects at one time: what a path's rays share. A scene of a few objects places
/// them all when the path starts; a scene of more places each when first needed and keeps it
/// for the rest of the path. A placement is a pure function of the time, so when it is
/// computed changes no bit.
#[derive(Clone, Debug, Default)]
pub struct Moment<'a> {
    motion: Option<&'a MotionAccel>,
    time: f64,
    placements: Placements,
}

/// A path's placements.
#[derive(Clone)]
enum Placements {
    /// For a few objects, every one's segment and placement, computed as the path starts:
    /// independent of what its rays find, that work overlaps the first traversal, where
    /// computed on first use it waited on it (10 % slower paths on `cornell-blur`).
    All(Vec<(usize, Placement)>),
    /// For more, only those the path meets, by object: a cell per object would cost every
    /// path its setting up and dropping, which a scene of 512 objects measured at a quarter
    /// of its render's instructions.
    Met(FrozenMap<u32, Box<Placement>, BuildHasherDefault<DefaultHasher>>),
}

impl std::fmt::Debug for Placements {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Placements::All(all) => f.debug_list().entries(all).finish(),
            Placements::Met(_) => f.write_str("the placements met"),
        }
    }
}

thread_local! {
    /// The buffer of the last path on this thread that placed every object, handed back when
    /// its [`Moment`] is dropped and filled again by the next: a path of a few moving objects
    /// then allocates nothing (an allocation and a free per path; `cornell-blur` runs 0.9 %
    /// fewer instructions without them). Every slot of a buffer is written over before the
    /// next path reads it, so no value crosses paths.
    static SPARE_PLACEMENTS: Cell<Vec<(usize, Placement)>> = const { Cell::new(Vec::new()) };
}

impl Drop for Moment<'_> {
    fn drop(&mut self) {
        if let Placements::All(all) = &mut self.placements
            && all.capacity() > 0
        {
            // `try_with`: while the thread's locals are being torn down the buffer is simply
            // freed.
            let all = std::mem::take(all);
            let _ = SPARE_PLACEMENTS.try_with(|spare| spare.set(all));
        }
    }
}

impl Default for Placements {
    fn default() -> Self {
        Placements::All(Vec::new())
    }
}

/// Most objects a path places as it starts ([`Placements::All`]).
const PLACED_AT_START: usize = 16;
const _: () = assert!(tree::FLAT_OBJECTS <= PLACED_AT_START);

/// Where a ray met a moving object: which object and which of its triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MovingTriangle {
    /// The moving object, an index into `Scene::moving`.
    pub object: usize,
    /// The triangle, an index into that object's own triangles (in object space).
    pub triangle: usize,
}

impl<'a> Moment<'a> {
    /// The placement of moving object `object` (its index in `Scene::moving`) at this moment:
    /// where light sampling finds a moving emitter ([`crate::lights`]).
    pub fn placement(&self, object: usize) -> &Placement {
        match &self.placements {
            Placements::All(all) => &all[object].1,
            Placements::Met(map) => {
                let key = object as u32;
                match map.get(&key) {
                    Some(placement) => placement,
                    None => {
                        let motion = self
                            .motion
                            .expect("a moment that places lazily was made by MotionAccel::moment");
                        map.insert(key, Box::new(motion.objects[object].track.at(self.time)))
                    }
                }
            }
        }
    }

    /// The accelerator this moment places the objects of, where it has moving objects.
    pub fn motion(&self) -> Option<&'a MotionAccel> {
        self.motion
    }

    /// Every object's segment and placement, where the path placed them all as it started:
    /// always where there is no tree (`tree::FLAT_OBJECTS` is at most [`PLACED_AT_START`]).
    fn all(&self) -> &[(usize, Placement)] {
        match &self.placements {
            Placements::All(all) => all,
            Placements::Met(_) => unreachable!("a scene without a tree places every object"),
        }
    }

    /// The keyframe segment of object `object` at this moment.
    fn segment(&self, motion: &MotionAccel, object: usize) -> usize {
        match &self.placements {
            Placements::All(all) => all[object].0,
            Placements::Met(_) => motion.objects[object].track.segment(self.time),
        }
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
                    normals: vertices.iter().map(object_normal).collect(),
                    vertices,
                    offset,
                };
                offset += u32::try_from(object.triangles.len())
                    .expect("fewer than 2^32 triangles: Hit::triangle is a u32");
                mover
            })
            .collect::<Vec<Mover>>();
        let tree = ObjectTree::build(objects.iter().map(|o| (&o.track, &o.bounds[..])));
        MotionAccel {
            objects,
            tree,
            first,
        }
    }

    /// Whether there is anything that moves.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// The objects at `time` (frames), for the rays of one path.
    pub fn moment(&self, time: f64) -> Moment<'_> {
        Moment {
            motion: Some(self),
            time,
            placements: if self.objects.len() <= PLACED_AT_START {
                let mut all = SPARE_PLACEMENTS.take();
                all.resize(self.objects.len(), (0, Placement::IDENTITY));
                self.place_all(&mut all, time);
                Placements::All(all)
            } else {
                Placements::Met(FrozenMap::default())
            },
        }
    }

    /// [`MotionAccel::moment`] at `time`, written over `moment`: where `moment` is one of this
    /// accelerator's that placed every object (the last path's, in the same lane), each
    /// placement in place, the buffer neither given back to the thread nor taken again (the
    /// lanes start a path every few rays, and the thread-local round trip took a third of
    /// `moment`'s time on `cornell-blur`); else a new moment.
    pub fn move_to<'a>(&'a self, moment: &mut Moment<'a>, time: f64) {
        match &mut moment.placements {
            Placements::All(all)
                if moment.motion.is_some_and(|m| std::ptr::eq(m, self))
                    && all.len() == self.objects.len() =>
            {
                moment.time = time;
                self.place_all(all, time);
            }
            _ => {
                // The old moment's buffer goes back to the thread first, for the new one.
                *moment = Moment::default();
                *moment = self.moment(time);
            }
        }
    }

    /// Every object's segment and placement at `time` into `all`, a slot per object: every
    /// slot written over, in place (`TransformTrack::place_in`), where collected afresh, each
    /// placement (240 bytes) was built aside and copied in. Each slot's segment is looked for
    /// first where the slot's last placement was (`TransformTrack::segment_near`).
    fn place_all(&self, all: &mut [(usize, Placement)], time: f64) {
        for ((segment, placed), o) in all.iter_mut().zip(&self.objects) {
            *segment = o.track.segment_near(*segment, time);
            o.track.place_in(*segment, time, placed);
        }
    }

    /// The objects whose box of their segment at `moment` `ray` may meet before `t_max`, with
    /// that segment, in object order: the order a flat list of their boxes would try them in.
    fn candidates(
        &self,
        moment: &Moment,
        ray: &SweptRay,
        t_max: f32,
        tested: &mut u64,
    ) -> Candidates {
        let mut found = Candidates::new();
        let segment_of = |object| moment.segment(self, object);
        let gather = |object, segment| {
            found.push((object, segment));
            t_max
        };
        self.tree
            .walk(ray, t_max, moment.time, segment_of, gather, tested);
        found.sort_unstable();
        found
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
    ///
    /// The objects used to be tried in turn, each up to the closest hit so far, exclusive: of
    /// equally close hits the first tried stayed, the still geometry's before any object's,
    /// and an object's of lower index before a later one's (as within one tree). That is the
    /// hit of least distance, then least triangle index, which the walk of the tree finds in
    /// any order: an object numbered before the best hit's triangle searches up to and
    /// including its distance. A certain query's result depends on the order itself (its first
    /// hit must be certain, the later ones need not be), so its candidates are gathered and
    /// tried in object order, as are all objects where there are too few for a tree, and the
    /// candidates of obvhs's comparison traversal (below).
    pub fn closest<const CERTAIN: bool>(
        &self,
        moment: &Moment,
        ray: &Ray,
        mut best: Option<Hit>,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        let mut tested = 0;
        // The ray's set-up for the boxes' tests, once for all of them.
        let swept = SweptRay::new(ray);
        if self.tree.is_flat() {
            for (mover, (segment, placement)) in self.objects.iter().zip(moment.all()) {
                let at = (mover, *segment, || placement);
                self.try_in_order::<CERTAIN>((ray, &swept), at, &mut best, traversal, stats);
            }
        } else if CERTAIN || traversal == Traversal::Obvhs {
            // obvhs's traversal (a comparison knob) culls a box whose entry is not strictly
            // before `t_max`, unpadded: searched up to just past the best distance, an object
            // may lose a tie it wins in order, so it too is tried in order.
            let limit = best.map_or(ray.t_max, |h| h.t);
            for (object, segment) in self.candidates(moment, &swept, limit, &mut tested) {
                let (object, segment) = (object as usize, segment as usize);
                let at = (&self.objects[object], segment, || moment.placement(object));
                self.try_in_order::<CERTAIN>((ray, &swept), at, &mut best, traversal, stats);
            }
        } else {
            // The box test passes a box whose near side is at `t_max` itself, so testing at
            // the best distance admits the objects that may tie with the best hit too.
            let bound = |best: &Option<Hit>| best.map_or(ray.t_max, |h| h.t);
            let start = bound(&best);
            let segment_of = |object| moment.segment(self, object);
            let visit = |object: u32, _| {
                let first = self.first + self.objects[object as usize].offset;
                let t_max = match best {
                    None => ray.t_max,
                    Some(h) if first < h.triangle => h.t.next_up(),
                    Some(h) => h.t,
                };
                let query = |accel: &Accel, local: &Ray, stats: &mut TraversalStats| {
                    accel.intersect_with(local, traversal, stats)
                };
                let object = object as usize;
                let at = (&self.objects[object], moment.placement(object));
                best = nearest(best, self.hit_on(at, ray, t_max, query, stats));
                bound(&best)
            };
            self.tree
                .walk(&swept, start, moment.time, segment_of, visit, &mut tested);
        }
        stats.nodes += tested;
        best
    }

    /// One step of trying the objects in order, as the flat list did: the object of `mover`,
    /// its box of `segment` and its `placement` (asked for only once the box is passed), tried
    /// up to the closest hit so far, exclusive, with a certain query while there is none under
    /// `CERTAIN`.
    #[inline(always)]
    fn try_in_order<'p, const CERTAIN: bool>(
        &self,
        (ray, swept): (&Ray, &SweptRay),
        (mover, segment, placement): (&Mover, usize, impl FnOnce() -> &'p Placement),
        best: &mut Option<Hit>,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) {
        // An object that cannot hold a closer hit is not transformed into.
        let t_max = best.map_or(ray.t_max, |h| h.t);
        stats.nodes += 1;
        if !mover.bounds[segment].may_hit(swept, t_max) {
            return;
        }
        let first = CERTAIN && best.is_none();
        let query = |accel: &Accel, local: &Ray, stats: &mut TraversalStats| {
            if first {
                accel.intersect_certain_with(local, traversal, stats)
            } else {
                accel.intersect_with(local, traversal, stats)
            }
        };
        *best = nearest(
            *best,
            self.hit_on((mover, placement()), ray, t_max, query, stats),
        );
    }

    /// The hit `query` finds on a moving object's tree before `t_max`, `ray` taken into its
    /// space by `placement`, numbered among all triangles.
    fn hit_on(
        &self,
        (mover, placement): (&Mover, &Placement),
        ray: &Ray,
        t_max: f32,
        query: impl FnOnce(&Accel, &Ray, &mut TraversalStats) -> Option<Hit>,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        let local = Ray {
            t_max,
            ..to_object(placement, ray)
        };
        query(&mover.accel, &local, stats).map(|hit| Hit {
            triangle: self.first + mover.offset + hit.triangle,
            ..hit
        })
    }

    /// Whether any moving object at `moment` is certainly hit in `(0, ray.t_max)`.
    #[inline]
    pub fn occluded(
        &self,
        moment: &Moment,
        ray: &Ray,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> bool {
        // Any object certainly hit will do: the answer does not depend on the order, and once
        // one is found a bound below zero ends the walk.
        let mut blocked = false;
        let mut tested = 0;
        let swept = SweptRay::new(ray);
        if self.tree.is_flat() {
            for (mover, (segment, placement)) in self.objects.iter().zip(moment.all()) {
                stats.nodes += 1;
                if mover.bounds[*segment].may_hit(&swept, ray.t_max)
                    && mover
                        .accel
                        .occluded_with(&to_object(placement, ray), traversal, stats)
                {
                    return true;
                }
            }
            return false;
        }
        let segment_of = |object| moment.segment(self, object);
        let visit = |object: u32, _| {
            let local = to_object(moment.placement(object as usize), ray);
            blocked = self.objects[object as usize]
                .accel
                .occluded_with(&local, traversal, stats);
            if blocked {
                f32::NEG_INFINITY
            } else {
                ray.t_max
            }
        };
        self.tree.walk(
            &swept,
            ray.t_max,
            moment.time,
            segment_of,
            visit,
            &mut tested,
        );
        stats.nodes += tested;
        blocked
    }

    /// The world-space hit point of `hit` on moving triangle `at`, with its bound and the
    /// origins rays leaving it start from ([`placed_point`]); its `normal` is the triangle's
    /// unit winding normal in the world (the side it faces, as [`Accel::unit_normal`] gives for
    /// still triangles).
    pub fn surface(&self, moment: &Moment, at: MovingTriangle, hit: &Hit) -> SurfacePoint {
        let (v, normal) = self.triangle(at);
        placed_point_with_normal(moment.placement(at.object), v, normal, hit.b1, hit.b2)
    }

    /// Moving triangle `at`'s object-space corners and unit plane normal ([`object_normal`]).
    pub fn triangle(&self, at: MovingTriangle) -> (&[Vec3; 3], DVec3) {
        let mover = &self.objects[at.object];
        (&mover.vertices[at.triangle], mover.normals[at.triangle])
    }

    /// The placement of object `object` at `moment`: for shading normals.
    pub fn placement<'a>(&self, moment: &'a Moment, object: usize) -> &'a Placement {
        moment.placement(object)
    }
}

/// Of two hits, the one first by distance, then by triangle index.
fn nearest(best: Option<Hit>, hit: Option<Hit>) -> Option<Hit> {
    match (best, hit) {
        (Some(b), Some(h)) if (h.t, h.triangle) < (b.t, b.triangle) => Some(h),
        (Some(b), _) => Some(b),
        (None, h) => h,
    }
}
