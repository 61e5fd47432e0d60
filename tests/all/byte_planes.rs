//! Format version 3 stores each payload's sample words as byte planes
//! (src/format/planes.rs). The same input prepared as version 2 and as
//! version 3 must hold the same volume: every brick reads back the same
//! words, octant codes and DDA planes, and renders are the same images.
//! The stored bytes themselves are checked against the documented
//! layout, so a writer and reader that both skipped the planes would
//! fail too.

use proptest::prelude::*;

use crate::common::{self, cdvol, fails, ok, write_stack};
use cdvol::format::reader::PackedVolume;
use cdvol::format::{planes, BYTE_PLANES_VERSION, FORMAT_VERSION};
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::Method;
use cdvol::render::{render, Mode};

/// The stored payload of brick `id` decompressed, without joining its
/// planes (None for a uniform brick); `bytes` is the whole file.
fn stored(bytes: &[u8], vol: &PackedVolume, id: u64) -> Option<Vec<u8>> {
    let e = vol.index()[id as usize];
    if e.is_uniform() {
        return None;
    }
    let comp = &bytes[e.offset as usize..e.offset as usize + e.length as usize];
    Some(zstd::decode_all(comp).unwrap())
}

/// `values` of `dtype` prepared as version 2 and as version 3 (iso 100,
/// `brick` cells per brick, octant codes and DDA planes when asked), and
/// checked alike.
fn check(dtype: &str, dims: [usize; 3], values: &[f64], brick: usize, aniso: bool, dda: bool) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let side = write_stack(d, "v", dims, dtype, values, ["1", "0.5", "2"], "");
    let prep = |version: u32, name: &str| {
        let out = d.join(name);
        let v = common::packed_with(&side, &out, 100.0, |o| {
            o.brick_size = brick;
            o.aniso = aniso;
            o.dda = dda;
            o.format_version = version;
        });
        (out, v)
    };
    let (p2, v2) = prep(2, "v2.cdv");
    let (p3, v3) = prep(BYTE_PLANES_VERSION, "v3.cdv");
    assert_eq!(v2.header().format_version, 2);
    assert_eq!(v3.header().format_version, 3);
    let width = v3.header().storage.size();
    assert_eq!(v3.header().byte_planes(), width > 1, "{dtype}");
    assert!(!v2.header().byte_planes());
    assert_eq!(v2.index().len(), v3.index().len());
    let (f2, f3) = (std::fs::read(&p2).unwrap(), std::fs::read(&p3).unwrap());
    for id in 0..v2.header().brick_count() {
        let (a, b) = (v2.index()[id as usize], v3.index()[id as usize]);
        assert_eq!(
            (a.flags, a.uniform_code, a.value_max),
            (b.flags, b.uniform_code, b.value_max),
            "{dtype} brick {id}: index"
        );
        // Read back, the payloads are the same bytes (words interleaved).
        let (r2, r3) = (v2.read_payload(id).unwrap(), v3.read_payload(id).unwrap());
        assert_eq!(r2, r3, "{dtype} brick {id}: payload read back");
        // Stored, version 3 holds the planes of version 2's words, then
        // the same octant and DDA bytes.
        let (Some(s2), Some(s3)) = (stored(&f2, &v2, id), stored(&f3, &v3, id)) else {
            continue;
        };
        assert_eq!(Some(&s2), r2.as_ref(), "version 2 is stored as read");
        let n = v3.header().words_len(v3.header().brick_coords(id)) as usize;
        let mut want = Vec::new();
        planes::split(&s2[..n], width, &mut want);
        want.extend_from_slice(&s2[n..]);
        assert_eq!(s3, want, "{dtype} brick {id}: stored layout");
        if width > 1 && n >= 2 * width {
            assert_ne!(s3, s2, "{dtype} brick {id}: planes differ from words");
        }
    }
    let cam = common::orbit(&v2, [30.0, 20.0], None, 24, 20);
    for mode in [
        Mode::Mip,
        Mode::Depth {
            hit: HitMethod::Int,
        },
    ] {
        let o = common::test_opts(mode.clone(), Method::Cd { min_leap: 1 });
        let (f2, _) = render(&v2, &cam, &o, &NoProgress).unwrap();
        let (f3, _) = render(&v3, &cam, &o, &NoProgress).unwrap();
        assert!(common::same_frame(&f2, &f3), "{dtype} {mode:?}: images");
    }
}

