//! Shading normals: how the gradient at a point of a 1-cell is estimated.
//!
//! The paper leaves the gradient reconstruction to the data (section 2,
//! citing filter analyses such as Bentum et al.'s of gradient estimators,
//! its ref. 20); section 5.3 (item 3) relies only on the gradient being
//! continuous *within* a cell, for Newton's hit refinement, which is why
//! hits keep the cell interpolant's derivative whatever the normals. Two
//! estimates for shading:
//!
//! - [`Normals::Cell`]: the derivative of the cell's own trilinear
//!   interpolant ([`CellEval::gradient`](super::shade::CellEval::gradient)).
//!   Always available, since every vertex of a 1-cell keeps its value, but
//!   discontinuous across cell faces: surfaces show terraces and a plaid of
//!   voxel rows (issue 15).
//! - [`Normals::Smooth`] (the default, as VTK's and Slicer's): central
//!   differences at the cell's 8 vertices, trilinearly interpolated. The
//!   result is continuous across cell faces wherever the same samples are
//!   read on both sides.
//!
//! **Rectilinear grids.** At a sample `x0` with neighbours `x- < x0 < x+`
//! (gaps `h- = x0 - x-`, `h+ = x+ - x0`) the derivative is the three-point
//! Lagrange derivative, the mean of the two one-sided slopes, each weighted
//! by the *other* gap:
//! `g = (h- s+ + h+ s-) / (h- + h+)`, `s+ = (f+ - f0) / h+`,
//! `s- = (f0 - f-) / h-`. It is exact for quadratics, and on a uniform
//! axis it is the usual `(f+ - f-) / 2h`.
//!
//! **Missing samples: the one-sided rule.** A neighbour is missing when it
//! lies outside the volume or when its word carries a distance code (the
//! docs/DESIGN.md "Embedding" invariant: a sample one step outside a 1-cell
//! carries code 1 when its cell is at chessboard distance 2 from the
//! object, unless the file was prepared with `--gradient-halo`). Then the
//! derivative along that axis is the one-sided slope towards the other
//! neighbour. At a vertex of a 1-cell the inner neighbour along each axis
//! is another vertex of the same cell, so at least one side always exists.
//!
//! **Which brick a sample is read from.** A sample inside the hit cell's
//! brick (its `cells + 1` samples per axis, apron included) is read from
//! it; any other sample `s` from the brick of cell `min(s, n - 2)` per axis
//! (the brick holding the cell that `s` is the minimum corner of, or the
//! last cell on the axis). That cell is always within chessboard distance
//! 1 of the hit cell, so it has code 0 or is a 1-cell, and its brick is
//! never uniform. A sample stored in two bricks has the same word in
//! both, but a brick with no 1-cell is decoded for its codes only
//! (`render/brick/decode.rs`); such a brick is read again with its values
//! ([`Accessor::brick_with_values`]). So a sample reads as its value
//! wherever its word is one, and the gradients do not depend on where the
//! bricks are cut (tests/all/normals.rs, brick sizes 4, 8 and 16 give the
//! same bytes; docs/TRADEOFFS.md, "Normals at brick faces"). In a scene
//! narrower than the file (`render --iso`) the values read so are the
//! file's, and the samples the scene's file would hold as codes are
//! then made missing, as for every other brick (`smooth_gradient_in`).

use glam::{DVec3, Vec3, Vec3A};

use crate::render::brick::gradients::three_point;
use crate::render::brick::RBrick;
use crate::render::cache::Accessor;
use crate::render::traverse::OBJECT;

/// How surface normals are estimated (`cdvol render --normals`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Normals {
    /// Central differences at the samples, trilinearly interpolated
    /// (this module).
    #[default]
    Smooth,
    /// The derivative of the cell's own trilinear interpolant.
    Cell,
}

impl Normals {
    /// `smooth` or `cell`.
    pub fn name(self) -> &'static str {
        match self {
            Normals::Smooth => "smooth",
            Normals::Cell => "cell",
        }
    }
}

/// The central-difference gradients at a cell's 8 vertices, ready to be
/// interpolated at any point of the cell: build once per cell
/// ([`vertex_gradients`]), then [`VertexGradients::at`] per sample (a
/// composite ray takes many samples in one cell).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexGradients {
    /// Lower corner of the cell (mm) and the inverse of its size.
    lo: [f64; 3],
    inv_size: [f64; 3],
    /// Gradient per mm at each vertex, x fastest.
    pub g: [DVec3; 8],
    /// Vertex-axis pairs (of 24) that used the one-sided rule because a
    /// neighbour was missing.
    pub one_sided: u32,
}

