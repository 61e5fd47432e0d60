//! Composite mode: front-to-back compositing of a transfer function
//! (tabulated for the step by sample/lut.rs) at samples `t = k * step_mm` along
//! the ray, the lattice restarted where the opacity rises sharply (at
//! onsets, refine.rs: no wood grain), stopping once the ray's opacity
//! exceeds [`RenderOptions::early_stop`](crate::render::RenderOptions::early_stop)
//! (0.99). Cells the ray only clips between two samples are not read.
//!
//! Two samplers, [`RenderOptions::sampling`](crate::render::RenderOptions::sampling):
//! [`composite32`] (the default) and [`composite`] (f64, the reference).
//! Both take the same samples in the same cells; the traversal that finds
//! the cells is f64 either way, so every exact traversal gives the same
//! image with either sampler. The f32 sampler takes a run's samples
//! eight at a time, their cells by position (batch.rs,
//! `--sample-batches`; shaded or with gradient opacity only with smooth
//! normals); the runs still start where the
//! traversal finds them, so every traversal gives the same image there
//! too.

use std::cell::Cell;

use glam::{Vec3, Vec3A, Vec4};

use super::batch::{self, trilinear_vec, Batches, End};
use super::refine::{
    band, cell_at, faint, faint64, first_sample, part, part32, rephase, Course, How, Onset, Took,
};
use super::sample::{Look, Trilinear32};
use super::{Ctx, Px};
use crate::render::brick::RBrick;
use crate::render::cache::Accessor;
use crate::render::clip::Span;
use crate::render::clock;
use crate::render::sample::lut::TfLut;
use crate::render::sample::normals::{outer_cell_gradients, vertex_gradients, VertexGradients};
use crate::render::sample::shade::{at, AlongRay, CellEval};
use crate::render::traverse::{trace_until, Flow, Ray, Real, StepCounts, OBJECT};

/// Composites `ray` into `px.rgb` with f64 samples (the reference
/// sampler, `--sample-precision f64`); `px.hit` when anything is opaque.
pub(super) fn composite<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    lut: &TfLut,
    step: f64,
    px: &mut Px,
) -> StepCounts {
    let mut s = Sampler64 {
        coords: ctx.coords,
        ray,
        lut,
        look: Look::new(&ctx.opts.look, ctx.opts.normals, ray),
        stop: ctx.opts.early_stop,
        faint: faint(ctx),
        c: None,
        ce: None,
        vg: None,
        col: [0.0; 3],
        alpha: 0.0,
        last: ([0.0; 4], 1.0),
    };
    let course = Course {
        ray,
        lut,
        step,
        end: span.end,
    };
    let counts = march(ctx, &course, span.start, acc, &mut s);
    px.hit = s.alpha > 0.0;
    px.alpha = s.alpha as f32;
    px.rgb = s.col.map(|x| x as f32);
    counts
}

/// [`composite`] with samples in f32 (the default sampler): per cell the
/// local coordinates of the first sample and their increment per sample
/// are computed once (by multiplication with the cell's inverse size),
/// then each sample is an f32 trilinear evaluation and an f32 table
/// lookup. The samples and their cells are [`composite`]'s;
/// docs/TRADEOFFS.md ("Sampling precision") measures the image
/// difference.
pub(super) fn composite32<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    span: &Span,
    acc: &mut Accessor,
    lut: &TfLut,
    step: f64,
    px: &mut Px,
) -> StepCounts {
    let look = Look::new(&ctx.opts.look, ctx.opts.normals, ray);
    // One marcher per look: without shading or gradient opacity, its
    // sample loop holds no gradient code at all.
    let course = Course {
        ray,
        lut,
        step,
        end: span.end,
    };
    if look.on {
        march32::<T, true>(ctx, &course, span.start, acc, look, px)
    } else {
        march32::<T, false>(ctx, &course, span.start, acc, look, px)
    }
}

