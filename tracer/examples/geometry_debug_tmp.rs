use glam::Vec3;
use tracer::geometry::*;
fn v(b: [u32; 3]) -> Vec3 { Vec3::from_array(b.map(f32::from_bits)) }
fn main() {
    let p = [v([1062413947, 1057128321, 3198242291]), v([1061894962, 1058252550, 3199631914]), v([1061108544, 1057424381, 3196402555])];
    let o = v([3189289118, 1065311373, 1035495222]);
    let d = v([1064749202, 3203316160, 3201709144]);
    let r = Ray { origin: o, dir: d, t_max: f32::INFINITY };
    println!("hit {:?} degenerate {}", intersect_triangle(&r, &p), is_degenerate(&p));
    let a = d.abs();
    let kz = if a.x > a.y { if a.x > a.z { 0 } else { 2 } } else if a.y > a.z { 1 } else { 2 };
    let kx = (kz + 1) % 3; let ky = (kx + 1) % 3;
    let (sx, sy, sz) = (-d[kx] / d[kz], -d[ky] / d[kz], 1.0 / d[kz]);
    let t: Vec<Vec3> = p.iter().map(|&q| { let w = q - o; Vec3::new(w[kx] + sx * w[kz], w[ky] + sy * w[kz], w[kz]) }).collect();
    let e0 = t[1].x * t[2].y - t[1].y * t[2].x;
    let e1 = t[2].x * t[0].y - t[2].y * t[0].x;
    let e2 = t[0].x * t[1].y - t[0].y * t[1].x;
    let det = e0 + e1 + e2;
    let ts = e0 * t[0].z * sz + e1 * t[1].z * sz + e2 * t[2].z * sz;
    let g = |n: f32| { let u = n * f32::EPSILON * 0.5; u / (1.0 - u) };
    let z: Vec<f32> = t.iter().map(|q| q.z * sz).collect();
    let max_zt = z.iter().fold(0f32, |m, z| m.max(z.abs()));
    let max_xt = t.iter().fold(0f32, |m, q| m.max(q.x.abs()));
    let max_yt = t.iter().fold(0f32, |m, q| m.max(q.y.abs()));
    let delta_z = g(3.0) * max_zt;
    let delta_x = g(5.0) * (max_xt + max_zt);
    let delta_y = g(5.0) * (max_yt + max_zt);
    let delta_e = 2.0 * (g(2.0) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    let max_e = e0.abs().max(e1.abs()).max(e2.abs());
    let delta_t = 3.0 * (g(3.0) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) / det.abs();
    println!("max x {max_xt} y {max_yt} z {max_zt}; delta_e {delta_e} delta_t {delta_t}; z {z:?}");
    println!("kz {kz} e {e0} {e1} {e2} det {det} ts {ts} t {}", ts / det);
}
