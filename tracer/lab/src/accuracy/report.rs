//! The three outputs of `tessera accuracy`: accuracy.csv (every rung, for other tools),
//! accuracy.md (tables and the comparisons in sentences, for people) and accuracy.svg (error
//! against time, log-log, one curve per knob).
//!
//! Every non-spp rung is also set against the spp ladder, which is the baseline settings at
//! growing sample counts and so the curve of "just render longer": at equal time, what error would
//! the baseline have reached; at equal error, how long would it have needed. Those two columns are
//! what tells a reader whether a knob beats simply taking more samples.

use super::Knob;
use super::bench::{ROULETTE_DEPTH_CAP, Row};
use super::curve::Curve;
use super::findings;
use super::leaks::LeakCheck;
use super::reference::{Reference, Source};
use crate::LabError;
use std::fmt::Write as _;
use std::path::Path;
use tracer::geometry::Traversal;
use tracer::scene::RenderSettings;
use tracer::{CameraRays, PathLanes};

/// Everything one run measured, and how.
pub struct Run<'a> {
    pub command: String,
    /// The machine's one-minute load average when the ladders started and when they ended.
    pub load_average: [Option<f64>; 2],
    pub cores: usize,
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    pub triangles: usize,
    /// The settings the scene file asks for (the baseline replaces depth and size).
    pub scene_settings: RenderSettings,
    pub baseline: RenderSettings,
    pub knob_spp: u32,
    pub timing: super::bench::Timing,
    /// What the comparisons count as cost.
    pub cost: super::Cost,
    pub reference: &'a Reference,
    pub rows: &'a [Row],
    pub leak_checks: &'a [LeakCheck],
    /// The closed-sphere check far from the origin, one per offset method.
    pub offset_checks: &'a [LeakCheck],
}

impl Run<'_> {
    pub fn rows_of(&self, knob: Knob) -> impl Iterator<Item = &Row> {
        self.rows.iter().filter(move |r| r.knob == knob)
    }

    pub fn leak_check(&self, traversal: Traversal) -> Option<&LeakCheck> {
        self.leak_checks.iter().find(|c| c.traversal == traversal)
    }

    /// The closed-sphere check shown beside a traversal rung: its traversal's, once per
    /// traversal (on the rung with camera rays in packets and paths in lanes, not again beside
    /// the ones without, since the check traces single rays either way).
    pub fn leak_check_of(&self, row: &Row) -> Option<&LeakCheck> {
        (row.knob == Knob::Traversal
            && row.camera_rays == CameraRays::default()
            && row.paths == PathLanes::default())
        .then(|| self.leak_check(row.traversal))
        .flatten()
    }
}

pub fn write_all(out: &Path, run: &Run) -> Result<(), LabError> {
    let write = |name: &str, text: String| {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(LabError::io("write", path))
    };
    write("accuracy.csv", csv(run))?;
    write("accuracy.md", markdown(run))?;
    super::plot::write_svg(&out.join("accuracy.svg"), run)
}

const CSV_HEADER: &str = "knob,setting,spp,max_depth,russian_roulette_depth,bvh,traversal,build_seconds,\
render_seconds,seconds,rays,work,mrays_per_second,rmse,rel_mse,mae,max_difference,flip,mean_bias,efficiency,efficiency_work,\
sphere_rays,sphere_edge_leaks,sphere_bounce_leaks,sphere_self_hits,note";

