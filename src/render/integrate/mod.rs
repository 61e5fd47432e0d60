//! Integrators: what one pixel's ray gathers from the cells the traversal
//! reports, one file per [`Mode`]. Each is a closure over
//! [`trace`](crate::render::traverse::trace)'s visits (paper section 4: the
//! traversal only decides which cells; sampling, hits and shading are
//! shared in `sample/`, so every traversal integrates the same cells the
//! same way).
//!
//! ```text
//! job/tiles.rs (a ray per pixel) -> pixel (here) -> surface | depth | mip
//!                                               | composite | cost -> Px
//! ```

mod batch;
mod composite;
mod cost;
mod depth;
mod index_map;
mod labels;
mod mip;
pub(crate) mod policy;
mod refine;
mod sample;
mod segment;
mod surface;

pub(crate) use mip::leaps_with as mip_leaps_with;

use crate::render::cache::{Accessor, LAZY_MIN_CODE_CD};
use crate::render::clip::{Clip, Cut, Span};
use crate::render::options::{Integrate, Mode, Precision, RenderOptions};
use crate::render::sample::lut::TfLut;
use crate::render::sample::pretable::PreTable;
use crate::render::traverse::{trace_until, Flow, Ray, Real, StepCounts, TGrid, Visit};
use crate::render::view::camera::Camera;

/// Per-pixel result before colouring (image.rs colours it; part files
/// store it).
#[derive(Clone, Copy, Default, Debug, PartialEq)]
pub struct Px {
    /// Colour, premultiplied by `alpha` (composite: composited over
    /// black).
    pub(crate) rgb: [f32; 3],
    /// Coverage in [0, 1]: the composite's opacity, else 1 on a hit and 0
    /// on a miss (the output's background shows through the rest).
    pub(crate) alpha: f32,
    pub(crate) depth: f32,
    pub(crate) steps: u32,
    pub(crate) hit: bool,
}

impl Px {
    /// The pixel of a ray that meets no 1-cell, as every integrator but
    /// the cost map draws it (no hit, no colour, no depth) and as a culled
    /// pixel is drawn without a ray (render/view/cull.rs).
    pub(crate) const MISS: Px = Px {
        rgb: [0.0; 3],
        alpha: 0.0,
        depth: f32::NAN,
        steps: 0,
        hit: false,
    };

    /// Whether this is [`Px::MISS`] bit for bit (any NaN depth): a pixel
    /// every colouring but the cost map's draws as zeros.
    #[inline]
    pub(crate) fn is_miss(&self) -> bool {
        self.rgb.map(f32::to_bits) == [0; 3]
            && self.alpha.to_bits() == 0
            && self.depth.is_nan()
            && self.steps == 0
            && !self.hit
    }
}

/// What every integrator reads: the grid in the traversal's arithmetic,
/// the sample positions, the camera, the options and the file's iso value.
pub(crate) struct Ctx<'a, T> {
    pub(crate) grid: &'a TGrid<T>,
    /// Sample positions in f64 for hits and shading.
    pub(crate) coords: [&'a [f64]; 3],
    pub(crate) camera: &'a Camera,
    pub(crate) opts: &'a RenderOptions,
    /// The scene's iso value as stored values compare
    /// ([`scene_iso`](crate::render::options::scene_iso): `--iso` or the file's;
    /// NaN for files classified by a transfer function without `--iso`).
    pub(crate) iso: f64,
    /// The iso value smooth normals judge missing samples by when the
    /// scene is narrower than the file ([`scene_code_at_least_1`](crate::render::sample::normals::scene_code_at_least_1));
    /// `None` otherwise and in `--gradient-halo` files.
    pub(crate) narrow: Option<f32>,
    /// The composite mode's transfer function, tabulated for its step.
    pub(crate) lut: Option<TfLut>,
    /// The segment composite's extinction integral table, its tolerance
    /// in value units ([`Integrate::Segment`]'s `tol` times the transfer
    /// function's narrowest gap between points) and the optical depth of
    /// a first part of a deep chord ([`segment::first_depth`]).
    pub(crate) pre: Option<(PreTable, f64, f64)>,
    /// The composite mode's ramps out of transparency, where the lattice
    /// restarts (refine.rs).
    pub(crate) ramps: Option<refine::Ramps>,
    /// `1 / (S[i + 1] - S[i])` per axis and cell: the samplers' local
    /// coordinates by multiplication.
    pub(crate) inv_size: [Vec<f64>; 3],
    /// Whether the tiles' accessors remember smooth-normal gradients per
    /// cell ([`Accessor::remember_gradients`]): when rays are dense
    /// enough to meet a cell more than once ([`rays_meet_cells_again`]).
    pub(crate) memo_gradients: bool,
    /// The stand-in threshold of this frame's CD walks:
    /// [`RenderOptions::cd_lazy_min`], or [`lazy_min_for`] the camera.
    pub(crate) lazy_min: u8,
    /// Where the composite takes its samples in batches
    /// ([`RenderOptions::sample_batches`]): the grid's map from positions
    /// to cells (batch.rs).
    pub(crate) index_map: Option<index_map::IndexMap>,
    /// The options' crop box and planes on this volume
    /// ([`Clip::within`]: faces that cut nothing dropped).
    pub(crate) clip: Clip,
}

