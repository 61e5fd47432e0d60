//! The value histogram of a volume (header field `summary.histogram`,
//! docs/FORMAT.md): counts of the rescaled sample values (HU for CT) in
//! equal bins, the NaN and infinite counts, and percentiles.
//!
//! Prep's first pass feeds every sample slice to a [`HistogramBuilder`]
//! before it knows the range of the whole volume, so the builder keeps
//! [`MAX_BINS`] bins of a width that doubles (merging pairs of bins)
//! whenever a slice reaches past them. Bin edges stay aligned through the
//! doubling, so every count is exact for its bin.
//!
//! For integer samples the bins are whole numbers of stored values (edges
//! half-way between integers, widths powers of two): data that spans at
//! most [`MAX_BINS`] integers (12-bit CT) gets one bin per value, and its
//! percentiles are exact. Otherwise a percentile is interpolated inside
//! its bin, so it is within one bin width of the exact one.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::input::{Dtype, Rescale};

/// Most bins a histogram keeps (enough for one bin per value of 12-bit CT).
pub const MAX_BINS: usize = 4096;

/// The percentiles recorded, in per mille (0.1 % .. 99.9 %).
pub const PERCENTILES_PER_MILLE: [u32; 9] = [1, 10, 50, 250, 500, 750, 950, 990, 999];

/// Samples per bin of a volume's rescaled values, with their percentiles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValueHistogram {
    /// Lower edge of bin 0, in rescaled units.
    pub lo: f64,
    /// Width of every bin, in rescaled units: bin `i` holds the values in
    /// `[lo + i * bin_width, lo + (i + 1) * bin_width)`.
    pub bin_width: f64,
    /// Samples per bin (finite values only). Empty when every sample is
    /// NaN or infinite.
    pub counts: Vec<u64>,
    /// Finite samples (the sum of `counts`).
    pub samples: u64,
    /// NaN samples (not in `counts`).
    pub nan: u64,
    /// Infinite samples (not in `counts`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub infinite: u64,
    /// Smallest and largest finite rescaled value.
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Each bin holds exactly one stored integer value, so the percentiles
    /// are exact sample values.
    pub exact: bool,
    /// `[p, value]`: the smallest value with at least `p` % of the finite
    /// samples at or below it (nearest rank), for `p` in 0.1, 1, 5, 25,
    /// 50, 75, 95, 99, 99.9. Exact when `exact`, else interpolated in the
    /// bin (within one bin width).
    pub percentiles: Vec<[f64; 2]>,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// A histogram field that breaks an invariant (reported by the reader as
/// a header error).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("field `summary.histogram.{field}`: {found}, expected {expected}")]
pub struct HistogramInvalid {
    pub field: &'static str,
    pub found: String,
    pub expected: &'static str,
}

impl ValueHistogram {
    /// Checks what readers rely on: finite edges, a positive width, at
    /// most [`MAX_BINS`] bins, `samples` the sum of the counts, finite
    /// percentiles.
    pub fn check(&self) -> Result<(), HistogramInvalid> {
        let bad = |field, found: String, expected| {
            Err(HistogramInvalid {
                field,
                found,
                expected,
            })
        };
        if !self.lo.is_finite() {
            return bad("lo", self.lo.to_string(), "a finite number");
        }
        if !(self.bin_width > 0.0 && self.bin_width.is_finite()) {
            return bad(
                "bin_width",
                self.bin_width.to_string(),
                "a finite number > 0",
            );
        }
        if !self.hi().is_finite() {
            return bad(
                "bin_width",
                self.bin_width.to_string(),
                "a width whose last bin edge is finite",
            );
        }
        if self.counts.len() > MAX_BINS {
            return bad(
                "counts",
                format!("{} bins", self.counts.len()),
                "at most 4096 bins",
            );
        }
        let sum = self.counts.iter().try_fold(0u64, |s, &c| s.checked_add(c));
        if sum != Some(self.samples) {
            return bad("samples", self.samples.to_string(), "the sum of `counts`");
        }
        for p in &self.percentiles {
            if !(p[0].is_finite() && p[1].is_finite()) {
                return bad("percentiles", format!("{p:?}"), "finite [p, value] pairs");
            }
        }
        Ok(())
    }

