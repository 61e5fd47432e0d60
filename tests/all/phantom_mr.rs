//! `cdvol phantom mr`: the MR head, generated and prepared by the binary,
//! has the value histogram of a T1-weighted scan on its own `--scale`: a
//! Rayleigh noise floor near 0 and a tissue mode at the white matter
//! intensity, far apart; skull-stripped, the floor is exactly 0.

use cdvol::format::histogram::ValueHistogram;
use cdvol::format::reader::PackedVolume;

use crate::common::{cdvol, ok};

/// Generates the default phantom (plus `extra` options), prepares it at
/// `iso`, and returns the packed file's value histogram.
fn histogram_of(dir: &std::path::Path, name: &str, extra: &[&str], iso: f64) -> ValueHistogram {
    let side = dir.join(format!("{name}.json"));
    let packed = dir.join(format!("{name}.cdv"));
    let out = ok(cdvol().args(["phantom", "mr", "-o"]).arg(&side).args(extra));
    assert!(out.contains("outer surface is at iso"), "{out}");
    ok(cdvol()
        .arg("prep")
        .arg(&side)
        .arg("-o")
        .arg(&packed)
        .args(["--iso", &iso.to_string()]));
    let vol = PackedVolume::open(&packed).unwrap();
    vol.header().summary.histogram.clone().expect("a histogram")
}

/// The histogram's counts summed over `[a, b)` (rescaled units).
fn count_in(h: &ValueHistogram, a: f64, b: f64) -> u64 {
    h.counts
        .iter()
        .enumerate()
        .filter(|&(i, _)| {
            let v = h.lo + (i as f64 + 0.5) * h.bin_width;
            v >= a && v < b
        })
        .map(|(_, &c)| c)
        .sum()
}

/// The percentile `p` (%) the header records.
fn pct(h: &ValueHistogram, p: f64) -> f64 {
    h.percentiles
        .iter()
        .find(|q| q[0] == p)
        .map(|q| q[1])
        .expect("a recorded percentile")
}

/// The most populated bucket of width `w` in `[a, b)`: its centre and
/// count.
fn mode_in(h: &ValueHistogram, a: f64, b: f64, w: f64) -> (f64, u64) {
    let mut best = (a, 0);
    let mut x = a;
    while x < b {
        let c = count_in(h, x, x + w);
        if c > best.1 {
            best = (x + 0.5 * w, c);
        }
        x += w;
    }
    best
}

#[test]
fn the_histogram_has_a_noise_floor_and_a_tissue_mode_on_the_scale() {
    let dir = tempfile::tempdir().unwrap();
    let scale = 713.0;
    let sigma = 0.03 * scale;
    let h = histogram_of(dir.path(), "head", &[], 0.3 * scale);
    assert_eq!(h.samples, 128 * 128 * 96);
    assert!(
        h.exact,
        "u16 samples spanning < 4096 values: exact percentiles"
    );
    println!("whole head: min {:?} max {:?}", h.min, h.max);
    for p in &h.percentiles {
        println!("  p{} = {}", p[0], p[1]);
    }
    // Two modes in buckets of 2 % of the scale: the Rayleigh floor peaks
    // at sigma, the tissue near the white matter intensity.
    let w = 0.02 * scale;
    let (bg, bg_n) = mode_in(&h, 0.0, 0.2 * scale, w);
    let (tissue, tissue_n) = mode_in(&h, 0.4 * scale, 1.4 * scale, w);
    println!("modes: background {bg} ({bg_n}), tissue {tissue} ({tissue_n})");
    assert!((bg - sigma).abs() <= 1.5 * w, "background mode {bg}");
    assert!(
        (0.6 * scale..=1.1 * scale).contains(&tissue),
        "tissue mode {tissue}"
    );
    // Between them (18 % to 40 % of the scale, CSF's partial volumes) a
    // valley far below both.
    let valley = (9..20)
        .map(|i| count_in(&h, i as f64 * w, (i + 1) as f64 * w))
        .min()
        .unwrap_or(u64::MAX);
    println!("valley {valley}");
    assert!(
        valley * 5 < tissue_n && valley * 50 < bg_n,
        "valley {valley}"
    );
    // The air around the head is most of the box, a Rayleigh floor (a few
    // samples round to 0); nothing is brighter than fat at the bright end
    // of the bias field plus noise.
    assert!(h.min.is_some_and(|m| m >= 0.0));
    assert!(pct(&h, 0.1) < 0.05 * scale);
    assert!(pct(&h, 50.0) < 0.1 * scale, "median {}", pct(&h, 50.0));
    assert!(pct(&h, 75.0) > 0.5 * scale, "p75 {}", pct(&h, 75.0));
    let p999 = pct(&h, 99.9);
    assert!((1.05 * scale..=1.5 * scale).contains(&p999), "p99.9 {p999}");
    assert!(h.max.is_some_and(|m| m < 1.6 * scale));

    // Skull-stripped: everything outside the brain is exactly 0, the brain
    // keeps its intensities (no fat: the top is white matter).
    let s = histogram_of(dir.path(), "brain", &["--skull-stripped"], 0.3 * scale);
    println!("skull-stripped: min {:?} max {:?}", s.min, s.max);
    for p in &s.percentiles {
        println!("  p{} = {}", p[0], p[1]);
    }
    assert_eq!(s.min, Some(0.0));
    let zeros = s.counts[0];
    assert!(zeros as f64 > 0.5 * s.samples as f64, "{zeros} zeros");
    // No noise floor: the darkest brain tissue (CSF, 0.25) is far above.
    let low = count_in(&s, 0.5, 0.1 * scale);
    assert!(low * 10_000 < s.samples, "{low} samples near 0");
    assert_eq!(pct(&s, 50.0), 0.0);
    let (brain, _) = mode_in(&s, 0.4 * scale, 1.4 * scale, w);
    assert!(
        (0.6 * scale..=1.1 * scale).contains(&brain),
        "brain mode {brain}"
    );
    let p999 = pct(&s, 99.9);
    assert!((0.95 * scale..=1.3 * scale).contains(&p999), "p99.9 {p999}");
}

#[test]
fn the_scale_moves_the_histogram() {
    let dir = tempfile::tempdir().unwrap();
    let a = histogram_of(
        dir.path(),
        "a",
        &["--dims", "48,48,36", "--scale", "713"],
        214.0,
    );
    let b = histogram_of(
        dir.path(),
        "b",
        &["--dims", "48,48,36", "--scale", "2139"],
        642.0,
    );
    for (p, q) in a.percentiles.iter().zip(&b.percentiles) {
        assert!(
            (q[1] - 3.0 * p[1]).abs() <= 3.0,
            "p{}: {} vs 3 x {}",
            p[0],
            q[1],
            p[1]
        );
    }
}
