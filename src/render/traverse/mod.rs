//! Ray traversal of rectilinear grids (paper section 4.1, Figs. 8, 11, 12).
//!
//! Rays are in millimetres; cells are indices of the secondary cubic grid
//! (paper eq. 9). Every axis with a negative direction component is
//! mirrored (`S'[i] = -S[n-1-i]`, section 4.1), so the walk only ever
//! moves towards higher indices; `-0.0` counts as non-negative and zero
//! components never divide (their planes are never crossed).
//!
//! All traversals share one parametrisation: the ray crosses plane `j` of
//! axis `k` at `t = plane_t(k, j) = (S'_k[j] - o'_k) / d'_k`, and the cell
//! along `k` at parameter `t` is the largest `j` with `plane_t(k, j) <= t`.
//! FVT (Cleary-Wyvill, Amanatides-Woo) crosses the planes one at a time;
//! CD jumps from cell `v` with code `n` to the nearest far face of its
//! empty cube, `S'[v + n + 1]` (eq. 12, where the paper's `N` is `n + 1`),
//! then *Locate*s the other axes by the same rule in `t`, by binary search
//! bounded by the cube on rectilinear axes and by direct computation on
//! uniform ones. Because both use the same `plane_t`, CD lands exactly in
//! the cell FVT reaches after crossing every plane with `t` up to the
//! landing point, and the two yield the same 1-cells with positive length
//! (cells a ray only grazes at an edge or corner have `t_exit == t_enter`
//! and are skipped by every traversal alike).
//!
//! Termination: every step raises at least one cell index by one and lowers
//! none, so a ray takes at most `ncx + ncy + ncz - 2` steps (the suite in
//! tests/all/extremes.rs checks this bound on every ray).
//!
//! Precision: [`trace`] is generic over [`Real`] (`f64` or `f32`). In f64
//! every computed crossing is the exact one times `(1 + e)`, `|e| <= 3u`
//! (`u = 2^-53`), and crossings are compared only through these values, so
//! the walk equals the exact one except for cells whose exact length along
//! the ray is within `6u * |t|` of zero; tests/all/extremes.rs checks exactly
//! this against rational arithmetic. f32 adds the rounding of origins and
//! sample positions to 24 bits, relative to their magnitude: it misses
//! cells (docs/TRADEOFFS.md), so f64 is the default.

use num_traits::Float;

use crate::grid::Axis;

mod cd;
mod dda;
mod frame;
mod fvt;
mod octree;
mod ray;
mod walker;

pub use cd::Cd;
pub use dda::Dda;
pub use fvt::Fvt;
pub use octree::Octree;
pub use ray::{Ray, RayError, MAX_DIR, MIN_DIR};
pub use walker::{CellWalker, Walker};

/// Code of a 1-cell in a [`CodeSource`]'s answers (and in the decoded code
/// plane of the render cache): every other value is a 0-cell's code,
/// saturated at 254.
pub const OBJECT: u8 = 255;

/// Arithmetic the walk runs in: `f64` (the default: it never misses a
/// 1-cell in the extreme-case suite) or `f32` (measured in
/// docs/TRADEOFFS.md). One generic walk, not two copies.
pub trait Real: Float + Send + Sync + std::fmt::Debug + 'static {
    /// Nearest value of this type (f64 -> f32 rounds; may overflow to inf).
    fn of(x: f64) -> Self;
    fn f64(self) -> f64;
}

