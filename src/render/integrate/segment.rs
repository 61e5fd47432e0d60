//! The composite per ray-cell segment (`--integrate segment`), and the
//! f64 reference both composites are measured against (`--integrate
//! reference`).
//!
//! The traversal reports, exactly, where the ray enters and leaves each
//! 1-cell (paper section 4; every exact traversal the same `t`s). Inside
//! one cell the trilinear interpolant along the ray is a cubic in the ray
//! parameter ([`Cubic`]): linear along an axis, its curvature bounded by
//! the cell's cross differences. So instead of sampling at a fixed step,
//! each segment is split into the fewest pieces whose chords are within
//! the tolerance of the cubic (the chord of a function with `|f''| <= M`
//! over a piece of length `l` is off by at most `M l^2 / 8`), and each
//! chord is integrated exactly from two lookups of the extinction
//! integral table ([`PreTable`]; pre-integrated volume rendering,
//! Röttger, Kraus and Ertl 2000, Engel, Kraus and Ertl 2001). The colour
//! is the extinction-weighted colour of the chord times its opacity
//! (self-attenuation inside a chord neglected); a chord deeper than
//! [`first_depth`] is split further so that this neglect stays small
//! where the ray turns opaque. (The exact pre-integration table of Lum,
//! Wilson and Ma 2004 holds a chord of one length; segments here have
//! every length, so it would be a table per length: not built.)
//!
//! A segment's exit value, on the face it shares with the next cell, is
//! that cell's entry value and table lookup: one trilinear evaluation and
//! one lookup per piece. Shading and gradient opacity are taken at each
//! piece's middle; the gradient opacity scales the extinction.
//!
//! Every exact traversal reports the same visits with the same `t`s, so
//! every traversal draws the same image, byte for byte.

use glam::{Vec3A, Vec4};

use super::batch::trilinear_vec;
use super::sample::Look;
use super::{walk_span, Ctx, Px};
use crate::classify::TransferFunction;
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::clock;
use crate::render::sample::normals::{outer_cell_gradients, vertex_gradients};
use crate::render::sample::pretable::{emission, PreTable, SlopeMemo};
use crate::render::sample::shade::{at, CellEval};
use crate::render::traverse::{Flow, Ray, Real, StepCounts, Visit};

/// The optical depth of the first part of a deep chord: parts are
/// value-linear, each lit at its own middle, the first this deep and
/// later ones deeper as the light left falls ([`deep`]); the colour of a
/// part is its extinction-weighted colour, exact while the part is thin.
/// Twice the tolerance, at most 0.02, so that both errors vanish together
/// (docs/DECISIONS.md, "Integrators").
pub(crate) fn first_depth(tol: f64) -> f64 {
    (2.0 * tol).min(0.02)
}

/// How far a segment's pieces may be from the cubic (`tol`, value units)
/// and how deep a chord's first part may be (`depth`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Limits {
    pub tol: f64,
    pub depth: f64,
}

/// Pieces of one segment at most (a segment along a cell's diagonal
/// through a sharp saddle).
pub const MAX_PIECES: u32 = 64;

/// The trilinear interpolant of a cell along a ray from `t0`:
/// `f(t0 + s) = k[0] + k[1] s + k[2] s^2 + k[3] s^3`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Cubic {
    pub k: [f64; 4],
    /// Local coordinates at `t0` and their change per unit of `t`.
    pub u0: [f64; 3],
    pub du: [f64; 3],
}

