//! The other commands: serve, experiment, info, histogram, presets,
//! export, phantom and demo.

use std::path::PathBuf;

use clap::{Args, Subcommand, ValueEnum};

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
    /// `cdvol render` with the switches that draw wrong images on purpose,
    /// for measurements: --no-switch-fvt (paper Fig. 18a).
    Render(Box<super::ExperimentRenderArgs>),
}

impl ExperimentCmd {
    /// The `--ct` scan the experiment reads, if given.
    pub fn ct(&self) -> Option<&std::path::Path> {
        match self {
            ExperimentCmd::Fig16(a)
            | ExperimentCmd::Fig17(a)
            | ExperimentCmd::Fig18(a)
            | ExperimentCmd::Fig20(a)
            | ExperimentCmd::Fig22(a)
            | ExperimentCmd::Table1(a)
            | ExperimentCmd::Table2(a)
            | ExperimentCmd::All(a) => a.ct.as_deref(),
            ExperimentCmd::Tradeoffs(a) => a.ct.as_deref(),
            ExperimentCmd::Render(_) => None,
        }
    }

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
            ExperimentCmd::Render(_) => anyhow::bail!("render is not a paper experiment"),
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

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A packed file, or an input before prep (a DICOM directory, NRRD,
    /// NIfTI or raw-stack sidecar: its grid, sample type, orientation and
    /// value range).
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

#[derive(Args, Debug)]
pub struct SegmentArgs {
    /// A CT (any input prep reads), in HU after its rescale.
    pub input: PathBuf,
    /// Output sidecar of the u8 label map; STEM.raw and the colour table
    /// STEM.lut.json go beside it.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Subcommand, Debug)]
pub enum PhantomCmd {
    /// The paper's section 5.1 scenes: N^3 random spheres of equal total volume.
    Spheres(SpheresArgs),
    /// A CT-like head with slices thin in the middle and 4x thicker on top.
    Ct(CtArgs),
    /// A T1-weighted-like MR head: arbitrary intensity scale, bias field,
    /// Rician noise (the air is a Rayleigh floor), optionally skull-stripped.
    Mr(MrArgs),
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
    #[arg(long, default_value = "1", allow_hyphen_values = true)]
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
    #[arg(long, default_value = "256,256,160", value_parser = parse_dims,
          allow_hyphen_values = true)]
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

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum MrType {
    U16,
    I16,
    F32,
}

impl From<MrType> for cdvol::tools::phantom::MrDtype {
    fn from(t: MrType) -> Self {
        match t {
            MrType::U16 => cdvol::tools::phantom::MrDtype::U16,
            MrType::I16 => cdvol::tools::phantom::MrDtype::I16,
            MrType::F32 => cdvol::tools::phantom::MrDtype::F32,
        }
    }
}

impl From<&MrArgs> for cdvol::tools::phantom::MrOptions {
    fn from(a: &MrArgs) -> Self {
        cdvol::tools::phantom::MrOptions {
            dims: a.dims,
            dtype: a.dtype.into(),
            scale: a.scale,
            noise: a.noise,
            bias: a.bias,
            skull_stripped: a.skull_stripped,
            seed: a.seed,
        }
    }
}

#[derive(Args, Debug)]
pub struct MrArgs {
    /// Output sidecar (raw data goes beside it).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples per axis, NX,NY,NZ, over a 192 mm cube (1.5 x 1.5 x 2 mm
    /// at the default).
    #[arg(long, default_value = "128,128,96", value_parser = parse_dims,
          allow_hyphen_values = true)]
    pub dims: [usize; 3],
    /// The white matter intensity; other tissues are fractions of it (fat
    /// 1.2, grey matter 0.68, CSF 0.25, bone 0.07).
    #[arg(long, default_value_t = 713.0)]
    pub scale: f64,
    /// Noise sigma per complex component, as a fraction of the scale.
    #[arg(long, default_value_t = 0.03)]
    pub noise: f64,
    /// Amplitude of the multiplicative bias field (0.12: +-12 %).
    #[arg(long, default_value_t = 0.12)]
    pub bias: f64,
    /// Brain only: every sample outside the brain is exactly 0.
    #[arg(long)]
    pub skull_stripped: bool,
    /// Sample type.
    #[arg(long, value_enum, default_value = "u16")]
    pub dtype: MrType,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
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