impl VertexGradients {
    /// Trilinear interpolation of the vertex gradients at local
    /// coordinates `u` in `[0, 1]^3`.
    #[inline]
    pub fn at_local(&self, u: [f64; 3]) -> DVec3 {
        let g = &self.g;
        let x00 = g[0] + u[0] * (g[1] - g[0]);
        let x10 = g[2] + u[0] * (g[3] - g[2]);
        let x01 = g[4] + u[0] * (g[5] - g[4]);
        let x11 = g[6] + u[0] * (g[7] - g[6]);
        let y0 = x00 + u[1] * (x10 - x00);
        let y1 = x01 + u[1] * (x11 - x01);
        y0 + u[2] * (y1 - y0)
    }

    /// The interpolated gradient at point `p` (mm), clamped into the cell.
    #[inline]
    pub fn at(&self, p: DVec3) -> DVec3 {
        self.at_local(std::array::from_fn(|k| {
            ((p[k] - self.lo[k]) * self.inv_size[k]).clamp(0.0, 1.0)
        }))
    }
}

/// The smooth gradient (per mm) at point `p` of `cell`:
/// [`vertex_gradients`] interpolated at `p`.
#[inline]
pub fn smooth_gradient(acc: &mut Accessor, coords: [&[f64]; 3], cell: [u32; 3], p: DVec3) -> DVec3 {
    vertex_gradients(acc, coords, cell).at(p)
}

/// [`smooth_gradient`] in a scene narrower than the file's classification
/// (`render --iso`; `narrow` is the scene's iso value, `None` for none):
/// a sample that a file prepared for the scene would hold as a code is
/// missing here too, so normals match that file's (module scene).
#[inline]
pub(crate) fn smooth_gradient_in(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
    p: DVec3,
    narrow: Option<f32>,
) -> DVec3 {
    vertex_gradients_in(acc, coords, cell, narrow).at(p)
}

/// The samples around a cell are held in a 4^3 block whose origin is the
/// sample at offset (-1, -1, -1) from the cell's minimum corner, x
/// fastest; of its 64 entries the vertex gradients read 32: the 8 vertices
/// and, per vertex and axis, the neighbour outside the cell.
const fn block_index(x: usize, y: usize, z: usize) -> usize {
    (z * 4 + y) * 4 + x
}

/// Whether block entry `(x, y, z)` (each 0..4) is one of the 32 samples
/// read: at most one coordinate outside the cell's `{1, 2}`.
const fn needed(x: usize, y: usize, z: usize) -> bool {
    let out = (x == 0 || x == 3) as u32 + (y == 0 || y == 3) as u32 + (z == 0 || z == 3) as u32;
    out <= 1
}

/// The block indices of the 32 samples read, ascending.
const CROSS: [usize; 32] = {
    let mut out = [0; 32];
    let (mut i, mut n) = (0, 0);
    while i < 64 {
        if needed(i & 3, i >> 2 & 3, i >> 4) {
            out[n] = i;
            n += 1;
        }
        i += 1;
    }
    out
};

/// The central-difference gradients at the 8 vertices of `cell` (samples
/// `cell .. cell + 1` per axis), with the one-sided rule where a neighbour
/// is missing (see the module docs). `coords` are the sample positions per
/// axis. A vertex whose own value is missing (never for a 1-cell) gets a
/// NaN gradient.
pub fn vertex_gradients(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
) -> VertexGradients {
    vertex_gradients_in(acc, coords, cell, None)
}

