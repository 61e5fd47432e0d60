//! Label mode (issue 55): the surfaces of the chosen labels of a label
//! file ([`crate::labels`]), front to back.
//!
//! The file's 1-cells are the cells with a vertex of any label, so the
//! traversal leaps the background. At a 1-cell the 8 vertex labels decide
//! (one lookup, as the surface mode reads its vertex values):
//! * no vertex of a chosen label: no chosen surface can cross the cell
//!   (the smoothed indicator of a label is below 0.5 at every sample of
//!   another, [`smoothed`](crate::labels::smoothed));
//! * all 8 the same chosen label: the ray is inside it for the whole cell.
//!   Met from outside, that is only possible where the ray's interval
//!   starts (a face of the volume or a cut), which is drawn there;
//! * else the labels of the 4^3 samples around the cell give each chosen
//!   label's smoothed indicator ([`smoothed`](crate::labels::smoothed))
//!   at the 8 vertices, and the first point
//!   where one reaches 0.5 is a hit ([`find_hit_with`], the surface
//!   mode's hit methods).
//!
//! A hit is shaded by the gradient of the filtered indicator before the
//! clamp ([`filtered`](crate::labels::filtered); central differences at the
//! vertices, interpolated) in the label's colour and
//! composited by its opacity; the ray goes on through translucent labels
//! (skipping the one it is inside until it leaves it) and stops once the
//! opacity reaches the early stop. No shadows.

use glam::DVec3;

use super::surface::on_cut;
use super::{walk_span, Ctx, Px};
use crate::labels::{LabelStyle, MARGIN};
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::clock;
use crate::render::sample::hit::{find_hit_with, HitMethod};
use crate::render::sample::shade::{at, shade, CellEval};
use crate::render::traverse::{Flow, Ray, Real, StepCounts, Visit};

/// Translucent labels a ray can be inside at once (more are drawn again
/// on leaving a cell).
const MAX_INSIDE: usize = 8;

/// The label a stored value stands for: a code word or a missing sample
/// (NaN) is label 0 (module docs of [`crate::labels`]).
#[inline]
fn label_of(v: f32) -> u16 {
    // `as` maps NaN to 0; the values are whole numbers 0..=65535.
    v as u16
}

/// The labels of the cube of `e`^3 samples (x fastest) that starts `off`
/// samples before `cell`'s minimum corner, 0 outside the volume of `n`
/// samples per axis. Each sample is read from the brick of the cell it is
/// the minimum corner of (the last sample of an axis from the last
/// cell's), as [`value_elsewhere`](crate::render::sample::normals) reads
/// it: the cube is cut into the parts that lie in one brick each (at most
/// 2 per axis), and each part is read from its brick in one lookup.
fn read_block(
    acc: &mut Accessor,
    n: [usize; 3],
    cell: [u32; 3],
    off: usize,
    e: usize,
    out: &mut [u16],
) {
    out[..e * e * e].fill(0);
    let bs = acc.brick_size() as usize;
    // Per axis, the runs of block offsets whose samples share a brick.
    let runs: [([usize; 3], usize); 3] = std::array::from_fn(|k| {
        let lo = cell[k] as i64 - off as i64;
        let first = (-lo).max(0) as usize;
        let last = (n[k] as i64 - lo).min(e as i64).max(0) as usize;
        let brick = |o: usize| ((lo + o as i64) as usize).min(n[k] - 2) / bs;
        let mut cuts = [first, last, last];
        let mut count = 0;
        if first < last {
            count = 1;
            if let Some(o) = (first + 1..last).find(|&o| brick(o) != brick(first)) {
                cuts = [first, o, last];
                count = 2;
            }
        }
        (cuts, count)
    });
    for iz in 0..runs[2].1 {
        for iy in 0..runs[1].1 {
            for ix in 0..runs[0].1 {
                let part = [ix, iy, iz];
                let from: [usize; 3] = std::array::from_fn(|k| runs[k].0[part[k]]);
                let to: [usize; 3] = std::array::from_fn(|k| runs[k].0[part[k] + 1]);
                // The first sample of the part, and the cell it reads from.
                let s0: [usize; 3] = std::array::from_fn(|k| {
                    (cell[k] as i64 - off as i64 + from[k] as i64) as usize
                });
                let c0: [u32; 3] = std::array::from_fn(|k| s0[k].min(n[k] - 2) as u32);
                let (b, l) = acc.brick_with_values(c0);
                if b.values.is_empty() {
                    continue;
                }
                let ls0: [usize; 3] =
                    std::array::from_fn(|k| l[k] as usize + s0[k] - c0[k] as usize);
                for z in from[2]..to[2] {
                    for y in from[1]..to[1] {
                        let base =
                            b.sample_index([ls0[0], ls0[1] + y - from[1], ls0[2] + z - from[2]]);
                        let row = &mut out[(z * e + y) * e + from[0]..(z * e + y) * e + to[0]];
                        for (x, o) in row.iter_mut().enumerate() {
                            *o = label_of(b.values.get(base + x));
                        }
                    }
                }
            }
        }
    }
}

