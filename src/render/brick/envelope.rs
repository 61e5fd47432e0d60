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
//! when [`Planes::narrow`](crate::render::brick::Planes::narrow) is set):
//! 1. **Classes.** A C-1-cell stays a 1-cell when its largest vertex value
//!    is at least the scene's iso value; otherwise it becomes a 0-cell.
//! 2. **Codes, tightened.** Left at 0, the new 0-cells would cost a
//!    single step each, and a scene much narrower than the envelope (bone
//!    from a file prepared for skin) would walk cell by cell through
//!    what it no longer shows. So each brick gets its own chessboard
//!    distance transform ([`local_distances_any`]), reaching [`REACH`] cells,
//!    with the cells around the brick at lower bounds the index gives
//!    ([`Edge`]: 0 where a neighbour may hold a scene 1-cell): a lower
//!    bound of the true distance, hence conservative. Each 0-cell keeps
//!    the larger of its file code and the local one; both are
//!    conservative, so the larger is. A brick whose index value maximum
//!    (format version 2) lies below the scene's iso value has no scene
//!    1-cell: it is decoded for its codes only and tightened the same way
//!    ([`tighten`]).
//! 3. **What a file prepared for C' would hold.** A brick left without
//!    1-cells drops its values (a reader decodes such a brick without
//!    them), and the minimum corner of a 0-cell whose code is now at least
//!    1 (at least 2 in a `--gradient-halo` file) reads as missing (NaN),
//!    as its word would carry that code. Sampling never reads those
//!    samples; smooth normals do (module gradient), so shading matches a
//!    file prepared for C' where this can see it. A sample one cell
//!    outside a brick is judged by [`scene_code_at_least_1`](crate::render::sample::normals::scene_code_at_least_1) when
//!    normals need it.
//!
//! Values compare with the iso value in f32, as the hit test does
//! ([`to_f32`](crate::render::brick::to_f32)): the classes are those of a file
//! prepared at V whenever V and the data are exact in f32 (every integer
//! value of 8-, 12- and 16-bit data).
//!
//! Surface and depth images are then byte-identical to those from a file
//! prepared at the scene's iso value (tests/all/scene.rs); cost maps differ
//! by design, since they show the steps.

use super::samples::Samples;
use super::{to_f32, Codes, RBrick};
use crate::format::reader::PackedVolume;
use crate::render::traverse::OBJECT;

/// What a narrowed brick knows of the world around it, from the index
/// alone: per neighbour brick, a lower bound of the chessboard distance
/// from each of its cells to the nearest 1-cell of the scene, and the
/// largest code the file's encoding holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Edge {
    /// Indexed `(dz + 1) * 9 + (dy + 1) * 3 + (dx + 1)` for the neighbour
    /// brick at brick offset `(dx, dy, dz)` (13: the brick itself, unused):
    /// - [`FAR`] outside the volume (the file's codes count cells outside
    ///   as empty, module dt);
    /// - the smallest code of its cells plus one for a brick the index
    ///   marks as holding no 1-cell of the file (code `c` means no 1-cell
    ///   within chessboard distance `c`);
    /// - 1 for a brick whose index value maximum lies below the scene's iso
    ///   value (no scene 1-cell in it);
    /// - 0 otherwise (it may hold one).
    pub(crate) pads: [u8; 27],
    /// The file's largest code ([`crate::format::CodeEncoding::max_code`]).
    pub(crate) max_code: u8,
}

impl Edge {
    /// Brick `id`'s neighbourhood for the scene's iso value `iso`.
    pub(crate) fn of(vol: &PackedVolume, id: u64, iso: f32) -> Edge {
        let h = vol.header();
        let c = h.brick_coords(id);
        let mut pads = [0u8; 27];
        for (i, pad) in pads.iter_mut().enumerate() {
            let d = [i % 3, i / 3 % 3, i / 9].map(|k| k as i64 - 1);
            let n: [i64; 3] = std::array::from_fn(|k| c[k] as i64 + d[k]);
            if (0..3).any(|k| n[k] < 0 || n[k] >= h.bricks[k] as i64) {
                *pad = FAR;
                continue;
            }
            let e = vol.index()[h.brick_id(n.map(|x| x as u64)) as usize];
            *pad = if e.has_no_object() {
                e.uniform_code.saturating_add(1).min(FAR as u32) as u8
            } else if e.value_max().is_some_and(|m| to_f32(m) < iso) {
                1
            } else {
                0
            };
        }
        Edge {
            pads,
            max_code: h.codes.max_code().min(FAR as u32 - 1) as u8,
        }
    }

