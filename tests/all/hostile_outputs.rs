//! Issue 57 regression tests (hostile_outputs): every writer refuses to
//! replace what it reads (the packed file, and the scan the packed file
//! was made from), `--mem-limit` above the machine's RAM never aborts,
//! `render --tf` reads a FIFO once, and `prep-batch` reports (and on
//! request prunes) the outputs of inputs that are gone.

use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::{cdvol, has_all, run, snapshot};

fn ok(c: &mut Command) -> String {
    let o = run(c, Duration::from_secs(60));
    assert!(
        o.status.success(),
        "{c:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs `c` (60 s at most), requires a non-zero exit by the program
/// itself (never a signal) and returns stderr.
fn refused(c: &mut Command) -> String {
    let o = run(c, Duration::from_secs(60));
    assert!(
        o.status.signal().is_none(),
        "{c:?} was killed by signal {:?}: {}",
        o.status.signal(),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        !o.status.success(),
        "{c:?} succeeded, expected a refusal: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// No Debug formatting in a message meant for people.
fn plain(text: &str) {
    for w in ["Some(", "None", "{ ", "Error {", "Os {"] {
        assert!(!text.contains(w), "Debug formatting {w:?} in: {text}");
    }
}

/// A small CT phantom `NAME.json` + `NAME.raw` in `dir`.
fn phantom(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(format!("{name}.json"));
    ok(cdvol()
        .args(["-q", "phantom", "ct", "--dims", "32,32,16", "-o"])
        .arg(&p));
    p
}

/// `input` prepared to `out` (8-cell bricks, iso 300).
fn prep(input: &Path, out: &Path) {
    ok(cdvol()
        .args(["-q", "prep", "--iso", "300", "--brick", "8"])
        .arg(input)
        .arg("-o")
        .arg(out));
}

// ---------------------------------------------------------------------------
// 1. One rule for every writer
// ---------------------------------------------------------------------------

/// `histogram x.png -o x.png`, where x.png is a packed file: refused,
/// naming the file, and nothing changes (also through a hard link).
#[test]
fn histogram_never_writes_over_its_packed_file() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let cdv = d.join("x.cdv");
    prep(&s, &cdv);
    let png = d.join("x.png");
    std::fs::rename(&cdv, &png).unwrap();
    std::fs::hard_link(&png, d.join("link.png")).unwrap();
    let before = snapshot(d);
    for out in ["x.png", "link.png"] {
        let err = refused(
            cdvol()
                .args(["-q", "histogram"])
                .arg(&png)
                .arg("-o")
                .arg(d.join(out)),
        );
        has_all(&err, &[out, "input"]);
        plain(&err);
        assert_eq!(snapshot(d), before, "histogram -o {out} changed a file");
    }
    // A plot beside it is still written.
    ok(cdvol()
        .args(["-q", "histogram"])
        .arg(&png)
        .arg("-o")
        .arg(d.join("plot.png")));
}

/// `export h.cdv --what values -o h.json`, where h.cdv was prepared from
/// h.json (+ h.raw): the scan is refused as an output, naming both files,
/// however prep was run (absolute name, or a relative one from the
/// scan's directory with export run from elsewhere). `histogram` refuses
/// it too.
#[test]
fn export_never_writes_over_the_scan_it_came_from() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let h = phantom(d, "h");
    let cdv = d.join("h.cdv");
    prep(&h, &cdv);
    // A second packed file whose header records the relative name `r.json`.
    std::fs::create_dir(d.join("sub")).unwrap();
    let r = phantom(&d.join("sub"), "r");
    ok(cdvol().current_dir(d.join("sub")).args([
        "-q", "prep", "--iso", "300", "--brick", "8", "r.json", "-o", "r.cdv",
    ]));
    // A sidecar whose data file is named unlike it: `export -o kdata.json`
    // would write its raw values over `kdata.raw`.
    let kdata = phantom(d, "kdata");
    let k = d.join("k.json");
    std::fs::rename(&kdata, &k).unwrap();
    prep(&k, &d.join("k.cdv"));
    let before = snapshot(d);
    let cases: [(&Path, PathBuf, &str); 4] = [
        (&cdv, h.clone(), "h.json"),
        (&d.join("k.cdv"), kdata.clone(), "kdata.raw"),
        (&d.join("sub/r.cdv"), r.clone(), "r.json"),
        (&d.join("sub/r.cdv"), d.join("sub/../sub/r.json"), "r.json"),
    ];
    for (packed, out, name) in &cases {
        let err = refused(
            cdvol()
                .current_dir(d)
                .args(["-q", "export", "--what", "values"])
                .arg(packed)
                .arg("-o")
                .arg(out),
        );
        let packed_name = packed.file_name().unwrap().to_str().unwrap();
        has_all(&err, &[name, packed_name]);
        plain(&err);
        assert_eq!(
            snapshot(d),
            before,
            "export -o {} changed a file",
            out.display()
        );
    }
    // The histogram writes images only, but a scan may be named like one.
    std::fs::copy(&cdv, d.join("copy.cdv")).unwrap();
    let scan = d.join("scan.png");
    std::fs::rename(d.join("h.raw"), d.join("scan-data.raw")).unwrap();
    let text = std::fs::read_to_string(&h)
        .unwrap()
        .replace("\"h.raw\"", "\"scan-data.raw\"");
    std::fs::write(&scan, text).unwrap();
    std::fs::remove_file(&h).unwrap();
    let made = d.join("made.cdv");
    prep(&scan, &made);
    let before = snapshot(d);
    let err = refused(
        cdvol()
            .args(["-q", "histogram"])
            .arg(&made)
            .arg("-o")
            .arg(&scan),
    );
    has_all(&err, &["scan.png", "made.cdv"]);
    plain(&err);
    assert_eq!(snapshot(d), before);
}

/// Every other writer, with its output naming one of its inputs:
/// refused by name before any work, nothing changes.
#[test]
fn every_writer_refuses_its_input_as_output() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let cdv = d.join("s.cdv");
    prep(&s, &cdv);
    let tf = d.join("tf.json");
    std::fs::write(
        &tf,
        r#"{"points": [{"value": 0, "opacity": 0}, {"value": 1000, "opacity": 0.5}]}"#,
    )
    .unwrap();
    let before = snapshot(d);
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        (
            vec![
                "prep".into(),
                "--iso".into(),
                "300".into(),
                s.clone().into(),
                "-o".into(),
                d.join("s.raw").into(),
            ],
            "s.raw",
        ),
        (
            vec![
                "prep".into(),
                "--classify-tf".into(),
                tf.clone().into(),
                s.clone().into(),
                "-o".into(),
                tf.clone().into(),
            ],
            "tf.json",
        ),
        (
            vec![
                "render".into(),
                "--mode".into(),
                "composite".into(),
                "--tf".into(),
                tf.clone().into(),
                cdv.clone().into(),
                "--width".into(),
                "16".into(),
                "--height".into(),
                "16".into(),
                "-o".into(),
                d.join("o.png").into(),
                "--stats".into(),
                tf.clone().into(),
            ],
            "tf.json",
        ),
        (
            vec![
                "render".into(),
                cdv.clone().into(),
                "--width".into(),
                "16".into(),
                "--height".into(),
                "16".into(),
                "-o".into(),
                d.join("o.png").into(),
                "--stats".into(),
                s.clone().into(),
            ],
            "s.json",
        ),
        (
            vec![
                "export".into(),
                "--what".into(),
                "codes".into(),
                cdv.clone().into(),
                "-o".into(),
                d.join("s.cdv").into(),
            ],
            "s.cdv",
        ),
        (
            vec![
                "histogram".into(),
                cdv.clone().into(),
                "-o".into(),
                d.join("s.cdv").into(),
            ],
            "s.cdv",
        ),
        (
            vec![
                "experiment".into(),
                "tradeoffs".into(),
                "--ct".into(),
                s.clone().into(),
                "--out".into(),
                s.clone().into(),
                "--size".into(),
                "16".into(),
                "--runs".into(),
                "1".into(),
            ],
            "s.json",
        ),
    ];
    for (args, name) in &cases {
        let err = refused(cdvol().current_dir(d).arg("-q").args(args));
        has_all(&err, &[name]);
        plain(&err);
        assert_eq!(snapshot(d), before, "{args:?} changed a file");
    }
}

