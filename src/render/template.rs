//! Template-based CD ray generation (paper section 4.2.2, after Yagel and
//! Kaufman's ray templates \[28\] with 26-connected templates \[29\]).
//!
//! # What is computed
//!
//! Under parallel projection every ray has the same direction. In *index
//! space* (a point's coordinate along axis `k` measured in cells,
//! `u_k = (x_k - lo_k) / h_k`) the direction is `r_k = d_k / h_k`. The
//! *major axis* `m` is the one with the largest `|r_k|`; the *base plane*
//! is the face of the volume perpendicular to `m` that the rays enter
//! first. Axes with `r_k < 0` are mirrored (`c' = n_k - 1 - c`, as in
//! traverse.rs), so in the walk's frame every offset is non-negative.
//!
//! The *template* is the 26-connected discrete line with exactly one cell
//! per step along `m`: for step `s` (`0 <= s < n_m`) the ray from the
//! centre of a base-plane cell has advanced `s + 1/2` cells along `m` (the
//! middle of slab `s`) and `(s + 1/2) * sigma_k` cells along minor axis
//! `k`, `sigma_k = |r_k| / |r_m|` in `[0, 1]`; the template's offset is
//! that position rounded to the nearest cell centre, ties down:
//! `o_k(s) = ceil((s + 1/2) sigma_k - 1/2)`. So the template cell of step
//! `s` is the cell containing the ray's point at the middle of slab `s`,
//! consecutive entries differ by exactly 1 along `m` and by 0 or 1 along
//! the minor axes, and each is within half a cell of the true line. It is
//! computed once per image ([`Template::new`]).
//!
//! One ray starts at the centre of every base-plane cell `(i, j)`; the
//! base plane is extended beyond the volume's face by the template's total
//! minor drift, so that every part of the volume is covered (rays from the
//! extension enter the volume through a side face). The ray from start
//! cell `c0` visits the cells `c0 + o(s)` for the entries `s` that lie
//! inside the volume (an interval of `s`, found by binary search, as each
//! offset is monotone).
//!
//! **CD leap.** At a 0-cell with chessboard code `n` (the cube of radius
//! `n` around the cell holds no 1-cell) the walk skips `n` entries: entries
//! `s + 1 ..= s + n` are at chessboard distance at most `n` from entry `s`
//! (every step changes every coordinate by at most one), so they are all
//! 0-cells, and the next entry read is `s + n + 1`, one array increment
//! (paper: "increment of the actual template voxel coordinate by n").
//! [`walk`] with leaps yields exactly the 1-cells the single-step template
//! walk yields (tests/all/template.rs checks this by property test).
//!
//! **Hit test.** At a 1-cell the hit is searched along the *true* ray of
//! that base-plane cell (origin at the start cell's centre on the base
//! plane, the camera's direction) between its entry into and exit from
//! the cell's box (the slab test, in mm), with the renderer's
//! [`find_hit_with`], so hits are found exactly as [`super::render`] finds
//! them. The true ray always passes through a template cell (the cell
//! contains the ray's point at the middle of its slab), so the interval is
//! never empty.
//!
//! **Gap refinement** ([`TemplateOptions::refine`], on by default). When
//! the template's hit cell is entered already inside the surface (the hit
//! is at its entry), the interpolant, continuous across cells, crossed iso
//! after the previous template entry's cell, whose values along the ray
//! were all below iso: in cells the template skipped (see the error
//! section). The refinement walks the true ray cell by cell ([`trace`]
//! with FVT) from the previous entry's exit to the hit and takes the first
//! hit there, so the depth is the one FVT finds. Its steps are counted as
//! single-cell steps. Without it, such hits are late by up to the skipped
//! cells' length along the ray (half of every slab on an exact diagonal).
//!
//! # The intermediate image and the warp
//!
//! The walk fills a distorted *intermediate image*, one pixel per
//! (extended) base-plane cell: hit or miss, `t` of the hit along that ray
//! (mm from the base plane), the interpolant's gradient at the hit, and
//! the traversal steps. Each final pixel's ray (parallel to the template
//! rays) meets the base plane at `p`, at `t = t_b` along it. With
//! [`Warp::Nearest`], the pixel takes the intermediate sample whose start
//! point is nearest to `p` (the cell of the base plane containing `p`):
//! hit or miss, steps, gradient as they are, and depth `t_b + t_i`, i.e.
//! the surface is assumed to be the same at `p` as at the sample's start
//! point, shifted along the base plane by at most half a cell per minor
//! axis. With [`Warp::Bilinear`] (the default of [`render_template`]) hit
//! or miss, steps and cost still come from the nearest sample, but depth
//! `t_i` and gradient are interpolated bilinearly from the four samples
//! around `p` when all four hit and their `t_i` lie within two cell
//! diagonals (`2 |h|`) of each other (no blending across silhouettes);
//! otherwise as [`Warp::Nearest`].
//!
//! # Error against the 6-connected walk (FVT)
//!
//! 1. **26-connected gaps.** The template visits one cell per slab of the
//!    major axis. The true ray also passes through the cells where it
//!    crosses a minor-axis boundary *between* two slab middles (a
//!    6-connected walk, FVT, visits them); the template skips those. A
//!    surface that the ray meets only inside such a skipped cell is found
//!    later, in a following template cell (the gap refinement recovers the
//!    crossing when that cell is entered inside the surface), or not at all
//!    (the ray grazes the surface through skipped cells only). tests/all/template.rs
//!    counts the FVT 1-cell visits the template skips on random volumes and
//!    the pixels whose hit/miss or depth differs from [`super::render`] on
//!    a sphere phantom.
//! 2. **Warp.** The final pixel does not trace its own ray: hit/miss comes
//!    from a ray up to half a cell away (per minor axis, in the base plane),
//!    so silhouettes are resampled at the base-plane cell size, and the depth
//!    is the neighbouring rays' (interpolated, or shifted for nearest), off
//!    by up to the surface's slope times half a cell.
//!
//! # Measured
//!
//! tests/all/template.rs, sphere phantom (48^3, cubic and 0.8 x 1 x 1.5 mm
//! grids, 96 x 96, four views), against FVT: hit/miss differs on
//! 0.65-1.02 % of the pixels; over pixels both hit, the median depth
//! difference is 0.03-0.09 mm (nearest warp 0.19-0.31 mm; without the
//! gap refinement up to 0.23 mm on the diagonal view), the 95th percentile
//! 0.63-1.23 mm. On random volumes the single-step template skips 46 % of
//! the 1-cell visits of FVT along the same rays (it visits one cell per
//! slab, FVT about two), and never visits a cell the ray misses.
//!
//! `cargo run --release --example template_timing` (256^3 spheres, depth
//! and surface, CD with leaps, 2 cores shared with other jobs, load ~6.7,
//! best of 3): 512 x 512: render 244-385 ms, template 220-306 ms; 1024 x
//! 1024: render 623-901 ms, template 272-379 ms. The template traces one
//! ray per base-plane cell (65 025 on the axis view, 155 820 oblique)
//! whatever the image size, and both decode the same 32 MB of bricks.
//!
//! # Refused inputs
//!
//! * **Perspective cameras**: rays are not parallel, so no two rays follow
//!   the same cell sequence and there is no base plane.
//! * **Rectilinear axes** (any axis whose gaps are not all equal,
//!   [`Axis::is_uniform`]): the template is one sequence of cell offsets
//!   relative to the start cell, valid for every start cell only if
//!   shifting the start by one cell along any axis shifts the whole ray's
//!   geometry by one cell too. That holds exactly when index space is an
//!   affine image of mm space, i.e. every axis uniform (spacing may differ
//!   between axes). On a rectilinear axis the map from mm to cell index is
//!   only piecewise affine, so a straight ray is a polyline in index space
//!   whose slope changes from cell to cell: the ray from start cell `i + 1`
//!   meets cells of other widths than the ray from `i`, crosses cell
//!   boundaries after other numbers of major-axis steps, and so visits a
//!   different offset sequence; one template would then skip cells the ray
//!   passes through and visit cells it does not touch (and with a
//!   rectilinear *major* axis the slab middles themselves move, changing
//!   the minor drift per step).
//! * **Modes** mip and composite, and surface with shadows (shadow rays
//!   run towards the light, not along the template), and the cd-aniso
//!   traversal (its octant codes would need their own leap rule): refused
//!   with [`RenderError::Template`] rather than rendered by another
//!   traversal.
//! * Eyes whose image plane cuts the volume: [`super::render`] starts rays
//!   at `t = 0`, the template at the base plane, so they would differ.
//!
//! The walk is always in f64 ([`RenderOptions::precision`] is ignored) and
//! the tile size is not used: rows of the intermediate image run in
//! parallel, each with its own [`Accessor`].