/// Whether neighbouring rays of `camera` meet the same cells often enough
/// for the per-cell memo of smooth-normal gradients to pay: the finest
/// mean spacing of the volume's axes is at least [`MEMO_MIN_PIXELS`]
/// pixels wide where the rays cross the volume (its centre, for a
/// perspective view). With sparser rays a cell is met about once, and
/// the memo only adds its lookups and pages (docs/BENCHMARKS.md, "Vertex
/// gradients remembered"; docs/DECISIONS.md, "The smooth-normal memo
/// where rays are sparse too").
pub(crate) fn rays_meet_cells_again(h: &crate::format::Header, camera: &Camera) -> bool {
    finest_spacing(h) >= MEMO_MIN_PIXELS * pixel_mm(h, camera)
}

/// See [`rays_meet_cells_again`].
pub(crate) const MEMO_MIN_PIXELS: f64 = 1.5;

/// The smallest code from which CD stands a brick without 1-cells in by
/// that code instead of reading it (`--cd-lazy-min`), when the options
/// leave it to the render: [`LAZY_MIN_CODE_CD`] where a brick spans at
/// least [`LAZY_DENSE_PIXELS`] pixels of the image (its edge at the finest
/// mean spacing, where the rays cross the volume: at its centre for a
/// perspective view, as the smooth normals' memo judges density), else
/// [`LAZY_MIN_CODE_SPARSE`].
///
/// Reading a brick costs the same whatever the image (about 0.1 ms to
/// decode 32^3 cells); its own codes, larger than the stand-in's, save
/// steps on every ray that crosses it, and the rays crossing a brick grow
/// with the square of its width in pixels. So dense rays (the real CT at
/// 1024^2, where a brick of 32 cells spans more than 64 pixels) read the
/// bricks whose smallest code is below 16, and sparse ones (the 1024^3
/// phantom at 1024^2) read only those below 4: there 31 % fewer bricks
/// and 13-19 % off the first frame, with the warm frame unchanged
/// (docs/BENCHMARKS.md, "The stand-in threshold by ray density"). The
/// images are the same either way: a stand-in is exact (traverse tests,
/// `lazy`).
pub fn lazy_min_for(h: &crate::format::Header, camera: &Camera) -> u8 {
    let brick_px = h.brick_size as f64 * finest_spacing(h) / pixel_mm(h, camera);
    if brick_px >= LAZY_DENSE_PIXELS {
        LAZY_MIN_CODE_CD
    } else {
        LAZY_MIN_CODE_SPARSE
    }
}

/// See [`lazy_min_for`].
pub const LAZY_DENSE_PIXELS: f64 = 64.0;
/// See [`lazy_min_for`].
pub const LAZY_MIN_CODE_SPARSE: u8 = 4;

