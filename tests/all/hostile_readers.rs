//! Issue 57 regression tests (hostile_readers): hostile NRRD, NIfTI and
//! sidecar inputs. Every size or offset read from a file is bounded before
//! it becomes an allocation or an offset, and refused fast, by name;
//! gzip trailers are verified; spacings are checked alike in every reader;
//! headers are read through a bounded reader; raw data longer than its
//! dims is accepted with a warning.
//!
//! The runs that used to allocate without bound are made under an address
//! space limit (`ulimit -v`), so that a regression aborts the run (a
//! signal, not the named error these tests require) instead of taking the
//! machine's memory.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::common::ok;

/// Address space of the limited runs, in KiB (2 GiB).
const LIMIT_KIB: u64 = 2 << 20;

/// Runs `cdvol ARGS` in `dir` under [`LIMIT_KIB`] of address space;
/// the output and the time it took.
fn limited(dir: &Path, args: &[&str]) -> (Output, Duration) {
    let t = Instant::now();
    let o = Command::new("sh")
        .current_dir(dir)
        .arg("-c")
        .arg(format!("ulimit -v {LIMIT_KIB} && exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_cdvol"))
        .args(args)
        .output()
        .unwrap();
    (o, t.elapsed())
}

/// `cdvol prep -q INPUT -o out.cdv --iso 100` under the limit: requires a
/// named refusal (exit 1, not a signal) within `secs` seconds whose
/// message holds every word of `want`.
fn refused_fast(dir: &Path, input: &str, secs: f64, want: &[&str]) -> String {
    let _ = std::fs::remove_file(dir.join("out.cdv"));
    let (o, t) = limited(dir, &["prep", "-q", input, "-o", "out.cdv", "--iso", "100"]);
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{input}: a named error, not a signal: {e}"
    );
    assert!(
        t.as_secs_f64() < secs,
        "{input}: refused after {t:?}, expected under {secs} s: {e}"
    );
    for w in want {
        assert!(e.contains(w), "{input}: {w:?} not in {e}");
    }
    assert!(!e.contains("panicked"), "{input}: {e}");
    assert!(!dir.join("out.cdv").exists());
    e
}

fn prep(dir: &Path, input: &str) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cdvol"));
    c.current_dir(dir)
        .args(["prep", "-q", input, "-o", "out.cdv", "--iso", "100"]);
    c
}

/// The sample values of a 4 x 4 x 3 u8 volume with something above 100.
fn samples() -> Vec<u8> {
    (0..48u32).map(|i| (i * 37 % 251) as u8).collect()
}

/// An NRRD header (ends with the empty line of an attached header when
/// `attached`).
fn nrrd(fields: &[(&str, &str)], attached: bool) -> Vec<u8> {
    let mut h = String::from("NRRD0004\n");
    for (k, v) in fields {
        h.push_str(&format!("{k}: {v}\n"));
    }
    if attached {
        h.push('\n');
    }
    h.into_bytes()
}

/// The fields of the 4 x 4 x 3 u8 volume, with `sizes` and `spacings`
/// replaced when given.
fn u8_fields<'a>(extra: &[(&'a str, &'a str)]) -> Vec<(&'a str, &'a str)> {
    let mut f = vec![
        ("type", "uint8"),
        ("dimension", "3"),
        ("sizes", "4 4 3"),
        ("spacings", "1 1 1"),
        ("encoding", "raw"),
    ];
    for (k, v) in extra {
        if let Some(e) = f.iter_mut().find(|(key, _)| key == k) {
            e.1 = v;
        } else {
            f.push((k, v));
        }
    }
    f
}

/// Writes `NAME` as an attached NRRD with `data` after the header.
fn attached(dir: &Path, name: &str, fields: &[(&str, &str)], data: &[u8]) {
    let mut b = nrrd(fields, true);
    b.extend_from_slice(data);
    std::fs::write(dir.join(name), b).unwrap();
}

