//! Glass inside glass: a `glass` material loaded with `outside_ior` reflects and refracts as the
//! Fresnel equations and Snell's law say for its two real indices, on either side, including an
//! outside denser than the inside (an air bubble in water), where total internal reflection
//! happens on the outside. Every expected value comes from the two indices by hand, in f64.

use super::{Bsdf, BsdfSample};
use crate::sampler::PixelSampler;
use crate::scene::load_str;
use crate::spectrum::{PathSpectrum, SpectralSampling};
use glam::{Vec2, Vec3};

/// (inside, outside) index pairs: glass in air, glass in water, water in glass, an air bubble
/// in water, diamond in glass, an index-matched pair, and a glass in a much denser one.
const PAIRS: [(f32, f32); 7] = [
    (1.5, 1.0),
    (1.5, 1.33),
    (1.33, 1.5),
    (1.0, 1.33),
    (2.4, 1.5),
    (1.33, 1.33),
    (1.2, 3.0),
];

/// Angles of incidence, in radians, from normal to nearly grazing.
const ANGLES: [f64; 6] = [0.0, 0.2, 0.5, 0.8, 1.1, 1.45];

/// The BSDF of a scene's glass material whose table's index keys are `keys`, a ball inside a
/// larger ball of glass of index `outside`, as the loader's nesting check wants it.
fn loaded_in(keys: &str, outside: f32) -> Bsdf {
    let toml = format!(
        "camera = {{ position = [0, 0, -5], look_at = [0, 0, 0] }}\n\
         object = [{{ shape = \"sphere\", material = \"g\" }},\n\
         {{ shape = \"sphere\", radius = 3, material = \"around\" }}]\n\
         [materials.g]\ntype = \"glass\"\n{keys}\n\
         [materials.around]\ntype = \"glass\"\nior = {outside}\n"
    );
    let scene = load_str(&toml).unwrap_or_else(|e| panic!("{keys}: {e}"));
    scene.materials[0].bsdf
}

/// The BSDF of a scene's glass material whose table's index keys are `keys`, in vacuum.
fn loaded(keys: &str) -> Bsdf {
    loaded_in(keys, 1.0)
}

fn glass(inside: f32, outside: f32) -> Bsdf {
    loaded_in(&format!("ior = {inside}\noutside_ior = {outside}"), outside)
}

/// The sample taken with `u_choice = 1`: the refraction whenever one exists (its `pdf` is then
/// 1 - F), the reflection under total internal reflection.
fn refract(bsdf: &Bsdf, wo: Vec3) -> BsdfSample {
    bsdf.sample(wo, 1.0, Vec2::splat(0.5))
        .expect("glass scatters every direction off the tangent plane")
}

/// The unpolarised Fresnel reflectance from index `n1` into `n2` at incidence `theta`.
fn fresnel(n1: f64, n2: f64, theta: f64) -> f64 {
    let sin_t = n1 / n2 * theta.sin();
    if sin_t >= 1.0 {
        return 1.0;
    }
    let (ci, ct) = (theta.cos(), (1.0 - sin_t * sin_t).sqrt());
    let rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct);
    let rp = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct);
    0.5 * (rs * rs + rp * rp)
}

/// A unit direction at `theta` from the normal, on the outside (`side` 1) or inside (-1).
fn at(theta: f64, side: f32) -> Vec3 {
    Vec3::new(theta.sin() as f32, 0.0, side * theta.cos() as f32)
}

fn sin_of(w: Vec3) -> f64 {
    f64::from((w.x * w.x + w.y * w.y).sqrt())
}

#[test]
fn normal_incidence_reflects_the_closed_form_from_both_sides() {
    for (inside, outside) in PAIRS {
        let bsdf = glass(inside, outside);
        let (n1, n2) = (f64::from(inside), f64::from(outside));
        let by_hand = ((n1 - n2) / (n1 + n2)).powi(2);
        for side in [1.0f32, -1.0] {
            let s = refract(&bsdf, Vec3::new(0.0, 0.0, side));
            assert!(s.transmission, "{inside} in {outside}, side {side}: {s:?}");
            let f = 1.0 - f64::from(s.pdf);
            assert!(
                (f - by_hand).abs() < 1e-6,
                "{inside} in {outside}, side {side}: F = {f}, expected {by_hand}"
            );
            assert!((s.wi - Vec3::new(0.0, 0.0, -side)).length() < 1e-6);
        }
    }
    // Index-matched, the interface reflects nothing at all.
    assert_eq!(refract(&glass(1.33, 1.33), Vec3::Z).pdf, 1.0);
}

