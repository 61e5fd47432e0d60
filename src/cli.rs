//! Command-line arguments (clap derive) and their conversion into the
//! library's checked options. Binary only: the library knows no clap.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

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
    /// Describe a packed file.
    Info(InfoArgs),
    /// Write values, codes or classes of a packed file as raw + sidecar.
    Export(ExportArgs),
    /// Generate test volumes.
    #[command(subcommand)]
    Phantom(PhantomCmd),
    /// Generate the CT-like phantom and a sphere scene, prepare them and
    /// report what was written.
    Demo(DemoArgs),
}

#[derive(Args, Debug)]
pub struct PrepArgs {
    /// Sidecar (JSON) of a raw stack.
    pub input: PathBuf,
    /// Packed output file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Iso value (rescaled units, e.g. HU): a cell is a 1-cell when its
    /// largest vertex value is >= T.
    #[arg(long, value_name = "T", conflicts_with = "classify_tf")]
    pub iso: Option<f64>,
    /// Transfer function (JSON): a cell is a 1-cell when its opacity is
    /// non-zero anywhere between the min and max of its vertex values.
    #[arg(long, value_name = "FILE")]
    pub classify_tf: Option<PathBuf>,
    /// Cells per brick edge (multiple of 4).
    #[arg(long, default_value_t = 32)]
    pub brick: usize,
    /// zstd compression level of brick payloads.
    #[arg(long, default_value_t = 3, allow_negative_numbers = true)]
    pub zstd_level: i32,
    /// Also compute anisotropic (octant) codes, paper section 4.2.1.
    #[arg(long)]
    pub aniso: bool,
    /// Directory for the temporary spill (default: beside the output).
    #[arg(long)]
    pub temp_dir: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum What {
    Values,
    Codes,
    Classes,
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

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum CtType {
    I16,
    U16,
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
