//! The closest-hit rule every traversal keeps ([`Closest`]: strictly closer, or as close with
//! a lower triangle index, so that the hit does not depend on the order triangles are tested
//! in), and brute force over all triangles by that rule: the reference the trees are tested
//! against.

use super::triangle::{ShearedRay, TriangleHit, is_degenerate};
use super::{Hit, Ray};
use crate::scene::Triangle;
use glam::Vec3;

/// The closest hit of `ray` among all `triangles`, testing every one: the reference the BVH is
/// tested against. Same triangle test and tie rule as [`Accel::intersect`](super::Accel::intersect).
pub fn intersect_brute_force(triangles: &[Triangle], ray: &Ray) -> Option<Hit> {
    brute_force::<false>(triangles, ray)
}

/// Whether any of `triangles` is certainly hit, as [`Accel::occluded`](super::Accel::occluded) decides, testing every
/// one: the reference for occlusion queries.
pub fn occluded_brute_force(triangles: &[Triangle], ray: &Ray) -> bool {
    brute_force::<true>(triangles, ray).is_some()
}

fn brute_force<const ANY_HIT: bool>(triangles: &[Triangle], ray: &Ray) -> Option<Hit> {
    let sheared = ShearedRay::new(ray);
    let mut closest = Closest::new(ray, ANY_HIT);
    for (i, triangle) in triangles.iter().enumerate() {
        if !is_degenerate(&triangle.p) {
            closest.offer(&sheared, &triangle.p, i as u32);
        }
    }
    closest.best
}

/// The closest hit found so far, and the rule by which a new hit replaces it.
#[derive(Clone, Copy)]
pub(super) struct Closest {
    pub(super) best: Option<Hit>,
    /// The end of the search interval: `best`'s `t`, or the ray's own `t_max` while there is
    /// no hit. Kept beside `best` rather than read from it, which cost a test of the option at
    /// every node a traversal culls against it.
    t_max: f32,
    ray_t_max: f32,
    /// For occlusion queries: a hit counts only if its `t` plus its error bound is below the
    /// ray's `t_max` (see [`Accel::occluded`](super::Accel::occluded)).
    certain: bool,
}

impl Closest {
    pub(super) fn new(ray: &Ray, certain: bool) -> Self {
        Closest {
            best: None,
            t_max: ray.t_max,
            ray_t_max: ray.t_max,
            certain,
        }
    }

    /// The current end of the search interval: the best `t`, or the ray's own `t_max`.
    #[inline(always)]
    pub(super) fn t_max(&self) -> f32 {
        self.t_max
    }

    /// Tests one triangle and keeps its hit if closer; returns whether it was kept. A hit
    /// replaces the best one when strictly closer, or equally close with a lower triangle
    /// index, so the result does not depend on the order triangles are tested in. The ray's own
    /// `t_max` is exclusive.
    #[inline(always)]
    pub(super) fn offer(&mut self, sheared: &ShearedRay, p: &[Vec3; 3], triangle: u32) -> bool {
        let Some(h) = sheared.intersect(p, self.t_max()) else {
            return false;
        };
        self.keep(h, triangle)
    }

    /// [`Closest::offer`] for a hit already computed, up to the triangle test's final
    /// `t <= t_max` check, which is made here against the same `t_max` that `offer` passes.
    #[inline(always)]
    pub(super) fn offer_hit(&mut self, h: TriangleHit, triangle: u32) -> bool {
        h.t <= self.t_max() && self.keep(h, triangle)
    }

    #[inline(always)]
    fn keep(&mut self, h: TriangleHit, triangle: u32) -> bool {
        let better = match self.best {
            // The sum rounds monotonically and t_max is a float: it stays >= t_max if the
            // exact sum is.
            None if self.certain => h.t + h.t_error < self.ray_t_max,
            None => h.t < self.ray_t_max,
            Some(best) => h.t < best.t || (h.t == best.t && triangle < best.triangle),
        };
        if better {
            self.t_max = h.t;
            self.best = Some(Hit {
                t: h.t,
                triangle,
                b1: h.b1,
                b2: h.b2,
            });
        }
        better
    }
}
