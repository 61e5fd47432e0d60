//! The composite's samples eight at a time (`--sample-batches`, on by
//! default; unshaded, or with smooth gradients for shading and gradient
//! opacity): the run marcher of composite.rs hands the samples of a
//! 1-cell run to [`run`], which takes them in batches of [`LANES`] along
//! the ray and finds each sample's cell by its position instead of
//! crossing the cell planes one at a time: on a uniform axis `floor` of
//! its index coordinate, on a rectilinear one (varying slice thickness) a
//! table lookup and one comparison ([`RectAxis`]). The
//! positions, cells, local coordinates and plane indices of the eight
//! samples are one loop over eight lanes, which the compiler turns into
//! SIMD arithmetic (AVX2 where the CPU has it, [`run`] dispatches); the
//! codes, the vertices, the trilinear value and the table go lane by
//! lane, and the samples are composited in order, the opacity carried as
//! transmittance. Shaded or with gradient opacity, each lane's gradient
//! is interpolated from its cell's vertex gradients in the brick's
//! gradient plane, the gradient opacity scales the sample by the
//! gradient's length, and the headlight's square roots and divisions go
//! in lanes ([`light`]). A sample whose cell the plane has not set yet
//! (a cell on the brick's outer layer, set by the first ray that needs
//! it) ends its batch before anything of the batch is composited; [`run`]
//! asks its [`Source`] for the cell's gradients and takes the same batch
//! again with them, from the same sample and with the same carried
//! colour, so the image does not depend on which thread set a cell first.
//!
//! What changes against the sampler one sample at a time: a sample on or
//! within rounding of a cell face may be given the neighbouring cell.
//! The trilinear interpolants of two cells agree on their shared face,
//! so the value moves by rounding only; a 0-cell's samples are
//! transparent either way (the transfer function is zero over its value
//! range). docs/TRADEOFFS.md ("Sample batches") measures the image
//! difference; docs/BENCHMARKS.md ("Composite samples eight at a time")
//! the time.

use std::cell::Cell;

use glam::{Vec3A, Vec4};

use super::index_map::{IndexMap, RectAxis};
use super::refine::{faint64, Onset};
use crate::render::brick::samples::{gather8, Corners, Samples};
use crate::render::brick::{Codes, RBrick};
use crate::render::options::CompositeLook;
use crate::render::sample::lut::TfLut;
use crate::render::traverse::{Ray, OBJECT};

/// Samples per batch.
pub(super) const LANES: usize = 8;

/// Above every index coordinate of a brick's cells (2^24: f32 counts
/// integers exactly up to it).
const TOP: f32 = 16_777_216.0;

/// Why [`run`] handed the samples back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum End {
    /// The next sample lies outside the brick (or the volume), or the
    /// brick holds no values and code plane to batch.
    Brick,
    /// The next sample lies in a 0-cell whose code says leap
    /// (`>= resume`): the marcher hands the ray back to the traversal.
    Leap,
    /// The ray became opaque.
    Stop,
    /// The next sample is an onset ([`Onset::how`]): the marcher
    /// refines it (refine.rs); nothing of it is composited.
    Onset,
    /// Only between [`lanes`] and [`run`]: the batch at the sample
    /// returned needs the gradients of a cell of the brick
    /// ([`Again::missing`]) that its gradient plane has not set (nothing
    /// of the batch is composited).
    Gradients,
}

/// Where [`run`] reads the ray's brick, and the gradients of a cell its
/// gradient plane has not set.
pub(super) trait Source {
    /// The brick the samples lie in.
    fn brick(&mut self) -> &RBrick;
    /// The 8 vertex gradients (x fastest) of the brick's cell at global
    /// cell index `cell`, as the plane would hold them.
    fn gradients(&mut self, cell: [u32; 3]) -> [Vec3A; 8];
}

/// The gradients [`run`] was given for cells of the current batch that
/// the brick's gradient plane had not set: per cell its index in the
/// code plane and its 8 vertex gradients.
type Given = Vec<(usize, [Vec3A; 8])>;

