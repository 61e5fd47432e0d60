//! Named extreme cases for the traversal: grids, objects and rays at the
//! edges of what the arithmetic must handle (issue "numerical stability
//! at the extremes"). tests/all/extremes.rs checks every case against an
//! exact rational oracle; `cdvol experiment tradeoffs` replays them in f32
//! and f64 and counts where the two differ.
//!
//! The volumes live in memory ([`MemVolume`]), with codes computed by
//! brute force from the list of 1-cells, so a case can reach the format's
//! largest axis (a thin slab) without writing a file. The packed-file
//! path is covered by tests/all/traverse.rs and tests/all/extremes.rs.

use crate::grid::{Axis, MAX_SAMPLES_PER_AXIS};
use crate::render::traverse::OBJECT;
use crate::render::traverse::{trace, CodeSource, DistKind, Flow, Method, Ray, Real, TGrid, Visit};

/// Largest code the in-memory volume stores (the format's cap, docs/FORMAT.md).
pub const MAX_CODE: u8 = 254;

/// A volume of cells in memory: the 1-cells, and every cell's code.
#[derive(Debug, Clone)]
pub struct MemVolume {
    pub axes: [Axis; 3],
    pub ncells: [u32; 3],
    /// The 1-cells, sorted.
    pub objects: Vec<[u32; 3]>,
    /// Code per cell, x fastest; `None` for huge volumes, whose codes are
    /// computed on demand from `objects`.
    codes: Option<Vec<u8>>,
}

impl MemVolume {
    /// A volume over `axes` whose 1-cells are `objects`.
    pub fn new(axes: [Axis; 3], mut objects: Vec<[u32; 3]>) -> MemVolume {
        let ncells = axes.each_ref().map(|a| a.cells() as u32);
        objects.sort();
        objects.dedup();
        assert!(
            objects.iter().all(|c| (0..3).all(|k| c[k] < ncells[k])),
            "1-cell outside the grid"
        );
        let total: u64 = ncells.iter().map(|&n| n as u64).product();
        let mut v = MemVolume {
            axes,
            ncells,
            objects,
            codes: None,
        };
        if total <= 1 << 16 {
            let codes = (0..total)
                .map(|i| {
                    let c = [
                        (i % ncells[0] as u64) as u32,
                        (i / ncells[0] as u64 % ncells[1] as u64) as u32,
                        (i / (ncells[0] as u64 * ncells[1] as u64)) as u32,
                    ];
                    v.code_of(c)
                })
                .collect();
            v.codes = Some(codes);
        }
        v
    }

    /// The code by definition: chessboard distance to the nearest 1-cell,
    /// minus one (cells outside the volume are empty), capped at
    /// [`MAX_CODE`].
    fn code_of(&self, c: [u32; 3]) -> u8 {
        let mut best = MAX_CODE as u64 + 1;
        for o in &self.objects {
            let d = (0..3)
                .map(|k| c[k].abs_diff(o[k]) as u64)
                .max()
                .unwrap_or(0);
            if d == 0 {
                return OBJECT;
            }
            best = best.min(d);
        }
        (best - 1) as u8
    }

    pub fn is_object(&self, c: [u32; 3]) -> bool {
        self.objects.binary_search(&c).is_ok()
    }

    /// Sum of cells over the axes: [`trace`] takes at most this minus 2
    /// steps.
    pub fn step_bound(&self) -> u64 {
        self.ncells.iter().map(|&n| n as u64).sum::<u64>() - 2
    }
}

impl CodeSource for &MemVolume {
    fn code(&mut self, c: [u32; 3], _octant: Option<usize>) -> u8 {
        match &self.codes {
            Some(codes) => {
                let n = self.ncells;
                codes[((c[2] as usize * n[1] as usize) + c[1] as usize) * n[0] as usize
                    + c[0] as usize]
            }
            None => self.code_of(c),
        }
    }

