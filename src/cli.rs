//! Command-line arguments (clap derive) and their conversion into the
//! library's checked options. Binary only: the library knows no clap.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use cdvol::classify::TransferFunction;
use cdvol::render::camera::CameraError;
use cdvol::render::job::{CameraSpec, JobError, RenderJob, View};
use cdvol::render::shade::{HitMethod, HitParams};
use cdvol::render::traverse::{DistKind, Method};
use cdvol::render::{
    CompositeLook, Mode, Precision, RenderError, RenderOptions, Shard, ShardLayout, Window,
};

#[derive(Parser, Debug)]
#[command(
    name = "cdvol",
    version,
    about = "Streaming out-of-core volume preparation for chessboard-distance ray casting"
)]
pub struct Cli {
    /// No progress bars (they are also hidden when stderr is not a terminal).
    #[arg(long, short, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Classify cells, compute distance codes and write a packed file.
    Prep(PrepArgs),
    /// Prepare every volume under a directory (DICOM series, NRRD, NIfTI,
    /// raw sidecars) into OUT_DIR, resuming where a previous run stopped.
    PrepBatch(PrepBatchArgs),
    /// Describe a packed file.
    Info(InfoArgs),
    /// Plot a packed file's value histogram (PNG or SVG, by the
    /// extension of -o) with the presets' value ranges and the file's
    /// classification marked.
    Histogram(HistogramArgs),
    /// List the named transfer-function presets (`prep --preset NAME`).
    Presets(PresetsArgs),
    /// Write values, codes or classes of a packed file as raw + sidecar.
    Export(ExportArgs),
    /// Generate test volumes.
    #[command(subcommand)]
    Phantom(PhantomCmd),
    /// Ray-cast a packed file into a PNG.
    Render(Box<RenderArgs>),
    /// Generate the CT-like phantom and a sphere scene, prepare and render
    /// them, and report what was written.
    Demo(DemoArgs),
    /// Join the part files of a sharded render (`render --shard K/N`) into
    /// the image one process would have written.
    Assemble(AssembleArgs),
    /// Reproducible measurements, written as reports under docs/.
    #[command(subcommand)]
    Experiment(ExperimentCmd),
    /// Serve a browser viewer of packed files: orbit, zoom, presets, live
    /// renders through one shared brick cache (docs/SERVE.md).
    Serve(ServeArgs),
}

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// Packed files to offer (the page picks one by its index).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Address to listen on (localhost by default; port 0: any free port).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub bind: std::net::SocketAddr,
    /// Brick cache budget in MiB, shared by every request.
    #[arg(long, default_value_t = 512)]
    pub cache_mb: usize,
    /// Render worker threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

impl ServeArgs {
    /// The library's configuration.
    pub fn config(&self) -> cdvol::serve::ServeConfig {
        cdvol::serve::ServeConfig {
            files: self.files.clone(),
            bind: self.bind,
            cache_mb: self.cache_mb,
            threads: self.threads,
        }
    }
}

#[derive(Subcommand, Debug)]
pub enum ExperimentCmd {
    /// Time against error for every hit method, traversal precision and
    /// composite step, on the sphere phantom (analytic truth) and the real
    /// CT: writes docs/TRADEOFFS.md, tradeoffs.csv and tradeoffs.svg.
    Tradeoffs(TradeoffsArgs),
    /// Fig. 16: background traversal time vs scene complexity (fvt,
    /// octree, cd, ...) on 128^3 sphere scenes.
    Fig16(PaperArgs),
    /// Fig. 17: cost maps of fvt, octree and cd on the real CT, one PNG.
    Fig17(PaperArgs),
    /// Fig. 18: mean step length of the DDA distances and CD.
    Fig18(PaperArgs),
    /// Fig. 20: CD switched to FVT at distance 1, 2, 3.
    Fig20(PaperArgs),
    /// Fig. 22: surface detection, samples on faces vs equidistant.
    Fig22(PaperArgs),
    /// Table 1: single-cell vs macro-region traversal, rectilinear CT.
    Table1(PaperArgs),
    /// Table 2: initialisation per ray and step cost of every generator.
    Table2(PaperArgs),
    /// Every paper experiment: writes docs/EXPERIMENTS.md and
    /// docs/experiments/ (CSV, SVG, PNG).
    All(PaperArgs),
}

