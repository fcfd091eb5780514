//! Several rays through the wide tree at once, one node each in turn, so that their cache
//! misses overlap.
//!
//! Why: on large meshes the single-ray traversal waits on memory one node at a time, since a
//! node's address is known only once its parent is tested. Rays of different paths are
//! independent, so while one ray waits on the node it just asked for (`prefetch_children`),
//! the others can test theirs: `K` rays in turn keep up to `K` misses in flight where one ray
//! keeps one.
//!
//! **Exactness.** Each ray's walk is the single-ray walk of `wide.rs` step for step (the same
//! box tests, the same order of leaves and postponed boxes, the same culling), only interleaved
//! with other rays' walks; rays share nothing but the tree, which they only read. So each ray's
//! hit is the single-ray traversal's, bit for bit, and so are the counted tests.

use super::bvh::{Accel, Closest};
#[cfg(target_arch = "x86_64")]
use super::node8::Avx;
use super::node8::{BoxTest, Node8, Portable, WIDTH, WideRay};
use super::quad::QuadRay;
use super::traverse::FAR_SCALE;
use super::triangle::ShearedRay;
use super::wide::BoxSimd;
use super::{Hit, Ray, TraversalStats};
use std::mem::MaybeUninit;

/// Postponed boxes one ray may hold: seven per level, as many levels as `wide.rs` holds in
/// place. Deeper trees take the single-ray traversal.
const STACK: usize = (WIDTH - 1) * 30;

#[derive(Clone, Copy)]
struct StackEntry {
    node: u32,
    t_near: f32,
}

/// One ray's walk, paused between nodes.
struct Walk {
    wide: WideRay,
    sheared: ShearedRay,
    quad_ray: QuadRay,
    closest: Closest,
    /// The node to test next.
    node: u32,
    len: usize,
    stack: [MaybeUninit<StackEntry>; STACK],
}

impl Walk {
    fn new(ray: &Ray) -> Self {
        let sheared = ShearedRay::new(ray);
        Walk {
            wide: WideRay::new(ray),
            quad_ray: QuadRay::new(&sheared),
            sheared,
            closest: Closest::new(ray, false),
            node: 0,
            len: 0,
            stack: [MaybeUninit::uninit(); STACK],
        }
    }
}

impl Accel {
    /// The closest hits of `rays`, each what [`Accel::intersect`] finds, bit for bit; the rays
    /// are walked `K` at a time, in turn.
    pub fn intersect_batch<const K: usize>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        assert!((1..=64).contains(&K), "1 to 64 walks at a time");
        if self.wide.nodes.is_empty() || self.wide.depth * (WIDTH - 1) > STACK {
            for (ray, hit) in rays.iter().zip(hits.iter_mut()) {
                *hit = self.intersect(ray, stats);
            }
            return;
        }
        let mut walks = Vec::with_capacity(K);
        for (rays, hits) in rays.chunks(K).zip(hits.chunks_mut(K)) {
            walks.clear();
            walks.extend(rays.iter().map(Walk::new));
            #[cfg(target_arch = "x86_64")]
            if self.wide.simd == BoxSimd::Avx {
                // SAFETY: `simd` is `Avx` only where the processor has AVX (`wide.rs`).
                unsafe { self.batch_avx(&mut walks, hits, stats) };
                continue;
            }
            self.batch_with::<Portable>(&mut walks, hits, stats);
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline(never)]
    unsafe fn batch_avx(
        &self,
        walks: &mut [Walk],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) {
        self.batch_with::<Avx>(walks, hits, stats);
    }

    #[inline(always)]
    fn batch_with<B: BoxTest>(
        &self,
        walks: &mut [Walk],
        hits: &mut [Option<Hit>],
        stats: &mut TraversalStats,
    ) {
        // The walks still going, as a bit set (K is at most 64).
        let mut active: u64 = if walks.len() == 64 {
            !0
        } else {
            (1u64 << walks.len()) - 1
        };
        while active != 0 {
            let mut left = active;
            while left != 0 {
                let w = left.trailing_zeros() as usize;
                left &= left - 1;
                if self.step::<B>(&mut walks[w], stats) {
                    hits[w] = walks[w].closest.best;
                    active &= !(1u64 << w);
                }
            }
        }
    }

    /// Tests `walk`'s node and moves it to its next one; returns whether the walk has ended.
    /// The body of `wide.rs`'s loop, for a closest-hit query.
    #[inline(always)]
    fn step<B: BoxTest>(&self, walk: &mut Walk, stats: &mut TraversalStats) -> bool {
        let nodes = &self.wide.nodes;
        let node: &Node8 = &nodes[walk.node as usize];
        let cull = |closest: &Closest| closest.t_max() * FAR_SCALE;
        stats.nodes += u64::from(node.children);
        let (mut entered, t_near) = B::enter(&walk.wide, node, cull(&walk.closest));
        self.prefetch_children(node, entered);
        let mut order = [(0usize, 0f32); WIDTH];
        let mut n = 0;
        while entered != 0 {
            let lane = entered.trailing_zeros() as usize;
            entered &= entered - 1;
            let mut k = n;
            while k > 0 && order[k - 1].1 > t_near[lane] {
                order[k] = order[k - 1];
                k -= 1;
            }
            order[k] = (lane, t_near[lane]);
            n += 1;
        }
        let mut next = None;
        let mut postponed = [(0u32, 0f32); WIDTH];
        let mut p = 0;
        for &(lane, t) in &order[..n] {
            let count = u32::from(node.count[lane]);
            if count > 0 {
                if t <= cull(&walk.closest) {
                    self.test_leaf::<false, B>(
                        node.index[lane],
                        count,
                        &walk.sheared,
                        &walk.quad_ray,
                        &mut walk.closest,
                        stats,
                    );
                }
            } else if next.is_none() {
                next = Some(node.index[lane]);
            } else {
                postponed[p] = (node.index[lane], t);
                p += 1;
            }
        }
        for &(index, t_near) in postponed[..p].iter().rev() {
            walk.stack[walk.len].write(StackEntry {
                node: index,
                t_near,
            });
            walk.len += 1;
        }
        if let Some(index) = next {
            walk.node = index;
            return false;
        }
        loop {
            if walk.len == 0 {
                return true;
            }
            walk.len -= 1;
            // SAFETY: entries below the old `len` were written by the pushes above.
            let entry = unsafe { walk.stack[walk.len].assume_init() };
            if entry.t_near <= cull(&walk.closest) {
                walk.node = entry.node;
                self.prefetch_node(entry.node);
                return false;
            }
        }
    }
}
