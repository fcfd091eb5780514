//! Motion-compensated prediction: where the cost landscape moved between the last two
//! measured frames, and the last one carried on by that motion to the frame being predicted.
//!
//! The PBT predicts a tile's cost from the previous frame's, which is right for a scene that
//! changes slowly and wrong, by a whole frame's motion, for a camera pan or an object crossing
//! the image: the cost of the moving part is predicted where it was, not where it will be. Video
//! codecs meet the same problem with motion compensation; here one global translation of the
//! block cost grid suffices for the two motions that dominate animation (a panning camera, one
//! expensive object moving), and it costs well under a millisecond per frame.
//!
//! The estimate is the integer block shift minimising the mean absolute difference between
//! the newer map and the older one shifted, searched coarse to fine (a pyramid of 2x2 block
//! sums, so a search of ±`max_shift` blocks costs about as much as one of ±2 at full size), then
//! refined to a fraction of a block by a parabola through the error at the best shift and its
//! neighbours. A shift is kept only when it beats standing still by [`MIN_GAIN`]: on a static
//! scene, noise must not invent motion. The extrapolated map samples the last one bilinearly at
//! the shifted position; blocks whose source lies outside the image take the nearest edge
//! block's cost. Everything is f64 arithmetic in a fixed order: the same maps give the same
//! prediction on any machine.

use crate::{CostMap, Error};

/// A global translation of the cost landscape per frame, in blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Columns of blocks the landscape moves right per frame (negative: left).
    pub dx: f64,
    /// Rows of blocks the landscape moves down per frame (negative: up).
    pub dy: f64,
}

/// [`Config::motion`](crate::Config::motion) as the command line and the statistics file spell
/// it: the largest shift searched, in blocks per frame (`16`), or `off` for no motion
/// compensation. Its default is the config's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotionSearch(pub Option<u32>);

impl Default for MotionSearch {
    fn default() -> Self {
        MotionSearch(crate::Config::default().motion)
    }
}

impl std::fmt::Display for MotionSearch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some(blocks) => write!(f, "{blocks}"),
            None => f.write_str("off"),
        }
    }
}

impl std::str::FromStr for MotionSearch {
    /// The text as given, in a sentence that says what a valid one looks like.
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "off" => Ok(MotionSearch(None)),
            _ => match text.parse::<u32>() {
                Ok(blocks) if blocks > 0 => Ok(MotionSearch(Some(blocks))),
                _ => Err(format!(
                    "{text:?}: give a positive number of blocks, or off"
                )),
            },
        }
    }
}

/// How much better than standing still a shift must explain the newer map (mean absolute
/// difference over the overlap) to be believed: a tenth.
pub const MIN_GAIN: f64 = 0.9;

/// Grids smaller than this many blocks a side are not shrunk further: a search there is cheap,
/// and coarser levels would blur the landscape into nothing.
const COARSEST: u32 = 16;

/// The motion that carries `older` onto `newer` (maps of one frame apart on the same block
/// grid), searching shifts of at most `max_shift` blocks each way. `None` when the maps' grids
/// differ, when nothing moved by half a block or more, or when no shift explains the newer map
/// clearly better than no motion. Motion under half a block is not sought: it costs the
/// prediction little, and on noisy measurements a fraction of a block found between whole
/// shifts that explain the map equally badly would be noise.
pub fn estimate(older: &CostMap, newer: &CostMap, max_shift: u32) -> Option<Motion> {
    if (older.columns(), older.rows(), older.block())
        != (newer.columns(), newer.rows(), newer.block())
        || max_shift == 0
    {
        return None;
    }
    let a = Grid::of(older);
    let b = Grid::of(newer);
    // A shift of half the grid or more leaves too little of the landscape to compare.
    let limit = i64::from(max_shift).min((a.columns.min(a.rows) - 1) / 2);
    if limit <= 0 {
        return None;
    }
    let (sx, sy) = search(&a, &b, limit);
    if (sx, sy) == (0, 0) {
        return None;
    }
    let still = b.difference(&a, 0, 0);
    let best = b.difference(&a, sx, sy);
    if best >= MIN_GAIN * still {
        return None;
    }
    // A parabola through the errors at the best shift and its two neighbours on each axis puts
    // the minimum between blocks; clamped to half a block either way, where the next integer
    // shift would have won.
    let refine = |m: f64, p: f64| match m + p - 2.0 * best > 0.0 {
        true => (0.5 * (m - p) / (m + p - 2.0 * best)).clamp(-0.5, 0.5),
        false => 0.0,
    };
    let fx = refine(b.difference(&a, sx - 1, sy), b.difference(&a, sx + 1, sy));
    let fy = refine(b.difference(&a, sx, sy - 1), b.difference(&a, sx, sy + 1));
    Some(Motion {
        dx: sx as f64 + fx,
        dy: sy as f64 + fy,
    })
}

