//! Timed renders and the one-knob-at-a-time ladders.
//!
//! A rung's time is the wall time of rendering the whole frame on the thread pool, tiles of
//! [`TILE`] pixels handed out by rayon as `tessera render` would. Renders shorter than a second
//! (`--repeat-below`) are repeated and the fastest run kept: a 1-spp render of a small image
//! lasts milliseconds, and a single measurement of it is mostly scheduler noise and whatever else
//! the machine is doing, which only ever adds time. The image is deterministic, so repeating
//! changes only the time.

use super::reference::Reference;
use super::{Cost, Knob};
use crate::compare::{Metrics, mean_flip};
use std::time::Instant;
use tracer::geometry::{Accel, BuildQuality, OffsetMethod, Traversal};
use tracer::output::RgbImage;
use tracer::scene::RenderSettings;
use tracer::{CameraRays, FrameConfig, PathLanes, World};

/// The side of the square tiles a frame is cut into.
pub const TILE: u32 = 32;
/// At most this many repetitions of a short render.
const MAX_REPEATS: usize = 31;

/// How often a render (or BVH build) is run for its time; the fastest run counts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Runs shorter than this many seconds are repeated until the runs fill it (at most 31).
    pub repeat_below: f64,
    /// Every measurement is run at least this many times.
    pub repeats: u32,
}

impl Timing {
    /// One run, whatever its length: for renders whose time is only informative.
    pub const ONCE: Timing = Timing {
        repeat_below: 0.0,
        repeats: 1,
    };
}
/// The depth cap of the roulette ladder: "off" needs one, or paths in a closed scene never end,
/// and every roulette rung gets the same cap so that only the roulette differs. At a survival
/// probability of at most 0.95 per bounce, paths this long are rare enough not to matter.
pub const ROULETTE_DEPTH_CAP: u32 = 64;

/// One measured rung of a ladder.
#[derive(Clone, Debug)]
pub struct Row {
    /// The knob this rung turns.
    pub knob: Knob,
    /// The knob's value, as a reader would name it ("16 spp", "depth 4", "off", "Medium", ...).
    pub setting: String,
    /// The render settings of this rung.
    pub settings: RenderSettings,
    /// The BVH build quality of this rung.
    pub bvh: BuildQuality,
    /// The traversal of this rung.
    pub traversal: Traversal,
    /// How this rung's camera rays met the tree: in packets (the default) or one by one.
    pub camera_rays: CameraRays,
    /// How this rung's paths were advanced: in lanes where the world allows it (the
    /// default), or one by one.
    pub paths: PathLanes,
    /// Seconds to build the BVH (the BVH ladder only; 0 elsewhere).
    pub build_seconds: f64,
    /// Seconds to render the frame (the fastest of the repeats).
    pub render_seconds: f64,
    /// Closest-hit plus shadow rays traced.
    pub rays: u64,
    /// The tracer's counted work ([`tracer::PathStats::work`]): a cost that, unlike the time, does
    /// not depend on the machine or its load.
    pub work: u64,
    /// The error against the reference.
    pub metrics: Metrics,
    /// Mean FLIP against the reference.
    pub flip: f64,
    /// Whatever else the rung showed (an image that changed when it must not, dropped samples).
    pub note: String,
}

impl Row {
    /// The time this rung cost: BVH build (for the BVH ladder) plus render.
    pub fn seconds(&self) -> f64 {
        self.build_seconds + self.render_seconds
    }

    /// What this rung cost: seconds, or millions of counted work units.
    pub fn cost(&self, cost: Cost) -> f64 {
        match cost {
            Cost::Time => self.seconds(),
            Cost::Work => self.work as f64 / 1e6,
        }
    }

    /// 1 / (relative MSE x cost): higher is better; equal for settings that trade one for the
    /// other.
    pub fn efficiency(&self, cost: Cost) -> f64 {
        1.0 / (self.metrics.rel_mse * self.cost(cost))
    }

    /// Closest-hit plus shadow rays per second of render time, in millions.
    pub fn mrays_per_second(&self) -> f64 {
        self.rays as f64 / self.render_seconds / 1e6
    }
}

/// A rendered frame and what it cost.
pub struct Timed {
    /// The frame's pixels.
    pub image: RgbImage,
    /// Wall seconds of the render (the fastest of the repeats).
    pub seconds: f64,
    /// Closest-hit plus shadow rays traced.
    pub rays: u64,
    /// The tracer's counted work.
    pub work: u64,
    /// Samples dropped as non-finite (a bug if ever non-zero).
    pub invalid_samples: u64,
}

