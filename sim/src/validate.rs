//! The simulator against a real render (`tessera simulate --validate STATS`): simulate the run a
//! `stats.json` describes (its peers, threads, balancer, deal, motion and tiles) on the
//! render's own cost trace, and compare frame by frame: frame times, simulated over measured,
//! and whether every peer started each frame with the same tiles.
//!
//! Here rather than in the command because it is the simulator's claim about itself: the rate
//! it assumes is measured from the render (counted work over busy slot time), and the tiles
//! must be cut exactly as the render cut them, so the render's own settings win over the flags.

use std::fmt::Write as _;

use balancer::{Kind, Order, Partitioner};
use runtime_core::stats::StatsFile;

use crate::{Error, Scenario, Trace, scenario};

/// What the flags of `simulate` say about a validation; `None` takes the render's.
#[derive(Clone, Copy, Debug, Default)]
pub struct Given {
    /// Whether peers steal (the policy's); the render's balancer is taken in any case.
    pub steal: bool,
    /// Counted work per second of a slot (default: measured from the render's statistics).
    pub rate: Option<f64>,
    /// Rendering slots per peer (default: the render's threads per peer).
    pub slots: Option<usize>,
    /// Frames to compare, at most (default: all the file holds).
    pub frames: Option<usize>,
}

/// One frame, measured and simulated.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameComparison {
    /// What the frame added to the real render's time, in seconds (`frame_intervals`).
    pub measured: f64,
    /// The frame's makespan in the simulation, in virtual seconds.
    pub simulated: f64,
    /// Tiles the frame was cut into.
    pub tiles: usize,
    /// Whether every tile was dealt to the same peer, cut the same way.
    pub same_initial_sets: bool,
}

/// The comparison, with the settings it was simulated with.
#[derive(Clone, Debug)]
pub struct Validation {
    /// Peers, the owner included, as in the render.
    pub peers: usize,
    /// Rendering slots per peer.
    pub slots: usize,
    /// The balancer, as the render named it.
    pub balancer: String,
    /// Whether peers stole.
    pub steal: bool,
    /// Tiles of the first frame, as in the render.
    pub tiles: usize,
    /// The render's motion search radius in blocks per frame; `None` for none.
    pub motion: Option<u32>,
    /// Counted work per second of a slot.
    pub rate: f64,
    /// The frames asked for: the file's, or fewer with [`Given::frames`].
    pub asked: usize,
    /// Each frame compared, in order.
    pub frames: Vec<FrameComparison>,
}

/// Simulates the render `stats` describes on `trace`, with `base`'s network and core settings.
pub fn validate(
    trace: &Trace,
    stats: &StatsFile,
    base: Scenario,
    given: Given,
) -> Result<Validation, Error> {
    let bad = |what: String| Error::Scenario(what);
    if stats.frames.is_empty() {
        return Err(bad("the statistics have no frames".into()));
    }
    // A resumed render began at a later frame, cut from a checkpoint's tiles: the simulator
    // replays from frame 0, so frame for frame it would compare different frames.
    if stats.first_frame > 0 {
        return Err(bad(format!(
            "the statistics are of a render resumed at frame {}: only a render from frame 0 \
             can be replayed",
            stats.first_frame
        )));
    }
    let kind: Kind = by_name(&stats.balancer)
        .ok_or_else(|| bad(format!("unknown balancer {:?}", stats.balancer)))?;
    let order: Order = match stats.deal.as_str() {
        "" => Order::Contiguous,
        name => by_name(name).ok_or_else(|| bad(format!("unknown deal {name:?}")))?,
    };
    // The render's own prediction, not the command's --motion: the tiles must be cut alike.
    let motion = match stats.motion.as_str() {
        "" | "off" => None,
        text => match text.parse::<u32>() {
            Ok(blocks) if blocks > 0 => Some(blocks),
            _ => {
                return Err(bad(format!(
                    "motion {text:?}: not a number of blocks, or off"
                )));
            }
        },
    };
    // Rate: counted work over busy slot time, over the frames every peer reported.
    let complete = || stats.frames.iter().filter(|f| f.peers.len() == stats.peers);
    let busy: f64 = complete()
        .flat_map(|f| f.peers.iter().map(|p| p.busy_seconds))
        .sum();
    let work: u64 = complete().map(|f| f.work).sum();
    let rate = match given.rate {
        Some(rate) => rate,
        None if busy > 0.0 => work as f64 / busy,
        None => {
            return Err(bad(
                "the statistics have no frame with every peer's: pass --rate".into(),
            ));
        }
    };
    let threads = stats
        .frames
        .iter()
        .flat_map(|f| f.peers.first())
        .map(|p| p.threads as usize)
        .next();
    let slots = given.slots.or(threads).unwrap_or(1);
    let frames = stats.frames.len().min(given.frames.unwrap_or(usize::MAX));
    let mut scenario = Scenario {
        slots,
        work_per_second: rate,
        peers: stats.peers,
        frames: Some(frames),
        keep_assignments: true,
        ..base
    };
    // As the real runtime does: only stealing follows the flag, backups stay on.
    scenario.core.steal = given.steal;
    let tiles = stats.frames[0].tiles.len();
    let config = balancer::Config::with_tiles(kind, tiles, order, motion);
    let partitioner = Partitioner::new(trace.width(), trace.height(), &config)?;
    let run = scenario::run(trace, partitioner, &scenario)?;
    let measured = frame_intervals(&stats.frames);
    let compared = stats
        .frames
        .iter()
        .zip(&run.frames)
        .zip(measured)
        .enumerate()
        .take(frames)
        .map(|(index, ((real, simulated), measured))| {
            let mut real_sets: Vec<_> = real.tiles.iter().collect();
            real_sets.sort_by_key(|t| t.tile);
            let dealt = &run.assignments[index];
            let same = real_sets.len() == dealt.len()
                && real_sets
                    .iter()
                    .zip(dealt)
                    .all(|(t, (rect, peer))| t.rect == *rect && t.initial_peer == *peer);
            FrameComparison {
                measured,
                simulated: simulated.makespan,
                tiles: real.tiles.len(),
                same_initial_sets: same,
            }
        })
        .collect();
    Ok(Validation {
        peers: stats.peers,
        slots,
        balancer: stats.balancer.clone(),
        steal: given.steal,
        tiles,
        motion,
        rate,
        asked: frames,
        frames: compared,
    })
}