impl ExperimentCmd {
    /// The paper experiment this command names, with its options. Refuses
    /// `tradeoffs` (not one of the paper's) and, naming `--ct`, the
    /// experiments that render the real CT when it is not given.
    pub fn paper_job(&self) -> anyhow::Result<cdvol::tools::experiment::paper::Job> {
        use cdvol::tools::experiment::paper::{Job, PaperOptions, Which};
        let (which, a) = match self {
            ExperimentCmd::Fig16(a) => (Which::Fig16, a),
            ExperimentCmd::Fig17(a) => (Which::Fig17, a),
            ExperimentCmd::Fig18(a) => (Which::Fig18, a),
            ExperimentCmd::Fig20(a) => (Which::Fig20, a),
            ExperimentCmd::Fig22(a) => (Which::Fig22, a),
            ExperimentCmd::Table1(a) => (Which::Table1, a),
            ExperimentCmd::Table2(a) => (Which::Table2, a),
            ExperimentCmd::All(a) => (Which::All, a),
            ExperimentCmd::Tradeoffs(_) => anyhow::bail!("tradeoffs is not a paper experiment"),
        };
        if a.ct.is_none() && matches!(which, Which::Fig17 | Which::Table1) {
            anyhow::bail!(
                "{} renders the real CT: give --ct DIR/cranium.json (tools/fetch-ct.sh DIR)",
                if which == Which::Fig17 {
                    "fig17"
                } else {
                    "table1"
                }
            );
        }
        Ok(Job {
            which,
            out: a.out.clone(),
            opts: PaperOptions {
                // CSV, SVG and PNG files go to `experiments/` beside the report.
                dir: a
                    .out
                    .parent()
                    .unwrap_or(std::path::Path::new("."))
                    .join("experiments"),
                ns: a.ns.clone(),
                size: a.size,
                rays: a.rays,
                runs: a.runs,
                ct: a.ct.clone(),
            },
        })
    }
}

#[derive(Args, Debug, Clone)]
pub struct PaperArgs {
    /// The Markdown report; CSV, SVG and PNG files go to `experiments/`
    /// beside it.
    #[arg(long, default_value = "docs/EXPERIMENTS.md")]
    pub out: PathBuf,
    /// Sidecar of the real CT (tools/fetch-ct.sh DIR writes DIR/cranium.json);
    /// table1 and fig17 need it.
    #[arg(long)]
    pub ct: Option<PathBuf>,
    /// Sphere scenes: N subregions per axis (paper: 2..21).
    #[arg(long, value_delimiter = ',', default_value = "2,3,4,5,6,8,10,13,17,21")]
    pub ns: Vec<usize>,
    /// Scene edge in samples (paper: 128).
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Rays per image edge (paper: 250).
    #[arg(long, default_value_t = 250)]
    pub rays: u32,
    /// Repetitions per setting (median reported).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
}

#[derive(Args, Debug)]
pub struct TradeoffsArgs {
    /// The Markdown report (CSV and SVG go beside it).
    #[arg(long, default_value = "docs/TRADEOFFS.md")]
    pub out: PathBuf,
    /// Sidecar of the real CT (tools/fetch-ct.sh DIR writes DIR/cranium.json).
    #[arg(long)]
    pub ct: Option<PathBuf>,
    /// Image edge in pixels.
    #[arg(long, default_value_t = 384)]
    pub size: u32,
    /// Runs per setting; the median is reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
}

impl TradeoffsArgs {
    /// The experiment's options; out-of-range values are named by flag.
    pub fn to_options(&self) -> anyhow::Result<cdvol::tools::experiment::TradeoffOptions> {
        if self.runs == 0 {
            anyhow::bail!("option --runs: 0, expected at least 1");
        }
        if !(16..=4096).contains(&self.size) {
            anyhow::bail!("option --size: {}, expected 16..=4096 pixels", self.size);
        }
        Ok(cdvol::tools::experiment::TradeoffOptions {
            out: self.out.clone(),
            ct: self.ct.clone(),
            size: self.size,
            runs: self.runs,
        })
    }
}

#[derive(Args, Debug)]
pub struct PrepArgs {
    /// The volume: a directory holding a DICOM series, a raw-stack sidecar
    /// (.json), NRRD (.nrrd, .nhdr) or NIfTI-1 (.nii, .nii.gz).
    pub input: PathBuf,
    /// Packed output file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The DICOM series to prepare when the directory holds several
    /// (SeriesInstanceUID).
    #[arg(long, value_name = "UID")]
    pub series: Option<String>,
    #[command(flatten)]
    pub settings: PrepSettings,
}

