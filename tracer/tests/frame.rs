//! A frame rendered tile by tile on a pool is the frame rendered as one tile: the same pixel
//! bits, the same cost map and the same counters, whatever the tile size and the thread count.

use std::path::Path;
use tracer::{Film, FrameConfig, Rect, World, render_frame, render_tile};

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a small rayon pool builds")
}

fn world(scene: &str, width: u32, height: u32) -> World {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(scene);
    let mut scene = tracer::scene::load(&path).expect("the shipped scene loads");
    scene.settings.width = width;
    scene.settings.height = height;
    scene.settings.samples_per_pixel = 2;
    World::prepare(scene, None)
}

/// The frame as one tile inserted into a film by hand: what the grid must reproduce.
fn whole(world: &World, frame: u32) -> Film {
    let (w, h) = (world.scene.settings.width, world.scene.settings.height);
    let out = render_tile(world, frame, Rect { x: 0, y: 0, w, h });
    let mut film = Film::new(w, h);
    film.insert(out.rect, &out.pixels, &out.cost);
    film.stats = out.stats;
    film
}

#[test]
fn a_frame_by_tiles_is_the_frame_as_one_tile() {
    // 37 x 29 is no multiple of the tile or block side, so the grid's last row and column and
    // the blocks cut by tile borders are exercised.
    let world = world("glass-cluster-pan/glass-cluster-pan.toml", 37, 29);
    for frame in [0, 3] {
        let expected = whole(&world, frame);
        assert!(expected.block_work.iter().all(|&w| w > 0));
        for (threads, tile) in [(1, 32), (3, 8), (2, 5), (4, 64)] {
            let film = render_frame(&world, frame, &pool(threads), FrameConfig { tile });
            let bits =
                |f: &Film| -> Vec<u32> { f.pixels.iter().flatten().map(|c| c.to_bits()).collect() };
            let what = format!("frame {frame}, {threads} threads, tiles of {tile}");
            assert_eq!(bits(&film), bits(&expected), "pixels of {what}");
            assert_eq!(film.block_work, expected.block_work, "costs of {what}");
            assert_eq!(film.stats, expected.stats, "counters of {what}");
        }
    }
}

#[test]
fn frames_differ() {
    // Guards the test above against a frame number that is ignored: the pan moves the camera.
    let world = world("glass-cluster-pan/glass-cluster-pan.toml", 16, 16);
    let pool = pool(2);
    let a = render_frame(&world, 0, &pool, FrameConfig::default());
    let b = render_frame(&world, 5, &pool, FrameConfig::default());
    assert_ne!(a.pixels, b.pixels);
}