/// The finest mean sample spacing of `h`'s axes, in mm.
fn finest_spacing(h: &crate::format::Header) -> f64 {
    h.axes
        .iter()
        .map(|a| {
            let c = a.coords();
            (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64
        })
        .fold(f64::INFINITY, f64::min)
}

/// The width of a pixel of `camera` in mm where its rays cross `h`'s
/// volume (at the volume's centre, for a perspective view).
fn pixel_mm(h: &crate::format::Header, camera: &Camera) -> f64 {
    use crate::render::view::camera::Projection;
    let centre = glam::DVec3::from_array(std::array::from_fn(|k| {
        let c = h.axes[k].coords();
        0.5 * (c[0] + c[c.len() - 1])
    }));
    let frame_mm = match camera.projection {
        Projection::Ortho { frame_mm } => frame_mm,
        Projection::Persp { fov_deg } => {
            2.0 * (0.5 * fov_deg).to_radians().tan() * (centre - camera.eye).length()
        }
    };
    frame_mm / camera.height.max(1) as f64
}

impl<'a, T: Real> Ctx<'a, T> {
    /// The context of a render of `h`'s volume: the iso value mapped like
    /// the stored values ([`to_f32`](crate::render::brick::to_f32)), the composite
    /// table for the mode's step, the cells' inverse sizes.
    pub(crate) fn new(
        grid: &'a TGrid<T>,
        h: &'a crate::format::Header,
        camera: &'a Camera,
        opts: &'a RenderOptions,
    ) -> Ctx<'a, T> {
        let coords = [h.axes[0].coords(), h.axes[1].coords(), h.axes[2].coords()];
        Ctx {
            grid,
            coords,
            camera,
            opts,
            iso: crate::render::options::scene_iso(h, opts),
            narrow: crate::render::options::narrowing(h, opts).filter(|_| !h.gradient_halo),
            lut: match &opts.mode {
                Mode::Composite { tf, step_mm } => Some(TfLut::new(tf, *step_mm)),
                _ => None,
            },
            pre: match (&opts.mode, opts.integrate) {
                (Mode::Composite { tf, .. }, Integrate::Segment { tol }) => Some((
                    PreTable::new(tf),
                    tol * narrowest_gap(tf),
                    segment::first_depth(tol),
                )),
                _ => None,
            },
            ramps: match &opts.mode {
                Mode::Composite { tf, step_mm } => Some(refine::Ramps::new(tf, *step_mm)),
                _ => None,
            },
            inv_size: coords.map(|c| c.windows(2).map(|w| 1.0 / (w[1] - w[0])).collect()),
            memo_gradients: rays_meet_cells_again(h, camera),
            lazy_min: opts.cd_lazy_min.unwrap_or_else(|| lazy_min_for(h, camera)),
            index_map: if opts.sample_batches && matches!(opts.mode, Mode::Composite { .. }) {
                index_map::IndexMap::of(coords, std::array::from_fn(|k| h.axes[k].is_uniform()))
            } else {
                None
            },
            clip: opts
                .clip
                .within(coords.map(|c| c[0]), coords.map(|c| c[c.len() - 1])),
        }
    }
}

/// Walks `ray` over `span` with the options' traversal, handing `visit`
/// each 1-cell's visit cut to the span ([`Span::cut`]); the walk ends at
/// the span's end ([`trace_until`]).
pub(crate) fn walk_span<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    mut visit: impl FnMut(&Visit, &mut Accessor) -> Flow,
) -> StepCounts {
    let (start, end) = (span.start, span.end);
    trace_until(
        ctx.grid,
        ray,
        start,
        end,
        ctx.opts.method,
        acc,
        |v, acc| match span.cut(v) {
            Cut::Kept(v) => visit(&v, acc),
            Cut::Empty => Flow::Continue,
            Cut::Past => Flow::Stop,
        },
    )
}