/// [`composite32`] with the look's `on` fixed at compile time (`LOOK`).
#[inline(always)]
fn march32<T: Real, const LOOK: bool>(
    ctx: &Ctx<T>,
    course: &Course,
    t_start: f64,
    acc: &mut Accessor,
    look: Look,
    px: &mut Px,
) -> StepCounts {
    let Course { ray, lut, step, .. } = *course;
    debug_assert_eq!(look.on, LOOK);
    // With a look, the batches weight and light their samples by smooth
    // normals (the brick's gradient plane); the cell interpolant's
    // normals take one sample at a time.
    let batches = ctx.index_map.as_ref().filter(|_| !LOOK || look.batches());
    let mut s = Sampler32::<LOOK> {
        coords: ctx.coords,
        inv_size: &ctx.inv_size,
        ray,
        lut,
        step,
        look,
        stop: ctx.opts.early_stop as f32,
        faint: faint(ctx) as f32,
        faint64: faint(ctx),
        band: band(ctx) as f32,
        cell: [0; 3],
        f: [0.0; 8],
        c: Trilinear32 { f: [0.0; 8] },
        u: Vec3::ZERO,
        du: Vec3::ZERO,
        inv: Vec3::ZERO,
        grads: [Vec3A::ZERO; 8],
        acc: Vec4::ZERO,
        last: Cell::new((Vec4::ZERO, 1.0)),
        batches,
    };
    let counts = march(ctx, course, t_start, acc, &mut s);
    px.hit = s.acc.w > 0.0;
    px.alpha = s.acc.w;
    px.rgb = s.acc.truncate().to_array();
    counts
}

/// What the composite samplers do along a run of 1-cells.
trait Sampler {
    /// Whether [`Sampler::enter`] wants the cell's vertex gradients from
    /// its brick's gradient plane.
    fn plane_gradients(&self) -> bool;
    /// The samples move into 1-cell `cell` with vertex values `f` (x
    /// fastest) and, when [`Sampler::plane_gradients`] and the plane holds
    /// them, vertex gradients `g` (else read or computed through `acc`);
    /// the next sample is at `t`.
    fn enter(
        &mut self,
        acc: &mut Accessor,
        cell: [u32; 3],
        f: [f32; 8],
        g: Option<[Vec3A; 8]>,
        t: f64,
    );
    /// The sample at `t` (in the cell last entered), taken as `how`
    /// says: faint or composited (`Stop` once opaque), or left for the
    /// marcher to refine (refine.rs).
    fn sample(&mut self, t: f64, how: How) -> Took;
    /// The last sample composited as faint (by [`Sampler::sample`] or
    /// [`Sampler::batch`]) stands for the share `keep` of its step:
    /// its contribution is replaced by [`part`]'s (refine.rs,
    /// [`Onset::kept`]).
    fn trim(&mut self, keep: f64);
    /// Whether [`Sampler::batch`] takes samples several at a time.
    fn batches(&self) -> bool {
        false
    }
    /// Composites samples `k, k + 1, ...` while they lie in the brick of
    /// cell `cell`, several at a time ([`batch::run`]), up to an onset
    /// by `onset`'s state: how many it took and why it stopped. A
    /// sampler that takes one sample at a time takes none.
    fn batch(&mut self, _: &mut Accessor, _: [u32; 3], _: f64, _: &Onset) -> (u64, End) {
        (0, End::Brick)
    }
}

/// A 0-cell code from which the run marcher hands the ray back to the
/// traversal to leap (below it, samples in the 0-cell are skipped and the
/// march goes on: a leap of at most 2 cells does not pay for a new
/// traversal). docs/BENCHMARKS.md, "Composite sampler".
const RESUME_CODE: u8 = 2;