/// Renders frame 0 of `world` on `pool`, timed (the fastest of repeats when short).
pub fn render(world: &World, pool: &rayon::ThreadPool, repeat_below: f64) -> Timed {
    render_with(
        world,
        pool,
        Timing {
            repeat_below,
            repeats: 1,
        },
    )
}

/// [`render`], timed as `timing` says.
pub fn render_with(world: &World, pool: &rayon::ThreadPool, timing: Timing) -> Timed {
    let (width, height) = (world.scene.settings.width, world.scene.settings.height);
    let once = || {
        let started = Instant::now();
        let film = tracer::render_frame(world, 0, pool, FrameConfig { tile: TILE });
        (film, started.elapsed().as_secs_f64())
    };
    let (film, first) = once();
    let seconds = fastest_time(first, timing, || once().1);
    Timed {
        rays: film.stats.rays + film.stats.shadow_rays,
        work: film.stats.work(),
        invalid_samples: film.stats.invalid_samples,
        image: RgbImage {
            width,
            height,
            pixels: film.pixels,
        },
        seconds,
    }
}

/// The fastest of `first` and as many further runs of `again` as `timing` asks for.
pub fn fastest_time(first: f64, timing: Timing, mut again: impl FnMut() -> f64) -> f64 {
    let fill = if first >= timing.repeat_below {
        1
    } else {
        ((timing.repeat_below / first.max(1e-6)).ceil() as usize).min(MAX_REPEATS)
    };
    let repeats = fill.max(timing.repeats as usize);
    (1..repeats).map(|_| again()).fold(first, f64::min)
}

/// The world being measured, the pool it renders on and the reference it is measured against.
pub struct Bench<'a> {
    pub(super) world: World,
    pool: &'a rayon::ThreadPool,
    reference: &'a Reference,
    /// The settings every rung starts from (`world.scene.settings` on entry).
    pub(super) baseline: RenderSettings,
    timing: Timing,
}

impl<'a> Bench<'a> {
    /// A bench of `world` on `pool`, measured against `reference`, each render timed as `timing`
    /// says; the world's settings on entry are every rung's baseline.
    pub fn new(
        world: World,
        pool: &'a rayon::ThreadPool,
        reference: &'a Reference,
        timing: Timing,
    ) -> Self {
        let baseline = world.scene.settings.clone();
        Bench {
            world,
            pool,
            reference,
            baseline,
            timing,
        }
    }

    /// The world as it is between rungs (the baseline settings).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// Samples per pixel 1, 2, 4, ... up to `max_spp`.
    pub fn spp_ladder(&mut self, max_spp: u32) -> Vec<Row> {
        let rungs = (0..32).map(|k| 1u32 << k).take_while(|&spp| spp <= max_spp);
        rungs
            .map(|spp| {
                let settings = RenderSettings {
                    samples_per_pixel: spp,
                    ..self.baseline.clone()
                };
                self.measure(Knob::Spp, format!("{spp} spp"), settings).0
            })
            .collect()
    }

    /// Maximum depth 1, 2, 4, 8, 16 and unlimited, at `spp`.
    pub fn depth_ladder(&mut self, spp: u32) -> Vec<Row> {
        [Some(1), Some(2), Some(4), Some(8), Some(16), None]
            .into_iter()
            .map(|max_depth| {
                let settings = RenderSettings {
                    samples_per_pixel: spp,
                    max_depth,
                    ..self.baseline.clone()
                };
                let label = max_depth.map_or("unlimited".to_owned(), |d| format!("depth {d}"));
                self.measure(Knob::Depth, label, settings).0
            })
            .collect()
    }

    /// Russian roulette off, and on from depth 1, 2, 3, 5 and 8, all capped at
    /// [`ROULETTE_DEPTH_CAP`], at `spp`.
    pub fn roulette_ladder(&mut self, spp: u32) -> Vec<Row> {
        [None, Some(1), Some(2), Some(3), Some(5), Some(8)]
            .into_iter()
            .map(|start| {
                let settings = RenderSettings {
                    samples_per_pixel: spp,
                    max_depth: Some(ROULETTE_DEPTH_CAP),
                    russian_roulette_depth: start,
                    ..self.baseline.clone()
                };
                let label = start.map_or("off".to_owned(), |d| format!("from depth {d}"));
                self.measure(Knob::Roulette, label, settings).0
            })
            .collect()
    }

