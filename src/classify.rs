//! Cell classification (paper section 4, Fig. 7): which cells can
//! contribute to an image (1-cells) and which can be leapt over (0-cells).
//!
//! A cell lies between 8 samples. With `--iso T` it is a 1-cell when the
//! largest of its 8 vertex values is >= T: the trilinear interpolant can
//! only reach T inside the cell then. With a transfer function it is a
//! 1-cell when the opacity is non-zero anywhere in the [min, max] of its
//! vertex values, which bounds every value the trilinear interpolant takes.
//!
//! NaN policy: a NaN sample is background. It never reaches an iso value
//! and is left out of a cell's [min, max]; a cell whose 8 samples are all
//! NaN is a 0-cell, and a transfer function gives NaN no opacity. A 1-cell
//! with some NaN vertices keeps them; its trilinear interpolant is NaN, so
//! the renderer finds no surface and no colour inside that cell (the
//! neighbouring cells without NaN vertices still render).

use std::path::Path;

use serde::{Deserialize, Serialize};

/// One control point of a piecewise-linear transfer function.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TfPoint {
    /// Rescaled sample value (HU for CT).
    pub value: f64,
    /// Opacity in [0, 1].
    pub opacity: f64,
    /// Colour in [0, 1]; white when left out.
    #[serde(default = "white")]
    pub color: [f64; 3],
}

fn white() -> [f64; 3] {
    [1.0; 3]
}

/// A piecewise-linear colour/opacity transfer function, constant beyond
/// its first and last points. JSON: `{"points": [{"value": v, "opacity":
/// a, "color": [r, g, b]}, ...]}` with values strictly increasing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransferFunction {
    pub points: Vec<TfPoint>,
}

/// Why a transfer function file was refused.
#[derive(Debug, thiserror::Error)]
#[error("{}: {msg}", path.display())]
pub struct TfError {
    pub path: std::path::PathBuf,
    pub msg: String,
}

/// A transfer function field that breaks an invariant of
/// [`TransferFunction::check`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("field `{field}`: {found}, expected {expected}")]
pub struct TfInvalid {
    pub field: String,
    pub found: String,
    pub expected: &'static str,
}

/// Largest transfer function file read (one is a few KiB).
pub const MAX_TF_BYTES: u64 = 16 << 20;

/// The text of transfer function file `path`, read once and at most
/// [`MAX_TF_BYTES`]. The file may be a FIFO (`--tf <(...)`): it is opened
/// once, read to its end, and never opened again.
pub fn read_tf_text(path: &Path) -> Result<String, TfError> {
    use std::io::Read;
    let e = |msg: String| TfError {
        path: path.to_path_buf(),
        msg,
    };
    let f = std::fs::File::open(path).map_err(|x| e(format!("cannot read: {x}")))?;
    let mut bytes = Vec::new();
    f.take(MAX_TF_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|x| e(format!("cannot read: {x}")))?;
    if bytes.len() as u64 > MAX_TF_BYTES {
        return Err(e(format!(
            "larger than {} MiB, expected a transfer function (a JSON file of a few KiB)",
            MAX_TF_BYTES >> 20
        )));
    }
    String::from_utf8(bytes)
        .map_err(|_| e("not UTF-8 text, expected a JSON transfer function".into()))
}

impl TransferFunction {
    /// Reads and checks a transfer function file.
    pub fn load(path: &Path) -> Result<TransferFunction, TfError> {
        TransferFunction::from_text(path, &read_tf_text(path)?)
    }

    /// Parses and checks `text`, the contents of transfer function file
    /// `path` (read once by [`read_tf_text`]: a FIFO or `<(...)` can be
    /// read only once).
    pub fn from_text(path: &Path, text: &str) -> Result<TransferFunction, TfError> {
        let e = |msg: String| TfError {
            path: path.to_path_buf(),
            msg,
        };
        if let Some(key) = crate::json::duplicate_key(text) {
            return Err(e(format!("{key}: duplicate key, expected each key once")));
        }
        let tf: TransferFunction = serde_json::from_str(text).map_err(|x| {
            e(format!(
                "expected {{\"points\": [{{\"value\", \"opacity\", \"color\"}}, ...]}}: {x}"
            ))
        })?;
        tf.check().map_err(|x| e(x.to_string()))?;
        Ok(tf)
    }

