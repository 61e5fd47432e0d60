//! A grid's map from positions to cells for the composite's 8-lane
//! batches (batch.rs): on a uniform axis a multiplication, on a
//! rectilinear one a bucket table and one comparison ([`RectAxis`]).

/// A grid's map from positions to cells. On a uniform axis `(p - s0) *
/// inv_h` is the sample index, its integer part the cell. On a grid with
/// a rectilinear axis, [`IndexMap::rect`] holds per axis a [`RectAxis`]
/// for the rectilinear ones (the cell from a table, the local coordinate
/// from the cell's planes) and `None` for the uniform ones.
#[derive(Clone, Debug)]
pub(crate) struct IndexMap {
    pub(super) s0: [f64; 3],
    pub(super) inv_h: [f64; 3],
    pub(super) rect: Option<Box<[Option<RectAxis>; 3]>>,
}

/// One axis of a rectilinear grid (varying slice thickness) as the
/// batches find cells on it, positions relative to its first sample `s0`
/// in f32: the axis is cut into buckets of half its thinnest cell, so
/// that at most one plane lies in a bucket and its neighbour, and each
/// bucket knows the cell holding its start. A position's cell is its
/// bucket's, or the next one when the position lies at or beyond that
/// cell's upper plane.
#[derive(Clone, Debug)]
pub(super) struct RectAxis {
    /// `1 / w`, `w` the bucket width.
    pub(super) inv_w: f32,
    /// The last bucket's index.
    pub(super) last: f32,
    /// Per bucket, the cell holding its start.
    pub(super) bucket: Vec<u32>,
    /// The sample positions less `s0`: one per plane.
    pub(super) s: Vec<f32>,
    /// `1 / (s[i + 1] - s[i])` per cell, and a 0 after the last.
    pub(super) inv: Vec<f32>,
}

/// Buckets per rectilinear axis, at most (4 MiB of cells): an axis whose
/// thinnest cell would need more takes one sample at a time.
const MAX_BUCKETS: usize = 1 << 20;

impl RectAxis {
    /// The axis of sample positions `c` (increasing, at least 2), or
    /// `None` when its thinnest cell is too thin for [`MAX_BUCKETS`].
    pub(super) fn of(c: &[f64]) -> Option<RectAxis> {
        let thinnest = c
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(f64::INFINITY, f64::min);
        let w = thinnest / 2.0;
        let extent = c[c.len() - 1] - c[0];
        let n = (extent / w).ceil() + 2.0;
        if !(w > 0.0 && n <= MAX_BUCKETS as f64) {
            return None;
        }
        let cells = c.len() - 1;
        // Per bucket the largest cell whose lower plane is at or before
        // the bucket's start, within the grid: one walk up the planes.
        let mut cell = 0;
        let bucket = (0..n as usize)
            .map(|k| {
                let start = c[0] + k as f64 * w;
                while cell + 1 < cells && c[cell + 1] <= start {
                    cell += 1;
                }
                cell as u32
            })
            .collect();
        let mut inv: Vec<f32> = c.windows(2).map(|w| (1.0 / (w[1] - w[0])) as f32).collect();
        inv.push(0.0);
        Some(RectAxis {
            inv_w: (1.0 / w) as f32,
            last: (n as usize - 1) as f32,
            bucket,
            s: c.iter().map(|&x| (x - c[0]) as f32).collect(),
            inv,
        })
    }

    /// The cell holding position `p` (relative to `s0`) less `first`
    /// (wrapping: below `first`, or before the axis, is above any brick
    /// size), and the local coordinate in it clamped to [0, 1]. A
    /// position within rounding of a plane may get the cell on its other
    /// side.
    #[inline(always)]
    pub(super) fn cell(&self, p: f32, first: u32) -> (u32, f32) {
        // Not `clamp`, which keeps NaN.
        #[allow(clippy::manual_clamp)]
        let kf = (p * self.inv_w).max(0.0).min(self.last);
        // SAFETY: `kf` is in [0, last] (`max` takes 0 for NaN), and `last`
        // is below 2^20, so it truncates to an i32. The NaN `max` may meet
        // is the product of run-time operands, so quiet (`TfLut::sample32`
        // says why that matters).
        let k = unsafe { kf.to_int_unchecked::<i32>() } as usize;
        // At most the last cell, whose upper plane `s` holds.
        let mut c = self.bucket[k] as usize;
        c += (p >= self.s[c + 1]) as usize;
        let u = ((p - self.s[c]) * self.inv[c]).clamp(0.0, 1.0);
        // Before the axis (or NaN): no cell.
        let c = if p >= 0.0 { c as u32 } else { u32::MAX };
        (c.wrapping_sub(first), u)
    }
}

impl IndexMap {
    /// The map of a grid with these sample positions (at least 2 per
    /// axis), `uniform[k]` when axis `k` is uniform; `None` when a
    /// rectilinear grid has an axis too fine for the tables.
    pub(crate) fn of(coords: [&[f64]; 3], uniform: [bool; 3]) -> Option<IndexMap> {
        if coords.iter().any(|c| c.len() < 2) {
            return None;
        }
        let rect = if uniform.iter().all(|&u| u) {
            None
        } else {
            let mut axes = [None, None, None];
            for a in 0..3 {
                if !uniform[a] {
                    axes[a] = Some(RectAxis::of(coords[a])?);
                }
            }
            Some(Box::new(axes))
        };
        Some(IndexMap {
            s0: coords.map(|c| c[0]),
            inv_h: coords.map(|c| (c.len() - 1) as f64 / (c[c.len() - 1] - c[0])),
            rect,
        })
    }

    /// The cell along axis `a` (of `n`) whose span holds position `p`, by
    /// the map, clamped to the grid: an estimate within a rounding of the
    /// planes' answer.
    pub(crate) fn cell(&self, a: usize, p: f64, n: u32) -> u32 {
        if let Some(Some(r)) = self.rect.as_ref().map(|r| &r[a]) {
            let p = (p - self.s0[a]) as f32;
            return if p >= 0.0 {
                r.cell(p, 0).0.min(n - 1)
            } else {
                0
            };
        }
        let q = ((p - self.s0[a]) * self.inv_h[a]).floor();
        // NaN and below 0 go to 0; above, to the last cell.
        if q >= 0.0 {
            q.min((n - 1) as f64) as u32
        } else {
            0
        }
    }
}