    /// Each BVH build quality: build time, render time at `spp`, and whether the image is
    /// bit-identical to the default quality's (it must be: the traversal finds the closest hit
    /// whatever the tree).
    pub fn bvh_ladder(&mut self, spp: u32) -> Vec<Row> {
        let settings = self.at_spp(spp);
        self.world.scene.settings = settings.clone();
        let default_image = render_with(&self.world, self.pool, Timing::ONCE).image;
        let rows = BuildQuality::ALL
            .into_iter()
            .map(|quality| {
                let triangles = &self.world.scene.triangles;
                let started = Instant::now();
                let accel = Accel::build(triangles, quality);
                let build_seconds =
                    fastest_time(started.elapsed().as_secs_f64(), self.timing, || {
                        let again = Instant::now();
                        drop(std::hint::black_box(Accel::build(triangles, quality)));
                        again.elapsed().as_secs_f64()
                    });
                self.world.set_accel(accel);
                let (mut row, image) =
                    self.measure(Knob::Bvh, format!("{quality:?}"), settings.clone());
                row.bvh = quality;
                row.build_seconds = build_seconds;
                row.note = difference_note(&image, &default_image, "the default BVH's image");
                row
            })
            .collect();
        let default = Accel::build(&self.world.scene.triangles, BuildQuality::default());
        self.world.set_accel(default);
        rows
    }

    /// Our robust traversal (8-wide, what renders use; a pixel's camera rays in packets, its
    /// paths in lanes where the world allows), the same with camera rays one by one, the same
    /// with paths one by one, the same tests over the binary tree, and obvhs's own, at `spp`;
    /// each image is compared with the first's.
    pub fn traversal_ladder(&mut self, spp: u32) -> Vec<Row> {
        let settings = self.at_spp(spp);
        let rungs = [
            (Traversal::Robust, CameraRays::Packets, PathLanes::Lanes),
            (Traversal::Robust, CameraRays::OneByOne, PathLanes::Lanes),
            (Traversal::Robust, CameraRays::Packets, PathLanes::OneByOne),
            (
                Traversal::RobustBinary,
                CameraRays::Packets,
                PathLanes::Lanes,
            ),
            (Traversal::Obvhs, CameraRays::Packets, PathLanes::Lanes),
        ];
        let rows = self.compared_ladder(
            Knob::Traversal,
            rungs,
            "the robust traversal's image",
            |bench, (traversal, camera_rays, paths)| {
                bench.world.set_traversal(traversal);
                bench.world.camera_rays = camera_rays;
                bench.world.paths = paths;
                (rung_name(traversal, camera_rays, paths), settings.clone())
            },
        );
        self.world.set_traversal(Traversal::Robust);
        self.world.camera_rays = CameraRays::default();
        self.world.paths = PathLanes::default();
        rows
    }

    /// The error-bound spawn offset and the fixed-ULP one, at `spp`. On a scene of the scale of
    /// its coordinates both start rays on the right side; the images differ by the noise of
    /// paths that took other turns, and the times by the cost of computing the bound.
    pub fn offset_ladder(&mut self, spp: u32) -> Vec<Row> {
        let settings = self.at_spp(spp);
        let rows = self.compared_ladder(
            Knob::Offset,
            OffsetMethod::ALL,
            "the error-bound offset's image",
            |bench, offset| {
                bench.world.offset = offset;
                (offset.name().to_owned(), settings.clone())
            },
        );
        self.world.offset = OffsetMethod::default();
        rows
    }

    /// The baseline settings at `spp` samples per pixel.
    pub(super) fn at_spp(&self, spp: u32) -> RenderSettings {
        RenderSettings {
            samples_per_pixel: spp,
            ..self.baseline.clone()
        }
    }

