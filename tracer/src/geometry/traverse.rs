//! Walking the tree: our robust traversal, and obvhs's own for comparison.
//!
//! The robust slab test follows Ize ("Robust BVH Ray Traversal", JCGT 2013) as pbrt-v4 does:
//! - The reciprocal direction is the IEEE `1 / d`, so a `+0.0` or `-0.0` component gives `+inf`
//!   or `-inf` and the slab on that axis is either everything or nothing, as it should be. (obvhs
//!   replaces small components by `±1/EPSILON`, which is a different ray.)
//! - When the origin lies exactly on a slab plane of such an axis, `0 * inf` is NaN. The ray then
//!   lies in the plane, inside the slab's closure, so a NaN must constrain nothing: the min and
//!   max below are written as explicit comparisons so that a NaN operand is dropped on every
//!   platform (glam leaves NaN handling of `min`/`max` unspecified).
//! - The far distance is multiplied by `1 + 2 gamma(3)`, which covers the rounding of both slab
//!   distances, so rounding alone never culls a box the ray passes through.
//!
//! Closest-hit traversal visits the nearer child first and culls boxes beyond the closest hit
//! found so far, widened by the same factor, so that a box holding a triangle at the same `t` (up
//! to rounding) is still opened and the tie rule of [`Closest::offer`] decides, as in brute force.
//!
//! Costs are counted in [`TraversalStats`]: `nodes` is the number of boxes tested (the root and
//! both children of every inner node opened), `triangles` the number of triangle tests.

