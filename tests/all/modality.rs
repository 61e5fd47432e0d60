//! A file knows its modality and the look it was prepared with; presets
//! of the other modality are refused with the fix named; MR presets are
//! placed on the file's own values (issue 51, items 3, 4 and 5).

use std::path::{Path, PathBuf};

use cdvol::format::reader::PackedVolume;

use crate::common::{cdvol, fails, ok};

/// An MR head phantom (`cdvol phantom mr`) of WM intensity `scale`,
/// prepared with `prep_args`; returns the packed file.
fn mr_file(dir: &Path, name: &str, scale: f64, extra: &[&str], prep_args: &[&str]) -> PathBuf {
    let input = dir.join(format!("{name}.json"));
    let mut c = cdvol();
    c.args(["-q", "phantom", "mr", "--dims", "64,64,48", "--seed", "3"])
        .args(["--scale", &scale.to_string(), "-o"])
        .arg(&input)
        .args(extra);
    ok(&mut c);
    let out = dir.join(format!("{name}.cdv"));
    ok(cdvol()
        .args(["-q", "prep"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(prep_args));
    out
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("cdvol-modality-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn presets_of_the_other_modality_are_refused_with_the_fix_named() {
    let d = tmp("refuse");
    let input = d.join("mr.json");
    ok(cdvol()
        .args(["-q", "phantom", "mr", "--dims", "48,48,32", "-o"])
        .arg(&input));
    // info on the input says what prep will decide.
    let info = ok(cdvol().arg("info").arg(&input));
    assert!(info.contains("modality     MR (guessed"), "{info}");
    // prep: refused before anything is written, naming the MR presets
    // and --force.
    let out = d.join("bone.cdv");
    let e = fails(
        cdvol()
            .args(["-q", "prep"])
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .args(["--preset", "ct-bone"]),
    );
    crate::common::has_all(&e, &["ct-bone", "CT", "MR", "mr-default", "--force"]);
    assert!(!out.exists(), "{e}");
    // render: the same, and --force takes it.
    let f = mr_file(&d, "mr", 713.0, &[], &["--envelope", "auto"]);
    let png = d.join("a.png");
    let e = fails(
        cdvol()
            .args(["-q", "render"])
            .arg(&f)
            .arg("-o")
            .arg(&png)
            .args(["--preset", "ct-bone", "--width", "32", "--height", "32"]),
    );
    crate::common::has_all(&e, &["ct-bone", "mr-default", "--force"]);
    ok(cdvol()
        .args(["-q", "render"])
        .arg(&f)
        .arg("-o")
        .arg(&png)
        .args([
            "--preset", "ct-bone", "--force", "--width", "32", "--height", "32",
        ]));
    // info lists only the presets of the file's modality, and says where
    // the modality came from.
    let info = ok(cdvol().arg("info").arg(&f));
    let presets = info
        .lines()
        .find(|l| l.contains("composite/--tf"))
        .unwrap_or_default();
    assert!(
        presets.contains("mr-default") && !presets.contains("ct-"),
        "{info}"
    );
    assert!(info.contains("modality     MR (guessed"), "{info}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn the_modality_comes_from_dicom_the_sidecar_or_the_flag() {
    let d = tmp("source");
    // DICOM: the series' Modality tag (the test writer says CT).
    let series = d.join("series");
    std::fs::create_dir_all(&series).unwrap();
    crate::common::dicom_series::write_series(&series);
    let f = d.join("dicom.cdv");
    ok(cdvol()
        .args(["-q", "prep"])
        .arg(&series)
        .arg("-o")
        .arg(&f)
        .args(["--iso", "0"]));
    let h = PackedVolume::open(&f).unwrap().header().modality();
    assert_eq!(h.modality, cdvol::presets::Modality::Ct);
    assert!(h.source.contains("DICOM Modality"), "{h:?}");
    // --modality wins over a guess, and is said to.
    let input = d.join("mr.json");
    ok(cdvol()
        .args(["-q", "phantom", "mr", "--dims", "32,32,24", "-o"])
        .arg(&input));
    let f = d.join("flag.cdv");
    ok(cdvol()
        .args(["-q", "prep"])
        .arg(&input)
        .arg("-o")
        .arg(&f)
        .args(["--iso", "100", "--modality", "ct"]));
    let m = PackedVolume::open(&f).unwrap().header().modality();
    assert_eq!(m.modality, cdvol::presets::Modality::Ct);
    assert_eq!(m.source, "prep --modality");
    // A sidecar's "modality" key.
    let text = std::fs::read_to_string(&input).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["modality"] = "CT".into();
    let side = d.join("said.json");
    std::fs::write(&side, v.to_string()).unwrap();
    let f = d.join("said.cdv");
    ok(cdvol()
        .args(["-q", "prep"])
        .arg(&side)
        .arg("-o")
        .arg(&f)
        .args(["--iso", "100"]));
    let m = PackedVolume::open(&f).unwrap().header().modality();
    assert_eq!(m.modality, cdvol::presets::Modality::Ct);
    assert!(m.source.contains("sidecar"), "{m:?}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_file_prepared_with_a_preset_renders_it_by_default() {
    let d = tmp("look");
    let f = mr_file(&d, "brain", 713.0, &[], &["--preset", "mr-default"]);
    let info = ok(cdvol().arg("info").arg(&f));
    assert!(info.contains("look         mr-default"), "{info}");
    // No --mode, --tf or --preset: the look, in composite.
    let a = d.join("a.png");
    let b = d.join("b.png");
    let size = ["--width", "48", "--height", "48"];
    ok(cdvol().arg("render").arg(&f).arg("-o").arg(&a).args(size));
    ok(cdvol()
        .args(["render", "--mode", "composite"])
        .arg(&f)
        .arg("-o")
        .arg(&b)
        .args(size));
    let c = d.join("c.png");
    ok(cdvol()
        .args(["render", "--mode", "composite", "--preset", "mr-default"])
        .arg(&f)
        .arg("-o")
        .arg(&c)
        .args(size));
    let px = |p: &Path| image::open(p).unwrap().to_rgb8().into_raw();
    assert_eq!(px(&a), px(&c), "the default is the look, in composite");
    assert_eq!(px(&b), px(&c));
    assert!(px(&c).iter().any(|&v| v > 20), "the look draws something");
    std::fs::remove_dir_all(&d).unwrap();
}

/// The landmarks of the same anatomy at two intensity scales: MR presets
/// placed on them move with the scale, so the same preset draws the same
/// picture (up to noise) whatever the scanner's units.
#[test]
fn mr_presets_follow_the_files_scale() {
    let d = tmp("scale");
    let small = mr_file(&d, "small", 300.0, &[], &["--envelope", "auto"]);
    let large = mr_file(&d, "large", 3000.0, &[], &["--envelope", "auto"]);
    let iso = |f: &Path| match PackedVolume::open(f).unwrap().header().classification {
        cdvol::classify::Classification::Iso { iso } => iso,
        _ => unreachable!(),
    };
    let (a, b) = (iso(&small), iso(&large));
    assert!((b / a - 10.0).abs() < 1.0, "envelope auto iso {a} vs {b}");
    let placed = |f: &Path| {
        let v = PackedVolume::open(f).unwrap();
        cdvol::look::preset(v.header(), "mr-brain", false).unwrap()
    };
    let (p, q) = (placed(&small), placed(&large));
    for (x, y) in p.tf.points.iter().zip(&q.tf.points) {
        let r = y.value / x.value;
        assert!(
            x.value <= 0.0 || (r - 10.0).abs() < 1.0,
            "{} vs {}",
            x.value,
            y.value
        );
    }
    std::fs::remove_dir_all(&d).unwrap();
}
