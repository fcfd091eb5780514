//! Portals: rectangles (windows, doorways) through which the environment reaches a scene's
//! interior, and the sampling of the directions through one, uniformly in solid angle as seen
//! from a shading point (Urena, Fajardo and King, "An area-preserving parametrization for
//! spherical rectangles", 2013; the form of pbrt-v4's `SampleSphericalRectangle`).
//!
//! Why: in a room lit by the sky through a window, a map sampled by its luminance spends almost
//! every sample on directions the walls block (the sun, seen from the shade), and the sky that
//! does come through the window is found only by chance. Sampling the window's solid angle
//! finds it every time. `Lights` takes this sample beside the map's own (a second light sample,
//! so neither strategy's share is halved: the sun's beam keeps every sample it had), and weighs
//! both with the BSDF's by the power heuristic over the three strategies. A portal that misses
//! some opening loses no light, only the help (every strategy stays unbiased, and BSDF sampling
//! still finds what comes through elsewhere).
//!
//! **Numerics.** The solid angle of a rectangle is a sum of four angles near `pi / 2` less
//! `2 pi`, which cancels badly when the rectangle is small or far: the sampling is done in
//! `f64` (with the portable functions of [`crate::math`]), and from where the portal
//! subtends less than [`MIN_SOLID_ANGLE`] (or a point in its plane, which sees it edge-on) it
//! is not sampled at all: the density is zero there for sampling and evaluation alike, so the
//! two always agree.

use crate::geometry::PACKET;
use crate::math::{acos_f64, branchless, sin_cos_f64};
use glam::{DVec3, Vec3};
use std::f64::consts::PI;

/// Below this solid angle (steradians) a portal is not sampled from a point: the cancellation in
/// its solid angle would leave too few correct digits in `f64`, and a window this small seen
/// from there lets in too little to be worth a strategy.
pub const MIN_SOLID_ANGLE: f64 = 1e-7;

/// A rectangle: a corner and two orthogonal edges from it, in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Portal {
    /// One corner.
    pub corner: Vec3,
    /// The edge to the next corner.
    pub edge_u: Vec3,
    /// The edge to the previous corner, orthogonal to `edge_u`.
    pub edge_v: Vec3,
}

impl Portal {
    /// The rectangle through `corners`, given in order around it, or why they are not one: the
    /// edges must be orthogonal and the fourth corner where the other three put it, both to a
    /// part in ten thousand of the edges' lengths, and neither edge may vanish.
    pub fn from_corners(corners: [Vec3; 4]) -> Result<Portal, String> {
        let [a, b, c, d] = corners.map(|p| p.as_dvec3());
        let (u, v) = (b - a, d - a);
        let (lu, lv) = (u.length(), v.length());
        if !(lu > 0.0 && lv > 0.0 && (lu * lv).is_finite()) {
            return Err("the corners span no area".to_owned());
        }
        if u.dot(v).abs() > 1e-4 * lu * lv {
            return Err("the edges are not at right angles: a portal is a rectangle".to_owned());
        }
        if (c - (a + u + v)).length() > 1e-4 * (lu + lv) {
            return Err(
                "the fourth corner is off the rectangle: give the corners in order around it"
                    .to_owned(),
            );
        }
        Ok(Portal {
            corner: corners[0],
            edge_u: corners[1] - corners[0],
            edge_v: corners[3] - corners[0],
        })
    }
}

/// A portal prepared for sampling: its frame in `f64`.
#[derive(Clone, Copy, Debug)]
pub struct PortalSampler {
    corner: DVec3,
    x: DVec3,
    y: DVec3,
    z: DVec3,
    width: f64,
    height: f64,
}

/// The rectangle as seen from a point: its corners' coordinates in the portal's frame moved to
/// the point (with `z0 <= 0`), the normals of the four planes through the point and an edge,
/// the solid angle, and whether the portal is sampled from there at all (where not, the rest
/// is of no meaning).
struct View {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    z0: f64,
    /// The frame's z, turned so that the rectangle lies at `z0 <= 0`.
    z: DVec3,
    b0: f64,
    b1: f64,
    /// `2 pi - g2 - g3` of Urena et al.
    k: f64,
    solid_angle: f64,
    sampled: bool,
}

