//! `cdvol render`: a tile-parallel CPU ray caster over packed files.
//!
//! ```text
//! BrickCache (cache.rs)    decoded bricks under a byte budget, shared
//!   -> trace (traverse.rs) fvt | cd | cd-aniso: the 1-cells a ray passes
//!   -> integrate (here)    surface | mip | composite | cost | depth
//!   -> tiles (here)        rayon over tiles, assembled in a fixed order
//! ```
//! Sampling, hit and shading code (shade.rs) is shared by all traversals,
//! so their images can differ only if their cell sequences differ.
//! Output is the same whatever the thread count, tile size or cache budget:
//! every pixel is computed on its own, from the same values.

pub mod cache;
pub mod camera;
pub mod lut;
pub mod policy;
pub mod shade;
pub mod shard;
pub mod template;
pub mod traverse;

use std::time::Instant;

use rayon::prelude::*;

use crate::classify::{Classification, TransferFunction};
use crate::format::reader::PackedVolume;
use crate::format::FormatError;
use crate::progress::Progress;
use cache::{Accessor, BrickCache, CacheCounters};
use camera::Camera;
use shade::{at, find_hit_with, shade, AlongRay, CellEval, HitMethod, HitParams};
use traverse::{trace, Flow, Method, Ray, Real, StepCounts, TGrid};

/// What a pixel shows.
#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    /// Shaded iso-surface at the file's iso value.
    Surface { hit: HitMethod, shadows: bool },
    /// Maximum of the interpolant at the 1-cells' face samples.
    Mip,
    /// Front-to-back compositing with a transfer function; `step_mm`
    /// apart, at `t = k * step_mm` along the ray.
    Composite { tf: TransferFunction, step_mm: f64 },
    /// Traversal steps per pixel until the surface is found (paper Fig.
    /// 17), as a heat map scaled to the largest count in the image.
    Cost,
    /// Distance to the iso-surface in mm.
    Depth { hit: HitMethod },
}

#[derive(Debug, Clone)]
pub struct RenderOptions {
    pub mode: Mode,
    pub method: Method,
    pub tile: u32,
    pub cache_bytes: usize,
    /// CD leaves a brick without 1-cells unread when its smallest code is
    /// at least this (255: read every brick CD enters).
    pub cd_lazy_min: u8,
    /// Arithmetic of the traversal (f64 by default; see docs/TRADEOFFS.md).
    pub precision: Precision,
    /// Iterations and tolerance of the bisect and newton hit methods.
    pub hit_params: HitParams,
}

impl RenderOptions {
    /// `mode` by `method` with the defaults of `cdvol render`: 32-pixel
    /// tiles, a 512 MiB cache, CD's lazy threshold, f64, default hit
    /// parameters.
    pub fn new(mode: Mode, method: Method) -> RenderOptions {
        RenderOptions {
            mode,
            method,
            tile: 32,
            cache_bytes: 512 << 20,
            cd_lazy_min: cache::LAZY_MIN_CODE_CD,
            precision: Precision::F64,
            hit_params: HitParams::default(),
        }
    }
}

/// Arithmetic of the traversal. Shading and hits are always f64.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    F32,
    /// Never misses a 1-cell in tests/extremes.rs (f32 does).
    #[default]
    F64,
}

/// Counters of a render (the `--stats` contract).
#[derive(Debug, Default, Clone, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    pub rays: u64,
    pub steps: u64,
    pub macro_steps: u64,
    pub cell_steps: u64,
    pub hits: u64,
    /// Brick payloads read and decoded into the cache (a brick evicted
    /// and needed again counts again; two threads racing to decode the
    /// same brick count once).
    pub bricks_read: u64,
    /// Distinct bricks read: the share of the file the scene needed. In
    /// merged statistics (parts, frames) the sum of theirs, an upper bound.
    #[serde(default)]
    pub bricks_distinct: u64,
    /// Bricks without 1-cells the traversal crossed without reading them.
    pub bricks_skipped: u64,
    pub cache_hits: u64,
    pub cache_misses: u64,
    pub bytes_decompressed: u64,
    pub peak_cache_bytes: u64,
    pub bricks_total: u64,
    pub seconds_total: f64,
    pub traversal: String,
    pub mode: String,
    pub width: u32,
    pub height: u32,
}

