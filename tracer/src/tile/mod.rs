//! The unit of work: render a rectangle of one frame, get its pixels and its cost.
//!
//! The cost is counted work (see [`PathStats::work`]), recorded per block of
//! [`BLOCK_SIZE`]-pixel squares on a grid anchored at the image origin, so the costs of tiles of
//! any partition add up to one map for the whole frame; the balancer predicts the next frame from
//! it. A block cut by tile borders simply receives contributions from several tiles.

mod lanes;

use crate::geometry::{Hit, PACKET, Ray, TraversalStats, UNUSED_RAY};
use crate::integrator::{PathStats, World};
use crate::sampler::{PixelKey, PixelSampler};
use crate::scene::CameraRays;
use serde::{Deserialize, Serialize};

/// The side of a cost block, in pixels.
pub const BLOCK_SIZE: u32 = 8;

/// A rectangle of pixels: columns `x..x + w`, rows `y..y + h`. The tracer's own, as
/// `balancer::Rect` is the balancer's, so that neither crate depends on the other; the one
/// place that converts between them is `runtime::node::bundle` (`tracer_rect`, `balancer_rect`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Rect {
    /// The leftmost column, counted from the image's left edge.
    pub x: u32,
    /// The top row, counted from the image's top edge (row 0 is the top of the image).
    pub y: u32,
    /// The width in pixels; 0 makes an empty rectangle.
    pub w: u32,
    /// The height in pixels; 0 makes an empty rectangle.
    pub h: u32,
}

impl Rect {
    /// The number of pixels, as `u64` because a whole large image overflows `u32` pixels.
    pub fn area(&self) -> u64 {
        u64::from(self.w) * u64::from(self.h)
    }

    /// The blocks this rectangle touches: (first column, first row, columns, rows).
    pub fn blocks(&self) -> (u32, u32, u32, u32) {
        if self.w == 0 || self.h == 0 {
            return (self.x / BLOCK_SIZE, self.y / BLOCK_SIZE, 0, 0);
        }
        let (bx0, by0) = (self.x / BLOCK_SIZE, self.y / BLOCK_SIZE);
        let bx1 = (self.x + self.w - 1) / BLOCK_SIZE;
        let by1 = (self.y + self.h - 1) / BLOCK_SIZE;
        (bx0, by0, bx1 - bx0 + 1, by1 - by0 + 1)
    }
}

/// A rendered tile. Why a type of its own: it is what the tracer makes of a rectangle, in the
/// tracer's own terms (float pixels, path statistics); the runtime encodes it for the wire.
#[derive(Clone, Debug, PartialEq)]
pub struct TileOutput {
    /// The animation frame rendered, counted from 0.
    pub frame: u32,
    /// Where the tile lies in the frame, and so how `pixels` is laid out.
    pub rect: Rect,
    /// Linear RGB, row-major within the rectangle.
    pub pixels: Vec<[f32; 3]>,
    /// The counted work of the tile, overall and per cost block.
    pub cost: TileCost,
    /// What the tile's paths did (rays, hits, shadow rays, ...), summed over its pixels.
    pub stats: PathStats,
}

/// What a tile cost: counted work, overall and per block. Why apart from [`TileOutput`]: it is
/// the part that travels and is summed into a [`Film`]'s cost map without the pixels.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TileCost {
    /// Rays traced for the tile: closest-hit rays (camera and bounces) plus shadow rays.
    pub rays: u64,
    /// The tile's counted work ([`PathStats::work`]), the sum of `blocks`.
    pub work: u64,
    /// Work per block for the blocks [`Rect::blocks`] names, row-major; only this tile's pixels
    /// are counted, so partial blocks carry partial work.
    pub blocks: Vec<u64>,
}