/// The arc cosine, sine and cosine a portal's sample takes: `libm`'s (the scalar paths'), or
/// their transcriptions without branches (`math::branchless`, for lanes), which give the same
/// bits wherever they cover the angle (every arc cosine; the sines and cosines of the angles
/// `branchless::sin_cos_covers`): [`PortalDraws::checked`] draws the others again with
/// libm.
pub(crate) trait Angles {
    fn acos(x: f64) -> f64;
    fn sin_cos(x: f64) -> (f64, f64);
}

/// `libm`'s, through [`crate::math`].
pub(crate) struct Libm;

/// `libm`'s bits without branches (`math::branchless`), for the angles whose sine and cosine
/// [`branchless::sin_cos`] covers; [`PortalDraws::checked`] draws the others again
/// with [`Libm`].
pub(crate) struct Branchless;

impl Angles for Branchless {
    #[inline(always)]
    fn acos(x: f64) -> f64 {
        branchless::acos(x)
    }
    #[inline(always)]
    fn sin_cos(x: f64) -> (f64, f64) {
        branchless::sin_cos(x)
    }
}

impl Angles for Libm {
    #[inline(always)]
    fn acos(x: f64) -> f64 {
        acos_f64(x)
    }
    #[inline(always)]
    fn sin_cos(x: f64) -> (f64, f64) {
        sin_cos_f64(x)
    }
}

/// A direction drawn through a portal as [`PortalSampler::draw`] computes it, before the
/// checks that it is one: the direction (unit length where it is one), the solid angle, the
/// angle whose sine and cosine it took, and whether the portal is sampled from the point.
pub(crate) struct Drawn {
    pub(crate) dir: DVec3,
    pub(crate) solid_angle: f64,
    pub(crate) angle: f64,
    pub(crate) sampled: bool,
}

impl PortalSampler {
    /// `portal`'s frame, in `f64`.
    pub fn new(portal: &Portal) -> PortalSampler {
        let (u, v) = (portal.edge_u.as_dvec3(), portal.edge_v.as_dvec3());
        let (x, y) = (u.normalize(), v.normalize());
        PortalSampler {
            corner: portal.corner.as_dvec3(),
            x,
            y,
            z: x.cross(y),
            width: u.length(),
            height: v.length(),
        }
    }

