//! Chi-square goodness of fit of a direction sampler against the density it claims, after
//! pbrt-v4's `bsdfs_test.cpp` and Mitsuba 3's `chi2.py`.
//!
//! A sampler and its `pdf` are written separately, so they drift apart silently: a wrong Jacobian
//! or a forgotten G1 still renders plausible images, only biased. This test catches that. The
//! sphere is cut into cells of equal extent in (cos theta, phi); each cell's expected count is
//! the number of samples times the pdf integrated over the cell, the observed count is how many
//! samples landed there, and one more cell counts the samples that failed (`None`), whose
//! expected share is what the pdf leaves of 1. Cells with small expectations are pooled, and the
//! chi-square statistic's p-value says how surprising the observed counts are if sampler and pdf
//! agree.
//!
//! Also here: the deterministic generator every check uses, since test outcomes must not depend
//! on a run's luck, and the chi-square survival function (the regularised upper incomplete gamma
//! function), written out because the workspace has no statistics crate.

use glam::{Vec2, Vec3};
use std::f64::consts::PI;

/// Cells along cos theta; an even number, so that the horizon (cos theta = 0), where reflection
/// densities jump, falls on a cell boundary and not inside a cell.
const N_COS: usize = 64;
/// Cells along phi.
const N_PHI: usize = 128;
/// Cells expected to hold fewer samples than this are pooled, so that the chi-square
/// approximation of the statistic's distribution holds (the usual rule of thumb).
const MIN_EXPECTED: f64 = 5.0;

/// SplitMix64: a tiny generator with full-period 64-bit state, deterministic per seed.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 24 bits, as the renderer's sampler produces them.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    pub fn next_vec2(&mut self) -> Vec2 {
        let x = self.next_f32();
        Vec2::new(x, self.next_f32())
    }
}

/// The result of one goodness-of-fit test.
#[derive(Debug)]
pub struct Fit {
    pub p_value: f64,
    pub chi2: f64,
    pub dof: usize,
    /// The cells that contributed most to the statistic, for the failure message.
    pub worst: String,
}

/// Draws `samples` directions with `sample` and compares their histogram with `pdf`.
///
/// Returns `Err` when the comparison is decided without statistics: a sample landed where the
/// pdf is exactly zero, or there are too few populated cells for a test.
pub fn fit(
    samples: usize,
    mut sample: impl FnMut(&mut Rng) -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f64,
    seed: u64,
) -> Result<Fit, String> {
    let failures = N_COS * N_PHI;
    let mut observed = vec![0.0f64; failures + 1];
    let mut rng = Rng::new(seed);
    for _ in 0..samples {
        match sample(&mut rng) {
            Some(w) => observed[cell_of(w)] += 1.0,
            None => observed[failures] += 1.0,
        }
    }

    let n = samples as f64;
    let mut expected = vec![0.0f64; failures + 1];
    for i in 0..N_COS {
        for j in 0..N_PHI {
            expected[i * N_PHI + j] = integrate_cell(&pdf, i, j, n) * n;
        }
    }
    let total: f64 = expected[..failures].iter().sum();
    expected[failures] = (n - total).max(0.0);

    for (cell, (&o, &e)) in observed.iter().zip(&expected).enumerate() {
        if o > 0.0 && e == 0.0 {
            return Err(format!(
                "{o} samples in {} where the pdf is zero",
                describe(cell)
            ));
        }
    }
    chi2_pooled(&observed, &expected)
}

