//! One PBT update plus assignment on a 1920x1080 frame whose cost is a hot spot moving across
//! a cheaper background, at m = 64 to 16384 leaves; and `check_partition` on 16k tiles of a 4k
//! image. Run with `cargo bench -p balancer`.

use balancer::{Config, CostMap, Pbt, Rect, Regular, check_partition};
use divan::Bencher;

const WIDTH: u32 = 1920;
const HEIGHT: u32 = 1080;
const BLOCK: u32 = 8;
const PEERS: usize = 16;
const LEAVES: [usize; 5] = [64, 256, 1024, 4096, 16384];

fn main() {
    divan::main();
}

/// Counted work per 8x8 block in frame `frame`: 64 units per pixel of background, 20 times
/// that inside a disc of radius 160 pixels whose centre moves 24 pixels a frame, and a mild
/// left-to-right gradient so that no two blocks tie.
fn frame(frame: u32) -> CostMap {
    let (cx, cy) = (
        300.0 + 24.0 * f64::from(frame),
        400.0 + 6.0 * f64::from(frame),
    );
    CostMap::from_fn(WIDTH, HEIGHT, BLOCK, |c, r| {
        let (x, y) = (
            f64::from(c * BLOCK + BLOCK / 2),
            f64::from(r * BLOCK + BLOCK / 2),
        );
        let per_pixel = if (x - cx).hypot(y - cy) < 160.0 {
            1280.0
        } else {
            64.0
        };
        (per_pixel + x / 64.0).round() * 64.0
    })
    .expect("the synthetic map is valid")
}

/// A tree that has followed the spot for a few frames, and the next frame's map.
fn steady(leaves: usize) -> (Pbt, CostMap) {
    let mut pbt = Pbt::new(
        WIDTH,
        HEIGHT,
        &Config {
            leaves,
            ..Config::default()
        },
    )
    .expect("valid");
    for f in 0..4 {
        pbt.observe(&frame(f)).expect("same size");
    }
    (pbt, frame(4))
}

#[divan::bench(args = LEAVES)]
fn update_and_assign(bencher: Bencher, leaves: usize) {
    let (pbt, next) = steady(leaves);
    bencher
        .with_inputs(|| pbt.clone())
        .bench_local_values(|mut pbt| {
            pbt.observe(&next).expect("same size");
            pbt.assign(PEERS, None).expect("valid peers")
        });
}

#[divan::bench(args = LEAVES)]
fn update_only(bencher: Bencher, leaves: usize) {
    let (pbt, next) = steady(leaves);
    bencher
        .with_inputs(|| pbt.clone())
        .bench_local_values(|mut pbt| pbt.observe(&next).expect("same size"));
}

#[divan::bench(args = LEAVES)]
fn assign_only(bencher: Bencher, leaves: usize) {
    let (mut pbt, next) = steady(leaves);
    pbt.observe(&next).expect("same size");
    bencher.bench_local(|| pbt.assign(PEERS, None).expect("valid peers"));
}

#[divan::bench]
fn check_16k_tiles_of_4k(bencher: Bencher) {
    let grid = Regular::grid(3840, 2160, 128, 128).expect("valid grid");
    let tiles: Vec<Rect> = grid.tiles().iter().map(|tile| tile.rect).collect();
    bencher.bench_local(|| check_partition(3840, 2160, &tiles, Some(16384), None));
}
