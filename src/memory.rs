//! Process-wide memory policy.
//!
//! The renderer's brick cache decodes and evicts hundreds of thousands of
//! ~140 KiB sample buffers per frame on big volumes, from several threads.
//! glibc's malloc raises its mmap threshold dynamically after the first
//! such buffer is freed and from then on serves them from per-thread heap
//! arenas, where the churn fragments: on a 32 GiB volume with
//! `--cache-mb 1024`, a 2048x2048 composite render peaked at 1752 MiB of
//! RSS, 700 MiB above the cache it was allowed. Pinning the threshold at
//! 64 KiB makes every large buffer its own mapping, returned to the system
//! on free, so RSS tracks the cache budget (measured in
//! docs/BENCHMARKS.md, "Larger than RAM").

/// Allocations at or above this size get their own mapping.
pub const MMAP_THRESHOLD: usize = 64 << 10;

/// Applies the policy; call once at start-up, before threads start.
/// Does nothing on platforms other than Linux with glibc.
pub fn bound_heap_fragmentation() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets a malloc parameter; it is called before
    // any other thread exists and the value is within glibc's range
    // (at most HEAP_MAX/2 = 32 MiB on 64-bit).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD as libc::c_int);
    }
}
