//! Surface mode: the first iso-surface hit (paper section 5.3), shaded by
//! the smooth gradient of [`gradient`](crate::render::sample::normals) or, with
//! `--normals cell`, the cell interpolant's own gradient; optional shadow
//! rays are traced by the same traversal. [`first_hit`] is shared with the
//! depth and cost modes. Hit refinement (Newton) and the shadow ray's
//! offset off the surface use the cell interpolant's gradient whatever the
//! normals, so hits and shadows are the same for both.

use glam::DVec3;

use super::{walk_span, Ctx, Px};
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::clock;
use crate::render::sample::hit::{find_hit_with, HitMethod};
use crate::render::sample::normals::{smooth_gradient_in, Normals};
use crate::render::sample::shade::{at, shade, CellEval};
use crate::render::traverse::{Flow, Ray, Real, StepCounts, Visit};

/// The first iso-surface hit along `ray` in `span`: `(t, cell values)`.
pub(super) fn first_hit<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    hit: HitMethod,
    acc: &mut Accessor,
) -> (Option<(f64, CellEval)>, StepCounts) {
    let (found, s) = first_hit_cell(ctx, ray, span, hit, acc);
    (found.map(|h| (h.t, h.c)), s)
}

/// A surface hit: where, the cell's interpolant and index, and whether it
/// is a cut face (the ray starts inside the object on a cut of the clip).
struct Hit {
    t: f64,
    c: CellEval,
    cell: [u32; 3],
    capped: bool,
}

/// Whether the first visit `v` (cut to `span`) starts on `span`'s cut:
/// its entry is the span's start (within the walk's rounding of it).
#[inline]
pub(super) fn on_cut(v: &Visit, span: &Span) -> bool {
    span.cut.is_some() && v.t_enter - span.start <= 1e-9 * span.start.abs().max(1.0)
}

/// [`first_hit`] with the hit cell's index. A ray that starts inside the
/// object on a cut hits the cut face there when the options cap; else it
/// goes on to the next surface it enters (as a shadow ray gets out first,
/// [`shadow_hit`]).
fn first_hit_cell<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    hit: HitMethod,
    acc: &mut Accessor,
) -> (Option<Hit>, StepCounts) {
    let coords = ctx.coords;
    // The hit's vertex values, not its `CellEval`: a small copy out of the
    // walk (the cell is evaluated again from them, to the same bits).
    let mut found = None;
    let mut first = true;
    // Inside the object from a cut, without capping: not out yet.
    let mut inside = false;
    let s = walk_span(ctx, ray, span, acc, |v, acc| {
        let starts_on_cut = std::mem::take(&mut first) && on_cut(v, span);
        clock::enter(acc);
        let f = acc.vertices(v.cell);
        let c = CellEval::new(coords, v.cell, f);
        if starts_on_cut && c.value(at(ray, v.t_enter)) >= ctx.iso {
            if ctx.opts.cap {
                clock::leave(acc);
                found = Some((v.t_enter, v.cell, f, true));
                return Flow::Stop;
            }
            inside = true;
        }
        if inside {
            // Out once the interpolant is below iso at the exit.
            inside = c.value(at(ray, v.t_exit)) >= ctx.iso;
            clock::leave(acc);
            return Flow::Continue;
        }
        let t_hit = find_hit_with(ray, v, &c, ctx.iso, hit, &ctx.opts.hit_params);
        clock::leave(acc);
        match t_hit {
            Some(t) => {
                found = Some((t, v.cell, f, false));
                Flow::Stop
            }
            None => Flow::Continue,
        }
    });
    let found = found.map(|(t, cell, f, capped)| Hit {
        t,
        c: CellEval::new(coords, cell, f),
        cell,
        capped,
    });
    (found, s)
}

