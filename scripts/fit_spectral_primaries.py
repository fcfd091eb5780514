#!/usr/bin/env python3
"""Fits the spectral primaries and the sensor of tracer/src/spectrum.rs and writes them as a Rust table.

Run from the repository root (needs numpy and scipy, `pip install scipy`):

    python3 scripts/fit_spectral_primaries.py

It overwrites tracer/src/spectrum/primaries.rs and prints the constraints' residuals, measured on
the table as written (f32 values, linear interpolation), to standard error.

What it computes, on a 5 nm grid over 380-780 nm:

* The sensor: S_c(l) = M xyz_bar(l) D65(l) / Y_D65, linear sRGB per unit of spectral radiance per
  nanometre, with M the XYZ to linear sRGB matrix of IEC 61966-2-1 and Y_D65 = integral
  y_bar D65 dl, so that a unit reflectance lit by D65 is RGB (1, 1, 1). The tabulated D65 and
  observer put D65's white a little off the rounded chromaticity (0.3127, 0.3290) that M is built
  for, so each channel is then scaled by 1 / integral S_c (a correction of a few parts in 10^4,
  printed), which makes the constant spectrum exactly white: the constraints below need that.
* The primaries (Mallett and Yuksel 2019, "Spectral Primary Decomposition for Rendering with sRGB
  Reflectance", EGSR): three spectra B_r, B_g, B_b with B >= 0, B_r + B_g + B_b = 1 at every
  wavelength and integral S_c B_d dl = delta_cd, the smoothest such (least sum of squared
  differences of neighbouring samples). Then RGB -> spectrum -> RGB is the identity in
  expectation, white stays white and an albedo in [0, 1] stays in [0, 1].

Integrals are those of the tracer: both functions are read by linear interpolation between the
grid's samples and wavelengths are drawn uniformly over 380-780 nm, so the integral of a product
of two tabulated functions is the exact integral of the product of their piecewise-linear
interpolants, h/6 (2 f_k g_k + f_k g_k+1 + f_k+1 g_k + 2 f_k+1 g_k+1) per interval.

Why 380-780 nm: the observer outside it (CIE tabulates 360-830) holds under 0.01 % of y_bar's
integral, while sampling it uniformly would spend a sixth more wavelengths where the eye sees
nearly nothing; 380-780 is the range the CIE's 5 nm tables and Mallett and Yuksel use.

Provenance of the data below (public CIE data):
* CIE 1931 2-degree colour-matching functions x_bar, y_bar, z_bar (CIE 015:2018 / CIE 018:2019,
  the 1 nm table) and the CIE standard illuminant D65 relative spectral power (ISO 11664-2,
  CIE S 014-2), both at every 5 nm from 380 to 780 nm, as tabulated in pbrt-v4's
  src/pbrt/util/spectrum.cpp (CIE_X, CIE_Y, CIE_Z, CIE_Illum_D6500), commit
  5f7a606806a4ac7b939131ded9d7a30ebd02416e of github.com/mmp/pbrt-v4. The 1 nm observer table's
  values at multiples of 5 nm are the CIE's 5 nm table.
* M: IEC 61966-2-1:1999 (sRGB), XYZ to linear RGB, to the four decimals the standard gives.
"""

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

OUTPUT = Path(__file__).resolve().parent.parent / "tracer" / "src" / "spectrum" / "primaries.rs"
FIRST_NM = 380
STEP_NM = 5

