//! The cluster simulator: a discrete-event cluster in virtual time that drives the runtime's
//! sans-IO scheduling core for every peer. (The simulator itself is being written; this crate
//! holds the charts it shares with real renders.)
//!
//! Module map:
//! - [`plot`]: SVG charts (Gantt) shared by real and simulated runs.

pub mod plot;
