//! `cdvol prep-batch` on a directory of mixed inputs with one broken: every
//! good input is prepared, the broken one is reported and makes the exit
//! code non-zero, a re-run skips what is complete and redoes what changed,
//! and shards split the inputs without overlap.

use crate::common::dicom_series;
use crate::common::gz;

use std::path::Path;
use std::process::{Command, Output};

use cdvol::format::reader::PackedVolume;
use cdvol::progress::NoProgress;
use cdvol::tools::phantom;

/// IN/ with a raw sidecar, a gzip NRRD, a DICOM series, a broken sidecar
/// and JSON that is not a volume.
fn inputs(root: &Path) {
    let ct = root.join("a/head.json");
    phantom::ct(
        &ct,
        &phantom::CtOptions {
            dims: [24, 20, 18],
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let raw = std::fs::read(root.join("a/head.raw")).unwrap();
    let mut nrrd = b"NRRD0004\ntype: short\ndimension: 3\nsizes: 24 20 18\n\
spacings: 0.9 0.9 2\nendian: little\nencoding: gzip\n\n"
        .to_vec();
    nrrd.extend(gz(&raw));
    std::fs::create_dir_all(root.join("b")).unwrap();
    std::fs::write(root.join("b/vol.nrrd"), nrrd).unwrap();
    dicom_series::write_series(&root.join("p1/ct"));
    std::fs::create_dir_all(root.join("broken")).unwrap();
    std::fs::write(root.join("broken/short.raw"), [0u8; 100]).unwrap();
    std::fs::write(
        root.join("broken/short.json"),
        r#"{"data": "short.raw", "dims": [8, 8, 8], "dtype": "u16", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    std::fs::write(root.join("a/stats.json"), r#"{"rays": 4}"#).unwrap();
}

fn batch(input: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cdvol"))
        // --allow-empty: some of the mixed inputs have no sample at 300.
        .args([
            "prep-batch",
            "-q",
            "--iso",
            "300",
            "--brick",
            "8",
            "--allow-empty",
        ])
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn rows(out: &Path, name: &str) -> Vec<serde_json::Value> {
    let b = std::fs::read(out.join(name)).unwrap();
    serde_json::from_slice::<Vec<serde_json::Value>>(&b).unwrap()
}

fn status(rows: &[serde_json::Value], input: &str) -> String {
    rows.iter()
        .find(|r| r["input"] == input)
        .unwrap_or_else(|| panic!("{input} not in {rows:#?}"))["status"]
        .as_str()
        .unwrap()
        .to_string()
}

#[test]
fn mixed_inputs_one_broken_then_resume() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("in"), dir.path().join("out"));
    inputs(&input);

    let o = batch(&input, &out, &["--jobs", "2"]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "one input is broken: {stdout}");
    assert!(stderr.contains("1 of 4 inputs failed"), "{stderr}");
    let r = rows(&out, "batch.json");
    assert_eq!(r.len(), 4, "{r:#?}");
    for good in ["a/head.json", "b/vol.nrrd", "p1/ct"] {
        assert_eq!(status(&r, good), "done");
    }
    assert_eq!(status(&r, "broken/short.json"), "failed");
    let err = r
        .iter()
        .find(|x| x["input"] == "broken/short.json")
        .unwrap()["error"]
        .to_string();
    assert!(
        err.contains("short.raw") && err.contains("expected at least"),
        "{err}"
    );
    // The table: one line per input, DICOM rectilinear with 20 slices.
    assert!(
        stdout.contains("| p1/ct | 33x28x20 | 20 | yes |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("| broken/short.json | - | - | - |"),
        "{stdout}"
    );
    // One line per finished input.
    assert_eq!(
        stdout.lines().filter(|l| l.contains(" -> ")).count(),
        4,
        "{stdout}"
    );
    // Outputs are complete packed files; the DICOM one has its positions.
    let v = PackedVolume::open(&out.join("p1_ct.cdv")).unwrap();
    assert_eq!(
        v.header().axes[2].coords(),
        dicom_series::z_positions().as_slice()
    );
    assert!(PackedVolume::open(&out.join("a_head.json.cdv")).is_ok());
    assert!(PackedVolume::open(&out.join("b_vol.nrrd.cdv")).is_ok());
    assert!(!out.join("broken_short.json.cdv").exists());

    // A re-run skips the complete outputs and still reports the failure.
    let o = batch(&input, &out, &[]);
    assert!(!o.status.success());
    let r = rows(&out, "batch.json");
    for good in ["a/head.json", "b/vol.nrrd", "p1/ct"] {
        assert_eq!(status(&r, good), "skipped", "{good}");
    }
    // A changed input is redone; a damaged output is redone.
    // The same bytes with a later modification time (set, not waited for:
    // some file systems keep whole seconds).
    let nrrd = std::fs::OpenOptions::new()
        .write(true)
        .open(input.join("b/vol.nrrd"))
        .unwrap();
    let was = nrrd.metadata().unwrap().modified().unwrap();
    nrrd.set_modified(was + std::time::Duration::from_secs(5))
        .unwrap();
    drop(nrrd);
    let cdv = std::fs::read(out.join("a_head.json.cdv")).unwrap();
    std::fs::write(out.join("a_head.json.cdv"), &cdv[..cdv.len() / 2]).unwrap();
    // Fix the broken input: the batch now succeeds.
    std::fs::write(input.join("broken/short.raw"), vec![0u8; 8 * 8 * 8 * 2]).unwrap();
    let o = batch(&input, &out, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = rows(&out, "batch.json");
    assert_eq!(status(&r, "b/vol.nrrd"), "done");
    assert_eq!(status(&r, "a/head.json"), "done");
    assert_eq!(status(&r, "p1/ct"), "skipped");
    assert_eq!(status(&r, "broken/short.json"), "done");

    // Asking for format version 2 (for older readers) redoes the version 3
    // outputs; asking for 3 again keeps those version 2 files, which read
    // as well.
    let o = batch(&input, &out, &["--format-version", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = rows(&out, "batch.json");
    for x in &r {
        assert_eq!(x["status"], "done", "{x:#?}");
        let why = x["reason"].as_str().unwrap_or_default();
        assert!(why.contains("format-version 3 -> 2"), "{why}");
    }
    assert_eq!(
        PackedVolume::open(&out.join("p1_ct.cdv"))
            .unwrap()
            .header()
            .format_version,
        2
    );
    let o = batch(&input, &out, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = rows(&out, "batch.json");
    assert!(r.iter().all(|x| x["status"] == "skipped"), "{r:#?}");
}

#[test]
fn shards_split_the_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    inputs(&input);
    std::fs::remove_dir_all(input.join("broken")).unwrap();
    let out = dir.path().join("out");
    let mut seen = Vec::new();
    for k in 0..2 {
        let o = batch(&input, &out, &["--shard", &format!("{k}/2")]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        for r in rows(&out, &format!("batch.{k}of2.json")) {
            seen.push(r["input"].as_str().unwrap().to_string());
        }
    }
    seen.sort();
    assert_eq!(seen, ["a/head.json", "b/vol.nrrd", "p1/ct"]);
    let o = batch(&input, &out, &["--shard", "2/2"]);
    assert!(!o.status.success());
}
