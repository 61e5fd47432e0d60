//! The reader checks the header's meaning, not only its CRC (issue 17,
//! item 10): a header with `codes.max` 100000, a rescale slope of 0, a
//! storage type narrower than the input's, a code range outside the
//! storage type, and so on, re-written with a correct trailer CRC (as the
//! writer computes it), is refused naming the field.
//! docs/RELIABILITY.md ("Header ranges") names the test.

use std::path::Path;

use cdvol::format::reader::PackedVolume;
use cdvol::progress::NoProgress;
use cdvol::tools::phantom;

use crate::common::{packed, rewrite_header};

/// A small packed CT phantom (i16 samples).
pub fn small_packed(dir: &Path) -> std::path::PathBuf {
    let ct = dir.join("ct.json");
    phantom::ct(
        &ct,
        &phantom::CtOptions {
            dims: [12, 10, 9],
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let out = dir.join("ct.cdv");
    packed(&ct, &out, 300.0);
    out
}

#[test]
fn header_out_of_range_with_a_good_crc_is_refused_by_field() {
    let dir = tempfile::tempdir().unwrap();
    let cdv = small_packed(dir.path());
    let file = std::fs::read(&cdv).unwrap();
    // The unchanged round trip opens: the helper writes what the writer does.
    let same = dir.path().join("same.cdv");
    std::fs::write(&same, rewrite_header(&file, |_| {})).unwrap();
    PackedVolume::open(&same).unwrap();
    let h0: serde_json::Value = {
        let v = PackedVolume::open(&cdv).unwrap();
        serde_json::to_value(v.header()).unwrap()
    };
    assert_eq!(h0["dtype"], "i16", "{h0}");
    assert_eq!(h0["codes"]["kind"], "int_range", "{h0}");

    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "codes.max 100000",
            Box::new(|h| h["codes"]["max"] = 100000.into()),
            "codes.max",
        ),
        (
            "rescale slope 0",
            Box::new(|h| h["rescale"]["slope"] = 0.into()),
            "rescale.slope",
        ),
        (
            "codes past the storage type",
            Box::new(|h| h["codes"]["base"] = 32767.into()),
            "codes.base",
        ),
        (
            "storage narrower than the input",
            Box::new(|h| {
                h["storage"] = "u8".into();
                h["codes"]["base"] = 0.into();
                h["codes"]["max"] = 10.into();
            }),
            "storage",
        ),
        (
            "bricks inconsistent",
            Box::new(|h| h["bricks"] = serde_json::json!([9, 9, 9])),
            "bricks",
        ),
        (
            "brick_size 0",
            Box::new(|h| h["brick_size"] = 0.into()),
            "brick_size",
        ),
        (
            "zstd_level 99",
            Box::new(|h| h["zstd_level"] = 99.into()),
            "zstd_level",
        ),
        (
            "histogram longer than the codes",
            Box::new(|h| h["summary"]["code_histogram"] = serde_json::json!(vec![0; 300])),
            "summary.code_histogram",
        ),
    ];
    let mut failures = Vec::new();
    for (what, edit, field) in cases {
        let p = dir.path().join("bad.cdv");
        std::fs::write(&p, rewrite_header(&file, edit)).unwrap();
        match PackedVolume::open(&p) {
            Ok(_) => failures.push(format!("{what}: accepted")),
            Err(e) => {
                let m = e.to_string();
                if !(m.contains(field) && m.contains("bad.cdv")) {
                    failures.push(format!("{what}: {m} does not name {field}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