use std::ops::Range;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::cache::{Accessor, BrickCache, CacheCounters, Planes, OBJECT};
use super::camera::{Camera, Projection};
use super::colour::{colour, Colouring};
use super::error::RenderError;
use super::gradient::{smooth_gradient_in, Normals};
use super::integrate::Px;
use super::options::{
    check_mode, check_scene_iso, check_tol_and_size, narrowing, scene_iso, Mode, RenderOptions,
    MAX_PIXELS,
};
use super::output::Frame;
use super::shade::{self, at, find_hit_with, CellEval, HitMethod};
use super::stats::Stats;
use super::traverse::{trace, CodeSource, Flow, Method, Ray, StepCounts, TGrid, Visit};
use crate::format::reader::PackedVolume;
use crate::grid::Axis;
use crate::progress::Progress;

/// A 26-connected ray template in the mirrored frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Template {
    /// Axis of the largest `|r_k|`.
    pub major: usize,
    /// The other two axes, increasing.
    pub minor: [usize; 2],
    /// Axes whose direction component is negative (walked mirrored).
    pub mirror: [bool; 3],
    /// `|r_k| / |r_m|` per axis (1 on the major axis).
    pub slope: [f64; 3],
    /// Offset of entry `s` from the start cell, mirrored frame: `s` on the
    /// major axis, non-decreasing on the others.
    pub offsets: Vec<[u32; 3]>,
}