/// How prep classifies and packs (shared by prep and prep-batch).
#[derive(Args, Debug)]
pub struct PrepSettings {
    /// Iso value (rescaled units, e.g. HU): a cell is a 1-cell when its
    /// largest vertex value is >= T.
    #[arg(
        long,
        value_name = "T",
        conflicts_with_all = ["classify_tf", "preset", "envelope"],
        allow_negative_numbers = true
    )]
    pub iso: Option<f64>,
    /// One file for a whole exploration: the iso classification that
    /// holds every item, so `render --iso`/`--tf`/`--preset` cover them all
    /// without another prep. Items: iso values, presets, or a modality
    /// (`ct`, `mr`: all its presets), comma-separated; e.g. `--envelope ct`
    /// or `--envelope ct-bone,ct-muscle,500`. `auto`: the envelope of the
    /// input's modality, CT or MR, guessed from its middle slice (values
    /// below -500 mean CT) — per input in prep-batch.
    #[arg(
        long,
        value_name = "ITEMS",
        value_delimiter = ',',
        conflicts_with_all = ["classify_tf", "preset"],
        allow_negative_numbers = true
    )]
    pub envelope: Vec<String>,
    /// Transfer function (JSON): a cell is a 1-cell when its opacity is
    /// non-zero anywhere between the min and max of its vertex values.
    #[arg(long, value_name = "FILE", conflicts_with = "preset")]
    pub classify_tf: Option<PathBuf>,
    /// A named preset's transfer function (`cdvol presets` lists them),
    /// as --classify-tf with that function.
    #[arg(long, value_name = "NAME")]
    pub preset: Option<String>,
    /// Cells per brick edge (multiple of 4).
    #[arg(long, default_value_t = 32)]
    pub brick: usize,
    /// zstd compression level of brick payloads.
    #[arg(long, default_value_t = 3, allow_negative_numbers = true)]
    pub zstd_level: i32,
    /// Format version to write: 3 (the default) stores sample words as
    /// byte planes, smaller and faster to decode; 2 is the layout cdvol
    /// builds before byte planes read (docs/FORMAT.md).
    #[arg(long, value_name = "N", default_value_t = cdvol::format::FORMAT_VERSION)]
    pub format_version: u32,
    /// Also compute anisotropic (octant) codes, paper section 4.2.1.
    #[arg(long)]
    pub aniso: bool,
    /// Also store extra city-block and chamfer distance planes for the DDA
    /// traversals (paper section 3), 2 bytes per cell.
    #[arg(long)]
    pub dda: bool,
    /// Embed only codes >= 2, so every sample within one cell of a 1-cell
    /// keeps its value: smooth normals read true central differences
    /// everywhere (docs/TRADEOFFS.md, "Normals").
    #[arg(long)]
    pub gradient_halo: bool,
    /// Directory for the temporary spill (default: beside the output).
    #[arg(long)]
    pub temp_dir: Option<PathBuf>,
    /// Memory prep may plan to use, in MiB (default: 3/4 of RAM); a prep
    /// whose planned peak (docs/RELIABILITY.md, "Memory") is above it is
    /// refused before it allocates.
    #[arg(long, value_name = "MIB")]
    pub mem_limit: Option<u64>,
}

impl PrepSettings {
    /// The checked prep options; errors name the flags.
    pub fn to_options(&self) -> anyhow::Result<cdvol::prep::PrepOptions> {
        use cdvol::classify::{Classification, TransferFunction};
        if self.envelope.len() == 1 && self.envelope[0].eq_ignore_ascii_case("auto") {
            let mut o = self.with(Classification::Iso { iso: 0.0 })?;
            o.auto_envelope = true;
            return Ok(o);
        }
        if !self.envelope.is_empty() {
            let (iso, _) = cdvol::presets::envelope(&self.envelope)
                .map_err(|e| anyhow::anyhow!("option --envelope: {e}"))?;
            return self.with(Classification::Iso { iso });
        }
        let classification = match (self.iso, &self.classify_tf, &self.preset) {
            (Some(iso), None, None) => {
                if !iso.is_finite() {
                    anyhow::bail!("option --iso: {iso}, expected a finite number");
                }
                Classification::Iso { iso }
            }
            (None, Some(tf), None) => Classification::TransferFunction {
                tf: TransferFunction::load(tf)?,
            },
            (None, None, Some(name)) => cdvol::presets::get(name)
                .map_err(|e| anyhow::anyhow!("option --preset: {e}"))?
                .classification(),
            (None, None, None) => anyhow::bail!(
                "prep needs --iso T, --classify-tf FILE, --preset NAME or --envelope ITEMS to \
                 decide which cells are objects"
            ),
            _ => anyhow::bail!(
                "--iso, --classify-tf and --preset each choose the classification: give one"
            ),
        };
        self.with(classification)
    }

    /// The checked prep options with `classification`.
    fn with(
        &self,
        classification: cdvol::classify::Classification,
    ) -> anyhow::Result<cdvol::prep::PrepOptions> {
        let opts = cdvol::prep::PrepOptions {
            classification,
            brick_size: self.brick,
            zstd_level: self.zstd_level,
            aniso: self.aniso,
            dda: self.dda,
            gradient_halo: self.gradient_halo,
            temp_dir: self.temp_dir.clone(),
            stamp: None,
            auto_envelope: false,
            mem_limit: self.mem_limit.map(|m| m.saturating_mul(1 << 20)),
            format_version: self.format_version,
        };
        opts.check().map_err(prep_error)?;
        Ok(opts)
    }
}

/// A prep error as the user of the command line needs it: the library
/// names the `PrepOptions` field, this adds the flag that sets it.
pub fn prep_error(e: cdvol::prep::PrepError) -> anyhow::Error {
    use cdvol::prep::PrepError;
    if let PrepError::Option { field, .. } = &e {
        let flag = match *field {
            "brick_size" => "--brick",
            "zstd_level" => "--zstd-level",
            "format_version" => "--format-version",
            other => other,
        };
        return anyhow::anyhow!("option {flag}: {e}");
    }
    match e {
        PrepError::Input(i) => input_error(i),
        e => e.into(),
    }
}

/// A phantom error naming the flag of the option at fault (the library
/// names the field: `z_scale` is set by `--z-scale`).
pub fn phantom_error(e: cdvol::tools::phantom::PhantomError) -> anyhow::Error {
    match &e {
        cdvol::tools::phantom::PhantomError::Option { option, .. } => {
            anyhow::anyhow!("--{}: {e}", option.replace('_', "-"))
        }
        _ => e.into(),
    }
}

