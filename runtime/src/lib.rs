//! The QUIC side of a peer: what moves bytes and timers. Everything that decides lives in
//! [`runtime_core`] (the scheduling core, the owner's director, membership, the wire format);
//! this crate drives it with tokio and quinn and renders on rayon.
//!
//! Module map:
//! - [`frames`]: the owner's output folder: each finished frame's files, written in order off
//!   the owner's loop, and which frames an earlier render left done (`--resume`).
//! - [`net`]: the QUIC transport that moves encoded messages between peers (mutual TLS,
//!   certificates).
//! - [`node`]: the driver: the owner and peer roles, the in-process cluster, rendering on rayon.
//! - [`slurm`]: a SLURM task's place in its step (rank, owner host, port) from its environment,
//!   with SLURM's compressed host lists expanded; pure, no I/O.

pub mod frames;
pub mod net;
pub mod node;
pub mod slurm;
