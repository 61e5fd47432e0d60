//! Hostile DICOM files (issue 57, items 2 and 5 and the lower-severity
//! list): each is refused as a named error for that file, within seconds
//! and under a 4 GiB address-space limit, and a `prep-batch` beside them
//! prepares the good series and writes batch.json. Before this module's
//! fixes, RLE garbage panicked inside dicom-transfer-syntax-registry,
//! 100,000 nested sequences overflowed the stack (SIGSEGV), Rows = Columns
//! = 65535 aborted on a 32 GiB allocation, a slice without
//! ImagePositionPatient was dropped silently and a NaN, infinite or zero
//! RescaleSlope, or a PixelSpacing of 1e-300, was taken.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::common::dicom_series::{write_slice, z_positions, Slice, EXPLICIT_LE, NY, SERIES};

/// RLE Lossless.
const RLE: &str = "1.2.840.10008.1.2.5";

/// A good series of `n` slices in `dir` with transfer syntax `ts`.
fn series(dir: &Path, n: usize, ts: &str) -> Vec<PathBuf> {
    series_uid(dir, n, ts, SERIES)
}

/// [`series`] with the SeriesInstanceUID `uid`.
fn series_uid(dir: &Path, n: usize, ts: &str, uid: &str) -> Vec<PathBuf> {
    (0..n)
        .map(|k| {
            let p = dir.join(format!("s{k:02}.dcm"));
            write_slice(
                &p,
                &Slice {
                    k,
                    series: uid,
                    rows: NY,
                    position: [10.0, -5.0, z_positions()[k]],
                    ts,
                },
            );
            p
        })
        .collect()
}

/// The offset of the top-level PixelData element (explicit VR little
/// endian, as the fixture writes it).
fn pixel_data_at(b: &[u8]) -> usize {
    b.windows(6)
        .rposition(|w| w == [0xE0, 0x7F, 0x10, 0x00, b'O', b'W'])
        .expect("PixelData")
}

/// Replaces the native PixelData of `path` with encapsulated pixel data
/// holding one fragment (after an empty offset table).
fn encapsulate(path: &Path, fragment: &[u8]) {
    let mut b = std::fs::read(path).unwrap();
    b.truncate(pixel_data_at(&b));
    b.extend_from_slice(&[
        0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
    ]);
    b.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 0, 0, 0, 0]);
    b.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0]);
    b.extend_from_slice(&(fragment.len() as u32).to_le_bytes());
    b.extend_from_slice(fragment);
    b.extend_from_slice(&[0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
    std::fs::write(path, b).unwrap();
}

/// Inserts, before the PixelData of `path`, a private sequence whose
/// items nest `depth` sequences deep (undefined lengths, delimited).
fn nest(path: &Path, depth: usize) {
    let mut b = std::fs::read(path).unwrap();
    let at = pixel_data_at(&b);
    let tail = b.split_off(at);
    for _ in 0..depth {
        b.extend_from_slice(&[
            0x29, 0x00, 0x10, 0x10, b'S', b'Q', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
        ]);
        b.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0, 0xFF, 0xFF, 0xFF, 0xFF]);
    }
    for _ in 0..depth {
        b.extend_from_slice(&[0xFE, 0xFF, 0x0D, 0xE0, 0, 0, 0, 0]);
        b.extend_from_slice(&[0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
    }
    b.extend_from_slice(&tail);
    std::fs::write(path, b).unwrap();
}

/// `cdvol ARGS` under a 4 GiB address-space limit, killed after 60 s.
fn run_limited(dir: &Path, args: &str) -> (Output, Duration) {
    let t = Instant::now();
    let out = Command::new("sh")
        .current_dir(dir)
        .arg("-c")
        .arg(format!(
            "ulimit -v 4194304; exec timeout -s KILL 60 {} {args}",
            env!("CARGO_BIN_EXE_cdvol")
        ))
        .output()
        .unwrap();
    (out, t.elapsed())
}

/// Prep of `dir/in` must fail with exit code 1 (not a signal, not a
/// panic), quickly, naming `file` and `field`, and write nothing.
fn refused(dir: &Path, file: &str, field: &str) -> String {
    let (out, took) = run_limited(dir, "prep -q in -o out.cdv --iso=-995");
    let e = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "a named error, not a signal: {e}"
    );
    assert!(!e.contains("panicked"), "{e}");
    assert!(e.contains(file), "{file:?} not named: {e}");
    assert!(e.contains(field), "{field:?} not named: {e}");
    assert!(took < Duration::from_secs(20), "took {took:?}");
    assert!(!dir.join("out.cdv").exists());
    e
}

