//! The ray/iso-surface intersection inside a 1-cell (paper section 5.3,
//! Fig. 22): the paper's three methods on the face samples, and the
//! exact first root of the trilinear interpolant along the ray, with
//! their speed/accuracy knobs. Shared by every traversal, as the cell
//! evaluation in [`super::shade`] is.

use super::shade::{at, CellEval};
use crate::render::traverse::{Ray, Visit};

/// How the ray/iso-surface intersection inside a 1-cell is found (paper
/// section 5.3, Fig. 22).
///
/// `Int`, `Bisect` and `Newton` follow the paper: whether the cell holds a
/// hit is judged from the two face samples alone (entry >= iso, or exit >=
/// iso), so a surface the ray enters and leaves again inside one cell is
/// missed. `Exact` finds the true first crossing of the interpolant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HitMethod {
    /// Linear interpolation between the two face samples that straddle the
    /// iso value (non-iterative).
    Int,
    /// Bisection on the trilinear interpolant along the ray.
    Bisect,
    /// Newton-Raphson on the trilinear interpolant (continuous derivative
    /// inside the cell), safeguarded by the bracket.
    Newton,
    /// The first root of the interpolant along the ray, to full f64
    /// precision: along a ray the trilinear interpolant is a cubic in `t`,
    /// split at its turning points into monotone pieces; the first piece
    /// that reaches iso is refined by safeguarded Newton. Unlike the
    /// face-sample methods, this finds hits where both face samples are
    /// below iso but the interpolant rises above it in between.
    Exact,
}

impl HitMethod {
    /// The stable name: `int`, `bisect`, `newton` or `exact`.
    pub fn name(self) -> &'static str {
        match self {
            HitMethod::Int => "int",
            HitMethod::Bisect => "bisect",
            HitMethod::Newton => "newton",
            HitMethod::Exact => "exact",
        }
    }
}

/// Iterations of bisection (relative bracket 2^-30) and at most Newton.
pub const BISECT_ITERS: u32 = 30;
pub const NEWTON_ITERS: u32 = 8;
/// Newton's relative stop tolerance (on the bracket and on |g|).
pub const NEWTON_TOL: f64 = 1e-12;

/// Speed/accuracy knobs of the iterative hit methods (paper section 5.3);
/// `Int` has none and `Exact` always iterates to full precision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HitParams {
    /// Bisection steps, one interpolant evaluation each: the error is at
    /// most `(t_exit - t_enter) * 2^-(bisect_iters + 1)`, so each step buys
    /// one bit; beyond ~53 steps the bracket is below f64 resolution and
    /// steps only cost time.
    pub bisect_iters: u32,
    /// Cap on Newton steps, one value and one gradient evaluation each.
    /// Near a simple root 3-5 steps usually meet `newton_tol`; the cap
    /// bounds the cost where Newton falls back to bisecting.
    pub newton_iters: u32,
    /// Newton stops once the bracket is within `newton_tol * (t_exit -
    /// t_enter)` or `|g| <= newton_tol * max(|iso|, 1)`. Smaller is more
    /// accurate and costs steps; below ~1e-15 it is rarely met and the cap
    /// decides.
    pub newton_tol: f64,
}

impl Default for HitParams {
    /// The paper's constants: 30 bisections, at most 8 Newton steps with
    /// relative tolerance 1e-12.
    fn default() -> HitParams {
        HitParams {
            bisect_iters: BISECT_ITERS,
            newton_iters: NEWTON_ITERS,
            newton_tol: NEWTON_TOL,
        }
    }
}

/// [`find_hit_with`] with [`HitParams::default`].
pub fn find_hit(ray: &Ray, v: &Visit, c: &CellEval, iso: f64, method: HitMethod) -> Option<f64> {
    find_hit_with(ray, v, c, iso, method, &HitParams::default())
}

