//! The peer. (Being written.)
