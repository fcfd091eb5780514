//! The cluster simulator: a discrete-event cluster in virtual time that drives the runtime's
//! sans-IO scheduling core for every peer, so that a 2-core machine can say how balancing
//! scales to a thousand machines, with the very code the real peers run.
//!
//! Nothing here schedules a tile: the pump is `runtime_core::peer::testing::Cluster` (the same one
//! the core's own tests use), every peer is a `runtime_core::peer::Core`, and the frame owner is
//! the QUIC node's own `runtime_core::director::Director`. The simulator supplies what surrounds them:
//! tile costs from a trace, a network, peers of different speeds that may crash, and the
//! accounting behind every number it reports.
//!
//! Module map:
//! - [`trace`]: cost traces (every frame's counted work per block of pixels), their JSON Lines
//!   format, reader and writer; what `tessera render --trace` records.
//! - [`synthetic`]: traces made up for tests and experiments: a hot spot orbiting the image.
//! - [`knobs`]: the scenario's knobs that are more than a number (crashes, the owner's costs,
//!   the pieces peers render), with their command-line spellings.
//! - [`network`]: the network model: per-link latency with jitter, bandwidth, loss.
//! - [`scenario`]: one run: the scenario's knobs, and the frame owner's loop (partition,
//!   assign, start the frame, feed the measured costs back) in virtual time.
//! - `world`: the simulator's side of the pump: renderers costed from the trace, the
//!   network, and the per-frame tally behind a [`RunReport`].
//! - [`report`]: what a run yields ([`RunReport`], [`FrameReport`]), CSV and JSON output.
//! - [`sweep`]: many runs (peers x policies x tile counts), in parallel, and everything they
//!   write: tables, charts, summary.
//! - [`summary`]: the summary of a sweep in Markdown, organised by the seed's three claims.
//! - [`validate`]: the simulator against a real render: the run a `stats.json` describes,
//!   simulated on the render's own trace and compared frame by frame (`simulate --validate`).
//! - [`plot`]: SVG charts: efficiency against peers and against tiles, and (`plot::gantt`)
//!   the pictures of who rendered what when, shared with real renders (`tessera render
//!   --gantt`): one frame in full, and a whole run's utilisation.

pub mod knobs;
pub mod network;
pub mod plot;
pub mod report;
pub mod scenario;
pub mod summary;
pub mod sweep;
pub mod synthetic;
pub mod trace;
pub mod validate;
mod world;

pub use network::Network;
pub use report::{FrameReport, RunReport};
pub use scenario::{Crash, CrashWhen, OwnerCosts, Scenario};
pub use sweep::{Charts, GanttChoice, Policy, Sweep};
pub use trace::{FrameCosts, Trace, TraceWriter};

use std::path::PathBuf;

/// What can go wrong reading a trace, running a scenario or writing its results.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// A line of a trace file is malformed.
    #[error("{path}, line {line}: {message}")]
    Trace {
        /// The trace file.
        path: PathBuf,
        /// The line, counting from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// A trace whose contents do not fit together (no blocks, wrong block counts); the text says
    /// how.
    #[error("invalid trace: {0}")]
    BadTrace(String),
    /// A scenario with a value out of range; the text names it.
    #[error("invalid scenario: {0}")]
    Scenario(String),
    /// The balancer refused to cut or learn.
    #[error(transparent)]
    Balancer(#[from] balancer::Error),
    /// A core refused a frame the simulated owner started, a bug the run reports rather than hides.
    #[error("starting a frame: {0}")]
    Frame(#[from] runtime_core::peer::FrameError),
    /// The director refused a step, a bug the run reports rather than hides.
    #[error(transparent)]
    Director(#[from] runtime_core::director::DirectorError),
    /// The run ran out of things to happen with tiles still missing: the cores deadlocked.
    #[error("frame {frame} stalled at {at:?}: nothing left to happen, {missing} tiles missing")]
    Stalled {
        /// The frame that stalled.
        frame: u32,
        /// The virtual time it stalled at.
        at: std::time::Duration,
        /// Its tiles still missing.
        missing: usize,
    },
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
}

impl Error {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
