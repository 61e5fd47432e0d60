//! The seams of a sharded distance transform (`prep --shard K/N`,
//! docs/DESIGN.md, "Sharded prep").
//!
//! A shard holds the cell slices `z0..z1` of whole brick layers. Both
//! passes of the transform are min-plus linear: a slice's distances are
//! the minimum, over the 1-cells, of each one's contribution. So a shard
//! that knows only its own 1-cells misses two planes' worth of
//! information, and nothing else:
//!
//! * going up, `F(z0 - 1)`, the forward distances of the slice under it
//!   (the distance to every 1-cell at or below it). Carried `d` slices
//!   further up through empty slices, a plane `P` becomes
//!   [`propagate`]`(P, d)`: `min(FAR, min over |dx|, |dy| <= d of P + d)`,
//!   the forward recurrence `F(z) = min(F(z), erode_xy(F(z-1)) + 1)`
//!   applied `d` times to slices without 1-cells;
//! * going down, `G(z1)` restricted to the 1-cells at or above `z1`.
//!
//! A shard's first pass (classify and forward transform from nothing)
//! gives its top plane `F_own(z1 - 1)`, and a short backward pass over its
//! lowest 255 slices gives its bottom plane `U`, the distance from slice
//! `z0` to its own 1-cells. Two chains ([`SeamChain`]) then carry the
//! planes across the shards, bottom to top and top to bottom: the true
//! `F(z1 - 1) = min(F_own(z1 - 1), propagate(F(z0 - 1), z1 - z0))`, and
//! the distance from `z0` to every 1-cell at or above it is
//! `min(U, propagate(that of z1, z1 - z0))`. With both, the second pass
//! corrects the lowest slices of its forward spill ([`fix_forward`]) and
//! runs the backward transform from the plane above
//! ([`super::BackwardDt::seeded`]): the distances equal a single pass's,
//! byte for byte, whatever the shards' depths.
//!
//! Saturation at [`FAR`] keeps this exact: every value is `min(FAR,
//! exact)`, and `min` with a constant commutes with the erosion and `+ d`.

use std::io;

use rayon::prelude::*;

use super::{merge_slice, Spill, FAR};

/// `min(FAR, min over |dx|, |dy| <= d of plane[x + dx, y + dy] + d)`: a
/// plane of distances carried `d` cell slices through slices without
/// 1-cells (the forward or backward recurrence applied `d` times). `plane`
/// is `ncx * ncy`, x fastest.
pub fn propagate(plane: &[u8], ncx: usize, ncy: usize, d: usize) -> Vec<u8> {
    assert_eq!(plane.len(), ncx * ncy, "a plane of ncx * ncy cells");
    if d == 0 {
        return plane.to_vec();
    }
    if d >= FAR as usize {
        return vec![FAR; plane.len()];
    }
    let mut rows = plane.to_vec();
    rows.par_chunks_mut(ncx.max(1))
        .for_each(|r| window_min(r, d));
    // Columns: transpose, filter as rows, transpose back.
    let mut cols = vec![0u8; plane.len()];
    transpose(&rows, ncx, ncy, &mut cols);
    cols.par_chunks_mut(ncy.max(1))
        .for_each(|c| window_min(c, d));
    transpose(&cols, ncy, ncx, &mut rows);
    let add = d as u8;
    rows.iter_mut().for_each(|v| *v = v.saturating_add(add));
    rows
}

/// `a[i] = min(a[j] for |j - i| <= r)` over the slice (the van Herk /
/// Gil-Werman sliding minimum: two running minima per block of `2r + 1`,
/// whatever `r`).
fn window_min(a: &mut [u8], r: usize) {
    let n = a.len();
    let w = 2 * r + 1;
    // `a` padded with FAR by r on each side, then rounded up to blocks.
    let len = (n + 2 * r).div_ceil(w) * w;
    let mut pad = vec![FAR; len];
    pad[r..r + n].copy_from_slice(a);
    let mut g = pad.clone();
    let mut h = pad.clone();
    for b in (0..len).step_by(w) {
        for i in b + 1..b + w {
            g[i] = g[i].min(g[i - 1]);
        }
        for i in (b..b + w - 1).rev() {
            h[i] = h[i].min(h[i + 1]);
        }
    }
    // Window of padded i + r (the cell i): pad[i ..= i + 2r].
    for (i, v) in a.iter_mut().enumerate() {
        *v = h[i].min(g[i + 2 * r]);
    }
}

/// `out[x * ny + y] = a[y * nx + x]`.
fn transpose(a: &[u8], nx: usize, ny: usize, out: &mut [u8]) {
    const T: usize = 64;
    for y0 in (0..ny).step_by(T) {
        for x0 in (0..nx).step_by(T) {
            for y in y0..(y0 + T).min(ny) {
                for x in x0..(x0 + T).min(nx) {
                    out[x * ny + y] = a[y * nx + x];
                }
            }
        }
    }
}

/// One chain of the seam exchange: the plane carried from shard to shard
/// (upwards: the forward distances under the next shard; downwards: the
/// distance from the next shard's top to the 1-cells above it).
pub struct SeamChain {
    ncx: usize,
    ncy: usize,
    plane: Option<Vec<u8>>,
}

