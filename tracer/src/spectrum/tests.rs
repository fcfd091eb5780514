//! The spectral pipeline's tests: the primaries and the sensor against published CIE data,
//! the round trip, hero wavelengths, and what an RGB or a dispersed path does.

use super::*;

/// The integral over the sampled range of `f`, by the midpoint rule on a fine grid,
/// summed in f64 so that the sum's own rounding stays far below the tolerances.
fn integrate(f: impl Fn(f32) -> Vec3) -> [f64; 3] {
    let steps = 40_000;
    let h = f64::from(LAMBDA_MAX - LAMBDA_MIN) / steps as f64;
    let mut sum = [0.0f64; 3];
    for i in 0..steps {
        let v = f((f64::from(LAMBDA_MIN) + (i as f64 + 0.5) * h) as f32);
        for (s, v) in sum.iter_mut().zip(v.to_array()) {
            *s += f64::from(v) * h;
        }
    }
    sum
}

/// The sRGB standard's (IEC 61966-2-1) linear RGB to XYZ matrix, as published, rows X, Y, Z:
/// typed in, not derived from the sensor's own matrix.
const SRGB_TO_XYZ: [[f32; 3]; 3] = [
    [0.4124, 0.3576, 0.1805],
    [0.2126, 0.7152, 0.0722],
    [0.0193, 0.1192, 0.9505],
];

fn xyz(rgb: Vec3) -> Vec3 {
    let row = |r: [f32; 3]| Vec3::from(r).dot(rgb);
    Vec3::new(
        row(SRGB_TO_XYZ[0]),
        row(SRGB_TO_XYZ[1]),
        row(SRGB_TO_XYZ[2]),
    )
}

#[test]
fn the_bands_are_a_partition_of_unity_in_zero_one() {
    for i in 0..=4000 {
        let nm = LAMBDA_MIN + i as f32 * 0.1;
        let b = basis(nm);
        let sum = b.x + b.y + b.z;
        assert!((sum - 1.0).abs() <= 2.0 * f32::EPSILON, "{sum} at {nm} nm");
        assert!(
            b.min_element() >= 0.0 && b.max_element() <= 1.0,
            "{b} at {nm} nm"
        );
    }
    // Where the table has a sample, the sum is exactly one: the script saw to it in f32.
    for i in 0..primaries::SAMPLES {
        let b = Vec3::from(primaries::BANDS[i]);
        assert_eq!(b.x + b.y + b.z, 1.0, "sample {i}");
    }
    // Violet and blue light falls mostly in the blue band, green in the green, red in the red.
    assert_eq!(channel(basis(450.0)), 2);
    assert_eq!(channel(basis(530.0)), 1);
    assert_eq!(channel(basis(650.0)), 0);
}

#[test]
fn rgb_to_spectrum_and_back_is_the_identity() {
    // The sensor measures each band as exactly its own channel, through the tracer's own
    // interpolation of the table, integrated independently of the script's quadrature.
    for (c, unit) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
        let measured = integrate(|nm| sensor(nm) * basis(nm).dot(unit));
        for (d, m) in measured.into_iter().enumerate() {
            let expected = if c == d { 1.0 } else { 0.0 };
            assert!((m - expected).abs() < 1e-4, "band {c}, channel {d}: {m}");
        }
    }
}

#[test]
fn the_equal_energy_spectrum_is_white() {
    // The sensor carries D65's weighting: the constant spectrum 1 (a unit reflectance under
    // the D65 the sensor assumes) is RGB (1, 1, 1), sRGB's white.
    let white = integrate(sensor);
    for w in white {
        assert!((w - 1.0).abs() < 1e-4, "{white:?}");
    }
}

