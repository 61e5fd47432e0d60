//! The shaded composite's gradient plane: per sample of a brick, its
//! vertex gradient in f32, as `gradient::vertex_gradients` computes it
//! (docs/TRADEOFFS.md, "Gradient plane").
//!
//! The samples strictly inside the brick are ready when the brick is
//! decoded (`gradient::brick_gradients`): their 6 neighbours are in the
//! brick. A sample on the outer layer has neighbours in other bricks, so
//! it is filled the first time a 1-cell with that vertex is sampled
//! (`gradient::outer_cell_gradients` computes the vertices the plane
//! lacks, one at a time) and read from the plane from then on, by every
//! thread and every later frame while the brick stays cached. Reading
//! the neighbours when the brick is decoded instead would read the bricks
//! around every face, whether any ray samples there or not: with a cache
//! budget below the working set that read evicted and decoded again, and
//! the shaded composite took 75 % longer (docs/DECISIONS.md, "The outer
//! layer built whole on first use").
//!
//! Which cells can be read is kept per cell, one bit each: a cell is set
//! when all 8 of its vertices hold their gradients, which costs the
//! sampler one bit test per cell. The gradients themselves are plain
//! floats, read as plain loads (8 vector loads a cell), because each
//! entry is written at most once and never while anyone may read it:
//!
//! - a filler first *claims* a sample (an atomic `fetch_or` on its claim
//!   bit: exactly one thread wins), writes it, then marks it *ready*
//!   (release);
//! - a sample another thread has claimed but not yet marked ready is left
//!   to that thread, and the cell is then not set by this fill (the next
//!   ray into the cell sets it);
//! - a cell is set (release) only after each of its 8 samples was seen
//!   ready (acquire): [`GradPlane::set_cell_if_ready`] checks them;
//! - a reader reads a cell's samples only after seeing the cell's bit
//!   ([`GradPlane::cell`], which derives the cell's vertices itself), or
//!   one sample only after seeing its ready bit ([`GradPlane::sample`]),
//!   both with acquire: these are the only reads.
//!
//! So every write happens before every read of the same entry, and no
//! entry is written twice. Every public function keeps these rules
//! whatever its arguments, so no caller can make a read race with a
//! write. A vertex's gradient is a function of the vertex (module
//! `render::gradient`, "Which brick a sample is read from"), so which
//! thread wins a claim does not change any bit.

use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::{Vec3, Vec3A};

use super::samples::{gather8_ref, Corners};

/// A brick's gradient plane: per sample its gradient, and per cell
/// whether its 8 vertices hold theirs. Empty for bricks without one.
#[derive(Debug, Default)]
pub struct GradPlane {
    /// Cells per axis (`cells + 1` samples).
    cells: [usize; 3],
    /// Per sample (x fastest) the gradient, written at most once (module
    /// docs).
    g: Vec<UnsafeCell<[f32; 3]>>,
    /// Per sample, whether a filler has claimed it (one bit each).
    claimed: Vec<AtomicU64>,
    /// Per sample, whether its gradient is written (one bit each).
    ready: Vec<AtomicU64>,
    /// Per cell (x fastest), whether `g` holds its vertices' gradients.
    set: Vec<AtomicU64>,
}

// SAFETY: the entries of `g` are only written by the one thread that
// claimed them, before they are marked ready, and only read through
// `cell` (the cell's own vertices, after an acquire of its bit, released
// only once all 8 were seen ready) or `sample` (after an acquire of the
// entry's own ready bit; module docs): no entry is written while another
// thread reads or writes it.
unsafe impl Sync for GradPlane {}

/// `n` bits, all clear.
fn bits(n: usize) -> Vec<AtomicU64> {
    (0..n.div_ceil(64)).map(|_| AtomicU64::new(0)).collect()
}

/// Word and mask of bit `i`.
#[inline(always)]
fn bit(i: usize) -> (usize, u64) {
    (i / 64, 1 << (i % 64))
}

impl GradPlane {
    /// An empty plane (no brick's).
    pub const EMPTY: GradPlane = GradPlane {
        cells: [0; 3],
        g: Vec::new(),
        claimed: Vec::new(),
        ready: Vec::new(),
        set: Vec::new(),
    };