/// The composite samples `t = k * step` of `ray` in 1-cells, in order,
/// handed to `s`.
///
/// The traversal (`ctx.opts.method`) finds the first 1-cell; from there
/// the samples are marched directly: per sample, the cell holding it is
/// advanced plane by plane (`S[j]` crossed at `(S[j] - o) / d`, the
/// sample belonging to the cell whose planes it has crossed), and its
/// code is read only when the cell changes. A sample in a 0-cell is
/// transparent (the transfer function is zero on the cell's value range)
/// and skipped; from a 0-cell with code >= [`RESUME_CODE`] the traversal
/// takes over again at that sample and leaps. So the walk costs one
/// code read per cell holding a sample instead of a traversal step per
/// cell, and a sample costs no visit.
///
/// Where a sample that is not faint follows faint ones (an onset), the
/// lattice restarts at the rise of opacity between them (refine.rs,
/// [`rephase`]).
///
/// Every exact traversal yields the same first 1-cell after a given `t`
/// (module traverse), so the marched samples, and the image, are the
/// same whichever traversal finds the runs.
fn march<T: Real, P: Sampler>(
    ctx: &Ctx<T>,
    course: &Course,
    t_start: f64,
    acc: &mut Accessor,
    s: &mut P,
) -> StepCounts {
    let Course { ray, step, .. } = *course;
    let coords = ctx.coords;
    let inv_step = 1.0 / step;
    let n: [u32; 3] = std::array::from_fn(|a| (coords[a].len() - 1) as u32);
    // The plane ahead of cell index `i` on axis `a`, and its `t`.
    let ahead = |a: usize, i: u32| -> f64 {
        let d = ray.dir[a];
        if d > 0.0 {
            (coords[a][i as usize + 1] - ray.origin[a]) / d
        } else if d < 0.0 {
            (coords[a][i as usize] - ray.origin[a]) / d
        } else {
            f64::INFINITY
        }
    };
    let mut counts = StepCounts::default();
    // Batches take samples while they stay in a brick; a ray the clip cuts
    // short takes them one at a time, each checked against its end.
    let batches = s.batches() && course.end == f64::INFINITY;
    let mut t_min = t_start;
    // The first sample not yet handled: runs never go back.
    let mut k_next = 0.0f64;
    // Onsets are refined where the ramps are known (in every composite
    // render).
    let ramps = ctx.ramps.as_ref();
    let onset = ramps.map_or_else(Onset::off, |r| Onset::new(r.faint(), r.band()));
    // After a restart at a ramp's top: the partial sample's fraction of a
    // step and the index of the top.
    let mut part_of: Option<(f64, f64)> = None;
    loop {
        let mut first = None;
        let c = trace_until(
            ctx.grid,
            ray,
            t_min,
            course.end,
            ctx.opts.method,
            acc,
            |v, _| {
                first = Some(*v);
                Flow::Stop
            },
        );
        counts.add(&c);
        let Some(v) = first else {
            return counts;
        };
        // The run marcher is the sampling section (render/clock.rs).
        clock::enter(acc);
        let resume = 'run: {
            let mut cell = v.cell;
            let mut tn: [f64; 3] = std::array::from_fn(|a| ahead(a, cell[a]));
            let mut k = first_sample(v.t_enter, step, inv_step).max(k_next);
            let mut entered = false;
            let mut batched = true;
            loop {
                let (t, ks) = (k * step, k);
                if t > course.end {
                    break 'run None;
                }
                for a in 0..3 {
                    while tn[a] <= t {
                        if ray.dir[a] > 0.0 {
                            cell[a] += 1;
                            if cell[a] >= n[a] {
                                break 'run None;
                            }
                        } else {
                            if cell[a] == 0 {
                                break 'run None;
                            }
                            cell[a] -= 1;
                        }
                        tn[a] = ahead(a, cell[a]);
                        counts.steps += 1;
                        counts.cell_steps += 1;
                        entered = false;
                    }
                }
                k += 1.0;
                if !entered {
                    // The code and, for a 1-cell, its vertices and
                    // gradients: one brick lookup.
                    let (b, l) = acc.brick(cell);
                    let code = b.code(l);
                    if code != OBJECT {
                        onset.clear.set(true);
                        onset.faint_k.set(f64::NAN);
                        if let Some((_, top)) = part_of.take() {
                            k = top;
                        }
                        if code >= RESUME_CODE {
                            break 'run Some((t, k));
                        }
                        continue;
                    }
                    let f = b.vertices(l);
                    let g = if s.plane_gradients() {
                        b.grad_cell(l)
                    } else {
                        None
                    };
                    s.enter(acc, cell, f, g, t);
                    entered = true;
                    batched = !batches;
                }
                let how = match part_of.take() {
                    Some((frac, top)) => {
                        (k, entered, batched) = (top, false, true);
                        How::Part(frac)
                    }
                    None => onset.how(ks),
                };
                // The onset's lattice index, if the sample is one.
                let mut refine = match s.sample(t, how) {
                    Took::Clear => {
                        onset.clear.set(true);
                        onset.faint_k.set(f64::NAN);
                        None
                    }
                    Took::Faint => {
                        onset.clear.set(true);
                        let part = matches!(how, How::Part(_));
                        onset.faint_k.set(if part { f64::NAN } else { ks });
                        None
                    }
                    Took::Added => {
                        onset.clear.set(false);
                        onset.faint_k.set(f64::NAN);
                        None
                    }
                    Took::Stop => break 'run None,
                    Took::Onset => Some(ks),
                };
                // The samples after it, in batches while they stay in
                // this brick (once per cell entered: a batch that took
                // nothing is not tried again in the same cell).
                if batches && !batched && refine.is_none() {
                    batched = true;
                    let mut at = Marched {
                        cell,
                        tn,
                        k,
                        counts,
                    };
                    let flow = batched_samples(ctx, course, acc, s, &mut at, &ahead, &onset);
                    (cell, tn, k, counts) = (at.cell, at.tn, at.k, at.counts);
                    match flow {
                        Batched::None => {}
                        Batched::Taken => entered = false,
                        Batched::Onset => refine = Some(k),
                        Batched::Done => break 'run None,
                    }
                }
                // An onset: the lattice restarts at it or at the top of its
                // ramp (after a partial sample), in its cell; the faint
                // sample before it keeps the part of its step before.
                if let (Some(ko), Some(ramps)) = (refine, ramps) {
                    let Some(r) = rephase(ctx, course, acc, ramps, cell, ko * step) else {
                        break 'run None;
                    };
                    if let Some(keep) = onset.kept(ko, r.from, step) {
                        s.trim(keep);
                    }
                    (k, cell, entered, part_of) = (r.k, r.cell, false, r.part);
                    tn = std::array::from_fn(|a| ahead(a, cell[a]));
                    onset.restarted(r.part.map_or(r.k, |p| p.1));
                }
            }
        };
        clock::leave(acc);
        match resume {
            Some((t, k)) => (t_min, k_next) = (t, k),
            None => return counts,
        }
    }
}