/// What one ray's batches need besides the brick.
#[derive(Clone)]
pub(super) struct Batches<'a> {
    pub map: &'a IndexMap,
    /// The grid's sample positions, for [`faint64`].
    pub coords: [&'a [f64]; 3],
    pub ray: &'a Ray,
    pub step: f64,
    pub lut: &'a TfLut,
    /// Codes from which the marcher leaps rather than skips.
    pub resume: u8,
    /// Shaded samples (smooth normals from the brick's gradient plane):
    /// the unit vector to the eye.
    pub shade: Option<Vec3A>,
    /// Gradient opacity ([`CompositeLook::gradient_factor`] of the
    /// smooth gradient's length), when the look has any.
    pub gradient_opacity: Option<&'a CompositeLook>,
    pub stop: f32,
    /// The marcher's onset state: read at the first sample, left as the
    /// last sample taken leaves it.
    pub onset: &'a Onset,
    /// The last sample composited as faint and the transmittance before
    /// it, for the onset after it (`Sampler::trim` in composite.rs): read
    /// and left like `onset`.
    pub last: &'a Cell<(Vec4, f32)>,
    /// Only [`run`]'s retry sets it; every caller gives the default.
    pub again: Again<'a>,
}

/// What [`run`] carries into a batch it takes again, and where a kernel's
/// pass leaves the batch that needs it; `Default` (nothing given, nothing
/// missing) from every caller of [`run`].
#[derive(Clone, Default)]
pub(super) struct Again<'a> {
    /// The gradients [`run`] was given for cells of the batch it takes
    /// again that the brick's gradient plane has not set, per cell its
    /// index in the code plane and its 8 vertex gradients.
    pub given: &'a [(usize, [Vec3A; 8])],
    /// The transmittance to take the batch again from.
    pub through: Option<f32>,
    /// Set by the kernels, for [`run`]: where one ending with
    /// [`End::Gradients`] leaves the cell (in the brick) whose gradients
    /// it needs ...
    pub missing: Cell<[u32; 3]>,
    /// ... and the transmittance it carried into that batch.
    pub carried: Cell<f32>,
}

/// Composites samples `k, k + 1, ...` (at `t = k * step`) of the ray into
/// `acc` while they lie in the brick of `src`, [`LANES`] at a time;
/// returns how many it took and why it stopped (never
/// [`End::Gradients`]). A sample in a 0-cell with a code below `resume`
/// adds nothing, as in the marcher.
///
/// With gradients, a batch that needs a cell the brick's plane has not
/// set is taken again once `src` has given that cell's gradients: from
/// the same sample index, whose position the lanes derive from it, and
/// with the same carried colour and transmittance, so that the batch's
/// bits are those of a plane that had the cell set.
#[inline(always)]
pub(super) fn run(x: &Batches, src: &mut impl Source, k: f64, acc: &mut Vec4) -> (u64, End) {
    run_on(x, src, k, acc, true)
}

/// [`run`], by the AVX2 kernels when `avx2` asks for them ([`select`]).
#[inline(always)]
fn run_on(x: &Batches, src: &mut impl Source, k: f64, acc: &mut Vec4, avx2: bool) -> (u64, End) {
    let (taken, end) = select(x, src.brick(), k, acc, avx2);
    if end == End::Gradients {
        return retry(x, src, k, acc, taken, avx2);
    }
    (taken, end)
}

