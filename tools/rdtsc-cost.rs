//! The cost of one reading of the time-stamp counter, which `--stats`
//! reads twice per sampled cell of its timed rays (src/render/clock.rs).
//! On a virtual machine it can cost several times what it costs on bare
//! metal. Standalone, no dependencies:
//!
//!     rustc -O tools/rdtsc-cost.rs -o /tmp/rdtsc-cost && taskset -c 1 /tmp/rdtsc-cost
use std::time::Instant;
fn main() {
    let n = 2_000_000u64;
    let mut best = f64::MAX;
    for _ in 0..5 {
        let t0 = Instant::now();
        let mut acc = 0u64;
        for _ in 0..n {
            // SAFETY: `rdtsc` has no preconditions and exists on every x86_64.
            acc = acc.wrapping_add(unsafe { core::arch::x86_64::_rdtsc() });
        }
        std::hint::black_box(acc);
        best = best.min(t0.elapsed().as_secs_f64() / n as f64);
    }
    println!("rdtsc: {:.1} ns per reading (best of 5 x {n})", best * 1e9);
}