/// Where the run marcher stands: the current cell, its planes ahead,
/// the next sample's index and the steps so far.
struct Marched {
    cell: [u32; 3],
    tn: [f64; 3],
    k: f64,
    counts: StepCounts,
}

/// What [`batched_samples`] did.
enum Batched {
    /// Took no sample.
    None,
    /// Took samples; the marcher stands at the next one's cell.
    Taken,
    /// Took samples up to an onset; the marcher stands at its cell.
    Onset,
    /// The ray is opaque or has left the volume.
    Done,
}

/// The samples from `at.k` on, handed to `s` in batches while they stay
/// in the current cell's brick ([`Sampler::batch`]), then the marcher
/// moved to the cell of the next sample (or, once opaque, of the last
/// one) as its plane crossings would have moved it, the crossings
/// counted as it counts them (at an onset, to the onset's sample). Not
/// inlined: called once per 1-cell entered, it keeps the marcher's loop
/// small (while it was inline, the compiler's inlining elsewhere changed
/// and the shaded composite, which never batches, ran 3-6 % more
/// instructions).
#[inline(never)]
fn batched_samples<T: Real, P: Sampler>(
    ctx: &Ctx<T>,
    course: &Course,
    acc: &mut Accessor,
    s: &mut P,
    at: &mut Marched,
    ahead: &impl Fn(usize, u32) -> f64,
    onset: &Onset,
) -> Batched {
    let Course { ray, step, .. } = *course;
    let (taken, end) = s.batch(acc, at.cell, at.k, onset);
    if taken == 0 {
        // Nothing, or an onset at the first sample, which the marcher
        // takes one at a time.
        return Batched::None;
    }
    let stop = end == End::Stop;
    let t = (at.k + taken as f64 - stop as u8 as f64) * step;
    for a in 0..3 {
        let Some(c) = cell_at(ctx, ray, a, at.cell[a], t, ahead) else {
            return Batched::Done;
        };
        let moved = c.abs_diff(at.cell[a]) as u64;
        at.counts.steps += moved;
        at.counts.cell_steps += moved;
        at.cell[a] = c;
        at.tn[a] = ahead(a, c);
    }
    if stop {
        return Batched::Done;
    }
    at.k += taken as f64;
    if end == End::Onset {
        Batched::Onset
    } else {
        Batched::Taken
    }
}

/// The f64 sampler: [`AlongRay`] per cell, the f64 table.
struct Sampler64<'a> {
    coords: [&'a [f64]; 3],
    ray: &'a Ray,
    lut: &'a TfLut,
    look: Look<'a>,
    stop: f64,
    /// The table opacity below which a sample is faint (refine.rs).
    faint: f64,
    c: Option<AlongRay>,
    ce: Option<CellEval>,
    /// Smooth normals: the cell's vertex gradients.
    vg: Option<VertexGradients>,
    col: [f64; 3],
    alpha: f64,
    /// The last faint sample as composited, and the transmittance before
    /// it ([`Sampler::trim`]).
    last: ([f64; 4], f64),
}

