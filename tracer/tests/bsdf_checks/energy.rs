//! Energy: how much of the light arriving along `wo` a BSDF scatters at all (its directional
//! albedo, the integral of f |cos theta_i| over the sphere).
//!
//! A passive surface cannot scatter more than it receives, and a lobe that does makes a path
//! tracer's estimates grow without bound over bounces. The albedo is estimated two ways that
//! share no code path: the mean sample weight (what the renderer computes) and quadrature of
//! `eval` over uniform directions. Each must stay at or below 1, they must agree with each other,
//! and where physics gives the exact answer (white Lambertian, unit mirror) they must find it.

use super::chi2::Rng;
use super::{direction, uniform_sphere};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use tracer::material::Bsdf;

/// A Monte Carlo estimate with its standard error.
struct Estimate {
    mean: f64,
    error: f64,
}

fn estimate(values: impl Iterator<Item = f64>) -> Estimate {
    let (mut n, mut sum, mut sum2) = (0.0, 0.0, 0.0);
    for v in values {
        n += 1.0;
        sum += v;
        sum2 += v * v;
    }
    let mean = sum / n;
    let variance = (sum2 / n - mean * mean).max(0.0);
    Estimate {
        mean,
        error: (variance / n).sqrt(),
    }
}

/// The directional albedo (integral of f |cos| over the sphere, averaged over channels) as the
/// mean sample weight: the estimator the renderer itself uses.
fn albedo_by_sampling(bsdf: Bsdf, wo: Vec3, n: usize, seed: u64) -> Estimate {
    let mut rng = Rng::new(seed);
    estimate((0..n).map(|_| {
        let u_choice = rng.next_f32();
        match bsdf.sample(wo, u_choice, rng.next_vec2()) {
            Some(s) => f64::from(s.weight.element_sum()) / 3.0,
            None => 0.0,
        }
    }))
}

/// The same integral from `eval` alone, by uniform directions jittered in an (cos theta, phi)
/// grid. The reported error is that of unstratified sampling, which bounds the stratified one.
fn albedo_by_quadrature(bsdf: Bsdf, wo: Vec3, side: usize, seed: u64) -> Estimate {
    let mut rng = Rng::new(seed);
    let cells = (0..side * side).map(|k| ((k / side) as f32, (k % side) as f32));
    estimate(cells.map(|(i, j)| {
        let u = (Vec2::new(i, j) + rng.next_vec2()) / side as f32;
        let wi = uniform_sphere(u);
        4.0 * std::f64::consts::PI * f64::from(bsdf.eval(wo, wi).element_sum()) / 3.0
    }))
}

#[test]
fn white_lambertian_albedo_is_one() {
    let bsdf = Bsdf::Diffuse {
        albedo: Vec3::ONE,
        texture: None,
    };
    for theta in [0.0, 0.8, 1.5, PI - 0.3] {
        let wo = direction(theta, 1.0);
        let sampled = albedo_by_sampling(bsdf, wo, 100_000, 1);
        assert!(
            (sampled.mean - 1.0).abs() < 1e-6,
            "sampling at {wo}: {}",
            sampled.mean
        );
        let quad = albedo_by_quadrature(bsdf, wo, 500, 2);
        let tolerance = 4.0 * quad.error;
        assert!(
            (quad.mean - 1.0).abs() < tolerance,
            "quadrature at {wo}: {}",
            quad.mean
        );
    }
}

#[test]
fn unit_mirror_reflects_everything() {
    let bsdf = Bsdf::Mirror {
        reflectance: Vec3::ONE,
    };
    for theta in [0.0, 0.8, 1.5, PI - 0.3] {
        let wo = direction(theta, 1.0);
        let sampled = albedo_by_sampling(bsdf, wo, 1000, 3);
        assert_eq!(sampled.mean, 1.0, "mirror at {wo}");
    }
}

#[test]
fn albedo_never_exceeds_one() {
    let mut cases = vec![(
        Bsdf::Diffuse {
            albedo: Vec3::splat(0.999),
            texture: None,
        },
        1.0,
    )];
    for alpha in [0.05, 0.3, 0.8, 1.0] {
        // With F = 1 only masking and shadowing lose energy; single scattering cannot gain any.
        cases.push((
            Bsdf::Conductor {
                f0: Vec3::ONE,
                alpha,
            },
            0.0,
        ));
    }
    for (k, (bsdf, _)) in cases.iter().enumerate() {
        for (m, theta) in [0.0, 0.7, 1.35, 1.55, PI - 0.9].into_iter().enumerate() {
            let wo = direction(theta, 0.3);
            let seed = (k * 10 + m) as u64;
            let sampled = albedo_by_sampling(*bsdf, wo, 200_000, seed);
            let quad = albedo_by_quadrature(*bsdf, wo, 1000, seed + 1000);
            let name = format!("{bsdf:?} at theta {theta}");
            assert!(
                sampled.mean <= 1.0 + 4.0 * sampled.error,
                "{name}: {}",
                sampled.mean
            );
            assert!(
                quad.mean <= 1.0 + 4.0 * quad.error,
                "{name}: quadrature {}",
                quad.mean
            );
            let both = (sampled.error.powi(2) + quad.error.powi(2)).sqrt();
            assert!(
                (sampled.mean - quad.mean).abs() <= 4.0 * both,
                "{name}: sampling gives {} +- {}, quadrature {} +- {}",
                sampled.mean,
                sampled.error,
                quad.mean,
                quad.error
            );
        }
    }
    // A nearly smooth white conductor seen head-on loses almost nothing to masking.
    let smooth = Bsdf::Conductor {
        f0: Vec3::ONE,
        alpha: 0.05,
    };
    let head_on = albedo_by_sampling(smooth, Vec3::Z, 100_000, 77);
    assert!(
        head_on.mean > 0.99,
        "alpha 0.05 head-on albedo {}",
        head_on.mean
    );
}
