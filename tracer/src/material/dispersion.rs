//! Glass whose index of refraction depends on the wavelength: Cauchy's and Sellmeier's formulas,
//! and a small catalogue of named glasses.
//!
//! Both formulas take the wavelength in micrometres, as optical catalogues (Schott, Ohara,
//! refractiveindex.info) quote their coefficients, so a user can copy them unchanged:
//! - Cauchy: `n(l) = A + B / l^2` (B in um^2). Two terms are enough over the visible range for
//!   most glasses, to a few parts in 10^4.
//! - Sellmeier: `n(l)^2 = 1 + sum_i B_i l^2 / (l^2 - C_i)` (C_i in um^2), three terms, the form
//!   of the Schott catalogue; accurate to about 10^-5 where fitted.
//!
//! The index is computed in f32 with basic operations and a square root only (both exact IEEE
//! operations), so it is the same on every machine. Where a path meets such a glass the
//! integrator turns spectral (`crate::spectrum`) and asks for the index at the path's wavelength.

/// How a dispersive glass's index depends on the wavelength.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dispersion {
    /// `n = a + b / l^2`, `l` in micrometres.
    Cauchy {
        /// The index the glass tends to at long wavelengths.
        a: f32,
        /// How much the index rises towards the blue, in square micrometres.
        b: f32,
    },
    /// `n^2 = 1 + sum b_i l^2 / (l^2 - c_i)`, `l` and `sqrt(c_i)` in micrometres.
    Sellmeier {
        /// The strengths of the three absorption resonances (dimensionless).
        b: [f32; 3],
        /// The squares of the three resonances' wavelengths, in square micrometres.
        c: [f32; 3],
    },
}

/// What the scene format says of a number that is not finite.
const NOT_FINITE: &str = "must be finite numbers (one overflows 32-bit floats or is nan/inf)";

/// The glasses a scene may name (`glass = "NAME"`), with their Sellmeier coefficients.
pub const GLASSES: [(&str, Dispersion); 3] = [
    // Schott N-BK7, the common borosilicate crown: n_d 1.5168, Abbe number 64.17.
    (
        "bk7",
        Dispersion::Sellmeier {
            b: [1.039_612, 0.231_792_34, 1.010_469_5],
            c: [0.006_000_698_7, 0.020_017_914, 103.560_65],
        },
    ),
    // Fused silica (Malitson 1965, C_i given squared here): n_d 1.4585, Abbe number 67.8.
    (
        "fused-silica",
        Dispersion::Sellmeier {
            b: [0.696_166_3, 0.407_942_6, 0.897_479_4],
            c: [0.004_679_148, 0.013_512_06, 97.934],
        },
    ),
    // Schott N-SF11, a dense flint: n_d 1.78472, Abbe number 25.68, the classic prism glass.
    (
        "sf11",
        Dispersion::Sellmeier {
            b: [1.737_597, 0.313_747_35, 1.898_781],
            c: [0.013_188_707, 0.062_306_814, 155.236_3],
        },
    ),
];

impl Dispersion {
    /// The named glass of [`GLASSES`], if any.
    pub fn named(name: &str) -> Option<Dispersion> {
        GLASSES.iter().find(|(n, _)| *n == name).map(|(_, d)| *d)
    }

    /// Cauchy's `[A, B]` as a scene gives it, checked: two finite numbers, B not negative
    /// (normal dispersion: blue bends more), an index of at least 1 ([`Dispersion::check`]).
    pub fn cauchy(v: &[f32]) -> Result<Dispersion, String> {
        let &[a, b] = v else {
            return Err(format!("must be two numbers `[A, B]`, not {}", v.len()));
        };
        if !a.is_finite() || !b.is_finite() {
            return Err(NOT_FINITE.to_owned());
        }
        if b < 0.0 {
            return Err(format!(
                "B = {b} must not be negative (glass disperses normally: blue bends more)"
            ));
        }
        let glass = Dispersion::Cauchy { a, b };
        glass.check().map(|()| glass)
    }

    /// Sellmeier's `[B1, B2, B3, C1, C2, C3]` as a scene gives them, checked: six finite
    /// numbers, none negative, and [`Dispersion::check`].
    pub fn sellmeier(v: &[f32]) -> Result<Dispersion, String> {
        let &[b1, b2, b3, c1, c2, c3] = v else {
            return Err(format!(
                "must be six numbers `[B1, B2, B3, C1, C2, C3]`, not {}",
                v.len()
            ));
        };
        if v.iter().any(|x| !x.is_finite()) {
            return Err(NOT_FINITE.to_owned());
        }
        if v.iter().any(|&x| x < 0.0) {
            return Err("no coefficient may be negative".to_owned());
        }
        let glass = Dispersion::Sellmeier {
            b: [b1, b2, b3],
            c: [c1, c2, c3],
        };
        glass.check().map(|()| glass)
    }

