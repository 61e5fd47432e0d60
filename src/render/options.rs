//! What to render and how, and the checks every renderer runs before it
//! casts a ray: the mode must be exact on the file's classification
//! (never render silently wrong), the traversal must fit the file's codes
//! and grid, and sizes stay within [`MAX_PIXELS`] and [`MIN_STEP_MM`].

use crate::classify::{Classification, TransferFunction};
use crate::format::reader::PackedVolume;

use crate::render::brick;
use crate::render::clip::Clip;
use crate::render::error::RenderError;
use crate::render::sample::hit::{HitMethod, HitParams};
use crate::render::sample::normals::Normals;
use crate::render::traverse::Method;

/// Smallest composite sample distance.
pub const MIN_STEP_MM: f64 = 1e-4;
/// The composite step of `--integrate step` when none is given (mm).
pub const DEFAULT_STEP_MM: f64 = 0.5;
/// Largest image (2^28 pixels, 16384 x 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

mod integrate;
pub use integrate::Integrate;

/// What a pixel shows.
#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    /// Shaded iso-surface at the scene's iso value ([`RenderOptions::iso`],
    /// else the file's).
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
    /// The surfaces of the chosen labels of a label file
    /// ([`crate::labels`]): each the 0.5 level of its smoothed indicator,
    /// shaded in its colour, drawn front to back by its opacity.
    Labels {
        hit: HitMethod,
        style: std::sync::Arc<crate::labels::LabelStyle>,
    },
}

impl Mode {
    /// The stable name of the mode (stats JSON, part keys): `surface`,
    /// `mip`, `composite`, `cost`, `depth`, `labels`.
    pub fn name(&self) -> &'static str {
        match self {
            Mode::Surface { .. } => "surface",
            Mode::Mip => "mip",
            Mode::Composite { .. } => "composite",
            Mode::Cost => "cost",
            Mode::Depth { .. } => "depth",
            Mode::Labels { .. } => "labels",
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
    /// at least this (255: read every brick CD enters); `None` leaves it
    /// to each frame, by how densely its rays cross the bricks
    /// ([`lazy_min_for`](crate::render::lazy_min_for)).
    pub cd_lazy_min: Option<u8>,
    /// Arithmetic of the traversal (f64 by default; see docs/TRADEOFFS.md).
    pub precision: Precision,
    /// Iterations and tolerance of the bisect and newton hit methods.
    pub hit_params: HitParams,
    /// Arithmetic of composite and MIP samples (f32 by default; the
    /// traversal keeps [`RenderOptions::precision`]). Measured against f64
    /// in docs/TRADEOFFS.md, "Sampling precision".
    pub sampling: Precision,
    /// The f32 composite takes a ray's samples eight at a time, their
    /// cells by position, unshaded or with smooth normals for shading and
    /// gradient opacity (on by default; docs/TRADEOFFS.md, "Sample
    /// batches").
    pub sample_batches: bool,
    /// Composite stops a ray once its opacity exceeds this (early ray
    /// termination; 0.99 by default, 1 never stops early).
    pub early_stop: f64,
    /// How composite and MIP integrate along a ray ([`Integrate`]).
    pub integrate: Integrate,
    /// Composite shading and gradient opacity.
    pub look: CompositeLook,
    /// MIP grey mapping.
    pub window: Window,
    /// How surface normals are estimated (smooth by default).
    pub normals: Normals,
    /// The scene's iso value (`render --iso`) for surface, depth, cost and
    /// MIP, when it is not the file's own: it must lie inside the file's
    /// classification, the envelope (render/brick/envelope.rs); `None` renders the
    /// file's iso value.
    pub iso: Option<f64>,
    /// Keep the frame's colour before rounding to 8 bits
    /// ([`Frame::linear`](crate::render::Frame::linear), 16 bytes a pixel), which
    /// 16-bit and float outputs need. Off by default: the frame then
    /// carries its 8-bit planes only, and a 1024^2 frame writes 16 MB less
    /// of fresh memory (docs/BENCHMARKS.md, "Per-frame memory"). A
    /// [`RenderJob`](crate::render::job::RenderJob) turns it on for its `--bit-depth`.
    pub unrounded: bool,
    /// Leave untraced the pixels whose rays can meet no 1-cell, judged
    /// from the brick index (render/view/cull.rs): the same image, fewer rays
    /// and bricks. On by default; the cost map always traces every ray.
    pub cull: bool,
    /// The crop box and clipping planes (render/view/clip.rs); the
    /// default keeps the whole volume. The cost map ignores them.
    pub clip: Clip,
    /// Surface and depth: a solid cut by the clip shows its cut face,
    /// shaded flat (on by default); off, rays that start inside the
    /// object go on to the next surface they enter.
    pub cap: bool,
    /// The colours of cut faces: the transfer function whose colour at
    /// the cut's data value tints it (a surface render's preset's); grey
    /// without one.
    pub cap_colours: Option<TransferFunction>,
    /// Labels drawn inside this render (`render --overlay`): surface and
    /// composite renders only ([`Overlay`]).
    pub overlay: Option<Overlay>,
}

/// A label file drawn inside a surface or composite render of a scan on
/// the same grid (`render --overlay`, issue 55). Each ray is first walked
/// through the label file (its own traversal and brick cache) to its
/// label surfaces ([`Mode::Labels`]), then through the scan up to the
/// first label hit only: the scan's surface or its composite samples in
/// front of the label occlude it, and the label's colour goes behind them
/// (`rgb = scan + (1 - scan alpha) * label`). Translucent labels are
/// composited among themselves; the scan behind the first label surface
/// is not drawn.
#[derive(Clone)]
pub struct Overlay {
    pub vol: std::sync::Arc<PackedVolume>,
    pub style: std::sync::Arc<crate::labels::LabelStyle>,
    pub hit: HitMethod,
    /// The label file's bricks, kept from frame to frame.
    pub(crate) cache: std::sync::Arc<crate::render::cache::BrickCache>,
}

impl Overlay {
    /// The labels `style` of `vol`, found by `hit`, with a brick cache of
    /// `cache_bytes` for them.
    pub fn new(
        vol: PackedVolume,
        style: crate::labels::LabelStyle,
        hit: HitMethod,
        cache_bytes: usize,
    ) -> Overlay {
        let style = std::sync::Arc::new(style);
        let mode = Mode::Labels {
            hit,
            style: style.clone(),
        };
        let mut o = RenderOptions::new(mode, crate::render::default_method(vol.header()));
        o.cache_bytes = cache_bytes;
        let cache = crate::render::cache_for(&vol, &o);
        Overlay {
            vol: std::sync::Arc::new(vol),
            style,
            hit,
            cache: std::sync::Arc::new(cache),
        }
    }