// ---------------------------------------------------------------------------
// 2. --mem-limit above the machine's RAM
// ---------------------------------------------------------------------------

/// A volume that needs far more than the machine has, with `--mem-limit`
/// far above RAM: a named error (never an abort); a small render with
/// that limit still works.
#[test]
fn mem_limit_above_ram_is_an_error_not_an_abort() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // 100000 x 100000 x 2 u8 samples: a sparse 20 GB data file.
    std::fs::write(
        d.join("big.json"),
        r#"{"data": "big.raw", "dims": [100000, 100000, 2], "dtype": "u8", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    let f = std::fs::File::create(d.join("big.raw")).unwrap();
    f.set_len(20_000_000_000).unwrap();
    drop(f);
    let err = refused(cdvol().current_dir(d).args([
        "-q",
        "prep",
        "--iso",
        "1",
        "--mem-limit",
        "100000000",
        "big.json",
        "-o",
        "big.cdv",
    ]));
    has_all(&err, &["big.json", "memory", "--mem-limit"]);
    plain(&err);
    assert!(!d.join("big.cdv").exists());

    let s = phantom(d, "s");
    let cdv = d.join("s.cdv");
    ok(cdvol()
        .args(["-q", "prep", "--iso", "300", "--mem-limit", "100000000"])
        .arg(&s)
        .arg("-o")
        .arg(&cdv));
    let o = run(
        cdvol()
            .args([
                "-q",
                "render",
                "--width",
                "16",
                "--height",
                "16",
                "--mem-limit",
                "100000000",
            ])
            .arg(&cdv)
            .arg("-o")
            .arg(d.join("s.png")),
        Duration::from_secs(60),
    );
    assert!(
        o.status.success(),
        "render --mem-limit 100000000: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

// ---------------------------------------------------------------------------
// 3. render --tf reads its file once
// ---------------------------------------------------------------------------

const TF: &str =
    r#"{"points": [{"value": 300, "opacity": 0}, {"value": 1500, "opacity": 0.5}], "shade": true}"#;

/// `render --mode composite --tf FIFO`: the FIFO is written once; the
/// render must finish (30 s at most) and write its image.
#[test]
fn render_tf_from_a_fifo_is_read_once() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let cdv = d.join("s.cdv");
    prep(&s, &cdv);
    std::fs::write(d.join("tf.json"), TF).unwrap();
    let fifo = d.join("tf.fifo");
    ok(Command::new("mkfifo").arg(&fifo));
    // One writer, once.
    let mut writer = Command::new("sh")
        .arg("-c")
        .arg("cat \"$0\" > \"$1\"")
        .arg(d.join("tf.json"))
        .arg(&fifo)
        .spawn()
        .unwrap();
    let o = std::panic::catch_unwind(|| {
        run(
            cdvol()
                .args([
                    "-q",
                    "render",
                    "--mode",
                    "composite",
                    "--width",
                    "24",
                    "--height",
                    "20",
                ])
                .arg(&cdv)
                .arg("--tf")
                .arg(&fifo)
                .arg("-o")
                .arg(d.join("fifo.png")),
            Duration::from_secs(30),
        )
    });
    let _ = writer.kill();
    let _ = writer.wait();
    let o = o.unwrap_or_else(|_| panic!("render --tf FIFO hangs"));
    assert!(
        o.status.success(),
        "render --tf FIFO: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(d.join("fifo.png").is_file());

    // Process substitution: a /dev/fd pipe, as a shell gives it.
    let o = run(
        Command::new("bash")
            .arg("-c")
            .arg(
                "exec \"$0\" -q render --mode composite --width 24 --height 20 \"$1\" \
                 --tf <(cat \"$2\") -o \"$3\"",
            )
            .arg(env!("CARGO_BIN_EXE_cdvol"))
            .arg(&cdv)
            .arg(d.join("tf.json"))
            .arg(d.join("subst.png")),
        Duration::from_secs(30),
    );
    assert!(
        o.status.success(),
        "render --tf <(...): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The same image as from the plain file.
    ok(cdvol()
        .args([
            "-q",
            "render",
            "--mode",
            "composite",
            "--width",
            "24",
            "--height",
            "20",
        ])
        .arg(&cdv)
        .arg("--tf")
        .arg(d.join("tf.json"))
        .arg("-o")
        .arg(d.join("file.png")));
    let file = std::fs::read(d.join("file.png")).unwrap();
    assert_eq!(std::fs::read(d.join("fifo.png")).unwrap(), file);
    assert_eq!(std::fs::read(d.join("subst.png")).unwrap(), file);
}

// ---------------------------------------------------------------------------
// 4. prep-batch reports orphans
// ---------------------------------------------------------------------------

/// A batch of two inputs, one deleted, run again: the gone input's output
/// is named as an orphan in the table and in batch.json, with how to
/// remove it; `--prune` removes exactly it.
#[test]
fn batch_reports_and_prunes_orphans() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let input = d.join("in");
    let out = d.join("out");
    std::fs::create_dir(&input).unwrap();
    phantom(&input, "a");
    phantom(&input, "b");
    let batch = |extra: &[&str]| {
        ok(cdvol()
            .args(["-q", "prep-batch", "--iso", "300", "--brick", "8"])
            .args(extra)
            .arg(&input)
            .arg("-o")
            .arg(&out))
    };
    batch(&[]);
    assert!(out.join("b.json.cdv").is_file());
    // Not a cdvol output: never touched.
    std::fs::write(out.join("notes.cdv"), b"mine").unwrap();
    std::fs::remove_file(input.join("b.json")).unwrap();
    std::fs::remove_file(input.join("b.raw")).unwrap();

    let text = batch(&[]);
    has_all(&text, &["orphan", "b.json.cdv", "--prune"]);
    assert!(out.join("b.json.cdv").is_file(), "removed without --prune");
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("batch.json")).unwrap()).unwrap();
    let orphan = rows
        .iter()
        .find(|r| r["status"] == "orphan")
        .unwrap_or_else(|| panic!("no orphan row in {rows:?}"));
    assert!(orphan["output"].as_str().unwrap().ends_with("b.json.cdv"));
    assert_eq!(orphan["input"], "b.json");
    assert!(!text.contains("notes.cdv"), "{text}");

    // Still reported by the next run (batch.json lists it).
    has_all(&batch(&[]), &["orphan", "b.json.cdv"]);

    let text = batch(&["--prune"]);
    has_all(&text, &["b.json.cdv"]);
    assert!(!out.join("b.json.cdv").exists());
    assert!(out.join("a.json.cdv").is_file());
    assert_eq!(std::fs::read(out.join("notes.cdv")).unwrap(), b"mine");
    let text = batch(&[]);
    assert!(!text.contains("orphan"), "{text}");
}
