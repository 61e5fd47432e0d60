//! `cdvol render` and `cdvol assemble`: their arguments (render_job.rs:
//! what they ask of the library).

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::heading;

use cdvol::render::HitMethod;
use cdvol::render::{Precision, ShardLayout};

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeArg {
    Surface,
    Mip,
    Composite,
    Cost,
    Depth,
}

/// `--traversal`. The inexact generators (they miss 1-cells, so they
/// draw wrong images) are accepted by `cdvol experiment render` only and
/// left out of the help ([`TraversalArg::exact`]).
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraversalArg {
    Cd,
    Fvt,
    CdAniso,
    Octree,
    #[value(hide = true)]
    DdaCityblock,
    DdaChessboard,
    #[value(hide = true)]
    DdaChamfer,
    #[value(hide = true)]
    Template,
}

impl TraversalArg {
    /// Whether the generator visits every 1-cell a single-cell traversal
    /// visits (README, "Traversals"): all but the city-block and chamfer
    /// DDAs and template-based CD.
    pub fn exact(self) -> bool {
        !matches!(
            self,
            TraversalArg::DdaCityblock | TraversalArg::DdaChamfer | TraversalArg::Template
        )
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum HitArg {
    Int,
    Bisect,
    Newton,
    Exact,
}

/// `--normals`: how surface normals are estimated.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormalsArg {
    /// Central differences at the samples, trilinearly interpolated.
    Smooth,
    /// The gradient of each cell's own trilinear interpolant (blocky).
    Cell,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrecisionArg {
    F32,
    F64,
}

/// `--integrate`: [`cdvol::render::Integrate`].
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntegrateArg {
    /// Composite: samples --step apart (as VTK); MIP: at cell faces.
    Step,
    /// Per ray-cell segment: exact opacity of each chord; MIP's exact
    /// maximum.
    Segment,
    /// The f64 reference (1/64-cell substeps, no early stop): slow.
    Reference,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnOff {
    On,
    Off,
}

/// `cdvol render`'s arguments. Each sits under a heading of `--help`
/// ([`crate::cli::heading`]), the everyday groups first; the tuning and
/// paper-experiment switches are left out of `-h` (`hide_short_help`).
/// `--no-switch-fvt`, which draws wrong images, is not one of them: it is
/// offered by `cdvol experiment render` only ([`ExperimentRenderArgs`]).
#[derive(Args, Debug)]
pub struct RenderArgs {
    // ---- Input -----------------------------------------------------------
    /// Packed file from `cdvol prep`.
    #[arg(help_heading = heading::INPUT)]
    pub file: PathBuf,

    // ---- View ------------------------------------------------------------
    /// The view: anterior, posterior, left, right, superior, inferior, or
    /// AZ,EL in degrees.
    ///
    /// A name in patient terms, or AZ,EL, azimuth and elevation in degrees
    /// around the centre of the object (the scene's 1-cells, which the
    /// default frame fits). Anterior looks at the face, head up, so the patient's
    /// left is on the image's right (the radiological convention); left
    /// looks at the patient's left side; superior and inferior look along
    /// the body axis with the face at the top.
    ///
    /// AZ,EL are in patient axes when the file records its orientation
    /// (`cdvol info`: DICOM, NIfTI, NRRD with a patient space, a sidecar
    /// with "orientation"): 0,0 = anterior, 90,0 = left, 180,0 =
    /// posterior, 270,0 = right; elevation lifts the eye towards the head,
    /// and the head is up in the image (at +-90 the back of the head is
    /// up). Otherwise they are in the file's sample axes (x = columns, y =
    /// rows, z = slices): azimuth turns about +z, 0 puts the eye on the -y
    /// side looking towards +y, 90 on the +x side looking towards -x;
    /// elevation lifts the eye towards +z, and +z is up in the image; named
    /// views are refused. Default: 0,0 (anterior for oriented files).
    #[arg(long, value_parser = parse_view, allow_hyphen_values = true,
          help_heading = heading::VIEW)]
    pub view: Option<ViewArg>,
    /// Perspective projection (default orthographic).
    #[arg(long, help_heading = heading::VIEW)]
    pub persp: bool,
    /// Perspective field of view in degrees.
    #[arg(long, default_value_t = 40.0, help_heading = heading::VIEW)]
    pub fov: f64,
    /// Orthographic frame height in mm (default: the object fits it, with
    /// a margin of 5 % each side).
    #[arg(long, help_heading = heading::VIEW)]
    pub frame: Option<f64>,
    /// Exact camera: eye, target and up in mm (all three needed).
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true,
          help_heading = heading::VIEW)]
    pub eye: Option<[f64; 3]>,
    /// Exact camera: the point looked at, in mm (with --eye and --up).
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true,
          help_heading = heading::VIEW)]
    pub target: Option<[f64; 3]>,
    /// Exact camera: the image's up direction (with --eye and --target).
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true,
          help_heading = heading::VIEW)]
    pub up: Option<[f64; 3]>,
    /// Keep only this box: X0:X1,Y0:Y1,Z0:Z1 in mm.
    ///
    /// In the file's coordinates (those of --eye and --target; `cdvol
    /// info` gives the volume's extents). Rays start and stop at its faces;
    /// bricks wholly outside are never read.
    #[arg(long, value_name = "X0:X1,Y0:Y1,Z0:Z1", value_parser = parse_crop,
          allow_hyphen_values = true, help_heading = heading::VIEW)]
    pub crop: Option<[[f64; 2]; 3]>,
    /// Keep the half-space NX*x + NY*y + NZ*z >= D (up to 6 planes).
    ///
    /// In the file's coordinates, mm: the side the normal points into is
    /// kept. A surface cut open shows its cut face (see --no-cap).
    #[arg(long, value_name = "NX,NY,NZ,D", value_parser = parse_plane,
          allow_hyphen_values = true, help_heading = heading::VIEW)]
    pub clip: Vec<[f64; 4]>,
    /// Keep one half of the volume: left, right, anterior, posterior,
    /// superior or inferior (files that record their orientation).
    #[arg(long, value_name = "SIDE", help_heading = heading::VIEW)]
    pub clip_half: Vec<String>,
    /// Surfaces cut by --crop or --clip are left open instead of showing
    /// their cut face.
    #[arg(long, help_heading = heading::VIEW)]
    pub no_cap: bool,
    /// A turntable of this many frames around the volume.
    ///
    /// Numbered PNGs OUT.0000.png ..., starting at --view.
    #[arg(long, default_value_t = 1, help_heading = heading::VIEW)]
    pub frames: u32,
    /// Degrees of azimuth the turntable covers.
    #[arg(long, default_value_t = 360.0, allow_hyphen_values = true,
          help_heading = heading::VIEW)]
    pub orbit: f64,

    // ---- Mode and look ---------------------------------------------------
    /// What the image shows (default: surface, or the file's preset look).
    ///
    /// Default: surface, or for a file prepared with `--preset` (its look,
    /// see `info`) and no --iso, --tf or --preset given, that preset's
    /// mode: composite, or MIP for the MIP presets.
    #[arg(long, value_enum, help_heading = heading::LOOK)]
    pub mode: Option<ModeArg>,
    /// A named preset (`cdvol presets`) for the look.
    ///
    /// Its transfer function and shading in composite mode, its iso value
    /// in surface, depth and cost modes, its window in MIP mode.
    #[arg(long, conflicts_with = "tf", help_heading = heading::LOOK)]
    pub preset: Option<String>,
    /// Place an MR preset between two values of the file.
    ///
    /// Instead of its landmarks (`info` shows them): the preset's low
    /// anchor (its threshold, where its opacity begins) at LO, its high one
    /// at HI.
    #[arg(long, value_name = "LO,HI", value_parser = parse_range, requires = "preset",
          help_heading = heading::LOOK)]
    pub preset_range: Option<[f64; 2]>,
    /// Take a preset of another modality than the file's.
    ///
    /// `info` says which modality the file is and where that came from.
    #[arg(long, help_heading = heading::LOOK)]
    pub force: bool,
    /// Iso value of the surface, when it is not the file's own.
    ///
    /// Surface, depth, cost and MIP modes: any value inside the file's
    /// classification, at or above its iso value, renders exactly without
    /// a new prep.
    #[arg(long, conflicts_with = "preset", help_heading = heading::LOOK)]
    pub iso: Option<f64>,
    /// Transfer function (JSON) for --mode composite.
    #[arg(long, help_heading = heading::LOOK)]
    pub tf: Option<PathBuf>,
    /// Composite: light the samples (a headlight).
    ///
    /// Also `"shade": true` in the --tf file.
    #[arg(long, help_heading = heading::LOOK)]
    pub shade: bool,
    /// Composite sample distance in mm [default: 0.5]; implies
    /// --integrate step when --integrate is not given.
    #[arg(long, help_heading = heading::LOOK)]
    pub step: Option<f64>,
    /// Composite and MIP: integrate per ray-cell segment or by steps.
    ///
    /// segment (the default): the composite integrates each cell's
    /// stretch of ray exactly through an integral table, the MIP takes
    /// each cell's exact maximum; step: samples --step apart, and the MIP
    /// at the cells' faces; reference: f64 at 1/64 of a cell, for
    /// measuring the others (docs/TRADEOFFS.md, "Integrators").
    #[arg(long, value_enum, help_heading = heading::LOOK)]
    pub integrate: Option<IntegrateArg>,
    /// Shadow rays, traced with the same traversal.
    #[arg(long, help_heading = heading::LOOK)]
    pub shadows: bool,
    /// Label files: the labels to draw (`1,5-9`, names, `all`).
    ///
    /// A file made by `prep --labels` draws all its labels by default;
    /// each label's surface is the 0.5 level of its smoothed indicator,
    /// in the colour table's colour and opacity.
    #[arg(long, value_name = "LIST", help_heading = heading::LOOK)]
    pub labels: Option<String>,
    /// Draw a label file (on this file's grid) inside this render.
    ///
    /// Surface and composite renders: each ray ends at the first surface
    /// of the chosen labels (--labels, --lut), which is drawn behind what
    /// the scan shows in front of it.
    #[arg(long, value_name = "FILE", help_heading = heading::LOOK)]
    pub overlay: Option<PathBuf>,
    /// Label files: a colour table over the file's own (ITK-SNAP,
    /// FreeSurfer *LUT.txt or JSON).
    #[arg(long, value_name = "FILE", help_heading = heading::LOOK)]
    pub lut: Option<PathBuf>,
    /// Surface normals: smooth or per cell.
    ///
    /// Central differences interpolated (smooth), or each cell's own
    /// interpolant gradient (cell; docs/TRADEOFFS.md, "Normals").
    #[arg(long, value_enum, default_value = "smooth", help_heading = heading::LOOK)]
    pub normals: NormalsArg,
    /// MIP grey window: auto, full, or a width W with --level L.
    ///
    /// `auto` (the 1st to the 99.9th percentile of the image's values),
    /// `full` (the file's value range) or a width W, with --level L (values
    /// L - W/2 .. L + W/2 map to black..white).
    #[arg(long, default_value = "auto", help_heading = heading::LOOK)]
    pub window: String,
    /// MIP: window centre (with a numeric --window).
    #[arg(long, allow_hyphen_values = true, help_heading = heading::LOOK)]
    pub level: Option<f64>,

    // ---- Output ----------------------------------------------------------
    /// Output image: PNG, TIFF or JPEG by the extension.
    ///
    /// .png, .tif, .tiff, .jpg, .jpeg; the depth mode writes PNG.
    #[arg(short, long, help_heading = heading::OUTPUT)]
    pub output: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512, help_heading = heading::OUTPUT)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512, help_heading = heading::OUTPUT)]
    pub height: u32,
    /// Background: black, white, R,G,B, #rrggbb or transparent.
    ///
    /// What shows behind the image where rays cover less than the pixel:
    /// black (default), white, R,G,B, #rrggbb, or transparent (RGBA PNG or
    /// TIFF whose alpha is each pixel's coverage: the composite's opacity,
    /// 1 on a surface).
    #[arg(long, default_value = "black", value_parser = cdvol::render::Background::parse,
          help_heading = heading::OUTPUT)]
    pub background: cdvol::render::Background,
    /// Bits per channel: 8, 16, or 32 (float32 TIFF).
    ///
    /// 8; 16 (PNG and TIFF; the same colours, rounded to 16 bits instead
    /// of 8); or 32, float32 TIFF: the colour unrounded in surface and
    /// composite, the data itself in one channel in depth (mm), MIP (data
    /// units, whatever the window) and cost (steps), NaN where a ray
    /// misses.
    #[arg(long, default_value = "8", value_parser = parse_bit_depth,
          help_heading = heading::OUTPUT)]
    pub bit_depth: cdvol::render::Bits,
    /// A scale bar in the lower left corner (orthographic views).
    ///
    /// `--scale-bar` alone picks the longest 1, 2 or 5 times a power of ten
    /// mm within a quarter of the width; `--scale-bar=MM` sets the length.
    #[arg(long, value_name = "MM", num_args = 0..=1, require_equals = true,
          default_missing_value = "auto",
          value_parser = cdvol::render::output::scalebar::ScaleBar::parse,
          help_heading = heading::OUTPUT)]
    pub scale_bar: Option<cdvol::render::output::scalebar::ScaleBar>,
    /// Write render statistics as JSON, with the camera the view was
    /// placed at (`camera`: eye, target, up, frame_mm or fov_deg; the same
    /// image again with --eye, --target, --up and --frame, or --persp --fov).
    #[arg(long, help_heading = heading::OUTPUT)]
    pub stats: Option<PathBuf>,

    // ---- Performance -----------------------------------------------------
    /// Worker threads (default: all cores).
    #[arg(long, help_heading = heading::PERFORMANCE)]
    pub threads: Option<usize>,
    /// Brick cache budget in MiB.
    #[arg(long, default_value_t = 512, help_heading = heading::PERFORMANCE)]
    pub cache_mb: usize,
    /// Memory the render may plan to use, in MiB (default: 3/4 of RAM).
    ///
    /// The cache plus 64 bytes a pixel (docs/RELIABILITY.md, "Memory").
    #[arg(long, value_name = "MIB", help_heading = heading::PERFORMANCE)]
    pub mem_limit: Option<u64>,
    /// Render shard K of N, for `cdvol assemble`.
    ///
    /// Tile i (Morton order) when i % N == K, written to a part file (-o
    /// NAME.cdvpart) for `cdvol assemble`; with --frames, frame f when f %
    /// N == K, written as PNGs.
    #[arg(long, value_parser = cdvol::render::Shard::parse,
          help_heading = heading::PERFORMANCE)]
    pub shard: Option<cdvol::render::Shard>,

    // ---- Tuning and paper experiments (left out of -h) --------------------
    /// Ray generator (paper section 5): chessboard distance, single-cell
    /// steps, CD with anisotropic codes (files prepared with --aniso), an
    /// octree, or the 3D DDA with chessboard leaps (regular grids), all
    /// exact: the same image either way. Default: cd-aniso when the file
    /// has anisotropic codes, else cd. The inexact generators are
    /// `cdvol experiment render`'s.
    #[arg(long, value_enum, help_heading = heading::TUNING, hide_short_help = true)]
    pub traversal: Option<TraversalArg>,
    /// CD leaps only over cells with at least this code; smaller codes take
    /// single-cell steps (1 = the paper).
    #[arg(long, default_value_t = 1, help_heading = heading::TUNING, hide_short_help = true)]
    pub min_leap: u8,
    /// CD switches to single-cell (FVT) steps in cells whose chessboard
    /// code is at most D (paper Fig. 20; the same as --min-leap D+1).
    #[arg(long, value_name = "D", conflicts_with = "min_leap",
          help_heading = heading::TUNING, hide_short_help = true)]
    pub switch_fvt_at: Option<u8>,
    /// Not a `render` option: DDA traversals without the switch to
    /// single-cell steps near objects draw wrong images (they miss
    /// 1-cells). Set by `cdvol experiment render --no-switch-fvt`.
    #[arg(skip)]
    pub no_switch_fvt: bool,
    /// Set by `cdvol experiment render`: the inexact traversals are
    /// accepted ([`TraversalArg::exact`]).
    #[arg(skip)]
    pub experiment: bool,
    /// Surface intersection inside a 1-cell.
    #[arg(long, value_enum, default_value = "int",
          help_heading = heading::TUNING, hide_short_help = true)]
    pub hit: HitArg,
    /// Bisection iterations for --hit bisect (each halves the bracket).
    #[arg(long, default_value_t = 30, help_heading = heading::TUNING, hide_short_help = true)]
    pub bisect_iters: u32,
    /// Largest number of Newton iterations for --hit newton.
    #[arg(long, default_value_t = 8, help_heading = heading::TUNING, hide_short_help = true)]
    pub newton_iters: u32,
    /// Newton's relative tolerance on the bracket and on the residual.
    #[arg(long, default_value_t = 1e-12, help_heading = heading::TUNING, hide_short_help = true)]
    pub newton_tol: f64,
    /// Arithmetic of the traversal: f64 never misses a 1-cell; f32 is
    /// measured in docs/TRADEOFFS.md.
    #[arg(long, value_enum, default_value = "f64",
          help_heading = heading::TUNING, hide_short_help = true)]
    pub precision: PrecisionArg,
    /// Arithmetic of composite samples: f32 (fast) or f64 (the
    /// reference); docs/TRADEOFFS.md measures the difference.
    #[arg(long, value_enum, default_value = "f32",
          help_heading = heading::TUNING, hide_short_help = true)]
    pub sample_precision: PrecisionArg,
    /// Composite, f32, unshaded or with smooth normals (shading, gradient
    /// opacity): take a ray's samples eight at a time,
    /// their cells found by position (on), or one at a time by the cell
    /// planes (off); docs/TRADEOFFS.md measures the difference.
    #[arg(long, value_enum, default_value = "on",
          help_heading = heading::TUNING, hide_short_help = true)]
    pub sample_batches: OnOff,
    /// --integrate segment: how far a chord may be from the interpolant,
    /// as a share of the transfer function's narrowest gap between
    /// points (smaller is slower and closer; docs/TRADEOFFS.md).
    #[arg(long, default_value_t = cdvol::render::Integrate::SEGMENT_TOL,
          help_heading = heading::TUNING, hide_short_help = true)]
    pub segment_tol: f64,
    /// Composite: stop a ray once its opacity exceeds this (1 = never).
    #[arg(long, default_value_t = cdvol::render::EARLY_STOP,
          help_heading = heading::TUNING, hide_short_help = true)]
    pub early_stop: f64,
    /// Tile edge in pixels.
    #[arg(long, default_value_t = 32, help_heading = heading::TUNING, hide_short_help = true)]
    pub tile: u32,
    /// CD leaves a brick without 1-cells unread when the smallest code in
    /// it (from the index) is at least this; 255 reads every brick entered.
    /// Default: 16 where a brick spans at least 64 pixels of the image,
    /// else 4 (docs/BENCHMARKS.md, "The stand-in threshold by ray density").
    #[arg(long, help_heading = heading::TUNING, hide_short_help = true)]
    pub cd_lazy_min: Option<u8>,
    /// Trace every pixel's ray from the volume's entry, also those no brick
    /// with 1-cells projects onto (by default they are drawn as misses
    /// without a ray, and the others start where the nearest such box
    /// begins: the same image; docs/BENCHMARKS.md, "Culling by the brick
    /// index" and "Rays start where the cover's boxes begin").
    #[arg(long, help_heading = heading::TUNING, hide_short_help = true)]
    pub no_cull: bool,
    /// How --shard deals tiles: every N-th tile (interleaved: shards take
    /// equal time) or contiguous runs of the Morton curve (blocks: shards
    /// read fewer bricks). See docs/BENCHMARKS.md.
    #[arg(long, value_enum, default_value = "interleaved",
          help_heading = heading::TUNING, hide_short_help = true)]
    pub shard_layout: ShardLayoutArg,
}