/// A fragment with a well-formed RLE header (two segments, for 16-bit
/// samples) and garbage after it, too short for the slice: the decoder
/// of dicom-transfer-syntax-registry 0.8 panics on it
/// (`rle_lossless.rs:230`, an index past the decoded segment).
fn rle_garbage() -> Vec<u8> {
    let mut f = vec![0u8; 64];
    f[0..4].copy_from_slice(&2u32.to_le_bytes());
    f[4..8].copy_from_slice(&64u32.to_le_bytes());
    f[8..12].copy_from_slice(&70u32.to_le_bytes());
    f.extend_from_slice(&[0x05, 1, 2, 3, 4, 5, 0x81, 9, 0x7f, 0x33]);
    f
}

#[test]
fn rle_garbage_is_a_named_error() {
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, RLE);
    for f in &files {
        encapsulate(f, &rle_garbage());
    }
    refused(d.path(), "s00.dcm", "PixelData");
}

#[test]
fn rle_header_with_a_huge_segment_count_is_refused_before_decoding() {
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, RLE);
    let mut f = rle_garbage();
    f[0..4].copy_from_slice(&u32::MAX.to_le_bytes());
    for p in &files {
        encapsulate(p, &f);
    }
    let e = refused(d.path(), "s00.dcm", "segments");
    assert!(e.contains("4294967295 segments"), "{e}");
}

#[test]
fn deep_nesting_is_refused_without_overflowing_the_stack() {
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, EXPLICIT_LE);
    nest(&files[1], 100_000);
    refused(d.path(), "s01.dcm", "sequence nesting");
}

#[test]
fn nesting_up_to_the_bound_is_read() {
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, EXPLICIT_LE);
    for f in &files {
        nest(f, cdvol::input::dicom::MAX_NESTING);
    }
    let (out, _) = run_limited(d.path(), "prep -q in -o out.cdv --iso=-995");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn huge_rows_and_columns_are_refused_before_allocating() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().join("in");
    for k in 0..3 {
        let h = cdvol::input::dicom::SliceHeader {
            series: SERIES,
            instance: k + 1,
            rows: 65535,
            cols: 65535,
            spacing: [0.8, 0.7],
            position: [0.0, 0.0, k as f64],
            orientation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            signed: false,
            rescale: cdvol::input::Rescale {
                slope: 1.0,
                intercept: 0.0,
            },
            transfer_syntax: EXPLICIT_LE,
        };
        cdvol::input::dicom::write_slice(&dir.join(format!("s{k:02}.dcm")), &h, &[7u16; 64])
            .unwrap();
    }
    let e = refused(d.path(), "s0", "Rows");
    assert!(e.contains("65535 x 65535"), "{e}");
}

#[test]
fn a_slice_without_position_is_named_not_dropped() {
    use dicom_dictionary_std::tags;
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 4, EXPLICIT_LE);
    let mut obj = dicom_object::open_file(&files[2]).unwrap();
    obj.remove_element(tags::IMAGE_POSITION_PATIENT);
    obj.write_to_file(&files[2]).unwrap();
    refused(d.path(), "s02.dcm", "ImagePositionPatient");
}

/// Rewrites the DS element `tag` of every file of `files` to `value`.
fn set_ds(files: &[PathBuf], tag: dicom_object::Tag, value: &str) {
    use dicom_core::{DataElement, PrimitiveValue, VR};
    for f in files {
        let mut obj = dicom_object::open_file(f).unwrap();
        let v: Vec<String> = value.split('\\').map(str::to_string).collect();
        obj.put(DataElement::new(
            tag,
            VR::DS,
            PrimitiveValue::Strs(v.into()),
        ));
        obj.write_to_file(f).unwrap();
    }
}

