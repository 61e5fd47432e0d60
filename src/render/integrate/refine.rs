//! Where the composite's samples go: the lattice `t = k * step`
//! ([`first_sample`]), the cells of positions along the ray as the run
//! marcher's plane crossings find them ([`cell_at`], [`cell_near`]), and
//! the lattice restarted where the opacity rises ([`rephase`]).
//!
//! # Onset refinement (issue 51, wood grain)
//!
//! With samples at fixed multiples of the step, the first sample past a
//! sharp rise of opacity lies anywhere in the step behind it, wherever
//! the lattice happens to fall. With a transfer function opaque from a
//! threshold and coloured by value (`ct-soft-tissue`: opacity 0 up to
//! -167 HU, 1 from -160 HU, grey rising with the value) a pixel shows the
//! value at that sample, so neighbouring rays, whose lattices cross the
//! surface at slowly drifting depths, draw bands: wood grain.
//!
//! The remedy is the hitpoint refinement of GPU ray casters (Hadwiger,
//! Sigg, Scharsach, Buehler and Gross, "Real-time ray-casting and
//! advanced shading of discrete isosurfaces", Eurographics 2005; for
//! direct volume rendering Scharsach, Hadwiger, Neubauer, Wolfsberger
//! and Buehler, "Perspective isosurface and direct volume rendering for
//! virtual endoscopy applications", EuroVis 2006): where the ray steps
//! from a sample without opacity to one with, bisect between the two for
//! where the opacity begins and restart the samples there. Here:
//!
//! * A sample is *faint* when its table opacity is below that of
//!   [`ONSET_OPACITY`] (1/8 per mm: 0.065 a sample at 0.5 mm). The first
//!   sample that is not faint after faint ones (or none, or 0-cells) is
//!   an *onset*: the marcher does not composite it but calls [`rephase`].
//! * [`rephase`] bisects between the two samples for the *onset* proper,
//!   where the table opacity reaches the faint threshold (to `step /
//!   64`). The transfer function's segment there rises towards a point,
//!   the ramp's *top*; where the ray passes it within a step, a second
//!   bisection finds it (to `step / 1024`), one partial sample at the
//!   middle of `[onset, top]` stands for the ramp, its opacity corrected
//!   for the partial length `L` (`1 - (1 - a)^(L / step)`, [`part`]), and
//!   the lattice restarts at the top: `t_top + j * step`. Else (a ramp
//!   wider than a step) the lattice restarts at the onset.
//! * The samples then sit at fixed depths below the surface, so their
//!   colour varies with the data, not with the lattice. An opaque
//!   threshold is drawn in the transfer function's colour at its top,
//!   where its opacity reaches 1: what the rendering integral gives, to
//!   which finer steps converge, where the fixed lattice drew the colour
//!   a random depth (up to a step) inside.
//! * Faint samples are not refined: one takes too small a share of its
//!   pixel for the lattice's phase to show, and gentle ramps (`ct-bone`'s
//!   soft tissue, about 0.06 per mm) would pay a bisection per ray for
//!   nothing one could see. The refinements' positions depend only on
//!   the ray, so images stay the same for any thread count, tile size or
//!   traversal, and the f32 and f64 samplers restart at the same places:
//!   the bisections evaluate in f64, and an f32 sample whose opacity lies
//!   within a rounding of the threshold is called faint or not by its f64
//!   value ([`faint_band`], [`faint64`]).
//! * The faint sample before an onset stood for the step after it, which
//!   the restarted samples now cover from the onset on: it keeps only the
//!   part of its step before the onset ([`Onset::kept`], its opacity
//!   corrected as a partial sample's). So an onset a rounding after a
//!   faint sample draws what one a rounding before it draws.
//! * After a restart neither the samples up to the top nor the next one
//!   is an onset ([`Onset::restarted`]): where the samplers' f32 value and
//!   the bisection's f64 value disagree by a rounding at the threshold,
//!   the marcher does not refine the same onset again and again.
//!
//! The grain figure of [`render::output::grain`](crate::render::output::grain) (a
//! render at 0.5 mm against 0.125 mm; 1 is clean) with an
//! opaque-from-threshold function coloured by value falls from 11.8 (9.2
//! shaded) to 1.0 on the real CT and from 17.6 (15.9) to 1.0 on the CT
//! phantom; for `ct-soft-tissue` from 3.3 to 1.0, while `ct-bone`,
//! `ct-muscle` and `ct-skin`, without visible grain, read 1.0-1.1 before
//! and after. The other remedy, interleaved sampling or a per-ray jitter
//! of the lattice, turns the bands into speckle of the same energy: the
//! figure stays where it was (12.4 on the real CT). The cost is
//! 5,500-6,800 instructions per onset, 12-25 % of a 512^2 frame with an
//! opaque surface, which stops its rays soon after (docs/TRADEOFFS.md,
//! "Wood grain").

