//! Where the BVH's arrays live: on transparent huge pages where Linux offers them.
//!
//! Why: on a mesh too large for the caches (the 871k-triangle dragon's tree, packed triangles
//! and normals are over 100 MB), nearly every node, leaf and hit the traversal reads is on a
//! different 4 KiB page, and the processor's TLB covers a few MiB of those: most reads then pay
//! a page-table walk on top of the cache miss. 2 MiB pages cover the arrays with a few hundred
//! TLB entries. Linux gives them to memory that asks (`madvise(MADV_HUGEPAGE)`) before its
//! pages are first touched, when the system's setting is `madvise` (as on our machines) or
//! `always`; with `never`, or elsewhere, the request does nothing.
//!
//! Where the memory lies changes no value, so this cannot change a result; nor can [`prefetch`],
//! the hint the traversal and the integrator give for what they will read next, nor can the
//! hints a closest-hit walk gives for the records its caller reads at the hit
//! ([`Accel::prefetch_at_hits`]).

use super::bvh::Accel;
use glam::Vec3;

/// `values`, its memory asked to be backed by huge pages: advised for any page not yet touched,
/// and collapsed into huge pages now where it already is (`MADV_COLLAPSE`, Linux 6.1 and later;
/// the arrays of a freshly built tree mostly reuse heap memory the scene's loading touched,
/// which the first request alone would leave on small pages). Arrays shorter than two huge
/// pages are left alone. Best effort: a kernel that refuses leaves ordinary pages.
pub(crate) fn on_huge_pages<T: Copy>(values: Vec<T>) -> Vec<T> {
    const HUGE_PAGE: usize = 2 << 20;
    let bytes = std::mem::size_of_val(values.as_slice());
    if bytes >= 2 * HUGE_PAGE {
        advise_huge_pages(values.as_ptr().cast::<u8>(), bytes);
    }
    values
}

/// Hands the memory the program has freed back to the system, where the allocator holds on to
/// it: glibc keeps freed heap pages resident, and a scene's loading and its trees' building
/// free far more than the scene keeps (the dragon's OBJ text, its parsed arrays, obvhs's
/// working arrays), which a machine rendering for minutes would otherwise hold all along.
pub(crate) fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only returns free memory of glibc's heap to the kernel; no
    // allocation the program holds moves or changes.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// A hint to bring the cache line holding `address` closer; it never faults, even for an
/// address outside any allocation, and does nothing on targets without one.
#[inline(always)]
pub(crate) fn prefetch(address: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `prefetcht0` (SSE, part of x86-64's baseline) only hints the cache; it reads no
    // value into the program and cannot fault, whatever the address.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(address.cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

#[cfg(target_os = "linux")]
fn advise_huge_pages(start: *const u8, bytes: usize) {
    const PAGE: usize = 4096;
    /// Linux's `MADV_COLLAPSE` (include/uapi/asm-generic/mman-common.h), which this version of
    /// the `libc` crate does not name.
    const MADV_COLLAPSE: libc::c_int = 25;
    // madvise wants a page-aligned start: the first whole page of the array. The kernel backs
    // each 2 MiB-aligned stretch inside the range with a huge page when it can.
    let first = (start as usize).next_multiple_of(PAGE);
    let end = start as usize + bytes;
    if end <= first {
        return;
    }
    for advice in [libc::MADV_HUGEPAGE, MADV_COLLAPSE] {
        // SAFETY: the range lies within an allocation this process owns; both advices only
        // tell the kernel how to back it (a collapse copies pages into huge ones, keeping
        // their contents) and move or free nothing the program sees. An error (a kernel
        // without THP or without MADV_COLLAPSE) leaves ordinary pages, the fallback wanted.
        unsafe {
            libc::madvise(first as *mut libc::c_void, end - first, advice);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_start: *const u8, _bytes: usize) {}

impl Accel {
    /// Prefetch `records[triangle]` and `attributes[triangle]` (an array that may be empty),
    /// with this tree's own normals of the triangle, whenever a closest-hit query keeps a hit
    /// on it, while the traversal goes on. What the caller reads first at a hit is that record
    /// and those attributes (on Sponza, the texture coordinates whose texel is the next miss);
    /// without the hint each is a cache miss that starts only once the query has returned. A
    /// prefetch reads nothing into the computation, so results are unchanged.
    pub fn prefetch_at_hits<T, U>(&mut self, records: &[T], attributes: &[U]) {
        self.hit_records = [hit_array(records), hit_array(attributes)];
    }

    /// Asks for what the caller will read first if `triangle` stays the closest hit: its
    /// normals here and its record (`Accel::prefetch_at_hits`), every line of each, down to
    /// its last byte, so that a record straddling lines comes whole. A hit later replaced wastes only the hint.
    #[inline(always)]
    pub(super) fn prefetch_hit(&self, triangle: u32) {
        let normals = self.normals.as_ptr().cast::<u8>();
        let size = std::mem::size_of::<[Vec3; 2]>();
        let at = normals.wrapping_add(triangle as usize * size);
        prefetch(at);
        prefetch(at.wrapping_add(size - 1));
        for &(base, size) in self.hit_records.iter().flatten() {
            let at = base.wrapping_add(triangle as usize * size);
            let mut offset = 0;
            while offset < size {
                prefetch(at.wrapping_add(offset) as *const u8);
                offset += 64;
            }
            prefetch(at.wrapping_add(size.saturating_sub(1)) as *const u8);
        }
    }
}

/// `items` as [`Accel::prefetch_at_hits`] keeps it: the address of the first and the size of
/// one; `None` where there is nothing to prefetch.
fn hit_array<T>(items: &[T]) -> Option<(usize, usize)> {
    let size = std::mem::size_of::<T>();
    (!items.is_empty() && size != 0).then_some((items.as_ptr() as usize, size))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_pages_keep_every_value_in_place() {
        let big: Vec<u64> = (0..1_000_000).map(|i| i * 7 + 3).collect();
        let (pointer, copy) = (big.as_ptr(), big.clone());
        let kept = on_huge_pages(big);
        assert_eq!(kept.as_ptr(), pointer);
        assert_eq!(kept, copy);
        assert_eq!(on_huge_pages(vec![1u8, 2, 3]), [1, 2, 3]);
    }
}