/// An input error, with the flag that picks a DICOM series where the
/// choice is the problem.
pub fn input_error(e: cdvol::input::InputError) -> anyhow::Error {
    use cdvol::input::InputError;
    match &e {
        InputError::SeveralSeries { .. } => anyhow::anyhow!("{e}: pick one with --series UID"),
        InputError::NoSuchSeries { uid, .. } => {
            anyhow::anyhow!("option --series {uid}: {e}")
        }
        _ => e.into(),
    }
}

/// Most inputs `prep-batch --jobs` prepares at once.
pub const MAX_JOBS: usize = 256;

#[derive(Args, Debug)]
pub struct PrepBatchArgs {
    /// Directory searched (recursively) for inputs.
    pub input: PathBuf,
    /// Directory for the packed files and the summary (batch.json).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Inputs prepared at once (memory grows with it: one prep each).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Process input i (sorted by path) when i % N == K.
    #[arg(long, value_parser = cdvol::render::Shard::parse)]
    pub shard: Option<cdvol::render::Shard>,
    #[command(flatten)]
    pub settings: PrepSettings,
}

impl PrepBatchArgs {
    /// Checks `--jobs` (each job is one prep's memory).
    pub fn check(&self) -> anyhow::Result<()> {
        if !(1..=MAX_JOBS).contains(&self.jobs) {
            anyhow::bail!(
                "option --jobs: {}, expected 1..={MAX_JOBS} (each job holds one prep's memory)",
                self.jobs
            );
        }
        Ok(())
    }

    /// `(K, N)` of `--shard K/N`; `(0, 1)` without it.
    pub fn shard(&self) -> (u32, u32) {
        self.shard.map(|s| (s.k, s.n)).unwrap_or((0, 1))
    }

    /// The summary JSON: `batch.json`, or `batch.KofN.json` for a shard.
    pub fn summary_path(&self) -> PathBuf {
        self.output.join(match self.shard {
            Some(s) => format!("batch.{}of{}.json", s.k, s.n),
            None => "batch.json".into(),
        })
    }
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Args, Debug)]
pub struct HistogramArgs {
    /// Packed file from `cdvol prep`.
    pub file: PathBuf,
    /// Output plot: .png or .svg.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Presets whose value ranges are marked: `auto` (the CT presets when
    /// the data reach below -500, as HU air does, else the MR ones),
    /// `all`, `none`, `ct`, `mr`, or names separated by commas.
    #[arg(long, default_value = "auto")]
    pub presets: String,
    #[arg(long, default_value_t = 1000)]
    pub width: u32,
    #[arg(long, default_value_t = 700)]
    pub height: u32,
}

impl HistogramArgs {
    /// The presets `--presets` names, for data whose smallest value is
    /// `min`.
    pub fn presets(&self, min: Option<f64>) -> anyhow::Result<Vec<cdvol::presets::Preset>> {
        use cdvol::presets::{all, get, Modality};
        let of = |m: Modality| all().iter().filter(|p| p.modality == m).cloned().collect();
        Ok(match self.presets.trim().to_ascii_lowercase().as_str() {
            "auto" => {
                if min.is_some_and(|v| v < -500.0) {
                    of(Modality::Ct)
                } else {
                    of(Modality::Mr)
                }
            }
            "all" => all().to_vec(),
            "none" | "" => Vec::new(),
            "ct" => of(Modality::Ct),
            "mr" => of(Modality::Mr),
            list => list
                .split(',')
                .map(|n| get(n).map_err(|e| anyhow::anyhow!("option --presets: {e}")))
                .collect::<anyhow::Result<_>>()?,
        })
    }
}

