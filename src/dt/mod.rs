//! Streaming chessboard distance transform (paper section 3, eqs. 1 and
//! 10, and section 4.2.1, Fig. 10, for the anisotropic codes).
//!
//! Distances are `u8`: 0 on 1-cells, otherwise the chessboard distance
//! `max(|dx|, |dy|, |dz|)` to the nearest 1-cell, saturating at [`FAR`].
//! Cells outside the volume count as empty. The code of a 0-cell is its
//! distance minus one (the radius of the largest empty cube centred on it);
//! saturation only ever lowers a distance, so saturated codes stay safe.
//!
//! The transform is exact and streams over z with two passes:
//!
//! 1. In each slice, the exact 2D distance `D2`: a 1D distance along x per
//!    row (two scans), then the recurrence `F(y) = min(D2x(y),
//!    erode_x(F(y-1)) + 1)` forwards and backwards over the rows.
//! 2. Forward over z, `F(z) = min(D2(z), erode_xy(F(z-1)) + 1)`, spilled to
//!    disk at one byte per cell; backward over z, `G(z) = min(F(z),
//!    erode_xy(G(z+1)) + 1)`, which is the final distance.
//!
//! Why the recurrences are exact: if `q` is a 1-cell with `dz = z - q_z >=
//! 1`, the neighbour of `v` one slice down and one step towards `q` along
//! each axis where `q` differs is exactly one chessboard unit closer to `q`
//! (every coordinate difference shrinks by one, or stays 0), so `F(z-1)`'s
//! 3x3 minimum plus one reaches `max(|dx|, |dy|, dz)`; the triangle
//! inequality rules out anything smaller. The same argument holds per row.
//! `erode` is the 3 (or 3x3) neighbourhood minimum, the paper's 3x3x3 mask
//! split into the part in the previous slice and the part in this one.
//!
//! Memory is a few slices of `(nx-1)(ny-1)` bytes, whatever nz is. Rows
//! are processed in parallel (rayon) where the recurrence allows.
//!
//! With DDA planes ([`ForwardDt::with_dda`], paper section 3, Figs. 4 and
//! 19), the same two z passes also run the classic two-pass raster
//! transforms of the city-block (`L1`, 6-neighbour half masks, weight 1)
//! and chamfer 3-4-5 (26-neighbour half masks, weights 3 face, 4 edge, 5
//! corner) distances, saturating at [`DDA_FAR`]. The forward pass visits z,
//! y, x ascending and takes the minimum over the 13 (chamfer) or 3 (city
//! block) neighbours already visited; the backward pass mirrors it. Both
//! are exact for their shortest-path distances: any shortest 26-path
//! between two cells can be made monotone in every coordinate and its
//! steps reordered so that the forward-mask steps come first, and every
//! such path stays in the bounding box of its ends, so inside the volume.
//! The spill record then holds 3 bytes per cell (chessboard, city block,
//! chamfer forward values).

use std::io;

use rayon::prelude::*;

pub mod seam;
mod spill;

pub use seam::{fix_forward, local_bottom, propagate, SeamChain};
pub use spill::{FileSpill, MemSpill, Spill};

/// Saturated distance ("no 1-cell within 254 cells").
pub const FAR: u8 = u8::MAX;

/// Exact in-slice chessboard distance to the 1-cells of this slice.
/// `obj[i] != 0` marks a 1-cell; `out` gets the distances.
pub fn slice_chessboard(obj: &[u8], ncx: usize, ncy: usize, out: &mut [u8]) {
    // 1D distance along x, two scans per row.
    out.par_chunks_mut(ncx)
        .zip(obj.par_chunks(ncx))
        .with_min_len(8)
        .for_each(|(row, o)| {
            let mut d = FAR;
            for x in 0..ncx {
                d = if o[x] != 0 { 0 } else { d.saturating_add(1) };
                row[x] = d;
            }
            let mut d = FAR;
            for x in (0..ncx).rev() {
                d = row[x].min(d.saturating_add(1));
                row[x] = d;
            }
        });
    // Rows forward then backward, each merging the eroded neighbour row.
    let mut eroded = vec![0u8; ncx];
    for y in 1..ncy {
        let (done, rest) = out.split_at_mut(y * ncx);
        erode_row(&done[(y - 1) * ncx..], &mut eroded);
        merge_plus_one(&mut rest[..ncx], &eroded);
    }
    for y in (0..ncy.saturating_sub(1)).rev() {
        let (head, tail) = out.split_at_mut((y + 1) * ncx);
        erode_row(&tail[..ncx], &mut eroded);
        merge_plus_one(&mut head[y * ncx..], &eroded);
    }
}