# (nm, x_bar, y_bar, z_bar, D65)
CIE = [
    (380, 0.001368, 3.9e-05, 0.006450001, 49.975498),
    (385, 0.002236, 6.4e-05, 0.01054999, 52.311798),
    (390, 0.004243, 0.00012, 0.02005001, 54.648201),
    (395, 0.00765, 0.000217, 0.03621, 68.7015),
    (400, 0.01431, 0.000396, 0.06785001, 82.754898),
    (405, 0.02319, 0.00064, 0.1102, 87.120399),
    (410, 0.04351, 0.00121, 0.2074, 91.486),
    (415, 0.07763, 0.00218, 0.3713, 92.4589),
    (420, 0.13438, 0.004, 0.6456, 93.431801),
    (425, 0.21477, 0.0073, 1.0390501, 90.056999),
    (430, 0.2839, 0.0116, 1.3856, 86.682297),
    (435, 0.3285, 0.01684, 1.62296, 95.773598),
    (440, 0.34828, 0.023, 1.74706, 104.864998),
    (445, 0.34806, 0.0298, 1.7826, 110.935997),
    (450, 0.3362, 0.038, 1.77211, 117.008003),
    (455, 0.3187, 0.048, 1.7441, 117.410004),
    (460, 0.2908, 0.06, 1.6692, 117.811996),
    (465, 0.2511, 0.0739, 1.5281, 116.335999),
    (470, 0.19536, 0.09098, 1.28764, 114.861),
    (475, 0.1421, 0.1126, 1.0419, 115.391998),
    (480, 0.09564, 0.13902, 0.8129501, 115.922997),
    (485, 0.05795001, 0.1693, 0.6162, 112.366997),
    (490, 0.03201, 0.20802, 0.46518, 108.810997),
    (495, 0.0147, 0.2586, 0.3533, 109.082001),
    (500, 0.0049, 0.323, 0.272, 109.353996),
    (505, 0.0024, 0.4073, 0.2123, 108.578003),
    (510, 0.0093, 0.503, 0.1582, 107.802002),
    (515, 0.0291, 0.6082, 0.1117, 106.295998),
    (520, 0.06327, 0.71, 0.07824999, 104.790001),
    (525, 0.1096, 0.7932, 0.05725001, 106.238998),
    (530, 0.1655, 0.862, 0.04216, 107.689003),
    (535, 0.2257499, 0.9148501, 0.02984, 106.046997),
    (540, 0.2904, 0.954, 0.0203, 104.404999),
    (545, 0.3597, 0.9803, 0.0134, 104.224998),
    (550, 0.4334499, 0.9949501, 0.008749999, 104.045998),
    (555, 0.5120501, 1.0, 0.005749999, 102.023003),
    (560, 0.5945, 0.995, 0.0039, 100.0),
    (565, 0.6784, 0.9786, 0.002749999, 98.167099),
    (570, 0.7621, 0.952, 0.0021, 96.334198),
    (575, 0.8425, 0.9154, 0.0018, 96.061096),
    (580, 0.9163, 0.87, 0.001650001, 95.788002),
    (585, 0.9786, 0.8163, 0.0014, 92.236801),
    (590, 1.0263, 0.757, 0.0011, 88.6856),
    (595, 1.0567, 0.6949, 0.001, 89.345901),
    (600, 1.0622, 0.631, 0.0008, 90.006203),
    (605, 1.0456, 0.5668, 0.0006, 89.802597),
    (610, 1.0026, 0.503, 0.00034, 89.599098),
    (615, 0.9384, 0.4412, 0.00024, 88.648903),
    (620, 0.8544499, 0.381, 0.00019, 87.6987),
    (625, 0.7514, 0.321, 0.0001, 85.493599),
    (630, 0.6424, 0.265, 4.999999e-05, 83.288597),
    (635, 0.5419, 0.217, 3e-05, 83.493896),
    (640, 0.4479, 0.175, 2e-05, 83.699203),
    (645, 0.3608, 0.1382, 1e-05, 81.862999),
    (650, 0.2835, 0.107, 0.0, 80.026802),
    (655, 0.2187, 0.0816, 0.0, 80.120697),
    (660, 0.1649, 0.061, 0.0, 80.2146),
    (665, 0.1212, 0.04458, 0.0, 81.246201),
    (670, 0.0874, 0.032, 0.0, 82.277802),
    (675, 0.0636, 0.0232, 0.0, 80.280998),
    (680, 0.04677, 0.017, 0.0, 78.284203),
    (685, 0.0329, 0.01192, 0.0, 74.002701),
    (690, 0.0227, 0.00821, 0.0, 69.721298),
    (695, 0.01584, 0.005723, 0.0, 70.665199),
    (700, 0.01135916, 0.004102, 0.0, 71.6091),
    (705, 0.008110916, 0.002929, 0.0, 72.978996),
    (710, 0.005790346, 0.002091, 0.0, 74.348999),
    (715, 0.004109457, 0.001484, 0.0, 67.976501),
    (720, 0.002899327, 0.001047, 0.0, 61.604),
    (725, 0.00204919, 0.00074, 0.0, 65.744797),
    (730, 0.001439971, 0.00052, 0.0, 69.885597),
    (735, 0.0009999493, 0.0003611, 0.0, 72.486298),
    (740, 0.0006900786, 0.0002492, 0.0, 75.086998),
    (745, 0.0004760213, 0.0001719, 0.0, 69.339798),
    (750, 0.0003323011, 0.00012, 0.0, 63.592701),
    (755, 0.0002348261, 8.48e-05, 0.0, 55.005402),
    (760, 0.0001661505, 6e-05, 0.0, 46.418201),
    (765, 0.000117413, 4.24e-05, 0.0, 56.611801),
    (770, 8.307527e-05, 3e-05, 0.0, 66.805397),
    (775, 5.870652e-05, 2.12e-05, 0.0, 65.094101),
    (780, 4.150994e-05, 1.499e-05, 0.0, 63.382801),
]

