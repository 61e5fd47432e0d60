//! Render-time classification inside the file's envelope (`render
//! --iso`, issue 16).
//!
//! A file's codes were computed for its classification C. For a narrower
//! classification C' whose 1-cells all lie among C's (an iso value at or
//! above the file's), they stay valid, conservative leaps: a cell's
//! chessboard distance to the nearest C'-1-cell is at least its distance
//! to the nearest C-1-cell (paper section 4: a code only has to be a lower
//! bound of the distance for the traversal to stay exact). And every
//! vertex of every C-1-cell keeps its exact value in the file, so C'
//! decides its 1-cells from exact values. So C' renders exactly from a
//! file prepared for C, with no new prep.
//!
//! [`narrow`] rewrites each decoded brick for C' (module cache calls it
//! when [`Planes::narrow`](super::cache::Planes::narrow) is set):
//! 1. **Classes.** A C-1-cell stays a 1-cell when its largest vertex value
//!    is at least the scene's iso value; otherwise it becomes a 0-cell.
//! 2. **Codes, tightened.** Left at 0, the new 0-cells would cost a
//!    single step each, and a scene much narrower than the envelope (bone
//!    from a file prepared for skin) would walk cell by cell through
//!    what it no longer shows. So each brick gets its own chessboard
//!    distance transform ([`local_distances`]), with every cell outside the
//!    brick counted as a 1-cell: a lower bound of the true distance, hence
//!    conservative. Each 0-cell keeps the larger of its file code and the
//!    local one; both are conservative, so the larger is.
//! 3. **What a file prepared for C' would hold.** A brick left without
//!    1-cells drops its values (a reader decodes such a brick without
//!    them), and the minimum corner of a 0-cell whose code is now at least
//!    1 (at least 2 in a `--gradient-halo` file) reads as missing (NaN),
//!    as its word would carry that code. Sampling never reads those
//!    samples; smooth normals do (module gradient), so shading matches a
//!    file prepared for C' where this can see it. A sample one cell
//!    outside a brick is judged by [`scene_code_at_least_1`] when
//!    normals need it.
//!
//! Values compare with the iso value in f32, as the hit test does
//! ([`to_f32`](super::cache::to_f32)): the classes are those of a file
//! prepared at V whenever V and the data are exact in f32 (every integer
//! value of 8-, 12- and 16-bit data).
//!
//! Surface and depth images are then byte-identical to those from a file
//! prepared at the scene's iso value (tests/all/scene.rs); cost maps differ
//! by design, since they show the steps.

use super::cache::{Accessor, Codes, RBrick};
use super::traverse::OBJECT;

/// Rewrites brick `b` (decoded for the file's classification) for the
/// scene's iso value `iso` (module docs). `halo`: the file was prepared
/// with `--gradient-halo`.
pub(crate) fn narrow(b: &mut RBrick, iso: f32, halo: bool) {
    if b.values.is_empty() {
        // No 1-cell of the file's: none of the scene's; codes stand.
        return;
    }
    let Codes::Plane(plane) = &mut b.codes else {
        return;
    };
    let [cx, cy, cz] = b.cells.map(|c| c as usize);
    let (sx, sy) = (cx + 1, cy + 1);
    // NaN compares false: never above.
    let above: Vec<bool> = b.values.iter().map(|&v| v >= iso).collect();
    let (mut any, mut demoted) = (false, 0usize);
    for z in 0..cz {
        for y in 0..cy {
            for x in 0..cx {
                let i = (z * cy + y) * cx + x;
                if plane[i] != OBJECT {
                    continue;
                }
                let s = (z * sy + y) * sx + x;
                let (r, l) = (sx, sx * sy);
                let obj = above[s]
                    | above[s + 1]
                    | above[s + r]
                    | above[s + r + 1]
                    | above[s + l]
                    | above[s + l + 1]
                    | above[s + l + r]
                    | above[s + l + r + 1];
                if obj {
                    any = true;
                } else {
                    plane[i] = 0;
                    demoted += 1;
                }
            }
        }
    }
    if demoted == 0 {
        // The scene's 1-cells here are the file's: its codes and values
        // stand (a code 0 inside the brick still has a scene 1-cell
        // next to it, as [`scene_code_at_least_1`] relies on).
        return;
    }
    let local = local_distances(plane, b.cells);
    let min_embedded = if halo { 2 } else { 1 };
    for z in 0..cz {
        for y in 0..cy {
            for x in 0..cx {
                let i = (z * cy + y) * cx + x;
                if plane[i] == OBJECT {
                    continue;
                }
                let code = plane[i].max(local[i] - 1);
                plane[i] = code;
                if any && code >= min_embedded {
                    b.values[(z * sy + y) * sx + x] = f32::NAN;
                }
            }
        }
    }
    if !any {
        b.values = Vec::new();
    }
}