impl Sampler for Sampler64<'_> {
    fn plane_gradients(&self) -> bool {
        false
    }

    #[inline]
    fn enter(
        &mut self,
        acc: &mut Accessor,
        cell: [u32; 3],
        f: [f32; 8],
        _g: Option<[Vec3A; 8]>,
        _t: f64,
    ) {
        self.c = Some(AlongRay::new(self.coords, cell, f, self.ray));
        self.ce = self.look.on.then(|| CellEval::new(self.coords, cell, f));
        self.vg =
            (self.look.on && self.look.smooth).then(|| vertex_gradients(acc, self.coords, cell));
    }

    #[inline]
    fn sample(&mut self, t: f64, how: How) -> Took {
        let Some(c) = &self.c else {
            return Took::Clear;
        };
        let mut s = self.lut.sample(c.value(t));
        if s[3] == 0.0 {
            // Transparent: adds nothing.
            return Took::Clear;
        }
        let faint = s[3] < self.faint;
        match how {
            How::Onset if !faint => return Took::Onset,
            How::Part(frac) => s = part(s, frac),
            _ => {}
        }
        let [r, g, b, a] = match &self.ce {
            Some(ce) => {
                let p = at(self.ray, t);
                let grad = match &self.vg {
                    Some(vg) => vg.at(p),
                    None => ce.gradient(p),
                }
                .as_vec3();
                let s = Vec4::from_array(s.map(|x| x as f32));
                self.look.apply(s, grad.into()).to_array().map(|x| x as f64)
            }
            None => s,
        };
        let w = 1.0 - self.alpha;
        self.col[0] += w * r;
        self.col[1] += w * g;
        self.col[2] += w * b;
        self.alpha += w * a;
        if self.alpha > self.stop {
            Took::Stop
        } else if faint {
            self.last = ([r, g, b, a], w);
            Took::Faint
        } else {
            Took::Added
        }
    }

    fn trim(&mut self, keep: f64) {
        let (s, w) = self.last;
        let p = part(s, keep);
        for c in 0..3 {
            self.col[c] -= w * (s[c] - p[c]);
        }
        self.alpha = 1.0 - w * (1.0 - p[3]);
    }
}

/// The f32 sampler: local coordinates per cell, advanced by a constant
/// increment per sample. `LOOK`: the look's `on` (shading or gradient
/// opacity), a constant so that the unshaded sampler's loop has no
/// gradient code in it.
struct Sampler32<'a, const LOOK: bool> {
    coords: [&'a [f64]; 3],
    inv_size: &'a [Vec<f64>; 3],
    ray: &'a Ray,
    lut: &'a TfLut,
    step: f64,
    look: Look<'a>,
    stop: f32,
    /// The table opacity below which a sample is faint (refine.rs), and
    /// how close to it the f64 value decides ([`faint64`]).
    faint: f32,
    faint64: f64,
    band: f32,
    /// The cell entered and its vertex values, for [`faint64`].
    cell: [u32; 3],
    f: [f32; 8],
    c: Trilinear32,
    /// Local coordinates of the next sample and their step.
    u: Vec3,
    du: Vec3,
    /// The cell's inverse sizes (local coordinates per mm).
    inv: Vec3,
    /// Smooth normals: the cell's vertex gradients (per mm), as SIMD
    /// vectors for the per-sample interpolation (the same lane arithmetic
    /// as `Vec3`'s, so the same bits).
    grads: [Vec3A; 8],
    /// The ray's premultiplied colour and opacity so far, `[r, g, b, a]`:
    /// a sample is composited into all four lanes at once.
    acc: Vec4,
    /// The last faint sample as composited, and the transmittance before
    /// it ([`Sampler::trim`]; the batches set it too).
    last: Cell<(Vec4, f32)>,
    /// The grid's index map when samples go in batches (batch.rs).
    batches: Option<&'a super::index_map::IndexMap>,
}

