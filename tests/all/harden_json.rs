//! Strict JSON from the user (issue 17, item 10): a duplicate key is
//! refused naming it (serde_json alone keeps the last), `positions` and
//! `spacing` on one axis are refused, and a spacing (or the mean gap of a
//! listed axis) below `cdvol::input::sidecar::MIN_SPACING_MM` is refused. Covers sidecars,
//! transfer functions (`prep --classify-tf`, `render --tf`) and the render
//! look keys. docs/RELIABILITY.md ("Strict JSON") names each test here.

use std::path::Path;

use crate::common::{cdvol, fails, ok};

const GOOD_AXES: &str = r#""x": 1, "y": 1, "z": 1"#;

/// A 6^3 u8 stack with a bright cube in the middle, described by a
/// sidecar whose axis keys are `axes` (and any `extra` keys).
fn stack(dir: &Path, name: &str, axes: &str, extra: &str) -> std::path::PathBuf {
    let mut raw = vec![0u8; 216];
    for z in 2..4 {
        for y in 2..4 {
            for x in 2..4 {
                raw[(z * 6 + y) * 6 + x] = 200;
            }
        }
    }
    std::fs::write(dir.join("s.raw"), raw).unwrap();
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(r#"{{"data": "s.raw", "dims": [6, 6, 6], "dtype": "u8", {axes}{extra}}}"#),
    )
    .unwrap();
    p
}

fn prep(dir: &Path, sidecar: &Path, extra: &[&str]) -> std::process::Command {
    let mut c = cdvol();
    c.current_dir(dir)
        .arg("prep")
        .arg("-q")
        .arg(sidecar)
        .args(["-o", "o.cdv", "--brick", "4"])
        .args(extra);
    c
}

fn has_all(text: &str, words: &[&str]) {
    for w in words {
        assert!(text.contains(w), "{w:?} not in: {text}");
    }
}

#[test]
fn sidecar_duplicate_keys_are_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let good = stack(d.path(), "good.json", GOOD_AXES, "");
    ok(&mut prep(d.path(), &good, &["--iso", "100"]));
    // Top level: the second dtype would win silently.
    let s = stack(d.path(), "a.json", GOOD_AXES, r#", "dtype": "u16""#);
    let e = fails(&mut prep(d.path(), &s, &["--iso", "100"]));
    has_all(&e, &["a.json", "dtype", "duplicate"]);
    // Nested, in an axis object.
    let s = stack(
        d.path(),
        "b.json",
        r#""x": {"spacing": [1, 1, 1, 1, 1], "spacing": [2, 2, 2, 2, 2]}, "y": 1, "z": 1"#,
        "",
    );
    let e = fails(&mut prep(d.path(), &s, &["--iso", "100"]));
    has_all(&e, &["b.json", "x.spacing", "duplicate"]);
}

#[test]
fn sidecar_positions_and_spacing_on_one_axis_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let s = stack(
        d.path(),
        "c.json",
        r#""x": {"positions": [0, 1, 2, 3, 4, 5], "spacing": [2, 2, 2, 2, 2]}, "y": 1, "z": 1"#,
        "",
    );
    let e = fails(&mut prep(d.path(), &s, &["--iso", "100"]));
    has_all(&e, &["c.json", "x", "positions", "spacing"]);
}

#[test]
fn sidecar_spacing_below_the_minimum_is_refused() {
    let d = tempfile::tempdir().unwrap();
    for (name, axes, field) in [
        ("u.json", r#""x": 5e-324, "y": 1, "z": 1"#, "x"),
        (
            "g.json",
            r#""x": 1, "y": {"spacing": [1e-9, 1e-9, 1e-9, 1e-9, 1e-9]}, "z": 1"#,
            "y.spacing",
        ),
        (
            "p.json",
            r#""x": 1, "y": 1, "z": {"positions": [7, 7.000000001, 7.000000002, 7.000000003, 7.000000004, 7.000000005]}"#,
            "z.positions",
        ),
    ] {
        let s = stack(d.path(), name, axes, "");
        let e = fails(&mut prep(d.path(), &s, &["--iso", "100"]));
        has_all(&e, &[name, field, "1e-6"]);
    }
}

#[test]
fn transfer_function_duplicate_keys_are_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let s = stack(d.path(), "s.json", GOOD_AXES, "");
    let tf = d.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"points": [{"value": 0, "opacity": 0, "color": [1, 1, 1]},
                       {"value": 150, "opacity": 1, "opacity": 0, "color": [1, 1, 1]}]}"#,
    )
    .unwrap();
    let e = fails(&mut prep(d.path(), &s, &["--classify-tf", "tf.json"]));
    has_all(&e, &["tf.json", "points[1].opacity", "duplicate"]);

    // The look keys of a render transfer function.
    std::fs::write(
        &tf,
        r#"{"points": [{"value": 0, "opacity": 0, "color": [1, 1, 1]},
                       {"value": 150, "opacity": 1, "color": [1, 1, 1]}],
            "shade": true, "shade": false}"#,
    )
    .unwrap();
    ok(&mut prep(d.path(), &s, &["--iso", "100"]));
    let e = fails(cdvol().current_dir(d.path()).args([
        "render",
        "-q",
        "o.cdv",
        "--mode",
        "composite",
        "--tf",
        "tf.json",
        "-o",
        "r.png",
        "--width",
        "16",
        "--height",
        "16",
    ]));
    has_all(&e, &["tf.json", "shade", "duplicate"]);
}
