//! Where a render's time goes: the split of the tiles' time into brick
//! decoding, traversal and sampling/shading that `--stats` reports
//! (`seconds_decode`, `seconds_traverse`, `seconds_sample`).
//!
//! Decoding is timed where it happens (the accessor, every brick). The
//! other two interleave at the scale of a cell, where reading a clock costs
//! as much as the work, so they are estimated: one ray in
//! [`TIMED_EVERY`] is timed whole and in its sampling sections with the
//! processor's tick counter; the sampled share of those rays' time (decode
//! taken out of both, and the counter's own cost, calibrated per tile,
//! taken out of every reading) splits the tiles' time without decode.
//!
//! A sampling section is what an integrator does with a cell the
//! traversal reported: the hit test of surface, depth and cost mode
//! (cell values, root finding), the shading after a hit (normals, light;
//! a shadow ray's own traversal stays traversal), MIP's per-cell maximum,
//! and the composite march along a run of 1-cells (samples, transfer
//! function, shading, and the cell-by-cell advance between samples; the
//! traversal's leaps between runs are traversal).

use std::cell::Cell;
use std::time::Instant;

use crate::render::cache::Accessor;

/// One ray in this many is timed. Each reading of the tick counter costs
/// about 26 ns on the virtual machines the benchmarks run on
/// (tools/rdtsc-cost.rs), and a timed ray reads it twice per cell it
/// samples: at one ray in 8, `perf` put 5-7 % of a warm surface or MIP
/// frame on the readings (docs/BENCHMARKS.md, "Fixed costs and the
/// clock's readings"). One in 64 still times some 16,000 rays of a 1024^2
/// frame and 60 of a 64^2 one.
pub const TIMED_EVERY: u32 = 64;

/// Whether ray `i` of a tile is timed: one in [`TIMED_EVERY`], spread over
/// the tile (the golden-ratio sequence `i * 0.618...` modulo 1 falls in
/// its lowest `1 / TIMED_EVERY` once in every run of about that many
/// rays), not every ray at the same column.
#[inline(always)]
pub(crate) fn is_timed(i: u32) -> bool {
    i.wrapping_mul(0x9E37_79B9) < u32::MAX / TIMED_EVERY
}

/// The tick counter: the time-stamp counter on x86_64, nanoseconds since
/// the first call elsewhere. Only ratios of ticks within one tile are used,
/// and the tile converts them with its own rate.
#[inline(always)]
fn ticks() -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: `rdtsc` has no preconditions and exists on every x86_64.
        unsafe { core::arch::x86_64::_rdtsc() }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        static EPOCH: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
        EPOCH.get_or_init(Instant::now).elapsed().as_nanos() as u64
    }
}

/// The split clock of the tile a thread is rendering: per-thread state,
/// as pbrt's `STAT_COUNTER`s are, so no integrator carries it. A tile runs
/// on one thread from [`start_tile`] to [`stop_tile`] (it calls no rayon
/// join inside), its rays between [`begin_ray`] and [`end_ray`], and the
/// integrators mark their sampling sections with [`enter`] and [`leave`].
/// The tiles' [`TileTime`]s are merged at the end of the frame ([`split`]).
#[derive(Debug, Clone, Copy)]
struct Clock {
    ray_start: u64,
    ray_decode: f64,
    section_start: Option<(u64, f64)>,
    sections: u64,
    /// Ticks of timed rays and of their sections; readings in them.
    ray_ticks: u64,
    sample_ticks: u64,
    readings_ray: u64,
    readings_sample: u64,
    /// Decode seconds inside timed rays and inside their sections.
    decode_ray: f64,
    decode_sample: f64,
}

impl Clock {
    const IDLE: Clock = Clock {
        ray_start: 0,
        ray_decode: 0.0,
        section_start: None,
        sections: 0,
        ray_ticks: 0,
        sample_ticks: 0,
        readings_ray: 0,
        readings_sample: 0,
        decode_ray: 0.0,
        decode_sample: 0.0,
    };
}

