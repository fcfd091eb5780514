//! The tree's own tests: empty and degenerate scenes, a root leaf, original indices, a
//! deterministic build, and obvhs's traversal agreeing with ours on interior hits.

use super::*;
use crate::geometry::intersect_brute_force;

fn triangle(p: [Vec3; 3]) -> Triangle {
    Triangle { p, material: 0 }
}

/// A bumpy grid of `n * n` quads, two triangles each, in the plane z = 0 (up to bumps).
fn grid(n: usize) -> Vec<Triangle> {
    let v = |i: usize, j: usize| {
        let bump = ((i * 7 + j * 13) % 5) as f32 * 0.01;
        Vec3::new(i as f32, j as f32, bump)
    };
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            out.push(triangle([v(i, j), v(i + 1, j), v(i + 1, j + 1)]));
            out.push(triangle([v(i, j), v(i + 1, j + 1), v(i, j + 1)]));
        }
    }
    out
}

fn down(x: f32, y: f32) -> Ray {
    Ray {
        origin: Vec3::new(x, y, 5.0),
        dir: -Vec3::Z,
        t_max: f32::INFINITY,
    }
}

#[test]
fn an_empty_or_all_degenerate_scene_misses_every_ray() {
    let degenerate = vec![triangle([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]); 3];
    for triangles in [Vec::new(), degenerate] {
        let accel = Accel::build(&triangles, BuildQuality::Medium);
        let mut stats = TraversalStats::default();
        for traversal in Traversal::ALL {
            assert_eq!(
                accel.intersect_with(&down(0.5, 0.0), traversal, &mut stats),
                None
            );
            assert!(!accel.occluded_with(&down(0.5, 0.0), traversal, &mut stats));
        }
        assert_eq!(stats, TraversalStats::default(), "no tree, no work");
    }
}

#[test]
fn a_single_triangle_is_a_root_leaf_and_costs_one_box_and_one_test() {
    let flat = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let accel = Accel::build(&[triangle(flat)], BuildQuality::Medium);
    assert_eq!((accel.node_count(), accel.depth()), (1, 1));
    let mut stats = TraversalStats::default();
    let hit = accel
        .intersect(&down(0.25, 0.25), &mut stats)
        .expect("inside");
    assert_eq!((hit.triangle, hit.t), (0, 5.0));
    assert_eq!(
        stats,
        TraversalStats {
            nodes: 1,
            triangles: 1
        }
    );
}

#[test]
fn hits_report_the_original_triangle_index_and_degenerates_are_skipped() {
    let mut triangles = grid(8);
    triangles.insert(0, triangle([Vec3::ONE; 3]));
    let accel = Accel::build(&triangles, BuildQuality::Medium);
    assert_eq!(accel.leaf_entries(), triangles.len() - 1);
    for (x, y) in [(0.75, 0.25), (5.2, 3.9), (7.9, 7.95)] {
        let mut stats = TraversalStats::default();
        let hit = accel
            .intersect(&down(x, y), &mut stats)
            .expect("inside the grid");
        assert_eq!(Some(hit), intersect_brute_force(&triangles, &down(x, y)));
        let p = hit.point(&triangles[hit.triangle as usize].p);
        assert!(
            (p.x - x).abs() < 1e-5 && (p.y - y).abs() < 1e-5,
            "{p} for {x},{y}"
        );
        assert!(stats.nodes > 1 && stats.triangles >= 1);
    }
}

#[test]
fn building_twice_gives_the_same_tree() {
    let triangles = grid(30);
    for quality in BuildQuality::ALL {
        let a = Accel::build(&triangles, quality);
        let b = Accel::build(&triangles, quality);
        let bytes = |accel: &Accel| bytemuck_nodes(&accel.binary_tree().bvh).to_vec();
        assert_eq!(bytes(&a), bytes(&b), "{quality:?}");
        assert_eq!(a.binary_tree().original, b.binary_tree().original);
    }
}

