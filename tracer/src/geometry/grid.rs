//! The 8-wide node's boxes on a grid of bytes: per axis, a corner shared by the node's children
//! and a step, and for each child's plane a byte, the number of steps
//! from the corner. A node's boxes take 48 bytes instead of 192, and the node two cache lines
//! instead of four.
//!
//! Why: on large meshes the traversal waits on memory, one node after another (on Sponza most of
//! its samples sit on node loads), and a node half the size brings in half the lines per visit
//! and lets twice as many stay in the caches. The price is a few instructions per node to turn
//! the bytes back into planes, and boxes up to a step larger than the child's, which may open a
//! few more nodes. Embree's compressed nodes and NVIDIA's CWBVH (Ylitie, Karras and Laine,
//! "Efficient incoherent ray traversal on GPUs through compressed wide BVHs", 2017) store boxes
//! the same way; what is ours is how exactness is kept.
//!
//! **Exactness.** A plane is decoded as `origin + q * step` in `f32` ([`decode`]): a
//! multiplication and an addition, each rounded to nearest, the same on every IEEE machine and
//! in every instruction set, and never falling as `q` grows. The build evaluates this very
//! expression and picks each byte by testing
//! it: a min plane's byte is the largest whose decoded plane is at or below the child's min
//! ([`below`]), a max plane's the smallest at or above the child's max ([`above`]). So the box the
//! traversal tests always holds the child's box, whatever the rounding, and the robust slab test
//! enters it whenever it would have entered the child's own: the traversal opens every node it
//! opened before (and maybe a few more), and since the closest hit is settled by `t` and then by
//! triangle index, never by order, every hit is the same bits.

/// The plane a byte stands for on the grid (`origin`, `step`) of one axis. The traversal's box
/// tests compute exactly this, lane by lane, in whatever instructions they use.
#[inline(always)]
pub(super) fn decode(origin: f32, step: f32, q: u8) -> f32 {
    origin + f32::from(q) * step
}

/// The grid for an axis on which a node's children span `[low, high]` (finite, `low <= high`):
/// the origin is `low`, and the step the smallest `f32` whose last byte, 255, decodes at or
/// above `high`, but never below the smallest normal `f32` (a subnormal step, or product, would
/// cost a microcode assist per operation on x86 and buy nothing).
pub(super) fn grid(low: f32, high: f32) -> (f32, f32) {
    debug_assert!(low.is_finite() && high.is_finite() && low <= high);
    // Positive floats are ordered as their bits are, and `decode(low, step, 255)` never falls
    // as the step grows, so the smallest step that reaches is found by bisecting the bits. The
    // largest finite step always reaches: `255 * f32::MAX` is infinite.
    let reaches = |bits: u32| decode(low, f32::from_bits(bits), u8::MAX) >= high;
    let (mut short, mut long) = (f32::MIN_POSITIVE.to_bits(), f32::MAX.to_bits());
    if reaches(short) {
        return (low, f32::MIN_POSITIVE);
    }
    while long - short > 1 {
        let mid = short + (long - short) / 2;
        if reaches(mid) {
            long = mid;
        } else {
            short = mid;
        }
    }
    (low, f32::from_bits(long))
}

/// The largest byte whose plane is at or below `value` (`value >= origin`): a min plane's.
pub(super) fn below(origin: f32, step: f32, value: f32) -> u8 {
    // `decode` never falls as the byte grows, and byte 0 decodes to `origin`: bisect.
    let (mut low, mut high) = (0u16, 256u16);
    while high - low > 1 {
        let mid = (low + high) / 2;
        if decode(origin, step, mid as u8) <= value {
            low = mid;
        } else {
            high = mid;
        }
    }
    debug_assert!(decode(origin, step, low as u8) <= value);
    low as u8
}