impl Stats {
    /// The counters of a render with `opts` through `cache`, started at
    /// `t0`; `traversal`, `width` and `height` are the caller's to fill.
    pub(crate) fn counted(
        rays: u64,
        hits: u64,
        steps: &StepCounts,
        cc: &CacheCounters,
        cache: &BrickCache,
        opts: &RenderOptions,
        t0: Instant,
    ) -> Stats {
        Stats {
            rays,
            steps: steps.steps,
            macro_steps: steps.macro_steps,
            cell_steps: steps.cell_steps,
            hits,
            bricks_read: cc.bricks_read,
            bricks_distinct: cache.distinct_read(),
            bricks_skipped: cc.bricks_skipped,
            cache_hits: cc.cache_hits,
            cache_misses: cc.cache_misses,
            bytes_decompressed: cc.bytes_decompressed,
            peak_cache_bytes: cache.peak_bytes() as u64,
            bricks_total: cache.volume().header().brick_count(),
            seconds_total: t0.elapsed().as_secs_f64(),
            traversal: String::new(),
            mode: mode_name(&opts.mode).into(),
            width: 0,
            height: 0,
        }
    }

    /// Adds the counters of `o` (another part or frame): sums, except
    /// `peak_cache_bytes` (the larger); `seconds_total` sums too.
    pub fn merge(&mut self, o: &Stats) {
        self.rays += o.rays;
        self.steps += o.steps;
        self.macro_steps += o.macro_steps;
        self.cell_steps += o.cell_steps;
        self.hits += o.hits;
        self.bricks_read += o.bricks_read;
        self.bricks_distinct += o.bricks_distinct;
        self.bricks_skipped += o.bricks_skipped;
        self.cache_hits += o.cache_hits;
        self.cache_misses += o.cache_misses;
        self.bytes_decompressed += o.bytes_decompressed;
        self.peak_cache_bytes = self.peak_cache_bytes.max(o.peak_cache_bytes);
        self.seconds_total += o.seconds_total;
    }
}

/// A rendered image: RGB8 for display, plus per-pixel data of the depth
/// and cost modes.
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    /// Depth mode: hit distance in mm, NaN where the ray misses.
    pub depth: Option<Vec<f32>>,
    /// Steps per pixel.
    pub steps: Vec<u32>,
}

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error("{}: {msg}", path.display())]
    Incompatible {
        path: std::path::PathBuf,
        msg: String,
    },
    #[error("option {option}: {msg}")]
    Option { option: &'static str, msg: String },
    /// Inputs the template traversal (template.rs) cannot render.
    #[error("template traversal: {0}")]
    Template(String),
}

/// Per-pixel result before colouring.
#[derive(Clone, Copy, Default, Debug, PartialEq)]
struct Px {
    rgb: [f32; 3],
    depth: f32,
    steps: u32,
    hit: bool,
}

/// Checks the options every renderer shares: Newton's tolerance and the
/// image size.
pub(crate) fn check_tol_and_size(opts: &RenderOptions, camera: &Camera) -> Result<(), RenderError> {
    let tol = opts.hit_params.newton_tol;
    if !(0.0..1.0).contains(&tol) {
        return Err(RenderError::Option {
            option: "--newton-tol",
            msg: format!("{tol}, expected a relative tolerance in [0, 1)"),
        });
    }
    let pixels = camera.width as u64 * camera.height as u64;
    if pixels > MAX_PIXELS {
        return Err(RenderError::Option {
            option: "--width/--height",
            msg: format!(
                "{} x {} = {pixels} pixels, expected at most {MAX_PIXELS}",
                camera.width, camera.height
            ),
        });
    }
    Ok(())
}

