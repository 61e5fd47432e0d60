//! Integrators: what one pixel's ray gathers from the cells the traversal
//! reports, one file per [`Mode`]. Each is a closure over
//! [`trace`](super::traverse::trace)'s visits (paper section 4: the
//! traversal only decides which cells; sampling, hits and shading are
//! shared in shade.rs, so every traversal integrates the same cells the
//! same way).
//!
//! ```text
//! tiles.rs (a ray per pixel) -> pixel (here) -> surface | depth | mip
//!                                               | composite | cost -> Px
//! ```

mod composite;
mod cost;
mod depth;
mod mip;
mod surface;

use super::cache::Accessor;
use super::camera::Camera;
use super::lut::TfLut;
use super::options::{Mode, RenderOptions};
use super::traverse::{Ray, Real, StepCounts, TGrid};

/// Per-pixel result before colouring (image.rs colours it; part files
/// store it).
#[derive(Clone, Copy, Default, Debug, PartialEq)]
pub struct Px {
    pub(crate) rgb: [f32; 3],
    pub(crate) depth: f32,
    pub(crate) steps: u32,
    pub(crate) hit: bool,
}

/// What every integrator reads: the grid in the traversal's arithmetic,
/// the sample positions, the camera, the options and the file's iso value.
pub(crate) struct Ctx<'a, T> {
    pub(crate) grid: &'a TGrid<T>,
    /// Sample positions in f64 for hits and shading.
    pub(crate) coords: [&'a [f64]; 3],
    pub(crate) camera: &'a Camera,
    pub(crate) opts: &'a RenderOptions,
    /// The file's iso value as stored (NaN for files classified by a
    /// transfer function).
    pub(crate) iso: f64,
    /// The composite mode's transfer function, tabulated for its step.
    pub(crate) lut: Option<TfLut>,
}

/// The pixel of `ray`: the mode's integrator, then its step count.
pub(crate) fn pixel<T: Real>(ctx: &Ctx<T>, ray: &Ray, acc: &mut Accessor) -> (Px, StepCounts) {
    let mut px = Px {
        depth: f32::NAN,
        ..Px::default()
    };
    let counts = match &ctx.opts.mode {
        Mode::Surface { hit, shadows } => surface::surface(ctx, ray, acc, *hit, *shadows, &mut px),
        Mode::Depth { hit } => depth::depth(ctx, ray, acc, *hit, &mut px),
        Mode::Mip => mip::mip(ctx, ray, acc, &mut px),
        Mode::Cost => cost::cost(ctx, ray, acc, &mut px),
        Mode::Composite { step_mm, .. } => {
            let lut = ctx.lut.as_ref().expect("composite renders carry a table");
            composite::composite(ctx, ray, acc, lut, *step_mm, &mut px)
        }
    };
    px.steps = counts.steps.min(u32::MAX as u64) as u32;
    (px, counts)
}
