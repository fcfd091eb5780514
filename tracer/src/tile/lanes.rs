//! A tile's paths as one stream through the lanes
//! ([`World::radiance_stream`](crate::World::radiance_stream)): the feed hands out each pixel's
//! samples in order, a camera packet at a time, and takes their values back in whatever order
//! the lanes end them. A pixel's values are added in sample order, so the tile is the same
//! bits as one rendered pixel by pixel. A value that comes back in its turn is added at once;
//! one that comes back ahead of a sample still out waits in a ring of 64 slots, added up as the
//! ring needs room and at the pixel's end (eight lanes hold at most eight paths, so few come
//! back far ahead), so a pixel's memory does not grow with the sample count. The ring is taken
//! for a pixel only when its first early value comes, from the rings of finished pixels: the
//! open pixels are not always few. Where paths end at their first surface (a depth cap of 0,
//! `tessera bench`'s camera-ray pass) or escape at once, one lane takes path after path of
//! pixel after pixel while the others still hold the first pixel's samples: every pixel of the
//! tile is open at once, and all but the first have their values back in order.
//!
//! Counted work goes to the cost map's block of the pixel it was counted for, not through the
//! pixel: a lane counts its paths' work (and the camera packets' walks it takes) into one
//! record for as long as its paths' pixels lie in one block, and the feed adds that record to
//! the block when the lane's next path lies in another, or when there are no more. Counts are
//! integers and a block's work is linear in them, so the cost map and the tile's statistics
//! are the same integers as counted path by path.

use super::{Cameras, Packet, TilePixels, add_sample};
use crate::integrator::{NOT_COUNTED, NewPath, PathFeed, PathStats};
use glam::Vec3;
use std::collections::VecDeque;

/// The tile's side of the stream, handing out the pixels `P` names in the tile's order
/// (`rect_pixels`).
pub(super) struct TileFeed<'a, 'w, P> {
    cameras: &'a Cameras<'w>,
    tile: &'a mut TilePixels,
    /// The pixels not yet started, and how many have been.
    pixels: P,
    started: u64,
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
    /// The cost map's block of the newest pixel (`TilePixels::block_of`), whose work the
    /// lanes given its paths count.
    newest_block: u32,
    /// The rings of early values of finished pixels, kept for the next pixels that need one.
    spare: Rings,
}

/// A pixel whose samples are out.
struct OpenPixel {
    x: u32,
    y: u32,
    /// The sum of its samples' values so far, in sample order.
    sum: InOrder,
    /// The samples not yet back.
    remaining: u32,
}

impl<'a, 'w, P: Iterator<Item = (u32, u32)>> TileFeed<'a, 'w, P> {
    pub(super) fn new(cameras: &'a Cameras<'w>, tile: &'a mut TilePixels, pixels: P) -> Self {
        TileFeed {
            cameras,
            tile,
            pixels,
            started: 0,
            packet: Packet::new(),
            packet_start: 0,
            handed: 0,
            next_sample: cameras.spp,
            open: VecDeque::new(),
            oldest: 0,
            newest_block: NOT_COUNTED,
            spare: Vec::new(),
        }
    }

    /// Checks that every pixel was stored.
    pub(super) fn finish(mut self) {
        assert!(
            self.open.is_empty() && self.pixels.next().is_none(),
            "the lanes hand back every path they are given"
        );
    }

    /// Starts the tile's next pixel, if it has one left.
    fn start_pixel(&mut self) -> Option<()> {
        let (x, y) = self.pixels.next()?;
        self.started += 1;
        self.open.push_back(OpenPixel {
            x,
            y,
            sum: InOrder::new(),
            remaining: self.cameras.spp,
        });
        self.newest_block = self.tile.block_of(x, y);
        self.next_sample = 0;
        Some(())
    }

    /// Adds a lane's counted work to the block it was counted for, if any, and marks the lane
    /// as counting for `next` from nothing.
    fn settle(&mut self, stats: &mut PathStats, counted_for: &mut u32, next: u32) {
        if *counted_for != NOT_COUNTED {
            self.tile.count(*counted_for, stats);
        }
        *stats = PathStats::default();
        *counted_for = next;
    }
}