    /// By definition: the largest level whose aligned node (clipped to
    /// the volume) holds no 1-cell, searched top-down over the list.
    fn empty_level(&mut self, c: [u32; 3]) -> Option<u8> {
        if self.is_object(c) {
            return None;
        }
        let top = self
            .ncells
            .iter()
            .map(|&n| n.next_power_of_two().trailing_zeros())
            .max();
        for l in (1..=top.unwrap_or(0)).rev() {
            let a = c.map(|x| (x >> l) << l);
            let inside = |o: &[u32; 3]| (0..3).all(|k| o[k] >= a[k] && o[k] - a[k] < (1 << l));
            if !self.objects.iter().any(inside) {
                return Some(l as u8);
            }
        }
        Some(0)
    }

    /// By brute force over `objects`, by definition (see [`distance_between`]).
    fn distance(&mut self, c: [u32; 3], kind: DistKind) -> u8 {
        self.objects
            .iter()
            .map(|o| distance_between(c, *o, kind))
            .min()
            .unwrap_or(u64::MAX)
            .min(MAX_CODE as u64) as u8
    }
}

/// Distance of `kind` between the centres of cells `a` and `b`, in stored
/// units ([`DistKind::unit`]), unsaturated. Chamfer 3-4-5: with the
/// absolute offsets sorted `p >= q >= r`, `3(p-q) + 4(q-r) + 5r`, the
/// length of the shortest 26-neighbour path with weights 3 (face), 4
/// (edge) and 5 (corner).
pub fn distance_between(a: [u32; 3], b: [u32; 3], kind: DistKind) -> u64 {
    let mut d = [0, 1, 2].map(|k| a[k].abs_diff(b[k]) as u64);
    match kind {
        DistKind::Cityblock => d.iter().sum(),
        DistKind::Chessboard => d[0].max(d[1]).max(d[2]),
        DistKind::Chamfer => {
            d.sort_unstable_by(|x, y| y.cmp(x));
            3 * (d[0] - d[1]) + 4 * (d[1] - d[2]) + 5 * d[2]
        }
    }
}

/// The result of walking one ray: the visits and the step count.
#[derive(Debug, Clone, PartialEq)]
pub struct Walked {
    pub visits: Vec<Visit>,
    pub steps: u64,
}

/// Walks `ray` through `vol` with `method` in arithmetic `T` from `t = 0`,
/// collecting every 1-cell visit.
pub fn walk<T: Real>(vol: &MemVolume, grid: &TGrid<T>, ray: &Ray, method: Method) -> Walked {
    walk_from(vol, grid, ray, 0.0, method)
}

/// [`walk`] from `t_min` on.
pub fn walk_from<T: Real>(
    vol: &MemVolume,
    grid: &TGrid<T>,
    ray: &Ray,
    t_min: f64,
    method: Method,
) -> Walked {
    let mut visits = Vec::new();
    let mut src = vol;
    let c = trace(grid, ray, t_min, method, &mut src, |v, _| {
        visits.push(*v);
        Flow::Continue
    });
    Walked {
        visits,
        steps: c.steps,
    }
}

/// Which invariant of [`check_walk`] a walk broke, with the visit at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WalkError {
    /// More steps than [`MemVolume::step_bound`].
    #[error("{steps} steps > bound {bound}")]
    TooManySteps { steps: u64, bound: u64 },
    /// A visit of a cell that is not a 1-cell.
    #[error("visited a 0-cell {cell:?}")]
    ZeroCell { cell: [u32; 3] },
    /// `t_enter` or `t_exit` is NaN or infinite.
    #[error("non-finite t in {visit:?}")]
    NonFinite { visit: Visit },
    /// `t_enter >= t_exit`.
    #[error("empty visit {visit:?}")]
    Empty { visit: Visit },
    /// The visit starts before the previous one ended.
    #[error("t went back at {visit:?} (after {prev})")]
    WentBack { visit: Visit, prev: f64 },
    /// The visit starts before `t_min`.
    #[error("{visit:?} before t_min {t_min}")]
    BeforeTMin { visit: Visit, t_min: f64 },
}