/// [`run_on`] after its first pass ended at a cell without gradients
/// (`taken` samples in): the missing cells' gradients asked of `src`
/// and the batch taken again, until a pass ends otherwise. Cold: only
/// the first rays into a brick's outer cells come here.
#[cold]
#[inline(never)]
fn retry(
    x: &Batches,
    src: &mut impl Source,
    k: f64,
    acc: &mut Vec4,
    mut taken: u64,
    avx2: bool,
) -> (u64, End) {
    let mut given = Given::new();
    // The batch start the given gradients are for.
    let mut given_at = taken;
    // Where the last pass left: the cell it needs and the transmittance
    // its batch started with.
    let (mut local, mut carried) = (x.again.missing.get(), x.again.carried.get());
    loop {
        if given_at != taken {
            given.clear();
            given_at = taken;
        }
        let b = src.brick();
        let (first, cells) = (b.first, b.cells);
        let at = (local[2] as usize * cells[1] as usize + local[1] as usize) * cells[0] as usize
            + local[0] as usize;
        let g = src.gradients(std::array::from_fn(|a| first[a] + local[a]));
        given.push((at, g));
        // The batch again from the transmittance it started with, not
        // from `1 - acc.w`, which need not round back to it.
        let y = Batches {
            again: Again {
                given: &given,
                through: Some(carried),
                ..Again::default()
            },
            ..x.clone()
        };
        let (n, end) = select(&y, src.brick(), k + taken as f64, acc, avx2);
        taken += n;
        if end != End::Gradients {
            return (taken, end);
        }
        (local, carried) = (y.again.missing.get(), y.again.carried.get());
    }
}

/// One pass of [`run`] by one of four kernels, with gradients (shading or
/// gradient opacity) or without, on a uniform or a rectilinear grid:
/// compiled for AVX2 when `avx2` asks for it and the CPU has it (four
/// functions, so none's code is laid out around another's), else for the
/// baseline CPU.
fn select(x: &Batches, b: &RBrick, k: f64, acc: &mut Vec4, avx2: bool) -> (u64, End) {
    let grads = x.shade.is_some() || x.gradient_opacity.is_some();
    match (grads, x.map.rect.is_some()) {
        (false, false) => kernel::<false, false>(x, b, k, acc, avx2),
        (false, true) => kernel::<false, true>(x, b, k, acc, avx2),
        (true, false) => kernel::<true, false>(x, b, k, acc, avx2),
        (true, true) => kernel::<true, true>(x, b, k, acc, avx2),
    }
}

/// See [`select`].
#[inline(always)]
fn kernel<const GRAD: bool, const RECT: bool>(
    x: &Batches,
    b: &RBrick,
    k: f64,
    acc: &mut Vec4,
    avx2: bool,
) -> (u64, End) {
    #[cfg(target_arch = "x86_64")]
    if avx2 && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { run_avx2::<GRAD, RECT>(x, b, k, acc) };
    }
    let _ = avx2;
    values::<GRAD, RECT>(x, b, k, acc)
}

/// [`values`] compiled for AVX2: the same code, the same results (no
/// fused multiply-add: Rust does not contract `a + b * c`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn run_avx2<const GRAD: bool, const RECT: bool>(
    x: &Batches,
    b: &RBrick,
    k: f64,
    acc: &mut Vec4,
) -> (u64, End) {
    values::<GRAD, RECT>(x, b, k, acc)
}

/// [`lanes`] with the brick's kind of values, with gradients or not, on a
/// rectilinear grid or not.
#[inline(always)]
fn values<const GRAD: bool, const RECT: bool>(
    x: &Batches,
    b: &RBrick,
    k: f64,
    acc: &mut Vec4,
) -> (u64, End) {
    let Codes::Plane(codes) = &b.codes else {
        return (0, End::Brick);
    };
    // Gradients come from the brick's gradient plane.
    if GRAD && b.grads.is_empty() {
        return (0, End::Brick);
    }
    match &b.values {
        Samples::F32(v) => lanes::<GRAD, RECT>(x, b, codes, k, acc, |c| gather8(v, c, |x| x)),
        Samples::Words16(w, t, _) => {
            lanes::<GRAD, RECT>(x, b, codes, k, acc, |c| gather8(w, c, |x| t[x as usize]))
        }
        Samples::Words8(w, t, _) => {
            lanes::<GRAD, RECT>(x, b, codes, k, acc, |c| gather8(w, c, |x| t[x as usize]))
        }
        Samples::Empty => (0, End::Brick),
    }
}

