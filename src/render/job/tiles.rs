//! Tile scheduling: the image is cut into `opts.tile`-pixel squares,
//! taken in Morton (Z) order so that rayon hands each thread compact runs
//! whose rays share bricks; a [`Shard`] selects some of them. Each tile is
//! one rayon task with its own [`Accessor`] in front of the shared
//! [`BrickCache`], and each pixel is computed on its own (integrate/), so
//! the output is the same whatever the thread count, tile size or cache
//! budget. Each tile colours its pixels as it finishes when the colours
//! do not depend on the whole image (output/canvas.rs); otherwise, and for the
//! parts of a sharded render, the tiles are placed and coloured together
//! (output/colour.rs).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use crate::format::reader::PackedVolume;
use crate::format::FormatError;
use crate::progress::Progress;
use crate::render::cache::{Accessor, BrickCache, CacheCounters};
use crate::render::clock::{self, KernelUse, TileTime};
use crate::render::error::RenderError;
use crate::render::integrate::{over, pixel_until, Ctx, Px};
use crate::render::options::{check_render, Precision, RenderOptions};
use crate::render::output::canvas::{Canvas, Planes};
use crate::render::output::colour::{colour_blocks, Colouring, PxBlock};
use crate::render::output::Frame;
use crate::render::stats::Stats;
use crate::render::traverse::{Real, StepCounts, TGrid};
use crate::render::view::camera::Camera;
use crate::render::view::cull::Cover;

/// Renders `vol` as seen by `camera`: every tile, then the colouring
/// [`shard::assemble`](super::shard::assemble) uses too, so a sharded
/// render assembles to the same bytes.
pub fn render(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<(Frame, Stats), RenderError> {
    render_in(
        vol,
        &crate::render::cache_for(vol, opts),
        camera,
        opts,
        progress,
    )
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
    let done = render_whole(vol, cache, camera, opts, progress, None)?;
    Ok(done.expect("a render without a stop flag is never stopped"))
}

/// A whole render's frame and counters, with the render's time and kernel
/// use; `None` when `stop` was set. The tiles colour their own pixels
/// when the colouring allows it ([`Planes`]); otherwise they are coloured
/// together ([`finish`]).
fn render_whole(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    progress: &dyn Progress,
    stop: Option<&AtomicBool>,
) -> Result<Option<(Frame, Stats)>, RenderError> {
    let (t0, k0) = (Instant::now(), KernelUse::now());
    check_shard(vol, camera, opts, Shard::WHOLE)?;
    let colouring = Colouring::of(vol, opts);
    let (w, h) = (camera.width, camera.height);
    let mut planes = Planes::new(&colouring, w, h, opts.unrounded);
    let canvas = planes.as_mut().map(|p| p.canvas(opts.tile));
    let tiles = render_checked(&TileJob {
        vol,
        cache,
        camera,
        opts,
        shard: Shard::WHOLE,
        progress,
        stop,
        canvas: canvas.as_ref(),
        under: None,
    });
    drop(canvas);
    let (tiles, stats) = tiles?;
    if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
        return Ok(None);
    }
    let (frame, mut stats) = match planes {
        // The tiles' pixels are in the planes already.
        Some(p) => (p.into_frame(), stats),
        None => finish(&colouring, w, h, tiles, stats, opts.unrounded),
    };
    stats.rays = w as u64 * h as u64;
    stats.seconds_total = t0.elapsed().as_secs_f64();
    stats.set_kernel(k0);
    Ok(Some((frame, stats)))
}