/// One line per rung; the leak-check columns are filled on the traversal rungs only.
pub fn csv(run: &Run) -> String {
    let mut out = String::from(CSV_HEADER);
    out.push('\n');
    for r in run.rows {
        let m = &r.metrics;
        let check = run.leak_check_of(r);
        let fields = [
            r.knob.name().to_owned(),
            r.setting.clone(),
            r.settings.samples_per_pixel.to_string(),
            depth_name(r.settings.max_depth),
            r.settings
                .russian_roulette_depth
                .map_or("off".to_owned(), |d| d.to_string()),
            format!("{:?}", r.bvh).to_lowercase(),
            format!("{:?}", r.traversal).to_lowercase(),
            format!("{:.6}", r.build_seconds),
            format!("{:.6}", r.render_seconds),
            format!("{:.6}", r.seconds()),
            r.rays.to_string(),
            r.work.to_string(),
            format!("{:.4}", r.mrays_per_second()),
            format!("{:.6e}", m.rmse),
            format!("{:.6e}", m.rel_mse),
            format!("{:.6e}", m.mae),
            format!("{:.6e}", m.max_difference.value),
            format!("{:.6}", r.flip),
            format!("{:.6}", m.mean_bias()),
            format!("{:.6e}", r.efficiency(super::Cost::Time)),
            format!("{:.6e}", r.efficiency(super::Cost::Work)),
            check.map_or(String::new(), |c| c.rays.to_string()),
            check.map_or(String::new(), |c| {
                (c.edge_leaks + c.aimed_leaks).to_string()
            }),
            check.map_or(String::new(), |c| c.bounce_leaks.to_string()),
            check.map_or(String::new(), |c| c.self_hits.to_string()),
            r.note.clone(),
        ];
        let quoted: Vec<String> = fields.iter().map(|f| csv_field(f)).collect();
        out += &quoted.join(",");
        out.push('\n');
    }
    out
}

fn csv_field(field: &str) -> String {
    if field.contains([',', '"', '\n']) {
        format!("\"{}\"", field.replace('"', "\"\""))
    } else {
        field.to_owned()
    }
}

pub fn depth_name(depth: Option<u32>) -> String {
    depth.map_or("unlimited".to_owned(), |d| d.to_string())
}

