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

use cdvol::{Look, View, Volume};

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args_os().skip(1);
    let Some(file) = args.next().map(PathBuf::from) else {
        return Err("usage: three_views FILE.cdv [OUT_DIR]".into());
    };
    let out_dir = args
        .next()
        .map_or_else(|| PathBuf::from("."), PathBuf::from);
    let vol = Volume::open(&file)?;
    // One renderer for the three views: the bricks the first decodes are
    // there for the others.
    let renderer = vol.renderer();
    // What `cdvol render FILE` draws with no options: the file's look if
    // it has one, else a surface at its iso value.
    let look = Look::default();
    for (name, az, el) in [
        ("front", 0.0, 0.0),
        ("side", 90.0, 0.0),
        ("above", 35.0, 50.0),
    ] {
        let image = renderer.render(&View::orbit(az, el, 512, 512), &look)?;
        let path = out_dir.join(format!("view-{name}.png"));
        image.save(&path)?;
        let s = &image.stats;
        println!(
            "{} ({} mode, {:.1} steps per ray, {} bricks read, {:.2} s)",
            path.display(),
            renderer.options(&look)?.mode.name(),
            s.steps as f64 / s.rays.max(1) as f64,
            s.cache_misses,
            s.seconds_total
        );
    }
    Ok(())
}
