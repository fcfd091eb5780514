//! The local shading frame: an orthonormal basis whose third axis is the shading normal.
//!
//! Every BSDF is written in this frame, where the normal is +z and `cos theta` is just the z
//! component; the integrator converts directions in and out once per bounce. The basis is built
//! with the branchless construction of Duff et al. 2017 ("Building an Orthonormal Basis,
//! Revisited", JCGT 6(1)), which stays orthonormal to rounding for every unit normal, including
//! the ones near -z where Frisvad's original method breaks down.

use glam::Vec3;

/// An orthonormal basis `(s, t, n)`, right-handed (`s x t = n`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// First tangent: the local x axis.
    pub s: Vec3,
    /// Second tangent: the local y axis.
    pub t: Vec3,
    /// The normal: the local z axis.
    pub n: Vec3,
}

impl Frame {
    /// The frame around the unit normal `n`. The tangents are a fixed function of `n`, so a
    /// frame rebuilt on another peer from the same normal is bit-identical.
    #[inline(always)]
    pub fn from_normal(n: Vec3) -> Self {
        // Duff et al. 2017, listing 3. `signum` is -1 for -0.0, so `sign + n.z` never cancels:
        // its magnitude is at least 1 for every unit normal.
        let sign = n.z.signum();
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }

    /// World direction to local coordinates (normal = +z).
    #[inline(always)]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local direction to world coordinates.
    #[inline(always)]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit normals that stress the construction: the poles (both signs of zero), the equator,
    /// the neighbourhood of -z where the division is closest to cancelling, and a spread of others.
    fn normals() -> Vec<Vec3> {
        let mut out = vec![
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(1.0, 0.0, -0.0),
            Vec3::new(-0.0, 0.0, -1.0),
            Vec3::X,
            -Vec3::Y,
            Vec3::new(1e-4, -2e-4, -1.0).normalize(),
            Vec3::new(-3e-7, 1e-7, -1.0).normalize(),
            Vec3::new(1.0, 1.0, 1e-6).normalize(),
        ];
        for i in 0..200 {
            // A golden-angle spiral over the whole sphere.
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / 200.0;
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            out.push(Vec3::new(r * phi.cos(), r * phi.sin(), z));
        }
        out
    }

    #[test]
    fn basis_is_orthonormal_and_right_handed() {
        for n in normals() {
            let f = Frame::from_normal(n);
            let tol = 4.0 * f32::EPSILON;
            for (name, v) in [("s", f.s), ("t", f.t)] {
                assert!(
                    (v.length() - 1.0).abs() < tol,
                    "|{name}| = {} for n = {n}",
                    v.length()
                );
                assert!(
                    v.dot(f.n).abs() < tol,
                    "{name}.n = {} for n = {n}",
                    v.dot(f.n)
                );
            }
            assert!(
                f.s.dot(f.t).abs() < tol,
                "s.t = {} for n = {n}",
                f.s.dot(f.t)
            );
            let handed = f.s.cross(f.t).dot(f.n);
            assert!(
                (handed - 1.0).abs() < tol,
                "(s x t).n = {handed} for n = {n}"
            );
        }
    }

    #[test]
    fn local_and_world_are_inverse_and_normal_maps_to_z() {
        for n in normals() {
            let f = Frame::from_normal(n);
            let z = f.to_local(n);
            assert!(
                (z - Vec3::Z).length() < 1e-6,
                "to_local(n) = {z} for n = {n}"
            );
            let v = Vec3::new(0.3, -0.8, 0.52).normalize();
            let back = f.to_local(f.to_world(v));
            assert!(
                (back - v).length() < 1e-6,
                "round trip gave {back} for n = {n}"
            );
            let w = f.to_world(v);
            assert!(
                (w.dot(n) - v.z).abs() < 1e-6,
                "cos theta not preserved for n = {n}"
            );
        }
    }
}