/// The largest distance [`local_distances`] gives: every value then stays
/// below 255 after adding one, so its sweeps need no saturation.
pub(crate) const FAR: u8 = 254;

/// The chessboard distance of every cell of a brick (`cells` per axis, x
/// fastest; `plane[i] == OBJECT` marks a 1-cell) to the nearest 1-cell,
/// counting every cell outside the brick as a 1-cell: 0 for a 1-cell, 1
/// on the brick's outer layer, at most [`FAR`].
///
/// Two raster passes with the 3x3x3 mask of unit weights (Rosenfeld and
/// Pfaltz's sequential chessboard transform in 3D), exact for the
/// chessboard metric; each pass takes per cell the smallest of the 3x3
/// eroded slice before, the 3-eroded row before and the cell before, plus
/// one. The brick is padded by one layer of 1-cells, the outside.
pub(crate) fn local_distances(plane: &[u8], cells: [u32; 3]) -> Vec<u8> {
    let [cx, cy, cz] = cells.map(|c| c as usize);
    let (px, py, pz) = (cx + 2, cy + 2, cz + 2);
    let at = |x: usize, y: usize, z: usize| (z * py + y) * px + x;
    let mut d = vec![0u8; px * py * pz];
    for z in 0..cz {
        for y in 0..cy {
            let row = &plane[(z * cy + y) * cx..(z * cy + y + 1) * cx];
            let o = at(1, y + 1, z + 1);
            for (dst, &c) in d[o..o + cx].iter_mut().zip(row) {
                *dst = if c == OBJECT { 0 } else { FAR };
            }
        }
    }
    // Per pass and slice: the slice before it (in the pass's order),
    // eroded over its 3x3 neighbourhoods; per row, the row before it
    // eroded over x, merged with that into `cand`, then the sweep along
    // x, which alone carries a dependency from cell to cell.
    let mut ex = vec![0u8; px * py];
    let mut exy = vec![0u8; px * py];
    let mut prev = vec![0u8; px];
    let mut cand = vec![0u8; px];
    for forward in [true, false] {
        for zi in 0..cz {
            let z = if forward { 1 + zi } else { cz - zi };
            let zn = if forward { z - 1 } else { z + 1 };
            let slice = &d[at(0, 0, zn)..at(0, 0, zn) + px * py];
            for (src, dst) in slice.chunks_exact(px).zip(ex.chunks_exact_mut(px)) {
                erode3(src, dst);
            }
            for y in 1..=cy {
                let (a, b, c) = (
                    &ex[(y - 1) * px..y * px],
                    &ex[y * px..(y + 1) * px],
                    &ex[(y + 1) * px..(y + 2) * px],
                );
                for (o, ((&a, &b), &c)) in exy[y * px..(y + 1) * px]
                    .iter_mut()
                    .zip(a.iter().zip(b).zip(c))
                {
                    *o = a.min(b).min(c);
                }
            }
            for yi in 0..cy {
                let y = if forward { 1 + yi } else { cy - yi };
                let yn = if forward { y - 1 } else { y + 1 };
                erode3(&d[at(0, yn, z)..at(0, yn, z) + px], &mut prev);
                for (o, (&a, &b)) in cand
                    .iter_mut()
                    .zip(exy[y * px..(y + 1) * px].iter().zip(&prev))
                {
                    *o = a.min(b) + 1;
                }
                let row = &mut d[at(0, y, z)..at(0, y, z) + px];
                if forward {
                    for x in 1..=cx {
                        row[x] = row[x].min(cand[x]).min(row[x - 1] + 1);
                    }
                } else {
                    for x in (1..=cx).rev() {
                        row[x] = row[x].min(cand[x]).min(row[x + 1] + 1);
                    }
                }
            }
        }
    }
    let mut out = Vec::with_capacity(cx * cy * cz);
    for z in 0..cz {
        for y in 0..cy {
            let o = at(1, y + 1, z + 1);
            out.extend_from_slice(&d[o..o + cx]);
        }
    }
    out
}

/// `out[x] = min(row[x - 1], row[x], row[x + 1])` for the interior `x`;
/// the ends copy `row` (they are the padding).
fn erode3(row: &[u8], out: &mut [u8]) {
    let n = row.len();
    out[..n].copy_from_slice(row);
    for x in 1..n - 1 {
        out[x] = row[x - 1].min(row[x]).min(row[x + 1]);
    }
}

