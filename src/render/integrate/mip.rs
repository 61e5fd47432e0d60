//! MIP mode: the maximum of the interpolant at the face samples of the
//! 1-cells the ray crosses.

use super::{Ctx, Px};
use crate::render::cache::Accessor;
use crate::render::clock::Clock;
use crate::render::shade::{at, CellEval};
use crate::render::traverse::{trace, Flow, Ray, Real, StepCounts, Visit};

/// Writes the largest value along `ray` into `px.rgb` (uncoloured).
pub(super) fn mip<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    acc: &mut Accessor,
    clock: &mut Clock,
    px: &mut Px,
) -> StepCounts {
    let coords = ctx.coords;
    let mut best = f64::NEG_INFINITY;
    let counts = trace(ctx.grid, ray, 0.0, ctx.opts.method, acc, |v, acc| {
        clock.enter(acc);
        raise(&mut best, coords, ray, v, acc);
        clock.leave(acc);
        Flow::Continue
    });
    if best > f64::NEG_INFINITY {
        px.hit = true;
        px.rgb = [best as f32; 3];
    }
    counts
}

/// Raises `best` to the largest value of the interpolant of `v`'s cell
/// where the ray enters and leaves it.
fn raise(best: &mut f64, coords: [&[f64]; 3], ray: &Ray, v: &Visit, acc: &mut Accessor) {
    let (b, l) = acc.brick(v.cell);
    // The interpolant never exceeds the largest vertex value (NaN
    // vertices give NaN, which max ignores): a cell whose vertices are
    // all <= best cannot raise it. For 8- and 16-bit words, one lookup
    // (render/samples.rs); NaN, no bound, never skips.
    if b.vertex_top(l) as f64 <= *best {
        return;
    }
    let c = CellEval::new(coords, v.cell, b.vertices(l));
    *best = best
        .max(c.value(at(ray, v.t_enter)))
        .max(c.value(at(ray, v.t_exit)));
}
