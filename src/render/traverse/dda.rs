//! The DDA generators of [`Method::Dda`](super::Method::Dda) (RADC,
//! proximity clouds; paper section 3, eqs. 2-3).
//!
//! The walk runs in cell units: on a uniform axis of spacing `h` the ray
//! advances `r_k = d_k / h` cells per unit of its parameter. A sample at
//! parameter `t` lies in the cell the `t` rule of the frame gives
//! (*Locate*), so a leap lands exactly where FVT would be at that `t`.
//! From a cell at distance `d` (in cells) the next sample is
//! `(d - 1) / D(r)` further (eq. 2; `D` is `L1` for city block, `L2` for
//! chamfer, `Linf` for chessboard, eq. 3), but at least `1 / Linf(r)`: one
//! cell along the major axis, the DDA's own step. With `switch_fvt`, a
//! cell whose free length `(d - 1) / D(r)` is shorter than that step (for
//! chessboard: `d < 2`) is left by single-cell steps, and the DDA resumes
//! from the face of the first cell where it is not. Leaps are shortened by
//! a relative `2^-40` so that rounding cannot carry a chessboard leap onto
//! the face of the cube at distance `d`: then every cell a chessboard leap
//! passes lies within `Linf` distance `d - 1` of the start cell, all
//! empty, and chessboard DDA with the switch visits exactly FVT's 1-cells.
//! City block and chamfer leaps of length `d - 1` from a point that is not
//! the centre can reach cells at distance `d + 1` (`L1`) and are not
//! exact; tests/all/generators.rs counts what they miss.
//!
//! A visit's entry and exit are the cell's slab interval along the ray,
//! computed by the same `plane_t` as FVT (bit-identical where FVT visits
//! the same cell). Without the switch, a cell sampled twice is visited
//! once. On an axis that is not uniform the walk has no cell units; it
//! takes single-cell steps there (renders refuse such grids first).

use super::frame::{argmin, Entry, Frame};
use super::walker::Walker;
use super::{CodeSource, DistKind, Flow, Real, StepCounts, Visit};

/// The DDA walk of one ray.
pub struct Dda<'f, 'g, T> {
    f: &'f Frame<'g, T>,
    kind: DistKind,
    switch_fvt: bool,
    /// Every crossed axis uniform: the walk has cell units.
    regular: bool,
    /// `D(r)` of eq. 3 and the DDA's own step `1 / Linf(r)`.
    norm: f64,
    unit_dt: f64,
    shrink: f64,
    v: [u32; 3],
    t: T,
    t_in: T,
    t_out: T,
    /// Whether the walk is in single-cell steps (`next` valid) or samples.
    fvt: bool,
    next: [T; 3],
    last_visit: Option<[u32; 3]>,
    /// The distance of the cell just visited, whose move is due.
    pending: Option<u8>,
    done: bool,
    counts: StepCounts,
}

