//! Why a render was refused or failed: the one error type of
//! [`render`](crate::render::render), [`render_part`](crate::render::render_part) and the
//! template renderer. Messages name fields and values, never CLI flags;
//! the CLI adds its flag names when it reports them.

use std::path::PathBuf;

use crate::format::FormatError;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Reading or decoding the packed file failed.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The file cannot be rendered exactly with these options (its
    /// classification, codes or grid do not fit the mode or traversal).
    #[error("{}: {msg}", path.display())]
    Incompatible { path: PathBuf, msg: String },
    /// An option out of range: `field` is its name in
    /// [`RenderOptions`](crate::render::RenderOptions) or the camera (`tile`,
    /// `step_mm`, `newton_tol`, `width x height`, `shard`).
    #[error("{field} {value}, expected {expected}")]
    Option {
        field: &'static str,
        value: String,
        expected: String,
    },
    /// A crop box or clipping plane that is no region.
    #[error(transparent)]
    Clip(#[from] crate::render::clip::ClipError),
    /// Inputs the template traversal (render/template/) cannot render.
    #[error("template traversal: {0}")]
    Template(String),
}