/// Checks that the mode can be rendered exactly from this file's
/// classification (never render silently wrong).
fn check_mode(vol: &PackedVolume, mode: &Mode) -> Result<(), RenderError> {
    let h = vol.header();
    let path = vol.path().to_path_buf();
    match (mode, &h.classification) {
        (Mode::Surface { .. } | Mode::Depth { .. }, Classification::TransferFunction { .. }) => {
            Err(RenderError::Incompatible {
                path,
                msg: "surface and depth modes need a file prepared with --iso T".into(),
            })
        }
        (Mode::Composite { tf, .. }, Classification::Iso { iso }) => {
            // Cells whose values all lie below iso were leapt over: the
            // transfer function must be transparent there.
            if tf.nonzero_on(f64::MIN, iso.next_down()) {
                Err(RenderError::Incompatible {
                    path,
                    msg: format!(
                        "the transfer function gives opacity to values below {iso}, which this \
                         file classified as empty (prepared with --iso {iso}); prepare it with \
                         `cdvol prep --classify-tf` and this transfer function, or --iso at the \
                         lowest value with opacity"
                    ),
                })
            } else {
                Ok(())
            }
        }
        (Mode::Composite { tf, .. }, Classification::TransferFunction { tf: file_tf }) => {
            let mut pts: Vec<f64> = tf
                .points
                .iter()
                .chain(&file_tf.points)
                .map(|p| p.value)
                .collect();
            pts.sort_by(f64::total_cmp);
            let mut probes = pts.clone();
            probes.extend(pts.windows(2).map(|w| 0.5 * (w[0] + w[1])));
            probes.push(pts[0] - 1.0);
            probes.push(pts[pts.len() - 1] + 1.0);
            match probes
                .iter()
                .find(|&&v| tf.opacity(v) > 0.0 && file_tf.opacity(v) == 0.0)
            {
                Some(v) => Err(RenderError::Incompatible {
                    path,
                    msg: format!(
                        "the transfer function gives opacity at value {v}, where the one the file \
                         was prepared with (--classify-tf) has none; prepare it with this \
                         transfer function"
                    ),
                }),
                None => Ok(()),
            }
        }
        _ => Ok(()),
    }
}

/// Smallest composite sample distance.
pub const MIN_STEP_MM: f64 = 1e-4;
/// Largest image (2^28 pixels, 16384 x 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

/// Renders `vol` as seen by `camera`: [`render_part`] over every tile,
/// then [`shard::assemble`]'s colouring, so a sharded render assembles to
/// the same bytes.
pub fn render(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<(Frame, Stats), RenderError> {
    render_in(vol, &policy::cache_for(vol, opts), camera, opts, progress)
}

/// [`render`] with a brick cache that outlives it: the frames of a
/// turntable share the bricks they decode (a frame's `bricks_distinct`
/// then counts the cache's whole history).
pub fn render_in(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<(Frame, Stats), RenderError> {
    let t0 = Instant::now();
    let part = render_part_in(vol, cache, camera, opts, Shard::WHOLE, progress)?;
    let (frame, mut stats) = shard::finish(&part.key, part.tiles, part.stats);
    stats.seconds_total = t0.elapsed().as_secs_f64();
    Ok((frame, stats))
}

/// Which tiles a render computes, out of the Morton-ordered tile list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Shard {
    pub k: u32,
    pub n: u32,
    pub layout: ShardLayout,
}

/// How the tiles are dealt to shards (docs/BENCHMARKS.md, "Sharded
/// renders", measures the two).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ShardLayout {
    /// Tile `i` to shard `i % n`: every shard gets a share of every part
    /// of the image, so shards take about the same time; but each reads
    /// most of the bricks the whole image needs.
    #[default]
    Interleaved,
    /// Tile `i` of `t` to shard `i * n / t`: contiguous runs of the Morton
    /// curve, compact on screen, so shards read mostly different bricks;
    /// but a shard over empty space finishes early.
    Blocks,
}

impl Shard {
    pub const WHOLE: Shard = Shard {
        k: 0,
        n: 1,
        layout: ShardLayout::Interleaved,
    };

    /// Parses `K/N` with `0 <= K < N` (interleaved layout).
    pub fn parse(s: &str) -> Result<Shard, String> {
        let bad = || format!("{s:?}: expected K/N with 0 <= K < N, e.g. 3/8");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let k: u32 = k.trim().parse().map_err(|_| bad())?;
        let n: u32 = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k >= n {
            return Err(bad());
        }
        Ok(Shard {
            k,
            n,
            layout: ShardLayout::Interleaved,
        })
    }

    /// Whether tile `i` of `t` (Morton order) belongs to this shard.
    pub fn owns(&self, i: u64, t: u64) -> bool {
        let (k, n) = (self.k as u64, self.n as u64);
        match self.layout {
            ShardLayout::Interleaved => i % n == k,
            ShardLayout::Blocks => i * n / t.max(1) == k,
        }
    }
}

