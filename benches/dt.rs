//! Distance-transform kernel throughput (cells/s): the in-slice exact 2D
//! transform, one z step of the recurrence, the whole streaming transform
//! in memory, and the anisotropic octant pass.
//!
//! Run: `cargo bench --bench dt`. Figures go to docs/BENCHMARKS.md,
//! "Distance-transform kernel".

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

use cdvol::dt::{chessboard_3d, merge_slice, octant_blocks_3d, slice_chessboard};

/// A hollow ellipsoid shell (CT-skull-like) plus a few scattered cells.
fn mask(n: [usize; 3]) -> Vec<u8> {
    let [nx, ny, nz] = n;
    let mut m = vec![0u8; nx * ny * nz];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let p = [
                    x as f64 / nx as f64 - 0.5,
                    y as f64 / ny as f64 - 0.5,
                    z as f64 / nz as f64 - 0.5,
                ];
                let r = (p[0] * p[0] / 0.16 + p[1] * p[1] / 0.12 + p[2] * p[2] / 0.18).sqrt();
                let i = (z * ny + y) * nx + x;
                m[i] = ((0.9..1.0).contains(&r) || i % 9973 == 0) as u8;
            }
        }
    }
    m
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("dt");
    for &n in &[128usize, 256] {
        let dims = [n, n, 64];
        let m = mask(dims);
        let cells = (n * n * 64) as u64;
        g.throughput(Throughput::Elements(cells));
        g.sample_size(10);
        g.bench_with_input(BenchmarkId::new("chessboard_3d", n), &m, |b, m| {
            b.iter(|| black_box(chessboard_3d(m, dims)))
        });
        if n == 128 {
            g.bench_with_input(BenchmarkId::new("octant_blocks_3d", n), &m, |b, m| {
                b.iter(|| black_box(octant_blocks_3d(m, dims)))
            });
        }
        let slice = &m[32 * n * n..33 * n * n];
        let mut out = vec![0u8; n * n];
        g.throughput(Throughput::Elements((n * n) as u64));
        g.sample_size(30);
        g.bench_function(BenchmarkId::new("slice_chessboard", n), |b| {
            b.iter(|| slice_chessboard(black_box(slice), n, n, &mut out))
        });
        let prev = out.clone();
        let mut cur = vec![3u8; n * n];
        g.bench_function(BenchmarkId::new("merge_slice", n), |b| {
            b.iter(|| merge_slice(black_box(&mut cur), &prev, n, n))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
