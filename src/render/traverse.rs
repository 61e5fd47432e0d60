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
//! Termination: every step raises at least one cell index by one, so a ray
//! takes at most `ncx + ncy + ncz` steps.

use super::cache::{Accessor, RBrick, OBJECT};
use crate::grid::Axis;

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
}

/// One axis in both orientations.
#[derive(Debug, Clone)]
struct TAxis {
    /// Increasing sample positions, as given and mirrored.
    s: [Vec<f64>; 2],
    /// `(s0, h)` of a uniform axis (both orientations share `h`).
    uniform: Option<f64>,
}

/// The grid as the traversal sees it: per axis the positions in both
/// orientations, computed once per image.
#[derive(Debug, Clone)]
pub struct TGrid {
    axes: [TAxis; 3],
    pub ncells: [u32; 3],
}

impl TGrid {
    pub fn new(axes: &[Axis; 3]) -> TGrid {
        let ta = |a: &Axis| {
            let c = a.coords().to_vec();
            let m: Vec<f64> = c.iter().rev().map(|x| -x).collect();
            let h = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
            TAxis {
                s: [c, m],
                uniform: a.is_uniform().then_some(h),
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

    /// Sample positions of axis `k` in the original orientation.
    pub fn coords(&self, k: usize) -> &[f64] {
        &self.axes[k].s[0]
    }

    /// Lower and upper corner of the volume in mm.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let lo = std::array::from_fn(|k| self.axes[k].s[0][0]);
        let hi = std::array::from_fn(|k| *self.axes[k].s[0].last().expect("axis"));
        (lo, hi)
    }
}

/// A ray in mm: `origin + t * dir`, `t >= t_min`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: [f64; 3],
    pub dir: [f64; 3],
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

/// Per-ray state of the walk (mirrored frame).
struct Walk<'g> {
    s: [&'g [f64]; 3],
    uniform: [Option<f64>; 3],
    o: [f64; 3],
    d: [f64; 3],
    /// `1 / |d|` (+inf where `d == 0`).
    inv_d: [f64; 3],
    mirror: [bool; 3],
    n: [u32; 3],
}

impl<'g> Walk<'g> {
    /// `t` at which the ray crosses plane `j` of axis `k` (+inf if the ray
    /// is parallel to it). The one formula every traversal uses:
    /// `(S'[j] - o') * (1 / d')`, a multiplication rather than a division
    /// in the step (paper section 4.1, last paragraph), monotone in `j`.
    #[inline(always)]
    fn plane_t(&self, k: usize, j: u32) -> f64 {
        if self.d[k] == 0.0 {
            f64::INFINITY
        } else {
            (self.s[k][j as usize] - self.o[k]) * self.inv_d[k]
        }
    }

    /// Largest `j` in `[lo, hi]` with `plane_t(k, j) <= t` (`plane_t(k,
    /// lo) <= t` must hold). Direct on uniform axes, binary search otherwise.
    #[inline(always)]
    fn locate(&self, k: usize, t: f64, lo: u32, hi: u32) -> u32 {
        if let Some(h) = self.uniform[k] {
            let p = self.o[k] + t * self.d[k];
            let est = ((p - self.s[k][0]) / h).floor();
            let mut j = if est.is_nan() {
                lo as f64
            } else {
                est.clamp(lo as f64, hi as f64)
            } as u32;
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
fn argmin(t: [f64; 3]) -> usize {
    if t[0] <= t[1] && t[0] <= t[2] {
        0
    } else if t[1] <= t[2] {
        1
    } else {
        2
    }
}

/// Walks `ray` through the grid from `t_min` on, calling `visit` for every
/// 1-cell it passes with positive length, in order, until `visit` says
/// stop or the ray leaves the volume. Returns the step counts.
pub fn trace<F>(
    grid: &TGrid,
    ray: &Ray,
    t_min: f64,
    method: Method,
    acc: &mut Accessor,
    mut visit: F,
) -> StepCounts
where
    F: FnMut(&Visit, &RBrick, [u32; 3]) -> Flow,
{
    let mut counts = StepCounts::default();
    // Mirror axes with negative components (-0.0 is not negative).
    let mirror = ray.dir.map(|d| d < 0.0);
    let w = Walk {
        s: std::array::from_fn(|k| &grid.axes[k].s[mirror[k] as usize][..]),
        uniform: std::array::from_fn(|k| grid.axes[k].uniform),
        o: std::array::from_fn(|k| {
            if mirror[k] {
                -ray.origin[k]
            } else {
                ray.origin[k]
            }
        }),
        d: std::array::from_fn(|k| {
            if mirror[k] {
                -ray.dir[k]
            } else {
                ray.dir[k].abs()
            }
        }),
        inv_d: std::array::from_fn(|k| 1.0 / ray.dir[k].abs()),
        mirror,
        n: grid.ncells,
    };
    let octant = (mirror[0] as usize) | (mirror[1] as usize) << 1 | (mirror[2] as usize) << 2;

    // Enter the volume: slab test, then the starting cell by the t rule.
    let mut t_in = t_min;
    let mut t_out = f64::INFINITY;
    for k in 0..3 {
        let s = w.s[k];
        if w.d[k] == 0.0 {
            if !(w.o[k] >= s[0] && w.o[k] <= s[s.len() - 1]) {
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
        if w.d[k] == 0.0 {
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
        Method::Fvt => (u8::MAX, false),
        Method::Cd { min_leap } => (min_leap.max(1), false),
        Method::CdAniso { min_leap } => (min_leap.max(1), true),
    };
    loop {
        let real = w.real(v);
        let (brick, local) = acc.brick(real);
        let mut code = brick.code(local);
        if aniso && code != OBJECT {
            // The cell's isotropic cube and its block's octant box are both
            // empty, so the larger of the two leaps is safe.
            code = code.max(brick.octant_code(local, octant));
        }
        counts.steps += 1;
        if code == OBJECT {
            let t_exit = next[0].min(next[1]).min(next[2]).min(t_out);
            if t_exit > t_enter {
                let vis = Visit {
                    cell: real,
                    t_enter,
                    t_exit,
                };
                if visit(&vis, brick, local) == Flow::Stop {
                    return counts;
                }
            }
        }
        if code != OBJECT && code >= min_leap {
            // Macro step (Figs. 11, 12): the nearest far face of the cube.
            counts.macro_steps += 1;
            let n = code as u32;
            let far: [u32; 3] = std::array::from_fn(|k| (v[k] + n + 1).min(w.n[k]));
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
                } else if w.d[k] != 0.0 {
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