#[derive(Args, Debug)]
pub struct PresetsArgs {
    /// Print JSON (every field, the sources too) instead of a table.
    #[arg(long, conflicts_with = "tf")]
    pub json: bool,
    /// Print only this preset's transfer function, as a --classify-tf /
    /// --tf file.
    #[arg(long, value_name = "NAME")]
    pub tf: Option<String>,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum What {
    Values,
    Codes,
    Classes,
}

impl From<What> for cdvol::export::ExportWhat {
    fn from(w: What) -> Self {
        match w {
            What::Values => cdvol::export::ExportWhat::Values,
            What::Codes => cdvol::export::ExportWhat::Codes,
            What::Classes => cdvol::export::ExportWhat::Classes,
        }
    }
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    pub file: PathBuf,
    #[arg(long, value_enum)]
    pub what: What,
    /// Output sidecar; the raw data goes beside it as STEM.raw.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Subcommand, Debug)]
pub enum PhantomCmd {
    /// The paper's section 5.1 scenes: N^3 random spheres of equal total volume.
    Spheres(SpheresArgs),
    /// A CT-like head with slices thin in the middle and 4x thicker on top.
    Ct(CtArgs),
}

#[derive(Args, Debug)]
pub struct SpheresArgs {
    /// Output sidecar (raw data and the sphere list go beside it).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples per axis.
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Subregions per axis (N); N^3 spheres.
    #[arg(long, default_value_t = 2)]
    pub per_axis: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Spacing in mm: one spec for all axes or three, comma-separated;
    /// "A:B" varies the gap linearly from A to B (rectilinear).
    #[arg(long, default_value = "1")]
    pub spacing: String,
}

impl SpheresArgs {
    /// The generator's options; a bad `--spacing` is named by its flag.
    pub fn to_options(&self) -> anyhow::Result<cdvol::tools::phantom::SpheresOptions> {
        let spacing = cdvol::tools::phantom::parse_spacing3(&self.spacing)
            .map_err(|e| anyhow::anyhow!("option --spacing: {e}"))?;
        Ok(cdvol::tools::phantom::SpheresOptions {
            size: self.size,
            per_axis: self.per_axis,
            seed: self.seed,
            spacing,
        })
    }
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum CtType {
    I16,
    U16,
}

impl From<CtType> for cdvol::tools::phantom::CtDtype {
    fn from(t: CtType) -> Self {
        match t {
            CtType::I16 => cdvol::tools::phantom::CtDtype::I16,
            CtType::U16 => cdvol::tools::phantom::CtDtype::U16,
        }
    }
}

impl From<&CtArgs> for cdvol::tools::phantom::CtOptions {
    fn from(a: &CtArgs) -> Self {
        cdvol::tools::phantom::CtOptions {
            dims: a.dims,
            dtype: a.dtype.into(),
            seed: a.seed,
            z_scale: a.z_scale,
        }
    }
}

#[derive(Args, Debug)]
pub struct CtArgs {
    /// Output sidecar (raw data goes beside it).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples per axis, NX,NY,NZ.
    #[arg(long, default_value = "256,256,160", value_parser = parse_dims)]
    pub dims: [usize; 3],
    /// Sample type: i16 in HU, or u16 = HU + 1024 with a rescale.
    #[arg(long, value_enum, default_value = "i16")]
    pub dtype: CtType,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Multiply the 2/1/4 mm slice gaps by this factor (160/NZ keeps a
    /// head's proportions on tall stacks).
    #[arg(long, default_value_t = 1.0)]
    pub z_scale: f64,
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Where the demo writes its files.
    #[arg(long, default_value = "target/cdvol-demo")]
    pub dir: PathBuf,
}

fn parse_dims(s: &str) -> Result<[usize; 3], String> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != 3 {
        return Err(format!("{s:?}: expected NX,NY,NZ"));
    }
    let mut out = [0; 3];
    for (o, p) in out.iter_mut().zip(v) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| format!("{p:?}: expected a whole number"))?;
    }
    Ok(out)
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeArg {
    Surface,
    Mip,
    Composite,
    Cost,
    Depth,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraversalArg {
    Cd,
    Fvt,
    CdAniso,
    Octree,
    DdaCityblock,
    DdaChessboard,
    DdaChamfer,
    Template,
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

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Packed file from `cdvol prep`.
    pub file: PathBuf,
    /// Output image: PNG, TIFF or JPEG by the extension (.png, .tif,
    /// .tiff, .jpg, .jpeg); the depth mode writes PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// What shows behind the image where rays cover less than the pixel:
    /// black (default), white, R,G,B, #rrggbb, or transparent (RGBA PNG or
    /// TIFF whose alpha is each pixel's coverage: the composite's opacity,
    /// 1 on a surface).
    #[arg(long, default_value = "black", value_parser = cdvol::render::Background::parse)]
    pub background: cdvol::render::Background,
    /// Bits per channel of the image: 8; 16 (PNG and TIFF; the same
    /// colours, rounded to 16 bits instead of 8); or 32, float32 TIFF:
    /// the colour unrounded in surface and composite, the data itself in
    /// one channel in depth (mm), MIP (data units, whatever the window)
    /// and cost (steps), NaN where a ray misses.
    #[arg(long, default_value = "8", value_parser = parse_bit_depth)]
    pub bit_depth: cdvol::render::Bits,
    /// A scale bar in the lower left corner, in orthographic views:
    /// `--scale-bar` alone picks the longest 1, 2 or 5 times a power of ten
    /// mm within a quarter of the width; `--scale-bar=MM` sets the length.
    #[arg(long, value_name = "MM", num_args = 0..=1, require_equals = true,
          default_missing_value = "auto",
          value_parser = cdvol::render::scalebar::ScaleBar::parse)]
    pub scale_bar: Option<cdvol::render::scalebar::ScaleBar>,
    #[arg(long, value_enum, default_value = "surface")]
    pub mode: ModeArg,
    /// Ray generator (paper section 5): chessboard distance (default),
    /// single-cell steps, CD with anisotropic codes (files prepared with
    /// --aniso), an octree, the 3D DDA with city-block / chessboard /
    /// chamfer leaps (regular grids; files prepared with --dda), or
    /// template-based CD (parallel projection, regular grids).
    #[arg(long, value_enum, default_value = "cd")]
    pub traversal: TraversalArg,
    /// CD leaps only over cells with at least this code; smaller codes take
    /// single-cell steps (1 = the paper).
    #[arg(long, default_value_t = 1)]
    pub min_leap: u8,
    /// CD switches to single-cell (FVT) steps in cells whose chessboard
    /// code is at most D (paper Fig. 20; the same as --min-leap D+1).
    #[arg(long, value_name = "D", conflicts_with = "min_leap")]
    pub switch_fvt_at: Option<u8>,
    /// DDA traversals: do not switch to single-cell steps near objects
    /// (misses 1-cells; for measuring step lengths, paper Fig. 18a).
    #[arg(long)]
    pub no_switch_fvt: bool,
    /// Surface intersection inside a 1-cell.
    #[arg(long, value_enum, default_value = "int")]
    pub hit: HitArg,
    /// Bisection iterations for --hit bisect (each halves the bracket).
    #[arg(long, default_value_t = 30)]
    pub bisect_iters: u32,
    /// Largest number of Newton iterations for --hit newton.
    #[arg(long, default_value_t = 8)]
    pub newton_iters: u32,
    /// Newton's relative tolerance on the bracket and on the residual.
    #[arg(long, default_value_t = 1e-12)]
    pub newton_tol: f64,
    /// Arithmetic of the traversal: f64 never misses a 1-cell; f32 is
    /// measured in docs/TRADEOFFS.md.
    #[arg(long, value_enum, default_value = "f64")]
    pub precision: PrecisionArg,
    /// Shadow rays, traced with the same traversal.
    #[arg(long)]
    pub shadows: bool,
    /// Surface normals: central differences interpolated (smooth), or each
    /// cell's own interpolant gradient (cell; docs/TRADEOFFS.md, "Normals").
    #[arg(long, value_enum, default_value = "smooth")]
    pub normals: NormalsArg,
    /// Iso value of the surface (surface, depth, cost and MIP modes),
    /// when it is not the file's own: any value inside the file's
    /// classification, at or above its iso value, renders exactly without
    /// a new prep.
    #[arg(long, conflicts_with = "preset")]
    pub iso: Option<f64>,
    /// A named preset (`cdvol presets`): its transfer function and shading
    /// in composite mode, its iso value in surface, depth and cost modes,
    /// its window in MIP mode.
    #[arg(long, conflicts_with = "tf")]
    pub preset: Option<String>,
    /// Transfer function (JSON) for --mode composite.
    #[arg(long)]
    pub tf: Option<PathBuf>,
    /// Composite sample distance in mm.
    #[arg(long, default_value_t = 0.5)]
    pub step: f64,
    /// Arithmetic of composite samples: f32 (fast) or f64 (the
    /// reference); docs/TRADEOFFS.md measures the difference.
    #[arg(long, value_enum, default_value = "f32")]
    pub sample_precision: PrecisionArg,
    /// Composite: stop a ray once its opacity exceeds this (1 = never).
    #[arg(long, default_value_t = cdvol::render::EARLY_STOP)]
    pub early_stop: f64,
    /// Composite: light the samples (headlight; also `"shade": true` in
    /// the --tf file).
    #[arg(long)]
    pub shade: bool,
    /// MIP grey window: `auto` (the 1st to the 99.9th percentile of the
    /// image's values), `full` (the file's value range) or a width W,
    /// with --level L (values L - W/2 .. L + W/2 map to black..white).
    #[arg(long, default_value = "auto")]
    pub window: String,
    /// MIP: window centre (with a numeric --window).
    #[arg(long, allow_hyphen_values = true)]
    pub level: Option<f64>,
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Tile edge in pixels.
    #[arg(long, default_value_t = 32)]
    pub tile: u32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// CD leaves a brick without 1-cells unread when the smallest code in
    /// it (from the index) is at least this; 255 reads every brick entered.
    #[arg(long, default_value_t = 16)]
    pub cd_lazy_min: u8,
    /// Trace every pixel's ray, also those no brick with 1-cells projects
    /// onto (by default they are drawn as misses without a ray: the same
    /// image; docs/BENCHMARKS.md, "Culling by the brick index").
    #[arg(long)]
    pub no_cull: bool,
    /// Brick cache budget in MiB.
    #[arg(long, default_value_t = 512)]
    pub cache_mb: usize,
    /// Memory the render may plan to use, in MiB (default: 3/4 of RAM):
    /// the cache plus 64 bytes a pixel (docs/RELIABILITY.md, "Memory").
    #[arg(long, value_name = "MIB")]
    pub mem_limit: Option<u64>,
    /// Perspective projection (default orthographic).
    #[arg(long)]
    pub persp: bool,
    /// Perspective field of view in degrees.
    #[arg(long, default_value_t = 40.0)]
    pub fov: f64,
    /// The view: a name in patient terms (anterior, posterior, left, right,
    /// superior, inferior) or AZ,EL, azimuth and elevation in degrees
    /// around the volume centre. Anterior looks at the face, head up, so
    /// the patient's left is on the image's right (the radiological
    /// convention); left looks at the patient's left side; superior and
    /// inferior look along the body axis with the face at the top.
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
    #[arg(long, value_parser = parse_view, allow_hyphen_values = true)]
    pub view: Option<ViewArg>,
    /// Exact camera: eye, target and up in mm (all three needed).
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub eye: Option<[f64; 3]>,
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub target: Option<[f64; 3]>,
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub up: Option<[f64; 3]>,
    /// Orthographic frame height in mm (default: the whole volume).
    #[arg(long)]
    pub frame: Option<f64>,
    /// Write render statistics as JSON.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Render shard K of N: tile i (Morton order) when i % N == K, written
    /// to a part file (-o NAME.cdvpart) for `cdvol assemble`; with
    /// --frames, frame f when f % N == K, written as PNGs.
    #[arg(long, value_parser = cdvol::render::Shard::parse)]
    pub shard: Option<cdvol::render::Shard>,
    /// How --shard deals tiles: every N-th tile (interleaved: shards take
    /// equal time) or contiguous runs of the Morton curve (blocks: shards
    /// read fewer bricks). See docs/BENCHMARKS.md.
    #[arg(long, value_enum, default_value = "interleaved")]
    pub shard_layout: ShardLayoutArg,
    /// A turntable of this many frames around the volume (numbered PNGs
    /// OUT.0000.png ...), starting at --view.
    #[arg(long, default_value_t = 1)]
    pub frames: u32,
    /// Degrees of azimuth the turntable covers.
    #[arg(long, default_value_t = 360.0, allow_hyphen_values = true)]
    pub orbit: f64,
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

impl RenderArgs {
    /// The mode, with the hit method, shadows and transfer function it
    /// takes (the composite mode loads `--tf`).
    pub fn mode(&self) -> anyhow::Result<Mode> {
        let hit = self.hit.into();
        Ok(match self.mode {
            ModeArg::Surface => Mode::Surface {
                hit,
                shadows: self.shadows,
            },
            ModeArg::Mip => Mode::Mip,
            ModeArg::Cost => Mode::Cost,
            ModeArg::Depth => Mode::Depth { hit },
            ModeArg::Composite => {
                let tf = match (&self.tf, self.preset()?) {
                    (Some(tf), _) => TransferFunction::load(tf)?,
                    (None, Some(p)) => p.tf,
                    (None, None) => {
                        anyhow::bail!("--mode composite needs --tf FILE or --preset NAME")
                    }
                };
                Mode::Composite {
                    tf,
                    step_mm: self.step,
                }
            }
        })
    }

