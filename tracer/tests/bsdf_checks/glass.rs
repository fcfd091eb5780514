//! Smooth dielectrics: the Fresnel split between reflection and refraction, total internal
//! reflection, and the 1/eta^2 radiance factor on refraction.
//!
//! The reflectance under test is checked against a transmittance computed from the transmission
//! amplitudes, a formula the implementation does not use, so that R + T = 1 says something.

use super::direction;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_2, PI};
use tracer::material::{Bsdf, fresnel_dielectric};

/// The relative index crossed by a ray leaving along `wo`, and the Fresnel transmittance
/// computed from the transmission amplitudes (Hecht, Optics, eq. 4.34 and 4.35), independently
/// of `fresnel_dielectric`, which computes reflection amplitudes. `None` under total internal
/// reflection.
fn transmittance_by_amplitudes(wo: Vec3, ior: f64) -> (f64, Option<f64>) {
    let eta = if wo.z > 0.0 { ior } else { 1.0 / ior };
    let cos_i = f64::from(wo.z.abs());
    let sin_t = (1.0 - cos_i * cos_i).max(0.0).sqrt() / eta;
    if sin_t >= 1.0 {
        return (eta, None);
    }
    let cos_t = (1.0 - sin_t * sin_t).sqrt();
    let t_perpendicular = 2.0 * cos_i / (cos_i + eta * cos_t);
    let t_parallel = 2.0 * cos_i / (eta * cos_i + cos_t);
    let ratio = eta * cos_t / cos_i;
    let t = 0.5 * ratio * (t_perpendicular.powi(2) + t_parallel.powi(2));
    (eta, Some(t))
}

#[test]
fn dielectric_splits_energy_by_fresnel() {
    let tint = Vec3::ONE;
    let strata = 100_000;
    for ior in [1.5f32, 1.33, 2.4, 0.7] {
        let bsdf = Bsdf::Dielectric { ior, tint };
        for theta in [0.0, 0.4, 0.9, 1.3, 1.52, PI - 0.2, PI - 0.7, PI - 1.4] {
            let wo = direction(theta, 2.0);
            let (eta, t) = transmittance_by_amplitudes(wo, f64::from(ior));
            let r = f64::from(fresnel_dielectric(wo.z, ior));
            let t = t.unwrap_or(0.0);
            let name = format!("ior {ior}, wo {wo}");
            assert!((r + t - 1.0).abs() < 1e-5, "{name}: R + T = {r} + {t}");
            let (mut transmitted, mut energy, mut radiance) = (0usize, 0.0f64, 0.0f64);
            for k in 0..strata {
                let u_choice = (k as f32 + 0.5) / strata as f32;
                let s = bsdf
                    .sample(wo, u_choice, Vec2::splat(0.5))
                    .expect("smooth glass scatters");
                assert!(s.delta && s.wi.is_finite(), "{name}: {s:?}");
                assert!(
                    s.transmission == (s.wi.z * wo.z < 0.0),
                    "{name}: side flag {s:?}"
                );
                let w = f64::from(s.weight.x);
                radiance += w;
                if s.transmission {
                    transmitted += 1;
                    // The radiance factor: 1 / eta^2 for the index crossed.
                    let expected = 1.0 / (eta * eta);
                    assert!((w - expected).abs() < 1e-5 * expected, "{name}: weight {w}");
                    energy += w * eta * eta;
                } else {
                    assert_eq!(s.wi, Vec3::new(-wo.x, -wo.y, wo.z), "{name}: not a mirror");
                    assert_eq!(w, 1.0, "{name}: reflection weight");
                    energy += w;
                }
            }
            let fraction = transmitted as f64 / strata as f64;
            assert!(
                (fraction - t).abs() < 2.0 / strata as f64 + 1e-5,
                "{name}: T {fraction}"
            );
            // R + T = 1: the interface neither creates nor destroys energy...
            assert!(
                (energy / strata as f64 - 1.0).abs() < 1e-6,
                "{name}: energy {energy}"
            );
            // ...while radiance changes by 1/eta^2 on the transmitted part.
            let expected = r + t / (eta * eta);
            let mean = radiance / strata as f64;
            assert!(
                (mean - expected).abs() < 1e-4,
                "{name}: throughput {mean} vs {expected}"
            );
        }
    }
}