impl Cubic {
    /// The interpolant of cell `cell` (vertex values `f`, x fastest) along
    /// `ray` from `t0`; `inv_size` the cells' inverse sizes per axis.
    #[inline(always)]
    pub fn along(
        coords: [&[f64]; 3],
        inv_size: &[Vec<f64>; 3],
        cell: [u32; 3],
        f: [f32; 8],
        ray: &Ray,
        t0: f64,
    ) -> Cubic {
        // Local coordinates u_a = p_a + q_a s.
        let mut p = [0.0f64; 3];
        let mut q = [0.0f64; 3];
        for a in 0..3 {
            let i = cell[a] as usize;
            let inv = inv_size[a][i];
            p[a] = (ray.origin[a] + t0 * ray.dir[a] - coords[a][i]) * inv;
            q[a] = ray.dir[a] * inv;
        }
        let f = f.map(|x| x as f64);
        // f = c + cx x + cy y + cz z + cxy xy + cxz xz + cyz yz + cxyz xyz.
        let c = f[0];
        let (cx, cy, cz) = (f[1] - f[0], f[2] - f[0], f[4] - f[0]);
        let cxy = f[3] - f[2] - f[1] + f[0];
        let cxz = f[5] - f[4] - f[1] + f[0];
        let cyz = f[6] - f[4] - f[2] + f[0];
        let cxyz = f[7] - f[6] - f[5] + f[4] - f[3] + f[2] + f[1] - f[0];
        let [px, py, pz] = p;
        let [qx, qy, qz] = q;
        let k0 = c
            + cx * px
            + cy * py
            + cz * pz
            + cxy * px * py
            + cxz * px * pz
            + cyz * py * pz
            + cxyz * px * py * pz;
        let k1 = cx * qx
            + cy * qy
            + cz * qz
            + cxy * (px * qy + qx * py)
            + cxz * (px * qz + qx * pz)
            + cyz * (py * qz + qy * pz)
            + cxyz * (qx * py * pz + px * qy * pz + px * py * qz);
        let k2 = cxy * qx * qy
            + cxz * qx * qz
            + cyz * qy * qz
            + cxyz * (qx * qy * pz + qx * py * qz + px * qy * qz);
        let k3 = cxyz * qx * qy * qz;
        Cubic {
            k: [k0, k1, k2, k3],
            u0: p,
            du: q,
        }
    }

    /// Local coordinates at `s`, clamped to the cell.
    #[inline(always)]
    pub fn local(&self, s: f64) -> [f32; 3] {
        std::array::from_fn(|a| (self.u0[a] + s * self.du[a]).clamp(0.0, 1.0) as f32)
    }

    /// The value at `s`.
    #[inline(always)]
    pub fn at(&self, s: f64) -> f64 {
        let k = &self.k;
        k[0] + s * (k[1] + s * (k[2] + s * k[3]))
    }

    /// The largest `|f''|` on `[0, len]` (`f''` is linear: at an end).
    #[inline(always)]
    pub fn curvature(&self, len: f64) -> f64 {
        let k = &self.k;
        (2.0 * k[2])
            .abs()
            .max((2.0 * k[2] + 6.0 * k[3] * len).abs())
    }

    /// The largest value at the stationary points strictly inside `(0,
    /// len)`, `-inf` if there are none: with the ends, the cubic's maximum
    /// over the segment.
    pub fn interior_max(&self, len: f64) -> f64 {
        let [_, k1, k2, k3] = self.k;
        // f'(s) = k1 + 2 k2 s + 3 k3 s^2, its roots by the stable
        // quadratic formula: q = -(b + sign(b) sqrt(b^2 - 4ac)) / 2,
        // roots q / a and c / q (a division by 0 gives an infinity or
        // NaN, which no interval holds).
        let (a, b, c) = (3.0 * k3, 2.0 * k2, k1);
        let disc = b * b - 4.0 * a * c;
        if !(disc >= 0.0) {
            return f64::NEG_INFINITY;
        }
        let q = -0.5 * (b + disc.sqrt().copysign(b));
        let mut best = f64::NEG_INFINITY;
        for s in [q / a, c / q] {
            if s > 0.0 && s < len {
                best = best.max(self.at(s));
            }
        }
        best
    }
}

/// The number of pieces whose chords stay within `tol` of a cubic with
/// curvature at most `m` over `len`: `M (len / n)^2 / 8 <= tol`.
#[inline(always)]
pub(crate) fn pieces(m: f64, len: f64, tol: f64) -> u32 {
    let n = len * (m / (8.0 * tol)).sqrt();
    if n > 1.0 {
        n.ceil().min(MAX_PIECES as f64) as u32
    } else {
        1
    }
}

/// The ray's colour and opacity so far, and what it looks like.
struct Acc<'a> {
    look: Look<'a>,
    col: [f64; 3],
    alpha: f64,
}