impl Template {
    /// The template of direction `r` (index space, cells per unit of `t`)
    /// through a volume of `ncells`: one entry per cell of the major axis.
    /// `None` when `r` is not finite or zero, or the major axis has no cell.
    pub fn new(r: [f64; 3], ncells: [u32; 3]) -> Option<Template> {
        if !r.iter().all(|x| x.is_finite()) {
            return None;
        }
        let a = r.map(f64::abs);
        let major = if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        };
        let major_cells = ncells[major];
        if !(a[major] > 0.0) || major_cells == 0 {
            return None;
        }
        let minor = match major {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        };
        let slope: [f64; 3] = std::array::from_fn(|k| {
            if k == major {
                1.0
            } else {
                (a[k] / a[major]).min(1.0)
            }
        });
        let offsets = (0..major_cells)
            .map(|s| {
                std::array::from_fn(|k| {
                    if k == major {
                        s
                    } else {
                        // Nearest cell centre to (s + 1/2) sigma, ties down.
                        let x = (s as f64 + 0.5) * slope[k];
                        (x - 0.5).ceil().max(0.0) as u32
                    }
                })
            })
            .collect();
        Some(Template {
            major,
            minor,
            mirror: r.map(|x| x < 0.0),
            slope,
            offsets,
        })
    }

    /// Total drift along minor axis `k` (the last entry's offset).
    pub fn drift(&self, k: usize) -> u32 {
        self.offsets.last().map_or(0, |o| o[k])
    }

    /// Offsets in the original (unmirrored) frame: `-o` on mirrored axes.
    pub fn signed_offsets(&self) -> Vec<[i64; 3]> {
        self.offsets
            .iter()
            .map(|o| {
                std::array::from_fn(|k| {
                    if self.mirror[k] {
                        -(o[k] as i64)
                    } else {
                        o[k] as i64
                    }
                })
            })
            .collect()
    }

    /// The entries of the ray whose start cell has mirrored minor indices
    /// `start` (`[minor[0], minor[1]]`; may lie outside the volume, on the
    /// extended base plane) that fall inside a volume of `ncells`.
    pub fn range(&self, ncells: [u32; 3], start: [i64; 2]) -> Range<usize> {
        let mut lo = 0;
        let mut hi = self.offsets.len().min(ncells[self.major] as usize);
        for (q, &k) in self.minor.iter().enumerate() {
            let s0 = start[q];
            let n = ncells[k] as i64;
            lo = lo.max(self.offsets.partition_point(|o| s0 + (o[k] as i64) < 0));
            hi = hi.min(self.offsets.partition_point(|o| s0 + (o[k] as i64) < n));
        }
        lo..hi.max(lo)
    }

    /// Original cell index of entry `s` of the ray from `start` (which must
    /// be in [`Template::range`]).
    #[inline]
    pub fn cell(&self, ncells: [u32; 3], start: [i64; 2], s: usize) -> [u32; 3] {
        let o = self.offsets[s];
        std::array::from_fn(|k| {
            let v = if k == self.major {
                o[k] as i64
            } else {
                let q = if k == self.minor[0] { 0 } else { 1 };
                start[q] + o[k] as i64
            };
            let v = v as u32;
            if self.mirror[k] {
                ncells[k] - 1 - v
            } else {
                v
            }
        })
    }
}