thread_local! {
    /// Whether the thread's current ray is timed: the one reading on the
    /// hot path ([`enter`], [`leave`]).
    static TIMED: Cell<bool> = const { Cell::new(false) };
    /// The thread's tile clock; touched only by timed rays and at a
    /// tile's start and stop.
    static CLOCK: Cell<Clock> = const { Cell::new(Clock::IDLE) };
    /// When the thread's tile started: wall time and ticks.
    static TILE_START: Cell<Option<(Instant, u64)>> = const { Cell::new(None) };
}

/// Applies `f` to the thread's clock.
#[inline]
fn with_clock(f: impl FnOnce(&mut Clock)) {
    CLOCK.with(|c| {
        let mut k = c.get();
        f(&mut k);
        c.set(k);
    });
}

/// A tile begins on this thread: its clock starts now.
pub(crate) fn start_tile() {
    TIMED.with(|t| t.set(false));
    CLOCK.with(|c| c.set(Clock::IDLE));
    TILE_START.with(|s| s.set(Some((Instant::now(), ticks()))));
}

/// Ray `i` of the tile begins; it is timed when [`is_timed`].
#[inline]
pub(crate) fn begin_ray(i: u32, acc: &Accessor) {
    let timed = is_timed(i);
    TIMED.with(|t| t.set(timed));
    if timed {
        with_clock(|k| {
            k.sections = 0;
            k.ray_decode = acc.counters.decode_seconds;
            k.ray_start = ticks();
        });
    }
}

/// The current ray ends.
#[inline]
pub(crate) fn end_ray(acc: &Accessor) {
    if TIMED.with(|t| t.replace(false)) {
        with_clock(|k| {
            k.ray_ticks += ticks().wrapping_sub(k.ray_start);
            k.decode_ray += acc.counters.decode_seconds - k.ray_decode;
            // A ray reads twice, a section twice more inside it.
            k.readings_ray += 1 + 2 * k.sections;
            k.readings_sample += k.sections;
        });
    }
}

/// A sampling section begins (sections do not nest).
#[inline]
pub(crate) fn enter(acc: &Accessor) {
    if TIMED.with(|t| t.get()) {
        with_clock(|k| {
            debug_assert!(k.section_start.is_none(), "sections do not nest");
            k.section_start = Some((ticks(), acc.counters.decode_seconds));
        });
    }
}

/// The current sampling section ends.
#[inline]
pub(crate) fn leave(acc: &Accessor) {
    if TIMED.with(|t| t.get()) {
        with_clock(|k| {
            if let Some((k0, d0)) = k.section_start.take() {
                k.sample_ticks += ticks().wrapping_sub(k0);
                k.decode_sample += acc.counters.decode_seconds - d0;
                k.sections += 1;
            }
        });
    }
}

/// The thread's tile ends: its time, split. A thread that started no
/// tile reports nothing.
pub(crate) fn stop_tile() -> TileTime {
    TIMED.with(|t| t.set(false));
    let k = CLOCK.with(|c| c.replace(Clock::IDLE));
    let Some((t0, k0)) = TILE_START.with(|s| s.take()) else {
        return TileTime::default();
    };
    let seconds = t0.elapsed().as_secs_f64();
    let dk = ticks().wrapping_sub(k0);
    if dk == 0 || seconds <= 0.0 {
        return TileTime {
            seconds,
            ..TileTime::default()
        };
    }
    let per_tick = seconds / dk as f64;
    let reading = reading_ticks();
    let net = |t: u64, readings: u64, decode: f64| {
        (t.saturating_sub(readings * reading) as f64 * per_tick - decode).max(0.0)
    };
    TileTime {
        seconds,
        timed_ray: net(k.ray_ticks, k.readings_ray, k.decode_ray),
        timed_sample: net(k.sample_ticks, k.readings_sample, k.decode_sample),
    }
}