    /// No knowledge: every neighbour may hold a scene 1-cell.
    #[cfg(test)]
    pub(crate) const BLIND: Edge = Edge {
        pads: [0; 27],
        max_code: 253,
    };
}

/// Brick `b`, decoded without values because the scene has none of its
/// 1-cells in it (its index value maximum lies below the scene's iso
/// value): each cell's code becomes the larger of its file code and its
/// local chessboard distance minus one ([`local_distances_any`] with no 1-cell
/// inside and `edge`'s lower bounds outside), what [`narrow`] would make
/// of it from its values.
#[inline(always)]
fn tighten_any(b: &mut RBrick, edge: &Edge) {
    let Codes::Plane(plane) = &mut b.codes else {
        return;
    };
    let local = local_distances_any(&vec![0u8; plane.len()], b.cells, &edge.pads);
    for (c, d) in plane.iter_mut().zip(local) {
        *c = (*c).max((d - 1).min(edge.max_code));
    }
}

/// Rewrites brick `b` (decoded for the file's classification) for the
/// scene's iso value `iso` (module docs); `edge`: what the index says of
/// its neighbours. `halo`: the file was prepared with `--gradient-halo`.
#[inline(always)]
fn narrow_any(b: &mut RBrick, iso: f32, halo: bool, edge: &Edge) {
    if b.values.is_empty() {
        // No 1-cell of the file's: none of the scene's; codes stand.
        return;
    }
    let Codes::Plane(plane) = &mut b.codes else {
        return;
    };
    let [cx, cy, cz] = b.cells.map(|c| c as usize);
    let (sx, sy) = (cx + 1, cy + 1);
    // Per cell, whether one of its 8 vertices is at or above `iso` (NaN
    // compares false: never above): OR over x, then y, then z, each over
    // whole rows or slices so that it vectorises.
    let above: Vec<u8> = b
        .values
        .to_f32()
        .iter()
        .map(|&v| u8::from(v >= iso))
        .collect();
    let sz = cz + 1;
    let mut ox = vec![0u8; cx * sy * sz];
    for (o, r) in ox.chunks_exact_mut(cx).zip(above.chunks_exact(sx)) {
        or2(&r[..cx], &r[1..], o);
    }
    let mut oxy = vec![0u8; cx * cy * sz];
    for (o, sl) in oxy.chunks_exact_mut(cx * cy).zip(ox.chunks_exact(cx * sy)) {
        or2(&sl[..cx * cy], &sl[cx..], o);
    }
    let n = cx * cy * cz;
    let mut cell_above = vec![0u8; n];
    or2(&oxy[..n], &oxy[cx * cy..], &mut cell_above);
    // Demote the file's 1-cells without a vertex at or above `iso`;
    // branch-free, so that it vectorises.
    let (mut kept, mut demoted) = (0u8, 0u8);
    let (plane_n, above_n) = (&mut plane[..n], &cell_above[..n]);
    for i in 0..n {
        let object = plane_n[i] == OBJECT;
        let up = above_n[i] != 0;
        kept |= u8::from(object & up);
        demoted |= u8::from(object & !up);
        plane_n[i] = if object & !up { 0 } else { plane_n[i] };
    }
    let any = kept != 0;
    if demoted == 0 {
        // The scene's 1-cells here are the file's: its codes and values
        // stand (a code 0 inside the brick still has a scene 1-cell
        // next to it, as [`scene_code_at_least_1`] relies on).
        return;
    }
    let local = local_distances_any(plane, b.cells, &edge.pads);
    let cap = edge.max_code;
    for (c, &l) in plane.iter_mut().zip(&local) {
        let tightened = (*c).max(l.saturating_sub(1).min(cap));
        *c = if *c == OBJECT { OBJECT } else { tightened };
    }
    if !any {
        b.values = Samples::Empty;
        return;
    }
    // A 0-cell's minimum corner holds its code in a file prepared for the
    // scene once the code is embedded: missing for smooth normals.
    let min_embedded = if halo { 2 } else { 1 };
    let values = b.values.make_f32();
    for z in 0..cz {
        for y in 0..cy {
            let codes = &plane[(z * cy + y) * cx..(z * cy + y + 1) * cx];
            let o = (z * sy + y) * sx;
            for (v, &c) in values[o..o + cx].iter_mut().zip(codes) {
                let coded = (c != OBJECT) & (c >= min_embedded);
                *v = if coded { f32::NAN } else { *v };
            }
        }
    }
}

