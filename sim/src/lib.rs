//! The cluster simulator. (Being written.)
