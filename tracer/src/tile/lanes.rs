//! A tile's paths as one stream through the lanes ([`World::radiance_stream`](crate::World::radiance_stream)): the feed
//! hands out each pixel's samples in order, a camera packet at a time, and takes their
//! values back in whatever order the lanes end them, adding a pixel's values in sample order
//! once all have come back, so that the tile is the same bits as one rendered pixel by pixel.

use super::{Cameras, Packet, TilePixels, add_sample};
use crate::integrator::{NewPath, PathFeed, PathStats};
use glam::Vec3;
use std::collections::VecDeque;

/// The tile's side of the stream.
pub(super) struct TileFeed<'a, 'w> {
    cameras: &'a Cameras<'w>,
    tile: &'a mut TilePixels,
    /// The index (in the tile's order) of the next pixel to start.
    next_pixel: u64,
    /// The packet being handed out, the sample it starts at, and how many of its paths are
    /// out (all of them before the first).
    packet: Packet,
    packet_start: u32,
    handed: usize,
    /// The next sample of the newest pixel to put in a packet (`spp` once all are).
    next_sample: u32,
    /// The pixels started and not yet finished, oldest first; `oldest` is the first one's
    /// index.
    open: VecDeque<OpenPixel>,
    oldest: u64,
    /// The value arrays of finished pixels, kept for the next ones.
    spare: Vec<Vec<Vec3>>,
}

/// A pixel whose samples are out.
struct OpenPixel {
    x: u32,
    y: u32,
    /// Each sample's radiance, by sample index.
    values: Vec<Vec3>,
    /// The samples not yet back.
    remaining: u32,
    /// The pixel's counted work: its camera packets' and its paths'.
    stats: PathStats,
}

impl<'a, 'w> TileFeed<'a, 'w> {
    pub(super) fn new(cameras: &'a Cameras<'w>, tile: &'a mut TilePixels) -> Self {
        TileFeed {
            cameras,
            tile,
            next_pixel: 0,
            packet: Packet::new(),
            packet_start: 0,
            handed: 0,
            next_sample: cameras.spp,
            open: VecDeque::new(),
            oldest: 0,
            spare: Vec::new(),
        }
    }

    /// Checks that every pixel was stored.
    pub(super) fn finish(self) {
        assert!(
            self.open.is_empty() && self.next_pixel == self.tile.rect.area(),
            "the lanes hand back every path they are given"
        );
    }

    /// Starts the tile's next pixel, if it has one left, and returns its index.
    fn start_pixel(&mut self) -> Option<u64> {
        let rect = self.tile.rect;
        let index = self.next_pixel;
        if index >= rect.area() {
            return None;
        }
        self.next_pixel += 1;
        let (x, y) = (
            rect.x + (index % u64::from(rect.w)) as u32,
            rect.y + (index / u64::from(rect.w)) as u32,
        );
        let mut values = self.spare.pop().unwrap_or_default();
        values.clear();
        values.resize(self.cameras.spp as usize, Vec3::ZERO);
        self.open.push_back(OpenPixel {
            x,
            y,
            values,
            remaining: self.cameras.spp,
            stats: PathStats::default(),
        });
        self.next_sample = 0;
        Some(index)
    }
}

impl PathFeed for TileFeed<'_, '_> {
    fn next_path(&mut self, lane: NewPath<'_>) -> Option<u64> {
        let spp = self.cameras.spp;
        if self.handed >= self.packet.n {
            if self.next_sample >= spp {
                self.start_pixel()?;
            }
            let first = self.next_sample;
            let newest = self.open.back_mut().expect("a pixel was just started");
            self.cameras.fill(
                &mut self.packet,
                (newest.x, newest.y),
                first,
                &mut newest.stats.traversal,
            );
            self.next_sample += self.packet.n as u32;
            self.packet_start = first;
            self.handed = 0;
        }
        let (packet, k) = (&self.packet, self.handed);
        self.handed += 1;
        let pixel = self.oldest + self.open.len() as u64 - 1;
        *lane.ray = packet.rays[k];
        *lane.first = packet.found.then_some(packet.hits[k]);
        lane.sampler.clone_from(&packet.samplers[k]);
        Some(tag(pixel, self.packet_start + k as u32))
    }

    fn path_done(&mut self, tag: u64, radiance: Vec3, stats: &PathStats) {
        let (pixel, sample) = ((tag >> 32) as u32, tag as u32 as usize);
        let open = &mut self.open[pixel.wrapping_sub(self.oldest as u32) as usize];
        open.values[sample] = radiance;
        open.stats.add(stats);
        open.remaining -= 1;
        while self.open.front().is_some_and(|p| p.remaining == 0) {
            let mut done = self.open.pop_front().expect("just checked");
            self.oldest += 1;
            let mut sum = Vec3::ZERO;
            for &value in &done.values {
                add_sample(&mut sum, value, &mut done.stats);
            }
            let spp = self.cameras.spp;
            self.tile
                .push(done.x, done.y, sum / spp as f32, &done.stats);
            self.spare.push(done.values);
        }
    }
}

/// A path's tag: its sample in the low half, its pixel's index in the tile in the high half,
/// modulo 2^32, which names it among the open pixels (far fewer) on a tile of any size. Shifts,
/// where a division by the sample count showed in the profile.
fn tag(pixel: u64, sample: u32) -> u64 {
    (pixel << 32) | u64::from(sample)
}
