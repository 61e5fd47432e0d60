//! Table 1 and Fig. 17 on the real CT (module docs of [`paper`](super)).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::classify::Classification;
use crate::format::reader::PackedVolume;
use crate::input::raw::RawSource;
use crate::input::SliceSource;
use crate::prep::{prep, PrepOptions};
use crate::progress::{NoProgress, Progress};
use crate::render::sample::hit::HitMethod;
use crate::render::traverse::{Method, TGrid};
use crate::render::view::camera::Camera;
use crate::render::{render, Mode, RenderOptions};

// The shared helpers of mod.rs.
use super::*;

/// Table 1: single-cell vs macro-region traversal on the real CT made
/// rectilinear like the paper's data set 1.
pub fn table1(o: &PaperOptions, ct: &Path, pr: &dyn Progress) -> anyhow::Result<String> {
    let tmp = tempfile::tempdir()?;
    let (side, desc) = rectilinear_ct(ct, tmp.path())?;
    let src = RawSource::open(&side)?;
    let packed = tmp.path().join("ct-rect.cdv");
    let iso = CT_ISO;
    prep(
        &src,
        &packed,
        &PrepOptions::new(Classification::Iso { iso }),
        &NoProgress,
    )?;
    let vol = PackedVolume::open(&packed)?;
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let size = 2 * o.rays;
    let cam = Camera::orbit(grid.bounds(), 30.0, 20.0, None, None, size, size)
        .map_err(anyhow::Error::msg)?;
    let rays = all_rays(&cam);
    let methods = [Method::Fvt, Method::Cd { min_leap: 1 }];
    pr.begin("table1", (o.runs.max(1) * 2) as u64);
    let bg = background(&vol, &rays, &methods, o.runs);
    let mut totals = vec![Vec::new(); 2];
    for _ in 0..o.runs.max(1) {
        for (i, &m) in methods.iter().enumerate() {
            let ro = RenderOptions::new(
                Mode::Surface {
                    hit: HitMethod::Int,
                    shadows: false,
                },
                m,
            );
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
            let t0 = Instant::now();
            pool.install(|| render(&vol, &cam, &ro, &NoProgress))?;
            totals[i].push(t0.elapsed().as_secs_f64());
            pr.advance(1);
        }
    }
    pr.end();
    let tot: Vec<f64> = totals.into_iter().map(median).collect();
    write_csv(
        &o.dir.join("table1.csv"),
        "version,background_s,render_s,steps",
        &[
            format!(
                "single voxel,{:.6},{:.6},{}",
                bg[0].seconds, tot[0], bg[0].counts.steps
            ),
            format!(
                "macro-region,{:.6},{:.6},{}",
                bg[1].seconds, tot[1], bg[1].counts.steps
            ),
        ],
    )?;
    let mut s =
        String::from("## Table 1: single-cell vs macro-region traversal on the rectilinear CT\n\n");
    let _ = writeln!(
        s,
        "{desc} Surface at {iso} (bone), {size}x{size} orthographic rays at azimuth 30, \
         elevation 20, one thread; background = every ray traced to its first 1-cell, \
         rendering = the whole surface render (hit search and shading).\n\n\
         | version | background traversal (ms) | rendering (ms) | steps |\n|---|---|---|---|\n\
         | single voxel (fvt) | {:.1} | {:.1} | {} |\n\
         | macro-region (cd) | {:.1} | {:.1} | {} |\n\
         | ratio fvt/cd | {:.2} | {:.2} | {:.2} |\n\n\
         Paper (data set 1): background 56.1 s vs 18.5 s (3.03x), rendering 67.2 s vs 29.1 s (2.31x).\n\n\
         The rendering ratio falls below the background ratio because the part \
         the traversal does not change (hit search, shading, and here reading and decoding \
         the bricks, since every render starts with an empty cache) is {:.0} % of our \
         macro-region render against 36 % (10.6 of 29.1 s) of the paper's.\n",
        bg[0].seconds * 1e3,
        tot[0] * 1e3,
        bg[0].counts.steps,
        bg[1].seconds * 1e3,
        tot[1] * 1e3,
        bg[1].counts.steps,
        bg[0].seconds / bg[1].seconds,
        tot[0] / tot[1],
        bg[0].counts.steps as f64 / bg[1].counts.steps as f64,
        100.0 * (tot[1] - bg[1].seconds) / tot[1],
    );
    Ok(s)
}

/// The iso value of the CT's bone surface used throughout (HU).
pub const CT_ISO: f64 = 300.0;

