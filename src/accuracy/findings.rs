//! The comparisons a reader wants, in sentences: how error and time scale with samples, and for
//! every other knob whether it beats simply rendering longer at the baseline settings.
//!
//! The spp ladder is the yardstick: a [`Curve`] of relative MSE against time, interpolated linearly in
//! log-log space between rungs. Outside the ladder nothing is extrapolated; the answer is a bound
//! ([`Estimate::Below`] or [`Estimate::Above`]), because a power law fitted to noisy rungs would
//! invent numbers the run did not measure.

use super::Knob;
use super::bench::Row;
use super::leaks::LeakCheck;
use super::report::Run;
use tracer::geometry::{BuildQuality, Traversal};
use tracer::scene::RenderSettings;

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

/// Relative MSE against time along the spp ladder. Relative, because absolute errors are
/// dominated by the brightest pixels (the edges of a visible light), which no knob but samples
/// changes; the relative error weighs every pixel by its own brightness, as pbrt's tools do.
pub struct Curve {
    /// (seconds, relMSE), sorted by seconds.
    by_time: Vec<(f64, f64)>,
    /// The same points sorted by decreasing relMSE.
    by_error: Vec<(f64, f64)>,
}

impl Curve {
    /// The spp ladder's curve, if it has at least two rungs with a positive error.
    pub fn of(run: &Run) -> Option<Curve> {
        let points: Vec<(f64, f64)> = run
            .rows_of(Knob::Spp)
            .map(|r| (r.seconds(), r.metrics.rel_mse))
            .filter(|&(t, e)| t > 0.0 && e > 0.0)
            .collect();
        if points.len() < 2 {
            return None;
        }
        let mut by_time = points.clone();
        by_time.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut by_error = points;
        by_error.sort_by(|a, b| b.1.total_cmp(&a.1));
        Some(Curve { by_time, by_error })
    }

    /// The baseline's relMSE after `seconds` of rendering.
    pub fn error_at(&self, seconds: f64) -> Estimate {
        let (first, last) = (self.by_time[0], self.by_time[self.by_time.len() - 1]);
        if seconds < first.0 {
            return Estimate::Above(first.1);
        }
        if seconds > last.0 {
            return Estimate::Below(last.1);
        }
        Estimate::Within(log_interpolate(
            self.by_time.iter().map(|&(t, e)| (t, e)),
            seconds,
        ))
    }

