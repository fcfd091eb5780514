//! Moving emitters: the emissive triangles of moving objects as area lights.
//!
//! A triangle of a moving object is a light like any other, sampled where the
//! path's [`Moment`] places it: its barycentrics are drawn on the object-space triangle (an
//! affine map keeps a uniform density uniform) and the point is placed in the world by
//! [`placed_point_with_normal`] with the triangle's kept normal, exactly as a hit there is, so
//! the shadow ray meets the same surface the camera would. Its area density is one over the
//! *placed* area at that time, which a scale changes (rotations and translations keep it), and
//! [`super::Lights::triangle_pdf`] computes the same area and normal at the same moment when a
//! BSDF-sampled ray hits it, so multiple importance sampling weighs the two strategies
//! consistently. Its choice probability is fixed, from its power at the mean of its keys'
//! areas: any fixed choice is unbiased, and one that depended on the time would make the choice
//! distribution differ per path for no gain with a few movers.
//!
//! Only the placement differs from a still triangle: the choice of light, the shadow ray and the
//! weights are the same code (`lights.rs`).

use super::LightSample;
use crate::geometry::{
    Moment, MovingTriangle, SurfacePoint, placed_normal, placed_point_with_normal,
};
use crate::scene::{Placement, Scene};
use glam::{DVec3, Vec2, Vec3};

/// Samples triangle `triangle` of moving object `object` as seen from `p` at `moment`; `choice`
/// is the probability of having chosen it.
pub(super) fn sample(
    scene: &Scene,
    moment: &Moment,
    (object, triangle): (u32, u32),
    p: Vec3,
    u: Vec2,
    choice: f32,
) -> Option<LightSample> {
    let (at, area, radiance) = placed_sample(scene, moment, (object, triangle), u);
    super::area_sample(p, at, (area, at.normal), radiance, choice)
}

/// The point that [`sample`] draws on triangle `triangle` of moving object `object` for the
/// numbers `u`, placed at `moment`, with the placed triangle's area and its radiance: all of
/// the sample that does not depend on the point it is seen from (the paths in lanes draw it
/// lane by lane and weigh it in their vector shading, as `super::area_sample` does).
pub(crate) fn placed_sample(
    scene: &Scene,
    moment: &Moment,
    (object, triangle): (u32, u32),
    u: Vec2,
) -> (SurfacePoint, f32, Vec3) {
    let (v, normal) = object_triangle(moment, (object, triangle));
    let material = scene.moving[object as usize].triangles[triangle as usize].material;
    let placement = moment.placement(object as usize);
    let su = u.x.sqrt();
    let (b1, b2) = (su * (1.0 - u.y), su * u.y);
    // The point and its normal exactly as a hit there is placed (`hits.rs`).
    let at = placed_point_with_normal(placement, v, normal, b1, b2);
    let radiance = scene.materials[material as usize].emission;
    (at, placed_area(placement, v), radiance)
}

/// Moving triangle `triangle` of object `object`: its object-space corners and unit normal,
/// as the moving objects' accelerator keeps them.
pub(super) fn object_triangle<'a>(
    moment: &Moment<'a>,
    (object, triangle): (u32, u32),
) -> (&'a [Vec3; 3], DVec3) {
    let motion = moment
        .motion()
        .expect("a moment at which moving emitters are sampled places the scene's moving objects");
    motion.triangle(MovingTriangle {
        object: object as usize,
        triangle: triangle as usize,
    })
}

/// The area of the object-space triangle `v` of object `object` placed by each of its keys,
/// averaged: what its power, and so its choice probability, is reckoned from.
pub(super) fn mean_area(scene: &Scene, object: u32, v: &[Vec3; 3]) -> f32 {
    let keys = scene.moving[object as usize].track.keys();
    keys.iter()
        .map(|k| placed_area(&k.placement(), v))
        .sum::<f32>()
        / keys.len() as f32
}

/// The area of the object-space triangle `v` placed by `placement`, and its unit normal in the
/// world as [`placed_point_with_normal`] gives it for the same `object_normal` (the side it
/// emits to: [`placed_normal`]).
pub(super) fn placed_shape(
    placement: &Placement,
    v: &[Vec3; 3],
    object_normal: DVec3,
) -> (f32, Vec3) {
    (
        placed_area(placement, v),
        placed_normal(placement, object_normal),
    )
}

/// The area of the object-space triangle `v` placed by `placement`, taken from the placed
/// edges in f64: a scale changes it, a rotation or translation does not.
fn placed_area(placement: &Placement, v: &[Vec3; 3]) -> f32 {
    let [a, b, c] = v.map(|p| p.as_dvec3());
    let placed = (placement.linear * (b - a)).cross(placement.linear * (c - a));
    (0.5 * placed.length()) as f32
}

/// For each moving object, the global index of its first triangle: they follow the still
/// triangles in object order (`geometry::motion`).
pub(super) fn moving_first(scene: &Scene) -> Vec<u32> {
    let mut next = scene.triangles.len();
    scene
        .moving
        .iter()
        .map(|o| {
            let first = next;
            next += o.triangles.len();
            u32::try_from(first).expect("fewer than 2^32 triangles: Hit::triangle is a u32")
        })
        .collect()
}

/// The moving object and its triangle that global index `index` names, or `None` for a still
/// triangle.
pub(super) fn locate(moving_first: &[u32], scene: &Scene, index: u32) -> Option<(u32, u32)> {
    if (index as usize) < scene.triangles.len() {
        return None;
    }
    let object = moving_first.partition_point(|&f| f <= index) - 1;
    Some((object as u32, index - moving_first[object]))
}
