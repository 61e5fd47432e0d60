//! Times the template-based CD traversal against the CD ray caster on a
//! sphere phantom: `cargo run --release --example template_timing [SIZE]
//! [PIXELS]` (defaults 256 samples per axis, 512 x 512 pixels). Prints the
//! best of three runs per renderer, mode and view, with their step counts,
//! and how their depth images differ.

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::template::render_template;
use cdvol::render::traverse::{Method, TGrid};
use cdvol::render::view::camera::Camera;
use cdvol::render::HitMethod;
use cdvol::render::{render, Frame, Mode, RenderOptions, Stats};
use cdvol::tools::phantom;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let size: usize = args.next().map_or(Ok(256), |s| s.parse())?;
    let px: u32 = args.next().map_or(Ok(512), |s| s.parse())?;
    let dir = tempfile::tempdir()?;
    let side = dir.path().join("spheres.json");
    let info = phantom::spheres(
        &side,
        &phantom::SpheresOptions {
            size,
            per_axis: 2,
            seed: 1,
            ..Default::default()
        },
        &NoProgress,
    )?;
    let out = dir.path().join("spheres.cdv");
    prep(
        &RawSource::open(&side)?,
        &out,
        &PrepOptions::new(Classification::Iso { iso: info.iso }),
        &NoProgress,
    )?;
    let vol = PackedVolume::open(&out)?;
    let g = TGrid::<f64>::new(&vol.header().axes);
    println!(
        "{size}^3 sphere phantom (N = 2), {px} x {px} orthographic, {} threads",
        rayon::current_num_threads()
    );
    for view in [[33.0, 21.0], [0.0, 0.0]] {
        let cam = Camera::orbit(g.bounds(), view[0], view[1], None, None, px, px)
            .map_err(anyhow::Error::msg)?;
        for mode in [
            Mode::Depth {
                hit: HitMethod::Newton,
            },
            Mode::Surface {
                hit: HitMethod::Newton,
                shadows: false,
            },
        ] {
            let opts = RenderOptions {
                mode: mode.clone(),
                method: Method::Cd { min_leap: 1 },
                tile: 16,
                cache_bytes: 1 << 30,
                ..RenderOptions::new(mode.clone(), Method::Cd { min_leap: 1 })
            };
            type R = fn(
                &PackedVolume,
                &Camera,
                &RenderOptions,
                &NoProgress,
            ) -> Result<(Frame, Stats), cdvol::render::RenderError>;
            let runs: [(&str, R); 2] = [
                ("render cd", |v, c, o, p| render(v, c, o, p)),
                ("template cd", |v, c, o, p| render_template(v, c, o, p)),
            ];
            let mut frames = Vec::new();
            for (name, f) in runs {
                let mut best = f64::INFINITY;
                let mut last = None;
                for _ in 0..3 {
                    let t0 = std::time::Instant::now();
                    let r = f(&vol, &cam, &opts, &NoProgress)?;
                    best = best.min(t0.elapsed().as_secs_f64());
                    last = Some(r);
                }
                let (frame, s) = last.expect("three runs");
                println!(
                    "view {view:?} {:<8} {name:<12} best {:7.1} ms  rays {:>7} steps {:>9} \
                     macro {:>8} cell {:>8} hits {:>7} bricks read {:>5} MB decoded {:>6.1}",
                    cdvol::render::mode_name(&mode),
                    best * 1e3,
                    s.rays,
                    s.steps,
                    s.macro_steps,
                    s.cell_steps,
                    s.hits,
                    s.bricks_read,
                    s.bytes_decompressed as f64 / 1e6
                );
                frames.push(frame);
            }
            if let (Some(a), Some(b)) = (&frames[0].depth, &frames[1].depth) {
                let mut differ = 0;
                let mut d: Vec<f64> = Vec::new();
                for (x, y) in a.iter().zip(b) {
                    match (x.is_finite(), y.is_finite()) {
                        (true, true) => d.push((x - y).abs() as f64),
                        (p, q) => differ += (p != q) as usize,
                    }
                }
                d.sort_by(f64::total_cmp);
                println!(
                    "    depth: hit/miss differs on {:.2} % of pixels; |diff| median {:.3} mm, \
                     p95 {:.3} mm, max {:.3} mm",
                    100.0 * differ as f64 / a.len() as f64,
                    d[d.len() / 2],
                    d[d.len() * 95 / 100],
                    d[d.len() - 1]
                );
            }
        }
    }
    Ok(())
}