impl<'a> Acc<'a> {
    /// A clear ray of `ctx`'s look.
    fn new<T: Real>(ctx: &'a Ctx<T>, ray: &Ray) -> Acc<'a> {
        Acc {
            look: Look::new(&ctx.opts.look, ctx.opts.normals, ray),
            col: [0.0; 3],
            alpha: 0.0,
        }
    }

    /// Composites a part of optical depth `e[0]` and extinction-weighted
    /// colour `e[1..]`, lit through gradient `g` (when the look is on).
    #[inline(always)]
    fn add(&mut self, e: [f64; 4], g: Option<Vec3A>) {
        let mut e = e;
        let mut lit = None;
        if let Some(g) = g {
            let len = g.length();
            if !self.look.look.gradient_opacity.is_empty() {
                let k = self.look.look.gradient_factor(len as f64);
                e = e.map(|x| x * k);
            }
            if self.look.look.shade {
                lit = Some((g, len));
            }
        }
        let d = e[0];
        if !(d > 0.0) {
            return;
        }
        // alpha / d = (1 - exp(-d)) / d; most parts are thin, where its
        // series to d^3 is off by under d^4 / 120 (7e-9 at 0.03).
        let k = if d < 0.03 {
            1.0 - d * (0.5 - d * (1.0 / 6.0 - d * (1.0 / 24.0)))
        } else {
            -(-d).exp_m1() / d
        };
        let alpha = k * d;
        // Colour: the extinction-weighted colour times the opacity.
        let mut s = [e[1] * k, e[2] * k, e[3] * k, alpha];
        if let Some((g, len)) = lit {
            let v = Vec4::from_array(s.map(|x| x as f32));
            s = self.look.lit(v, g, len).to_array().map(|x| x as f64);
        }
        let w = 1.0 - self.alpha;
        for (c, x) in self.col.iter_mut().zip(s) {
            *c += w * x;
        }
        self.alpha += w * s[3];
    }

    fn finish(&self, px: &mut Px) {
        px.hit = self.alpha > 0.0;
        px.alpha = self.alpha as f32;
        px.rgb = self.col.map(|x| x as f32);
    }
}

/// Where the last segment left the ray: its exit `t` (NaN: none) and the
/// value and table integral there; and the table's stretch the last
/// cell's values lay in.
struct Exit {
    t: f64,
    v: f64,
    p: [f64; 4],
    memo: SlopeMemo,
}

/// Composites `ray` over `span` segment by segment (module docs) within
/// `limits`, stopping at the options' early stop.
pub(super) fn composite<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    table: &PreTable,
    limits: Limits,
    px: &mut Px,
) -> StepCounts {
    let mut a = Acc::new(ctx, ray);
    let stop = ctx.opts.early_stop;
    // mm per unit of t (camera rays are unit: 1).
    let mm = ray.dir.length();
    let mut last = Exit {
        t: f64::NAN,
        v: f64::NAN,
        p: [0.0; 4],
        memo: SlopeMemo::default(),
    };
    let counts = walk_span(ctx, ray, span, acc, |v, acc| {
        clock::enter(acc);
        let flow = segment(ctx, ray, v, acc, table, limits, mm, &mut a, &mut last, stop);
        clock::leave(acc);
        flow
    });
    a.finish(px);
    counts
}

