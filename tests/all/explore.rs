//! Issue 16, items 3 and 4 and the silent empty results: value histograms
//! recorded by prep (counts against a brute-force count of the raw
//! samples, percentiles against a sort), shown by `info` and plotted by
//! `cdvol histogram`; the warning when a classification selects no cells
//! or nearly all; the shipped presets and `prep --preset`.

use std::path::{Path, PathBuf};

use crate::common::{cdvol, fails, ok, packed, real_ct, rewrite_header, write_stack};
use cdvol::format::histogram::ValueHistogram;
use cdvol::format::reader::PackedVolume;
use cdvol::progress::NoProgress;
use cdvol::tools::phantom;

/// Nearest-rank percentile (per mille) of sorted values, as the header
/// defines it: the smallest value with at least that share at or below.
fn nearest_rank(sorted: &[f64], per_mille: u64) -> f64 {
    let rank = (per_mille as usize * sorted.len()).div_ceil(1000).max(1);
    sorted[rank - 1]
}

/// The percentiles the header records, in per mille.
const PER_MILLE: [u64; 9] = [1, 10, 50, 250, 500, 750, 950, 990, 999];

/// A CT phantom stored as u16 = HU + 1024 with a rescale back to HU.
fn u16_phantom(dir: &Path) -> (PathBuf, Vec<f64>) {
    let json = dir.join("head.json");
    phantom::ct(
        &json,
        &phantom::CtOptions {
            dims: [40, 36, 30],
            dtype: phantom::CtDtype::U16,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    // The rescale from the sidecar, the samples from the raw file: no
    // library code between them and the oracle.
    let side: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let slope = side["rescale"]["slope"].as_f64().unwrap_or(1.0);
    let intercept = side["rescale"]["intercept"].as_f64().unwrap_or(0.0);
    assert!(
        intercept != 0.0,
        "the u16 phantom carries a rescale: {side}"
    );
    let raw = std::fs::read(dir.join("head.raw")).unwrap();
    let hu = raw
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]) as f64 * slope + intercept)
        .collect();
    (json, hu)
}

#[test]
fn histogram_counts_every_raw_sample_in_rescaled_units() {
    let dir = tempfile::tempdir().unwrap();
    let (json, hu) = u16_phantom(dir.path());
    let vol = packed(&json, &dir.path().join("head.cdv"), 300.0);
    let h = vol.header().summary.histogram.clone().expect("a histogram");
    assert_eq!(h.samples, hu.len() as u64);
    assert_eq!(h.nan, 0);
    let (lo, hi) = hu
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    assert_eq!((h.min, h.max), (Some(lo), Some(hi)));
    // The phantom spans fewer than 4096 integers: one bin per value.
    assert!(h.exact && h.bin_width == 1.0, "{} {}", h.exact, h.bin_width);
    assert_eq!(h.lo, lo - 0.5);
    assert_eq!(h.counts.len() as f64, hi - lo + 1.0);
    let mut brute = vec![0u64; h.counts.len()];
    for &v in &hu {
        brute[(v - lo) as usize] += 1;
    }
    assert_eq!(h.counts, brute);
    let mut sorted = hu.clone();
    sorted.sort_by(f64::total_cmp);
    for (p, &pm) in h.percentiles.iter().zip(&PER_MILLE) {
        assert_eq!(p[0], pm as f64 / 10.0);
        assert_eq!(p[1], nearest_rank(&sorted, pm), "percentile {}", p[0]);
    }
}

#[test]
fn integer_percentiles_are_exact_nearest_ranks() {
    // 1001 distinct values in shuffled order: every rank is a different
    // value, so an off-by-one rank shows.
    let dir = tempfile::tempdir().unwrap();
    let dims = [11usize, 13, 7];
    let values: Vec<f64> = (0..1001u64)
        .map(|i| ((i * 7919) % 1001) as f64 - 500.0)
        .collect();
    let json = write_stack(dir.path(), "d", dims, "i16", &values, ["1", "1", "1"], "");
    let vol = packed(&json, &dir.path().join("d.cdv"), 0.0);
    let h = vol.header().summary.histogram.clone().unwrap();
    assert!(h.exact);
    assert_eq!(h.counts, vec![1u64; 1001]);
    let mut sorted = values.clone();
    sorted.sort_by(f64::total_cmp);
    let got: Vec<f64> = h.percentiles.iter().map(|p| p[1]).collect();
    let want: Vec<f64> = PER_MILLE
        .iter()
        .map(|&pm| nearest_rank(&sorted, pm))
        .collect();
    assert_eq!(got, want);
    // Nearest rank: p0.1 of 1001 values is the 2nd smallest.
    assert_eq!(got[0], -499.0);
}

