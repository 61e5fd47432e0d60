//! Tooling on top of the library, compiled only with the cargo feature
//! `tools` (on by default through `cli`, the binary's feature): test
//! scenes, the traversal corpus and the reproducible experiments. Nothing under `src/` outside this folder may
//! use it; it uses the library like any other client, plus `anyhow` and
//! `plotters`, which the library proper does not depend on
//! (`cargo tree -e normal --no-default-features` shows neither).
//!
//! - [`phantom`]: the paper's section 5.1 sphere scenes and a CT-like head
//!   with variable slice thickness (section 4.3's data set 2), streamed to
//!   a raw stack + sidecar.
//! - [`corpus`]: named extreme cases for the traversal, in memory, checked
//!   against an exact oracle by the tests.
//! - [`normals`]: shading normals against analytic sphere normals
//!   (docs/TRADEOFFS.md, "Normals").
//! - [`experiment`]: `cdvol experiment ...`, the paper's Figs. 16-22 and
//!   Tables 1-2 and the speed/accuracy trade-offs, written under docs/.
//!
//! Why a feature and not a workspace crate under `tools/`: the `cdvol`
//! binary runs these (`cdvol phantom`, `demo`, `experiment`), so its
//! package would depend on the tooling crate, and the tooling needs the
//! library, which lives in the same package as the binary. A package
//! cannot depend on a package that depends on it, so the tooling stays in
//! this package, behind `tools`. Build the library alone with
//! `cargo build --lib --no-default-features`.

pub mod corpus;
pub mod experiment;
pub mod normals;
pub mod phantom;
pub mod segment;
