//! The one seeded generator of everything that decides or simulates: victim choice in the peer
//! cores, jitter and loss in the simulator's network. SplitMix64: tiny, fast, and good enough for
//! these choices; its whole state is one `u64`, so a run is a pure function of its seed and
//! inputs. (Pixel sampling is not drawn from here: the tracer's sampler is counter-based.)

/// SplitMix64 (Steele, Lea and Flood 2014).
#[derive(Clone, Debug)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The generator of participant `id` in a run seeded with `seed`. SplitMix's state only
    /// moves by a constant step, so states that differ by a small multiple of it give the same
    /// stream shifted: seeding peer `k` with `seed + k * step` (as the cores once did) had every
    /// thief draw the same victims one draw apart, and left some victims never asked. Starting
    /// from hashed states keeps the streams unrelated.
    pub fn stream(seed: u64, id: u64) -> Self {
        let salted = SplitMix(id ^ 0x5851_F42D_4C95_7F2D).next_u64();
        SplitMix(SplitMix(seed ^ salted).next_u64())
    }

    /// The next number of the stream, advancing it.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform index below `n` (which must not be 0), by multiply-shift.
    pub fn below(&mut self, n: usize) -> usize {
        ((u128::from(self.next_u64()) * n as u128) >> 64) as usize
    }

    /// Uniform in `[0, 1)`: the top 53 bits as a double.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Thieves of one cluster share a seed; their victim draws must not be one stream seen at
    /// different offsets, or some victims are never asked.
    #[test]
    fn peers_of_one_seed_draw_unrelated_victims() {
        let draws = |peer: u64| -> Vec<usize> {
            let mut rng = SplitMix::stream(7, peer);
            (0..64).map(|_| rng.below(1000)).collect()
        };
        let streams: Vec<Vec<usize>> = (0..32).map(draws).collect();
        for (a, first) in streams.iter().enumerate() {
            for second in &streams[a + 1..] {
                for shift in 0..8 {
                    let agree = first[shift..]
                        .iter()
                        .zip(second)
                        .filter(|(x, y)| x == y)
                        .count();
                    assert!(
                        agree <= 3,
                        "two peers' draws agree {agree} times at shift {shift}"
                    );
                }
            }
        }
        // Together, 32 thieves drawing 64 times each ask nearly every one of 1000 victims.
        let asked: std::collections::BTreeSet<usize> = streams.into_iter().flatten().collect();
        assert!(
            asked.len() > 850,
            "only {} of 1000 victims asked",
            asked.len()
        );
    }
}