/// The real CT with its slices summed (averaged) in pairs over the lower
/// 60 % of the stack and in fours above, each new slice at the mean
/// position of its sources (the paper's data set 1: 1 x 1 x 2 in the
/// facial part, 1 x 1 x 4 in the cranial part). Writes an f32 raw stack
/// and a sidecar with per-slice positions.
pub fn rectilinear_ct(ct: &Path, dir: &Path) -> anyhow::Result<(PathBuf, String)> {
    let src = RawSource::open(ct)?;
    let meta = src.meta().clone();
    let [nx, ny, nz] = meta.grid.dims();
    let zs = meta.grid.axes[2].coords().to_vec();
    let split = nz * 6 / 10;
    let mut groups: Vec<std::ops::Range<usize>> = Vec::new();
    let mut z = 0;
    while z < nz {
        let g = if z < split { 2 } else { 4 };
        groups.push(z..(z + g).min(nz));
        z += g;
    }
    let mut data: Vec<u8> = Vec::with_capacity(nx * ny * groups.len() * 4);
    let mut pos = Vec::new();
    let mut slice = vec![0.0f64; nx * ny];
    for g in &groups {
        let mut acc = vec![0.0f64; nx * ny];
        for z in g.clone() {
            src.read_slice(z, &mut slice)?;
            for (a, v) in acc.iter_mut().zip(&slice) {
                *a += v;
            }
        }
        let k = g.len() as f64;
        for a in acc {
            data.extend_from_slice(&((a / k) as f32).to_le_bytes());
        }
        pos.push(g.clone().map(|z| zs[z]).sum::<f64>() / k);
    }
    let raw = dir.join("ct-rect.raw");
    std::fs::write(&raw, &data)?;
    let ax = |k: usize| {
        let c = meta.grid.axes[k].coords();
        (c[1] - c[0], c[0])
    };
    let (hx, ox) = ax(0);
    let (hy, oy) = ax(1);
    let side = dir.join("ct-rect.json");
    let json = serde_json::json!({
        "data": "ct-rect.raw",
        "dims": [nx, ny, groups.len()],
        "dtype": "f32",
        "endian": "little",
        "x": hx,
        "y": hy,
        "z": {"positions": pos},
        "origin": [ox, oy, 0.0],
    });
    std::fs::write(&side, serde_json::to_vec_pretty(&json)?)?;
    let gaps: Vec<f64> = pos.windows(2).map(|w| w[1] - w[0]).collect();
    let (gmin, gmax) = gaps
        .iter()
        .fold((f64::INFINITY, 0.0f64), |a, &g| (a.0.min(g), a.1.max(g)));
    let desc = format!(
        "The real CT ({nx}x{ny}x{nz}, {:.3} mm slices) with slices averaged in pairs over \
         its lower {split} slices and in fours above: {nx}x{ny}x{} samples, slice gaps \
         {gmin:.2} to {gmax:.2} mm, kept as a rectilinear z axis.",
        zs[1] - zs[0],
        groups.len()
    );
    Ok((side, desc))
}

/// Fig. 17: shaded surface and the cost maps of fvt, octree and cd on the
/// real CT, side by side in one PNG on one common scale (brighter = more
/// steps until the surface).
pub fn fig17(o: &PaperOptions, ct: &Path, pr: &dyn Progress) -> anyhow::Result<String> {
    let tmp = tempfile::tempdir()?;
    let src = RawSource::open(ct)?;
    let packed = tmp.path().join("ct.cdv");
    prep(
        &src,
        &packed,
        &PrepOptions::new(Classification::Iso { iso: CT_ISO }),
        &NoProgress,
    )?;
    let vol = PackedVolume::open(&packed)?;
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let size = 2 * o.rays;
    let cam = Camera::orbit(grid.bounds(), 0.0, 0.0, None, None, size, size)
        .map_err(anyhow::Error::msg)?;
    let ro = RenderOptions::new;
    pr.begin("fig17", 4);
    let (surface, _) = render(
        &vol,
        &cam,
        &ro(
            Mode::Surface {
                hit: HitMethod::Int,
                shadows: false,
            },
            Method::Cd { min_leap: 1 },
        ),
        &NoProgress,
    )?;
    pr.advance(1);
    let ms = [Method::Fvt, Method::Octree, Method::Cd { min_leap: 1 }];
    let mut maps = Vec::new();
    for m in ms {
        let (f, st) = render(&vol, &cam, &ro(Mode::Cost, m), &NoProgress)?;
        maps.push((f.steps, st.steps));
        pr.advance(1);
    }
    pr.end();
    let max = maps
        .iter()
        .flat_map(|m| m.0.iter())
        .copied()
        .max()
        .unwrap_or(1)
        .max(1) as f32;
    let (w, h) = (size, size);
    let mut img = image::RgbImage::new(4 * w, h);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            img.put_pixel(
                x,
                y,
                image::Rgb([
                    surface.rgb[3 * i],
                    surface.rgb[3 * i + 1],
                    surface.rgb[3 * i + 2],
                ]),
            );
            for (j, m) in maps.iter().enumerate() {
                let g = (255.0 * (m.0[i] as f32 / max).sqrt()).round() as u8;
                img.put_pixel((j as u32 + 1) * w + x, y, image::Rgb([g, g, g]));
            }
        }
    }
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
    super::super::write_atomic(&o.dir.join("fig17.png"), &png)?;
    let mut s = String::from(
        "## Fig. 17: cost maps\n\n\
         ![fig17](experiments/fig17.png)\n\n",
    );
    let _ = writeln!(
        s,
        "The real CT (bone surface at {CT_ISO}), {size}x{size} orthographic, from the front. \
         Left to right: shaded surface, then the steps per ray until the surface for fvt, \
         octree and cd, on one common scale (grey = sqrt(steps / {max}), the largest count \
         of the three). Steps per image: fvt {}, octree {} ({:.2}x fewer), cd {} ({:.2}x fewer).",
        maps[0].1,
        maps[1].1,
        maps[0].1 as f64 / maps[1].1.max(1) as f64,
        maps[2].1,
        maps[0].1 as f64 / maps[2].1.max(1) as f64,
    );
    Ok(s)
}
