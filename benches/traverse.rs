//! Background traversal in the paper's Fig. 16 setting: 128^3 sphere
//! scenes of N^3 spheres, 250x250 parallel primary rays along +y framing
//! the whole scene, each traced until its first 1-cell (no shading), with
//! every brick already decoded in the cache. One thread.
//!
//! Run: `cargo bench --bench traverse`. The `background` group measures
//! every ray generator of the paper's section 5 (FVT, CD, CD with octant
//! codes, octree, DDA with the three distances with and without the switch
//! to FVT, CD switched to FVT at distance D = 1, 2, 3) on N = 2, 10, 21;
//! the `init` group measures the initialisation per ray (paper Table 2).
//! Criterion reports time per image and rays/s; once per scene the bench
//! prints on stderr, per generator, steps per ray, the mean cost per step
//! (median time per image over criterion's own samples / total steps) and
//! that cost relative to FVT's (Table 2, "step cost"). docs/BENCHMARKS.md
//! holds the tables ("Background traversal (paper Fig. 16 setting)",
//! "Ray generators per step (paper Table 2)").

use std::time::{Duration, Instant};

use criterion::measurement::WallTime;
use criterion::{
    black_box, criterion_group, criterion_main, BenchmarkGroup, BenchmarkId, Criterion, Throughput,
};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::cache::{Accessor, BrickCache};
use cdvol::render::traverse::{trace, DistKind, Flow, Method, Ray, Real, TGrid};
use cdvol::render::view::camera::Camera;
use cdvol::tools::phantom;

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
    o.dda = true;
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

/// Like [`background`], each ray from its own `t_min`.
fn from_t<T: Real>(grid: &TGrid<T>, rays: &[(Ray, f64)], m: Method, acc: &mut Accessor) -> u64 {
    let mut steps = 0;
    for (r, t) in rays {
        steps += trace(grid, r, *t, m, acc, |_, _| Flow::Stop).steps;
    }
    steps
}

/// The ray generators of the paper's section 5 (name, method). With
/// `no_switch`, also the DDA generators without the switch to FVT (Fig.
/// 18a; they may miss 1-cells, so their rays may stop later).
fn generators(no_switch: bool) -> Vec<(String, Method)> {
    let kinds = [
        ("city", DistKind::Cityblock),
        ("chess", DistKind::Chessboard),
        ("chamfer", DistKind::Chamfer),
    ];
    let mut g: Vec<(String, Method)> = vec![
        ("fvt".into(), Method::Fvt),
        ("cd".into(), Method::Cd { min_leap: 1 }),
        ("cd-aniso".into(), Method::CdAniso { min_leap: 1 }),
        ("octree".into(), Method::Octree),
    ];
    for (k, kind) in kinds {
        g.push((
            format!("dda-{k}"),
            Method::Dda {
                kind,
                switch_fvt: true,
            },
        ));
    }
    if no_switch {
        for (k, kind) in kinds {
            g.push((
                format!("dda-{k}-noswitch"),
                Method::Dda {
                    kind,
                    switch_fvt: false,
                },
            ));
        }
    }
    // Fig. 20: CD switched to FVT at distance D, i.e. single-cell steps
    // in cells of code <= D (`min_leap = D + 1`; D = 3 is the old
    // `cd-leap4`).
    for d in 1..=3u8 {
        g.push((format!("cd-switch{d}"), Method::Cd { min_leap: d + 1 }));
    }
    g
}

/// Benchmarks `f` (one image) under criterion with `iter_custom` and
/// returns the median time per call over the measurement samples (the
/// last `samples` criterion took; the warm-up comes first), or `None` when
/// the benchmark was filtered out.
fn measure(
    g: &mut BenchmarkGroup<'_, WallTime>,
    id: BenchmarkId,
    samples: usize,
    mut f: impl FnMut() -> u64,
) -> Option<f64> {
    let mut log: Vec<f64> = Vec::new();
    g.bench_function(id, |b| {
        b.iter_custom(|iters| {
            let t = Instant::now();
            for _ in 0..iters {
                black_box(f());
            }
            let e = t.elapsed();
            log.push(e.as_secs_f64() / iters.max(1) as f64);
            e
        })
    });
    if log.is_empty() {
        return None;
    }
    let mut last = log[log.len().saturating_sub(samples)..].to_vec();
    last.sort_by(f64::total_cmp);
    Some(last[last.len() / 2])
}

const SAMPLES: usize = 10;

