// Throwaway measurement for the geometry report; deleted after use.
use glam::Vec3;
use std::time::Instant;

/// This thread's CPU time in seconds (utime + stime from /proc), less sensitive to other
/// processes sharing the two cores than wall time.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap();
    let after = &stat[stat.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = after.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap();
    ticks / 100.0
}
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

fn sphere_escapes() {
    // Closed icosphere-like mesh (octahedron subdivided, radial jitter), rays from inside.
    let mut rng = Rng(9);
    let mut vertices = vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    let mut faces: Vec<[u32; 3]> = vec![[0,2,4],[2,1,4],[1,3,4],[3,0,4],[2,0,5],[1,2,5],[3,1,5],[0,3,5]];
    for _ in 0..5 {
        let mut mids = std::collections::BTreeMap::new();
        let mut next = Vec::new();
        for [a, b, c] in faces {
            let mut mid = |a: u32, b: u32| *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
                vertices.push((vertices[a as usize] + vertices[b as usize]).normalize());
                vertices.len() as u32 - 1
            });
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    for v in &mut vertices { *v *= 1.0 + rng.range(-0.05, 0.05); }
    for (scale, shift) in [(1.0f32, Vec3::ZERO), (1.0, Vec3::new(100.0, -50.0, 30.0)), (1e3, Vec3::new(1e4, 0.0, 0.0))] {
        let tris: Vec<Triangle> = faces.iter().map(|f| Triangle { p: f.map(|i| vertices[i as usize] * scale + shift), n: None, uv: None, material: 0 }).collect();
        let accel = Accel::build(&tris, BuildQuality::Medium);
        let n = 2_000_000;
        let (mut robust, mut theirs) = (0, [0u32; 4]);
        for k in 0..n {
            let origin = shift + if k % 2 == 0 { Vec3::ZERO } else { Vec3::new(0.3, -0.2, 0.1) * scale };
            let f = &tris[(rng.next_u64() % tris.len() as u64) as usize];
            let target = match k % 4 { 0 | 1 => f.p[(rng.next_u64() % 3) as usize], 2 => (f.p[0] + f.p[1]) * 0.5, _ => f.p[1] + (f.p[2] - f.p[1]) * rng.unit() };
            let r = Ray { origin, dir: target - origin, t_max: f32::INFINITY };
            let mut st = TraversalStats::default();
            robust += accel.intersect_with(&r, Traversal::Robust, &mut st).is_none() as u32;
            theirs[k % 4] += accel.intersect_with(&r, Traversal::Obvhs, &mut st).is_none() as u32;
        }
        eprintln!("sphere ({} tris) scale {scale} shift {shift}: escapes out of {n}: robust {robust}, obvhs {theirs:?} (vertex, vertex, edge midpoint, random edge point)", tris.len());
    }
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("sphere") { return sphere_escapes(); }
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
    let mut rays: Vec<Ray> = (0..n_rays)
        .map(|_| Ray {
            origin: Vec3::new(rng.range(-0.95, 0.95), rng.range(0.05, 1.9), rng.range(-0.95, 0.95)),
            dir: rng.direction(),
            t_max: f32::INFINITY,
        })
        .collect();
    if args.get(3).map(|s| s.as_str()) == Some("camera") {
        // The reference camera: eye (0, 1, 3.9) toward (0, 1, 0), vertical fov 39.3077 degrees.
        let n = (n_rays as f64).sqrt() as usize;
        let tan = (39.3077f32.to_radians() / 2.0).tan();
        rays.clear();
        for j in 0..n {
            for i in 0..n {
                let x = ((i as f32 + 0.5) / n as f32 * 2.0 - 1.0) * tan;
                let y = (1.0 - (j as f32 + 0.5) / n as f32 * 2.0) * tan;
                rays.push(Ray { origin: Vec3::new(0.0, 1.0, 3.9), dir: Vec3::new(x, y, -1.0).normalize(), t_max: f32::INFINITY });
            }
        }
        eprintln!("camera rays: {}", rays.len());
    }
    let qualities: Vec<BuildQuality> = match args.get(2).map(|s| s.as_str()) {
        Some("medium") => vec![BuildQuality::Medium],
        _ => BuildQuality::ALL.to_vec(),
    };
    for quality in qualities {
        let mut build = std::time::Duration::MAX;
        let mut accel = None;
        for _ in 0..3 {
            let t = cpu_seconds();
            accel = Some(Accel::build(&triangles, quality));
            build = build.min(std::time::Duration::from_secs_f64(cpu_seconds() - t));
        }
        let accel = accel.unwrap();
        eprintln!("{quality:?}: build {:.2} s, {:?}", build.as_secs_f64(), accel);
        for traversal in [Traversal::Robust, Traversal::Obvhs] {
          let (mut secs, mut osecs) = (f64::MAX, f64::MAX);
          let (mut stats, mut ostats, mut hits, mut occ) = Default::default();
          for _rep in 0..3 {
            stats = TraversalStats::default();
            let t = cpu_seconds();
            hits = 0;
            for r in &rays {
                hits += accel.intersect_with(r, traversal, &mut stats).is_some() as usize;
            }
            secs = secs.min(cpu_seconds() - t);
            let t = cpu_seconds();
            occ = 0;
            ostats = TraversalStats::default();
            for r in &rays {
                occ += accel.occluded_with(r, traversal, &mut ostats) as usize;
            }
            osecs = osecs.min(cpu_seconds() - t);
          }
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