#[test]
fn tint_multiplies_transmission_only() {
    let tint = Vec3::new(0.2, 0.5, 0.9);
    let bsdf = Bsdf::Dielectric { ior: 1.5, tint };
    let wo = direction(0.5, 0.0);
    let reflected = bsdf
        .sample(wo, 0.0, Vec2::ZERO)
        .expect("reflection at u_choice = 0");
    assert_eq!(reflected.weight, Vec3::ONE);
    let refracted = bsdf
        .sample(wo, 0.999, Vec2::ZERO)
        .expect("refraction at u_choice ~ 1");
    assert!(refracted.transmission);
    assert!(
        (refracted.weight - tint / 2.25).abs().max_element() < 1e-6,
        "{refracted:?}"
    );
}

#[test]
fn fresnel_at_normal_incidence_matches_hand_computation() {
    // ((1.5 - 1) / (1.5 + 1))^2 = (0.5 / 2.5)^2 = 0.04; ((2 - 1) / (2 + 1))^2 = 1/9.
    assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-7);
    assert!((fresnel_dielectric(1.0, 2.0) - 1.0 / 9.0).abs() < 1e-7);
    assert!(
        (fresnel_dielectric(-1.0, 1.5) - 0.04).abs() < 1e-7,
        "from inside"
    );
    assert_eq!(
        fresnel_dielectric(1.0, 1.0),
        0.0,
        "index-matched interfaces do not reflect"
    );
    // The BSDF draws reflection exactly when u_choice < F.
    let glass = Bsdf::Dielectric {
        ior: 1.5,
        tint: Vec3::ONE,
    };
    let below = glass
        .sample(Vec3::Z, 0.0399, Vec2::ZERO)
        .expect("normal incidence scatters");
    let above = glass
        .sample(Vec3::Z, 0.0401, Vec2::ZERO)
        .expect("normal incidence scatters");
    assert!(!below.transmission && below.wi == Vec3::Z, "{below:?}");
    assert!(
        above.transmission && (above.wi + Vec3::Z).length() < 1e-6,
        "{above:?}"
    );
    assert!((below.pdf - 0.04).abs() < 1e-6 && (above.pdf - 0.96).abs() < 1e-6);
}

#[test]
fn total_internal_reflection_beyond_the_critical_angle() {
    // Inside glass (wo below the surface, the normal pointing out), and outside a medium less
    // dense than vacuum's surroundings (ior < 1), where the same happens from the front.
    for (ior, inside) in [(1.5f32, true), (0.7, false)] {
        let bsdf = Bsdf::Dielectric {
            ior,
            tint: Vec3::ONE,
        };
        let critical = if inside {
            (1.0 / ior).asin()
        } else {
            ior.asin()
        };
        let wo_at = |theta: f32| {
            let w = direction(theta, 0.8);
            if inside { Vec3::new(w.x, w.y, -w.z) } else { w }
        };
        for theta in [critical + 1e-3, critical + 0.2, 1.5, FRAC_PI_2 - 1e-4] {
            let wo = wo_at(theta);
            assert_eq!(
                fresnel_dielectric(wo.z, ior),
                1.0,
                "ior {ior}, theta {theta}"
            );
            for u_choice in [0.0, 0.5, 1.0 - f32::EPSILON] {
                let s = bsdf.sample(wo, u_choice, Vec2::ZERO).expect("TIR reflects");
                assert!(!s.transmission && s.wi.z * wo.z > 0.0, "ior {ior}: {s:?}");
                assert_eq!(s.weight, Vec3::ONE, "ior {ior}, theta {theta}");
            }
        }
        let wo = wo_at(critical - 0.02);
        let f = fresnel_dielectric(wo.z, ior);
        assert!(f < 1.0, "ior {ior}: TIR before the critical angle");
        let s = bsdf
            .sample(wo, 0.5 * (1.0 + f), Vec2::ZERO)
            .expect("refracts");
        assert!(s.transmission && s.wi.z * wo.z < 0.0, "ior {ior}: {s:?}");
    }
}