/// The invariants every walk keeps, in any arithmetic: at most
/// [`MemVolume::step_bound`] steps; every visit a 1-cell with finite
/// `t_enter < t_exit`; visits never going back in `t`; and, where given,
/// none before `t_min` (f32 walks round `t_min`, so tests pass `None`).
pub fn check_walk(vol: &MemVolume, w: &Walked, t_min: Option<f64>) -> Result<(), WalkError> {
    if w.steps > vol.step_bound() {
        return Err(WalkError::TooManySteps {
            steps: w.steps,
            bound: vol.step_bound(),
        });
    }
    let mut prev = f64::NEG_INFINITY;
    for &visit in &w.visits {
        if !vol.is_object(visit.cell) {
            return Err(WalkError::ZeroCell { cell: visit.cell });
        }
        if !(visit.t_enter.is_finite() && visit.t_exit.is_finite()) {
            return Err(WalkError::NonFinite { visit });
        }
        if !(visit.t_enter < visit.t_exit) {
            return Err(WalkError::Empty { visit });
        }
        if visit.t_enter < prev {
            return Err(WalkError::WentBack { visit, prev });
        }
        if let Some(t_min) = t_min.filter(|&t| visit.t_enter < t) {
            return Err(WalkError::BeforeTMin { visit, t_min });
        }
        prev = visit.t_exit;
    }
    Ok(())
}

/// A named grid.
pub struct GridCase {
    pub name: &'static str,
    pub axes: [Axis; 3],
}

fn ax(coords: Vec<f64>) -> Axis {
    Axis::from_coords(coords).expect("corpus axis")
}

fn uniform(origin: f64, h: f64, n: usize) -> Axis {
    Axis::uniform(origin, h, n).expect("corpus axis")
}

/// The grids of the corpus. Every one is small except `format-max-x`,
/// which has [`MAX_SAMPLES_PER_AXIS`] samples along x (a thin slab).
pub fn grids(with_huge: bool) -> Vec<GridCase> {
    let mut g = vec![
        GridCase {
            name: "unit-8",
            axes: [
                uniform(0.0, 1.0, 9),
                uniform(0.0, 1.0, 9),
                uniform(0.0, 1.0, 9),
            ],
        },
        GridCase {
            name: "one-cell-x",
            axes: [
                uniform(-1.0, 2.0, 2),
                uniform(0.0, 0.5, 7),
                uniform(0.0, 1.5, 6),
            ],
        },
        GridCase {
            name: "one-cell-every-axis",
            axes: [
                uniform(0.0, 1.0, 2),
                uniform(0.0, 3.0, 2),
                uniform(0.0, 0.25, 2),
            ],
        },
        GridCase {
            name: "axis-ratio-1e-4-1-1e4",
            axes: [
                uniform(0.0, 1e-4, 7),
                uniform(0.0, 1.0, 7),
                uniform(0.0, 1e4, 7),
            ],
        },
        GridCase {
            name: "slice-ratio-1e4",
            axes: [
                uniform(0.0, 1.0, 6),
                uniform(0.0, 1.0, 6),
                ax(vec![
                    0.0,
                    1e-2,
                    1e2 + 1e-2,
                    1e2 + 2e-2,
                    2e2 + 2e-2,
                    2e2 + 3e-2,
                    3e2 + 3e-2,
                ]),
            ],
        },
        GridCase {
            name: "offset-1e6",
            axes: [
                uniform(1e6, 0.5, 7),
                uniform(-1e6, 0.75, 6),
                ax(vec![1e6, 1e6 + 0.6, 1e6 + 2.5, 1e6 + 3.0, 1e6 + 4.7]),
            ],
        },
        GridCase {
            name: "gap-1e-9-at-1e6",
            axes: [
                uniform(0.0, 1.0, 5),
                ax(vec![
                    1e6,
                    1e6 + 1e-9,
                    1e6 + 1.0,
                    1e6 + 1.0 + 1e-9,
                    1e6 + 2.0,
                ]),
                ax(vec![0.0, 1e-9, 2e-9, 1.0, 1.0 + 1e-9, 3.0]),
            ],
        },
        GridCase {
            name: "rectilinear-mixed",
            axes: [
                ax(vec![-3.0, -2.5, -0.5, 0.0, 0.25, 4.0, 4.125]),
                ax(vec![0.0, 1.0, 1.5, 3.5, 3.75, 6.0]),
                ax(vec![10.0, 10.5, 12.5, 13.0, 16.0, 16.1, 17.0, 20.0]),
            ],
        },
    ];
    if with_huge {
        g.push(GridCase {
            name: "format-max-x",
            axes: [
                uniform(0.0, 1.0, MAX_SAMPLES_PER_AXIS),
                uniform(0.0, 1.0, 2),
                uniform(0.0, 1.0, 3),
            ],
        });
    }
    g
}