    /// Upper edge of the last bin.
    pub fn hi(&self) -> f64 {
        self.lo + self.counts.len() as f64 * self.bin_width
    }

    /// The value of percentile `p` (in %), if recorded.
    pub fn percentile(&self, p: f64) -> Option<f64> {
        self.percentiles
            .iter()
            .find(|q| (q[0] - p).abs() < 1e-9)
            .map(|q| q[1])
    }

    /// At most `n` coarser bins (consecutive bins summed, all but the last
    /// of the same width): `(lower edge, upper edge, count)`.
    pub fn coarse(&self, n: usize) -> Vec<(f64, f64, u64)> {
        if self.counts.is_empty() || n == 0 {
            return Vec::new();
        }
        let k = self.counts.len().div_ceil(n);
        self.counts
            .chunks(k)
            .enumerate()
            .map(|(j, c)| {
                let a = self.lo + (j * k) as f64 * self.bin_width;
                let b = self.lo + (j * k + c.len()) as f64 * self.bin_width;
                (a, b, c.iter().fold(0u64, |s, &x| s.saturating_add(x)))
            })
            .collect()
    }
}

/// Builds a [`ValueHistogram`] from sample slices in stored units (before
/// the rescale), as prep's first pass reads them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistogramBuilder {
    /// Integer samples: bins are whole numbers of integers.
    integer: bool,
    /// Lower edge of bin 0 and bin width, stored units (width a power of
    /// two; at least 1 for integers, whose edges lie half-way between them).
    #[serde(with = "crate::json::f64_bits")]
    lo: f64,
    #[serde(with = "crate::json::f64_bits")]
    width: f64,
    /// [`MAX_BINS`] counts once the first finite sample is seen.
    counts: Vec<u64>,
    nan: u64,
    infinite: u64,
    /// Smallest and largest finite stored value so far.
    #[serde(with = "crate::json::f64_bits")]
    min: f64,
    #[serde(with = "crate::json::f64_bits")]
    max: f64,
}

impl HistogramBuilder {
    pub fn new(dtype: Dtype) -> HistogramBuilder {
        HistogramBuilder {
            integer: !dtype.is_float(),
            lo: 0.0,
            width: 1.0,
            counts: Vec::new(),
            nan: 0,
            infinite: 0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
        }
    }