/// Where motion carries the landscape over the next `frames` frames, from the motions of the
/// frames measured so far (oldest first): the sum of the coming frames' motions.
///
/// The coming motions continue the last one. Constant velocity repeats it; an object on a curve
/// or an orbiting camera turns it, frame after frame, by about the same angle, and a camera
/// easing in or out scales it: so when the last two motions are each a block or more, their
/// ratio as complex numbers (turn and change of speed) is carried on too, never more than
/// [`MAX_TURN`] radians or a factor of two a frame. With three motions or more, only where the
/// ratio of the two before would have predicted the last motion better than constant velocity
/// did; with two there is nothing to check it against, and it is taken as it is, because the
/// frame after the second motion is the first dealt two frames ahead (frames in flight), where
/// going straight misses an orbit by most of a frame's motion (on the fast orbit, the frame
/// then costs 1.6 times its work instead of 1.0).
pub fn ahead(history: &[Motion], frames: u32) -> Motion {
    let Some(&last) = history.last() else {
        return Motion { dx: 0.0, dy: 0.0 };
    };
    let turn = match history {
        [.., a, b, c] => {
            let (r_ab, r_bc) = (ratio(*a, *b), ratio(*b, *c));
            let turned = r_ab.map(|r| distance(times(*b, r), *c));
            match (r_bc, turned) {
                (Some(r), Some(error)) if error < distance(*b, *c) => Some(r),
                _ => None,
            }
        }
        [a, b] => ratio(*a, *b),
        _ => None,
    };
    let (mut step, mut total) = (last, Motion { dx: 0.0, dy: 0.0 });
    for _ in 0..frames {
        if let Some(r) = turn {
            step = times(step, r);
        }
        total = Motion {
            dx: total.dx + step.dx,
            dy: total.dy + step.dy,
        };
    }
    total
}

/// The most a motion is believed to turn from one frame to the next, in radians (45 degrees).
pub const MAX_TURN: f64 = std::f64::consts::FRAC_PI_4;

/// `b / a` as complex numbers (the turn and change of speed from `a` to `b`), clamped to
/// [`MAX_TURN`] and a factor of two; `None` where either is under a block.
fn ratio(a: Motion, b: Motion) -> Option<(f64, f64)> {
    let (na, nb) = (a.dx.hypot(a.dy), b.dx.hypot(b.dy));
    if na < 1.0 || nb < 1.0 {
        return None;
    }
    let angle = (a.dx * b.dy - a.dy * b.dx)
        .atan2(a.dx * b.dx + a.dy * b.dy)
        .clamp(-MAX_TURN, MAX_TURN);
    let scale = (nb / na).clamp(0.5, 2.0);
    Some((scale * angle.cos(), scale * angle.sin()))
}

fn times(m: Motion, (re, im): (f64, f64)) -> Motion {
    Motion {
        dx: m.dx * re - m.dy * im,
        dy: m.dx * im + m.dy * re,
    }
}

fn distance(a: Motion, b: Motion) -> f64 {
    (a.dx - b.dx).hypot(a.dy - b.dy)
}

/// `last` moved by `shift` blocks: block `(c, r)` of the result is `last` sampled at
/// `(c - shift.dx, r - shift.dy)`.
pub fn extrapolate(last: &CostMap, shift: Motion) -> Result<CostMap, Error> {
    let grid = Grid::of(last);
    CostMap::from_fn(last.width(), last.height(), last.block(), |c, r| {
        grid.sample(f64::from(c) - shift.dx, f64::from(r) - shift.dy)
    })
}

