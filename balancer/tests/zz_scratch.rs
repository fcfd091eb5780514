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
#[test]
fn scratch2() {
    let m = 16384;
    let mut pbt = Pbt::new(1920, 1080, &Config { leaves: m, ..Config::default() }).unwrap();
    let map = frame(3);
    for f in 0..4 { pbt.observe(&frame(f)).unwrap(); }
    let tiles = pbt.tiles();
    let mean = tiles.iter().map(|t| t.predicted).sum::<f64>() / tiles.len() as f64;
    let mut sorted = tiles.clone(); sorted.sort_by(|a, b| b.predicted.total_cmp(&a.predicted));
    for t in &sorted[..5] {
        let (a, b) = t.rect.halves().unwrap();
        eprintln!("{:?} {:.2} halves {:.2} {:.2} gain/mean2 {:.3}", t.rect, t.predicted / mean, map.cost(a) / mean, map.cost(b) / mean, map.cost(a) * map.cost(b) / mean / mean);
    }
    let min = sorted.last().unwrap();
    eprintln!("min {:?} {:.4}", min.rect, min.predicted / mean);
    let mut areas: Vec<u64> = tiles.iter().map(|t| t.rect.area()).collect(); areas.sort();
    eprintln!("area min {} median {} max {}", areas[0], areas[areas.len()/2], areas[areas.len()-1]);
}
#[test]
fn scratch3() {
    for m in [4096, 16384] {
    let mut pbt = Pbt::new(1920, 1080, &Config { leaves: m, ..Config::default() }).unwrap();
    for f in 0..4 { pbt.observe(&frame(f)).unwrap(); }
    let map = frame(4);
    let rects: Vec<_> = pbt.tiles().iter().map(|t| t.rect).collect();
    let t = Instant::now();
    let mut s = 0.0;
    for _ in 0..100 { for r in &rects { s += map.cost(*r); } }
    let e = t.elapsed() / 100;
    eprintln!("m={m} {} queries {:?} = {:?}/query {s}", rects.len(), e, e / rects.len() as u32);
    let t = Instant::now();
    for _ in 0..10 { let mut p = pbt.clone(); p.observe(&map).unwrap(); }
    eprintln!("clone+observe {:?}", t.elapsed() / 10);
    let t = Instant::now();
    for _ in 0..10 { let p = pbt.clone(); std::hint::black_box(p); }
    eprintln!("clone {:?}", t.elapsed() / 10);
    }
}
#[test]
fn scratch4() {
    let m = 16384;
    let mut pbt = Pbt::new(1920, 1080, &Config { leaves: m, ..Config::default() }).unwrap();
    for f in 0..4 { pbt.observe(&frame(f)).unwrap(); }
    let map = frame(4);
    let t = Instant::now();
    for _ in 0..100 { let mut p = pbt.clone(); p.observe(&map).unwrap(); std::hint::black_box(p); }
    eprintln!("clone+observe {:?}", t.elapsed() / 100);
}
