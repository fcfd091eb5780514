//! Rays and their intersection with triangles and the BVH.
//!
//! Contract (see ARCHITECTURE.md): the BVH is *built* by obvhs but *traversed* by our own robust
//! slab test; triangles are intersected with the watertight Woop-Benthin-Wald test; secondary rays
//! leave surfaces offset by a conservative bound of their hit point's rounding error (pbrt-v4).
//! No scene-scale epsilon appears anywhere.
//!
//! - `triangle`: the watertight ray/triangle test ([`intersect_triangle`]).
//! - `offset`: hit points with their error bounds ([`SurfacePoint`]) and where secondary rays
//!   start ([`spawn_ray`], [`OffsetMethod`]).
//! - `bvh`: the [`Accel`] API, and brute force for tests.
//! - `build`: building the tree with obvhs, deterministically and without cracks.
//! - `wide`: the tree of 8-wide nodes, and our robust traversal of it: what renders use.
//! - `collapse`: which binary nodes become 8-wide nodes (least summed surface area, Ylitie et
//!   al. 2017), and the leaves packed for the SIMD tests.
//! - `packet`: up to eight rays that travel side by side (a pixel's camera rays) walked
//!   through the wide tree together, each tested as it would be alone ([`PACKET`]).
//! - `packet_box`: a packet's box tests: one box against eight rays, exactly as each alone,
//!   and a conservative filter of a node's boxes against the interval the rays span.
//! - `packed_hit`: the wide traversal's answer in two registers, so that it reaches the
//!   renderer without a trip through memory.
//! - `leaf`: a leaf's triangles through the SIMD filters (four lanes, or eight with AVX) and
//!   the scalar test on what they leave.
//! - `memory`: the BVH's large arrays on transparent huge pages, where Linux offers them, and
//!   the prefetch hint.
//! - `node8`: the 8-wide node and its box test, in AVX where the processor has it and in SSE
//!   where not, with the same results bit for bit ([`BoxSimd`]).
//! - `quad`: leaves packed four triangles to a group, and the SIMD filter that rejects four at
//!   a time what the watertight test would reject at its first step.
//! - `motion`: moving objects, each in its own tree in object space, under a tree of the
//!   boxes swept over their keyframe segments; rays taken into object space at their time, and
//!   hits brought back with error bounds that keep spawned rays off the surface
//!   ([`MotionAccel`], [`placed_point`]).
//! - `quad_avx`: the same filter on two groups at once in AVX's eight lanes, where the
//!   processor has them, with the same results bit for bit.
//! - `ray_setup`: what the wide traversals make of their rays first: one ray's box set-up, and
//!   a packet's rays gathered into rows (with AVX, transposed in registers).
//! - `traverse`: the same robust traversal over the binary tree, and obvhs's own, for
//!   comparison ([`Traversal`]).

mod build;
mod bvh;
mod closest;
mod collapse;
mod leaf;
mod memory;
mod motion;
mod node8;
mod offset;
mod packed_hit;
mod packet;
mod packet_box;
mod quad;
#[cfg(target_arch = "x86_64")]
mod quad_avx;
mod ray_setup;
mod traverse;
mod triangle;
mod wide;

pub use bvh::{Accel, BuildQuality, Traversal};
pub use closest::{intersect_brute_force, occluded_brute_force};
pub(crate) use memory::{on_huge_pages, prefetch, release_freed_memory};
pub use motion::{
    Moment, MotionAccel, MovingTriangle, object_normal, placed_normal, placed_point,
    placed_point_with_normal,
};
pub use offset::{
    OffsetMethod, SurfacePoint, hit_point, offset_ray_origin, plane_normal, spawn_ray, spawn_ray_to,
};
pub use packet::PACKET;
pub(crate) use ray_setup::SetUpRows;
pub(crate) use triangle::gamma;
pub use triangle::{TriangleHit, intersect_triangle, is_degenerate};
pub use wide::BoxSimd;
pub(crate) use wide::SetUp;

use glam::Vec3;

/// A ray segment `origin + t * dir` for `t` in `(0, t_max)`. Laid out as C would, seven f32
/// in this order, which the packets' AVX gather reads four at a time (`ray_setup.rs`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Ray {
    /// Where the segment starts, in world space (already offset off any surface it leaves).
    pub origin: Vec3,
    /// Its direction; not necessarily unit length, and `t` is measured in its units.
    pub dir: Vec3,
    /// The end of the segment, exclusive; infinite for rays that may escape.
    pub t_max: f32,
}

impl Ray {
    /// This ray, its seven floats read one at a time (see [`read_apart`]): what a single-ray
    /// walk starts from. Its callers write a ray a float at a time just before the walk (a
    /// lane's shadow ray and next ray are gathered from the lanes' rows), and the walk's
    /// set-up read two neighbouring floats with one eight-byte load.
    #[inline(always)]
    pub(crate) fn read_apart(&self) -> Ray {
        let (o, d) = (&self.origin, &self.dir);
        Ray {
            origin: Vec3::new(read_apart(&o.x), read_apart(&o.y), read_apart(&o.z)),
            dir: Vec3::new(read_apart(&d.x), read_apart(&d.y), read_apart(&d.z)),
            t_max: read_apart(&self.t_max),
        }
    }
}

/// What fills a ray slot that holds no ray yet (a packet's past its samples, an idle lane's):
/// an empty segment, never traced.
pub(crate) const UNUSED_RAY: Ray = Ray {
    origin: Vec3::ZERO,
    dir: Vec3::Z,
    t_max: 0.0,
};

/// The closest hit of a ray: distance, triangle index and barycentrics of vertices 1 and 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The distance along the ray, in units of its direction.
    pub t: f32,
    /// The triangle: an index into the still triangles, or past them into the moving objects'
    /// (numbered in object order, as the lights number them).
    pub triangle: u32,
    /// The barycentric coordinate of vertex 1.
    pub b1: f32,
    /// The barycentric coordinate of vertex 2.
    pub b2: f32,
}

impl Hit {
    /// This hit, its four fields read one at a time (see [`read_apart`]): for a hit that was
    /// just written as the walk's two eight-byte halves, or field by field, and would be read
    /// back whole.
    #[inline(always)]
    pub(crate) fn read_apart(&self) -> Hit {
        Hit {
            t: read_apart(&self.t),
            triangle: read_apart(&self.triangle),
            b1: read_apart(&self.b1),
            b2: read_apart(&self.b2),
        }
    }
}

/// A field read by a load of its own, never merged with its neighbours' into one
/// wider load. Where a value was written by narrow stores just before it is read, a wider
/// load spanning two of them cannot be forwarded from the processor's store buffer: it waits
/// until both stores reach the cache, a stall of a dozen cycles or more that showed at the
/// start of every walk (docs/bench.md, issue 12, thirty-third round). A load no wider than the
/// stores is always forwarded. A volatile read is the one way to keep the compiler from
/// merging loads; it is an ordinary load of an initialised value, so the bits are the same.
#[inline(always)]
fn read_apart<T: Copy>(value: &T) -> T {
    // SAFETY: `value` is a reference: valid, aligned and initialised for a read of a `T`.
    unsafe { std::ptr::read_volatile(value) }
}

/// Counted traversal work: the deterministic cost measure of a tile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalStats {
    /// Bounding boxes tested against a ray: the root, then both children of every inner node
    /// opened.
    pub nodes: u64,
    /// Ray/triangle tests.
    pub triangles: u64,
}