impl<P: Iterator<Item = (u32, u32)>> PathFeed for TileFeed<'_, '_, P> {
    fn next_path(&mut self, lane: NewPath<'_>) -> Option<u64> {
        let fill = self.handed >= self.packet.n;
        if fill && self.next_sample >= self.cameras.spp && self.start_pixel().is_none() {
            // No paths left: the lane's counts are taken now, so that none stay behind.
            self.settle(lane.stats, lane.counted_for, NOT_COUNTED);
            return None;
        }
        // The lane's work is the newest pixel's block's from here on.
        if *lane.counted_for != self.newest_block {
            self.settle(lane.stats, lane.counted_for, self.newest_block);
        }
        if fill {
            let first = self.next_sample;
            let newest = self.open.back().expect("a pixel was just started");
            // The packet's walk is counted with the lane's: the same block.
            self.cameras.fill(
                &mut self.packet,
                (newest.x, newest.y),
                first,
                &mut lane.stats.traversal,
            );
            self.next_sample += self.packet.n as u32;
            self.packet_start = first;
            self.handed = 0;
        }
        let (packet, k) = (&self.packet, self.handed);
        self.handed += 1;
        *lane.ray = packet.rays[k];
        *lane.first = packet.found.then_some(packet.hits[k]);
        lane.sampler.clone_from(&packet.samplers[k]);
        *lane.time = packet.times[k];
        // The packet's pixel is the newest one started.
        Some(tag(self.started - 1, self.packet_start + k as u32))
    }

    fn path_done(&mut self, tag: u64, radiance: Vec3) {
        let (pixel, sample) = ((tag >> 32) as u32, tag as u32);
        let open = &mut self.open[pixel.wrapping_sub(self.oldest as u32) as usize];
        open.remaining -= 1;
        // A dropped value is counted in the tile's statistics, which are not a block's work.
        let stats = &mut self.tile.stats;
        open.sum.add(sample, radiance, stats, &mut self.spare);
        while self.open.front().is_some_and(|p| p.remaining == 0) {
            let mut done = self.open.pop_front().expect("just checked");
            self.oldest += 1;
            let total = done.sum.total(&mut self.tile.stats, &mut self.spare);
            let spp = self.cameras.spp;
            self.tile.store(done.x, done.y, total / spp as f32);
        }
    }
}

/// A path's tag: its sample in the low half, its pixel's index in the tile in the high half,
/// modulo 2^32, which names it among the open pixels (far fewer) on a tile of any size. Shifts,
/// where a division by the sample count showed in the profile.
fn tag(pixel: u64, sample: u32) -> u64 {
    (pixel << 32) | u64::from(sample)
}

/// The slots of a pixel's ring of early values: 64, one bit each in a word. With a depth cap
/// of 7, while one lane's path lives its eight bounces the seven others end at most 56 paths,
/// so no value comes back 64 samples ahead of one still out; only much longer paths (no cap,
/// Russian roulette alone) can, and those few wait aside ([`Early::far`]).
const WINDOW: u32 = 64;

/// A pixel's sum of its samples' values in sample order, from values that come back in any
/// order: a value in its turn is added at once, and where a value comes back ahead of one still
/// out the pixel takes a ring ([`Early`]), in which sample `s`'s value waits in slot
/// `s % WINDOW`; the ring is added up in sample order from the next sample on when a value
/// needs a slot the ring does not reach yet, and at the pixel's end, which gives it back. Per
/// path a store and a bit; a pixel of at most [`WINDOW`] samples is added once, at its end, as
/// an array of its values would be.
pub(super) struct InOrder {
    sum: Vec3,
    /// The next sample to add.
    next: u32,
    /// The values that came back early, once one has.
    early: Option<Box<Early>>,
}

/// Rings of early values, each boxed so that taking one and giving it back moves a pointer,
/// not the ring's kilobyte.
#[allow(clippy::vec_box)]
type Rings = Vec<Box<Early>>;

/// A pixel's values that came back ahead of a sample still out.
struct Early {
    slots: [Vec3; WINDOW as usize],
    /// Which slots hold a value.
    full: u64,
    /// Values too far ahead for the ring, with their samples (almost always empty).
    far: Vec<(u32, Vec3)>,
}

impl InOrder {
    fn new() -> Self {
        InOrder {
            sum: Vec3::ZERO,
            next: 0,
            early: None,
        }
    }

    /// Takes sample `sample`'s value (each sample's once): added at once in its turn while no
    /// value waits, else put in the pixel's ring, taken from `spare` (or made) when the first
    /// early value comes. A non-finite value is dropped and counted in `stats` when its turn
    /// comes.
    #[inline]
    fn add(&mut self, sample: u32, value: Vec3, stats: &mut PathStats, spare: &mut Rings) {
        let early = match &mut self.early {
            None if sample == self.next => {
                add_sample(&mut self.sum, value, stats);
                self.next += 1;
                return;
            }
            Some(early) => early,
            None => self.early.insert(spare.pop().unwrap_or_else(Early::new)),
        };
        if sample - self.next >= WINDOW {
            early.add_ready(&mut self.sum, &mut self.next, stats);
        }
        if sample - self.next < WINDOW {
            let slot = sample % WINDOW;
            early.slots[slot as usize] = value;
            early.full |= 1 << slot;
        } else {
            early.far.push((sample, value));
        }
    }