    /// Counts one slice of stored values. `range` is the slice's (min,
    /// max) with NaN left out, if the caller has it (prep's extrema pass
    /// does); infinite ends are handled. Samples of an integer type are
    /// finite (the sources convert integers exactly), so only float
    /// samples are checked for NaN and infinity.
    pub fn add_slice(&mut self, values: &[f64], range: Option<(f64, f64)>) {
        let (mut a, mut b) = range.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
        if !(a.is_finite() && b.is_finite()) {
            // Infinite (or unknown) ends: the finite range needs a scan.
            (a, b) = values
                .par_chunks(1 << 16)
                .map(|c| {
                    c.iter()
                        .filter(|v| v.is_finite())
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                            (lo.min(v), hi.max(v))
                        })
                })
                .reduce(
                    || (f64::INFINITY, f64::NEG_INFINITY),
                    |x, y| (x.0.min(y.0), x.1.max(y.1)),
                );
        }
        if a <= b {
            self.cover(a, b);
        }
        let (lo, n, integer) = (self.lo, self.counts.len(), self.integer);
        if n == 0 {
            // No finite value yet (and none in this slice): NaN and inf only.
            self.nan += values.iter().filter(|v| v.is_nan()).count() as u64;
            self.infinite += values.iter().filter(|v| v.is_infinite()).count() as u64;
            return;
        }
        // The width is a power of two, so multiplying by its inverse is
        // the same as dividing; the saturating cast is the floor of the
        // non-negative quotient (a value below `lo` by rounding goes to
        // bin 0, one above the last bin to the last).
        let inv = 1.0 / self.width;
        let last = n - 1;
        let bin = move |v: f64| (((v - lo) * inv) as usize).min(last);
        let (counts, nan, inf) = values
            .par_chunks(1 << 16)
            .map(|c| {
                // Four interleaved tables, so a run of one value (air)
                // does not wait on its previous increment; u32 holds a
                // chunk's counts.
                let mut h = vec![0u32; 4 * n];
                let (mut nan, mut inf) = (0u64, 0u64);
                if integer {
                    // Integer samples are always finite.
                    let mut quads = c.chunks_exact(4);
                    for q in &mut quads {
                        for (k, &v) in q.iter().enumerate() {
                            h[k * n + bin(v)] += 1;
                        }
                    }
                    for &v in quads.remainder() {
                        h[bin(v)] += 1;
                    }
                } else {
                    let mut k = 0;
                    for &v in c {
                        if v.is_finite() {
                            h[k * n + bin(v)] += 1;
                            k = (k + 1) & 3;
                        } else if v.is_nan() {
                            nan += 1;
                        } else {
                            inf += 1;
                        }
                    }
                }
                let mut out = vec![0u64; n];
                for t in h.chunks_exact(n) {
                    out.iter_mut().zip(t).for_each(|(o, &x)| *o += x as u64);
                }
                (out, nan, inf)
            })
            .reduce(
                || (vec![0u64; n], 0, 0),
                |mut x, y| {
                    x.0.iter_mut().zip(&y.0).for_each(|(s, &c)| *s += c);
                    (x.0, x.1 + y.1, x.2 + y.2)
                },
            );
        self.counts
            .iter_mut()
            .zip(&counts)
            .for_each(|(s, &c)| *s += c);
        self.nan += nan;
        self.infinite += inf;
    }

    /// Widens the bins until they hold `[a, b]` and every value seen.
    ///
    /// The grid is a function of the range seen alone, not of the order
    /// the values came in: the width is the smallest power of two (at
    /// least 1 for integers, at least `2^-40` of the largest magnitude for
    /// floats, so a constant slice gets a width) whose grid of
    /// [`MAX_BINS`] bins, edges at whole multiples of the width (minus
    /// one half for integers), holds the range. Grids of such widths nest,
    /// so re-binning is exact, and two builders of disjoint slices merge
    /// ([`HistogramBuilder::merge`]) into exactly the builder of all of
    /// them: a sharded prep writes the histogram one prep writes.
    fn cover(&mut self, a: f64, b: f64) {
        let n = MAX_BINS as f64;
        let (lo_all, hi_all) = (self.min.min(a), self.max.max(b));
        self.min = lo_all;
        self.max = hi_all;
        let fits = |lo: f64, w: f64| lo <= lo_all && hi_all < lo + n * w;
        if !self.counts.is_empty() && fits(self.lo, self.width) {
            return;
        }
        let off = if self.integer { 0.5 } else { 0.0 };
        let edge = |w: f64| ((lo_all + off) / w).floor() * w - off;
        let base = if self.integer {
            1.0
        } else {
            let mag = lo_all.abs().max(hi_all.abs());
            let mag = if mag == 0.0 { 1.0 } else { mag };
            pow2_at_least(((hi_all - lo_all) / n).max(mag * 2f64.powi(-40)))
        };
        // The width of a smaller range is never larger (its grid's first
        // edge is no lower): start from the current one.
        let mut w = if self.counts.is_empty() {
            base
        } else {
            base.max(self.width)
        };
        while w.is_finite() && !fits(edge(w), w) {
            w *= 2.0;
        }
        let mut lo = edge(w);
        if !(lo.is_finite() && w.is_finite()) {
            // Values near the ends of f64 on both sides: no aligned grid
            // is finite; bins from the smallest value (order-dependent
            // only there).
            lo = lo_all;
            w = pow2_at_least(hi_all / n - lo_all / n);
        }
        let old = std::mem::replace(&mut self.counts, vec![0; MAX_BINS]);
        let (old_lo, old_w) = (self.lo, self.width);
        self.lo = lo;
        self.width = w;
        for (i, &c) in old.iter().enumerate().filter(|(_, &c)| c > 0) {
            self.add_bin(old_lo + i as f64 * old_w, c);
        }
    }

    /// Adds `c` samples at the bin whose lower edge is `e` (of a grid that
    /// nests in this one).
    fn add_bin(&mut self, e: f64, c: u64) {
        let j = ((e - self.lo) / self.width).floor();
        self.counts[(j.max(0.0) as usize).min(MAX_BINS - 1)] += c;
    }

    /// Adds the counts of `other`, a builder of other samples of the same
    /// type: the result is the builder of both sets of samples, whatever
    /// the order (the grid depends on the range alone).
    pub fn merge(&mut self, other: &HistogramBuilder) {
        self.nan += other.nan;
        self.infinite += other.infinite;
        if other.counts.is_empty() {
            return;
        }
        self.cover(other.min, other.max);
        for (i, &c) in other.counts.iter().enumerate().filter(|(_, &c)| c > 0) {
            self.add_bin(other.lo + i as f64 * other.width, c);
        }
    }

    /// The histogram in rescaled units, bins trimmed to the data; `None`
    /// when a rescaled figure would not be finite.
    pub fn finish(&self, rescale: Rescale) -> Option<ValueHistogram> {
        let first = self.counts.iter().position(|&c| c > 0);
        let last = self.counts.iter().rposition(|&c| c > 0);
        let samples: u64 = self.counts.iter().sum();
        let (Some(first), Some(last)) = (first, last) else {
            return Some(ValueHistogram {
                lo: 0.0,
                bin_width: 1.0,
                counts: Vec::new(),
                samples: 0,
                nan: self.nan,
                infinite: self.infinite,
                min: None,
                max: None,
                exact: false,
                percentiles: Vec::new(),
            });
        };
        let s = rescale.slope;
        let mut counts = self.counts[first..=last].to_vec();
        let lo_stored = self.lo + first as f64 * self.width;
        let hi_stored = self.lo + (last + 1) as f64 * self.width;
        let exact = self.integer && self.width == 1.0;
        // The stored value of bin i (ascending in rescaled units) when
        // exact: the integer at its centre.
        let first_int = lo_stored + 0.5;
        let last_int = hi_stored - 0.5;
        let (lo, bin_width) = if s > 0.0 {
            (rescale.apply(lo_stored), self.width * s)
        } else if s < 0.0 {
            counts.reverse();
            (rescale.apply(hi_stored), self.width * -s)
        } else {
            // Slope 0: every value is the intercept.
            counts = vec![samples];
            (rescale.intercept - 0.5, 1.0)
        };
        let (mut min, mut max) = (rescale.apply(self.min), rescale.apply(self.max));
        if min > max {
            std::mem::swap(&mut min, &mut max);
        }
        let exact_value = |i: usize| {
            if s >= 0.0 {
                rescale.apply(first_int + i as f64)
            } else {
                rescale.apply(last_int - i as f64)
            }
        };
        let percentiles = PERCENTILES_PER_MILLE
            .iter()
            .map(|&pm| {
                let rank = (pm as u128 * samples as u128).div_ceil(1000).max(1) as u64;
                let mut before = 0u64;
                let mut i = 0;
                while i + 1 < counts.len() && before + counts[i] < rank {
                    before += counts[i];
                    i += 1;
                }
                let v = if exact || s == 0.0 {
                    exact_value(i)
                } else {
                    let f = (rank - before) as f64 / counts[i].max(1) as f64;
                    (lo + (i as f64 + f) * bin_width).clamp(min, max)
                };
                [pm as f64 / 10.0, v]
            })
            .collect();
        let h = ValueHistogram {
            lo,
            bin_width,
            counts,
            samples,
            nan: self.nan,
            infinite: self.infinite,
            min: Some(min),
            max: Some(max),
            exact,
            percentiles,
        };
        h.check().is_ok().then_some(h)
    }
}