/// `out[x] = min(row[x-1], row[x], row[x+1])` (edges use what exists).
#[inline]
fn erode_row(row: &[u8], out: &mut [u8]) {
    let n = out.len();
    let row = &row[..n];
    if n == 1 {
        out[0] = row[0];
        return;
    }
    out[0] = row[0].min(row[1]);
    out[n - 1] = row[n - 2].min(row[n - 1]);
    // Zipped slices: no bounds checks, so this vectorizes.
    let mid = out[1..n - 1]
        .iter_mut()
        .zip(row[..n - 2].iter().zip(&row[1..n - 1]).zip(&row[2..]));
    for (o, ((&a, &b), &c)) in mid {
        *o = a.min(b).min(c);
    }
}

/// `cur[x] = min(cur[x], eroded[x] + 1)` with saturation.
#[inline]
fn merge_plus_one(cur: &mut [u8], eroded: &[u8]) {
    for (c, &e) in cur.iter_mut().zip(eroded) {
        *c = (*c).min(e.saturating_add(1));
    }
}

/// `cur = min(cur, erode_xy(prev) + 1)`: one z step of the recurrence.
pub fn merge_slice(cur: &mut [u8], prev: &[u8], ncx: usize, ncy: usize) {
    cur.par_chunks_mut(ncx)
        .enumerate()
        .with_min_len(8)
        .for_each_init(
            || (vec![0u8; ncx], vec![0u8; ncx]),
            |(col, eroded), (y, row)| {
                let y0 = y.saturating_sub(1);
                let y1 = (y + 1).min(ncy - 1);
                col.copy_from_slice(&prev[y0 * ncx..(y0 + 1) * ncx]);
                for yy in y0 + 1..=y1 {
                    for (c, &p) in col.iter_mut().zip(&prev[yy * ncx..(yy + 1) * ncx]) {
                        *c = (*c).min(p);
                    }
                }
                erode_row(col, eroded);
                merge_plus_one(row, eroded);
            },
        );
}

/// Saturated value of the DDA distance planes (city block, chamfer): "no
/// 1-cell within 254 units". Matches the 254 cap of
/// [`crate::render::traverse::CodeSource::distance`].
pub const DDA_FAR: u8 = 254;

/// Metrics of the DDA distance planes (the chessboard one is the code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DdaMetric {
    /// `L1`, in cells: 6-neighbour steps of weight 1.
    Cityblock,
    /// Chamfer 3-4-5 (Borgefors), in thirds of a cell: face, edge and
    /// corner steps of weights 3, 4 and 5.
    Chamfer,
}

impl DdaMetric {
    /// Weights of face, edge and corner steps (`None`: not in the mask).
    #[inline]
    fn weights(self) -> (u8, Option<u8>, Option<u8>) {
        match self {
            DdaMetric::Cityblock => (1, None, None),
            DdaMetric::Chamfer => (3, Some(4), Some(5)),
        }
    }
}

/// `a + w`, saturating (the caller's `min` with a value `<= DDA_FAR` keeps
/// the result `<= DDA_FAR`).
#[inline(always)]
fn plus(a: u8, w: u8) -> u8 {
    a.saturating_add(w)
}

