//! The peer. (Being written.)

pub mod net;