/// A NIfTI-1 single-file header (little endian, 348 bytes + 4 bytes of
/// no extension) for `dims` samples of u8, spacing `pixdim`, samples at
/// byte 352.
fn nifti_header(dims: [i16; 3], pixdim: [f32; 3]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    let dim = [3, dims[0], dims[1], dims[2], 1, 1, 1, 1];
    for (k, d) in dim.iter().enumerate() {
        h[40 + 2 * k..42 + 2 * k].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&2i16.to_le_bytes()); // datatype uint8
    h[72..74].copy_from_slice(&8i16.to_le_bytes()); // bitpix
    let pd = [1.0, pixdim[0], pixdim[1], pixdim[2], 0.0, 0.0, 0.0, 0.0];
    for (k, p) in pd.iter().enumerate() {
        h[76 + 4 * k..80 + 4 * k].copy_from_slice(&f32::to_le_bytes(*p));
    }
    set_f32(&mut h, 108, 352.0); // vox_offset
    h[123] = 2; // mm
    h[344..348].copy_from_slice(b"n+1\0");
    h
}

fn set_f32(b: &mut [u8], at: usize, v: f32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn gzip(b: &[u8], level: flate2::Compression) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), level);
    e.write_all(b).unwrap();
    e.finish().unwrap()
}

// ---------------------------------------------------------------------------
// 1. Sizes and dims are bounded before anything is allocated
// ---------------------------------------------------------------------------

#[test]
fn nrrd_sizes_are_bounded_before_any_allocation() {
    let d = tempfile::tempdir().unwrap();
    for (i, sizes) in [
        "2147483648 2 2",
        "68719476736 2 2",
        "18446744073709551615 2 2",
        "2 2 18446744073709551616",
        "2 1048577 2",
        "2 -2 2",
    ]
    .iter()
    .enumerate()
    {
        let name = format!("s{i}.nrrd");
        attached(d.path(), &name, &u8_fields(&[("sizes", sizes)]), &samples());
        refused_fast(d.path(), &name, 2.0, &[&name, "field `sizes`"]);
    }
    let e = refused_fast(d.path(), "s0.nrrd", 2.0, &[]);
    assert!(
        e.contains("2147483648 samples along x, expected at most 1048576"),
        "{e}"
    );
    // In bounds along each axis, but far more samples than the file has.
    attached(
        d.path(),
        "big.nrrd",
        &u8_fields(&[("sizes", "1048576 1048576 1048576")]),
        &samples(),
    );
    refused_fast(
        d.path(),
        "big.nrrd",
        2.0,
        &["big.nrrd", "expected at least"],
    );
    // gzip: the decompressed size is bounded by the compressed one.
    attached(
        d.path(),
        "bigz.nrrd",
        &u8_fields(&[("sizes", "1048576 1048576 2"), ("encoding", "gzip")]),
        &gzip(&samples(), flate2::Compression::fast()),
    );
    refused_fast(d.path(), "bigz.nrrd", 2.0, &["bigz.nrrd", "field `sizes`"]);
}

#[test]
fn nifti_dims_are_bounded_before_any_allocation() {
    let d = tempfile::tempdir().unwrap();
    // 30000^3 u8 samples in a .nii.gz of a few hundred bytes.
    let mut b = nifti_header([30000, 30000, 30000], [1.0; 3]);
    b.extend_from_slice(&samples());
    std::fs::write(
        d.path().join("big.nii.gz"),
        gzip(&b, flate2::Compression::fast()),
    )
    .unwrap();
    refused_fast(d.path(), "big.nii.gz", 2.0, &["big.nii.gz", "field `dim`"]);
    // A negative dim (stored as i16) is refused as such.
    let mut b = nifti_header([4, -4, 3], [1.0; 3]);
    b.extend_from_slice(&samples());
    std::fs::write(d.path().join("neg.nii"), &b).unwrap();
    refused_fast(d.path(), "neg.nii", 2.0, &["neg.nii", "dim[2]", "-4"]);
    // dim[0] out of range (big-endian read of a little-endian 3 is 768,
    // so use a value that stays out of range both ways).
    let mut b = nifti_header([4, 4, 3], [1.0; 3]);
    b[40..42].copy_from_slice(&0x0909i16.to_le_bytes());
    b.extend_from_slice(&samples());
    std::fs::write(d.path().join("nd.nii"), &b).unwrap();
    refused_fast(d.path(), "nd.nii", 2.0, &["nd.nii"]);
}

