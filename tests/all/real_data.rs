//! Prep on the real head CT (Debian's invesalius-examples) and on both
//! phantoms: every 1-cell keeps its 8 exact vertex values and the codes
//! equal the breadth-first oracle; info and export describe the result.

use crate::common::dicom_series;

use std::path::Path;
use std::process::Command;

use crate::common::*;
use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::input::SliceSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;

/// All raw values of a source, x fastest.
fn all_values(src: &dyn SliceSource) -> Vec<f64> {
    let [nx, ny, nz] = src.meta().dims();
    let mut out = vec![0.0; nx * ny * nz];
    for z in 0..nz {
        src.read_slice(z, &mut out[z * nx * ny..(z + 1) * nx * ny])
            .unwrap();
    }
    out
}

/// Preps `sidecar` at `iso` (rescaled units) and checks it against the
/// oracles. Returns the packed path.
fn prep_and_check(sidecar: &Path, out: &Path, iso: f64, aniso: bool) -> PackedVolume {
    let src = RawSource::open(sidecar).unwrap();
    let mut opts = PrepOptions::new(Classification::Iso { iso });
    opts.aniso = aniso;
    prep(&src, out, &opts, &NoProgress).unwrap();
    let vol = PackedVolume::open(out).unwrap();
    let raw = all_values(&src);
    let rs = src.meta().rescale;
    let rescaled: Vec<f64> = raw.iter().map(|&v| rs.apply(v)).collect();
    let dims = src.meta().dims();
    let obj = classify_iso(&rescaled, dims, iso);
    let n_obj = obj.iter().filter(|&&o| o != 0).count();
    assert!(n_obj > 0, "no 1-cells at iso {iso}");
    let dist = chessboard_bfs(&obj, dims.map(|d| d - 1));
    let back = read_back(&vol, &raw);
    assert_eq!(back.checked_one_cells, n_obj);
    assert!(
        back.codes == expected_codes(&dist, vol.header().codes.max_code()),
        "codes differ from the BFS oracle"
    );
    vol
}

#[test]
fn real_ct_bone_and_skin() {
    let ct = real_ct();
    let dir = tempfile::tempdir().unwrap();
    let vol = prep_and_check(&ct, &dir.path().join("bone.cdv"), 300.0, false);
    let h = vol.header();
    assert_eq!(h.dims, [256, 256, 108]);
    assert_eq!(h.storage, cdvol::input::Dtype::I16, "CT i16 keeps its type");
    let s = &h.summary;
    let raw = all_values(&RawSource::open(&ct).unwrap());
    let lo = raw.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = raw.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    assert_eq!((s.raw_min, s.raw_max), (Some(lo), Some(hi)));
    assert_eq!(lo, -1024.0, "air in HU");
    // Skin, with anisotropic codes.
    prep_and_check(&ct, &dir.path().join("skin.cdv"), -300.0, true);
}

#[test]
fn phantoms_prepare_and_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let head = dir.path().join("head.json");
    let opts = cdvol::tools::phantom::CtOptions {
        dims: [96, 88, 60],
        dtype: cdvol::tools::phantom::CtDtype::U16,
        seed: 3,
        ..Default::default()
    };
    cdvol::tools::phantom::ct(&head, &opts, &NoProgress).unwrap();
    let vol = prep_and_check(&head, &dir.path().join("head.cdv"), 300.0, false);
    assert!(
        !vol.header().axes[2].is_uniform(),
        "CT phantom z is rectilinear"
    );

    for spacing in ["1", "0.8,1,0.5:2"] {
        let scene = dir.path().join("scene.json");
        let sopts = cdvol::tools::phantom::SpheresOptions {
            size: 48,
            per_axis: 3,
            seed: 7,
            spacing: cdvol::tools::phantom::parse_spacing3(spacing).unwrap(),
        };
        let info = cdvol::tools::phantom::spheres(&scene, &sopts, &NoProgress).unwrap();
        assert_eq!(info.spheres.len(), 27);
        prep_and_check(&scene, &dir.path().join("scene.cdv"), info.iso, true);
    }
}

