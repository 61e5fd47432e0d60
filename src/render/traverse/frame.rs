//! The per-ray frame every walker shares (paper section 4.1): mirrored
//! axes, the one crossing formula `plane_t`, *Locate*, the entry into the
//! volume, and the two moves of Figs. 11-12: the leap out of an empty
//! region ([`Cursor::leap`], whose exit [`leap_exit`] and far faces
//! [`cube_far`] are short pure functions) and the single-cell step
//! ([`Cursor::step`]).
//!
//! Every axis with a negative direction component is mirrored
//! (`S'[i] = -S[n-1-i]`), so a walk only ever moves towards higher
//! indices; `-0.0` counts as non-negative and zero components never
//! divide (their planes are never crossed).

use super::{Ray, Real, TGrid, Visit};

/// One ray in the walk's frame: mirrored, scaled, in arithmetic `T`.
pub(super) struct Frame<'g, T> {
    s: [&'g [T]; 3],
    pub(super) uniform: [Option<T>; 3],
    /// `1 / h` of uniform axes (*Locate*'s estimate; 0 elsewhere).
    inv_h: [T; 3],
    o: [T; 3],
    /// `|d|`, divided by the power of two `p` where `T` needs it.
    pub(super) d: [T; 3],
    /// `1 / d` (+inf where `d == 0`).
    inv_d: [T; 3],
    /// Axes crossed by multiplying with `1 / d`: `d != 0` and `1 / d`
    /// finite. Elsewhere `d == 0` (never crossed) or `1 / d` overflows
    /// (subnormal `d`), and [`Frame::plane_t`] divides instead.
    mul: [bool; 3],
    mirror: [bool; 3],
    /// [`Frame::real`] without a branch: per axis `!0` and `n` where
    /// mirrored, else `0` and `0` (`(v ^ !0) + n = n - 1 - v`).
    flip: [u32; 3],
    shift: [u32; 3],
    /// Cells per axis.
    pub(super) n: [u32; 3],
    /// The exact power of two the direction was divided by (1 in f64).
    p: f64,
    /// `1 / p`, also a power of two and exact: [`Frame::to_t`]
    /// multiplies by it, which rounds as the division by `p` does.
    inv_p: f64,
}

/// Where a walk starts: the first cell (mirrored frame) and the ray's
/// entry into and exit from the volume, in the frame's parameter.
#[derive(Clone, Copy)]
pub(super) struct Entry<T> {
    pub(super) v: [u32; 3],
    pub(super) t_in: T,
    pub(super) t_out: T,
}