/// A neighbour bound ([`Edge::pads`]) for "no 1-cell in reach": outside
/// the volume, or the largest code plus one.
pub(crate) const FAR: u8 = 254;

/// How far [`local_distances_any`] looks: distances above it read as
/// `REACH + 1`, so a narrowed code is at most `REACH` (where the file's
/// own code is not larger). 6 costs 0.5 % more steps than an unbounded
/// transform on the 512^3 phantom (1 % on the real CT) for well under
/// half its work (docs/BENCHMARKS.md, "Render-time iso").
pub(crate) const REACH: u8 = 6;

/// The chessboard distance of every cell of a brick (`cells` per axis, x
/// fastest; `plane[i] == OBJECT` marks a 1-cell) to the nearest 1-cell,
/// where the cells of the layer around the brick count as 1-cells at the
/// distances `pads` gives (lower bounds, per neighbour brick, indexed as
/// [`Edge::pads`]; all 0: everything outside is a 1-cell), capped at
/// [`REACH`]` + 1`: 0 for a 1-cell. The result is a lower bound of the
/// true distance whenever the pads are: a chessboard geodesic from a cell
/// to a 1-cell outside the brick passes through the layer around it, and
/// a cell with none within `REACH` is at least `REACH + 1` away.
///
/// `REACH` rounds of min-plus dilation with the 3x3x3 cube, each one
/// erosion per axis over the whole padded brick (flat loops that
/// vectorise) and `d = min(d, eroded + 1)` inside, the layer around held
/// at its bounds: after `k` rounds a cell holds the exact distance to the
/// 1-cells and layer cells within `k`.
#[inline(always)]
fn local_distances_any(plane: &[u8], cells: [u32; 3], pads: &[u8; 27]) -> Vec<u8> {
    let [cx, cy, cz] = cells.map(|c| c as usize);
    let (px, py, pz) = (cx + 2, cy + 2, cz + 2);
    let (n, slice) = (px * py * pz, px * py);
    let at = |x: usize, y: usize, z: usize| (z * py + y) * px + x;
    let side = |v: usize, n: usize| {
        if v == 0 {
            0
        } else if v == n + 1 {
            2
        } else {
            1
        }
    };
    let cap = REACH + 1;
    // `fixed`: the layer's bounds (capped), and INSIDE for the brick.
    const INSIDE: u8 = u8::MAX;
    let mut fixed = vec![INSIDE; n];
    for z in 0..pz {
        for y in 0..py {
            let (sy, sz) = (side(y, cy), side(z, cz));
            let row = &mut fixed[at(0, y, z)..at(0, y, z) + px];
            row[0] = pads[sz * 9 + sy * 3].min(cap);
            row[px - 1] = pads[sz * 9 + sy * 3 + 2].min(cap);
            if sy != 1 || sz != 1 {
                row[1..px - 1].fill(pads[sz * 9 + sy * 3 + 1].min(cap));
            }
        }
    }
    let mut d: Vec<u8> = fixed
        .iter()
        .map(|&f| if f == INSIDE { cap } else { f })
        .collect();
    let keep: Vec<u8> = fixed
        .iter()
        .map(|&f| if f == INSIDE { 0xff } else { 0 })
        .collect();
    let bound: Vec<u8> = fixed
        .iter()
        .map(|&f| if f == INSIDE { 0 } else { f })
        .collect();
    for z in 0..cz {
        for y in 0..cy {
            let row = &plane[(z * cy + y) * cx..(z * cy + y + 1) * cx];
            let o = at(1, y + 1, z + 1);
            for (dst, &c) in d[o..o + cx].iter_mut().zip(row) {
                *dst = if c == OBJECT { 0 } else { *dst };
            }
        }
    }
    // Erosions along x, y, z read across row and slice ends only for the
    // layer's cells, whose values `fixed` restores.
    let (mut t1, mut t2) = (vec![0u8; n], vec![0u8; n]);
    for _ in 0..REACH {
        min3(&d[..n - 2], &d[1..n - 1], &d[2..], &mut t1[1..n - 1]);
        min3(
            &t1[..n - 2 * px],
            &t1[px..n - px],
            &t1[2 * px..],
            &mut t2[px..n - px],
        );
        min3(
            &t2[..n - 2 * slice],
            &t2[slice..n - slice],
            &t2[2 * slice..],
            &mut t1[slice..n - slice],
        );
        // Inside `(grown & 0xff) | 0`, on the layer `(grown & 0) | bound`:
        // branch-free, so that it vectorises.
        let (e, k, b) = (&t1[..n], &keep[..n], &bound[..n]);
        for i in 0..n {
            d[i] = (d[i].min(e[i] + 1) & k[i]) | b[i];
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

/// `out[i] = a[i] | b[i]` over `out`'s length.
#[inline(always)]
fn or2(a: &[u8], b: &[u8], out: &mut [u8]) {
    let n = out.len();
    let (a, b) = (&a[..n], &b[..n]);
    for i in 0..n {
        out[i] = a[i] | b[i];
    }
}

/// `out[i] = min(a[i], b[i], c[i])`: one step of an erosion, over whole
/// slices so that it vectorises.
#[inline(always)]
fn min3(a: &[u8], b: &[u8], c: &[u8], out: &mut [u8]) {
    let n = out.len();
    let (a, b, c) = (&a[..n], &b[..n], &c[..n]);
    for i in 0..n {
        out[i] = a[i].min(b[i]).min(c[i]);
    }
}

/// Each entry point below runs its body compiled for AVX2 where the CPU
/// has it (twice the bytes an instruction of the flat byte loops), and for
/// the baseline target elsewhere: the same code, the same results.
macro_rules! dispatch {
    ($(#[$doc:meta])* $name:ident, $avx2:ident, $any:ident, ($($arg:ident: $ty:ty),*) $(-> $ret:ty)?) => {
        $(#[$doc])*
        pub(crate) fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2, checked just above.
                return unsafe { $avx2($($arg),*) };
            }
            $any($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $avx2($($arg: $ty),*) $(-> $ret)? {
            $any($($arg),*)
        }
    };
}

dispatch!(
    /// [`tighten_any`].
    tighten, tighten_avx2, tighten_any, (b: &mut RBrick, edge: &Edge)
);
dispatch!(
    /// [`narrow_any`].
    narrow, narrow_avx2, narrow_any, (b: &mut RBrick, iso: f32, halo: bool, edge: &Edge)
);

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// [`local_distances_any`] as compiled for the baseline target, checked
    /// equal to its AVX2 build where the CPU has one.
    fn distances(plane: &[u8], cells: [u32; 3], pads: &[u8; 27]) -> Vec<u8> {
        let got = local_distances_any(plane, cells, pads);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            #[target_feature(enable = "avx2")]
            fn avx2(plane: &[u8], cells: [u32; 3], pads: &[u8; 27]) -> Vec<u8> {
                local_distances_any(plane, cells, pads)
            }
            // SAFETY: the CPU has AVX2, checked just above.
            assert_eq!(unsafe { avx2(plane, cells, pads) }, got);
        }
        got
    }

    /// Chessboard distance by brute force: to the brick's 1-cells, and to
    /// every cell `q` of the layer around the brick plus its pad value.
    fn brute(plane: &[u8], c: [usize; 3], pads: &[u8; 27]) -> Vec<u8> {
        let mut out = vec![0u8; plane.len()];
        let ci = c.map(|x| x as i64);
        for z in 0..c[2] {
            for y in 0..c[1] {
                for x in 0..c[0] {
                    let p = [x, y, z].map(|v| v as i64);
                    let mut best = u64::MAX;
                    for qz in -1..=ci[2] {
                        for qy in -1..=ci[1] {
                            for qx in -1..=ci[0] {
                                let q = [qx, qy, qz];
                                let d = (0..3).map(|k| p[k].abs_diff(q[k])).max().unwrap();
                                let side = |k: usize| match q[k] {
                                    -1 => 0,
                                    v if v == ci[k] => 2,
                                    _ => 1,
                                };
                                let sides = [side(0), side(1), side(2)];
                                let v = if sides == [1, 1, 1] {
                                    let i = ((qz * ci[1] + qy) * ci[0] + qx) as usize;
                                    if plane[i] != OBJECT {
                                        continue;
                                    }
                                    0
                                } else {
                                    pads[sides[2] * 9 + sides[1] * 3 + sides[0]] as u64
                                };
                                best = best.min(v + d);
                            }
                        }
                    }
                    out[(z * c[1] + y) * c[0] + x] = best.min(FAR as u64) as u8;
                }
            }
        }
        out
    }

    proptest! {
        #[test]
        fn local_distances_are_the_chessboard_distances(
            c in prop::array::uniform3(1usize..22),
            density in 0.0f64..0.05,
            seed in any::<u64>(),
            pads in prop::array::uniform27(prop_oneof![Just(0u8), Just(FAR), 0u8..=FAR]),
            blind in any::<bool>(),
        ) {
            let plane = random_plane(c, density, seed);
            let pads = if blind { [0; 27] } else { pads };
            let got = distances(&plane, c.map(|x| x as u32), &pads);
            let want: Vec<u8> = brute(&plane, c, &pads).iter().map(|&d| d.min(REACH + 1)).collect();
            prop_assert_eq!(got, want);
        }
    }

    /// Random 1-cells (density `density`, seeded) in a brick of `c`.
    fn random_plane(c: [usize; 3], density: f64, seed: u64) -> Vec<u8> {
        let mut s = seed | 1;
        (0..c[0] * c[1] * c[2])
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                if ((s >> 11) as f64 / (1u64 << 53) as f64) < density {
                    OBJECT
                } else {
                    3
                }
            })
            .collect()
    }

    proptest! {
        /// Long rows in thin bricks: the flat erosions read across row and
        /// slice ends, where only the layer may be read.
        #[test]
        fn local_distances_in_long_thin_bricks(
            cx in 60usize..140,
            c in prop::array::uniform2(1usize..4),
            density in 0.0f64..0.03,
            seed in any::<u64>(),
            pads in prop::array::uniform27(prop_oneof![Just(0u8), Just(FAR), 0u8..=FAR]),
        ) {
            let c = [cx, c[0], c[1]];
            let plane = random_plane(c, density, seed);
            let got = distances(&plane, c.map(|x| x as u32), &pads);
            let want: Vec<u8> = brute(&plane, c, &pads).iter().map(|&d| d.min(REACH + 1)).collect();
            prop_assert_eq!(got, want);
        }
    }

    #[test]
    fn an_empty_cube_counts_to_its_centre() {
        let c = [9u32, 9, 9];
        let d = distances(&vec![0u8; 729], c, &Edge::BLIND.pads);
        assert_eq!(d[(4 * 9 + 4) * 9 + 4], 5);
        assert_eq!(d[0], 1);
        // Far neighbours on every side but one face (x below, at 2): 11
        // cells away at the far side, read as REACH + 1.
        let mut pads = [FAR; 27];
        pads[9 + 3] = 2;
        let d = distances(&vec![0u8; 729], c, &pads);
        assert_eq!(d[(4 * 9 + 4) * 9 + 8], REACH + 1);
        assert_eq!(d[(4 * 9 + 4) * 9 + 4], 2 + 5);
        assert_eq!(d[(4 * 9 + 4) * 9], 3);
    }
}