#[test]
fn info_and_export_through_the_cli() {
    let ct = real_ct();
    let dir = tempfile::tempdir().unwrap();
    let packed = dir.path().join("ct.cdv");
    let st = cdvol()
        .args(["prep", "-q", "--iso", "300"])
        .arg(&ct)
        .arg("-o")
        .arg(&packed)
        .status()
        .unwrap();
    assert!(st.success());
    let out = cdvol()
        .arg("info")
        .arg(&packed)
        .arg("--json")
        .output()
        .unwrap();
    assert!(out.status.success());
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["dims"], serde_json::json!([256, 256, 108]));
    assert_eq!(info["brick_count"], 8 * 8 * 4);
    let frac = info["one_cell_fraction"].as_f64().unwrap();
    assert!(frac > 0.001 && frac < 0.5, "{frac}");
    let text = cdvol().arg("info").arg(&packed).output().unwrap();
    let text = String::from_utf8_lossy(&text.stdout);
    for part in [
        "256 x 256 x 108 samples",
        "0.9570 .. 0.9570 mm",
        "code histogram",
        "ratio",
    ] {
        assert!(text.contains(part), "info lacks {part:?}:\n{text}");
    }

    // Exports read back through the raw reader, and agree with the oracle.
    let src = RawSource::open(&ct).unwrap();
    let raw = all_values(&src);
    let dims = src.meta().dims();
    let obj = classify_iso(&raw, dims, 300.0);
    let dist = chessboard_bfs(&obj, dims.map(|d| d - 1));
    for what in ["values", "codes", "classes"] {
        let side = dir.path().join(format!("{what}.json"));
        let st = cdvol()
            .args([
                "export",
                "-q",
                &packed.display().to_string(),
                "--what",
                what,
                "-o",
            ])
            .arg(&side)
            .status()
            .unwrap();
        assert!(st.success());
        let back = RawSource::open(&side).unwrap();
        let got = all_values(&back);
        match what {
            "values" => {
                // 1-cell vertices exact; replaced samples are the fill value.
                let fill = -1024.0;
                let [nx, ny, _] = dims;
                let mut checked = 0;
                for (i, (&g, &w)) in got.iter().zip(&raw).enumerate() {
                    if g != w {
                        assert_eq!(g, fill, "sample {i}: {g} exported, {w} in the input");
                    }
                }
                for (ci, &o) in obj.iter().enumerate() {
                    if o == 0 {
                        continue;
                    }
                    let (cx, cy) = (nx - 1, ny - 1);
                    let (x, y, z) = (ci % cx, ci / cx % cy, ci / cx / cy);
                    for k in 0..8 {
                        let s = ((z + (k >> 2)) * ny + y + (k >> 1 & 1)) * nx + x + (k & 1);
                        assert_eq!(got[s], raw[s]);
                        checked += 1;
                    }
                }
                assert!(checked > 0);
            }
            "codes" => {
                let want = expected_codes(&dist, 254);
                assert_eq!(got.iter().map(|&v| v as u8).collect::<Vec<_>>(), want);
            }
            _ => assert_eq!(got.iter().map(|&v| v as u8).collect::<Vec<_>>(), obj),
        }
    }
}