/// A tile's time: its whole time and its share per phase, in seconds.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct TileTime {
    /// The tile's wall time (one thread's).
    pub(crate) seconds: f64,
    /// Timed rays: their time and their sampling sections' time, decode
    /// and the clock's own readings taken out.
    pub(crate) timed_ray: f64,
    pub(crate) timed_sample: f64,
}

/// The cost of one reading of [`ticks`], in ticks (the least of a few
/// trials of 64 readings; measured once per process).
fn reading_ticks() -> u64 {
    static READING: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *READING.get_or_init(|| {
        (0..8)
            .map(|_| {
                let k0 = ticks();
                let mut last = k0;
                for _ in 0..64 {
                    last = std::hint::black_box(ticks());
                }
                last.wrapping_sub(k0) / 64
            })
            .min()
            .unwrap_or(0)
    })
}

/// The tiles' time split into decode, traversal and sampling, summed over
/// threads: `(tiles, traverse, sample)` seconds, given the tiles' decode
/// seconds.
pub(crate) fn split(times: &[TileTime], decode: f64) -> (f64, f64, f64) {
    let tiles: f64 = times.iter().map(|t| t.seconds).sum();
    let ray: f64 = times.iter().map(|t| t.timed_ray).sum();
    let sample: f64 = times.iter().map(|t| t.timed_sample).sum();
    let rest = (tiles - decode).max(0.0);
    let share = if ray > 0.0 {
        (sample / ray).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (tiles, rest * (1.0 - share), rest * share)
}

/// The kernel's share of a render, from the process's resource usage
/// (`getrusage`, all threads): system CPU seconds and page faults. Most of
/// a first frame's system time is the kernel clearing fresh pages for the
/// bricks it decodes, which on a virtual machine can take longer than the
/// decoding itself (docs/BENCHMARKS.md, "The kernel's share of the first
/// frame").
/// Process-wide, so other threads' work in the same process (a `serve`
/// reading a request) counts too. Zero where the platform gives no
/// figures (only Linux with glibc is asked).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct KernelUse {
    pub(crate) seconds_system: f64,
    pub(crate) page_faults: u64,
    /// Chunks of the registered plane pool that asked for a huge page,
    /// and how many of those were slow at their first touch
    /// ([`PlanePool::huge_chunks`](crate::memory::pool::PlanePool::huge_chunks));
    /// 0 without a registered pool.
    pub(crate) huge_pages: u64,
    pub(crate) huge_pages_slow: u64,
}

impl KernelUse {
    /// The process's kernel use so far.
    pub(crate) fn now() -> KernelUse {
        let (huge, slow) =
            crate::memory::pool::PlanePool::registered().map_or((0, 0), |p| p.huge_chunks());
        KernelUse {
            huge_pages: huge as u64,
            huge_pages_slow: slow as u64,
            ..KernelUse::rusage()
        }
    }

