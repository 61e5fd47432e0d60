//! Colouring, the step between the integrators and the image file: a
//! mode's [`Colouring`] turns the pixels (from the tiles of a render or
//! from part files) into a [`Frame`]. A single-process render and an
//! assembled sharded one colour their tiles through the same
//! [`colour_blocks`] (in parallel by rows, without gathering the pixels
//! first), so their bytes are the same.

use serde::{Deserialize, Serialize};

use super::Frame;
use crate::format::reader::PackedVolume;
use crate::render::integrate::Px;
use crate::render::options::{Mode, RenderOptions, Window};

/// How pixels become colours: the only part of the mode colouring needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Colouring {
    /// Surface and composite: the pixel's colour as it is.
    Rgb,
    /// Grey from `lo` to `hi`; `None` for the automatic window
    /// (`auto_window`).
    Mip { window: Option<[f64; 2]> },
    /// Heat map scaled to the largest step count of the whole image.
    Cost,
    /// Grey scaled to the depth range of the whole image.
    Depth,
}

impl Colouring {
    /// The colouring of a render of `vol` with `opts` (MIP: `opts.window`).
    pub fn of(vol: &PackedVolume, opts: &RenderOptions) -> Colouring {
        match opts.mode {
            Mode::Surface { .. } | Mode::Composite { .. } | Mode::Labels { .. } => Colouring::Rgb,
            Mode::Mip => Colouring::Mip {
                window: match opts.window {
                    Window::Auto => None,
                    Window::Full => Some(value_range(vol)),
                    Window::Fixed { width, level } => {
                        Some([level - 0.5 * width, level + 0.5 * width])
                    }
                },
            },
            Mode::Cost => Colouring::Cost,
            Mode::Depth { .. } => Colouring::Depth,
        }
    }

    /// Whether a whole render's tiles colour their own pixels with this
    /// colouring ([`Planes`](super::canvas::Planes)): its scale does not
    /// depend on the image.
    pub(crate) fn paints(&self) -> bool {
        self.fixed_scale().is_some()
    }

    /// The scale when it does not depend on the image: colours as they
    /// are, or a MIP's given window ([`Planes`](super::canvas::Planes)).
    pub(super) fn fixed_scale(&self) -> Option<Scale> {
        match *self {
            Colouring::Rgb => Some(Scale::Rgb),
            Colouring::Mip {
                window: Some([lo, hi]),
            } => Some(Scale::Mip { lo, hi }),
            Colouring::Mip { window: None } | Colouring::Cost | Colouring::Depth => None,
        }
    }
}

/// The file's rescaled raw range ([`Window::Full`]).
pub fn value_range(vol: &PackedVolume) -> [f64; 2] {
    let s = &vol.header().summary;
    let rs = vol.header().rescale;
    let (a, b) = (
        rs.apply(s.raw_min.unwrap_or(0.0)),
        rs.apply(s.raw_max.unwrap_or(1.0)),
    );
    [a.min(b), a.max(b)]
}

/// Percentiles of the automatic MIP window: the values the rays meet,
/// from the 1st to the 99.9th percentile, map to black..white (robust
/// against a few metal or air pixels, unlike the raw range).
pub const AUTO_WINDOW_PERCENTILES: [f64; 2] = [0.01, 0.999];

/// The automatic MIP window of an image: the [`AUTO_WINDOW_PERCENTILES`]
/// of its hit pixels' values `v` (the maxima the rays met, in any order;
/// the caller leaves NaN out), `[0, 1]` when no ray hit; never an empty
/// range. The values at the percentiles' ranks are found by selection,
/// not a sort.
pub fn auto_window(mut v: Vec<f32>) -> [f64; 2] {
    debug_assert!(v.iter().all(|x| !x.is_nan()), "NaN in the window's values");
    if v.is_empty() {
        return [0.0, 1.0];
    }
    let rank = |q: f64| ((v.len() - 1) as f64 * q).round() as usize;
    let (i, j) = (
        rank(AUTO_WINDOW_PERCENTILES[0]),
        rank(AUTO_WINDOW_PERCENTILES[1]),
    );
    // In the total order every rank holds one value (bits and all), so
    // selection gives exactly what a sort would.
    let (_, &mut lo, above) = v.select_nth_unstable_by(i, f32::total_cmp);
    let hi = if j > i {
        *above.select_nth_unstable_by(j - i - 1, f32::total_cmp).1
    } else {
        lo
    };
    let (lo, hi) = (lo as f64, hi as f64);
    if hi > lo {
        [lo, hi]
    } else {
        [lo - 0.5, lo + 0.5]
    }
}