/// The smallest byte whose plane is at or above `value` (within the grid's reach): a max plane's.
pub(super) fn above(origin: f32, step: f32, value: f32) -> u8 {
    if decode(origin, step, 0) >= value {
        return 0;
    }
    // Byte `low` falls short, byte `high` reaches (255 always does, by the grid's choice).
    let (mut low, mut high) = (0u8, u8::MAX);
    while high - low > 1 {
        let mid = low + (high - low) / 2;
        if decode(origin, step, mid) >= value {
            high = mid;
        } else {
            low = mid;
        }
    }
    debug_assert!(decode(origin, step, high) >= value);
    high
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Planes at every scale a scene can have, near and far from the origin, on both sides of
    /// zero: for each, a node of children spread over its extent, and every child's box must
    /// hold on the grid, with a grid no coarser than needed.
    #[test]
    fn decoded_planes_hold_every_child_at_every_scale_and_distance() {
        let mut checked = 0;
        for scale_exponent in (-40..=38).step_by(2) {
            let scale = 10f64.powi(scale_exponent);
            for centre in [0.0, 1.0, -3.7e3, 1e6, -2.5e9, 3e20, -1e35] {
                let low = (centre - scale) as f32;
                let high = (centre + scale) as f32;
                if !(low.is_finite() && high.is_finite()) {
                    continue;
                }
                let (origin, step) = grid(low, high);
                assert!(
                    decode(origin, step, 255) >= high,
                    "{low} {high}: step {step}"
                );
                if step > f32::MIN_POSITIVE {
                    // The next smaller step would not have reached.
                    let smaller = f32::from_bits(step.to_bits() - 1);
                    assert!(decode(origin, smaller, 255) < high, "{low} {high}: {step}");
                }
                // Children: fractions of the span, including its ends and single points.
                for (a, b) in [
                    (0.0, 1.0),
                    (0.0, 0.0),
                    (1.0, 1.0),
                    (0.3, 0.31),
                    (0.999, 1.0),
                ] {
                    let at = |f: f64| {
                        let v = f64::from(low) + f * (f64::from(high) - f64::from(low));
                        (v as f32).clamp(low, high)
                    };
                    let (min, max) = (at(a), at(b));
                    let (q_min, q_max) = (below(origin, step, min), above(origin, step, max));
                    assert!(
                        decode(origin, step, q_min) <= min,
                        "{min} on {origin}+{step}"
                    );
                    assert!(
                        decode(origin, step, q_max) >= max,
                        "{max} on {origin}+{step}"
                    );
                    // Tight: one byte further in would cut the child.
                    if q_min < 255 {
                        assert!(decode(origin, step, q_min + 1) > min);
                    }
                    if q_max > 0 {
                        assert!(decode(origin, step, q_max - 1) < max);
                    }
                    checked += 1;
                }
            }
        }
        assert!(checked > 1000, "only {checked} children checked");
    }

    /// The extremes: spans across the whole finite range, flat spans, spans at the smallest
    /// normal and subnormal values, and planes at `-0.0`.
    #[test]
    fn extreme_spans_still_hold_their_children() {
        let cases = [
            (-f32::MAX, f32::MAX),
            (0.0, f32::MAX),
            (-f32::MAX, -f32::MAX),
            (-0.0, 0.0),
            (-0.0, -0.0),
            (0.0, f32::MIN_POSITIVE / 8.0),
            (-f32::MIN_POSITIVE, f32::MIN_POSITIVE),
            (1.0, 1.0 + f32::EPSILON),
            (16_777_216.0, 16_777_218.0),
        ];
        for (low, high) in cases {
            let (origin, step) = grid(low, high);
            assert!(step >= f32::MIN_POSITIVE, "{low} {high}: a subnormal step");
            for value in [low, high, low / 2.0 + high / 2.0] {
                assert!(decode(origin, step, below(origin, step, value)) <= value);
                assert!(decode(origin, step, above(origin, step, value)) >= value);
            }
        }
    }
}
