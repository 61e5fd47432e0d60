//! Label mode (issue 55): the surfaces of the chosen labels of a label
//! file ([`crate::labels`]), front to back.
//!
//! The file's 1-cells are the cells with a vertex of any label, so the
//! traversal leaps the background. At a 1-cell the 8 vertex labels decide
//! (one lookup, as the surface mode reads its vertex values):
//! * no vertex of a chosen label: no chosen surface can cross the cell
//!   (the smoothed indicator of a label is below 0.5 at every sample of
//!   another, [`smoothed`]);
//! * all 8 the same chosen label: the ray is inside it for the whole cell.
//!   Met from outside, that is only possible where the ray's interval
//!   starts (a face of the volume or a cut), which is drawn there;
//! * else the labels of the 4^3 samples around the cell give each chosen
//!   label's smoothed indicator at the 8 vertices, and the first point
//!   where one reaches 0.5 is a hit ([`find_hit_with`], the surface
//!   mode's hit methods).
//!
//! A hit is shaded by the smoothed indicator's gradient (central
//! differences at the vertices, interpolated) in the label's colour and
//! composited by its opacity; the ray goes on through translucent labels
//! (skipping the one it is inside until it leaves it) and stops once the
//! opacity reaches the early stop. No shadows.

use glam::DVec3;

use super::surface::on_cut;
use super::{walk_span, Ctx, Px};
use crate::labels::{filtered, smoothed, LabelStyle};
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::clock;
use crate::render::sample::hit::{find_hit_with, HitMethod};
use crate::render::sample::normals::value_elsewhere;
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

/// The labels of the cube of `e`^3 samples whose first is global sample
/// `lo` (x fastest), 0 outside the volume of `n` samples per axis.
fn read_block(acc: &mut Accessor, n: [usize; 3], lo: [i64; 3], e: usize, out: &mut [u16]) {
    for z in 0..e {
        for y in 0..e {
            for x in 0..e {
                let s = [lo[0] + x as i64, lo[1] + y as i64, lo[2] + z as i64];
                let inside = (0..3).all(|k| s[k] >= 0 && (s[k] as usize) < n[k]);
                out[(z * e + y) * e + x] = if inside {
                    label_of(value_elsewhere(acc, n, s.map(|v| v as usize)))
                } else {
                    0
                };
            }
        }
    }
}

/// The smoothed indicator of `label` at the 8 vertices of the cell whose
/// 4^3 block of labels is `block` (origin one sample before the cell).
#[inline]
fn vertex_values(block: &[u16; 64], label: u16) -> [f64; 8] {
    std::array::from_fn(|v| {
        smoothed(
            block,
            4,
            [1 + (v & 1), 1 + (v >> 1 & 1), 1 + (v >> 2)],
            label,
        )
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
            let mut block = [0u16; 64];
            let lo = v.cell.map(|c| c as i64 - 1);
            read_block(acc, n, lo, 4, &mut block);
            let shape = CellEval::new(coords, v.cell, [0.0; 8]);
            let cells: [CellEval; 8] = std::array::from_fn(|j| CellEval {
                f: if j < k {
                    vertex_values(&block, cand[j])
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
/// ([`filtered`]: smoothed, not clamped) at point `p` of `cell`: central
/// differences at the 8 vertices (one-sided at the volume's faces),
/// interpolated trilinearly. It points into the label,
/// as an iso-surface's gradient points into the object.
fn smooth_normal(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    n: [usize; 3],
    cell: [u32; 3],
    p: DVec3,
    label: u16,
) -> DVec3 {
    // Labels of samples cell - 2 ..= cell + 3: the smoothed indicator at
    // cell - 1 ..= cell + 2, block offsets 1..=4.
    let mut block = [0u16; 216];
    read_block(acc, n, cell.map(|c| c as i64 - 2), 6, &mut block);
    let c = cell.map(|x| x as usize);
    let s = |o: [usize; 3]| filtered(&block, 6, [o[0] + 1, o[1] + 1, o[2] + 1], label);
    let g: [DVec3; 8] = std::array::from_fn(|v| {
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
    });
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