    /// The `--preset`, looked up.
    pub fn preset(&self) -> anyhow::Result<Option<cdvol::presets::Preset>> {
        Ok(match &self.preset {
            Some(name) => Some(cdvol::presets::get(name)?),
            None => None,
        })
    }

    /// The scene's iso value: `--iso`, or the preset's in surface, depth
    /// and cost modes.
    pub fn iso(&self) -> anyhow::Result<Option<f64>> {
        let Some(p) = self.preset()? else {
            return Ok(self.iso);
        };
        if !matches!(self.mode, ModeArg::Surface | ModeArg::Depth | ModeArg::Cost) {
            return Ok(None);
        }
        match p.iso {
            Some(v) => Ok(Some(v)),
            None => {
                let with: Vec<&str> = cdvol::presets::all()
                    .iter()
                    .filter(|q| q.iso.is_some())
                    .map(|q| q.name.as_str())
                    .collect();
                anyhow::bail!(
                    "preset {} has no iso value for --mode {}; presets with one: {} \
                     (or render it with --mode composite)",
                    p.name,
                    format!("{:?}", self.mode).to_lowercase(),
                    with.join(", ")
                )
            }
        }
    }

    /// The MIP window of `--window` and `--level`.
    pub fn window(&self) -> anyhow::Result<Window> {
        Ok(match (self.window.as_str(), self.level) {
            ("auto", None) => match self.preset()?.and_then(|p| p.window) {
                Some(w) => Window::Fixed {
                    width: w.width,
                    level: w.level,
                },
                None => Window::Auto,
            },
            ("full", None) => Window::Full,
            ("auto" | "full", Some(_)) => {
                anyhow::bail!(
                    "--level goes with a numeric --window W, not --window {}",
                    self.window
                )
            }
            (w, Some(level)) => Window::Fixed {
                width: w.parse().map_err(|_| {
                    anyhow::anyhow!("--window {w:?}: expected auto, full or a width (a number)")
                })?,
                level,
            },
            (w, None) => {
                anyhow::bail!("--window {w}: a numeric window needs --level L (its centre)")
            }
        })
    }

