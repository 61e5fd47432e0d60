//! Where a volume's values put its background and its object: the
//! landmarks that MR presets are placed on ([`crate::presets::Preset::fitted`];
//! docs/PRESETS.md, "Fitted to the file").
//!
//! MR intensities have no absolute scale, so a preset's numbers mean
//! something only relative to the file's own background and tissue. The
//! landmarks come from the value histogram alone (smoothed by a box of
//! 1 % of its bins where a count is read):
//! 1. Otsu's threshold `t_o` (the split of the histogram that maximises
//!    the between-class variance) separates the background (air and its
//!    noise, or the zeros around a skull-stripped brain) from most of the
//!    object. It lies inside the tissue (about 0.75 of white matter on a
//!    T1 head), so it is not the object's edge.
//! 2. The background's mode `m` (the highest bin below `t_o`) is the noise
//!    level: for magnitude images the air is Rayleigh-distributed with its
//!    mode at the noise sigma, so `5 m` is above all but 4e-6 of it.
//! 3. The valley `v`: the first bin past `m` where the counts stop
//!    falling, where the noise has died out and the tissue begins.
//! 4. The **threshold** is `max(v, 5 m)`, at most `t_o`: the object's
//!    edge (skin on a whole-head scan, the brain's surface on a
//!    skull-stripped one, whose zeros have `m = 0`). It is the surface iso
//!    of MR presets and the floor of their transfer functions.
//! 5. **p50**, **p95** and **p99** are percentiles of the samples at or
//!    above the threshold: the object's median and its bright end.

use serde::{Deserialize, Serialize};

use super::histogram::ValueHistogram;
use crate::presets::Landmark;

/// A volume's landmarks (module docs), in rescaled units, with where they
/// were measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Landmarks {
    pub threshold: f64,
    pub p50: f64,
    pub p95: f64,
    pub p99: f64,
    /// What they were measured on: the whole value histogram, or the
    /// slices prep sampled before its first pass to place a preset.
    pub measured_on: String,
}

impl Landmarks {
    /// The value of landmark `l`.
    pub fn at(&self, l: Landmark) -> f64 {
        match l {
            Landmark::Threshold => self.threshold,
            Landmark::P50 => self.p50,
            Landmark::P95 => self.p95,
            Landmark::P99 => self.p99,
        }
    }

    /// The landmarks of `h` (module docs); `None` when it has fewer than
    /// two occupied bins (no split) or its figures are not finite.
    pub fn of(h: &ValueHistogram, measured_on: &str) -> Option<Landmarks> {
        let c = &h.counts;
        if c.iter().filter(|&&n| n > 0).count() < 2 {
            return None;
        }
        let centre = |i: usize| h.lo + (i as f64 + 0.5) * h.bin_width;
        let k = otsu(c, centre)?;
        let t_o = h.lo + (k + 1) as f64 * h.bin_width;
        let sm = smoothed(c, (c.len() / 100).max(1));
        let below = &sm[..=k];
        let mode = (0..below.len()).fold(0, |m, i| if below[i] > below[m] { i } else { m });
        // The first bin past the mode where the counts stop falling.
        let valley = (mode..below.len())
            .find(|&i| i + 1 == below.len() || below[i + 1] >= below[i])
            .unwrap_or(mode);
        let noise = 5.0 * centre(mode).max(0.0);
        let threshold = centre(valley).max(noise).min(t_o);
        let first = ((threshold - h.lo) / h.bin_width).floor().max(0.0) as usize;
        let first = first.min(c.len() - 1);
        let l = Landmarks {
            threshold,
            p50: quantile(h, first, c.len(), 0.50)?.max(threshold),
            p95: quantile(h, first, c.len(), 0.95)?.max(threshold),
            p99: quantile(h, first, c.len(), 0.99)?.max(threshold),
            measured_on: measured_on.into(),
        };
        [l.threshold, l.p50, l.p95, l.p99]
            .iter()
            .all(|v| v.is_finite())
            .then_some(l)
    }
}