/// [`vertex_gradients`], in a scene narrower than the file's when
/// `narrow` holds its iso value ([`smooth_gradient_in`]).
///
/// When `acc` remembers gradients ([`Accessor::remember_gradients`]) and
/// outside narrowed scenes, the gradients come from this thread's [`Memo`]
/// when it holds the cell (a vertex's gradient is a function of the
/// vertex, module docs, "Which brick a sample is read from", so the
/// cell's 8 are a function of the cell),
/// else they are computed and remembered. Rays denser than the cells meet
/// the same cells: at 1024^2 on the head CT a cell is some 4 x 4 pixels
/// wide.
pub(crate) fn vertex_gradients_in(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
    narrow: Option<f32>,
) -> VertexGradients {
    if narrow.is_some() || !acc.remembers_gradients() {
        return compute_vertex_gradients(acc, coords, cell, narrow);
    }
    let cache = acc.cache_id();
    let n: [u64; 3] = std::array::from_fn(|k| coords[k].len() as u64 - 1);
    let c = cell.map(u64::from);
    let key = (c[2] * n[1] + c[1]) * n[0] + c[0];
    MEMO.with(|m| {
        let mut m = m.borrow_mut();
        let e = m.entry(cache, key);
        if e.cache == cache && e.cell == key {
            // The fields `compute_vertex_gradients` derives from the cell.
            let ck = cell.map(|x| x as usize);
            return VertexGradients {
                lo: std::array::from_fn(|k| coords[k][ck[k]]),
                inv_size: std::array::from_fn(|k| 1.0 / (coords[k][ck[k] + 1] - coords[k][ck[k]])),
                g: e.g.map(DVec3::from_array),
                one_sided: e.one_sided as u32,
            };
        }
        let vg = compute_vertex_gradients(acc, coords, cell, None);
        // After a read error the accessor answers empty cells: nothing
        // from such a render is remembered.
        if acc.error.is_none() {
            *e = MemoEntry {
                cache,
                cell: key,
                g: vg.g.map(|v| v.to_array()),
                one_sided: u64::from(vg.one_sided),
            };
        }
        vg
    })
}

/// The 8 vertex gradients of cells this thread has computed, by cell and
/// cache: a direct-mapped table of [`MEMO_CELLS`] entries, a newer cell
/// replacing an older one in its slot. Per thread, so rayon's workers
/// share nothing; keyed by the cache's process-unique id, so it never
/// answers for another volume, another scene or another render's planes.
/// Allocated zeroed (an empty slot has cache id 0, which no cache has), so
/// a render touches only the pages of the slots it uses.
struct Memo {
    slots: Vec<MemoEntry>,
}

#[derive(Clone, Copy)]
#[repr(C)]
struct MemoEntry {
    cache: u64,
    cell: u64,
    g: [[f64; 3]; 8],
    one_sided: u64,
}

// SAFETY: every field is a `u64` or `f64`, for which all-zero bytes are a
// valid value, and `repr(C)` with only 8-byte fields has no padding.
unsafe impl bytemuck::Zeroable for MemoEntry {}

/// Cells a thread's [`Memo`] holds (216 bytes each: 864 KiB a thread).
/// docs/BENCHMARKS.md, "Vertex gradients remembered", measures the size.
const MEMO_CELLS: usize = 1 << 12;

thread_local! {
    static MEMO: std::cell::RefCell<Memo> = std::cell::RefCell::new(Memo {
        slots: bytemuck::allocation::zeroed_vec(MEMO_CELLS),
    });
}

