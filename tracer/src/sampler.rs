//! The deterministic random stream of one pixel sample.
//!
//! Every random number is a pure function of (seed, frame, pixel, sample index, dimension): a
//! counter-based generator, not a stateful one, so no tile boundary, thread count or peer can
//! change a bit. The integrator gives each bounce a fixed block of dimensions
//! ([`DIMENSIONS_PER_BOUNCE`]) whether or not it uses them all, so turning an effect off (say,
//! shadow rays) never shifts the numbers the next bounce sees.
//!
//! The thin lens's two numbers ([`PixelSampler::lens`]) are camera dimensions too, but they come
//! from a stream of their own rather than from dimensions 2 and 3: placing them there would have
//! moved every bounce's block, so every image rendered before the lens existed would have changed
//! its bits. A pinhole camera never draws them, and its images are the same bits as before.
//! The sample's time within the shutter ([`PixelSampler::time`]) has a stream of its own for the
//! same reason, and so do the wavelengths of a path that turns spectral at dispersive glass
//! ([`PixelSampler::wavelength`], [`crate::spectrum`]).

use glam::Vec2;

/// Dimensions used before the first bounce: the pixel jitter (2).
pub const CAMERA_DIMENSIONS: u32 = 2;

/// Dimensions reserved for each bounce: light selection (1) and light position (2) for next-event
/// estimation, the BSDF's direction (2) and discrete choice (1), Russian roulette (1).
pub const DIMENSIONS_PER_BOUNCE: u32 = 7;

/// The random stream of one sample of one pixel.
#[derive(Clone, Debug)]
pub struct PixelSampler {
    key: u64,
    dimension: u32,
    /// The bounce [`PixelSampler::start_bounce`] last started, which keys the medium stream.
    bounce: u32,
}

impl PixelSampler {
    /// The stream of sample `sample` of pixel (`x`, `y`) of frame `frame` under `seed`: a pure
    /// function of the five, so a pixel's value never depends on who renders it or when.
    pub fn new(seed: u64, frame: u32, x: u32, y: u32, sample: u32) -> Self {
        PixelKey::new(seed, frame, x, y).sample(sample)
    }

    /// What fills a sampler slot that holds no sample's stream yet (a packet's past its
    /// samples, an idle lane's); replaced before any number is drawn from it.
    pub(crate) fn placeholder() -> Self {
        Self::stream(0)
    }

    /// Moves to the first dimension of bounce `bounce` (0 is the camera ray's first hit).
    pub fn start_bounce(&mut self, bounce: u32) {
        self.dimension = CAMERA_DIMENSIONS + bounce * DIMENSIONS_PER_BOUNCE;
        self.bounce = bounce;
    }

    /// The next `N` numbers, uniform in [0, 1): what `N` calls of [`PixelSampler::next_1d`]
    /// return, bit for bit. Each dimension's offset is the first one's plus a constant
    /// multiple of the increment (`(d + k) G = d G + k G` modulo 2^64), so a bounce's block
    /// takes one multiplication for its offsets rather than one per number.
    #[inline(always)]
    pub fn next_nd<const N: usize>(&mut self) -> [f32; N] {
        let first = u64::from(self.dimension).wrapping_mul(GOLDEN_GAMMA);
        self.dimension += N as u32;
        std::array::from_fn(|k| {
            let offset = first.wrapping_add((k as u64).wrapping_mul(GOLDEN_GAMMA));
            unit_f32(mix(self.key ^ offset))
        })
    }

    /// The next number, uniform in [0, 1).
    pub fn next_1d(&mut self) -> f32 {
        let [u] = self.next_nd::<1>();
        u
    }

    /// A stream of its own under `key` (the lens's, the time's, a bounce's medium's...), from
    /// its first dimension.
    fn stream(key: u64) -> PixelSampler {
        PixelSampler {
            key,
            dimension: 0,
            bounce: 0,
        }
    }