/// Otsu's split of `counts`: the last bin of the lower class, chosen to
/// maximise `w0 w1 (m0 - m1)^2`; `None` when no split has two classes.
fn otsu(counts: &[u64], centre: impl Fn(usize) -> f64) -> Option<usize> {
    let total: f64 = counts.iter().map(|&n| n as f64).sum();
    let sum: f64 = counts
        .iter()
        .enumerate()
        .map(|(i, &n)| n as f64 * centre(i))
        .sum();
    let (mut w0, mut s0) = (0.0, 0.0);
    // The best split, and the run of splits as good right after it (an
    // empty gap between two classes scores the same at every bin of it:
    // its middle is taken).
    let mut best: Option<(usize, usize, f64)> = None;
    for (i, &n) in counts.iter().enumerate().take(counts.len() - 1) {
        w0 += n as f64;
        s0 += n as f64 * centre(i);
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let d = s0 / w0 - (sum - s0) / w1;
        let between = w0 * w1 * d * d;
        best = match best {
            Some((a, b, v)) if b + 1 == i && (between - v).abs() <= 1e-12 * v => Some((a, i, v)),
            Some((_, _, v)) if between <= v => best,
            _ => Some((i, i, between)),
        };
    }
    best.map(|(a, b, _)| (a + b) / 2)
}

/// `counts` averaged over a box of `2 r + 1` bins (fewer at the ends).
fn smoothed(counts: &[u64], r: usize) -> Vec<f64> {
    let mut prefix = vec![0.0f64; counts.len() + 1];
    for (i, &n) in counts.iter().enumerate() {
        prefix[i + 1] = prefix[i] + n as f64;
    }
    (0..counts.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(r), (i + r + 1).min(counts.len()));
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

/// The `q` quantile of the samples in bins `a..b` of `h`, interpolated
/// inside its bin; `None` when those bins are empty.
fn quantile(h: &ValueHistogram, a: usize, b: usize, q: f64) -> Option<f64> {
    let bins = &h.counts[a..b];
    let n: u64 = bins.iter().sum();
    if n == 0 {
        return None;
    }
    let rank = (q * n as f64).clamp(0.0, n as f64);
    let mut before = 0.0;
    for (j, &c) in bins.iter().enumerate() {
        let c = c as f64;
        if c > 0.0 && before + c >= rank {
            let f = ((rank - before) / c).clamp(0.0, 1.0);
            return Some(h.lo + ((a + j) as f64 + f) * h.bin_width);
        }
        before += c;
    }
    Some(h.lo + b as f64 * h.bin_width)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A histogram of bins of width 1 from 0 with these counts.
    fn hist(counts: Vec<u64>) -> ValueHistogram {
        ValueHistogram {
            lo: 0.0,
            bin_width: 1.0,
            samples: counts.iter().sum(),
            counts,
            nan: 0,
            infinite: 0,
            min: None,
            max: None,
            exact: false,
            percentiles: Vec::new(),
        }
    }

    #[test]
    fn the_threshold_splits_noise_from_tissue() {
        // Noise in 0..10 (most at 3), tissue in 100..200.
        let mut c = vec![0u64; 200];
        for (i, n) in c.iter_mut().enumerate().take(10) {
            *n = 1000 / (1 + (i as i64 - 3).unsigned_abs());
        }
        for n in &mut c[100..200] {
            *n = 50;
        }
        let c0 = c.clone();
        let l = Landmarks::of(&hist(c), "test").unwrap();
        assert!(l.threshold > 10.0 && l.threshold < 100.0, "{l:?}");
        assert!((l.p50 - 150.0).abs() < 1.5, "{l:?}");
        assert!((l.p99 - 199.0).abs() < 1.5, "{l:?}");
        assert!(l.threshold < l.p50 && l.p50 < l.p95 && l.p95 <= l.p99);
        // The same counts in bins 7 times wider: every landmark scales.
        let mut h7 = hist(c0);
        h7.bin_width = 7.0;
        let l7 = Landmarks::of(&h7, "test").unwrap();
        for (a, b) in [
            (l.threshold, l7.threshold),
            (l.p50, l7.p50),
            (l.p99, l7.p99),
        ] {
            assert!((a * 7.0 - b).abs() < 1e-9, "{a} {b}");
        }
    }

    #[test]
    fn a_skull_stripped_background_of_zeros_is_split_off() {
        // Zeros outside, brain in 40..100.
        let mut c = vec![0u64; 100];
        c[0] = 100_000;
        for n in &mut c[40..100] {
            *n = 300;
        }
        let l = Landmarks::of(&hist(c), "test").unwrap();
        assert!(l.threshold > 1.0 && l.threshold < 40.0, "{l:?}");
        assert!(l.p50 > 60.0 && l.p50 < 80.0, "{l:?}");
    }

    #[test]
    fn one_value_has_no_landmarks() {
        assert!(Landmarks::of(&hist(vec![0, 5, 0]), "test").is_none());
        assert!(Landmarks::of(&hist(vec![]), "test").is_none());
    }
}
