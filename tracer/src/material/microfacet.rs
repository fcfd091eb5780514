//! Rough conductors: the GGX (Trowbridge-Reitz) microfacet model.
//!
//! The BRDF is Walter et al. 2007's `D(h) G2(wo, wi) F(wo.h) / (4 cos_o cos_i)` with the
//! height-correlated Smith masking-shadowing G2 (Heitz 2014, "Understanding the Masking-Shadowing
//! Function"), which is more accurate than the separable G1 G1 and no dearer, and Schlick's
//! Fresnel from the colour at normal incidence `f0`. Directions are drawn from the distribution of
//! *visible* normals (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"): only
//! microfacets that face `wo` and are not masked are proposed, so the sample weight is
//! F G2 / G1(wo) <= F and grazing views no longer produce the fireflies of plain D(h) cos
//! sampling.
//!
//! Everything here works in the upper hemisphere (`wo.z > 0`); the caller mirrors back-facing
//! directions. The formulas are rearranged so that no cosine is ever a divisor: with
//! `s(w) = sqrt(w.z^2 + alpha^2 (w.x^2 + w.y^2))`, Smith's `G1(w) = 2 w.z / (w.z + s(w))` and the
//! height-correlated `G2 = 2 cos_o cos_i / (cos_i s(wo) + cos_o s(wi))`, so
//! `f * cos_i = D F cos_i / (2 (cos_i s(wo) + cos_o s(wi)))` and the visible-normal density of
//! `wi` is `D / (2 (cos_o + s(wo)))`. Grazing directions then give finite, correct limits.

use super::dielectric::fresnel_schlick;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// The smallest roughness used. `alpha` is clamped to [`MIN_ALPHA`, 1] rather than switched to a
/// mirror below a threshold: at 1e-4 the lobe is already narrower than a pixel's footprint in any
/// practical scene, D peaks at 1 / (pi alpha^2) ~ 3e7 which f32 holds with room to spare, and one
/// continuous model is simpler to test than a model with a branch. NaN becomes [`MIN_ALPHA`].
pub const MIN_ALPHA: f32 = 1e-4;

/// A GGX lobe with colour `f0` at normal incidence and roughness `alpha` (already clamped).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ggx {
    pub f0: Vec3,
    pub alpha: f32,
}

impl Ggx {
    pub fn new(f0: Vec3, alpha: f32) -> Self {
        let alpha = if alpha.is_nan() {
            MIN_ALPHA
        } else {
            alpha.clamp(MIN_ALPHA, 1.0)
        };
        Self { f0, alpha }
    }

    /// `f(wo, wi) * cos_i` for `wo.z > 0`; zero unless `wi` is in the upper hemisphere too.
    ///
    /// Written without branches (every value computed, the answer a select), so that the
    /// paths in lanes (`integrator/lanes/`) call it in their vector shading as it is, eight
    /// lanes at a time; inlined for the same reason. The values it selects are what the
    /// branches computed, so the bits are those of the branches.
    #[inline(always)]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let (h, upper) = half_vector(wo, wi);
        let denominator = 2.0 * (wi.z * self.s(wo) + wo.z * self.s(wi));
        let value = self.d(h) * wi.z / denominator;
        let reflected = fresnel_schlick(self.f0, wo.dot(h)) * value;
        // `&`, not `&&`: a short-circuit is a branch.
        if upper & (denominator > 0.0) & value.is_finite() {
            reflected
        } else {
            Vec3::ZERO
        }
    }

    /// The solid-angle density of [`Ggx::sample`] at `wi`, for `wo.z > 0`. Without branches,
    /// as [`Ggx::eval`] is, and for the same reason.
    #[inline(always)]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let (h, upper) = half_vector(wo, wi);
        let pdf = self.d(h) / (2.0 * (wo.z + self.s(wo)));
        if upper & pdf.is_finite() { pdf } else { 0.0 }
    }

    /// A direction reflected about a visible normal, as `(wi, weight, pdf)`; `None` when the
    /// reflection goes below the surface (the microfacet faces `wo` but `wi` is occluded by the
    /// macro-surface), which happens with probability 1 minus the integral of [`Ggx::pdf`].
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        let h = self.sample_visible_normal(wo, u);
        // Each `filter` also rejects NaN, which compares false.
        let wi = Some(2.0 * wo.dot(h) * h - wo).filter(|wi| wi.z > 0.0)?;
        let pdf = Some(self.pdf(wo, wi)).filter(|&pdf| pdf > 0.0)?;
        // eval / pdf with D cancelled: F cos_i (cos_o + s(wo)) / (cos_i s(wo) + cos_o s(wi)).
        let so = self.s(wo);
        let denominator = Some(wi.z * so + wo.z * self.s(wi)).filter(|&d| d > 0.0)?;
        let weight = fresnel_schlick(self.f0, wo.dot(h)) * (wi.z * (wo.z + so) / denominator);
        Some((wi, weight, pdf))
    }

    /// The GGX normal distribution D(h) for a unit `h` with `h.z > 0`.
    #[inline(always)]
    fn d(&self, h: Vec3) -> f32 {
        let a2 = self.alpha * self.alpha;
        // 1 + tan^2 / alpha^2, times cos^2: never below 1 for alpha <= 1 and unit h.
        let t = (h.x * h.x + h.y * h.y) / a2 + h.z * h.z;
        1.0 / (PI * a2 * t * t)
    }

    /// `s(w) = sqrt(w.z^2 + alpha^2 (w.x^2 + w.y^2))`: `w.z (1 + 2 Lambda(w))` without dividing.
    #[inline(always)]
    fn s(&self, w: Vec3) -> f32 {
        let a2 = self.alpha * self.alpha;
        (w.z * w.z + a2 * (w.x * w.x + w.y * w.y)).sqrt()
    }

    /// Heitz 2018, listing 1: a microfacet normal with density `D_wo(h) = G1(wo) max(0, wo.h)
    /// D(h) / wo.z`, by sampling the projected area of a hemisphere in the stretched
    /// configuration where the surface has roughness 1.
    fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let a = self.alpha;
        let vh = Vec3::new(a * wo.x, a * wo.y, wo.z).normalize_or(Vec3::Z);
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        let r = u.x.max(0.0).sqrt();
        let (sin_phi, cos_phi) = crate::math::sin_cos(2.0 * PI * u.y);
        let p1 = r * cos_phi;
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * sin_phi;
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        Vec3::new(a * nh.x, a * nh.y, nh.z.max(0.0)).normalize_or(Vec3::Z)
    }
}