    /// Checks the invariants `load` promises.
    pub fn check(&self) -> Result<(), TfInvalid> {
        let bad = |field: String, found: String, expected: &'static str| {
            Err(TfInvalid {
                field,
                found,
                expected,
            })
        };
        if self.points.is_empty() {
            return bad("points".into(), "empty".into(), "at least one point");
        }
        for (i, p) in self.points.iter().enumerate() {
            if !p.value.is_finite() {
                return bad(
                    format!("points[{i}].value"),
                    p.value.to_string(),
                    "a finite number",
                );
            }
            if !(0.0..=1.0).contains(&p.opacity) {
                return bad(
                    format!("points[{i}].opacity"),
                    p.opacity.to_string(),
                    "0..=1",
                );
            }
            if i > 0 && p.value <= self.points[i - 1].value {
                return bad(
                    format!("points[{i}].value"),
                    format!("{} after {}", p.value, self.points[i - 1].value),
                    "strictly increasing values",
                );
            }
        }
        Ok(())
    }

    /// Opacity at `v` (linear between points, constant beyond the ends).
    pub fn opacity(&self, v: f64) -> f64 {
        let p = &self.points;
        if v.is_nan() {
            // NaN samples are background (module docs).
            return 0.0;
        }
        if v <= p[0].value {
            return p[0].opacity;
        }
        let last = p[p.len() - 1];
        if v >= last.value {
            return last.opacity;
        }
        let i = p.partition_point(|q| q.value <= v);
        let (a, b) = (p[i - 1], p[i]);
        let f = (v - a.value) / (b.value - a.value);
        a.opacity + f * (b.opacity - a.opacity)
    }

    /// Colour at `v` (linear between points, constant beyond the ends;
    /// the first point's for NaN).
    pub fn colour(&self, v: f64) -> [f64; 3] {
        let p = &self.points;
        if !(v > p[0].value) {
            return p[0].color;
        }
        let last = p[p.len() - 1];
        if v >= last.value {
            return last.color;
        }
        let i = p.partition_point(|q| q.value <= v);
        let (a, b) = (p[i - 1], p[i]);
        let f = (v - a.value) / (b.value - a.value);
        std::array::from_fn(|k| a.color[k] + f * (b.color[k] - a.color[k]))
    }

    /// The hull of the values where the opacity is non-zero: from the
    /// point before the first point with opacity > 0 to the point after
    /// the last one, infinite at an end whose point has opacity > 0 (the
    /// function is constant beyond its ends). `None` when the opacity is
    /// zero everywhere.
    pub fn support(&self) -> Option<(f64, f64)> {
        let p = &self.points;
        let first = p.iter().position(|q| q.opacity > 0.0)?;
        let last = p.iter().rposition(|q| q.opacity > 0.0)?;
        let lo = match first {
            0 => f64::NEG_INFINITY,
            i => p[i - 1].value,
        };
        let hi = match p.get(last + 1) {
            Some(q) => q.value,
            None => f64::INFINITY,
        };
        Some((lo, hi))
    }

    /// A value where this function gives opacity and `outer` none, if
    /// any: `None` means every value this one shows lies inside `outer`'s
    /// support, so a file classified by `outer` renders it exactly. Both
    /// are piecewise linear, so probing their points, the midpoints
    /// between them and one value beyond each end is exact.
    pub fn outside(&self, outer: &TransferFunction) -> Option<f64> {
        let mut pts: Vec<f64> = self
            .points
            .iter()
            .chain(&outer.points)
            .map(|p| p.value)
            .collect();
        pts.sort_by(f64::total_cmp);
        let mut probes = pts.clone();
        probes.extend(pts.windows(2).map(|w| 0.5 * (w[0] + w[1])));
        probes.push(pts[0] - 1.0);
        probes.push(pts[pts.len() - 1] + 1.0);
        probes
            .into_iter()
            .find(|&v| self.opacity(v) > 0.0 && outer.opacity(v) == 0.0)
    }

    /// The largest iso value whose classification holds every cell this
    /// function gives opacity: the last zero-opacity point before the
    /// first non-zero one; `None` when the function is non-zero below its
    /// first point (or nowhere).
    pub fn iso_floor(&self) -> Option<f64> {
        match self.support()?.0 {
            lo if lo.is_finite() => Some(lo),
            _ => None,
        }
    }

    /// True when the opacity is non-zero anywhere on `[lo, hi]`. A
    /// piecewise-linear function is largest at an end of the interval or
    /// at a control point inside it, so checking those is exact.
    pub fn nonzero_on(&self, lo: f64, hi: f64) -> bool {
        if self.opacity(lo) > 0.0 || self.opacity(hi) > 0.0 {
            return true;
        }
        self.points
            .iter()
            .any(|p| p.value > lo && p.value < hi && p.opacity > 0.0)
    }
}