// ---------------------------------------------------------------------------
// 2. byte skip
// ---------------------------------------------------------------------------

#[test]
fn nrrd_byte_skip_is_checked() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("v.raw"), samples()).unwrap();
    // Wrapped around, this read the data one byte early, silently.
    for (i, skip) in [
        "18446744073709551615",
        "-2",
        "49",
        "99999999999999999999999",
    ]
    .iter()
    .enumerate()
    {
        let name = format!("k{i}.nhdr");
        std::fs::write(
            d.path().join(&name),
            nrrd(
                &u8_fields(&[("data file", "v.raw"), ("byte skip", skip)]),
                false,
            ),
        )
        .unwrap();
        refused_fast(d.path(), &name, 5.0, &[&name, "field `byte skip`"]);
    }
    // -1: the samples are the last bytes of the file (raw only).
    let mut junk = vec![7u8; 5];
    junk.extend_from_slice(&samples());
    std::fs::write(d.path().join("j.raw"), &junk).unwrap();
    std::fs::write(
        d.path().join("end.nhdr"),
        nrrd(
            &u8_fields(&[("data file", "j.raw"), ("byte skip", "-1")]),
            false,
        ),
    )
    .unwrap();
    let src = cdvol::input::open(&d.path().join("end.nhdr")).unwrap();
    let want = samples();
    for z in 0..3 {
        let mut out = vec![0.0; 16];
        src.read_slice(z, &mut out).unwrap();
        let got: Vec<u8> = out.iter().map(|&v| v as u8).collect();
        assert_eq!(got, want[z * 16..z * 16 + 16], "slice {z}");
    }
    ok(&mut prep(d.path(), "end.nhdr"));
    // ... and refused for gzip data.
    attached(
        d.path(),
        "endz.nrrd",
        &u8_fields(&[("encoding", "gzip"), ("byte skip", "-1")]),
        &gzip(&samples(), flate2::Compression::fast()),
    );
    refused_fast(
        d.path(),
        "endz.nrrd",
        5.0,
        &["endz.nrrd", "field `byte skip`"],
    );
    // A skip past the end of a gzip stream names the field too.
    attached(
        d.path(),
        "farz.nrrd",
        &u8_fields(&[("encoding", "gzip"), ("byte skip", "1000")]),
        &gzip(&samples(), flate2::Compression::fast()),
    );
    refused_fast(d.path(), "farz.nrrd", 5.0, &["farz.nrrd", "byte skip"]);
}

// ---------------------------------------------------------------------------
// 3. gzip trailers
// ---------------------------------------------------------------------------

/// The ways a gzip file is corrupted in these tests: `(name, bytes)`.
fn corruptions(good: &[u8]) -> Vec<(&'static str, Vec<u8>)> {
    let n = good.len();
    let mut crc = good.to_vec();
    crc[n - 8] ^= 1;
    let mut isize = good.to_vec();
    isize[n - 4] ^= 1;
    let mut garbage = good.to_vec();
    garbage.extend_from_slice(b"garbage");
    let truncated = good[..n - 3].to_vec();
    vec![
        ("crc", crc),
        ("isize", isize),
        ("garbage", garbage),
        ("truncated", truncated),
    ]
}