    /// The portal as seen from `p`, with no branch a vectorising compiler cannot make a select:
    /// every lane computes every step, and `sampled` says whether the result means anything.
    #[inline(always)]
    fn view<A: Angles>(&self, p: DVec3) -> View {
        let d = self.corner - p;
        let (x0, y0, z0) = (d.dot(self.x), d.dot(self.y), d.dot(self.z));
        // Turned so that the rectangle lies at `z0 <= 0`.
        let turned = z0 > 0.0;
        let z = if turned { -self.z } else { self.z };
        let z0 = if turned { -z0 } else { z0 };
        let (x1, y1) = (x0 + self.width, y0 + self.height);
        let n0 = DVec3::new(0.0, z0, -y0).normalize();
        let n1 = DVec3::new(-z0, 0.0, x1).normalize();
        let n2 = DVec3::new(0.0, -z0, y1).normalize();
        let n3 = DVec3::new(z0, 0.0, -x0).normalize();
        let angle = |a: DVec3, b: DVec3| A::acos(clamp(-a.dot(b), -1.0, 1.0));
        let (g0, g1, g2, g3) = (angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0));
        let solid_angle = g0 + g1 + g2 + g3 - 2.0 * PI;
        View {
            x0,
            x1,
            y0,
            y1,
            z0,
            z,
            b0: n0.z,
            b1: n2.z,
            k: 2.0 * PI - g2 - g3,
            solid_angle,
            // A point in the portal's plane sees it edge-on.
            sampled: z0 != 0.0 && !solid_angle.is_nan() && solid_angle >= MIN_SOLID_ANGLE,
        }
    }

    /// The direction from `p` through the portal for `u` in [0, 1)^2, uniform in solid angle,
    /// before [`PortalSampler::sample`]'s checks: the same steps for the scalar paths and the
    /// lanes, which differ only in `A`, whose functions give the same bits where they cover the
    /// angle ([`Angles`]).
    #[inline(always)]
    pub(crate) fn draw<A: Angles>(&self, p: DVec3, u: (f64, f64)) -> Drawn {
        let view = self.view::<A>(p);
        let View {
            x0,
            x1,
            y0,
            y1,
            z0,
            b0,
            b1,
            ..
        } = view;
        let au = u.0 * view.solid_angle + view.k;
        let (sin_au, cos_au) = A::sin_cos(au);
        let fu = (cos_au * b0 - b1) / sin_au;
        let cu = clamp(
            (1.0 / (fu * fu + b0 * b0).sqrt()).copysign(fu),
            -1.0 + f64::EPSILON,
            1.0 - f64::EPSILON,
        );
        let xu = clamp(-(cu * z0) / (1.0 - cu * cu).sqrt(), x0, x1);
        let dd = (xu * xu + z0 * z0).sqrt();
        let h0 = y0 / (dd * dd + y0 * y0).sqrt();
        let h1 = y1 / (dd * dd + y1 * y1).sqrt();
        let hv = h0 + u.1 * (h1 - h0);
        let yv = if hv * hv < 1.0 - 1e-12 {
            clamp(hv * dd / (1.0 - hv * hv).sqrt(), y0, y1)
        } else {
            y1
        };
        Drawn {
            dir: (self.x * xu + self.y * yv + view.z * z0).normalize(),
            solid_angle: view.solid_angle,
            angle: au,
            sampled: view.sampled,
        }
    }

    /// `drawn` from `p` as [`PortalSampler::sample`] gives it: `None` where the portal is not
    /// sampled from `p` or where rounding put the direction off the rectangle.
    #[inline(always)]
    pub(crate) fn checked(&self, p: DVec3, drawn: &Drawn) -> Option<(Vec3, f32)> {
        self.accepts(p, drawn)
            .then(|| (drawn.dir.as_vec3(), density(true, drawn.solid_angle)))
    }

    /// Whether [`PortalSampler::checked`] takes `drawn`: the portal is sampled from `p`, and
    /// the direction, rounded to `f32`, is one and crosses the rectangle. Without a branch, for
    /// the lanes' loop too.
    #[inline(always)]
    fn accepts(&self, p: DVec3, drawn: &Drawn) -> bool {
        let wi = drawn.dir.as_vec3();
        drawn.sampled & wi.is_finite() & (wi != Vec3::ZERO) & self.crosses(p, wi.as_dvec3())
    }

    /// A direction from `p` through the portal for `u` in [0, 1)^2, uniform in solid angle,
    /// with its density; `None` where the portal is not sampled from `p`, or where rounding put
    /// the direction off the rectangle (a set of no measure, left out so that the density
    /// [`PortalSampler::pdf`] gives is always the one the sample was drawn with).
    pub fn sample(&self, p: Vec3, u: (f64, f64)) -> Option<(Vec3, f32)> {
        let p64 = p.as_dvec3();
        self.checked(p64, &self.draw::<Libm>(p64, u))
    }

    /// The density in solid angle with which [`PortalSampler::sample`] produces `wi` from `p`:
    /// one over the solid angle where the ray crosses the rectangle, zero elsewhere.
    pub fn pdf(&self, p: Vec3, wi: Vec3) -> f32 {
        // The cheap test first: most directions a map or a BSDF samples miss the window.
        let p64 = p.as_dvec3();
        if !self.crosses(p64, wi.as_dvec3()) {
            return 0.0;
        }
        let view = self.view::<Libm>(p64);
        density(view.sampled, view.solid_angle)
    }

    /// Whether the ray from `p` along `w` meets the rectangle (its edges included).
    #[inline(always)]
    fn crosses(&self, p: DVec3, w: DVec3) -> bool {
        let t = (self.corner - p).dot(self.z) / w.dot(self.z);
        let at = p + w * t - self.corner;
        let (s, r) = (at.dot(self.x), at.dot(self.y));
        // Every test evaluated and combined without a branch (where `t` is not a positive
        // finite distance, `s` and `r` are of no meaning, and the first test fails).
        (t > 0.0 && t.is_finite())
            & (0.0 <= s)
            & (s <= self.width)
            & (0.0 <= r)
            & (r <= self.height)
    }

    /// The solid angle the portal subtends from `p`, zero where it is not sampled from there.
    pub fn solid_angle(&self, p: Vec3) -> f64 {
        let view = self.view::<Libm>(p.as_dvec3());
        if view.sampled { view.solid_angle } else { 0.0 }
    }
}