    /// The render options of the overlay's own walk within a render with
    /// `opts`: its labels, the file's default traversal, `opts`' tiles,
    /// clip, culling and early stop.
    pub(crate) fn options(&self, opts: &RenderOptions) -> RenderOptions {
        RenderOptions {
            tile: opts.tile,
            cache_bytes: opts.cache_bytes,
            early_stop: opts.early_stop,
            clip: opts.clip.clone(),
            cap: opts.cap,
            cull: opts.cull,
            ..RenderOptions::new(
                Mode::Labels {
                    hit: self.hit,
                    style: self.style.clone(),
                },
                crate::render::default_method(self.vol.header()),
            )
        }
    }
}

/// The label file's path and the style (render part keys hold the
/// options' debug text).
impl std::fmt::Debug for Overlay {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Overlay")
            .field("vol", &self.vol.path())
            .field("style", &self.style)
            .field("hit", &self.hit)
            .finish()
    }
}

/// Refuses an overlay on another grid than the scan's (naming both), on a
/// file without labels, or under a mode that draws no surface to put it
/// in.
pub(crate) fn check_overlay(vol: &PackedVolume, opts: &RenderOptions) -> Result<(), RenderError> {
    let Some(ov) = &opts.overlay else {
        return Ok(());
    };
    let (a, b) = (vol.header(), ov.vol.header());
    if !matches!(opts.mode, Mode::Surface { .. } | Mode::Composite { .. }) {
        return Err(bad(
            "overlay",
            ov.vol.path().display().to_string(),
            format!(
                "a surface or composite render to draw the labels in, not mode {}",
                opts.mode.name()
            ),
        ));
    }
    if b.labels.is_none() {
        return Err(RenderError::Incompatible {
            path: ov.vol.path().to_path_buf(),
            msg: "--overlay draws a label file, and this file holds no labels: prepare the \
                  segmentation with `cdvol prep --labels`"
                .into(),
        });
    }
    let same = a.dims == b.dims
        && (0..3).all(|k| {
            let (x, y) = (a.axes[k].coords(), b.axes[k].coords());
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
        });
    if !same {
        return Err(RenderError::Incompatible {
            path: ov.vol.path().to_path_buf(),
            msg: format!(
                "the label file's grid, {}, is not the scan's, {} ({}): labels are drawn on \
                 the scan's own samples, and cdvol does not resample",
                grid_words(b),
                grid_words(a),
                vol.path().display()
            ),
        });
    }
    Ok(())
}