/// The unit half vector of two directions, and whether it is one of two upper-hemisphere
/// directions: both strictly above the surface, and their sum long enough to normalise (the
/// half vector is then above it too). Where it is not, the vector is whatever the arithmetic
/// gave, for the caller to select away.
#[inline(always)]
fn half_vector(wo: Vec3, wi: Vec3) -> (Vec3, bool) {
    let h = (wo + wi).normalize_or_zero();
    (h, (wo.z > 0.0) & (wi.z > 0.0) & (h.z > 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Midpoint quadrature over the hemisphere in (cos theta, phi), fine enough for alpha >= 0.1.
    fn integrate_hemisphere(f: impl Fn(Vec3) -> f64) -> f64 {
        let (n_cos, n_phi) = (2000, 400);
        let mut sum = 0.0;
        for i in 0..n_cos {
            let z = (i as f64 + 0.5) / n_cos as f64;
            let r = (1.0 - z * z).sqrt();
            for j in 0..n_phi {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n_phi as f64;
                sum += f(Vec3::new(
                    (r * phi.cos()) as f32,
                    (r * phi.sin()) as f32,
                    z as f32,
                ));
            }
        }
        sum * 2.0 * std::f64::consts::PI / (n_cos * n_phi) as f64
    }

    #[test]
    fn projected_microfacet_area_is_one() {
        // The defining normalisation of a microfacet distribution: integral of D(h) cos theta_h.
        for alpha in [0.1f32, 0.3, 0.8, 1.0] {
            let ggx = Ggx::new(Vec3::ONE, alpha);
            let area = integrate_hemisphere(|h| f64::from(ggx.d(h) * h.z));
            assert!(
                (area - 1.0).abs() < 2e-3,
                "alpha {alpha}: projected area {area}"
            );
        }
    }

    #[test]
    fn visible_normals_integrate_to_one() {
        // Heitz 2014 eq. 2: the projected area of visible microfacets equals that of the
        // macro-surface, i.e. integral of G1(wo) max(0, wo.h) D(h) / wo.z over h is 1.
        for alpha in [0.2f32, 0.6, 1.0] {
            let ggx = Ggx::new(Vec3::ONE, alpha);
            for theta in [0.0f32, 0.7, 1.3, 1.55] {
                let wo = Vec3::new(theta.sin(), 0.0, theta.cos());
                let g1 = 2.0 * wo.z / (wo.z + ggx.s(wo));
                let total =
                    integrate_hemisphere(|h| f64::from(g1 * wo.dot(h).max(0.0) * ggx.d(h) / wo.z));
                assert!(
                    (total - 1.0).abs() < 3e-3,
                    "alpha {alpha}, theta {theta}: {total}"
                );
            }
        }
    }

    #[test]
    fn sampled_normals_face_the_viewer() {
        let ggx = Ggx::new(Vec3::ONE, 0.5);
        let wo = Vec3::new(0.8, 0.3, 0.2).normalize();
        for i in 0..64 {
            for j in 0..64 {
                let u = Vec2::new((i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 64.0);
                let h = ggx.sample_visible_normal(wo, u);
                assert!((h.length() - 1.0).abs() < 1e-5 && h.z >= 0.0, "h = {h}");
                assert!(
                    wo.dot(h) >= -1e-6,
                    "back-facing microfacet {h} sampled for {wo}"
                );
            }
        }
    }

    #[test]
    fn alpha_is_clamped() {
        assert_eq!(Ggx::new(Vec3::ONE, 0.0).alpha, MIN_ALPHA);
        assert_eq!(Ggx::new(Vec3::ONE, f32::NAN).alpha, MIN_ALPHA);
        assert_eq!(Ggx::new(Vec3::ONE, 7.0).alpha, 1.0);
        assert_eq!(Ggx::new(Vec3::ONE, 0.25).alpha, 0.25);
    }
}