/// The first `t` in `[t_enter, t_exit]` where the interpolant reaches
/// `iso` (paper section 5.3): `t_enter` when the entry sample is already
/// `>= iso`. Otherwise `Int`, `Bisect` and `Newton` judge from the face
/// samples, as in the paper (Fig. 22): a hit only when the exit sample is
/// `>= iso`, then located between the faces (bisection may converge to a
/// later crossing when there are several). `Exact` looks at the whole
/// cubic along the ray, so it also reports a surface both face samples
/// miss, and it locates the first crossing.
///
/// Never returns NaN: a returned `t` lies in `[t_enter, t_exit]`, and NaN
/// or infinite vertex values give `None` or such a `t`.
pub fn find_hit_with(
    ray: &Ray,
    v: &Visit,
    c: &CellEval,
    iso: f64,
    method: HitMethod,
    params: &HitParams,
) -> Option<f64> {
    let g = |t: f64| c.value(at(ray, t)) - iso;
    let (t0, t1) = (v.t_enter, v.t_exit);
    if !(t0 <= t1) {
        return None;
    }
    let (g0, g1) = (g(t0), g(t1));
    if g0 >= 0.0 {
        return Some(t0);
    }
    if method == HitMethod::Exact {
        return first_root(&cubic_along(ray, c, t0, t1, iso), t0, t1);
    }
    if !(g1 >= 0.0) {
        return None;
    }
    // Infinite samples can make the linear guess NaN.
    let t_int = t0 + (t1 - t0) * (-g0 / (g1 - g0));
    let t_int = if t_int.is_finite() {
        t_int.clamp(t0, t1)
    } else {
        0.5 * (t0 + t1)
    };
    Some(match method {
        HitMethod::Int => t_int,
        HitMethod::Exact => unreachable!("returned above"),
        HitMethod::Bisect => {
            let (mut a, mut b) = (t0, t1);
            for _ in 0..params.bisect_iters {
                let m = 0.5 * (a + b);
                if g(m) >= 0.0 {
                    b = m;
                } else {
                    a = m;
                }
            }
            0.5 * (a + b)
        }
        HitMethod::Newton => {
            // Newton on g(t), kept inside the shrinking bracket [a, b]
            // (g(a) < 0 <= g(b)); a step that leaves it bisects instead.
            let tol = params.newton_tol;
            let (mut a, mut b) = (t0, t1);
            let mut t = t_int;
            for _ in 0..params.newton_iters {
                let gt = g(t);
                if gt.abs() <= tol * iso.abs().max(1.0) {
                    break;
                }
                if gt > 0.0 {
                    b = t;
                } else {
                    a = t;
                }
                let gr = c.gradient(at(ray, t));
                let nt = t - gt / gr.dot(ray.dir);
                t = if nt >= a && nt <= b {
                    nt
                } else {
                    0.5 * (a + b)
                };
                if b - a <= tol * (t1 - t0) {
                    break;
                }
            }
            t
        }
    })
}

/// The interpolant minus `iso` along the ray as a cubic in `s` in [0, 1],
/// `t = t0 + s (t1 - t0)`, coefficients constant first. The local
/// coordinates are exactly linear, `u = u(t0) + s (u(t1) - u(t0))`, all
/// terms in [-1, 1]; the nested lerps of [`CellEval::value_local`] are
/// expanded as polynomials, keeping its vertex differences (better
/// conditioned than fitting a cubic to samples).
fn cubic_along(ray: &Ray, c: &CellEval, t0: f64, t1: f64, iso: f64) -> [f64; 4] {
    let (ua, ub) = (c.local(at(ray, t0)), c.local(at(ray, t1)));
    let u: [[f64; 2]; 3] = std::array::from_fn(|k| [ua[k], ub[k] - ua[k]]);
    // p + u (q - p) with u = u[0] + u[1] s; degrees stay <= 3.
    let lerp = |p: [f64; 4], q: [f64; 4], u: [f64; 2]| -> [f64; 4] {
        std::array::from_fn(|i| {
            let up = if i > 0 {
                u[1] * (q[i - 1] - p[i - 1])
            } else {
                0.0
            };
            p[i] + u[0] * (q[i] - p[i]) + up
        })
    };
    let f = c.f.map(|x| [x, 0.0, 0.0, 0.0]);
    let x00 = lerp(f[0], f[1], u[0]);
    let x10 = lerp(f[2], f[3], u[0]);
    let x01 = lerp(f[4], f[5], u[0]);
    let x11 = lerp(f[6], f[7], u[0]);
    let mut p = lerp(lerp(x00, x10, u[1]), lerp(x01, x11, u[1]), u[2]);
    p[0] -= iso;
    p
}

