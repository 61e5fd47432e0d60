//! What to render and how, and the checks every renderer runs before it
//! casts a ray: the mode must be exact on the file's classification
//! (never render silently wrong), the traversal must fit the file's codes
//! and grid, and sizes stay within [`MAX_PIXELS`] and [`MIN_STEP_MM`].

use crate::classify::{Classification, TransferFunction};
use crate::format::reader::PackedVolume;

use super::cache;
use super::camera::Camera;
use super::error::RenderError;
use super::gradient::Normals;
use super::shade::{HitMethod, HitParams};
use super::traverse::Method;

/// Smallest composite sample distance.
pub const MIN_STEP_MM: f64 = 1e-4;
/// Largest image (2^28 pixels, 16384 x 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

/// What a pixel shows.
#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    /// Shaded iso-surface at the file's iso value.
    Surface { hit: HitMethod, shadows: bool },
    /// Maximum of the interpolant at the 1-cells' face samples.
    Mip,
    /// Front-to-back compositing with a transfer function; `step_mm`
    /// apart, at `t = k * step_mm` along the ray.
    Composite { tf: TransferFunction, step_mm: f64 },
    /// Traversal steps per pixel until the surface is found (paper Fig.
    /// 17), as a heat map scaled to the largest count in the image.
    Cost,
    /// Distance to the iso-surface in mm.
    Depth { hit: HitMethod },
}

impl Mode {
    /// The stable name of the mode (stats JSON, part keys): `surface`,
    /// `mip`, `composite`, `cost`, `depth`.
    pub fn name(&self) -> &'static str {
        match self {
            Mode::Surface { .. } => "surface",
            Mode::Mip => "mip",
            Mode::Composite { .. } => "composite",
            Mode::Cost => "cost",
            Mode::Depth { .. } => "depth",
        }
    }
}

/// [`Mode::name`].
pub fn mode_name(m: &Mode) -> &'static str {
    m.name()
}

#[derive(Debug, Clone)]
pub struct RenderOptions {
    pub mode: Mode,
    pub method: Method,
    pub tile: u32,
    pub cache_bytes: usize,
    /// CD leaves a brick without 1-cells unread when its smallest code is
    /// at least this (255: read every brick CD enters).
    pub cd_lazy_min: u8,
    /// Arithmetic of the traversal (f64 by default; see docs/TRADEOFFS.md).
    pub precision: Precision,
    /// Iterations and tolerance of the bisect and newton hit methods.
    pub hit_params: HitParams,
    /// How surface normals are estimated (smooth by default).
    pub normals: Normals,
}

impl RenderOptions {
    /// `mode` by `method` with the defaults of `cdvol render`: 32-pixel
    /// tiles, a 512 MiB cache, CD's lazy threshold, f64, default hit
    /// parameters, smooth normals.
    pub fn new(mode: Mode, method: Method) -> RenderOptions {
        RenderOptions {
            mode,
            method,
            tile: 32,
            cache_bytes: 512 << 20,
            cd_lazy_min: cache::LAZY_MIN_CODE_CD,
            precision: Precision::F64,
            hit_params: HitParams::default(),
            normals: Normals::default(),
        }
    }
}

/// Arithmetic of the traversal. Shading and hits are always f64.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    F32,
    /// Never misses a 1-cell in tests/all/extremes.rs (f32 does).
    #[default]
    F64,
}

