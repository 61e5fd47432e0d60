//! Ray traversal of rectilinear grids (paper section 4.1, Figs. 8, 11, 12).
//!
//! Rays are in millimetres; cells are indices of the secondary cubic grid
//! (paper eq. 9). Every axis with a negative direction component is
//! mirrored (`S'[i] = -S[n-1-i]`, section 4.1), so the walk only ever
//! moves towards higher indices; `-0.0` counts as non-negative and zero
//! components never divide (their planes are never crossed).
//!
//! All traversals share one parametrisation: the ray crosses plane `j` of
//! axis `k` at `t = plane_t(k, j) = (S'_k[j] - o'_k) / d'_k`, and the cell
//! along `k` at parameter `t` is the largest `j` with `plane_t(k, j) <= t`.
//! FVT (Cleary-Wyvill, Amanatides-Woo) crosses the planes one at a time;
//! CD jumps from cell `v` with code `n` to the nearest far face of its
//! empty cube, `S'[v + n + 1]` (eq. 12, where the paper's `N` is `n + 1`),
//! then *Locate*s the other axes by the same rule in `t`, by binary search
//! bounded by the cube on rectilinear axes and by direct computation on
//! uniform ones. Because both use the same `plane_t`, CD lands exactly in
//! the cell FVT reaches after crossing every plane with `t` up to the
//! landing point, and the two yield the same 1-cells with positive length
//! (cells a ray only grazes at an edge or corner have `t_exit == t_enter`
//! and are skipped by every traversal alike).
//!
//! Termination: every step raises at least one cell index by one and lowers
//! none, so a ray takes at most `ncx + ncy + ncz - 2` steps (the suite in
//! tests/extremes.rs checks this bound on every ray).
//!
//! Precision: [`trace`] is generic over [`Real`] (`f64` or `f32`). In f64
//! every computed crossing is the exact one times `(1 + e)`, `|e| <= 3u`
//! (`u = 2^-53`), and crossings are compared only through these values, so
//! the walk equals the exact one except for cells whose exact length along
//! the ray is within `6u * |t|` of zero; tests/extremes.rs checks exactly
//! this against rational arithmetic. f32 adds the rounding of origins and
//! sample positions to 24 bits, relative to their magnitude: it misses
//! cells (docs/TRADEOFFS.md), so f64 is the default.

use num_traits::Float;

use super::cache::OBJECT;
use crate::grid::Axis;

mod ray;
pub use ray::{Ray, RayError, MAX_DIR, MIN_DIR};

/// Arithmetic the walk runs in: `f64` (the default: it never misses a
/// 1-cell in the extreme-case suite) or `f32` (measured in
/// docs/TRADEOFFS.md). One generic walk, not two copies.
pub trait Real: Float + Send + Sync + std::fmt::Debug + 'static {
    /// Nearest value of this type (f64 -> f32 rounds; may overflow to inf).
    fn of(x: f64) -> Self;
    fn f64(self) -> f64;
}