use std::cell::Cell;

use glam::Vec4;

use super::Ctx;
use crate::classify::TransferFunction;
use crate::render::cache::Accessor;
use crate::render::sample::lut::{exact_sample, TfLut};
use crate::render::sample::shade::AlongRay;
use crate::render::traverse::{Ray, Real, OBJECT};

/// The opacity per mm below which samples are faint: a sample after
/// faint ones (or transparent ones, or none) whose opacity reaches it is
/// an onset. The threshold in the table's opacity per sample is `1 - (1 -
/// 1/8)^step` (0.065 at the default 0.5 mm), below which one sample
/// takes too small a share of its pixel for the lattice's phase to show
/// (a few grey levels at most): a sharp rise of opacity is refined, the
/// first samples of a gentle ramp (`ct-bone`'s soft tissue, about 0.06
/// per mm) are not, which would cost a bisection per ray and change
/// nothing one could see. Being per mm, the onsets lie where they lie
/// whatever the step.
pub(super) const ONSET_OPACITY: f64 = 0.125;

/// Bisection steps that locate an onset: the bracket, one step wide,
/// shrinks to `step / 64`. Enough to tell which ramp the ray climbs and
/// where its top lies; where the lattice restarts at the onset itself
/// (a ramp wider than a step), the samples after it lie within `step /
/// 64` of fixed depths, where the unrefined lattice put them anywhere in
/// a step.
pub(super) const ONSET_ITERS: u32 = 6;

/// Bisection steps that locate a ramp's top in a bracket of at most a
/// step: to `step / 1024` (0.5 um at 0.5 mm; through a skin's 1000 HU
/// per mm, 0.5 HU: a fifth of a grey level of a ramp from 0 to 1 over
/// 400 HU).
pub(super) const TOP_ITERS: u32 = 10;

/// How far below the ramp top's opacity the table may stay where the
/// lattice restarts at the top ([`rephase`]): the table's kink there is
/// exact only a bin away.
const TOP_SHORT: f64 = 1e-3;

/// What [`rephase`] needs of the transfer function: the points' values
/// and opacities, the table opacity (for the composite's step) from
/// which a sample is past each point, and the table opacity below which
/// samples are faint ([`ONSET_OPACITY`]).
#[derive(Clone, Debug)]
pub(crate) struct Ramps {
    value: Vec<f64>,
    opacity: Vec<f64>,
    need: Vec<f64>,
    faint: f64,
    band: f64,
}

impl Ramps {
    /// The ramps of `tf` for samples `step_mm` apart.
    pub(crate) fn new(tf: &TransferFunction, step_mm: f64) -> Ramps {
        let p = &tf.points;
        Ramps {
            value: p.iter().map(|q| q.value).collect(),
            opacity: p.iter().map(|q| q.opacity).collect(),
            need: p
                .iter()
                .map(|q| (1.0 - TOP_SHORT) * exact_sample(tf, step_mm, q.value).1)
                .collect(),
            faint: 1.0 - (1.0 - ONSET_OPACITY).powf(step_mm),
            band: faint_band(tf, step_mm),
        }
    }

    /// How far from the faint threshold an f32 sample's table opacity
    /// may lie for the f64 value to decide ([`faint_band`]).
    pub(crate) fn band(&self) -> f64 {
        self.band
    }

    /// The table opacity below which a sample is faint.
    pub(crate) fn faint(&self) -> f64 {
        self.faint
    }

    /// The top of the ramp a ray climbs at an onset with value `v`: the
    /// end of the transfer function's segment holding `v` towards which
    /// the opacity rises (the ray's values go that way, since the
    /// opacity rises along it there), as the table opacity from which a
    /// sample is past it; `None` outside the points, on a flat segment,
    /// or when the top's opacity is faint.
    pub(crate) fn top(&self, v: f64) -> Option<f64> {
        let j = self.value.partition_point(|&x| x <= v);
        let (lo, hi) = (self.opacity.get(j.checked_sub(1)?)?, self.opacity.get(j)?);
        let top = if hi > lo {
            j
        } else if hi < lo {
            j - 1
        } else {
            return None;
        };
        Some(self.need[top]).filter(|&n| n >= self.faint)
    }
}