/// Renders the tiles of `shard` (pixels before colouring, and their
/// counters): one part of a render for [`shard::assemble`].
pub fn render_part(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<shard::Part, RenderError> {
    let cache = policy::cache_for(vol, opts);
    render_part_in(vol, &cache, camera, opts, shard, progress)
}

/// [`render_part`] with a brick cache from [`policy::cache_for`]
/// (with another cache the result is the same, only slower or larger).
pub fn render_part_in(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<shard::Part, RenderError> {
    let t0 = Instant::now();
    check_mode(vol, &opts.mode)?;
    if opts.tile == 0 {
        return Err(RenderError::Option {
            option: "--tile",
            msg: "0, expected at least 1".into(),
        });
    }
    if let Mode::Composite { step_mm, .. } = opts.mode {
        // Samples sit at t = k * step; k must stay far below 2^53.
        if !(step_mm >= MIN_STEP_MM && step_mm.is_finite()) {
            return Err(RenderError::Option {
                option: "--step",
                msg: format!("{step_mm} mm, expected at least {MIN_STEP_MM} mm"),
            });
        }
    }
    check_tol_and_size(opts, camera)?;
    if matches!(opts.method, Method::CdAniso { .. }) && vol.header().aniso_block.is_none() {
        return Err(RenderError::Incompatible {
            path: vol.path().to_path_buf(),
            msg: "--traversal cd-aniso needs anisotropic codes: prepare with `cdvol prep --aniso`"
                .into(),
        });
    }
    if opts.method.needs_regular_grid() {
        if let Some(k) = (0..3).find(|&k| !vol.header().axes[k].is_uniform()) {
            return Err(RenderError::Incompatible {
                path: vol.path().to_path_buf(),
                msg: format!(
                    "--traversal {:?} needs a regular grid, but axis {} has varying spacing: \
                     the DDA steps in cells of one size per axis (use cd or fvt)",
                    opts.method,
                    ["x", "y", "z"][k]
                ),
            });
        }
    }
    if shard.n == 0 || shard.k >= shard.n {
        return Err(RenderError::Option {
            option: "--shard",
            msg: format!("{}/{}, expected K/N with 0 <= K < N", shard.k, shard.n),
        });
    }
    let (w, hgt) = (camera.width, camera.height);
    let results = match opts.precision {
        Precision::F64 => render_tiles::<f64>(vol, cache, camera, opts, shard, progress),
        Precision::F32 => render_tiles::<f32>(vol, cache, camera, opts, shard, progress),
    };

    // Merge counters; keep the tiles' pixels for colouring.
    let mut steps = StepCounts::default();
    let mut cc = CacheCounters::default();
    let mut hits = 0u64;
    let mut rays = 0u64;
    let mut tiles = Vec::with_capacity(results.len());
    for r in results {
        if let Some(e) = r.error {
            return Err(e.into());
        }
        steps.add(&r.steps);
        cc.add(&r.cache);
        hits += r.hits;
        rays += r.pixels.len() as u64;
        tiles.push(shard::TilePx {
            x0: r.x0,
            y0: r.y0,
            w: r.w,
            pixels: r.pixels,
        });
    }
    let mut stats = Stats::counted(rays, hits, &steps, &cc, cache, opts, t0);
    stats.traversal = format!("{:?}", opts.method);
    (stats.width, stats.height) = (w, hgt);
    Ok(shard::Part {
        key: shard::RenderKey::new(vol, camera, opts, shard.n, shard.layout),
        shard,
        tiles,
        stats,
    })
}

/// Renders the tiles of `shard` in the traversal arithmetic `T`.
fn render_tiles<T: Real>(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
    progress: &dyn Progress,
) -> Vec<TileOut> {
    let h = vol.header();
    let grid = TGrid::<T>::new(&h.axes);
    let (w, hgt) = (camera.width, camera.height);
    let ts = opts.tile;
    let (ntx, nty) = (w.div_ceil(ts), hgt.div_ceil(ts));
    // Tiles in Morton (Z) order: rayon hands each thread contiguous runs,
    // which are then compact squares of the image whose rays share bricks.
    let mut tiles: Vec<(u32, u32)> = (0..nty)
        .flat_map(|ty| (0..ntx).map(move |tx| (tx, ty)))
        .collect();
    tiles.sort_by_key(|&(tx, ty)| morton(tx, ty));
    let total = tiles.len() as u64;
    let tiles: Vec<(u32, u32)> = tiles
        .into_iter()
        .enumerate()
        .filter(|(i, _)| shard.owns(*i as u64, total))
        .map(|(_, t)| t)
        .collect();
    let ctx = Ctx {
        grid: &grid,
        coords: [h.axes[0].coords(), h.axes[1].coords(), h.axes[2].coords()],
        camera,
        opts,
        // Mapped like the stored values (see cache::to_f32).
        iso: match h.classification {
            Classification::Iso { iso } => cache::to_f32(iso) as f64,
            _ => f64::NAN,
        },
        lut: match &opts.mode {
            Mode::Composite { tf, step_mm } => Some(lut::TfLut::new(tf, *step_mm)),
            _ => None,
        },
    };
    progress.begin("render tiles", tiles.len() as u64);
    let results = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let r = render_tile(&ctx, cache, tx * ts, ty * ts, ts);
            progress.advance(1);
            r
        })
        .collect();
    progress.end();
    results
}

