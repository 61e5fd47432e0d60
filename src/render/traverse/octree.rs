//! Octree (min-max pyramid) traversal in the spirit of SMART (paper
//! section 5.1): at each cell the largest empty aligned node holding it is
//! found top-down ([`CodeSource::empty_level`]) and the ray leaps to the
//! node's far faces by the same move as CD, so it lands exactly where FVT
//! would. SMART's incremental neighbour finding is replaced by this
//! re-descent per leap (docs/DESIGN.md).

use super::frame::Frame;
use super::walker::{Action, CellRule};
use super::{CodeSource, Real};

/// The rule of the octree walk.
pub struct Octree;

impl<S: CodeSource> CellRule<S> for Octree {
    #[inline(always)]
    fn at<T: Real>(&self, f: &Frame<'_, T>, _: [u32; 3], real: [u32; 3], src: &mut S) -> Action {
        match src.empty_level(real) {
            None => Action::Visit,
            Some(0) => Action::Step,
            Some(l) => Action::Leap(f.node_far(real, l)),
        }
    }
}
