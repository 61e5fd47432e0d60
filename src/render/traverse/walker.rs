//! The walker interface and the cell-stepping walk that FVT, CD and the
//! octree share (paper Figs. 11-12): at each cell the method's rule says
//! what the cell is (a 1-cell to visit, a cell to step over, or an empty
//! region to leap over), and the walk takes the matching move from
//! [`super::frame`].

use super::frame::{Cursor, Entry, Frame};
use super::{CodeSource, Flow, Real, StepCounts, Visit};

/// One ray generator walking one ray (paper section 5: FVT, CD, octree,
/// DDA), in the manner of pbrt-v4's `DDAMajorantIterator`: each call
/// yields the next 1-cell the ray passes with positive length, in order,
/// reading cell codes from `src`.
pub trait Walker<S> {
    /// The next 1-cell with its entry and exit `t`, or `None` once the ray
    /// has left the volume. A walker stops where it yields: the step out
    /// of a visited cell is taken by the next call, so a caller that stops
    /// asking has counted no step beyond the cell it stopped at.
    fn next_visit(&mut self, src: &mut S) -> Option<Visit>;

    /// The steps taken so far.
    fn counts(&self) -> StepCounts;

    /// Walks on, handing each 1-cell to `visit` until it says stop or the
    /// ray leaves the volume; returns the steps taken. The same visits and
    /// counts as calling [`Walker::next_visit`] in a loop, but the walkers
    /// call `visit` from inside their loop, so a visit costs no return and
    /// re-entry (composite and MIP visit every 1-cell of a ray).
    fn walk<F: FnMut(&Visit, &mut S) -> Flow>(&mut self, src: &mut S, mut visit: F) -> StepCounts {
        while let Some(v) = self.next_visit(src) {
            if visit(&v, src) == Flow::Stop {
                break;
            }
        }
        self.counts()
    }
}

/// What a cell-stepping method makes of the cell the walk is in.
pub(super) enum Action {
    /// A 1-cell: visit it, then take a single-cell step.
    Visit,
    /// An empty cell to cross by a single-cell step.
    Step,
    /// An empty region whose far faces are these planes (mirrored frame):
    /// leap to the nearest of them.
    Leap([u32; 3]),
}

/// The rule of one cell-stepping method: FVT, CD or the octree.
pub(super) trait CellRule<S> {
    /// What cell `v` (mirrored frame; `real` in the original grid) is.
    fn at<T: Real>(&self, f: &Frame<'_, T>, v: [u32; 3], real: [u32; 3], src: &mut S) -> Action;
}

/// A walk by single-cell steps and leaps, the method's rule deciding at
/// each cell which.
pub struct CellWalker<'f, 'g, T, R> {
    /// The ray's frame, borrowed: a walker is small to move.
    f: &'f Frame<'g, T>,
    c: Cursor<T>,
    rule: R,
    /// The last call yielded a visit; the step out of that cell is due.
    pending: bool,
    done: bool,
    counts: StepCounts,
}

impl<'f, 'g, T: Real, R> CellWalker<'f, 'g, T, R> {
    #[inline(always)]
    pub(super) fn new(f: &'f Frame<'g, T>, e: Entry<T>, rule: R) -> Self {
        let c = Cursor::new(f, e);
        CellWalker {
            f,
            c,
            rule,
            pending: false,
            done: false,
            counts: StepCounts::default(),
        }
    }
}

impl<T: Real, R> CellWalker<'_, '_, T, R> {
    /// The walk: from where the last call stopped, each cell's rule picks
    /// the move; each 1-cell goes to `on_visit`, and the walk stops where
    /// that says stop (the step out of that cell is then due).
    #[inline(always)]
    fn run<S, F>(&mut self, src: &mut S, mut on_visit: F)
    where
        S: CodeSource,
        R: CellRule<S>,
        F: FnMut(&Visit, &mut S) -> Flow,
    {
        if self.done {
            return;
        }
        // The walk's state in locals for the loop (the struct is written
        // back on return), so the compiler keeps it in registers.
        let f = self.f;
        let mut c = self.c;
        let mut counts = self.counts;
        let mut moved = true;
        if self.pending {
            self.pending = false;
            counts.cell_steps += 1;
            moved = c.step(f);
        }
        let mut stopped = false;
        while moved {
            let real = f.real(c.v);
            counts.steps += 1;
            moved = match self.rule.at(f, c.v, real, src) {
                Action::Visit => {
                    let flow = match c.visit(f, real) {
                        Some(vis) => on_visit(&vis, src),
                        None => Flow::Continue,
                    };
                    match flow {
                        Flow::Continue => {
                            counts.cell_steps += 1;
                            c.step(f)
                        }
                        Flow::Stop => {
                            stopped = true;
                            break;
                        }
                        Flow::LeapNode(l) => {
                            counts.macro_steps += 1;
                            c.leap(f, f.node_far(real, l))
                        }
                    }
                }
                Action::Step => {
                    counts.cell_steps += 1;
                    c.step(f)
                }
                Action::Leap(far) => {
                    counts.macro_steps += 1;
                    c.leap(f, far)
                }
            };
        }
        self.c = c;
        self.counts = counts;
        self.pending = stopped;
        self.done = !moved;
    }
}

impl<T: Real, S: CodeSource, R: CellRule<S>> Walker<S> for CellWalker<'_, '_, T, R> {
    #[inline(always)]
    fn next_visit(&mut self, src: &mut S) -> Option<Visit> {
        let mut found = None;
        self.run(src, |v, _| {
            found = Some(*v);
            Flow::Stop
        });
        found
    }

    fn counts(&self) -> StepCounts {
        self.counts
    }

    #[inline(always)]
    fn walk<F: FnMut(&Visit, &mut S) -> Flow>(&mut self, src: &mut S, visit: F) -> StepCounts {
        self.run(src, visit);
        self.counts
    }
}