impl Memo {
    /// The slot of `cell` (whatever it holds).
    #[inline]
    fn entry(&mut self, cache: u64, cell: u64) -> &mut MemoEntry {
        let h = (cell ^ cache.rotate_left(32)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        &mut self.slots[(h >> (64 - MEMO_CELLS.trailing_zeros())) as usize]
    }
}

/// [`vertex_gradients`] computed from the samples every time, without the
/// thread's memo: the reference the memo is tested against
/// (tests/all/normals.rs).
pub fn vertex_gradients_uncached(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
) -> VertexGradients {
    compute_vertex_gradients(acc, coords, cell, None)
}

/// [`vertex_gradients_in`] computed from the samples.
fn compute_vertex_gradients(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
    narrow: Option<f32>,
) -> VertexGradients {
    let n: [usize; 3] = std::array::from_fn(|k| coords[k].len());
    let c: [usize; 3] = cell.map(|x| x as usize);
    // The 4^3 block around the cell, NaN where a sample is missing.
    let mut f = [f32::NAN; 64];
    // Block entries outside the hit cell's brick (bit per entry).
    let mut todo = 0u64;
    // The hit cell's place in its brick, and whether the brick's
    // samples hold values.
    let (lc, cells, has) = {
        let (b, l) = acc.brick(cell);
        let has = !b.values.is_empty();
        let sx = b.cells[0] as usize + 1;
        let sy = b.cells[1] as usize + 1;
        let lc = l.map(|x| x as usize);
        // Inside the brick's samples along every axis: one index check.
        let inside = (0..3).all(|k| lc[k] >= 1 && lc[k] + 2 <= b.cells[k] as usize);
        if inside && has {
            let base = ((lc[2] - 1) * sy + lc[1] - 1) * sx + lc[0] - 1;
            let at = |i: usize| base + ((i >> 4) * sy + (i >> 2 & 3)) * sx + (i & 3);
            b.values.gather_into(CROSS.map(at), CROSS, &mut f);
        } else {
            for i in CROSS {
                let o = [i & 3, i >> 2 & 3, i >> 4];
                // Global sample, or outside the volume.
                let s: [usize; 3] = std::array::from_fn(|k| (c[k] + o[k]).wrapping_sub(1));
                if (0..3).any(|k| s[k] >= n[k]) {
                    continue;
                }
                let ls: [usize; 3] = std::array::from_fn(|k| (lc[k] + o[k]).wrapping_sub(1));
                if (0..3).all(|k| ls[k] <= b.cells[k] as usize) {
                    if has {
                        f[i] = b.values.get(b.sample_index(ls));
                    }
                } else {
                    todo |= 1 << i;
                }
            }
        }
        (lc, b.cells.map(|x| x as usize), has)
    };
    while todo != 0 {
        let i = todo.trailing_zeros() as usize;
        todo &= todo - 1;
        let o = [i & 3, i >> 2 & 3, i >> 4];
        let s: [usize; 3] = std::array::from_fn(|k| c[k] + o[k] - 1);
        f[i] = value_elsewhere(acc, n, s);
    }
    if narrow.is_some() {
        // Only a sample two past the cell can be a code in a file
        // prepared for the scene and a value in this one: its cell is at
        // chessboard distance 2 from this 1-cell (module scene). The
        // bricks' narrowing already removed those inside a brick: a value
        // left at the minimum corner of a cell of the hit brick off its
        // outer layer is no code's (`scene_code_at_least_1`'s rule,
        // without its brick lookup).
        for i in CROSS {
            let o = [i & 3, i >> 2 & 3, i >> 4];
            if !(o.contains(&3) && f[i].is_finite()) {
                continue;
            }
            let in_brick = |k: usize| {
                (1..cells[k].saturating_sub(1)).contains(&(lc[k] + o[k]).wrapping_sub(1))
            };
            if has && (0..3).all(in_brick) {
                continue;
            }
            let s: [usize; 3] = std::array::from_fn(|k| c[k] + o[k] - 1);
            if scene_code_at_least_1(acc, n, s) {
                f[i] = f32::NAN;
            }
        }
    }
    // Gaps around the cell per axis: h[0] before its minimum corner (NaN
    // at the border), h[1] the cell, h[2] after its maximum corner.
    let h: [[f64; 3]; 3] = std::array::from_fn(|k| {
        let x = coords[k];
        let ck = c[k];
        [
            if ck >= 1 { x[ck] - x[ck - 1] } else { f64::NAN },
            x[ck + 1] - x[ck],
            if ck + 2 < n[k] {
                x[ck + 2] - x[ck + 1]
            } else {
                f64::NAN
            },
        ]
    });
    // Per axis: the inverse gaps, and per vertex side the weight of the
    // slope after it in the three-point rule, `h- / (h- + h+)`: five
    // divisions per axis instead of three per vertex and axis.
    let inv: [[f64; 3]; 3] = h.map(|hk| hk.map(|x| 1.0 / x));
    let lam: [[f64; 2]; 3] = h.map(|hk| [hk[0] / (hk[0] + hk[1]), hk[1] / (hk[1] + hk[2])]);
    let mut one_sided = 0;
    let g: [DVec3; 8] = std::array::from_fn(|v| {
        let a = [v & 1, v >> 1 & 1, v >> 2];
        let mut out = [0.0; 3];
        for k in 0..3 {
            let mut at = [a[0] + 1, a[1] + 1, a[2] + 1];
            let f0 = f[block_index(at[0], at[1], at[2])] as f64;
            at[k] -= 1;
            let fm = f[block_index(at[0], at[1], at[2])] as f64;
            at[k] += 2;
            let fp = f[block_index(at[0], at[1], at[2])] as f64;
            let (g, one) = three_point(f0, fm, fp, [inv[k][a[k]], inv[k][a[k] + 1]], lam[k][a[k]]);
            out[k] = g;
            one_sided += u32::from(one);
        }
        DVec3::from_array(out)
    });
    VertexGradients {
        lo: std::array::from_fn(|k| coords[k][c[k]]),
        inv_size: std::array::from_fn(|k| inv[k][1]),
        g,
        one_sided,
    }
}

/// The 8 vertex gradients of 1-cell `cell` (x fastest), as
/// [`vertex_gradients`] gives them, in f32: from its brick's gradient
/// plane ([`brick_gradients`](crate::render::brick::gradients::brick_gradients)) when the cache built one and the cell is
/// set in it (from the decode on for a cell strictly inside the brick),
/// else computed, one vertex at a time, and kept in the plane for the
/// next ray ([`GradPlane`], [`outer_cell_gradients`]).
///
/// The composite sampler reads the plane in the lookup that gives it the
/// cell's values and calls [`outer_cell_gradients`] for the rest; this is
/// the same per cell on its own, for tests.
///
/// [`GradPlane`]: crate::render::brick::GradPlane
#[cfg(test)]
pub(crate) fn cell_gradients(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
) -> [Vec3A; 8] {
    let (b, l) = acc.brick(cell);
    match b.grad_cell(l) {
        Some(g) => g,
        None => outer_cell_gradients(acc, coords, cell),
    }
}

/// The 8 vertex gradients of 1-cell `cell` when its brick's plane does
/// not hold them all ([`RBrick::grad_cell`]), as [`vertex_gradients`]
/// gives them. In a brick with a plane, a vertex the plane holds is read
/// from it; each other one is computed on its own ([`sample_gradient`])
/// and kept there for the next cell that shares it, and the cell is set
/// once all 8 are kept. Without a plane, or after a read error (nothing
/// is kept then), all 8 are computed.
///
/// [`RBrick::grad_cell`]: crate::render::brick::RBrick::grad_cell
#[cold]
pub(crate) fn outer_cell_gradients(
    acc: &mut Accessor,
    coords: [&[f64]; 3],
    cell: [u32; 3],
) -> [Vec3A; 8] {
    let home = acc
        .brick_arc(cell)
        .filter(|(b, l)| acc.error.is_none() && !b.grads.is_empty() && b.code(*l) == OBJECT);
    let Some((home, l)) = home else {
        return vertex_gradients(acc, coords, cell)
            .g
            .map(|g| Vec3A::from(g.as_vec3()));
    };
    let idx = home.corner_indices(l);
    let g = std::array::from_fn(|v| {
        if let Some(g) = home.grads.sample(idx[v]) {
            return g;
        }
        let s = std::array::from_fn(|k| cell[k] as usize + (v >> k & 1));
        let g = sample_gradient(acc, coords, &home, s);
        // After a read error the neighbours read as missing: keep nothing.
        if acc.error.is_none() {
            home.grads.fill_sample(idx[v], g);
        }
        Vec3A::from(g)
    });
    // Unless another thread is still writing one of the vertices.
    home.grads.set_cell_if_ready(l);
    g
}

/// The gradient at global sample `s`, a vertex of a 1-cell of `home`,
/// exactly as [`vertex_gradients`] computes it at that vertex: the same
/// samples (read by [`sample_value`]), gaps, weights and rule
/// ([`three_point`]), in the same order of operations.
fn sample_gradient(acc: &mut Accessor, coords: [&[f64]; 3], home: &RBrick, s: [usize; 3]) -> Vec3 {
    let n: [usize; 3] = std::array::from_fn(|k| coords[k].len());
    let f0 = sample_value(acc, home, n, s) as f64;
    DVec3::from_array(std::array::from_fn(|k| {
        let x = coords[k];
        let (before, after) = (s[k] >= 1, s[k] + 1 < n[k]);
        let mut at = s;
        let (hm, fm) = if before {
            at[k] = s[k] - 1;
            (x[s[k]] - x[s[k] - 1], sample_value(acc, home, n, at) as f64)
        } else {
            (f64::NAN, f64::NAN)
        };
        let (hp, fp) = if after {
            at[k] = s[k] + 1;
            (x[s[k] + 1] - x[s[k]], sample_value(acc, home, n, at) as f64)
        } else {
            (f64::NAN, f64::NAN)
        };
        three_point(f0, fm, fp, [1.0 / hm, 1.0 / hp], hm / (hm + hp)).0
    }))
    .as_vec3()
}

/// Global sample `p` (inside the volume of `n` samples per axis) as
/// [`vertex_gradients`] reads it for a cell of `home` (module docs, "Which
/// brick a sample is read from"): from `home` when it holds the sample,
/// else from the brick of cell `min(p, n - 2)` with its values; NaN where
/// the word is a code or the brick has no values.
fn sample_value(acc: &mut Accessor, home: &RBrick, n: [usize; 3], p: [usize; 3]) -> f32 {
    let lh: [usize; 3] = std::array::from_fn(|k| p[k].wrapping_sub(home.first[k] as usize));
    if (0..3).all(|k| lh[k] <= home.cells[k] as usize) {
        if home.values.is_empty() {
            return f32::NAN;
        }
        return home.values.get(home.sample_index(lh));
    }
    value_elsewhere(acc, n, p)
}

/// Global sample `p` (inside the volume of `n` samples per axis) read
/// outside the asking cell's brick: from the brick of cell
/// `min(p, n - 2)` with its values (module docs, "Which brick a sample is
/// read from"); NaN where the word is a code or the brick has no values.
fn value_elsewhere(acc: &mut Accessor, n: [usize; 3], p: [usize; 3]) -> f32 {
    let at: [u32; 3] = std::array::from_fn(|k| p[k].min(n[k] - 2) as u32);
    let (b, l) = acc.brick_with_values(at);
    let ls: [usize; 3] = std::array::from_fn(|k| l[k] as usize + p[k] - at[k] as usize);
    if b.values.is_empty() || (0..3).any(|k| ls[k] > b.cells[k] as usize) {
        return f32::NAN;
    }
    b.values.get(b.sample_index(ls))
}

/// Whether the cell whose minimum corner is global sample `s` has a
/// scene code of at least 1 (no scene 1-cell within chessboard distance
/// 1), so that a file prepared for the scene would carry a code in `s`'s
/// word; false when `s` is the minimum corner of no cell. Called only in
/// narrowed renders, where every brick marks exactly the scene's 1-cells
/// as [`OBJECT`]: [`narrow`](crate::render::brick::envelope::narrow) demotes the others, and a brick decoded
/// without values ([`tighten`](crate::render::brick::envelope::tighten), or no 1-cell of the file's) or standing
/// in by its index code has none. `n` are the samples per axis.
pub(crate) fn scene_code_at_least_1(acc: &mut Accessor, n: [usize; 3], s: [usize; 3]) -> bool {
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
    // The 26 cells around, those in the volume.
    let lo: [usize; 3] = std::array::from_fn(|k| s[k].saturating_sub(1));
    let hi: [usize; 3] = std::array::from_fn(|k| (s[k] + 1).min(n[k] - 2));
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                let (b, l) = acc.brick([x, y, z].map(|v| v as u32));
                if b.code(l) == OBJECT {
                    return false;
                }
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_32_samples() {
        assert!(CROSS.windows(2).all(|w| w[0] < w[1]));
        assert!(CROSS.iter().all(|&i| needed(i & 3, i >> 2 & 3, i >> 4)));
        let mut count = 0;
        for z in 0..4 {
            for y in 0..4 {
                for x in 0..4 {
                    count += needed(x, y, z) as u32;
                }
            }
        }
        assert_eq!(count, 32);
    }

    #[test]
    fn interpolation_reproduces_vertices() {
        let g = std::array::from_fn(|i| DVec3::new(i as f64, 2.0 * i as f64, -(i as f64)));
        let vg = VertexGradients {
            lo: [1.0, 2.0, 3.0],
            inv_size: [0.5, 1.0, 0.25],
            g,
            one_sided: 0,
        };
        for (i, want) in g.iter().enumerate() {
            let p = DVec3::new(
                1.0 + 2.0 * (i & 1) as f64,
                2.0 + (i >> 1 & 1) as f64,
                3.0 + 4.0 * (i >> 2) as f64,
            );
            assert_eq!(vg.at(p), *want);
        }
    }
}
