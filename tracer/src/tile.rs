//! The unit of work: render a rectangle of one frame.