/// Values for `dtype` around the tests' iso of 100: object samples 200,
/// background 0..99, and at the type's extremes where it has them.
fn values_for(dtype: &str, raw: &[f64]) -> Vec<f64> {
    raw.iter()
        .enumerate()
        .map(|(i, &v)| match (dtype, i % 11) {
            ("f32" | "f64", 5) => f64::NAN,
            ("f32" | "f64", 7) => -1e30,
            ("i16", 7) => -32768.0,
            ("u16", 7) => 65535.0,
            ("i32", 7) => -2147483648.0,
            _ => v,
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn version_3_holds_the_same_volume_as_version_2(
        (dims, raw, brick) in common::random_volume([14, 12, 10], 30),
        dtype in prop::sample::select(vec!["u8", "i16", "u16", "i32", "f32", "f64"]),
        aniso in any::<bool>(),
        dda in any::<bool>(),
    ) {
        check(dtype, dims, &values_for(dtype, &raw), brick, aniso, dda);
    }
}

/// The real CT (i16) in both layouts: same volume, and the byte planes
/// are smaller (measured sizes in docs/BENCHMARKS.md, "Byte planes").
#[test]
fn real_ct_in_both_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let prep = |v: u32, name: &str| {
        common::packed_with(&ct, &dir.path().join(name), 300.0, |o| {
            o.brick_size = 32;
            o.format_version = v;
        })
    };
    let (v2, v3) = (prep(2, "v2.cdv"), prep(3, "v3.cdv"));
    let (h2, h3) = (v2.header(), v3.header());
    assert!(h3.summary.payload_bytes < h2.summary.payload_bytes);
    let mut s3 = h3.summary.clone();
    s3.payload_bytes = h2.summary.payload_bytes;
    // Not assert_eq: the summary's histogram would fill the screen.
    assert!(
        s3 == h2.summary,
        "summaries differ beyond the payload bytes"
    );
    assert_eq!(
        (h3.dims, h3.storage, h3.codes),
        (h2.dims, h2.storage, h2.codes)
    );
    for id in 0..h2.brick_count() {
        let same = v2.read_payload(id).unwrap() == v3.read_payload(id).unwrap();
        assert!(same, "brick {id}: payloads differ");
    }
}

/// `prep --format-version`: 2 and 3 are written, anything else is refused
/// by the flag's name before any output exists; `info` names the version.
#[test]
fn prep_format_version_flag() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let side = write_stack(d, "v", [6, 5, 4], "u16", &[150.0; 120], ["1", "1", "1"], "");
    for v in [2, FORMAT_VERSION] {
        let out = d.join(format!("v{v}.cdv"));
        ok(cdvol()
            .args([
                "prep",
                "-q",
                "--iso",
                "100",
                "--format-version",
                &v.to_string(),
            ])
            .arg(&side)
            .arg("-o")
            .arg(&out));
        assert_eq!(PackedVolume::open(&out).unwrap().header().format_version, v);
        let info = ok(cdvol().arg("info").arg(&out));
        assert!(info.contains(&format!("version {v}")), "{info}");
    }
    for bad in ["1", "4"] {
        let out = d.join(format!("bad{bad}.cdv"));
        let err = fails(
            cdvol()
                .args(["prep", "-q", "--iso", "100", "--format-version", bad])
                .arg(&side)
                .arg("-o")
                .arg(&out),
        );
        assert!(
            err.contains("--format-version") && err.contains("2 to 3"),
            "{err}"
        );
        assert!(!out.exists());
    }
}