#[test]
fn float_histogram_counts_nan_apart_and_percentiles_within_a_bin() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [17usize, 13, 11];
    let n = dims.iter().product::<usize>();
    // Slices of growing ranges, so the bins widen on the way; NaN too.
    let values: Vec<f64> = (0..n)
        .map(|i| {
            let z = i / (dims[0] * dims[1]);
            match crate::common::mix(i as u64) % 97 {
                0 => f64::NAN,
                r => ((r as f64 * 0.731).sin() * (1.0 + z as f64 * 300.0)) as f32 as f64,
            }
        })
        .collect();
    let axes = ["1", "1", "1"];
    let json = write_stack(dir.path(), "f", dims, "f32", &values, axes, "");
    let vol = packed(&json, &dir.path().join("f.cdv"), 0.0);
    let h = vol.header().summary.histogram.clone().unwrap();
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    assert_eq!(h.nan, (n - finite.len()) as u64);
    assert!(h.nan > 0);
    assert_eq!(h.samples, finite.len() as u64);
    assert!(!h.exact);
    assert!(h.counts.len() <= 4096);
    let mut brute = vec![0u64; h.counts.len()];
    for &v in &finite {
        brute[((v - h.lo) / h.bin_width).floor() as usize] += 1;
    }
    assert_eq!(h.counts, brute);
    let mut sorted = finite.clone();
    sorted.sort_by(f64::total_cmp);
    for (p, &pm) in h.percentiles.iter().zip(&PER_MILLE) {
        let want = nearest_rank(&sorted, pm);
        assert!(
            (p[1] - want).abs() <= h.bin_width,
            "p{}: {} vs {want} (bin {})",
            p[0],
            p[1],
            h.bin_width
        );
    }
}

#[test]
fn info_shows_the_histogram_and_its_json_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let (json, _) = u16_phantom(dir.path());
    let file = dir.path().join("head.cdv");
    let vol = packed(&json, &file, 300.0);
    let want = vol.header().summary.histogram.clone().unwrap();
    let out = ok(cdvol().args(["info", "--json"]).arg(&file));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let got: ValueHistogram = serde_json::from_value(v["histogram"].clone()).unwrap();
    assert_eq!(got, want);
    let text = ok(cdvol().arg("info").arg(&file));
    let p50 = want.percentile(50.0).unwrap();
    for part in [
        "percentiles  p0.1=".to_string(),
        format!("p50={p50}"),
        "(exact)".into(),
        "value histogram".into(),
    ] {
        assert!(text.contains(&part), "{part} missing from:\n{text}");
    }
}

#[test]
fn files_without_a_histogram_still_read() {
    let dir = tempfile::tempdir().unwrap();
    let (json, _) = u16_phantom(dir.path());
    let file = dir.path().join("head.cdv");
    packed(&json, &file, 300.0);
    // An older file: no `histogram` key in the summary.
    let old = rewrite_header(&std::fs::read(&file).unwrap(), |h| {
        let removed = h["summary"].as_object_mut().unwrap().remove("histogram");
        assert!(removed.is_some());
    });
    let old_file = dir.path().join("old.cdv");
    std::fs::write(&old_file, old).unwrap();
    let vol = PackedVolume::open(&old_file).unwrap();
    assert!(vol.header().summary.histogram.is_none());
    let text = ok(cdvol().arg("info").arg(&old_file));
    assert!(!text.contains("percentiles"));
    let err = fails(
        cdvol()
            .arg("histogram")
            .arg(&old_file)
            .arg("-o")
            .arg(dir.path().join("h.png")),
    );
    assert!(err.contains("no value histogram"), "{err}");
    // A histogram whose counts do not add up is refused on open.
    let bad = rewrite_header(&std::fs::read(&file).unwrap(), |h| {
        h["summary"]["histogram"]["samples"] = 7.into();
    });
    std::fs::write(&old_file, bad).unwrap();
    let e = PackedVolume::open(&old_file).err().unwrap().to_string();
    assert!(e.contains("summary.histogram.samples"), "{e}");
}

