//! No wood grain in composite renders (issue 51, item 3): a transfer
//! function opaque from a threshold and coloured by value (as the
//! `ct-soft-tissue` preset, but given as `--tf` so that the presets may
//! change) draws, with samples at fixed multiples of the step, the value
//! at a depth behind the surface that drifts with the lattice: bands.
//! The composite refines each onset and restarts the lattice there
//! (render/integrate/refine.rs). Judged by
//! [`grain`](cdvol::render::output::grain::grain): the high-pass energy of the
//! render at the default step against the same view at a quarter of it,
//! about 1 without grain (shaded and unshaded, on the CT phantom and
//! the real CT); before the refinement it read 9 to 18. Both the step
//! integrator (`--integrate step`, which the refinement is for) and the
//! segment integrator (the default, issue 54) are judged against steps
//! of a quarter of the default.
//!
//! `WOOD_GRAIN_BIN=PATH` judges another `cdvol` build (to measure an
//! older one); `WOOD_GRAIN_PNG=DIR` keeps the renders there.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{self, ok};
use cdvol::render::output::grain::{grain, Image};

/// At most this figure: clean renders read 1.0-1.1, grain 9-18.
const MOST: f64 = 2.0;

/// Opaque from -160 HU (a 7 HU ramp from -167), grey from 0.05 there to
/// white at 240 HU.
const TF: &str = r#"{"points": [
  {"value": -1024.0, "opacity": 0.0, "color": [0.0, 0.0, 0.0]},
  {"value": -167.0, "opacity": 0.0, "color": [0.0, 0.0, 0.0]},
  {"value": -160.0, "opacity": 1.0, "color": [0.05, 0.05, 0.05]},
  {"value": 240.0, "opacity": 1.0, "color": [1.0, 1.0, 1.0]},
  {"value": 3071.0, "opacity": 1.0, "color": [1.0, 1.0, 1.0]}
]}"#;

/// The `cdvol` to judge.
fn cdvol() -> Command {
    match std::env::var_os("WOOD_GRAIN_BIN") {
        Some(bin) => Command::new(bin),
        None => common::cdvol(),
    }
}

/// Where renders go: `WOOD_GRAIN_PNG` or the test's directory.
fn out_dir(dir: &Path) -> PathBuf {
    std::env::var_os("WOOD_GRAIN_PNG").map_or_else(|| dir.to_path_buf(), PathBuf::from)
}

/// `file` rendered composite with the test's transfer function at step
/// `step`, `size` pixels square from azimuth 150, elevation 20, on a
/// transparent background: colour over black and coverage.
fn render(
    file: &Path,
    dir: &Path,
    name: &str,
    integrate: &str,
    step: f64,
    shade: bool,
    size: u32,
) -> (Vec<u8>, Vec<u8>) {
    let tf = dir.join("tf.json");
    std::fs::write(&tf, TF).unwrap();
    let png = out_dir(dir).join(format!(
        "{name}-{}{integrate}-{step}.png",
        if shade { "shaded-" } else { "" }
    ));
    let mut c = cdvol();
    c.arg("-q")
        .arg("render")
        .arg(file)
        .args(["--mode", "composite", "--tf"])
        .arg(&tf);
    c.args([
        "--integrate",
        integrate,
        "--step",
        &step.to_string(),
        "--view",
        "150,20",
        "--background",
        "transparent",
    ]);
    c.args(["--width", &size.to_string(), "--height", &size.to_string()]);
    if shade {
        c.arg("--shade");
    }
    ok(c.arg("-o").arg(&png));
    let img = image::open(&png).unwrap().to_rgba8();
    let (mut rgb, mut alpha) = (Vec::new(), Vec::new());
    for p in img.pixels() {
        let a = p[3] as u32;
        // Colour over black, as a frame holds it.
        rgb.extend((0..3).map(|k| ((p[k] as u32 * a + 127) / 255) as u8));
        alpha.push(p[3]);
    }
    (rgb, alpha)
}

/// The grain figure of `file` by `integrate` (at 0.5 mm for steps)
/// against steps of 0.125 mm.
fn figure(file: &Path, dir: &Path, name: &str, integrate: &str, shade: bool, size: u32) -> f64 {
    let coarse = render(file, dir, name, integrate, 0.5, shade, size);
    let fine = render(file, dir, name, "step", 0.125, shade, size);
    let side = size as usize;
    let a = Image {
        width: side,
        height: side,
        rgb: &coarse.0,
        alpha: &coarse.1,
    };
    let b = Image {
        rgb: &fine.0,
        alpha: &fine.1,
        ..a
    };
    let g = grain(a, b).expect("the renders show the head");
    eprintln!("wood grain: {name}, {integrate}, shaded {shade}: {g:.2}");
    g
}

/// `input` prepared for every CT preset into `dir`.
fn prep(input: &Path, dir: &Path) -> PathBuf {
    let out = dir.join("ct.cdv");
    ok(cdvol()
        .arg("-q")
        .arg("prep")
        .arg(input)
        .arg("-o")
        .arg(&out)
        .args(["--envelope", "ct"]));
    out
}

#[test]
fn phantom_composite_has_no_wood_grain() {
    let dir = tempfile::tempdir().unwrap();
    let head = dir.path().join("head.json");
    ok(cdvol()
        .args(["-q", "phantom", "ct", "-o"])
        .arg(&head)
        .args(["--dims", "128,128,80"]));
    let file = prep(&head, dir.path());
    for integrate in ["step", "segment"] {
        let g =
            [false, true].map(|shade| figure(&file, dir.path(), "phantom", integrate, shade, 192));
        assert!(
            g.iter().all(|&g| g <= MOST),
            "phantom, {integrate}: grain {g:.2?} (unshaded, shaded) > {MOST}"
        );
    }
}

#[test]
fn real_ct_composite_has_no_wood_grain() {
    let ct = common::real_ct();
    let dir = tempfile::tempdir().unwrap();
    let file = prep(&ct, dir.path());
    for integrate in ["step", "segment"] {
        let g =
            [false, true].map(|shade| figure(&file, dir.path(), "real-ct", integrate, shade, 256));
        assert!(
            g.iter().all(|&g| g <= MOST),
            "real CT, {integrate}: grain {g:.2?} (unshaded, shaded) > {MOST}"
        );
    }
}
