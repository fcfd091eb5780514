//! Smooth dielectrics (glass, water) and the Fresnel equations shared by every lobe.
//!
//! A smooth interface is two delta lobes, specular reflection and refraction, mixed by the exact
//! unpolarised Fresnel reflectance F. One lobe is picked per sample with probability F (so the
//! reflected throughput is exactly 1 and the refracted one exactly `tint / eta^2`): sampling in
//! proportion to the lobes' weights keeps the estimator's variance low and never wastes a path on
//! a lobe that carries nothing, as under total internal reflection, where F = 1.
//!
//! The renderer transports *radiance*, which is not conserved across a refracting interface: the
//! bend compresses or widens the beam's solid angle, so L / n^2 is what is invariant. Radiance
//! arriving along `-wi` in a medium of index n_i leaves along `wo` in the medium of index n_o
//! scaled by (n_o / n_i)^2 = 1 / eta'^2, with eta' = n_i / n_o. Hence a path that enters glass
//! from the camera's side carries 1/ior^2 and one that leaves it carries ior^2. A light tracer,
//! transporting importance, would leave this factor out; tessera has none.

use super::BsdfSample;
use glam::Vec3;
use std::ops::RangeInclusive;

/// The exact unpolarised Fresnel reflectance of a smooth dielectric interface.
///
/// `cos_i` is the cosine between the incident direction and the normal, positive on the side the
/// normal points to; `eta` is the relative index of refraction (the index on the far side of the
/// normal over the index on the normal's side, so 1.5 for air-to-glass with the normal in air).
/// A negative `cos_i` means the light arrives from inside, and the interface is seen with 1/eta.
/// Returns 1 under total internal reflection. Never NaN for `eta > 0` and any `cos_i`.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let mut cos_i = cos_i.clamp(-1.0, 1.0);
    let mut eta = eta;
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
    }
    // Snell's law in sin^2 form; sin^2 >= 1 on the far side means no transmitted wave exists.
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    // Both denominators are positive here: cos_t > 0 because sin2_t < 1, and eta > 0.
    let r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)
}

/// Schlick's approximation of a conductor's Fresnel reflectance from its colour at normal
/// incidence, `f0`; `cos_h` is the cosine between the direction and the microfacet normal.
/// Inlined, so that the lanes' vector shading (through the GGX lobe's value) vectorises.
#[inline(always)]
pub fn fresnel_schlick(f0: Vec3, cos_h: f32) -> Vec3 {
    let m = (1.0 - cos_h.clamp(0.0, 1.0)).max(0.0);
    let m2 = m * m;
    f0 + (Vec3::ONE - f0) * (m2 * m2 * m)
}

