// Throwaway measurement for the geometry report; deleted after use.
use glam::Vec3;
use std::time::Instant;
use tracer::geometry::*;
use tracer::scene::Triangle;

struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f32 { (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32 }
    fn range(&mut self, lo: f32, hi: f32) -> f32 { lo + (hi - lo) * self.unit() }
    fn direction(&mut self) -> Vec3 {
        let z = 1.0 - 2.0 * self.unit();
        let phi = std::f32::consts::TAU * self.unit();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n_rays: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(500_000);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes/stanford-dragon/cornell-dragon.obj");
    let t = Instant::now();
    let (models, _) = tobj::load_obj(&path, &tobj::GPU_LOAD_OPTIONS).unwrap();
    let mut triangles = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let v = |i: u32| Vec3::from_slice(&m.positions[3 * i as usize..3 * i as usize + 3]);
        for f in m.indices.chunks_exact(3) {
            triangles.push(Triangle { p: [v(f[0]), v(f[1]), v(f[2])], n: None, uv: None, material: 0 });
        }
    }
    eprintln!("loaded {} triangles in {:?}", triangles.len(), t.elapsed());
    let mut rng = Rng(42);
    let rays: Vec<Ray> = (0..n_rays)
        .map(|_| Ray {
            origin: Vec3::new(rng.range(-0.95, 0.95), rng.range(0.05, 1.9), rng.range(-0.95, 0.95)),
            dir: rng.direction(),
            t_max: f32::INFINITY,
        })
        .collect();
    let qualities: Vec<BuildQuality> = match args.get(2).map(|s| s.as_str()) {
        Some("medium") => vec![BuildQuality::Medium],
        _ => BuildQuality::ALL.to_vec(),
    };
    for quality in qualities {
        let t = Instant::now();
        let accel = Accel::build(&triangles, quality);
        let build = t.elapsed();
        eprintln!("{quality:?}: build {:.2} s, {:?}", build.as_secs_f64(), accel);
        for traversal in [Traversal::Robust, Traversal::Obvhs] {
            let mut stats = TraversalStats::default();
            let t = Instant::now();
            let mut hits = 0;
            for r in &rays {
                hits += accel.intersect_with(r, traversal, &mut stats).is_some() as usize;
            }
            let secs = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let mut occ = 0;
            let mut ostats = TraversalStats::default();
            for r in &rays {
                occ += accel.occluded_with(r, traversal, &mut ostats) as usize;
            }
            let osecs = t.elapsed().as_secs_f64();
            eprintln!(
                "  {traversal:?}: closest {:.2} Mrays/s (hits {hits}, {:.1} nodes {:.1} tris per ray); any-hit {:.2} Mrays/s ({:.1} tris per ray, occ {occ})",
                rays.len() as f64 / secs / 1e6,
                stats.nodes as f64 / rays.len() as f64,
                stats.triangles as f64 / rays.len() as f64,
                rays.len() as f64 / osecs / 1e6,
                ostats.triangles as f64 / rays.len() as f64,
            );
        }
    }
}