/// Interleaves the bits of `x` and `y` (Z-order curve).
fn morton(x: u32, y: u32) -> u64 {
    let spread = |v: u32| {
        let mut v = v as u64;
        v = (v | (v << 16)) & 0x0000_ffff_0000_ffff;
        v = (v | (v << 8)) & 0x00ff_00ff_00ff_00ff;
        v = (v | (v << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        (v | (v << 1)) & 0x5555_5555_5555_5555
    };
    spread(x) | (spread(y) << 1)
}

pub fn mode_name(m: &Mode) -> &'static str {
    match m {
        Mode::Surface { .. } => "surface",
        Mode::Mip => "mip",
        Mode::Composite { .. } => "composite",
        Mode::Cost => "cost",
        Mode::Depth { .. } => "depth",
    }
}

struct Ctx<'a, T> {
    grid: &'a TGrid<T>,
    /// Sample positions in f64 for hits and shading.
    coords: [&'a [f64]; 3],
    camera: &'a Camera,
    opts: &'a RenderOptions,
    iso: f64,
    /// The composite mode's transfer function, tabulated for its step.
    lut: Option<lut::TfLut>,
}

struct TileOut {
    x0: u32,
    y0: u32,
    w: u32,
    pixels: Vec<Px>,
    steps: StepCounts,
    cache: CacheCounters,
    hits: u64,
    error: Option<FormatError>,
}

fn render_tile<T: Real>(ctx: &Ctx<T>, cache: &BrickCache, x0: u32, y0: u32, ts: u32) -> TileOut {
    let cam = ctx.camera;
    let w = ts.min(cam.width - x0);
    let hh = ts.min(cam.height - y0);
    let policy = policy::brick_policy(ctx.opts.method, ctx.opts.cd_lazy_min);
    let mut acc = Accessor::for_policy(cache, &policy);
    let mut pixels = Vec::with_capacity((w * hh) as usize);
    let mut steps = StepCounts::default();
    let mut hits = 0;
    for y in y0..y0 + hh {
        for x in x0..x0 + w {
            let ray = cam.ray(x, y);
            let (p, s) = pixel(ctx, &ray, &mut acc);
            steps.add(&s);
            hits += p.hit as u64;
            pixels.push(p);
        }
    }
    TileOut {
        x0,
        y0,
        w,
        pixels,
        steps,
        cache: acc.counters,
        hits,
        error: acc.error.take(),
    }
}

/// The first iso-surface hit along `ray` after `t_min`: `(t, cell values)`.
fn first_hit<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    t_min: f64,
    hit: HitMethod,
    acc: &mut Accessor,
) -> (Option<(f64, CellEval)>, StepCounts) {
    let g = ctx.grid;
    let coords = ctx.coords;
    let mut found = None;
    let s = trace(g, ray, t_min, ctx.opts.method, acc, |v, acc| {
        let c = CellEval::new(coords, v.cell, acc.vertices(v.cell));
        match find_hit_with(ray, v, &c, ctx.iso, hit, &ctx.opts.hit_params) {
            Some(t) => {
                found = Some((t, c));
                Flow::Stop
            }
            None => Flow::Continue,
        }
    });
    (found, s)
}

