//! The composite mode's transfer function as a lookup table.
//!
//! Evaluating the transfer function exactly at every sample costs a search
//! of its points, two interpolations and a `powf` (the opacity is per mm,
//! corrected for the sample distance: `1 - (1 - a)^step`). [`TfLut`] does
//! that once per table entry instead: entry `i` holds the exact colour
//! times the corrected opacity (premultiplied) and the corrected opacity at
//! `v_i = v_first + i h`, and a sample takes the linear interpolation of
//! the two entries around its value.
//!
//! Resolution: the entries span the points' values `[v_first, v_last]`
//! (the function is constant beyond them, and so is the table) with at
//! least [`TfLut::MIN_BINS`] bins, more (up to [`TfLut::MAX_BINS`]) when
//! two points are closer than 16 bins, and the smallest such count that
//! puts every point on an entry when there is one (e.g. 4104 bins of
//! 0.22 HU for the skin-bone function of `tools/peers/skin-bone-tf.json`,
//! whose points are multiples of 100 HU apart). Inside a bin without a
//! point the exact function is smooth (opacity linear, corrected opacity
//! `1 - (1 - a)^step` and premultiplied colour nearly quadratic), so the
//! interpolation error is `h^2 / 8` times its second derivative; in a bin
//! holding a point (a kink: only when the points do not all fit on
//! entries) every channel still lies between its exact values at the
//! bin's ends, i.e. it is the exact function at a value less than one bin
//! `h` away. For skin-bone at steps of 0.1 to 3 mm the largest error of
//! any channel is below 1e-8, and below 1e-4 with one point moved off the
//! entries (test `skin_bone_table_error`); the composite images of the
//! head CT are byte-identical to the exact evaluation's in both cases
//! (docs/BENCHMARKS.md, "Composite and MIP per-sample cost").

use glam::Vec4;

use crate::classify::TransferFunction;

/// Premultiplied colour and step-corrected opacity at uniformly spaced
/// values.
#[derive(Debug, Clone)]
pub struct TfLut {
    v0: f64,
    /// Bins per value unit (1 / h); 0 for a single-point function.
    inv_h: f64,
    /// Largest bin index (entries - 2), as f64 for the clamp.
    last_bin: f64,
    /// `[r a, g a, b a, a]` with `a` the corrected opacity.
    entries: Vec<[f64; 4]>,
    /// Per bin `i`, the entry at its start rounded to f32 and the f32
    /// difference to the next (`[e_i, e_(i+1) - e_i]`, as SIMD vectors),
    /// for the f32 sampler ([`TfLut::sample32`]): a sample's
    /// interpolation is one load of the pair, one multiplication and one
    /// addition, with the same bits as `a + f (b - a)` computed per sample.
    bins32: Vec<[Vec4; 2]>,
    /// `v0`, `inv_h` and `last_bin` in f32, for the same sampler.
    v0_32: f32,
    inv_h32: f32,
    last_bin32: f32,
}

impl TfLut {
    /// Bins of a table, at least.
    pub const MIN_BINS: usize = 4096;
    /// Bins of a table, at most (2 MiB of entries).
    pub const MAX_BINS: usize = 1 << 16;

    /// The table of `tf` for samples `step_mm` apart (opacity per mm).
    pub fn new(tf: &TransferFunction, step_mm: f64) -> TfLut {
        let p = &tf.points;
        let (v0, v1) = (p[0].value, p[p.len() - 1].value);
        let exact = |v: f64| {
            let (rgb, a) = exact_sample(tf, step_mm, v);
            [rgb[0] * a, rgb[1] * a, rgb[2] * a, a]
        };
        if p.len() < 2 || !(v1 > v0) || !(v1 - v0).is_finite() {
            // Constant: two equal entries, any value maps to them.
            let e = exact(v0);
            return TfLut::with_entries(v0, 0.0, 0.0, vec![e, e]);
        }
        let bins = table_bins(tf, Self::MIN_BINS, Self::MAX_BINS);
        let span = v1 - v0;
        let h = span / bins as f64;
        let mut entries: Vec<[f64; 4]> = (0..=bins)
            .map(|i| exact(if i == bins { v1 } else { v0 + i as f64 * h }))
            .collect();
        for q in p {
            if let Some(i) = at_entry(v0, span, q.value, bins) {
                entries[i] = exact(q.value);
            }
        }
        TfLut::with_entries(v0, 1.0 / h, (bins - 1) as f64, entries)
    }