/// One visit of [`composite`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn segment<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    v: &Visit,
    acc: &mut Accessor,
    table: &PreTable,
    limits: Limits,
    mm: f64,
    a: &mut Acc,
    last: &mut Exit,
    stop: f64,
) -> Flow {
    let len = v.t_exit - v.t_enter;
    if !(len > 0.0) {
        return Flow::Continue;
    }
    let (b, l) = acc.brick(v.cell);
    // A cell whose vertices all lie where the function is transparent
    // adds nothing (the interpolant never exceeds its largest vertex; a
    // NaN vertex gives no bound and never skips): one lookup, as the
    // MIP's. A file classified wider than the function (`prep
    // --envelope`) has many.
    if (b.vertex_top(l) as f64) <= table.clear_below {
        last.t = f64::NAN;
        return Flow::Continue;
    }
    let f = b.vertices(l);
    let (lo, hi) = f
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x as f64), hi.max(x as f64))
        });
    let slope = if f.iter().any(|x| x.is_nan()) {
        f64::INFINITY
    } else {
        table.slope_memo(lo, hi, &mut last.memo)
    };
    // Where the table changes little over the cell's vertex values (the
    // interpolant stays between them), the segment is one part at the
    // rate of their middle: off by at most `slope` times half their range
    // per mm, no more than a chord within `tol` of the cubic where the
    // table is steepest (below); exact where the table is constant. No
    // cubic, one lookup. Unlit, and where the part is thin or its colour
    // spread small (as a deep chord's, below).
    if !a.look.on && (hi - lo) * slope <= 2.0 * limits.tol * table.slope_max() {
        let e = table.rate(0.5 * (lo + hi)).map(|x| x * len * mm);
        if e[0] <= limits.depth
            || e[0] * table.spread_memo(lo, hi, &last.memo).sqrt() <= limits.depth
        {
            a.add(e, None);
            last.t = f64::NAN;
            return if a.alpha > stop {
                Flow::Stop
            } else {
                Flow::Continue
            };
        }
    }
    let plane = if a.look.on && a.look.smooth {
        b.grad_cell(l)
    } else {
        None
    };
    let cub = Cubic::along(ctx.coords, &ctx.inv_size, v.cell, f, ray, v.t_enter);
    let (mut fa, mut pa) = if v.t_enter == last.t {
        (last.v, last.p)
    } else {
        (cub.k[0], table.integral(cub.k[0]))
    };
    // A chord off the cubic by `e` in value is off by at most `e` times
    // the table's slope over the cell in each channel: pieces within
    // `tol` where the table is steepest, within proportionally more
    // where it is flatter (one where it is flat), so that every chord is
    // within the same bound of its integral.
    let m = cub.curvature(len);
    let n = if len * len * m * slope <= 8.0 * limits.tol * table.slope_max() {
        1
    } else {
        pieces(m, len, limits.tol * (table.slope_max() / slope))
    };
    // The look's gradients at a piece's middle: smooth normals from the
    // cell's vertex gradients (the brick's gradient plane, else computed
    // and kept there), or the cell interpolant's own.
    let grads: Option<[Vec3A; 8]> = (a.look.on && a.look.smooth)
        .then(|| plane.unwrap_or_else(|| outer_cell_gradients(acc, ctx.coords, v.cell)));
    let ce = (a.look.on && !a.look.smooth).then(|| CellEval::new(ctx.coords, v.cell, f));
    let gradient = |s: f64| -> Option<Vec3A> {
        match (&grads, &ce) {
            (Some(g), _) => Some(trilinear_vec(g, Vec3A::from_array(cub.local(s)))),
            (None, Some(ce)) => Some(Vec3A::from(ce.gradient(at(ray, v.t_enter + s)).as_vec3())),
            _ => None,
        }
    };
    let mut sa = 0.0;
    for i in 1..=n {
        let sb = if i == n {
            len
        } else {
            len * i as f64 / n as f64
        };
        let fb = cub.at(sb);
        let pb = table.integral(fb);
        let e = table.chord(fa, &pa, fb, &pb, (sb - sa) * mm);
        if e[0] > 0.0 {
            // Unlit, a deep chord is off only by its colour's spread: the
            // colour-weighted mean stands for the whole, off by about
            // `spread D^2 / 2` at depth `D` (self-attenuation), so a chord
            // whose colour spreads little may be `1 / sqrt(spread)` deeper
            // for the error a chord of any colour has at `depth`.
            let spread = if a.look.on {
                1.0
            } else if e[0] <= limits.depth {
                0.0
            } else {
                table.spread_memo(fa.min(fb), fa.max(fb), &last.memo)
            };
            let root = spread.sqrt();
            if e[0] * root <= limits.depth {
                a.add(e, gradient(0.5 * (sa + sb)));
            } else {
                let d = limits.depth / root;
                deep(table, (sa, fa, pa), (sb, fb, pb), mm, d, &gradient, a, stop);
            }
            if a.alpha > stop {
                last.t = f64::NAN;
                return Flow::Stop;
            }
        }
        (sa, fa, pa) = (sb, fb, pb);
    }
    (last.t, last.v, last.p) = (v.t_exit, fa, pa);
    Flow::Continue
}

