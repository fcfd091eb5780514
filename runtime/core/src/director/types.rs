//! The director's vocabulary: the knobs it is built with ([`Config`]) and what it hands its
//! driver (a [`Deal`] to start, the [`Piece`]s of a completed frame, an [`Event`], or a
//! [`DirectorError`]).
//!
//! One unit because these are plain data with no logic beyond defaults: the drivers build and
//! read them, and keeping them apart lets the state machine in `director.rs` read on its own.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::peer::Audit;
use crate::wire::{FrameId, PeerId, TileResult, TileSpec};

/// The director's policy knobs.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The frame count of the animation: frames are numbered from 0 to `frames - 1`.
    pub frames: u32,
    /// The first frame to deal. The frames before it are done already (a resumed render), so
    /// the director deals `first..frames`. Default 0. The balancer has then no costs of frame
    /// `first - 1` and cuts `first` as it would cut frame 0; pixels do not depend on tiles.
    pub first: u32,
    /// How long after the last frame completes the director waits for participants'
    /// statistics before it finishes without them. Default 1 s: statistics are sent the moment
    /// a peer learns the frame is done, so this only matters for a peer that is dying.
    pub stats_grace: Duration,
    /// Faulty results (a duplicate whose pixels differ, a wrong rectangle) tolerated per frame,
    /// besides two per tile. A renderer that keeps producing results the ledger refuses would
    /// have its tiles re-issued forever; past this the render stops with an error.
    pub fault_allowance: usize,
    /// Peers hand their renderers pieces of at most this many times the frame's mean tile
    /// area; larger tiles are rendered half by half, so that the unrendered part of a tile
    /// stays in a queue a thief can take from. The partition makes large tiles where it
    /// predicts cheap pixels, which is exactly where a misprediction leaves one peer with a
    /// long tile. `None` renders every tile whole.
    pub render_piece_factor: Option<f64>,
    /// Frames dealt and not yet measured, at most. 1 deals each frame once the last is
    /// measured (a barrier between frames); 2, the default, deals the next frame when the
    /// running one wanes. From 1 to [`wire::MAX_FRAMES_IN_FLIGHT`]. Frames overlap only while
    /// the prediction is trusted (see `doubt_error`): a frame dealt early is cut from costs one
    /// frame older, which pays only when costs move slowly.
    ///
    /// [`wire::MAX_FRAMES_IN_FLIGHT`]: crate::wire::MAX_FRAMES_IN_FLIGHT
    pub frames_in_flight: usize,
    /// The prediction is doubted before any frame is measured (tiles cut by area alone: the
    /// first frame, or a resumed render's first), and when the last measured frame's tiles
    /// missed their predicted costs by more than this share of the frame's cost (the sum over
    /// tiles of |predicted - measured|, over the sum measured; 0 is a perfect prediction, 2
    /// the worst). A frame dealt while the prediction is doubted is not overlapped with the
    /// next, and renders in pieces of `doubtful_piece_factor`. Default 0.5: above the error of a
    /// prediction two frames old where costs move slowly (the synthetic orbit's 0.34), below
    /// that of one whose costs move by more than their size each frame (the fast orbit's 0.78).
    pub doubt_error: f64,
    /// A frame dealt while the prediction is doubted renders in pieces of at most this many
    /// times its mean tile area (never below [`wire::MIN_PIECE_PIXELS`]), instead of
    /// `render_piece_factor`: nothing then bounds what one
    /// tile costs, and smaller pieces let thieves share out a costly region the prediction did
    /// not see. `None` uses `render_piece_factor`.
    ///
    /// [`wire::MIN_PIECE_PIXELS`]: crate::wire::MIN_PIECE_PIXELS
    pub doubtful_piece_factor: Option<f64>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            frames: 1,
            first: 0,
            stats_grace: Duration::from_secs(1),
            fault_allowance: 8,
            render_piece_factor: Some(2.0),
            frames_in_flight: 2,
            doubt_error: 0.5,
            doubtful_piece_factor: Some(0.125),
        }
    }
}

/// One frame as dealt: what the driver starts in the owner's core.
#[derive(Clone, Debug, PartialEq)]
pub struct Deal {
    /// The frame these tiles belong to.
    pub frame: FrameId,
    /// The partition's tiles, by tile id.
    pub tiles: Vec<balancer::Tile>,
    /// The participant each tile was dealt to, by tile id.
    pub initial: Vec<PeerId>,
    /// Each participant's initial tiles, for [`Core::start_frame`](crate::peer::Core::start_frame).
    pub assignments: BTreeMap<PeerId, Vec<TileSpec>>,
    /// The largest piece a participant renders at once (see [`Config::render_piece_factor`]).
    pub render_pixels: u64,
}

impl Deal {
    /// The participants dealt to, in id order.
    pub fn participants(&self) -> impl Iterator<Item = PeerId> + '_ {
        self.assignments.keys().copied()
    }
}

/// One finished tile of a completed frame. Why a type of its own: it is the result the owner
/// kept, still encoded, with who rendered it and what was predicted; the driver decodes and
/// measures it into a `stats::TileStats`.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    /// The accepted result, still as the wire carries it.
    pub result: TileResult,
    /// Who rendered it (sent the accepted result).
    pub peer: PeerId,
    /// Whose initial share it was in; differs from `peer` when it was stolen or re-issued.
    pub initial: PeerId,
    /// The cost the balancer predicted for it.
    pub predicted: f64,
}

/// What the director tells its driver.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Every tile of `frame` is in, `elapsed` after it was dealt; `pieces` cover the image once,
    /// in tile order (a tile that was cut on the way by its pieces, in tree order). The driver
    /// measures them and calls [`Director::handle_measured`].
    ///
    /// [`Director::handle_measured`]: super::Director::handle_measured
    FrameComplete {
        /// The frame that is complete.
        frame: FrameId,
        /// Time from the frame's deal to its last piece, on the driver's clock.
        elapsed: Duration,
        /// Every piece of the frame, in the order described above.
        pieces: Vec<Piece>,
        /// How the frame's duplicate results compared with the first.
        audit: Audit,
    },
    /// Every frame is measured and every participant's statistics are in (or it left, or
    /// [`Config::stats_grace`] ran out): the driver may say goodbye and close.
    Finished,
}

/// Why the director stopped the render.
#[derive(Debug, thiserror::Error)]
pub enum DirectorError {
    /// The balancer refused to cut or learn, e.g. a cost map of the wrong size.
    #[error(transparent)]
    Balancer(#[from] balancer::Error),
    /// Too many results of one frame failed their checks to go on trusting the cluster.
    #[error(
        "frame {frame}: {faults} faulty results; a peer keeps sending results that cannot be right"
    )]
    Faulty {
        /// The frame the faults arrived in.
        frame: FrameId,
        /// How many faulty results it had.
        faults: usize,
    },
    /// The driver measured a frame the director was not waiting on, a bug in the driver.
    #[error("{frame} was measured, but it is not the frame waiting for its measurement")]
    NotWaiting {
        /// The frame measured.
        frame: FrameId,
    },
    /// The driver started a frame's deal a second time, a bug in the driver.
    #[error("{frame} was dealt twice")]
    DealtTwice {
        /// The frame dealt twice.
        frame: FrameId,
    },
}
