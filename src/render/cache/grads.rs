//! The shaded composite's gradient plane: per sample of a brick, its
//! vertex gradient in f32, as `gradient::vertex_gradients` computes it
//! (docs/TRADEOFFS.md, "Gradient plane").
//!
//! The samples strictly inside the brick are set when the brick is
//! decoded (`gradient::brick_gradients`): their 6 neighbours are in the
//! brick. A sample on the outer layer has neighbours in other bricks, so
//! it is filled the first time a 1-cell with that vertex is sampled
//! (`gradient::cell_gradients`, from the cell's computed gradients) and
//! read from the plane from then on, by every thread and every later
//! frame while the brick stays cached. Reading the neighbours when the
//! brick is decoded instead would read the bricks around every face,
//! whether any ray samples there or not: with a cache budget below the
//! working set that read evicted and decoded again, and the shaded
//! composite took 75 % longer (docs/BENCHMARKS.md).
//!
//! Which entries hold their gradient is kept per cell, one bit each: a
//! cell is set when all 8 of its vertices are, which costs the sampler
//! one bit test per cell. A vertex's gradient is a function of the vertex
//! (module `render::gradient`, "Which brick a sample is read from"), so
//! threads that fill the same sample write the same bits; atomics make
//! those writes defined, and a cell counts as set only once its bit is
//! published (release) and seen (acquire) after its 8 gradients are
//! stored.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use glam::Vec3;

use crate::render::samples::{gather8_ref, Corners};

/// A brick's gradient plane: per sample its gradient, and per cell
/// whether its 8 vertices hold theirs. Empty for bricks without one.
#[derive(Debug, Default)]
pub struct GradPlane {
    /// Per sample (x fastest) the f32 bits of the gradient.
    g: Vec<[AtomicU32; 3]>,
    /// Per cell (x fastest), whether `g` holds its vertices' gradients.
    set: Vec<AtomicU64>,
}

impl GradPlane {
    /// An empty plane (no brick's).
    pub const EMPTY: GradPlane = GradPlane {
        g: Vec::new(),
        set: Vec::new(),
    };

    /// A plane holding `g` for the samples strictly inside a brick of
    /// `c` cells per axis (`c + 1` samples, x fastest): the cells whose 8
    /// vertices are all such samples are set, the others not yet.
    pub fn inner(g: &[Vec3], c: [usize; 3]) -> GradPlane {
        let s = c.map(|x| x + 1);
        assert_eq!(g.len(), s[0] * s[1] * s[2], "gradient plane size");
        let cells = c[0] * c[1] * c[2];
        let mut set: Vec<AtomicU64> = (0..cells.div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
        // Cell l has vertices l and l + 1: inner on an axis of n cells
        // when 1 <= l and l + 2 <= n.
        let inside = |l: usize, n: usize| l >= 1 && l + 2 <= n;
        for z in 0..c[2] {
            for y in 0..c[1] {
                for x in 0..c[0] {
                    if inside(x, c[0]) && inside(y, c[1]) && inside(z, c[2]) {
                        let i = (z * c[1] + y) * c[0] + x;
                        *set[i / 64].get_mut() |= 1 << (i % 64);
                    }
                }
            }
        }
        GradPlane {
            g: g.iter()
                .map(|v| v.to_array().map(|x| AtomicU32::new(x.to_bits())))
                .collect(),
            set,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.g.is_empty()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.g.len() * std::mem::size_of::<[AtomicU32; 3]>()
            + self.set.len() * std::mem::size_of::<AtomicU64>()
    }

    /// Whether the plane holds the gradients of cell `cell`'s vertices
    /// (false for an empty plane).
    #[inline(always)]
    pub fn cell_set(&self, cell: usize) -> bool {
        self.set
            .get(cell / 64)
            .is_some_and(|w| w.load(Ordering::Acquire) >> (cell % 64) & 1 == 1)
    }

    /// The gradients at the 8 vertices `c` (x fastest), whether set or
    /// not (an unset sample reads as whatever it holds).
    #[inline(always)]
    pub fn corners(&self, c: Corners) -> [Vec3; 8] {
        gather8_ref(&self.g, c, |v| {
            Vec3::from_array(
                v.each_ref()
                    .map(|x| f32::from_bits(x.load(Ordering::Relaxed))),
            )
        })
    }

    /// Stores `g` at the samples `idx`, the vertices of cell `cell` (the
    /// same order), and sets the cell. A sample some other cell set
    /// already gets the bits it holds.
    pub fn fill(&self, cell: usize, idx: [usize; 8], g: [Vec3; 8]) {
        for (&i, v) in idx.iter().zip(g) {
            for (a, x) in self.g[i].iter().zip(v.to_array()) {
                a.store(x.to_bits(), Ordering::Relaxed);
            }
        }
        self.set[cell / 64].fetch_or(1 << (cell % 64), Ordering::Release);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inner_cells_are_set_and_filled_cells_read_back() {
        let c = [3, 2, 4];
        let s = c.map(|x| x + 1);
        let n = s[0] * s[1] * s[2];
        let g: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f32)).collect();
        let p = GradPlane::inner(&g, c);
        let at = |x: usize, y: usize, z: usize| (z * s[1] + y) * s[0] + x;
        let corners = |x: usize, y: usize, z: usize| Corners {
            base: at(x, y, z),
            sx: s[0],
            z: s[0] * s[1],
        };
        // A cell is inner on an axis of n cells when 1 <= l <= n - 2: on
        // the y axis of 2 cells none is, so no cell of `p` is set.
        let set: Vec<bool> = (0..c[0] * c[1] * c[2]).map(|i| p.cell_set(i)).collect();
        assert!(set.iter().all(|&x| !x), "{set:?}");
        let c2 = [4, 3, 4];
        let s2 = c2.map(|x| x + 1);
        let p2 = GradPlane::inner(&vec![Vec3::ONE; s2[0] * s2[1] * s2[2]], c2);
        let set: Vec<usize> = (0..c2[0] * c2[1] * c2[2])
            .filter(|&i| p2.cell_set(i))
            .collect();
        // x in 1..=2, y = 1, z in 1..=2.
        let want: Vec<usize> = [(1, 1, 1), (2, 1, 1), (1, 1, 2), (2, 1, 2)]
            .iter()
            .map(|&(x, y, z)| (z * c2[1] + y) * c2[0] + x)
            .collect();
        assert_eq!(set, want);
        assert!(!p2.cell_set(c2[0] * c2[1] * c2[2] + 64), "beyond the plane");
        // A filled cell reads back what was filled, and is set.
        let cell = (c[1] + 1) * c[0] + 2; // (2, 1, 1)
        let k = corners(2, 1, 1);
        assert_eq!(p.corners(k)[0], Vec3::splat(at(2, 1, 1) as f32));
        let fill: [Vec3; 8] = std::array::from_fn(|v| Vec3::splat(-(v as f32)));
        p.fill(cell, k.indices(), fill);
        assert!(p.cell_set(cell));
        assert!(!p.cell_set(cell - 1));
        assert_eq!(p.corners(k), fill);
        assert!(GradPlane::EMPTY.is_empty() && !GradPlane::EMPTY.cell_set(0));
    }
}
