//! A whole frame on one machine: the frame cut into a grid of tiles, the tiles rendered on a
//! given rayon pool, and their pixels and costs put into one [`Film`].
//!
//! Every caller that renders a whole frame outside the cluster (the benchmark and the accuracy
//! ladders, the trace recorder, the traversal examples and tests) goes through here, so that the
//! grid and the film assembly are written once. The image does not depend on the grid, the pool
//! or the order the tiles finish in: a pixel is a pure function of (scene, frame, pixel, sample
//! index, seed), each pixel lands in exactly one tile, and the film only adds integers.
//!
//! The world itself comes from [`World::prepare`](crate::World::prepare).

use crate::integrator::World;
use crate::tile::{BLOCK_SIZE, Film, Rect, TileOutput, render_tile};
use rayon::prelude::*;

/// How a frame is cut for rendering on one machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameConfig {
    /// The side of the square tiles, in pixels (the last row and column may be narrower). A
    /// multiple of [`BLOCK_SIZE`] keeps every cost block inside one tile.
    pub tile: u32,
}

impl Default for FrameConfig {
    /// Tiles of 32 x 32 pixels: small enough that a pool of a few dozen threads stays busy on a
    /// small image, large enough that handing a tile out costs nothing next to rendering it.
    fn default() -> Self {
        Self {
            tile: 4 * BLOCK_SIZE,
        }
    }
}

/// Renders every pixel of `frame` of `world` on `pool`, tiles cut as `config` says, into a film
/// with the pixels, the per-block cost map and the summed path statistics.
pub fn render_frame(
    world: &World,
    frame: u32,
    pool: &rayon::ThreadPool,
    config: FrameConfig,
) -> Film {
    render_frame_by(world, pool, config, |rect| render_tile(world, frame, rect))
}

/// [`render_frame`] with each tile rendered by `tile` (given the tile's rectangle), for callers
/// that measure around each tile: the tracer has no clock, so a caller that wants tile times
/// wraps [`render_tile`] here.
pub fn render_frame_by(
    world: &World,
    pool: &rayon::ThreadPool,
    config: FrameConfig,
    tile: impl Fn(Rect) -> TileOutput + Sync,
) -> Film {
    let settings = &world.scene.settings;
    let rects = tile_grid(settings.width, settings.height, config.tile);
    let outputs: Vec<TileOutput> = pool.install(|| rects.par_iter().map(|&r| tile(r)).collect());
    let mut film = Film::new(settings.width, settings.height);
    for output in &outputs {
        film.insert(output.rect, &output.pixels, &output.cost);
        film.stats.add(&output.stats);
    }
    film
}

/// The square tiles of side `side` (at least 1) covering a `width` x `height` image, row by row
/// from the top left; the last column and row are cut to the image.
pub fn tile_grid(width: u32, height: u32, side: u32) -> Vec<Rect> {
    let side = side.max(1);
    (0..height.div_ceil(side))
        .flat_map(|row| (0..width.div_ceil(side)).map(move |column| (column, row)))
        .map(|(column, row)| {
            let (x, y) = (column * side, row * side);
            Rect {
                x,
                y,
                w: side.min(width - x),
                h: side.min(height - y),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_covers_every_pixel_once() {
        for (width, height, side) in [(1, 1, 32), (33, 17, 8), (64, 64, 32), (5, 70, 7)] {
            let mut seen = vec![0u32; (width * height) as usize];
            for rect in tile_grid(width, height, side) {
                assert!(rect.w > 0 && rect.h > 0 && rect.w <= side && rect.h <= side);
                for y in rect.y..rect.y + rect.h {
                    for x in rect.x..rect.x + rect.w {
                        seen[(y * width + x) as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&n| n == 1), "{width}x{height} by {side}");
        }
    }

    #[test]
    fn a_zero_side_is_taken_as_one_pixel() {
        assert_eq!(tile_grid(2, 1, 0).len(), 2);
    }
}