impl Real for f64 {
    #[inline(always)]
    fn of(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

impl Real for f32 {
    #[inline(always)]
    fn of(x: f64) -> f32 {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

/// Where the walk reads cell codes: the renderer's brick accessor, or an
/// in-memory volume in tests and the fuzz target.
pub trait CodeSource {
    /// Code of cell `c` ([`OBJECT`] for a 1-cell). With `Some(octant)`, the
    /// larger of its isotropic code and its block's code for that octant
    /// (section 4.2.1): both cubes are empty, so the larger leap is safe.
    fn code(&mut self, c: [u32; 3], octant: Option<usize>) -> u8;

    /// Distance of the DDA generators (paper section 3, Figs. 4, 5, 19)
    /// from the centre of cell `c` to the centre of the nearest 1-cell, in
    /// stored units ([`DistKind::unit`]): 0 for a 1-cell, saturating at
    /// 254. The default derives it from the chessboard code, a lower bound
    /// for all three kinds (`L1 >= Linf`, chamfer 3-4-5 `>= 3 Linf`), so
    /// it is always safe, if short, for sources without DDA planes.
    fn distance(&mut self, c: [u32; 3], kind: DistKind) -> u8 {
        let code = self.code(c, None);
        if code == OBJECT {
            return 0;
        }
        let d = code as u32 + 1;
        (d * kind.unit()).min(254) as u8
    }

    /// Largest level `L` such that the octree node of `2^L` cells per
    /// axis, aligned to multiples of `2^L` in the original grid, that
    /// contains cell `c` holds no 1-cell; `None` for a 1-cell. The default
    /// knows only the cell itself (level 0).
    fn empty_level(&mut self, c: [u32; 3]) -> Option<u8> {
        (self.code(c, None) != OBJECT).then_some(0)
    }
}

/// Distance types of the DDA ray generators (RADC, proximity clouds;
/// paper section 3, Fig. 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub enum DistKind {
    /// `L1`, stored in cells (exact two-pass transform).
    Cityblock,
    /// `Linf`, stored in cells: the CD code plus one.
    Chessboard,
    /// Chamfer 3-4-5 (Borgefors), approximating the Euclidean distance,
    /// stored in thirds of a cell.
    Chamfer,
}

impl DistKind {
    /// Stored units per cell.
    pub fn unit(self) -> u32 {
        match self {
            DistKind::Chamfer => 3,
            _ => 1,
        }
    }

    /// Stable name (`cityblock`, `chessboard`, `chamfer`).
    pub fn name(self) -> &'static str {
        match self {
            DistKind::Cityblock => "cityblock",
            DistKind::Chessboard => "chessboard",
            DistKind::Chamfer => "chamfer",
        }
    }
}

/// Which ray generator to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Single-cell steps (the reference).
    Fvt,
    /// Chessboard-distance macro steps over cells with code `>= min_leap`,
    /// single-cell steps elsewhere (1 = the paper).
    Cd { min_leap: u8 },
    /// CD with the octant (anisotropic) codes of section 4.2.1.
    CdAniso { min_leap: u8 },
    /// Octree (min-max pyramid) traversal in the spirit of SMART (paper
    /// section 5.1): at each cell the largest empty aligned node holding
    /// it is found top-down ([`CodeSource::empty_level`]) and the ray
    /// leaps to the node's exit face by the same step as CD, so it lands
    /// exactly where FVT would.
    Octree,
    /// Floating-point 3D DDA with distance-coded leaps (RADC, proximity
    /// clouds; paper section 3, eqs. 2-3): from a sample in a cell at
    /// distance `d`, the next sample is `(d - 1) / D(r)` further along the
    /// ray (`D` the ray direction's norm in the distance's metric, in cell
    /// units; `- 1` because distances are from cell centres), at least one
    /// cell along the major axis. With `switch_fvt`, cells whose free
    /// length along the ray is shorter than that one DDA step are walked
    /// by single-cell steps until a leap is possible again; without it the
    /// DDA samples one cell per major-axis step there and may miss 1-cells
    /// (Fig. 18a only).
    /// Regular grids only (every axis uniform).
    Dda { kind: DistKind, switch_fvt: bool },
}

impl Method {
    /// Whether every 1-cell the FVT visits is visited, in the same order
    /// with the same entry and exit (tests/generators.rs checks these bit
    /// for bit against FVT).
    pub fn is_exact(self) -> bool {
        match self {
            Method::Dda { kind, switch_fvt } => switch_fvt && kind == DistKind::Chessboard,
            _ => true,
        }
    }

    /// Whether the method needs every axis uniform.
    pub fn needs_regular_grid(self) -> bool {
        matches!(self, Method::Dda { .. })
    }

