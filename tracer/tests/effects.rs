use glam::{Vec2, Vec3};
use tracer::geometry::{Accel, BuildQuality, TraversalStats, hit_point, spawn_ray, spawn_ray_to};

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn experiment(name: &str, toml: &str, light: Vec3, outside_env: bool) {
    let scene = tracer::scene::load_str(toml).unwrap();
    let accel = Accel::build(&scene.triangles, BuildQuality::default());
    let mut rng = Rng(1);
    let mut stats = TraversalStats::default();
    let (mut traced, mut occluded) = (0u64, 0u64);
    for t in &scene.triangles {
        let ng = t.area_vector().normalize();
        for k in 0..200 {
            let (mut b1, mut b2) = (rng.next(), rng.next());
            if b1 + b2 > 1.0 { b1 = 1.0 - b1; b2 = 1.0 - b2; }
            match k % 8 { 0 => b1 = 0.0, 1 => b2 = 0.0, 2 => b1 = 1.0 - b2, 3 => {b1 = 0.0; b2 = 0.0}, 4 => {b1 = 1.0; b2 = 0.0}, _ => {} }
            let p = hit_point(&t.p, b1, b2);
            let ray = if outside_env {
                let z = rng.next(); let phi = rng.next() * 6.2831853;
                let r = (1.0 - z * z).sqrt();
                let (a, b) = if ng.x.abs() > 0.5 { (Vec3::Y, ng.cross(Vec3::Y).normalize()) } else { (Vec3::X, ng.cross(Vec3::X).normalize()) };
                let u = ng.cross(b);
                let _ = a;
                let d = (u * (r * phi.cos()) + b * (r * phi.sin()) + ng * z).normalize();
                if d.dot(ng) <= 0.0 { continue; }
                spawn_ray(p, ng, d)
            } else {
                spawn_ray_to(p, ng, light, None)
            };
            traced += 1;
            if accel.occluded(&ray, &mut stats) { occluded += 1; }
        }
    }
    let _ = Vec2::ZERO;
    println!("{name}: {occluded} of {traced} occluded");
}

#[test]
fn exp() {
    let sphere = |sub: u32, r: f32, c: &str| format!("[camera]\nposition=[0,0,0]\nlook_at=[0,0,1]\n[[object]]\nshape=\"sphere\"\nradius={r}\ncenter={c}\nsubdivisions={sub}\ninward=true\nmaterial=\"m\"\n[materials.m]\ntype=\"diffuse\"\n");
    for (sub, r, c) in [(5, 1.0, "[0,0,0]"), (3, 1.0, "[0,0,0]"), (1, 1.0, "[0,0,0]"), (0, 1.0, "[0,0,0]"), (3, 1e-4, "[0,0,0]"), (3, 1e4, "[1e5,0,0]"), (3, 3.0, "[1e5,1e5,0]")] {
        let cv: Vec<f32> = c.trim_matches(['[', ']']).split(',').map(|x| x.parse().unwrap()).collect();
        experiment(&format!("sphere sub {sub} r {r} c {c} inside"), &sphere(sub, r, c), Vec3::new(cv[0], cv[1], cv[2]), false);
        experiment(&format!("sphere sub {sub} r {r} c {c} outside env"), &sphere(sub, r, c).replace("inward=true", "inward=false"), Vec3::ZERO, true);
    }
    let bx = "[camera]\nposition=[0,0,0]\nlook_at=[0,0,1]\n[[object]]\nshape=\"box\"\nmin=[-1.3,-0.7,-2.1]\nmax=[1.1,0.9,0.3]\ninward=true\nmaterial=\"m\"\n[materials.m]\ntype=\"diffuse\"\n";
    experiment("box inside", bx, Vec3::new(0.1, 0.2, -0.5), false);
    experiment("box outside env", &bx.replace("inward=true", "inward=false"), Vec3::ZERO, true);
}