#[test]
fn gzip_trailers_are_verified() {
    let d = tempfile::tempdir().unwrap();
    let mut nii = nifti_header([4, 4, 3], [1.0; 3]);
    nii.extend_from_slice(&samples());
    // Stored blocks: a flipped sample still inflates, only the CRC tells.
    let good = gzip(&nii, flate2::Compression::none());
    std::fs::write(d.path().join("good.nii.gz"), &good).unwrap();
    ok(&mut prep(d.path(), "good.nii.gz"));
    let mut flip = good.clone();
    let at = flip.len() - 8 - 20; // a sample of the last slice
    flip[at] ^= 0x10;
    std::fs::write(d.path().join("flip.nii.gz"), &flip).unwrap();
    refused_fast(
        d.path(),
        "flip.nii.gz",
        5.0,
        &["flip.nii.gz", "gzip CRC-32 mismatch", "corrupt"],
    );
    for (what, bytes) in corruptions(&good) {
        let name = format!("{what}.nii.gz");
        std::fs::write(d.path().join(&name), bytes).unwrap();
        refused_fast(d.path(), &name, 5.0, &[&name]);
    }
    let e = refused_fast(d.path(), "crc.nii.gz", 5.0, &["gzip CRC-32 mismatch"]);
    assert!(e.contains("corrupt"), "{e}");
    // Zero padding after the stream is accepted (as gzip(1) does).
    let mut padded = good.clone();
    padded.extend_from_slice(&[0u8; 100]);
    std::fs::write(d.path().join("padded.nii.gz"), &padded).unwrap();
    ok(&mut prep(d.path(), "padded.nii.gz"));

    // NRRD `encoding: gzip`, attached and detached.
    let fields = u8_fields(&[("encoding", "gzip")]);
    let good = gzip(&samples(), flate2::Compression::best());
    attached(d.path(), "good.nrrd", &fields, &good);
    ok(&mut prep(d.path(), "good.nrrd"));
    for (what, bytes) in corruptions(&good) {
        let name = format!("{what}.nrrd");
        attached(d.path(), &name, &fields, &bytes);
        refused_fast(d.path(), &name, 5.0, &[&name]);
        let raw = format!("{what}.raw.gz");
        std::fs::write(d.path().join(&raw), &bytes).unwrap();
        let mut f = fields.clone();
        f.push(("data file", &raw));
        let name = format!("{what}.nhdr");
        std::fs::write(d.path().join(&name), nrrd(&f, false)).unwrap();
        refused_fast(d.path(), &name, 5.0, &[&raw]);
    }
    refused_fast(d.path(), "crc.nrrd", 5.0, &["gzip CRC-32 mismatch"]);
}

// ---------------------------------------------------------------------------
// 4. Spacing
// ---------------------------------------------------------------------------

#[test]
fn tiny_and_non_finite_spacings_are_refused_by_every_reader() {
    let d = tempfile::tempdir().unwrap();
    for (i, (k, v, field)) in [
        ("spacings", "1e-300 1 1", "spacings"),
        ("spacings", "1 nan 1", "spacings"),
        ("spacings", "1 1 inf", "spacings"),
        (
            "space directions",
            "(1e-300,0,0) (0,1,0) (0,0,1)",
            "space directions",
        ),
        (
            "space directions",
            "(1,0,0) (0,1e-7,0) (0,0,1)",
            "space directions",
        ),
        (
            "space directions",
            "(1,0,0) (0,1,0) (0,0,nan)",
            "space directions",
        ),
    ]
    .iter()
    .enumerate()
    {
        let name = format!("sp{i}.nrrd");
        let mut f = u8_fields(&[]);
        if *k == "space directions" {
            f.retain(|(key, _)| *key != "spacings");
        }
        f.push((*k, *v));
        attached(d.path(), &name, &u8_fields_dedup(f), &samples());
        refused_fast(d.path(), &name, 5.0, &[&name, &format!("field `{field}`")]);
    }
    let mut f = u8_fields(&[("space origin", "(nan,0,0)")]);
    f.push(("space directions", "(1,0,0) (0,1,0) (0,0,1)"));
    f.retain(|(key, _)| *key != "spacings");
    attached(d.path(), "or.nrrd", &f, &samples());
    refused_fast(
        d.path(),
        "or.nrrd",
        5.0,
        &["or.nrrd", "field `space origin`"],
    );

    for (i, pd) in [[1e-45, 1.0, 1.0], [1.0, 1e-7, 1.0], [1.0, 1.0, f32::NAN]]
        .iter()
        .enumerate()
    {
        let name = format!("p{i}.nii");
        let mut b = nifti_header([4, 4, 3], *pd);
        b.extend_from_slice(&samples());
        std::fs::write(d.path().join(&name), &b).unwrap();
        refused_fast(d.path(), &name, 5.0, &[&name, "field `pixdim["]);
    }
    let mut b = nifti_header([4, 4, 3], [1.0; 3]);
    b[254..256].copy_from_slice(&1i16.to_le_bytes()); // sform_code
    set_f32(&mut b, 280 + 12, f32::INFINITY); // srow_x[3]
    b.extend_from_slice(&samples());
    std::fs::write(d.path().join("o.nii"), &b).unwrap();
    refused_fast(d.path(), "o.nii", 5.0, &["o.nii", "srow_x"]);
    // The sidecar keeps its refusal.
    std::fs::write(d.path().join("v.raw"), samples()).unwrap();
    std::fs::write(
        d.path().join("s.json"),
        r#"{"data": "v.raw", "dims": [4, 4, 3], "dtype": "u8", "x": 1e-300, "y": 1, "z": 1}"#,
    )
    .unwrap();
    refused_fast(d.path(), "s.json", 5.0, &["s.json", "field `x`"]);
}