#[test]
fn monochromatic_light_lies_on_the_spectral_locus() {
    // CIE 1931 2-degree chromaticity coordinates (x, y) of monochromatic light, from the
    // CIE's published table (CIE 015:2018), typed in. They are given to five decimals and
    // the sRGB matrices to four, which bounds how close the sensor can come.
    let locus = [
        (450.0, 0.15664, 0.01771),
        (475.0, 0.10959, 0.08684),
        (500.0, 0.00817, 0.53842),
        (520.0, 0.07430, 0.83380),
        (550.0, 0.30160, 0.69231),
        (600.0, 0.62704, 0.37249),
        (650.0, 0.72599, 0.27401),
        (700.0, 0.73469, 0.26531),
    ];
    for (nm, x, y) in locus {
        let c = xyz(sensor(nm));
        let sum = c.x + c.y + c.z;
        let (seen_x, seen_y) = (c.x / sum, c.y / sum);
        assert!(
            (seen_x - x).abs() < 3e-4 && (seen_y - y).abs() < 3e-4,
            "{nm} nm: ({seen_x}, {seen_y}), the CIE gives ({x}, {y})"
        );
    }
}

#[test]
fn the_sensors_luminance_is_y_bar_times_d65() {
    // y_bar (CIE 1931, 5 nm table) and D65's relative power (ISO 11664-2) as published,
    // typed in; the luminance the sensor gives a wavelength, relative to 560 nm's, must be
    // their product's.
    let at_560 = 0.995 * 100.0;
    let published = [
        (450.0, 0.038, 117.008),
        (500.0, 0.323, 109.354),
        (600.0, 0.631, 90.006),
        (650.0, 0.107, 80.027),
    ];
    let luminance = |nm: f32| xyz(sensor(nm)).y;
    for (nm, y_bar, d65) in published {
        let seen = luminance(nm) / luminance(560.0);
        let expected = y_bar * d65 / at_560;
        assert!(
            (seen / expected - 1.0).abs() < 2e-3,
            "{nm} nm: {seen}, published {expected}"
        );
    }
}

#[test]
fn hero_wavelengths_are_stratified_and_cover_the_range() {
    let visible = visible::Visible::new();
    for u in [0.0f32, 0.2, 0.5, 0.999] {
        let w = Wavelengths::sample(u);
        // A third of the density apart: the images of u, u + 1/3 and u + 2/3.
        for (i, offset) in [0.0f32, 1.0 / 3.0, 2.0 / 3.0].into_iter().enumerate() {
            let x = (u + offset).fract();
            assert_eq!(w.nm[i], visible.sample(x), "slot {i} of {u}");
            assert_eq!(w.pdf[i], visible.pdf(w.nm[i]));
            assert!(w.nm[i] >= LAMBDA_MIN && w.nm[i] < LAMBDA_MAX, "{:?}", w.nm);
        }
    }
}

#[test]
fn an_rgb_path_is_left_alone() {
    let sampler = PixelSampler::new(1, 0, 2, 3, 4);
    let (rgb, beta) = PathSpectrum::start(SpectralSampling::Auto, &sampler);
    assert_eq!(beta, Vec3::ONE);
    let v = Vec3::new(0.3, 0.7, 0.1);
    assert_eq!(rgb.of(v), v);
    assert_eq!(rgb.channels(v), v);
    assert_eq!(rgb.finish(v), v);
    let glass = Bsdf::Dielectric { ior: 1.5, tint: v };
    let mut seen = glass;
    rgb.see_bsdf(&mut seen);
    assert_eq!(seen, glass);
}

#[test]
fn dispersing_keeps_the_first_wavelength_three_times() {
    let sampler = PixelSampler::new(1, 0, 2, 3, 4);
    let (mut spectrum, mut beta) = PathSpectrum::start(SpectralSampling::Hero, &sampler);
    let mut radiance = Vec3::ZERO;
    beta *= 0.5;
    spectrum.disperse(&sampler, &mut beta, &mut radiance);
    assert_eq!(beta, Vec3::new(1.5, 0.0, 0.0));
    spectrum.disperse(&sampler, &mut beta, &mut radiance);
    assert_eq!(beta, Vec3::new(1.5, 0.0, 0.0), "ended once only");
}
