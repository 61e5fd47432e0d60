//! `cdvol demo`: the whole pipeline once, on generated data. Writes the
//! CT-like head (variable slice thickness, paper section 4.3's data set 2)
//! and a sphere scene of the paper's section 5.1, prepares both, and
//! renders the head as a shaded bone surface with shadows, a traversal
//! cost map and a skin-and-bone composite.
//!
//! Binary side (declared by main.rs, not the library): it is a scripted
//! session for a person at a terminal, printing as it goes, and uses only
//! the library's public API plus `tools::phantom`, so nothing in the
//! library needs it and the library exposes no printing routine.

use std::path::Path;

use anyhow::{Context, Result};

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::info::Info;
use cdvol::prep::{prep, PrepOptions, PrepReport};
use cdvol::progress::Progress;
use cdvol::render::camera::Camera;
use cdvol::render::shade::HitMethod;
use cdvol::render::traverse::TGrid;
use cdvol::render::{default_method, render, Mode, RenderOptions};
use cdvol::tools::phantom;

use crate::print_prep;

/// `cdvol demo`: generates the CT-like head and a sphere scene, prepares
/// them, renders the head three ways and prints what was written.
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

    // Renders of the head: shaded bone with shadows, the traversal cost
    // map, and a composite of skin and bone from a transfer-function prep.
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let camera = Camera::orbit(grid.bounds(), 35.0, 15.0, None, None, 768, 768)
        .map_err(anyhow::Error::msg)?;
    let mut outputs = Vec::new();
    let mut show = |name: &str, vol: &PackedVolume, mode: Mode| -> Result<()> {
        // The defaults of `cdvol render`: 32-pixel tiles, 512 MiB cache,
        // f64.
        let opts = RenderOptions::new(mode, default_method(vol));
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
        outputs.push(path);
        Ok(())
    };
    show(
        "head-surface",
        &vol,
        Mode::Surface {
            hit: HitMethod::Newton,
            shadows: true,
        },
    )?;
    show("head-cost", &vol, Mode::Cost)?;
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
    show(
        "head-composite",
        &tf_vol,
        Mode::Composite { tf, step_mm: 0.5 },
    )?;
    println!();
    println!(
        "Images: {}",
        outputs
            .iter()
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