/// Renders `rect` of `frame`: every pixel, every sample, in a fixed order.
pub fn render_tile(world: &World, frame: u32, rect: Rect) -> TileOutput {
    let cameras = Cameras::new(world, frame);
    let mut tile = TilePixels::new(rect);
    if world.lanes_fit() {
        // The tile's paths as one stream through the lanes, each pixel's values added in
        // sample order as they come back (`lanes.rs`).
        let mut feed = lanes::TileFeed::new(&cameras, &mut tile, rect_pixels(rect));
        world.radiance_stream(&mut feed);
        feed.finish();
    } else {
        let spp = cameras.spp;
        let mut packet = Packet::new();
        for (x, y) in rect_pixels(rect) {
            let mut pixel_stats = PathStats::default();
            let mut sum = glam::Vec3::ZERO;
            // The pixel's samples in packets of up to eight, whose camera rays the world may
            // trace together; each sample's radiance is added in sample order, as ever.
            for first in (0..spp).step_by(PACKET) {
                cameras.fill(&mut packet, (x, y), first, &mut pixel_stats.traversal);
                for k in 0..packet.n {
                    let radiance = world.radiance_from(
                        &packet.rays[k],
                        packet.found.then_some(packet.hits[k]),
                        packet.times[k],
                        &mut packet.samplers[k],
                        &mut pixel_stats,
                    );
                    add_sample(&mut sum, radiance, &mut pixel_stats);
                }
            }
            tile.push(x, y, sum / spp as f32, &pixel_stats);
        }
    }
    tile.output(frame)
}

/// The pixels of `rect`, row by row, each row left to right: the order a tile's pixels are
/// stored in.
fn rect_pixels(rect: Rect) -> impl Iterator<Item = (u32, u32)> {
    (rect.y..rect.y + rect.h).flat_map(move |y| (rect.x..rect.x + rect.w).map(move |x| (x, y)))
}

/// Adds a sample's radiance to a pixel's sum; a non-finite one is dropped and counted.
fn add_sample(sum: &mut glam::Vec3, radiance: glam::Vec3, stats: &mut PathStats) {
    if radiance.is_finite() {
        *sum += radiance;
    } else {
        stats.invalid_samples += 1;
    }
}

/// A frame's camera, set up once for all of a tile's pixels.
struct Cameras<'w> {
    world: &'w World,
    frame: u32,
    spp: u32,
    /// The instant every sample is taken at without motion blur: the shutter's opening.
    instant: f64,
    /// The camera at that instant.
    still: CameraRays,
    /// Whether samples draw a time within the shutter interval (motion blur).
    blur: bool,
    /// Whether the camera must be set up again at each sample's time.
    camera_moves: bool,
}

/// A pixel's samples `first..first + n` (`n` at most [`PACKET`]): their numbers, times and
/// camera rays, and their closest hits where `found` (the camera packet traced together).
/// Slots past the `n`th repeat the last sample and are never used.
struct Packet {
    n: usize,
    samplers: [PixelSampler; PACKET],
    times: [f64; PACKET],
    rays: [Ray; PACKET],
    hits: [Option<Hit>; PACKET],
    found: bool,
}

impl Packet {
    /// An empty packet, to be filled by [`Cameras::fill`].
    fn new() -> Self {
        Packet {
            n: 0,
            samplers: std::array::from_fn(|_| PixelSampler::placeholder()),
            times: [0.0; PACKET],
            rays: [UNUSED_RAY; PACKET],
            hits: [None; PACKET],
            found: false,
        }
    }
}

impl<'w> Cameras<'w> {
    fn new(world: &'w World, frame: u32) -> Self {
        let settings = &world.scene.settings;
        let (track, shutter) = (&world.scene.camera, world.scene.shutter);
        // Without motion blur every sample is taken at one instant, the shutter's opening, and
        // never draws a time; with the shutter opening at the frame (the default) that is the
        // frame, and the camera is the one it always was there.
        let instant = shutter.time(frame, 0.0);
        let blur = world.effects.motion_blur;
        Cameras {
            world,
            frame,
            spp: settings.samples_per_pixel.max(1),
            instant,
            still: track.at_time(instant).rays(settings.width, settings.height),
            blur,
            // A camera that never moves is the same at every time, to the bit: set up once.
            camera_moves: blur && track.moves(),
        }
    }