impl Real for f64 {
    #[inline(always)]
    fn of(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

impl Real for f32 {
    #[inline(always)]
    fn of(x: f64) -> f32 {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

/// Where the walk reads cell codes: the renderer's brick accessor, or an
/// in-memory volume in tests and the fuzz target.
pub trait CodeSource {
    /// Code of cell `c` ([`OBJECT`] for a 1-cell). With `Some(octant)`, the
    /// larger of its isotropic code and its block's code for that octant
    /// (section 4.2.1): both cubes are empty, so the larger leap is safe.
    fn code(&mut self, c: [u32; 3], octant: Option<usize>) -> u8;

    /// Distance of the DDA generators (paper section 3, Figs. 4, 5, 19)
    /// from the centre of cell `c` to the centre of the nearest 1-cell, in
    /// stored units ([`DistKind::unit`]): 0 for a 1-cell, saturating at
    /// 254. The default derives it from the chessboard code, a lower bound
    /// for all three kinds (`L1 >= Linf`, chamfer 3-4-5 `>= 3 Linf`), so
    /// it is always safe, if short, for sources without DDA planes.
    fn distance(&mut self, c: [u32; 3], kind: DistKind) -> u8 {
        let code = self.code(c, None);
        if code == OBJECT {
            return 0;
        }
        let d = code as u32 + 1;
        (d * kind.unit()).min(254) as u8
    }

    /// Largest level `L` such that the octree node of `2^L` cells per
    /// axis, aligned to multiples of `2^L` in the original grid, that
    /// contains cell `c` holds no 1-cell; `None` for a 1-cell. The default
    /// knows only the cell itself (level 0).
    fn empty_level(&mut self, c: [u32; 3]) -> Option<u8> {
        (self.code(c, None) != OBJECT).then_some(0)
    }
}

/// Distance types of the DDA ray generators (RADC, proximity clouds;
/// paper section 3, Fig. 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub enum DistKind {
    /// `L1`, stored in cells (exact two-pass transform).
    Cityblock,
    /// `Linf`, stored in cells: the CD code plus one.
    Chessboard,
    /// Chamfer 3-4-5 (Borgefors), approximating the Euclidean distance,
    /// stored in thirds of a cell.
    Chamfer,
}

impl DistKind {
    /// Stored units per cell.
    pub fn unit(self) -> u32 {
        match self {
            DistKind::Chamfer => 3,
            _ => 1,
        }
    }

    /// Stable name (`cityblock`, `chessboard`, `chamfer`).
    pub fn name(self) -> &'static str {
        match self {
            DistKind::Cityblock => "cityblock",
            DistKind::Chessboard => "chessboard",
            DistKind::Chamfer => "chamfer",
        }
    }
}

/// Which ray generator to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Single-cell steps (the reference).
    Fvt,
    /// Chessboard-distance macro steps over cells with code `>= min_leap`,
    /// single-cell steps elsewhere (1 = the paper).
    Cd { min_leap: u8 },
    /// CD with the octant (anisotropic) codes of section 4.2.1.
    CdAniso { min_leap: u8 },
    /// Octree (min-max pyramid) traversal in the spirit of SMART (paper
    /// section 5.1): at each cell the largest empty aligned node holding
    /// it is found top-down ([`CodeSource::empty_level`]) and the ray
    /// leaps to the node's exit face by the same step as CD, so it lands
    /// exactly where FVT would.
    Octree,
    /// Floating-point 3D DDA with distance-coded leaps (RADC, proximity
    /// clouds; paper section 3, eqs. 2-3): from a sample in a cell at
    /// distance `d`, the next sample is `(d - 1) / D(r)` further along the
    /// ray (`D` the ray direction's norm in the distance's metric, in cell
    /// units; `- 1` because distances are from cell centres), at least one
    /// cell along the major axis. With `switch_fvt`, cells whose free
    /// length along the ray is shorter than that one DDA step are walked
    /// by single-cell steps until a leap is possible again; without it the
    /// DDA samples one cell per major-axis step there and may miss 1-cells
    /// (Fig. 18a only).
    /// Regular grids only (every axis uniform).
    Dda { kind: DistKind, switch_fvt: bool },
}

impl Method {
    /// Whether every 1-cell the FVT visits is visited, in the same order
    /// with the same entry and exit (tests/all/generators.rs checks these bit
    /// for bit against FVT).
    pub fn is_exact(self) -> bool {
        match self {
            Method::Dda { kind, switch_fvt } => switch_fvt && kind == DistKind::Chessboard,
            _ => true,
        }
    }

    /// Whether the method needs every axis uniform.
    pub fn needs_regular_grid(self) -> bool {
        matches!(self, Method::Dda { .. })
    }