    /// Stable name for stats, part-file keys and messages: the traversal's
    /// name as `cdvol render --traversal` spells it, followed by any
    /// parameter that differs from that traversal's default
    /// (`cd min_leap=3`, `dda-chamfer no_switch`). Never Debug text.
    pub fn name(self) -> String {
        match self {
            Method::Fvt => "fvt".into(),
            Method::Octree => "octree".into(),
            Method::Cd { min_leap } | Method::CdAniso { min_leap } => {
                let base = if matches!(self, Method::Cd { .. }) {
                    "cd"
                } else {
                    "cd-aniso"
                };
                if min_leap <= 1 {
                    base.into()
                } else {
                    format!("{base} min_leap={min_leap}")
                }
            }
            Method::Dda { kind, switch_fvt } => {
                let base = format!("dda-{}", kind.name());
                if switch_fvt {
                    base
                } else {
                    format!("{base} no_switch")
                }
            }
        }
    }
}

/// One axis in both orientations.
#[derive(Debug, Clone)]
struct TAxis<T> {
    /// Increasing sample positions, as given and mirrored.
    s: [Vec<T>; 2],
    /// Spacing `h` of a uniform axis (both orientations share it).
    uniform: Option<T>,
}

/// The grid as the traversal sees it: per axis the positions in both
/// orientations, in the walk's arithmetic, computed once per image.
#[derive(Debug, Clone)]
pub struct TGrid<T = f64> {
    axes: [TAxis<T>; 3],
    pub ncells: [u32; 3],
}

impl<T: Real> TGrid<T> {
    pub fn new(axes: &[Axis; 3]) -> TGrid<T> {
        let ta = |a: &Axis| {
            let c: Vec<T> = a.coords().iter().map(|&x| T::of(x)).collect();
            let m: Vec<T> = c.iter().rev().map(|&x| -x).collect();
            let co = a.coords();
            let h = (co[co.len() - 1] - co[0]) / (co.len() - 1) as f64;
            TAxis {
                s: [c, m],
                uniform: a.is_uniform().then_some(T::of(h)),
            }
        };
        TGrid {
            axes: [ta(&axes[0]), ta(&axes[1]), ta(&axes[2])],
            ncells: [
                (axes[0].samples() - 1) as u32,
                (axes[1].samples() - 1) as u32,
                (axes[2].samples() - 1) as u32,
            ],
        }
    }

    /// Lower and upper corner of the volume in mm (as this arithmetic
    /// holds them).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let lo = std::array::from_fn(|k| self.axes[k].s[0][0].f64());
        let hi = std::array::from_fn(|k| self.axes[k].s[0].last().expect("axis").f64());
        (lo, hi)
    }
}

/// A 1-cell the ray passes through with positive length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Visit {
    /// Cell index in the original (unmirrored) grid.
    pub cell: [u32; 3],
    pub t_enter: f64,
    pub t_exit: f64,
}

/// Step counts of one ray (summed per tile).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct StepCounts {
    /// All traversal steps.
    pub steps: u64,
    /// Steps over a macro region (code > 0).
    pub macro_steps: u64,
    /// Single-cell steps.
    pub cell_steps: u64,
}

impl StepCounts {
    pub fn add(&mut self, o: &StepCounts) {
        self.steps += o.steps;
        self.macro_steps += o.macro_steps;
        self.cell_steps += o.cell_steps;
    }
}

/// What the integrator tells the traversal after a visit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    Continue,
    Stop,
}

/// Per-ray state of the walk (mirrored, scaled frame).
struct Walk<'g, T> {
    s: [&'g [T]; 3],
    uniform: [Option<T>; 3],
    o: [T; 3],
    /// `|d|`, divided by a power of two where `T` needs it (see [`trace`]).
    d: [T; 3],
    /// `1 / d` (+inf where `d == 0`).
    inv_d: [T; 3],
    /// Axes whose `1 / d` overflows (subnormal `d`): divide instead.
    div: [bool; 3],
    mirror: [bool; 3],
    n: [u32; 3],
}

impl<'g, T: Real> Walk<'g, T> {
    /// `t` at which the ray crosses plane `j` of axis `k` (+inf if the ray
    /// is parallel to it). The one formula every traversal uses:
    /// `(S'[j] - o') * (1 / d')`, a multiplication rather than a division
    /// in the step (paper section 4.1, last paragraph), monotone in `j`.
    #[inline(always)]
    fn plane_t(&self, k: usize, j: u32) -> T {
        if self.d[k] == T::zero() {
            T::infinity()
        } else if self.div[k] {
            (self.s[k][j as usize] - self.o[k]) / self.d[k]
        } else {
            (self.s[k][j as usize] - self.o[k]) * self.inv_d[k]
        }
    }

