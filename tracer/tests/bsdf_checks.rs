//! Statistical and physical checks of the BSDFs, through their public interface only.
//!
//! A BSDF can be wrong in ways no image shows at a glance: a sampler that disagrees with its
//! pdf biases every MIS-weighted estimate, a lobe that reflects more than it receives makes
//! lighting explode slowly over bounces, a missing 1/eta^2 makes glass too bright. Each test below
//! pins one such property with a check that fails when it is broken:
//! - goodness of fit of `sample` against `pdf` (chi-square; the machinery is in
//!   `bsdf_checks/chi2.rs`), together with a demonstration that the test rejects a slightly wrong
//!   pdf;
//! - energy (`bsdf_checks/energy.rs`): albedo <= 1 by two independent estimators, exactly 1 where
//!   physics says so;
//! - glass (`bsdf_checks/glass.rs`): the Fresnel split, total internal reflection, the radiance
//!   factor;
//! - reciprocity, `weight == eval / pdf`, and no NaN or infinity for degenerate directions and
//!   parameters.
//!
//! All randomness comes from fixed seeds, so a failure reproduces bit for bit.

#[path = "bsdf_checks/chi2.rs"]
mod chi2;
#[path = "bsdf_checks/energy.rs"]
mod energy;
#[path = "bsdf_checks/glass.rs"]
mod glass;

use chi2::Rng;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use tracer::material::Bsdf;

/// The family-wise significance level of all goodness-of-fit tests in this file together.
const SIGNIFICANCE: f64 = 0.01;
/// Samples per goodness-of-fit test.
const FIT_SAMPLES: usize = 1_000_000;
/// Polar angles of `wo` for the diffuse fits; beyond pi/2, `wo` is below the surface.
const DIFFUSE_THETAS: [f32; 3] = [0.3, 1.2, PI - 0.7];
/// Polar angles of `wo` for the conductor fits: normal incidence (the VNDF sampler's special
/// case), oblique, grazing, and seen from the back.
const CONDUCTOR_THETAS: [f32; 4] = [0.0, 0.7, 1.4, PI - 1.0];
const CONDUCTOR_ALPHAS: [f32; 3] = [0.05, 0.3, 0.8];
/// How many goodness-of-fit tests this file runs, for the Sidak correction.
const FIT_TESTS: usize = DIFFUSE_THETAS.len() + CONDUCTOR_THETAS.len() * CONDUCTOR_ALPHAS.len();

/// The per-test level that keeps the chance of any false rejection at [`SIGNIFICANCE`].
fn sidak_level() -> f64 {
    1.0 - (1.0 - SIGNIFICANCE).powf(1.0 / FIT_TESTS as f64)
}

