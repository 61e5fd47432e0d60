//! Every bad input is refused with a message that names the file, the
//! field and what was expected; nothing panics and nothing partial is left.

use std::path::Path;

use crate::common::{cdvol, fails, rewrite_header, write_stack};
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;

fn sidecar(dir: &Path, json: &str) -> std::path::PathBuf {
    std::fs::write(dir.join("data.raw"), vec![0u8; 4 * 4 * 3 * 2]).unwrap();
    let p = dir.join("bad.json");
    std::fs::write(&p, json).unwrap();
    p
}

/// Opens a sidecar that must fail; returns the message.
fn refused(json: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let p = sidecar(dir.path(), json);
    match RawSource::open(&p) {
        Ok(_) => panic!("accepted: {json}"),
        Err(e) => {
            let m = e.to_string();
            assert!(
                m.contains("bad.json") || m.contains("data.raw"),
                "no file named: {m}"
            );
            m
        }
    }
}

const GOOD: &str =
    r#"{"data": "data.raw", "dims": [4, 4, 3], "dtype": "u16", "x": 1, "y": 1, "z": 2}"#;

fn with(field: &str, value: &str) -> String {
    let mut v: serde_json::Value = serde_json::from_str(GOOD).unwrap();
    v[field] = serde_json::from_str(value).unwrap();
    v.to_string()
}

fn assert_has(m: &str, parts: &[&str]) {
    for p in parts {
        assert!(m.contains(p), "message {m:?} lacks {p:?}");
    }
}

#[test]
fn good_sidecar_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let p = sidecar(dir.path(), GOOD);
    RawSource::open(&p).unwrap();
}

#[test]
fn short_file() {
    let m = refused(&with("dims", "[4, 4, 4]"));
    assert_has(
        &m,
        &["data.raw", "96 bytes", "expected at least 128", "bad.json"],
    );
    let m = refused(&with("header_bytes", "8"));
    assert_has(&m, &["data.raw", "expected at least 104", "header_bytes 8"]);
}

#[test]
fn per_slice_files_short_or_missing() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s0.raw"), vec![0u8; 32]).unwrap();
    std::fs::write(dir.path().join("s1.raw"), vec![0u8; 31]).unwrap();
    let p = dir.path().join("bad.json");
    let j = r#"{"data": ["s0.raw", "s1.raw"], "dims": [4, 4, 2], "dtype": "u16", "x": 1, "y": 1, "z": 2}"#;
    std::fs::write(&p, j).unwrap();
    let m = RawSource::open(&p).err().unwrap().to_string();
    assert_has(&m, &["s1.raw", "31 bytes", "expected at least 32"]);
    let j = j.replace("s1.raw", "s9.raw");
    std::fs::write(&p, j).unwrap();
    let m = RawSource::open(&p).err().unwrap().to_string();
    assert_has(&m, &["s9.raw", "cannot open"]);
    let j = r#"{"data": ["s0.raw"], "dims": [4, 4, 2], "dtype": "u16", "x": 1, "y": 1, "z": 2}"#;
    std::fs::write(&p, j).unwrap();
    let m = RawSource::open(&p).err().unwrap().to_string();
    assert_has(&m, &["field `data`", "1 files", "expected one per z slice"]);
}

