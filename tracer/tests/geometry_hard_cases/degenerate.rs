//! Triangles without area, exactly or nearly: never hit, never a NaN, whatever the scale.

use super::*;

#[test]
fn degenerate_triangles_are_never_hit_and_never_give_nan() {
    let mut rng = Rng(6);
    let tri = |p: [Vec3; 3]| Triangle { p, material: 0 };
    // Exactly degenerate in f32: small integer coordinates, scaled by powers of two and moved by
    // integers, so every coordinate and product is exact.
    let int = |rng: &mut Rng| rng.index(17) as f32 - 8.0;
    let int_vec = |rng: &mut Rng| Vec3::new(int(rng), int(rng), int(rng));
    let mut degenerate = Vec::new();
    for _ in 0..200 {
        let a = int_vec(&mut rng);
        let d = [int_vec(&mut rng), Vec3::X, Vec3::new(1.0, 2.0, 3.0)][rng.index(3)];
        let (k1, k2) = (int(&mut rng), [1000.0, 1.0 / 1024.0, -3.0][rng.index(3)]);
        let shape = match rng.index(5) {
            0 => [a, a, a],              // a point
            1 => [a, a, a + d],          // repeated vertex
            2 => [a, a + d, a + d * k1], // collinear
            3 => [a, a + d * k2, a + d], // needle: a vertex very close to another
            _ => [a + d, a, a],          // repeated, other order
        };
        let power = [1.0, 1.0 / 1048576.0, 1048576.0][rng.index(3)];
        degenerate.push(tri(shape.map(|v| v * power)));
    }
    // Rays aimed at a vertex, a midpoint, or a point along the segment of each.
    let aimed_at = |t: &Triangle, rng: &mut Rng| {
        let target = match rng.index(3) {
            0 => t.p[rng.index(3)],
            1 => (t.p[0] + t.p[2]) * 0.5,
            _ => t.p[0] + (t.p[2] - t.p[0]) * rng.unit(),
        };
        let dir = rng.direction();
        let scale = t.p[0].abs().max(t.p[2].abs()).max_element().max(1e-3);
        ray(target - dir * scale * 2.0, dir)
    };
    for t in &degenerate {
        assert!(is_degenerate(&t.p), "{:?}", t.p);
        for _ in 0..20 {
            let r = aimed_at(t, &mut rng);
            assert_eq!(intersect_triangle(&r, &t.p), None, "{:?} hit by {r:?}", t.p);
        }
    }
    let only = Accel::build(&degenerate, BuildQuality::Medium);
    assert_eq!(
        only.node_count(),
        0,
        "degenerate triangles stay out of the tree"
    );

    // Mixed with real triangles, hits never report a degenerate one.
    let mut mixed = quad_grid(8).triangles();
    let first_degenerate = mixed.len() as u32;
    mixed.extend(degenerate.iter().copied());
    let accel = Accel::build(&mixed, BuildQuality::Medium);
    for k in 0..20_000 {
        let r = if k % 2 == 0 {
            let origin = Vec3::new(
                rng.range(0.0, 8.0),
                rng.range(0.0, 8.0),
                rng.range(-3.0, 3.0),
            );
            ray(origin, rng.direction())
        } else {
            aimed_at(&degenerate[rng.index(degenerate.len())], &mut rng)
        };
        if let Some(hit) = closest(&accel, &r) {
            assert!(hit.triangle < first_degenerate, "{hit:?}");
        }
    }

    // Slivers of tiny but nonzero area may be hit; when they are, every number is sane.
    let mut hits = 0;
    for _ in 0..20_000 {
        let a = rng.direction() * rng.range(0.0, 10.0);
        let b = a + rng.direction() * rng.range(1e-3, 10.0);
        let along = a + (b - a) * rng.range(-2.0, 2.0);
        let off = rng.direction() * [1e-3, 1e-5, 1e-7, 1e-12, 1e-30, 0.0][rng.index(6)];
        let p = [a, b, along + off];
        // Aim inside the sliver (up to rounding): a random convex combination of its vertices.
        let w = Vec3::new(rng.unit(), rng.unit(), rng.unit());
        let w = w / (w.x + w.y + w.z);
        let target = p[0] * w.x + p[1] * w.y + p[2] * w.z;
        let dir = rng.direction();
        let r = ray(target - dir * 5.0, dir);
        if let Some(h) = intersect_triangle(&r, &p) {
            hits += 1;
            let bs = [h.b0, h.b1, h.b2];
            assert!(h.t.is_finite() && h.t > 0.0, "{h:?} for {p:?}");
            assert!(
                bs.iter().all(|b| (0.0..=1.000_001).contains(b)),
                "{h:?} for {p:?}"
            );
            assert!(
                (bs.iter().sum::<f32>() - 1.0).abs() < 1e-5,
                "{h:?} for {p:?}"
            );
        }
    }
    assert!(
        hits > 1_000,
        "{hits} slivers hit: too few for the checks above to mean much"
    );
}