/// A rectangle of an image's pixels before colouring: `h` rows of `w`
/// pixels whose first pixel is at `(x0, y0)` (a tile, or a whole image).
/// `pixels` holds them row by row, or is empty when every one is
/// [`Px::MISS`] (a tile the cover leaves out whole,
/// [`TilePx`](crate::render::TilePx)).
#[derive(Clone, Copy)]
pub(crate) struct PxBlock<'a> {
    pub(crate) x0: u32,
    pub(crate) y0: u32,
    pub(crate) w: u32,
    pub(crate) h: u32,
    pub(crate) pixels: &'a [Px],
}

impl PxBlock<'_> {
    /// Pixels left out of `pixels` as misses.
    fn misses(&self) -> usize {
        match self.pixels.is_empty() {
            true => self.w as usize * self.h as usize,
            false => 0,
        }
    }
}

/// What colouring a pixel needs from the whole image.
#[derive(Clone, Copy)]
pub(super) enum Scale {
    Rgb,
    Mip { lo: f64, hi: f64 },
    Cost { max: f32 },
    Depth { lo: f32, hi: f32 },
}

/// The blocks of an image, by row: the blocks of each band of rows that
/// start at the same `y0`, in `x0` order.
struct Rows<'a> {
    w: u32,
    blocks: Vec<PxBlock<'a>>,
    /// `(y0, range of blocks)`, by `y0`.
    bands: Vec<(u32, std::ops::Range<usize>)>,
}