/// The density in solid angle of a direction through a portal that subtends `solid_angle`
/// from where it is seen, where it is `sampled` from there.
#[inline(always)]
fn density(sampled: bool, solid_angle: f64) -> f32 {
    if sampled {
        (1.0 / solid_angle) as f32
    } else {
        0.0
    }
}

/// `v` held to `[low, high]` as `f64::clamp` holds it, without its check that `low <= high`
/// (a branch to a panic, which would keep a loop of lanes from vectorising; the callers' bounds
/// are ordered wherever the result is used).
#[inline(always)]
fn clamp(v: f64, low: f64, high: f64) -> f64 {
    let v = if v < low { low } else { v };
    if v > high { high } else { v }
}

/// The lanes' draws through portals (`integrator/lanes/`): each lane's portal, point and
/// numbers, set lane by lane, then drawn all together in one loop that vectorises (with AVX
/// where the processor has it), then checked lane by lane: each lane's direction what
/// [`PortalSampler::sample`] gives, bit for bit, as [`Branchless`] gives `libm`'s bits and
/// the angles it does not cover are drawn again with `libm`. Why: drawn one lane at a time,
/// the chain of square roots, divisions and arc cosines of a draw was two fifths of a render
/// of a room lit through its window (docs/bench.md, issue 16).
#[derive(Clone, Copy, Default)]
pub(crate) struct PortalDraws {
    /// Which lanes have a draw set and not yet checked, and through which portal (its index
    /// among the scene's).
    pub(crate) pending: [bool; PACKET],
    pub(crate) portal: [usize; PACKET],
    /// Each lane's portal's frame: its corner, its axes and its sides' lengths, a coordinate
    /// at a time.
    corner: [[f64; PACKET]; 3],
    x: [[f64; PACKET]; 3],
    y: [[f64; PACKET]; 3],
    z: [[f64; PACKET]; 3],
    width: [f64; PACKET],
    height: [f64; PACKET],
    p: [[f64; PACKET]; 3],
    u: [[f64; PACKET]; 2],
    dir: [[f64; PACKET]; 3],
    solid_angle: [f64; PACKET],
    angle: [f64; PACKET],
    sampled: [bool; PACKET],
    accepted: [bool; PACKET],
    /// Each lane's other direction (the environment's own sample) and, once drawn, the
    /// portal's density of it, [`PortalSampler::pdf`]'s bits: the lane's point sees the
    /// portal as its draw does.
    other: [[f64; PACKET]; 3],
    other_density: [f32; PACKET],
}

impl PortalDraws {
    /// Sets lane `i`'s draw through `portal`, the scene's `k`th, from `p` for `u`; the
    /// direction whose density through the portal the draw finds too is set apart
    /// ([`PortalDraws::set_other`]).
    #[inline(always)]
    pub(crate) fn set(
        &mut self,
        i: usize,
        (k, portal): (usize, &PortalSampler),
        p: Vec3,
        u: (f64, f64),
    ) {
        self.portal[i] = k;
        let rows = |rows: &mut [[f64; PACKET]; 3], v: DVec3| {
            (rows[0][i], rows[1][i], rows[2][i]) = (v.x, v.y, v.z);
        };
        rows(&mut self.corner, portal.corner);
        rows(&mut self.x, portal.x);
        rows(&mut self.y, portal.y);
        rows(&mut self.z, portal.z);
        (self.width[i], self.height[i]) = (portal.width, portal.height);
        rows(&mut self.p, p.as_dvec3());
        (self.u[0][i], self.u[1][i]) = u;
        self.pending[i] = true;
    }