/// Whether the shadow ray `ray`, which starts on (or a rounding error
/// inside) the surface it leaves, meets the iso-surface once it is out of
/// the object.
///
/// A hit lies only as close to the true surface as the hit method puts
/// it: `--hit int` interpolates linearly between the face samples, up to
/// a fraction of a cell off the trilinear surface, so a shadow ray from
/// there may start inside the object. Counted from its start, such a ray
/// "hits" the surface it leaves, and shadows speckle the lit side (shadow
/// acne). So the ray first has to get out: cells whose samples along the
/// ray are all `>= iso` are passed, and the cell in which the interpolant
/// falls below iso is left without a test; from then on the first cell
/// whose face samples reach iso (paper section 5.3, `Int`) shadows the
/// point. A point whose face is turned away from the light is drawn at
/// the ambient level, lit or not ([`shade`]), so a ray that goes through
/// the object changes nothing. Test: `shadow_acne` (an analytic sphere
/// over a plane, every hit method).
///
/// Only what the clip keeps casts shadows: the ray is walked in its own
/// kept interval.
fn shadow_hit<T: Real>(ctx: &Ctx<T>, ray: &Ray, acc: &mut Accessor) -> (bool, StepCounts) {
    let coords = ctx.coords;
    let Some(span) = ctx.clip.span(ray, 0.0) else {
        return (false, StepCounts::default());
    };
    let mut out = false;
    let mut hit = false;
    let s = walk_span(ctx, ray, &span, acc, |v, acc| {
        clock::enter(acc);
        let c = CellEval::new(coords, v.cell, acc.vertices(v.cell));
        let below = |t: f64| !(c.value(at(ray, t)) >= ctx.iso);
        if !out && below(v.t_enter) {
            out = true;
        }
        let flow = if out {
            hit =
                find_hit_with(ray, v, &c, ctx.iso, HitMethod::Int, &ctx.opts.hit_params).is_some();
            if hit {
                Flow::Stop
            } else {
                Flow::Continue
            }
        } else {
            // Still inside: out once the interpolant is below iso at the
            // exit; a re-entry within this same cell is not looked for.
            out = below(v.t_exit);
            Flow::Continue
        };
        clock::leave(acc);
        flow
    });
    (hit, s)
}

/// Shades the first hit of `ray` in `span` into `px`; with `shadows`, a
/// shadow ray towards a key light decides whether it is lit. A cut face is
/// shaded flat, by the cut's normal.
pub(super) fn surface<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    hit: HitMethod,
    shadows: bool,
    px: &mut Px,
) -> StepCounts {
    let (found, mut counts) = first_hit_cell(ctx, ray, span, hit, acc);
    let Some(Hit { t, c, cell, capped }) = found else {
        return counts;
    };
    px.hit = true;
    clock::enter(acc);
    let p = at(ray, t);
    let grad = match span.cut.filter(|_| capped) {
        // The shading takes a gradient, whose opposite is the outward
        // normal.
        Some(cut) => -cut,
        None => c.gradient(p),
    };
    let normal = match ctx.opts.normals {
        _ if capped => grad,
        Normals::Cell => grad,
        Normals::Smooth => {
            let s = smooth_gradient_in(acc, ctx.coords, cell, p, ctx.narrow);
            // A vertex without its own value (never in a 1-cell) or a
            // saturated sample: keep the cell's gradient.
            if s.is_finite() && s != DVec3::ZERO {
                s
            } else {
                grad
            }
        }
    };
    let to_eye = -ray.dir;
    let cam = ctx.camera;
    let to_light = if shadows {
        // A key light above and to the left of the viewer.
        let l = to_eye + 0.8 * cam.up - 0.6 * cam.right;
        l / l.length()
    } else {
        to_eye
    };
    clock::leave(acc);
    let mut lit = true;
    if shadows {
        // Shadow ray from just outside the surface, traced with the same
        // traversal, starting inside the volume.
        let gl = grad.length();
        let eps = 1e-3 * c.size.iter().cloned().fold(f64::INFINITY, f64::min);
        let out: DVec3 = if gl > 0.0 { -grad / gl } else { to_light };
        let sign = if out.dot(to_light) >= 0.0 { 1.0 } else { -1.0 };
        let sray = Ray {
            origin: p + sign * eps * out + eps * to_light,
            dir: to_light,
        };
        let (sh, s2) = shadow_hit(ctx, &sray, acc);
        counts.add(&s2);
        lit = !sh;
    }
    let v = shade(normal, to_light, to_eye, lit) as f32;
    px.rgb = match ctx.opts.cap_colours.as_ref().filter(|_| capped) {
        // A cut face in the colour of its data value (the cells hold
        // rescaled values, the transfer function's units).
        Some(tf) => tf.colour(c.value(p)).map(|k| v * k as f32),
        None => [v, v, v],
    };
    px.depth = t as f32;
    counts
}