/// `cdvol experiment render`: `cdvol render` with the switches that draw
/// wrong images on purpose, for measurements.
#[derive(Args, Debug)]
pub struct ExperimentRenderArgs {
    #[command(flatten)]
    pub render: RenderArgs,
    /// DDA traversals: do not switch to single-cell steps near objects.
    /// Draws wrong images: misses 1-cells; for measuring step lengths
    /// (paper Fig. 18a).
    #[arg(long, help_heading = heading::TUNING)]
    pub no_switch_fvt: bool,
}

impl ExperimentRenderArgs {
    /// The render these arguments ask for, the experiment switches set.
    pub fn into_render(self) -> RenderArgs {
        RenderArgs {
            no_switch_fvt: self.no_switch_fvt,
            experiment: true,
            ..self.render
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum ShardLayoutArg {
    Interleaved,
    Blocks,
}

impl From<HitArg> for HitMethod {
    fn from(h: HitArg) -> HitMethod {
        match h {
            HitArg::Int => HitMethod::Int,
            HitArg::Bisect => HitMethod::Bisect,
            HitArg::Newton => HitMethod::Newton,
            HitArg::Exact => HitMethod::Exact,
        }
    }
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Precision {
        match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
        }
    }
}

impl From<ShardLayoutArg> for ShardLayout {
    fn from(l: ShardLayoutArg) -> ShardLayout {
        match l {
            ShardLayoutArg::Interleaved => ShardLayout::Interleaved,
            ShardLayoutArg::Blocks => ShardLayout::Blocks,
        }
    }
}

/// `LO,HI`: two finite numbers, LO < HI.
fn parse_range(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    match v[..] {
        [lo, hi] if lo.is_finite() && hi.is_finite() && lo < hi => Ok([lo, hi]),
        _ => Err(format!(
            "{s:?}: expected LO,HI, two finite numbers with LO < HI"
        )),
    }
}

#[derive(Args, Debug)]
pub struct AssembleArgs {
    /// Part files from `cdvol render --shard K/N`, every K once.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write the merged statistics as JSON.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// What shows behind the image: black (default), white, R,G,B,
    /// #rrggbb, or transparent (RGBA: alpha is each pixel's coverage).
    #[arg(long, default_value = "black", value_parser = cdvol::render::Background::parse)]
    pub background: cdvol::render::Background,
    /// Bits per channel of the image: 8; 16 (PNG and TIFF; the same
    /// colours, rounded to 16 bits instead of 8); or 32, float32 TIFF:
    /// the colour unrounded in surface and composite, the data itself in
    /// one channel in depth (mm), MIP (data units, whatever the window)
    /// and cost (steps), NaN where a ray misses.
    #[arg(long, default_value = "8", value_parser = parse_bit_depth)]
    pub bit_depth: cdvol::render::Bits,
}

impl AssembleArgs {
    /// The image's background and bits.
    pub fn image(&self) -> cdvol::render::ImageSpec {
        cdvol::render::ImageSpec {
            background: self.background,
            bits: self.bit_depth,
        }
    }
}

/// `--bit-depth`: 8, 16 or 32 (float, TIFF).
fn parse_bit_depth(s: &str) -> Result<cdvol::render::Bits, String> {
    use cdvol::render::Bits;
    match s.trim() {
        "8" => Ok(Bits::Eight),
        "16" => Ok(Bits::Sixteen),
        "32" => Ok(Bits::Float),
        _ => Err(format!("{s:?}: expected 8, 16 or 32 (float, TIFF only)")),
    }
}

fn parse_floats<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != N {
        return Err(format!("{s:?}: expected {N} comma-separated numbers"));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(v) {
        *o = p
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{p:?}: expected a finite number"))?;
    }
    Ok(out)
}

/// `render --view`: a named view or `AZ,EL`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ViewArg {
    Angles([f64; 2]),
    Named(cdvol::orient::NamedView),
}

fn parse_view(s: &str) -> Result<ViewArg, String> {
    use cdvol::orient::NamedView;
    if let Some(v) = NamedView::parse(s) {
        return Ok(ViewArg::Named(v));
    }
    if !s.contains(',') {
        return Err(format!(
            "{s:?}: expected AZ,EL in degrees or one of {}",
            NamedView::NAMES
        ));
    }
    parse_floats::<2>(s).map(ViewArg::Angles)
}

fn parse_triple(s: &str) -> Result<[f64; 3], String> {
    parse_floats::<3>(s)
}

/// `--crop X0:X1,Y0:Y1,Z0:Z1`.
fn parse_crop(s: &str) -> Result<[[f64; 2]; 3], String> {
    let expected = || format!("{s:?}: expected X0:X1,Y0:Y1,Z0:Z1 in mm");
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(expected());
    }
    let mut out = [[0.0; 2]; 3];
    for (k, p) in parts.iter().enumerate() {
        let (a, b) = p.split_once(':').ok_or_else(expected)?;
        out[k] = [
            a.trim().parse().map_err(|_| expected())?,
            b.trim().parse().map_err(|_| expected())?,
        ];
    }
    Ok(out)
}

/// `--clip NX,NY,NZ,D`.
fn parse_plane(s: &str) -> Result<[f64; 4], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{s:?}: expected NX,NY,NZ,D"))?;
    <[f64; 4]>::try_from(v).map_err(|_| format!("{s:?}: expected NX,NY,NZ,D"))
}