/// [`run`] on brick `b` with code plane `codes`, whose cells' vertex
/// values `vertices` reads (x fastest, as [`RBrick::vertices`]); with
/// `GRAD`, weighted by the gradient opacity and lit by [`light`] with the
/// gradients of the brick's gradient plane ([`shaded`]); with `RECT`,
/// each lane's cells from the map's [`RectAxis`] tables.
#[inline(always)]
fn lanes<const GRAD: bool, const RECT: bool>(
    x: &Batches,
    b: &RBrick,
    codes: &[u8],
    k: f64,
    acc: &mut Vec4,
    vertices: impl Fn(Corners) -> [f32; 8],
) -> (u64, End) {
    let cells = b.cells;
    let (sx, sy) = (cells[0] as usize + 1, cells[1] as usize + 1);
    let sxy = sx * sy;
    // Brick-local index coordinate per axis, `q(t) = q0 + t * qd`; on a
    // rectilinear axis, the position relative to the axis's first sample.
    let (m, ray) = (x.map, x.ray);
    let rect: [Option<&RectAxis>; 3] = match (RECT, m.rect.as_deref()) {
        (true, Some(r)) => r.each_ref().map(Option::as_ref),
        _ => [None; 3],
    };
    let q0: [f64; 3] = std::array::from_fn(|a| {
        if rect[a].is_some() {
            ray.origin[a] - m.s0[a]
        } else {
            (ray.origin[a] - m.s0[a]) * m.inv_h[a] - b.first[a] as f64
        }
    });
    let qd: [f64; 3] = std::array::from_fn(|a| {
        if rect[a].is_some() {
            ray.dir[a]
        } else {
            ray.dir[a] * m.inv_h[a]
        }
    });
    // Per lane, the increment of `q` by one step, in f32.
    let dq: [f32; 3] = std::array::from_fn(|a| (x.step * qd[a]) as f32);
    let lane: [f32; LANES] = std::array::from_fn(|j| j as f32);
    // The ray's colour and transmittance (1 - opacity) so far (a batch
    // taken again: the transmittance it started with); it stops once the
    // transmittance falls below `clear` (opacity above `stop`).
    // The colour is kept in a `Vec4` whose `w` is never read: one
    // vector, where a `Vec3` was a scalar and a pair, each spilled and
    // reloaded on every sample (docs/BENCHMARKS.md, "The colour carried
    // in a `Vec4`").
    let mut colour = *acc;
    let mut through = x.again.through.unwrap_or(1.0 - acc.w);
    let clear = 1.0 - x.stop;
    // Whether the last sample was faint, for onsets (refine.rs), and the
    // last one composited as faint, for the trim after an onset.
    let (mut gap, from) = (x.onset.clear.get(), x.onset.from.get());
    let (mut faint_k, mut last) = (x.onset.faint_k.get(), x.last.get());
    let (faint, band) = (x.onset.faint as f32, x.onset.band as f32);
    let mut taken = 0u64;
    loop {
        let (batch_gap, batch_faint) = (gap, (faint_k, last));
        let t = (k + taken as f64) * x.step;
        let base: [f32; 3] = std::array::from_fn(|a| (q0[a] + t * qd[a]) as f32);
        // Each lane's cell and local coordinates: `floor(q)` as the
        // truncation of `q + 1` (clamped to [0, 2^24], so that it converts
        // without the checks of `as`), less 1. A lane whose `q + 1` rounds
        // up to an integer gets the next cell with a local coordinate a
        // rounding below 0, clamped as the one-at-a-time sampler clamps.
        // Then whether the cell is in the brick (-1 wraps to above any
        // size), its index in the code plane and its minimum corner's in
        // the values.
        let mut u = [[0f32; LANES]; 3];
        let mut local = [[0u32; 3]; LANES];
        let mut inside = [0u32; LANES];
        let mut code_at = [0usize; LANES];
        let mut value_at = [0usize; LANES];
        for j in 0..LANES {
            let mut c = [0u32; 3];
            for a in 0..3 {
                let q = base[a] + lane[j] * dq[a];
                if let (true, Some(r)) = (RECT, rect[a]) {
                    (c[a], u[a][j]) = r.cell(q, b.first[a]);
                    continue;
                }
                // Not `clamp`, which keeps NaN.
                #[allow(clippy::manual_clamp)]
                let q1 = (q + 1.0).max(0.0).min(TOP);
                // SAFETY: `q1` is in [0, 2^24] (`max` takes 0 for NaN, a
                // quiet one from this sum; `TfLut::sample32`), so it
                // truncates to an i32.
                let ci = unsafe { q1.to_int_unchecked::<i32>() } - 1;
                u[a][j] = (q - ci as f32).clamp(0.0, 1.0);
                c[a] = ci as u32;
            }
            inside[j] = ((c[0] < cells[0]) & (c[1] < cells[1]) & (c[2] < cells[2])) as u32;
            local[j] = c;
            // In usize, where a lane outside (below 2^32 per axis) cannot
            // overflow; only the lanes inside are read.
            let c = c.map(|x| x as usize);
            code_at[j] = (c[2] * cells[1] as usize + c[1]) * cells[0] as usize + c[0];
            value_at[j] = (c[2] * sy + c[1]) * sx + c[0];
        }
        // Along the ray each axis's cell moves one way only, and the brick
        // is a box: the lanes inside are a prefix when lane 0 is. The
        // tables of a rectilinear grid may put a lane within rounding of
        // a plane across it, so there the prefix is counted.
        let inside = if RECT {
            inside.iter().take_while(|&&i| i == 1).count()
        } else if inside[0] == 1 {
            inside.iter().sum::<u32>() as usize
        } else {
            0
        };
        // Their codes: stop before a leap; 0-cells add nothing.
        let (mut n, mut end) = (inside, End::Brick);
        let mut object = [false; LANES];
        for j in 0..inside {
            let code = codes[code_at[j]];
            if code != OBJECT && code >= x.resume {
                (n, end) = (j, End::Leap);
                break;
            }
            object[j] = code == OBJECT;
        }
        // Their trilinear values, as `Trilinear32::value` computes them.
        let mut value = [0f32; LANES];
        for j in 0..n {
            let f = vertices(Corners {
                base: value_at[j],
                sx,
                z: sxy,
            });
            let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
            let (ux, uy, uz) = (u[0][j], u[1][j], u[2][j]);
            let x00 = lerp(f[0], f[1], ux);
            let x10 = lerp(f[2], f[3], ux);
            let x01 = lerp(f[4], f[5], ux);
            let x11 = lerp(f[6], f[7], ux);
            value[j] = lerp(lerp(x00, x10, uy), lerp(x01, x11, uy), uz);
        }
        // Front to back, in order, by transmittance: one multiplication
        // carries from sample to sample (`a + (1 - a) s` would be three).
        // With gradients, the samples are weighted and lit first
        // ([`shaded`]); that may end the batch early, to be taken again
        // from the same onset state.
        let (lit, tf_w) = if GRAD {
            let lanes = Lanes {
                object: &object,
                value: &value,
                u: &u,
                local: &local,
                code_at: &code_at,
            };
            let (lit, tf_w, upto) = shaded(x, b, &lanes, n);
            if upto < n {
                x.onset.clear.set(batch_gap);
                x.onset.faint_k.set(batch_faint.0);
                x.last.set(batch_faint.1);
                return missed(x, acc, colour, through, local[upto], taken);
            }
            (lit, tf_w)
        } else {
            ([Vec4::ZERO; LANES], [0f32; LANES])
        };
        for j in 0..n {
            // The sample, and the table's opacity: transparent, faint, or
            // an onset after faint ones.
            let s = if GRAD {
                lit[j].with_w(tf_w[j])
            } else if object[j] {
                x.lut.sample32(value[j])
            } else {
                Vec4::ZERO
            };
            let c = if GRAD { lit[j] } else { s };
            if s.w == 0.0 {
                (gap, faint_k) = (true, f64::NAN);
                continue;
            }
            // Near the threshold, the f64 value decides (refine.rs).
            let dim = if (s.w - faint).abs() <= band {
                let kj = k + (taken + j as u64) as f64;
                let cell = std::array::from_fn(|a| b.first[a] + local[j][a]);
                let corners = Corners {
                    base: value_at[j],
                    sx,
                    z: sxy,
                };
                let f = (cell, vertices(corners));
                faint64(x.coords, x.ray, x.lut, f, kj * x.step, x.onset.faint)
            } else {
                s.w < faint
            };
            if dim {
                gap = true;
                (faint_k, last) = (k + (taken + j as u64) as f64, (c, through));
            } else {
                if gap && k + (taken + j as u64) as f64 > from {
                    *acc = colour.with_w(1.0 - through);
                    x.onset.faint_k.set(faint_k);
                    x.last.set(last);
                    return (taken + j as u64, End::Onset);
                }
                gap = false;
                faint_k = f64::NAN;
            }
            colour += c * through;
            through *= 1.0 - c.w;
            if through < clear {
                *acc = colour.with_w(1.0 - through);
                x.onset.clear.set(gap);
                return (taken + j as u64 + 1, End::Stop);
            }
        }
        taken += n as u64;
        if n < LANES {
            *acc = colour.with_w(1.0 - through);
            x.onset.clear.set(gap);
            x.onset.faint_k.set(faint_k);
            x.last.set(last);
            return (taken, end);
        }
    }
}