    /// The index of refraction at `nanometres`.
    pub fn ior(&self, nanometres: f32) -> f32 {
        let l = nanometres * 1e-3;
        let l2 = l * l;
        match *self {
            Dispersion::Cauchy { a, b } => a + b / l2,
            Dispersion::Sellmeier { b, c } => {
                let n2 = 1.0
                    + b[0] * l2 / (l2 - c[0])
                    + b[1] * l2 / (l2 - c[1])
                    + b[2] * l2 / (l2 - c[2]);
                n2.max(0.0).sqrt()
            }
        }
    }

    /// Whether the coefficients give an index of at least 1, finite and without a pole, over
    /// the wavelengths the renderer samples; the error says what is wrong, for the loader.
    pub fn check(&self) -> Result<(), String> {
        let (lo, hi) = (crate::spectrum::LAMBDA_MIN, crate::spectrum::LAMBDA_MAX);
        if let Dispersion::Sellmeier { c, .. } = self {
            let (lo_um, hi_um) = (lo * 1e-3, hi * 1e-3);
            let (lo2, hi2) = (lo_um * lo_um, hi_um * hi_um);
            if let Some(c) = c.iter().find(|c| (lo2..=hi2).contains(*c)) {
                return Err(format!(
                    "C = {c} um^2 puts a pole at {:.0} nm, inside the rendered range {lo}-{hi} nm",
                    c.sqrt() * 1e3
                ));
            }
        }
        // Every nanometre: n is smooth between poles, so a dip below 1 cannot hide between them.
        for (nm, n) in self.rendered_indices() {
            if !n.is_finite() || n < 1.0 {
                return Err(format!(
                    "the index at {nm} nm is {n}: it must be finite and at least 1 over {lo}-{hi} nm"
                ));
            }
        }
        Ok(())
    }

    /// The smallest and the largest index over the wavelengths the renderer samples, taken every
    /// nanometre as [`Dispersion::check`] does: what the loader holds against the accepted
    /// relative indices once it knows what surrounds the glass.
    pub fn index_range(&self) -> (f32, f32) {
        self.rendered_indices()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(low, high), (_, n)| {
                (low.min(n), high.max(n))
            })
    }

    /// (wavelength in nm, index) at every whole nanometre of the rendered range.
    fn rendered_indices(&self) -> impl Iterator<Item = (f32, f32)> + '_ {
        let (lo, hi) = (crate::spectrum::LAMBDA_MIN, crate::spectrum::LAMBDA_MAX);
        (0..=(hi - lo) as u32).map(move |step| {
            let nm = lo + step as f32;
            (nm, self.ior(nm))
        })
    }

    /// The index at the helium d line (587.56 nm), the one catalogues quote as `n_d`: what a
    /// dispersive glass is taken to be where no wavelength is known.
    pub fn ior_d(&self) -> f32 {
        self.ior(587.56)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_glasses_have_their_published_index_and_abbe_number() {
        // (name, n_d, V_d) from the Schott catalogue and Malitson.
        for (name, n_d, abbe) in [
            ("bk7", 1.5168, 64.17),
            ("fused-silica", 1.4585, 67.8),
            ("sf11", 1.78472, 25.68),
        ] {
            let glass = Dispersion::named(name).expect("a catalogue glass");
            let n = |nm: f32| f64::from(glass.ior(nm));
            assert!((n(587.56) - n_d).abs() < 2e-4, "{name}: n_d {}", n(587.56));
            // Abbe number: (n_d - 1) / (n_F - n_C), F = 486.13 nm, C = 656.27 nm.
            let v = (n(587.56) - 1.0) / (n(486.13) - n(656.27));
            assert!((v - abbe).abs() < 0.3, "{name}: V_d {v}, published {abbe}");
            assert!(glass.check().is_ok());
        }
        assert_eq!(Dispersion::named("crown"), None);
    }

    #[test]
    fn bad_coefficients_are_refused() {
        let below_one = Dispersion::Cauchy { a: 0.9, b: 0.001 };
        assert!(below_one.check().unwrap_err().contains("at least 1"));
        let pole = Dispersion::Sellmeier {
            b: [1.0, 0.0, 0.0],
            c: [0.25, 0.0, 0.0],
        };
        assert!(pole.check().unwrap_err().contains("pole at 500 nm"));
        let fine = Dispersion::Cauchy { a: 1.5, b: 0.004 };
        assert!(fine.check().is_ok());
        assert!((fine.ior(500.0) - (1.5 + 0.004 / 0.25)).abs() < 1e-6);
    }
}