/// Whether the cell whose minimum corner is global sample `s` has a
/// scene code of at least 1 (no scene 1-cell within chessboard distance
/// 1), so that a file prepared for the scene would carry a code in `s`'s
/// word; false when `s` is the minimum corner of no cell. Called only in
/// narrowed renders (bricks rewritten by [`narrow`]). Where the cell's
/// code cannot tell, reads the samples `s - 1 ..= s + 2` per axis (the
/// vertices of the 27 cells around): a cell is a scene 1-cell when one of
/// its vertices is at least `iso`. `n` are the samples per axis.
pub(crate) fn scene_code_at_least_1(
    acc: &mut Accessor,
    n: [usize; 3],
    s: [usize; 3],
    iso: f32,
) -> bool {
    if (0..3).any(|k| s[k] + 1 >= n[k]) {
        return false;
    }
    // Mostly the cell's code answers: codes are lower bounds of the
    // scene's (1 or more: so is the scene's), and a narrowed brick's code
    // 0 inside its outer layer is the scene's (the local transform found
    // a scene 1-cell next to it). Left: code 0 on a brick's outer layer,
    // where the neighbour that made it 0 may be no scene 1-cell.
    let (b, l) = acc.brick(s.map(|x| x as u32));
    let code = b.code(l);
    if code == OBJECT {
        return false;
    }
    if code >= 1 {
        return true;
    }
    if !b.values.is_empty() && (0..3).all(|k| l[k] >= 1 && l[k] + 2 <= b.cells[k]) {
        return false;
    }
    let lo: [usize; 3] = std::array::from_fn(|k| s[k].saturating_sub(1));
    let hi: [usize; 3] = std::array::from_fn(|k| (s[k] + 2).min(n[k] - 1));
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                if sample(acc, n, [x, y, z]) >= iso {
                    return false;
                }
            }
        }
    }
    true
}

/// Global sample `s` from the brick of cell `min(s, n - 2)` (module
/// gradient's rule); NaN when that brick holds no values.
fn sample(acc: &mut Accessor, n: [usize; 3], s: [usize; 3]) -> f32 {
    let at: [u32; 3] = std::array::from_fn(|k| s[k].min(n[k] - 2) as u32);
    let (b, l) = acc.brick(at);
    if b.values.is_empty() {
        return f32::NAN;
    }
    let ls: [usize; 3] = std::array::from_fn(|k| l[k] as usize + s[k] - at[k] as usize);
    let sx = b.cells[0] as usize + 1;
    let sy = b.cells[1] as usize + 1;
    b.values[(ls[2] * sy + ls[1]) * sx + ls[0]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Chessboard distance by brute force, outside the brick a 1-cell.
    fn brute(plane: &[u8], c: [usize; 3]) -> Vec<u8> {
        let mut out = vec![0u8; plane.len()];
        for z in 0..c[2] {
            for y in 0..c[1] {
                for x in 0..c[0] {
                    let p = [x, y, z];
                    // Distance to the outside: one step past the nearest face.
                    let mut best = (0..3).map(|k| p[k].min(c[k] - 1 - p[k]) + 1).min().unwrap();
                    for (i, &v) in plane.iter().enumerate() {
                        if v == OBJECT {
                            let q = [i % c[0], i / c[0] % c[1], i / (c[0] * c[1])];
                            let d = (0..3).map(|k| p[k].abs_diff(q[k])).max().unwrap();
                            best = best.min(d);
                        }
                    }
                    out[(z * c[1] + y) * c[0] + x] = best.min(254) as u8;
                }
            }
        }
        out
    }

    proptest! {
        #[test]
        fn local_distances_are_the_chessboard_distances(
            c in prop::array::uniform3(1usize..12),
            density in 0.0f64..0.05,
            seed in any::<u64>(),
        ) {
            let n = c[0] * c[1] * c[2];
            let mut s = seed | 1;
            let plane: Vec<u8> = (0..n)
                .map(|_| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    if ((s >> 11) as f64 / (1u64 << 53) as f64) < density { OBJECT } else { 3 }
                })
                .collect();
            let got = local_distances(&plane, c.map(|x| x as u32));
            prop_assert_eq!(got, brute(&plane, c));
        }
    }

    #[test]
    fn an_empty_cube_counts_to_its_centre() {
        let c = [9u32, 9, 9];
        let d = local_distances(&vec![0u8; 729], c);
        assert_eq!(d[(4 * 9 + 4) * 9 + 4], 5);
        assert_eq!(d[0], 1);
    }
}