    /// Stable name for stats, part-file keys and messages: the traversal's
    /// name as `cdvol render --traversal` spells it, followed by any
    /// parameter that differs from that traversal's default
    /// (`cd min_leap=3`, `dda-chamfer no_switch`). Never Debug text.
    pub fn name(self) -> String {
        match self {
            Method::Fvt => "fvt".into(),
            Method::Octree => "octree".into(),
            Method::Cd { min_leap } | Method::CdAniso { min_leap } => {
                let base = if matches!(self, Method::Cd { .. }) {
                    "cd"
                } else {
                    "cd-aniso"
                };
                if min_leap <= 1 {
                    base.into()
                } else {
                    format!("{base} min_leap={min_leap}")
                }
            }
            Method::Dda { kind, switch_fvt } => {
                let base = format!("dda-{}", kind.name());
                if switch_fvt {
                    base
                } else {
                    format!("{base} no_switch")
                }
            }
        }
    }
}

/// One axis in both orientations.
#[derive(Debug, Clone)]
struct TAxis<T> {
    /// Increasing sample positions, as given and mirrored.
    s: [Vec<T>; 2],
    /// Spacing `h` of a uniform axis (both orientations share it).
    uniform: Option<T>,
    /// `1 / h` on a uniform axis, else 0.
    inv_h: T,
}

/// The grid as the traversal sees it: per axis the positions in both
/// orientations, in the walk's arithmetic, computed once per image.
#[derive(Debug, Clone)]
pub struct TGrid<T = f64> {
    axes: [TAxis<T>; 3],
    pub ncells: [u32; 3],
}

impl<T: Real> TGrid<T> {
    pub fn new(axes: &[Axis; 3]) -> TGrid<T> {
        let ta = |a: &Axis| {
            let c: Vec<T> = a.coords().iter().map(|&x| T::of(x)).collect();
            let m: Vec<T> = c.iter().rev().map(|&x| -x).collect();
            let co = a.coords();
            let h = (co[co.len() - 1] - co[0]) / (co.len() - 1) as f64;
            let uniform = a.is_uniform().then_some(T::of(h));
            TAxis {
                s: [c, m],
                uniform,
                inv_h: uniform.map_or(T::zero(), |h| T::one() / h),
            }
        };
        TGrid {
            axes: [ta(&axes[0]), ta(&axes[1]), ta(&axes[2])],
            ncells: [
                (axes[0].samples() - 1) as u32,
                (axes[1].samples() - 1) as u32,
                (axes[2].samples() - 1) as u32,
            ],
        }
    }

    /// Lower and upper corner of the volume in mm (as this arithmetic
    /// holds them).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let lo = std::array::from_fn(|k| self.axes[k].s[0][0].f64());
        let hi = std::array::from_fn(|k| self.axes[k].s[0].last().expect("axis").f64());
        (lo, hi)
    }
}

/// A 1-cell the ray passes through with positive length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Visit {
    /// Cell index in the original (unmirrored) grid.
    pub cell: [u32; 3],
    pub t_enter: f64,
    pub t_exit: f64,
}

/// Step counts of one ray (summed per tile).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct StepCounts {
    /// All traversal steps.
    pub steps: u64,
    /// Steps over a macro region (code > 0).
    pub macro_steps: u64,
    /// Single-cell steps.
    pub cell_steps: u64,
}

impl StepCounts {
    pub fn add(&mut self, o: &StepCounts) {
        self.steps += o.steps;
        self.macro_steps += o.macro_steps;
        self.cell_steps += o.cell_steps;
    }
}

/// What the integrator tells the traversal after a visit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    Continue,
    Stop,
    /// Nothing in the visited cell's node of `2^l` cells per axis
    /// (aligned to multiples of `2^l` in the original grid, as the
    /// octree's) matters to the integrator: the cell-stepping walkers
    /// leap out of the node through its nearest far face (FVT, CD and the
    /// octree; the DDA generators and template walks go on as for
    /// [`Flow::Continue`]). The walk after the leap is the exact one from
    /// where the ray leaves the node, so the 1-cells skipped are exactly
    /// the node's.
    LeapNode(u8),
}

/// Walks `ray` through the grid from `t_min` on with `method`, calling
/// `visit` for every 1-cell it passes with positive length, in order, until
/// `visit` says stop or the ray leaves the volume. Returns the step counts.
/// A ray that fails [`Ray::check`], or a non-finite `t_min`, visits nothing
/// (see `frame::Frame::new` for how extreme directions are
/// scaled).
///
/// The method is chosen once per ray; the loop then runs one walker
/// ([`Walker`]) to the end, so no step tests which method it is in.
///
/// Termination: every step raises one cell index by at least one and
/// never lowers another, so a ray takes at most `ncx + ncy + ncz - 2`
/// steps.
pub fn trace<T, S, F>(
    grid: &TGrid<T>,
    ray: &Ray,
    t_min: f64,
    method: Method,
    src: &mut S,
    visit: F,
) -> StepCounts
where
    T: Real,
    S: CodeSource,
    F: FnMut(&Visit, &mut S) -> Flow,
{
    trace_until(grid, ray, t_min, f64::INFINITY, method, src, visit)
}

