//! The tests' random stream: hard cases drawn the same way on every run.

use glam::{Mat3, Vec3};

/// splitmix64: a tiny, fixed, well-mixed stream, so that every run checks the same cases.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    pub fn index(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// Uniform on the unit sphere.
    pub fn direction(&mut self) -> Vec3 {
        let z = 1.0 - 2.0 * self.unit();
        let phi = std::f32::consts::TAU * self.unit();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Uniform on the hemisphere around the unit vector `n`, grazing directions included.
    pub fn hemisphere(&mut self, n: Vec3) -> Vec3 {
        let d = self.direction();
        if d.dot(n) < 0.0 { -d } else { d }
    }

    /// A random rotation: an orthonormal frame from two random directions.
    pub fn rotation(&mut self) -> Mat3 {
        let a = self.direction();
        let d = self.direction();
        let b = (d - a * a.dot(d)).normalize();
        Mat3::from_cols(a, b, a.cross(b))
    }

    /// Barycentrics (b1, b2): inside, on an edge, or at a vertex, each often.
    pub fn barycentrics(&mut self) -> (f32, f32) {
        let (r, s) = (self.unit().sqrt(), self.unit());
        match self.index(6) {
            0 => [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)][self.index(3)],
            1 => (self.unit(), 0.0),
            2 => (0.0, self.unit()),
            3 => {
                let b1 = self.unit();
                (b1, 1.0 - b1)
            }
            _ => (r * (1.0 - s), r * s),
        }
    }
}