    /// The sum of every value, once all have come back; the ring, if the pixel took one, goes
    /// back to `spare`, empty.
    fn total(&mut self, stats: &mut PathStats, spare: &mut Rings) -> Vec3 {
        if let Some(mut early) = self.early.take() {
            early.add_ready(&mut self.sum, &mut self.next, stats);
            debug_assert!(
                early.full == 0 && early.far.is_empty(),
                "every value came back"
            );
            spare.push(early);
        }
        self.sum
    }
}

impl Early {
    fn new() -> Box<Self> {
        Box::new(Early {
            slots: [Vec3::ZERO; WINDOW as usize],
            full: 0,
            far: Vec::new(),
        })
    }

    /// Adds to `sum` the run of values in from sample `next` on, in sample order, taking in
    /// the values waiting aside as the ring comes to reach them.
    fn add_ready(&mut self, sum: &mut Vec3, next: &mut u32, stats: &mut PathStats) {
        loop {
            let start = *next % WINDOW;
            let run = self.full.rotate_right(start).trailing_ones();
            for k in 0..run {
                let slot = ((start + k) % WINDOW) as usize;
                add_sample(sum, self.slots[slot], stats);
            }
            let taken = if run == WINDOW {
                u64::MAX
            } else {
                (1 << run) - 1
            };
            self.full &= !taken.rotate_left(start);
            *next += run;
            if self.far.is_empty() {
                return;
            }
            let (reached, before) = (*next, self.far.len());
            let mut aside = std::mem::take(&mut self.far);
            aside.retain(|&(sample, value)| {
                let fits = sample - reached < WINDOW;
                if fits {
                    let slot = sample % WINDOW;
                    self.slots[slot as usize] = value;
                    self.full |= 1 << slot;
                }
                !fits
            });
            self.far = aside;
            if self.far.len() == before {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values handed to a pixel's sum in scrambled orders (neighbours swapped, blocks reversed,
    /// samples hundreds ahead of one still out, far past the ring) sum to the same bits as
    /// the same values added one after another, a non-finite one dropped and counted.
    #[test]
    fn values_in_any_order_sum_as_in_sample_order() {
        let count = 700u32;
        let value = |s: u32| {
            if s == 333 {
                Vec3::NAN
            } else {
                // Magnitudes far apart, so that another order of the additions rounds
                // differently.
                Vec3::new(1.0 + s as f32 * 1e-3, 1e-7 * s as f32, (s % 7) as f32 * 1e5)
            }
        };
        let mut expected = Vec3::ZERO;
        let mut dropped = PathStats::default();
        for s in 0..count {
            add_sample(&mut expected, value(s), &mut dropped);
        }
        let in_order: Vec<u32> = (0..count).collect();
        let swapped: Vec<u32> = (0..count).map(|s| s ^ 1).collect();
        let blocks_reversed: Vec<u32> = (0..count)
            .map(|s| (s / 50) * 50 + 49 - s % 50)
            .filter(|&s| s < count)
            .collect();
        // Sample 0 and then 1 come back last: everything else waits, most of it aside.
        let late_first: Vec<u32> = (2..count).chain([0, 1]).collect();
        let strided: Vec<u32> = (0..97).flat_map(|r| (r..count).step_by(97)).collect();
        // The rings of finished pixels, shared by the pixels one after another as a tile's are.
        let mut spare = Vec::new();
        for (round, order) in [in_order, swapped, blocks_reversed, late_first, strided]
            .into_iter()
            .enumerate()
        {
            assert_eq!(order.len(), count as usize);
            let mut sum = InOrder::new();
            let mut stats = PathStats::default();
            for &s in &order {
                sum.add(s, value(s), &mut stats, &mut spare);
            }
            let total = sum.total(&mut stats, &mut spare);
            assert_eq!(sum.next, count, "every value added");
            assert!(sum.early.is_none(), "the ring is given back at the end");
            // Values in order take no ring; the first pixel with early values makes one, and
            // the pixels after it take that one back from the spares.
            assert_eq!(spare.len(), usize::from(round > 0), "round {round}");
            assert!(
                spare.iter().all(|e| e.full == 0 && e.far.is_empty()),
                "nothing left waiting"
            );
            assert_eq!(
                total.to_array().map(f32::to_bits),
                expected.to_array().map(f32::to_bits)
            );
            assert_eq!(stats.invalid_samples, dropped.invalid_samples);
        }
    }
}
