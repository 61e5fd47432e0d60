//! `prep-batch` identity (issue 17, item 1): each output records its
//! input's identity (path, size, mtime, content fingerprint) and the prep
//! options in its header; a re-run redoes an output whose input or options
//! changed and says why, and two inputs never share an output name.
//! docs/RELIABILITY.md ("Batch identity") names each test here.

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, SystemTime};

use cdvol::format::reader::PackedVolume;
use cdvol::progress::NoProgress;
use cdvol::tools::phantom;

fn ct(path: &Path, dims: [usize; 3]) {
    phantom::ct(
        path,
        &phantom::CtOptions {
            dims,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
}

fn batch(input: &Path, out: &Path, extra: &[&str]) -> Output {
    let o = Command::new(env!("CARGO_BIN_EXE_cdvol"))
        .args(["prep-batch", "-q", "--allow-empty"])
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

fn rows(out: &Path) -> Vec<serde_json::Value> {
    serde_json::from_slice(&std::fs::read(out.join("batch.json")).unwrap()).unwrap()
}

fn row(out: &Path, input: &str) -> serde_json::Value {
    rows(out)
        .into_iter()
        .find(|r| r["input"] == input)
        .unwrap_or_else(|| panic!("{input} not in {:#?}", rows(out)))
}

fn status(out: &Path, input: &str) -> (String, String) {
    let r = row(out, input);
    (
        r["status"].as_str().unwrap().to_string(),
        r["reason"].as_str().unwrap_or("").to_string(),
    )
}

fn set_mtime(p: &Path, t: SystemTime) {
    std::fs::File::options()
        .write(true)
        .open(p)
        .unwrap()
        .set_modified(t)
        .unwrap();
}

#[test]
fn batch_rerun_with_other_options_redoes_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("in"), dir.path().join("out"));
    ct(&input.join("head.json"), [20, 18, 16]);
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    assert_eq!(status(&out, "head.json").0, "done");
    let o = batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    let (s, why) = status(&out, "head.json");
    assert_eq!(s, "skipped");
    assert!(why.contains("unchanged"), "{why}");
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("unchanged"),
        "the reason is printed"
    );

    for (extra, want) in [
        (
            &["--iso", "500", "--brick", "8"][..],
            "options changed (iso 300 -> 500)",
        ),
        (
            &["--iso", "500", "--brick", "16"][..],
            "options changed (brick 8 -> 16)",
        ),
        (
            &["--iso", "500", "--brick", "16", "--aniso"][..],
            "options changed (aniso no -> yes)",
        ),
    ] {
        batch(&input, &out, extra);
        let (s, why) = status(&out, "head.json");
        assert_eq!(s, "done", "{extra:?}");
        assert!(why.contains(want), "{extra:?}: {why}");
    }
    let v = PackedVolume::open(&out.join("head.json.cdv")).unwrap();
    let h = v.header();
    assert_eq!(
        h.classification,
        cdvol::classify::Classification::Iso { iso: 500.0 }
    );
    assert_eq!(h.brick_size, 16);
    assert!(h.aniso_block.is_some());
}

#[test]
fn batch_input_changed_in_place_is_redone() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("in"), dir.path().join("out"));
    ct(&input.join("head.json"), [20, 18, 16]);
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    // Same size, same mtime, other bytes (as `cp -p` of another scan, or
    // an edit followed by `touch -r`): the fingerprint sees it.
    let raw = input.join("head.raw");
    let t = std::fs::metadata(&raw).unwrap().modified().unwrap();
    let mut b = std::fs::read(&raw).unwrap();
    for x in b.iter_mut().take(64) {
        *x ^= 0x5a;
    }
    std::fs::write(&raw, &b).unwrap();
    set_mtime(&raw, t);
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    let (s, why) = status(&out, "head.json");
    assert_eq!(s, "done");
    assert!(why.contains("input changed (content"), "{why}");
    // A grown file (trailing bytes a raw stack ignores): size named.
    b.extend([0u8; 2]);
    std::fs::write(&raw, &b).unwrap();
    set_mtime(&raw, t);
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    let (s, why) = status(&out, "head.json");
    assert_eq!(s, "done");
    assert!(why.contains("input changed (size of"), "{why}");
}

#[test]
fn batch_input_added_later_with_an_older_mtime_is_prepared() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("in"), dir.path().join("out"));
    ct(&input.join("b_vol.json"), [20, 18, 16]);
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    // A second volume whose name flattens to the same output name,
    // copied in with an old timestamp (`cp -p`, rsync).
    ct(&input.join("b/vol.json"), [14, 12, 10]);
    let old = SystemTime::now() - Duration::from_secs(86400 * 365);
    set_mtime(&input.join("b/vol.json"), old);
    set_mtime(&input.join("b/vol.raw"), old);
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    let r = rows(&out);
    assert_eq!(r.len(), 2, "{r:#?}");
    let (a, b) = (row(&out, "b_vol.json"), row(&out, "b/vol.json"));
    assert_eq!(b["status"], "done", "{r:#?}");
    assert_ne!(a["output"], b["output"], "two inputs, one output name");
    assert_eq!(b["dims"], serde_json::json!([14, 12, 10]));
    let va = PackedVolume::open(Path::new(a["output"].as_str().unwrap())).unwrap();
    let vb = PackedVolume::open(Path::new(b["output"].as_str().unwrap())).unwrap();
    assert_eq!(va.header().dims, [20, 18, 16]);
    assert_eq!(vb.header().dims, [14, 12, 10]);
    // The names do not depend on the order the inputs came in: a third run
    // skips both.
    batch(&input, &out, &["--iso", "300", "--brick", "8"]);
    assert_eq!(status(&out, "b_vol.json").0, "skipped");
    assert_eq!(status(&out, "b/vol.json").0, "skipped");
}