/// One slice of a two-pass DDA transform. `cur` holds the slice's start
/// values (the forward pass: 0 on 1-cells, [`DDA_FAR`] elsewhere; the
/// backward pass: the forward values); `other` is the slice already done
/// in the pass's z direction (`None` at the volume's end). Rows are then
/// visited in the pass's y direction and cells in its x direction, each
/// taking the minimum over its neighbours already visited plus their
/// weights (the half mask).
pub fn dda_slice(
    metric: DdaMetric,
    cur: &mut [u8],
    other: Option<&[u8]>,
    ncx: usize,
    ncy: usize,
    forward: bool,
) {
    let (wf, we, wc) = metric.weights();
    // The neighbouring slice: all 9 (chamfer) or 1 (city block) of its
    // cells next to each cell are in the half mask. Rows are independent.
    if let Some(other) = other {
        cur.par_chunks_mut(ncx)
            .enumerate()
            .with_min_len(8)
            .for_each(|(y, row)| {
                let mid = &other[y * ncx..(y + 1) * ncx];
                merge_row(row, mid, wf, we);
                if let (Some(we), Some(wc)) = (we, wc) {
                    for yy in [y.wrapping_sub(1), y + 1] {
                        if yy < ncy {
                            merge_row(row, &other[yy * ncx..(yy + 1) * ncx], we, Some(wc));
                        }
                    }
                }
            });
    }
    // In the slice: the row before (3 or 1 cells), then the cell before.
    let rows: Box<dyn Iterator<Item = usize>> = if forward {
        Box::new(0..ncy)
    } else {
        Box::new((0..ncy).rev())
    };
    let mut prev_row: Option<usize> = None;
    for y in rows {
        if let Some(p) = prev_row {
            let (row, before) = if p < y {
                let (a, b) = cur.split_at_mut(y * ncx);
                (&mut b[..ncx], &a[p * ncx..(p + 1) * ncx])
            } else {
                let (a, b) = cur.split_at_mut(p * ncx);
                (&mut a[y * ncx..(y + 1) * ncx], &b[..ncx])
            };
            merge_row(row, before, wf, we);
        }
        let row = &mut cur[y * ncx..(y + 1) * ncx];
        if forward {
            for x in 1..ncx {
                row[x] = row[x].min(plus(row[x - 1], wf));
            }
        } else {
            for x in (0..ncx.saturating_sub(1)).rev() {
                row[x] = row[x].min(plus(row[x + 1], wf));
            }
        }
        prev_row = Some(y);
    }
}

/// `row[x] = min(row[x], n[x] + w0, n[x-1] + w1, n[x+1] + w1)` (the side
/// terms only with `w1`; edges use what exists).
#[inline]
fn merge_row(row: &mut [u8], n: &[u8], w0: u8, w1: Option<u8>) {
    let len = row.len();
    let n = &n[..len];
    for (r, &v) in row.iter_mut().zip(n) {
        *r = (*r).min(plus(v, w0));
    }
    if let Some(w1) = w1 {
        if len > 1 {
            for (r, &v) in row[1..].iter_mut().zip(&n[..len - 1]) {
                *r = (*r).min(plus(v, w1));
            }
            for (r, &v) in row[..len - 1].iter_mut().zip(&n[1..]) {
                *r = (*r).min(plus(v, w1));
            }
        }
    }
}

/// The city-block and chamfer slices of one pass.
struct DdaPass {
    /// `[city block, chamfer]` of the slice done last (empty before the
    /// first) and of the current one.
    prev: [Vec<u8>; 2],
    cur: [Vec<u8>; 2],
}

const DDA_METRICS: [DdaMetric; 2] = [DdaMetric::Cityblock, DdaMetric::Chamfer];

impl DdaPass {
    fn new(n: usize) -> DdaPass {
        DdaPass {
            prev: [Vec::new(), Vec::new()],
            cur: [vec![0; n], vec![0; n]],
        }
    }