fn u8_fields_dedup<'a>(f: Vec<(&'a str, &'a str)>) -> Vec<(&'a str, &'a str)> {
    let mut out: Vec<(&str, &str)> = Vec::new();
    for (k, v) in f {
        if let Some(e) = out.iter_mut().find(|(key, _)| *key == k) {
            e.1 = v;
        } else {
            out.push((k, v));
        }
    }
    out
}

// ---------------------------------------------------------------------------
// 5. Headers are read through a bounded reader
// ---------------------------------------------------------------------------

#[test]
fn huge_headers_are_refused_in_bounded_memory() {
    let d = tempfile::tempdir().unwrap();
    // 3 GB, sparse: a header of one line of NUL bytes.
    let big = 3u64 << 30;
    let mut f = std::fs::File::create(d.path().join("line.nrrd")).unwrap();
    f.write_all(b"NRRD0004\ntype: uint8\n# ").unwrap();
    f.set_len(big).unwrap();
    refused_fast(d.path(), "line.nrrd", 5.0, &["line.nrrd", "1048576"]);
    let mut f = std::fs::File::create(d.path().join("big.json")).unwrap();
    f.write_all(br#"{"data": "v.raw", "pad": ""#).unwrap();
    f.set_len(big).unwrap();
    refused_fast(d.path(), "big.json", 5.0, &["big.json", "67108864"]);
    // A sidecar just under the bound is read.
    std::fs::write(d.path().join("v.raw"), samples()).unwrap();
    let mut json = String::from(
        r#"{"data": "v.raw", "dims": [4, 4, 3], "dtype": "u8", "x": 1, "y": 1, "z": 1, "pad": ""#,
    );
    json.push_str(&" ".repeat(1 << 20));
    json.push_str("\"}");
    std::fs::write(d.path().join("ok.json"), json).unwrap();
    ok(&mut prep(d.path(), "ok.json"));
}

// ---------------------------------------------------------------------------
// 6. Raw data longer than its dims
// ---------------------------------------------------------------------------

#[test]
fn raw_data_longer_than_its_dims_is_accepted_with_a_warning() {
    let d = tempfile::tempdir().unwrap();
    let mut long = samples();
    long.extend_from_slice(&[0u8; 10]);
    std::fs::write(d.path().join("long.raw"), &long).unwrap();
    std::fs::write(
        d.path().join("s.json"),
        r#"{"data": "long.raw", "dims": [4, 4, 3], "dtype": "u8", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    std::fs::write(
        d.path().join("d.nhdr"),
        nrrd(&u8_fields(&[("data file", "long.raw")]), false),
    )
    .unwrap();
    for input in ["s.json", "d.nhdr"] {
        let o = prep(d.path(), input).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{input}: {e}");
        let all = format!("{out}{e}");
        for w in ["warning", "long.raw", "58 bytes", "expected 48"] {
            assert!(all.contains(w), "{input}: {w:?} not in {all}");
        }
    }
    // Exactly as long: no warning.
    std::fs::write(d.path().join("long.raw"), samples()).unwrap();
    let o = prep(d.path(), "s.json").output().unwrap();
    assert!(o.status.success());
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!all.contains("long.raw"), "{all}");
}