/// A chord of optical depth above `first` ([`first_depth`]), from `sa` to
/// `sb` along the segment (`mm` mm per unit), composited in value-linear
/// parts, each lit at its own middle. A part's colour error grows with
/// its depth and counts as much as the light left to it (the ray's
/// transmittance `T`), so each part ends where the chord's depth since
/// its start reaches `first / T` ([`PreTable::value_at`]): about
/// `1 / first` parts from clear to opaque (50 at the default), whatever
/// the extinction and however much of the chord is clear, where equal
/// parts of `first` take `ln(100) / first`. Ends once the ray is opaque
/// (`stop`).
#[cold]
#[allow(clippy::too_many_arguments)]
fn deep(
    table: &PreTable,
    (sa, fa, pa): (f64, f64, [f64; 4]),
    (sb, fb, pb): (f64, f64, [f64; 4]),
    mm: f64,
    first: f64,
    gradient: &dyn Fn(f64) -> Option<Vec3A>,
    a: &mut Acc,
    stop: f64,
) {
    // Depth per value unit along the chord: P[0] changes by `want / c`.
    let c = (sb - sa) * mm / (fb - fa);
    let up = fb > fa;
    let (mut x, mut px, mut s) = (fa, pa, sa);
    // From clear to opaque takes about 1 / first parts; a last one takes
    // what is left after 4096.
    for _ in 0..4096 {
        let want = first / (1.0 - a.alpha).max(1e-6);
        let y = table
            .value_at(px[0] + want / c, up)
            .filter(|&y| if up { y < fb } else { y > fb });
        let (y, py, s1) = match y {
            Some(y) if y != x => (y, table.integral(y), sa + (sb - sa) * (y - fa) / (fb - fa)),
            _ => (fb, pb, sb),
        };
        let e = table.chord(x, &px, y, &py, (s1 - s) * mm);
        a.add(e, gradient(0.5 * (s + s1)));
        if s1 == sb || a.alpha > stop {
            return;
        }
        (x, px, s) = (y, py, s1);
    }
    let e = table.chord(x, &px, fb, &pb, (sb - s) * mm);
    a.add(e, gradient(0.5 * (s + sb)));
}

