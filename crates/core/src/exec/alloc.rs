//! The process's allocator: glibc's malloc with one arena, or mimalloc, chosen per run from
//! the budget and the thread count ([`for_run`]).
//!
//! # Why two
//!
//! glibc with one arena (`main.rs`) keeps a run within `--mem` plus the README's margin on
//! any budget, but every worker takes the arena's lock and the solves' megabyte buffers go
//! back to the kernel and fault in again. On 16 cores that is the bound: a 1M-point
//! reconstruction at depth 10 on an H200 host spent 136 s of system time in 27.8 s (its
//! tiles 10.1 s); with mimalloc, 8 s of system time in 14.9 s (tiles 2.7 s), the same bytes.
//! On 2 cores the two are as fast. mimalloc keeps freed pages in per-thread heaps instead:
//! measured 100 to 110 MiB over glibc's peak with 2 threads and 526 MiB with 16, so it is
//! taken only where that slack ([`slack_bytes`]) fits in the share of the budget set aside
//! for the allocator ([`reserve_bytes`]).
//!
//! # The budget stays the same for any thread count
//!
//! What a run plans from its budget (a reconstruction's levels) must not depend on
//! `--threads`, so the reserve depends on `--mem` alone: an eighth of budgets from
//! [`RESERVE_FROM`] up, nothing below. Which allocator serves the run then depends on the
//! threads, but that changes no output byte.
//!
//! # Safety
//!
//! [`Alloc`] serves new blocks from the allocator chosen when they are made and frees each
//! block through the allocator that owns it (mimalloc's page map answers for its own
//! pointers), so switching while blocks are live is sound.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, Ordering};

/// Budgets from here up set an eighth aside for the allocator.
pub const RESERVE_FROM: u64 = 2 << 30;

/// New blocks come from mimalloc.
static MIMALLOC: AtomicBool = AtomicBool::new(false);
/// mimalloc has served a block (until then no pointer needs its page map).
static EVER: AtomicBool = AtomicBool::new(false);

/// The global allocator of the `scanflow` binary (see the module docs).
pub struct Alloc;

/// A new block from mimalloc or from System (zeroed or not).
///
/// # Safety
///
/// As [`GlobalAlloc::alloc`].
unsafe fn alloc_from(mimalloc: bool, layout: Layout, zeroed: bool) -> *mut u8 {
    // SAFETY: the caller's contract, forwarded.
    unsafe {
        match (mimalloc, zeroed) {
            (true, false) => mimalloc::MiMalloc.alloc(layout),
            (true, true) => mimalloc::MiMalloc.alloc_zeroed(layout),
            (false, false) => System.alloc(layout),
            (false, true) => System.alloc_zeroed(layout),
        }
    }
}

fn mimalloc_owns(p: *mut u8) -> bool {
    // SAFETY: mi_is_in_heap_region reads mimalloc's page map for any address.
    EVER.load(Ordering::Acquire)
        && unsafe { libmimalloc_sys::mi_is_in_heap_region(p as *const std::ffi::c_void) }
}

// SAFETY: each call forwards to an allocator that meets GlobalAlloc's contract, and a block
// is always freed or resized by the allocator that made it (`mimalloc_owns`).
unsafe impl GlobalAlloc for Alloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, forwarded.
        unsafe { alloc_from(MIMALLOC.load(Ordering::Relaxed), layout, false) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract, forwarded.
        unsafe { alloc_from(MIMALLOC.load(Ordering::Relaxed), layout, true) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if mimalloc_owns(ptr) {
            // SAFETY: mimalloc made the block.
            unsafe { mimalloc::MiMalloc.dealloc(ptr, layout) }
        } else {
            // SAFETY: System made the block.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if mimalloc_owns(ptr) {
            // SAFETY: mimalloc made the block.
            unsafe { mimalloc::MiMalloc.realloc(ptr, layout, new_size) }
        } else {
            // SAFETY: System made the block.
            unsafe { System.realloc(ptr, layout, new_size) }
        }
    }
}

/// Bytes of a budget of `mem` set aside for the allocator: an eighth from [`RESERVE_FROM`]
/// up, else none. Independent of the thread count.
pub fn reserve_bytes(mem: u64) -> u64 {
    if mem >= RESERVE_FROM { mem / 8 } else { 0 }
}

/// What mimalloc may hold beyond glibc's peak with `threads` workers: 64 MiB and 32 MiB a
/// worker (measured: 100–110 MiB with 2, 526 MiB with 16; see the module docs).
pub fn slack_bytes(threads: usize) -> u64 {
    (64 << 20) + (32 << 20) * threads as u64
}

/// Choose the allocator of a run with `threads` workers under a budget of `mem` bytes and
/// give the bytes left for its buffers (`mem` less [`reserve_bytes`]). mimalloc serves the
/// run where its slack fits the reserve (the binary's [`Alloc`]; elsewhere nothing changes).
pub fn for_run(threads: usize, mem: u64) -> u64 {
    let reserve = reserve_bytes(mem);
    let mimalloc = reserve > 0 && slack_bytes(threads) <= reserve;
    if mimalloc {
        EVER.store(true, Ordering::Release);
    }
    MIMALLOC.store(mimalloc, Ordering::Release);
    log::debug!(
        "allocator: {} ({} threads, {} of {} set aside)",
        if mimalloc { "mimalloc" } else { "glibc" },
        threads,
        super::human_bytes(reserve),
        crate::Setting::Mem
    );
    mem - reserve
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reserve_depends_on_the_budget_alone() {
        assert_eq!(reserve_bytes(RESERVE_FROM - 1), 0);
        assert_eq!(reserve_bytes(RESERVE_FROM), RESERVE_FROM / 8);
        // 16 workers fit the reserve of 4.5 GiB, 2 that of 1 GiB would (but 1 GiB is below
        // RESERVE_FROM: glibc).
        assert!(slack_bytes(16) <= reserve_bytes(9 << 29));
        assert!(slack_bytes(17) > reserve_bytes(9 << 29));
    }

    #[test]
    fn blocks_are_freed_by_the_allocator_that_made_them() {
        // Not the global allocator here: Alloc's paths driven directly (the switch itself is
        // left alone, other tests' contexts set it).
        let a = Alloc;
        let l = Layout::from_size_align(3 << 20, 64).unwrap();
        let small = Layout::from_size_align(24, 8).unwrap();
        EVER.store(true, Ordering::Release);
        // SAFETY: layouts of non-zero size; each block freed once with its layout.
        unsafe {
            let g = alloc_from(false, l, false);
            let m = alloc_from(true, l, true);
            let s = alloc_from(true, small, false);
            assert!(!g.is_null() && !m.is_null() && !s.is_null());
            assert!(!mimalloc_owns(g) && mimalloc_owns(m) && mimalloc_owns(s));
            assert_eq!(*m.add(12345), 0);
            let g2 = a.realloc(g, l, 4 << 20);
            assert!(!mimalloc_owns(g2));
            let s2 = a.realloc(s, small, 48);
            assert!(mimalloc_owns(s2));
            a.dealloc(g2, Layout::from_size_align(4 << 20, 64).unwrap());
            a.dealloc(m, l);
            a.dealloc(s2, Layout::from_size_align(48, 8).unwrap());
        }
    }
}