/// [`render_in`] that gives up when `stop` is set: tiles not yet started
/// are skipped (a tile in flight finishes), and the render returns `None`
/// instead of a frame. For `cdvol serve`, where a newer request makes an
/// older one's frame worthless. A render that is not stopped returns the
/// same frame and counters as [`render_in`].
pub fn render_in_until(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<Option<(Frame, Stats)>, RenderError> {
    render_whole(vol, cache, camera, opts, progress, Some(stop))
}

/// Renders the tiles of `shard` after checking the options: their pixels
/// before colouring, and the summed counters (`width` and `height` set).
/// The common core of [`render_in`] and
/// [`render_part_in`](super::shard::render_part_in).
pub(crate) fn render_shard(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<(Vec<TilePx>, Stats), RenderError> {
    check_shard(vol, camera, opts, shard)?;
    render_checked(&TileJob {
        vol,
        cache,
        camera,
        opts,
        shard,
        progress,
        stop: None,
        canvas: None,
        under: None,
    })
}

/// What the tiles of one render need: the file and its cache, the view
/// and options, which tiles ([`Shard`]), progress, a flag that skips the
/// tiles not yet started once set, and where the tiles colour their
/// pixels (none: they return them).
struct TileJob<'a, 'c> {
    vol: &'a PackedVolume,
    cache: &'a BrickCache,
    camera: &'a Camera,
    opts: &'a RenderOptions,
    shard: Shard,
    progress: &'a dyn Progress,
    stop: Option<&'a AtomicBool>,
    canvas: Option<&'a Canvas<'c>>,
    /// The overlay's label pixels of the whole image, row by row, which
    /// this render's pixels end at and are drawn over
    /// ([`RenderOptions::overlay`]).
    under: Option<&'a [Px]>,
}

/// Checks the options ([`check_render`]) and the shard.
fn check_shard(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
) -> Result<(), RenderError> {
    check_render(vol, [camera.width, camera.height], opts)?;
    if shard.n == 0 || shard.k >= shard.n {
        return Err(RenderError::Option {
            field: "shard",
            value: format!("{}/{}", shard.k, shard.n),
            expected: "K/N with 0 <= K < N".into(),
        });
    }
    Ok(())
}

/// The tiles of `job` after [`check_shard`]: their pixels (none where
/// they coloured them into the job's canvas) and the summed counters.
fn render_checked(job: &TileJob) -> Result<(Vec<TilePx>, Stats), RenderError> {
    let (t0, k0) = (Instant::now(), KernelUse::now());
    let (cache, opts) = (job.cache, job.opts);
    let (w, hgt) = (job.camera.width, job.camera.height);
    // An overlay's labels first, in the same tiles: the scan's rays then
    // end at them.
    let (under, label_stats) = match &opts.overlay {
        Some(ov) if job.under.is_none() => {
            let (px, s) = overlay_pixels(job, ov)?;
            (Some(px), Some(s))
        }
        _ => (None, None),
    };
    let with_under = TileJob {
        under: under.as_deref().or(job.under),
        canvas: job.canvas,
        ..*job
    };
    let results = match opts.precision {
        Precision::F64 => render_tiles::<f64>(&with_under),
        Precision::F32 => render_tiles::<f32>(&with_under),
    };

    // Merge counters; keep the tiles' pixels for colouring.
    let mut steps = StepCounts::default();
    let mut cc = CacheCounters::default();
    let mut hits = 0u64;
    let mut rays = 0u64;
    let mut culled = 0u64;
    let mut tiles = Vec::with_capacity(results.len());
    let mut times = Vec::with_capacity(results.len());
    for r in results {
        if let Some(e) = r.error {
            return Err(e.into());
        }
        steps.add(&r.steps);
        cc.add(&r.cache);
        hits += r.hits;
        culled += r.culled;
        rays += r.w as u64 * r.h as u64;
        times.push(r.time);
        tiles.push(TilePx {
            x0: r.x0,
            y0: r.y0,
            w: r.w,
            h: r.h,
            pixels: r.pixels,
        });
    }
    if let Some(ls) = &label_stats {
        // The labels' walks are part of this render's work.
        steps.steps += ls.steps;
        steps.macro_steps += ls.macro_steps;
        steps.cell_steps += ls.cell_steps;
    }
    let mut stats = Stats::counted(rays, hits, &steps, &cc, cache, opts, t0);
    (stats.width, stats.height) = (w, hgt);
    stats.camera = Some(job.camera.used());
    stats.rays_culled = culled;
    stats.set_kernel(k0);
    (
        stats.seconds_tiles,
        stats.seconds_traverse,
        stats.seconds_sample,
    ) = clock::split(&times, cc.decode_seconds);
    Ok((tiles, stats))
}

/// The label pixels of `job`'s overlay over the whole image (misses
/// outside the job's shard), rendered in the job's tiles with the label
/// file's own cache (kept from frame to frame) and the job's clip, and
/// that pass's counters.
fn overlay_pixels(
    job: &TileJob,
    ov: &crate::render::options::Overlay,
) -> Result<(Vec<Px>, Stats), RenderError> {
    let lopts = ov.options(job.opts);
    let vol: &PackedVolume = &ov.vol;
    check_render(vol, [job.camera.width, job.camera.height], &lopts)?;
    let (tiles, stats) = render_checked(&TileJob {
        vol,
        cache: &ov.cache,
        camera: job.camera,
        opts: &lopts,
        shard: job.shard,
        progress: job.progress,
        stop: job.stop,
        canvas: None,
        under: None,
    })?;
    let w = job.camera.width as usize;
    let mut px = vec![Px::MISS; w * job.camera.height as usize];
    for t in &tiles {
        for (i, p) in t.px().enumerate() {
            let (x, y) = (
                t.x0 as usize + i % t.w as usize,
                t.y0 as usize + i / t.w as usize,
            );
            px[y * w + x] = *p;
        }
    }
    Ok((px, stats))
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
    pub fn parse(s: &str) -> Result<Shard, ShardParseError> {
        let bad = || ShardParseError {
            found: s.to_string(),
        };
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

/// A `--shard`-style `K/N` that is not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("shard {found:?}, expected K/N with 0 <= K < N, e.g. 3/8")]
pub struct ShardParseError {
    /// The text given.
    pub found: String,
}

/// One tile's pixels before colouring, row by row.
#[derive(Debug, Clone, PartialEq)]
pub struct TilePx {
    pub x0: u32,
    pub y0: u32,
    pub w: u32,
    /// Rows.
    pub h: u32,
    /// The `w * h` pixels row by row, or none when every pixel is a miss
    /// ([`Px::MISS`]): a tile the cover leaves out whole (render/view/cull.rs)
    /// is neither written nor coloured pixel by pixel.
    pub(crate) pixels: Vec<Px>,
}

impl TilePx {
    /// The distance in mm along its ray of each pixel's first hit (NaN
    /// on a miss), row by row: what a part file stores, before colouring.
    pub fn depths(&self) -> Vec<f32> {
        self.px().map(|p| p.depth).collect()
    }

    /// Each pixel's coverage in [0, 1] (the composite's or the labels'
    /// opacity, 1 on a surface hit), row by row.
    pub fn coverage(&self) -> Vec<f32> {
        self.px().map(|p| p.alpha).collect()
    }

    /// The `w * h` pixels row by row, a left-out tile's as misses.
    pub(crate) fn px(&self) -> impl Iterator<Item = &Px> {
        let missing = if self.pixels.is_empty() {
            self.w as usize * self.h as usize
        } else {
            0
        };
        self.pixels
            .iter()
            .chain(std::iter::repeat_n(&Px::MISS, missing))
    }
}

/// Colours the tiles as one `w` x `h` image; `stats` are the summed
/// counters. Shared by [`render_in`] and
/// [`shard::assemble`](super::shard::assemble). The tiles are coloured
/// where they are, in parallel by rows ([`colour_blocks`]), so a render
/// holds one copy of the pixels (the tiles) besides the image, and the
/// colouring is not a serial tail of every frame (docs/BENCHMARKS.md,
/// "Colouring: no serial tail"). `unrounded`: whether the frame keeps
/// [`Frame::linear`].
pub(crate) fn finish<T: std::borrow::Borrow<TilePx>>(
    colouring: &Colouring,
    w: u32,
    h: u32,
    tiles: impl IntoIterator<Item = T>,
    mut stats: Stats,
    unrounded: bool,
) -> (Frame, Stats) {
    let tiles: Vec<T> = tiles.into_iter().collect();
    let blocks: Vec<PxBlock> = tiles
        .iter()
        .map(|t| {
            let t = t.borrow();
            PxBlock {
                x0: t.x0,
                y0: t.y0,
                w: t.w,
                h: t.h,
                pixels: &t.pixels,
            }
        })
        .collect();
    let frame = colour_blocks(colouring, w, h, &blocks, unrounded);
    stats.rays = w as u64 * h as u64;
    (frame, stats)
}

/// Renders the tiles of `job` in the traversal arithmetic `T`.
fn render_tiles<T: Real>(job: &TileJob) -> Vec<TileOut> {
    let (vol, cache, camera, opts) = (job.vol, job.cache, job.camera, job.opts);
    let (progress, stop) = (job.progress, job.stop);
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
        .filter(|(i, _)| job.shard.owns(*i as u64, total))
        .map(|(_, t)| t)
        .collect();
    let ctx = Ctx::new(&grid, h, camera, opts);
    let cover = crate::render::view::cull::Cover::of(vol, cache, camera, opts);
    progress.begin("render tiles", tiles.len() as u64);
    // One tile per rayon leaf. rayon splits an indexed range adaptively:
    // a few halvings up front and more only when a thread steals, and a
    // leaf runs sequentially, beyond stealing. The tiles' costs differ
    // by orders of magnitude (empty air against the middle of a head), so
    // one thread ended a 2-thread composite with a quarter of the frame
    // left in its leaf while the other waited (docs/BENCHMARKS.md,
    // "Tiles: one per rayon leaf"). With single-tile leaves every tile
    // not yet started can be stolen; each steal still takes half of what
    // is left, a contiguous run of the Morton order.
    let results = tiles
        .par_iter()
        .with_max_len(1)
        .map(|&(tx, ty)| {
            if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
                return TileOut::skipped(tx * ts, ty * ts);
            }
            let r = render_tile(
                &ctx,
                cover.as_ref(),
                job.canvas,
                job.under,
                cache,
                tx * ts,
                ty * ts,
                ts,
            );
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

/// One tile's pixels and counters, as a rayon task returns them.
struct TileOut {
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    /// As [`TilePx::pixels`]: none when the cover leaves the tile out.
    pixels: Vec<Px>,
    steps: StepCounts,
    cache: CacheCounters,
    hits: u64,
    /// Pixels left untraced (render/view/cull.rs).
    culled: u64,
    time: TileTime,
    error: Option<FormatError>,
}

impl TileOut {
    /// A tile left out of a stopped render: no pixels, no counts.
    fn skipped(x0: u32, y0: u32) -> TileOut {
        TileOut {
            x0,
            y0,
            w: 1,
            h: 0,
            pixels: Vec::new(),
            steps: StepCounts::default(),
            cache: CacheCounters::default(),
            hits: 0,
            culled: 0,
            time: TileTime::default(),
            error: None,
        }
    }
}

/// Renders the tile at `(x0, y0)`, at most `ts` pixels square, with one
/// accessor in front of the shared cache; a pixel `cover` leaves out is a
/// miss without a ray (render/view/cull.rs), and a tile it leaves out whole
/// has no pixels to write. With a `canvas` the tile colours its pixels
/// into it and returns none.
#[allow(clippy::too_many_arguments)]
fn render_tile<T: Real>(
    ctx: &Ctx<T>,
    cover: Option<&Cover>,
    canvas: Option<&Canvas>,
    under: Option<&[Px]>,
    cache: &BrickCache,
    x0: u32,
    y0: u32,
    ts: u32,
) -> TileOut {
    let cam = ctx.camera;
    let w = ts.min(cam.width - x0);
    let hh = ts.min(cam.height - y0);
    if under.is_none() && cover.is_some_and(|c| !c.any_in(x0, y0, w, hh)) {
        return TileOut {
            w,
            h: hh,
            culled: w as u64 * hh as u64,
            ..TileOut::skipped(x0, y0)
        };
    }
    let policy = crate::render::brick_policy(ctx.opts.method, ctx.lazy_min);
    let mut acc = Accessor::for_policy(cache, &policy);
    acc.remember_gradients(ctx.memo_gradients);
    let mut pixels = Vec::with_capacity((w * hh) as usize);
    let mut steps = StepCounts::default();
    let mut hits = 0;
    let mut culled = 0;
    clock::start_tile();
    // An exact traversal visits the same 1-cells from the cover's start as
    // from the volume's entry; the others' walks depend on where they
    // start, so they start at the entry.
    let exact = ctx.opts.method.is_exact();
    for y in y0..y0 + hh {
        for x in x0..x0 + w {
            // The overlay's labels at this pixel, if any.
            let back = under.map_or(Px::MISS, |u| u[(y * cam.width + x) as usize]);
            if cover.is_some_and(|c| !c.covered(x, y)) {
                culled += 1;
                hits += back.hit as u64;
                pixels.push(back);
                continue;
            }
            let ray = cam.ray(x, y);
            clock::begin_ray(pixels.len() as u32, &acc);
            let t0 = match cover {
                Some(c) if exact => c.start(x, y),
                _ => 0.0,
            };
            let t_end = if back.hit {
                back.depth as f64
            } else {
                f64::INFINITY
            };
            let (p, s) = pixel_until(ctx, &ray, t0, t_end, &mut acc);
            let p = over(p, back);
            clock::end_ray(&acc);
            steps.add(&s);
            hits += p.hit as u64;
            pixels.push(p);
        }
    }
    if let Some(c) = canvas {
        c.paint(x0, y0, w, &pixels);
        pixels = Vec::new();
    }
    TileOut {
        time: clock::stop_tile(),
        x0,
        y0,
        w,
        h: hh,
        pixels,
        steps,
        cache: acc.counters,
        hits,
        culled,
        error: acc.error.take(),
    }
}