// ---------------------------------------------------------------------------
// 7. Other offsets: NIfTI vox_offset
// ---------------------------------------------------------------------------

#[test]
fn nifti_vox_offset_is_checked() {
    let d = tempfile::tempdir().unwrap();
    for (i, (v, gz)) in [
        (1e30f32, false),
        (1e30, true),
        (352.5, false),
        (4096.0, false),
        (f32::NAN, false),
        (1e9, true),
    ]
    .iter()
    .enumerate()
    {
        let name = format!("v{i}.nii{}", if *gz { ".gz" } else { "" });
        let mut b = nifti_header([4, 4, 3], [1.0; 3]);
        set_f32(&mut b, 108, *v);
        b.extend_from_slice(&samples());
        let b = if *gz {
            gzip(&b, flate2::Compression::fast())
        } else {
            b
        };
        std::fs::write(d.path().join(&name), &b).unwrap();
        refused_fast(d.path(), &name, 5.0, &[&name, "field `vox_offset`"]);
    }
    let mut b = nifti_header([4, 4, 3], [1.0; 3]);
    b.extend_from_slice(&samples());
    std::fs::write(d.path().join("good.nii"), &b).unwrap();
    ok(&mut prep(d.path(), "good.nii"));
}

// ---------------------------------------------------------------------------
// Lower severity: a NIfTI scl_slope of NaN or infinity is not silent
// ---------------------------------------------------------------------------

#[test]
fn a_nifti_slope_that_is_not_finite_is_read_as_no_rescale_with_a_warning() {
    let d = tempfile::tempdir().unwrap();
    for (name, slope) in [("nan.nii", f32::NAN), ("inf.nii", f32::INFINITY)] {
        let mut b = nifti_header([4, 4, 3], [1.0, 1.0, 1.0]);
        set_f32(&mut b, 112, slope);
        b.extend_from_slice(&samples());
        std::fs::write(d.path().join(name), &b).unwrap();
        let o = prep(d.path(), name).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{name}: {e}");
        for w in ["warning", name, "scl_slope", "no rescale"] {
            assert!(e.contains(w), "{name}: {w:?} not in {e}");
        }
    }
    // A slope of 0 means no rescale by the standard: no warning.
    let mut b = nifti_header([4, 4, 3], [1.0, 1.0, 1.0]);
    set_f32(&mut b, 112, 0.0);
    b.extend_from_slice(&samples());
    std::fs::write(d.path().join("zero.nii"), &b).unwrap();
    let o = prep(d.path(), "zero.nii").output().unwrap();
    assert!(o.status.success());
    assert!(!String::from_utf8_lossy(&o.stderr).contains("scl_slope"));
}

// ---------------------------------------------------------------------------
// Found by the fuzz target fuzz_readers_nrrd: errors of detached gzip
// data name the header, and an empty `data file` is refused by field
// ---------------------------------------------------------------------------

#[test]
fn detached_gzip_errors_name_the_header() {
    let d = tempfile::tempdir().unwrap();
    // An empty `data file` value: before, "DIR/: cannot open gzip data
    // file: a directory", naming neither the header nor the field.
    attached(
        d.path(),
        "empty.nrrd",
        &u8_fields(&[("encoding", "gzip"), ("data file", "")]),
        &gzip(&samples(), flate2::Compression::default()),
    );
    refused_fast(
        d.path(),
        "empty.nrrd",
        5.0,
        &["empty.nrrd", "data file", "empty"],
    );
    // A corrupt deflate stream in a detached data file.
    let mut z = gzip(&samples(), flate2::Compression::default());
    let n = z.len();
    for b in &mut z[10..n - 8] {
        *b ^= 0x5a;
    }
    std::fs::write(d.path().join("bad.raw.gz"), z).unwrap();
    std::fs::write(
        d.path().join("bad.nhdr"),
        nrrd(
            &u8_fields(&[("encoding", "gzip"), ("data file", "bad.raw.gz")]),
            false,
        ),
    )
    .unwrap();
    refused_fast(d.path(), "bad.nhdr", 5.0, &["bad.raw.gz", "bad.nhdr"]);
}