    /// Fills `packet` with the camera rays of pixel (`x`, `y`)'s samples from `first` on
    /// (up to [`PACKET`] of them), traced together where the world does (their work counted
    /// in `traversal`). In place: a packet is some 600 bytes, and moving one per call showed
    /// in the profile.
    fn fill(
        &self,
        packet: &mut Packet,
        (x, y): (u32, u32),
        first: u32,
        traversal: &mut TraversalStats,
    ) {
        let world = self.world;
        let settings = &world.scene.settings;
        let n = (self.spp - first).min(PACKET as u32) as usize;
        packet.n = n;
        let key = PixelKey::new(settings.seed, self.frame, x, y);
        for (k, sampler) in packet.samplers.iter_mut().enumerate() {
            *sampler = key.sample(first + k.min(n - 1) as u32);
        }
        packet.times = [self.instant; PACKET];
        // Each sample's jitter first (each sample draws from its own sampler, so the order
        // across samples moves no number).
        let (mut px, mut py) = ([x as f32; PACKET], [y as f32; PACKET]);
        for k in 0..n {
            let jitter = packet.samplers[k].next_2d();
            (px[k], py[k]) = (x as f32 + jitter.x, y as f32 + jitter.y);
        }
        // Then, under motion blur, each sample's time (before a lens's numbers: the order
        // within a sampler is jitter, time, lens).
        if self.blur {
            for (time, sampler) in packet.times.iter_mut().zip(&mut packet.samplers).take(n) {
                *time = world.scene.shutter.time(self.frame, sampler.time());
            }
        }
        // A still pinhole, the common camera: the eight rays at once, their divisions and
        // square roots in vector lanes (`CameraRays::rays_into`).
        let lens = world.effects.depth_of_field && self.still.has_lens();
        if !self.blur && !lens {
            self.still.rays_into(&px, &py, &mut packet.rays);
        } else if self.camera_moves && !world.effects.depth_of_field {
            // A moving pinhole under motion blur (no lens at any time: the effect is off): the
            // eight rays, each from its own pose, at once (`CameraTrack::pinhole_rays_into`).
            let size = (settings.width, settings.height);
            let track = &world.scene.camera;
            track.pinhole_rays_into(&packet.times, size, (&px, &py), &mut packet.rays);
        } else {
            for k in 0..n {
                let sampler = &mut packet.samplers[k];
                let moved;
                let camera = if self.camera_moves {
                    moved = world
                        .scene
                        .camera
                        .at_time(packet.times[k])
                        .rays(settings.width, settings.height);
                    &moved
                } else {
                    &self.still
                };
                // A pinhole never draws the lens's numbers, so it traces exactly the rays
                // it traced before lenses existed.
                // Each branch writes its ray into the slot itself: as one value chosen
                // between the two, the ray was built aside field by field and copied
                // whole into the slot, read back across those narrow stores, which the
                // processor cannot forward (a stall per camera ray; docs/bench.md, issue
                // 12, twenty-second round).
                if world.effects.depth_of_field && camera.has_lens() {
                    packet.rays[k] = camera.ray_through_lens(px[k], py[k], sampler.lens());
                } else {
                    packet.rays[k] = camera.ray(px[k], py[k]);
                }
            }
        }
        packet.found = world.camera_hits(&packet.rays[..n], &mut packet.hits[..n], traversal);
    }
}

/// A tile's pixels and costs as they are rendered, each pixel stored where it lies.
struct TilePixels {
    rect: Rect,
    /// The first block's column and row, and the blocks per row ([`Rect::blocks`]).
    blocks_at: (u32, u32, u32),
    pixels: Vec<[f32; 3]>,
    blocks: Vec<u64>,
    stats: PathStats,
}

impl TilePixels {
    fn new(rect: Rect) -> Self {
        let (bx0, by0, bw, bh) = rect.blocks();
        TilePixels {
            rect,
            blocks_at: (bx0, by0, bw),
            pixels: vec![[0.0; 3]; rect.area() as usize],
            blocks: vec![0u64; (bw * bh) as usize],
            stats: PathStats::default(),
        }
    }

