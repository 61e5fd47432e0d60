//! Times a loop of views through the library, the Rust side of
//! tools/bench-python.sh (the same loop from Python is its other side).
//!
//! `cargo run --release --example render_views -- FILE.cdv VIEWS SIZE
//! [PRESET] [FRAME_MM]`
//!
//! Renders VIEWS orbit views 360/VIEWS degrees apart at elevation 0, SIZE
//! x SIZE pixels, on one renderer, in the file's look or PRESET's, with an
//! orthographic frame FRAME_MM high when given (as `cdvol render --frames`
//! fixes one frame for a whole turntable). Prints the first frame's
//! seconds and the warm frames' mean, each the wall time of
//! `Renderer::render` and of the 8-bit RGBA the Python package returns.

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use cdvol::render::Background;
use cdvol::{Look, View, Volume};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err("usage: render_views FILE.cdv VIEWS SIZE [PRESET] [FRAME_MM]".into());
    }
    let vol = Volume::open(&PathBuf::from(&args[0]))?;
    let views: u32 = args[1].parse()?;
    let size: u32 = args[2].parse()?;
    let look = match args.get(3).filter(|p| !p.is_empty()) {
        Some(p) => Look::preset(p),
        None => Look::default(),
    };
    let frame_mm = args.get(4).map(|f| f.parse::<f64>()).transpose()?;
    let renderer = vol.renderer();
    let mut secs = Vec::new();
    for k in 0..views {
        let mut view = View::orbit(k as f64 * 360.0 / views as f64, 0.0, size, size);
        view.frame_mm = frame_mm;
        let t = Instant::now();
        let image = renderer.render(&view, &look)?;
        let rgba = image.rgba8(Background::BLACK);
        secs.push(t.elapsed().as_secs_f64());
        std::hint::black_box(rgba);
    }
    let warm = &secs[1.min(secs.len() - 1)..];
    println!(
        "first {:.4} s, warm mean {:.4} s over {} frames, total {:.3} s",
        secs[0],
        warm.iter().sum::<f64>() / warm.len() as f64,
        warm.len(),
        secs.iter().sum::<f64>()
    );
    Ok(())
}
