//! A closest-hit answer in two registers, for the one call that crosses from the renderer into
//! the wide traversal on every ray.

use super::Hit;

/// An `Option<Hit>` as two integers, which x86-64 returns in two registers (`rax`, `rdx`).
///
/// Why: returned as itself, an `Option<Hit>` (20 bytes) goes through memory, written field by
/// field by the traversal and read back whole by its caller, and a read spanning several
/// smaller writes cannot be forwarded from the store buffer: it waits until they reach the
/// cache, once per ray, on the path from one bounce to the next. Packing moves the same bits;
/// nothing is computed differently.
#[derive(Clone, Copy)]
pub(super) struct PackedHit {
    /// `t`'s bits, then the triangle index above them; the index [`PackedHit::NONE_INDEX`] for
    /// no hit.
    t_and_triangle: u64,
    /// `b1`'s bits, then `b2`'s above them.
    barycentrics: u64,
}

impl PackedHit {
    /// The triangle index that says "no hit": no scene holds 2^32 - 1 triangles (they would
    /// take over 100 GiB), so no hit carries it.
    const NONE_INDEX: u32 = u32::MAX;

    #[inline(always)]
    pub(super) fn pack(hit: Option<Hit>) -> PackedHit {
        let (t, triangle, b1, b2) = match hit {
            Some(h) => (h.t, h.triangle, h.b1, h.b2),
            None => (0.0, Self::NONE_INDEX, 0.0, 0.0),
        };
        PackedHit {
            t_and_triangle: u64::from(t.to_bits()) | u64::from(triangle) << 32,
            barycentrics: u64::from(b1.to_bits()) | u64::from(b2.to_bits()) << 32,
        }
    }

    #[inline(always)]
    pub(super) fn unpack(self) -> Option<Hit> {
        let triangle = (self.t_and_triangle >> 32) as u32;
        (triangle != Self::NONE_INDEX).then(|| Hit {
            t: f32::from_bits(self.t_and_triangle as u32),
            triangle,
            b1: f32::from_bits(self.barycentrics as u32),
            b2: f32::from_bits((self.barycentrics >> 32) as u32),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_hit_and_no_hit_come_back_bit_for_bit() {
        let floats = [
            0.0f32,
            -0.0,
            f32::MIN_POSITIVE,
            1e-45,
            0.5,
            1.0,
            3.4e38,
            f32::INFINITY,
            -1e-7,
            f32::from_bits(0x7fc0_0001),
        ];
        for &t in &floats {
            for triangle in [0u32, 1, 65_535, 1 << 31, u32::MAX - 1] {
                for &b1 in &floats {
                    for &b2 in &floats {
                        let hit = Hit {
                            t,
                            triangle,
                            b1,
                            b2,
                        };
                        let back = PackedHit::pack(Some(hit))
                            .unpack()
                            .expect("a hit stays a hit");
                        assert_eq!(
                            [
                                back.t.to_bits(),
                                back.triangle,
                                back.b1.to_bits(),
                                back.b2.to_bits()
                            ],
                            [t.to_bits(), triangle, b1.to_bits(), b2.to_bits()]
                        );
                    }
                }
            }
        }
        assert!(PackedHit::pack(None).unpack().is_none());
    }
}