/// tools/fixtures.rs turns the real CT into a DICOM series with varying
/// slice spacing (and broken copies), NRRD and NIfTI; each prepares like
/// its raw reference, and each broken copy is refused by name.
#[test]
fn real_ct_as_dicom_nrrd_and_nifti() {
    let ct = real_ct();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let st = Command::new(env!("CARGO_BIN_EXE_cdvol-fixtures"))
        .arg(&ct)
        .arg(d)
        .status()
        .unwrap();
    assert!(st.success());
    let pack = |src: &dyn SliceSource, name: &str| {
        prep(
            src,
            &d.join(name),
            &PrepOptions::new(Classification::Iso { iso: 300.0 }),
            &NoProgress,
        )
        .unwrap();
        PackedVolume::open(&d.join(name)).unwrap()
    };
    let series = cdvol::input::dicom::open_dir(&d.join("series"), None).unwrap();
    assert!(!series.meta().grid.axes[2].is_uniform(), "rectilinear z");
    let report = series.spacing_report().to_vec();
    assert!(
        report[0].contains("most common spacing 1.50 mm"),
        "{report:?}"
    );
    assert!(report
        .iter()
        .any(|l| l.starts_with("1.50 mm expected, 3.00 mm found between IM")));
    assert!(report
        .iter()
        .any(|l| l.starts_with("1.50 mm expected, 6.00 mm found between IM")));
    let want = pack(&RawSource::open(&d.join("series.json")).unwrap(), "ref.cdv");
    assert_same_volume(&pack(&series, "series.cdv"), &want, "DICOM series");

    let whole = pack(&RawSource::open(&ct).unwrap(), "ct.cdv");
    for name in ["volume.nrrd", "volume.nii.gz"] {
        let src = cdvol::input::open(&d.join(name)).unwrap();
        assert_same_volume(&pack(src.as_ref(), &format!("{name}.cdv")), &whole, name);
    }

    let refused = |sub: &str, words: &[&str]| {
        let e = dicom_series::series_error(&d.join(sub), None, &d.join("x.cdv"));
        for w in words {
            assert!(e.contains(w), "{sub}: {e:?} does not mention {w:?}");
        }
    };
    refused("dup", &["the same position as", "ImagePositionPatient"]);
    refused("mixed", &["2 series", "SeriesInstanceUID"]);
    // The header says how much native pixel data the file must hold.
    refused(
        "truncated",
        &["need 131072 bytes of pixel data", "Rows/Columns"],
    );
}

/// README's account of the real CT's axes (issue 51, item 8), checked
/// against its anatomy: tooth enamel, the densest tissue (above 1800 HU),
/// sits at the front and the bottom of the head, so row 0 is the back of
/// the head (+y anterior) and slice 0 the jaw (+z superior). Before,
/// README said the rows ran from the face to the back of the head and
/// advised `"orientation": "LPS"`, under which `--view anterior` showed
/// the back of the head.
#[test]
fn the_real_ct_faces_plus_y_with_the_jaw_at_slice_0() {
    use cdvol::input::SliceSource;
    let src = cdvol::input::raw::RawSource::open(&crate::common::real_ct()).unwrap();
    let [nx, ny, nz] = src.meta().dims();
    let mut slice = vec![0.0; nx * ny];
    let (mut teeth, mut bone) = ([0.0; 3], [0.0; 3]);
    let (mut n_teeth, mut n_bone) = (0.0, 0.0);
    for z in 0..nz {
        src.read_slice(z, &mut slice).unwrap();
        for (i, &v) in slice.iter().enumerate() {
            let p = [(i % nx) as f64, (i / nx) as f64, z as f64];
            if v > 1800.0 {
                (0..3).for_each(|k| teeth[k] += p[k]);
                n_teeth += 1.0;
            }
            if v > 300.0 {
                (0..3).for_each(|k| bone[k] += p[k]);
                n_bone += 1.0;
            }
        }
    }
    let teeth = teeth.map(|s| s / n_teeth);
    let bone = bone.map(|s| s / n_bone);
    assert!(n_teeth > 100.0, "{n_teeth} enamel samples");
    // In front of the skull's centre by over a quarter of the rows, and
    // in the lowest tenth of the slices.
    assert!(
        teeth[1] > bone[1] + 0.25 * ny as f64,
        "teeth y {} bone y {}",
        teeth[1],
        bone[1]
    );
    assert!(teeth[2] < 0.1 * nz as f64, "teeth z {} of {nz}", teeth[2]);
}