/// A grid for people: `256 x 256 x 108 samples over 0 .. 244 x 0 .. 244 x
/// 0 .. 160.5 mm`, and `(rectilinear z)` where an axis is not uniform.
fn grid_words(h: &crate::format::Header) -> String {
    let ext: Vec<String> = h
        .axes
        .iter()
        .map(|a| {
            let c = a.coords();
            format!("{} .. {}", c[0], c[c.len() - 1])
        })
        .collect();
    let rect: Vec<&str> = (0..3)
        .filter(|&k| !h.axes[k].is_uniform())
        .map(|k| ["x", "y", "z"][k])
        .collect();
    format!(
        "{} x {} x {} samples over {} mm{}",
        h.dims[0],
        h.dims[1],
        h.dims[2],
        ext.join(" x "),
        if rect.is_empty() {
            String::new()
        } else {
            format!(" (rectilinear {})", rect.join(", "))
        }
    )
}

/// Default of [`RenderOptions::early_stop`].
pub const EARLY_STOP: f64 = 0.99;

/// How composite samples are lit and weighted beyond the transfer
/// function's colour and opacity. Read from the transfer function file's
/// optional keys `"shade": true` and `"gradient_opacity": [{"gradient":
/// g, "opacity": f}, ...]` (g in value units per mm, f in [0, 1], g
/// strictly increasing) by [`CompositeLook::load`]; `render --shade` sets
/// `shade` too. Render-time only: the file's classification is untouched,
/// and neither can make a transparent sample opaque, so the prepared
/// envelope stays valid.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CompositeLook {
    /// Light each sample with the surface mode's headlight model
    /// ([`shade`](crate::render::sample::shade::shade): ambient 0.12, diffuse 0.75,
    /// specular 0.25 with exponent 32), the normal from the gradient.
    #[serde(default)]
    pub shade: bool,
    /// Opacity factor by gradient magnitude, linear between points and
    /// constant beyond the ends; empty for none.
    #[serde(default)]
    pub gradient_opacity: Vec<GradientPoint>,
}

/// A point of [`CompositeLook::gradient_opacity`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GradientPoint {
    /// Gradient magnitude, value units per mm.
    pub gradient: f64,
    /// Factor on the sample's opacity, 0..=1.
    pub opacity: f64,
}

impl CompositeLook {
    /// The look keys of transfer function file `path` (absent keys give
    /// no shading and no gradient opacity), checked.
    pub fn load(path: &std::path::Path) -> Result<CompositeLook, crate::classify::TfError> {
        CompositeLook::from_text(path, &crate::classify::read_tf_text(path)?)
    }

    /// [`CompositeLook::load`] of `text`, the contents of transfer
    /// function file `path` (read once by
    /// [`read_tf_text`](crate::classify::read_tf_text): a FIFO or `<(...)`
    /// can be read only once).
    pub fn from_text(
        path: &std::path::Path,
        text: &str,
    ) -> Result<CompositeLook, crate::classify::TfError> {
        let e = |msg: String| crate::classify::TfError {
            path: path.to_path_buf(),
            msg,
        };
        if let Some(key) = crate::json::duplicate_key(text) {
            return Err(e(format!("{key}: duplicate key, expected each key once")));
        }
        let look: CompositeLook = serde_json::from_str(text).map_err(|x| {
            e(format!(
                "expected optional \"shade\": true|false and \"gradient_opacity\": \
                 [{{\"gradient\", \"opacity\"}}, ...]: {x}"
            ))
        })?;
        look.check().map_err(|x| e(x.to_string()))?;
        Ok(look)
    }