/// Bits of an f32 sample's value error, relative to the largest value of
/// the transfer function's points: the f32 trilinear evaluation and the
/// local coordinates advanced per sample through a cell are good to a
/// few 1e-7 of the values; 2^-14 (6e-5) leaves a hundredfold margin.
const F32_VALUE_BITS: i32 = 14;

/// The band of table opacity around the faint threshold inside which an
/// f32 sampler does not trust its own opacity to tell faint from not and
/// asks the f64 value ([`faint64`]): the steepest rise of the table
/// opacity at the threshold (where the opacity per mm is
/// [`ONSET_OPACITY`], `step (1 - 1/8)^(step - 1)` times the steepest
/// segment of the transfer function) over the f32 value error
/// ([`F32_VALUE_BITS`]). Whether a sample is faint decides whether the
/// lattice restarts after it, so a sample that the two precisions call
/// differently moved the f32 lattice against the f64 one: the
/// brute-force oracle test found pixels 6/255 and 11/255 apart. The
/// samples inside the band lie within the value error of where the table
/// crosses the threshold: few, on any function whose opacity does not
/// stay at the threshold.
fn faint_band(tf: &TransferFunction, step_mm: f64) -> f64 {
    let p = &tf.points;
    let steepest = p
        .windows(2)
        .filter(|w| w[1].value > w[0].value)
        .map(|w| ((w[1].opacity - w[0].opacity) / (w[1].value - w[0].value)).abs())
        .fold(0.0, f64::max);
    let scale = p.iter().map(|q| q.value.abs()).fold(1.0, f64::max);
    let rise = step_mm * (1.0 - ONSET_OPACITY).powf(step_mm - 1.0) * steepest;
    let band = rise * scale * 2f64.powi(-F32_VALUE_BITS);
    // A step (an infinite slope) or a value scale beyond f64: every
    // sample near the threshold asks.
    if band.is_finite() {
        band + 1e-6
    } else {
        f64::INFINITY
    }
}

/// Whether the sample at `t` in 1-cell `cell` (vertex values `f`) is
/// faint by its f64 value: the f64 sampler's decision, which the f32
/// samplers take where their own opacity lies within [`Onset::band`] of
/// the threshold.
#[inline(never)]
pub(super) fn faint64(
    coords: [&[f64]; 3],
    ray: &Ray,
    lut: &TfLut,
    (cell, f): ([u32; 3], [f32; 8]),
    t: f64,
    faint: f64,
) -> bool {
    lut.sample(AlongRay::new(coords, cell, f, ray).value(t))[3] < faint
}

/// The table opacity below which the samplers of `ctx` call a sample
/// faint (without ramps, every sample: none is an onset).
pub(super) fn faint<T: Real>(ctx: &Ctx<T>) -> f64 {
    ctx.ramps.as_ref().map_or(f64::INFINITY, Ramps::faint)
}

/// [`Ramps::band`] of `ctx` (without ramps 0: nothing to decide).
pub(super) fn band<T: Real>(ctx: &Ctx<T>) -> f64 {
    ctx.ramps.as_ref().map_or(0.0, Ramps::band)
}

/// How the marcher wants a sample taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum How {
    /// Composited.
    Plain,
    /// Composited unless its opacity is not faint: then left as an
    /// onset.
    Onset,
    /// Composited as standing for this fraction of a step (the ramp
    /// before a restart at its top): opacity `1 - (1 - a)^f`, colour
    /// in proportion.
    Part(f64),
}

/// What a composite sampler did with one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Took {
    /// Transparent: nothing composited.
    Clear,
    /// Faint, and composited.
    Faint,
    /// Composited.
    Added,
    /// Composited, and the ray is now opaque.
    Stop,
    /// Not composited: an onset to refine ([`rephase`]).
    Onset,
}

/// The table sample `s` (premultiplied colour, opacity) as standing for
/// `frac` of a step ([`How::Part`]).
#[inline]
pub(super) fn part(s: [f64; 4], frac: f64) -> [f64; 4] {
    let a = s[3];
    if a <= 0.0 {
        return s;
    }
    let b = 1.0 - (1.0 - a).max(0.0).powf(frac);
    s.map(|x| x * (b / a))
}

/// [`part`] of an f32 sample.
#[inline]
pub(super) fn part32(s: Vec4, frac: f64) -> Vec4 {
    Vec4::from_array(part(s.to_array().map(f64::from), frac).map(|x| x as f32))
}