/// How prep decides 1-cells; stored in the packed file's header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Classification {
    /// 1-cell when the largest vertex value is >= `iso`.
    Iso { iso: f64 },
    /// 1-cell when the opacity is non-zero somewhere in the vertex range.
    TransferFunction { tf: TransferFunction },
}

/// For people: `iso 300` or `transfer function of 5 points, opaque
/// somewhere in 100 .. 3071`.
impl std::fmt::Display for Classification {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Classification::Iso { iso } => write!(f, "iso {iso}"),
            Classification::TransferFunction { tf } => {
                let opaque: Vec<f64> = tf
                    .points
                    .iter()
                    .filter(|p| p.opacity > 0.0)
                    .map(|p| p.value)
                    .collect();
                write!(f, "transfer function of {} points", tf.points.len())?;
                match (opaque.first(), opaque.last()) {
                    (Some(a), Some(b)) => write!(f, ", opaque at points {a} .. {b}"),
                    _ => write!(f, ", transparent everywhere"),
                }
            }
        }
    }
}

impl Classification {
    /// Classifies a cell from the min and max of its vertex values (NaN
    /// excluded; both NaN when all 8 are NaN).
    #[inline]
    pub fn is_object(&self, min: f64, max: f64) -> bool {
        match self {
            Classification::Iso { iso } => max >= *iso,
            // An empty range (all 8 NaN: min > max, or NaN) is background.
            Classification::TransferFunction { tf } => min <= max && tf.nonzero_on(min, max),
        }
    }

    /// Whether this classification holds every 1-cell of an iso value
    /// `v` (a cell whose largest vertex value is >= v), so that a file
    /// classified by it renders surfaces at `v` exactly (`render --iso`):
    /// `v` at or above the iso value, or where the transfer function is
    /// non-zero from `v` up.
    pub fn holds_iso(&self, v: f64) -> bool {
        match self {
            Classification::Iso { iso } => v >= *iso,
            Classification::TransferFunction { tf } => {
                tf.opacity(v) > 0.0 && tf.points.iter().all(|p| p.value < v || p.opacity > 0.0)
            }
        }
    }

