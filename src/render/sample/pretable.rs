//! The segment integrator's transfer function table: the extinction
//! `tau(v) = -ln(1 - a(v))` per mm of the opacity `a` per mm, and the
//! colour it emits, `[tau, tau r, tau g, tau b]`, integrated over the
//! value (the "integral table" of pre-integrated volume rendering:
//! Röttger, Kraus and Ertl 2000; Engel, Kraus and Ertl 2001).
//!
//! Along a chord whose value runs linearly from `a` to `b` over `len` mm,
//! `int tau dt = len (P(b) - P(a)) / (b - a)` with `P` the table's
//! integral: the optical depth of any chord from two lookups, whatever
//! its length, and the colour-weighted integral likewise. The table holds
//! `q = [tau, tau r, tau g, tau b]` at uniformly spaced values (the bins
//! of [`TfLut`](super::lut::TfLut), every point of the function on an
//! entry when the points allow) and the exact integral of its linear
//! interpolation, so `P` is a quadratic inside each bin and its slope is
//! the interpolated `q`: a chord too short in value for the difference
//! quotient takes `q` at its middle, and both agree as `b -> a`.

use crate::classify::TransferFunction;

/// Extinction per mm for an opacity per mm of 1 (and the cap of any):
/// a chord of 0.05 mm at this rate is opaque to 1e-21.
pub const TAU_MAX: f64 = 1000.0;

/// Extinction per mm of opacity `a` per mm: `-ln(1 - a)`, at most
/// [`TAU_MAX`].
#[inline]
pub fn extinction(a: f64) -> f64 {
    if a >= 1.0 {
        TAU_MAX
    } else {
        (-(-a).ln_1p()).clamp(0.0, TAU_MAX)
    }
}

/// `[tau, tau r, tau g, tau b]` of `tf` at `v`, exactly; zero at NaN
/// (background).
pub fn emission(tf: &TransferFunction, v: f64) -> [f64; 4] {
    if v.is_nan() {
        return [0.0; 4];
    }
    let tau = extinction(tf.opacity(v));
    let c = tf.colour(v);
    [tau, tau * c[0], tau * c[1], tau * c[2]]
}

/// See the module docs.
#[derive(Debug, Clone)]
pub struct PreTable {
    v0: f64,
    /// Bin width and its inverse; 0 and 0 for a one-point function.
    h: f64,
    inv_h: f64,
    /// `q` at `v0 + i h`.
    q: Vec<[f64; 4]>,
    /// The integral of the interpolated `q` from `v0` to `v0 + i h`.
    p: Vec<[f64; 4]>,
    /// The function is transparent at every value up to this one (`-inf`
    /// when its first point is not).
    pub clear_below: f64,
    /// The stretches of value the function's points bound, for
    /// [`PreTable::slope`] and [`PreTable::spread`].
    stretches: Stretches,
}

/// One stretch of [`PreTable::slope_memo`]: values `from <= v < to`,
/// and its slope. The default holds no value.
#[derive(Debug, Clone, Copy)]
pub struct SlopeMemo {
    from: f64,
    to: f64,
    slope: f64,
    colour_slope: f64,
}

impl Default for SlopeMemo {
    fn default() -> SlopeMemo {
        SlopeMemo {
            from: f64::INFINITY,
            to: f64::NEG_INFINITY,
            slope: 0.0,
            colour_slope: 0.0,
        }
    }
}

/// The function's points cut the values into stretches: before the
/// first point, between each two, after the last.
#[derive(Debug, Clone)]
struct Stretches {
    /// The function (its points' values ascending).
    tf: TransferFunction,
    /// Per stretch, the largest change of any channel of the table's `q`
    /// per value unit between two entries over it (the bins a point
    /// falls inside count to both its stretches); 0 where the table is
    /// constant there, as before the first point and after the last.
    slope: Vec<f64>,
    /// The largest of `slope`.
    slope_max: f64,
    /// Per stretch, the largest change of any colour channel per value
    /// unit (the colour is linear inside a stretch).
    colour_slope: Vec<f64>,
}