/// The pixel of `ray`: the mode's integrator, then its step count. The
/// ray is traced from `t_start` (at least 0), before which it meets no
/// 1-cell ([`Cover::start`](crate::render::view::cull::Cover::start)),
/// over the interval the clip keeps ([`Clip::span`]): a ray it keeps none
/// of is a miss without a walk. The cost map traces from 0 and ignores the
/// clip, as it shows what the whole traversal costs.
///
/// The walk also ends at `t_end` (an overlay's first label hit,
/// [`RenderOptions::overlay`]; infinite without one).
pub(crate) fn pixel_until<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    t_start: f64,
    t_end: f64,
    acc: &mut Accessor,
) -> (Px, StepCounts) {
    let mut px = Px {
        depth: f32::NAN,
        ..Px::default()
    };
    let mut span = match &ctx.opts.mode {
        Mode::Cost => Span::from(0.0),
        _ if ctx.clip.is_none() => Span::from(t_start),
        _ => match ctx.clip.span(ray, t_start) {
            Some(s) => s,
            None => return (Px::MISS, StepCounts::default()),
        },
    };
    if t_end < span.end {
        if !(t_end > span.start) {
            return (Px::MISS, StepCounts::default());
        }
        span.end = t_end;
    }
    let span = &span;
    let counts = match &ctx.opts.mode {
        Mode::Surface { hit, shadows } => {
            surface::surface(ctx, ray, span, acc, *hit, *shadows, &mut px)
        }
        Mode::Depth { hit } => depth::depth(ctx, ray, span, acc, *hit, &mut px),
        Mode::Labels { hit, style } => labels::labels(ctx, ray, span, acc, *hit, style, &mut px),
        Mode::Mip => match ctx.opts.integrate {
            Integrate::Step => mip::mip(ctx, ray, span, acc, false, &mut px),
            Integrate::Segment { .. } => mip::mip(ctx, ray, span, acc, true, &mut px),
            Integrate::Reference { substeps } => {
                mip::reference(ctx, ray, span, acc, substeps, &mut px)
            }
        },
        Mode::Cost => cost::cost(ctx, ray, acc, &mut px),
        Mode::Composite { tf, .. } if ctx.opts.integrate != Integrate::Step => {
            match (ctx.opts.integrate, &ctx.pre) {
                (Integrate::Reference { substeps }, _) => {
                    segment::reference(ctx, ray, span, acc, tf, substeps, &mut px)
                }
                (_, Some((table, tol, depth))) => {
                    let limits = segment::Limits {
                        tol: *tol,
                        depth: *depth,
                    };
                    segment::composite(ctx, ray, span, acc, table, limits, &mut px)
                }
                _ => unreachable!("segment composites carry their table"),
            }
        }
        Mode::Composite { step_mm, .. } => {
            let lut = ctx.lut.as_ref().expect("composite renders carry a table");
            match ctx.opts.sampling {
                Precision::F32 => {
                    composite::composite32(ctx, ray, span, acc, lut, *step_mm, &mut px)
                }
                Precision::F64 => composite::composite(ctx, ray, span, acc, lut, *step_mm, &mut px),
            }
        }
    };
    if !matches!(ctx.opts.mode, Mode::Composite { .. } | Mode::Labels { .. }) {
        px.alpha = if px.hit { 1.0 } else { 0.0 };
    }
    px.steps = counts.steps.min(u32::MAX as u64) as u32;
    (px, counts)
}

/// The narrowest gap between `tf`'s points in value units (the value
/// span, or 1, for fewer than two points): the scale of the segment
/// integrator's tolerance.
pub(crate) fn narrowest_gap(tf: &crate::classify::TransferFunction) -> f64 {
    let g = tf
        .points
        .windows(2)
        .map(|w| w[1].value - w[0].value)
        .fold(f64::INFINITY, f64::min);
    if g.is_finite() && g > 0.0 {
        g
    } else {
        1.0
    }
}

/// `front` (a scan's pixel over the interval before the label hit) over
/// `back` (the labels' pixel): colours premultiplied, so `front + (1 -
/// its alpha) * back`; the nearer depth, the summed steps.
pub(crate) fn over(front: Px, back: Px) -> Px {
    if back.is_miss() {
        return front;
    }
    let k = 1.0 - front.alpha;
    Px {
        rgb: std::array::from_fn(|i| front.rgb[i] + k * back.rgb[i]),
        alpha: front.alpha + k * back.alpha,
        depth: if front.hit { front.depth } else { back.depth },
        steps: front.steps.saturating_add(back.steps),
        hit: front.hit || back.hit,
    }
}
