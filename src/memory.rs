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
//! docs/BENCHMARKS.md, "Larger than RAM"). The binary's allocator
//! ([`pool`], Linux) now takes the brick planes themselves out of that
//! path: they come from huge-page chunks and are reused between bricks;
//! the pin still applies to every other large buffer.

#[cfg(target_os = "linux")]
pub mod pool;

/// Allocations at or above this size get their own mapping.
pub const MMAP_THRESHOLD: usize = 64 << 10;

/// Free memory an arena keeps at its top before returning it to the
/// system. With the mmap threshold pinned, glibc keeps its default of
/// 128 KiB, and a brick decode's temporaries (a few hundred KiB of
/// buffers under [`MMAP_THRESHOLD`] each: the render-time iso's narrowing
/// and transform, module render::scene) were returned after every brick
/// and faulted in again by the next: 43,000 of the 96,000 page faults of a
/// cold 1024^2 frame of the 512^3 phantom at `--iso 1000` from an
/// envelope file, about a quarter of its time (docs/BENCHMARKS.md,
/// "Render-time iso"). 4 MiB per arena is a bound on what this keeps.
pub const TRIM_THRESHOLD: usize = 4 << 20;

/// Applies the policy; call once at start-up, before threads start.
/// Does nothing on platforms other than Linux with glibc.
pub fn bound_heap_fragmentation() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets malloc parameters; it is called before
    // any other thread exists and the values are within glibc's range
    // (the mmap threshold at most HEAP_MAX/2 = 32 MiB on 64-bit).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD as libc::c_int);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD as libc::c_int);
    }
}

/// The share of physical memory a command may plan to use when no
/// `--mem-limit` is given: 3/4 of RAM (`MemTotal`), leaving the rest to
/// the page cache and other processes.
pub const DEFAULT_FRACTION: (u64, u64) = (3, 4);

/// Bytes of physical memory (`MemTotal` of /proc/meminfo), if known.
pub fn ram_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The default memory limit: [`DEFAULT_FRACTION`] of RAM, or no limit
/// where RAM is unknown.
pub fn default_limit() -> u64 {
    ram_bytes()
        .map(|r| r / DEFAULT_FRACTION.1 * DEFAULT_FRACTION.0)
        .unwrap_or(u64::MAX)
}

/// The limit of `--mem-limit MIB`, in bytes, at most the machine's RAM
/// ([`ram_bytes`]): a plan above RAM cannot be kept, and the allocation it
/// allowed would abort the process instead of failing with a message.
/// The second value says so when the given limit was lowered.
pub fn limit_from_mib(mib: u64) -> (u64, Option<String>) {
    let bytes = mib.saturating_mul(1 << 20);
    match ram_bytes() {
        Some(ram) if bytes > ram => (
            ram,
            Some(format!(
                "--mem-limit {mib} MiB is above this machine's {} of RAM; using {}",
                human(ram),
                human(ram)
            )),
        ),
        _ => (bytes, None),
    }
}

/// How a limit was set, for messages: `--mem-limit` or the default.
pub fn describe_limit(limit: u64, explicit: bool) -> String {
    if explicit {
        format!("{} (--mem-limit)", human(limit))
    } else {
        match ram_bytes() {
            Some(r) => format!(
                "{} ({}/{} of {} RAM; raise it with --mem-limit)",
                human(limit),
                DEFAULT_FRACTION.0,
                DEFAULT_FRACTION.1,
                human(r)
            ),
            None => "no limit".into(),
        }
    }
}

/// `1.5 GiB`, `300.0 MiB`, `2.0 TiB`.
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    let units = [("TiB", 40), ("GiB", 30), ("MiB", 20), ("KiB", 10)];
    for (u, shift) in units {
        if b >= (1u64 << shift) as f64 {
            return format!("{:.1} {u}", b / (1u64 << shift) as f64);
        }
    }
    format!("{bytes} B")
}