impl Stretches {
    /// The stretch of `v`: how many points lie at or below it.
    #[inline(always)]
    fn of(&self, v: f64) -> usize {
        self.tf.points.partition_point(|p| p.value <= v)
    }

    /// The values of stretch `k`, `from <= v < to`.
    fn bounds(&self, k: usize) -> (f64, f64) {
        let pts = &self.tf.points;
        let from = if k == 0 { f64::NEG_INFINITY } else { pts[k - 1].value };
        let to = pts.get(k).map_or(f64::INFINITY, |p| p.value);
        (from, to)
    }
}

impl PreTable {
    /// Bins of a table, at least and at most (as
    /// [`TfLut`](super::lut::TfLut)'s; 4 MiB of entries at most).
    pub const MIN_BINS: usize = 4096;
    pub const MAX_BINS: usize = 1 << 16;

    /// The table of `tf`.
    pub fn new(tf: &TransferFunction) -> PreTable {
        let pts = &tf.points;
        let clear_below = match pts.iter().position(|p| p.opacity > 0.0) {
            Some(0) => f64::NEG_INFINITY,
            Some(i) => pts[i - 1].value,
            None => f64::INFINITY,
        };
        let (v0, v1) = (pts[0].value, pts[pts.len() - 1].value);
        let mut stretches = Stretches {
            tf: tf.clone(),
            slope: vec![0.0; pts.len() + 1],
            slope_max: 0.0,
            colour_slope: vec![0.0; pts.len() + 1],
        };
        if pts.len() < 2 || !(v1 > v0) || !(v1 - v0).is_finite() {
            let q = emission(tf, v0);
            return PreTable {
                v0,
                h: 0.0,
                inv_h: 0.0,
                q: vec![q, q],
                p: vec![[0.0; 4], [0.0; 4]],
                clear_below,
                stretches,
            };
        }
        let bins = super::lut::table_bins(tf, Self::MIN_BINS, Self::MAX_BINS);
        let h = (v1 - v0) / bins as f64;
        let mut q: Vec<[f64; 4]> = (0..=bins)
            .map(|i| emission(tf, if i == bins { v1 } else { v0 + i as f64 * h }))
            .collect();
        for pt in pts {
            if let Some(i) = super::lut::at_entry(v0, v1 - v0, pt.value, bins) {
                q[i] = emission(tf, pt.value);
            }
        }
        let mut p = Vec::with_capacity(q.len());
        let mut sum = [0.0f64; 4];
        p.push(sum);
        for w in q.windows(2) {
            for k in 0..4 {
                sum[k] += 0.5 * h * (w[0][k] + w[1][k]);
            }
            p.push(sum);
        }
        // Each stretch between two points: the entries from the bin of
        // its first point to the bin end past its last.
        for k in 1..pts.len() {
            let entry = |v: f64| (v - v0) / h;
            let i0 = (entry(pts[k - 1].value).floor().max(0.0) as usize).min(bins);
            let i1 = (entry(pts[k].value).ceil().max(0.0) as usize).min(bins);
            stretches.slope[k] = q[i0..=i1]
                .windows(2)
                .flat_map(|w| (0..4).map(|c| (w[1][c] - w[0][c]).abs() / h))
                .fold(0.0, f64::max);
            let (a, b) = (&pts[k - 1], &pts[k]);
            stretches.colour_slope[k] = (0..3)
                .map(|c| (b.color[c] - a.color[c]).abs() / (b.value - a.value))
                .fold(0.0, f64::max);
        }
        stretches.slope_max = stretches.slope.iter().copied().fold(0.0, f64::max);
        PreTable {
            v0,
            h,
            inv_h: 1.0 / h,
            q,
            p,
            clear_below,
            stretches,
        }
    }