/// What each frame added to the render's time, as the simulator's makespan counts it: from
/// the later of the frame before's completion and its own first tile out, to its completion.
/// Frames overlap (the next is dealt while one wanes), so a frame's own span, first tile out to
/// last result in, counts the overlap twice: compared with it, the replays read 0.54 to 0.68
/// (docs/results.md, "Validation"). The first frame starts at its first tile, not at the
/// render's start, which includes peers joining. Files written before `completed_at` have only
/// the spans, which were the intervals while frames did not overlap.
fn frame_intervals(frames: &[runtime_core::stats::FrameStats]) -> Vec<f64> {
    if frames.iter().any(|f| f.completed_at <= 0.0) {
        return frames.iter().map(|f| f.seconds).collect();
    }
    let mut before = 0.0f64;
    frames
        .iter()
        .map(|f| {
            let start = before.max(f.completed_at - f.seconds);
            before = f.completed_at;
            f.completed_at - start
        })
        .collect()
}

/// A balancer's or deal's value by the name its files and flags use.
fn by_name<T: serde::de::DeserializeOwned>(name: &str) -> Option<T> {
    serde_json::from_value(serde_json::Value::String(name.to_owned())).ok()
}

impl Validation {
    /// What was simulated, and a table of the frames, as the command prints them.
    pub fn table(&self) -> String {
        let motion = self.motion.map_or("off".to_string(), |m| m.to_string());
        let mut text = format!(
            "simulating {} peers x {} slots, {} with{} stealing, {} tiles, motion {motion}, at {:.4e} work/s per slot\n",
            self.peers,
            self.slots,
            self.balancer,
            if self.steal { "" } else { "out" },
            self.tiles,
            self.rate
        );
        let _ = writeln!(
            text,
            "{:>6} {:>11} {:>12} {:>8} {:>13}",
            "frame", "measured s", "simulated s", "ratio", "same sets"
        );
        for (index, f) in self.frames.iter().enumerate() {
            let _ = writeln!(
                text,
                "{index:>6} {:>11.4} {:>12.4} {:>8.3} {:>13}",
                f.measured,
                f.simulated,
                f.simulated / f.measured,
                f.same_initial_sets
            );
        }
        text
    }

    /// `validation.csv`: a row per frame.
    pub fn csv(&self) -> String {
        let mut csv = String::from("frame,measured_s,simulated_s,ratio,tiles,same_initial_sets\n");
        for (index, f) in self.frames.iter().enumerate() {
            let _ = writeln!(
                csv,
                "{index},{},{},{},{},{}",
                f.measured,
                f.simulated,
                f.simulated / f.measured,
                f.tiles,
                f.same_initial_sets
            );
        }
        csv
    }

