//! `cdvol demo`: the whole pipeline once, on generated data. Writes the
//! CT-like head (variable slice thickness, paper section 4.3's data set 2)
//! and a sphere scene of the paper's section 5.1, prepares both, and
//! renders the head as a bone surface with smooth shading and shadows, a
//! shaded skin-and-bone composite and the traversal cost map (where the
//! chessboard distance codes let rays leap), then lays the three side by
//! side, labelled, in `contact-sheet.png` (README's picture,
//! `docs/demo-contact-sheet.png`).
//!
//! Binary side (declared by main.rs, not the library): it is a scripted
//! session for a person at a terminal, printing as it goes, and uses only
//! the library's public API plus `tools::phantom`, so nothing in the
//! library needs it and the library exposes no printing routine.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::info::Info;
use cdvol::prep::{prep, PrepOptions, PrepReport};
use cdvol::progress::Progress;
use cdvol::render::view::camera::orbit_dirs;
use cdvol::render::view::framing::{self, Framing};
use cdvol::render::HitMethod;
use cdvol::render::{default_method, render, Mode, RenderOptions};
use cdvol::tools::phantom;

use crate::print_prep;

/// `cdvol demo`: generates the CT-like head and a sphere scene, prepares
/// them, renders the head three ways, lays the renders out on a contact
/// sheet and prints what was written.
pub fn run(dir: &Path, progress: &dyn Progress) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create demo directory", dir.display()))?;
    // The CT-like head: variable slice thickness, bone at 300 HU.
    let head = dir.join("head.json");
    let ct = phantom::ct(
        &head,
        &phantom::CtOptions {
            dims: [256, 256, 160],
            dtype: phantom::CtDtype::I16,
            seed: 1,
            ..Default::default()
        },
        progress,
    )?;
    println!(
        "phantom   {} ({:.1} MiB)",
        ct.raw_path.display(),
        ct.bytes as f64 / 1048576.0
    );
    let head_packed = dir.join("head.cdv");
    let r = prep_file(
        &head,
        &head_packed,
        &PrepOptions::new(Classification::Iso { iso: 300.0 }),
        progress,
    )?;
    print_prep(&head_packed, &r)?;
    // A sphere scene of the paper's section 5.1 (N = 5).
    let scene = dir.join("spheres.json");
    let sp = phantom::spheres(
        &scene,
        &phantom::SpheresOptions {
            size: 128,
            per_axis: 5,
            seed: 1,
            spacing: phantom::parse_spacing3("1")?,
        },
        progress,
    )?;
    let scene_packed = dir.join("spheres.cdv");
    let r = prep_file(
        &scene,
        &scene_packed,
        &PrepOptions::new(Classification::Iso { iso: sp.iso }),
        progress,
    )?;
    print_prep(&scene_packed, &r)?;
    println!();
    let vol = PackedVolume::open(&head_packed)?;
    print!("{}", Info::of(&vol).to_text());
    println!();

    // Renders of the head: bone with smooth normals and shadows, a shaded
    // composite of skin and bone from a transfer-function prep and the
    // traversal cost map; each with its label on the contact sheet. First the
    // composite's file, classified by its transfer function (skin faint,
    // bone brighter).
    let tf = TransferFunction {
        points: vec![
            TfPoint {
                value: -300.0,
                opacity: 0.0,
                color: [0.9, 0.6, 0.5],
            },
            TfPoint {
                value: -100.0,
                opacity: 0.02,
                color: [0.9, 0.6, 0.5],
            },
            TfPoint {
                value: 100.0,
                opacity: 0.02,
                color: [0.9, 0.7, 0.6],
            },
            TfPoint {
                value: 300.0,
                opacity: 0.0,
                color: [1.0, 1.0, 0.9],
            },
            TfPoint {
                value: 600.0,
                opacity: 0.08,
                color: [1.0, 1.0, 0.95],
            },
        ],
    };
    let tf_path = dir.join("head-tf.json");
    cdvol::fsutil::write_atomic(&tf_path, &serde_json::to_vec_pretty(&tf)?)?;
    let tf_packed = dir.join("head-tf.cdv");
    let opts = PrepOptions::new(Classification::TransferFunction { tf: tf.clone() });
    let r = prep_file(&head, &tf_packed, &opts, progress)?;
    print_prep(&tf_packed, &r)?;
    let tf_vol = PackedVolume::open(&tf_packed)?;
    let composite = Mode::Composite { tf, step_mm: 0.5 };
    // One camera for all three, framed as `cdvol render` frames a view:
    // the box of the composite's object (the skin, the outermost).
    let framing = Framing::of(
        &tf_vol,
        &RenderOptions::new(composite.clone(), default_method(tf_vol.header())),
    );
    let camera = framing::orbit(&framing, orbit_dirs(35.0, 15.0), None, None, 768, 768)
        .map_err(anyhow::Error::msg)?;
    let mut outputs: Vec<(PathBuf, &str)> = Vec::new();
    let mut show =
        |name: &str, label: &'static str, vol: &PackedVolume, mode: Mode| -> Result<()> {
            // The defaults of `cdvol render` (32-pixel tiles, 512 MiB cache,
            // smooth normals), with the composite shaded.
            let mut opts = RenderOptions::new(mode, default_method(vol.header()));
            opts.look.shade = matches!(opts.mode, Mode::Composite { .. });
            let (frame, stats) = render(vol, &camera, &opts, progress)?;
            let path = dir.join(format!("{name}.png"));
            cdvol::render::save(&frame, &path).map_err(anyhow::Error::msg)?;
            println!(
                "render    {} ({} rays, {:.1} steps per ray, {} of {} bricks read, {:.2} s)",
                path.display(),
                stats.rays,
                stats.steps as f64 / stats.rays.max(1) as f64,
                stats.bricks_distinct,
                stats.bricks_total,
                stats.seconds_total
            );
            outputs.push((path, label));
            Ok(())
        };
    show(
        "head-surface",
        "bone, smooth shading, shadows",
        &vol,
        Mode::Surface {
            hit: HitMethod::Newton,
            shadows: true,
        },
    )?;
    show(
        "head-composite",
        "skin and bone, shaded composite",
        &tf_vol,
        composite,
    )?;
    show("head-cost", "traversal cost map", &vol, Mode::Cost)?;
    let sheet = dir.join("contact-sheet.png");
    let (w, h) = contact_sheet(&outputs, &sheet)?;
    println!(
        "sheet     {} ({w} x {h}, the renders side by side)",
        sheet.display()
    );
    println!();
    println!(
        "Images: {}",
        outputs
            .iter()
            .map(|(p, _)| p)
            .chain([&sheet])
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "Try: cdvol render {} -o view.png --view 120,30 --shadows",
        head_packed.display()
    );
    Ok(())
}

