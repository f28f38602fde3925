//! The process's memory policy: what glibc's allocator keeps after a free.

/// The free memory at the heap's top that glibc keeps rather than returns
/// (beyond it the whole free top goes back): a bound on what a process holds
/// past its peak's live data.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const KEPT_FREE: libc::c_int = 1 << 30;

/// glibc's malloc hands large blocks back to the kernel when they are
/// freed (those over its mmap threshold, and the heap's free top over 128
/// KiB), so every CPU step, which allocates the rasterizer's and the
/// update's arrays anew, took each of their pages again as a zeroed page
/// fault: 3.75 million faults in 22 steps of a 2,000,000-Gaussian scene,
/// about a quarter of its step time. Served from the heap, and with up to
/// [`KEPT_FREE`] of freed memory kept for the next step, the arrays come back
/// from the allocator instead (docs/figures.md). First in `main`, before any
/// thread exists.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
pub fn keep_freed() {
    // SAFETY: mallopt only sets the allocator's parameters; called first in
    // `main`, before any other thread allocates.
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, KEPT_FREE);
    }
}

/// Hands the free memory [`keep_freed`] kept back to the system: a studio
/// run's end, after which the window may stay open for long without one.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
pub fn give_back_freed() {
    // SAFETY: malloc_trim is thread-safe (it locks each arena it trims).
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn keep_freed() {}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn give_back_freed() {}
