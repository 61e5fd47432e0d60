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
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};

const NX: usize = 33;
const NY: usize = 28;
const SERIES: &str = "1.2.826.0.1.3680043.9.7777.1";
const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// Slice positions: 2 mm gaps low, 1 mm in the middle, 4 mm on top.
fn z_positions() -> Vec<f64> {
    let mut z = vec![-40.0];
    for i in 0..19 {
        let g = if i < 6 {
            2.0
        } else if i < 14 {
            1.0
        } else {
            4.0
        };
        z.push(z[i] + g);
    }
    z
}

/// Stored u16 values (HU + 1024) of slice `k`: a sphere and noise.
fn slice(k: usize) -> Vec<u16> {
    let z = z_positions()[k];
    let mut v = Vec::with_capacity(NX * NY);
    for y in 0..NY {
        for x in 0..NX {
            let (px, py, pz) = (x as f64 * 0.7 - 11.0, y as f64 * 0.8 - 11.0, z + 25.0);
            let r = (px * px + py * py + pz * pz).sqrt();
            let noise = ((x * 7 + y * 13 + k * 31) % 17) as f64;
            let hu = if r < 9.0 { 700.0 } else { -1000.0 } + noise;
            v.push((hu + 1024.0) as u16);
        }
    }
    v
}

struct Slice<'a> {
    k: usize,
    series: &'a str,
    rows: usize,
    position: [f64; 3],
    ts: &'a str,
}

fn write_slice(path: &Path, s: &Slice) {
    let ds = |v: &[f64]| PrimitiveValue::Strs(v.iter().map(|x| format!("{x}")).collect());
    let mut obj = InMemDicomObject::new_empty();
    let uid = format!("{}.{}.{}", s.series, s.k, s.rows);
    let put = |o: &mut InMemDicomObject, tag, vr, v: PrimitiveValue| {
        o.put(DataElement::new(tag, vr, v));
    };
    put(
        &mut obj,
        tags::SOP_CLASS_UID,
        VR::UI,
        "1.2.840.10008.5.1.4.1.1.2".into(),
    );
    put(
        &mut obj,
        tags::SOP_INSTANCE_UID,
        VR::UI,
        uid.as_str().into(),
    );
    put(&mut obj, tags::MODALITY, VR::CS, "CT".into());
    put(&mut obj, tags::SERIES_INSTANCE_UID, VR::UI, s.series.into());
    put(
        &mut obj,
        tags::INSTANCE_NUMBER,
        VR::IS,
        format!("{}", s.k + 1).as_str().into(),
    );
    put(
        &mut obj,
        tags::IMAGE_POSITION_PATIENT,
        VR::DS,
        ds(&s.position),
    );
    put(
        &mut obj,
        tags::IMAGE_ORIENTATION_PATIENT,
        VR::DS,
        ds(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
    );
    put(&mut obj, tags::PIXEL_SPACING, VR::DS, ds(&[0.8, 0.7]));
    put(
        &mut obj,
        tags::SAMPLES_PER_PIXEL,
        VR::US,
        PrimitiveValue::from(1u16),
    );
    put(
        &mut obj,
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        "MONOCHROME2".into(),
    );
    put(
        &mut obj,
        tags::ROWS,
        VR::US,
        PrimitiveValue::from(s.rows as u16),
    );
    put(
        &mut obj,
        tags::COLUMNS,
        VR::US,
        PrimitiveValue::from(NX as u16),
    );
    put(
        &mut obj,
        tags::BITS_ALLOCATED,
        VR::US,
        PrimitiveValue::from(16u16),
    );
    put(
        &mut obj,
        tags::BITS_STORED,
        VR::US,
        PrimitiveValue::from(16u16),
    );
    put(
        &mut obj,
        tags::HIGH_BIT,
        VR::US,
        PrimitiveValue::from(15u16),
    );
    put(
        &mut obj,
        tags::PIXEL_REPRESENTATION,
        VR::US,
        PrimitiveValue::from(0u16),
    );
    put(&mut obj, tags::RESCALE_INTERCEPT, VR::DS, ds(&[-1024.0]));
    put(&mut obj, tags::RESCALE_SLOPE, VR::DS, ds(&[1.0]));
    let mut px = slice(s.k);
    px.resize(NX * s.rows, 0);
    put(
        &mut obj,
        tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(px.into()),
    );
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(s.ts)
                .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.2")
                .media_storage_sop_instance_uid(uid.as_str()),
        )
        .unwrap();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    file.write_to_file(path).unwrap();
}

/// The series in `dir` under scrambled names, some nested; returns the
/// file of each slice.
fn write_series(dir: &Path) -> Vec<PathBuf> {
    (0..z_positions().len())
        .map(|k| {
            let name = format!("{:08x}", (k as u64 * 2654435761) % 4294967291);
            let p = if k % 3 == 0 {
                dir.join("sub").join(name)
            } else {
                dir.join(format!("{name}.dcm"))
            };
            write_slice(
                &p,
                &Slice {
                    k,
                    series: SERIES,
                    rows: NY,
                    position: [10.0, -5.0, z_positions()[k]],
                    ts: EXPLICIT_LE,
                },
            );
            p
        })
        .collect()
}

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
    let (g, w) = (got.header(), want.header());
    assert_eq!(g.axes, w.axes);
    assert_eq!((g.dtype, g.rescale), (w.dtype, w.rescale));
    assert_eq!(g.summary, w.summary);
    assert!(w.summary.one_cells > 0);
    for id in 0..w.brick_count() {
        assert_eq!(
            got.read_payload(id).unwrap(),
            want.read_payload(id).unwrap(),
            "brick {id}"
        );
    }
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
    refused(&p, None, &["2 series", SERIES, other, "--series"]);
    assert_eq!(
        open_dir(&p, Some(SERIES)).unwrap().meta().grid.dims(),
        [NX, NY, 20]
    );
    assert_eq!(
        open_dir(&p, Some(other)).unwrap().meta().grid.dims(),
        [NX, NY, 3]
    );
    refused(&p, Some("9.9.9"), &["--series 9.9.9", SERIES]);

    // A truncated file.
    let (p, files) = fresh("cut");
    let b = std::fs::read(&files[7]).unwrap();
    std::fs::write(&files[7], &b[..b.len() / 2]).unwrap();
    let cut = files[7].file_name().unwrap().to_string_lossy().into_owned();
    // Headers are read first, pixel data when prep reaches the slice: the
    // error comes from prep, names the file, and leaves no output.
    let src = open_dir(&p, None).unwrap();
    let out = d.join("cut.cdv");
    let e = prep(
        &src,
        &out,
        &PrepOptions::new(Classification::Iso { iso: 300.0 }),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains(&cut) && e.contains("not a readable DICOM file"),
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
}