    fn with_entries(v0: f64, inv_h: f64, last_bin: f64, entries: Vec<[f64; 4]>) -> TfLut {
        TfLut {
            v0,
            inv_h,
            last_bin,
            bins32: entries
                .windows(2)
                .map(|w| {
                    let [a, b] = [w[0], w[1]].map(|e| Vec4::from_array(e.map(|x| x as f32)));
                    [a, b - a]
                })
                .collect(),
            entries,
            v0_32: v0 as f32,
            inv_h32: inv_h as f32,
            last_bin32: last_bin as f32,
        }
    }

    /// [`TfLut::sample`] in f32, for the f32 sampler: `[r a, g a, b a,
    /// a]` at `v`. The bin position is computed in f32 from the f32 value
    /// with the f32-rounded `v0` and `1 / h`: a relative error of a few
    /// 1e-7 of `v - v0`, the same order as the f32 interpolation that
    /// produced `v`, so the table is read at a value off by at most a few
    /// 1e-7 of the transfer function's span (about 1e-3 HU for
    /// skin-bone's 4100 HU). docs/TRADEOFFS.md ("Composite sampler")
    /// measures the image difference against the f64 sampler.
    #[inline(always)]
    pub fn sample32(&self, v: f32) -> Vec4 {
        // NaN and values below the first entry take x = 0 (max(NaN) is
        // the other operand); NaN is then made transparent below.
        let x = ((v - self.v0_32) * self.inv_h32)
            .max(0.0)
            .min(self.last_bin32 + 1.0);
        // SAFETY: `x` is finite and in [0, last_bin + 1] (`max` takes 0 for
        // NaN, `min` bounds infinities), so its minimum with `last_bin`
        // (at most MAX_BINS - 1) truncates to an i32 in [0, last_bin].
        // `max` meets a NaN only as the result of this subtraction and
        // product of run-time operands, which x86-64 returns quiet; LLVM's
        // `maxnum` may return NaN only for a signalling one (LangRef), so
        // this holds where the processor, not constant folding, computes
        // `x`. A comparison in place of `max` is no firmer (LLVM turns it
        // into `maxnum`, llvm/llvm-project#170486) and `as i32` costs
        // 10-13 % more instructions per frame (docs/DECISIONS.md, "`as
        // i32` ... instead of `to_int_unchecked`"): the unchecked conversion is one
        // instruction, where `as` adds the saturation and NaN checks, and
        // an i32 converts back to f32 in one more.
        let i: i32 = unsafe { x.min(self.last_bin32).to_int_unchecked() };
        let f = x - i as f32;
        let [a, d] = self.bins32[i as usize];
        if v.is_nan() {
            return Vec4::ZERO;
        }
        a + f * d
    }

    /// Premultiplied colour and corrected opacity at `v`; NaN is
    /// transparent (background).
    #[inline(always)]
    pub fn sample(&self, v: f64) -> [f64; 4] {
        if v.is_nan() {
            return [0.0; 4];
        }
        // x in [0, bins]: clamped, so values beyond the ends (and
        // infinities) take the end entries; NaN from an infinite value
        // times the constant table's 0 takes the first.
        let x = (v - self.v0) * self.inv_h;
        let x = if x > 0.0 {
            x.min(self.last_bin + 1.0)
        } else {
            0.0
        };
        let i = bin(x, self.last_bin);
        let f = x - i as f64;
        let (a, b) = (&self.entries[i], &self.entries[i + 1]);
        std::array::from_fn(|k| a[k] + f * (b[k] - a[k]))
    }
}