/// Walks the template ray from mirrored start `start` through a volume of
/// `ncells`, calling `visit(entry, cell, src)` for every 1-cell, in order,
/// until it says stop or the ray leaves. With `min_leap = Some(l)`, a
/// 0-cell with code `n >= l` skips the next `n` entries (CD); with `None`
/// every entry is read (the single-step template walk).
pub fn walk<S, F>(
    tpl: &Template,
    ncells: [u32; 3],
    start: [i64; 2],
    min_leap: Option<u8>,
    src: &mut S,
    mut visit: F,
) -> StepCounts
where
    S: CodeSource,
    F: FnMut(usize, [u32; 3], &mut S) -> Flow,
{
    let mut counts = StepCounts::default();
    let range = tpl.range(ncells, start);
    let min_leap = min_leap.map_or(u16::MAX, |l| l.max(1) as u16);
    let mut s = range.start;
    while s < range.end {
        let cell = tpl.cell(ncells, start, s);
        let code = src.code(cell, None);
        counts.steps += 1;
        if code == OBJECT {
            counts.cell_steps += 1;
            if visit(s, cell, src) == Flow::Stop {
                break;
            }
            s += 1;
        } else if code as u16 >= min_leap {
            counts.macro_steps += 1;
            s += code as usize + 1;
        } else {
            counts.cell_steps += 1;
            s += 1;
        }
    }
    counts
}

/// How the intermediate image is resampled to the final one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Warp {
    /// The sample whose start point is nearest.
    Nearest,
    /// Depth and gradient bilinear over the four samples around the final
    /// ray's base-plane point when all four hit at similar depths;
    /// hit/miss and steps from the nearest.
    #[default]
    Bilinear,
}

/// Choices of the template render beyond [`RenderOptions`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TemplateOptions {
    pub warp: Warp,
    /// Gap refinement (module docs): when the template's hit cell is
    /// entered already inside the surface, search the cells the template
    /// skipped just before it with a single-cell walk.
    pub refine: bool,
}

impl Default for TemplateOptions {
    /// Bilinear warp with gap refinement.
    fn default() -> TemplateOptions {
        TemplateOptions {
            warp: Warp::Bilinear,
            refine: true,
        }
    }
}

/// One pixel of the intermediate image.
#[derive(Debug, Clone, Copy, Default)]
struct IPx {
    hit: bool,
    /// Hit distance from the base plane, mm.
    t: f64,
    grad: [f64; 3],
    steps: u32,
}

