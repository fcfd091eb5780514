//! Measured cost over a whole image, by block of pixels, with O(1) rectangle queries.
//!
//! The tracer reports deterministic counted work per block of pixels (8x8 by default); the
//! caller merges the blocks of every tile of a frame into one [`CostMap`] with a
//! [`CostMapBuilder`]. Blocks tile the image from its top-left corner; the last column and row
//! of blocks may be partial (a 10-pixel-wide image in 4-pixel blocks has block columns 4, 4 and
//! 2 pixels wide). A tile that is not block-aligned reports its share of a block with
//! [`CostMapBuilder::add_rect`], and the shares of the tiles that split a block add up.
//!
//! **Queries.** [`CostMap::cost`] of any pixel rectangle is O(1): a summed-area table over the
//! blocks gives the sum over any block-aligned rectangle with four lookups, so a block-aligned
//! rectangle (every edge on a block boundary or the image edge) gets its blocks' exact sum, up
//! to floating-point rounding (none at all for counted work; see below). A
//! rectangle that cuts through blocks is charged for each cut block in proportion to the area
//! it covers: cost is taken as spread evenly over a block's pixels, which is all a per-block
//! measurement can say. Three block ranges per axis (a partial first block, whole middle
//! blocks, a partial last block) give nine block-aligned sums from sixteen lookups.
//!
//! **Precision.** When every block cost is an integer and the total is below 2^53 (counted work,
//! the tracer's case), plain f64 prefix sums are exact, and so is every block-aligned query.
//! Otherwise the table is kept in double-double arithmetic (a pair of f64 whose sum is the value,
//! added with error-free transformations), so that differencing large prefix sums does not
//! cancel away small costs: a query is off by about 2^-104 of the map's total rather than
//! 2^-52, so next to a block of cost 1e30 a block of cost 1 still queries as exactly 1.

use std::sync::Arc;

use crate::{Error, Rect};

/// Cost per block of pixels over a whole image, immutable once built. Clones are cheap (the
/// tables are shared).
#[derive(Clone, Debug)]
pub struct CostMap {
    width: u32,
    height: u32,
    block: u32,
    columns: u32,
    rows: u32,
    /// Cost of each block, row-major.
    blocks: Arc<[f64]>,
    /// `log2(block)` when the block size is a power of two, for shifts instead of divisions.
    shift: Option<u32>,
    /// Summed-area table: entry `(c, r)` at `r * (columns + 1) + c` is the cost of blocks
    /// `0..c` x `0..r`; the high parts of the double-double values.
    sat: Arc<[f64]>,
    /// The low parts, `None` where they are all zero because plain f64 sums are exact (see the
    /// module docs).
    sat_low: Option<Arc<[f64]>>,
}

/// Accumulates block costs for a [`CostMap`], e.g. from the tiles of one frame.
#[derive(Clone, Debug)]
pub struct CostMapBuilder {
    width: u32,
    height: u32,
    block: u32,
    columns: u32,
    rows: u32,
    costs: Vec<f64>,
}

impl CostMap {
    /// A map from the cost of every block, row-major (`columns() * rows()` of them).
    pub fn from_blocks(
        width: u32,
        height: u32,
        block: u32,
        costs: Vec<f64>,
    ) -> Result<Self, Error> {
        let mut builder = Self::builder(width, height, block)?;
        if costs.len() != builder.costs.len() {
            return Err(Error::BlockCount {
                expected: builder.costs.len(),
                found: costs.len(),
            });
        }
        for (index, &cost) in costs.iter().enumerate() {
            let (column, row) = (
                index as u32 % builder.columns,
                index as u32 / builder.columns,
            );
            builder.add_block(column, row, cost)?;
        }
        builder.build()
    }

    /// A map from counted work per block, row-major. Counts above 2^53 round to the nearest f64.
    pub fn from_counts(width: u32, height: u32, block: u32, counts: &[u64]) -> Result<Self, Error> {
        Self::from_blocks(
            width,
            height,
            block,
            counts.iter().map(|&c| c as f64).collect(),
        )
    }