/// The first `t` in `[t0, t1]` where the cubic `p` (as from
/// [`cubic_along`]) is >= 0, if any: `[0, 1]` is split at the real roots of
/// `p'`, so `p` is monotone on each piece, and the first piece whose end
/// reaches 0 holds the first crossing.
fn first_root(p: &[f64; 4], t0: f64, t1: f64) -> Option<f64> {
    let eval = |s: f64| ((p[3] * s + p[2]) * s + p[1]) * s + p[0];
    let deriv = |s: f64| (3.0 * p[3] * s + 2.0 * p[2]) * s + p[1];
    // Roots of p' = a s^2 + b s + c, without cancellation: q / a and c / q
    // (also right when a = 0; missing roots come out inf or NaN).
    let (a, b, c) = (3.0 * p[3], 2.0 * p[2], p[1]);
    let q = -0.5 * (b + b.signum() * (b * b - 4.0 * a * c).sqrt());
    let mut knots = [0.0, 1.0, 1.0, 1.0];
    let mut n = 1;
    for r in [q / a, c / q] {
        if r > 0.0 && r < 1.0 {
            knots[n] = r;
            n += 1;
        }
    }
    knots[1..n].sort_by(f64::total_cmp);
    let i = (0..=n).find(|&i| eval(knots[i]) >= 0.0)?;
    if i == 0 {
        return Some(t0);
    }
    let l = t1 - t0;
    let to_t = |s: f64| if s == 1.0 { t1 } else { t0 + s * l };
    let pt = |t: f64| {
        let s = (t - t0) / l;
        (eval(s), deriv(s) / l)
    };
    Some(refine(pt, to_t(knots[i - 1]), to_t(knots[i])).clamp(t0, t1))
}