    /// The composite look: the --tf file's `shade` and
    /// `gradient_opacity` keys, `--shade` on top.
    pub fn look(&self) -> anyhow::Result<CompositeLook> {
        let mut look = match (&self.tf, self.mode) {
            (Some(tf), ModeArg::Composite) => CompositeLook::load(tf)?,
            (None, ModeArg::Composite) => CompositeLook {
                shade: self.preset()?.is_some_and(|p| p.shade),
                ..CompositeLook::default()
            },
            _ => CompositeLook::default(),
        };
        look.shade |= self.shade;
        Ok(look)
    }

    /// The traversal; `template` leaps like `cd` (its renderer is chosen
    /// by [`RenderJob::template`]).
    pub fn method(&self) -> Method {
        let min_leap = self
            .switch_fvt_at
            .map_or(self.min_leap, |d| d.saturating_add(1));
        let dda = |kind| Method::Dda {
            kind,
            switch_fvt: !self.no_switch_fvt,
        };
        match self.traversal {
            TraversalArg::Fvt => Method::Fvt,
            TraversalArg::Cd | TraversalArg::Template => Method::Cd { min_leap },
            TraversalArg::CdAniso => Method::CdAniso { min_leap },
            TraversalArg::Octree => Method::Octree,
            TraversalArg::DdaCityblock => dda(DistKind::Cityblock),
            TraversalArg::DdaChessboard => dda(DistKind::Chessboard),
            TraversalArg::DdaChamfer => dda(DistKind::Chamfer),
        }
    }