    /// A map whose block `(column, row)` costs `cost(column, row)`.
    pub fn from_fn(
        width: u32,
        height: u32,
        block: u32,
        mut cost: impl FnMut(u32, u32) -> f64,
    ) -> Result<Self, Error> {
        let mut builder = Self::builder(width, height, block)?;
        for row in 0..builder.rows {
            for column in 0..builder.columns {
                builder.add_block(column, row, cost(column, row))?;
            }
        }
        builder.build()
    }

    /// An all-zero builder for a `width` x `height` image in `block` x `block` blocks.
    pub fn builder(width: u32, height: u32, block: u32) -> Result<CostMapBuilder, Error> {
        if width == 0 || height == 0 {
            return Err(Error::EmptyImage { width, height });
        }
        if block == 0 {
            return Err(Error::ZeroBlock);
        }
        let (columns, rows) = (width.div_ceil(block), height.div_ceil(block));
        let costs = vec![0.0; columns as usize * rows as usize];
        Ok(CostMapBuilder {
            width,
            height,
            block,
            columns,
            rows,
            costs,
        })
    }

    /// The image's width in pixels (not in blocks).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// The image's height in pixels (not in blocks).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Side of a block in pixels.
    pub fn block(&self) -> u32 {
        self.block
    }

    /// Number of block columns (the last may be narrower than [`Self::block`]).
    pub fn columns(&self) -> u32 {
        self.columns
    }

    /// Number of block rows (the last may be shorter than [`Self::block`]).
    pub fn rows(&self) -> u32 {
        self.rows
    }

    /// Cost of the whole image.
    pub fn total(&self) -> f64 {
        let last = self.sat.len() - 1;
        self.sat[last] + self.sat_low.as_ref().map_or(0.0, |low| low[last])
    }

    /// Cost of one block, `None` outside the block grid.
    pub fn block_cost(&self, column: u32, row: u32) -> Option<f64> {
        (column < self.columns && row < self.rows)
            .then(|| self.blocks[(row * self.columns + column) as usize])
    }

    /// The pixels of one block (partial at the right and bottom edges), `None` outside the
    /// block grid.
    pub fn block_rect(&self, column: u32, row: u32) -> Option<Rect> {
        (column < self.columns && row < self.rows).then(|| {
            let (x, y) = (column * self.block, row * self.block);
            let (w, h) = (
                self.block.min(self.width - x),
                self.block.min(self.height - y),
            );
            Rect::new(x, y, w, h)
        })
    }

    /// Cost of the pixels of `rect` (the part outside the image costs nothing): exact for
    /// block-aligned rectangles, area-weighted within cut blocks (see the module docs).
    pub fn cost(&self, rect: Rect) -> f64 {
        let x1 = rect.right().min(u64::from(self.width)) as u32;
        let y1 = rect.bottom().min(u64::from(self.height)) as u32;
        if rect.x >= x1 || rect.y >= y1 {
            return 0.0;
        }
        let xs = Segments::new(rect.x, x1, self.block, self.shift, self.width);
        let ys = Segments::new(rect.y, y1, self.block, self.shift, self.height);
        let stride = self.columns as usize + 1;
        let at = |j: usize, i: usize| ys.bounds[j] as usize * stride + xs.bounds[i] as usize;
        let mut total = 0.0;
        match &self.sat_low {
            None => {
                let c: [[f64; 4]; 4] =
                    std::array::from_fn(|j| std::array::from_fn(|i| self.sat[at(j, i)]));
                for j in 0..3 {
                    for i in 0..3 {
                        let sum = ((c[j + 1][i + 1] - c[j][i + 1]) - c[j + 1][i]) + c[j][i];
                        total += xs.weights[i] * ys.weights[j] * sum;
                    }
                }
            }
            Some(low) => {
                let c: [[Dd; 4]; 4] = std::array::from_fn(|j| {
                    std::array::from_fn(|i| Dd {
                        hi: self.sat[at(j, i)],
                        lo: low[at(j, i)],
                    })
                });
                for j in 0..3 {
                    for i in 0..3 {
                        let sum = c[j + 1][i + 1]
                            .sub(c[j][i + 1])
                            .sub(c[j + 1][i])
                            .add(c[j][i]);
                        total += xs.weights[i] * ys.weights[j] * sum.value().max(0.0);
                    }
                }
            }
        }
        total
    }