impl SeamChain {
    /// A chain that has crossed no shard yet (no 1-cells beyond).
    pub fn new(ncx: usize, ncy: usize) -> SeamChain {
        SeamChain {
            ncx,
            ncy,
            plane: None,
        }
    }

    /// Crosses a shard of `depth` cell slices whose own plane on the far
    /// side is `own`: `min(own, propagate(carried, depth))`.
    pub fn cross(&mut self, own: &[u8], depth: usize) {
        let mut next = own.to_vec();
        if let Some(p) = &self.plane {
            let carried = propagate(p, self.ncx, self.ncy, depth);
            next.iter_mut()
                .zip(&carried)
                .for_each(|(a, &b)| *a = (*a).min(b));
        }
        self.plane = Some(next);
    }

    /// The carried plane; `None` before the first shard.
    pub fn plane(&self) -> Option<&[u8]> {
        self.plane.as_deref()
    }
}

/// Corrects a shard's forward spill, written from its own 1-cells alone
/// ([`super::ForwardDt::starting_at`] without a plane below), for the
/// 1-cells below it: `below` is the true `F(z0 - 1)`. Rewrites the
/// records of slices `z0..z1` in order, `F(z) = min(F_own(z),
/// erode_xy(F(z-1)) + 1)`, and stops at the first slice it leaves
/// unchanged (the recurrence is then the shard's own from there on: at
/// most 255 slices). Idempotent. Returns the slices rewritten.
pub fn fix_forward(
    spill: &mut dyn Spill,
    below: &[u8],
    z0: usize,
    z1: usize,
    ncx: usize,
    ncy: usize,
) -> io::Result<usize> {
    let mut prev = below.to_vec();
    let mut cur = vec![0u8; below.len()];
    let mut own = vec![0u8; below.len()];
    for z in z0..z1 {
        spill.get(z, &mut own)?;
        cur.copy_from_slice(&own);
        merge_slice(&mut cur, &prev, ncx, ncy);
        if cur == own {
            return Ok(z - z0);
        }
        spill.put(z, &cur)?;
        std::mem::swap(&mut prev, &mut cur);
    }
    Ok(z1 - z0)
}

/// A shard's bottom plane: `min(FAR, chessboard distance from cell (x, y,
/// z0) to the shard's own 1-cells)`, from its forward spill of slices
/// `z0..z1` (written from its own 1-cells alone): the backward recurrence
/// over the lowest 255 slices, since 1-cells further up are at least
/// [`FAR`] away.
pub fn local_bottom(
    spill: &mut dyn Spill,
    z0: usize,
    z1: usize,
    ncx: usize,
    ncy: usize,
) -> io::Result<Vec<u8>> {
    let n = ncx * ncy;
    let top = z1.min(z0 + FAR as usize);
    let mut g = vec![FAR; n];
    let mut cur = vec![0u8; n];
    for z in (z0..top).rev() {
        spill.get(z, &mut cur)?;
        merge_slice(&mut cur, &g, ncx, ncy);
        std::mem::swap(&mut g, &mut cur);
    }
    Ok(g)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `propagate` by its definition, cell by cell.
    fn brute(plane: &[u8], ncx: usize, ncy: usize, d: usize) -> Vec<u8> {
        let mut out = vec![FAR; plane.len()];
        for y in 0..ncy {
            for x in 0..ncx {
                let mut m = u32::MAX;
                for yy in y.saturating_sub(d)..(y + d + 1).min(ncy) {
                    for xx in x.saturating_sub(d)..(x + d + 1).min(ncx) {
                        m = m.min(plane[yy * ncx + xx] as u32);
                    }
                }
                out[y * ncx + x] = (m + d as u32).min(FAR as u32) as u8;
            }
        }
        out
    }

    proptest::proptest! {
        #[test]
        fn propagate_is_the_windowed_minimum(
            ncx in 1usize..20,
            ncy in 1usize..20,
            d in proptest::prop_oneof![0usize..12, 250usize..300],
            seed in proptest::collection::vec(0u8..=255, 400),
        ) {
            let plane: Vec<u8> = seed[..ncx * ncy].to_vec();
            proptest::prop_assert_eq!(
                propagate(&plane, ncx, ncy, d),
                brute(&plane, ncx, ncy, d)
            );
        }
    }

    /// `propagate(P, d)` is the forward recurrence applied `d` times to
    /// empty slices (what the seam chains rely on).
    #[test]
    fn propagate_is_the_recurrence_over_empty_slices() {
        let (ncx, ncy) = (13, 9);
        let plane: Vec<u8> = (0..ncx * ncy).map(|i| (i * 37 % 23) as u8).collect();
        let mut p = plane.clone();
        for d in 1..30 {
            let mut next = vec![FAR; ncx * ncy];
            merge_slice(&mut next, &p, ncx, ncy);
            p = next;
            assert_eq!(propagate(&plane, ncx, ncy, d), p, "d {d}");
        }
    }
}
