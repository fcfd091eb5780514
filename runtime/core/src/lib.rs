//! Everything a tessera peer *decides*, with no I/O: no sockets, no clock, no threads, no async.
//!
//! As quinn-proto is to quinn: drivers feed inputs (`handle_*`, each with the current time) and
//! drain outputs (`poll_*`). Two drivers use it: the tokio + quinn node (`runtime::node`) and the
//! discrete-event simulator (`sim`), so that a thousand simulated peers run the very code a real
//! cluster runs. The dependency tree has no tokio, quinn, rustls or rayon.
//!
//! Module map:
//! - [`peer`]: one peer's scheduling core: queues, prefetch, stealing, frame completion
//!   (`peer/worker.rs`, its renderer's side in `peer/worker/render.rs`; `peer/steal.rs`) and the
//!   owner's ledger (`peer/ledger.rs`, its re-issue and speculation rules in
//!   `peer/ledger/recovery.rs`); protocol in `peer/README.md`. Plus [`peer::testing`], a
//!   virtual-time cluster of cores for tests and the simulator: the pump in `peer/testing.rs`,
//!   what surrounds it (the `World` trait and the tests' scripted world) in
//!   `peer/testing/world.rs`.
//! - [`director`]: the frame owner's per-frame logic: cut each frame with the balancer, deal the
//!   shares, start it in the owner's core, and turn its results into the next cost map (the
//!   state machine in `director.rs`; its config and outputs in `director/types.rs`).
//! - [`membership`]: admission of peers to a render (hello, scene, ready, leave) as a state
//!   machine, so join/leave races are scripted, not timed.
//! - [`wire`]: the messages peers exchange (`wire.rs`; the data they carry in `wire/types.rs`)
//!   and their pure, bounded postcard encoding (`wire/codec.rs`).
//! - [`rng`]: the one seeded generator every deciding part draws from.
//! - [`stats`]: what a render records (the `stats.json` schema, a frame's tiles and pieces,
//!   each peer's timeline), written by the QUIC node's renders and read back by the simulator.

pub mod director;
pub mod membership;
pub mod peer;
pub mod rng;
pub mod stats;
pub mod wire;