    /// The largest change of any channel of `q` per value unit over
    /// `[lo, hi]` (the stretches it meets, [`Stretches::slope`]): 0 where
    /// `q` is constant over it, so any chord there is exact; infinite at
    /// NaN.
    #[inline]
    pub fn slope(&self, lo: f64, hi: f64) -> f64 {
        self.slope_of(lo, hi).0
    }

    /// [`PreTable::slope`], and the stretch `[lo, hi]` lies in when it
    /// lies in one.
    #[inline(always)]
    fn slope_of(&self, lo: f64, hi: f64) -> (f64, Option<usize>) {
        if !(lo <= hi) {
            return (f64::INFINITY, None);
        }
        let st = &self.stretches;
        let (a, b) = (st.of(lo), st.of(hi));
        let slope = st.slope[a..=b].iter().copied().fold(0.0, f64::max);
        (slope, (a == b).then_some(a))
    }

    /// [`PreTable::slope`] through `memo`, the last stretch a ray's cell
    /// lay in: a ray's next cell mostly lies in it too.
    #[inline(always)]
    pub fn slope_memo(&self, lo: f64, hi: f64, memo: &mut SlopeMemo) -> f64 {
        if lo >= memo.from && hi < memo.to {
            return memo.slope;
        }
        let (slope, one) = self.slope_of(lo, hi);
        if let Some(k) = one {
            let (from, to) = self.stretches.bounds(k);
            *memo = SlopeMemo {
                from,
                to,
                slope,
                colour_slope: self.stretches.colour_slope[k],
            };
        }
        slope
    }

    /// The largest [`PreTable::slope`] anywhere.
    pub fn slope_max(&self) -> f64 {
        self.stretches.slope_max
    }

    /// [`PreTable::spread`] through `memo` ([`PreTable::slope_memo`]):
    /// inside one stretch the colour is linear, so its spread is its slope
    /// times the range widened a bin each way, when that lies inside the
    /// stretch (a bin holding a point mixes in the next stretch's colour).
    #[inline(always)]
    pub fn spread_memo(&self, lo: f64, hi: f64, memo: &SlopeMemo) -> f64 {
        if lo - self.h >= memo.from && hi + self.h < memo.to {
            return (memo.colour_slope * (hi - lo + 2.0 * self.h)).min(1.0);
        }
        self.spread(lo, hi)
    }

    /// How far apart the function's colours lie over `[lo, hi]`, widened
    /// by a bin each way (the entries a chord's lookups read): the
    /// largest spread of any channel, 0..=1; 1 at NaN. A chord whose
    /// colour is constant composites exactly, however deep.
    pub fn spread(&self, lo: f64, hi: f64) -> f64 {
        if !(lo <= hi) {
            return 1.0;
        }
        let st = &self.stretches;
        let (lo, hi) = (lo - self.h, hi + self.h);
        let (mut min, mut max) = (st.tf.colour(lo), st.tf.colour(lo));
        let mut take = |c: [f64; 3]| {
            for k in 0..3 {
                min[k] = min[k].min(c[k]);
                max[k] = max[k].max(c[k]);
            }
        };
        take(st.tf.colour(hi));
        for p in &st.tf.points[st.of(lo)..st.of(hi)] {
            take(p.color);
        }
        (0..3).map(|k| max[k] - min[k]).fold(0.0, f64::max)
    }

    /// The bin of `v` and its fraction, `v` clamped to the table.
    #[inline(always)]
    fn bin(&self, v: f64) -> (usize, f64) {
        let last = (self.q.len() - 2) as f64;
        let x = ((v - self.v0) * self.inv_h).clamp(0.0, last + 1.0);
        let i = x.min(last) as usize;
        (i, x - i as f64)
    }

    /// `q` at `v`, interpolated; zero at NaN.
    #[inline]
    pub fn rate(&self, v: f64) -> [f64; 4] {
        if v.is_nan() {
            return [0.0; 4];
        }
        let (i, f) = self.bin(v);
        let (a, b) = (&self.q[i], &self.q[i + 1]);
        std::array::from_fn(|k| a[k] + f * (b[k] - a[k]))
    }