    /// Stores pixel (`x`, `y`)'s value and adds its work to its block's.
    fn push(&mut self, x: u32, y: u32, value: glam::Vec3, pixel_stats: &PathStats) {
        self.store(x, y, value);
        self.count(self.block_of(x, y), pixel_stats);
    }

    /// Stores pixel (`x`, `y`)'s value.
    fn store(&mut self, x: u32, y: u32, value: glam::Vec3) {
        let rect = self.rect;
        let index = (y - rect.y) as usize * rect.w as usize + (x - rect.x) as usize;
        self.pixels[index] = [value.x, value.y, value.z];
    }

    /// The index in `blocks` of the block that holds pixel (`x`, `y`).
    fn block_of(&self, x: u32, y: u32) -> u32 {
        let (bx0, by0, bw) = self.blocks_at;
        (y / BLOCK_SIZE - by0) * bw + (x / BLOCK_SIZE - bx0)
    }

    /// Adds `work`, counted for pixels of block `block` (an index of [`TilePixels::block_of`]),
    /// to that block's work and the tile's. The work is a sum of counts and
    /// [`PathStats::work`] is linear in them, so work counted path by path, pixel by pixel
    /// or for a run of a block's paths at once adds up to the same integers.
    fn count(&mut self, block: u32, work: &PathStats) {
        self.blocks[block as usize] += work.work();
        self.stats.add(work);
    }

    fn output(self, frame: u32) -> TileOutput {
        let stats = self.stats;
        TileOutput {
            frame,
            rect: self.rect,
            pixels: self.pixels,
            cost: TileCost {
                rays: stats.rays + stats.shadow_rays,
                work: stats.work(),
                blocks: self.blocks,
            },
            stats,
        }
    }
}

/// A whole frame being assembled from tiles: pixels and the per-block cost map.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// The image width in pixels.
    pub width: u32,
    /// The image height in pixels.
    pub height: u32,
    /// Linear RGB, row-major over the whole image, top row first; black until inserted.
    pub pixels: Vec<[f32; 3]>,
    /// Counted work per block, row-major over `blocks_x` x `blocks_y` blocks.
    pub block_work: Vec<u64>,
    /// Block columns: the width divided by [`BLOCK_SIZE`], rounded up (the last may be partial).
    pub blocks_x: u32,
    /// Block rows: the height divided by [`BLOCK_SIZE`], rounded up (the last may be partial).
    pub blocks_y: u32,
    /// The path statistics of the tiles inserted so far, summed by whoever assembles the film.
    pub stats: PathStats,
}

impl Film {
    /// A black film of `width` x `height` pixels with no work counted yet.
    pub fn new(width: u32, height: u32) -> Self {
        let blocks_x = width.div_ceil(BLOCK_SIZE);
        let blocks_y = height.div_ceil(BLOCK_SIZE);
        Self {
            width,
            height,
            pixels: vec![[0.0; 3]; (width as usize) * (height as usize)],
            block_work: vec![0; (blocks_x * blocks_y) as usize],
            blocks_x,
            blocks_y,
            stats: PathStats::default(),
        }
    }

    /// Copies a tile's pixels into place and adds its cost to the block map.
    pub fn insert(&mut self, rect: Rect, pixels: &[[f32; 3]], cost: &TileCost) {
        for row in 0..rect.h {
            let src = (row * rect.w) as usize;
            let dst = ((rect.y + row) * self.width + rect.x) as usize;
            self.pixels[dst..dst + rect.w as usize]
                .copy_from_slice(&pixels[src..src + rect.w as usize]);
        }
        let (bx0, by0, bw, bh) = rect.blocks();
        for by in 0..bh {
            for bx in 0..bw {
                self.block_work[((by0 + by) * self.blocks_x + bx0 + bx) as usize] +=
                    cost.blocks[(by * bw + bx) as usize];
            }
        }
    }
}