/// The marcher's onset state, which the batches read and leave updated.
#[derive(Debug)]
pub(super) struct Onset {
    /// Whether the last sample handled was faint (0-cell, transparent,
    /// below the threshold, or none yet).
    pub clear: Cell<bool>,
    /// Only a sample after a faint one with a lattice index above this
    /// is an onset (the restarted samples and the one after are not).
    pub from: Cell<f64>,
    /// The lattice index of the last sample, if it was composited as
    /// faint (NaN if not): an onset right after it trims it
    /// ([`Onset::kept`]).
    pub faint_k: Cell<f64>,
    /// The table opacity below which a sample is faint.
    pub faint: f64,
    /// Within this of `faint`, an f32 sampler asks [`faint64`].
    pub band: f64,
}

impl Onset {
    /// The state at the start of a ray: nothing taken, any onset refined;
    /// samples faint below table opacity `faint`, decided in f64 within
    /// `band` of it.
    pub(super) fn new(faint: f64, band: f64) -> Onset {
        Onset {
            clear: Cell::new(true),
            from: Cell::new(f64::NEG_INFINITY),
            faint_k: Cell::new(f64::NAN),
            faint,
            band,
        }
    }

    /// The state of a marcher that refines nothing.
    pub(super) fn off() -> Onset {
        Onset {
            clear: Cell::new(false),
            from: Cell::new(f64::INFINITY),
            faint_k: Cell::new(f64::NAN),
            faint: f64::INFINITY,
            band: 0.0,
        }
    }

    /// How the sample with lattice index `k` is to be taken: as a
    /// possible onset after a faint sample.
    #[inline(always)]
    pub(super) fn how(&self, k: f64) -> How {
        if self.clear.get() && k > self.from.get() {
            How::Onset
        } else {
            How::Plain
        }
    }

    /// The lattice restarted, its first full sample at index `k`:
    /// neither the samples up to it nor the next one is an onset.
    pub(super) fn restarted(&self, k: f64) {
        self.from.set(k + 1.5);
        self.faint_k.set(f64::NAN);
    }

    /// The share of its step that the faint sample just before the onset
    /// sample `k` keeps when the restarted samples stand from `from` on
    /// (a `t`, [`Restart::from`]): the part of its step before `from`.
    /// `None` when the sample before the onset was not composited as
    /// faint. Without the trim the step's overlap was counted twice, and
    /// an onset just past a faint sample drew up to the faint opacity
    /// (0.065 at 0.5 mm) more than one just before it, where the samples
    /// it started from differed by a rounding: f32 and f64 samplers
    /// called such a sample faint or not by that rounding, and their
    /// pixels differed by up to 11/255.
    pub(super) fn kept(&self, k: f64, from: f64, step: f64) -> Option<f64> {
        let f = self.faint_k.get();
        ((k - f - 1.0).abs() < 0.25).then(|| ((from - f * step) / step).clamp(0.0, 1.0))
    }
}

/// What one composite ray marches along: the ray, the transfer
/// function's table for the step, and the step in mm (the lattice's
/// spacing).
#[derive(Clone, Copy)]
pub(super) struct Course<'a> {
    pub ray: &'a Ray,
    pub lut: &'a TfLut,
    pub step: f64,
    /// The last `t` the clip keeps (infinite without one).
    pub end: f64,
}

/// Where [`rephase`] restarts the lattice.
#[derive(Clone, Copy, Debug)]
pub(super) struct Restart {
    /// The index of the next sample (the partial one, if any) and its
    /// cell.
    pub k: f64,
    pub cell: [u32; 3],
    /// The partial sample's fraction of a step and the index of the
    /// first full sample after it.
    pub part: Option<(f64, f64)>,
    /// Where the restarted samples' steps begin: the onset, or the top
    /// when the lattice restarts at a top behind the onset.
    pub from: f64,
}

