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

use crate::math::{acos_f64, sin_cos_f64};
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
/// and the solid angle.
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

    fn view(&self, p: DVec3) -> Option<View> {
        let d = self.corner - p;
        let (x0, y0, mut z0) = (d.dot(self.x), d.dot(self.y), d.dot(self.z));
        let mut z = self.z;
        if z0 == 0.0 {
            return None;
        }
        if z0 > 0.0 {
            z = -z;
            z0 = -z0;
        }
        let (x1, y1) = (x0 + self.width, y0 + self.height);
        let n0 = DVec3::new(0.0, z0, -y0).normalize();
        let n1 = DVec3::new(-z0, 0.0, x1).normalize();
        let n2 = DVec3::new(0.0, -z0, y1).normalize();
        let n3 = DVec3::new(z0, 0.0, -x0).normalize();
        let angle = |a: DVec3, b: DVec3| acos_f64((-a.dot(b)).clamp(-1.0, 1.0));
        let (g0, g1, g2, g3) = (angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0));
        let solid_angle = g0 + g1 + g2 + g3 - 2.0 * PI;
        if solid_angle.is_nan() || solid_angle < MIN_SOLID_ANGLE {
            return None;
        }
        Some(View {
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
        })
    }

    /// A direction from `p` through the portal for `u` in [0, 1)^2, uniform in solid angle,
    /// with its density; `None` where the portal is not sampled from `p`, or where rounding put
    /// the direction off the rectangle (a set of no measure, left out so that the density
    /// [`PortalSampler::pdf`] gives is always the one the sample was drawn with).
    pub fn sample(&self, p: Vec3, u: (f64, f64)) -> Option<(Vec3, f32)> {
        let p64 = p.as_dvec3();
        let view = self.view(p64)?;
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
        let (sin_au, cos_au) = sin_cos_f64(au);
        let fu = (cos_au * b0 - b1) / sin_au;
        let cu = (1.0 / (fu * fu + b0 * b0).sqrt())
            .copysign(fu)
            .clamp(-1.0 + f64::EPSILON, 1.0 - f64::EPSILON);
        let xu = (-(cu * z0) / (1.0 - cu * cu).sqrt()).clamp(x0, x1);
        let dd = (xu * xu + z0 * z0).sqrt();
        let h0 = y0 / (dd * dd + y0 * y0).sqrt();
        let h1 = y1 / (dd * dd + y1 * y1).sqrt();
        let hv = h0 + u.1 * (h1 - h0);
        let yv = if hv * hv < 1.0 - 1e-12 {
            (hv * dd / (1.0 - hv * hv).sqrt()).clamp(y0, y1)
        } else {
            y1
        };
        let dir = (self.x * xu + self.y * yv + view.z * z0).normalize();
        let wi = dir.as_vec3();
        if !wi.is_finite() || wi == Vec3::ZERO || !self.crosses(p64, wi.as_dvec3()) {
            return None;
        }
        Some((wi, (1.0 / view.solid_angle) as f32))
    }

    /// The density in solid angle with which [`PortalSampler::sample`] produces `wi` from `p`:
    /// one over the solid angle where the ray crosses the rectangle, zero elsewhere.
    pub fn pdf(&self, p: Vec3, wi: Vec3) -> f32 {
        // The cheap test first: most directions a map or a BSDF samples miss the window.
        let p64 = p.as_dvec3();
        if !self.crosses(p64, wi.as_dvec3()) {
            return 0.0;
        }
        self.view(p64)
            .map_or(0.0, |view| (1.0 / view.solid_angle) as f32)
    }

    /// Whether the ray from `p` along `w` meets the rectangle (its edges included).
    fn crosses(&self, p: DVec3, w: DVec3) -> bool {
        let t = (self.corner - p).dot(self.z) / w.dot(self.z);
        if !(t > 0.0 && t.is_finite()) {
            return false;
        }
        let at = p + w * t - self.corner;
        let (s, r) = (at.dot(self.x), at.dot(self.y));
        (0.0..=self.width).contains(&s) && (0.0..=self.height).contains(&r)
    }

    /// The solid angle the portal subtends from `p`, zero where it is not sampled from there.
    pub fn solid_angle(&self, p: Vec3) -> f64 {
        self.view(p.as_dvec3()).map_or(0.0, |v| v.solid_angle)
    }
}
