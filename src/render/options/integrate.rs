//! [`Integrate`]: how the composite and MIP modes integrate along a ray.

/// How the composite and MIP modes integrate along a ray (`render
/// --integrate`). docs/TRADEOFFS.md ("Integrators") measures each
/// against [`Integrate::Reference`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Integrate {
    /// Composite: samples `step_mm` apart ([`Mode::Composite`](super::Mode::Composite)), as VTK
    /// takes them. MIP: the interpolant where the ray crosses the 1-cells'
    /// faces.
    Step,
    /// Per ray-cell segment, from the traversal's entry and exit of each
    /// 1-cell. Composite: the interpolant's cubic along the segment split
    /// where its chord may be more than `tol` times the transfer
    /// function's narrowest gap between points off, each chord integrated
    /// exactly through the extinction integral table (pre-integration,
    /// integrate/segment.rs). MIP: the cubic's exact maximum.
    Segment { tol: f64 },
    /// The accuracy harness's reference: f64, `substeps` substeps per
    /// cell width (1/64 of a cell at 64) at their midpoints, the transfer
    /// function evaluated exactly, no early stop. Slow.
    Reference { substeps: u32 },
}

impl Integrate {
    /// The segment integrator's default tolerance (docs/TRADEOFFS.md,
    /// "Integrators").
    pub const SEGMENT_TOL: f64 = 0.01;
    /// The reference's substeps per cell width.
    pub const REFERENCE_SUBSTEPS: u32 = 64;

    /// The stable name: `step`, `segment` or `reference`.
    pub fn name(self) -> &'static str {
        match self {
            Integrate::Step => "step",
            Integrate::Segment { .. } => "segment",
            Integrate::Reference { .. } => "reference",
        }
    }
}

impl Default for Integrate {
    /// Segments at [`Integrate::SEGMENT_TOL`]: more accurate than steps of
    /// 0.5 mm on every transfer function the harness measures, and the
    /// exact MIP (docs/TRADEOFFS.md, "Integrators").
    fn default() -> Integrate {
        Integrate::Segment {
            tol: Integrate::SEGMENT_TOL,
        }
    }
}
