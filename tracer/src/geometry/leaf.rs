//! A leaf's triangles as the wide traversal tests them: the SIMD filter four at a time
//! (`quad.rs`), or eight, two groups in one step, where the box test's instructions have the
//! lanes (`quad_avx.rs`), then the scalar watertight test on the lanes it leaves.
//!
//! **Exactness.** Whatever the lanes, each candidate is offered to [`Closest`] lowest lane
//! first, with the SIMD test's own hit where that is the scalar test's result, else through
//! the scalar test; since [`Closest::offer`] keeps the closest hit with ties broken by
//! triangle index, the order of offers never changes the result, and an any-hit query stops at
//! the same triangle whether it came in a pair or a group. Counted work is the same too: a
//! pair counts what its two groups count one by one.

use super::bvh::Accel;
use super::closest::Closest;
use super::node8::BoxTest;
use super::quad::{LANES, LaneHits, Quad, QuadRay};
use super::triangle::ShearedRay;
use super::{Ray, TraversalStats};

impl Accel {
    /// Tests the `count` triangles of the leaf whose groups start at `first`: the SIMD filter
    /// four at a time (eight, two groups in one step, where `B` has the lanes), then the
    /// scalar test on the lanes it leaves. Returns whether any became the closest hit (with
    /// `ANY_HIT`, stops at the first). Every triangle up to where it stops counts as tested,
    /// filtered out or not, so pairs count what groups one by one count.
    ///
    /// # Safety
    /// `first` and `count` must be a leaf entry of this tree: the `index` and `count` of a lane
    /// of one of its `Node8`s whose count is not 0 (the groups `Bvh8::collapse` packed for it),
    /// which are read without a bounds check.
    #[inline(always)]
    pub(super) unsafe fn test_leaf<const ANY_HIT: bool, B: BoxTest>(
        &self,
        first: u32,
        count: u32,
        ray: &Ray,
        quad_ray: &QuadRay,
        closest: &mut Closest,
        stats: &mut TraversalStats,
    ) -> bool {
        let groups = (count as usize).div_ceil(LANES);
        let first = first as usize;
        debug_assert!(
            first + groups <= self.wide.quads.len(),
            "a leaf's groups were packed"
        );
        // SAFETY: a leaf's entry names the groups `Bvh8::collapse` packed for it: `first` is
        // where they start in `quads` and `count` the triangles they hold, four to a group, so
        // the `count.div_ceil(4)` groups from `first` were all pushed.
        let quads = unsafe { self.wide.quads.get_unchecked(first..first + groups) };
        let mut found = false;
        let mut g = 0;
        while g < groups {
            let step = if B::PAIRS && g + 1 < groups { 2 } else { 1 };
            let stop = if step == 2 {
                let hits = B::intersect_pair(quad_ray, &quads[g], &quads[g + 1]);
                self.offer_lanes::<ANY_HIT, 8>(&hits, &quads[g..g + 2], ray, closest, &mut found)
            } else {
                let hits = quad_ray.intersect(&quads[g]);
                self.offer_lanes::<ANY_HIT, LANES>(
                    &hits,
                    &quads[g..g + 1],
                    ray,
                    closest,
                    &mut found,
                )
            };
            if let Some(lane) = stop {
                // Only a leaf's last group is partial, so the groups before this step are
                // full: this counts what testing one triangle after another up to the stop
                // counts.
                stats.triangles += (g * LANES) as u64 + u64::from(lane) + 1;
                return true;
            }
            g += step;
        }
        // Every group tested: the leaf's triangles, counted once rather than group by group.
        stats.triangles += u64::from(count);
        found
    }