fn small_group<'c>(c: &'c mut Criterion, name: &str) -> BenchmarkGroup<'c, WallTime> {
    let mut g = c.benchmark_group(name);
    g.sample_size(SAMPLES);
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(1));
    g
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let mut g = small_group(c, "background");
    for n in [2usize, 10, 21] {
        let vol = scene(dir.path(), n);
        let grid = TGrid::<f64>::new(&vol.header().axes);
        let (lo, hi) = grid.bounds();
        let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let cam = Camera::look_at(
            [centre[0], lo[1] - 10.0, centre[2]],
            centre,
            [0.0, 0.0, 1.0],
            cdvol::render::view::camera::Projection::Ortho {
                frame_mm: hi[2] - lo[2],
            },
            250,
            250,
        )
        .unwrap();
        let rays = all_rays(&cam);
        let cache = BrickCache::new(&vol, 1 << 30);
        let ocache = BrickCache::new(&vol, 1 << 30).with_octree();
        g.throughput(Throughput::Elements(rays.len() as u64));
        let mut fvt_ns = None;
        let mut table = Vec::new();
        // The DDA without the switch once, on the middle scene.
        for (name, m) in generators(n == 10) {
            let c = if m == Method::Octree { &ocache } else { &cache };
            let mut acc = Accessor::new(c);
            let steps = background(&grid, &rays, m, &mut acc);
            let t = measure(&mut g, BenchmarkId::new(&name, n), SAMPLES, || {
                background(&grid, &rays, m, &mut acc)
            });
            let Some(t) = t else { continue };
            let ns = t * 1e9 / steps as f64;
            if m == Method::Fvt {
                fvt_ns = Some(ns);
            }
            table.push((name, t, steps, ns));
        }
        eprintln!(
            "\nN={n}: generator | ms/image | Mrays/s | steps/ray | ns/step | step cost / FVT"
        );
        for (name, t, steps, ns) in table {
            eprintln!(
                "N={n} {name} | {:.2} | {:.2} | {:.2} | {:.2} | {}",
                t * 1e3,
                rays.len() as f64 / t * 1e-6,
                steps as f64 / rays.len() as f64,
                ns,
                fvt_ns.map_or("-".into(), |f| format!("{:.2}", ns / f)),
            );
        }
    }
    g.finish();
}

/// Initialisation per ray (paper Table 2, "initialization time"). The
/// definition used here: 250x250 parallel rays of an oblique view
/// (azimuth 30, elevation 20, so no direction component is zero), each
/// started `1e-3 mm / max|dir_k|` before the point where it leaves the
/// volume (`t_min`), i.e. inside the last cell it crosses, and traced as in
/// [`background`]. Every ray then takes one step (checked: steps per ray
/// is printed) and leaves, or stops at once in a 1-cell, so the time per
/// ray is the generator's set-up (direction, mirroring, slab test, Locate
/// of the first cell, the first plane crossings, and the DDA's norms) plus
/// one step. Rays that miss the volume, or cross it over less than
/// `2e-3 mm / max|dir_k|`, are left out. One scene (N = 10): the measure
/// does not depend on the scene.
fn init(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let mut g = small_group(c, "init");
    let n = 10;
    let vol = scene(dir.path(), n);
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let (lo, hi) = grid.bounds();
    let cam = Camera::orbit((lo, hi), 30.0, 20.0, None, None, 250, 250).unwrap();
    let rays: Vec<(Ray, f64)> = all_rays(&cam)
        .into_iter()
        .filter_map(|r| {
            let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
            for k in 0..3 {
                let d = r.dir[k];
                if d == 0.0 {
                    return None;
                }
                let (a, b) = ((lo[k] - r.origin[k]) / d, (hi[k] - r.origin[k]) / d);
                t_in = t_in.max(a.min(b));
                t_out = t_out.min(a.max(b));
            }
            let m = r.dir.to_array().iter().fold(0.0f64, |m, d| m.max(d.abs()));
            let eps = 1e-3 / m;
            (t_out - t_in > 2.0 * eps).then_some((r, t_out - eps))
        })
        .collect();
    let cache = BrickCache::new(&vol, 1 << 30);
    let ocache = BrickCache::new(&vol, 1 << 30).with_octree();
    g.throughput(Throughput::Elements(rays.len() as u64));
    let mut fvt_ns = None;
    let mut table = Vec::new();
    // The CD switch variants and the DDA without the switch set up as CD
    // and the DDA do.
    for (name, m) in generators(false)
        .into_iter()
        .filter(|(n, _)| !n.starts_with("cd-switch"))
    {
        let c = if m == Method::Octree { &ocache } else { &cache };
        let mut acc = Accessor::new(c);
        let steps = from_t(&grid, &rays, m, &mut acc);
        let Some(t) = measure(&mut g, BenchmarkId::new(&name, n), SAMPLES, || {
            from_t(&grid, &rays, m, &mut acc)
        }) else {
            continue;
        };
        let ns = t * 1e9 / rays.len() as f64;
        if m == Method::Fvt {
            fvt_ns = Some(ns);
        }
        table.push((name, steps, ns));
    }
    eprintln!(
        "\ninit ({} rays): generator | steps/ray | ns/ray | init / FVT",
        rays.len()
    );
    for (name, steps, ns) in table {
        eprintln!(
            "init {name} | {:.3} | {:.2} | {}",
            steps as f64 / rays.len() as f64,
            ns,
            fvt_ns.map_or("-".into(), |f| format!("{:.2}", ns / f)),
        );
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

criterion_group!(benches, bench, init, precision);
criterion_main!(benches);