    /// `P(v)`: the integral of the interpolated `q` from the first
    /// point's value to `v` (continued linearly beyond the ends, where
    /// the function is constant); NaN at NaN.
    #[inline]
    pub fn integral(&self, v: f64) -> [f64; 4] {
        if v.is_nan() {
            return [f64::NAN; 4];
        }
        let last = self.q.len() - 1;
        let end = self.v0 + last as f64 * self.h;
        if self.h == 0.0 || v <= self.v0 {
            let q = &self.q[0];
            return std::array::from_fn(|k| q[k] * (v - self.v0));
        }
        if v >= end {
            let (q, p) = (&self.q[last], &self.p[last]);
            return std::array::from_fn(|k| p[k] + q[k] * (v - end));
        }
        let (i, x) = self.bin(v);
        let (a, b, p) = (&self.q[i], &self.q[i + 1], &self.p[i]);
        std::array::from_fn(|k| p[k] + self.h * x * (a[k] + 0.5 * x * (b[k] - a[k])))
    }

    /// The value where the extinction integral `P[0]` reaches `target`
    /// first going up (`up`) or last going down: `P[0]` never decreases
    /// (the extinction is not negative), so this inverts it: a binary
    /// search of the entries, then the bin's quadratic. `None` where it
    /// never reaches `target` (transparent beyond).
    pub fn value_at(&self, target: f64, up: bool) -> Option<f64> {
        let last = self.q.len() - 1;
        let end = self.v0 + last as f64 * self.h;
        let (q0, ql, pl) = (self.q[0][0], self.q[last][0], self.p[last][0]);
        if target < 0.0 || self.h == 0.0 {
            // Below the first point (or a one-point function): linear.
            return (q0 > 0.0).then(|| self.v0 + target / q0);
        }
        if target > pl {
            return (ql > 0.0).then(|| end + (target - pl) / ql);
        }
        // The bin `i` whose span holds the crossing.
        let i = if up {
            self.p.partition_point(|p| p[0] < target).max(1) - 1
        } else {
            self.p.partition_point(|p| p[0] <= target).clamp(1, last) - 1
        };
        let (a, b) = (self.q[i][0], self.q[i + 1][0]);
        // P = P_i + h (a x + (b - a) x^2 / 2) = target, x in [0, 1],
        // by the form without cancellation.
        let (qa, qb, qc) = (0.5 * self.h * (b - a), self.h * a, self.p[i][0] - target);
        let disc = (qb * qb - 4.0 * qa * qc).max(0.0);
        let den = qb + disc.sqrt();
        let x = if den > 0.0 { (-2.0 * qc / den).clamp(0.0, 1.0) } else { 0.0 };
        Some(self.v0 + (i as f64 + x) * self.h)
    }