impl<const LOOK: bool> Sampler for Sampler32<'_, LOOK> {
    #[inline(always)]
    fn plane_gradients(&self) -> bool {
        LOOK && self.look.smooth
    }

    #[inline(always)]
    fn enter(
        &mut self,
        acc: &mut Accessor,
        cell: [u32; 3],
        f: [f32; 8],
        g: Option<[Vec3A; 8]>,
        t: f64,
    ) {
        if self.plane_gradients() {
            // From the brick's gradient plane where it holds them, else
            // computed (and kept there): the same values as
            // `vertex_gradients` (render/sample/normals.rs).
            self.grads = match g {
                Some(g) => g,
                None => outer_cell_gradients(acc, self.coords, cell),
            };
        }
        let ray = self.ray;
        for (a, &i) in cell.iter().enumerate() {
            let i = i as usize;
            let s = self.inv_size[a][i];
            self.u[a] = ((ray.origin[a] - self.coords[a][i] + t * ray.dir[a]) * s) as f32;
            self.du[a] = (self.step * ray.dir[a] * s) as f32;
            self.inv[a] = s as f32;
        }
        self.c = Trilinear32::new(f);
        (self.cell, self.f) = (cell, f);
    }

    #[inline(always)]
    fn sample(&mut self, t: f64, how: How) -> Took {
        let uc = self.u.clamp(Vec3::ZERO, Vec3::ONE);
        self.u += self.du;
        let mut s = self.lut.sample32(self.c.value(uc));
        if s.w == 0.0 {
            return Took::Clear;
        }
        let faint = if (s.w - self.faint).abs() <= self.band {
            let cell = (self.cell, self.f);
            faint64(self.coords, self.ray, self.lut, cell, t, self.faint64)
        } else {
            s.w < self.faint
        };
        match how {
            How::Onset if !faint => return Took::Onset,
            How::Part(frac) => s = part32(s, frac),
            _ => {}
        }
        if LOOK {
            let g = if self.look.smooth {
                trilinear_vec(&self.grads, uc.into())
            } else {
                Vec3A::from(self.c.gradient(uc) * self.inv)
            };
            s = self.look.apply(s, g);
        }
        // Front to back: colour and opacity both gain (1 - a) s.
        let w = 1.0 - self.acc.w;
        self.acc += w * s;
        if self.acc.w > self.stop {
            Took::Stop
        } else if faint {
            self.last.set((s, w));
            Took::Faint
        } else {
            Took::Added
        }
    }

    fn trim(&mut self, keep: f64) {
        let (s, w) = self.last.get();
        let p = part32(s, keep);
        self.acc = (self.acc - w * (s - p)).with_w(1.0 - w * (1.0 - p.w));
    }

    #[inline(always)]
    fn batches(&self) -> bool {
        self.batches.is_some()
    }

    #[inline(always)]
    fn batch(&mut self, acc: &mut Accessor, cell: [u32; 3], k: f64, onset: &Onset) -> (u64, End) {
        let Some(map) = self.batches else {
            return (0, End::Brick);
        };
        let x = Batches {
            map,
            coords: self.coords,
            ray: self.ray,
            step: self.step,
            lut: self.lut,
            resume: RESUME_CODE,
            stop: self.stop,
            shade: (LOOK && self.look.look.shade).then_some(self.look.to_eye),
            gradient_opacity: (LOOK && !self.look.look.gradient_opacity.is_empty())
                .then_some(self.look.look),
            onset,
            last: &self.last,
            again: Default::default(),
        };
        let mut src = BatchSource {
            acc,
            cell,
            coords: self.coords,
        };
        batch::run(&x, &mut src, k, &mut self.acc)
    }
}

/// The batches' [`batch::Source`]: the brick of the marcher's cell, and
/// the gradients of a cell its plane has not set, computed (and kept in
/// the plane) as the one-at-a-time sampler computes them
/// ([`outer_cell_gradients`]).
struct BatchSource<'a, 'c> {
    acc: &'a mut Accessor<'c>,
    cell: [u32; 3],
    coords: [&'a [f64]; 3],
}

impl batch::Source for BatchSource<'_, '_> {
    #[inline(always)]
    fn brick(&mut self) -> &RBrick {
        self.acc.brick(self.cell).0
    }

    #[cold]
    fn gradients(&mut self, cell: [u32; 3]) -> [Vec3A; 8] {
        outer_cell_gradients(self.acc, self.coords, cell)
    }
}