#[test]
fn a_rescale_slope_that_is_not_finite_or_zero_is_refused() {
    use dicom_dictionary_std::tags;
    for bad in ["NaN", "inf", "-inf", "0"] {
        let d = tempfile::tempdir().unwrap();
        let files = series(&d.path().join("in"), 3, EXPLICIT_LE);
        set_ds(&files, tags::RESCALE_SLOPE, bad);
        let e = refused(d.path(), "s0", "RescaleSlope");
        assert!(
            e.contains("expected a finite, non-zero number"),
            "{bad}: {e}"
        );
    }
}

#[test]
fn a_tiny_pixel_spacing_is_refused() {
    use dicom_dictionary_std::tags;
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, EXPLICIT_LE);
    set_ds(&files, tags::PIXEL_SPACING, "1e-300\\1e-300");
    let e = refused(d.path(), "s0", "PixelSpacing");
    assert!(
        e.contains("1e-300, 1e-300, expected spacings >= 1e-6 mm"),
        "{e}"
    );
}

#[test]
fn a_batch_prepares_the_good_series_beside_hostile_ones() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("in");
    series_uid(&root.join("good"), 3, EXPLICIT_LE, "1.2.3.1");
    for f in series_uid(&root.join("rle"), 3, RLE, "1.2.3.2") {
        encapsulate(&f, &rle_garbage());
    }
    let nested = series_uid(&root.join("nested"), 3, EXPLICIT_LE, "1.2.3.3");
    nest(&nested[0], 100_000);
    let (out, took) = run_limited(
        d.path(),
        "prep-batch -q in -o out --iso=-995 --brick 8 --jobs 2",
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "some inputs failed: {e}");
    assert!(!e.contains("panicked"), "{e}");
    assert!(took < Duration::from_secs(60), "took {took:?}");
    let batch: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.path().join("out/batch.json")).unwrap()).unwrap();
    let text = batch.to_string();
    let rows = batch.as_array().expect("rows");
    let row = |name: &str| {
        rows.iter()
            .find(|r| r["input"].as_str() == Some(name))
            .unwrap_or_else(|| panic!("{name} not in batch.json: {text}"))
    };
    assert_eq!(row("good")["status"], "done", "{text}");
    for (name, why) in [("rle", "PixelData"), ("nested", "sequence nesting")] {
        assert_eq!(row(name)["status"], "failed", "{text}");
        let e = row(name)["error"].as_str().unwrap_or("");
        assert!(e.contains("s00.dcm") && e.contains(why), "{name}: {e}");
    }
    let prepared: Vec<_> = std::fs::read_dir(d.path().join("out"))
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".cdv"))
        .collect();
    assert_eq!(prepared.len(), 1, "only the good series: {prepared:?}");
    assert!(prepared[0].contains("good"), "{prepared:?}");
}

/// Found by the fuzz target `fuzz_readers_dicom`: nine zero bytes before
/// PixelData make dicom-parser read a garbage element length and allocate
/// it (276 MB for a 2.7 KB file) before any error.
#[test]
fn a_length_past_the_end_of_the_file_is_refused_before_allocating() {
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, EXPLICIT_LE);
    let mut b = std::fs::read(&files[1]).unwrap();
    let at = pixel_data_at(&b);
    b.splice(at..at, [0u8; 9]);
    std::fs::write(&files[1], b).unwrap();
    let e = refused(d.path(), "s01.dcm", "element length");
    assert!(e.contains("past the end of the file"), "{e}");
}

/// Found by the fuzz target `fuzz_readers_dicom`: HighBit (0028,0102)
/// written as a UL of 2 bytes. dicom-parser reads no UL from 2 bytes but
/// counts them as read, so it took the next 2 bytes on as a header, read
/// text as a length and reserved 540 MB for a 2.7 KB file.
#[test]
fn a_binary_value_of_a_length_its_vr_cannot_hold_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let files = series(&d.path().join("in"), 3, EXPLICIT_LE);
    let mut b = std::fs::read(&files[2]).unwrap();
    let high_bit = [0x28, 0x00, 0x02, 0x01, b'U', b'S', 2, 0];
    let at = b.windows(8).position(|w| w == high_bit).expect("HighBit");
    b[at + 5] = b'L';
    std::fs::write(&files[2], b).unwrap();
    let e = refused(d.path(), "s02.dcm", "element length");
    assert!(e.contains("(0028,0102) of VR UL declares 2 bytes"), "{e}");
    assert!(e.contains("a multiple of 4"), "{e}");
}