/// The per-image geometry of a template render.
struct Setup<'a> {
    tpl: Template,
    /// For the gap refinement's single-cell walks.
    grid: TGrid<f64>,
    refine: bool,
    ncells: [u32; 3],
    coords: [&'a [f64]; 3],
    lo: [f64; 3],
    h: [f64; 3],
    dir: [f64; 3],
    /// Base-plane position along the major axis, mm.
    base: f64,
    /// Intermediate image size (minor[0], minor[1]).
    size: [u32; 2],
    /// The scene's iso value for smooth normals when narrower than the
    /// file's and the file has no gradient halo (module scene).
    narrow: Option<f32>,
    /// Mirrored start index of intermediate pixel 0 per minor axis.
    first: [i64; 2],
}

impl Setup<'_> {
    /// The ray of intermediate pixel `(pa, pb)` and its mirrored start.
    fn ray(&self, pa: u32, pb: u32) -> (Ray, [i64; 2]) {
        let start = [self.first[0] + pa as i64, self.first[1] + pb as i64];
        let m = self.tpl.major;
        let mut origin = [0.0; 3];
        origin[m] = self.base;
        for (q, &k) in self.tpl.minor.iter().enumerate() {
            let n = self.ncells[k] as f64;
            // Centre of mirrored index start + 1/2, in original cells.
            let u = start[q] as f64 + 0.5;
            let u = if self.tpl.mirror[k] { n - u } else { u };
            origin[k] = self.lo[k] + u * self.h[k];
        }
        (
            Ray {
                origin: DVec3::from_array(origin),
                dir: DVec3::from_array(self.dir),
            },
            start,
        )
    }
}