    /// Largest `j` in `[lo, hi]` with `plane_t(k, j) <= t` (`plane_t(k,
    /// lo) <= t` must hold). Locate of Fig. 11: direct on uniform axes
    /// (an estimate corrected by the same `plane_t`), binary search
    /// bounded by the cube otherwise.
    #[inline(always)]
    fn locate(&self, k: usize, t: T, lo: u32, hi: u32) -> u32 {
        if let Some(h) = self.uniform[k] {
            let p = self.o[k] + t * self.d[k];
            // Clamped before truncating: inside (lo, hi) the estimate is
            // positive, where truncation is floor (no libm call); NaN
            // goes to lo.
            let est = ((p - self.s[k][0]) / h).f64();
            let mut j = if est > lo as f64 {
                est.min(hi as f64) as u32
            } else {
                lo
            };
            while j < hi && self.plane_t(k, j + 1) <= t {
                j += 1;
            }
            while j > lo && self.plane_t(k, j) > t {
                j -= 1;
            }
            j
        } else {
            let (mut a, mut b) = (lo, hi);
            while a < b {
                let m = a + (b - a).div_ceil(2);
                if self.plane_t(k, m) <= t {
                    a = m;
                } else {
                    b = m - 1;
                }
            }
            a
        }
    }

    /// Far faces, in the mirrored frame, of the octree node of level `l`
    /// holding original cell `real`: the node spans `[a, a + 2^l)` along
    /// each axis of the original grid (clipped to the volume), so its far
    /// face is `a + 2^l` on an unmirrored axis and `n - a` on a mirrored
    /// one.
    #[inline(always)]
    fn node_far(&self, real: [u32; 3], l: u8) -> [u32; 3] {
        let l = l.min(40);
        std::array::from_fn(|k| {
            let a = (real[k] as u64 >> l) << l;
            if self.mirror[k] {
                (self.n[k] as u64 - a) as u32
            } else {
                (a + (1u64 << l)).min(self.n[k] as u64) as u32
            }
        })
    }

    /// Original cell index of mirrored cell `v`.
    #[inline(always)]
    fn real(&self, v: [u32; 3]) -> [u32; 3] {
        std::array::from_fn(|k| {
            if self.mirror[k] {
                self.n[k] - 1 - v[k]
            } else {
                v[k]
            }
        })
    }
}

/// Axis of the smallest `t`, ties to x, then y (paper Fig. 11a).
#[inline(always)]
fn argmin<T: Real>(t: [T; 3]) -> usize {
    if t[0] <= t[1] && t[0] <= t[2] {
        0
    } else if t[1] <= t[2] {
        1
    } else {
        2
    }
}

/// Power of two `p` with `max |d_k| / p` in [1, 2) (exact scaling).
fn pow2_scale(m: f64) -> f64 {
    let e = m.log2().floor().clamp(-1022.0, 1023.0) as i32;
    let mut p = 2f64.powi(e);
    // log2 may round across a power of two; fix up exactly.
    if m / p >= 2.0 {
        p *= 2.0;
    } else if m / p < 1.0 {
        p *= 0.5;
    }
    p
}