/// [`trace`] that also stops where the ray reaches `t_max` (a clip's far
/// face, render/clip.rs): no cell beyond it is entered, so no code beyond
/// it is read; a visit there ends at `t_max` (within the walk's rounding).
pub fn trace_until<T, S, F>(
    grid: &TGrid<T>,
    ray: &Ray,
    t_min: f64,
    t_max: f64,
    method: Method,
    src: &mut S,
    visit: F,
) -> StepCounts
where
    T: Real,
    S: CodeSource,
    F: FnMut(&Visit, &mut S) -> Flow,
{
    if ray.check().is_err() || !t_min.is_finite() || t_max.is_nan() {
        return StepCounts::default();
    }
    let f = frame::Frame::new(grid, ray);
    let Some(e) = f.entry(ray, t_min, t_max) else {
        return StepCounts::default();
    };
    match method {
        Method::Fvt => drive(CellWalker::new(&f, e, Fvt), src, visit),
        Method::Cd { min_leap } => {
            let rule = Cd {
                min_leap: min_leap.max(1),
                octant: None,
            };
            drive(CellWalker::new(&f, e, rule), src, visit)
        }
        Method::CdAniso { min_leap } => {
            let rule = Cd {
                min_leap: min_leap.max(1),
                octant: Some(f.octant()),
            };
            drive(CellWalker::new(&f, e, rule), src, visit)
        }
        Method::Octree => drive(CellWalker::new(&f, e, Octree), src, visit),
        Method::Dda { kind, switch_fvt } => drive(Dda::new(&f, e, kind, switch_fvt), src, visit),
    }
}

/// Runs walker `w` to the end or until `visit` says stop.
#[inline(always)]
fn drive<S, W, F>(mut w: W, src: &mut S, visit: F) -> StepCounts
where
    W: Walker<S>,
    F: FnMut(&Visit, &mut S) -> Flow,
{
    w.walk(src, visit)
}

#[cfg(test)]
mod tests {
    //! The two ways to drive a walker give the same walk: pulling visits
    //! with [`Walker::next_visit`] and pushing them with [`Walker::walk`]
    //! yield the same 1-cells with the same `t`, and the same step counts
    //! when stopped after any visit. (That these walks are the exact ones
    //! is checked against FVT and an exact enumeration in tests/all/.)
    use super::frame::Frame;
    use super::*;
    use proptest::prelude::*;

    /// Codes from a table, consistent or not: both drives must agree on
    /// any input.
    struct Table {
        n: [u32; 3],
        codes: Vec<u8>,
    }

    impl CodeSource for Table {
        fn code(&mut self, c: [u32; 3], _: Option<usize>) -> u8 {
            self.codes[((c[2] * self.n[1] + c[1]) * self.n[0] + c[0]) as usize]
        }
    }

    /// One `next_visit` call and the counts after it.
    type Pull<'a> = Box<dyn FnMut(&mut Table) -> (Option<Visit>, StepCounts) + 'a>;