/// Where the lattice restarts before the onset sample at `t` (in cell
/// `cell`); `None` when the restart lies outside the volume.
///
/// The onset is where the table opacity reaches the faint threshold (in
/// a 1-cell, by the f64 interpolant), bisected in `[t - step, t]`. When
/// the ray then passes the transfer function's next point ([`Ramps::top`],
/// the top of the ramp it climbs) within a step of the onset, the
/// lattice restarts at the top, bisected in the bracket that holds it
/// (`[onset, t]` when the sample at `t` is past it, else
/// `[onset, onset + step]`), after one partial sample at the middle of
/// `[onset, top]` for the ramp; else at the onset.
pub(super) fn rephase<T: Real>(
    ctx: &Ctx<T>,
    course: &Course,
    acc: &mut Accessor,
    ramps: &Ramps,
    cell: [u32; 3],
    t: f64,
) -> Option<Restart> {
    let Course { ray, lut, step, .. } = *course;
    let mut p = Probe {
        coords: ctx.coords,
        ray,
        from: cell,
        held: None,
    };
    let onset_at = |v: Option<f64>| v.is_some_and(|v| lut.sample(v)[3] >= ramps.faint);
    let mut onset = (t - step, t);
    bisect(&mut p, acc, &mut onset, ONSET_ITERS, onset_at);
    let w = p.value(acc, t);
    let need = p.value(acc, onset.1).and_then(|v| ramps.top(v));
    let mut top = None;
    if let Some(need) = need {
        let past = |v: Option<f64>| v.is_some_and(|v| lut.sample(v)[3] >= need);
        let end = onset.1 + step;
        let mut bracket = if past(w) {
            Some((onset.0, t))
        } else {
            past(p.value(acc, end)).then_some((onset.1, end))
        };
        if let Some(b) = &mut bracket {
            bisect(&mut p, acc, b, TOP_ITERS, past);
            top = Some(b.1);
        }
    }
    let restart = |at: f64, part, from| {
        let k = at / step;
        cell_near(ctx.coords, ray, cell, k * step).map(|cell| Restart {
            k,
            cell,
            part,
            from,
        })
    };
    match top {
        Some(top) if top > onset.1 => {
            let part = ((top - onset.1) / step, top / step);
            restart(0.5 * (onset.1 + top), Some(part), onset.1)
        }
        Some(top) => restart(top, None, top),
        None => restart(onset.1, None, onset.1),
    }
}

/// Shrinks the bracket `(lo, hi)` by `iters` bisection steps around
/// where `yes` of the value turns true (false at `lo`, true at `hi`).
#[inline]
fn bisect(
    p: &mut Probe,
    acc: &mut Accessor,
    (lo, hi): &mut (f64, f64),
    iters: u32,
    yes: impl Fn(Option<f64>) -> bool,
) {
    for _ in 0..iters {
        let mid = 0.5 * (*lo + *hi);
        if yes(p.value(acc, mid)) {
            *hi = mid;
        } else {
            *lo = mid;
        }
    }
}

/// Positions along a ray evaluated for [`rephase`]: the cell holding
/// each found from `from`, the last cell met kept with its span of `t`
/// and, for a 1-cell, its interpolant, so that the bisection's probes
/// within one cell cost the interpolation only.
struct Probe<'a> {
    coords: [&'a [f64]; 3],
    ray: &'a Ray,
    from: [u32; 3],
    held: Option<Held>,
}

/// A cell [`Probe`] met: where the ray is in it, `[t_in, t_out)`, and
/// its interpolant unless it is a 0-cell.
struct Held {
    cell: [u32; 3],
    t_in: f64,
    t_out: f64,
    along: Option<AlongRay>,
}

impl Probe<'_> {
    /// The f64 value at `t`: `None` outside the volume and in 0-cells.
    #[inline(always)]
    fn value(&mut self, acc: &mut Accessor, t: f64) -> Option<f64> {
        match &self.held {
            Some(h) if h.t_in <= t && t < h.t_out => h.along.as_ref().map(|a| a.value(t)),
            _ => self.refill(acc, t),
        }
    }

    /// [`Probe::value`] in a cell other than the one held, which it then
    /// holds.
    #[inline(never)]
    fn refill(&mut self, acc: &mut Accessor, t: f64) -> Option<f64> {
        let from = self.held.as_ref().map_or(self.from, |h| h.cell);
        let c = cell_near(self.coords, self.ray, from, t)?;
        let (b, l) = acc.brick(c);
        let along =
            (b.code(l) == OBJECT).then(|| AlongRay::new(self.coords, c, b.vertices(l), self.ray));
        let (t_in, t_out) = span(self.coords, self.ray, c);
        let h = self.held.insert(Held {
            cell: c,
            t_in,
            t_out,
            along,
        });
        h.along.as_ref().map(|a| a.value(t))
    }
}