/// Walks `ray` through the grid from `t_min` on, calling `visit` for every
/// 1-cell it passes with positive length, in order, until `visit` says
/// stop or the ray leaves the volume. Returns the step counts. A ray that
/// fails [`Ray::check`], or a non-finite `t_min`, visits nothing.
///
/// Where the largest direction component `m` or `1 / m` is not a normal
/// number of `T` (f32 outside its range; never in f64, as `m` is within
/// 2^+-600), the direction is divided by a power of two `p` so that `m / p`
/// lies in [1, 2); the walk's parameter is then `t * p`, and is reported
/// divided by `p`. Both are exact, so in f64 every direction is walked as
/// given. A component whose inverse overflows (subnormal) is divided by
/// rather than multiplied with. A component that underflows to 0 in `T`
/// (f32 only) is treated as parallel, keeping its sign for mirroring and
/// leaving at once from the far face.
///
/// Termination: every step raises one cell index by at least one and
/// never lowers another, so a ray takes at most `ncx + ncy + ncz - 2`
/// steps.
pub fn trace<T, S, F>(
    grid: &TGrid<T>,
    ray: &Ray,
    t_min: f64,
    method: Method,
    src: &mut S,
    mut visit: F,
) -> StepCounts
where
    T: Real,
    S: CodeSource,
    F: FnMut(&Visit, &mut S) -> Flow,
{
    let mut counts = StepCounts::default();
    if ray.check().is_err() || !t_min.is_finite() {
        return counts;
    }
    let m = ray
        .dir
        .to_array()
        .iter()
        .fold(0.0f64, |m, d| m.max(d.abs()));
    let p = if T::of(m).is_normal() && T::of(1.0 / m).is_normal() {
        1.0
    } else {
        pow2_scale(m)
    };
    // Mirror axes with negative components (-0.0 is not negative).
    let mirror = ray.dir.to_array().map(|d| d < 0.0);
    let d: [T; 3] = std::array::from_fn(|k| T::of(ray.dir[k].abs() / p));
    let inv_d = d.map(|x| T::one() / x);
    let div = std::array::from_fn(|k| d[k] != T::zero() && !inv_d[k].is_finite());
    let o: [T; 3] = std::array::from_fn(|k| {
        T::of(if mirror[k] {
            -ray.origin[k]
        } else {
            ray.origin[k]
        })
    });
    if !o.iter().all(|x| x.is_finite()) {
        // Only in f32: an origin beyond its range.
        return counts;
    }
    let w = Walk {
        s: std::array::from_fn(|k| &grid.axes[k].s[mirror[k] as usize][..]),
        uniform: std::array::from_fn(|k| grid.axes[k].uniform),
        o,
        d,
        inv_d,
        div,
        mirror,
        n: grid.ncells,
    };
    let octant = (mirror[0] as usize) | (mirror[1] as usize) << 1 | (mirror[2] as usize) << 2;
    let to_t = |t: T| t.f64() / p;

    // Enter the volume: slab test, then the starting cell by the t rule.
    let mut t_in = T::of(t_min * p);
    let mut t_out = T::infinity();
    for k in 0..3 {
        let s = w.s[k];
        if w.d[k] == T::zero() {
            // Parallel: inside the closed slab. A flushed component still
            // moves the ray, so on the far face it leaves at once.
            let top = s[s.len() - 1];
            let below_top = if ray.dir[k] == 0.0 {
                w.o[k] <= top
            } else {
                w.o[k] < top
            };
            if !(w.o[k] >= s[0] && below_top) {
                return counts;
            }
        } else {
            t_in = t_in.max(w.plane_t(k, 0));
            t_out = t_out.min(w.plane_t(k, w.n[k]));
        }
    }
    if !(t_in < t_out) {
        return counts;
    }
    let mut v: [u32; 3] = std::array::from_fn(|k| {
        if w.d[k] == T::zero() {
            // Largest sample position <= o, kept inside the last cell.
            let s = w.s[k];
            (s.partition_point(|&x| x <= w.o[k]).max(1) - 1).min(w.n[k] as usize - 1) as u32
        } else {
            w.locate(k, t_in, 0, w.n[k] - 1)
        }
    });
    let mut t_enter = t_in;
    let mut next = [
        w.plane_t(0, v[0] + 1),
        w.plane_t(1, v[1] + 1),
        w.plane_t(2, v[2] + 1),
    ];
    let (min_leap, aniso) = match method {
        Method::Fvt | Method::Octree => (u8::MAX, None),
        Method::Cd { min_leap } => (min_leap.max(1), None),
        Method::CdAniso { min_leap } => (min_leap.max(1), Some(octant)),
        Method::Dda { kind, switch_fvt } => {
            let st = Start {
                v,
                t_in,
                t_out,
                to_t: &to_t,
            };
            return dda(&w, st, kind, switch_fvt, src, visit);
        }
    };
    let octree = method == Method::Octree;
    loop {
        let real = w.real(v);
        // What the cell is: a 1-cell, or the far faces of an empty region
        // to leap to (None: a single-cell step).
        let (object, leap) = if octree {
            match src.empty_level(real) {
                None => (true, None),
                Some(0) => (false, None),
                Some(l) => (false, Some(w.node_far(real, l))),
            }
        } else {
            let code = src.code(real, aniso);
            let leap = (code != OBJECT && code >= min_leap).then(|| {
                let n = code as u32;
                std::array::from_fn(|k| (v[k] + n + 1).min(w.n[k]))
            });
            (code == OBJECT, leap)
        };
        counts.steps += 1;
        if object {
            let t_exit = next[0].min(next[1]).min(next[2]).min(t_out);
            if t_exit > t_enter {
                let vis = Visit {
                    cell: real,
                    t_enter: to_t(t_enter),
                    t_exit: to_t(t_exit),
                };
                if visit(&vis, src) == Flow::Stop {
                    return counts;
                }
            }
        }
        if let Some(far) = leap {
            // Macro step (Figs. 11, 12): the nearest far face of the
            // region (CD: the cube of eq. 12; octree: the node).
            counts.macro_steps += 1;
            let t_far = [
                w.plane_t(0, far[0]),
                w.plane_t(1, far[1]),
                w.plane_t(2, far[2]),
            ];
            let m = argmin(t_far);
            let t = t_far[m];
            if far[m] >= w.n[m] {
                return counts;
            }
            for k in 0..3 {
                if k == m {
                    v[k] = far[k];
                } else if w.d[k] != T::zero() {
                    v[k] = w.locate(k, t, v[k], far[k]);
                    if v[k] >= w.n[k] {
                        return counts;
                    }
                }
                next[k] = w.plane_t(k, v[k] + 1);
            }
            t_enter = t;
        } else {
            // Single-cell step (MasterStep_1 / SlaveStep_1).
            counts.cell_steps += 1;
            let m = argmin(next);
            let t = next[m];
            if t >= t_out {
                return counts;
            }
            v[m] += 1;
            if v[m] >= w.n[m] {
                return counts;
            }
            next[m] = w.plane_t(m, v[m] + 1);
            t_enter = t;
        }
    }
}