/// The reference composite: per visit, `substeps` substeps per cell
/// width (the cell's narrowest edge) and at least as many as keep each
/// substep's change of value within `2/substeps` of the transfer
/// function's narrowest gap between points (at most 4096), the value at
/// each substep's middle
/// in f64 ([`CellEval`]), the transfer function evaluated exactly
/// ([`emission`]), the opacity `1 - exp(-tau h)`; shading and gradient
/// opacity as the segment integrator takes them; no early stop.
pub(super) fn reference<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    tf: &TransferFunction,
    substeps: u32,
    px: &mut Px,
) -> StepCounts {
    let mut a = Acc::new(ctx, ray);
    let gap = super::narrowest_gap(tf);
    let mm = ray.dir.length();
    let counts = walk_span(ctx, ray, span, acc, |v, acc| {
        let len = v.t_exit - v.t_enter;
        if !(len > 0.0) {
            return Flow::Continue;
        }
        let (b, l) = acc.brick(v.cell);
        let f = b.vertices(l);
        let ce = CellEval::new(ctx.coords, v.cell, f);
        let edge = ce.size.iter().copied().fold(f64::INFINITY, f64::min);
        // Substeps of at most 1/substeps of a cell width and of
        // 2/substeps of the function's narrowest gap in value (the
        // cubic's slope bounded over the segment), at most 4096 a
        // segment.
        let cub = Cubic::along(ctx.coords, &ctx.inv_size, v.cell, f, ray, v.t_enter);
        let [_, k1, k2, k3] = cub.k;
        let slope = k1.abs() + 2.0 * k2.abs() * len + 3.0 * k3.abs() * len * len;
        let by_value = slope * len / (gap * 2.0 / substeps as f64);
        let n = (substeps as f64 * len * mm / edge)
            .max(by_value)
            .ceil()
            .clamp(1.0, 4096.0);
        let h = len / n;
        let vg = (a.look.on && a.look.smooth).then(|| vertex_gradients(acc, ctx.coords, v.cell));
        for j in 0..n as u64 {
            let p = at(ray, v.t_enter + (j as f64 + 0.5) * h);
            let e = emission(tf, ce.value(p)).map(|x| x * h * mm);
            let g = match (&vg, a.look.on) {
                (Some(vg), _) => Some(vg.at(p)),
                (None, true) => Some(ce.gradient(p)),
                _ => None,
            }
            .map(|g| Vec3A::from(g.as_vec3()));
            a.add(e, g);
        }
        Flow::Continue
    });
    a.finish(px);
    counts
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn grid(n: usize, h: f64) -> Vec<f64> {
        (0..n).map(|i| i as f64 * h).collect()
    }

    /// The cubic equals the trilinear interpolant along oblique rays
    /// through cells of unequal sizes, and its interior maximum is the
    /// maximum of a dense sweep.
    #[test]
    fn cubic_is_the_interpolant_along_the_ray() {
        let (x, y, z) = (grid(3, 0.7), grid(3, 1.3), vec![0.0, 0.4, 2.1]);
        let coords = [&x[..], &y[..], &z[..]];
        let inv: [Vec<f64>; 3] =
            coords.map(|c| c.windows(2).map(|w| 1.0 / (w[1] - w[0])).collect());
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            let f: [f32; 8] = std::array::from_fn(|_| (rnd() * 2000.0 - 1000.0) as f32);
            let cell = [1, 0, 1];
            let ce = CellEval::new(coords, cell, f);
            let dir = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
            let inside = DVec3::new(0.7 + 0.7 * rnd(), 1.3 * rnd(), 0.4 + 1.7 * rnd());
            let ray = Ray {
                origin: inside - 3.0 * dir,
                dir,
            };
            // Entry and exit of the cell's box.
            let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
            for a in 0..3 {
                let (lo, hi) = (ce.lo[a], ce.lo[a] + ce.size[a]);
                let (u, w) = ((lo - ray.origin[a]) / dir[a], (hi - ray.origin[a]) / dir[a]);
                t0 = t0.max(u.min(w));
                t1 = t1.min(u.max(w));
            }
            let cub = Cubic::along(coords, &inv, cell, f, &ray, t0);
            let len = t1 - t0;
            let mut sweep = f64::NEG_INFINITY;
            for j in 0..=2000 {
                let s = len * j as f64 / 2000.0;
                let want = ce.value(at(&ray, t0 + s));
                assert!(
                    (cub.at(s) - want).abs() < 1e-9 * 1000.0,
                    "{} {}",
                    cub.at(s),
                    want
                );
                sweep = sweep.max(want);
            }
            let exact = cub.interior_max(len).max(cub.at(0.0)).max(cub.at(len));
            assert!(exact >= sweep - 1e-9 * 1000.0, "{exact} < {sweep}");
            // The sweep's spacing bounds how far below the true maximum
            // it may be.
            assert!(exact - sweep <= 1e-2, "{exact} far above {sweep}");
        }
    }

    /// Pieces keep the chord within the tolerance: the chord of each
    /// piece against a dense sweep of the cubic.
    #[test]
    fn pieces_bound_the_chord() {
        let cub = Cubic {
            k: [3.0, -40.0, 55.0, -18.0],
            u0: [0.0; 3],
            du: [0.0; 3],
        };
        let len = 1.7;
        for tol in [0.01, 0.1, 1.0] {
            let n = pieces(cub.curvature(len), len, tol);
            for i in 0..n {
                let (s0, s1) = (len * i as f64 / n as f64, len * (i + 1) as f64 / n as f64);
                let (a, b) = (cub.at(s0), cub.at(s1));
                for j in 0..=100 {
                    let x = j as f64 / 100.0;
                    let chord = a + x * (b - a);
                    let err = (cub.at(s0 + x * (s1 - s0)) - chord).abs();
                    assert!(err <= tol * (1.0 + 1e-9), "tol {tol}: {err}");
                }
            }
        }
    }
}