XYZ_TO_SRGB = np.array(
    [
        [3.2406, -1.5372, -0.4986],
        [-0.9689, 1.8758, 0.0415],
        [0.0557, -0.2040, 1.0570],
    ]
)


def product_weights(n, h):
    """The matrix W with f W g = integral of the product of f's and g's linear interpolants."""
    w = np.zeros((n, n))
    for k in range(n - 1):
        w[k, k] += 2 * h / 6
        w[k + 1, k + 1] += 2 * h / 6
        w[k, k + 1] += h / 6
        w[k + 1, k] += h / 6
    return w


def fit():
    table = np.array(CIE, dtype=np.float64)
    nm = table[:, 0]
    assert nm[0] == FIRST_NM and np.all(np.diff(nm) == STEP_NM), "the grid is 5 nm from 380"
    n = len(nm)
    xyz = table[:, 1:4].T
    d65 = table[:, 4]
    w = product_weights(n, STEP_NM)
    ones = np.ones(n)

    y_d65 = xyz[1] @ w @ d65
    sensor = XYZ_TO_SRGB @ (xyz * d65) / y_d65
    white = sensor @ w @ ones
    print(f"white before the per-channel correction: {white}", file=sys.stderr)
    sensor = sensor / white[:, None]

    # Unknowns: B_r and B_g at every sample; B_b = 1 - B_r - B_g. The constraints on B_b follow
    # from those on B_r and B_g, since every channel of the sensor integrates to one.
    a = sensor @ w  # a[c] . f = integral S_c f

    def bands(x):
        r, g = x[:n], x[n:]
        return np.array([r, g, 1.0 - r - g])

    def objective(x):
        b = bands(x)
        return float(np.sum(np.diff(b, axis=1) ** 2))

    def gradient(x):
        b = bands(x)
        grad = np.zeros((3, n))
        for d in range(3):
            diff = np.diff(b[d])
            grad[d, :-1] -= 2 * diff
            grad[d, 1:] += 2 * diff
        return np.concatenate([grad[0] - grad[2], grad[1] - grad[2]])

    eq = []
    for c in range(3):
        for d in range(2):
            target = 1.0 if c == d else 0.0
            row = np.zeros(2 * n)
            row[d * n : (d + 1) * n] = a[c]
            eq.append((row, target))
    eq_rows = np.array([r for r, _ in eq])
    eq_targets = np.array([t for _, t in eq])
    blue_rows = np.hstack([-np.eye(n), -np.eye(n)])

    constraints = [
        {"type": "eq", "fun": lambda x: eq_rows @ x - eq_targets, "jac": lambda x: eq_rows},
        {"type": "ineq", "fun": lambda x: 1.0 + blue_rows @ x, "jac": lambda x: blue_rows},
    ]
    # Start from the bands of a hard split at 490 and 580 nm (a partition of unity).
    start = np.concatenate([(nm >= 580).astype(float), ((nm >= 490) & (nm < 580)).astype(float)])
    result = minimize(
        objective,
        start,
        jac=gradient,
        method="SLSQP",
        bounds=[(0.0, 1.0)] * (2 * n),
        constraints=constraints,
        options={"maxiter": 2000, "ftol": 1e-15},
    )
    if not result.success:
        sys.exit(f"the fit failed: {result.message}")
    b = np.clip(bands(result.x), 0.0, 1.0)
    # The solver leaves round-off (1e-17) where a band is zero; zero it, so the table says so.
    b[b < 1e-12] = 0.0
    b = b / b.sum(axis=0)
    return nm, sensor, b, w