    /// Runs both metrics on `cur` (already holding the start values).
    fn run(&mut self, ncx: usize, ncy: usize, forward: bool) {
        let [c0, c1] = &mut self.cur;
        let (p0, p1) = (&self.prev[0], &self.prev[1]);
        let o0 = (!p0.is_empty()).then_some(&p0[..]);
        let o1 = (!p1.is_empty()).then_some(&p1[..]);
        rayon::join(
            || dda_slice(DDA_METRICS[0], c0, o0, ncx, ncy, forward),
            || dda_slice(DDA_METRICS[1], c1, o1, ncx, ncy, forward),
        );
    }

    /// The current slice becomes the previous one.
    fn advance(&mut self) {
        std::mem::swap(&mut self.prev, &mut self.cur);
        for c in self.cur.iter_mut() {
            c.resize(self.prev[0].len(), 0);
        }
    }
}

/// Bytes per cell slice of the forward spill record: the chessboard
/// forward values, plus the city-block and chamfer ones with DDA planes.
pub fn spill_record(n_cells_slice: usize, dda: bool) -> usize {
    n_cells_slice * if dda { 3 } else { 1 }
}

/// Block size (cells per axis) of the anisotropic codes. Each block keeps,
/// per octant, the smallest code of its cells: conservative, and 8 bytes
/// per 64 cells instead of 8 bytes per cell (docs/FORMAT.md).
pub const ANISO_BLOCK: usize = 4;

/// Octant `o` (0..8): bit `k` set means the ray's component along axis `k`
/// is negative, so the macro region extends towards lower indices on that
/// axis (paper eqs. 13-15).
#[inline]
pub fn octant_negative(o: usize, axis: usize) -> bool {
    o >> axis & 1 == 1
}

/// One slice of the one-sided chessboard distance of octant `o` (paper
/// Fig. 10: one pass per octant, starting from the opposite corner).
/// `dist` is the isotropic distance of this slice (only `== 0`, a 1-cell,
/// is used). `prev` is this octant's slice one step in its z direction,
/// `None` beyond the volume.
///
/// Per row, in the octant's y order: the column minimum of the three
/// neighbour rows already known (this slice's row one step in y, the
/// previous slice's rows at y and one step in y), then its minimum with
/// the neighbour one step in x, then one scan along x in the octant's x
/// order that adds the row's own neighbour. The first two are whole-row
/// passes without branches, which the compiler vectorises; the scan is a
/// running minimum.
pub fn octant_slice(
    o: usize,
    dist: &[u8],
    prev: Option<&[u8]>,
    ncx: usize,
    ncy: usize,
    out: &mut [u8],
) {
    let x_neg = octant_negative(o, 0);
    let y_neg = octant_negative(o, 1);
    let mut col = vec![FAR; ncx];
    let mut m = vec![FAR; ncx];
    for i in 0..ncy {
        let y = if y_neg { i } else { ncy - 1 - i };
        // The neighbour row one step in the octant's y direction.
        let yn = if y_neg {
            y.checked_sub(1)
        } else {
            (y + 1 < ncy).then_some(y + 1)
        };
        col.fill(FAR);
        let mut fold = |r: &[u8]| {
            for (c, &v) in col.iter_mut().zip(r) {
                *c = (*c).min(v);
            }
        };
        if let Some(yn) = yn {
            fold(&out[yn * ncx..(yn + 1) * ncx]);
        }
        if let Some(p) = prev {
            fold(&p[y * ncx..(y + 1) * ncx]);
            if let Some(yn) = yn {
                fold(&p[yn * ncx..(yn + 1) * ncx]);
            }
        }
        // `m[x] = min(col[x], col[x + sx])`, FAR beyond the row.
        if ncx > 0 {
            if x_neg {
                m[0] = col[0];
                for ((d, &a), &b) in m[1..].iter_mut().zip(&col[1..]).zip(&col[..ncx - 1]) {
                    *d = a.min(b);
                }
            } else {
                m[ncx - 1] = col[ncx - 1];
                for ((d, &a), &b) in m[..ncx - 1].iter_mut().zip(&col[..ncx - 1]).zip(&col[1..]) {
                    *d = a.min(b);
                }
            }
        }
        let row = &mut out[y * ncx..(y + 1) * ncx];
        let d_row = &dist[y * ncx..(y + 1) * ncx];
        // The scan `r = 0` at a 1-cell, else `min(m, r_before) + 1`,
        // saturating, is `min(255, min over k <= i of (m'_k + i - k))`
        // with `m'` 0 at a 1-cell and `m + 1` elsewhere (`i`, `k`:
        // positions in scan order): one running minimum of `m'_k - k`,
        // so each cell waits on one `min` instead of a compare, a `min`,
        // an add and a select.
        // In i64, where `k` and `i` cannot overflow.
        let mut best = i64::MAX / 2;
        let mut cell = |i: usize, r: &mut u8, d: u8, m: u8| {
            let mp = if d == 0 { 0 } else { m as i64 + 1 };
            best = best.min(mp - i as i64);
            *r = (best + i as i64).min(FAR as i64) as u8;
        };
        if x_neg {
            for (i, ((r, &d), &mm)) in row.iter_mut().zip(d_row).zip(&m).enumerate() {
                cell(i, r, d, mm);
            }
        } else {
            for (i, ((r, &d), &mm)) in row.iter_mut().zip(d_row).zip(&m).rev().enumerate() {
                cell(i, r, d, mm);
            }
        }
    }
}

