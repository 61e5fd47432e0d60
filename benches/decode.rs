//! Brick decode throughput against zstd alone, on the real bricks of a
//! packed file: per brick, (1) zstd decompression of the stored bytes,
//! (2) `read_payload` (positioned read, CRC, zstd), (3) the render
//! cache's whole decode (`RBrick::decode`: read, zstd, values, codes,
//! classification) and (4)/(5) the fast and reference paths from the
//! decompressed payload alone. Throughput in decoded sample bytes (the
//! decompressed payload), so MB/s compare directly with `zstd -d`.
//!
//! Bricks are split into those holding 1-cells and those without (the
//! index's flag: only their codes are built).
//!
//! Run: `CDVOL_DECODE_FILE=ph1024.cdv cargo bench --bench decode`
//! (`CDVOL_DECODE_DUMP=PREFIX` also writes the stored frames of each set
//! to `PREFIX.object.zst` and `PREFIX.no_object.zst` for `zstd -d`); without
//! the variable, a 256^3 u16 CT phantom (bone at 300 HU) is made in a
//! temporary directory. Figures go to docs/BENCHMARKS.md, "What a
//! decode costs".

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::render::brick::{Planes, RBrick};

fn volume(tmp: &tempfile::TempDir) -> PackedVolume {
    let path = match std::env::var_os("CDVOL_DECODE_FILE") {
        Some(p) => std::path::PathBuf::from(p),
        None => {
            use cdvol::tools::phantom::{ct, CtDtype, CtOptions};
            let json = tmp.path().join("ph.json");
            let opts = CtOptions {
                dims: [256, 256, 256],
                dtype: CtDtype::U16,
                ..CtOptions::default()
            };
            ct(&json, &opts, &cdvol::progress::NoProgress).expect("phantom");
            let src = cdvol::input::open(&json).expect("open phantom");
            let out = tmp.path().join("ph.cdv");
            let popts = cdvol::prep::PrepOptions::new(Classification::Iso { iso: 300.0 });
            cdvol::prep::prep(src.as_ref(), &out, &popts, &cdvol::progress::NoProgress)
                .expect("prep");
            out
        }
    };
    PackedVolume::open(&path).expect("open packed file")
}

fn bench(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("tempdir");
    let vol = volume(&tmp);
    let h = vol.header().clone();
    let mut g = c.benchmark_group("decode");
    g.sample_size(10)
        .warm_up_time(std::time::Duration::from_secs(1))
        .measurement_time(std::time::Duration::from_secs(3));
    for (name, no_object) in [("object", false), ("no_object", true)] {
        // Up to 256 bricks of the kind, spread over the file.
        let all: Vec<u64> = (0..h.brick_count())
            .filter(|&i| {
                let e = vol.index()[i as usize];
                !e.is_uniform() && e.has_no_object() == no_object
            })
            .collect();
        let ids: Vec<u64> = all
            .iter()
            .step_by(all.len().div_ceil(256).max(1))
            .copied()
            .collect();
        if ids.is_empty() {
            continue;
        }
        let comp: Vec<Vec<u8>> = ids
            .iter()
            .map(|&i| {
                let e = vol.index()[i as usize];
                let mut b = vec![0u8; e.length as usize];
                std::os::unix::fs::FileExt::read_exact_at(
                    &std::fs::File::open(vol.path()).expect("reopen"),
                    &mut b,
                    e.offset,
                )
                .expect("read");
                b
            })
            .collect();
        let raws: Vec<Vec<u8>> = ids
            .iter()
            .map(|&i| vol.read_payload(i).expect("payload").expect("not uniform"))
            .collect();
        // For `zstd -d` of the same bytes: the stored frames, one after
        // another (a valid multi-frame stream).
        if let Some(d) = std::env::var_os("CDVOL_DECODE_DUMP") {
            let mut p = std::path::PathBuf::from(d).into_os_string();
            p.push(format!(".{name}.zst"));
            std::fs::write(&p, comp.concat()).expect("dump");
        }
        let bytes: u64 = raws.iter().map(|r| r.len() as u64).sum();
        let stored: u64 = comp.iter().map(|r| r.len() as u64).sum();
        eprintln!(
            "{name}: {} bricks, {bytes} payload bytes, {stored} stored ({:.1}:1)",
            ids.len(),
            bytes as f64 / stored as f64
        );
        g.throughput(Throughput::Bytes(bytes));
        let mut dctx = zstd::bulk::Decompressor::new().expect("zstd context");
        let mut out = Vec::new();
        g.bench_function(format!("{name}/zstd"), |b| {
            b.iter(|| {
                for (c, r) in comp.iter().zip(&raws) {
                    out.clear();
                    out.reserve(r.len());
                    dctx.decompress_to_buffer(c.as_slice(), &mut out)
                        .expect("zstd");
                    black_box(&out);
                }
            })
        });
        g.bench_function(format!("{name}/read_payload"), |b| {
            b.iter(|| {
                for &i in &ids {
                    black_box(vol.read_payload(i).expect("payload"));
                }
            })
        });
        g.bench_function(format!("{name}/rbrick_decode"), |b| {
            b.iter(|| {
                for &i in &ids {
                    black_box(RBrick::decode(&vol, i, Planes::NONE, false).expect("decode"));
                }
            })
        });
        g.bench_function(format!("{name}/from_payload"), |b| {
            b.iter(|| {
                for (&i, r) in ids.iter().zip(&raws) {
                    black_box(RBrick::from_payload(&h, i, no_object, r, Planes::NONE));
                }
            })
        });
        g.bench_function(format!("{name}/from_payload_reference"), |b| {
            b.iter(|| {
                for (&i, r) in ids.iter().zip(&raws) {
                    black_box(RBrick::from_payload_reference(
                        &h,
                        i,
                        no_object,
                        r,
                        Planes::NONE,
                    ));
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
