//! Chessboard Distance traversal (paper section 4, Figs. 11-12, eq. 12):
//! from a 0-cell with code `n`, leap out of the empty cube of `n` cells on
//! every side through its nearest far face `S'[v + n + 1]` (the paper's
//! `N` is `n + 1`), then *Locate* the other axes; single-cell steps where
//! the code is below `min_leap` (1 = the paper) and out of 1-cells.
//!
//! Because the leap lands by the same `plane_t` rule FVT uses, CD lands
//! exactly in the cell FVT reaches after crossing every plane up to the
//! landing `t`, and yields the same 1-cells bit for bit.

use super::frame::{cube_far, Frame};
use super::walker::{Action, CellRule};
use super::{CodeSource, Real, OBJECT};

/// The rule of CD: with `octant`, the code is the larger of the cell's
/// isotropic code and its block's code for the ray's octant (section
/// 4.2.1, anisotropic codes); both cubes are empty, so either leap is safe.
pub struct Cd {
    /// Smallest code leapt over (at least 1).
    pub min_leap: u8,
    pub octant: Option<usize>,
}

impl<S: CodeSource> CellRule<S> for Cd {
    #[inline(always)]
    fn at<T: Real>(&self, f: &Frame<'_, T>, v: [u32; 3], real: [u32; 3], src: &mut S) -> Action {
        let code = src.code(real, self.octant);
        if code == OBJECT {
            Action::Visit
        } else if code >= self.min_leap {
            Action::Leap(cube_far(v, code, f.n))
        } else {
            Action::Step
        }
    }
}
