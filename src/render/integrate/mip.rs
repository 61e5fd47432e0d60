//! MIP mode: the maximum of the interpolant at the face samples of the
//! 1-cells the ray crosses.
//!
//! Where a visit enters through the face the previous visit left by (a
//! single-cell step between two 1-cells: the same `t`), its entry sample is
//! that face's exit sample, already taken or already bounded: the
//! trilinear interpolants of two cells agree on their shared face, so only
//! the exit is evaluated. Every exact traversal yields the same visits
//! with the same `t` (module traverse), so every traversal shares the same
//! faces and draws the same image.

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
    let mut m = Max::default();
    let counts = trace(ctx.grid, ray, 0.0, ctx.opts.method, acc, |v, acc| {
        clock.enter(acc);
        m.raise(coords, ray, v, acc);
        clock.leave(acc);
        Flow::Continue
    });
    if m.best > f64::NEG_INFINITY {
        px.hit = true;
        px.rgb = [m.best as f32; 3];
    }
    counts
}

/// The ray's maximum so far and the face the last visit left by.
struct Max {
    best: f64,
    /// `t_exit` of the last visit when the value there is known to be at
    /// most `best` (evaluated and not NaN, or bounded by the cell's
    /// vertices); NaN otherwise, which no `t_enter` equals.
    covered_exit: f64,
}

impl Default for Max {
    fn default() -> Max {
        Max {
            best: f64::NEG_INFINITY,
            covered_exit: f64::NAN,
        }
    }
}

impl Max {
    /// Raises `best` to the largest value of the interpolant of `v`'s cell
    /// where the ray enters and leaves it; the entry is skipped when it is
    /// the face the last visit left by and that face is covered.
    #[inline]
    fn raise(&mut self, coords: [&[f64]; 3], ray: &Ray, v: &Visit, acc: &mut Accessor) {
        let shared = v.t_enter == self.covered_exit;
        let (b, l) = acc.brick(v.cell);
        // The interpolant never exceeds the largest vertex value (NaN
        // vertices give NaN, which max ignores): a cell whose vertices are
        // all <= best cannot raise it. For 8- and 16-bit words, one lookup
        // (render/samples.rs); NaN, no bound, never skips.
        if b.vertex_top(l) as f64 <= self.best {
            self.covered_exit = v.t_exit;
            return;
        }
        let c = CellEval::new(coords, v.cell, b.vertices(l));
        if !shared {
            self.best = self.best.max(c.value(at(ray, v.t_enter)));
        }
        let exit = c.value(at(ray, v.t_exit));
        self.best = self.best.max(exit);
        self.covered_exit = if exit.is_nan() { f64::NAN } else { v.t_exit };
    }
}