/// A batch's exit at a cell whose gradients neither the plane nor
/// [`Again::given`] holds: the colour kept in `acc`, the transmittance
/// and the cell left for [`run`]. Cold, so that the kernel's layout keeps
/// its loop on the common path.
#[cold]
#[inline(never)]
fn missed(
    x: &Batches,
    acc: &mut Vec4,
    colour: Vec4,
    through: f32,
    cell: [u32; 3],
    taken: u64,
) -> (u64, End) {
    *acc = colour.with_w(1.0 - through);
    x.again.carried.set(through);
    x.again.missing.set(cell);
    (taken, End::Gradients)
}

/// A batch's samples, per lane: whether its cell is a 1-cell, its value,
/// its local coordinates in the cell, the cell in the brick and the
/// cell's index in the brick's code plane.
#[derive(Clone, Copy)]
struct Lanes<'a> {
    object: &'a [bool; LANES],
    value: &'a [f32; LANES],
    u: &'a [[f32; LANES]; 3],
    local: &'a [[u32; 3]; LANES],
    code_at: &'a [usize; LANES],
}

/// The first `n` samples of a batch lit: per lane the table's colour and
/// opacity at `value` where `object`, with the gradient interpolated at
/// `u` from the gradient plane of brick `b` (`local`: the cell in the
/// brick, `code_at`: its index in the code plane; [`Lanes`]), or from
/// [`Again::given`] for a cell the plane has not set, scaled by the
/// gradient opacity and shaded by [`light`], as `Look::apply` does each.
/// Also the table's opacities before the gradient opacity scales them,
/// and how many lanes it lit: fewer than `n` when neither holds a
/// sample's cell's gradients.
#[inline(always)]
fn shaded(
    x: &Batches,
    b: &RBrick,
    lanes: &Lanes,
    n: usize,
) -> ([Vec4; LANES], [f32; LANES], usize) {
    let Lanes {
        object,
        value,
        u,
        local,
        code_at,
    } = *lanes;
    let mut lit = [Vec4::ZERO; LANES];
    for j in 0..n {
        if object[j] {
            lit[j] = x.lut.sample32(value[j]);
        }
    }
    // The table's opacities, before the gradient opacity scales them.
    let tf_w = lit.map(|s| s.w);
    // Per lane the gradient's squared length and its dot product with the
    // direction to the eye, as `Look::apply` computes them.
    let (mut len2, mut dot) = ([0f32; LANES], [0f32; LANES]);
    let to_eye = x.shade.unwrap_or(Vec3A::ZERO);
    // Consecutive samples often share a cell: its gradients once (`held`:
    // the code-plane index of the cell they are of).
    let (mut grads, mut held) = ([Vec3A::ZERO; 8], usize::MAX);
    let mut upto = n;
    for j in 0..n {
        if lit[j].w == 0.0 {
            continue;
        }
        if held != code_at[j] {
            let Some(v) = b
                .grads
                .cell(local[j])
                .or_else(|| given_cell(x.again.given, code_at[j]))
            else {
                upto = j;
                break;
            };
            (grads, held) = (v, code_at[j]);
        }
        let g = trilinear_vec(&grads, Vec3A::new(u[0][j], u[1][j], u[2][j]));
        (len2[j], dot[j]) = (g.dot(g), g.dot(to_eye));
    }
    // The gradient opacity scales the sample before it is lit, by the
    // gradient's length as `Look::apply` takes it (`length` is the square
    // root of `dot`).
    if let Some(look) = x.gradient_opacity {
        for j in 0..upto {
            if lit[j].w != 0.0 {
                lit[j] *= look.gradient_factor(len2[j].sqrt() as f64) as f32;
            }
        }
    }
    if x.shade.is_some() {
        let (k, spec) = light(&len2, &dot);
        for j in 0..upto {
            let s = lit[j];
            lit[j] = (s * k[j] + Vec4::splat(spec[j] * s.w)).with_w(s.w);
        }
    }
    (lit, tf_w, upto)
}