impl<'a> Rows<'a> {
    fn new(w: u32, blocks: &[PxBlock<'a>]) -> Rows<'a> {
        debug_assert!(
            blocks.iter().all(|b| b.w == 0
                || ((b.pixels.is_empty() || b.pixels.len() == b.w as usize * b.h as usize)
                    && b.x0 as u64 + b.w as u64 <= w as u64)),
            "blocks must hold whole rows inside the image"
        );
        let mut blocks: Vec<PxBlock> = blocks
            .iter()
            .copied()
            .filter(|b| b.w > 0 && b.h > 0)
            .collect();
        blocks.sort_by_key(|b| (b.y0, b.x0));
        let mut bands: Vec<(u32, std::ops::Range<usize>)> = Vec::new();
        for (i, b) in blocks.iter().enumerate() {
            match bands.last_mut() {
                Some((y0, r)) if *y0 == b.y0 => r.end = i + 1,
                _ => bands.push((b.y0, i..i + 1)),
            }
        }
        Rows { w, blocks, bands }
    }

    /// Whether some pixel of the image is in no block (it colours as
    /// [`Px::default`]).
    fn has_gaps(&self, h: u32) -> bool {
        let mut covered = 0u64;
        for b in &self.blocks {
            let rows = b.h as u64;
            let cols = (b.x0.saturating_add(b.w)).min(self.w).saturating_sub(b.x0) as u64;
            covered += rows.min(h.saturating_sub(b.y0) as u64) * cols;
        }
        covered < self.w as u64 * h as u64
    }

    /// Calls `f(x, pixel)` for every pixel of row `y`, left to right
    /// ([`Px::default`] where no block covers it), but for the misses of
    /// blocks without pixels when `skip_left_out`.
    #[inline]
    fn each(&self, y: u32, skip_left_out: bool, mut f: impl FnMut(usize, &Px)) {
        let empty = Px::default();
        let mut x = 0u32;
        let band = self.bands.partition_point(|(y0, _)| *y0 <= y);
        if band > 0 {
            let (y0, r) = &self.bands[band - 1];
            let ly = (y - y0) as usize;
            for b in &self.blocks[r.clone()] {
                let bw = b.w as usize;
                if ly >= b.h as usize {
                    continue;
                }
                let row = match b.pixels.is_empty() {
                    true => None,
                    false => match b.pixels.get(ly * bw..(ly + 1) * bw) {
                        Some(row) => Some(row),
                        None => continue,
                    },
                };
                while x < b.x0.min(self.w) {
                    f(x as usize, &empty);
                    x += 1;
                }
                let xs = b.x0 as usize..(b.x0 as usize + bw).min(self.w as usize);
                match row {
                    Some(row) => xs.zip(row).for_each(|(px, p)| f(px, p)),
                    None if skip_left_out => {}
                    None => xs.for_each(|px| f(px, &Px::MISS)),
                }
                x = x.max(b.x0.saturating_add(b.w).min(self.w));
            }
        }
        while x < self.w {
            f(x as usize, &empty);
            x += 1;
        }
    }
}

/// Colours the pixels `px` of a `w` x `h` image ([`colour_blocks`]).
pub(crate) fn colour(kind: &Colouring, w: u32, h: u32, px: &[Px], unrounded: bool) -> Frame {
    let whole = PxBlock {
        x0: 0,
        y0: 0,
        w,
        h: px.len().checked_div(w as usize).unwrap_or(0) as u32,
        pixels: px,
    };
    colour_blocks(kind, w, h, &[whole], unrounded)
}

/// Colours a `w` x `h` image whose pixels are in `blocks` (tiles, as they
/// come from the renderer or from part files), row by row in parallel and
/// without gathering the pixels into one buffer first. A pixel no block
/// covers colours as [`Px::default`]. The same bytes as colouring the
/// gathered image (test `colour_blocks_equals_the_sequential_colouring`)
/// when the blocks are what every caller gives: tiles of one grid (rows
/// of blocks share their `y0` and height), disjoint, inside the image,
/// each holding whole rows. Overlapping or ragged blocks are not merged
/// as a sequential placement would merge them.
///
/// The depth range's folds may meet -0.0 and 0.0 in either order and
/// keep either; the grey `1 - (x - lo) / (hi - lo)` is the same for both.
///
/// [`Frame::linear`] (16 bytes a pixel) is filled only when `unrounded`
/// ([`RenderOptions::unrounded`](crate::render::RenderOptions::unrounded)), and
/// is empty otherwise.
pub(crate) fn colour_blocks(
    kind: &Colouring,
    w: u32,
    h: u32,
    blocks: &[PxBlock],
    unrounded: bool,
) -> Frame {
    use rayon::prelude::*;
    let rows = Rows::new(w, blocks);
    let gaps = rows.has_gaps(h);
    let left_out: usize = rows.blocks.iter().map(PxBlock::misses).sum();
    let empty = Px::default();
    let all = || {
        rows.blocks
            .par_iter()
            .flat_map_iter(|b| b.pixels.iter())
            .chain(rayon::iter::repeat_n(&empty, gaps as usize))
            .chain(rayon::iter::repeat_n(&Px::MISS, left_out))
    };
    let scale = match kind {
        Colouring::Rgb => Scale::Rgb,
        Colouring::Mip { window } => {
            let [lo, hi] = match window {
                Some(win) => *win,
                None => auto_window(
                    all()
                        .filter(|p| p.hit && !p.rgb[0].is_nan())
                        .map(|p| p.rgb[0])
                        .collect(),
                ),
            };
            Scale::Mip { lo, hi }
        }
        Colouring::Cost => Scale::Cost {
            max: all().map(|p| p.steps).max().unwrap_or(1).max(1) as f32,
        },
        Colouring::Depth => {
            let (lo, hi) = all()
                .map(|p| p.depth)
                .filter(|x| x.is_finite())
                .fold(
                    || (f32::INFINITY, f32::NEG_INFINITY),
                    |(a, b), x| (a.min(x), b.max(x)),
                )
                .reduce(
                    || (f32::INFINITY, f32::NEG_INFINITY),
                    |(a, b), (c, d)| (a.min(c), b.max(d)),
                );
            Scale::Depth { lo, hi }
        }
    };
    let (wu, n) = (w as usize, w as usize * h as usize);
    let (mut rgb, mut alpha) = (vec![0u8; 3 * n], vec![0u8; n]);
    let mut linear = vec![0f32; if unrounded { 4 * n } else { 0 }];
    let mut steps = vec![0u32; n];
    // A missed pixel (every culled one, render/view/cull.rs) colours as +0.0
    // in all four channels, 0 in 8 bits, with 0 steps in every colouring
    // but the cost map's: what the planes already hold.
    let skip_misses = !matches!(scale, Scale::Cost { .. });
    // Row `y` of the planes (`linear` when kept).
    let row = |y: usize,
               rgb: &mut [u8],
               alpha: &mut [u8],
               steps: &mut [u32],
               mut linear: Option<&mut [f32]>| {
        rows.each(y as u32, skip_misses, |x, p| {
            if skip_misses && p.is_miss() {
                return;
            }
            put(scale, p, x, rgb, alpha, steps, linear.as_deref_mut());
        });
    };
    if wu > 0 {
        let planes = rgb
            .par_chunks_mut(3 * wu)
            .zip(alpha.par_chunks_mut(wu))
            .zip(steps.par_chunks_mut(wu));
        if unrounded {
            planes
                .zip(linear.par_chunks_mut(4 * wu))
                .enumerate()
                .for_each(|(y, (((rgb, alpha), steps), l))| row(y, rgb, alpha, steps, Some(l)));
        } else {
            planes
                .enumerate()
                .for_each(|(y, ((rgb, alpha), steps))| row(y, rgb, alpha, steps, None));
        }
    }
    // One f32 per pixel from `f`, in parallel by rows.
    let plane = |f: fn(&Px) -> f32| {
        let mut v = vec![0f32; n];
        if wu > 0 {
            v.par_chunks_mut(wu)
                .enumerate()
                .for_each(|(y, row)| rows.each(y as u32, false, |x, p| row[x] = f(p)));
        }
        v
    };
    let (depth, values) = match kind {
        Colouring::Rgb => (None, None),
        Colouring::Mip { .. } => (
            None,
            Some(plane(|p| if p.hit { p.rgb[0] } else { f32::NAN })),
        ),
        Colouring::Cost => (None, Some(plane(|p| p.steps as f32))),
        Colouring::Depth => (Some(plane(|p| p.depth)), None),
    };
    Frame {
        width: w,
        height: h,
        rgb,
        alpha,
        linear,
        depth,
        values,
        steps,
    }
}

/// Writes pixel `p`, coloured by `scale`, at `x` of the planes (and of
/// `linear` when kept): where a pixel becomes bytes, for
/// [`colour_blocks`] and for tiles that colour their own pixels
/// ([`Canvas`](super::canvas::Canvas)).
#[inline]
pub(super) fn put(
    scale: Scale,
    p: &Px,
    x: usize,
    rgb: &mut [u8],
    alpha: &mut [u8],
    steps: &mut [u32],
    linear: Option<&mut [f32]>,
) {
    let c = colour_px(scale, p);
    if let Some(l) = linear {
        l[4 * x..4 * x + 4].copy_from_slice(&c);
    }
    for k in 0..3 {
        rgb[3 * x + k] = to8(c[k]);
    }
    alpha[x] = to8(c[3]);
    steps[x] = p.steps;
}

/// One pixel's colour and coverage in [0, 1] (NaN colour channels as 0).
#[inline]
fn colour_px(scale: Scale, p: &Px) -> [f32; 4] {
    let alpha = match scale {
        Scale::Rgb => p.alpha,
        Scale::Cost { .. } => 1.0,
        Scale::Mip { .. } | Scale::Depth { .. } => f32::from(u8::from(p.hit)),
    }
    .clamp(0.0, 1.0);
    let unit = |x: f32| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let grey = |g: f32| {
        let g = unit(g);
        [g, g, g, alpha]
    };
    match scale {
        Scale::Rgb => [unit(p.rgb[0]), unit(p.rgb[1]), unit(p.rgb[2]), alpha],
        Scale::Mip { lo, hi } => grey(if p.hit {
            ((p.rgb[0] as f64 - lo) / (hi - lo).max(1e-300)) as f32
        } else {
            0.0
        }),
        Scale::Cost { max } => {
            let c = heat(p.steps as f32 / max);
            [
                unit(c[0] as f32 / 255.0),
                unit(c[1] as f32 / 255.0),
                unit(c[2] as f32 / 255.0),
                alpha,
            ]
        }
        Scale::Depth { lo, hi } => {
            let x = p.depth;
            grey(if x.is_finite() {
                1.0 - (x - lo) / (hi - lo).max(1e-30) * 0.9
            } else {
                0.0
            })
        }
    }
}

/// `(x * 255).round() as u8`, the colour channel `x` in 8 bits, with
/// the same result for every `x` (NaN and below 0 give 0, above 1 give
/// 255), without a call to libm's `roundf` (the default x86-64 target
/// has no rounding instruction; four calls per pixel were 2 % of a warm
/// surface frame), and without a branch. `y` is clamped to `[0, 255]`
/// first (`max` and `min` take the number over a NaN, so NaN gives 0;
/// from 255 up every rounding is 255). There the truncation `t` and the
/// fraction `y - t` are exact, so comparing the fraction with 0.5 rounds
/// half away from zero as `round` does.
#[inline]
// `clamp` would keep a NaN; `max` turns it into 0.
#[allow(clippy::manual_clamp)]
pub(crate) fn to8(x: f32) -> u8 {
    let y = (x * 255.0).max(0.0).min(255.0);
    let t = y as i32 as f32;
    (t + f32::from(u8::from(y - t >= 0.5))) as u8
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
    std::array::from_fn(|k| to8(a.1[k] + f * (b.1[k] - a.1[k])))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn to8_rounds_as_round_does() {
        let want = |x: f32| (x * 255.0).round() as u8;
        let mut xs = vec![
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            -1e-30,
            -0.001,
            -1.0,
            1.0,
            1.001,
            2.0,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            1e-45,
        ];
        // Around every half step (k + 1/2) / 255 and every step k / 255,
        // 200 neighbouring floats each way.
        for k in 0..=256 {
            for c in [(k as f32 + 0.5) / 255.0, k as f32 / 255.0] {
                let mut a = c;
                let mut b = c;
                for _ in 0..200 {
                    a = a.next_up();
                    b = b.next_down();
                    xs.extend([a, b]);
                }
                xs.push(c);
            }
        }
        // And a dense sweep of [-0.01, 1.01].
        xs.extend((0..=1_020_000).map(|i| -0.01 + i as f32 * 1e-6));
        for x in xs {
            assert_eq!(to8(x), want(x), "{x:e} ({:#x})", x.to_bits());
        }
    }

    // The colouring as it was before `colour_blocks`: one gathered pixel
    // buffer, coloured sequentially, the window by a full sort. The
    // oracle of the parallel per-block colouring.
    /// The automatic MIP window of an image: the [`AUTO_WINDOW_PERCENTILES`]
    /// of its hit pixels' values (the maxima the rays met), `[0, 1]` when no
    /// ray hit; never an empty range.
    fn auto_window_reference(px: &[Px]) -> [f64; 2] {
        let mut v: Vec<f32> = px
            .iter()
            .filter(|p| p.hit && !p.rgb[0].is_nan())
            .map(|p| p.rgb[0])
            .collect();
        if v.is_empty() {
            return [0.0, 1.0];
        }
        v.sort_by(f32::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64;
        let [lo, hi] = AUTO_WINDOW_PERCENTILES.map(at);
        if hi > lo {
            [lo, hi]
        } else {
            [lo - 0.5, lo + 0.5]
        }
    }

    /// Colours the pixels `px` of a `w` x `h` image.
    fn colour_reference(kind: &Colouring, w: u32, h: u32, px: &[Px]) -> Frame {
        let n = (w * h) as usize;
        let mut linear = vec![0f32; 4 * n];
        for (i, p) in px.iter().enumerate() {
            linear[4 * i + 3] = match kind {
                Colouring::Rgb => p.alpha,
                Colouring::Cost => 1.0,
                Colouring::Mip { .. } | Colouring::Depth => f32::from(u8::from(p.hit)),
            }
            .clamp(0.0, 1.0);
        }
        // Pixel `i`, channel `k` (`None`: all three) set to `x` in [0, 1].
        let mut put = |i: usize, k: Option<usize>, x: f32| {
            let ks = match k {
                Some(k) => k..k + 1,
                None => 0..3,
            };
            let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
            for k in ks {
                linear[4 * i + k] = x;
            }
        };
        let miss_nan = |p: &Px, x: f32| if p.hit { x } else { f32::NAN };
        let (mut depth, mut values) = (None::<Vec<f32>>, None);
        match kind {
            Colouring::Rgb => {
                for (i, p) in px.iter().enumerate() {
                    for k in 0..3 {
                        put(i, Some(k), p.rgb[k]);
                    }
                }
            }
            Colouring::Mip { window } => {
                let [lo, hi] = window.unwrap_or_else(|| auto_window_reference(px));
                for (i, p) in px.iter().enumerate() {
                    let g = if p.hit {
                        ((p.rgb[0] as f64 - lo) / (hi - lo).max(1e-300)) as f32
                    } else {
                        0.0
                    };
                    put(i, None, g);
                }
                values = Some(px.iter().map(|p| miss_nan(p, p.rgb[0])).collect());
            }
            Colouring::Cost => {
                let max = px.iter().map(|p| p.steps).max().unwrap_or(1).max(1) as f32;
                for (i, p) in px.iter().enumerate() {
                    let c = heat(p.steps as f32 / max);
                    for (k, &v) in c.iter().enumerate() {
                        put(i, Some(k), v as f32 / 255.0);
                    }
                }
                values = Some(px.iter().map(|p| p.steps as f32).collect());
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
                    put(i, None, g);
                }
                depth = Some(d);
            }
        }
        let to8 = |x: &f32| to8(*x);
        let rgb = linear
            .chunks_exact(4)
            .flat_map(|c| c[..3].iter().map(to8))
            .collect();
        let alpha = linear.chunks_exact(4).map(|c| to8(&c[3])).collect();
        Frame {
            width: w,
            height: h,
            rgb,
            alpha,
            linear,
            depth,
            values,
            steps: px.iter().map(|p| p.steps).collect(),
        }
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn assert_same(a: &Frame, b: &Frame) {
        assert_eq!((a.width, a.height), (b.width, b.height));
        assert_eq!(a.rgb, b.rgb);
        assert_eq!(a.alpha, b.alpha);
        assert_eq!(bits(&a.linear), bits(&b.linear));
        assert_eq!(a.depth.as_deref().map(bits), b.depth.as_deref().map(bits));
        assert_eq!(a.values.as_deref().map(bits), b.values.as_deref().map(bits));
        assert_eq!(a.steps, b.steps);
    }

    /// Awkward floats: NaN, infinities, out of [0, 1], ties.
    fn float() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => -0.5f32..1.5,
            1 => Just(f32::NAN),
            1 => Just(f32::INFINITY),
            1 => Just(f32::NEG_INFINITY),
            1 => Just(0.25f32),
            1 => Just(0.0f32),
            1 => Just(-0.0f32),
            1 => -1e30f32..1e30,
        ]
    }

    fn pixel() -> impl Strategy<Value = Px> {
        let any_px = (
            proptest::array::uniform3(float()),
            float(),
            float(),
            0u32..1000,
            any::<bool>(),
        )
            .prop_map(|(rgb, alpha, depth, steps, hit)| Px {
                rgb,
                alpha,
                depth,
                steps,
                hit,
            });
        // Culled pixels, and pixels one field away from them (the
        // colouring skips the first only).
        let near_miss = (0usize..7).prop_map(|i| {
            let mut p = Px::MISS;
            match i {
                1 => p.alpha = -0.0,
                2 => p.steps = 1,
                3 => p.hit = true,
                4 => p.rgb[1] = -0.0,
                5 => p.depth = 0.5,
                6 => p.depth = -f32::NAN,
                _ => {}
            }
            p
        });
        prop_oneof![3 => any_px, 1 => near_miss]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn colour_blocks_equals_the_sequential_colouring(
            w in 1u32..40,
            h in 1u32..40,
            ts in 1u32..12,
            pool in proptest::collection::vec(pixel(), 64),
            keep in proptest::collection::vec(prop::bool::weighted(0.9), 64),
            left_out in proptest::collection::vec(prop::bool::weighted(0.2), 64),
            seed in any::<u64>(),
            window in prop_oneof![Just(None), (-2.0f64..2.0, 0.0f64..3.0).prop_map(|(l, d)| Some([l, l + d]))],
        ) {
            // Tiles of `ts` (clipped at the edges), some missing, some
            // left out (all misses, no pixels); pixels drawn from `pool`
            // so values repeat (ties in the window).
            let mut tiles = Vec::new();
            let mut k = seed;
            for (i, (ty, tx)) in (0..h.div_ceil(ts))
                .flat_map(|ty| (0..w.div_ceil(ts)).map(move |tx| (ty, tx)))
                .enumerate()
            {
                if !keep[i % keep.len()] {
                    continue;
                }
                let (x0, y0) = (tx * ts, ty * ts);
                let (tw, th) = (ts.min(w - x0), ts.min(h - y0));
                let pixels = match left_out[(i * 7) % left_out.len()] {
                    true => Vec::new(),
                    false => (0..tw * th)
                        .map(|_| {
                            k = k.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                            pool[(k >> 33) as usize % pool.len()]
                        })
                        .collect(),
                };
                tiles.push(crate::render::TilePx { x0, y0, w: tw, h: th, pixels });
            }
            // The old placement: default pixels, tiles copied in.
            let mut px = vec![Px::default(); (w * h) as usize];
            for t in &tiles {
                for (i, p) in t.px().enumerate() {
                    let (lx, ly) = (i as u32 % t.w, i as u32 / t.w);
                    px[((t.y0 + ly) * w + t.x0 + lx) as usize] = *p;
                }
            }
            // Blocks in a scrambled order: the colouring must not depend on it.
            let mut blocks: Vec<PxBlock> = tiles
                .iter()
                .map(|t| PxBlock { x0: t.x0, y0: t.y0, w: t.w, h: t.h, pixels: &t.pixels })
                .collect();
            blocks.reverse();
            for kind in [
                Colouring::Rgb,
                Colouring::Mip { window },
                Colouring::Cost,
                Colouring::Depth,
            ] {
                let reference = colour_reference(&kind, w, h, &px);
                assert_same(&colour_blocks(&kind, w, h, &blocks, true), &reference);
                assert_same(&colour(&kind, w, h, &px, true), &reference);
                // Without the unrounded colour: the rest unchanged.
                let rounded = colour_blocks(&kind, w, h, &blocks, false);
                prop_assert!(rounded.linear.is_empty());
                assert_same(&rounded, &Frame { linear: Vec::new(), ..reference });
            }
        }
    }

    #[test]
    fn auto_window_by_selection_equals_the_sorted_percentiles() {
        // Many ties, -0.0 and 0.0, a single value, none.
        let px = |v: &[f32]| -> Vec<Px> {
            v.iter()
                .map(|&x| Px {
                    rgb: [x; 3],
                    hit: true,
                    ..Px::default()
                })
                .collect()
        };
        let many: Vec<f32> = (0..5000)
            .map(|i| ((i * 7919) % 1013) as f32 * 0.5 - 100.0)
            .collect();
        for v in [vec![], vec![3.0], vec![-0.0, 0.0, -0.0], many] {
            let p = px(&v);
            let want = auto_window_reference(&p);
            let got = auto_window(v.clone());
            assert_eq!(want.map(f64::to_bits), got.map(f64::to_bits), "{v:?}");
        }
    }
}