/// Cells whose label blocks a thread remembers, and (cell, label) pairs
/// whose vertex gradients it remembers: direct-mapped tables, a newer
/// entry replacing an older one in its slot. Rays denser than the cells
/// meet each cell many times (at 1024^2 on the head CT a cell is some 4 x
/// 4 pixels wide), and a cell's block and gradients are functions of the
/// file and the cell: every sample whose word is a value reads as that
/// value from whichever brick, and a code or a uniform brick is label 0.
/// Keyed by the cache's process-unique id, so a table never answers for
/// another file; nothing is remembered after a read error.
const MEMO_SLOTS: usize = 1 << 12;

#[derive(Clone, Copy)]
#[repr(C)]
struct BlockEntry {
    cache: u64,
    cell: u64,
    block: [u16; 64],
    /// 1 + the label whose [`vertex_values`] `values` holds (0: none).
    label: u64,
    values: [f64; 8],
}

#[derive(Clone, Copy)]
#[repr(C)]
struct GradEntry {
    cache: u64,
    cell: u64,
    label: u64,
    g: [[f64; 3]; 8],
}

// SAFETY: every field is an integer or a float (or arrays of them), for
// which all-zero bytes are valid, and `repr(C)` with these sizes (8-byte
// fields, 2-byte ones filling 128 bytes, 8-byte ones) has no padding.
unsafe impl bytemuck::Zeroable for BlockEntry {}
// SAFETY: as above; all fields are 8 bytes wide.
unsafe impl bytemuck::Zeroable for GradEntry {}

thread_local! {
    static BLOCKS: std::cell::RefCell<Vec<BlockEntry>> =
        std::cell::RefCell::new(bytemuck::allocation::zeroed_vec(MEMO_SLOTS));
    static GRADS: std::cell::RefCell<Vec<GradEntry>> =
        std::cell::RefCell::new(bytemuck::allocation::zeroed_vec(MEMO_SLOTS));
}

