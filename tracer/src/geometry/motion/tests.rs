//! The swept boxes against placed vertices, and the accelerator against brute force.

use super::bounds::swept_bounds;
use super::*;
use crate::geometry::intersect_brute_force;
use crate::geometry::offset::SurfacePoint;
use crate::scene::{TransformKey, Triangle};

/// A splitmix64 stream, so every run checks the same cases.
struct Stream(u64);

impl Stream {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

/// Three keys, the middle one turning or not, scales of one sign per axis.
fn track(s: &mut Stream, turn: bool) -> TransformTrack {
    let sign = s.vec(-1.0, 1.0).signum();
    let keys = (0..3)
        .map(|i| TransformKey {
            frame: 2 * i,
            scale: sign * s.vec(0.3, 3.0),
            rotate_degrees: if turn || i == 0 {
                s.vec(-400.0, 400.0)
            } else {
                Vec3::ZERO
            },
            translate: s.vec(-5.0, 5.0),
        })
        .collect();
    let mut track = TransformTrack::new(keys).expect("keys differ");
    if !turn {
        // Every key with the first key's angles: segments that do not turn.
        let first = track.keys()[0].rotate_degrees;
        let keys = track
            .keys()
            .iter()
            .map(|k| TransformKey {
                rotate_degrees: first,
                ..*k
            })
            .collect();
        track = TransformTrack::new(keys).expect("keys differ");
    }
    track
}

fn triangles(s: &mut Stream, n: usize) -> Vec<Triangle> {
    (0..n)
        .map(|_| {
            let at = s.vec(-1.0, 1.0) + Vec3::new(0.5, 0.0, 0.0);
            Triangle {
                p: [0, 1, 2].map(|_| at + s.vec(-0.3, 0.3)),
                material: 0,
            }
        })
        .collect()
}

#[test]
fn swept_boxes_hold_the_object_at_every_time_of_their_segment() {
    let mut s = Stream(7);
    for turn in [false, true] {
        for _ in 0..40 {
            let track = track(&mut s, turn);
            let v: Vec<[Vec3; 3]> = triangles(&mut s, 20).iter().map(|t| t.p).collect();
            let bounds = swept_bounds(&track, &v);
            for step in 0..=200 {
                let time = -1.0 + 6.0 * f64::from(step) / 200.0;
                let b = &bounds[track.segment(time)];
                let placement = track.at(time);
                for p in v.iter().flatten() {
                    let w = placement.point(p.as_dvec3()).as_vec3();
                    assert!(
                        w.cmpge(b.min).all() && w.cmple(b.max).all(),
                        "turn {turn}, time {time}: {w} outside {b:?}"
                    );
                }
            }
        }
    }
}

/// `count` objects of 30 triangles each; beyond three, in twin pairs of the same triangles and
/// track, far apart in index so that the tree may meet them in either order.
fn objects(s: &mut Stream, count: usize, turn: bool) -> Vec<MovingObject> {
    let mut objects: Vec<MovingObject> = (0..count)
        .map(|_| MovingObject {
            triangles: triangles(s, 30),
            attributes: Vec::new(),
            track: track(s, turn),
        })
        .collect();
    if count > 3 {
        let half = count / 2;
        for k in 0..half {
            objects[half + k] = objects[k].clone();
        }
    }
    objects
}

/// A time of the tracks' range and a little beyond; a quarter of them on a key, where one
/// segment ends and the next begins.
fn time(s: &mut Stream) -> f64 {
    if s.unit() < 0.25 {
        f64::from(2 * (s.unit() * 3.0) as u32)
    } else {
        f64::from(s.range(-0.5, 4.5))
    }
}

/// A ray from near the objects, most aimed at a vertex or an edge of some triangle where it is
/// at `time`, where rounding decides; the rest anywhere near.
fn aimed_ray(s: &mut Stream, objects: &[MovingObject], time: f64) -> Ray {
    let origin = s.vec(-12.0, 12.0);
    let count = objects.len();
    let object = &objects[(s.unit() * count as f32) as usize % count];
    let t = &object.triangles[(s.unit() * 30.0) as usize % 30];
    let (a, b) = (s.unit(), s.unit());
    let on = match (s.unit() * 3.0) as u32 {
        0 => t.p[0],
        1 => t.p[1] + a * (t.p[2] - t.p[1]),
        _ => s.vec(-6.0, 6.0) + Vec3::splat(b),
    };
    let target = object.track.at(time).point(on.as_dvec3()).as_vec3();
    Ray {
        origin,
        dir: target - origin,
        t_max: f32::INFINITY,
    }
}

/// A point's coordinates, bound, normal and spawned origins as bits, signed zeros apart.
fn point_bits(point: &SurfacePoint) -> Vec<u32> {
    let mut vectors = vec![point.p, point.error, point.normal];
    vectors.extend(point.spawn.into_iter().flatten());
    vectors
        .iter()
        .flat_map(|v| v.to_array().map(f32::to_bits))
        .collect()
}

/// The accelerator keeps each moving triangle's corners and unit normal under the index the
/// scene gives it: every triangle of every object, the normal [`object_normal`] of its own
/// corners to the bit.
#[test]
fn each_moving_triangle_keeps_its_own_corners_and_normal() {
    let mut s = Stream(5);
    let objects = objects(&mut s, 12, true);
    let motion = MotionAccel::build(&objects, 3, BuildQuality::Medium);
    for (object, o) in objects.iter().enumerate() {
        for (triangle, t) in o.triangles.iter().enumerate() {
            let (v, normal) = motion.triangle(MovingTriangle { object, triangle });
            assert_eq!(v, &t.p, "object {object}, triangle {triangle}");
            let bits = |n: DVec3| n.to_array().map(f64::to_bits);
            assert_eq!(bits(normal), bits(object_normal(&t.p)));
        }
    }
}

/// Three objects, as most scenes move (tried in turn), twelve (a tree, the path's placements
/// made as it starts) and forty (a tree, placements made when first needed), where the tree
/// over their boxes prunes (its nodes padded and spanning times, `tree.rs`) and walks them in
/// its own order: every hit is brute force's. Beyond three, every object has a twin of the
/// same triangles and track, so that every hit on one is a tie between two objects, which the
/// lower index must win whichever the walk reaches first; and a still hit passed in, in front
/// of, level with or behind the moving one, must win or lose as trying them in order did.
#[test]
fn moving_objects_are_hit_as_brute_force_over_their_triangles_in_object_space() {
    let mut s = Stream(11);
    let mut hits = 0;
    for (count, worlds) in [(3, 20), (12, 6), (40, 4)] {
        for turn in [false, true] {
            for _ in 0..worlds {
                let objects = objects(&mut s, count, turn);
                let motion = MotionAccel::build(&objects, 5, BuildQuality::Medium);
                for _ in 0..300 {
                    let time = time(&mut s);
                    let moment = motion.moment(time);
                    let ray = aimed_ray(&mut s, &objects, time);
                    let mut stats = TraversalStats::default();
                    let found =
                        motion.closest::<false>(&moment, &ray, None, Traversal::Robust, &mut stats);
                    // Brute force: every object's every triangle against the ray in its space.
                    let mut expected: Option<Hit> = None;
                    for (i, object) in objects.iter().enumerate() {
                        let local = to_object(&object.track.at(time), &ray);
                        if let Some(h) = intersect_brute_force(&object.triangles, &local)
                            && expected.is_none_or(|e| h.t < e.t)
                        {
                            let first = 5 + 30 * i as u32;
                            expected = Some(Hit {
                                triangle: first + h.triangle,
                                ..h
                            });
                        }
                    }
                    assert_eq!(
                        found, expected,
                        "{count} objects, turn {turn}, time {time}, {ray:?}"
                    );
                    let occluded = motion.occluded(&moment, &ray, Traversal::Robust, &mut stats);
                    assert_eq!(occluded, expected.is_some());
                    if let Some(e) = expected {
                        // The hit's point, placed with the normal the accelerator keeps for its
                        // triangle, is the one placed from the triangle alone, bit for bit.
                        let at = motion.locate(e.triangle).expect("a moving triangle's hit");
                        let object = &objects[at.object];
                        let alone = placed_point(
                            &object.track.at(time),
                            &object.triangles[at.triangle].p,
                            e.b1,
                            e.b2,
                        );
                        assert_eq!(
                            point_bits(&motion.surface(&moment, at, &e)),
                            point_bits(&alone)
                        );
                        // Numbered below every moving triangle: level, the still hit stays.
                        let t = [e.t, 0.5 * e.t, 2.0 * e.t][(s.unit() * 3.0) as usize % 3];
                        let still = Hit {
                            t,
                            triangle: 4,
                            b1: 0.25,
                            b2: 0.25,
                        };
                        let found = motion.closest::<false>(
                            &moment,
                            &ray,
                            Some(still),
                            Traversal::Robust,
                            &mut stats,
                        );
                        let wanted = if e.t < t { e } else { still };
                        assert_eq!(found, Some(wanted), "{count} objects, still hit at {t}");
                        // Nothing of the objects lies before their closest hit.
                        let short = Ray { t_max: e.t, ..ray };
                        assert!(!motion.occluded(&moment, &short, Traversal::Robust, &mut stats));
                    }
                    hits += expected.is_some() as u32;
                }
            }
        }
    }
    assert!(
        hits > 4000,
        "{hits} hits: the rays must find the objects often"
    );
}

/// What a shadow query finds depends on the order objects are tried in (its first hit must be
/// certain, the later ones need not be), so the tree gathers a shadow query's candidates and
/// tries them in object order. Here the same twelve objects (six twin pairs) with their tree
/// and tried in turn without it, by both robust traversals, with and without a still hit
/// passed in: every query, closest, certain-first and any-hit, answers the same.
#[test]
fn the_tree_answers_every_query_as_the_objects_tried_in_turn() {
    let mut s = Stream(23);
    for turn in [false, true] {
        for _ in 0..8 {
            let objects = objects(&mut s, 12, turn);
            let with_tree = MotionAccel::build(&objects, 5, BuildQuality::Medium);
            assert!(!with_tree.tree.is_flat(), "twelve objects get a tree");
            let in_turn = MotionAccel {
                tree: ObjectTree::default(),
                ..with_tree.clone()
            };
            for _ in 0..200 {
                let time = time(&mut s);
                let mut ray = aimed_ray(&mut s, &objects, time);
                // Half the rays end just past their closest hit, which a certain query may
                // then not count: where the order of trying objects decides.
                let mut stats = TraversalStats::default();
                let moment = in_turn.moment(time);
                let closest =
                    in_turn.closest::<false>(&moment, &ray, None, Traversal::Robust, &mut stats);
                if let Some(hit) = closest
                    && s.unit() < 0.5
                {
                    ray.t_max = hit.t.next_up().next_up();
                }
                let still = (s.unit() < 0.5).then(|| Hit {
                    t: s.range(0.2, 1.5),
                    triangle: 4,
                    b1: 0.25,
                    b2: 0.25,
                });
                for traversal in [Traversal::Robust, Traversal::RobustBinary] {
                    let mut stats = TraversalStats::default();
                    let [a, b] = [&with_tree, &in_turn].map(|motion| {
                        let moment = motion.moment(time);
                        (
                            motion.closest::<true>(&moment, &ray, still, traversal, &mut stats),
                            motion.closest::<false>(&moment, &ray, still, traversal, &mut stats),
                            motion.occluded(&moment, &ray, traversal, &mut stats),
                        )
                    });
                    assert_eq!(a, b, "turn {turn}, time {time}, {traversal:?}, {ray:?}");
                }
            }
        }
    }
}

/// The swept boxes' test is conservative at their very faces, edges and corners, at every
/// scale and distance: a ray whose segment ends exactly on a box (its origin and target on a
/// grid of one power of two, so that the direction between them is exact and the target is
/// reached at `t = 1` exactly) passes the test with `t_max = 1`, whether it comes from far away,
/// from inside, along a face (directions with zero components, `+0.0` and `-0.0`), or toward a
/// corner; and a box wholly behind the origin, or beyond a segment's end, never does.
#[test]
fn the_swept_box_test_passes_every_ray_that_ends_on_a_box_at_every_scale() {
    let mut s = Stream(23);
    let grid = |s: &mut Stream, reach: f32| (s.range(-reach, reach)).round();
    let grid_point =
        |s: &mut Stream, reach: f32| Vec3::new(grid(s, reach), grid(s, reach), grid(s, reach));
    let (mut passed, mut behind) = (0, 0);
    for exponent in [-40, -20, -7, 0, 9, 20, 40] {
        let unit = 2f32.powi(exponent);
        for _ in 0..400 {
            let (a, b) = (grid_point(&mut s, 1000.0), grid_point(&mut s, 1000.0));
            let (min, max) = (a.min(b), a.max(b));
            let swept = SweptBox::unpadded(min * unit, max * unit);
            // A target on the box's boundary: each coordinate at a face or between, at least
            // one at a face.
            let mut target = Vec3::ZERO;
            for axis in 0..3 {
                target[axis] = match (s.unit() * 3.0) as u32 {
                    0 => min[axis],
                    1 => max[axis],
                    _ => min[axis] + (s.unit() * (max[axis] - min[axis])).floor(),
                };
            }
            let face = (s.unit() * 3.0) as usize % 3;
            target[face] = if s.unit() < 0.5 { min[face] } else { max[face] };
            // Origins near and far (up to 2^22 units away), some sharing coordinates with
            // the target (the ray then lies along the face's plane on that axis).
            let far = [10.0, 1e4, 4e6][(s.unit() * 3.0) as usize % 3];
            let mut origin = grid_point(&mut s, far);
            for axis in 0..3 {
                if s.unit() < 0.2 {
                    origin[axis] = target[axis];
                }
            }
            let mut dir = (target - origin) * unit;
            if dir == Vec3::ZERO {
                continue;
            }
            for axis in 0..3 {
                if dir[axis] == 0.0 && s.unit() < 0.5 {
                    dir[axis] = -0.0;
                }
            }
            let ray = Ray {
                origin: origin * unit,
                dir,
                t_max: 1.0,
            };
            assert_eq!(
                ray.origin + ray.dir,
                target * unit,
                "the grid keeps the sums exact"
            );
            let test = SweptRay::new(&ray);
            assert!(
                swept.may_hit(&test, 1.0) && swept.may_hit(&test, f32::INFINITY),
                "2^{exponent}: {ray:?} ends on {swept:?}"
            );
            passed += 1;
            // The same box seen from beyond its far side along x, going away from it; and
            // from before its near side, the segment stopping half way there (its near
            // distance about two, far above any rounding): neither may pass.
            let away = Ray {
                origin: Vec3::new(max.x + 1.0 + far, origin.y, origin.z) * unit,
                dir: Vec3::new(unit, dir.y, dir.z),
                t_max: f32::INFINITY,
            };
            let gap = 2.0 + (s.unit() * far).floor();
            let short = Ray {
                origin: Vec3::new(min.x - gap, origin.y, origin.z) * unit,
                dir: Vec3::new((gap / 2.0).floor(), dir.y / unit, dir.z / unit) * unit,
                t_max: 1.0,
            };
            for (missing, t_max) in [(away, f32::INFINITY), (short, 1.0)] {
                assert!(
                    !swept.may_hit(&SweptRay::new(&missing), t_max),
                    "2^{exponent}: {missing:?} never reaches {swept:?}"
                );
            }
            behind += 1;
        }
    }
    assert!(passed > 2500 && behind > 2500, "{passed} {behind}");
}