fn pixel<T: Real>(ctx: &Ctx<T>, ray: &Ray, acc: &mut Accessor) -> (Px, StepCounts) {
    let g = ctx.grid;
    let coords = ctx.coords;
    let mut px = Px {
        depth: f32::NAN,
        ..Px::default()
    };
    let mut counts;
    match &ctx.opts.mode {
        Mode::Surface { hit, shadows } => {
            let (found, s) = first_hit(ctx, ray, 0.0, *hit, acc);
            counts = s;
            if let Some((t, c)) = found {
                px.hit = true;
                let p = at(ray, t);
                let grad = c.gradient(p);
                let to_eye = ray.dir.map(|d| -d);
                let cam = ctx.camera;
                let to_light = if *shadows {
                    // A key light above and to the left of the viewer.
                    shade::normalize(std::array::from_fn(|k| {
                        to_eye[k] + 0.8 * cam.up[k] - 0.6 * cam.right[k]
                    }))
                } else {
                    to_eye
                };
                let mut lit = true;
                if *shadows {
                    // Shadow ray from just outside the surface, traced with
                    // the same traversal, starting inside the volume.
                    let gl = shade::dot(grad, grad).sqrt();
                    let eps = 1e-3 * c.size.iter().cloned().fold(f64::INFINITY, f64::min);
                    let out = if gl > 0.0 {
                        grad.map(|x| -x / gl)
                    } else {
                        to_light
                    };
                    let sign = if shade::dot(out, to_light) >= 0.0 {
                        1.0
                    } else {
                        -1.0
                    };
                    let origin =
                        std::array::from_fn(|k| p[k] + sign * eps * out[k] + eps * to_light[k]);
                    let sray = Ray {
                        origin,
                        dir: to_light,
                    };
                    let (sh, s2) = first_hit(ctx, &sray, 0.0, HitMethod::Int, acc);
                    counts.add(&s2);
                    lit = sh.is_none();
                }
                let v = shade(grad, to_light, to_eye, lit) as f32;
                px.rgb = [v, v, v];
                px.depth = t as f32;
            }
        }
        Mode::Depth { hit } => {
            let (found, s) = first_hit(ctx, ray, 0.0, *hit, acc);
            counts = s;
            if let Some((t, _)) = found {
                px.hit = true;
                px.depth = t as f32;
            }
        }
        Mode::Mip => {
            let mut best = f64::NEG_INFINITY;
            counts = trace(g, ray, 0.0, ctx.opts.method, acc, |v, acc| {
                let f = acc.vertices(v.cell);
                // The interpolant never exceeds the largest vertex value
                // (NaN vertices give NaN, which max ignores): a cell whose
                // vertices are all <= best cannot raise it.
                let top = f.iter().fold(f32::NEG_INFINITY, |m, &x| m.max(x));
                if top as f64 <= best {
                    return Flow::Continue;
                }
                let c = CellEval::new(coords, v.cell, f);
                best = best
                    .max(c.value(at(ray, v.t_enter)))
                    .max(c.value(at(ray, v.t_exit)));
                Flow::Continue
            });
            if best > f64::NEG_INFINITY {
                px.hit = true;
                px.rgb = [best as f32; 3];
            }
        }
        Mode::Cost => {
            // Steps needed to find the surface, or to leave the volume on a
            // miss (paper Fig. 17); on files classified by a transfer
            // function, steps to the first 1-cell.
            if ctx.iso.is_nan() {
                counts = trace(g, ray, 0.0, ctx.opts.method, acc, |_, _| Flow::Stop);
            } else {
                let (found, s) = first_hit(ctx, ray, 0.0, HitMethod::Int, acc);
                counts = s;
                px.hit = found.is_some();
            }
        }
        Mode::Composite { step_mm, .. } => {
            let lut = ctx.lut.as_ref().expect("composite renders carry a table");
            let step = *step_mm;
            let inv_step = 1.0 / step;
            let mut col = [0.0f64; 3];
            let mut alpha = 0.0f64;
            counts = trace(g, ray, 0.0, ctx.opts.method, acc, |v, acc| {
                // Samples at t = k * step inside [t_enter, t_exit); a cell
                // the ray only clips between two samples is not read.
                let mut k = first_sample(v.t_enter, step, inv_step);
                if !(k * step < v.t_exit) {
                    return Flow::Continue;
                }
                let c = AlongRay::new(coords, v.cell, acc.vertices(v.cell), ray);
                while k * step < v.t_exit {
                    let val = c.value(k * step);
                    let [r, gr, b, a] = lut.sample(val);
                    k += 1.0;
                    if a == 0.0 {
                        // Transparent: adds nothing.
                        continue;
                    }
                    let w = 1.0 - alpha;
                    col[0] += w * r;
                    col[1] += w * gr;
                    col[2] += w * b;
                    alpha += w * a;
                    if alpha > 0.99 {
                        return Flow::Stop;
                    }
                }
                Flow::Continue
            });
            px.hit = alpha > 0.0;
            px.rgb = col.map(|x| x as f32);
        }
    }
    px.steps = counts.steps.min(u32::MAX as u64) as u32;
    (px, counts)
}

