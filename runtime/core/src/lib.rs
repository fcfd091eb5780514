//! Everything a tessera peer *decides*, with no I/O: no sockets, no clock, no threads, no async.
//!
//! As quinn-proto is to quinn: drivers feed inputs (`handle_*`, each with the current time) and
//! drain outputs (`poll_*`). Two drivers use it: the tokio + quinn node (`runtime::node`) and the
//! discrete-event simulator (`sim`), so that a thousand simulated peers run the very code a real
//! cluster runs. The dependency tree has no tokio, quinn, rustls or rayon.
//!
//! Module map:
//! - [`peer`]: one peer's scheduling core: queues, prefetch, stealing, frame completion and the
//!   owner's ledger (protocol in `peer/README.md`); plus [`peer::testing`], a virtual-time
//!   cluster of cores for tests and the simulator.
//! - [`director`]: the frame owner's per-frame logic: cut each frame with the balancer, deal the
//!   shares, start it in the owner's core, and turn its results into the next cost map.
//! - [`membership`]: admission of peers to a render (hello, scene, ready, leave) as a state
//!   machine, so join/leave races are scripted, not timed.
//! - [`wire`]: the messages peers exchange and their pure, bounded postcard encoding.
//! - [`rng`]: the one seeded generator every deciding part draws from.
//! - [`stats`]: what a render records (the `stats.json` schema, a frame's tiles and pieces,
//!   each peer's timeline), written by the QUIC node's renders and read back by the simulator.

pub mod director;
pub mod membership;
pub mod peer;
pub mod rng;
pub mod stats;
pub mod wire;