    /// The library's render job for these arguments.
    pub fn job(&self) -> anyhow::Result<RenderJob> {
        if self.cache_mb < 1 {
            anyhow::bail!(
                "option --cache-mb: {} MiB, expected at least 1 (with no cache every brick \
                 is decoded again at each visit)",
                self.cache_mb
            );
        }
        let view = match (self.eye, self.target, self.up) {
            (Some(eye), Some(target), Some(up)) => View::LookAt { eye, target, up },
            (None, None, None) => match self.view.unwrap_or(ViewArg::Angles([0.0, 0.0])) {
                ViewArg::Angles([az_deg, el_deg]) => View::Orbit { az_deg, el_deg },
                ViewArg::Named(v) => View::Named(v),
            },
            _ => anyhow::bail!("--eye, --target and --up go together: give all three or none"),
        };
        Ok(RenderJob {
            camera: CameraSpec {
                view,
                persp_fov_deg: self.persp.then_some(self.fov),
                frame_mm: self.frame,
                width: self.width,
                height: self.height,
            },
            options: RenderOptions {
                mode: self.mode()?,
                method: self.method(),
                tile: self.tile,
                cache_bytes: self.cache_mb.saturating_mul(1 << 20),
                cd_lazy_min: self.cd_lazy_min,
                hit_params: HitParams {
                    bisect_iters: self.bisect_iters,
                    newton_iters: self.newton_iters,
                    newton_tol: self.newton_tol,
                },
                precision: self.precision.into(),
                sampling: self.sample_precision.into(),
                early_stop: self.early_stop,
                look: self.look()?,
                window: self.window()?,
                normals: match self.normals {
                    NormalsArg::Smooth => cdvol::render::Normals::Smooth,
                    NormalsArg::Cell => cdvol::render::Normals::Cell,
                },
                iso: self.iso()?,
                unrounded: self.bit_depth != cdvol::render::Bits::Eight,
                cull: !self.no_cull,
            },
            template: self.traversal == TraversalArg::Template,
            output: self.output.clone(),
            stats: self.stats.clone(),
            frames: self.frames,
            orbit_deg: self.orbit,
            shard: self.shard.map(|s| Shard {
                layout: self.shard_layout.into(),
                ..s
            }),
            threads: self.threads,
            image: cdvol::render::ImageSpec {
                background: self.background,
                bits: self.bit_depth,
            },
            mem_limit: self.mem_limit.map(|m| m.saturating_mul(1 << 20)),
            scale_bar: self.scale_bar,
        })
    }
}

/// The `cdvol render` flag of a library field name, for error messages.
fn render_flag(field: &str) -> Option<&'static str> {
    Some(match field {
        "tile" => "--tile",
        "step_mm" => "--step",
        "early_stop" => "--early-stop",
        "window" => "--window",
        "newton_tol" => "--newton-tol",
        "bisect_iters" => "--bisect-iters",
        "newton_iters" => "--newton-iters",
        "width x height" => "--width/--height",
        "shard" => "--shard",
        _ => return None,
    })
}

/// A render job's error as the CLI reports it: with the flag that set
/// the bad value.
pub fn render_error(e: JobError) -> anyhow::Error {
    let flag = match &e {
        JobError::Render(RenderError::Option { field, .. }) => render_flag(field),
        JobError::NoFrames | JobError::TooManyFrames { .. } | JobError::TurntableLookAt { .. } => {
            Some("--frames")
        }
        JobError::TemplateShard => Some("--traversal template"),
        JobError::Memory { .. } => Some("--mem-limit"),
        JobError::Bound { field, .. } => Some(match *field {
            "threads" => "--threads",
            "orbit_deg" => "--orbit",
            _ => *field,
        }),
        JobError::PartName { .. } => Some("--shard"),
        JobError::Camera(c) => Some(match c {
            CameraError::FarPoint { what: "eye", .. } => "--eye",
            CameraError::FarPoint { .. } => "--target",
            CameraError::SamePoint { .. } => "--eye/--target/--view",
            CameraError::UpParallel { .. } => "--up",
            CameraError::EmptyImage { .. } => "--width/--height",
            CameraError::Frame { .. } => "--frame",
            CameraError::Fov { .. } => "--fov",
            CameraError::TooFar { .. } => "--frame/--eye",
            CameraError::NoOrientation { .. } => "--view",
        }),
        _ => None,
    };
    match flag {
        Some(f) => anyhow::Error::new(e).context(format!("option {f}")),
        None => e.into(),
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