/// Contact sheet tiles: renders scaled to this height.
const TILE: u32 = 256;
/// Space around and between the tiles.
const GAP: u32 = 6;
/// The band under each tile that holds its label.
const LABEL_BAND: u32 = 26;

/// Lays `images` out in one row on a dark grey sheet, each scaled to
/// [`TILE`] pixels high with its label centred under it (the plots' font,
/// `plot::font`), and writes the sheet to `out` as PNG. Returns its
/// width and height.
fn contact_sheet(images: &[(PathBuf, &str)], out: &Path) -> Result<(u32, u32)> {
    use image::imageops::{self, FilterType};
    use plotters::prelude::*;
    use plotters::style::text_anchor::{HPos, Pos, VPos};

    let mut tiles = Vec::new();
    for (path, label) in images {
        let img = image::open(path)
            .with_context(|| format!("{}: cannot read the render back", path.display()))?
            .to_rgb8();
        let tw = (u64::from(img.width()) * u64::from(TILE) / u64::from(img.height().max(1))) as u32;
        tiles.push((
            imageops::resize(&img, tw.max(1), TILE, FilterType::Triangle),
            *label,
        ));
    }
    let w = GAP + tiles.iter().map(|(t, _)| t.width() + GAP).sum::<u32>();
    let h = GAP + TILE + LABEL_BAND;
    let mut sheet = image::RgbImage::from_pixel(w, h, image::Rgb([30, 30, 30]));
    let mut x = GAP;
    for (tile, _) in &tiles {
        imageops::replace(&mut sheet, tile, i64::from(x), i64::from(GAP));
        x += tile.width() + GAP;
    }
    cdvol::plot::font::register();
    {
        let root = BitMapBackend::with_buffer(sheet.as_mut(), (w, h)).into_drawing_area();
        let style = ("sans-serif", 16)
            .into_font()
            .color(&RGBColor(235, 235, 235))
            .pos(Pos::new(HPos::Center, VPos::Center));
        let mut x = GAP;
        for (tile, label) in &tiles {
            let at = (
                (x + tile.width() / 2) as i32,
                (GAP + TILE + LABEL_BAND / 2) as i32,
            );
            root.draw_text(label, &style, at)
                .map_err(|e| anyhow::anyhow!("{}: label {label:?}: {e}", out.display()))?;
            x += tile.width() + GAP;
        }
        root.present()
            .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    }
    let mut png = Vec::new();
    use image::codecs::png::{CompressionType, FilterType as PngFilter, PngEncoder};
    use image::ImageEncoder;
    PngEncoder::new_with_quality(&mut png, CompressionType::Best, PngFilter::Adaptive)
        .write_image(sheet.as_raw(), w, h, image::ExtendedColorType::Rgb8)
        .with_context(|| format!("{}: PNG encoding", out.display()))?;
    cdvol::fsutil::write_atomic(out, &png)?;
    Ok((w, h))
}

/// Opens `input` and prepares it into `output`.
fn prep_file(
    input: &Path,
    output: &Path,
    opts: &PrepOptions,
    progress: &dyn Progress,
) -> Result<PrepReport> {
    let src = cdvol::input::open(input)?;
    Ok(prep(src.as_ref(), output, opts, progress)?)
}
