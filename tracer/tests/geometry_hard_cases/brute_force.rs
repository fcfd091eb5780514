//! The BVH against a brute-force loop over every triangle: random soups, every build quality,
//! and the dragon of `../shared/scenes`.

use super::*;

/// A triangle soup strategy: coordinates in [-10, 10], optionally snapped to a grid of 0.5 so
/// that vertices, planes and box faces coincide.
fn soup(snap: bool) -> impl Strategy<Value = Vec<Triangle>> {
    let coordinate = -10.0f32..10.0;
    let vertex = [coordinate.clone(), coordinate.clone(), coordinate].prop_map(move |c| {
        Vec3::from_array(c.map(|x| if snap { (x * 2.0).round() / 2.0 } else { x }))
    });
    let triangle =
        [vertex.clone(), vertex.clone(), vertex].prop_map(|p| Triangle { p, material: 0 });
    prop::collection::vec(triangle, 1..120)
}

fn direction_component() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => -1.0f32..1.0,
        1 => prop::sample::select(vec![0.0, -0.0, 1e-8, -1e-40, 1.0, -0.5]),
    ]
}

fn quality() -> impl Strategy<Value = BuildQuality> {
    prop::sample::select(BuildQuality::ALL.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn the_bvh_agrees_with_brute_force_on_random_soups(
        triangles in prop_oneof![soup(false), soup(true)],
        quality in quality(),
        rays in prop::collection::vec(
            ([-12.0f32..12.0, -12.0f32..12.0, -12.0f32..12.0],
             [direction_component(), direction_component(), direction_component()],
             prop_oneof![Just(f32::INFINITY), 0.1f32..30.0]),
            1..40,
        ),
    ) {
        let accel = Accel::build(&triangles, quality);
        for (origin, dir, t_max) in rays {
            let r = Ray { origin: Vec3::from_array(origin), dir: Vec3::from_array(dir), t_max };
            let brute = intersect_brute_force(&triangles, &r);
            prop_assert_eq!(closest(&accel, &r), brute, "{:?}", r);
            let occluded = accel.occluded(&r, &mut TraversalStats::default());
            prop_assert_eq!(occluded, occluded_brute_force(&triangles, &r));
            prop_assert!(!occluded || brute.is_some());
        }
    }
}

#[test]
fn the_bvh_agrees_with_brute_force_on_the_dragon() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/scenes/stanford-dragon/cornell-dragon.obj");
    if !path.exists() {
        eprintln!("skipped: {} is absent (see DEVELOPERS.md)", path.display());
        return;
    }
    let (models, _) = tobj::load_obj(&path, &tobj::GPU_LOAD_OPTIONS).expect("the dragon loads");
    let mut triangles = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let v = |i: u32| Vec3::from_slice(&m.positions[3 * i as usize..3 * i as usize + 3]);
        for f in m.indices.chunks_exact(3) {
            triangles.push(Triangle {
                p: [v(f[0]), v(f[1]), v(f[2])],
                material: 0,
            });
        }
    }
    assert!(triangles.len() > 800_000);
    let accel = Accel::build(&triangles, BuildQuality::Medium);
    let mut rng = Rng(7);
    let mut hits = 0;
    for _ in 0..100 {
        // From inside the Cornell box toward the dragon's region.
        let origin = Vec3::new(
            rng.range(-0.9, 0.9),
            rng.range(0.1, 1.9),
            rng.range(-0.9, 0.9),
        );
        let target = Vec3::new(
            rng.range(-0.8, 0.8),
            rng.range(0.0, 1.2),
            rng.range(-0.4, 0.4),
        );
        let r = ray(origin, target - origin);
        let brute = intersect_brute_force(&triangles, &r);
        assert_eq!(closest(&accel, &r), brute, "{r:?}");
        hits += brute.is_some() as u32;
    }
    assert!(hits > 50);
}