/// Pools the cells with small expectations (smallest first, until the pool is large enough),
/// then computes the statistic and its p-value.
fn chi2_pooled(observed: &[f64], expected: &[f64]) -> Result<Fit, String> {
    let mut order: Vec<usize> = (0..expected.len()).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let (mut pool_o, mut pool_e, mut first) = (0.0, 0.0, 0);
    while let Some(&cell) = order.get(first) {
        let e = expected[cell];
        // Stop at the first well-populated cell once the pool is empty or large enough itself.
        if e >= MIN_EXPECTED && (pool_e == 0.0 || pool_e >= MIN_EXPECTED) {
            break;
        }
        pool_o += observed[cell];
        pool_e += e;
        first += 1;
    }
    let mut terms: Vec<(f64, String)> = Vec::new();
    if pool_e > 0.0 {
        let term = (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        terms.push((
            term,
            format!("pool of {first} cells: {pool_o} vs {pool_e:.1}"),
        ));
    }
    for &cell in &order[first..] {
        let (o, e) = (observed[cell], expected[cell]);
        terms.push((
            (o - e) * (o - e) / e,
            format!("{}: {o} vs {e:.1}", describe(cell)),
        ));
    }
    if terms.len() < 3 {
        return Err(format!(
            "only {} populated cells: too few for a test",
            terms.len()
        ));
    }
    let chi2: f64 = terms.iter().map(|t| t.0).sum();
    let dof = terms.len() - 1;
    terms.sort_by(|a, b| b.0.total_cmp(&a.0));
    let worst = terms
        .iter()
        .take(4)
        .map(|t| format!("{} (+{:.1})", t.1, t.0));
    Ok(Fit {
        p_value: chi2_survival(chi2, dof as f64),
        chi2,
        dof,
        worst: worst.collect::<Vec<_>>().join("; "),
    })
}

fn cell_of(w: Vec3) -> usize {
    let c = f64::from(w.z).clamp(-1.0, 1.0);
    let i = (((c + 1.0) * 0.5 * N_COS as f64) as usize).min(N_COS - 1);
    let mut phi = f64::from(w.y).atan2(f64::from(w.x));
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let j = ((phi / (2.0 * PI) * N_PHI as f64) as usize).min(N_PHI - 1);
    i * N_PHI + j
}

fn describe(cell: usize) -> String {
    if cell == N_COS * N_PHI {
        return "the failed-sample cell".to_string();
    }
    let (i, j) = (cell / N_PHI, cell % N_PHI);
    let c0 = -1.0 + 2.0 * i as f64 / N_COS as f64;
    let phi0 = 360.0 * j as f64 / N_PHI as f64;
    format!(
        "cell cos [{c0:.3}, {:.3}) phi [{phi0:.1}, {:.1}) deg",
        c0 + 2.0 / N_COS as f64,
        phi0 + 360.0 / N_PHI as f64
    )
}

/// The pdf's integral over cell (i, j) by composite Simpson in (theta, phi), doubling the
/// resolution until two successive estimates differ by much less than the cell's sampling noise
/// (sqrt of its expected count out of `n`). Integrating in theta rather than cos theta keeps
/// peaks at the poles (a narrow lobe around the normal) smooth in the integration variable.
fn integrate_cell(pdf: &impl Fn(Vec3) -> f64, i: usize, j: usize, n: f64) -> f64 {
    let c0 = -1.0 + 2.0 * i as f64 / N_COS as f64;
    let c1 = c0 + 2.0 / N_COS as f64;
    let (theta0, theta1) = (c1.clamp(-1.0, 1.0).acos(), c0.clamp(-1.0, 1.0).acos());
    // Nudge the bounds inwards (by a negligible sliver) so that nodes on the horizon see the
    // one-sided limit of the density on this cell's side, not the zero of the tangent plane.
    let nudge = 1e-6 * (theta1 - theta0);
    let (theta0, theta1) = (theta0 + nudge, theta1 - nudge);
    let phi0 = 2.0 * PI * j as f64 / N_PHI as f64;
    let phi1 = phi0 + 2.0 * PI / N_PHI as f64;
    let simpson = |k: usize| {
        let (ht, hp) = ((theta1 - theta0) / k as f64, (phi1 - phi0) / k as f64);
        let weight = |m: usize| match m {
            0 => 1.0,
            m if m == k => 1.0,
            m if m % 2 == 1 => 4.0,
            _ => 2.0,
        };
        let mut sum = 0.0;
        for a in 0..=k {
            let theta = theta0 + a as f64 * ht;
            let (sin, cos) = theta.sin_cos();
            for b in 0..=k {
                let phi = phi0 + b as f64 * hp;
                let w = Vec3::new(
                    (sin * phi.cos()) as f32,
                    (sin * phi.sin()) as f32,
                    cos as f32,
                );
                sum += weight(a) * weight(b) * pdf(w) * sin;
            }
        }
        sum * ht * hp / 9.0
    };
    let mut k = 4;
    let mut coarse = simpson(k);
    loop {
        k *= 2;
        let fine = simpson(k);
        let difference = (fine - coarse).abs() * n;
        if difference < 0.02 * (fine * n).max(1.0).sqrt() || k >= 512 {
            // Richardson extrapolation: Simpson's error falls as h^4.
            return fine + (fine - coarse) / 15.0;
        }
        coarse = fine;
    }
}

/// P(X > x) for X chi-square distributed with `dof` degrees of freedom.
pub fn chi2_survival(x: f64, dof: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    gamma_q(0.5 * dof, 0.5 * x)
}

/// The regularised upper incomplete gamma function Q(a, x), by its series for x < a + 1 and by
/// its continued fraction (modified Lentz) otherwise: each converges fast in its own region
/// (Numerical Recipes, section 6.2).
fn gamma_q(a: f64, x: f64) -> f64 {
    let log_prefactor = -x + a * x.ln() - ln_gamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..1_000_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (1.0 - sum * log_prefactor.exp()).max(0.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1_000_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (log_prefactor.exp() * h).clamp(0.0, 1.0)
    }
}

/// ln Gamma(x) for x > 0 by the Lanczos approximation (g = 7, 9 terms; relative error ~1e-15).
fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const COEFFICIENTS: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection formula: Gamma(x) Gamma(1 - x) = pi / sin(pi x).
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut sum = COEFFICIENTS[0];
    for (k, &c) in COEFFICIENTS.iter().enumerate().skip(1) {
        sum += c / (x + k as f64);
    }
    let t = x + G + 0.5;
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}
