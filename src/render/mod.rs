//! `cdvol render`: a tile-parallel CPU ray caster over packed files, the
//! last stage of the pipeline (`input -> classify -> dt -> format ->
//! render`), arranged by the stages of a frame:
//!
//! ```text
//! options.rs   Mode, RenderOptions; the checks before any ray
//! clip.rs      crop box and clipping planes: each ray's kept interval
//! stats.rs     counters of a render (`--stats`); clock.rs where its time goes
//! error.rs     RenderError
//!
//! stage folders, each importing only those above it in this list
//! (tests/all/layout.rs):
//! traverse/    fvt | cd | cd-aniso | octree | dda: the 1-cells a ray
//!              passes (paper section 4.1, Figs. 11-12); knows the grid only
//! brick/       a decoded brick and what is derived from it at decode:
//!              values, codes, TF cell classes, envelope narrowing,
//!              gradient planes, occupancy
//! cache/       decoded bricks under a byte budget, shared; the per-tile
//!              accessor in front of it
//! sample/      hits, shading, normals and lookup tables at a 1-cell
//! view/        camera, culling, the default frame
//! integrate/   surface | depth | mip | composite | cost, per pixel; the
//!              brick policy each needs
//! output/      pixels -> coloured Frame -> PNG; scale bar
//! template/    template-based CD (section 4.2.2), its own renderer
//! job/         tiles (one frame, rayon), shards, a whole `cdvol render` job
//! ```
//! Sampling, hit and shading code (`sample/`) is shared by all
//! traversals, so their images can differ only if their cell sequences
//! differ.
//! Output is the same whatever the thread count, tile size or cache budget:
//! every pixel is computed on its own, from the same values.

/// Declares modules that are the library's own: crate-private, or public
/// and hidden from the API docs with the feature `internals`.
macro_rules! internal_mods {
    ($($m:ident),*) => {$(
        #[cfg(feature = "internals")]
        #[doc(hidden)]
        pub mod $m;
        // What only the tests and tools use is unused without them.
        #[cfg(not(feature = "internals"))]
        #[allow(dead_code)]
        pub(crate) mod $m;
    )*};
}

// The renderer's insides (the decoded brick, the cache and its accessor,
// what a ray does at a cell, the template renderer of the paper's
// experiments) are the library's own: a caller renders through `Renderer`
// or `render`. The tests, benchmarks and tools that check them from
// outside reach them with the feature `internals` (on with `tools`).
internal_mods!(brick, cache, sample, template);
pub mod clip;
mod clock;
mod error;
mod integrate;
pub mod job;
mod options;
pub mod output;
mod stats;
pub mod traverse;
pub mod view;

pub use error::RenderError;
pub use integrate::policy::{brick_policy, cache_for, gradient_plane, planes_for};
pub use integrate::{lazy_min_for, LAZY_DENSE_PIXELS, LAZY_MIN_CODE_SPARSE};
pub use job::shard::{render_part, render_part_in};
pub use job::tiles::{
    render, render_in, render_in_until, Shard, ShardLayout, ShardParseError, TilePx,
};
pub use options::{
    default_method, mode_name, CompositeLook, GradientPoint, Integrate, Mode, Overlay, Precision,
    RenderOptions, Window, DEFAULT_CACHE_BYTES, DEFAULT_STEP_MM, EARLY_STOP, MAX_PIXELS,
    MIN_STEP_MM,
};
pub use output::colour::Colouring;
pub use output::{
    float_rgba, image_files, rgba8, save, save_on, stage, stage_on, Background, BackgroundError,
    Bits, Frame, ImageSpec, SaveError,
};
pub use sample::hit::{HitMethod, HitParams};
pub use sample::normals::Normals;
pub use stats::Stats;
pub use traverse::Method;
