//! The comparisons a reader wants, in sentences: how error and time scale with samples, and for
//! every other knob whether it beats simply rendering longer at the baseline settings.
//!
//! The spp ladder is the yardstick ([`Curve`]): at equal cost, what error would the baseline have
//! reached; at equal error, what would it have cost.

use super::bench::Row;
use super::curve::{Curve, loglog_slope};
use super::leaks::LeakCheck;
use super::report::Run;
use super::{Cost, Knob};
use tracer::geometry::{BuildQuality, Traversal};
use tracer::scene::RenderSettings;
use tracer::{CameraRays, PathLanes};

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
                && r.camera_rays == CameraRays::default()
                && r.paths == PathLanes::default()
        })
        .collect();
    if same.len() < 2 {
        return None;
    }
    let seconds = |r: &&Row| r.render_seconds;
    let fastest = same.iter().map(seconds).fold(f64::INFINITY, f64::min);
    let slowest = same.iter().map(seconds).fold(0.0, f64::max);
    Some(
        format!(
            "Timing noise: the same render (the baseline at {} spp) took {:.3} to {:.3} s in the {} ladders that \
         contain it, a spread of {:.0}%; differences between rungs smaller than that are not significant. The tables also \
         give each rung's counted work (the tracer's deterministic cost: nodes visited, triangles tested and \
         a charge per ray, larger for rays that are shaded than for rays that escape), which the machine's load does not change.",
            run.knob_spp,
            fastest,
            slowest,
            same.len(),
            100.0 * (slowest / fastest - 1.0),
        ) + &work_rate_sentence(run),
    )
}

/// When the comparisons count work: how work converts to seconds, at the fastest rate any rung of
/// our own traversal reached (the machine at its least disturbed).
fn work_rate_sentence(run: &Run) -> String {
    if run.cost != Cost::Work {
        return String::new();
    }
    let rate = run
        .rows
        .iter()
        .filter(|r| {
            r.traversal == Traversal::Robust
                && r.camera_rays == CameraRays::default()
                && r.paths == PathLanes::default()
                && r.render_seconds > 0.0
        })
        .map(|r| r.work as f64 / 1e6 / r.render_seconds)
        .fold(0.0, f64::max);
    format!(
        " The comparisons below count work, not seconds; the fastest rung ran at {} M units per second, so \
         at that rate 1 M units is {} s.",
        significant(rate),
        significant(1.0 / rate),
    )
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
            " The shallowest cap within 1% of the reference's mean brightness is {}, at {:.0}% of unlimited \
             depth's {}.",
            close.setting,
            100.0 * close.cost(run.cost) / unlimited.cost(run.cost),
            run.cost.name(),
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
    let c = run.cost;
    let best = roulette
        .iter()
        .max_by(|a, b| a.efficiency(c).total_cmp(&b.efficiency(c)))?;
    let mut s = format!(
        "Russian roulette: the most efficient setting is {} ({:.2}x the efficiency 1/(relMSE x {}) of no \
         roulette: {} {unit} against {} {unit}, relMSE {:.3e} against {:.3e}).",
        best.setting,
        best.efficiency(c) / off.efficiency(c),
        c.name(),
        significant(best.cost(c)),
        significant(off.cost(c)),
        best.metrics.rel_mse,
        off.metrics.rel_mse,
        unit = c.unit(),
    );
    if let Some(curve) = curve {
        s += &beats_more_samples(curve, &roulette, "the baseline");
    }
    Some(s)
}

/// " At equal cost, A and B beat rendering more samples at WHAT, and C does not. For its relMSE
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
    let (c, name) = (curve.cost, curve.cost.name());
    let mut s = match (won.is_empty(), lost.is_empty()) {
        (true, true) => return String::new(),
        (false, true) => {
            format!(" At equal {name}, every rung beats rendering more samples at {what}.")
        }
        (true, false) => {
            format!(" At equal {name}, no rung beats rendering more samples at {what}.")
        }
        (false, false) => format!(
            " At equal {name}, {} {} rendering more samples at {what}, and {} {} not.",
            join_and(won.iter().copied()),
            verb(&won, "beats", "beat"),
            join_and(lost.iter().copied()),
            verb(&lost, "does", "do"),
        ),
    };
    if let Some(best) = rows
        .iter()
        .max_by(|a, b| a.efficiency(c).total_cmp(&b.efficiency(c)))
    {
        s += &format!(
            " At equal error, {} reaches relMSE {:.3e} for {} {unit}, where more samples at the baseline need \
             {} {unit}.",
            best.setting,
            best.metrics.rel_mse,
            significant(best.cost(c)),
            curve.cost_for(best.metrics.rel_mse),
            unit = c.unit(),
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
    let least = rows.iter().min_by_key(|r| r.work)?;
    let most = rows.iter().max_by_key(|r| r.work)?;
    Some(format!(
        "BVH: {images} Builds took {} to {} s, at most {:.2}% of a frame; build plus render ranged from {:.4} s \
         ({}) to {:.4} s ({}). The trees' counted work per frame ranged from {:.1} M ({}) to {:.1} M ({}).",
        significant(build(f64::min, f64::INFINITY)),
        significant(build(f64::max, 0.0)),
        100.0 * largest_share,
        fastest.seconds(),
        fastest.setting,
        slowest.seconds(),
        slowest.setting,
        least.work as f64 / 1e6,
        least.setting,
        most.work as f64 / 1e6,
        most.setting,
    ))
}

/// A traversal rung's note against the robust traversal's image, shortened to "differs" or
/// "bit-identical" for a sentence that has named what it is compared with.
fn short_note(note: &str) -> String {
    note.replace("differs from the robust traversal's image", "differs")
        .replace(
            "bit-identical to the robust traversal's image",
            "bit-identical",
        )
}

fn traversal_sentence(run: &Run) -> Option<String> {
    let robust = run.rows_of(Knob::Traversal).find(|r| {
        r.traversal == Traversal::Robust
            && r.camera_rays == CameraRays::Packets
            && r.paths == PathLanes::Lanes
    })?;
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
    if let Some(single) = run
        .rows_of(Knob::Traversal)
        .find(|r| r.traversal == Traversal::Robust && r.camera_rays == CameraRays::OneByOne)
    {
        s += &format!(
            " Ours with a pixel's camera rays in packets: {:.3} s, against {:.3} s with every ray alone, and the image {}.",
            robust.render_seconds,
            single.render_seconds,
            short_note(&single.note),
        );
    }
    if let Some(single) = run
        .rows_of(Knob::Traversal)
        .find(|r| r.traversal == Traversal::Robust && r.paths == PathLanes::OneByOne)
    {
        s += &format!(
            " Ours with the paths in lanes where the scene allows them: {:.3} s, against {:.3} s one path at a time, and the image {}.",
            robust.render_seconds,
            single.render_seconds,
            short_note(&single.note),
        );
    }
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
}