#[test]
fn coordinates() {
    let m = refused(&with("z", r#"{"positions": [0, 1, 1]}"#));
    assert_has(
        &m,
        &["field `z.positions`", "coordinate 2", "strictly increasing"],
    );
    let m = refused(&with("z", r#"{"positions": [0, 2, 1]}"#));
    assert_has(&m, &["field `z.positions`", "coordinate 2"]);
    let m = refused(&with("z", r#"{"positions": [0, 1]}"#));
    assert_has(&m, &["field `z.positions`", "2 entries, expected 3"]);
    let m = refused(&with("z", r#"{"spacing": [1, 0]}"#));
    assert_has(&m, &["field `z.spacing[1]`", "gap 0", "> 0"]);
    // Positions beyond 1e15 mm are refused before their sum can overflow.
    let m = refused(&with("y", r#"{"spacing": [1e308, 1e308, 1e308]}"#));
    assert_has(&m, &["field `y.spacing`", "expected at most 1e15 mm"]);
    let m = refused(&with("x", "0"));
    assert_has(&m, &["field `x`", "spacing >= 1e-6 mm"]);
    let m = refused(&with("x", "-1.5"));
    assert_has(&m, &["field `x`", "-1.5"]);
    let m = refused(&with("z", r#""thick""#));
    assert_has(&m, &["field `z`", "positions"]);
    let m = refused(&with("origin", "[0, 0]"));
    assert_has(&m, &["field `origin`", "[x, y, z]"]);
}

#[test]
fn dims_dtype_endian_and_missing_fields() {
    let m = refused(&with("dims", "[1, 4, 3]"));
    assert_has(&m, &["field `dims[0]`", "at least 2"]);
    let m = refused(&with("dims", "[4, 4]"));
    assert_has(&m, &["field `dims`", "[nx, ny, nz]"]);
    let m = refused(&with("dtype", r#""u12""#));
    assert_has(&m, &["field `dtype`", "u12", "expected one of u8"]);
    let m = refused(&with("endian", r#""middle""#));
    assert_has(&m, &["field `endian`", "\"little\" or \"big\""]);
    let m = refused(&with("rescale", r#"{"slope": 0}"#));
    assert_has(&m, &["field `rescale.slope`", "non-zero"]);
    let m = refused(&with("data", "null"));
    assert_has(&m, &["field `data`", "missing"]);
    let m = refused(&with("data", r#""nowhere.raw""#));
    assert_has(&m, &["nowhere.raw", "cannot open"]);
    let m = refused("[1, 2]");
    assert_has(&m, &["bad.json", "JSON object"]);
    let m = refused("{\"dims\": ");
    assert_has(&m, &["bad.json", "not valid JSON"]);
}

fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".cdvol-partial") || n.ends_with(".cdv"))
        .collect()
}

#[test]
fn cli_fails_non_zero_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let p = sidecar(dir.path(), &with("dims", "[4, 4, 9]"));
    let err = fails(
        cdvol()
            .args(["prep", "-q", "--iso", "1"])
            .arg(&p)
            .arg("-o")
            .arg(dir.path().join("o.cdv")),
    );
    assert_has(&err, &["cdvol: error:", "data.raw", "expected at least"]);
    assert!(
        leftovers(dir.path()).is_empty(),
        "{:?}",
        leftovers(dir.path())
    );
    // No classification given.
    let p = sidecar(dir.path(), GOOD);
    let err = fails(
        cdvol()
            .args(["prep", "-q"])
            .arg(&p)
            .arg("-o")
            .arg(dir.path().join("o.cdv")),
    );
    assert_has(&err, &["--iso", "--classify-tf"]);
    // Bad transfer function.
    let tf = dir.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"points": [{"value": 5, "opacity": 0}, {"value": 1, "opacity": 1}]}"#,
    )
    .unwrap();
    let err = fails(
        cdvol()
            .args(["prep", "-q", "--classify-tf"])
            .arg(&tf)
            .arg(&p)
            .arg("-o")
            .arg(dir.path().join("o.cdv")),
    );
    assert_has(&err, &["tf.json", "points[1].value", "strictly increasing"]);
    // Bad brick size.
    let err = fails(
        cdvol()
            .args(["prep", "-q", "--iso", "1", "--brick", "6"])
            .arg(&p)
            .arg("-o")
            .arg(dir.path().join("o.cdv")),
    );
    assert_has(&err, &["--brick", "multiple of 4"]);
    assert!(
        leftovers(dir.path()).is_empty(),
        "{:?}",
        leftovers(dir.path())
    );
}

/// A small valid packed file to damage.
fn valid_file(dir: &Path) -> std::path::PathBuf {
    let dims = [20, 18, 16];
    let v: Vec<f64> = (0..20 * 18 * 16).map(|i| ((i * 31) % 97) as f64).collect();
    let side = write_stack(dir, "v", dims, "u8", &v, ["1", "1", "1"], "");
    let out = dir.join("v.cdv");
    let st = cdvol()
        .args(["prep", "-q", "--iso", "90", "--brick", "8"])
        .arg(&side)
        .arg("-o")
        .arg(&out)
        .status()
        .unwrap();
    assert!(st.success());
    out
}

#[test]
fn damaged_packed_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let good = valid_file(dir.path());
    let bytes = std::fs::read(&good).unwrap();
    let vol = PackedVolume::open(&good).unwrap();
    let payload_brick = vol.index().iter().position(|e| !e.is_uniform()).unwrap();
    let e = vol.index()[payload_brick];
    drop(vol);
    let bad = dir.path().join("bad.cdv");
    let open_err = |b: &[u8]| {
        std::fs::write(&bad, b).unwrap();
        PackedVolume::open(&bad).err().map(|e| e.to_string())
    };
    // Truncated anywhere.
    for cut in [0, 7, 16, bytes.len() / 2, bytes.len() - 1] {
        let m = open_err(&bytes[..cut]).unwrap_or_else(|| panic!("accepted file cut at {cut}"));
        assert!(m.contains("bad.cdv"), "{m}");
        assert!(m.contains("truncated") || m.contains("not a cdvol"), "{m}");
    }
    // Not a packed file.
    let m =
        open_err(b"P6\n1 1\n255\n\0\0\0 and then some more bytes to be long enough for a footer")
            .unwrap();
    assert!(m.contains("not a cdvol packed file"), "{m}");
    // A flipped bit in the header or index.
    let mut b = bytes.clone();
    let n = b.len();
    b[n - 60] ^= 0x10;
    let m = open_err(&b).unwrap();
    assert!(m.contains("checksum"), "{m}");
    // A flipped bit in a payload: opening works, reading that brick fails.
    let mut b = bytes.clone();
    b[e.offset as usize + e.length as usize / 2] ^= 0x01;
    std::fs::write(&bad, &b).unwrap();
    let vol = PackedVolume::open(&bad).unwrap();
    let m = vol
        .read_brick(payload_brick as u64)
        .unwrap_err()
        .to_string();
    assert!(
        m.contains(&format!("brick {payload_brick}")) && m.contains("checksum"),
        "{m}"
    );
    // Info on a truncated file exits non-zero with the reason.
    std::fs::write(&bad, &bytes[..bytes.len() - 3]).unwrap();
    let err = fails(cdvol().arg("info").arg(&bad));
    assert!(err.contains("truncated"));
}

#[test]
fn inconsistent_headers_with_valid_checksums_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let good = valid_file(dir.path());
    let bytes = std::fs::read(&good).unwrap();
    // The rewrite itself keeps a good file good.
    let same = rewrite_header(&bytes, |_| {});
    let bad = dir.path().join("bad.cdv");
    std::fs::write(&bad, &same).unwrap();
    PackedVolume::open(&bad).unwrap();
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|h| {
                h["classification"] =
                    serde_json::json!({"transfer_function": {"tf": {"points": []}}})
            }),
            "points",
        ),
        (
            Box::new(|h| h["bricks"] = serde_json::json!([1, 1, 1])),
            "bricks",
        ),
        (
            Box::new(|h| h["dims"][0] = serde_json::json!(7)),
            "positions",
        ),
        (
            Box::new(|h| h["axes"][1][2] = serde_json::json!(-5.0)),
            "increasing",
        ),
        (
            Box::new(|h| h["brick_size"] = serde_json::json!(6)),
            "brick_size",
        ),
        (
            Box::new(|h| h["brick_size"] = serde_json::json!(1024)),
            "bricks",
        ),
        (
            Box::new(|h| h["storage"] = serde_json::json!("f32")),
            "storage",
        ),
        (
            Box::new(|h| h["classification"] = serde_json::json!({"iso": {"iso": null}})),
            "expected f64",
        ),
        (
            Box::new(|h| h["format_version"] = serde_json::json!(9)),
            "format_version",
        ),
    ];
    for (edit, needle) in cases {
        std::fs::write(&bad, rewrite_header(&bytes, edit)).unwrap();
        let m = PackedVolume::open(&bad)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_else(|| panic!("accepted ({needle})"));
        assert!(m.contains("bad.cdv") && m.contains(needle), "{needle}: {m}");
    }
    // A payload offset that overflows.
    let n = bytes.len();
    let trailer = u64::from_le_bytes(bytes[n - 40..n - 32].try_into().unwrap()) as usize;
    let hlen = u64::from_le_bytes(bytes[n - 32..n - 24].try_into().unwrap()) as usize;
    let mut b = bytes.clone();
    let first_entry = trailer + hlen;
    b[first_entry..first_entry + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    b[first_entry + 16..first_entry + 20].copy_from_slice(&0u32.to_le_bytes()); // not uniform
    b[first_entry + 24..first_entry + 32].fill(0); // and no value maximum
    let b = rewrite_header(&b, |_| {});
    std::fs::write(&bad, b).unwrap();
    let m = PackedVolume::open(&bad).err().unwrap().to_string();
    assert!(
        m.contains("brick 0") && m.contains("outside the payload area"),
        "{m}"
    );
}