/// The bin count of a table of `tf` over its points' values `[v_first,
/// v_last]` (which must differ and be finite): at least `min` bins, more
/// (up to `max`) when two points are closer than 16 bins, and the
/// smallest such count that puts every point on an entry when there is
/// one ([`TfLut`]; the segment integrator's table,
/// [`PreTable`](super::pretable::PreTable), too).
pub(crate) fn table_bins(tf: &TransferFunction, min: usize, max: usize) -> usize {
    let p = &tf.points;
    let (v0, v1) = (p[0].value, p[p.len() - 1].value);
    let min_gap = p
        .windows(2)
        .map(|w| w[1].value - w[0].value)
        .fold(f64::INFINITY, f64::min);
    let want = ((v1 - v0) / min_gap * 16.0).ceil();
    let least = if want.is_finite() {
        (want as usize).clamp(min, max)
    } else {
        max
    };
    // Where every point falls on an entry (commensurate points, as in
    // hand-written functions), the table is exact at the kinks and only
    // the smooth h^2 error remains; else the least count.
    let span = v1 - v0;
    if p.len() <= 64 {
        (least..=max)
            .find(|&b| p.iter().all(|q| at_entry(v0, span, q.value, b).is_some()))
            .unwrap_or(least)
    } else {
        least
    }
}

/// The entry of a table of `bins` bins over `[v0, v0 + span]` that value
/// `q` falls on, if it falls on one.
pub(crate) fn at_entry(v0: f64, span: f64, q: f64, bins: usize) -> Option<usize> {
    let x = (q - v0) / span * bins as f64;
    ((x - x.round()).abs() <= 1e-9 * bins as f64).then_some(x.round() as usize)
}

/// `min(floor(x), last_bin)` for `x` in `[0, last_bin + 1]` (`last_bin` a
/// whole number): through `i64`, which x86-64 converts in one
/// instruction, where a conversion to `usize` takes a branch and a
/// second conversion (about a tenth of a composite sample's time).
#[inline(always)]
fn bin(x: f64, last_bin: f64) -> usize {
    x.min(last_bin) as i64 as usize
}