#[test]
fn histogram_plots_png_and_svg_and_refuses_other_extensions() {
    let dir = tempfile::tempdir().unwrap();
    let (json, _) = u16_phantom(dir.path());
    let file = dir.path().join("head.cdv");
    packed(&json, &file, 300.0);
    let png = dir.path().join("h.png");
    ok(cdvol()
        .arg("histogram")
        .arg(&file)
        .arg("-o")
        .arg(&png)
        .args(["--width", "640", "--height", "480"]));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (640, 480));
    // The bars (blue) and the iso line (red) are drawn.
    let has = |f: &dyn Fn(&image::Rgb<u8>) -> bool| img.pixels().any(f);
    assert!(has(&|p| p[2] > 150 && p[0] < 80), "no bars");
    assert!(
        has(&|p| p[0] > 180 && p[1] < 60 && p[2] < 60),
        "no iso line"
    );
    let svg = dir.path().join("h.svg");
    ok(cdvol().arg("histogram").arg(&file).arg("-o").arg(&svg));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg"));
    for part in ["iso 300", "ct-bone", "ct-lung", "percentiles"] {
        assert!(text.contains(part), "{part} missing from the SVG");
    }
    // --presets picks the lanes.
    ok(cdvol()
        .arg("histogram")
        .arg(&file)
        .arg("-o")
        .arg(&svg)
        .args(["--presets", "mr-mip"]));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("mr-mip") && !text.contains("ct-bone"));
    for bad in ["h.jpg", "h.tiff", "h"] {
        let out = dir.path().join(bad);
        let err = fails(cdvol().arg("histogram").arg(&file).arg("-o").arg(&out));
        assert!(err.contains("expected .png or .svg"), "{err}");
        assert!(!out.exists());
    }
    let err = fails(
        cdvol()
            .arg("histogram")
            .arg(&file)
            .arg("-o")
            .arg(&png)
            .args(["--presets", "ct-bonez"]),
    );
    assert!(err.contains("unknown preset \"ct-bonez\"") && err.contains("ct-bone"));
}

