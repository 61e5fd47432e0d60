//! Background traversal in the paper's Fig. 16 setting: 128^3 sphere
//! scenes of N^3 spheres, 250x250 parallel primary rays along +y framing
//! the whole scene, each traced until its first 1-cell (no shading), with
//! every brick already decoded in the cache. One thread.
//!
//! Run: `cargo bench --bench traverse`. Reports rays/s per traversal; the
//! CD/FVT ratios and steps per ray go to docs/BENCHMARKS.md
//! (`cargo run --release --example ...` is not needed: the steps per ray
//! are printed once per scene on stderr).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::phantom;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::cache::{Accessor, BrickCache};
use cdvol::render::camera::Camera;
use cdvol::render::traverse::{trace, Flow, Method, Ray, Real, TGrid};

fn scene(dir: &std::path::Path, n: usize) -> PackedVolume {
    let side = dir.join(format!("n{n}.json"));
    let opts = phantom::SpheresOptions {
        size: 128,
        per_axis: n,
        seed: 1,
        spacing: phantom::parse_spacing3("1").unwrap(),
    };
    let info = phantom::spheres(&side, &opts, &NoProgress).unwrap();
    let src = RawSource::open(&side).unwrap();
    let out = dir.join(format!("n{n}.cdv"));
    let mut o = PrepOptions::new(Classification::Iso { iso: info.iso });
    o.aniso = true;
    prep(&src, &out, &o, &NoProgress).unwrap();
    PackedVolume::open(&out).unwrap()
}

/// Traces every ray to its first 1-cell; returns total steps.
fn background<T: Real>(grid: &TGrid<T>, rays: &[Ray], m: Method, acc: &mut Accessor) -> u64 {
    let mut steps = 0;
    for r in rays {
        steps += trace(grid, r, 0.0, m, acc, |_, _| Flow::Stop).steps;
    }
    steps
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let mut g = c.benchmark_group("background");
    g.sample_size(10);
    for n in [2usize, 5, 10, 21] {
        let vol = scene(dir.path(), n);
        let grid = TGrid::<f64>::new(&vol.header().axes);
        let (lo, hi) = grid.bounds();
        let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let cam = Camera::look_at(
            [centre[0], lo[1] - 10.0, centre[2]],
            centre,
            [0.0, 0.0, 1.0],
            cdvol::render::camera::Projection::Ortho {
                frame_mm: hi[2] - lo[2],
            },
            250,
            250,
        )
        .unwrap();
        let rays = all_rays(&cam);
        let cache = BrickCache::new(&vol, 1 << 30);
        g.throughput(Throughput::Elements(rays.len() as u64));
        for (name, m) in [
            ("fvt", Method::Fvt),
            ("cd", Method::Cd { min_leap: 1 }),
            ("cd-leap4", Method::Cd { min_leap: 4 }),
            ("cd-aniso", Method::CdAniso { min_leap: 1 }),
        ] {
            let mut acc = Accessor::new(&cache);
            let steps = background(&grid, &rays, m, &mut acc);
            eprintln!(
                "N={n} {name}: {:.2} steps per ray",
                steps as f64 / rays.len() as f64
            );
            g.bench_function(BenchmarkId::new(name, n), |b| {
                b.iter(|| background(&grid, &rays, m, &mut acc))
            });
        }
    }
    g.finish();
}

/// One ray per pixel of `cam`, row by row.
fn all_rays(cam: &Camera) -> Vec<Ray> {
    (0..cam.height)
        .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
        .map(|(x, y)| cam.ray(x, y))
        .collect()
}

/// The same background traversal in f32 and f64 arithmetic
/// (`--precision`), on the sparsest and a dense scene.
fn precision(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let mut g = c.benchmark_group("precision");
    g.sample_size(10);
    for n in [2usize, 10] {
        let vol = scene(dir.path(), n);
        let g64 = TGrid::<f64>::new(&vol.header().axes);
        let g32 = TGrid::<f32>::new(&vol.header().axes);
        let (lo, hi) = g64.bounds();
        let cam = Camera::orbit((lo, hi), 30.0, 20.0, None, None, 250, 250).unwrap();
        let rays = all_rays(&cam);
        let cache = BrickCache::new(&vol, 1 << 30);
        g.throughput(Throughput::Elements(rays.len() as u64));
        for (name, m) in [("fvt", Method::Fvt), ("cd", Method::Cd { min_leap: 1 })] {
            let mut acc = Accessor::new(&cache);
            background(&g64, &rays, m, &mut acc);
            g.bench_function(BenchmarkId::new(format!("{name}-f64"), n), |b| {
                b.iter(|| background(&g64, &rays, m, &mut acc))
            });
            g.bench_function(BenchmarkId::new(format!("{name}-f32"), n), |b| {
                b.iter(|| background(&g32, &rays, m, &mut acc))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench, precision);
criterion_main!(benches);
