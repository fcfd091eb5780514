//! Piecewise-constant distributions in one and two dimensions, for importance sampling tabulated
//! functions (an environment map's luminance).
//!
//! The domain is [0, 1) in each dimension, cut into as many equal cells as the function has
//! values; a sample lands in a cell with probability proportional to its value and uniformly
//! within it, so the density is the cell's value over the function's integral. Cumulative sums
//! are taken in f64 and stored in f32: with a million cells, f32 running sums would lose the
//! small cells beside a bright sun. A cell whose value is zero is never sampled, and one with a
//! positive value always can be, so the density is positive exactly where the function is.

use glam::Vec2;

/// The largest f32 below 1: samples stay inside the half-open domain.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// A piecewise-constant density on [0, 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution1D {
    func: Vec<f32>,
    /// `cdf[i]` is the probability of the cells before `i`; `cdf[n]` is exactly 1.
    cdf: Vec<f32>,
    /// The integral of the function over [0, 1): the mean of `func`.
    integral: f64,
}

impl Distribution1D {
    /// The distribution proportional to `func`; `None` when `func` is empty, has a negative or
    /// non-finite value, or sums to zero.
    pub fn new(func: Vec<f32>) -> Option<Self> {
        if func.is_empty() || func.iter().any(|f| !f.is_finite() || *f < 0.0) {
            return None;
        }
        let total: f64 = func.iter().map(|&f| f64::from(f)).sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let mut cdf = Vec::with_capacity(func.len() + 1);
        let mut running = 0.0f64;
        cdf.push(0.0);
        for &f in &func {
            running += f64::from(f);
            cdf.push((running / total) as f32);
        }
        *cdf.last_mut().expect("cdf has n + 1 >= 2 entries") = 1.0;
        let integral = total / func.len() as f64;
        Some(Self {
            func,
            cdf,
            integral,
        })
    }

    /// The number of cells, one per value of the function.
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// Always false for a distribution [`Distribution1D::new`] made (it refuses an empty
    /// function); here because clippy pairs it with `len`.
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// The mean of the function: its integral over [0, 1).
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// A point in [0, 1) for `u` in [0, 1), its density, and its cell.
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        // The cell whose cumulative range [cdf[i], cdf[i + 1]) holds u; an empty range (a zero
        // value) never does.
        let cell = (self.cdf.partition_point(|&c| c <= u).max(1) - 1).min(self.func.len() - 1);
        let (lo, hi) = (self.cdf[cell], self.cdf[cell + 1]);
        let within = if hi > lo { (u - lo) / (hi - lo) } else { 0.5 };
        let x = ((cell as f32 + within) / self.func.len() as f32).min(ONE_MINUS_EPSILON);
        (x, self.cell_pdf(cell), cell)
    }

    /// The density of the cell that holds `x` in [0, 1).
    pub fn pdf(&self, x: f32) -> f32 {
        self.cell_pdf(self.cell_of(x))
    }

    /// The cell that holds `x`, clamped into the domain.
    pub fn cell_of(&self, x: f32) -> usize {
        let n = self.func.len();
        ((x.max(0.0) * n as f32) as usize).min(n - 1)
    }

    fn cell_pdf(&self, cell: usize) -> f32 {
        (f64::from(self.func[cell]) / self.integral) as f32
    }
}

/// A piecewise-constant density on [0, 1)^2: rows (the second coordinate) by a marginal
/// distribution of their integrals, then a column within the row by the row's own distribution.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution2D {
    /// One per row that has a positive integral; `None` for rows that are zero throughout.
    rows: Vec<Option<Distribution1D>>,
    marginal: Distribution1D,
    width: usize,
}

impl Distribution2D {
    /// The distribution proportional to `func`, `width` values per row, rows top first; `None`
    /// when the function is zero everywhere or has a negative or non-finite value.
    pub fn new(func: &[f32], width: usize) -> Option<Self> {
        if width == 0 || func.is_empty() || !func.len().is_multiple_of(width) {
            return None;
        }
        if func.iter().any(|f| !f.is_finite() || *f < 0.0) {
            return None;
        }
        let rows: Vec<Option<Distribution1D>> = func
            .chunks(width)
            .map(|row| Distribution1D::new(row.to_vec()))
            .collect();
        let row_integrals = rows
            .iter()
            .map(|r| r.as_ref().map_or(0.0, |r| r.integral() as f32))
            .collect();
        let marginal = Distribution1D::new(row_integrals)?;
        Some(Self {
            rows,
            marginal,
            width,
        })
    }