/// The gradients `given` holds for the cell at `code_at` in the code
/// plane, if any. Inline, though only the first rays into a brick's
/// outer cells come here: a call inside the batch's loop would make the
/// gradients held in registers live across it.
#[inline(always)]
fn given_cell(given: &[(usize, [Vec3A; 8])], code_at: usize) -> Option<[Vec3A; 8]> {
    given.iter().find(|(at, _)| *at == code_at).map(|(_, g)| *g)
}

/// Trilinear interpolation of 8 vertex vectors (x fastest) at `u`, as the
/// one-at-a-time sampler interpolates its gradients.
#[inline(always)]
pub(super) fn trilinear_vec(g: &[Vec3A; 8], u: Vec3A) -> Vec3A {
    let x00 = g[0].lerp(g[1], u.x);
    let x10 = g[2].lerp(g[3], u.x);
    let x01 = g[4].lerp(g[5], u.x);
    let x11 = g[6].lerp(g[7], u.x);
    x00.lerp(x10, u.y).lerp(x01.lerp(x11, u.y), u.z)
}

/// The composite's headlight shading (`Look::apply` in composite.rs, the
/// surface mode's model: ambient 0.12, diffuse 0.75, white specular 0.25
/// with exponent 32, two-sided) of [`LANES`] samples whose gradients (per
/// mm) have squared lengths `len2` and dot products `dot` with the unit
/// vector to the eye: per lane the factor `k` of the premultiplied colour
/// and the specular term per unit opacity, so that the lit sample is
/// `s k + spec s.a`. Lane by lane in arrays, which the compiler turns into
/// SIMD arithmetic: the square roots and divisions of eight samples in
/// one instruction each, with `Look::apply`'s bits.
#[inline(always)]
fn light(len2: &[f32; LANES], dot: &[f32; LANES]) -> ([f32; LANES], [f32; LANES]) {
    const AMBIENT: f32 = 0.12;
    let mut k = [0f32; LANES];
    let mut spec = [0f32; LANES];
    for j in 0..LANES {
        let len = len2[j].sqrt();
        // n.l = |g.e| / |g| for the normal facing the eye; r.e = 2 (n.l)^2 - 1.
        let ndl = (dot[j].abs() / len).min(1.0);
        let re = (2.0 * ndl * ndl - 1.0).max(0.0);
        // re^32 by squaring, as `powi(32)` computes it.
        let re32 = (0..5).fold(re, |p, _| p * p);
        // No gradient: the surface mode's flat fallback.
        let on = len > 0.0;
        k[j] = AMBIENT + 0.75 * if on { ndl } else { 0.5 };
        spec[j] = if on { 0.25 * re32 } else { 0.0 };
    }
    (k, spec)
}

#[cfg(test)]
#[path = "batch_tests.rs"]
mod tests;
