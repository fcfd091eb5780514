//! The knobs of a [`Scenario`](crate::Scenario) that are more than a number: which peers crash
//! and when, what the frame owner's control loop costs, and the bound on the pieces peers
//! render. Each type comes with its spelling on the command line (`tessera simulate --crash`,
//! `--render-pieces`), parsed here beside the type it makes, so that the binary only names the
//! flag and a test of the spelling needs no process.

use std::str::FromStr;
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// A spelling of a knob that does not parse; the text shows the value as given and what a
/// valid one looks like (the caller adds the flag's name).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KnobError {
    /// Not `PEER@SECONDS` or `PEER@tile:N`.
    #[error("{0:?}: expected PEER@SECONDS (e.g. 3@0.5) or PEER@tile:N (e.g. 3@tile:40)")]
    Crash(String),
    /// Not a positive multiple of the mean tile area, or `off`.
    #[error("{0:?}: give a positive multiple of the mean tile area, or off")]
    PieceFactor(String),
}

/// What the frame owner's control loop spends on each tile, one thing at a time, besides
/// rendering: every result received waits for it to finish the ones before, so a large cluster
/// converging on one owner can find it the bottleneck. The owner's rendering slots are not
/// slowed by it (the control loop has a core of its own on a real machine).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OwnerCosts {
    /// Per tile result received: the wire decoder, the ledger's bookkeeping, decoding its pixels
    /// and costs, copying them into the frame.
    pub per_result: Duration,
    /// Per pixel of each result received, on top of `per_result`.
    pub per_result_pixel_ns: f64,
    /// Per tile dealt to a remote peer: the director's cut and deal, the core's start of the
    /// frame, encoding its part of an `Assign`; paid before the `Assign` leaves.
    pub per_dealt_tile: Duration,
}

impl OwnerCosts {
    /// Free: the owner of an idealised cluster.
    pub const NONE: Self = Self {
        per_result: Duration::ZERO,
        per_result_pixel_ns: 0.0,
        per_dealt_tile: Duration::ZERO,
    };

    /// Measured on the development machine (2 AMD EPYC cores, shared) with the real code,
    /// `cargo run --release -p runtime --example owner_costs`: the least-squares line through
    /// the fastest of five runs for tiles of 8 to 128 pixels a side (1024x1024 image, 8 peers),
    /// and per dealt tile the fastest of five runs at 256 to 4096 tiles. See `docs/results.md`.
    pub const MEASURED: Self = Self {
        per_result: Duration::from_nanos(OWNER_PER_RESULT_NS),
        per_result_pixel_ns: OWNER_PER_PIXEL_NS,
        per_dealt_tile: Duration::from_nanos(OWNER_PER_DEALT_NS),
    };

    /// The owner's time for one result of `pixels` pixels.
    pub fn result(&self, pixels: u64) -> Duration {
        self.per_result
            + Duration::from_nanos((pixels as f64 * self.per_result_pixel_ns).ceil() as u64)
    }
}

// 2026-12-01, load average about 3: results of 8x8 to 128x128 pixels took 1.51, 3.18, 7.27,
// 23.69 and 99.88 us (fit: 0.83 us + 6.02 ns per pixel); a dealt tile 0.35 to 0.38 us.
const OWNER_PER_RESULT_NS: u64 = 830;
const OWNER_PER_PIXEL_NS: f64 = 6.02;
const OWNER_PER_DEALT_NS: u64 = 380;

/// A peer that stops dead `when` it is told to. Its connections time out
/// `Network::loss_detection` later.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Crash {
    /// The peer that crashes (never 0, the owner).
    pub peer: u32,
    /// When it crashes.
    pub when: CrashWhen,
}

/// The moment a peer crashes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum CrashWhen {
    /// At this virtual time since the run began, after everything else due at that instant.
    At(Duration),
    /// As it starts its `n`-th tile of the run (counting from 1), which it never finishes: a
    /// moment when it holds work in flight, whatever the timing of the run.
    Starting(u64),
}