/// `ceil(t / step)`, the first composite sample at or after `t`, with a
/// multiplication by `inv_step = 1 / step` instead of the division where
/// that cannot change the result: the two quotients differ by a few ulps,
/// so only when `t / step` is within 1e-12 (relative) of an integer does
/// the division decide.
#[inline]
fn first_sample(t: f64, step: f64, inv_step: f64) -> f64 {
    let q = t * inv_step;
    let k = ceil(q);
    // Distance to the nearest integer (no libm `round`).
    if (k - q).min(q - (k - 1.0)) <= 1e-12 * q.abs().max(1.0) {
        ceil(t / step)
    } else {
        k
    }
}

/// `x.ceil()` without a libm call (the default x86-64 target has no
/// rounding instruction); the same value for every `x`.
#[inline]
fn ceil(x: f64) -> f64 {
    const BIG: f64 = (1u64 << 52) as f64;
    if x.abs() < BIG {
        // |x| < 2^52: truncation is exact in i64, and so is adding 1.
        let t = x as i64 as f64;
        if t < x {
            t + 1.0
        } else {
            t
        }
    } else {
        // Already an integer, infinite or NaN.
        x
    }
}

/// The value range MIP maps to black..white: the file's rescaled raw range.
fn mip_range(vol: &PackedVolume) -> [f64; 2] {
    let s = &vol.header().summary;
    let rs = vol.header().rescale;
    let (a, b) = (
        rs.apply(s.raw_min.unwrap_or(0.0)),
        rs.apply(s.raw_max.unwrap_or(1.0)),
    );
    [a.min(b), a.max(b)]
}

fn colour(kind: &shard::Colouring, w: u32, h: u32, px: &[Px]) -> Frame {
    use shard::Colouring;
    let n = (w * h) as usize;
    let mut rgb = vec![0u8; 3 * n];
    let to8 = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    let mut depth = None;
    match kind {
        Colouring::Rgb => {
            for (i, p) in px.iter().enumerate() {
                for k in 0..3 {
                    rgb[3 * i + k] = to8(p.rgb[k]);
                }
            }
        }
        Colouring::Mip { lo, hi } => {
            let (lo, hi) = (*lo, *hi);
            for (i, p) in px.iter().enumerate() {
                let g = if p.hit {
                    ((p.rgb[0] as f64 - lo) / (hi - lo).max(1e-300)) as f32
                } else {
                    0.0
                };
                rgb[3 * i..3 * i + 3].fill(to8(g));
            }
        }
        Colouring::Cost => {
            let max = px.iter().map(|p| p.steps).max().unwrap_or(1).max(1) as f32;
            for (i, p) in px.iter().enumerate() {
                let c = heat(p.steps as f32 / max);
                rgb[3 * i..3 * i + 3].copy_from_slice(&c);
            }
        }
        Colouring::Depth => {
            let d: Vec<f32> = px.iter().map(|p| p.depth).collect();
            let (lo, hi) = d
                .iter()
                .filter(|x| x.is_finite())
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            for (i, &x) in d.iter().enumerate() {
                let g = if x.is_finite() {
                    1.0 - (x - lo) / (hi - lo).max(1e-30) * 0.9
                } else {
                    0.0
                };
                rgb[3 * i..3 * i + 3].fill(to8(g));
            }
            depth = Some(d);
        }
    }
    Frame {
        width: w,
        height: h,
        rgb,
        depth,
        steps: px.iter().map(|p| p.steps).collect(),
    }
}