    /// A point in [0, 1)^2 (`x` along rows, `y` down the rows) for `u` in [0, 1)^2 and its
    /// density: `u.y` picks the row, `u.x` the place in it. The density is [`Self::pdf`] at the
    /// point, computed the same way, so a later lookup of the same point agrees to the bit.
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (y, _, row) = self.marginal.sample(u.y);
        let row = self.rows[row]
            .as_ref()
            .expect("the marginal never picks a row whose integral is zero");
        let (x, _, _) = row.sample(u.x);
        let point = Vec2::new(x, y);
        (point, self.pdf(point))
    }

    /// The density at `p` in [0, 1)^2.
    pub fn pdf(&self, p: Vec2) -> f32 {
        let row = self.marginal.cell_of(p.y);
        let Some(distribution) = &self.rows[row] else {
            return 0.0;
        };
        let x = distribution.cell_of(p.x);
        (f64::from(distribution.func[x]) / self.marginal.integral) as f32
    }

    /// Cells per row: the tabulated function's width.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The number of rows: the tabulated function's height.
    pub fn height(&self) -> usize {
        self.rows.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::PixelSampler;

    #[test]
    fn bad_functions_give_no_distribution() {
        assert!(Distribution1D::new(vec![]).is_none());
        assert!(Distribution1D::new(vec![0.0, 0.0]).is_none());
        assert!(Distribution1D::new(vec![1.0, -1.0]).is_none());
        assert!(Distribution1D::new(vec![1.0, f32::NAN]).is_none());
        assert!(Distribution2D::new(&[0.0; 6], 3).is_none());
        assert!(Distribution2D::new(&[1.0; 5], 3).is_none());
    }

    #[test]
    fn zero_cells_are_never_sampled_and_every_sample_stays_in_the_domain() {
        let d = Distribution1D::new(vec![0.0, 3.0, 0.0, 1.0, 0.0]).unwrap();
        for u in [0.0, 1e-7, 0.25, 0.75 - 1e-7, 0.75, 0.999_999_94] {
            let (x, pdf, cell) = d.sample(u);
            assert!((0.0..1.0).contains(&x), "{u}: {x}");
            assert!(cell == 1 || cell == 3, "{u}: cell {cell}");
            assert_eq!(d.cell_of(x), cell, "{u}");
            assert_eq!(pdf, d.pdf(x));
        }
        // The density integrates to one: cells of width 1/5 with densities 0, 3.75, 0, 1.25, 0.
        assert_eq!(d.pdf(0.3), 3.75);
        assert_eq!(d.pdf(0.7), 1.25);
        assert_eq!(d.pdf(0.1), 0.0);
    }

    /// Pearson's chi-square over the cells of a 2D distribution: the counts of `n` samples
    /// against the probabilities its `pdf` gives. The limit is far in the tail (about 7 standard
    /// deviations of the statistic above its mean, the cell count), so the test fails for a
    /// sampler that disagrees with its density, not for bad luck.
    #[test]
    fn samples_2d_follow_the_density_they_report() {
        let (w, h) = (8usize, 6usize);
        // A lumpy function with a zero row and zero cells, like a map with a sun and a black
        // ground.
        let func: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if y == 4 || (x + y) % 5 == 0 {
                    0.0
                } else {
                    1.0 + (x * x) as f32 + if (x, y) == (6, 1) { 40.0 } else { 0.0 }
                }
            })
            .collect();
        let d = Distribution2D::new(&func, w).unwrap();
        let n = 200_000u32;
        let mut counts = vec![0u32; w * h];
        for i in 0..n {
            let mut s = PixelSampler::new(11, 0, i, 0, 0);
            let (p, pdf) = d.sample(s.next_2d());
            let cell = ((p.y * h as f32) as usize) * w + (p.x * w as f32) as usize;
            assert_eq!(
                pdf,
                d.pdf(p),
                "the reported density is the density at the point"
            );
            assert!(pdf > 0.0 && func[cell] > 0.0, "sampled a zero cell");
            counts[cell] += 1;
        }
        let mut chi2 = 0.0f64;
        let mut cells = 0;
        let mut total_probability = 0.0f64;
        for (cell, &count) in counts.iter().enumerate() {
            let centre = Vec2::new(
                ((cell % w) as f32 + 0.5) / w as f32,
                ((cell / w) as f32 + 0.5) / h as f32,
            );
            let probability = f64::from(d.pdf(centre)) / (w * h) as f64;
            total_probability += probability;
            if probability == 0.0 {
                assert_eq!(count, 0);
                continue;
            }
            let expected = probability * f64::from(n);
            chi2 += (f64::from(count) - expected).powi(2) / expected;
            cells += 1;
        }
        assert!(
            (total_probability - 1.0).abs() < 1e-5,
            "{total_probability}"
        );
        let limit = cells as f64 + 7.0 * (2.0 * cells as f64).sqrt();
        assert!(chi2 < limit, "chi-square {chi2} over {cells} cells");
    }
}
