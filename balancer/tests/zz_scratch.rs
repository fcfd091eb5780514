use balancer::{Config, CostMap, Pbt};
use std::time::Instant;
fn frame(frame: u32) -> CostMap {
    let (cx, cy) = (300.0 + 24.0 * f64::from(frame), 400.0 + 6.0 * f64::from(frame));
    CostMap::from_fn(1920, 1080, 8, |c, r| {
        let (x, y) = (f64::from(c * 8 + 4), f64::from(r * 8 + 4));
        let per_pixel = if (x - cx).hypot(y - cy) < 160.0 { 1280.0 } else { 64.0 };
        (per_pixel + x / 64.0).round() * 64.0
    }).unwrap()
}
#[test]
fn scratch() {
    for m in [1024, 4096, 16384] {
        let mut pbt = Pbt::new(1920, 1080, &Config { leaves: m, ..Config::default() }).unwrap();
        for f in 0..8 {
            let map = frame(f);
            let t = Instant::now();
            let u = pbt.observe(&map).unwrap();
            let e = t.elapsed();
            let t = Instant::now();
            let tiles = pbt.tiles();
            let e2 = t.elapsed();
            let p: Vec<f64> = tiles.iter().map(|t| t.predicted).collect();
            let max = p.iter().cloned().fold(0.0, f64::max); let mean = p.iter().sum::<f64>() / p.len() as f64;
            eprintln!("m={m} f={f} {:?} observe {:?} tiles {:?} max/mean {:.2}", u, e, e2, max / mean);
        }
    }
}