    /// The next two numbers as a point in [0, 1)^2, x drawn first.
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::from_array(self.next_nd::<2>())
    }

    /// The point on the lens, in [0, 1)^2: a fixed pair of camera dimensions in the lens's own
    /// stream, the same whenever it is asked for and independent of every other number.
    pub fn lens(&self) -> Vec2 {
        Self::stream(mix(self.key ^ LENS_STREAM)).next_2d()
    }

    /// The sample's fraction of the exposure, in [0, 1): one camera dimension in the time's own
    /// stream, the same whenever it is asked for and independent of every other number, so a
    /// render without motion blur, which never asks, draws what it drew before time existed.
    pub fn time(&self) -> f32 {
        Self::stream(mix(self.key ^ TIME_STREAM)).next_1d()
    }

    /// The number that places a spectral path's wavelengths, in [0, 1): one dimension in the
    /// wavelengths' own stream, the same whenever it is asked for and independent of every
    /// other number, so paths that stay RGB, which never ask, draw what they always drew.
    pub fn wavelength(&self) -> f32 {
        Self::stream(mix(self.key ^ WAVELENGTH_STREAM)).next_1d()
    }

    /// The channel choice and the free-flight distance of the current bounce's segment through
    /// a medium, in [0, 1)^2: a pair in the medium stream of this bounce, independent of every
    /// other number and the same however often it is asked for.
    pub fn medium(&self) -> Vec2 {
        Self::stream(mix(mix(self.key ^ MEDIUM_STREAM) ^ u64::from(self.bounce))).next_2d()
    }
}

/// A pixel's part of its samples' streams: (seed, frame, pixel) hashed once for all of its
/// samples, which [`PixelKey::sample`] finishes, as [`PixelSampler::new`] does for one.
#[derive(Clone, Copy, Debug)]
pub struct PixelKey(u64);

impl PixelKey {
    /// The key of pixel (`x`, `y`) of frame `frame` under `seed`.
    pub fn new(seed: u64, frame: u32, x: u32, y: u32) -> Self {
        let mut key = mix(seed ^ 0x7e55_e7a0_0000_0000);
        key = mix(key ^ u64::from(frame));
        PixelKey(mix(key ^ (u64::from(x) << 32 | u64::from(y))))
    }

    /// The stream of the pixel's sample `sample`.
    pub fn sample(self, sample: u32) -> PixelSampler {
        PixelSampler {
            key: mix(self.0 ^ u64::from(sample)),
            dimension: 0,
            bounce: 0,
        }
    }
}

/// Tells the lens's stream from the main one (any constant that is not a small integer would do).
const LENS_STREAM: u64 = 0x1e45_0000_0000_0001;
/// Tells the media's streams from the others, as [`LENS_STREAM`] does.
const MEDIUM_STREAM: u64 = 0x3ed1_0000_0000_0002;
/// Tells the time's stream from the others, as [`LENS_STREAM`] does.
const TIME_STREAM: u64 = 0x71e0_0000_0000_0003;
/// Tells the wavelengths' stream from the others, as [`LENS_STREAM`] does.
const WAVELENGTH_STREAM: u64 = 0x3a5e_0000_0000_0004;

/// SplitMix64's increment, 2^64 over the golden ratio.
pub(crate) const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// One SplitMix64 step on `z`: the increment, then the finaliser.
fn mix(z: u64) -> u64 {
    splitmix_finalise(z.wrapping_add(GOLDEN_GAMMA))
}