/// The slot of `key` in a table of [`MEMO_SLOTS`].
#[inline]
fn slot(cache: u64, key: u64) -> usize {
    let h = (key ^ cache.rotate_left(32)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    (h >> (64 - MEMO_SLOTS.trailing_zeros())) as usize
}

/// The global index of `cell` in a volume of `n` samples per axis.
#[inline]
fn cell_key(n: [usize; 3], cell: [u32; 3]) -> u64 {
    let c = cell.map(u64::from);
    (c[2] * (n[1] as u64 - 1) + c[1]) * (n[0] as u64 - 1) + c[0]
}

/// The 4^3 labels around `cell` ([`read_block`] from one sample before
/// it), from this thread's memo when it holds them, and a way to the
/// smoothed indicator of a label at the cell's vertices
/// ([`vertex_values`]), remembered for the last label asked.
struct CellLabels {
    block: [u16; 64],
    slot: usize,
    cache: u64,
    key: u64,
}

impl CellLabels {
    fn of(acc: &mut Accessor, n: [usize; 3], cell: [u32; 3]) -> CellLabels {
        let (cache, key) = (acc.cache_id(), cell_key(n, cell));
        let slot = slot(cache, key);
        let held = BLOCKS.with(|m| {
            let m = m.borrow();
            let e = &m[slot];
            (e.cache == cache && e.cell == key).then_some(e.block)
        });
        let block = match held {
            Some(b) => b,
            None => {
                let mut block = [0u16; 64];
                read_block(acc, n, cell, 1, 4, &mut block);
                if acc.error.is_none() {
                    BLOCKS.with(|m| {
                        m.borrow_mut()[slot] = BlockEntry {
                            cache,
                            cell: key,
                            block,
                            label: 0,
                            values: [0.0; 8],
                        }
                    });
                }
                block
            }
        };
        CellLabels {
            block,
            slot,
            cache,
            key,
        }
    }

    /// [`vertex_values`] of `label` in this cell.
    fn values(&self, label: u16) -> [f64; 8] {
        let tag = u64::from(label) + 1;
        BLOCKS.with(|m| {
            let mut m = m.borrow_mut();
            let e = &mut m[self.slot];
            let ours = e.cache == self.cache && e.cell == self.key;
            if ours && e.label == tag {
                return e.values;
            }
            let v = vertex_values(&self.block, label);
            if ours {
                (e.label, e.values) = (tag, v);
            }
            v
        })
    }
}

/// The binomial [1, 2, 1] / 4 filter of the indicator of `label` over the
/// cube `block` of edge `E` (x fastest), at its `M`^3 inner samples
/// (`M = E - 2`), separably: [`filtered`](crate::labels::filtered) at
/// each, to the same bits (every
/// term is a multiple of 1/64, exact in f64 in any order).
#[inline]
fn filter_block<const E: usize, const M: usize>(block: &[u16], label: u16) -> [f64; 64] {
    const W: [f64; 3] = [0.25, 0.5, 0.25];
    debug_assert!(M == E - 2 && M * M * M <= 64);
    let ind = |i: usize| if block[i] == label { 1.0 } else { 0.0 };
    // Along x: E * E rows of M.
    let mut a = [0.0f64; 144];
    for r in 0..E * E {
        for x in 0..M {
            a[r * M + x] = (0..3).map(|d| W[d] * ind(r * E + x + d)).sum();
        }
    }
    // Along y: E slabs of M * M.
    let mut b = [0.0f64; 96];
    for z in 0..E {
        for y in 0..M {
            for x in 0..M {
                b[(z * M + y) * M + x] = (0..3).map(|d| W[d] * a[(z * E + y + d) * M + x]).sum();
            }
        }
    }
    // Along z.
    let mut out = [0.0f64; 64];
    for z in 0..M {
        for i in 0..M * M {
            out[z * M * M + i] = (0..3).map(|d| W[d] * b[(z + d) * M * M + i]).sum();
        }
    }
    out
}

/// The smoothed indicator of `label` at the 8 vertices of the cell whose
/// 4^3 block of labels is `block` (origin one sample before the cell):
/// [`smoothed`](crate::labels::smoothed) at each, by [`filter_block`].
#[inline]
fn vertex_values(block: &[u16; 64], label: u16) -> [f64; 8] {
    let f = filter_block::<4, 2>(block, label);
    std::array::from_fn(|v| {
        let own = block[((1 + (v >> 2)) * 4 + 1 + (v >> 1 & 1)) * 4 + 1 + (v & 1)];
        if own == label {
            f[v].max(0.5 + MARGIN)
        } else {
            f[v].min(0.5 - MARGIN)
        }
    })
}

/// The chosen labels among `f` (each once), and how many.
#[inline]
fn chosen(f: &[u16; 8], style: &LabelStyle) -> ([u16; 8], usize) {
    let mut out = [0u16; 8];
    let mut k = 0;
    for &l in f {
        if style.slot(l) != 0 && !out[..k].contains(&l) {
            out[k] = l;
            k += 1;
        }
    }
    (out, k)
}

/// The labels a ray is inside of after meeting them translucent.
#[derive(Default)]
struct Inside {
    l: [u16; MAX_INSIDE],
    n: usize,
}

impl Inside {
    fn has(&self, l: u16) -> bool {
        self.l[..self.n].contains(&l)
    }
    fn push(&mut self, l: u16) {
        if self.n < MAX_INSIDE && !self.has(l) {
            self.l[self.n] = l;
            self.n += 1;
        }
    }
    fn retain(&mut self, mut keep: impl FnMut(u16) -> bool) {
        let mut k = 0;
        for i in 0..self.n {
            if keep(self.l[i]) {
                self.l[k] = self.l[i];
                k += 1;
            }
        }
        self.n = k;
    }
}

/// Draws the chosen labels `ray` meets in `span` into `px`: colour
/// premultiplied by the coverage in `alpha`, the first hit's depth.
pub(super) fn labels<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    hit: HitMethod,
    style: &LabelStyle,
    px: &mut Px,
) -> StepCounts {
    let coords = ctx.coords;
    let n = coords.map(|c| c.len());
    let mut first = true;
    let mut inside = Inside::default();
    let mut last_exit = f64::NEG_INFINITY;
    let mut rgb = [0.0f32; 3];
    let mut alpha = 0.0f32;
    let mut depth = f64::NAN;
    let stop = ctx.opts.early_stop as f32;
    let counts = walk_span(ctx, ray, span, acc, |v, acc| {
        let starts_on_cut = std::mem::take(&mut first) && on_cut(v, span);
        clock::enter(acc);
        // A gap since the last 1-cell: the ray crossed background.
        if v.t_enter - last_exit > 1e-9 * v.t_enter.abs().max(1.0) {
            inside = Inside::default();
        }
        last_exit = v.t_exit;
        let f = acc.vertices(v.cell).map(label_of);
        let (cand, k) = chosen(&f, style);
        inside.retain(|l| f.contains(&l));
        let mut draw = |t: f64, label: u16, capped: bool, acc: &mut Accessor| {
            let i = style.slot(label) - 1;
            let p = at(ray, t);
            let normal = match span.cut.filter(|_| capped) {
                Some(cut) => -cut,
                None => smooth_normal(acc, coords, n, v.cell, p, label),
            };
            let s = shade(normal, -ray.dir, -ray.dir, true) as f32;
            let a = style.opacity[i];
            let w = (1.0 - alpha) * a;
            for (o, c) in rgb.iter_mut().zip(style.colour[i]) {
                *o += w * s * c;
            }
            alpha += w;
            if depth.is_nan() {
                depth = t;
            }
            alpha >= stop
        };
        let flow = if k == 0 {
            Flow::Continue
        } else if f.iter().all(|&l| l == f[0]) {
            // Inside one chosen label for the whole cell.
            let l = f[0];
            if inside.has(l) {
                Flow::Continue
            } else if starts_on_cut && !ctx.opts.cap {
                inside.push(l);
                Flow::Continue
            } else if draw(v.t_enter, l, starts_on_cut, acc) {
                Flow::Stop
            } else {
                inside.push(l);
                Flow::Continue
            }
        } else {
            let labels = CellLabels::of(acc, n, v.cell);
            let shape = CellEval::new(coords, v.cell, [0.0; 8]);
            let cells: [CellEval; 8] = std::array::from_fn(|j| CellEval {
                f: if j < k {
                    labels.values(cand[j])
                } else {
                    [0.0; 8]
                },
                ..shape
            });
            let mut t0 = v.t_enter;
            let mut flow = Flow::Continue;
            loop {
                let sub = Visit { t_enter: t0, ..*v };
                let mut best: Option<(f64, usize)> = None;
                for j in 0..k {
                    if inside.has(cand[j]) {
                        continue;
                    }
                    let t = find_hit_with(ray, &sub, &cells[j], 0.5, hit, &ctx.opts.hit_params);
                    if let Some(t) = t.filter(|&t| best.is_none_or(|b| t < b.0)) {
                        best = Some((t, j));
                    }
                }
                let Some((t, j)) = best else { break };
                let capped = starts_on_cut && t == v.t_enter;
                if capped && !ctx.opts.cap {
                    inside.push(cand[j]);
                    continue;
                }
                if draw(t, cand[j], capped, acc) {
                    flow = Flow::Stop;
                    break;
                }
                inside.push(cand[j]);
                t0 = t;
            }
            // Out of a label once its indicator is below 0.5 at the exit.
            let exit = at(ray, v.t_exit);
            inside.retain(|l| (0..k).any(|j| cand[j] == l && cells[j].value(exit) >= 0.5));
            flow
        };
        clock::leave(acc);
        flow
    });
    if !depth.is_nan() {
        px.hit = true;
        px.rgb = rgb;
        px.alpha = alpha;
        px.depth = depth as f32;
    }
    counts
}