    /// Offers the candidate lanes of `hits` (lane `i` is lane `i % 4` of `groups[i / 4]`) to
    /// `closest`, lowest lane first: a lane settled in SIMD with its hit, the others through
    /// the scalar test. Sets `found` when one is kept; returns the lane where an any-hit query
    /// stops.
    #[inline(always)]
    fn offer_lanes<const ANY_HIT: bool, const N: usize>(
        &self,
        hits: &LaneHits<N>,
        groups: &[Quad],
        ray: &Ray,
        closest: &mut Closest,
        found: &mut bool,
    ) -> Option<u32> {
        let mut candidates = hits.candidates;
        while candidates != 0 {
            let lane = candidates.trailing_zeros();
            candidates &= candidates - 1;
            let group = &groups[lane as usize / LANES];
            let i = lane as usize % LANES;
            let original = group.original[i];
            let kept = if hits.exact & (1 << lane) != 0 {
                closest.offer_hit(hits.hit(lane as usize), original)
            } else {
                // The scalar test's set-up made here, for the few lanes the SIMD test leaves
                // it, rather than once per ray: the walk's set-up then stored it for every ray
                // (4.9 % of a Cornell box shadow ray's instructions). The same values: it is a
                // function of the ray alone.
                closest.offer(&ShearedRay::new(ray), &group.triangle(i), original)
            };
            if kept {
                *found = true;
                if ANY_HIT {
                    return Some(lane);
                }
                self.prefetch_hit(original);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::node8::WIDTH;
    use crate::geometry::{BoxSimd, BuildQuality, Ray};
    use crate::scene::Triangle;
    use glam::Vec3;

    #[test]
    fn leaves_of_five_to_eight_triangles_find_the_same_hits_through_avx_pairs_and_sse_groups() {
        // Long thin slivers crossing a small cube: their boxes overlap so much that obvhs's
        // collapse keeps leaves of up to eight, which the AVX traversal tests two groups at a
        // time and the SSE one group by group.
        let mut state = 0x0005_ca1e;
        let mut next = || crate::geometry::build::tests::next_signed(&mut state);
        let triangles: Vec<Triangle> = (0..600)
            .map(|_| {
                let a = Vec3::new(next(), next(), next());
                let d = Vec3::new(next(), next(), next()) * 3.0;
                let e = Vec3::new(next(), next(), next()) * 0.05;
                Triangle {
                    p: [a - d, a + d, a + e],
                    material: 0,
                }
            })
            .collect();
        let mut avx = Accel::build(&triangles, BuildQuality::Medium);
        let pairs = avx
            .wide
            .nodes
            .iter()
            .flat_map(|node| (0..WIDTH).map(|lane| node.count(lane)))
            .filter(|&c| c as usize > LANES)
            .count();
        assert!(
            pairs > 10,
            "only {pairs} leaves of more than four triangles"
        );
        if !avx.set_box_simd(BoxSimd::Avx) {
            eprintln!("skipped the comparison: this processor has no AVX");
            return;
        }
        let mut sse = avx.clone();
        assert!(sse.set_box_simd(BoxSimd::Sse));
        let (mut avx_stats, mut sse_stats) = (TraversalStats::default(), TraversalStats::default());
        let mut hits = 0;
        for i in 0..3000 {
            let origin = Vec3::new(next(), next(), next()) * 4.0;
            let aim = Vec3::new(next(), next(), next()) * 0.5;
            let ray = Ray {
                origin,
                dir: aim - origin,
                t_max: if i % 3 == 0 { 0.9 } else { f32::INFINITY },
            };
            let hit = avx.intersect(&ray, &mut avx_stats);
            assert_eq!(hit, sse.intersect(&ray, &mut sse_stats), "{ray:?}");
            assert_eq!(
                avx.occluded(&ray, &mut avx_stats),
                sse.occluded(&ray, &mut sse_stats),
                "{ray:?}"
            );
            assert_eq!(avx_stats, sse_stats, "the same work, ray {i}");
            hits += hit.is_some() as u32;
        }
        assert!(hits > 1000, "only {hits} hits");
    }

    #[test]
    fn prefetching_records_at_hits_changes_no_hit_even_for_records_too_short() {
        // The hint is given for every kept hit, at addresses computed from the records'
        // start: with records far too few for the triangles, most lie outside the slice, which
        // a prefetch must never read. Hits and counted work stay those of the plain tree.
        let v = |i: usize, j: usize| Vec3::new(i as f32, j as f32, ((i * 7 + j * 13) % 5) as f32);
        let triangles: Vec<Triangle> = (0..400)
            .flat_map(|k| {
                let (i, j) = (k % 20, k / 20);
                [
                    [v(i, j), v(i + 1, j), v(i + 1, j + 1)],
                    [v(i, j), v(i + 1, j + 1), v(i, j + 1)],
                ]
            })
            .map(|p| Triangle { p, material: 0 })
            .collect();
        let plain = Accel::build(&triangles, BuildQuality::Medium);
        let mut hinted = plain.clone();
        let records = [0u64; 3];
        hinted.prefetch_at_hits(&records, &records);
        let (mut a, mut b) = (TraversalStats::default(), TraversalStats::default());
        let mut hits = 0;
        for i in 0..400 {
            let (x, y) = ((i % 20) as f32 + 0.37, (i / 20) as f32 + 0.61);
            let ray = Ray {
                origin: Vec3::new(x, y, 10.0),
                dir: Vec3::new(0.013 * (i % 7) as f32, -0.011 * (i % 5) as f32, -1.0),
                t_max: f32::INFINITY,
            };
            let hit = plain.intersect(&ray, &mut a);
            assert_eq!(hit, hinted.intersect(&ray, &mut b), "{ray:?}");
            hits += hit.is_some() as u32;
        }
        assert_eq!(a, b);
        assert!(hits > 300, "only {hits} hits");
    }
}