    /// Draws every lane's direction at once: the lanes not pending too, on what they hold, so
    /// that the loop has no branch and vectorises (their results are never read).
    pub(crate) fn draw(&mut self) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: the processor has AVX, just checked.
            return unsafe { self.draw_avx() };
        }
        self.draw_lanes();
    }

    /// [`PortalDraws::draw_lanes`] compiled with AVX: four lanes of `f64` a step.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn draw_avx(&mut self) {
        self.draw_lanes();
    }

    #[inline(always)]
    fn draw_lanes(&mut self) {
        let at =
            |rows: &[[f64; PACKET]; 3], i: usize| DVec3::new(rows[0][i], rows[1][i], rows[2][i]);
        for i in 0..PACKET {
            let portal = PortalSampler {
                corner: at(&self.corner, i),
                x: at(&self.x, i),
                y: at(&self.y, i),
                z: at(&self.z, i),
                width: self.width[i],
                height: self.height[i],
            };
            let p = at(&self.p, i);
            let drawn = portal.draw::<Branchless>(p, (self.u[0][i], self.u[1][i]));
            self.accepted[i] = portal.accepts(p, &drawn);
            // The portal's density of the other direction, as `PortalSampler::pdf` computes it:
            // its view is from the same point as the draw's, so it is not computed again.
            let crossed = portal.crosses(p, at(&self.other, i));
            self.other_density[i] = if crossed {
                density(drawn.sampled, drawn.solid_angle)
            } else {
                0.0
            };
            (self.dir[0][i], self.dir[1][i], self.dir[2][i]) =
                (drawn.dir.x, drawn.dir.y, drawn.dir.z);
            self.solid_angle[i] = drawn.solid_angle;
            self.angle[i] = drawn.angle;
            self.sampled[i] = drawn.sampled;
        }
    }

    /// Sets lane `i`'s other direction: the environment's own sample, whose density through
    /// the portal the draw finds.
    #[inline(always)]
    pub(crate) fn set_other(&mut self, i: usize, other: Vec3) {
        (self.other[0][i], self.other[1][i], self.other[2][i]) =
            (f64::from(other.x), f64::from(other.y), f64::from(other.z));
    }

    /// The portal's density of lane `i`'s other direction, as [`PortalSampler::pdf`] gives
    /// it (drawn by [`PortalDraws::draw`]).
    #[inline(always)]
    pub(crate) fn other_density(&self, i: usize) -> f32 {
        self.other_density[i]
    }

    /// The point lane `i` draws from.
    #[inline(always)]
    pub(crate) fn point(&self, i: usize) -> Vec3 {
        DVec3::new(self.p[0][i], self.p[1][i], self.p[2][i]).as_vec3()
    }

    /// Lane `i`'s draw, drawn, as [`PortalSampler::sample`] gives it through `portal`, the
    /// lane's; the lane is no longer pending.
    #[inline(always)]
    pub(crate) fn checked(&mut self, i: usize, portal: &PortalSampler) -> Option<(Vec3, f32)> {
        self.pending[i] = false;
        let p = DVec3::new(self.p[0][i], self.p[1][i], self.p[2][i]);
        // The view, its arc cosines libm's bits everywhere, says exactly where the portal is
        // not sampled (a point in its plane, a wall around the window, sees it edge-on): no
        // direction there, and nothing to draw again.
        if !self.sampled[i] {
            return None;
        }
        if !branchless::sin_cos_covers(self.angle[i]) {
            return portal.checked(p, &portal.draw::<Libm>(p, (self.u[0][i], self.u[1][i])));
        }
        let dir = DVec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i]);
        self.accepted[i].then(|| (dir.as_vec3(), density(true, self.solid_angle[i])))
    }
}