/// The gradient (per mm) of `label`'s filtered indicator
/// ([`filtered`](crate::labels::filtered): smoothed, not clamped) at
/// point `p` of `cell`: [`vertex_gradients`], remembered per thread,
/// interpolated trilinearly. It points into the label, as an
/// iso-surface's gradient points into the object.
fn smooth_normal(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    n: [usize; 3],
    cell: [u32; 3],
    p: DVec3,
    label: u16,
) -> DVec3 {
    let (cache, key) = (acc.cache_id(), cell_key(n, cell));
    let g = GRADS.with(|m| {
        let mut m = m.borrow_mut();
        let e = &mut m[slot(cache, key ^ (u64::from(label) << 48))];
        if e.cache == cache && e.cell == key && e.label == u64::from(label) {
            return e.g.map(DVec3::from_array);
        }
        let g = vertex_gradients(acc, coords, n, cell, label);
        if acc.error.is_none() {
            *e = GradEntry {
                cache,
                cell: key,
                label: u64::from(label),
                g: g.map(|v| v.to_array()),
            };
        }
        g
    });
    let c = cell.map(|x| x as usize);
    let u: [f64; 3] = std::array::from_fn(|k| {
        let (x0, x1) = (coords[k][c[k]], coords[k][c[k] + 1]);
        ((p[k] - x0) / (x1 - x0)).clamp(0.0, 1.0)
    });
    let lerp = |a: DVec3, b: DVec3, t: f64| a + t * (b - a);
    let x0 = lerp(g[0], g[1], u[0]);
    let x1 = lerp(g[2], g[3], u[0]);
    let x2 = lerp(g[4], g[5], u[0]);
    let x3 = lerp(g[6], g[7], u[0]);
    lerp(lerp(x0, x1, u[1]), lerp(x2, x3, u[1]), u[2])
}