impl Precision {
    /// `f32` or `f64`.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

fn bad(field: &'static str, value: String, expected: String) -> RenderError {
    RenderError::Option {
        field,
        value,
        expected,
    }
}

/// Checks the options every renderer shares: Newton's tolerance and the
/// image size.
pub(crate) fn check_tol_and_size(opts: &RenderOptions, camera: &Camera) -> Result<(), RenderError> {
    let tol = opts.hit_params.newton_tol;
    if !(0.0..1.0).contains(&tol) {
        return Err(bad(
            "newton_tol",
            tol.to_string(),
            "a relative tolerance in [0, 1)".into(),
        ));
    }
    let pixels = camera.width as u64 * camera.height as u64;
    if pixels > MAX_PIXELS {
        return Err(bad(
            "width x height",
            format!("{} x {} = {pixels} pixels", camera.width, camera.height),
            format!("at most {MAX_PIXELS}"),
        ));
    }
    Ok(())
}

/// Checks everything the tile renderer needs before its first ray: the
/// mode on this file ([`check_mode`]), the tile size, the composite step,
/// Newton's tolerance and the image size, and that the traversal has the
/// codes and the grid it walks.
pub(crate) fn check_render(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<(), RenderError> {
    check_mode(vol, &opts.mode)?;
    if opts.tile == 0 {
        return Err(bad("tile", "0".into(), "at least 1".into()));
    }
    if let Mode::Composite { step_mm, .. } = opts.mode {
        // Samples sit at t = k * step; k must stay far below 2^53.
        if !(step_mm >= MIN_STEP_MM && step_mm.is_finite()) {
            return Err(bad(
                "step_mm",
                format!("{step_mm} mm"),
                format!("at least {MIN_STEP_MM} mm"),
            ));
        }
    }
    check_tol_and_size(opts, camera)?;
    if matches!(opts.method, Method::CdAniso { .. }) && vol.header().aniso_block.is_none() {
        return Err(RenderError::Incompatible {
            path: vol.path().to_path_buf(),
            msg: "traversal cd-aniso needs anisotropic codes, and this file was prepared \
                  without them"
                .into(),
        });
    }
    if opts.method.needs_regular_grid() {
        if let Some(k) = (0..3).find(|&k| !vol.header().axes[k].is_uniform()) {
            return Err(RenderError::Incompatible {
                path: vol.path().to_path_buf(),
                msg: format!(
                    "traversal {} needs a regular grid, but axis {} has varying spacing: \
                     the DDA steps in cells of one size per axis (use cd or fvt)",
                    opts.method.name(),
                    ["x", "y", "z"][k]
                ),
            });
        }
    }
    Ok(())
}

/// Checks that the mode can be rendered exactly from this file's
/// classification (never render silently wrong).
pub(crate) fn check_mode(vol: &PackedVolume, mode: &Mode) -> Result<(), RenderError> {
    let h = vol.header();
    let path = vol.path().to_path_buf();
    match (mode, &h.classification) {
        (Mode::Surface { .. } | Mode::Depth { .. }, Classification::TransferFunction { .. }) => {
            Err(RenderError::Incompatible {
                path,
                msg: "surface and depth modes need a file classified by an iso value, and this \
                      one was classified by a transfer function"
                    .into(),
            })
        }
        (Mode::Composite { tf, .. }, Classification::Iso { iso }) => {
            // Cells whose values all lie below iso were leapt over: the
            // transfer function must be transparent there.
            if tf.nonzero_on(f64::MIN, iso.next_down()) {
                Err(RenderError::Incompatible {
                    path,
                    msg: format!(
                        "the transfer function gives opacity to values below {iso}, which this \
                         file classified as empty (prepared with iso value {iso}); prepare it \
                         classified by this transfer function, or with the iso value at the \
                         lowest value with opacity"
                    ),
                })
            } else {
                Ok(())
            }
        }
        (Mode::Composite { tf, .. }, Classification::TransferFunction { tf: file_tf }) => {
            let mut pts: Vec<f64> = tf
                .points
                .iter()
                .chain(&file_tf.points)
                .map(|p| p.value)
                .collect();
            pts.sort_by(f64::total_cmp);
            let mut probes = pts.clone();
            probes.extend(pts.windows(2).map(|w| 0.5 * (w[0] + w[1])));
            probes.push(pts[0] - 1.0);
            probes.push(pts[pts.len() - 1] + 1.0);
            match probes
                .iter()
                .find(|&&v| tf.opacity(v) > 0.0 && file_tf.opacity(v) == 0.0)
            {
                Some(v) => Err(RenderError::Incompatible {
                    path,
                    msg: format!(
                        "the transfer function gives opacity at value {v}, where the one the file \
                         was classified by has none; prepare it classified by this transfer \
                         function"
                    ),
                }),
                None => Ok(()),
            }
        }
        _ => Ok(()),
    }
}