/// Colour and step-corrected opacity of `tf` at `v`, evaluated exactly:
/// what [`TfLut`] tabulates.
pub fn exact_sample(tf: &TransferFunction, step_mm: f64, v: f64) -> ([f64; 3], f64) {
    let p = &tf.points;
    if v.is_nan() {
        // Interpolated from a NaN sample: background, transparent.
        return ([0.0; 3], 0.0);
    }
    let a = tf.opacity(v);
    let rgb = if v <= p[0].value {
        p[0].color
    } else if v >= p[p.len() - 1].value {
        p[p.len() - 1].color
    } else {
        let i = p.partition_point(|q| q.value <= v);
        let f = (v - p[i - 1].value) / (p[i].value - p[i - 1].value);
        std::array::from_fn(|k| p[i - 1].color[k] + f * (p[i].color[k] - p[i - 1].color[k]))
    };
    // Opacity is per mm; corrected for the step length.
    (rgb, 1.0 - (1.0 - a).powf(step_mm))
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

    /// Largest error of any channel over a dense sweep of `[lo, hi]`.
    fn max_error(t: &TransferFunction, step: f64, lo: f64, hi: f64) -> f64 {
        let lut = TfLut::new(t, step);
        let n = 200_000;
        (0..=n)
            .map(|i| {
                let v = lo + (hi - lo) * i as f64 / n as f64;
                let (rgb, a) = exact_sample(t, step, v);
                let want = [rgb[0] * a, rgb[1] * a, rgb[2] * a, a];
                let got = lut.sample(v);
                (0..4).map(|k| (got[k] - want[k]).abs()).fold(0.0, f64::max)
            })
            .fold(0.0, f64::max)
    }

    fn skin_bone() -> TransferFunction {
        tf(&[
            (-300.0, 0.0, [0.9, 0.6, 0.5]),
            (-100.0, 0.02, [0.9, 0.6, 0.5]),
            (100.0, 0.02, [0.9, 0.7, 0.6]),
            (300.0, 0.0, [1.0, 1.0, 0.9]),
            (600.0, 0.08, [1.0, 1.0, 0.95]),
        ])
    }

    #[test]
    fn skin_bone_table_error() {
        // tools/peers/skin-bone-tf.json, at the peers' step and others:
        // its points land on entries, so only the smooth error is left.
        assert_eq!(TfLut::new(&skin_bone(), 0.5).entries.len(), 4104 + 1);
        for step in [0.5, 0.1, 1.0, 3.0] {
            let e = max_error(&skin_bone(), step, -1100.0, 1500.0);
            assert!(e < 1e-8, "step {step}: max error {e}");
        }
        // A point off the entries: its kink is smeared over one bin,
        // still a small error.
        let mut t = skin_bone();
        t.points[2].value += 0.1 * 2f64.sqrt();
        for step in [0.5, 3.0] {
            let e = max_error(&t, step, -1100.0, 1500.0);
            assert!(e < 1e-4, "step {step}: max error {e}");
        }
    }

    #[test]
    fn ends_nan_and_constant_functions() {
        let t = skin_bone();
        let lut = TfLut::new(&t, 0.5);
        let end = |v: f64| {
            let (rgb, a) = exact_sample(&t, 0.5, v);
            [rgb[0] * a, rgb[1] * a, rgb[2] * a, a]
        };
        for v in [
            f64::NEG_INFINITY,
            -1e300,
            -300.0,
            600.0,
            1e300,
            f64::INFINITY,
        ] {
            let (got, want) = (lut.sample(v), end(v));
            for k in 0..4 {
                assert!((got[k] - want[k]).abs() < 1e-15, "{v}: {got:?} vs {want:?}");
            }
        }
        assert_eq!(lut.sample(f64::NAN), [0.0; 4]);
        // Exactly transparent where the function is.
        assert_eq!(lut.sample(-500.0)[3], 0.0);
        assert!(lut.sample(300.0)[3] < 1e-15);
        let one = tf(&[(5.0, 0.3, [0.2, 0.4, 0.6])]);
        let lut = TfLut::new(&one, 2.0);
        let a = 1.0 - 0.7f64.powf(2.0);
        for v in [f64::NEG_INFINITY, 0.0, 5.0, 7.0] {
            let got = lut.sample(v);
            assert!((got[3] - a).abs() < 1e-15 && (got[2] - 0.6 * a).abs() < 1e-15);
        }
    }

    /// `sample32(v)` is the f64 table read at a value within a few f32
    /// rounding errors of `v` (relative to the table's span), up to the
    /// entries' rounding to f32: every channel lies within the range the
    /// f64 table takes over `[v - d, v + d]`, which is piecewise linear
    /// and so bounded by its values at the ends and at the entries in
    /// between. At the extremes: NaN is transparent, infinities and
    /// values beyond the points take the end entries.
    #[test]
    fn sample32_reads_the_f64_table_near_the_value() {
        let steep = tf(&[
            (0.0, 0.0, [1.0; 3]),
            (500.0, 0.0, [1.0; 3]),
            (500.01, 1.0, [1.0, 0.0, 0.0]),
            (1000.0, 1.0, [0.0, 0.0, 1.0]),
        ]);
        let mut off = skin_bone();
        off.points[2].value += 0.1 * 2f64.sqrt();
        for (t, lo, hi) in [
            (skin_bone(), -1100.0, 1500.0),
            (off, -1100.0, 1500.0),
            (steep, -10.0, 1010.0),
        ] {
            let lut = TfLut::new(&t, 0.5);
            let (v0, v1) = (t.points[0].value, t.points[t.points.len() - 1].value);
            let d = 8.0 * f32::EPSILON as f64 * v0.abs().max(v1.abs()).max(v1 - v0);
            let n = 100_000;
            for i in 0..=n {
                let v = (lo + (hi - lo) * i as f64 / n as f64) as f32;
                let got = lut.sample32(v).to_array();
                let (a, b) = (v as f64 - d, v as f64 + d);
                let mut range = [lut.sample(a), lut.sample(b)];
                let bins = |v: f64| ((v - lut.v0) * lut.inv_h).clamp(0.0, lut.last_bin + 1.0);
                let mut near: Vec<[f64; 4]> = (bins(a).ceil() as usize..=bins(b).floor() as usize)
                    .map(|j| lut.entries[j])
                    .collect();
                near.extend_from_slice(&range[..]);
                range[0] = near.iter().fold([f64::INFINITY; 4], |m, e| {
                    std::array::from_fn(|k| m[k].min(e[k]))
                });
                range[1] = near.iter().fold([f64::NEG_INFINITY; 4], |m, e| {
                    std::array::from_fn(|k| m[k].max(e[k]))
                });
                for k in 0..4 {
                    let g = got[k] as f64;
                    assert!(
                        g >= range[0][k] - 1e-6 && g <= range[1][k] + 1e-6,
                        "{v}: channel {k} {g} outside {:?}",
                        (range[0][k], range[1][k])
                    );
                }
            }
            let e32 = |e: [f64; 4]| Vec4::from_array(e.map(|x| x as f32));
            let first = e32(lut.entries[0]);
            let last = e32(lut.entries[lut.entries.len() - 1]);
            for v in [f32::NEG_INFINITY, f32::MIN, (v0 - 1.0) as f32] {
                assert_eq!(lut.sample32(v), first, "{v}");
            }
            // The last bin at its far end: a + 1 (b - a), within an ulp of b.
            for v in [f32::INFINITY, f32::MAX, (v1 + 1.0) as f32] {
                let g = lut.sample32(v);
                assert!((g - last).abs().max_element() < 1e-6, "{v}: {g} vs {last}");
            }
            assert_eq!(lut.sample32(f32::NAN), Vec4::ZERO);
            // Signalling NaNs of either sign, as code words are (NaN
            // payloads), hidden from the optimiser as samples are.
            for bits in [0x7f80_0001, 0x7fbf_ffff, 0xff80_0001, 0x7fc0_0001] {
                let v = std::hint::black_box(f32::from_bits(bits));
                assert_eq!(lut.sample32(v), Vec4::ZERO, "{bits:#x}");
            }
        }
        // A single point: the same entry everywhere.
        let one = TfLut::new(&tf(&[(5.0, 0.3, [0.2, 0.4, 0.6])]), 2.0);
        for v in [f32::NEG_INFINITY, 0.0, 5.0, 7.0, f32::INFINITY] {
            let e = Vec4::from_array(one.entries[0].map(|x| x as f32));
            assert_eq!(one.sample32(v), e, "{v}");
        }
        assert_eq!(one.sample32(f32::NAN), Vec4::ZERO);
    }

    #[test]
    fn close_points_get_finer_bins_and_opaque_ends_stay_bounded() {
        // Points 0.01 apart over a range of 1000: h <= 0.01 / 16 up to the
        // cap of 2^16 bins, so the kink error stays a fraction of a bin.
        let t = tf(&[
            (0.0, 0.0, [1.0; 3]),
            (500.0, 0.0, [1.0; 3]),
            (500.01, 1.0, [1.0, 0.0, 0.0]),
            (1000.0, 1.0, [0.0, 0.0, 1.0]),
        ]);
        let lut = TfLut::new(&t, 0.5);
        assert_eq!(lut.entries.len(), TfLut::MAX_BINS + 1);
        // One bin is 1000 / 65536 = 0.015 units: the steep ramp (slope 100
        // per unit of opacity) is smeared over at most that, away from it
        // the table is exact to rounding.
        assert!(max_error(&t, 0.5, 0.0, 499.9) < 1e-12);
        assert!(max_error(&t, 0.5, 500.1, 1000.0) < 1e-9);
    }
}
