//! The template render (module docs of `render/template`): the
//! intermediate image on the base plane, traced with [`walk`] and the gap
//! refinement, and its warp to the final image.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::{walk, Template};
use crate::format::reader::PackedVolume;
use crate::grid::Axis;
use crate::progress::Progress;
use crate::render::brick::Planes;
use crate::render::cache::{Accessor, BrickCache, CacheCounters};
use crate::render::error::RenderError;
use crate::render::integrate::Px;
use crate::render::options::{
    check_mode, check_scene_iso, check_tol_and_size, narrowing, scene_iso, Mode, RenderOptions,
    MAX_PIXELS,
};
use crate::render::output::colour::{colour, Colouring};
use crate::render::output::Frame;
use crate::render::sample::hit::{find_hit_with, HitMethod};
use crate::render::sample::normals::{smooth_gradient_in, Normals};
use crate::render::sample::shade::{self, at, CellEval};
use crate::render::stats::Stats;
use crate::render::traverse::{trace, Flow, Method, Ray, StepCounts, TGrid, Visit};
use crate::render::view::camera::{Camera, Projection};

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
    /// Intermediate image size (`minor[0]`, `minor[1]`).
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
    let (t0, k0) = (Instant::now(), crate::render::clock::KernelUse::now());
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
            Mode::Mip | Mode::Composite { .. } | Mode::Labels { .. } => {
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
    check_tol_and_size(opts, [camera.width, camera.height])?;
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
            let policy = crate::render::brick_policy(
                opts.method,
                opts.cd_lazy_min
                    .unwrap_or(crate::render::cache::LAZY_MIN_CODE_CD),
            );
            let mut acc = Accessor::for_policy(&cache, &policy);
            let mut counts = StepCounts::default();
            let mut out = Vec::with_capacity(size[0] as usize);
            for pa in 0..size[0] {
                let (ray, start) = setup.ray(pa, pb);
                let (px, c) = inter_pixel(&setup, &ray, start, min_leap, iso, opts, &mut acc);
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
                    &setup,
                    &inter,
                    camera,
                    [x as u32, y as u32],
                    topts.warp,
                    diag,
                    &opts.mode,
                );
            }
        });
    let frame = colour(&colouring, w, hh, &px, opts.unrounded);
    let mut stats = Stats::counted(inter_px, hits, &steps, &cc, &cache, opts, t0);
    stats.traversal = format!("template {}", opts.method.name());
    (stats.width, stats.height) = (w, hh);
    stats.camera = Some(camera.used());
    stats.set_kernel(k0);
    Ok((frame, stats))
}

/// Traces one template ray: its intermediate pixel and step counts.
fn inter_pixel(
    st: &Setup,
    ray: &Ray,
    start: [i64; 2],
    min_leap: Option<u8>,
    iso: f64,
    opts: &RenderOptions,
    acc: &mut Accessor,
) -> (IPx, StepCounts) {
    let mode = &opts.mode;
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

/// The final pixel `[x, y]` from the intermediate image.
fn warp_pixel(
    st: &Setup,
    inter: &[IPx],
    camera: &Camera,
    [x, y]: [u32; 2],
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