/// Reduces one slice of octant distances into the running per-block code
/// minimum of its block row: `blocks[(by * nbx) + bx] = min(.., d - 1)`,
/// with 1-cells counting as code 0.
pub fn reduce_blocks(dist: &[u8], ncx: usize, ncy: usize, blocks: &mut [u8]) {
    let nbx = ncx.div_ceil(ANISO_BLOCK);
    for (y, row) in dist.chunks_exact(ncx).take(ncy).enumerate() {
        let bs = &mut blocks[y / ANISO_BLOCK * nbx..][..nbx];
        // `d.max(1) - 1` is monotone, so it applies to the run's minimum.
        for (b, run) in bs.iter_mut().zip(row.chunks(ANISO_BLOCK)) {
            let d = run.iter().fold(u8::MAX, |a, &d| a.min(d));
            *b = (*b).min(d.max(1) - 1);
        }
    }
}

/// Forward half of the streaming transform. Feed it the class slices in
/// increasing z; it spills `F(z)` at index z of `spill`.
pub struct ForwardDt {
    ncx: usize,
    ncy: usize,
    z: usize,
    prev: Vec<u8>,
    cur: Vec<u8>,
    aniso: Option<AnisoPass>,
    dda: Option<DdaPass>,
    /// The spill record (chessboard, city block, chamfer) with DDA planes.
    record: Vec<u8>,
}

/// Four octants computed in one z direction, reduced to blocks.
struct AnisoPass {
    /// Octants handled in this pass (z bit fixed).
    octants: [usize; 4],
    prev: [Vec<u8>; 4],
    cur: [Vec<u8>; 4],
    /// Running block minima of the current block slab, per octant.
    blocks: [Vec<u8>; 4],
}

impl AnisoPass {
    fn new(z_negative: bool, ncx: usize, ncy: usize) -> AnisoPass {
        let zb = if z_negative { 4 } else { 0 };
        let nb = ncx.div_ceil(ANISO_BLOCK) * ncy.div_ceil(ANISO_BLOCK);
        AnisoPass {
            octants: [zb, zb + 1, zb + 2, zb + 3],
            prev: std::array::from_fn(|_| Vec::new()),
            cur: std::array::from_fn(|_| vec![0; ncx * ncy]),
            blocks: std::array::from_fn(|_| vec![u8::MAX; nb]),
        }
    }