    /// A plane holding `g` for the samples strictly inside a brick of
    /// `c` cells per axis (`c + 1` samples, x fastest): those samples are
    /// ready, the cells whose 8 vertices are all such samples are set,
    /// the others not yet.
    pub fn inner(g: &[Vec3], c: [usize; 3]) -> GradPlane {
        let s = c.map(|x| x + 1);
        assert_eq!(g.len(), s[0] * s[1] * s[2], "gradient plane size");
        let mut set = bits(c[0] * c[1] * c[2]);
        let mut ready = bits(g.len());
        // Sample i is inner on an axis of n cells when 1 <= i < n; cell l
        // (vertices l and l + 1) when 1 <= l and l + 2 <= n.
        for z in 1..c[2] {
            for y in 1..c[1] {
                for x in 1..c[0] {
                    let (w, m) = bit((z * s[1] + y) * s[0] + x);
                    *ready[w].get_mut() |= m;
                }
            }
        }
        let inside = |l: usize, n: usize| l >= 1 && l + 2 <= n;
        for z in 0..c[2] {
            for y in 0..c[1] {
                for x in 0..c[0] {
                    if inside(x, c[0]) && inside(y, c[1]) && inside(z, c[2]) {
                        let (w, m) = bit((z * c[1] + y) * c[0] + x);
                        *set[w].get_mut() |= m;
                    }
                }
            }
        }
        // Claimed as they are ready: no filler writes an inner sample.
        let claimed = ready
            .iter_mut()
            .map(|w| AtomicU64::new(*w.get_mut()))
            .collect();
        GradPlane {
            cells: c,
            g: g.iter().map(|v| UnsafeCell::new(v.to_array())).collect(),
            claimed,
            ready,
            set,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.g.is_empty()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.g.len() * std::mem::size_of::<[f32; 3]>()
            + (self.claimed.len() + self.ready.len() + self.set.len())
                * std::mem::size_of::<AtomicU64>()
    }

    /// Whether the plane holds the gradients of cell `cell`'s vertices
    /// (false for an empty plane).
    #[inline(always)]
    pub fn cell_set(&self, cell: usize) -> bool {
        let (w, m) = bit(cell);
        self.set
            .get(w)
            .is_some_and(|x| x.load(Ordering::Acquire) & m != 0)
    }

    /// Index of local cell `l` and its vertices, if `l` is one of the
    /// plane's cells.
    #[inline(always)]
    fn locate(&self, l: [u32; 3]) -> Option<(usize, Corners)> {
        let [x, y, z] = l.map(|v| v as usize);
        let c = self.cells;
        if x >= c[0] || y >= c[1] || z >= c[2] {
            return None;
        }
        let (sx, sy) = (c[0] + 1, c[1] + 1);
        let corners = Corners {
            base: (z * sy + y) * sx + x,
            sx,
            z: sx * sy,
        };
        Some(((z * c[1] + y) * c[0] + x, corners))
    }

    /// The gradients at the 8 vertices of local cell `l` (x fastest), if
    /// the cell is set; `None` otherwise.
    #[inline(always)]
    pub fn cell(&self, l: [u32; 3]) -> Option<[Vec3A; 8]> {
        let (i, c) = self.locate(l)?;
        if !self.cell_set(i) {
            return None;
        }
        // SAFETY: the cell's bit was seen with acquire, and it was
        // released after each of its 8 entries, the vertices `c` of that
        // same cell, was seen ready; no entry is written again (module
        // docs).
        Some(gather8_ref(&self.g, c, |v| {
            Vec3A::from(unsafe { *v.get() })
        }))
    }

    /// The gradient of sample `i` if it is ready (written); `None`
    /// otherwise.
    ///
    /// Panics if `i` lies beyond the plane.
    #[inline]
    pub fn sample(&self, i: usize) -> Option<Vec3A> {
        let (w, m) = bit(i);
        if self.ready[w].load(Ordering::Acquire) & m == 0 {
            return None;
        }
        // SAFETY: the entry's ready bit was seen with acquire, and it was
        // released after the entry's one write (module docs).
        Some(Vec3A::from(unsafe { *self.g[i].get() }))
    }

    /// Stores `g` at sample `i` unless the sample is claimed already (by
    /// this or another thread, which then writes it).
    pub fn fill_sample(&self, i: usize, g: Vec3) {
        let (w, m) = bit(i);
        if self.ready[w].load(Ordering::Acquire) & m != 0 {
            return;
        }
        if self.claimed[w].fetch_or(m, Ordering::Relaxed) & m != 0 {
            return;
        }
        // SAFETY: this thread alone claimed entry i, and nobody reads it
        // before it is marked ready below (module docs).
        unsafe { *self.g[i].get() = g.to_array() };
        self.ready[w].fetch_or(m, Ordering::Release);
    }

    /// Sets local cell `l` if all 8 of its vertices are ready, so that
    /// readers may read them.
    pub fn set_cell_if_ready(&self, l: [u32; 3]) {
        let Some((i, c)) = self.locate(l) else {
            return;
        };
        let ready = c.indices().iter().all(|&v| {
            let (w, m) = bit(v);
            self.ready[w].load(Ordering::Acquire) & m != 0
        });
        if ready {
            let (w, m) = bit(i);
            self.set[w].fetch_or(m, Ordering::Release);
        }
    }

    /// Stores `g` at the vertices of local cell `l` (x fastest), each
    /// unless it is claimed already, and sets the cell when all 8 are
    /// ready. A contended vertex leaves the cell unset: another fill sets
    /// it later.
    #[cfg(test)]
    pub fn fill(&self, l: [u32; 3], g: [Vec3; 8]) {
        let (_, c) = self.locate(l).expect("a cell of the plane");
        for (i, v) in c.indices().into_iter().zip(g) {
            self.fill_sample(i, v);
        }
        self.set_cell_if_ready(l);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vertices of cell `(x, y, z)` of a brick of `s` samples per axis.
    fn corners(s: [usize; 3], x: usize, y: usize, z: usize) -> Corners {
        Corners {
            base: (z * s[1] + y) * s[0] + x,
            sx: s[0],
            z: s[0] * s[1],
        }
    }

    /// Sample i's gradient in these tests: a function of the sample, as
    /// the renderer's are.
    fn grad(i: usize) -> Vec3 {
        Vec3::new(i as f32, -(i as f32), 0.5 * i as f32)
    }

    #[test]
    fn inner_cells_are_set_and_filled_cells_read_back() {
        let c = [3, 2, 4];
        let s = c.map(|x| x + 1);
        let n = s[0] * s[1] * s[2];
        let g: Vec<Vec3> = (0..n).map(grad).collect();
        let p = GradPlane::inner(&g, c);
        // A cell is inner on an axis of n cells when 1 <= l <= n - 2: on
        // the y axis of 2 cells none is, so no cell of `p` is set.
        let set: Vec<bool> = (0..c[0] * c[1] * c[2]).map(|i| p.cell_set(i)).collect();
        assert!(set.iter().all(|&x| !x), "{set:?}");
        let c2 = [4, 3, 4];
        let s2 = c2.map(|x| x + 1);
        let g2: Vec<Vec3> = (0..s2[0] * s2[1] * s2[2]).map(grad).collect();
        let p2 = GradPlane::inner(&g2, c2);
        let set: Vec<usize> = (0..c2[0] * c2[1] * c2[2])
            .filter(|&i| p2.cell_set(i))
            .collect();
        // x in 1..=2, y = 1, z in 1..=2.
        let cell2 = |x: usize, y: usize, z: usize| (z * c2[1] + y) * c2[0] + x;
        let want: Vec<usize> = [(1, 1, 1), (2, 1, 1), (1, 1, 2), (2, 1, 2)]
            .iter()
            .map(|&(x, y, z)| cell2(x, y, z))
            .collect();
        assert_eq!(set, want);
        assert!(!p2.cell_set(c2[0] * c2[1] * c2[2] + 64), "beyond the plane");
        // A set cell reads its vertices' gradients; an unset one nothing.
        let k = corners(s2, 2, 1, 1);
        let read = p2.cell([2, 1, 1]).expect("inner cell");
        assert_eq!(read, k.indices().map(|i| Vec3A::from(grad(i))));
        assert_eq!(p2.cell([0, 1, 1]), None);
        assert_eq!(p2.cell([4, 1, 1]), None, "beyond the plane");
        // Filling cell (0, 1, 1) writes its outer vertices and keeps the
        // inner ones (x = 1) as they were.
        let k = corners(s2, 0, 1, 1);
        let fill: [Vec3; 8] = std::array::from_fn(|v| Vec3::splat(-(v as f32) - 1.0));
        p2.fill([0, 1, 1], fill);
        let read = p2.cell([0, 1, 1]).expect("filled");
        for (v, i) in k.indices().into_iter().enumerate() {
            let want = if v % 2 == 1 { grad(i) } else { fill[v] };
            assert_eq!(read[v], Vec3A::from(want), "vertex {v}");
        }
        assert!(!p2.cell_set(cell2(0, 0, 1)));
        assert!(GradPlane::EMPTY.is_empty() && !GradPlane::EMPTY.cell_set(0));
        assert_eq!(GradPlane::EMPTY.cell([0, 0, 0]), None);
    }

    #[test]
    fn a_sample_claimed_elsewhere_leaves_the_cell_unset_until_ready() {
        let c = [2, 2, 2];
        let s = c.map(|x| x + 1);
        let all: Vec<Vec3> = (0..s[0] * s[1] * s[2]).map(grad).collect();
        let p = GradPlane::inner(&all, c);
        let k = corners(s, 0, 0, 0);
        let idx = k.indices();
        // Another filler has claimed vertex 0 (an outer sample; vertex 7 is
        // the one inner sample) and not yet written it.
        let (w, m) = bit(idx[0]);
        p.claimed[w].fetch_or(m, Ordering::Relaxed);
        let g: [Vec3; 8] = idx.map(grad);
        p.fill([0, 0, 0], g);
        assert!(!p.cell_set(0), "set before vertex 0 is ready");
        // That filler finishes; the next fill of the cell sets it.
        // SAFETY: this test plays the claiming thread; nothing reads the
        // entry before its ready bit below.
        unsafe { *p.g[idx[0]].get() = grad(idx[0]).to_array() };
        p.ready[w].fetch_or(m, Ordering::Release);
        p.fill([0, 0, 0], [Vec3::splat(f32::NAN); 8]);
        assert_eq!(
            p.cell([0, 0, 0]),
            Some(g.map(Vec3A::from)),
            "written once each"
        );
    }

    #[test]
    fn threads_filling_shared_vertices_read_every_gradient() {
        let c = [6, 5, 7];
        let s = c.map(|x| x + 1);
        let cells: Vec<[usize; 3]> = (0..c[2])
            .flat_map(|z| (0..c[1]).flat_map(move |y| (0..c[0]).map(move |x| [x, y, z])))
            .collect();
        for round in 0..20 {
            // The inner samples hold theirs; the threads fill the outer
            // layer, many vertices by more than one thread at once.
            let all: Vec<Vec3> = (0..s[0] * s[1] * s[2]).map(grad).collect();
            let p = GradPlane::inner(&all, c);
            std::thread::scope(|sc| {
                for t in 0..4 {
                    let (p, cells) = (&p, &cells);
                    sc.spawn(move || {
                        // Each thread walks the cells from its own start.
                        for j in 0..cells.len() {
                            let [x, y, z] = cells[(j * 7 + t * 11 + round) % cells.len()];
                            let k = corners(s, x, y, z);
                            match p.cell([x, y, z].map(|v| v as u32)) {
                                Some(got) => assert_eq!(got, k.indices().map(|i| grad(i).into())),
                                None => p.fill([x, y, z].map(|v| v as u32), k.indices().map(grad)),
                            }
                        }
                    });
                }
            });
            // One more pass sets the cells a contended fill left unset.
            for (cell, &[x, y, z]) in cells.iter().enumerate() {
                let k = corners(s, x, y, z);
                if !p.cell_set(cell) {
                    p.fill([x, y, z].map(|v| v as u32), k.indices().map(grad));
                }
                let got = p.cell([x, y, z].map(|v| v as u32)).expect("set");
                assert_eq!(
                    got,
                    k.indices().map(|i| Vec3A::from(grad(i))),
                    "cell {cell}"
                );
            }
        }
    }
}