/// Black -> purple -> orange -> yellow-white heat map.
fn heat(x: f32) -> [u8; 3] {
    let stops: [(f32, [f32; 3]); 4] = [
        (0.0, [0.0, 0.0, 0.0]),
        (0.35, [0.45, 0.05, 0.55]),
        (0.7, [0.95, 0.45, 0.1]),
        (1.0, [1.0, 1.0, 0.75]),
    ];
    let x = x.clamp(0.0, 1.0);
    let i = stops.iter().position(|s| s.0 >= x).unwrap_or(3).max(1);
    let (a, b) = (stops[i - 1], stops[i]);
    let f = (x - a.0) / (b.0 - a.0);
    std::array::from_fn(|k| ((a.1[k] + f * (b.1[k] - a.1[k])) * 255.0).round() as u8)
}

/// Writes `bytes` to `target` through a temporary file beside it, renamed
/// when complete.
pub fn write_atomic(target: &std::path::Path, bytes: &[u8]) -> Result<(), String> {
    let dir = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let tmp = tempfile::Builder::new()
        .prefix(".cdvol-partial-")
        .tempfile_in(&dir)
        .map_err(|e| format!("{}: cannot create a temporary file: {e}", target.display()))?;
    std::fs::write(tmp.path(), bytes).map_err(|e| format!("{}: {e}", target.display()))?;
    tmp.persist(target)
        .map_err(|e| format!("{}: {}", target.display(), e.error))?;
    Ok(())
}

/// Writes `frame` as PNG to `path` (temporary file beside it, renamed when
/// complete); the depth mode also writes `path` with `.f32` (raw
/// little-endian f32, NaN = miss) and a 16-bit PNG `*.depth16.png`.
pub fn save(frame: &Frame, path: &std::path::Path) -> Result<Vec<std::path::PathBuf>, String> {
    let write = write_atomic;
    let png = |img: image::DynamicImage| -> Result<Vec<u8>, String> {
        let mut buf = std::io::Cursor::new(Vec::new());
        img.write_to(&mut buf, image::ImageFormat::Png)
            .map_err(|e| e.to_string())?;
        Ok(buf.into_inner())
    };
    if frame.depth.is_some() && path.extension().is_some_and(|e| e == "f32") {
        return Err(format!(
            "{}: the depth mode writes its raw f32 beside the PNG with the extension .f32; \
             use a .png name",
            path.display()
        ));
    }
    let rgb = image::RgbImage::from_raw(frame.width, frame.height, frame.rgb.clone())
        .ok_or("image size does not match its pixels")?;
    write(path, &png(image::DynamicImage::ImageRgb8(rgb))?)?;
    let mut out = vec![path.to_path_buf()];
    if let Some(d) = &frame.depth {
        let raw: Vec<u8> = d.iter().flat_map(|x| x.to_le_bytes()).collect();
        let f32_path = path.with_extension("f32");
        write(&f32_path, &raw)?;
        let (lo, hi) = d
            .iter()
            .filter(|x| x.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let px16: Vec<u16> = d
            .iter()
            .map(|&x| {
                if x.is_finite() {
                    1 + ((x - lo) / (hi - lo).max(1e-30) * 65534.0) as u16
                } else {
                    0
                }
            })
            .collect();
        let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
            frame.width,
            frame.height,
            px16,
        )
        .ok_or("depth size does not match")?;
        let p16 = path.with_extension("depth16.png");
        write(&p16, &png(image::DynamicImage::ImageLuma16(img))?)?;
        out.push(f32_path);
        out.push(p16);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::{ceil, first_sample};

    #[test]
    fn ceil_and_first_sample_match_the_division() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e15,
            4503599627370495.5,
            1e300,
        ] {
            assert_eq!(ceil(x), x.ceil(), "{x}");
        }
        assert!(ceil(f64::NAN).is_nan());
        assert_eq!(ceil(f64::INFINITY), f64::INFINITY);
        // Entry points on, next to and between sample positions.
        for step in [0.5, 0.3, 0.7, 1.3, 1e-4, 0.1] {
            let inv = 1.0 / step;
            for i in 0..20_000 {
                let k = i as f64;
                for t in [
                    k * step,
                    (k * step).next_up(),
                    (k * step).next_down(),
                    (k + 0.5) * step,
                ] {
                    assert_eq!(
                        first_sample(t, step, inv),
                        (t / step).ceil(),
                        "{t} / {step}"
                    );
                }
            }
        }
    }
}
