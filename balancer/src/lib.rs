//! The Prediction Binary Tree and its baselines: measured costs in, tiles out. Pure: std and serde
//! only, never a clock, never I/O.

mod rect;
pub use rect::Rect;