/// `w` mirrored about the normal +z: the specular reflection in the local frame.
pub(crate) fn reflect_local(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// The direction refracted from `wo` through a smooth interface with normal +z, with `eta` the
/// relative index as in [`fresnel_dielectric`]. Returns the transmitted direction (unit length,
/// on the other side) and the relative index `eta'` actually crossed, i.e. `eta` when `wo` is on
/// the normal's side and `1 / eta` otherwise; `None` under total internal reflection.
pub(crate) fn refract_local(wo: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let (cos_i, eta, sign) = if wo.z >= 0.0 {
        (wo.z, eta, 1.0)
    } else {
        (-wo.z, 1.0 / eta, -1.0)
    };
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    // Tangential component shrinks by 1/eta; the normal component is -cos_t on the far side.
    let wt = Vec3::new(-wo.x / eta, -wo.y / eta, -sign * cos_t);
    Some((wt.normalize_or_zero(), eta))
}

/// The relative indices of refraction (inside over outside) the renderer accepts. Real
/// interfaces lie far inside it: water in air 1.33, diamond 2.42, germanium in the infrared 4,
/// an air bubble in glass 0.66. Beyond it Fresnel's and Snell's arithmetic in `f32` loses its
/// meaning (`eta * eta` overflows near 1.8e19), and nothing physical lies there.
///
/// The one owner of the limit: the scene loader refuses a glass whose relative index leaves it
/// ([`check_relative_ior`]), and the sampler clamps to it (`sanitize_ior`).
pub const RELATIVE_IOR: RangeInclusive<f32> = 1e-3..=1e3;

/// `relative` (inside over outside) when it lies in [`RELATIVE_IOR`], else what is wrong, for
/// the loader to show with the keys that gave it.
pub fn check_relative_ior(relative: f32) -> Result<f32, String> {
    if RELATIVE_IOR.contains(&relative) {
        Ok(relative)
    } else {
        Err(format!(
            "gives a relative index of refraction (inside over outside) of {relative}, outside [{}, {}]",
            RELATIVE_IOR.start(),
            RELATIVE_IOR.end()
        ))
    }
}

/// The index of refraction the sampler works with: finite and in [`RELATIVE_IOR`].
///
/// The scene loader refuses indices outside it with a message; this clamp only keeps a bad
/// value that slipped through (a hand-built [`super::Bsdf`]) from poisoning the image with NaN
/// (NaN becomes 1, an index-matched interface that lets light through unchanged).
pub(crate) fn sanitize_ior(ior: f32) -> f32 {
    if ior.is_nan() {
        1.0
    } else {
        ior.clamp(*RELATIVE_IOR.start(), *RELATIVE_IOR.end())
    }
}

/// One sample of a smooth dielectric with index `ior` (inside over outside; the normal points
/// outside) and transmission `tint`.
///
/// `u_choice < F` picks reflection, otherwise refraction; total internal reflection always
/// reflects. The returned `pdf` is the discrete probability of the lobe picked (F or 1 - F): the
/// lobes are deltas, so there is no density. A refracted sample's `weight` is
/// `tint / eta'^2`, with `eta'` the index of the side `wi` enters over the side `wo` is on (`ior`
/// when `wo.z > 0`, `1 / ior` when `wo` is inside): the radiance scaling explained above.
/// Returns `None` when `wo` lies in the tangent plane (`wo.z == 0`), where nothing is scattered.
pub(crate) fn sample_dielectric(
    ior: f32,
    tint: Vec3,
    wo: Vec3,
    u_choice: f32,
) -> Option<BsdfSample> {
    if wo.z == 0.0 || wo.z.is_nan() {
        return None;
    }
    let eta = sanitize_ior(ior);
    let f = fresnel_dielectric(wo.z, eta);
    let reflected = BsdfSample {
        wi: reflect_local(wo),
        weight: Vec3::ONE,
        pdf: f,
        delta: true,
        transmission: false,
    };
    // Decide by F alone at its extremes, so that a `u_choice` outside [0, 1) can never pick a
    // lobe of probability zero.
    let reflect = f >= 1.0 || (f > 0.0 && u_choice < f);
    if reflect {
        return Some(reflected);
    }
    match refract_local(wo, eta) {
        Some((wi, eta_crossed)) if wi.z != 0.0 => Some(BsdfSample {
            wi,
            weight: tint / (eta_crossed * eta_crossed),
            pdf: 1.0 - f,
            delta: true,
            transmission: true,
        }),
        // `fresnel_dielectric` returns exactly 1 whenever `refract_local` finds total internal
        // reflection (they test the same `sin2_t >= 1`), which reflected above; this arm only
        // catches a transmitted ray that rounding put in the tangent plane.
        _ => Some(BsdfSample {
            pdf: 1.0,
            ..reflected
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_reflectance_matches_the_closed_form() {
        for eta in [1.0f32, 1.33, 1.5, 2.4, 0.6] {
            let by_hand = ((eta - 1.0) / (eta + 1.0)).powi(2);
            let f = fresnel_dielectric(1.0, eta);
            assert!(
                (f - by_hand).abs() < 1e-6,
                "eta {eta}: F = {f}, expected {by_hand}"
            );
            // Seen from the other side, normal incidence reflects the same fraction.
            let back = fresnel_dielectric(-1.0, eta);
            assert!(
                (back - by_hand).abs() < 1e-6,
                "eta {eta} from inside: F = {back}"
            );
        }
    }

    #[test]
    fn total_internal_reflection_starts_at_the_critical_angle() {
        let eta = 1.5f32;
        let critical = (1.0 / eta).asin();
        let below = (critical - 1e-3).cos();
        let above = (critical + 1e-3).cos();
        // From inside the glass (cos_i < 0 with the normal pointing out).
        assert!(fresnel_dielectric(-below, eta) < 1.0);
        assert_eq!(fresnel_dielectric(-above, eta), 1.0);
        let wo = Vec3::new((critical + 1e-3).sin(), 0.0, -above);
        assert!(refract_local(wo, eta).is_none());
        // From outside there is no critical angle.
        assert!(fresnel_dielectric(above, eta) < 1.0);
    }

    #[test]
    fn refraction_obeys_snell_and_is_reversible() {
        let eta = 1.5f32;
        // Not closer to grazing: the way back starts just inside the critical angle, where
        // cos_t = sqrt(1 - sin^2) amplifies rounding beyond any fixed tolerance.
        for theta in [0.0f32, 0.3, 0.9, 1.4, 1.55] {
            let wo = Vec3::new(theta.sin(), 0.0, theta.cos());
            let (wt, crossed) = refract_local(wo, eta).expect("no TIR entering a denser medium");
            assert_eq!(crossed, eta);
            assert!(wt.z < 0.0 && (wt.length() - 1.0).abs() < 1e-6);
            let sin_t = (wt.x * wt.x + wt.y * wt.y).sqrt();
            assert!(
                (theta.sin() - eta * sin_t).abs() < 1e-5,
                "Snell fails at theta {theta}"
            );
            // Tangential components point the opposite way: wo and wt are on opposite sides.
            assert!(wt.x <= 0.0);
            let (back, crossed_back) = refract_local(wt, eta).expect("the reverse path exists");
            assert_eq!(crossed_back, 1.0 / eta);
            assert!((back - wo).length() < 1e-5, "reverse of {wo} gave {back}");
        }
    }

    #[test]
    fn schlick_spans_f0_to_one() {
        let f0 = Vec3::new(0.9, 0.6, 0.2);
        assert!((fresnel_schlick(f0, 1.0) - f0).abs().max_element() < 1e-7);
        assert!((fresnel_schlick(f0, 0.0) - Vec3::ONE).abs().max_element() < 1e-7);
        // (1 - 0.5)^5 = 1/32 of the way from f0 to white.
        let mid = fresnel_schlick(f0, 0.5);
        let by_hand = Vec3::new(0.9 + 0.1 / 32.0, 0.6 + 0.4 / 32.0, 0.2 + 0.8 / 32.0);
        assert!((mid - by_hand).abs().max_element() < 1e-6, "F(0.5) = {mid}");
    }
}
