//! FVT, the reference (Cleary-Wyvill, Amanatides-Woo; paper Fig. 11):
//! single-cell steps through every cell, visiting the 1-cells.

use super::frame::Frame;
use super::walker::{Action, CellRule};
use super::{CodeSource, Real, OBJECT};

/// The rule of FVT: a 1-cell is visited, every other cell stepped over.
pub struct Fvt;

impl<S: CodeSource> CellRule<S> for Fvt {
    #[inline(always)]
    fn at<T: Real>(&self, _: &Frame<'_, T>, _: [u32; 3], real: [u32; 3], src: &mut S) -> Action {
        if src.code(real, None) == OBJECT {
            Action::Visit
        } else {
            Action::Step
        }
    }
}