/// The gradients of `label`'s filtered indicator at the 8 vertices of
/// `cell` (x fastest), by central differences (one-sided at the volume's
/// faces).
fn vertex_gradients(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    n: [usize; 3],
    cell: [u32; 3],
    label: u16,
) -> [DVec3; 8] {
    // Labels of samples cell - 2 ..= cell + 3: the filtered indicator at
    // cell - 1 ..= cell + 2, block offsets 1..=4.
    let mut block = [0u16; 216];
    read_block(acc, n, cell, 2, 6, &mut block);
    let c = cell.map(|x| x as usize);
    let f = filter_block::<6, 4>(&block, label);
    let s = |o: [usize; 3]| f[(o[2] * 4 + o[1]) * 4 + o[0]];
    std::array::from_fn(|v| {
        // Vertex v at block offset 1 + (0 or 1) per axis.
        let o = [1 + (v & 1), 1 + (v >> 1 & 1), 1 + (v >> 2)];
        let mut out = [0.0; 3];
        for k in 0..3 {
            // Global sample of the vertex along axis k.
            let i = c[k] + o[k] - 1;
            let lo = if i >= 1 { i - 1 } else { i };
            let hi = if i + 1 < n[k] { i + 1 } else { i };
            let mut a = o;
            let mut b = o;
            a[k] = o[k] - (i - lo);
            b[k] = o[k] + (hi - i);
            let h = coords[k][hi] - coords[k][lo];
            out[k] = if h > 0.0 { (s(b) - s(a)) / h } else { 0.0 };
        }
        DVec3::from_array(out)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{filtered, smoothed};

    /// The separable filter equals the reference at every inner sample,
    /// bit for bit, on random blocks of a few labels.
    #[test]
    fn separable_filter_is_the_reference() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..200 {
            let mut block = [0u16; 216];
            for b in block.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *b = (x % 3) as u16;
            }
            for label in 0..3 {
                let f = filter_block::<6, 4>(&block, label);
                for (i, fi) in f.iter().enumerate() {
                    let at = [1 + i % 4, 1 + i / 4 % 4, 1 + i / 16];
                    assert_eq!(fi.to_bits(), filtered(&block, 6, at, label).to_bits());
                }
                let mut small = [0u16; 64];
                for (i, s) in small.iter_mut().enumerate() {
                    *s = block[((i / 16) * 6 + i / 4 % 4) * 6 + i % 4];
                }
                let v = vertex_values(&small, label);
                for (j, vj) in v.iter().enumerate() {
                    let at = [1 + (j & 1), 1 + (j >> 1 & 1), 1 + (j >> 2)];
                    assert_eq!(vj.to_bits(), smoothed(&small, 4, at, label).to_bits());
                }
            }
        }
    }
}
