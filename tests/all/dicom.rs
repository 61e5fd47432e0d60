//! DICOM series (written here with dicom-rs) prepare to the same packed
//! volume as the raw stack of the same samples and z positions, whatever
//! the file names and order; the z spacing report names the files; broken
//! series are refused naming the file and the tag.

use std::path::{Path, PathBuf};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::dicom::{open_dir, DicomSource};
use cdvol::input::SliceSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;

use crate::common::assert_same_volume;
use crate::common::dicom_series;
use dicom_series::*;

/// The same samples as a raw stack with listed z positions.
fn reference(dir: &Path) -> PathBuf {
    let raw: Vec<u8> = (0..z_positions().len())
        .flat_map(slice)
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(dir.join("ref.raw"), raw).unwrap();
    let side = serde_json::json!({
        "data": "ref.raw", "dims": [NX, NY, z_positions().len()], "dtype": "u16",
        "x": 0.7, "y": 0.8, "z": {"positions": z_positions()}, "origin": [10.0, -5.0, 0.0],
        "rescale": {"slope": 1.0, "intercept": -1024.0},
    });
    let p = dir.join("ref.json");
    std::fs::write(&p, side.to_string()).unwrap();
    p
}

fn pack(src: &dyn cdvol::input::SliceSource, out: &Path) -> PackedVolume {
    let mut o = PrepOptions::new(Classification::Iso { iso: 300.0 });
    o.brick_size = 8;
    prep(src, out, &o, &NoProgress).unwrap();
    PackedVolume::open(out).unwrap()
}

#[test]
fn series_prepares_like_the_raw_stack_and_reports_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let series = d.join("series");
    let files = write_series(&series);
    std::fs::write(series.join("README.txt"), "not DICOM").unwrap();
    let src: DicomSource = open_dir(&series, None).unwrap();
    let got = pack(&src, &d.join("dicom.cdv"));
    let want = pack(
        &cdvol::input::raw::RawSource::open(&reference(d)).unwrap(),
        &d.join("ref.cdv"),
    );
    assert_same_volume(&got, &want, "DICOM series");
    // 8 gaps of 1 mm are the most common; 6 of 2 mm and 5 of 4 mm differ.
    let r = src.spacing_report();
    assert_eq!(r.len(), 1 + 6 + 5, "{r:#?}");
    assert!(
        r[0].contains("most common spacing 1.00 mm (8 of 19 gaps)"),
        "{}",
        r[0]
    );
    let name = |k: usize| files[k].file_name().unwrap().to_string_lossy().into_owned();
    let want_line = format!(
        "1.00 mm expected, 4.00 mm found between {} and {}: kept as a rectilinear z axis, no resampling",
        name(14),
        name(15)
    );
    assert!(r.contains(&want_line), "{want_line} not in {r:#?}");
}

fn one<'a>(k: usize, series: &'a str, rows: usize, position: [f64; 3], ts: &'a str) -> Slice<'a> {
    Slice {
        k,
        series,
        rows,
        position,
        ts,
    }
}

fn refused(dir: &Path, series: Option<&str>, words: &[&str]) {
    let e = match open_dir(dir, series) {
        Ok(_) => panic!("{} was accepted", dir.display()),
        Err(e) => e.to_string(),
    };
    for w in words {
        assert!(e.contains(w), "{e:?} does not mention {w:?}");
    }
}