impl<'g, T: Real> Frame<'g, T> {
    /// The frame of `ray`, which has passed [`Ray::check`].
    ///
    /// Where the largest direction component `m` or `1 / m` is not a
    /// normal number of `T` (f32 outside its range; never in f64, as `m`
    /// is within 2^+-600), the direction is divided by a power of two `p`
    /// so that `m / p` lies in [1, 2); the walk's parameter is then
    /// `t * p`, reported divided by `p` ([`Frame::to_t`]). Both are exact,
    /// so in f64 every direction is walked as given. A component whose
    /// inverse overflows (subnormal) is divided by rather than multiplied
    /// with. A component that underflows to 0 in `T` (f32 only) is treated
    /// as parallel, keeping its sign for mirroring and leaving at once
    /// from the far face.
    ///
    /// Returned by value and never wrapped, so it is built in place (a
    /// frame in an `Option` cost a 200-byte copy per ray).
    #[inline(always)]
    pub(super) fn new(grid: &'g TGrid<T>, ray: &Ray) -> Frame<'g, T> {
        let m = ray.dir[0].abs().max(ray.dir[1].abs()).max(ray.dir[2].abs());
        let p = if T::of(m).is_normal() && T::of(1.0 / m).is_normal() {
            1.0
        } else {
            pow2_scale(m)
        };
        // Mirror axes with negative components (-0.0 is not negative).
        let mirror: [bool; 3] = std::array::from_fn(|k| ray.dir[k] < 0.0);
        let d: [T; 3] = std::array::from_fn(|k| T::of(ray.dir[k].abs() / p));
        let inv_d = d.map(|x| T::one() / x);
        let o: [T; 3] = std::array::from_fn(|k| {
            T::of(if mirror[k] {
                -ray.origin[k]
            } else {
                ray.origin[k]
            })
        });
        Frame {
            s: std::array::from_fn(|k| &grid.axes[k].s[mirror[k] as usize][..]),
            uniform: std::array::from_fn(|k| grid.axes[k].uniform),
            inv_h: std::array::from_fn(|k| grid.axes[k].inv_h),
            o,
            d,
            inv_d,
            mul: std::array::from_fn(|k| d[k] != T::zero() && inv_d[k].is_finite()),
            mirror,
            flip: mirror.map(|m| if m { !0 } else { 0 }),
            shift: std::array::from_fn(|k| if mirror[k] { grid.ncells[k] } else { 0 }),
            n: grid.ncells,
            p,
            inv_p: 1.0 / p,
        }
    }

    /// Where the ray enters the volume at or after `t_min` (finite): the
    /// slab test, then the starting cell by the `t` rule; it leaves at the
    /// volume's far face or at `t_max`, whichever comes first. `None` when
    /// it misses the volume between them (or, in f32, its origin is beyond
    /// the range).
    #[inline(always)]
    pub(super) fn entry(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Entry<T>> {
        let f = self;
        if !f.o.iter().all(|x| x.is_finite()) {
            // Only in f32: an origin beyond its range.
            return None;
        }
        let mut t_in = T::of(t_min * f.p);
        let mut t_out = if t_max == f64::INFINITY {
            T::infinity()
        } else {
            T::of(t_max * f.p)
        };
        for k in 0..3 {
            let s = f.s[k];
            if f.d[k] == T::zero() {
                // Parallel: inside the closed slab. A flushed component
                // still moves the ray, so on the far face it leaves at once.
                let top = s[s.len() - 1];
                let below_top = if ray.dir[k] == 0.0 {
                    f.o[k] <= top
                } else {
                    f.o[k] < top
                };
                if !(f.o[k] >= s[0] && below_top) {
                    return None;
                }
            } else {
                t_in = t_in.max(f.plane_t(k, 0));
                t_out = t_out.min(f.plane_t(k, f.n[k]));
            }
        }
        if !(t_in < t_out) {
            return None;
        }
        let v: [u32; 3] = std::array::from_fn(|k| {
            if f.d[k] == T::zero() {
                // Largest sample position <= o, kept inside the last cell.
                let s = f.s[k];
                (s.partition_point(|&x| x <= f.o[k]).max(1) - 1).min(f.n[k] as usize - 1) as u32
            } else {
                f.locate(k, t_in, 0, f.n[k] - 1)
            }
        });
        Some(Entry { v, t_in, t_out })
    }

    /// The ray's `t` of the frame's parameter `t`.
    #[inline(always)]
    pub(super) fn to_t(&self, t: T) -> f64 {
        t.f64() * self.inv_p
    }

    /// The octant of the ray's direction (bit `k` set when axis `k` is
    /// mirrored): which of a block's 8 anisotropic codes apply (section
    /// 4.2.1).
    pub(super) fn octant(&self) -> usize {
        (self.mirror[0] as usize) | (self.mirror[1] as usize) << 1 | (self.mirror[2] as usize) << 2
    }

    /// `t` at which the ray crosses plane `j` of axis `k` (+inf if the ray
    /// is parallel to it). The one formula every traversal uses:
    /// `(S'[j] - o') * (1 / d')`, a multiplication rather than a division
    /// in the step (paper section 4.1, last paragraph), monotone in `j`.
    #[inline(always)]
    pub(super) fn plane_t(&self, k: usize, j: u32) -> T {
        if self.mul[k] {
            (self.s[k][j as usize] - self.o[k]) * self.inv_d[k]
        } else if self.d[k] == T::zero() {
            T::infinity()
        } else {
            (self.s[k][j as usize] - self.o[k]) / self.d[k]
        }
    }

    /// The next plane crossing along each axis from cell `v`.
    #[inline(always)]
    pub(super) fn crossings(&self, v: [u32; 3]) -> [T; 3] {
        [
            self.plane_t(0, v[0] + 1),
            self.plane_t(1, v[1] + 1),
            self.plane_t(2, v[2] + 1),
        ]
    }

    /// Largest `j` in `[lo, hi]` with `plane_t(k, j) <= t` (`plane_t(k,
    /// lo) <= t` must hold). Locate of Fig. 11: direct on uniform axes
    /// (an estimate corrected by the same `plane_t`), binary search
    /// bounded by the cube otherwise.
    #[inline(always)]
    pub(super) fn locate(&self, k: usize, t: T, lo: u32, hi: u32) -> u32 {
        self.locate_next(k, t, lo, hi).0
    }

    /// [`Frame::locate`], with `plane_t(k, j + 1)` of the `j` it finds when
    /// its search computed that plane on the way (the same value, so a
    /// leap need not compute it again for the cell's next crossing).
    #[inline(always)]
    pub(super) fn locate_next(&self, k: usize, t: T, lo: u32, hi: u32) -> (u32, Option<T>) {
        if self.uniform[k].is_some() {
            let p = self.o[k] + t * self.d[k];
            // Clamped before truncating: inside (lo, hi) the estimate is
            // positive, where truncation is floor (no libm call); NaN
            // goes to lo. Multiplied by `1 / h` rather than divided by
            // `h`: only an estimate, which the two loops below correct
            // by `plane_t` whatever it is, and a division's latency sat
            // on every leap (docs/BENCHMARKS.md, "Locate by
            // multiplication").
            let est = ((p - self.s[k][0]) * self.inv_h[k]).f64();
            let mut j = if est > lo as f64 {
                est.min(hi as f64) as u32
            } else {
                lo
            };
            // Up while the next plane is at or before t, then down while
            // the cell's own plane is after it; `after` keeps the last
            // plane found after t, which is then plane `j + 1`.
            let mut after = None;
            while j < hi {
                let tp = self.plane_t(k, j + 1);
                if tp > t {
                    after = Some(tp);
                    break;
                }
                j += 1;
            }
            while j > lo {
                let tp = self.plane_t(k, j);
                if tp <= t {
                    break;
                }
                j -= 1;
                after = Some(tp);
            }
            (j, after)
        } else {
            let (mut a, mut b) = (lo, hi);
            // The last plane found after t: plane `b + 1`, and at the end
            // `a == b`.
            let mut after = None;
            while a < b {
                let m = a + (b - a).div_ceil(2);
                let tp = self.plane_t(k, m);
                if tp <= t {
                    a = m;
                } else {
                    b = m - 1;
                    after = Some(tp);
                }
            }
            (a, after)
        }
    }

    /// Far faces, in the mirrored frame, of the octree node of level `l`
    /// holding original cell `real`: the node spans `[a, a + 2^l)` along
    /// each axis of the original grid (clipped to the volume), so its far
    /// face is `a + 2^l` on an unmirrored axis and `n - a` on a mirrored
    /// one.
    #[inline(always)]
    pub(super) fn node_far(&self, real: [u32; 3], l: u8) -> [u32; 3] {
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
    pub(super) fn real(&self, v: [u32; 3]) -> [u32; 3] {
        std::array::from_fn(|k| (v[k] ^ self.flip[k]).wrapping_add(self.shift[k]))
    }
}

/// Far faces of the empty cube around cell `v` with code `n` (eq. 12):
/// the cube spans `n` cells on every side, so the ray leaves it through
/// plane `v + n + 1` of some axis (the paper's `N` is `n + 1`), clipped to
/// the volume's `ncells`.
#[inline(always)]
pub(super) fn cube_far(v: [u32; 3], n: u8, ncells: [u32; 3]) -> [u32; 3] {
    let n = n as u32;
    std::array::from_fn(|k| (v[k] + n + 1).min(ncells[k]))
}

/// Axis of the smallest `t`, ties to x, then y (paper Fig. 11a).
#[inline(always)]
pub(super) fn argmin<T: Real>(t: [T; 3]) -> usize {
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

/// Where a cell-stepping walk stands: the current cell `v` (mirrored
/// frame), the next plane crossing along each axis, and the parameter at
/// which the ray entered `v`.
#[derive(Clone, Copy)]
pub(super) struct Cursor<T> {
    pub(super) v: [u32; 3],
    next: [T; 3],
    t_enter: T,
    t_out: T,
}

impl<T: Real> Cursor<T> {
    pub(super) fn new(f: &Frame<'_, T>, e: Entry<T>) -> Cursor<T> {
        Cursor {
            v: e.v,
            next: f.crossings(e.v),
            t_enter: e.t_in,
            t_out: e.t_out,
        }
    }

    /// The visit of the current cell, which is `real` in the original
    /// grid; `None` when the ray only grazes it (zero length).
    #[inline(always)]
    pub(super) fn visit(&self, f: &Frame<'_, T>, real: [u32; 3]) -> Option<Visit> {
        let t_exit = self.next[0]
            .min(self.next[1])
            .min(self.next[2])
            .min(self.t_out);
        (t_exit > self.t_enter).then(|| Visit {
            cell: real,
            t_enter: f.to_t(self.t_enter),
            t_exit: f.to_t(t_exit),
        })
    }

    /// Single-cell step (Fig. 11, MasterStep_1 / SlaveStep_1): across the
    /// nearest plane. `false` when the ray leaves the volume.
    #[inline(always)]
    pub(super) fn step(&mut self, f: &Frame<'_, T>) -> bool {
        let m = argmin(self.next);
        let t = self.next[m];
        if t >= self.t_out {
            return false;
        }
        self.v[m] += 1;
        if self.v[m] >= f.n[m] {
            return false;
        }
        self.next[m] = f.plane_t(m, self.v[m] + 1);
        self.t_enter = t;
        true
    }

    /// Macro step (Figs. 11-12): out of the empty region whose far faces
    /// are planes `far` through the nearest of them ([`leap_exit`]), then
    /// *Locate* the other axes at that `t` within the region. `false` when
    /// the ray leaves the volume.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // v[k], far[k], f.d[k] side by side
    pub(super) fn leap(&mut self, f: &Frame<'_, T>, far: [u32; 3]) -> bool {
        let Some((m, t)) = leap_exit(f, far) else {
            return false;
        };
        // Past the walk's end (a clip's far face): out.
        if t >= self.t_out {
            return false;
        }
        for k in 0..3 {
            let mut after = None;
            if k == m {
                self.v[k] = far[k];
            } else if f.d[k] != T::zero() {
                (self.v[k], after) = f.locate_next(k, t, self.v[k], far[k]);
                if self.v[k] >= f.n[k] {
                    return false;
                }
            }
            self.next[k] = after.unwrap_or_else(|| f.plane_t(k, self.v[k] + 1));
        }
        self.t_enter = t;
        true
    }
}

/// Where the leap of Figs. 11-12 leaves an empty region whose far faces
/// are planes `far` (mirrored frame; [`cube_far`] for CD, eq. 12;
/// [`Frame::node_far`] for the octree): the axis and `t` of the nearest far
/// face, ties to x then y; `None` when that face is the volume's own far
/// face, where the ray leaves. A short pure function of the frame and the
/// faces.
#[inline(always)]
pub(super) fn leap_exit<T: Real>(f: &Frame<'_, T>, far: [u32; 3]) -> Option<(usize, T)> {
    let t_far = [
        f.plane_t(0, far[0]),
        f.plane_t(1, far[1]),
        f.plane_t(2, far[2]),
    ];
    let m = argmin(t_far);
    (far[m] < f.n[m]).then_some((m, t_far[m]))
}