    /// Gradient points finite, strictly increasing, opacities in 0..=1.
    pub fn check(&self) -> Result<(), crate::classify::TfInvalid> {
        for (i, p) in self.gradient_opacity.iter().enumerate() {
            let bad = |field: &str, found: String, expected: &'static str| {
                Err(crate::classify::TfInvalid {
                    field: format!("gradient_opacity[{i}].{field}"),
                    found,
                    expected,
                })
            };
            if !(p.gradient.is_finite() && p.gradient >= 0.0) {
                return bad("gradient", p.gradient.to_string(), "a finite number >= 0");
            }
            if !(0.0..=1.0).contains(&p.opacity) {
                return bad("opacity", p.opacity.to_string(), "0..=1");
            }
            if i > 0 && p.gradient <= self.gradient_opacity[i - 1].gradient {
                return bad(
                    "gradient",
                    p.gradient.to_string(),
                    "strictly increasing gradients",
                );
            }
        }
        Ok(())
    }

    /// The opacity factor at gradient magnitude `g` (1 without points).
    pub fn gradient_factor(&self, g: f64) -> f64 {
        let p = &self.gradient_opacity;
        let (Some(first), Some(last)) = (p.first(), p.last()) else {
            return 1.0;
        };
        if !(g > first.gradient) {
            return first.opacity;
        }
        if g >= last.gradient {
            return last.opacity;
        }
        let i = p.partition_point(|q| q.gradient <= g);
        let (a, b) = (p[i - 1], p[i]);
        a.opacity + (g - a.gradient) / (b.gradient - a.gradient) * (b.opacity - a.opacity)
    }
}

/// How MIP values map to black..white.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub enum Window {
    /// The 1st to the 99.9th percentile of the image's values
    /// (`colour::auto_window`).
    #[default]
    Auto,
    /// The file's whole value range (`--window full`; before the
    /// automatic window, the only mapping).
    Full,
    /// `level - width / 2 .. level + width / 2` (`--window W --level L`,
    /// as in radiology viewers).
    Fixed { width: f64, level: f64 },
}

/// The traversal a render of the file with header `h` uses when none is
/// named (`cdvol render` without `--traversal`, `cdvol serve`, the demo;
/// the one place that chooses it): CD with the
/// file's anisotropic (octant) codes where `prep --aniso` stored them
/// (paper section 4.2.1), else CD. Both are exact, so the image is the
/// same; the octant codes leap further (docs/BENCHMARKS.md, "Octant codes
/// by default in the render").
pub fn default_method(h: &crate::format::Header) -> Method {
    if h.aniso_block.is_some() {
        Method::CdAniso { min_leap: 1 }
    } else {
        Method::Cd { min_leap: 1 }
    }
}

impl RenderOptions {
    /// `mode` by `method` with the defaults of `cdvol render`: 32-pixel
    /// tiles, a 512 MiB cache, CD's lazy threshold, f64, default hit
    /// parameters, smooth normals, 8-bit frames.
    pub fn new(mode: Mode, method: Method) -> RenderOptions {
        RenderOptions {
            mode,
            method,
            tile: 32,
            cache_bytes: DEFAULT_CACHE_BYTES,
            cd_lazy_min: None,
            precision: Precision::F64,
            hit_params: HitParams::default(),
            sampling: Precision::F32,
            sample_batches: true,
            early_stop: EARLY_STOP,
            integrate: Integrate::default(),
            look: CompositeLook::default(),
            window: Window::Auto,
            normals: Normals::default(),
            iso: None,
            unrounded: false,
            cull: true,
            clip: Clip::default(),
            cap: true,
            cap_colours: None,
            overlay: None,
        }
    }
}

/// The brick cache's default budget in bytes (`render --cache-mb 512`).
pub const DEFAULT_CACHE_BYTES: usize = 512 << 20;

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

/// Most bisection or Newton steps of a surface hit: each halves the
/// bracket, which is below f64 resolution after ~53, so more only costs
/// time (`--bisect-iters 4000000000` ran for minutes).
pub const MAX_HIT_ITERS: u32 = 200;

fn bad(field: &'static str, value: String, expected: String) -> RenderError {
    RenderError::Option {
        field,
        value,
        expected,
    }
}