#[test]
fn broken_series_are_refused_by_file_and_tag() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fresh = |name: &str| {
        let p = d.join(name);
        let files = write_series(&p);
        (p, files)
    };

    // A duplicate slice under another name.
    let (p, files) = fresh("dup");
    std::fs::copy(&files[4], p.join("copy-of-4")).unwrap();
    refused(
        &p,
        None,
        &["ImagePositionPatient", "the same position as", "duplicate"],
    );

    // A second series mixed in; --series picks one.
    let (p, _) = fresh("two");
    let other = "1.2.826.0.1.3680043.9.7777.2";
    for k in 0..3 {
        write_slice(
            &p.join(format!("other{k}")),
            &one(k, other, NY, [10.0, -5.0, z_positions()[k]], EXPLICIT_LE),
        );
    }
    refused(&p, None, &["2 series", SERIES, other, "SeriesInstanceUID"]);
    assert_eq!(
        open_dir(&p, Some(SERIES)).unwrap().meta().grid.dims(),
        [NX, NY, 20]
    );
    assert_eq!(
        open_dir(&p, Some(other)).unwrap().meta().grid.dims(),
        [NX, NY, 3]
    );
    refused(&p, Some("9.9.9"), &["SeriesInstanceUID 9.9.9", SERIES]);

    // A truncated file.
    let (p, files) = fresh("cut");
    let b = std::fs::read(&files[7]).unwrap();
    std::fs::write(&files[7], &b[..b.len() / 2]).unwrap();
    let cut = files[7].file_name().unwrap().to_string_lossy().into_owned();
    // Its header says how many bytes of native pixel data it must hold,
    // so the series is refused when it is opened (before issue 57, only
    // when prep reached the slice), naming the file; no output.
    let out = d.join("cut.cdv");
    let e = series_error(&p, None, &out);
    assert!(
        e.contains(&cut) && e.contains("need 1848 bytes of pixel data"),
        "{e}"
    );
    assert!(!out.exists());

    // Rows differ in one slice.
    let (p, files) = fresh("rows");
    write_slice(
        &files[9],
        &one(
            9,
            SERIES,
            NY - 2,
            [10.0, -5.0, z_positions()[9]],
            EXPLICIT_LE,
        ),
    );
    refused(&p, None, &["Rows", "must agree"]);

    // Gantry tilt: each slice shifted in y.
    let p = d.join("tilt");
    for (k, z) in z_positions().into_iter().enumerate() {
        write_slice(
            &p.join(format!("t{k}")),
            &one(k, SERIES, NY, [10.0, -5.0 + 0.3 * k as f64, z], EXPLICIT_LE),
        );
    }
    refused(&p, None, &["ImagePositionPatient", "tilted"]);

    // A transfer syntax whose pixel data cannot be decoded is named.
    let (p, files) = fresh("ts");
    let jpeg2000 = "1.2.840.10008.1.2.4.90";
    write_slice(
        &files[0],
        &one(0, SERIES, NY, [10.0, -5.0, z_positions()[0]], jpeg2000),
    );
    let e = series_error(&p, None, &d.join("ts.cdv"));
    let f0 = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(e.contains(&f0) && e.contains(jpeg2000), "{e}");

    // No DICOM at all.
    let p = d.join("empty");
    std::fs::create_dir(&p).unwrap();
    std::fs::write(p.join("a.txt"), "x").unwrap();
    refused(&p, None, &["no DICOM image slices"]);
}

#[test]
fn cli_prep_reads_a_series_directory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_series(&d.join("s"));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_cdvol"))
        .args(["prep", "-q", "--iso", "300"])
        .arg(d.join("s"))
        .arg("-o")
        .arg(d.join("s.cdv"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("most common spacing 1.00 mm"), "{text}");
    assert!(text.contains("kept as a rectilinear z axis"), "{text}");
    let v = PackedVolume::open(&d.join("s.cdv")).unwrap();
    assert_eq!(v.header().axes[2].coords(), z_positions().as_slice());
    // `info` repeats the spacing report from the file's header.
    let info = std::process::Command::new(env!("CARGO_BIN_EXE_cdvol"))
        .arg("info")
        .arg(d.join("s.cdv"))
        .output()
        .unwrap();
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.contains("most common spacing 1.00 mm (8 of 19 gaps)"),
        "{info}"
    );
    assert_eq!(
        info.matches("kept as a rectilinear z axis").count(),
        11,
        "{info}"
    );
}