/// A block cost grid, row-major.
struct Grid {
    columns: i64,
    rows: i64,
    costs: Vec<f64>,
}

impl Grid {
    fn of(map: &CostMap) -> Grid {
        let (columns, rows) = (map.columns(), map.rows());
        let mut costs = Vec::with_capacity(columns as usize * rows as usize);
        for r in 0..rows {
            for c in 0..columns {
                costs.push(map.block_cost(c, r).unwrap_or(0.0));
            }
        }
        Grid {
            columns: i64::from(columns),
            rows: i64::from(rows),
            costs,
        }
    }

    fn at(&self, c: i64, r: i64) -> f64 {
        self.costs[(r * self.columns + c) as usize]
    }

    /// The grid of 2x2 block sums (a last odd column or row summed alone).
    fn halved(&self) -> Grid {
        let (columns, rows) = ((self.columns + 1) / 2, (self.rows + 1) / 2);
        let mut costs = vec![0.0; (columns * rows) as usize];
        for r in 0..self.rows {
            for c in 0..self.columns {
                costs[((r / 2) * columns + c / 2) as usize] += self.at(c, r);
            }
        }
        Grid {
            columns,
            rows,
            costs,
        }
    }

    /// Mean |self(c, r) - older(c - sx, r - sy)| over every block, the older grid clamped to
    /// its edge as [`extrapolate`] clamps it: over the overlap alone, a shift that pushes the
    /// expensive part out of both would look like a perfect match.
    fn difference(&self, older: &Grid, sx: i64, sy: i64) -> f64 {
        let mut sum = 0.0;
        for r in 0..self.rows {
            let source_row = (r - sy).clamp(0, older.rows - 1);
            for c in 0..self.columns {
                let source = older.at((c - sx).clamp(0, older.columns - 1), source_row);
                sum += (self.at(c, r) - source).abs();
            }
        }
        sum / (self.columns * self.rows) as f64
    }

    /// The cost at a fractional block position, bilinearly, clamped to the grid's edge.
    fn sample(&self, x: f64, y: f64) -> f64 {
        let x = x.clamp(0.0, (self.columns - 1) as f64);
        let y = y.clamp(0.0, (self.rows - 1) as f64);
        let (c, r) = (x.floor() as i64, y.floor() as i64);
        let (c1, r1) = ((c + 1).min(self.columns - 1), (r + 1).min(self.rows - 1));
        let (fx, fy) = (x - c as f64, y - r as f64);
        let top = self.at(c, r) * (1.0 - fx) + self.at(c1, r) * fx;
        let bottom = self.at(c, r1) * (1.0 - fx) + self.at(c1, r1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// The best integer shift of `older` onto `newer` within ±`max_shift` blocks, coarse to fine.
fn search(older: &Grid, newer: &Grid, max_shift: i64) -> (i64, i64) {
    if older.columns.min(older.rows) >= 2 * i64::from(COARSEST) && max_shift > 2 {
        // Half the grid, half the shift: the coarse answer, doubled, is within a block or two
        // of the fine one.
        let (cx, cy) = search(&older.halved(), &newer.halved(), (max_shift + 1) / 2);
        return best_shift(older, newer, (2 * cx, 2 * cy), 2, max_shift);
    }
    best_shift(older, newer, (0, 0), max_shift, max_shift)
}

/// The shift within `radius` of `centre` (and within ±`limit`) of least difference; ties go to
/// the smaller shift, then to the first in row-major order, so that the answer is unique.
fn best_shift(
    older: &Grid,
    newer: &Grid,
    centre: (i64, i64),
    radius: i64,
    limit: i64,
) -> (i64, i64) {
    let mut best: Option<(f64, i64, (i64, i64))> = None;
    for sy in (centre.1 - radius).max(-limit)..=(centre.1 + radius).min(limit) {
        for sx in (centre.0 - radius).max(-limit)..=(centre.0 + radius).min(limit) {
            let error = newer.difference(older, sx, sy);
            let size = sx * sx + sy * sy;
            let better = match best {
                None => true,
                Some((e, s, _)) => error < e || (error == e && size < s),
            };
            if better {
                best = Some((error, size, (sx, sy)));
            }
        }
    }
    best.map_or((0, 0), |(_, _, shift)| shift)
}

#[cfg(test)]
mod tests;