    /// Advances every octant by one slice and folds it into the blocks.
    fn push(&mut self, dist: &[u8], ncx: usize, ncy: usize) {
        let octants = self.octants;
        self.cur
            .par_iter_mut()
            .zip(self.prev.par_iter())
            .zip(self.blocks.par_iter_mut())
            .enumerate()
            .for_each(|(i, ((cur, prev), blocks))| {
                let p = if prev.is_empty() {
                    None
                } else {
                    Some(&prev[..])
                };
                octant_slice(octants[i], dist, p, ncx, ncy, cur);
                reduce_blocks(cur, ncx, ncy, blocks);
            });
        std::mem::swap(&mut self.prev, &mut self.cur);
        for c in self.cur.iter_mut() {
            c.resize(ncx * ncy, 0);
        }
    }

    /// Takes the finished block slab (4 octants, concatenated) and resets.
    fn take_blocks(&mut self) -> Vec<u8> {
        let mut out = Vec::new();
        for b in self.blocks.iter_mut() {
            out.extend_from_slice(b);
            b.fill(u8::MAX);
        }
        out
    }
}

impl ForwardDt {
    pub fn new(ncx: usize, ncy: usize, aniso: bool) -> ForwardDt {
        ForwardDt {
            ncx,
            ncy,
            z: 0,
            prev: vec![0; ncx * ncy],
            cur: vec![0; ncx * ncy],
            aniso: aniso.then(|| AnisoPass::new(true, ncx, ncy)),
            dda: None,
            record: Vec::new(),
        }
    }

    /// Also runs the forward city-block and chamfer passes; the spill
    /// record grows to [`spill_record`]`(n, true)` bytes.
    pub fn with_dda(mut self, dda: bool) -> ForwardDt {
        let n = self.ncx * self.ncy;
        self.dda = dda.then(|| DdaPass::new(n));
        self.record = if dda { vec![0; 3 * n] } else { Vec::new() };
        self
    }

    /// Starts at cell slice `z0` instead of 0, as the forward pass of a
    /// shard of a sharded prep ([`seam`]): `below` is `F(z0 - 1)`, the
    /// forward distances of the slice under it, or `None` to count only
    /// the shard's own 1-cells. Spills at indices from `z0` on.
    pub fn starting_at(mut self, z0: usize, below: Option<&[u8]>) -> ForwardDt {
        self.z = z0;
        match below {
            Some(p) => self.prev.copy_from_slice(p),
            None => self.prev.fill(FAR),
        }
        self
    }

    /// Consumes the class slice `z` (in order) and spills `F(z)`. With
    /// anisotropic codes, the -z octants' block slab goes to `block_spill`
    /// at index `z / ANISO_BLOCK` when it is complete (or at `last`).
    pub fn push(
        &mut self,
        obj: &[u8],
        last: bool,
        spill: &mut dyn Spill,
        block_spill: Option<&mut dyn Spill>,
    ) -> io::Result<()> {
        let (ncx, ncy) = (self.ncx, self.ncy);
        slice_chessboard(obj, ncx, ncy, &mut self.cur);
        if self.z > 0 {
            merge_slice(&mut self.cur, &self.prev, ncx, ncy);
        }
        match self.dda.as_mut() {
            None => spill.put(self.z, &self.cur)?,
            Some(d) => {
                let n = ncx * ncy;
                for (c, &o) in d.cur.iter_mut().flat_map(|c| c.iter_mut().zip(obj)) {
                    *c = if o != 0 { 0 } else { DDA_FAR };
                }
                d.run(ncx, ncy, true);
                self.record[..n].copy_from_slice(&self.cur);
                self.record[n..2 * n].copy_from_slice(&d.cur[0]);
                self.record[2 * n..].copy_from_slice(&d.cur[1]);
                spill.put(self.z, &self.record)?;
                d.advance();
            }
        }
        if let Some(a) = self.aniso.as_mut() {
            // The isotropic in-slice D2 is 0 exactly on 1-cells; F(z) too.
            a.push(&self.cur, ncx, ncy);
            if (self.z + 1).is_multiple_of(ANISO_BLOCK) || last {
                let blocks = a.take_blocks();
                if let Some(bs) = block_spill {
                    bs.put(self.z / ANISO_BLOCK, &blocks)?;
                }
            }
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.z += 1;
        Ok(())
    }
}

/// Backward half: reads `F` back in decreasing z and yields the final
/// distances `G(z)` (and, with anisotropic codes, each completed block
/// slab's 8 octant codes) to `emit`.
pub struct BackwardDt {
    ncx: usize,
    ncy: usize,
    ncz: usize,
    next: Vec<u8>,
    cur: Vec<u8>,
    started: bool,
    aniso: Option<AnisoPass>,
    dda: Option<DdaPass>,
    record: Vec<u8>,
}

/// The 8 octant block codes of one block slab: `codes[o][by * nbx + bx]`.
pub type OctantBlocks = [Vec<u8>; 8];

impl BackwardDt {
    pub fn new(ncx: usize, ncy: usize, ncz: usize, aniso: bool) -> BackwardDt {
        BackwardDt {
            ncx,
            ncy,
            ncz,
            next: vec![0; ncx * ncy],
            cur: vec![0; ncx * ncy],
            started: false,
            aniso: aniso.then(|| AnisoPass::new(false, ncx, ncy)),
            dda: None,
            record: Vec::new(),
        }
    }

