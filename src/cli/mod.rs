//! Command-line arguments (clap derive) and their conversion into the
//! library's checked options. Binary only: the library knows no clap.
//!
//! Split by command group: [`render`] (render and assemble), [`prep`]
//! (prep and prep-batch) and [`tools`] (the other commands).

use clap::{Arg, ArgAction, CommandFactory, FromArgMatches, Parser, Subcommand};

mod prep;
mod render;
mod render_job;
mod tools;

pub use prep::{input_error, prep_error, PrepArgs, PrepBatchArgs, PrepMergeArgs};
pub use render::{AssembleArgs, ExperimentRenderArgs, RenderArgs};
pub use render_job::render_error;
pub use tools::{
    phantom_error, DemoArgs, ExperimentCmd, ExportArgs, HistogramArgs, InfoArgs, PhantomCmd,
    PresetsArgs, SegmentArgs, ServeArgs,
};

/// The headings of `--help`, in the order the commands list them: the
/// everyday groups first, the tuning and paper-experiment switches last
/// (and left out of `-h`: their args set `hide_short_help`).
pub mod heading {
    pub const INPUT: &str = "Input";
    pub const VIEW: &str = "View";
    pub const LOOK: &str = "Mode and look";
    /// prep: which cells are objects.
    pub const CLASSIFY: &str = "Classification";
    pub const OUTPUT: &str = "Output";
    pub const PERFORMANCE: &str = "Performance";
    pub const TUNING: &str = "Tuning and paper experiments";
}

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
    /// Join the parts of a sharded prep (`prep --shard K/N`) into the
    /// packed file one prep would have written.
    PrepMerge(PrepMergeArgs),
    /// Prepare every volume under a directory (DICOM series, NRRD, NIfTI,
    /// raw sidecars) into OUT_DIR, resuming where a previous run stopped.
    PrepBatch(PrepBatchArgs),
    /// Describe a packed file, or an input before prep.
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
    /// A label map of a CT by thresholds (soft tissue, bone, air spaces)
    /// with its colour table, for `prep --labels`.
    Segment(SegmentArgs),
    /// Ray-cast a packed file into a PNG.
    Render(Box<RenderArgs>),
    /// Generate the CT-like phantom and a sphere scene, prepare and render
    /// them, and report what was written.
    Demo(DemoArgs),
    /// Join the part files of a sharded render (`render --shard K/N`) into
    /// the image one process would have written.
    Assemble(AssembleArgs),
    /// Reproducible measurements, written as reports under docs/, and
    /// renders with the switches only measurements want.
    #[command(subcommand)]
    Experiment(ExperimentCmd),
    /// Serve a browser viewer of packed files: orbit, zoom, presets, live
    /// renders through one shared brick cache (docs/SERVE.md).
    Serve(ServeArgs),
}

/// `--mem-limit MIB` in bytes, lowered to the machine's RAM with a
/// warning on stderr when above it (cdvol::memory::limit_from_mib).
pub fn mem_limit(mib: u64) -> u64 {
    let (bytes, warning) = cdvol::memory::limit_from_mib(mib);
    if let Some(w) = warning {
        eprintln!("cdvol: warning: {w}");
    }
    bytes
}

/// The command line as clap builds it from [`Cli`], with negative numbers
/// taken as values by every option of every command: `--iso -700` as
/// `--iso=-700` (Hounsfield units are mostly negative). Options whose
/// values are lists (`--view -30,20`) allow hyphen values themselves.
///
/// A command with options left out of `-h` (`hide_short_help`: the
/// tuning and paper-experiment switches) also takes `--help-all`, the
/// same as `--help`, and `-h` ends by saying where the others are.
pub fn command() -> clap::Command {
    fn finish(c: clap::Command) -> clap::Command {
        let c = c.allow_negative_numbers(true).mut_subcommands(finish);
        if c.get_arguments().any(Arg::is_hide_short_help_set) {
            help_all(c)
        } else {
            c
        }
    }
    finish(Cli::command())
}

/// `--help-all` and the closing lines of `-h` and `--help` for a command
/// whose tuning options `-h` leaves out.
fn help_all(c: clap::Command) -> clap::Command {
    c.arg(
        Arg::new("help_all")
            .long("help-all")
            .action(ArgAction::HelpLong)
            .help("Print help with every option, tuning too (the same as --help)"),
    )
    .after_help(format!(
        "The \"{}\" options are left out here: see them with --help or --help-all.",
        heading::TUNING
    ))
    .after_long_help(format!(
        "The \"{}\" options choose among equivalent algorithms, trade accuracy for speed, or \
         reproduce the paper's measurements (docs/TRADEOFFS.md, docs/EXPERIMENTS.md); their \
         defaults suit every other use.",
        heading::TUNING
    ))
}

/// Parses the process's arguments with [`command`]; on an error or
/// `--help`, prints and exits as clap does.
pub fn parse() -> Cli {
    let matches = command().get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}
