//! `cdvol demo`'s contact sheet (issue 51, item 11; issue 52, item 6):
//! the demo's three renders (smooth shading, a shaded composite, the cost
//! map) side by side, each scaled to 256 pixels high with its label
//! under it, written as `contact-sheet.png` beside them and printed with
//! them. README shows a copy, `docs/demo-contact-sheet.png`.

use std::time::Duration;

use image::imageops::{self, FilterType};
use image::RgbImage;

use crate::common::{cdvol, has_all, run};

/// The sheet's layout (src/demo.rs): tiles 256 high, 6 pixels around and
/// between them, a 26-pixel band under each for its label.
const TILE: u32 = 256;
const GAP: u32 = 6;
const BAND: u32 = 26;
/// The renders, in the sheet's order.
const RENDERS: [&str; 3] = ["head-surface", "head-composite", "head-cost"];

#[test]
fn the_demo_writes_a_labelled_contact_sheet_of_its_renders() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        cdvol().args(["-q", "demo", "--dir"]).arg(dir.path()),
        Duration::from_secs(600),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "cdvol demo failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sheet_path = dir.path().join("contact-sheet.png");
    let shown = sheet_path.display().to_string();
    has_all(&stdout, &["sheet     ", &shown, "792 x 288"]);
    let images = stdout
        .lines()
        .find(|l| l.starts_with("Images: "))
        .expect("the Images line");
    assert!(images.contains(&shown), "{images}");

    let sheet = image::open(&sheet_path).unwrap().to_rgb8();
    let n = RENDERS.len() as u32;
    assert_eq!(
        sheet.dimensions(),
        (GAP + n * (TILE + GAP), GAP + TILE + BAND)
    );
    for (i, name) in RENDERS.iter().enumerate() {
        // The tile is the render, scaled as the sheet scales it.
        let render = image::open(dir.path().join(format!("{name}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(render.dimensions(), (768, 768), "{name}");
        let want = imageops::resize(&render, TILE, TILE, FilterType::Triangle);
        let x0 = GAP + i as u32 * (TILE + GAP);
        let got = imageops::crop_imm(&sheet, x0, GAP, TILE, TILE).to_image();
        assert!(got == want, "{name}: the tile is not the scaled render");
        // A picture, not a black square.
        let lit = got
            .pixels()
            .filter(|p| p.0.iter().any(|&c| c >= 60))
            .count();
        assert!(lit > 2000, "{name}: {lit} lit pixels");
        // Its label: light text on the band's dark grey, centred under it.
        let band = imageops::crop_imm(&sheet, x0, GAP + TILE, TILE, BAND).to_image();
        let text = bright(&band, 160);
        assert!((50..3000).contains(&text), "{name}: {text} label pixels");
        let ink: Vec<u32> = band
            .enumerate_pixels()
            .filter(|(_, _, p)| p.0.iter().all(|&c| c >= 160))
            .map(|(x, _, _)| x)
            .collect();
        let (lo, hi) = (ink.iter().min().unwrap(), ink.iter().max().unwrap());
        let mid = (lo + hi) as i64 / 2;
        assert!(
            (mid - TILE as i64 / 2).abs() <= 3,
            "{name}: label {lo}..{hi}"
        );
    }

    // README's copy: the same layout, small enough for a README.
    let docs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/demo-contact-sheet.png");
    let bytes = std::fs::metadata(&docs).unwrap().len();
    assert!(bytes < 300 * 1024, "{}: {bytes} bytes", docs.display());
    let copy = image::open(&docs).unwrap();
    assert_eq!(
        (copy.width(), copy.height()),
        sheet.dimensions(),
        "{}: rerun `cdvol demo` and copy its contact-sheet.png there",
        docs.display()
    );
}

/// Pixels of `img` whose every channel is at least `level`.
fn bright(img: &RgbImage, level: u8) -> usize {
    img.pixels()
        .filter(|p| p.0.iter().all(|&c| c >= level))
        .count()
}