    /// The totals: measured and simulated time, their ratio, and the frames dealt alike.
    pub fn totals(&self) -> String {
        let measured: f64 = self.frames.iter().map(|f| f.measured).sum();
        let simulated: f64 = self.frames.iter().map(|f| f.simulated).sum();
        let agree = self.frames.iter().filter(|f| f.same_initial_sets).count();
        format!(
            "total: measured {measured:.3} s, simulated {simulated:.3} s, ratio {:.3}; initial tile sets identical in {agree} of {} frames",
            simulated / measured,
            self.asked
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::HotSpot;
    use runtime_core::stats::{FrameStats, PeerFrameStats, TileStats};

    /// A render's statistics as the node writes them: `peers` peers of `threads` threads, every
    /// frame cut into `tiles` tiles, `busy` slot-seconds each for `work` counted work a frame.
    fn stats(balancer: &str, deal: &str, motion: &str) -> StatsFile {
        let peers = 2;
        let frame = |frame| FrameStats {
            frame,
            seconds: 0.5,
            work: 3_000,
            tiles: (0..16)
                .map(|t| TileStats {
                    tile: t,
                    ..TileStats::default()
                })
                .collect(),
            peers: (0..peers)
                .map(|peer| PeerFrameStats {
                    peer,
                    threads: 3,
                    busy_seconds: 1.5,
                    ..PeerFrameStats::default()
                })
                .collect(),
            ..FrameStats::default()
        };
        StatsFile {
            balancer: balancer.into(),
            deal: deal.into(),
            motion: motion.into(),
            peers: peers as usize,
            frames: vec![frame(0), frame(1)],
            ..StatsFile::default()
        }
    }

    /// Frames overlap: each is measured from the completion of the one before (or its own
    /// first tile, if later), as the simulator's makespan is, not by its own span; files
    /// without completion times keep the spans.
    #[test]
    fn frames_are_measured_by_what_they_added_to_the_render() {
        let mut file = stats("pbt", "", "off");
        // Frame 0 (a span of 0.5 s) completes 2 s into the render, after the peers joined;
        // frame 1 (0.5 s too) overlaps it by 0.2 s.
        file.frames[0].completed_at = 2.0;
        file.frames[1].completed_at = 2.3;
        assert_eq!(frame_intervals(&file.frames), [0.5, 2.3 - 2.0]);
        // A gap before the next frame's first tile is not the frame's.
        file.frames[1].completed_at = 3.0;
        assert_eq!(frame_intervals(&file.frames), [0.5, 0.5]);
        file.frames[1].completed_at = 0.0;
        assert_eq!(frame_intervals(&file.frames), [0.5, 0.5]);
    }

    /// The render's settings win over the flags': its rate (work over busy slot time), its
    /// threads, its tile count and its motion; what it names wrongly is refused by name.
    #[test]
    fn the_render_is_simulated_with_its_own_settings() {
        let trace = HotSpot::parse("synthetic:32x32:2")
            .unwrap()
            .trace()
            .unwrap();
        let given = Given {
            steal: true,
            ..Given::default()
        };
        let v = validate(&trace, &stats("pbt", "", "off"), Scenario::default(), given).unwrap();
        // 2 frames x 3,000 work over 2 frames x 2 peers x 1.5 s.
        assert_eq!((v.rate, v.slots, v.tiles, v.motion), (1_000.0, 3, 16, None));
        assert_eq!((v.asked, v.frames.len()), (2, 2));
        assert!(
            v.frames
                .iter()
                .all(|f| f.measured == 0.5 && f.simulated > 0.0)
        );
        // The tiles written above are empty rectangles: no frame was dealt alike.
        assert!(v.frames.iter().all(|f| !f.same_initial_sets));
        assert!(
            v.totals().ends_with("identical in 0 of 2 frames"),
            "{}",
            v.totals()
        );
        assert_eq!(v.csv().lines().count(), 3);

        let one = Given {
            frames: Some(1),
            slots: Some(1),
            rate: Some(5.0),
            ..given
        };
        let v = validate(
            &trace,
            &stats("regular", "round-robin", "4"),
            Scenario::default(),
            one,
        );
        let v = v.unwrap();
        assert_eq!(
            (v.rate, v.slots, v.motion, v.frames.len()),
            (5.0, 1, Some(4), 1)
        );

        let mut resumed = stats("pbt", "", "off");
        resumed.first_frame = 3;
        let error = validate(&trace, &resumed, Scenario::default(), given).unwrap_err();
        assert!(error.to_string().contains("resumed at frame 3"), "{error}");

        for (balancer, deal, motion, named) in [
            ("fastest", "", "off", "fastest"),
            ("pbt", "sideways", "off", "sideways"),
            ("pbt", "", "-3", "-3"),
        ] {
            let error = validate(
                &trace,
                &stats(balancer, deal, motion),
                Scenario::default(),
                given,
            )
            .unwrap_err()
            .to_string();
            assert!(error.contains(named), "{error}");
        }
    }
}