    /// One rung per choice, each set up by `set` (on the world, and by the settings and name it
    /// returns) and its image compared with the first rung's, which `first` names in the notes;
    /// a rung's own note (samples dropped) is kept after the comparison.
    pub(super) fn compared_ladder<T>(
        &mut self,
        knob: Knob,
        choices: impl IntoIterator<Item = T>,
        first: &str,
        mut set: impl FnMut(&mut Self, T) -> (String, RenderSettings),
    ) -> Vec<Row> {
        let mut rows = Vec::new();
        let mut first_image = None;
        for choice in choices {
            let (name, settings) = set(self, choice);
            let (mut row, image) = self.measure(knob, name, settings);
            match &first_image {
                None => first_image = Some(image),
                Some(first_image) => {
                    let note = difference_note(&image, first_image, first);
                    row.note = if row.note.is_empty() {
                        note
                    } else {
                        format!("{note}; {}", row.note)
                    };
                }
            }
            rows.push(row);
        }
        rows
    }

    /// Renders with `settings` and measures the image against the reference; returns the image
    /// too, for ladders that compare rungs with each other.
    pub(super) fn measure(
        &mut self,
        knob: Knob,
        setting: String,
        settings: RenderSettings,
    ) -> (Row, RgbImage) {
        self.world.scene.settings = settings.clone();
        let timed = render_with(&self.world, self.pool, self.timing);
        let reference = self.reference.image();
        let metrics = Metrics::between(&timed.image, reference)
            .expect("every rung renders at the reference's size: both come from the same settings");
        let flip = mean_flip(&timed.image, reference);
        let note = if timed.invalid_samples > 0 {
            format!("{} non-finite samples dropped", timed.invalid_samples)
        } else {
            String::new()
        };
        println!(
            "  {:<9} {:<16} {:>9.4} s  RMSE {:.4e}  relMSE {:.4e}  FLIP {:.4}  mean {:+.2}%",
            knob.name(),
            setting,
            timed.seconds,
            metrics.rmse,
            metrics.rel_mse,
            flip,
            100.0 * metrics.mean_bias(),
        );
        self.world.scene.settings = self.baseline.clone();
        let row = Row {
            knob,
            setting,
            settings,
            bvh: BuildQuality::default(),
            traversal: self.world.traversal(),
            camera_rays: self.world.camera_rays,
            paths: self.world.paths,
            build_seconds: 0.0,
            render_seconds: timed.seconds,
            rays: timed.rays,
            work: timed.work,
            metrics,
            flip,
            note,
        };
        (row, timed.image)
    }
}

/// A traversal rung's name: the traversal's ("robust", "robustbinary", "obvhs"),
/// "robust-one-by-one" for ours with camera rays one by one (packets are used only by ours),
/// and "robust-paths-one-by-one" for ours with paths one by one rather than in lanes.
pub fn rung_name(traversal: Traversal, camera_rays: CameraRays, paths: PathLanes) -> String {
    let mut name = format!("{traversal:?}").to_lowercase();
    if camera_rays == CameraRays::OneByOne {
        name += "-one-by-one";
    }
    if paths == PathLanes::OneByOne {
        name += "-paths-one-by-one";
    }
    name
}

/// "identical to WHAT", or how much `image` differs from `other`.
pub(super) fn difference_note(image: &RgbImage, other: &RgbImage, what: &str) -> String {
    let bits = |i: &RgbImage| {
        i.pixels
            .iter()
            .flatten()
            .map(|c| c.to_bits())
            .collect::<Vec<_>>()
    };
    let (a, b) = (bits(image), bits(other));
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    if differing == 0 {
        return format!("bit-identical to {what}");
    }
    let largest = Metrics::between(image, other).map_or(f64::NAN, |m| m.max_difference.value);
    format!(
        "differs from {what} in {differing} of {} values (largest {largest:.3e})",
        a.len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_runs_are_repeated_and_the_fastest_kept() {
        let second = Timing {
            repeat_below: 1.0,
            repeats: 1,
        };
        assert_eq!(
            fastest_time(2.0, second, || unreachable!("a long run is timed once")),
            2.0
        );
        let runs = std::cell::Cell::new(0);
        let times = [0.3, 0.1, 0.2, 0.4, 0.05];
        let again = || {
            runs.set(runs.get() + 1);
            times[runs.get() - 1]
        };
        // 0.25 s fills a second in four runs: the first and three more.
        assert_eq!(fastest_time(0.25, second, again), 0.1);
        assert_eq!(runs.get(), 3);
        // Asked for three runs, a long one is run twice more.
        let thrice = Timing {
            repeat_below: 1.0,
            repeats: 3,
        };
        assert_eq!(fastest_time(2.0, thrice, again), 0.05);
        assert_eq!(runs.get(), 5);
    }
}