/// Where a walk starts: the first cell, the volume's entry and exit in
/// the walk's parameter, and the map back to the ray's `t`.
struct Start<'f, T> {
    v: [u32; 3],
    t_in: T,
    t_out: T,
    to_t: &'f dyn Fn(T) -> f64,
}

/// The DDA generators of [`Method::Dda`] (paper section 3, eqs. 2-3).
///
/// The walk runs in cell units: on a uniform axis of spacing `h` the ray
/// advances `r_k = d_k / h` cells per unit of its parameter. A sample at
/// parameter `t` lies in the cell the `t` rule of [`trace`] gives
/// (Locate), so a leap lands exactly where FVT would be at that `t`. From
/// a cell at distance `d` (in cells) the next sample is `(d - 1) / D(r)`
/// further (eq. 2; `D` is `L1` for city block, `L2` for chamfer, `Linf`
/// for chessboard, eq. 3), but at least `1 / Linf(r)`: one cell along the
/// major axis, the DDA's own step. With `switch_fvt`, a cell whose free
/// length `(d - 1) / D(r)` is shorter than that step (for chessboard:
/// `d < 2`) is left by single-cell steps, and the DDA resumes from the
/// face of the first cell where it is not. Leaps are shortened by a relative `2^-40` so that rounding
/// cannot carry a chessboard leap onto the face of the cube at distance
/// `d`: then every cell a chessboard leap passes lies within `Linf`
/// distance `d - 1` of the start cell, all empty, and chessboard DDA with
/// the switch visits exactly FVT's 1-cells. City block and chamfer leaps
/// of length `d - 1` from a point that is not the centre can reach cells
/// at distance `d + 1` (`L1`) and are not exact; tests/generators.rs
/// counts what they miss.
///
/// A visit's entry and exit are the cell's slab interval along the ray,
/// computed by the same `plane_t` as FVT (bit-identical where FVT visits
/// the same cell). Without the switch, a cell sampled twice is visited
/// once. On an axis that is not uniform the walk has no cell units; it
/// takes single-cell steps there (renders refuse such grids first).
#[allow(clippy::needless_range_loop)] // v[k], w.d[k], w.n[k] side by side
fn dda<T, S, F>(
    w: &Walk<'_, T>,
    st: Start<'_, T>,
    kind: DistKind,
    switch_fvt: bool,
    src: &mut S,
    mut visit: F,
) -> StepCounts
where
    T: Real,
    S: CodeSource,
    F: FnMut(&Visit, &mut S) -> Flow,
{
    let mut counts = StepCounts::default();
    let Start {
        mut v,
        t_in,
        t_out,
        to_t,
    } = st;
    let regular = (0..3).all(|k| w.d[k] == T::zero() || w.uniform[k].is_some());
    // Direction in cells per unit of t, and its norms (eq. 3).
    let r: [f64; 3] = std::array::from_fn(|k| match w.uniform[k] {
        Some(h) if w.d[k] != T::zero() => w.d[k].f64() / h.f64(),
        _ => 0.0,
    });
    let linf = r[0].max(r[1]).max(r[2]);
    let norm = match kind {
        DistKind::Cityblock => r[0] + r[1] + r[2],
        DistKind::Chessboard => linf,
        DistKind::Chamfer => (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt(),
    };
    let unit_dt = 1.0 / linf;
    let shrink = 1.0 - 2f64.powi(-40);
    let unit = kind.unit() as f64;
    // Slab interval of cell v along the ray.
    let span = |v: [u32; 3]| -> (T, T) {
        let (mut a, mut b) = (t_in, t_out);
        for (k, &vk) in v.iter().enumerate() {
            if w.d[k] != T::zero() {
                a = a.max(w.plane_t(k, vk));
                b = b.min(w.plane_t(k, vk + 1));
            }
        }
        (a, b)
    };
    let mut t = t_in;
    // Whether the walk is in single-cell steps (`next` valid) or samples.
    let mut fvt = false;
    let mut next = [T::zero(); 3];
    let mut last_visit: Option<[u32; 3]> = None;
    loop {
        let real = w.real(v);
        let dist = src.distance(real, kind);
        counts.steps += 1;
        if dist == 0 && last_visit != Some(v) {
            let (a, b) = span(v);
            if b > a {
                let vis = Visit {
                    cell: real,
                    t_enter: to_t(a),
                    t_exit: to_t(b),
                };
                if visit(&vis, src) == Flow::Stop {
                    return counts;
                }
            }
            last_visit = Some(v);
        }
        let leap = dist as f64 / unit - 1.0;
        // Near objects (the free length along the ray, eq. 2, is shorter
        // than one DDA step) the switch takes single-cell steps.
        let mut single = !regular || (switch_fvt && leap / norm < unit_dt);
        let mut tn = t;
        if !single {
            // The DDA resumes from the face single-cell steps entered by.
            let from = if fvt { span(v).0 } else { t };
            let dt = if leap >= 1.0 {
                (leap / norm * shrink).max(unit_dt)
            } else {
                unit_dt
            };
            tn = T::of(from.f64() + dt);
            // A step lost to rounding (t huge against a cell): one cell.
            single = !(tn > from);
        }
        if single {
            if !fvt {
                fvt = true;
                next = std::array::from_fn(|k| w.plane_t(k, v[k] + 1));
            }
            counts.cell_steps += 1;
            let m = argmin(next);
            if next[m] >= t_out {
                return counts;
            }
            v[m] += 1;
            if v[m] >= w.n[m] {
                return counts;
            }
            next[m] = w.plane_t(m, v[m] + 1);
            continue;
        }
        fvt = false;
        if leap >= 1.0 {
            counts.macro_steps += 1;
        }
        if tn >= t_out {
            return counts;
        }
        t = tn;
        for (k, vk) in v.iter_mut().enumerate() {
            if w.d[k] != T::zero() {
                *vk = w.locate(k, t, *vk, w.n[k]);
                if *vk >= w.n[k] {
                    return counts;
                }
            }
        }
    }
}