/// Where the ray is in cell `c` as the marcher's planes say: `[t_in,
/// t_out)`, the latest entry and the earliest exit over the axes.
fn span(coords: [&[f64]; 3], ray: &Ray, c: [u32; 3]) -> (f64, f64) {
    let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        let (o, d) = (ray.origin[a], ray.dir[a]);
        let i = c[a] as usize;
        let (lo, hi) = ((coords[a][i] - o) / d, (coords[a][i + 1] - o) / d);
        if d > 0.0 {
            (t_in, t_out) = (t_in.max(lo), t_out.min(hi));
        } else if d < 0.0 {
            (t_in, t_out) = (t_in.max(hi), t_out.min(lo));
        }
    }
    (t_in, t_out)
}

/// The cell holding the ray's position at `t` as the run marcher's plane
/// crossings assign it (cell `c` holds `[enter(c), ahead(c))`), walked
/// from cell `from` back or forth; `None` outside the volume.
pub(super) fn cell_near(
    coords: [&[f64]; 3],
    ray: &Ray,
    from: [u32; 3],
    t: f64,
) -> Option<[u32; 3]> {
    let mut c = from;
    for a in 0..3 {
        let (o, d) = (ray.origin[a], ray.dir[a]);
        let last = (coords[a].len() - 2) as u32;
        // The `t` of plane `i`, as the marcher computes it.
        let plane = |i: u32| (coords[a][i as usize] - o) / d;
        let i = &mut c[a];
        if d > 0.0 {
            // Cell i: [plane(i), plane(i + 1)).
            while plane(*i + 1) <= t {
                if *i == last {
                    return None;
                }
                *i += 1;
            }
            while plane(*i) > t {
                if *i == 0 {
                    return None;
                }
                *i -= 1;
            }
        } else if d < 0.0 {
            // Cell i: [plane(i + 1), plane(i)).
            while plane(*i) <= t {
                if *i == 0 {
                    return None;
                }
                *i -= 1;
            }
            while plane(*i + 1) > t {
                if *i == last {
                    return None;
                }
                *i += 1;
            }
        }
    }
    Some(c)
}

/// The cell along axis `a` of the ray's sample at `t`, found forward
/// from cell `from` (that of an earlier sample) exactly as the run
/// marcher's plane crossings (`ahead(a, i) <= t`) would find it; `None`
/// when the ray leaves the volume first. It jumps to the cell the
/// position names (batch.rs's `IndexMap`) and corrects by the
/// planes, so the batches' samples cost no crossing each.
pub(super) fn cell_at<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    a: usize,
    from: u32,
    t: f64,
    ahead: &impl Fn(usize, u32) -> f64,
) -> Option<u32> {
    let d = ray.dir[a];
    if d == 0.0 {
        return Some(from);
    }
    let n = (ctx.coords[a].len() - 1) as u32;
    let guess = ctx
        .index_map
        .as_ref()
        .map_or(from, |m| m.cell(a, ray.origin[a] + t * d, n));
    let mut c;
    if d > 0.0 {
        c = guess.max(from);
        while ahead(a, c) <= t {
            c += 1;
            if c >= n {
                return None;
            }
        }
        while c > from && ahead(a, c - 1) > t {
            c -= 1;
        }
    } else {
        c = guess.min(from);
        while ahead(a, c) <= t {
            if c == 0 {
                return None;
            }
            c -= 1;
        }
        while c < from && ahead(a, c + 1) > t {
            c += 1;
        }
    }
    Some(c)
}

/// `ceil(t / step)`, the first composite sample at or after `t`, with a
/// multiplication by `inv_step = 1 / step` instead of the division where
/// that cannot change the result: the two quotients differ by a few ulps,
/// so only when `t / step` is within 1e-12 (relative) of an integer does
/// the division decide.
#[inline]
pub(super) fn first_sample(t: f64, step: f64, inv_step: f64) -> f64 {
    let q = t * inv_step;
    let k = ceil(q);
    // Distance to the nearest integer (no libm `round`).
    if (k - q).min(q - (k - 1.0)) <= 1e-12 * q.abs().max(1.0) {
        ceil(t / step)
    } else {
        k
    }
}

/// `x.ceil()` without a libm call (the default x86-64 target has no
/// rounding instruction); the same value for every `x`.
#[inline]
fn ceil(x: f64) -> f64 {
    const BIG: f64 = (1u64 << 52) as f64;
    if x.abs() < BIG {
        // |x| < 2^52: truncation is exact in i64, and so is adding 1.
        let t = x as i64 as f64;
        if t < x {
            t + 1.0
        } else {
            t
        }
    } else {
        // Already an integer, infinite or NaN.
        x
    }
}

#[cfg(test)]
#[path = "refine_tests.rs"]
mod tests;