impl Crash {
    /// Peer `peer` crashes at virtual time `at`.
    pub fn at(peer: u32, at: Duration) -> Self {
        Self {
            peer,
            when: CrashWhen::At(at),
        }
    }

    /// Peer `peer` crashes as it starts its `tile`-th tile of the run (counting from 1).
    pub fn starting(peer: u32, tile: u64) -> Self {
        Self {
            peer,
            when: CrashWhen::Starting(tile),
        }
    }
}

impl FromStr for Crash {
    type Err = KnobError;

    /// `PEER@SECONDS` (virtual time since the run began, finite and not negative) or
    /// `PEER@tile:N` (as the peer starts its N-th tile, N >= 1). Whether the peer exists, and
    /// is not the owner, is the scenario's to check: the peer count is not known here.
    fn from_str(spec: &str) -> Result<Self, KnobError> {
        let bad = || KnobError::Crash(spec.to_owned());
        let (peer, when) = spec.split_once('@').ok_or_else(bad)?;
        let peer = peer.parse().map_err(|_| bad())?;
        if let Some(tile) = when.strip_prefix("tile:") {
            return match tile.parse::<u64>() {
                Ok(tile) if tile > 0 => Ok(Crash::starting(peer, tile)),
                _ => Err(bad()),
            };
        }
        match when.parse::<f64>() {
            // Up to a million seconds, as the network's times (`tessera simulate`).
            Ok(at) if (0.0..=1e6).contains(&at) => Ok(Crash::at(peer, Duration::from_secs_f64(at))),
            _ => Err(bad()),
        }
    }
}

/// The director's bound on the pieces a peer renders at once, as a multiple of the frame's
/// mean tile area, or `None` to render tiles whole (`Scenario::render_piece_factor`). Spelled
/// as the factor, or `off`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PieceFactor(pub Option<f64>);

impl FromStr for PieceFactor {
    type Err = KnobError;

    fn from_str(text: &str) -> Result<Self, KnobError> {
        if text == "off" {
            return Ok(PieceFactor(None));
        }
        match text.parse::<f64>() {
            Ok(factor) if factor > 0.0 && factor.is_finite() => Ok(PieceFactor(Some(factor))),
            _ => Err(KnobError::PieceFactor(text.to_owned())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crashes_parse_at_a_time_or_on_starting_a_tile() {
        let crash = |spec: &str| spec.parse::<Crash>();
        assert_eq!(crash("3@0.5"), Ok(Crash::at(3, Duration::from_millis(500))));
        assert_eq!(crash("2@0"), Ok(Crash::at(2, Duration::ZERO)));
        assert_eq!(crash("3@tile:40"), Ok(Crash::starting(3, 40)));
        for bad in [
            "3",
            "@1",
            "x@1",
            "-1@1",
            "3@",
            "3@-1",
            "3@inf",
            "3@nan",
            "3@tile:0",
            "3@tile:x",
            "3@tile:-2",
        ] {
            assert_eq!(crash(bad), Err(KnobError::Crash(bad.to_owned())), "{bad}");
        }
        assert_eq!(
            crash("3").unwrap_err().to_string(),
            "\"3\": expected PEER@SECONDS (e.g. 3@0.5) or PEER@tile:N (e.g. 3@tile:40)"
        );
    }

    #[test]
    fn piece_factors_are_positive_or_off() {
        let factor = |text: &str| text.parse::<PieceFactor>();
        assert_eq!(factor("off"), Ok(PieceFactor(None)));
        assert_eq!(factor("2"), Ok(PieceFactor(Some(2.0))));
        assert_eq!(factor("0.125"), Ok(PieceFactor(Some(0.125))));
        for bad in ["0", "-1", "inf", "NaN", "", "Off"] {
            assert_eq!(
                factor(bad),
                Err(KnobError::PieceFactor(bad.to_owned())),
                "{bad}"
            );
        }
    }
}
