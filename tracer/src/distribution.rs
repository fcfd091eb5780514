//! Piecewise-constant distributions in one and two dimensions, for importance sampling tabulated
//! functions (an environment map's luminance).
//!
//! The domain is [0, 1) in each dimension, cut into as many equal cells as the function has
//! values; a sample lands in a cell with probability proportional to its value and uniformly
//! within it, so the density is the cell's value over the function's integral. Cumulative sums
//! are taken in f64 and stored in f32: with a million cells, f32 running sums would lose the
//! small cells beside a bright sun. A cell whose value is zero is never sampled, and one with a
//! positive value always can be, so the density is positive exactly where the function is.
//!
//! A sample inverts the cumulative sums by a search, narrowed first by a guide table (the
//! cutpoint method, Chen and Asau 1974): for each of `n` equal stretches of [0, 1), the cells
//! whose cumulative range can hold a number in it. A plain binary search over a large map's row
//! reads a new cache line at most of its steps, each step waiting on the one before; the guided
//! one reads the guide's line and one or two of the cells'. Both find the same cell for every
//! number (see [`Distribution1D::sample`]), so the images are the same bits.

use glam::Vec2;

/// The most cells a distribution may have: up to it, an f32 times the cell count is exact in
/// f64, which the guide table's exactness rests on ([`Distribution1D::sample`]). An environment
/// map has at most 2^27 texels (`environment::MAX_MAP_TEXELS`), so its rows and columns are far
/// below.
pub const MAX_CELLS: usize = (1 << 29) - 1;

/// The largest f32 below 1: samples stay inside the half-open domain.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// A piecewise-constant density on [0, 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution1D {
    /// The `n` cells and an end: `cells[i].start` is the probability of the cells before `i`
    /// (`cells[n].start` is exactly 1), `cells[i].value` the function's value (0 at the end).
    /// One array, so that the start a sample's search ends on and the value its density reads
    /// share a cache line: on a large map, one cache miss a sample instead of two.
    cells: Vec<Cell>,
    /// The guide table: `n` stretches of [0, 1) (as many as cells), `guide[j]` for `j` in `1..=n`
    /// the number of cell starts at most `j / n`, and `guide[0]` 0; see [`Self::sample`].
    guide: Vec<u32>,
    /// The integral of the function over [0, 1): the mean of the function.
    integral: f64,
}

/// A cell of a [`Distribution1D`]: where its share of [0, 1) starts, and its value.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cell {
    start: f32,
    value: f32,
}

impl Distribution1D {
    /// The distribution proportional to `func`; `None` when `func` is empty or longer than
    /// [`MAX_CELLS`], has a negative or non-finite value, or sums to zero.
    pub fn new(func: &[f32]) -> Option<Self> {
        if func.is_empty() || func.len() > MAX_CELLS {
            return None;
        }
        if func.iter().any(|f| !f.is_finite() || *f < 0.0) {
            return None;
        }
        let total: f64 = func.iter().map(|&f| f64::from(f)).sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let mut cells = Vec::with_capacity(func.len() + 1);
        let mut running = 0.0f64;
        for &value in func {
            let start = (running / total) as f32;
            cells.push(Cell { start, value });
            running += f64::from(value);
        }
        cells.push(Cell {
            start: 1.0,
            value: 0.0,
        });
        let integral = total / func.len() as f64;
        let guide = guide_table(&cells, func.len());
        Some(Self {
            cells,
            guide,
            integral,
        })
    }

    /// The number of cells, one per value of the function.
    pub fn len(&self) -> usize {
        self.cells.len() - 1
    }

    /// Always false for a distribution [`Distribution1D::new`] made (it refuses an empty
    /// function); here because clippy pairs it with `len`.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The mean of the function: its integral over [0, 1).
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// A point in [0, 1) for `u` in [0, 1), its density, and its cell.
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        // The cell whose share [start of i, start of i + 1) holds u; an empty share (a zero
        // value) never does. That is one less than the number of starts at most u, which lie
        // before the first start above u (the starts never decrease), searched for among those
        // the guide leaves: with `stretches` the guide's count and `j` the stretch holding u,
        // the starts before `guide[j]` are at most j / stretches, so at most u, and those from
        // `guide[j + 1]` on are above (j + 1) / stretches, so above u. The stretch is exact: u
        // times a count below 2^29 is exact in f64 ([`MAX_CELLS`]). A NaN or negative u lands
        // in stretch 0, whose lower end is the first cell, and a u of 1 or more in the last.
        let stretches = self.guide.len() - 1;
        let j = ((f64::from(u) * stretches as f64) as usize).min(stretches - 1);
        let (first, end) = (self.guide[j] as usize, self.guide[j + 1] as usize);
        let at_most_u = first + self.cells[first..end].partition_point(|c| c.start <= u);
        let cell = (at_most_u.max(1) - 1).min(self.len() - 1);
        let (lo, hi) = (self.cells[cell].start, self.cells[cell + 1].start);
        let within = if hi > lo { (u - lo) / (hi - lo) } else { 0.5 };
        let x = ((cell as f32 + within) / self.len() as f32).min(ONE_MINUS_EPSILON);
        (x, self.cell_pdf(cell), cell)
    }

    /// The density of the cell that holds `x` in [0, 1).
    pub fn pdf(&self, x: f32) -> f32 {
        self.cell_pdf(self.cell_of(x))
    }

    /// The cell that holds `x`, clamped into the domain.
    pub fn cell_of(&self, x: f32) -> usize {
        let n = self.len();
        ((x.max(0.0) * n as f32) as usize).min(n - 1)
    }

    fn cell_pdf(&self, cell: usize) -> f32 {
        (f64::from(self.cells[cell].value) / self.integral) as f32
    }
}