impl<'f, 'g, T: Real> Dda<'f, 'g, T> {
    #[inline(always)]
    pub(super) fn new(f: &'f Frame<'g, T>, e: Entry<T>, kind: DistKind, switch_fvt: bool) -> Self {
        let regular = (0..3).all(|k| f.d[k] == T::zero() || f.uniform[k].is_some());
        // Direction in cells per unit of t, and its norms (eq. 3).
        let r: [f64; 3] = std::array::from_fn(|k| match f.uniform[k] {
            Some(h) if f.d[k] != T::zero() => f.d[k].f64() / h.f64(),
            _ => 0.0,
        });
        let linf = r[0].max(r[1]).max(r[2]);
        let norm = match kind {
            DistKind::Cityblock => r[0] + r[1] + r[2],
            DistKind::Chessboard => linf,
            DistKind::Chamfer => (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt(),
        };
        Dda {
            f,
            kind,
            switch_fvt,
            regular,
            norm,
            unit_dt: 1.0 / linf,
            shrink: 1.0 - 2f64.powi(-40),
            v: e.v,
            t: e.t_in,
            t_in: e.t_in,
            t_out: e.t_out,
            fvt: false,
            next: [T::zero(); 3],
            last_visit: None,
            pending: None,
            done: false,
            counts: StepCounts::default(),
        }
    }

    /// Slab interval of cell `v` along the ray.
    #[inline(always)]
    fn span(&self, v: [u32; 3]) -> (T, T) {
        let (mut a, mut b) = (self.t_in, self.t_out);
        for (k, &vk) in v.iter().enumerate() {
            if self.f.d[k] != T::zero() {
                a = a.max(self.f.plane_t(k, vk));
                b = b.min(self.f.plane_t(k, vk + 1));
            }
        }
        (a, b)
    }

    /// The move out of the current cell, at distance `dist` (stored
    /// units): a leap of eq. 2 or a single-cell step. `false` when the ray
    /// leaves the volume.
    #[inline(always)]
    fn advance(&mut self, dist: u8) -> bool {
        let f = self.f;
        let leap = dist as f64 / self.kind.unit() as f64 - 1.0;
        // Near objects (the free length along the ray, eq. 2, is shorter
        // than one DDA step) the switch takes single-cell steps.
        let mut single = !self.regular || (self.switch_fvt && leap / self.norm < self.unit_dt);
        let mut tn = self.t;
        if !single {
            // The DDA resumes from the face single-cell steps entered by.
            let from = if self.fvt {
                self.span(self.v).0
            } else {
                self.t
            };
            let dt = if leap >= 1.0 {
                (leap / self.norm * self.shrink).max(self.unit_dt)
            } else {
                self.unit_dt
            };
            tn = T::of(from.f64() + dt);
            // A step lost to rounding (t huge against a cell): one cell.
            single = !(tn > from);
        }
        if single {
            if !self.fvt {
                self.fvt = true;
                self.next = f.crossings(self.v);
            }
            self.counts.cell_steps += 1;
            let m = argmin(self.next);
            if self.next[m] >= self.t_out {
                return false;
            }
            self.v[m] += 1;
            if self.v[m] >= f.n[m] {
                return false;
            }
            self.next[m] = f.plane_t(m, self.v[m] + 1);
            return true;
        }
        self.fvt = false;
        if leap >= 1.0 {
            self.counts.macro_steps += 1;
        }
        if tn >= self.t_out {
            return false;
        }
        self.t = tn;
        for k in 0..3 {
            if f.d[k] != T::zero() {
                self.v[k] = f.locate(k, tn, self.v[k], f.n[k]);
                if self.v[k] >= f.n[k] {
                    return false;
                }
            }
        }
        true
    }
}

impl<T: Real> Dda<'_, '_, T> {
    /// The walk from where the last call stopped: each sampled 1-cell
    /// goes to `on_visit`, once, and the walk stops where that says stop
    /// (the move out of that cell is then due).
    #[inline(always)]
    fn run<S, F>(&mut self, src: &mut S, mut on_visit: F)
    where
        S: CodeSource,
        F: FnMut(&Visit, &mut S) -> Flow,
    {
        if self.done {
            return;
        }
        if let Some(dist) = self.pending.take() {
            if !self.advance(dist) {
                self.done = true;
                return;
            }
        }
        loop {
            let real = self.f.real(self.v);
            let dist = src.distance(real, self.kind);
            self.counts.steps += 1;
            if dist == 0 && self.last_visit != Some(self.v) {
                self.last_visit = Some(self.v);
                let (a, b) = self.span(self.v);
                if b > a {
                    let vis = Visit {
                        cell: real,
                        t_enter: self.f.to_t(a),
                        t_exit: self.f.to_t(b),
                    };
                    if on_visit(&vis, src) == Flow::Stop {
                        self.pending = Some(dist);
                        return;
                    }
                }
            }
            if !self.advance(dist) {
                self.done = true;
                return;
            }
        }
    }
}

impl<T: Real, S: CodeSource> Walker<S> for Dda<'_, '_, T> {
    #[inline]
    fn next_visit(&mut self, src: &mut S) -> Option<Visit> {
        let mut found = None;
        self.run(src, |v, _| {
            found = Some(*v);
            Flow::Stop
        });
        found
    }

    fn counts(&self) -> StepCounts {
        self.counts
    }

    #[inline(always)]
    fn walk<F: FnMut(&Visit, &mut S) -> Flow>(&mut self, src: &mut S, visit: F) -> StepCounts {
        self.run(src, visit);
        self.counts
    }
}
