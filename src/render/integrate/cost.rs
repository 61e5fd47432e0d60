//! Cost mode (paper Fig. 17): the traversal steps a ray needs to find the
//! surface, or to leave the volume on a miss; on files classified by a
//! transfer function, the steps to the first 1-cell.

use super::surface::first_hit;
use super::{Ctx, Px};
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::sample::hit::HitMethod;
use crate::render::traverse::{trace, Flow, Ray, Real, StepCounts};

/// The steps of `ray`; `px.hit` says whether it found the surface.
pub(super) fn cost<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    acc: &mut Accessor,
    px: &mut Px,
) -> StepCounts {
    if ctx.iso.is_nan() {
        trace(ctx.grid, ray, 0.0, ctx.opts.method, acc, |_, _| Flow::Stop)
    } else {
        let (found, counts) = first_hit(ctx, ray, &Span::from(0.0), HitMethod::Int, acc);
        px.hit = found.is_some();
        counts
    }
}
