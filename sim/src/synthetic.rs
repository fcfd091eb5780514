//! Synthetic traces: a cost landscape we choose, for tests and for experiments at sizes no
//! render on this machine could record (1024 peers need an image of many thousand tiles).
//!
//! [`HotSpot`] is the textbook uneven, moving load: a cheap background with one expensive
//! Gaussian spot orbiting the image centre. The spot moves a little each frame, so last frame's
//! costs predict this frame's well but not exactly, which is the temporal coherence the PBT
//! relies on; a regular grid meanwhile puts the whole spot into a few tiles.

use std::f64::consts::TAU;

use serde::{Deserialize, Serialize};

use crate::{Error, Trace};

/// A Gaussian hot spot orbiting the image centre on a cheap background.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HotSpot {
    /// The image's width in pixels.
    pub width: u32,
    /// The image's height in pixels.
    pub height: u32,
    /// How many frames the trace holds.
    pub frames: u32,
    /// Side of a cost block in pixels.
    pub block_size: u32,
    /// Counted work of one background pixel.
    pub base: f64,
    /// Extra work at the spot's centre, as a multiple of `base`.
    pub peak: f64,
    /// The spot's standard deviation, as a fraction of the image's shorter side.
    pub radius: f64,
    /// The orbit's radius, as a fraction of each image side (an ellipse on a wide image).
    pub orbit: f64,
    /// Frames per full orbit; the spot moves `1 / period` of a turn per frame.
    pub period: f64,
}

impl Default for HotSpot {
    /// 1024 x 1024 pixels (16k tiles of 8x8), 100 frames, a background of 1000 units of work
    /// per pixel (the shipped glass-cluster-pan scene averages 900 to 1700 at 16 samples per
    /// pixel), a spot 100 times as expensive at its centre with a standard deviation of 6% of
    /// the image, going once around an orbit of 30% of the image over the 100 frames (about
    /// 19 pixels a frame). A frame is then about 3.4e9 units: some 47 s on one thread at
    /// the default rate.
    fn default() -> Self {
        Self {
            width: 1024,
            height: 1024,
            frames: 100,
            block_size: 8,
            base: 1000.0,
            peak: 100.0,
            radius: 0.06,
            orbit: 0.3,
            period: 100.0,
        }
    }
}

impl HotSpot {
    /// Parses `synthetic[:WIDTHxHEIGHT[:FRAMES]]`; the rest is [`HotSpot::default`].
    pub fn parse(spec: &str) -> Result<Self, Error> {
        let bad = || {
            Error::BadTrace(format!(
                "{spec:?}: expected synthetic, synthetic:WIDTHxHEIGHT or synthetic:WIDTHxHEIGHT:FRAMES"
            ))
        };
        let mut parts = spec.split(':');
        if parts.next() != Some("synthetic") {
            return Err(bad());
        }
        let mut spot = Self::default();
        if let Some(size) = parts.next() {
            let (w, h) = size.split_once('x').ok_or_else(bad)?;
            spot.width = w.parse().map_err(|_| bad())?;
            spot.height = h.parse().map_err(|_| bad())?;
        }
        if let Some(frames) = parts.next() {
            spot.frames = frames.parse().map_err(|_| bad())?;
            spot.period = f64::from(spot.frames.max(1));
        }
        if parts.next().is_some() || spot.width == 0 || spot.height == 0 || spot.frames == 0 {
            return Err(bad());
        }
        Ok(spot)
    }

    /// The trace: each block costs its pixels' work, evaluated at the block centre (the spot
    /// is several blocks wide, so that is accurate enough and fast), rounded to whole counts.
    pub fn trace(&self) -> Result<Trace, Error> {
        let source = format!(
            "synthetic hot spot: {}x{}, {} frames, base {} per pixel, peak x{}, radius {}, orbit {}, period {} frames",
            self.width,
            self.height,
            self.frames,
            self.base,
            self.peak,
            self.radius,
            self.orbit,
            self.period
        );
        let mut trace = Trace::new(self.width, self.height, self.block_size, &source)?;
        let (w, h, b) = (
            f64::from(self.width),
            f64::from(self.height),
            self.block_size,
        );
        let sigma = self.radius * w.min(h);
        let (columns, rows) = (self.width.div_ceil(b), self.height.div_ceil(b));
        for frame in 0..self.frames {
            let angle = TAU * f64::from(frame) / self.period;
            let (cx, cy) = (
                w / 2.0 + self.orbit * w * angle.cos(),
                h / 2.0 + self.orbit * h * angle.sin(),
            );
            let mut blocks = Vec::with_capacity(columns as usize * rows as usize);
            for row in 0..rows {
                for column in 0..columns {
                    let (x0, y0) = (column * b, row * b);
                    let (bw, bh) = (b.min(self.width - x0), b.min(self.height - y0));
                    let (x, y) = (
                        f64::from(x0) + f64::from(bw) / 2.0,
                        f64::from(y0) + f64::from(bh) / 2.0,
                    );
                    let d2 = ((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * sigma * sigma);
                    let per_pixel = self.base * (1.0 + self.peak * (-d2).exp());
                    blocks.push((per_pixel * f64::from(bw * bh)).round() as u64);
                }
            }
            trace.push(blocks)?;
        }
        Ok(trace)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spot_is_expensive_and_moves() {
        let spot = HotSpot {
            width: 128,
            height: 64,
            frames: 4,
            period: 4.0,
            ..HotSpot::default()
        };
        let trace = spot.trace().unwrap();
        assert_eq!(trace.frames.len(), 4);
        let first = &trace.frames[0].blocks;
        let (min, max) = (first.iter().min().unwrap(), first.iter().max().unwrap());
        assert_eq!(*min, 64_000, "a background block is 64 pixels at 1000");
        assert!(*max > 20 * min, "the spot's centre block costs {max}");
        let hottest = |blocks: &[u64]| (0..blocks.len()).max_by_key(|&i| blocks[i]).unwrap();
        assert_ne!(hottest(first), hottest(&trace.frames[1].blocks));
    }

    #[test]
    fn specs_parse_and_bad_ones_are_refused() {
        let spot = HotSpot::parse("synthetic:64x32:5").unwrap();
        assert_eq!((spot.width, spot.height, spot.frames), (64, 32, 5));
        assert_eq!(HotSpot::parse("synthetic").unwrap(), HotSpot::default());
        for bad in [
            "synth",
            "synthetic:64",
            "synthetic:0x4",
            "synthetic:4x4:x",
            "synthetic:4x4:2:1",
        ] {
            assert!(HotSpot::parse(bad).is_err(), "{bad}");
        }
    }
}