/// The lanes' draws give what the scalar sample gives, bit for bit, from points all about a
/// portal, near its plane (where it is seen edge-on, and the angles its draw turns through
/// reach the ones `math::branchless` leaves to `libm`) and far from it, at every scale, through
/// an upright portal and a tilted one, each lane its own, some lanes left unset; and the
/// portal's density of another direction what `PortalSampler::pdf` gives. Both instruction
/// sets' loops are held to it.
#[cfg(test)]
#[test]
fn lanes_draw_what_the_scalar_sample_draws() {
    let mut state = 7u64;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut compared, mut drawn_again, mut sampled, mut crossing) = (0, 0, 0, 0);
    for scale in [1e-3f32, 1.0, 40.0, 1e4] {
        let upright = [
            [0.0, 0.9, 2.0],
            [0.0, 2.6, 2.0],
            [0.0, 2.6, 4.2],
            [0.0, 0.9, 4.2],
        ];
        // A rectangle turned about two axes, its corner off the origin.
        let (u, v) = (
            Vec3::new(1.0, 0.4, -0.3).normalize() * 1.3,
            Vec3::new(-0.2, 1.0, 0.6).normalize(),
        );
        let v = (v - u * (u.dot(v) / u.dot(u))).normalize() * 0.7;
        let c = Vec3::new(0.3, 1.1, 2.5);
        let tilted = [c, c + u, c + u + v, c + v].map(|p| p.to_array());
        let portals = [upright, tilted].map(|corners| {
            Portal::from_corners(corners.map(|p| Vec3::from(p) * scale)).expect("a rectangle")
        });
        let samplers = portals.each_ref().map(PortalSampler::new);
        let mut draws = PortalDraws::default();
        for round in 0..4000 {
            let mut set = Vec::new();
            for i in 0..PACKET {
                // One lane in five left unset.
                if (i + round) % 5 == 4 {
                    continue;
                }
                let k = (i + round / 2) % 2;
                let (portal, sampler) = (&portals[k], &samplers[k]);
                // Half the points within a thousandth of the plane, some beyond the edges.
                let (a, b) = (next() * 1.6 - 0.3, next() * 1.6 - 0.3);
                let normal = portal.edge_u.cross(portal.edge_v).normalize();
                let off = if round % 2 == 0 { 1e-3 } else { 3.0 };
                let p = portal.corner
                    + portal.edge_u * a
                    + portal.edge_v * b
                    + normal * ((next() - 0.5) * off * scale);
                let u = (f64::from(next()), f64::from(next()));
                // The other direction: towards a point of the portal for half the lanes
                // (its edges too), anywhere for the rest.
                let other = if i % 2 == 0 {
                    let (a, b) = (next() * 1.02 - 0.01, next() * 1.02 - 0.01);
                    portal.corner + portal.edge_u * a + portal.edge_v * b - p
                } else {
                    Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5)
                }
                .normalize();
                draws.set(i, (k, sampler), p, u);
                draws.set_other(i, other);
                set.push((i, k, p, u, other));
            }
            // The plain loop's results, then the one `draw` picks (AVX where the processor
            // has it): the same for every lane set (NaN as NaN: an unset lane's, never read,
            // may differ in its sign).
            let lane = |d: &PortalDraws, i: usize| {
                let bits = |x: f64| if x.is_nan() { u64::MAX } else { x.to_bits() };
                let dir = [0, 1, 2].map(|c| bits(d.dir[c][i]));
                let density = d.other_density[i].to_bits();
                (dir, bits(d.solid_angle[i]), d.accepted[i], density)
            };
            draws.draw_lanes();
            let plain: Vec<_> = set.iter().map(|&(i, ..)| lane(&draws, i)).collect();
            draws.draw();
            let picked: Vec<_> = set.iter().map(|&(i, ..)| lane(&draws, i)).collect();
            assert_eq!(plain, picked, "the two loops differ");
            // A lane whose angle the branch-free sine leaves out is drawn again: here one
            // whose stored draw is spoilt and its angle put outside, which must not be read.
            if let Some(&(i, ..)) = set.first().filter(|_| round % 7 == 0) {
                draws.angle[i] = -1.0;
                draws.dir[0][i] = f64::NAN;
                draws.accepted[i] = !draws.accepted[i];
            }
            for &(i, k, p, u, other) in &set {
                let sampler = &samplers[k];
                assert_eq!(draws.portal[i], k, "lane {i}'s portal");
                let density = sampler.pdf(p, other);
                assert_eq!(
                    draws.other_density(i).to_bits(),
                    density.to_bits(),
                    "from {p} along {other}"
                );
                crossing += usize::from(density > 0.0);
                if !branchless::sin_cos_covers(draws.angle[i]) {
                    drawn_again += 1;
                }
                let (lanes, scalar) = (draws.checked(i, sampler), sampler.sample(p, u));
                let bits = |s: Option<(Vec3, f32)>| {
                    s.map(|(w, pdf)| (w.to_array().map(f32::to_bits), pdf.to_bits()))
                };
                assert_eq!(bits(lanes), bits(scalar), "from {p} for {u:?}");
                assert!(!draws.pending[i], "a checked lane is no longer pending");
                compared += 1;
                sampled += usize::from(scalar.is_some());
            }
            assert!(
                !draws.pending.contains(&true),
                "an unset lane is not pending"
            );
        }
    }
    assert!(
        sampled > compared / 2,
        "{sampled} of {compared} drew a direction"
    );
    assert!(
        crossing > compared / 5,
        "{crossing} of {compared} other directions crossed"
    );
    // Every angle a draw turns through is now covered but for four narrow bands: a draw
    // redrawn by libm is rare, and the count is no test of the redraw (the unit tests of
    // `math::branchless` are).
    eprintln!("{compared} draws, {sampled} directions, {drawn_again} drawn again by libm");
}
