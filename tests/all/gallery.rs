//! The preset gallery (issue 51, item 3): every preset of each modality
//! rendered on the real CT, the CT phantom and MR phantoms (whole head
//! and skull-stripped, `cdvol phantom mr`: arbitrary scale, Rician
//! noise), each image checked by machine, and all of them written to
//! `docs/gallery/` (docs/PRESETS.md shows them).
//!
//! The checks, on the object's pixels (coverage above 5 %):
//! - not black: the mean grey level (over black) is at least [`FLOOR`];
//! - not saturated: at most [`WHITE`] of them are white (every channel at
//!   least 250);
//! - no wood grain (composites): [`cdvol::render::output::grain::grain`] of the
//!   render at step 0.5 mm against one at 0.125 mm is at most [`GRAIN`].

use std::path::{Path, PathBuf};

use cdvol::format::reader::PackedVolume;
use cdvol::render::output::grain::{grain, Image};

use crate::common::{cdvol, ok};

/// Mean grey level of the object's pixels, at least (0..1).
const FLOOR: f64 = 0.10;
/// Fraction of the object's pixels that may be white.
const WHITE: f64 = 0.25;
/// Largest grain figure (about 1 without grain; 5-11 with it).
const GRAIN: f64 = 2.0;
/// Image side (pixels).
const SIDE: u32 = 192;

struct Picture {
    rgb: Vec<u8>,
    alpha: Vec<u8>,
}

/// Renders `file` with `args` (RGBA, coverage in alpha) into `out`.
fn render(file: &Path, out: &Path, args: &[&str]) -> Picture {
    let side = SIDE.to_string();
    ok(cdvol()
        .args(["-q", "render"])
        .arg(file)
        .arg("-o")
        .arg(out)
        .args(["--width", &side, "--height", &side, "--view", "150,20"])
        .args(["--background", "transparent"])
        .args(args));
    let img = image::open(out).unwrap().to_rgba8();
    let mut rgb = Vec::new();
    let mut alpha = Vec::new();
    for p in img.pixels() {
        // Over black, as the page and the default PNG show it.
        let a = p[3] as u32;
        rgb.extend((0..3).map(|k| (p[k] as u32 * a / 255) as u8));
        alpha.push(p[3]);
    }
    Picture { rgb, alpha }
}

/// Mean grey level and white fraction of the object's pixels.
fn levels(p: &Picture) -> (f64, f64, usize) {
    let mut sum = 0.0;
    let (mut n, mut white) = (0usize, 0usize);
    for (c, &a) in p.rgb.chunks_exact(3).zip(&p.alpha) {
        if a < 13 {
            continue;
        }
        n += 1;
        sum += (c[0] as f64 + c[1] as f64 + c[2] as f64) / (3.0 * 255.0);
        if c.iter().all(|&v| v >= 250) {
            white += 1;
        }
    }
    (sum / n.max(1) as f64, white as f64 / n.max(1) as f64, n)
}

fn image(x: &Picture) -> Image<'_> {
    Image {
        width: SIDE as usize,
        height: SIDE as usize,
        rgb: &x.rgb,
        alpha: &x.alpha,
    }
}

fn gallery_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/gallery");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Every preset `file` offers, rendered and checked; returns the
/// failures (one line each) and the lines of the figures.
fn check_file(label: &str, file: &Path, scratch: &Path) -> (Vec<String>, Vec<String>) {
    let vol = PackedVolume::open(file).unwrap();
    let offered = cdvol::look::offered(vol.header());
    assert!(!offered.is_empty(), "{label}: no presets offered");
    let (mut bad, mut figures) = (Vec::new(), Vec::new());
    for p in &offered {
        let mip = p.name.ends_with("-mip");
        let mode = if mip { "mip" } else { "composite" };
        let name = format!("{label}-{}.png", p.name);
        let out = scratch.join(&name);
        let a = render(file, &out, &["--mode", mode, "--preset", &p.name]);
        // The gallery shows it over black, as `render` writes it by default.
        image::RgbImage::from_raw(SIDE, SIDE, a.rgb.clone())
            .unwrap()
            .save(gallery_dir().join(&name))
            .unwrap();
        let (mean, white, n) = levels(&a);
        let mut line = format!(
            "{label} {}: {mode}, {n} object pixels, mean {mean:.3}, white {white:.3}",
            p.name
        );
        if n < (SIDE * SIDE / 20) as usize {
            bad.push(format!("{label} {}: only {n} object pixels", p.name));
        }
        if mean < FLOOR {
            bad.push(format!(
                "{label} {}: mean {mean:.3} < {FLOOR} (black)",
                p.name
            ));
        }
        if white > WHITE {
            bad.push(format!(
                "{label} {}: {white:.3} of the object white > {WHITE}",
                p.name
            ));
        }
        if !mip {
            let fine = scratch.join(format!("{label}-{}-fine.png", p.name));
            let b = render(
                file,
                &fine,
                &["--mode", mode, "--preset", &p.name, "--step", "0.125"],
            );
            match grain(image(&a), image(&b)) {
                Some(g) => {
                    line += &format!(", grain {g:.2}");
                    if g > GRAIN {
                        bad.push(format!("{label} {}: grain {g:.2} > {GRAIN}", p.name));
                    }
                }
                None => bad.push(format!("{label} {}: no grain figure", p.name)),
            }
        }
        figures.push(line);
    }
    (bad, figures)
}

fn prep(input: &Path, out: &Path, args: &[&str]) {
    ok(cdvol()
        .args(["-q", "prep"])
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(args));
}

#[test]
fn every_ct_preset_draws_a_readable_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ct = d.join("ct.cdv");
    prep(&crate::common::real_ct(), &ct, &["--envelope", "ct"]);
    let head = d.join("head.json");
    ok(cdvol()
        .args(["-q", "phantom", "ct", "--dims", "128,128,80", "-o"])
        .arg(&head));
    let phantom = d.join("phantom.cdv");
    prep(&head, &phantom, &["--envelope", "ct"]);
    let mut bad = Vec::new();
    for (label, f) in [("ct", &ct), ("ct-phantom", &phantom)] {
        let (b, figures) = check_file(label, f, d);
        eprintln!("{}", figures.join("\n"));
        bad.extend(b);
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn every_mr_preset_draws_a_readable_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut bad = Vec::new();
    for (label, extra) in [("mr", &[][..]), ("mr-stripped", &["--skull-stripped"][..])] {
        let input = d.join(format!("{label}.json"));
        ok(cdvol()
            .args(["-q", "phantom", "mr", "--dims", "112,112,84", "-o"])
            .arg(&input)
            .args(extra));
        let f = d.join(format!("{label}.cdv"));
        prep(&input, &f, &["--envelope", "auto"]);
        let (b, figures) = check_file(label, &f, d);
        eprintln!("{}", figures.join("\n"));
        bad.extend(b);
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