/// The visit of `ray` in `cell`: its slab entry and exit (mm), never empty.
fn visit_of(coords: [&[f64]; 3], ray: &Ray, cell: [u32; 3]) -> Visit {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for k in 0..3 {
        let d = ray.dir[k];
        if d != 0.0 {
            let a = (coords[k][cell[k] as usize] - ray.origin[k]) / d;
            let b = (coords[k][cell[k] as usize + 1] - ray.origin[k]) / d;
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    // The template cell contains the ray's point at the middle of its slab;
    // only rounding (at a tie on a cell boundary) can make this empty.
    Visit {
        cell,
        t_enter: t0,
        t_exit: t1.max(t0),
    }
}

fn refuse(msg: impl Into<String>) -> RenderError {
    RenderError::Template(msg.into())
}

const AXES: [&str; 3] = ["x", "y", "z"];

/// Renders `vol` as seen by the orthographic `camera` with the
/// template-based CD traversal and the bilinear warp (module docs).
/// `opts.method` chooses single-step templates (`Fvt`) or CD leaps (`Cd`).
pub fn render_template(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<(Frame, Stats), RenderError> {
    render_template_with(vol, camera, opts, TemplateOptions::default(), progress)
}

/// [`render_template`] with chosen [`TemplateOptions`].
pub fn render_template_with(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    topts: TemplateOptions,
    progress: &dyn Progress,
) -> Result<(Frame, Stats), RenderError> {
    let t0 = Instant::now();
    check_mode(vol, &opts.mode, opts.iso)?;
    check_scene_iso(vol, opts)?;
    if let Projection::Persp { .. } = camera.projection {
        return Err(refuse(
            "a perspective camera: templates need parallel rays (an orthographic camera), \
             as every ray must follow the same cell sequence",
        ));
    }
    let colouring =
        match &opts.mode {
            Mode::Surface { shadows: true, .. } => return Err(refuse(
                "surface with shadows: shadow rays run towards the light, not along the template",
            )),
            Mode::Surface { .. } => Colouring::Rgb,
            Mode::Depth { .. } => Colouring::Depth,
            Mode::Cost => Colouring::Cost,
            Mode::Mip | Mode::Composite { .. } => {
                return Err(refuse(format!(
                    "mode {} is not implemented for templates (surface, depth and cost are)",
                    opts.mode.name()
                )))
            }
        };
    let min_leap = match opts.method {
        Method::Fvt => None,
        Method::Cd { min_leap } => Some(min_leap),
        m @ (Method::CdAniso { .. } | Method::Octree | Method::Dda { .. }) => {
            return Err(refuse(format!(
                "traversal {} (cd-aniso, octree, dda): templates leap by chessboard codes only \
                 (cd) or step every entry (fvt)",
                m.name()
            )))
        }
    };
    check_tol_and_size(opts, camera)?;
    let hdr = vol.header();
    let axes: &[Axis; 3] = &hdr.axes;
    for (k, a) in axes.iter().enumerate() {
        if !a.is_uniform() {
            let (lo, hi) = a.spacing_range();
            return Err(refuse(format!(
                "axis {} is rectilinear (gaps {lo} to {hi} mm): a template is one cell sequence \
                 relative to its start cell, which rays from other start cells follow only on \
                 uniform axes",
                AXES[k]
            )));
        }
    }
    let coords: [&[f64]; 3] = [axes[0].coords(), axes[1].coords(), axes[2].coords()];
    let ncells: [u32; 3] = std::array::from_fn(|k| axes[k].cells() as u32);
    let lo: [f64; 3] = std::array::from_fn(|k| coords[k][0]);
    let hi: [f64; 3] = std::array::from_fn(|k| coords[k][ncells[k] as usize]);
    let h: [f64; 3] = std::array::from_fn(|k| (hi[k] - lo[k]) / ncells[k] as f64);
    let dir = camera.forward.to_array();
    // Every corner in front of the image plane: both walks then start
    // before the volume.
    for c in 0..8 {
        let p: [f64; 3] = std::array::from_fn(|k| if c >> k & 1 == 1 { hi[k] } else { lo[k] });
        let ahead: f64 = (0..3).map(|k| (p[k] - camera.eye[k]) * dir[k]).sum();
        if ahead < 0.0 {
            return Err(refuse(format!(
                "the eye {:?} is not in front of the whole volume (corner {p:?} is behind the \
                 image plane); move it back",
                camera.eye.to_array()
            )));
        }
    }
    let r: [f64; 3] = std::array::from_fn(|k| dir[k] / h[k]);
    let tpl = Template::new(r, ncells)
        .ok_or_else(|| refuse(format!("view direction {dir:?} is not usable")))?;
    let m = tpl.major;
    let size = [
        ncells[tpl.minor[0]] + tpl.drift(tpl.minor[0]),
        ncells[tpl.minor[1]] + tpl.drift(tpl.minor[1]),
    ];
    let inter_px = size[0] as u64 * size[1] as u64;
    if inter_px > MAX_PIXELS {
        return Err(refuse(format!(
            "the intermediate image would have {} x {} = {inter_px} pixels, expected at most \
             {MAX_PIXELS}",
            size[0], size[1]
        )));
    }
    let setup = Setup {
        grid: TGrid::new(axes),
        refine: topts.refine,
        ncells,
        coords,
        lo,
        h,
        dir,
        base: if tpl.mirror[m] { hi[m] } else { lo[m] },
        size,
        narrow: narrowing(hdr, opts).filter(|_| !hdr.gradient_halo),
        first: [
            -(tpl.drift(tpl.minor[0]) as i64),
            -(tpl.drift(tpl.minor[1]) as i64),
        ],
        tpl,
    };
    let iso = scene_iso(hdr, opts);
    let narrow = narrowing(hdr, opts);

    // Intermediate image, rows in parallel.
    let cache = BrickCache::with_planes(
        vol,
        opts.cache_bytes,
        Planes {
            narrow,
            ..Planes::FILE
        },
    );
    progress.begin("template rows", size[1] as u64);
    let rows: Vec<_> = (0..size[1])
        .into_par_iter()
        .map(|pb| {
            let policy = super::policy::brick_policy(opts.method, opts.cd_lazy_min);
            let mut acc = Accessor::for_policy(&cache, &policy);
            let mut counts = StepCounts::default();
            let mut out = Vec::with_capacity(size[0] as usize);
            for pa in 0..size[0] {
                let (ray, start) = setup.ray(pa, pb);
                let (px, c) = inter_pixel(
                    &setup, &ray, start, min_leap, &opts.mode, iso, opts, &mut acc,
                );
                counts.add(&c);
                out.push(px);
            }
            progress.advance(1);
            (out, counts, acc.counters, acc.error.take())
        })
        .collect();
    progress.end();
    let mut inter = Vec::with_capacity(inter_px as usize);
    let mut steps = StepCounts::default();
    let mut cc = CacheCounters::default();
    for (out, c, k, e) in rows {
        if let Some(e) = e {
            return Err(e.into());
        }
        inter.extend(out);
        steps.add(&c);
        cc.add(&k);
    }
    let hits = inter.iter().filter(|p| p.hit).count() as u64;

    // Warp to the final image.
    let (w, hh) = (camera.width, camera.height);
    let mut px = vec![Px::default(); w as usize * hh as usize];
    let diag = 2.0 * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    px.par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, p) in row.iter_mut().enumerate() {
                *p = warp_pixel(
                    &setup, &inter, camera, x as u32, y as u32, topts.warp, diag, &opts.mode,
                );
            }
        });
    let frame = colour(&colouring, w, hh, &px, opts.unrounded);
    let mut stats = Stats::counted(inter_px, hits, &steps, &cc, &cache, opts, t0);
    stats.traversal = format!("template {}", opts.method.name());
    (stats.width, stats.height) = (w, hh);
    Ok((frame, stats))
}