/// The first float where `p` becomes >= 0 in `[a, b]`, given `p(a) < 0 <=
/// p(b)`; `p` returns value and derivative. Newton steps from inside the
/// bracket, each followed by a probe one step further: near a simple root
/// Newton's error is about the square of its step, so the probe lands
/// across the root and closes the bracket from the other side. Whenever a
/// step leaves the bracket or the bracket failed to halve, bisect. Stops
/// when the bracket is two adjacent floats (or after 100 rounds).
fn refine(p: impl Fn(f64) -> (f64, f64), mut a: f64, mut b: f64) -> f64 {
    let mut x = 0.5 * (a + b);
    for _ in 0..100 {
        let width = b - a;
        let (px, dpx) = p(x);
        if px >= 0.0 {
            b = x;
        } else {
            a = x;
        }
        let n = x - px / dpx;
        let d = (n - x).abs().max(f64::EPSILON * x.abs());
        let probe = if px >= 0.0 { n - d } else { n + d };
        if probe > a && probe < b {
            if p(probe).0 >= 0.0 {
                b = probe;
            } else {
                a = probe;
            }
        }
        let m = 0.5 * (a + b);
        if m <= a || m >= b {
            break;
        }
        x = if n > a && n < b && b - a <= 0.5 * width {
            n
        } else {
            m
        };
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        DVec3::from_array(a).dot(DVec3::from_array(b))
    }

    fn normalize(a: [f64; 3]) -> DVec3 {
        let v = DVec3::from_array(a);
        v / v.length()
    }

    fn v3(a: [f64; 3]) -> DVec3 {
        DVec3::from_array(a)
    }

    /// A ray along +x through the unit cell at y = z = 0.5, entering at
    /// t = 1 and leaving at t = 2.
    fn along_x() -> (Ray, Visit) {
        let ray = Ray {
            origin: v3([-1.0, 0.5, 0.5]),
            dir: v3([1.0, 0.0, 0.0]),
        };
        let v = Visit {
            cell: [0; 3],
            t_enter: 1.0,
            t_exit: 2.0,
        };
        (ray, v)
    }

    #[test]
    fn hit_methods_agree_on_a_linear_field() {
        // f = x along x in [0, 1]; iso 0.3; ray along +x.
        let coords: [Vec<f64>; 3] = [vec![0.0, 1.0], vec![0.0, 1.0], vec![0.0, 1.0]];
        let f = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], f);
        let (ray, v) = along_x();
        for m in [HitMethod::Int, HitMethod::Bisect, HitMethod::Newton] {
            let t = find_hit(&ray, &v, &c, 0.3, m).unwrap();
            assert!((t - 1.3).abs() < 1e-7, "{m:?}: {t}");
        }
        assert_eq!(find_hit(&ray, &v, &c, 1.5, HitMethod::Int), None);
    }

    #[test]
    fn newton_and_bisect_agree_on_a_nonlinear_field() {
        // A distance-like field: the trilinear interpolant is not linear
        // along the ray, so the three methods differ; Newton and bisection
        // must converge to the same root, including when the linear guess
        // is already the root.
        let coords: [Vec<f64>; 3] = [vec![0.0, 1.0], vec![0.0, 1.0], vec![0.0, 1.5]];
        let fun = |p: [f64; 3]| {
            10.0 - ((p[0] - 3.0).powi(2) + (p[1] + 1.0).powi(2) + (p[2] - 0.2).powi(2)).sqrt()
        };
        let mut f = [0f32; 8];
        for (i, v) in f.iter_mut().enumerate() {
            *v = fun([coords[0][i & 1], coords[1][i >> 1 & 1], coords[2][i >> 2]]) as f32;
        }
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], f);
        let ray = Ray {
            origin: v3([-1.0, 0.3, 0.4]),
            dir: normalize([1.0, 0.1, 0.2]),
        };
        let v = Visit {
            cell: [0; 3],
            t_enter: 1.0 / ray.dir[0],
            t_exit: 2.0 / ray.dir[0],
        };
        for frac in [0.1, 0.5, 0.93] {
            let iso = c.value(at(&ray, (1.0 + frac) / ray.dir[0]));
            let tb = find_hit(&ray, &v, &c, iso, HitMethod::Bisect).unwrap();
            let tn = find_hit(&ray, &v, &c, iso, HitMethod::Newton).unwrap();
            assert!((tb - tn).abs() < 1e-8, "bisect {tb} newton {tn}");
            assert!((c.value(at(&ray, tn)) - iso).abs() < 1e-9);
        }
        // The linear guess is exact on a linear field: Newton must keep it.
        let lin = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], lin);
        let (ray, v) = along_x();
        assert_eq!(find_hit(&ray, &v, &c, 0.25, HitMethod::Newton), Some(1.25));
    }

    use proptest::prelude::*;

    const ALL: [HitMethod; 4] = [
        HitMethod::Int,
        HitMethod::Bisect,
        HitMethod::Newton,
        HitMethod::Exact,
    ];

    /// Parameter range `[t0, t1]` of the ray inside the cell (slab clip).
    fn clip(ray: &Ray, c: &CellEval) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (lo, hi) = (c.lo[k], c.lo[k] + c.size[k]);
            if ray.dir[k] == 0.0 {
                if ray.origin[k] < lo || ray.origin[k] > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = (
                (lo - ray.origin[k]) / ray.dir[k],
                (hi - ray.origin[k]) / ray.dir[k],
            );
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 < t1).then_some((t0, t1))
    }

    /// A cell of size `10^size_exp` (per axis, so up to 1e6 anisotropic)
    /// at `lo = lo_f * size`, and the ray through the local points `p` and
    /// `q`, starting `10^far_exp` cell diagonals before `p` (at `p` if
    /// `None`), with the visit of its chord.
    fn cell_ray(
        f: [f64; 8],
        size_exp: [f64; 3],
        lo_f: [f64; 3],
        p: [f64; 3],
        q: [f64; 3],
        far_exp: Option<f64>,
    ) -> Option<(CellEval, Ray, Visit)> {
        let size = size_exp.map(|e| 10f64.powf(e));
        let lo = std::array::from_fn(|k| lo_f[k] * size[k]);
        let c = CellEval { lo, size, f };
        let pt = |u: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| lo[k] + u[k] * size[k]) };
        let (pp, qq) = (pt(p), pt(q));
        let d: [f64; 3] = std::array::from_fn(|k| qq[k] - pp[k]);
        let len = dot(d, d).sqrt();
        if !(len > 1e-3 * dot(size, size).sqrt()) {
            return None;
        }
        let dir = d.map(|x| x / len);
        let back = far_exp.map_or(0.0, |e| 10f64.powf(e) * dot(size, size).sqrt());
        let ray = Ray {
            origin: v3(std::array::from_fn(|k| pp[k] - back * dir[k])),
            dir: v3(dir),
        };
        let (t_enter, t_exit) = clip(&ray, &c)?;
        let v = Visit {
            cell: [0; 3],
            t_enter,
            t_exit,
        };
        Some((c, ray, v))
    }

    fn g(c: &CellEval, ray: &Ray, iso: f64, t: f64) -> f64 {
        c.value(at(ray, t)) - iso
    }

    /// Rounding noise of `g(t)`, the bound Exact's root is held to. With
    /// `M` the largest |vertex value| or |iso|: `value_local`'s lerps and
    /// Exact's Horner evaluation of the cubic (coefficient sum <= 8 * 8 M)
    /// round by a few hundred ulps of `M` at most. The local coordinates
    /// `(o + t d - lo) / size` carry an error of ~eps * (|o| + |t d| + |lo|)
    /// / size per axis (a far origin, or a thin cell, costs digits), and the
    /// interpolant's slope per local unit is <= 2 M per axis; this also
    /// covers the root being one float ulp(t) <= eps |t| off. Hence
    /// 512 eps M (1 + sum_k (|o_k| + |t d_k| + |lo_k|) / size_k), ~1e-13 M
    /// for a ray from inside a well-shaped cell.
    fn noise(c: &CellEval, ray: &Ray, iso: f64, t: f64) -> f64 {
        let m = c.f.iter().fold(iso.abs(), |m, f| m.max(f.abs()));
        let cond: f64 = (0..3)
            .map(|k| (ray.origin[k].abs() + (t * ray.dir[k]).abs() + c.lo[k].abs()) / c.size[k])
            .sum();
        512.0 * f64::EPSILON * m * (1.0 + cond)
    }

    fn unit() -> impl Strategy<Value = f64> {
        // Corners, faces and edges as well as interior points.
        prop_oneof![3 => 0.0..=1.0, 1 => Just(0.0), 1 => Just(1.0)]
    }

    proptest! {
        // (b) rejects the ~40% of cells where g is not monotone on the
        // chord; proptest still runs `cases` accepted ones.
        #![proptest_config(ProptestConfig {
            cases: 512,
            max_global_rejects: 1 << 20,
            ..ProptestConfig::default()
        })]

        /// (a) Exact's root is a root up to rounding noise, and g stays
        /// below iso (up to the same noise) everywhere before it.
        #[test]
        fn exact_finds_the_first_crossing(
            f in prop::array::uniform8(-1.0f64..1.0),
            scale_exp in -3.0f64..3.0,
            size_exp in prop::array::uniform3(-3.0f64..3.0),
            lo_f in prop::array::uniform3(-10.0f64..10.0),
            p in prop::array::uniform3(unit()),
            q in prop::array::uniform3(unit()),
            far_exp in -3.0f64..3.0,
            theta in 0.0f64..=1.0,
        ) {
            let f = f.map(|x| x * 10f64.powf(scale_exp));
            let Some((c, ray, v)) = cell_ray(f, size_exp, lo_f, p, q, Some(far_exp)) else {
                return Ok(());
            };
            let (lo, hi) = f.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
            let iso = lo + theta * (hi - lo);
            let (t0, t1) = (v.t_enter, v.t_exit);
            let te = find_hit(&ray, &v, &c, iso, HitMethod::Exact);
            let end = match te {
                Some(t) => {
                    prop_assert!(t >= t0 && t <= t1, "{t} outside [{t0}, {t1}]");
                    let gt = g(&c, &ray, iso, t);
                    let tol = noise(&c, &ray, iso, t);
                    if t == t0 {
                        prop_assert!(gt >= -tol, "hit at entry with g = {gt}");
                    } else {
                        prop_assert!(gt.abs() <= tol, "|g({t})| = {} > {tol}", gt.abs());
                    }
                    t
                }
                None => t1,
            };
            const N: usize = 2000;
            for i in 0..=N {
                let t = t0 + (end - t0) * (i as f64 / N as f64);
                if te.is_some() && t >= end {
                    break;
                }
                let gt = g(&c, &ray, iso, t);
                prop_assert!(gt < noise(&c, &ray, iso, t), "g({t}) = {gt} before the hit {te:?}");
            }
        }

        /// (b) Where the crossing is the only one and well-conditioned,
        /// bisection (60 steps) and Newton (tol 1e-15) agree with Exact to
        /// the root's condition: the rounding noise of g (plus Newton's
        /// own |g| stop) over the slope, plus Newton's 1e-15 bracket stop
        /// and a few ulps of t.
        #[test]
        fn bisect_and_newton_agree_with_exact(
            f in prop::array::uniform8(-1.0f64..1.0),
            scale_exp in -3.0f64..3.0,
            size_exp in prop::array::uniform3(-3.0f64..3.0),
            lo_f in prop::array::uniform3(-2.0f64..2.0),
            p in prop::array::uniform3(0.0f64..=1.0),
            q in prop::array::uniform3(0.0f64..=1.0),
            theta in 0.02f64..0.98,
        ) {
            let f = f.map(|x| x * 10f64.powf(scale_exp));
            let Some((c, ray, v)) = cell_ray(f, size_exp, lo_f, p, q, None) else {
                return Ok(());
            };
            let (t0, t1) = (v.t_enter, v.t_exit);
            let l = t1 - t0;
            let mut c = c;
            let mut iso = c.value(at(&ray, t0 + theta * l));
            // Make g rise along the ray (negating values and iso keeps the
            // surface).
            if c.value(at(&ray, t0)) > c.value(at(&ray, t1)) {
                c.f = c.f.map(|x| -x);
                iso = -iso;
            }
            let m = c.f.iter().fold(iso.abs(), |m, f| m.max(f.abs()));
            prop_assume!(g(&c, &ray, iso, t0) < 0.0 && g(&c, &ray, iso, t1) >= 0.0);
            let mut prev = f64::NEG_INFINITY;
            for i in 0..=1000 {
                let t = t0 + l * (i as f64 / 1000.0);
                let gt = g(&c, &ray, iso, t);
                prop_assume!(gt >= prev - noise(&c, &ray, iso, t), "not monotone");
                prev = gt;
            }
            let te = find_hit(&ray, &v, &c, iso, HitMethod::Exact).unwrap();
            let slope = c.gradient(at(&ray, te)).dot(ray.dir).abs();
            prop_assume!(slope * l >= 1e-2 * m, "ill-conditioned crossing");
            let params = HitParams { bisect_iters: 60, newton_iters: 100, newton_tol: 1e-15 };
            let dg = noise(&c, &ray, iso, te) + 1e-15 * iso.abs().max(1.0);
            let tol = 4.0 * dg / slope + 1e-15 * l + 8.0 * f64::EPSILON * t0.abs().max(t1.abs());
            for method in [HitMethod::Bisect, HitMethod::Newton] {
                let t = find_hit_with(&ray, &v, &c, iso, method, &params).unwrap();
                prop_assert!((t - te).abs() <= tol, "{method:?} {t} exact {te}: {} > {tol}", (t - te).abs());
            }
        }

        /// (d) NaN and infinite vertex values (and iso): never NaN, never
        /// outside the visit, with default and with fine parameters.
        #[test]
        fn special_values_give_no_nan(
            f in prop::array::uniform8(prop_oneof![
                4 => -10.0f64..10.0,
                1 => Just(f64::NAN),
                1 => Just(f64::INFINITY),
                1 => Just(f64::NEG_INFINITY),
            ]),
            iso in prop_oneof![
                4 => -10.0f64..10.0,
                1 => Just(f64::NAN),
                1 => Just(f64::INFINITY),
                1 => Just(f64::NEG_INFINITY),
            ],
            size_exp in prop::array::uniform3(-1.0f64..1.0),
            p in prop::array::uniform3(unit()),
            q in prop::array::uniform3(unit()),
        ) {
            let Some((c, ray, v)) = cell_ray(f, size_exp, [0.0; 3], p, q, Some(0.0)) else {
                return Ok(());
            };
            let fine = HitParams { bisect_iters: 60, newton_iters: 100, newton_tol: 1e-15 };
            for params in [HitParams::default(), fine] {
                for method in ALL {
                    if let Some(t) = find_hit_with(&ray, &v, &c, iso, method, &params) {
                        prop_assert!(
                            t >= v.t_enter && t <= v.t_exit,
                            "{method:?}: {t} outside [{}, {}]", v.t_enter, v.t_exit
                        );
                    }
                }
            }
        }
    }

    /// (c) Both face samples below iso, the interpolant above it in
    /// between: only Exact sees the surface.
    #[test]
    fn exact_finds_a_surface_between_the_face_samples() {
        // f = x y, on the diagonal from (0, 1) to (1, 0): s (1 - s), which
        // peaks at 0.25 mid-cell and is 0 on both faces.
        let mut f = [0.0; 8];
        f[3] = 1.0;
        f[7] = 1.0;
        let c = CellEval {
            lo: [0.0; 3],
            size: [1.0; 3],
            f,
        };
        let ray = Ray {
            origin: v3([0.0, 1.0, 0.5]),
            dir: normalize([1.0, -1.0, 0.0]),
        };
        let v = Visit {
            cell: [0; 3],
            t_enter: 0.0,
            t_exit: 2f64.sqrt(),
        };
        let iso = 0.2;
        for m in [HitMethod::Int, HitMethod::Bisect, HitMethod::Newton] {
            assert_eq!(find_hit(&ray, &v, &c, iso, m), None, "{m:?}");
        }
        // s (1 - s) = 0.2 first at s = (1 - sqrt(0.2)) / 2.
        let t = find_hit(&ray, &v, &c, iso, HitMethod::Exact).unwrap();
        let want = (1.0 - 0.2f64.sqrt()) / 2.0 * 2f64.sqrt();
        assert!((t - want).abs() < 1e-14, "{t} vs {want}");
        // Above the peak there is no surface.
        assert_eq!(find_hit(&ray, &v, &c, 0.26, HitMethod::Exact), None);
        // Entry already inside: the entry point, as for every method.
        for m in ALL {
            assert_eq!(find_hit(&ray, &v, &c, -0.1, m), Some(0.0), "{m:?}");
        }
    }

    /// Several crossings in one cell: Exact returns the first, while
    /// bisection on the face-sample bracket converges to whichever its
    /// halving meets (here the last).
    #[test]
    fn exact_takes_the_first_of_several_crossings() {
        // f = c0 + c1 x + c2 x y + c3 x y z is (s - 0.1)(s - 0.3)(s - 0.9)
        // + iso on the diagonal x = y = z = s.
        let (iso, c1, c2, c3) = (0.5, 0.39, -1.3, 1.0);
        let c0 = iso - 0.027;
        let f = std::array::from_fn(|i| {
            let (x, y, z) = ((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2) as f64);
            c0 + c1 * x + c2 * x * y + c3 * x * y * z
        });
        let c = CellEval {
            lo: [0.0; 3],
            size: [1.0; 3],
            f,
        };
        let ray = Ray {
            origin: DVec3::ZERO,
            dir: normalize([1.0; 3]),
        };
        let r3 = 3f64.sqrt();
        let v = Visit {
            cell: [0; 3],
            t_enter: 0.0,
            t_exit: r3,
        };
        let t = find_hit(&ray, &v, &c, iso, HitMethod::Exact).unwrap();
        assert!((t - 0.1 * r3).abs() < 1e-14, "{t}");
        let t = find_hit(&ray, &v, &c, iso, HitMethod::Bisect).unwrap();
        assert!((t - 0.9 * r3).abs() < 1e-8, "{t}");
    }

    #[test]
    fn params_default_is_the_paper_constants_and_knobs_act() {
        let d = HitParams::default();
        assert_eq!(
            (d.bisect_iters, d.newton_iters, d.newton_tol),
            (30, 8, 1e-12)
        );
        // On a linear field: no Newton steps keep the linear guess, no
        // bisection steps give the midpoint.
        let f = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let c = CellEval {
            lo: [0.0; 3],
            size: [1.0; 3],
            f,
        };
        let (ray, v) = along_x();
        let p = HitParams {
            bisect_iters: 0,
            newton_iters: 0,
            ..d
        };
        assert_eq!(
            find_hit_with(&ray, &v, &c, 0.3, HitMethod::Bisect, &p),
            Some(1.5)
        );
        let tn = find_hit_with(&ray, &v, &c, 0.3, HitMethod::Newton, &p).unwrap();
        assert!((tn - 1.3).abs() < 1e-15);
        let te = find_hit(&ray, &v, &c, 0.3, HitMethod::Exact).unwrap();
        assert!((te - 1.3).abs() <= 2.0 * f64::EPSILON, "{te}");
    }
}