def to_f32_partition(b):
    """The bands in f32, nudged so that red + green + blue is exactly 1 in f32 at every sample."""
    b32 = b.astype(np.float32)
    for k in range(b32.shape[1]):
        # Blue takes what red and green leave; where that rounds, step it by ulps until the
        # left-to-right f32 sum is one.
        r, g = b32[0, k], b32[1, k]
        blue = np.float32(np.float32(1.0) - np.float32(r + g))
        for _ in range(8):
            total = np.float32(np.float32(r + g) + blue)
            if total == np.float32(1.0):
                break
            blue = np.nextafter(blue, np.float32(2.0) if total < 1 else np.float32(-1.0))
        assert np.float32(np.float32(r + g) + blue) == np.float32(1.0), f"sample {k}"
        b32[2, k] = max(blue, np.float32(0.0))
    return b32


def check(sensor32, bands32, w):
    s = sensor32.astype(np.float64)
    b = bands32.astype(np.float64)
    overlap = s @ w @ b.T
    white = s @ w @ np.ones(b.shape[1])
    worst = max(np.abs(overlap - np.eye(3)).max(), np.abs(white - 1).max())
    print(f"integral S B^T as written:\n{overlap}\nwhite: {white}", file=sys.stderr)
    assert worst < 1e-6, f"constraints off by {worst}"
    assert b.min() >= 0 and b.max() <= 1
    return worst


def rust_rows(values):
    return "\n".join(
        "    [" + ", ".join(str(np.float32(v)) for v in values[:, k]) + "],"
        for k in range(values.shape[1])
    )


def write(nm, sensor32, bands32, worst):
    n = len(nm)
    text = f"""//! GENERATED by `scripts/fit_spectral_primaries.py`; do not edit. To regenerate, run
//! `python3 scripts/fit_spectral_primaries.py` from the repository root (numpy and scipy).
//!
//! Samples every {STEP_NM} nm from {FIRST_NM} to {FIRST_NM + STEP_NM * (n - 1)} nm, read by linear interpolation
//! ([`super::basis`], [`super::sensor`]). `SENSOR` is linear sRGB per unit of spectral radiance
//! per nanometre: the CIE 1931 2-degree observer weighted by D65, through the sRGB matrix, white
//! balanced so that the constant spectrum 1 integrates to (1, 1, 1). `BANDS` are the spectral
//! primaries of Mallett and Yuksel 2019 fitted to it: at least 0, summing to 1 in f32 at every
//! sample, and `integral SENSOR_c BANDS_d = delta_cd` to within {worst:.1e} as written. The
//! script's docstring gives the data's provenance and the fit.

/// The wavelength of the first sample, in nanometres.
pub(super) const FIRST_NM: f32 = {FIRST_NM}.0;
/// The distance between samples, in nanometres.
pub(super) const STEP_NM: f32 = {STEP_NM}.0;
/// The number of samples.
pub(super) const SAMPLES: usize = {n};

/// The sensor's (red, green, blue) at each sample.
#[rustfmt::skip]
pub(super) const SENSOR: [[f32; 3]; SAMPLES] = [
{rust_rows(sensor32)}
];

/// The (red, green, blue) spectral primaries at each sample.
#[rustfmt::skip]
pub(super) const BANDS: [[f32; 3]; SAMPLES] = [
{rust_rows(bands32)}
];
"""
    OUTPUT.write_text(text)
    print(f"wrote {OUTPUT}", file=sys.stderr)


def main():
    nm, sensor, bands, w = fit()
    sensor32 = sensor.astype(np.float32)
    bands32 = to_f32_partition(bands)
    worst = check(sensor32, bands32, w)
    write(nm, sensor32, bands32, worst)


if __name__ == "__main__":
    main()
