//! Depth mode: the distance in mm to the first iso-surface hit (the
//! surface mode's [`first_hit`](super::surface::first_hit), unshaded).

use super::surface::first_hit;
use super::{Ctx, Px};
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::sample::hit::HitMethod;
use crate::render::traverse::{Ray, Real, StepCounts};

/// Writes the distance of `ray`'s first hit in `span` into `px` (NaN
/// stays on a miss); a cut face is a hit.
pub(super) fn depth<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    hit: HitMethod,
    px: &mut Px,
) -> StepCounts {
    let (found, counts) = first_hit(ctx, ray, span, hit, acc);
    if let Some((t, _)) = found {
        px.hit = true;
        px.depth = t as f32;
    }
    counts
}
