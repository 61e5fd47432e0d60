//! # cdvol: streaming out-of-core volume processing for CD ray casting
//!
//! cdvol prepares CT and other scan series, which may be larger than RAM
//! and have slice thickness that varies along the stack, for fast ray
//! casting with the Chessboard Distance (CD) traversal of Sramek and
//! Kaufman, "Fast Ray-Tracing of Rectilinear Volume Data Using Distance
//! Transforms" (IEEE TVCG 2000; `../shared/paper/`).
//!
//! ## The pipeline, one module a stage
//! ```text
//! input::SliceSource   raw+sidecar (memmap2), DICOM, NRRD, NIfTI: z slices
//!   -> classify        cells between 8 samples -> 1-cells / 0-cells
//!                      (an iso value, a transfer function, or one of the
//!                      named presets of `presets`)
//!   -> dt              streaming chessboard distance transform (2 passes)
//!   -> prep            slabs of bricks, codes embedded, zstd, atomic write
//! == packed file (format, docs/FORMAT.md) ==
//!   -> format::reader  header, index, checked brick payloads on demand
//!   -> format::brick   the one payload decoder (values, codes, planes)
//!   -> info, export    summaries (value histogram, percentiles) and
//!                      full-resolution arrays back out
//!   -> render          camera -> tiles (rayon) -> cache (decoded bricks,
//!                      bounded) -> traverse (walkers: fvt, cd, octree,
//!                      dda; paper Figs. 11-12) -> integrate (surface,
//!                      depth, mip, composite, cost) -> output (PNG)
//! ```
//! ## From another program
//! [`Volume::open`] a packed file, take its [`Renderer`] (which owns its
//! brick cache and can be shared across threads) and
//! [`render`](Renderer::render) a [`View`] in a [`Look`] to an [`Image`];
//! the images are those `cdvol render` writes for the same view and look.
//!
//! docs/DESIGN.md maps every room: what it owns and what it may import
//! (checked by tests/all/layout.rs).
//!
//! With the cargo feature `tools` (on by default, through the binary's
//! feature `cli`), `tools` adds what is built
//! on the library rather than part of it: test scenes (`tools::phantom`,
//! the paper's sphere scenes of section 5.1 and a CT-like head with
//! variable slice thickness), the traversal corpus and the experiments.
//!
//! Samples sit on grid points and a cell spans 2x2x2 samples, so n samples
//! give n-1 cells per axis ([`grid`]). Codes live on the cells.

// `!(x > 0.0)` is deliberate throughout: it is true for NaN, which is
// what the checks of untrusted numbers want.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(target_endian = "big")]
compile_error!(
    "cdvol's packed format is little-endian and is only built for little-endian targets"
);

mod api;
pub mod batch;
pub mod classify;
pub mod dt;
pub mod export;
pub mod format;
pub mod fsutil;
pub mod grid;
pub mod identity;
pub mod info;
pub mod input;
pub mod json;
pub mod labels;
pub mod look;
pub mod memory;
pub mod orient;
#[cfg(feature = "plots")]
pub mod plot;
pub mod prep;
pub mod presets;
pub mod progress;
pub mod render;
#[cfg(feature = "serve")]
pub mod serve;
#[cfg(feature = "tools")]
pub mod tools;

pub use api::{Error, Image, Look, Renderer, Volume};
pub use render::job::{Aim, View};
