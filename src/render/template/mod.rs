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
//! [`find_hit_with`], so hits are found exactly as [`crate::render::render`] finds
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
//!    the pixels whose hit/miss or depth differs from [`crate::render::render`] on
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
//! * Eyes whose image plane cuts the volume: [`crate::render::render`] starts rays
//!   at `t = 0`, the template at the base plane, so they would differ.
//!
//! The walk is always in f64 ([`RenderOptions::precision`] is ignored) and
//! the tile size is not used: rows of the intermediate image run in
//! parallel, each with its own [`Accessor`].
//!
//! [`find_hit_with`]: crate::render::sample::hit::find_hit_with
//! [`trace`]: crate::render::traverse::trace
//! [`Axis::is_uniform`]: crate::grid::Axis::is_uniform
//! [`RenderError::Template`]: crate::render::RenderError::Template
//! [`RenderOptions::precision`]: crate::render::RenderOptions::precision
//! [`Accessor`]: crate::render::cache::Accessor

use std::ops::Range;

use crate::render::traverse::OBJECT;
use crate::render::traverse::{CodeSource, Flow, StepCounts};

mod image;

// Some are used only by the tests and tools (feature `internals`).
#[cfg_attr(not(feature = "internals"), allow(unused_imports))]
pub use image::{render_template, render_template_with, TemplateOptions, Warp};

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
