//! The peer. (Being written.)
//!
//! Module map:
//! - [`core`]: the sans-IO scheduling core: queues, prefetch, stealing, frame completion and
//!   the owner's ledger, driven by `handle_*(now, ..)` and drained by `poll_*`; plus
//!   `core::testing`, a virtual-time cluster of cores for tests and the simulator.
//! - [`wire`]: the messages peers exchange and their pure, bounded postcard encoding.
//! - [`net`]: the QUIC transport that moves encoded messages between peers.
//! - [`node`]: the driver: the owner and peer roles, the in-process cluster, rendering on rayon.

pub mod core;
pub mod net;
pub mod node;
pub mod wire;