fn bytemuck_nodes(bvh: &Bvh2) -> Vec<u32> {
    bvh.nodes
        .iter()
        .flat_map(|n| {
            let (min, max) = (n.aabb().min.to_array(), n.aabb().max.to_array());
            let floats = min.into_iter().chain(max).map(f32::to_bits);
            floats
                .chain([n.prim_count, n.first_index])
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn obvhs_traversal_finds_the_same_interior_hits_with_consistent_barycentrics() {
    let triangles = grid(8);
    let accel = Accel::build(&triangles, BuildQuality::Medium);
    let mut stats = TraversalStats::default();
    for (x, y) in [(0.7, 0.2), (5.3, 3.9), (2.6, 6.1)] {
        let ours = accel.intersect(&down(x, y), &mut stats).expect("inside");
        let theirs = accel
            .intersect_with(&down(x, y), Traversal::Obvhs, &mut stats)
            .expect("inside");
        assert_eq!(ours.triangle, theirs.triangle);
        assert!((ours.t - theirs.t).abs() < 1e-5);
        assert!((ours.b1 - theirs.b1).abs() < 1e-5 && (ours.b2 - theirs.b2).abs() < 1e-5);
    }
}

#[test]
fn a_build_for_rendering_is_the_full_build_without_its_binary_tree() {
    // A bumpy grid with degenerate triangles among its faces (left out of both builds), and
    // long slivers whose boxes overlap (leaves of up to eight triangles, two groups each).
    let mut mixed = grid(24);
    for k in (0..mixed.len()).step_by(7) {
        let p = mixed[k].p[0];
        mixed.insert(k, triangle([p, p, p + Vec3::X]));
    }
    let mut state = 0x1ea0_u64;
    let mut next = || crate::geometry::build::tests::next_signed(&mut state);
    let slivers: Vec<Triangle> = (0..500)
        .map(|_| {
            let a = Vec3::new(next(), next(), next());
            let d = Vec3::new(next(), next(), next()) * 3.0;
            triangle([a - d, a + d, a + Vec3::splat(0.05)])
        })
        .collect();
    // Degenerate triangles alone: no tree at all, and still none kept beside it.
    let degenerate = vec![triangle([Vec3::ZERO, Vec3::ZERO, Vec3::X]); 5];
    for triangles in [mixed, slivers, degenerate] {
        for quality in BuildQuality::ALL {
            let mut full = Accel::build(&triangles, quality);
            let lean = Accel::build_for_rendering(&triangles, quality);
            assert!(full.has_binary_tree() && !lean.has_binary_tree());
            assert_eq!(wide_bits(&lean), wide_bits(&full), "{quality:?}");
            assert_eq!(
                (lean.node_count(), lean.leaf_entries(), lean.depth()),
                (full.node_count(), full.leaf_entries(), full.depth())
            );
            assert!(full.release_binary_tree());
            assert_eq!(wide_bits(&lean), wide_bits(&full));
        }
    }
}

/// Every bit of the wide tree: its nodes' boxes, children and counts, and its groups'
/// vertices, entries and input triangles.
fn wide_bits(accel: &Accel) -> Vec<u32> {
    let nodes = accel.wide.nodes.iter().flat_map(|n| {
        let boxes = n.bounds.iter().flatten().map(|b| b.to_bits());
        let lanes = n.refs.iter().copied();
        boxes
            .chain(lanes)
            .chain([u32::from(n.valid), u32::from(n.children)])
            .collect::<Vec<_>>()
    });
    let quads = accel.wide.quads.iter().flat_map(|q| {
        let vertices =
            q.p.iter()
                .flatten()
                .flat_map(|lanes| lanes.to_array().map(f32::to_bits));
        vertices
            .chain(q.original)
            .chain([q.entry, q.valid, q.len])
            .collect::<Vec<_>>()
    });
    let depth = [accel.wide.depth as u32];
    nodes.chain(quads).chain(depth).collect()
}
