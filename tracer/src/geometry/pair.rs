//! Two rays walked through the wide tree at once, a step of each in turn within one loop, so
//! that the processor overlaps their chains of dependent steps (PROTOTYPE).

use super::bvh::{Accel, Closest};
#[cfg(target_arch = "x86_64")]
use super::node8::Avx;
use super::node8::{BoxTest, Portable, WideRay};
use super::packed_hit::PackedHit;
use super::quad::QuadRay;
use super::traverse::FAR_SCALE;
use super::triangle::ShearedRay;
use super::wide::{BoxSimd, StackEntry, WalkStack, push_sorted};
use super::{Hit, Ray, TraversalStats};
use std::mem::MaybeUninit;

/// One ray's walk as state that advances a step at a time.
struct Walk<'s, const ANY_HIT: bool, const CERTAIN: bool> {
    wide: WideRay,
    sheared: ShearedRay,
    quad_ray: QuadRay,
    closest: Closest,
    current: StackEntry,
    len: usize,
    stack: &'s mut [MaybeUninit<StackEntry>],
}

impl<'s, const ANY_HIT: bool, const CERTAIN: bool> Walk<'s, ANY_HIT, CERTAIN> {
    #[inline(always)]
    fn new(ray: &Ray, stack: &'s mut [MaybeUninit<StackEntry>]) -> Self {
        let sheared = ShearedRay::new(ray);
        let quad_ray = QuadRay::new(&sheared);
        Walk {
            wide: WideRay::new(ray),
            sheared,
            quad_ray,
            closest: Closest::new(ray, CERTAIN),
            current: StackEntry {
                child: 0,
                count: 0,
                t_near: 0.0,
            },
            len: 0,
            stack,
        }
    }

    /// One step: a leaf's triangles or a node's boxes, then the next entry. Returns whether
    /// the walk is over.
    #[inline(always)]
    fn step<B: BoxTest>(&mut self, accel: &Accel, stats: &mut TraversalStats) -> bool {
        let cull = |closest: &Closest| closest.t_max() * FAR_SCALE;
        let current = self.current;
        if current.count > 0 {
            if accel.test_leaf::<ANY_HIT, B>(
                current.child,
                current.count,
                &self.sheared,
                &self.quad_ray,
                &mut self.closest,
                stats,
            ) && ANY_HIT
            {
                return true;
            }
        } else {
            // SAFETY: as in `wide_with_stack`.
            let node = unsafe { accel.wide.nodes.get_unchecked(current.child as usize) };
            stats.nodes += u64::from(node.children);
            let (mut entered, t_near) = B::enter(&self.wide, node, cull(&self.closest));
            let base = self.len;
            while entered != 0 {
                let lane = entered.trailing_zeros() as usize;
                entered &= entered - 1;
                let entry = StackEntry {
                    child: node.index[lane],
                    count: u32::from(node.count[lane]),
                    t_near: t_near[lane],
                };
                accel.prefetch_child(entry.child, entry.count);
                if ANY_HIT && entry.count > 0 {
                    if accel.test_leaf::<ANY_HIT, B>(
                        entry.child,
                        entry.count,
                        &self.sheared,
                        &self.quad_ray,
                        &mut self.closest,
                        stats,
                    ) {
                        return true;
                    }
                    continue;
                }
                let run = if ANY_HIT { self.len } else { base };
                // SAFETY: as in `wide_with_stack`.
                unsafe { push_sorted(self.stack, run, self.len, entry, |e| e.t_near) };
                self.len += 1;
            }
            if self.len > base {
                self.len -= 1;
                // SAFETY: written by the pushes above.
                self.current = unsafe { self.stack.get_unchecked(self.len).assume_init() };
                return false;
            }
        }
        loop {
            if self.len == 0 {
                return true;
            }
            self.len -= 1;
            // SAFETY: written by earlier pushes.
            let entry = unsafe { self.stack.get_unchecked(self.len).assume_init() };
            if entry.t_near <= cull(&self.closest) {
                self.current = entry;
                return false;
            }
        }
    }
}

impl Accel {
    /// The closest hit of `ray` and whether `shadow` is occluded, walked together.
    pub fn intersect_and_occluded(
        &self,
        ray: &Ray,
        shadow: &Ray,
        stats: &mut TraversalStats,
    ) -> (Option<Hit>, bool) {
        if self.wide.nodes.is_empty() {
            return (None, false);
        }
        #[cfg(target_arch = "x86_64")]
        if self.wide.simd == BoxSimd::Avx {
            // SAFETY: `simd` is `Avx` only where AVX was detected.
            let (hit, blocked) = unsafe { self.pair_avx(ray, shadow, stats) };
            return (hit.unpack(), blocked);
        }
        let (hit, blocked) = self.pair_portable(ray, shadow, stats);
        (hit.unpack(), blocked)
    }

    #[inline(never)]
    fn pair_portable(
        &self,
        ray: &Ray,
        shadow: &Ray,
        stats: &mut TraversalStats,
    ) -> (PackedHit, bool) {
        let (hit, blocked) = self.pair_with::<Portable>(ray, shadow, stats);
        (PackedHit::pack(hit), blocked)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline(never)]
    unsafe fn pair_avx(
        &self,
        ray: &Ray,
        shadow: &Ray,
        stats: &mut TraversalStats,
    ) -> (PackedHit, bool) {
        let (hit, blocked) = self.pair_with::<Avx>(ray, shadow, stats);
        (PackedHit::pack(hit), blocked)
    }

    #[inline(always)]
    fn pair_with<B: BoxTest>(
        &self,
        ray: &Ray,
        shadow: &Ray,
        stats: &mut TraversalStats,
    ) -> (Option<Hit>, bool) {
        let mut counted = *stats;
        let mut stack_a = WalkStack::<StackEntry>::new();
        let mut stack_b = WalkStack::<StackEntry>::new();
        let mut a = Walk::<false, false>::new(ray, stack_a.for_tree(&self.wide));
        let mut b = Walk::<true, true>::new(shadow, stack_b.for_tree(&self.wide));
        loop {
            let a_done = a.step::<B>(self, &mut counted);
            let b_done = b.step::<B>(self, &mut counted);
            if a_done || b_done {
                if !a_done {
                    while !a.step::<B>(self, &mut counted) {}
                }
                if !b_done {
                    while !b.step::<B>(self, &mut counted) {}
                }
                break;
            }
        }
        *stats = counted;
        (a.closest.best, b.closest.best.is_some())
    }
}