/// Traces one template ray: its intermediate pixel and step counts.
#[allow(clippy::too_many_arguments)]
fn inter_pixel(
    st: &Setup,
    ray: &Ray,
    start: [i64; 2],
    min_leap: Option<u8>,
    mode: &Mode,
    iso: f64,
    opts: &RenderOptions,
    acc: &mut Accessor,
) -> (IPx, StepCounts) {
    let mut px = IPx::default();
    let hit = match mode {
        Mode::Surface { hit, .. } | Mode::Depth { hit } => Some(*hit),
        _ if iso.is_nan() => None,
        _ => Some(HitMethod::Int),
    };
    let range = st.tpl.range(st.ncells, start);
    // The template's hit: (t, cell values, entry, whether entered inside,
    // cell).
    let mut found: Option<(f64, CellEval, usize, bool, [u32; 3])> = None;
    let mut counts = walk(&st.tpl, st.ncells, start, min_leap, acc, |s, cell, acc| {
        let Some(hit) = hit else {
            // Cost on a transfer-function file: steps to the first 1-cell.
            px.hit = true;
            return Flow::Stop;
        };
        let v = visit_of(st.coords, ray, cell);
        let c = CellEval::new(st.coords, cell, acc.vertices(cell));
        match find_hit_with(ray, &v, &c, iso, hit, &opts.hit_params) {
            Some(t) => {
                found = Some((t, c, s, t <= v.t_enter, cell));
                Flow::Stop
            }
            None => Flow::Continue,
        }
    });
    if let (Some(hit), Some((mut t, mut c, s, inside, mut hit_cell))) = (hit, found) {
        if st.refine && inside {
            // The surface was crossed before this cell: after the previous
            // entry's cell (all below iso there), in cells the template
            // skipped. Walk them cell by cell, as FVT would.
            let from = if s > range.start {
                visit_of(st.coords, ray, st.tpl.cell(st.ncells, start, s - 1)).t_exit
            } else {
                0.0
            };
            let g = trace(&st.grid, ray, from, Method::Fvt, acc, |v, acc| {
                if v.t_enter >= t {
                    return Flow::Stop;
                }
                let cv = CellEval::new(st.coords, v.cell, acc.vertices(v.cell));
                match find_hit_with(ray, v, &cv, iso, hit, &opts.hit_params) {
                    Some(tg) if tg < t => {
                        t = tg;
                        c = cv;
                        hit_cell = v.cell;
                        Flow::Stop
                    }
                    _ => Flow::Continue,
                }
            });
            counts.add(&g);
        }
        px.hit = true;
        px.t = t;
        if matches!(mode, Mode::Surface { .. }) {
            let p = at(ray, t);
            let cell_grad = c.gradient(p);
            // The surface mode's normals (integrate/surface.rs).
            let g = match opts.normals {
                Normals::Cell => cell_grad,
                Normals::Smooth => {
                    let g = smooth_gradient_in(acc, st.coords, hit_cell, p, st.narrow);
                    if g.is_finite() && g != DVec3::ZERO {
                        g
                    } else {
                        cell_grad
                    }
                }
            };
            px.grad = g.to_array();
        }
    }
    px.steps = counts.steps.min(u32::MAX as u64) as u32;
    (px, counts)
}