/// The guide table of `cells` over `stretches` equal stretches of [0, 1): entry `j`
/// (`1..=stretches`) counts the cells that start at most at `j / stretches`, entry 0 is 0.
/// The comparison is exact: an f32 (24 significant bits) times a count below 2^29
/// ([`MAX_CELLS`]) has at most 53, so it is exact in f64, and `start <= j / stretches` is
/// `start * stretches <= j` without a rounding.
fn guide_table(cells: &[Cell], stretches: usize) -> Vec<u32> {
    let mut guide = Vec::with_capacity(stretches + 1);
    guide.push(0);
    let mut counted = 0usize;
    for j in 1..=stretches {
        while counted < cells.len()
            && f64::from(cells[counted].start) * stretches as f64 <= j as f64
        {
            counted += 1;
        }
        // `counted <= cells.len() <= MAX_CELLS + 1 < 2^32`: `new` refuses more cells.
        guide.push(counted as u32);
    }
    guide
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
        let rows: Vec<Option<Distribution1D>> =
            func.chunks(width).map(Distribution1D::new).collect();
        let row_integrals: Vec<f32> = rows
            .iter()
            .map(|r| r.as_ref().map_or(0.0, |r| r.integral() as f32))
            .collect();
        let marginal = Distribution1D::new(&row_integrals)?;
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
        (f64::from(distribution.cells[x].value) / self.marginal.integral) as f32
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
    use crate::sampler::{PixelSampler, unit_f32};

    #[test]
    fn bad_functions_give_no_distribution() {
        assert!(Distribution1D::new(&[]).is_none());
        assert!(Distribution1D::new(&[0.0, 0.0]).is_none());
        assert!(Distribution1D::new(&[1.0, -1.0]).is_none());
        assert!(Distribution1D::new(&[1.0, f32::NAN]).is_none());
        assert!(Distribution2D::new(&[0.0; 6], 3).is_none());
        assert!(Distribution2D::new(&[1.0; 5], 3).is_none());
    }

    #[test]
    fn zero_cells_are_never_sampled_and_every_sample_stays_in_the_domain() {
        let d = Distribution1D::new(&[0.0, 3.0, 0.0, 1.0, 0.0]).unwrap();
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

    /// The guided search finds the cell the plain binary search over all the cumulative sums
    /// finds, for every number that could matter: the sums themselves and their neighbours
    /// (where a cell starts), the stretches' ends and their neighbours (where the guide cuts),
    /// the domain's ends, numbers outside it, and a spread of others; over functions of every
    /// shape a map gives (flat, a sun, runs of zeros at either end and inside, a range of
    /// sixty decades, one cell, many cells).
    #[test]
    fn the_guided_search_finds_the_cell_the_plain_search_finds() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut functions: Vec<Vec<f32>> = vec![
            vec![1.0],
            vec![0.0, 0.0, 5.0],
            vec![5.0, 0.0, 0.0],
            vec![1.0; 1000],
            (0..1000)
                .map(|i| if i == 417 { 1e6 } else { 1.0 })
                .collect(),
            (0..777)
                .map(|i| if i % 97 < 60 { 0.0 } else { (i % 13) as f32 })
                .collect(),
            (0..4096).map(|i| 10f32.powi(i % 61 - 30)).collect(),
        ];
        for n in [2usize, 3, 17, 256, 5000] {
            functions.push(
                (0..n)
                    .map(|_| {
                        let bits = next();
                        if bits % 5 == 0 {
                            0.0
                        } else {
                            (bits >> 40) as f32 * 1e-3
                        }
                    })
                    .collect(),
            );
        }
        for func in functions {
            let n = func.len();
            let d = Distribution1D::new(&func).expect("each function has a positive value");
            let starts: Vec<f32> = d.cells.iter().map(|c| c.start).collect();
            let plain = |u: f32| (starts.partition_point(|&c| c <= u).max(1) - 1).min(n - 1);
            let mut numbers = vec![0.0, ONE_MINUS_EPSILON, 1.0, 2.0, -1.0, f32::NAN];
            for &c in &starts {
                numbers.extend([c, c.next_down(), c.next_up()]);
            }
            for j in 0..=n {
                let end = (j as f64 / n as f64) as f32;
                numbers.extend([end, end.next_down(), end.next_up()]);
            }
            numbers.extend((0..2000).map(|_| unit_f32(next())));
            for u in numbers {
                assert_eq!(d.sample(u).2, plain(u), "{n} cells, u = {u:e}");
            }
        }
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