    /// `keep * self + (1 - keep) * newer`, block by block. The caller makes sure both maps have
    /// the same geometry.
    pub(crate) fn blend(&self, newer: &CostMap, keep: f64) -> CostMap {
        debug_assert_eq!(
            (self.width, self.height, self.block),
            (newer.width, newer.height, newer.block)
        );
        let blocks = self.blocks.iter().zip(newer.blocks.iter());
        let blended = blocks
            .map(|(old, new)| keep * old + (1.0 - keep) * new)
            .collect();
        let (width, height, block) = (self.width, self.height, self.block);
        let (columns, rows) = (self.columns, self.rows);
        let builder = CostMapBuilder {
            width,
            height,
            block,
            columns,
            rows,
            costs: blended,
        };
        // Invariant: convex combinations of finite non-negative maps are finite and non-negative.
        builder.build().expect("a blend of two valid maps is valid")
    }
}

impl CostMapBuilder {
    /// Adds `cost` to block `(column, row)`.
    pub fn add_block(&mut self, column: u32, row: u32, cost: f64) -> Result<(), Error> {
        if column >= self.columns || row >= self.rows {
            let rect = Rect::new(
                column.saturating_mul(self.block),
                row.saturating_mul(self.block),
                self.block,
                self.block,
            );
            return Err(Error::OutOfBounds {
                rect,
                width: self.width,
                height: self.height,
            });
        }
        let rect = Rect::new(
            column * self.block,
            row * self.block,
            self.block,
            self.block,
        );
        validate(cost, rect)?;
        self.costs[(row * self.columns + column) as usize] += cost;
        Ok(())
    }

    /// Adds `cost`, measured over the pixels of `rect`, to the blocks `rect` overlaps, each in
    /// proportion to the pixels it shares with `rect`. Exact when `rect` is one block or a
    /// block-aligned part of one (e.g. a tile's share of a block that a tile boundary cuts).
    pub fn add_rect(&mut self, rect: Rect, cost: f64) -> Result<(), Error> {
        validate(cost, rect)?;
        if rect.is_empty() || !rect.inside(self.width, self.height) {
            return Err(Error::OutOfBounds {
                rect,
                width: self.width,
                height: self.height,
            });
        }
        let (first_column, last_column) = (rect.x / self.block, (rect.x + rect.w - 1) / self.block);
        let (first_row, last_row) = (rect.y / self.block, (rect.y + rect.h - 1) / self.block);
        let area = rect.area() as f64;
        for row in first_row..=last_row {
            let rows = overlap(rect.y, rect.h, row * self.block, self.block);
            for column in first_column..=last_column {
                let columns = overlap(rect.x, rect.w, column * self.block, self.block);
                let share = (u64::from(columns) * u64::from(rows)) as f64 / area;
                self.costs[(row * self.columns + column) as usize] += cost * share;
            }
        }
        Ok(())
    }

    /// The finished map; [`Error::Overflow`] if the costs add up to infinity.
    pub fn build(self) -> Result<CostMap, Error> {
        let stride = self.columns as usize + 1;
        let mut sat = vec![Dd::ZERO; stride * (self.rows as usize + 1)];
        for row in 0..self.rows as usize {
            let mut running = Dd::ZERO;
            for column in 0..self.columns as usize {
                running = running.add(Dd::from(self.costs[row * self.columns as usize + column]));
                sat[(row + 1) * stride + column + 1] = sat[row * stride + column + 1].add(running);
            }
        }
        let total = sat[sat.len() - 1].value();
        if !total.is_finite() {
            return Err(Error::Overflow);
        }
        // Below 2^53 every integer is an f64 and sums of integers are exact.
        let exact = total < 9_007_199_254_740_992.0 && self.costs.iter().all(|c| c.fract() == 0.0);
        let sat_low = (!exact).then(|| sat.iter().map(|dd| dd.lo).collect());
        Ok(CostMap {
            width: self.width,
            height: self.height,
            block: self.block,
            columns: self.columns,
            rows: self.rows,
            shift: self
                .block
                .is_power_of_two()
                .then(|| self.block.trailing_zeros()),
            blocks: self.costs.into(),
            sat: sat.iter().map(|dd| dd.hi).collect(),
            sat_low,
        })
    }
}