    /// Visits and counts of `method` on `ray`, pulled one by one, and the
    /// counts after each visit.
    fn pulled(
        g: &TGrid<f64>,
        ray: &Ray,
        method: Method,
        src: &mut Table,
    ) -> (Vec<Visit>, Vec<StepCounts>) {
        let f = Frame::new(g, ray);
        let Some(e) = f.entry(ray, 0.0, f64::INFINITY) else {
            return (Vec::new(), vec![StepCounts::default()]);
        };
        let mut w: Pull<'_> = match method {
            Method::Fvt => {
                let mut w = CellWalker::new(&f, e, Fvt);
                Box::new(move |s| (w.next_visit(s), Walker::<Table>::counts(&w)))
            }
            Method::Cd { min_leap } => {
                let rule = Cd {
                    min_leap,
                    octant: None,
                };
                let mut w = CellWalker::new(&f, e, rule);
                Box::new(move |s| (w.next_visit(s), Walker::<Table>::counts(&w)))
            }
            Method::Octree => {
                let mut w = CellWalker::new(&f, e, Octree);
                Box::new(move |s| (w.next_visit(s), Walker::<Table>::counts(&w)))
            }
            Method::Dda { kind, switch_fvt } => {
                let mut w = Dda::new(&f, e, kind, switch_fvt);
                Box::new(move |s| (w.next_visit(s), Walker::<Table>::counts(&w)))
            }
            Method::CdAniso { .. } => unreachable!("not generated"),
        };
        let (mut visits, mut counts) = (Vec::new(), Vec::new());
        // A ray crosses at most ncx + ncy + ncz - 2 cells.
        let bound = (g.ncells.iter().sum::<u32>()) as usize;
        loop {
            let (v, c) = w(src);
            assert!(
                visits.len() <= bound,
                "{method:?} yields more visits than cells"
            );
            match v {
                Some(v) => {
                    visits.push(v);
                    counts.push(c);
                }
                None => {
                    counts.push(c);
                    return (visits, counts);
                }
            }
        }
    }

    proptest! {
        /// Locate with the plane after the cell it finds: the cell a scan
        /// of every plane finds, and that plane's `t` bit for bit, on
        /// uniform axes (estimate and correction) and rectilinear ones
        /// (binary search), both orientations, any `t` in or beyond the
        /// bounds searched.
        #[test]
        fn locate_next_gives_the_plane_after_the_cell(
            gaps in proptest::collection::vec(0.05f64..3.0, 1..40),
            uniform in any::<bool>(),
            o in -5.0f64..80.0,
            d in prop_oneof![-2.0f64..-0.01, 0.01f64..2.0],
            t in -50.0f64..150.0,
            bounds in (0usize..40, 0usize..40),
            on in (0usize..40, 0usize..4),
        ) {
            let axis = if uniform {
                crate::grid::Axis::uniform(-1.0, gaps[0], gaps.len() + 1).expect("axis")
            } else {
                let mut p = vec![-1.0];
                for g in &gaps {
                    p.push(p[p.len() - 1] + g);
                }
                crate::grid::Axis::from_coords(p).expect("axis")
            };
            let cells = axis.cells() as u32;
            let g = TGrid::<f64>::new(&[axis.clone(), axis.clone(), axis]);
            let ray = Ray::new([o, o, o], [d, 0.3, -0.2]).expect("finite ray");
            let f = Frame::new(&g, &ray);
            let (a, b) = (bounds.0 as u32 % cells, bounds.1 as u32 % cells);
            let (lo, hi) = (a.min(b), a.max(b));
            // Also on, just before and just after a plane, where the
            // uniform estimate can land a cell off and be corrected.
            let p = f.plane_t(0, on.0 as u32 % (cells + 1));
            let t = [t, p, p.next_down(), p.next_up()][on.1];
            // Locate's precondition: the plane of `lo` is at or before t.
            let t = t.max(f.plane_t(0, lo));
            let (j, after) = f.locate_next(0, t, lo, hi);
            // The oracle: the largest j in [lo, hi] whose plane is at or
            // before t, by scanning every plane.
            let want = (lo..=hi).rev().find(|&i| f.plane_t(0, i) <= t).expect("lo qualifies");
            prop_assert_eq!(j, want);
            if let Some(after) = after {
                prop_assert_eq!(after.to_bits(), f.plane_t(0, j + 1).to_bits());
            }
        }
    }

    fn method() -> impl Strategy<Value = Method> {
        prop_oneof![
            Just(Method::Fvt),
            (1u8..4).prop_map(|min_leap| Method::Cd { min_leap }),
            Just(Method::Octree),
            (0usize..3, any::<bool>()).prop_map(|(k, switch_fvt)| Method::Dda {
                kind: [DistKind::Cityblock, DistKind::Chessboard, DistKind::Chamfer][k],
                switch_fvt,
            }),
        ]
    }

    proptest! {
        #[test]
        fn pulled_and_pushed_walks_agree(
            n in proptest::array::uniform3(1u32..7),
            seed in proptest::collection::vec(0u8..8, 343),
            o in proptest::array::uniform3(-3.0f64..10.0),
            d in proptest::array::uniform3(-1.0f64..1.0),
            method in method(),
            stop_at in 0usize..6,
        ) {
            prop_assume!(d.iter().any(|x| x.abs() > 1e-3));
            let axes = n.map(|c| {
                crate::grid::Axis::uniform(0.0, 1.0, c as usize + 1).expect("axis")
            });
            let g = TGrid::<f64>::new(&axes);
            let cells = (n[0] * n[1] * n[2]) as usize;
            // 0..5: codes, 6 and 7: 1-cells.
            let codes = seed[..cells].iter().map(|&x| if x >= 6 { OBJECT } else { x }).collect();
            let mut src = Table { n, codes };
            let ray = Ray::new(o, d).expect("finite ray");
            let (visits, counts) = pulled(&g, &ray, method, &mut src);
            // Pushed to the end.
            let mut pushed = Vec::new();
            let all = trace(&g, &ray, 0.0, method, &mut src, |v, _| {
                pushed.push(*v);
                Flow::Continue
            });
            prop_assert_eq!(&pushed, &visits);
            prop_assert_eq!(all, *counts.last().expect("final counts"));
            // Pushed and stopped after visit `stop_at`: the counts pulling
            // had right after yielding it.
            if stop_at < visits.len() {
                let mut seen = 0;
                let part = trace(&g, &ray, 0.0, method, &mut src, |_, _| {
                    seen += 1;
                    if seen > stop_at { Flow::Stop } else { Flow::Continue }
                });
                prop_assert_eq!(part, counts[stop_at]);
            }
        }
    }

    proptest! {
        /// A visit that answers `Flow::LeapNode(l)` ends the walk's stay
        /// in the visited cell's aligned node of `2^l` cells per axis: the
        /// walk yields exactly the single-cell walk's 1-cells, with the
        /// same `t` bit for bit, less those of the node after the visit
        /// (a ray leaves a box once). Rectilinear axes, random 1-cells,
        /// leaps at cells chosen by a hash, levels 0 to 3.
        #[test]
        fn leap_node_skips_exactly_the_nodes_later_cells(
            n in proptest::array::uniform3(1u32..12),
            gaps in proptest::collection::vec(0.2f64..2.0, 36),
            seed in proptest::collection::vec(0u8..8, 1728),
            o in proptest::array::uniform3(-3.0f64..15.0),
            d in proptest::array::uniform3(-1.0f64..1.0),
            salt in any::<u64>(),
        ) {
            prop_assume!(d.iter().any(|x| x.abs() > 1e-3));
            let axes: [crate::grid::Axis; 3] = std::array::from_fn(|k| {
                let mut p = vec![0.0];
                for i in 0..n[k] as usize {
                    p.push(p[i] + gaps[12 * k + i]);
                }
                crate::grid::Axis::from_coords(p).expect("axis")
            });
            let g = TGrid::<f64>::new(&axes);
            let cells = (n[0] * n[1] * n[2]) as usize;
            let codes = seed[..cells].iter().map(|&x| if x >= 4 { OBJECT } else { 0 }).collect();
            let mut src = Table { n, codes };
            let ray = Ray::new(o, d).expect("finite ray");
            let choice = |c: [u32; 3]| -> Option<u8> {
                let h = ((c[0] as u64 * 73_856_093)
                    ^ (c[1] as u64 * 19_349_663)
                    ^ (c[2] as u64 * 83_492_791))
                    .wrapping_mul(salt | 1)
                    >> 40;
                h.is_multiple_of(3).then_some((h / 3 % 4) as u8)
            };
            for method in [Method::Fvt, Method::Octree] {
                let mut all = Vec::new();
                trace(&g, &ray, 0.0, method, &mut src, |v, _| {
                    all.push(*v);
                    Flow::Continue
                });
                let mut want = Vec::new();
                let mut node: Option<(u8, [u32; 3])> = None;
                for v in all {
                    if let Some((l, a)) = node {
                        if (0..3).all(|k| v.cell[k] >> l == a[k] >> l) {
                            continue;
                        }
                    }
                    want.push(v);
                    node = choice(v.cell).map(|l| (l, v.cell));
                }
                let mut got = Vec::new();
                trace(&g, &ray, 0.0, method, &mut src, |v, _| {
                    got.push(*v);
                    choice(v.cell).map_or(Flow::Continue, Flow::LeapNode)
                });
                prop_assert_eq!(&got, &want, "{:?}", method);
            }
        }
    }
}