/// Named object patterns over a grid with `n` cells per axis.
pub fn objects(n: [u32; 3]) -> Vec<(&'static str, Vec<[u32; 3]>)> {
    let total: u64 = n.iter().map(|&x| x as u64).product();
    let mut out = vec![
        ("all-empty", vec![]),
        ("corners", corners(n)),
        ("centre", vec![[n[0] / 2, n[1] / 2, n[2] / 2]]),
    ];
    if total <= 4096 {
        let all: Vec<[u32; 3]> = (0..n[2])
            .flat_map(|z| (0..n[1]).flat_map(move |y| (0..n[0]).map(move |x| [x, y, z])))
            .collect();
        // A checkerboard-ish scatter: every cell whose index sum is 0 mod 5.
        let sparse = all
            .iter()
            .copied()
            .filter(|c| (c[0] + 2 * c[1] + 3 * c[2]) % 5 == 0)
            .collect();
        out.push(("all-full", all));
        out.push(("scatter-1-in-5", sparse));
    } else {
        // Huge slab: a few 1-cells along x, the last one in the last cell.
        let xs = [0, 1, n[0] / 3, n[0] / 2 + 7, n[0] - 1];
        out.push((
            "sparse-along-x",
            xs.iter().map(|&x| [x, n[1] - 1, n[2] / 2]).collect(),
        ));
    }
    out
}

fn corners(n: [u32; 3]) -> Vec<[u32; 3]> {
    let mut v = Vec::new();
    for i in 0..8u32 {
        v.push([
            if i & 1 == 0 { 0 } else { n[0] - 1 },
            if i & 2 == 0 { 0 } else { n[1] - 1 },
            if i & 4 == 0 { 0 } else { n[2] - 1 },
        ]);
    }
    v
}