    /// Classifies a cell from its 8 vertex values (NaN skipped).
    #[inline]
    pub fn is_object_vertices(&self, v: &[f64; 8]) -> bool {
        let (lo, hi) = v
            .iter()
            .fold((f64::NAN, f64::NAN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        self.is_object(lo, hi)
    }

    /// The one rule that reads a cell's class back from a packed file,
    /// from its 8 vertex words (x fastest): `codes[i]` the code word `i`
    /// carries, if any, and `values[i]` its rescaled value otherwise.
    ///
    /// A code at the minimum corner is the cell's code (docs/FORMAT.md,
    /// "Embedding"). A code at any other vertex makes the cell a 0-cell
    /// with code 0: prep replaces only samples that are vertices of no
    /// 1-cell. Otherwise this classification decides from the 8 values,
    /// which are then exact (a 0-cell there has code 0).
    #[inline(always)]
    pub fn cell_of_words(&self, codes: [Option<u32>; 8], values: [f64; 8]) -> CellClass {
        if let Some(c) = codes[0] {
            CellClass::Empty(c)
        } else if codes.iter().any(Option::is_some) || !self.is_object_vertices(&values) {
            CellClass::Empty(0)
        } else {
            CellClass::Object
        }
    }
}

/// Class of one cell as read back from a packed file
/// ([`Classification::cell_of_words`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellClass {
    /// A 1-cell.
    Object,
    /// A 0-cell and its distance code.
    Empty(u32),
}

/// Larger of two values, never NaN unless `m` is (`v` NaN keeps `m`).
/// Plain comparisons so the compiler vectorizes the loops below.
#[inline(always)]
fn max_nn(m: f64, v: f64) -> f64 {
    if v > m {
        v
    } else {
        m
    }
}

#[inline(always)]
fn min_nn(m: f64, v: f64) -> f64 {
    if v < m {
        v
    } else {
        m
    }
}

/// Per-column extrema of one sample slice over the 2x2 samples of each
/// cell column: `max[y * (nx-1) + x]` is the max of samples `x..=x+1`,
/// `y..=y+1`, likewise `min`. NaN samples are skipped; a column of four
/// NaNs gives max = -inf and min = +inf (an empty range). Returns the
/// (min, max) of the whole slice (every sample is in some column).
pub fn slice_extrema(
    values: &[f64],
    nx: usize,
    ny: usize,
    max: &mut [f64],
    min: &mut [f64],
) -> (f64, f64) {
    use rayon::prelude::*;
    let ncx = nx - 1;
    debug_assert_eq!(values.len(), nx * ny);
    debug_assert_eq!(max.len(), ncx * (ny - 1));
    max.par_chunks_mut(ncx)
        .zip(min.par_chunks_mut(ncx))
        .enumerate()
        .with_min_len(8)
        .map(|(y, (mx, mn))| {
            let a = &values[y * nx..(y + 1) * nx];
            let b = &values[(y + 1) * nx..(y + 2) * nx];
            let cols = mx.iter_mut().zip(mn.iter_mut());
            let quads = a.windows(2).zip(b.windows(2));
            for ((hi, lo), (p, q)) in cols.zip(quads) {
                *hi = max_nn(
                    max_nn(max_nn(max_nn(f64::NEG_INFINITY, p[0]), p[1]), q[0]),
                    q[1],
                );
                *lo = min_nn(
                    min_nn(min_nn(min_nn(f64::INFINITY, p[0]), p[1]), q[0]),
                    q[1],
                );
            }
            // Row range with 8 independent lanes (a plain fold of floats
            // cannot be vectorized without reassociation).
            let mut hi8 = [f64::NEG_INFINITY; 8];
            let mut lo8 = [f64::INFINITY; 8];
            for (h, l) in mx.chunks(8).zip(mn.chunks(8)) {
                for i in 0..h.len() {
                    hi8[i] = max_nn(hi8[i], h[i]);
                    lo8[i] = min_nn(lo8[i], l[i]);
                }
            }
            (
                lo8.iter().fold(f64::INFINITY, |m, &v| min_nn(m, v)),
                hi8.iter().fold(f64::NEG_INFINITY, |m, &v| max_nn(m, v)),
            )
        })
        .reduce(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |a, b| (min_nn(a.0, b.0), max_nn(a.1, b.1)),
        )
}

/// Iso fast path of pass 1: `flags[y * (nx-1) + x] = 1` when any of the
/// four samples `x..=x+1`, `y..=y+1` has a rescaled value `>= iso` (NaN
/// never does). A cell is a 1-cell exactly when the flag of its column is
/// set in the sample slice below or above it, so classification needs one
/// byte per column instead of two f64 extrema. Returns the raw (min, max)
/// of the slice, NaN excluded.
pub fn slice_iso_flags(
    values: &[f64],
    nx: usize,
    ny: usize,
    rescale: crate::input::Rescale,
    iso: f64,
    flags: &mut [u8],
) -> (f64, f64) {
    use rayon::prelude::*;
    let ncx = nx - 1;
    debug_assert_eq!(values.len(), nx * ny);
    debug_assert_eq!(flags.len(), ncx * (ny - 1));
    flags
        .par_chunks_mut(ncx)
        .enumerate()
        .with_min_len(8)
        .map_init(
            || vec![0u8; nx],
            |above, (y, out)| {
                let a = &values[y * nx..(y + 1) * nx];
                let b = &values[(y + 1) * nx..(y + 2) * nx];
                for ((f, &p), &q) in above.iter_mut().zip(a).zip(b) {
                    *f = (rescale.apply(p) >= iso) as u8 | (rescale.apply(q) >= iso) as u8;
                }
                let pairs = above[..ncx].iter().zip(&above[1..]);
                for (o, (&l, &r)) in out.iter_mut().zip(pairs) {
                    *o = l | r;
                }
                // Range of row y (the last row pair also covers row y+1).
                let mut range = lane_range(a);
                if y + 2 == ny {
                    let rb = lane_range(b);
                    range = (min_nn(range.0, rb.0), max_nn(range.1, rb.1));
                }
                range
            },
        )
        .reduce(
            || (f64::INFINITY, f64::NEG_INFINITY),
            |a, b| (min_nn(a.0, b.0), max_nn(a.1, b.1)),
        )
}

/// (min, max) of a row, NaN skipped, with 8 independent lanes so the loop
/// vectorizes.
fn lane_range(row: &[f64]) -> (f64, f64) {
    let mut hi8 = [f64::NEG_INFINITY; 8];
    let mut lo8 = [f64::INFINITY; 8];
    for c in row.chunks(8) {
        for (i, &v) in c.iter().enumerate() {
            hi8[i] = max_nn(hi8[i], v);
            lo8[i] = min_nn(lo8[i], v);
        }
    }
    (
        lo8.iter().fold(f64::INFINITY, |m, &v| min_nn(m, v)),
        hi8.iter().fold(f64::NEG_INFINITY, |m, &v| max_nn(m, v)),
    )
}

/// Classifies the cell slice between two sample slices from their column
/// extrema (see [`slice_extrema`]); values are rescaled here, per cell.
/// Returns the number of 1-cells.
pub fn classify_slice(
    cls: &Classification,
    rescale: crate::input::Rescale,
    max: [&[f64]; 2],
    min: [&[f64]; 2],
    ncx: usize,
    out: &mut [u8],
) -> u64 {
    use rayon::prelude::*;
    let neg = rescale.slope < 0.0;
    out.par_chunks_mut(ncx)
        .enumerate()
        .with_min_len(8)
        .map(|(y, row)| {
            let r = y * ncx..(y + 1) * ncx;
            let (a, b) = (&max[0][r.clone()], &max[1][r.clone()]);
            let (c, d) = (&min[0][r.clone()], &min[1][r]);
            let mut n = 0u64;
            match cls {
                Classification::Iso { iso } if !neg => {
                    for x in 0..row.len() {
                        let hi = rescale.apply(max_nn(a[x], b[x]));
                        row[x] = (hi >= *iso) as u8;
                        n += row[x] as u64;
                    }
                }
                _ => {
                    for x in 0..row.len() {
                        let (rl, rh) = (min_nn(c[x], d[x]), max_nn(a[x], b[x]));
                        let (lo, hi) = if neg {
                            (rescale.apply(rh), rescale.apply(rl))
                        } else {
                            (rescale.apply(rl), rescale.apply(rh))
                        };
                        row[x] = cls.is_object(lo, hi) as u8;
                        n += row[x] as u64;
                    }
                }
            }
            n
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf(points: &[(f64, f64)]) -> TransferFunction {
        TransferFunction {
            points: points
                .iter()
                .map(|&(value, opacity)| TfPoint {
                    value,
                    opacity,
                    color: [1.0; 3],
                })
                .collect(),
        }
    }

    #[test]
    fn tf_nonzero_on_matches_dense_sampling() {
        let t = tf(&[(0.0, 0.0), (10.0, 0.0), (20.0, 1.0), (30.0, 0.0)]);
        for lo in -5..40 {
            for hi in lo..40 {
                let (lo, hi) = (lo as f64, hi as f64);
                let dense = (0..=1000)
                    .map(|i| lo + (hi - lo) * i as f64 / 1000.0)
                    .any(|v| t.opacity(v) > 0.0);
                assert_eq!(t.nonzero_on(lo, hi), dense, "[{lo}, {hi}]");
            }
        }
    }

    #[test]
    fn nan_vertices_are_background() {
        let c = Classification::Iso { iso: 1.0 };
        let mut v = [f64::NAN; 8];
        assert!(!c.is_object_vertices(&v));
        v[3] = 1.0;
        assert!(c.is_object_vertices(&v));
        v[3] = 0.5;
        assert!(!c.is_object_vertices(&v));
        let t = Classification::TransferFunction {
            tf: tf(&[(0.0, 1.0)]),
        };
        assert!(!t.is_object_vertices(&[f64::NAN; 8]));
    }
}