fn direction(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Runs one goodness-of-fit test of `bsdf` at `wo` and says whether it rejects.
fn fit_rejects(bsdf: Bsdf, wo: Vec3, pdf: impl Fn(Vec3) -> f64, seed: u64) -> Result<(), String> {
    let sample = |rng: &mut Rng| {
        let u_choice = rng.next_f32();
        let s = bsdf.sample(wo, u_choice, rng.next_vec2())?;
        assert!(!s.delta, "{bsdf:?} produced a delta sample");
        Some(s.wi)
    };
    match chi2::fit(FIT_SAMPLES, sample, pdf, seed) {
        Err(reason) => Err(reason),
        Ok(fit) if fit.p_value < sidak_level() => Err(format!(
            "p = {:.3e} < {:.3e} (chi2 = {:.1} with {} dof); worst: {}",
            fit.p_value,
            sidak_level(),
            fit.chi2,
            fit.dof,
            fit.worst
        )),
        Ok(_) => Ok(()),
    }
}

fn assert_fits(bsdf: Bsdf, theta: f32, seed: u64) {
    let wo = direction(theta, 0.4);
    if let Err(reason) = fit_rejects(bsdf, wo, |wi| f64::from(bsdf.pdf(wo, wi)), seed) {
        panic!("{bsdf:?} at wo = {wo}: sample disagrees with pdf: {reason}");
    }
}

#[test]
fn diffuse_sampling_fits_its_pdf() {
    let bsdf = Bsdf::Diffuse {
        albedo: Vec3::new(0.8, 0.5, 0.2),
        texture: None,
    };
    for (k, theta) in DIFFUSE_THETAS.into_iter().enumerate() {
        assert_fits(bsdf, theta, 100 + k as u64);
    }
}

fn conductor_fits(alpha: f32, seed: u64) {
    let bsdf = Bsdf::Conductor {
        f0: Vec3::new(0.95, 0.6, 0.3),
        alpha,
    };
    for (k, theta) in CONDUCTOR_THETAS.into_iter().enumerate() {
        assert_fits(bsdf, theta, seed + k as u64);
    }
}

#[test]
fn conductor_sampling_fits_its_pdf_at_alpha_0_05() {
    conductor_fits(CONDUCTOR_ALPHAS[0], 200);
}

#[test]
fn conductor_sampling_fits_its_pdf_at_alpha_0_3() {
    conductor_fits(CONDUCTOR_ALPHAS[1], 300);
}

#[test]
fn conductor_sampling_fits_its_pdf_at_alpha_0_8() {
    conductor_fits(CONDUCTOR_ALPHAS[2], 400);
}

#[test]
fn goodness_of_fit_rejects_a_slightly_wrong_pdf() {
    // The sampler of alpha = 0.3 against the pdf of alpha = 0.33: a 10% roughness error.
    let sampled = Bsdf::Conductor {
        f0: Vec3::ONE,
        alpha: 0.3,
    };
    let claimed = Bsdf::Conductor {
        f0: Vec3::ONE,
        alpha: 0.33,
    };
    let wo = direction(0.7, 0.4);
    let wrong_alpha = fit_rejects(sampled, wo, |wi| f64::from(claimed.pdf(wo, wi)), 500);
    assert!(
        wrong_alpha.is_err(),
        "a pdf with the wrong roughness passed"
    );

    // The pdf of plain D(h) cos sampling where visible normals are sampled: G1(wo) forgotten.
    let (alpha, wo) = (0.8f32, direction(1.4, 0.4));
    let bsdf = Bsdf::Conductor {
        f0: Vec3::ONE,
        alpha,
    };
    let s = (wo.z * wo.z + alpha * alpha * (wo.x * wo.x + wo.y * wo.y)).sqrt();
    let g1 = 2.0 * wo.z / (wo.z + s);
    let no_g1 = fit_rejects(bsdf, wo, |wi| f64::from(bsdf.pdf(wo, wi) / g1), 501);
    assert!(no_g1.is_err(), "a pdf without the masking term passed");

    // Cosine-weighted samples against a uniform-hemisphere pdf.
    let diffuse = Bsdf::Diffuse {
        albedo: Vec3::ONE,
        texture: None,
    };
    let uniform = |wi: Vec3| {
        if wi.z > 0.0 {
            0.5 / std::f64::consts::PI
        } else {
            0.0
        }
    };
    assert!(
        fit_rejects(diffuse, Vec3::Z, uniform, 502).is_err(),
        "uniform pdf passed"
    );
}

#[test]
fn chi_square_survival_matches_reference_values() {
    // Reference values from mpmath 1.3: gammainc(dof / 2, x / 2, inf, regularized=True).
    let references = [
        (3.841458820694124, 1.0, 0.05),
        (18.307038053275146, 10.0, 0.05),
        (124.342113404, 100.0, 0.05),
        (1106.969, 1000.0, 0.009_999_996_853_907_445),
        (2.0, 7.0, 0.959_840_368_730_101_6),
        (5000.0, 5001.0, 0.501_329_868_177_318_8),
        (20500.0, 20001.0, 0.006_609_533_248_889_083),
    ];
    for (x, dof, q) in references {
        let p = chi2::chi2_survival(x, dof);
        assert!(
            (p - q).abs() < 1e-9 * q.max(1e-3),
            "Q({x}; {dof} dof) = {p}, expected {q}"
        );
    }
    // For even dof = 2k the survival function is a Poisson sum: e^(-x/2) sum_{i<k} (x/2)^i / i!.
    for k in 1..40 {
        for x in [0.5, 3.0, 20.0, 75.0] {
            let (half, mut term, mut sum) = (0.5 * x, 1.0f64, 0.0f64);
            for i in 0..k {
                if i > 0 {
                    term *= half / i as f64;
                }
                sum += term;
            }
            let expected = (-half).exp() * sum;
            let p = chi2::chi2_survival(x, 2.0 * k as f64);
            assert!(
                (p - expected).abs() < 1e-10,
                "Q({x}; {} dof) = {p} vs {expected}",
                2 * k
            );
        }
    }
}

fn rough_materials() -> Vec<Bsdf> {
    let mut out = vec![Bsdf::Diffuse {
        albedo: Vec3::new(0.7, 0.4, 0.1),
        texture: None,
    }];
    for alpha in [0.01, 0.05, 0.3, 0.8, 1.0] {
        out.push(Bsdf::Conductor {
            f0: Vec3::new(0.95, 0.64, 0.54),
            alpha,
        });
    }
    out
}

#[test]
fn diffuse_and_conductor_are_reciprocal() {
    let mut rng = Rng::new(11);
    for bsdf in rough_materials() {
        for _ in 0..20_000 {
            let wo = uniform_sphere(rng.next_vec2());
            let mut wi = uniform_sphere(rng.next_vec2());
            if wi.z * wo.z < 0.0 {
                wi.z = -wi.z;
            }
            // f = eval / |cos|; at grazing angles that division amplifies rounding too much.
            if wo.z.abs() < 0.02 || wi.z.abs() < 0.02 {
                continue;
            }
            let forward = bsdf.eval(wo, wi) / wi.z.abs();
            let backward = bsdf.eval(wi, wo) / wo.z.abs();
            let scale = forward.abs().max(backward.abs()).max_element();
            let gap = (forward - backward).abs().max_element();
            assert!(
                gap <= 1e-4 * scale,
                "{bsdf:?}: f({wo}, {wi}) = {forward}, reversed {backward}"
            );
            assert!(scale > 0.0 || matches!(bsdf, Bsdf::Conductor { alpha, .. } if alpha < 0.1));
            let across = Vec3::new(wi.x, wi.y, -wi.z);
            assert_eq!(bsdf.eval(wo, across), Vec3::ZERO, "{bsdf:?} transmits");
            assert_eq!(bsdf.eval(across, wo), Vec3::ZERO, "{bsdf:?} transmits");
        }
    }
}

#[test]
fn sample_weight_is_eval_over_pdf() {
    let mut rng = Rng::new(12);
    for bsdf in rough_materials() {
        let mut successes = 0;
        for _ in 0..50_000 {
            let wo = uniform_sphere(rng.next_vec2());
            let u_choice = rng.next_f32();
            let Some(s) = bsdf.sample(wo, u_choice, rng.next_vec2()) else {
                continue;
            };
            successes += 1;
            let name = format!("{bsdf:?} at wo {wo}: {s:?}");
            assert!(!s.delta && !s.transmission, "{name}");
            assert!(
                (s.wi.length() - 1.0).abs() < 1e-5 && s.wi.z * wo.z > 0.0,
                "{name}"
            );
            let pdf = bsdf.pdf(wo, s.wi);
            assert!(
                pdf > 0.0 && (pdf - s.pdf).abs() <= 1e-5 * pdf,
                "{name}: pdf {pdf}"
            );
            let ratio = bsdf.eval(wo, s.wi) / pdf;
            let gap = (ratio - s.weight).abs().max_element();
            assert!(
                gap <= 1e-4 * ratio.max_element().max(1e-6),
                "{name}: eval/pdf {ratio}"
            );
        }
        // Failures are only reflections that leave below the horizon; at high roughness and grazing
        // `wo` that is common, but never the majority.
        assert!(
            successes > 25_000,
            "{bsdf:?}: only {successes} of 50000 samples succeeded"
        );
    }
}

#[test]
fn degenerate_inputs_stay_finite() {
    let tiny = f32::MIN_POSITIVE * 1e-3; // subnormal
    let mut directions = vec![Vec3::Z, -Vec3::Z, Vec3::X, -Vec3::Y, Vec3::ZERO];
    for z in [1e-7f32, 1e-20, tiny, 0.0] {
        let r = (1.0 - z * z).sqrt();
        directions.extend([Vec3::new(r, 0.0, z), Vec3::new(0.0, -r, -z)]);
        directions.push(Vec3::new(r * 0.6, r * 0.8, -z));
    }
    directions.push(Vec3::new(1e-20, 0.0, 1.0));
    let mut materials = vec![
        Bsdf::Diffuse {
            albedo: Vec3::ZERO,
            texture: None,
        },
        Bsdf::Diffuse {
            albedo: Vec3::ONE,
            texture: Some(0),
        },
        Bsdf::Mirror {
            reflectance: Vec3::ONE,
        },
    ];
    for alpha in [
        0.0,
        1e-12,
        1e-4,
        0.05,
        1.0,
        7.0,
        -1.0,
        f32::NAN,
        f32::INFINITY,
    ] {
        for f0 in [Vec3::ZERO, Vec3::ONE] {
            materials.push(Bsdf::Conductor { f0, alpha });
        }
    }
    for ior in [
        1.0,
        1.0 + 1e-7,
        1.5,
        1e-9,
        1e9,
        0.0,
        -1.0,
        f32::NAN,
        f32::INFINITY,
    ] {
        for tint in [Vec3::ZERO, Vec3::ONE] {
            materials.push(Bsdf::Dielectric { ior, tint });
        }
    }
    let us = [0.0, 0.5, 1.0 - f32::EPSILON / 2.0, 1.0];
    for bsdf in &materials {
        for &wo in &directions {
            for &wi in &directions {
                let f = bsdf.eval(wo, wi);
                let pdf = bsdf.pdf(wo, wi);
                assert!(
                    f.is_finite() && f.min_element() >= 0.0,
                    "{bsdf:?} eval({wo}, {wi}) = {f}"
                );
                assert!(
                    pdf.is_finite() && pdf >= 0.0,
                    "{bsdf:?} pdf({wo}, {wi}) = {pdf}"
                );
            }
            for u_choice in us {
                for (ux, uy) in us.iter().flat_map(|&x| us.iter().map(move |&y| (x, y))) {
                    let Some(s) = bsdf.sample(wo, u_choice, Vec2::new(ux, uy)) else {
                        continue;
                    };
                    let name = format!("{bsdf:?} sample({wo}, {u_choice}, {ux}, {uy}) = {s:?}");
                    assert!(
                        s.wi.is_finite() && (s.wi.length() - 1.0).abs() < 1e-3,
                        "{name}"
                    );
                    assert!(
                        s.weight.is_finite() && s.weight.min_element() >= 0.0,
                        "{name}"
                    );
                    assert!(s.pdf.is_finite() && s.pdf > 0.0, "{name}");
                    assert!(s.wi.z != 0.0, "{name}: sample in the tangent plane");
                }
            }
        }
    }
}

/// Walter et al. 2007's microfacet BRDF times cos theta_i, written in its textbook form (tangents
/// and Lambda, f64) rather than the division-free form the implementation uses.
fn textbook_conductor(f0: f64, alpha: f64, wo: Vec3, wi: Vec3) -> f64 {
    let (wo, wi) = (wo.as_dvec3(), wi.as_dvec3());
    let h = (wo + wi).normalize();
    let tan2 = |z: f64| (1.0 - z * z) / (z * z);
    let d = 1.0
        / (std::f64::consts::PI
            * alpha.powi(2)
            * h.z.powi(4)
            * (1.0 + tan2(h.z) / alpha.powi(2)).powi(2));
    let lambda = |z: f64| ((1.0 + alpha * alpha * tan2(z)).sqrt() - 1.0) / 2.0;
    let g2 = 1.0 / (1.0 + lambda(wo.z) + lambda(wi.z));
    let f = f0 + (1.0 - f0) * (1.0 - wo.dot(h)).powi(5);
    d * g2 * f / (4.0 * wo.z * wi.z) * wi.z
}

#[test]
fn conductor_matches_the_textbook_formula() {
    // One case by hand: alpha = 0.5 at normal incidence has D = 1 / (pi 0.25), G2 = 1, F = f0,
    // so f cos = (4 / pi) * 0.5 / 4 = 0.5 / pi.
    let bsdf = Bsdf::Conductor {
        f0: Vec3::splat(0.5),
        alpha: 0.5,
    };
    let head_on = bsdf.eval(Vec3::Z, Vec3::Z).x;
    assert!((head_on - 0.5 / PI).abs() < 1e-6, "head-on value {head_on}");
    let mut rng = Rng::new(13);
    for alpha in [0.05f32, 0.3, 0.8, 1.0] {
        let bsdf = Bsdf::Conductor {
            f0: Vec3::new(0.04, 0.5, 0.9),
            alpha,
        };
        for _ in 0..20_000 {
            let wo = uniform_sphere(rng.next_vec2());
            let wi = uniform_sphere(rng.next_vec2());
            let (wo, wi) = (wo.with_z(wo.z.abs()), wi.with_z(wi.z.abs()));
            if wo.z < 0.05 || wi.z < 0.05 {
                continue;
            }
            let value = bsdf.eval(wo, wi);
            for (channel, f0) in [0.04, 0.5, 0.9].into_iter().enumerate() {
                let expected = textbook_conductor(f0, f64::from(alpha), wo, wi);
                let got = f64::from(value[channel]);
                assert!(
                    (got - expected).abs() <= 1e-4 * expected + 1e-12,
                    "alpha {alpha}, wo {wo}, wi {wi}, f0 {f0}: {got} vs {expected}"
                );
            }
        }
    }
}