    /// The system seconds and page faults so far.
    fn rusage() -> KernelUse {
        #[cfg(all(target_os = "linux", target_env = "gnu"))]
        {
            // SAFETY: `getrusage` writes one `rusage` into the zeroed
            // value it is given and reads nothing else.
            let mut u: libc::rusage = unsafe { std::mem::zeroed() };
            if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } == 0 {
                let t = u.ru_stime;
                return KernelUse {
                    seconds_system: t.tv_sec as f64 + t.tv_usec as f64 * 1e-6,
                    page_faults: (u.ru_minflt + u.ru_majflt).max(0) as u64,
                    ..KernelUse::default()
                };
            }
        }
        KernelUse::default()
    }

    /// The kernel use since `earlier` (never negative).
    pub(crate) fn since(earlier: KernelUse) -> KernelUse {
        let n = KernelUse::now();
        KernelUse {
            seconds_system: (n.seconds_system - earlier.seconds_system).max(0.0),
            page_faults: n.page_faults.saturating_sub(earlier.page_faults),
            huge_pages: n.huge_pages.saturating_sub(earlier.huge_pages),
            huge_pages_slow: n.huge_pages_slow.saturating_sub(earlier.huge_pages_slow),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// About one ray in `TIMED_EVERY` is timed in every stretch of a tile,
    /// the first included, with no two timed rays adjacent.
    #[test]
    fn timed_rays_are_one_in_timed_every_and_spread() {
        let timed: Vec<u32> = (0..1 << 16).filter(|&i| is_timed(i)).collect();
        let n = (1u32 << 16) / TIMED_EVERY;
        assert!(
            timed.len().abs_diff(n as usize) <= 2,
            "{} timed of 65536",
            timed.len()
        );
        assert_eq!(timed[0], 0);
        let gaps: Vec<u32> = timed.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            gaps.iter()
                .all(|&g| (TIMED_EVERY / 2..=2 * TIMED_EVERY).contains(&g)),
            "{gaps:?}"
        );
        // A 64^2 tile: timed rays in every quarter of its rows.
        for q in 0..4u32 {
            let r = q * 1024..(q + 1) * 1024;
            let k = timed.iter().filter(|i| r.contains(i)).count();
            assert!((12..=20).contains(&k), "quarter {q}: {k}");
        }
    }

    /// Touching fresh memory shows up as page faults between two
    /// readings. (Tests run in parallel threads of one process, which the
    /// readings also count, so only a lower bound is checked.)
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn kernel_use_counts_the_faults_of_fresh_memory() {
        const LEN: usize = 64 << 20;
        let k0 = KernelUse::now();
        // SAFETY: a private anonymous mapping of the kernel's choosing,
        // checked, written inside its length and unmapped once.
        unsafe {
            let p = libc::mmap(
                std::ptr::null_mut(),
                LEN,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            );
            assert_ne!(p, libc::MAP_FAILED);
            let b = p as *mut u8;
            for i in (0..LEN).step_by(4096) {
                std::ptr::write_volatile(b.add(i), 1);
            }
            libc::munmap(p, LEN);
        }
        let d = KernelUse::since(k0);
        // One fault per page, or one per 2 MiB where huge pages back the
        // mapping: at least LEN / 2 MiB = 32.
        assert!(d.page_faults >= 32, "{d:?}");
        assert!(d.seconds_system >= 0.0 && d.seconds_system.is_finite());
    }

    /// The registered plane pool's huge pages show between two readings:
    /// a size class's chunk after its first `SMALL_CHUNKS` asks for one,
    /// and it counts as slow or not by its first touch. (The only test
    /// that registers a pool; the test binary's allocator is the
    /// system's, so this one is used directly.)
    #[test]
    fn kernel_use_counts_the_registered_pools_huge_pages() {
        use crate::memory::pool::{PlanePool, SMALL_CHUNKS};
        use std::alloc::{GlobalAlloc, Layout};
        static POOL: PlanePool = PlanePool::new();
        POOL.register();
        assert!(PlanePool::registered().is_some_and(|p| std::ptr::eq(p, &POOL)));
        let l = Layout::from_size_align(40 << 10, 8).expect("a layout");
        let k0 = KernelUse::now();
        let mut slots = Vec::new();
        while POOL.chunks() <= SMALL_CHUNKS {
            // SAFETY: a non-zero layout; each slot is freed once below.
            let p = unsafe { POOL.alloc(l) };
            assert!(!p.is_null());
            slots.push(p);
        }
        let d = KernelUse::since(k0);
        assert_eq!(d.huge_pages, 1, "{d:?}");
        assert!(d.huge_pages_slow <= 1, "{d:?}");
        assert_eq!(POOL.huge_chunks(), (1, d.huge_pages_slow as usize));
        for p in slots {
            // SAFETY: from `alloc` with `l`, freed once.
            unsafe { POOL.dealloc(p, l) };
        }
    }
}
