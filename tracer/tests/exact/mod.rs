//! Exact geometric predicates for tests: Shewchuk's adaptive `orient3d` (the `robust` crate)
//! on f32 coordinates widened to f64, which is exact (see `offsets.rs` for why this predicate).

use glam::Vec3;
use robust::{Coord3D, orient3d};

/// The exact side of `q` relative to the plane of `v`: positive on the side its winding normal
/// `(v1 - v0) x (v2 - v0)` points to, negative on the other, zero on the plane.
pub fn side(v: &[Vec3; 3], q: Vec3) -> f64 {
    let c = |p: Vec3| Coord3D {
        x: f64::from(p.x),
        y: f64::from(p.y),
        z: f64::from(p.z),
    };
    // Shewchuk's orient3d is positive when q lies below the plane, "above" being the side
    // from which v0, v1, v2 appear counterclockwise, which is where the winding normal points.
    -orient3d(c(v[0]), c(v[1]), c(v[2]), c(q))
}

/// Whether every triangle faces `c` (`inward`) or away from it, exactly: for a mesh built
/// radially around `c`, as the loader's spheres are, that means no facet has folded over.
#[allow(dead_code)]
pub fn faces_centre(v: &[[Vec3; 3]], c: Vec3, inward: bool) -> bool {
    v.iter().all(|t| {
        if inward {
            side(t, c) > 0.0
        } else {
            side(t, c) < 0.0
        }
    })
}