#[test]
fn refraction_and_reflectance_follow_the_two_real_indices_on_either_side() {
    for (inside, outside) in PAIRS {
        let bsdf = glass(inside, outside);
        let (n_in, n_out) = (f64::from(inside), f64::from(outside));
        // wo outside: the far side (wi) is inside, and the other way round.
        for (side, n_near, n_far) in [(1.0f32, n_out, n_in), (-1.0, n_in, n_out)] {
            for theta in ANGLES {
                let what = format!("{inside} in {outside}, side {side}, theta {theta}");
                let s = refract(&bsdf, at(theta, side));
                let f = fresnel(n_near, n_far, theta);
                if n_near * theta.sin() >= n_far {
                    assert!(!s.transmission && s.pdf == 1.0, "{what}: no TIR: {s:?}");
                    continue;
                }
                assert!(s.transmission, "{what}: {s:?}");
                assert!(s.wi.z * side < 0.0 && (s.wi.length() - 1.0).abs() < 1e-6);
                // The tangential components point the other way: wo and wi face apart.
                assert!(s.wi.x <= 0.0 && s.wi.y == 0.0, "{what}: {}", s.wi);
                let (near, far) = (n_near * theta.sin(), n_far * sin_of(s.wi));
                assert!((near - far).abs() < 2e-6, "{what}: Snell {near} vs {far}");
                let got_f = 1.0 - f64::from(s.pdf);
                assert!((got_f - f).abs() < 2e-6, "{what}: F {got_f}, expected {f}");
                // Radiance is scaled by (n_near / n_far)^2: L / n^2 is invariant.
                let scale = (n_near / n_far).powi(2);
                let got = f64::from(s.weight.x);
                assert!((got - scale).abs() < 2e-6 * scale, "{what}: weight {got}");
            }
        }
    }
}

#[test]
fn total_internal_reflection_starts_at_the_critical_angle_on_the_denser_side() {
    for (inside, outside) in PAIRS.into_iter().filter(|(i, o)| i != o) {
        let bsdf = glass(inside, outside);
        let (n_in, n_out) = (f64::from(inside), f64::from(outside));
        let critical = (n_in.min(n_out) / n_in.max(n_out)).asin();
        // The denser side: outside for a bubble (water around air), inside for glass in air.
        let dense = if n_out > n_in { 1.0f32 } else { -1.0 };
        let what = format!("{inside} in {outside}");
        let below = refract(&bsdf, at(critical - 1e-3, dense));
        assert!(below.transmission, "{what}: reflected below {critical}");
        let above = refract(&bsdf, at(critical + 1e-3, dense));
        assert!(!above.transmission && above.pdf == 1.0, "{what}: {above:?}");
        assert_eq!(above.wi, super::reflect_local(at(critical + 1e-3, dense)));
        // From the rarer side, light gets through up to grazing.
        for theta in [critical + 1e-3, 1.5] {
            let s = refract(&bsdf, at(theta, -dense));
            assert!(s.transmission, "{what}: TIR from the rarer side at {theta}");
        }
    }
}

#[test]
fn an_outside_index_of_one_keeps_the_glass_bit_for_bit() {
    for ior in [1.0f32, 1.33, 1.5, 2.4] {
        let plain = loaded(&format!("ior = {ior}"));
        assert_eq!(plain, glass(ior, 1.0));
        let Bsdf::Dielectric { ior: kept, .. } = plain else {
            panic!("{plain:?}")
        };
        assert_eq!(kept.to_bits(), ior.to_bits());
    }
    let dispersive = loaded("glass = \"bk7\"");
    assert_eq!(dispersive, loaded("glass = \"bk7\"\noutside_ior = 1"));
}

#[test]
fn dispersive_glass_refracts_by_its_index_at_the_wavelength_over_the_outside_index() {
    // Cauchy's n = A + B / lambda^2 (lambda in micrometres), worked out here in f64.
    let (a, b) = (1.6, 0.01);
    let cauchy = |nm: f64| a + b / (nm * 1e-3).powi(2);
    for outside in [1.0f32, 1.33, 1.9] {
        let bsdf = loaded_in(
            &format!("cauchy = [{a}, {b}]\noutside_ior = {outside}"),
            outside,
        );
        let n_out = f64::from(outside);
        // An RGB path samples the glass at the d line; spectral paths at their wavelength.
        let mut cases = vec![(bsdf, 587.56)];
        for nm in [420.0f32, 550.0, 680.0] {
            let sampler = PixelSampler::new(1, 0, 2, 3, 4);
            let (spectrum, _) = PathSpectrum::start(SpectralSampling::Monochrome(nm), &sampler);
            let mut seen = bsdf;
            spectrum.see_bsdf(&mut seen);
            cases.push((seen, f64::from(nm)));
        }
        for (resolved, nm) in cases {
            let n_in = cauchy(nm);
            for theta in [0.0, 0.4, 0.9, 1.3] {
                let what = format!("outside {outside}, {nm} nm, theta {theta}");
                let s = refract(&resolved, at(theta, 1.0));
                if n_out * theta.sin() >= n_in {
                    assert!(!s.transmission && s.pdf == 1.0, "{what}: no TIR: {s:?}");
                    continue;
                }
                assert!(s.transmission, "{what}");
                let (near, far) = (n_out * theta.sin(), n_in * sin_of(s.wi));
                assert!((near - far).abs() < 2e-6, "{what}: Snell {near} vs {far}");
                let f = fresnel(n_out, n_in, theta);
                let got_f = 1.0 - f64::from(s.pdf);
                assert!((got_f - f).abs() < 2e-6, "{what}: F {got_f}, expected {f}");
            }
        }
    }
}
