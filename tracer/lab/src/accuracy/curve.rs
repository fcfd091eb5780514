//! The spp ladder as a yardstick: a [`Curve`] of relative MSE against cost (time or counted
//! work), interpolated linearly in log-log space between rungs, and the log-log slope fit.
//!
//! Outside the ladder nothing is extrapolated; the answer is a bound ([`Estimate::Below`] or
//! [`Estimate::Above`]), because a power law fitted to noisy rungs would invent numbers the run did
//! not measure.

use super::bench::Row;
use super::findings::significant;
use super::report::Run;
use super::{Cost, Knob};

/// A value read off the spp ladder: measured between two rungs, or only bounded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Estimate {
    Within(f64),
    /// Lower than this (beyond the ladder's end).
    Below(f64),
    /// Higher than this (before the ladder's start).
    Above(f64),
}

impl std::fmt::Display for Estimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Estimate::Within(v) => write!(f, "{}", significant(v)),
            Estimate::Below(v) => write!(f, "< {}", significant(v)),
            Estimate::Above(v) => write!(f, "> {}", significant(v)),
        }
    }
}

/// Relative MSE against cost (time or counted work) along the spp ladder. Relative, because absolute errors are
/// dominated by the brightest pixels (the edges of a visible light), which no knob but samples
/// changes; the relative error weighs every pixel by its own brightness, as pbrt's tools do.
pub struct Curve {
    /// What the curve's x axis counts.
    pub cost: Cost,
    /// (cost, relMSE), sorted by cost.
    by_time: Vec<(f64, f64)>,
    /// The same points sorted by decreasing relMSE.
    by_error: Vec<(f64, f64)>,
}

impl Curve {
    /// The spp ladder's curve, if it has at least two rungs with a positive error.
    pub fn of(run: &Run) -> Option<Curve> {
        let points: Vec<(f64, f64)> = run
            .rows_of(Knob::Spp)
            .map(|r| (r.cost(run.cost), r.metrics.rel_mse))
            .filter(|&(t, e)| t > 0.0 && e > 0.0)
            .collect();
        if points.len() < 2 {
            return None;
        }
        let mut by_time = points.clone();
        by_time.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut by_error = points;
        by_error.sort_by(|a, b| b.1.total_cmp(&a.1));
        Some(Curve {
            cost: run.cost,
            by_time,
            by_error,
        })
    }

    /// The baseline's relMSE at a cost of `spent`.
    pub fn error_at(&self, spent: f64) -> Estimate {
        let (first, last) = (self.by_time[0], self.by_time[self.by_time.len() - 1]);
        if spent < first.0 {
            return Estimate::Above(first.1);
        }
        if spent > last.0 {
            return Estimate::Below(last.1);
        }
        Estimate::Within(log_interpolate(
            self.by_time.iter().map(|&(t, e)| (t, e)),
            spent,
        ))
    }

    /// The baseline's cost to reach a relMSE of `error`.
    pub fn cost_for(&self, error: f64) -> Estimate {
        let (worst, best) = (self.by_error[0], self.by_error[self.by_error.len() - 1]);
        if error > worst.1 {
            return Estimate::Below(worst.0);
        }
        if error < best.1 {
            return Estimate::Above(best.0);
        }
        // Along decreasing error: interpolate in -ln(error), which increases.
        let points = self.by_error.iter().map(|&(t, e)| (1.0 / e, t));
        Estimate::Within(log_interpolate(points, 1.0 / error))
    }

    /// Whether `row` has a lower relMSE than the baseline reaches at the same cost; `None` when
    /// the ladder cannot tell.
    pub fn beaten_by(&self, row: &Row) -> Option<bool> {
        let error = row.metrics.rel_mse;
        match self.error_at(row.cost(self.cost)) {
            Estimate::Within(e) => Some(error < e),
            Estimate::Above(e) => (error <= e).then_some(true),
            Estimate::Below(e) => (error >= e).then_some(false),
        }
    }
}

/// Piecewise-linear interpolation of ln(y) against ln(x) over points sorted by increasing x;
/// `x` must lie within them.
fn log_interpolate(points: impl Iterator<Item = (f64, f64)>, x: f64) -> f64 {
    let points: Vec<(f64, f64)> = points.collect();
    for pair in points.windows(2) {
        let ((x0, y0), (x1, y1)) = (pair[0], pair[1]);
        if x0 <= x && x <= x1 {
            if x1 == x0 {
                return y0;
            }
            let s = (x.ln() - x0.ln()) / (x1.ln() - x0.ln());
            return (y0.ln() + s * (y1.ln() - y0.ln())).exp();
        }
    }
    points.last().map_or(f64::NAN, |p| p.1)
}

/// The least-squares slope of ln(y) against ln(x); points with a non-positive coordinate are
/// left out. NaN with fewer than two points.
pub fn loglog_slope(points: &[(f64, f64)]) -> f64 {
    let logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let n = logs.len() as f64;
    let (mx, my) = (
        logs.iter().map(|p| p.0).sum::<f64>() / n,
        logs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = logs.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = logs.iter().map(|(x, _)| (x - mx) * (x - mx)).sum();
    if logs.len() < 2 || sxx == 0.0 {
        f64::NAN
    } else {
        sxy / sxx
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slope_of_a_power_law_is_its_exponent() {
        let points: Vec<(f64, f64)> = (0..8)
            .map(|k| (2f64.powi(k), 3.0 * 2f64.powi(k).powf(-0.5)))
            .collect();
        assert!((loglog_slope(&points) + 0.5).abs() < 1e-12);
        assert!(loglog_slope(&points[..1]).is_nan());
    }

    #[test]
    fn interpolation_is_linear_in_log_log() {
        let curve = Curve {
            cost: Cost::Time,
            by_time: vec![(1.0, 1.0), (4.0, 0.5)],
            by_error: vec![(1.0, 1.0), (4.0, 0.5)],
        };
        assert!(
            matches!(curve.error_at(2.0), Estimate::Within(e) if (e - 0.5f64.sqrt()).abs() < 1e-12)
        );
        assert!(
            matches!(curve.cost_for(0.5f64.sqrt()), Estimate::Within(t) if (t - 2.0).abs() < 1e-12)
        );
        assert_eq!(curve.error_at(0.5), Estimate::Above(1.0));
        assert_eq!(curve.error_at(8.0), Estimate::Below(0.5));
        assert_eq!(curve.cost_for(2.0), Estimate::Below(1.0));
        assert_eq!(curve.cost_for(0.25), Estimate::Above(4.0));
    }
}