    /// The baseline's time to reach a relMSE of `error`.
    pub fn time_for(&self, error: f64) -> Estimate {
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

    /// Whether `row` has a lower relMSE than the baseline reaches in the same time; `None` when
    /// the ladder cannot tell.
    pub fn beaten_by(&self, row: &Row) -> Option<bool> {
        let error = row.metrics.rel_mse;
        match self.error_at(row.seconds()) {
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

/// The findings of a run, a few sentences per knob measured.
pub fn sentences(run: &Run, curve: Option<&Curve>) -> Vec<String> {
    let mut out = Vec::new();
    out.extend(timing_sentence(run));
    out.extend(spp_sentence(run));
    out.extend(depth_sentence(run, curve));
    out.extend(roulette_sentence(run, curve));
    out.extend(bvh_sentence(run));
    out.extend(traversal_sentence(run));
    out
}

/// How much the same render's time varied across the run: the baseline at the knob ladders'
/// sample count appears in several ladders (the spp rung, unlimited depth, the default BVH, the
/// robust traversal), so its spread is a measured bound on timing noise, which a reader needs
/// before trusting a difference between rungs.
fn timing_sentence(run: &Run) -> Option<String> {
    let baseline = RenderSettings {
        samples_per_pixel: run.knob_spp,
        ..run.baseline.clone()
    };
    let same: Vec<&Row> = run
        .rows
        .iter()
        .filter(|r| {
            r.settings == baseline
                && r.bvh == BuildQuality::default()
                && r.traversal == Traversal::Robust
        })
        .collect();
    if same.len() < 2 {
        return None;
    }
    let seconds = |r: &&Row| r.render_seconds;
    let fastest = same.iter().map(seconds).fold(f64::INFINITY, f64::min);
    let slowest = same.iter().map(seconds).fold(0.0, f64::max);
    Some(format!(
        "Timing noise: the same render (the baseline at {} spp) took {:.3} to {:.3} s in the {} ladders that \
         contain it, a spread of {:.0}%; differences between rungs smaller than that are not significant. The tables also \
         give each rung's counted work (the tracer's deterministic cost: nodes visited, triangles tested and \
         a fixed charge per ray), which the machine's load does not change.",
        run.knob_spp,
        fastest,
        slowest,
        same.len(),
        100.0 * (slowest / fastest - 1.0),
    ))
}

fn spp_sentence(run: &Run) -> Option<String> {
    let spp: Vec<&Row> = run.rows_of(Knob::Spp).collect();
    if spp.len() < 2 {
        return None;
    }
    let n = |r: &Row| f64::from(r.settings.samples_per_pixel);
    let fit = |y: &dyn Fn(&Row) -> f64| {
        loglog_slope(&spp.iter().map(|r| (n(r), y(r))).collect::<Vec<_>>())
    };
    let (rmse_slope, time_slope) = (fit(&|r| r.metrics.rmse), fit(&|r| r.seconds()));
    let (first, last) = (spp[0], spp[spp.len() - 1]);
    let mut s = format!(
        "Samples: RMSE falls as spp^{rmse_slope:.3} from {} to {} spp (Monte Carlo predicts -0.5) while time \
         grows as spp^{time_slope:.3}, so halving the error costs {:.1}x the time. At {} spp a frame takes {:.4} \
         s for RMSE {:.3e} (relMSE {:.3e}); at {} spp {:.3} s for RMSE {:.3e} (relMSE {:.3e}).",
        first.settings.samples_per_pixel,
        last.settings.samples_per_pixel,
        2f64.powf(-time_slope / rmse_slope),
        first.settings.samples_per_pixel,
        first.seconds(),
        first.metrics.rmse,
        first.metrics.rel_mse,
        last.settings.samples_per_pixel,
        last.seconds(),
        last.metrics.rmse,
        last.metrics.rel_mse,
    );
    let noise = run.reference.noise_mse;
    if noise > 0.0 {
        let net = fit(&|r| (r.metrics.mse - noise).max(0.0).sqrt());
        s += &format!(
            " Net of the reference's own noise the slope is {net:.3}; that noise is {:.0}% of the RMSE at {} spp.",
            100.0 * (noise / last.metrics.mse).sqrt(),
            last.settings.samples_per_pixel,
        );
    }
    Some(s)
}

fn depth_sentence(run: &Run, curve: Option<&Curve>) -> Option<String> {
    let depth: Vec<&Row> = run.rows_of(Knob::Depth).collect();
    let unlimited = depth.iter().find(|r| r.settings.max_depth.is_none())?;
    let capped: Vec<&Row> = depth
        .iter()
        .copied()
        .filter(|r| r.settings.max_depth.is_some())
        .collect();
    let shallowest = capped.first()?;
    let mut s = format!(
        "Depth: a cap at {} makes the image {} on average, a bias no number of samples removes.",
        shallowest.setting,
        brightness(shallowest.metrics.mean_bias()),
    );
    s += &match capped.iter().find(|r| r.metrics.mean_bias().abs() < 0.01) {
        Some(close) => format!(
            " The shallowest cap within 1% of the reference's mean brightness is {}, at {:.0}% of unlimited depth's time.",
            close.setting,
            100.0 * close.seconds() / unlimited.seconds(),
        ),
        None => " No cap measured comes within 1% of the reference's mean brightness.".to_owned(),
    };
    if let Some(curve) = curve {
        s += &beats_more_samples(curve, &capped, "unlimited depth");
    }
    Some(s)
}

fn roulette_sentence(run: &Run, curve: Option<&Curve>) -> Option<String> {
    let roulette: Vec<&Row> = run.rows_of(Knob::Roulette).collect();
    let off = roulette
        .iter()
        .find(|r| r.settings.russian_roulette_depth.is_none())?;
    let best = roulette
        .iter()
        .max_by(|a, b| a.efficiency().total_cmp(&b.efficiency()))?;
    let mut s = format!(
        "Russian roulette: the most efficient setting is {} ({:.2}x the efficiency 1/(relMSE x time) of no \
         roulette: {:.3} s against {:.3} s, relMSE {:.3e} against {:.3e}).",
        best.setting,
        best.efficiency() / off.efficiency(),
        best.seconds(),
        off.seconds(),
        best.metrics.rel_mse,
        off.metrics.rel_mse,
    );
    if let Some(curve) = curve {
        s += &beats_more_samples(curve, &roulette, "the baseline");
    }
    Some(s)
}

/// " At equal time, A and B beat rendering more samples at WHAT, and C does not. For its relMSE
/// the baseline needs ...": the rungs set against the spp ladder, and the equal-error numbers of
/// the most efficient rung.
fn beats_more_samples(curve: &Curve, rows: &[&Row], what: &str) -> String {
    let judged: Vec<(&Row, bool)> = rows
        .iter()
        .filter_map(|r| curve.beaten_by(r).map(|won| (*r, won)))
        .collect();
    let names = |won: bool| -> Vec<&str> {
        judged
            .iter()
            .filter(|(_, w)| *w == won)
            .map(|(r, _)| r.setting.as_str())
            .collect()
    };
    let (won, lost) = (names(true), names(false));
    let verb = |rungs: &[&str], one: &'static str, many: &'static str| {
        if rungs.len() == 1 { one } else { many }
    };
    let mut s = match (won.is_empty(), lost.is_empty()) {
        (true, true) => return String::new(),
        (false, true) => {
            format!(" At equal time, every rung beats rendering more samples at {what}.")
        }
        (true, false) => format!(" At equal time, no rung beats rendering more samples at {what}."),
        (false, false) => format!(
            " At equal time, {} {} rendering more samples at {what}, and {} {} not.",
            join_and(won.iter().copied()),
            verb(&won, "beats", "beat"),
            join_and(lost.iter().copied()),
            verb(&lost, "does", "do"),
        ),
    };
    if let Some(best) = rows
        .iter()
        .max_by(|a, b| a.efficiency().total_cmp(&b.efficiency()))
    {
        s += &format!(
            " At equal error, {} reaches relMSE {:.3e} in {:.3} s, where more samples at the baseline need {} s.",
            best.setting,
            best.metrics.rel_mse,
            best.seconds(),
            curve.time_for(best.metrics.rel_mse),
        );
    }
    s
}

/// "a", "a and b", "a, b and c".
fn join_and<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let names: Vec<&str> = names.collect();
    match names.split_last() {
        None => String::new(),
        Some((last, [])) => (*last).to_owned(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
    }
}

/// Four significant digits: plain decimals between 0.001 and 10000, scientific notation outside.
pub fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let magnitude = v.abs().log10().floor();
    if (-3.0..4.0).contains(&magnitude) {
        format!("{v:.*}", (3.0 - magnitude).max(0.0) as usize)
    } else {
        format!("{v:.3e}")
    }
}

/// "12.3% darker" or "0.4% brighter".
fn brightness(bias: f64) -> String {
    format!(
        "{:.1}% {}",
        100.0 * bias.abs(),
        if bias < 0.0 { "darker" } else { "brighter" }
    )
}

fn bvh_sentence(run: &Run) -> Option<String> {
    let rows: Vec<&Row> = run.rows_of(Knob::Bvh).collect();
    let fastest = rows
        .iter()
        .min_by(|a, b| a.seconds().total_cmp(&b.seconds()))?;
    let slowest = rows
        .iter()
        .max_by(|a, b| a.seconds().total_cmp(&b.seconds()))?;
    let changed: Vec<&str> = rows
        .iter()
        .filter(|r| !r.note.starts_with("bit-identical"))
        .map(|r| r.setting.as_str())
        .collect();
    let images = if changed.is_empty() {
        format!(
            "All {} build qualities gave bit-identical images.",
            rows.len()
        )
    } else {
        format!(
            "The images of {} DIFFER from the default quality's: the BVH must never change an image.",
            changed.join(", ")
        )
    };
    let build = |pick: fn(f64, f64) -> f64, start: f64| {
        rows.iter().map(|r| r.build_seconds).fold(start, pick)
    };
    let largest_share = rows
        .iter()
        .map(|r| r.build_seconds / r.seconds())
        .fold(0.0, f64::max);
    Some(format!(
        "BVH: {images} Builds took {} to {} s, at most {:.2}% of a frame; build plus render ranged from {:.4} s \
         ({}) to {:.4} s ({}).",
        significant(build(f64::min, f64::INFINITY)),
        significant(build(f64::max, 0.0)),
        100.0 * largest_share,
        fastest.seconds(),
        fastest.setting,
        slowest.seconds(),
        slowest.setting,
    ))
}

fn traversal_sentence(run: &Run) -> Option<String> {
    let robust = run
        .rows_of(Knob::Traversal)
        .find(|r| r.traversal == Traversal::Robust)?;
    let obvhs = run
        .rows_of(Knob::Traversal)
        .find(|r| r.traversal == Traversal::Obvhs)?;
    let mut s = format!(
        "Traversal: obvhs's own traversal renders at {:.2} Mrays/s against {:.2} for ours ({:.2}x), and its image {} \
         (its counted work counts only the leaves obvhs reports, not its inner nodes, so it is not comparable).",
        obvhs.mrays_per_second(),
        robust.mrays_per_second(),
        obvhs.mrays_per_second() / robust.mrays_per_second(),
        obvhs
            .note
            .replace(
                "differs from the robust traversal's image",
                "differs from ours"
            )
            .replace(
                "bit-identical to the robust traversal's image",
                "is bit-identical to ours"
            ),
    );
    if let (Some(r), Some(o)) = (
        run.leak_check(Traversal::Robust),
        run.leak_check(Traversal::Obvhs),
    ) {
        let counts = |c: &LeakCheck| {
            format!(
                "{} of {} rays aimed at edges and vertices leaked, {} of {} bounces leaked and {} hit the triangle they \
                 left ({:.2} Mrays/s)",
                c.edge_leaks,
                c.edge_rays,
                c.bounce_leaks,
                c.bounce_rays,
                c.self_hits,
                c.mrays_per_second()
            )
        };
        s += &format!(
            " On a closed sphere of {} triangles, with obvhs's traversal {}; with ours {}.",
            o.triangles,
            counts(o),
            counts(r)
        );
    }
    Some(s)
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
    fn numbers_keep_four_significant_digits() {
        assert_eq!(significant(0.39754), "0.3975");
        assert_eq!(significant(12.3456), "12.35");
        assert_eq!(significant(0.0012344), "0.001234");
        assert_eq!(significant(4.07e-6), "4.070e-6");
        assert_eq!(significant(0.0), "0");
    }

    #[test]
    fn names_are_joined_as_in_a_sentence() {
        assert_eq!(join_and(["a"].into_iter()), "a");
        assert_eq!(join_and(["a", "b", "c"].into_iter()), "a, b and c");
        assert_eq!(join_and(std::iter::empty()), "");
    }

    #[test]
    fn interpolation_is_linear_in_log_log() {
        let curve = Curve {
            by_time: vec![(1.0, 1.0), (4.0, 0.5)],
            by_error: vec![(1.0, 1.0), (4.0, 0.5)],
        };
        assert!(
            matches!(curve.error_at(2.0), Estimate::Within(e) if (e - 0.5f64.sqrt()).abs() < 1e-12)
        );
        assert!(
            matches!(curve.time_for(0.5f64.sqrt()), Estimate::Within(t) if (t - 2.0).abs() < 1e-12)
        );
        assert_eq!(curve.error_at(0.5), Estimate::Above(1.0));
        assert_eq!(curve.error_at(8.0), Estimate::Below(0.5));
        assert_eq!(curve.time_for(2.0), Estimate::Below(1.0));
        assert_eq!(curve.time_for(0.25), Estimate::Above(4.0));
    }
}