    /// Also finishes the city-block and chamfer transforms (the spill must
    /// come from a [`ForwardDt::with_dda`] with the same flag).
    pub fn with_dda(mut self, dda: bool) -> BackwardDt {
        let n = self.ncx * self.ncy;
        self.dda = dda.then(|| DdaPass::new(n));
        self.record = if dda { vec![0; 3 * n] } else { Vec::new() };
        self
    }

    /// Continues from the final distances `above` of the cell slice over
    /// the first one [`BackwardDt::step`] is given (a shard's top, [`seam`]).
    pub fn seeded(mut self, above: &[u8]) -> BackwardDt {
        self.cur.copy_from_slice(above);
        self.started = true;
        self
    }

    /// The final city-block and chamfer distances of the slice the last
    /// [`BackwardDt::step`] computed (`None` without DDA planes).
    pub fn dda(&self) -> Option<[&[u8]; 2]> {
        // After `step`, `advance` has moved the slice into `prev`.
        self.dda.as_ref().map(|d| [&d.prev[0][..], &d.prev[1][..]])
    }

    /// Computes `G(z)` for the next z (they must come in decreasing order,
    /// starting at `ncz - 1`). Returns the distances of slice z, and the
    /// octant blocks when z starts a block slab.
    pub fn step(
        &mut self,
        z: usize,
        spill: &mut dyn Spill,
        block_spill: Option<&mut dyn Spill>,
    ) -> io::Result<(&[u8], Option<OctantBlocks>)> {
        debug_assert!(z < self.ncz);
        let (ncx, ncy) = (self.ncx, self.ncy);
        std::mem::swap(&mut self.next, &mut self.cur);
        match self.dda.as_mut() {
            None => spill.get(z, &mut self.cur)?,
            Some(d) => {
                let n = ncx * ncy;
                spill.get(z, &mut self.record)?;
                self.cur.copy_from_slice(&self.record[..n]);
                d.cur[0].copy_from_slice(&self.record[n..2 * n]);
                d.cur[1].copy_from_slice(&self.record[2 * n..]);
                d.run(ncx, ncy, false);
                d.advance();
            }
        }
        if self.started {
            merge_slice(&mut self.cur, &self.next, ncx, ncy);
        }
        self.started = true;
        let mut blocks_out = None;
        if let Some(a) = self.aniso.as_mut() {
            a.push(&self.cur, ncx, ncy);
            if z.is_multiple_of(ANISO_BLOCK) {
                let pos = a.take_blocks();
                let nb = pos.len() / 4;
                let mut neg = vec![0u8; 4 * nb];
                if let Some(bs) = block_spill {
                    bs.get(z / ANISO_BLOCK, &mut neg)?;
                }
                blocks_out = Some(std::array::from_fn(|o| {
                    let src = if o >= 4 { &neg } else { &pos };
                    let i = o % 4;
                    src[i * nb..(i + 1) * nb].to_vec()
                }));
            }
        }
        Ok((&self.cur, blocks_out))
    }
}

/// Whole-volume transform in memory through the streaming passes (tests,
/// benchmarks, small volumes). `obj` is `ncx * ncy * ncz` with x fastest.
pub fn chessboard_3d(obj: &[u8], dims: [usize; 3]) -> Vec<u8> {
    let [ncx, ncy, ncz] = dims;
    let n = ncx * ncy;
    let mut spill = MemSpill::default();
    let mut fwd = ForwardDt::new(ncx, ncy, false);
    for z in 0..ncz {
        fwd.push(&obj[z * n..(z + 1) * n], z + 1 == ncz, &mut spill, None)
            .expect("memory spill");
    }
    let mut out = vec![0u8; n * ncz];
    let mut bwd = BackwardDt::new(ncx, ncy, ncz, false);
    for z in (0..ncz).rev() {
        let (g, _) = bwd.step(z, &mut spill, None).expect("memory spill");
        out[z * n..(z + 1) * n].copy_from_slice(g);
    }
    out
}

/// Anisotropic block codes in memory through the streaming passes:
/// `result[o]` holds, per block (x fastest), octant `o`'s code.
pub fn octant_blocks_3d(obj: &[u8], dims: [usize; 3]) -> [Vec<u8>; 8] {
    let [ncx, ncy, ncz] = dims;
    let n = ncx * ncy;
    let nb = ncx.div_ceil(ANISO_BLOCK) * ncy.div_ceil(ANISO_BLOCK);
    let nbz = ncz.div_ceil(ANISO_BLOCK);
    let mut spill = MemSpill::default();
    let mut bspill = MemSpill::default();
    let mut fwd = ForwardDt::new(ncx, ncy, true);
    for z in 0..ncz {
        fwd.push(
            &obj[z * n..(z + 1) * n],
            z + 1 == ncz,
            &mut spill,
            Some(&mut bspill),
        )
        .expect("memory spill");
    }
    let mut out: [Vec<u8>; 8] = std::array::from_fn(|_| vec![0u8; nb * nbz]);
    let mut bwd = BackwardDt::new(ncx, ncy, ncz, true);
    for z in (0..ncz).rev() {
        let (_, blocks) = bwd
            .step(z, &mut spill, Some(&mut bspill))
            .expect("memory spill");
        if let Some(b) = blocks {
            let bz = z / ANISO_BLOCK;
            for o in 0..8 {
                out[o][bz * nb..(bz + 1) * nb].copy_from_slice(&b[o]);
            }
        }
    }
    out
}

/// City-block and chamfer 3-4-5 distances in memory through the streaming
/// passes: `[city block, chamfer]`, x fastest, saturated at [`DDA_FAR`].
pub fn dda_3d(obj: &[u8], dims: [usize; 3]) -> [Vec<u8>; 2] {
    let [ncx, ncy, ncz] = dims;
    let n = ncx * ncy;
    let mut spill = MemSpill::default();
    let mut fwd = ForwardDt::new(ncx, ncy, false).with_dda(true);
    for z in 0..ncz {
        fwd.push(&obj[z * n..(z + 1) * n], z + 1 == ncz, &mut spill, None)
            .expect("memory spill");
    }
    let mut out = [vec![0u8; n * ncz], vec![0u8; n * ncz]];
    let mut bwd = BackwardDt::new(ncx, ncy, ncz, false).with_dda(true);
    for z in (0..ncz).rev() {
        bwd.step(z, &mut spill, None).expect("memory spill");
        let planes = bwd.dda().expect("dda pass");
        for (o, p) in out.iter_mut().zip(planes) {
            o[z * n..(z + 1) * n].copy_from_slice(p);
        }
    }
    out
}

#[cfg(test)]
mod tests;