use super::bvh::{Accel, BinaryTree};
use super::closest::Closest;
use super::triangle::{ShearedRay, gamma};
use super::{Hit, Ray, TraversalStats};
use glam::{BVec3A, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::ray::RayHit;

/// Widening of far slab distances (and of the culling distance) for rounding: `1 + 2 gamma(3)`.
pub(super) const FAR_SCALE: f32 = 1.0 + 2.0 * gamma(3);
const _: () = assert!(
    FAR_SCALE > 1.0 && FAR_SCALE < 1.0 + 1e-6,
    "a few ULPs of widening"
);

/// Stack entries held in place before falling back to the heap; trees built by obvhs on real
/// scenes are far shallower (the 871k-triangle dragon is under 40 levels).
const INLINE_STACK: usize = 64;

/// A ray prepared for slab tests: the binary tree's walk, and the moving objects' swept boxes
/// (`motion/bounds.rs`), test their boxes through it.
pub(super) struct SlabRay {
    origin: Vec3A,
    inv_dir: Vec3A,
    /// Lanes whose direction is negative (including -0.0), whose near plane is the box's max.
    negative: BVec3A,
}

impl SlabRay {
    pub(super) fn new(ray: &Ray) -> Self {
        let inv_dir = Vec3A::ONE / Vec3A::from(ray.dir);
        SlabRay {
            origin: ray.origin.into(),
            inv_dir,
            negative: inv_dir.cmplt(Vec3A::ZERO),
        }
    }

    /// The entry distance into `aabb` if the ray passes through it within `(0, t_max]`.
    #[inline(always)]
    fn enter(&self, aabb: &Aabb, t_max: f32) -> Option<f32> {
        self.enter_box(aabb.min, aabb.max, t_max)
    }

    /// [`SlabRay::enter`] for the box from `min` to `max`.
    #[inline(always)]
    pub(super) fn enter_box(&self, min: Vec3A, max: Vec3A, t_max: f32) -> Option<f32> {
        let near_plane = Vec3A::select(self.negative, max, min);
        let far_plane = Vec3A::select(self.negative, min, max);
        let near = (near_plane - self.origin) * self.inv_dir;
        let far = (far_plane - self.origin) * self.inv_dir * FAR_SCALE;
        // `a > b ? a : b` keeps b when a is NaN; likewise for the minimum.
        let zero = Vec3A::ZERO;
        let t0 = Vec3A::select(near.cmpgt(zero), near, zero).max_element();
        let end = Vec3A::splat(t_max);
        let t1 = Vec3A::select(far.cmplt(end), far, end).min_element();
        (t0 <= t1).then_some(t0)
    }
}

#[derive(Clone, Copy, Default)]
struct StackEntry {
    node: u32,
    t_near: f32,
}

impl Accel {
    /// Closest hit (or, with `ANY_HIT`, the first hit found) by our robust traversal.
    #[inline(never)]
    pub(super) fn traverse_robust<const ANY_HIT: bool, const CERTAIN: bool>(
        &self,
        ray: &Ray,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        if self.binary_tree().bvh.nodes.is_empty() {
            return None;
        }
        if self.depth <= INLINE_STACK {
            let mut stack = [StackEntry::default(); INLINE_STACK];
            self.robust_with_stack::<ANY_HIT, CERTAIN>(ray, stats, &mut stack)
        } else {
            let mut stack = vec![StackEntry::default(); self.depth];
            self.robust_with_stack::<ANY_HIT, CERTAIN>(ray, stats, &mut stack)
        }
    }

    /// The traversal proper. `stack` must hold `depth - 1` entries: each level of the current
    /// path pushes at most one far child.
    ///
    /// As in obvhs, a child that is a leaf is tested as soon as its box is hit rather than
    /// descended into later: large triangles high in the tree (walls, floors) then bound the
    /// search, or end an any-hit query, before any deeper subtree is opened.
    #[inline(always)]
    fn robust_with_stack<const ANY_HIT: bool, const CERTAIN: bool>(
        &self,
        ray: &Ray,
        stats: &mut TraversalStats,
        stack: &mut [StackEntry],
    ) -> Option<Hit> {
        let tree = self.binary_tree();
        let nodes = &tree.bvh.nodes;
        let slab = SlabRay::new(ray);
        let sheared = ShearedRay::new(ray);
        let mut closest = Closest::new(ray, CERTAIN);
        let cull = |closest: &Closest| closest.t_max() * FAR_SCALE;

        stats.nodes += 1;
        slab.enter(nodes[0].aabb(), cull(&closest))?;
        if nodes[0].is_leaf() {
            tree.intersect_leaf::<ANY_HIT>(&nodes[0], &sheared, &mut closest, stats);
            return closest.best;
        }
        // From here on `node` is always an inner node.
        let mut node: &Bvh2Node = &nodes[0];
        let mut len = 0;
        loop {
            let first = node.first_index as usize;
            stats.nodes += 2;
            let limit = cull(&closest);
            let t_left = slab.enter(nodes[first].aabb(), limit);
            let t_right = slab.enter(nodes[first + 1].aabb(), limit);
            let right_first = matches!((t_left, t_right), (Some(l), Some(r)) if r < l);
            let order = if right_first {
                [(first + 1, t_right), (first, t_left)]
            } else {
                [(first, t_left), (first + 1, t_right)]
            };
            let mut next = None;
            for (index, t_near) in order {
                let Some(t_near) = t_near else { continue };
                let child = &nodes[index];
                if child.is_leaf() {
                    // The near leaf may have moved the closest hit in front of this one.
                    if t_near <= cull(&closest)
                        && tree.intersect_leaf::<ANY_HIT>(child, &sheared, &mut closest, stats)
                        && ANY_HIT
                    {
                        return closest.best;
                    }
                } else if next.is_none() {
                    next = Some(child);
                } else {
                    stack[len] = StackEntry {
                        node: index as u32,
                        t_near,
                    };
                    len += 1;
                }
            }
            if let Some(child) = next {
                node = child;
                continue;
            }
            // Resume at the nearest postponed box that may still hold a closer hit.
            loop {
                if len == 0 {
                    return closest.best;
                }
                len -= 1;
                let entry = stack[len];
                if entry.t_near <= cull(&closest) {
                    node = &nodes[entry.node as usize];
                    break;
                }
            }
        }
    }

    /// Closest hit (or, with `ANY_HIT`, the first hit found) by obvhs's traversal, ray and
    /// Moller-Trumbore test. Barycentrics are computed for the winner with the same formulas.
    #[inline(never)]
    pub(super) fn traverse_obvhs<const ANY_HIT: bool>(
        &self,
        ray: &Ray,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        let tree = self.binary_tree();
        if tree.bvh.nodes.is_empty() {
            return None;
        }
        let obvhs_ray = obvhs::ray::Ray::new(ray.origin.into(), ray.dir.into(), 0.0, ray.t_max);
        let mut hit = RayHit::none();
        let mut leaf = |node: &Bvh2Node, r: &mut obvhs::ray::Ray, hit: &mut RayHit| {
            stats.nodes += 1;
            for k in node.first_index..node.first_index + node.prim_count {
                stats.triangles += 1;
                let t = tree.obvhs_triangle(k as usize).intersect(r);
                if t < r.tmax {
                    hit.primitive_id = k;
                    hit.t = t;
                    r.tmax = t;
                    if ANY_HIT {
                        return false;
                    }
                }
            }
            true
        };
        obvhs::fast_stack!(u32, (96, 192), tree.bvh.max_depth, stack, {
            tree.bvh
                .ray_traverse_dynamic(&mut stack, obvhs_ray, &mut hit, &mut leaf)
        });
        if hit.primitive_id == obvhs::ray::INVALID_ID {
            return None;
        }
        let k = hit.primitive_id as usize;
        let (b1, b2) = moller_trumbore_barycentrics(&tree.obvhs_triangle(k), &obvhs_ray);
        Some(Hit {
            t: hit.t,
            triangle: tree.original[k],
            b1,
            b2,
        })
    }
}

impl BinaryTree {
    /// Tests the triangles of a leaf; returns whether any became the closest hit (with
    /// `ANY_HIT`, stops at the first).
    #[inline(always)]
    fn intersect_leaf<const ANY_HIT: bool>(
        &self,
        leaf: &Bvh2Node,
        sheared: &ShearedRay,
        closest: &mut Closest,
        stats: &mut TraversalStats,
    ) -> bool {
        let first = leaf.first_index as usize;
        let mut found = false;
        for k in first..first + leaf.prim_count as usize {
            stats.triangles += 1;
            if closest.offer(sheared, &self.vertices[k], self.original[k]) {
                found = true;
                if ANY_HIT {
                    break;
                }
            }
        }
        found
    }

    fn obvhs_triangle(&self, k: usize) -> obvhs::triangle::Triangle {
        let [v0, v1, v2] = self.vertices[k].map(Vec3A::from);
        obvhs::triangle::Triangle { v0, v1, v2 }
    }
}

/// The barycentrics of vertices 1 and 2 as obvhs's `Triangle::intersect` computes them (its `u`
/// and `v`); obvhs's own `compute_barycentric` divides by a normalised normal and is not used.
fn moller_trumbore_barycentrics(
    tri: &obvhs::triangle::Triangle,
    ray: &obvhs::ray::Ray,
) -> (f32, f32) {
    let e1 = tri.v0 - tri.v1;
    let e2 = tri.v2 - tri.v0;
    let n = e1.cross(e2);
    let r = ray.direction.cross(tri.v0 - ray.origin);
    let inv_det = 1.0 / n.dot(ray.direction);
    (r.dot(e2) * inv_det, r.dot(e1) * inv_det)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn slab(origin: Vec3, dir: Vec3) -> SlabRay {
        SlabRay::new(&Ray {
            origin,
            dir,
            t_max: f32::INFINITY,
        })
    }

    const UNIT_BOX: Aabb = Aabb {
        min: Vec3A::ZERO,
        max: Vec3A::ONE,
    };

    #[test]
    fn signed_zero_directions_select_the_slab_or_nothing() {
        for zero in [0.0, -0.0] {
            let dir = Vec3::new(zero, zero, 1.0);
            assert_eq!(
                slab(Vec3::new(0.5, 0.5, -2.0), dir).enter(&UNIT_BOX, 10.0),
                Some(2.0)
            );
            assert_eq!(
                slab(Vec3::new(1.5, 0.5, -2.0), dir).enter(&UNIT_BOX, 10.0),
                None
            );
            assert_eq!(
                slab(Vec3::new(-0.5, 0.5, -2.0), dir).enter(&UNIT_BOX, 10.0),
                None
            );
        }
    }

    #[test]
    fn an_origin_on_a_slab_plane_with_a_zero_component_is_inside_not_nan() {
        // (min - o) * inf = 0 * inf = NaN on x; the ray runs along the face x = 0 and x = 1.
        for x in [0.0, 1.0] {
            for zero in [0.0, -0.0] {
                let s = slab(Vec3::new(x, 0.5, -2.0), Vec3::new(zero, 0.0, 1.0));
                assert_eq!(
                    s.enter(&UNIT_BOX, 10.0),
                    Some(2.0),
                    "x = {x}, dir.x = {zero}"
                );
            }
        }
        // A flat box (min = max on x) containing the ray's plane.
        let flat = Aabb {
            min: Vec3A::new(1.0, 0.0, 0.0),
            max: Vec3A::new(1.0, 1.0, 1.0),
        };
        let s = slab(Vec3::new(1.0, 0.5, -2.0), Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(s.enter(&flat, 10.0), Some(2.0));
    }

    #[test]
    fn a_ray_grazing_an_edge_hits_and_boxes_outside_the_range_miss() {
        // The ray touches the box along its edge x = 0, y = 1: t_near == t_far.
        let s = slab(Vec3::new(-1.0, 0.0, 0.5), Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(s.enter(&UNIT_BOX, 10.0), Some(1.0));
        // A box entirely behind the origin or beyond t_max is missed.
        assert_eq!(s.enter(&UNIT_BOX, 0.5), None);
        let behind = slab(Vec3::new(2.0, 0.5, 0.5), Vec3::X);
        assert_eq!(behind.enter(&UNIT_BOX, 10.0), None);
    }

    #[test]
    fn the_origin_inside_a_box_enters_at_zero() {
        let s = slab(Vec3::splat(0.5), Vec3::new(0.3, -0.2, 0.9));
        assert_eq!(s.enter(&UNIT_BOX, f32::INFINITY), Some(0.0));
    }
}
