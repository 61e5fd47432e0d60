//! cdvol as a library: open a packed file, resolve its look as `cdvol
//! render` does, and render three views of it to PNG files.
//!
//! `cargo run --release --example three_views -- FILE.cdv [OUT_DIR]`
//!
//! A file prepared with a preset (`cdvol prep --preset NAME`) is drawn in
//! that preset's look (a composite, or a MIP for the `-mip` presets);
//! any other file as a shaded surface at its own iso value. The three
//! views are the front, the left side and a view from above and to the
//! side, each framed on the object; the images go to OUT_DIR (default: the
//! current directory) as `view-front.png`, `view-side.png` and
//! `view-above.png`. Try it on the demo's head:
//!
//! `cargo run --release -- demo && cargo run --release --example
//! three_views -- target/cdvol-demo/head.cdv target/cdvol-demo`

use std::error::Error;
use std::path::PathBuf;

use cdvol::format::reader::PackedVolume;
use cdvol::look::{resolve, Ask};
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::view::camera::orbit_dirs;
use cdvol::render::view::framing::{self, Framing};
use cdvol::render::{default_method, render, save, RenderOptions};

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args_os().skip(1);
    let Some(file) = args.next().map(PathBuf::from) else {
        return Err("usage: three_views FILE.cdv [OUT_DIR]".into());
    };
    let out_dir = args
        .next()
        .map_or_else(|| PathBuf::from("."), PathBuf::from);
    let vol = PackedVolume::open(&file)?;

    // What `cdvol render FILE` draws with no options: the file's look if
    // it has one, else a surface; shaded with Newton hits.
    let look = resolve(
        vol.header(),
        &Ask {
            mode: None,
            preset: None,
            preset_range: None,
            force: false,
            iso: None,
            tf: None,
            window: None,
            shade: false,
            hit: HitMethod::Newton,
            shadows: true,
            step_mm: 0.5,
        },
    )?;
    let mut opts = RenderOptions::new(look.mode, default_method(vol.header()));
    opts.iso = look.iso;
    opts.window = look.window;
    opts.look = look.look;

    // One framing for all three views: the object's box.
    let framing = Framing::of(&vol, &opts);
    for (name, az, el) in [
        ("front", 0.0, 0.0),
        ("side", 90.0, 0.0),
        ("above", 35.0, 50.0),
    ] {
        let camera = framing::orbit(&framing, orbit_dirs(az, el), None, None, 512, 512)?;
        let (frame, stats) = render(&vol, &camera, &opts, &NoProgress)?;
        let path = out_dir.join(format!("view-{name}.png"));
        save(&frame, &path)?;
        println!(
            "{} ({} mode, {:.1} steps per ray, {:.2} s)",
            path.display(),
            opts.mode.name(),
            stats.steps as f64 / stats.rays.max(1) as f64,
            stats.seconds_total
        );
    }
    Ok(())
}