/// Named rays for a grid: origins on samples, faces, edges and corners,
/// inside cells and far away; directions along axes (with 0.0 and -0.0),
/// through lattice diagonals, with 1e-30 and subnormal components, not
/// normalised, and of huge magnitude.
pub fn rays(axes: &[Axis; 3]) -> Vec<(String, Ray)> {
    let c: [&[f64]; 3] = [axes[0].coords(), axes[1].coords(), axes[2].coords()];
    let lo: [f64; 3] = std::array::from_fn(|k| c[k][0]);
    let hi: [f64; 3] = std::array::from_fn(|k| c[k][c[k].len() - 1]);
    let mid_sample: [f64; 3] = std::array::from_fn(|k| c[k][c[k].len() / 2]);
    let in_cell: [f64; 3] = std::array::from_fn(|k| {
        let i = (c[k].len() - 1) / 2;
        c[k][i] + 0.375 * (c[k][i + 1] - c[k][i])
    });
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let sub = f64::MIN_POSITIVE / 4.0; // a subnormal
    let dirs: Vec<(&str, [f64; 3])> = vec![
        ("+x", [1.0, 0.0, 0.0]),
        ("-x-0", [-1.0, -0.0, -0.0]),
        ("+y", [0.0, 1.0, 0.0]),
        ("-y", [0.0, -1.0, 0.0]),
        ("+z-0", [-0.0, 0.0, 1.0]),
        ("-z", [0.0, 0.0, -1.0]),
        ("diag+++", [1.0, 1.0, 1.0]),
        ("diag-+-", [-1.0, 1.0, -1.0]),
        ("xy-plane", [1.0, -1.0, 0.0]),
        ("1e-30", [1.0, 1e-30, -1e-30]),
        ("subnormal", [sub, 1.0, -sub]),
        ("min-subnormal", [-5e-324, 5e-324, 1.0]),
        // Near MAX_DIR (2^600 = 4.15e180), the largest Ray::new accepts.
        ("huge", [4e180, -3e179, 7e179]),
        ("unnormalised", [3.0, -7.0, 11.0]),
        ("tiny-overall", [3e-150, 2e-150, -1e-150]),
        ("skew", [0.3, -0.5, 0.7]),
    ];
    let span: f64 = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    let mut out = Vec::new();
    for (dn, d) in &dirs {
        let len = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        let unit = if len.is_finite() && len > 0.0 {
            d.map(|x| x / len)
        } else {
            let m = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            d.map(|x| x / m)
        };
        let origins: Vec<(&str, [f64; 3])> = vec![
            ("at-lo-corner", lo),
            ("at-hi-corner", hi),
            ("on-mid-sample", mid_sample),
            ("inside-cell", in_cell),
            ("on-lo-x-face", [lo[0], in_cell[1], in_cell[2]]),
            ("on-edge", [lo[0], hi[1], in_cell[2]]),
            (
                "outside-1e9",
                std::array::from_fn(|k| centre[k] - 1e9 * unit[k]),
            ),
            (
                "before-mid-sample",
                std::array::from_fn(|k| mid_sample[k] - 2.0 * span * unit[k]),
            ),
            // Grazes the box: runs in the plane of the lo-y face.
            (
                "graze-lo-y",
                [centre[0] - 2.0 * span, lo[1], centre[2] - 2.0 * span],
            ),
        ];
        for (on, o) in origins {
            let ray = Ray::new(o, *d).expect("corpus rays are valid");
            out.push((format!("{on}/{dn}"), ray));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The brute-force distances of the in-memory volume equal the
        /// streaming transforms of src/dt.rs (and the chessboard one the
        /// code plus one).
        #[test]
        fn mem_volume_distances_equal_the_transforms(
            dims in [1usize..8, 1usize..8, 1usize..8],
            bits in proptest::collection::vec(0u8..12, 512),
        ) {
            let n = dims.iter().product::<usize>();
            let obj: Vec<u8> = bits[..n].iter().map(|&b| (b == 0) as u8).collect();
            let objects: Vec<[u32; 3]> = (0..n)
                .filter(|&i| obj[i] != 0)
                .map(|i| [(i % dims[0]) as u32, (i / dims[0] % dims[1]) as u32, (i / dims[0] / dims[1]) as u32])
                .collect();
            let axes = dims.map(|d| Axis::uniform(0.0, 1.0, d + 1).expect("axis"));
            let vol = MemVolume::new(axes, objects);
            let [cb, ch] = crate::dt::dda_3d(&obj, dims);
            let cheb = crate::dt::chessboard_3d(&obj, dims);
            let mut src = &vol;
            for i in 0..n {
                let c = [(i % dims[0]) as u32, (i / dims[0] % dims[1]) as u32, (i / dims[0] / dims[1]) as u32];
                prop_assert_eq!(src.distance(c, DistKind::Cityblock), cb[i]);
                prop_assert_eq!(src.distance(c, DistKind::Chamfer), ch[i]);
                prop_assert_eq!(src.distance(c, DistKind::Chessboard), cheb[i].min(254));
            }
        }
    }
}