    /// `[int tau, int tau r, int tau g, int tau b]` over a chord of `len`
    /// mm whose value runs linearly from `a` to `b`, given `pa =
    /// P(a)` and `pb = P(b)`: zero where either value is NaN.
    #[inline]
    pub fn chord(&self, a: f64, pa: &[f64; 4], b: f64, pb: &[f64; 4], len: f64) -> [f64; 4] {
        let dv = b - a;
        // Below a ten-thousandth of a bin, the difference quotient loses
        // more to cancellation than the middle's rate is off.
        let out = if dv.abs() > 1e-4 * self.h {
            let k = len / dv;
            std::array::from_fn(|c| (pb[c] - pa[c]) * k)
        } else {
            self.rate(0.5 * (a + b)).map(|x| x * len)
        };
        if out[0] >= 0.0 && out[0].is_finite() {
            // Rounding may leave a channel a hair below 0.
            out.map(|x| x.max(0.0))
        } else {
            [0.0; 4]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::TfPoint;

    fn tf(points: &[(f64, f64, [f64; 3])]) -> TransferFunction {
        TransferFunction {
            points: points
                .iter()
                .map(|&(value, opacity, color)| TfPoint {
                    value,
                    opacity,
                    color,
                })
                .collect(),
        }
    }

    /// `int_a^b q(v) dv` by the composite Simpson rule on the exact
    /// function, 20,000 panels.
    fn simpson(t: &TransferFunction, a: f64, b: f64) -> [f64; 4] {
        let n = 20_000;
        let h = (b - a) / n as f64;
        let mut s = [0.0; 4];
        for i in 0..=n {
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let q = emission(t, a + i as f64 * h);
            for k in 0..4 {
                s[k] += w * q[k];
            }
        }
        s.map(|x| x * h / 3.0)
    }

    /// The chord integrals equal a dense quadrature of the exact function
    /// over value ranges inside, across and beyond the points, forwards
    /// and backwards, to 1e-3 relative: the table interpolates the
    /// extinction `-ln(1 - a)` linearly between entries, and these points
    /// do not all fall on entries, so a kink lies inside a bin (2.0e-4
    /// off across the steep 40-41.5 drop, 1.0e-5 elsewhere).
    #[test]
    fn chords_match_quadrature() {
        let t = tf(&[
            (-1000.0, 0.0, [0.0, 0.0, 0.0]),
            (-37.0, 0.0, [0.9, 0.5, 0.4]),
            (40.0, 0.6, [1.0, 0.8, 0.7]),
            (41.5, 0.05, [1.0, 1.0, 1.0]),
            (300.0, 0.999, [0.9, 0.9, 0.8]),
        ]);
        let table = PreTable::new(&t);
        for &(a, b) in &[
            (-50.0, 60.0),
            (60.0, -50.0),
            (39.0, 42.0),
            (250.0, 900.0),
            (-2000.0, -1500.0),
            (-1200.0, 400.0),
        ] {
            let len = 0.37;
            let got = table.chord(a, &table.integral(a), b, &table.integral(b), len);
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            let want = simpson(&t, lo, hi).map(|x| x * len / (hi - lo));
            for k in 0..4 {
                let err = (got[k] - want[k]).abs();
                assert!(
                    err <= 1e-3 * want[k].abs().max(1e-3),
                    "{a}..{b} channel {k}: {} against {}",
                    got[k],
                    want[k]
                );
            }
        }
    }

    /// A chord of constant value integrates the rate (to the table's
    /// interpolation, 1e-5), and values a hair apart agree with it; NaN
    /// is transparent.
    #[test]
    fn short_and_nan_chords() {
        let t = tf(&[(0.0, 0.0, [1.0; 3]), (100.0, 0.5, [0.2, 0.4, 0.6])]);
        let table = PreTable::new(&t);
        let v = 61.3;
        let e = table.chord(v, &table.integral(v), v, &table.integral(v), 2.0);
        let q = emission(&t, v);
        for k in 0..4 {
            assert!((e[k] - 2.0 * q[k]).abs() < 1e-5 * q[k], "{} {}", e[k], 2.0 * q[k]);
        }
        let w = v + 1e-3;
        let e2 = table.chord(v, &table.integral(v), w, &table.integral(w), 2.0);
        assert!((e2[0] - e[0]).abs() < 1e-4 * e[0]);
        let n = f64::NAN;
        assert_eq!(table.chord(n, &table.integral(n), v, &table.integral(v), 1.0), [0.0; 4]);
    }

    /// `value_at` inverts the integral: going up and down, inside the
    /// points, beyond them and across a transparent stretch.
    #[test]
    fn value_at_inverts_the_integral() {
        let t = tf(&[
            (-100.0, 0.2, [1.0; 3]),
            (0.0, 0.0, [1.0; 3]),
            (50.0, 0.0, [1.0; 3]),
            (60.0, 0.999, [1.0; 3]),
            (300.0, 0.4, [1.0; 3]),
        ]);
        let table = PreTable::new(&t);
        for v in [-250.0, -100.0, -37.5, 51.0, 55.5, 59.99, 120.0, 299.0, 800.0] {
            let p = table.integral(v)[0];
            for up in [true, false] {
                let got = table.value_at(p, up).unwrap();
                assert!(
                    (table.integral(got)[0] - p).abs() <= 1e-9 * p.abs().max(1.0),
                    "{v} {up}: {got}"
                );
            }
        }
        // Across the clear stretch 0..50: a hair above its integral lands
        // just past its top going up, a hair below just before its
        // bottom going down.
        let p = table.integral(25.0)[0];
        let up = table.value_at(p + 1e-9, true).unwrap();
        assert!((50.0..50.01).contains(&up), "{up}");
        let down = table.value_at(p - 1e-9, false).unwrap();
        assert!((-0.01..0.0).contains(&down), "{down}");
    }

    proptest::proptest! {
        /// Over random functions (flat stretches, steps, steep drops) and
        /// random value ranges: `slope` bounds the table's change of every
        /// channel between any two values of the range (the rate at 200
        /// points of it), is 0 only where the rate is constant there, and
        /// `spread` bounds the rate's colour spread over it; the memos
        /// give the same slope and a spread no smaller, whatever stretch
        /// they last held.
        #[test]
        fn slope_and_spread_bound_the_table(
            pts in proptest::collection::vec(
                (-500.0f64..500.0, 0.0f64..1.0, 0.0f64..1.0, proptest::bool::ANY), 2..7),
            a in -700.0f64..700.0,
            w in 0.0f64..300.0,
            prior in -700.0f64..700.0,
        ) {
            let mut pts = pts;
            pts.sort_by(|x, y| x.0.total_cmp(&y.0));
            // Some stretches flat: a point repeats the one before it.
            for i in 1..pts.len() {
                if pts[i].3 {
                    (pts[i].1, pts[i].2) = (pts[i - 1].1, pts[i - 1].2);
                }
            }
            let t = tf(&pts.iter().map(|&(v, o, c, _)| (v, o, [c, 1.0 - c, 0.5])).collect::<Vec<_>>());
            let table = PreTable::new(&t);
            let (lo, hi) = (a, a + w);
            let slope = table.slope(lo, hi);
            let rates: Vec<(f64, [f64; 4])> = (0..=200)
                .map(|j| lo + w * j as f64 / 200.0)
                .map(|v| (v, table.rate(v)))
                .collect();
            let (mut cmin, mut cmax) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for (i, (v, q)) in rates.iter().enumerate() {
                for (u, r) in &rates[..i] {
                    for k in 0..4 {
                        let d = (q[k] - r[k]).abs();
                        proptest::prop_assert!(
                            d <= slope * (v - u) * (1.0 + 1e-9) + 1e-12,
                            "{u}..{v} channel {k}: {d} > slope {slope}"
                        );
                    }
                }
                if q[0] > 1e-9 {
                    for k in 0..3 {
                        cmin[k] = cmin[k].min(q[k + 1] / q[0]);
                        cmax[k] = cmax[k].max(q[k + 1] / q[0]);
                    }
                }
            }
            let spread = table.spread(lo, hi);
            let true_spread = (0..3).map(|k| cmax[k] - cmin[k]).fold(0.0, f64::max);
            proptest::prop_assert!(true_spread <= spread + 1e-9, "{true_spread} > {spread}");
            let mut memo = SlopeMemo::default();
            table.slope_memo(prior, prior, &mut memo);
            proptest::prop_assert_eq!(table.slope_memo(lo, hi, &mut memo), slope);
            let sm = table.spread_memo(lo, hi, &memo);
            proptest::prop_assert!(true_spread <= sm + 1e-9, "memo {sm} < {true_spread}");
        }
    }

    /// An opacity of 1 per mm is the capped extinction, not infinite.
    #[test]
    fn opaque_is_capped() {
        assert_eq!(extinction(1.0), TAU_MAX);
        assert!((extinction(0.5) - std::f64::consts::LN_2).abs() < 1e-15);
        assert_eq!(extinction(0.0), 0.0);
    }
}
