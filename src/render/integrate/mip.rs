//! MIP mode: the maximum of the interpolant along the ray over the
//! 1-cells it crosses: exactly (`--integrate segment`, the default: the
//! maximum of each cell's cubic along the ray, [`Cubic`], at the segment's
//! ends and the real roots of its derivative), or at the face samples
//! only (`--integrate step`, which misses peaks inside cells).
//!
//! Where a visit enters through the face the previous visit left by (a
//! single-cell step between two 1-cells: the same `t`), its entry sample is
//! that face's exit sample, already taken or already bounded: the
//! trilinear interpolants of two cells agree on their shared face, so only
//! the exit is evaluated. Every exact traversal yields the same visits
//! with the same `t` (module traverse), so every traversal shares the same
//! faces and draws the same image.
//!
//! A cell that cannot raise the ray's maximum also tells CD and the octree
//! to leap out of the largest node around it, up to the brick, whose
//! vertices cannot either (`Flow::LeapNode`, the bricks' max pyramid): the
//! cells skipped could not have changed the maximum, so the image is the
//! one FVT, which steps through them, draws.

use super::segment::Cubic;
use super::{walk_span, Ctx, Px};
use crate::render::brick::BLOCK;
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::clock;
use crate::render::sample::shade::{at, CellEval};
use crate::render::traverse::{Flow, Method, Ray, Real, StepCounts, Visit};

/// Writes the largest value along `ray` in `span` into `px.rgb`
/// (uncoloured): the visits cut to the span, their samples at its ends,
/// and with `exact` each cell's maximum between them.
pub(super) fn mip<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    exact: bool,
    px: &mut Px,
) -> StepCounts {
    let mut m = Max::default();
    let leaps = block_leaps(ctx.opts.method, acc.brick_size());
    let counts = walk_span(ctx, ray, span, acc, |v, acc| {
        clock::enter(acc);
        let flow = if exact {
            m.raise::<true, T>(ctx, ray, v, acc, leaps)
        } else {
            m.raise::<false, T>(ctx, ray, v, acc, leaps)
        };
        clock::leave(acc);
        flow
    });
    if m.best > f64::NEG_INFINITY {
        px.hit = true;
        px.rgb = [m.best as f32; 3];
    }
    counts
}

/// Whether a MIP with `method` on bricks of `brick_size` cells leaps out of
/// nodes whose maximum cannot raise the ray's: the cell-stepping leaps of
/// CD and the octree (FVT stays the single-cell walk it is measured as),
/// and only where the bricks' blocks are the grid's aligned nodes of
/// [`BLOCK`] cells (bricks start at multiples of their size).
fn block_leaps(method: Method, brick_size: u32) -> bool {
    leaps_with(method) && brick_size.is_multiple_of(BLOCK)
}

/// Whether a MIP with `method` leaps out of nodes of the bricks' max
/// pyramid: CD and the octree, whose walkers leap; so the cache builds
/// the pyramid for those only (render/integrate/policy.rs).
pub(crate) fn leaps_with(method: Method) -> bool {
    matches!(
        method,
        Method::Cd { .. } | Method::CdAniso { .. } | Method::Octree
    )
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
    ///
    /// With `leaps`, at a cell that cannot raise `best`, the walk is told
    /// to leap out of the largest node of the brick's max pyramid
    /// ([`RBrick::node_below`](crate::render::brick::RBrick::node_below))
    /// whose largest vertex value is at most `best`: no value the
    /// interpolant takes in the node's cells can raise `best`, so the
    /// maximum is the same with or without them.
    ///
    /// With `EXACT`, a cell whose largest vertex value is above the new
    /// `best` also raises it to its cubic's largest value between entry
    /// and exit ([`Cubic::interior_max`]).
    #[inline]
    fn raise<const EXACT: bool, T: Real>(
        &mut self,
        ctx: &Ctx<T>,
        ray: &Ray,
        v: &Visit,
        acc: &mut Accessor,
        leaps: bool,
    ) -> Flow {
        let coords = ctx.coords;
        let shared = v.t_enter == self.covered_exit;
        let (b, l) = acc.brick(v.cell);
        // The interpolant never exceeds the largest vertex value (NaN
        // vertices give NaN, which max ignores): a cell whose vertices are
        // all <= best cannot raise it. For 8- and 16-bit words, one lookup
        // (render/brick/samples.rs); NaN, no bound, never skips.
        if b.vertex_top(l) as f64 <= self.best {
            if leaps {
                if let Some(level) = b.node_below(l, self.best) {
                    // Where the leap lands is not known here: no face is
                    // covered.
                    self.covered_exit = f64::NAN;
                    return Flow::LeapNode(level);
                }
            }
            self.covered_exit = v.t_exit;
            return Flow::Continue;
        }
        let top = b.vertex_top(l) as f64;
        let f = b.vertices(l);
        let c = CellEval::new(coords, v.cell, f);
        if !shared {
            self.best = self.best.max(c.value(at(ray, v.t_enter)));
        }
        let exit = c.value(at(ray, v.t_exit));
        self.best = self.best.max(exit);
        // A peak inside the cell can only be above the ends when a vertex
        // is (the interpolant never exceeds its largest vertex).
        if EXACT && top > self.best {
            let cub = Cubic::along(coords, &ctx.inv_size, v.cell, f, ray, v.t_enter);
            self.best = self.best.max(cub.interior_max(v.t_exit - v.t_enter));
        }
        self.covered_exit = if exit.is_nan() { f64::NAN } else { v.t_exit };
        Flow::Continue
    }
}

/// The reference MIP: per visit, the interpolant in f64 at `substeps`
/// points per cell width (the cell's narrowest edge) and at both ends;
/// no cell skipped.
pub(super) fn reference<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    substeps: u32,
    px: &mut Px,
) -> StepCounts {
    let mut best = f64::NEG_INFINITY;
    let mm = ray.dir.length();
    let counts = walk_span(ctx, ray, span, acc, |v, acc| {
        let (b, l) = acc.brick(v.cell);
        let c = CellEval::new(ctx.coords, v.cell, b.vertices(l));
        let len = v.t_exit - v.t_enter;
        let edge = c.size.iter().copied().fold(f64::INFINITY, f64::min);
        let n = (substeps as f64 * len * mm / edge).ceil().max(1.0) as u64;
        for j in 0..=n {
            let t = v.t_enter + len * j as f64 / n as f64;
            best = best.max(c.value(at(ray, t)));
        }
        Flow::Continue
    });
    if best > f64::NEG_INFINITY {
        px.hit = true;
        px.rgb = [best as f32; 3];
    }
    counts
}
