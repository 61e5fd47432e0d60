//! The decoded brick, below the cache: everything derived from a brick's
//! payload when it is decoded, and nothing that reads another brick
//! through the cache.
//!
//! ```text
//! decode.rs     a decoded brick (RBrick): codes, values, the planes built
//!               on them (its tests in decode_tests.rs)
//! samples.rs    the brick's sample values in their stored word (Samples)
//! tf_cells.rs   a transfer function's cell classes, decided at decode
//! envelope.rs   render-time classification inside the file's envelope
//!               (`render --iso`): classes narrowed, codes tightened
//! gradients.rs  the gradient plane of the samples inside a brick
//! grads.rs      the shaded composite's gradient plane, its outer layer
//!               filled on first use
//! occupancy.rs  which sub-blocks of a brick hold a 1-cell (culling)
//! ```

mod decode;
pub(crate) mod envelope;
pub(crate) mod gradients;
mod grads;
mod occupancy;
pub mod samples;
pub(crate) mod tf_cells;

// Some are used only by the tests and tools (feature `internals`).
#[cfg_attr(not(feature = "internals"), allow(unused_imports))]
pub use decode::{block_maxima, max_pyramid, octree_levels, Codes, RBrick, BLOCK};
pub use grads::GradPlane;
pub use occupancy::{occupancy, Occupancy, SUB};

/// A sample value as the renderer holds it: rounded to f32 and saturated
/// to the finite f32 range (+-inf and values beyond it become +-f32::MAX,
/// so the trilinear interpolant stays finite); NaN stays NaN. Monotone, so
/// a value `>= iso` stays `>= to_f32(iso)`: the renderer compares against
/// the iso value mapped the same way, and every 1-cell keeps a vertex at
/// or above it.
#[inline]
pub fn to_f32(v: f64) -> f32 {
    if v.is_nan() {
        f32::NAN
    } else {
        (v as f32).clamp(-f32::MAX, f32::MAX)
    }
}

/// Which planes the cache builds beside each decoded brick's codes and
/// values. On read, a plane not built answers as if the file had none
/// (the isotropic code, the chessboard bound, single-cell octree levels),
/// which is always conservative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Planes {
    /// The octant codes of anisotropic files (section 4.2.1).
    pub octants: bool,
    /// The city-block and chamfer planes of files prepared with `--dda`.
    pub dda: bool,
    /// Octree levels inside each brick and, for power-of-two brick sizes,
    /// above the bricks from the index (section 5.1).
    pub octree: bool,
    /// The max pyramid ([`RBrick::block_max`]: the largest vertex value
    /// per node of [`BLOCK`]^3 cells and up), for bricks with values.
    pub block_max: bool,
    /// Each sample's vertex gradient ([`RBrick::grads`]), for bricks with
    /// values: the shaded composite with smooth normals.
    pub grads: bool,
    /// The scene's iso value when it is narrower than the file's
    /// classification (`render --iso`): each brick is rewritten for it
    /// (render/brick/envelope.rs) before any other plane is built.
    pub narrow: Option<f32>,
}

impl Planes {
    /// Codes and values only.
    pub const NONE: Planes = Planes {
        octants: false,
        dda: false,
        octree: false,
        block_max: false,
        grads: false,
        narrow: None,
    };

    /// Every plane the file has; no octree.
    pub const FILE: Planes = Planes {
        octants: true,
        dda: true,
        octree: false,
        block_max: false,
        grads: false,
        narrow: None,
    };
}