#[test]
fn prep_warns_when_the_iso_selects_no_cells_or_nearly_all() {
    let ct = real_ct();
    let dir = tempfile::tempdir().unwrap();
    // No cell: refused before anything is written (issue 51, item 5).
    let out = cdvol()
        .args(["prep", "--iso", "5000"])
        .arg(&ct)
        .arg("-o")
        .arg(dir.path().join("empty.cdv"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    for w in [
        "iso 5000 selects no cells",
        "the data range is -1024 .. 2986",
        "nothing written",
        "--allow-empty",
    ] {
        assert!(err.contains(w), "{w:?} not in {err}");
    }
    assert!(!dir.path().join("empty.cdv").exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "no temporary left"
    );
    // --allow-empty writes it, with the warning.
    let out = cdvol()
        .args(["prep", "--iso", "5000", "--allow-empty"])
        .arg(&ct)
        .arg("-o")
        .arg(dir.path().join("empty.cdv"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    for text in [&*err, &*stdout] {
        assert!(
            text.contains("warning: iso 5000 selects no cells")
                && text.contains("the data range is -1024 .. 2986"),
            "{text}"
        );
    }
    let info = ok(cdvol().arg("info").arg(dir.path().join("empty.cdv")));
    assert!(
        info.contains("warning      iso 5000 selects no cells"),
        "{info}"
    );
    // Nearly every cell: below the air.
    let out = cdvol()
        .args(["prep", "--iso", "-2000"])
        .arg(&ct)
        .arg("-o")
        .arg(dir.path().join("full.cdv"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("iso -2000 selects 100.0 % of the cells"),
        "{err}"
    );
    // A sensible iso: no warning.
    let out = cdvol()
        .args(["prep", "--iso", "300"])
        .arg(&ct)
        .arg("-o")
        .arg(dir.path().join("bone.cdv"))
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
}

#[test]
fn prep_batch_reports_inputs_whose_classification_is_empty() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    // Two phantoms: HU (air -1000 .. bone) and a small-valued "MR".
    phantom::ct(
        &input.join("ct.json"),
        &phantom::CtOptions {
            dims: [20, 18, 12],
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let mr: Vec<f64> = (0..16 * 16 * 10).map(|i| (i % 131) as f64).collect();
    write_stack(&input, "mr", [16, 16, 10], "u8", &mr, ["1", "1", "1"], "");
    let out = dir.path().join("out");
    let run = cdvol()
        .args(["prep-batch", "-q", "--iso", "300", "--allow-empty"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("batch.json")).unwrap()).unwrap();
    let row = |name: &str| {
        rows.iter()
            .find(|r| r["input"] == name)
            .unwrap_or_else(|| panic!("{name} in {rows:?}"))
            .clone()
    };
    assert!(row("ct.json")["warning"].is_null(), "{rows:?}");
    let w = row("mr.json")["warning"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(
        w.contains("iso 300 selects no cells") && w.contains("0 .. 130"),
        "{w}"
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("warning: mr.json: iso 300 selects no cells"),
        "{stdout}"
    );
}

#[test]
fn every_preset_is_listed_and_checks() {
    let out = ok(cdvol().args(["presets", "--json"]));
    let all: Vec<serde_json::Value> = serde_json::from_str(&out).unwrap();
    assert!(all.len() >= 10);
    for p in &all {
        let tf: cdvol::classify::TransferFunction =
            serde_json::from_value(p["tf"].clone()).unwrap();
        tf.check().unwrap_or_else(|e| panic!("{}: {e}", p["name"]));
        assert!(p["sources"]["tf"].as_str().is_some_and(|s| !s.is_empty()));
    }
    let table = ok(cdvol().arg("presets"));
    for name in [
        "ct-bone",
        "ct-skin",
        "ct-soft-tissue",
        "ct-muscle",
        "ct-lung",
        "ct-vessels",
        "ct-mip",
        "mr-default",
        "mr-brain",
        "mr-mip",
    ] {
        assert!(table.contains(name), "{name} missing:\n{table}");
        cdvol::presets::get(name).unwrap();
    }
}

#[test]
fn prep_preset_equals_classify_tf_with_the_same_function() {
    let ct = real_ct();
    let dir = tempfile::tempdir().unwrap();
    let tf = dir.path().join("bone.json");
    std::fs::write(&tf, ok(cdvol().args(["presets", "--tf", "ct-bone"]))).unwrap();
    let (a, b) = (dir.path().join("preset.cdv"), dir.path().join("tf.cdv"));
    ok(cdvol()
        .args(["prep", "--preset", "ct-bone", "--brick", "16"])
        .arg(&ct)
        .arg("-o")
        .arg(&a));
    ok(cdvol()
        .args(["prep", "--brick", "16", "--classify-tf"])
        .arg(&tf)
        .arg(&ct)
        .arg("-o")
        .arg(&b));
    let (va, vb) = (
        PackedVolume::open(&a).unwrap(),
        PackedVolume::open(&b).unwrap(),
    );
    assert_eq!(va.header().classification, vb.header().classification);
    assert_eq!(
        va.header().classification,
        cdvol::presets::get("ct-bone").unwrap().classification()
    );
    crate::common::assert_same_volume(&va, &vb, "--preset ct-bone vs --classify-tf");
    // The same header but for the look `--preset` records.
    assert_eq!(va.header().look.as_deref(), Some("ct-bone"));
    assert_eq!(vb.header().look, None);
    let mut ha = va.header().clone();
    ha.look = None;
    assert_eq!(&ha, vb.header());
    // One classification at a time.
    for other in [["--iso", "300"], ["--classify-tf", "x.json"]] {
        let err = fails(
            cdvol()
                .args(["prep", "--preset", "ct-bone"])
                .args(other)
                .arg(&ct)
                .arg("-o")
                .arg(dir.path().join("x.cdv")),
        );
        assert!(err.contains("--preset") && err.contains(other[0]), "{err}");
    }
    let err = fails(
        cdvol()
            .args(["prep", "--preset", "ct-bonez"])
            .arg(&ct)
            .arg("-o")
            .arg(dir.path().join("x.cdv")),
    );
    assert!(
        err.contains("option --preset: unknown preset \"ct-bonez\"") && err.contains("mr-mip"),
        "{err}"
    );
}