/// The report for people: setup, findings in sentences, one table per knob, the plot.
pub fn markdown(run: &Run) -> String {
    let mut md = String::new();
    let b = &run.baseline;
    let s = &run.scene_settings;
    let _ = writeln!(md, "# What accuracy costs in time: `{}`\n", run.scene);
    let _ = writeln!(md, "Generated by `{}`.\n", run.command);
    if let [Some(before), Some(after)] = run.load_average {
        let _ = writeln!(
            md,
            "The machine's load average was {before:.1} when the ladders started and {after:.1} when they ended, on \
             {} cores{}.\n",
            run.cores,
            if before.max(after) > run.cores as f64 + 0.5 {
                ": other work shared the cores, so times are inflated and noisier than on an idle machine"
            } else {
                ""
            },
        );
    }
    let _ = writeln!(
        md,
        "{}x{} pixels, {} triangles, {} rendering threads, frame 0. Times are wall-clock seconds of a whole \
         frame, the fastest of at least {} run{} (more for renders under {} s). Errors are against the reference, \
         over all pixels and channels: RMSE, relMSE = mean (a-b)^2/(b+0.01)^2, mean FLIP (8-bit sRGB at \
         exposure 1), and the mean bias (how much brighter or darker the whole image is).\n",
        run.width,
        run.height,
        run.triangles,
        run.threads,
        run.timing.repeats,
        if run.timing.repeats == 1 { "" } else { "s" },
        run.timing.repeat_below,
    );
    let _ = writeln!(
        md,
        "**Baseline** (what every rung changes one thing of): unlimited depth ended by Russian roulette from depth {}, \
         our robust traversal, the default BVH quality, seed {}. The scene file itself asks for {} spp, max depth {} and \
         roulette {}.\n",
        b.russian_roulette_depth.unwrap_or(0),
        b.seed,
        s.samples_per_pixel,
        depth_name(s.max_depth),
        s.russian_roulette_depth
            .map_or("off".to_owned(), |d| format!("from depth {d}")),
    );
    let _ = writeln!(md, "**Reference**: {}.\n", run.reference.describe());
    let _ = writeln!(
        md,
        "![relMSE against {}, log-log, one curve per knob](accuracy.svg)\n",
        run.cost.name()
    );
    let curve = Curve::of(run);
    let findings = findings::sentences(run, curve.as_ref());
    if !findings.is_empty() {
        md += "## Findings\n\n";
        for sentence in findings {
            let _ = writeln!(md, "- {sentence}");
        }
        md.push('\n');
    }
    let versus = |r: &Row| match &curve {
        Some(c) => format!(
            "{} | {}",
            c.error_at(r.cost(run.cost)),
            c.cost_for(r.metrics.rel_mse)
        ),
        None => "- | -".to_owned(),
    };
    let common = |r: &Row| {
        format!(
            "{:.4} | {:.1} | {:.3e} | {:.3e} | {:.4} | {:+.2}%",
            r.seconds(),
            r.work as f64 / 1e6,
            r.metrics.rmse,
            r.metrics.rel_mse,
            r.flip,
            100.0 * r.metrics.mean_bias()
        )
    };
    const COMMON: &str = "time (s) | counted work (M) | RMSE | relMSE | FLIP | mean bias";
    let versus_head = format!(
        "baseline relMSE at equal {name} | baseline {name} ({unit}) at equal relMSE",
        name = run.cost.name(),
        unit = run.cost.unit()
    );
    let versus_head = versus_head.as_str();
    let mut table = |title: String, head: &str, rows: Vec<String>| {
        if rows.is_empty() {
            return;
        }
        let columns = head.matches('|').count() + 1;
        let _ = writeln!(md, "## {title}\n\n| {head} |\n|{}", "---|".repeat(columns));
        for row in rows {
            let _ = writeln!(md, "| {row} |");
        }
        md.push('\n');
    };
    table(
        "Samples per pixel".into(),
        &format!("spp | {COMMON} | Mrays/s"),
        run.rows_of(Knob::Spp)
            .map(|r| {
                format!(
                    "{} | {} | {:.2}",
                    r.settings.samples_per_pixel,
                    common(r),
                    r.mrays_per_second()
                )
            })
            .collect(),
    );
    table(
        format!("Maximum path depth, at {} spp", run.knob_spp),
        &format!("max depth | {COMMON} | {versus_head}"),
        run.rows_of(Knob::Depth)
            .map(|r| format!("{} | {} | {}", r.setting, common(r), versus(r)))
            .collect(),
    );
    let roulette: Vec<&Row> = run.rows_of(Knob::Roulette).collect();
    let best = roulette
        .iter()
        .map(|r| r.efficiency(run.cost))
        .fold(0.0f64, f64::max);
    table(
        format!(
            "Russian roulette, at {} spp, depth capped at {ROULETTE_DEPTH_CAP}",
            run.knob_spp
        ),
        &format!(
            "roulette | {COMMON} | efficiency 1/(relMSE x {}) | of the best | {versus_head}",
            run.cost.unit()
        ),
        roulette
            .iter()
            .map(|r| {
                let e = r.efficiency(run.cost);
                format!(
                    "{} | {} | {:.4e} | {:.2} | {}",
                    r.setting,
                    common(r),
                    e,
                    e / best,
                    versus(r)
                )
            })
            .collect(),
    );
    table(
        format!("BVH build quality, at {} spp", run.knob_spp),
        &format!("quality | build (s) | render (s) | {COMMON} | image"),
        run.rows_of(Knob::Bvh)
            .map(|r| {
                format!(
                    "{} | {:.6} | {:.4} | {} | {}",
                    r.setting,
                    r.build_seconds,
                    r.render_seconds,
                    common(r),
                    r.note
                )
            })
            .collect(),
    );
    table(
        format!(
            "Traversal, at {} spp, and the closed-sphere check",
            run.knob_spp
        ),
        &format!(
            "traversal | {COMMON} | Mrays/s | image | sphere rays | sphere Mrays/s | primary leaks | bounce leaks | self-hits"
        ),
        run.rows_of(Knob::Traversal)
            .map(|r| {
                let check = run
                    .leak_check_of(r)
                    .map_or("- | - | - | - | -".to_owned(), |c| {
                        let primary = format!(
                            "{} of {}",
                            c.edge_leaks + c.aimed_leaks,
                            c.edge_rays + c.aimed_rays
                        );
                        let bounce = format!("{} of {}", c.bounce_leaks, c.bounce_rays);
                        format!(
                            "{} | {:.2} | {primary} | {bounce} | {}",
                            c.rays,
                            c.mrays_per_second(),
                            c.self_hits
                        )
                    });
                format!(
                    "{} | {} | {:.2} | {} | {}",
                    r.setting,
                    common(r),
                    r.mrays_per_second(),
                    image(r),
                    check
                )
            })
            .collect(),
    );
    table(
        format!(
            "Spawn offset, at {} spp, and the closed-sphere check {} from the origin",
            run.knob_spp,
            super::leaks::FAR.x
        ),
        &format!("offset | {COMMON} | image | far sphere: bounce leaks | self-hits"),
        run.rows_of(Knob::Offset)
            .map(|r| {
                let check = run
                    .offset_checks
                    .iter()
                    .find(|c| c.offset.name() == r.setting)
                    .map_or("- | -".to_owned(), |c| {
                        format!("{} of {} | {}", c.bounce_leaks, c.bounce_rays, c.self_hits)
                    });
                format!("{} | {} | {} | {check}", r.setting, common(r), image(r))
            })
            .collect(),
    );
    // The sampling knobs share one table shape: the setting, the common columns, the comparison
    // with the ladder's first rung, and how its image differs.
    let sampling = [
        (
            Knob::Lights,
            "Area light sampling",
            "emissive triangles found by next-event estimation and BSDF sampling weighted by the \
             power heuristic, by next-event estimation alone, or by BSDF sampling alone; in a \
             scene without area lights the rungs are the same bits",
            "strategies",
        ),
        (
            Knob::Environment,
            "Environment sampling",
            "next-event estimation of the environment: by importance (and through the scene's \
             portals, where it has them), by importance with the portals ignored, uniformly over \
             the sphere, or not at all, leaving it to BSDF sampling",
            "environment sampling",
        ),
        (
            Knob::Spectral,
            "Wavelength sampling",
            "RGB until dispersive glass, the default; or spectral from the camera on, with three \
             hero wavelengths or one; in a scene without dispersion the spectral rungs are what an \
             always-spectral renderer pays",
            "wavelengths",
        ),
        (
            Knob::Media,
            "Media sampling",
            "free flights: analytic by a hero channel, a per-flight channel mixture, or delta \
             tracking; shadow rays: closed-form transmittance or ratio tracking; xN: the \
             trackers' majorant over the largest extinction",
            "flights+shadows",
        ),
    ];
    for (knob, title, what, column) in sampling {
        table(
            format!("{title}, at {} spp ({what})", run.knob_spp),
            &format!("{column} | {COMMON} | {versus_head} | image"),
            run.rows_of(knob)
                .map(|r| {
                    format!(
                        "{} | {} | {} | {}",
                        r.setting,
                        common(r),
                        versus(r),
                        image(r)
                    )
                })
                .collect(),
        );
    }
    if let Source::Rendered { .. } | Source::Cached = run.reference.source {
        let _ = writeln!(
            md,
            "The reference's own noise (RMSE about {:.3e}, relMSE about {:.3e}) is part of every error above: \
             rungs within about twice that are limited by the reference, not by the knob. Render it with more \
             samples (`--reference-spp`) to lower the floor.",
            run.reference.noise_rmse(),
            run.reference.noise_rel_mse
        );
    }
    md
}

/// What a rung's image was, beside the first rung of its ladder.
fn image(row: &Row) -> &str {
    if row.note.is_empty() {
        "(the baseline)"
    } else {
        &row.note
    }
}
