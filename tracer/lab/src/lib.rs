//! Measurements of the tracer, as a library: what `tessera compare`, `tessera accuracy` and
//! `tessera bench` compute, callable from tests and examples without the command line (and
//! without the two QUIC peers a render starts).
//!
//! Module map:
//! - [`compare`]: the error metrics of one linear image against a reference (RMSE, relative MSE,
//!   mean absolute error, the largest difference, mean FLIP), and of two OpenEXR files.
//! - [`accuracy`]: what accuracy costs in time: one scene over a ladder of values per accuracy
//!   knob, each rung measured against a reference, written as a table, a report and a plot.
//! - [`bench`](mod@bench): rays per second of the tracer alone on real scenes, and the steal
//!   round trip between two peers on loopback.
//! - [`meshes`]: a scene's still triangles as the loader made them, as PLY files with an index
//!   of their materials, so that another renderer (Mitsuba 3, in the comparison scripts) traces
//!   exactly what tessera traces.
//!
//! Every whole-frame render here goes through [`tracer::render_frame`]; errors are [`LabError`],
//! whose message and causes are what a user reads.

pub mod accuracy;
pub mod bench;
pub mod compare;
pub mod meshes;

use std::path::PathBuf;

/// Why a measurement stopped.
#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// A file or folder could not be read, written or created; `what` says which.
    #[error("cannot {what} {}", path.display())]
    Io {
        /// What was being done: read, write, create.
        what: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A scene did not load.
    #[error(transparent)]
    Scene(#[from] tracer::SceneError),
    /// An image could not be read or written.
    #[error(transparent)]
    Output(#[from] tracer::output::OutputError),
    /// The rendering thread pool could not start.
    #[error(transparent)]
    Pool(#[from] rayon::ThreadPoolBuildError),
    /// A report could not be serialised or a sidecar parsed.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The input is not what the measurement needs (sizes, channel sets, argument values).
    #[error("{0}")]
    Invalid(String),
    /// A plotting back end failed.
    #[error("cannot draw {}: {message}", path.display())]
    Plot {
        /// The plot being drawn.
        path: PathBuf,
        /// What the back end said.
        message: String,
    },
    /// The steal round trip's transport failed.
    #[error("{0}")]
    Net(String),
    /// A failure, with what was being done when it happened.
    #[error("{context}")]
    Context {
        /// What was being done.
        context: String,
        /// What went wrong.
        #[source]
        source: Box<LabError>,
    },
}

impl LabError {
    /// This error, as the cause of a failure at `context` (a sentence saying what was being done).
    pub fn context(self, context: impl Into<String>) -> Self {
        LabError::Context {
            context: context.into(),
            source: Box::new(self),
        }
    }

    /// An [`Io`](LabError::Io) error maker for `map_err`.
    pub fn io(what: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| LabError::Io { what, path, source }
    }
}

/// `Ok` when `holds`, else the [`Invalid`](LabError::Invalid) error `message`.
pub(crate) fn ensure(holds: bool, message: &str) -> Result<(), LabError> {
    if holds {
        Ok(())
    } else {
        Err(LabError::Invalid(message.to_owned()))
    }
}

/// A rayon pool of `threads` threads (`None`: one per core), and its size.
pub(crate) fn pool(threads: Option<usize>) -> Result<(usize, rayon::ThreadPool), LabError> {
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    Ok((threads, pool))
}