fn validate(cost: f64, rect: Rect) -> Result<(), Error> {
    if cost.is_finite() && cost >= 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidCost { value: cost, rect })
    }
}

/// Pixels shared by the spans `start..start + len` and `block_start..block_start + block`.
fn overlap(start: u32, len: u32, block_start: u32, block: u32) -> u32 {
    let end = (u64::from(start) + u64::from(len)).min(u64::from(block_start) + u64::from(block));
    (end - u64::from(start.max(block_start))) as u32
}

/// The pixel span `lo..hi` of one axis as three runs of blocks (some possibly empty), each with
/// the fraction of its blocks' pixels the span covers: a partial first block, the whole blocks
/// between, a partial last block. Run `k` is blocks `bounds[k]..bounds[k + 1]`, weight
/// `weights[k]`. A fixed shape keeps the query branch-free.
struct Segments {
    bounds: [u32; 4],
    weights: [f64; 3],
}

impl Segments {
    /// `lo < hi <= extent`, where `extent` is the image's size along this axis; `shift` is
    /// `log2(block)` if `block` is a power of two. Always inlined: returned through the stack,
    /// the struct costs a store-forwarding stall that doubled the time of a query.
    #[inline(always)]
    fn new(lo: u32, hi: u32, block: u32, shift: Option<u32>, extent: u32) -> Self {
        let index = |pixel: u32| match shift {
            Some(shift) => pixel >> shift,
            None => pixel / block,
        };
        let (first, last) = (index(lo), index(hi - 1));
        // The fraction of block `b`'s pixels that `covered` pixels are; exactly 1 when whole.
        let fraction = |covered: u32, b: u32| {
            let span = block.min(extent - b * block);
            if covered == span {
                1.0
            } else {
                f64::from(covered) / f64::from(span)
            }
        };
        if first == last {
            let end = first + 1;
            Segments {
                bounds: [first, end, end, end],
                weights: [fraction(hi - lo, first), 0.0, 0.0],
            }
        } else {
            let head = fraction((first + 1) * block - lo, first);
            let tail = fraction(hi - last * block, last);
            Segments {
                bounds: [first, first + 1, last, last + 1],
                weights: [head, 1.0, tail],
            }
        }
    }
}

/// A double-double number `hi + lo`, with `hi` the f64 nearest the value.
#[derive(Clone, Copy, Debug, Default)]
struct Dd {
    hi: f64,
    lo: f64,
}

impl Dd {
    const ZERO: Dd = Dd { hi: 0.0, lo: 0.0 };

    fn add(self, other: Dd) -> Dd {
        let (sum, error) = two_sum(self.hi, other.hi);
        let (hi, lo) = two_sum(sum, error + self.lo + other.lo);
        Dd { hi, lo }
    }

    fn sub(self, other: Dd) -> Dd {
        self.add(Dd {
            hi: -other.hi,
            lo: -other.lo,
        })
    }

    fn value(self) -> f64 {
        self.hi + self.lo
    }
}

impl From<f64> for Dd {
    fn from(hi: f64) -> Self {
        Dd { hi, lo: 0.0 }
    }
}

/// Knuth's error-free sum: `a + b == s + e` exactly, with `s` the rounded sum.
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let b_virtual = s - a;
    let a_virtual = s - b_virtual;
    (s, (a - a_virtual) + (b - b_virtual))
}

#[cfg(test)]
mod tests;