/// The smallest power of two >= `x` (`x` > 0 and finite).
fn pow2_at_least(x: f64) -> f64 {
    let mut w = 2f64.powi(x.log2().ceil().clamp(-1000.0, 1000.0) as i32);
    while w < x {
        w *= 2.0;
    }
    while w / 2.0 >= x && w > f64::MIN_POSITIVE {
        w /= 2.0;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Nearest-rank percentile of `v` (finite values), per mille.
    fn nearest_rank(sorted: &[f64], pm: u32) -> f64 {
        let rank = (pm as usize * sorted.len()).div_ceil(1000).max(1);
        sorted[rank - 1]
    }

    fn build(dtype: Dtype, slices: &[Vec<f64>], rescale: Rescale) -> ValueHistogram {
        let mut b = HistogramBuilder::new(dtype);
        for s in slices {
            b.add_slice(s, None);
        }
        b.finish(rescale).expect("finite")
    }

    #[test]
    fn integers_get_one_bin_per_value_and_exact_percentiles() {
        // A first slice of air, then a wider range: the builder grows.
        let slices = vec![
            vec![-1024.0; 50],
            (0..3000).map(|i| (i % 3072) as f64 - 1024.0).collect(),
            vec![2000.0, 3071.0],
        ];
        let h = build(Dtype::I16, &slices, Rescale::IDENTITY);
        assert!(h.exact);
        assert_eq!(h.bin_width, 1.0);
        assert_eq!(h.lo, -1024.5);
        assert_eq!(h.nan, 0);
        let mut all: Vec<f64> = slices.concat();
        all.sort_by(f64::total_cmp);
        assert_eq!(h.samples, all.len() as u64);
        for (i, &c) in h.counts.iter().enumerate() {
            let v = -1024.0 + i as f64;
            assert_eq!(c, all.iter().filter(|&&x| x == v).count() as u64, "bin {v}");
        }
        for (q, &pm) in h.percentiles.iter().zip(&PERCENTILES_PER_MILLE) {
            assert_eq!(q[1], nearest_rank(&all, pm), "p{}", q[0]);
        }
        assert_eq!((h.min, h.max), (Some(-1024.0), Some(3071.0)));
    }

    #[test]
    fn wide_integers_merge_bins_exactly() {
        let v: Vec<f64> = (0..20000).map(|i| (i * 7 % 10000) as f64).collect();
        let h = build(Dtype::U16, std::slice::from_ref(&v), Rescale::IDENTITY);
        assert!(!h.exact);
        assert!(h.counts.len() <= MAX_BINS);
        // Bin edges between integers: each bin's count is exact.
        for (i, &c) in h.counts.iter().enumerate() {
            let (a, b) = (
                h.lo + i as f64 * h.bin_width,
                h.lo + (i + 1) as f64 * h.bin_width,
            );
            assert_eq!(c, v.iter().filter(|&&x| x >= a && x < b).count() as u64);
        }
        let mut s = v.clone();
        s.sort_by(f64::total_cmp);
        for (q, &pm) in h.percentiles.iter().zip(&PERCENTILES_PER_MILLE) {
            assert!((q[1] - nearest_rank(&s, pm)).abs() <= h.bin_width, "{q:?}");
        }
    }

    #[test]
    fn negative_slope_reverses_the_bins() {
        let v: Vec<f64> = vec![0.0, 1.0, 1.0, 5.0];
        let r = Rescale {
            slope: -2.0,
            intercept: 10.0,
        };
        let h = build(Dtype::U8, std::slice::from_ref(&v), r);
        // Rescaled: 10, 8, 8, 0.
        assert_eq!((h.min, h.max), (Some(0.0), Some(10.0)));
        assert_eq!(h.lo, -1.0);
        assert_eq!(h.bin_width, 2.0);
        assert_eq!(h.counts, vec![1, 0, 0, 0, 2, 1]);
        assert_eq!(h.percentile(50.0), Some(8.0));
    }

    #[test]
    fn floats_grow_and_stay_within_a_bin() {
        let mut slices = vec![vec![0.25f64; 10]];
        slices.push((0..5000).map(|i| (i as f64 * 0.37).sin() * 1e3).collect());
        slices.push(vec![f64::INFINITY, -1e4, f64::NAN]);
        let h = build(Dtype::F32, &slices, Rescale::IDENTITY);
        assert_eq!((h.nan, h.infinite), (1, 1));
        let mut all: Vec<f64> = slices
            .concat()
            .into_iter()
            .filter(|v| v.is_finite())
            .collect();
        all.sort_by(f64::total_cmp);
        assert_eq!(h.samples, all.len() as u64);
        assert!(h.counts.len() <= MAX_BINS);
        for (i, &c) in h.counts.iter().enumerate() {
            let bin = |x: f64| ((x - h.lo) / h.bin_width).floor() as usize;
            assert_eq!(c, all.iter().filter(|&&x| bin(x) == i).count() as u64);
        }
        for (q, &pm) in h.percentiles.iter().zip(&PERCENTILES_PER_MILLE) {
            assert!(
                (q[1] - nearest_rank(&all, pm)).abs() <= h.bin_width,
                "{q:?}"
            );
        }
        // The width is at most 4x what the range needs.
        assert!(h.bin_width <= 4.0 * (1e4 + 1e3) / MAX_BINS as f64);
    }

    proptest::proptest! {
        /// Builders of two runs of slices, merged either way round, equal
        /// the builder of all the slices in order: the grid depends on the
        /// range seen, not the order (what sharded prep relies on).
        #[test]
        fn merged_builders_equal_one_builder(
            slices in proptest::collection::vec(
                proptest::collection::vec(
                    proptest::prop_oneof![
                        8 => -1e5f64..1e5,
                        1 => -1e12f64..1e12,
                        1 => proptest::strategy::Just(f64::NAN),
                        1 => proptest::strategy::Just(7.0),
                    ],
                    0..40,
                ),
                1..8,
            ),
            split in 0usize..8,
            integer in proptest::bool::ANY,
        ) {
            let dtype = if integer { Dtype::I64 } else { Dtype::F64 };
            let slices: Vec<Vec<f64>> = slices
                .into_iter()
                .map(|s| {
                    s.into_iter()
                        .filter(|v| !(integer && v.is_nan()))
                        .map(|v| if integer { v.round() } else { v })
                        .collect()
                })
                .collect();
            let k = split.min(slices.len());
            let run = |part: &[Vec<f64>]| {
                let mut b = HistogramBuilder::new(dtype);
                for s in part {
                    b.add_slice(s, None);
                }
                b
            };
            let one = run(&slices);
            let mut ab = run(&slices[..k]);
            ab.merge(&run(&slices[k..]));
            let mut ba = run(&slices[k..]);
            ba.merge(&run(&slices[..k]));
            proptest::prop_assert_eq!(&ab, &one);
            proptest::prop_assert_eq!(&ba, &one);
            let json = serde_json::to_string(&one).expect("serialises");
            let back: HistogramBuilder = serde_json::from_str(&json).expect("parses");
            proptest::prop_assert_eq!(back, one);
        }
    }

    #[test]
    fn all_nan_gives_an_empty_histogram() {
        let h = build(Dtype::F64, &[vec![f64::NAN; 4]], Rescale::IDENTITY);
        assert_eq!((h.samples, h.nan), (0, 4));
        assert!(h.counts.is_empty() && h.percentiles.is_empty());
        assert!(h.check().is_ok());
    }
}