/// The SplitMix64 finaliser: a bijection on u64 with full avalanche. The one hash of every
/// random number the tracer draws (this sampler's, and the media trackers' streams).
pub(crate) fn splitmix_finalise(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The top 24 bits of `bits` as a float in [0, 1) with spacing 2^-24: every such float, never
/// 1.0 itself, so `1 - u` is exact and never 0.
pub(crate) fn unit_f32(bits: u64) -> f32 {
    (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_inputs_same_numbers_and_inputs_matter() {
        let a: Vec<f32> = (0..8)
            .map({
                let mut s = PixelSampler::new(1, 2, 3, 4, 5);
                move |_| s.next_1d()
            })
            .collect();
        let mut s = PixelSampler::new(1, 2, 3, 4, 5);
        let b: Vec<f32> = (0..8).map(|_| s.next_1d()).collect();
        assert_eq!(a, b);
        for other in [
            PixelSampler::new(9, 2, 3, 4, 5),
            PixelSampler::new(1, 9, 3, 4, 5),
            PixelSampler::new(1, 2, 9, 4, 5),
            PixelSampler::new(1, 2, 3, 9, 5),
            PixelSampler::new(1, 2, 3, 4, 9),
        ] {
            let mut o = other;
            assert_ne!(o.next_1d(), a[0]);
        }
    }

    /// A block of numbers drawn at once is the numbers drawn one by one, bit for bit, and
    /// each is its dimension's number as the stream was first defined, the key XOR the
    /// dimension times the increment, hashed (written out here), from any dimension (bounce
    /// blocks, the camera's, far dimensions) and any key; and a pixel's key finished per
    /// sample is the sample's stream hashed in one go, as first defined (written out too).
    #[test]
    fn blocks_and_pixel_keys_draw_what_single_numbers_and_whole_keys_draw() {
        for (i, dimension) in [0u32, 2, 9, 700, 1 << 20, u32::MAX - 40]
            .into_iter()
            .enumerate()
        {
            let mut one = PixelSampler::new(3, 1, i as u32, 7, 11);
            one.dimension = dimension;
            let mut block = one.clone();
            let defined: [u32; 7] = std::array::from_fn(|k| {
                let d = u64::from(dimension + k as u32);
                unit_f32(mix(one.key ^ d.wrapping_mul(GOLDEN_GAMMA))).to_bits()
            });
            let singles: [f32; 7] = std::array::from_fn(|_| one.next_1d());
            assert_eq!(singles.map(f32::to_bits), defined);
            assert_eq!(
                block.next_nd::<7>().map(f32::to_bits),
                singles.map(f32::to_bits)
            );
            assert_eq!(block.dimension, one.dimension);
            assert_eq!(
                block.next_nd::<2>().map(f32::to_bits),
                [one.next_1d(), one.next_1d()].map(f32::to_bits)
            );
        }
        for (seed, frame, x, y, sample) in [
            (0, 0, 0, 0, 0),
            (u64::MAX, 9, 4000, 3, 1023),
            (42, 1 << 20, 7, 9000, 5),
        ] {
            let mut key = mix(seed ^ 0x7e55_e7a0_0000_0000);
            key = mix(key ^ u64::from(frame));
            key = mix(key ^ (u64::from(x) << 32 | u64::from(y)));
            key = mix(key ^ u64::from(sample));
            assert_eq!(PixelKey::new(seed, frame, x, y).sample(sample).key, key);
        }
    }

    #[test]
    fn uniform_mean_and_range() {
        let mut sum = 0.0f64;
        let n = 100_000;
        for i in 0..n {
            let mut s = PixelSampler::new(7, 0, i % 317, i / 317, 0);
            let u = s.next_1d();
            assert!((0.0..1.0).contains(&u));
            sum += f64::from(u);
        }
        let mean = sum / f64::from(n);
        // Standard error of the mean of U(0,1) over 1e5 draws is 0.0009.
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
    }

    #[test]
    fn the_lens_stream_is_fixed_and_apart_from_the_main_one() {
        let s = PixelSampler::new(1, 0, 0, 0, 0);
        let lens = s.lens();
        let mut t = s.clone();
        let main: Vec<f32> = (0..64).map(|_| t.next_1d()).collect();
        assert_eq!(
            t.lens(),
            lens,
            "drawing other numbers moves nothing in the lens stream"
        );
        assert!(!main.contains(&lens.x) && !main.contains(&lens.y));
        assert_ne!(PixelSampler::new(1, 0, 0, 0, 1).lens(), lens);
    }

    #[test]
    fn the_time_stream_is_fixed_and_apart_from_the_lens_and_the_main_one() {
        let s = PixelSampler::new(1, 0, 0, 0, 0);
        let time = s.time();
        let mut t = s.clone();
        let main: Vec<f32> = (0..64).map(|_| t.next_1d()).collect();
        assert_eq!(
            t.time(),
            time,
            "drawing other numbers moves nothing in the time stream"
        );
        assert!(!main.contains(&time));
        let lens = s.lens();
        assert!(time != lens.x && time != lens.y);
        let mut u = PixelSampler::new(1, 0, 0, 0, 0);
        let _ = u.time();
        assert_eq!(
            u.next_1d(),
            main[0],
            "drawing the time shifts no main number"
        );
        // Uniform over the exposure: the mean of many samples' times is a half.
        let n = 20_000;
        let mean = (0..n)
            .map(|i| f64::from(PixelSampler::new(3, 1, i % 101, i / 101, i % 7).time()))
            .sum::<f64>()
            / f64::from(n);
        assert!((mean - 0.5).abs() < 0.01, "mean {mean}");
    }

    #[test]
    fn the_wavelength_stream_is_fixed_and_apart_from_the_others() {
        let s = PixelSampler::new(1, 0, 0, 0, 0);
        let w = s.wavelength();
        let mut t = s.clone();
        let main: Vec<f32> = (0..64).map(|_| t.next_1d()).collect();
        assert_eq!(t.wavelength(), w, "drawing other numbers moves nothing");
        assert!(!main.contains(&w));
        assert!(w != s.time() && w != s.lens().x && w != s.lens().y && w != s.medium().x);
        let mut u = PixelSampler::new(1, 0, 0, 0, 0);
        let _ = u.wavelength();
        assert_eq!(u.next_1d(), main[0], "drawing it shifts no main number");
        let n = 20_000;
        let mean = (0..n)
            .map(|i| f64::from(PixelSampler::new(3, 1, i % 101, i / 101, i % 7).wavelength()))
            .sum::<f64>()
            / f64::from(n);
        assert!((mean - 0.5).abs() < 0.01, "mean {mean}");
    }

    #[test]
    fn medium_streams_are_per_bounce_and_apart_from_the_main_one() {
        let mut s = PixelSampler::new(1, 0, 0, 0, 0);
        let mut seen = Vec::new();
        for bounce in 0..16 {
            s.start_bounce(bounce);
            let m = s.medium();
            assert_eq!(s.medium(), m, "asking twice gives the same pair");
            let main = s.next_2d();
            assert_ne!(m, main);
            seen.push(m);
        }
        seen.sort_by(|a, b| a.x.total_cmp(&b.x));
        seen.dedup();
        assert_eq!(seen.len(), 16, "every bounce has its own pair");
        let mut t = PixelSampler::new(1, 0, 0, 0, 0);
        t.start_bounce(3);
        let before = t.next_1d();
        let mut u = PixelSampler::new(1, 0, 0, 0, 0);
        u.start_bounce(3);
        let _ = u.medium();
        assert_eq!(
            u.next_1d(),
            before,
            "drawing the medium pair shifts no main number"
        );
    }

    #[test]
    fn bounce_blocks_are_fixed() {
        let mut s = PixelSampler::new(1, 0, 0, 0, 0);
        s.start_bounce(1);
        let first = s.next_1d();
        let mut t = PixelSampler::new(1, 0, 0, 0, 0);
        t.start_bounce(0);
        for _ in 0..3 {
            t.next_1d();
        }
        t.start_bounce(1);
        assert_eq!(first, t.next_1d());
    }
}
