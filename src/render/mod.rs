//! `cdvol render`: a tile-parallel CPU ray caster over packed files, the
//! last stage of the pipeline (`input -> classify -> dt -> format ->
//! render`). One file a stage:
//!
//! ```text
//! options.rs     Mode, RenderOptions; the checks before any ray
//! camera.rs      a ray per pixel (orthographic or perspective)
//! tiles.rs       Morton-ordered tiles, one rayon task each; Shard
//!   -> cull.rs       pixels no brick with 1-cells projects onto: no ray
//!   -> cache/        decoded bricks under a byte budget, shared
//!   -> traverse/     fvt | cd | cd-aniso | octree | dda: the 1-cells a
//!                    ray passes (paper section 4.1, Figs. 11-12)
//!   -> integrate/    surface | depth | mip | composite | cost, per pixel
//!                    (sampling, shading in shade.rs; hits in hit.rs; lut.rs;
//!                    smooth normals in gradient.rs)
//! output.rs      pixels -> coloured Frame -> PNG
//! stats.rs       counters of a render (`--stats`)
//! shard.rs       parts of a sharded render: write, read, assemble
//! framing.rs     the default frame: the box of the scene's 1-cells
//! job.rs         a whole `cdvol render` job: camera framing,
//!                turntables, numbered frames, part files
//! template/      template-based CD (section 4.2.2), its own renderer:
//!                the template and its walk; image.rs the warp
//! ```
//! Sampling, hit and shading code (shade.rs, hit.rs) is shared by all
//! traversals, so their images can differ only if their cell sequences
//! differ.
//! Output is the same whatever the thread count, tile size or cache budget:
//! every pixel is computed on its own, from the same values.

pub mod cache;
pub mod camera;
mod canvas;
mod clock;
mod colour;
mod cull;
mod error;
pub mod framing;
pub mod gradient;
pub mod grain;
mod held;
pub mod hit;
mod integrate;
pub mod job;
pub mod lut;
mod options;
mod output;
pub mod policy;
pub mod samples;
pub mod scalebar;
mod scene;
pub mod shade;
pub mod shard;
mod stats;
pub mod template;
mod tf_cells;
mod tiles;
pub mod traverse;

pub use colour::Colouring;
pub use error::RenderError;
pub use gradient::Normals;
pub use integrate::{lazy_min_for, LAZY_DENSE_PIXELS, LAZY_MIN_CODE_SPARSE};
pub use options::{
    default_method, mode_name, CompositeLook, GradientPoint, Mode, Precision, RenderOptions,
    Window, EARLY_STOP, MAX_PIXELS, MIN_STEP_MM,
};
pub use output::{
    image_files, save, save_on, stage, stage_on, Background, BackgroundError, Bits, Frame,
    ImageSpec, SaveError,
};
pub use shard::{render_part, render_part_in};
pub use stats::Stats;
pub use tiles::{render, render_in, render_in_until, Shard, ShardLayout, ShardParseError, TilePx};