/// Checks the options every renderer shares: Newton's tolerance and the
/// image size (`[width, height]` in pixels).
pub(crate) fn check_tol_and_size(opts: &RenderOptions, size: [u32; 2]) -> Result<(), RenderError> {
    let tol = opts.hit_params.newton_tol;
    if !(0.0..1.0).contains(&tol) {
        return Err(bad(
            "newton_tol",
            tol.to_string(),
            "a relative tolerance in [0, 1)".into(),
        ));
    }
    for (field, n) in [
        ("bisect_iters", opts.hit_params.bisect_iters),
        ("newton_iters", opts.hit_params.newton_iters),
    ] {
        if n > MAX_HIT_ITERS {
            return Err(bad(
                field,
                n.to_string(),
                format!(
                    "at most {MAX_HIT_ITERS} (each step halves the bracket; \
                     past ~53 it is below f64 resolution)"
                ),
            ));
        }
    }
    let [width, height] = size;
    let pixels = width as u64 * height as u64;
    if pixels > MAX_PIXELS {
        return Err(bad(
            "width x height",
            format!("{width} x {height} = {pixels} pixels"),
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
    size: [u32; 2],
    opts: &RenderOptions,
) -> Result<(), RenderError> {
    check_mode(vol, &opts.mode, opts.iso)?;
    check_scene_iso(vol, opts)?;
    check_overlay(vol, opts)?;
    let h = vol.header();
    let lo = h.axes.each_ref().map(|a| a.coords()[0]);
    let hi = h.axes.each_ref().map(|a| a.coords()[a.coords().len() - 1]);
    opts.clip.check(lo, hi)?;
    if opts.tile == 0 {
        return Err(bad("tile", "0".into(), "at least 1".into()));
    }
    match opts.integrate {
        Integrate::Segment { tol } if !(tol > 0.0 && tol.is_finite()) => {
            return Err(bad(
                "segment_tol",
                format!("{tol}"),
                "a finite number above 0".into(),
            ));
        }
        Integrate::Reference { substeps: 0 } => {
            return Err(bad("substeps", "0".into(), "at least 1".into()));
        }
        _ => {}
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
    check_tol_and_size(opts, size)?;
    if !(opts.early_stop > 0.0 && opts.early_stop <= 1.0) {
        return Err(bad(
            "early_stop",
            opts.early_stop.to_string(),
            "an opacity in (0, 1]".into(),
        ));
    }
    if let Window::Fixed { width, level } = opts.window {
        if !(width > 0.0 && width.is_finite() && level.is_finite()) {
            return Err(bad(
                "window",
                format!("width {width} level {level}"),
                "a finite width > 0 and a finite level".into(),
            ));
        }
    }
    if matches!(opts.method, Method::CdAniso { .. }) && vol.header().aniso_block.is_none() {
        return Err(RenderError::Incompatible {
            path: vol.path().to_path_buf(),
            msg: "traversal cd-aniso needs anisotropic codes, and this file was prepared \
                  without them"
                .into(),
        });
    }
    if let Method::Dda {
        kind:
            kind @ (crate::render::traverse::DistKind::Cityblock
            | crate::render::traverse::DistKind::Chamfer),
        ..
    } = opts.method
    {
        if !vol.header().dda {
            return Err(RenderError::Incompatible {
                path: vol.path().to_path_buf(),
                msg: format!(
                    "traversal {} needs the {} distance planes, and this file was prepared \
                     without them: prepare it again with `cdvol prep --dda`, or use \
                     dda-chessboard, cd or fvt",
                    opts.method.name(),
                    match kind {
                        crate::render::traverse::DistKind::Cityblock => "city-block",
                        _ => "chamfer 3-4-5",
                    }
                ),
            });
        }
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
pub(crate) fn check_mode(
    vol: &PackedVolume,
    mode: &Mode,
    opts_iso: Option<f64>,
) -> Result<(), RenderError> {
    let h = vol.header();
    let path = vol.path().to_path_buf();
    match (mode, &h.classification) {
        (Mode::Surface { .. } | Mode::Depth { .. }, Classification::TransferFunction { .. })
            if opts_iso.is_none() =>
        {
            Err(RenderError::Incompatible {
                path,
                msg: "surface and depth modes need an iso value, and this file was classified by \
                      a transfer function: give one with --iso (inside the transfer function's \
                      support)"
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
                         file classified as empty (prepared with iso value {iso}); prepare a \
                         file classified by this transfer function: cdvol prep --classify-tf \
                         TF.json {} -o {} (TF.json holding it; `cdvol presets --tf NAME` writes \
                         a preset's)",
                        shell_word(&h.source),
                        shell_word(&suffixed(vol.path(), "tf")),
                    ),
                })
            } else {
                Ok(())
            }
        }
        (Mode::Composite { tf, .. }, Classification::TransferFunction { tf: file_tf }) => {
            match tf.outside(file_tf) {
                Some(v) => Err(RenderError::Incompatible {
                    path,
                    msg: format!(
                        "the transfer function gives opacity at value {v}, where the one the file \
                         was classified by has none; prepare a file classified by this transfer \
                         function: cdvol prep --classify-tf TF.json {} -o {} (TF.json holding \
                         it; `cdvol presets --tf NAME` writes a preset's)",
                        shell_word(&h.source),
                        shell_word(&suffixed(vol.path(), "tf")),
                    ),
                }),
                None => Ok(()),
            }
        }
        (Mode::Labels { .. }, _) if h.labels.is_none() => Err(RenderError::Incompatible {
            path,
            msg: "--labels draws the labels of a label file, and this file holds none: prepare \
                  the segmentation with `cdvol prep --labels`"
                .into(),
        }),
        _ => Ok(()),
    }
}

/// The iso value a render with `opts` draws surfaces at, as the samplers
/// compare it ([`to_f32`](crate::render::brick::to_f32) like the stored values):
/// `opts.iso`, else the file's; NaN for a file classified by a transfer
/// function without `opts.iso`.
pub(crate) fn scene_iso(h: &crate::format::Header, opts: &RenderOptions) -> f64 {
    match (opts.iso, &h.classification) {
        (Some(v), _) => brick::to_f32(v) as f64,
        (None, Classification::Iso { iso }) => brick::to_f32(*iso) as f64,
        (None, _) => f64::NAN,
    }
}

/// The iso value the decoded bricks must be narrowed to, when the scene's
/// 1-cells are fewer than the file's: `opts.iso` above the file's iso, or
/// any `opts.iso` on a file classified by a transfer function.
pub(crate) fn narrowing(h: &crate::format::Header, opts: &RenderOptions) -> Option<f32> {
    let v = opts.iso?;
    match &h.classification {
        Classification::Iso { iso } if brick::to_f32(*iso) == brick::to_f32(v) => None,
        _ => Some(brick::to_f32(v)),
    }
}

/// `opts.iso` must lie inside the file's classification (issue 16: codes
/// computed for a classification are conservative for any narrower one,
/// and every vertex of a 1-cell keeps its value): at or above the file's
/// iso value, or where the file's transfer function is non-zero from it
/// up. Refused otherwise, with the `cdvol prep` command that covers it.
pub(crate) fn check_scene_iso(vol: &PackedVolume, opts: &RenderOptions) -> Result<(), RenderError> {
    let Some(v) = opts.iso else {
        return Ok(());
    };
    if !v.is_finite() {
        return Err(bad("iso", v.to_string(), "a finite value".into()));
    }
    if let Mode::Composite { .. } = opts.mode {
        return Err(bad(
            "iso",
            v.to_string(),
            "no --iso in composite mode: the transfer function (--tf) chooses what it shows".into(),
        ));
    }
    let h = vol.header();
    if h.classification.holds_iso(v) {
        return Ok(());
    }
    let envelope = match &h.classification {
        Classification::Iso { iso } => format!("values >= {iso} (prepared with --iso {iso})"),
        Classification::TransferFunction { .. } => {
            "the values its transfer function gives opacity (prepared with --classify-tf)".into()
        }
    };
    Err(RenderError::Incompatible {
        path: vol.path().to_path_buf(),
        msg: format!(
            "iso value {v} lies outside the file's envelope, {envelope}: cells below it were \
             leapt over when the file was made. Prepare a file that covers it: cdvol prep \
             --iso {v} {} -o {}",
            shell_word(&h.source),
            shell_word(&envelope_name(vol.path(), v)),
        ),
    })
}

/// `path` with `-iso{v}` before its extension.
fn envelope_name(path: &std::path::Path, v: f64) -> String {
    suffixed(path, &format!("iso{v}"))
}

/// `path` with `-{tag}.cdv` in place of its extension.
fn suffixed(path: &std::path::Path, tag: &str) -> String {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}-{tag}.cdv"))
        .display()
        .to_string()
}

/// `s` quoted for a POSIX shell when it needs it.
fn shell_word(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+,:=@".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}