/// The final pixel `(x, y)` from the intermediate image.
#[allow(clippy::too_many_arguments)]
fn warp_pixel(
    st: &Setup,
    inter: &[IPx],
    camera: &Camera,
    x: u32,
    y: u32,
    warp: Warp,
    diag: f64,
    mode: &Mode,
) -> Px {
    let mut out = Px {
        depth: f32::NAN,
        ..Px::default()
    };
    let ray = camera.ray(x, y);
    let m = st.tpl.major;
    let t_b = (st.base - ray.origin[m]) / ray.dir[m];
    let p = at(&ray, t_b);
    // Continuous intermediate-pixel coordinates: pixel i has its start
    // centre at i + 1/2.
    let xy: [f64; 2] = std::array::from_fn(|q| {
        let k = st.tpl.minor[q];
        let u = (p[k] - st.lo[k]) / st.h[k];
        let u = if st.tpl.mirror[k] {
            st.ncells[k] as f64 - u
        } else {
            u
        };
        u - st.first[q] as f64
    });
    let get = |i: f64, j: f64| -> Option<&IPx> {
        if i >= 0.0 && j >= 0.0 && i < st.size[0] as f64 && j < st.size[1] as f64 {
            Some(&inter[j as usize * st.size[0] as usize + i as usize])
        } else {
            None
        }
    };
    let Some(near) = get(xy[0].floor(), xy[1].floor()) else {
        return out;
    };
    out.steps = near.steps;
    out.hit = near.hit;
    out.alpha = if near.hit { 1.0 } else { 0.0 };
    if !near.hit || matches!(mode, Mode::Cost) {
        return out;
    }
    let (mut t, mut grad) = (near.t, near.grad);
    if warp == Warp::Bilinear {
        let (fx, fy) = (xy[0] - 0.5, xy[1] - 0.5);
        let (i0, j0) = (fx.floor(), fy.floor());
        let (wx, wy) = (fx - i0, fy - j0);
        let four = [
            get(i0, j0),
            get(i0 + 1.0, j0),
            get(i0, j0 + 1.0),
            get(i0 + 1.0, j0 + 1.0),
        ];
        if let [Some(a), Some(b), Some(c), Some(d)] = four {
            let ts = [a.t, b.t, c.t, d.t];
            let spread = ts.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - ts.iter().cloned().fold(f64::INFINITY, f64::min);
            if a.hit && b.hit && c.hit && d.hit && spread <= diag {
                let wts = [
                    (1.0 - wx) * (1.0 - wy),
                    wx * (1.0 - wy),
                    (1.0 - wx) * wy,
                    wx * wy,
                ];
                let s = [a, b, c, d];
                t = (0..4).map(|i| wts[i] * s[i].t).sum();
                grad = std::array::from_fn(|k| (0..4).map(|i| wts[i] * s[i].grad[k]).sum());
            }
        }
    }
    let depth = t_b + t;
    out.depth = depth as f32;
    if matches!(mode, Mode::Surface { .. }) {
        let to_eye = ray.dir.map(|d| -d);
        let v = shade::shade(DVec3::from_array(grad), to_eye, to_eye, true) as f32;
        out.rgb = [v, v, v];
    }
    out
}
