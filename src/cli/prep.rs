//! `cdvol prep` and `cdvol prep-batch`: their arguments, the checked
//! prep options, and prep and input errors with their flags.

use std::path::PathBuf;

use clap::Args;

use super::heading;

#[derive(Args, Debug)]
pub struct PrepArgs {
    /// The volume: a directory holding a DICOM series or one TIFF per
    /// slice, a multi-page TIFF, a raw-stack sidecar (.json), NRRD (.nrrd,
    /// .nhdr) or NIfTI-1 (.nii, .nii.gz).
    #[arg(help_heading = heading::INPUT, display_order = 0)]
    pub input: PathBuf,
    /// The DICOM series to prepare when the directory holds several
    /// (SeriesInstanceUID).
    // After <INPUT> (0), which is first under its heading.
    #[arg(long, value_name = "UID", help_heading = heading::INPUT, display_order = 1)]
    pub series: Option<String>,
    #[command(flatten)]
    pub settings: PrepSettings,
    /// Packed output file.
    // After the settings, so that the headings come in their order (the
    // first argument under a heading places it); first among its own.
    #[arg(short, long, help_heading = heading::OUTPUT, display_order = 0)]
    pub output: PathBuf,
    /// Prepare shard K of N (brick layers) into --parts, for prep-merge.
    ///
    /// With --pass 1 (every shard), then --pass 2 (every shard, once
    /// every scan is written), then `cdvol prep-merge`: the file is the
    /// one a single prep writes, byte for byte (docs/SCALE.md;
    /// tools/slurm/prep-array.sbatch runs them as Slurm arrays).
    #[arg(long, value_name = "K/N", value_parser = cdvol::render::Shard::parse,
          requires = "pass", help_heading = heading::PERFORMANCE)]
    pub shard: Option<cdvol::render::Shard>,
    /// With --shard: 1 (classify, forward transform, seam planes) or 2
    /// (backward transform and bricks, after every shard's pass 1).
    #[arg(long, value_name = "1|2", value_parser = clap::value_parser!(u8).range(1..=2),
          requires = "shard", help_heading = heading::PERFORMANCE)]
    pub pass: Option<u8>,
    /// With --shard: the directory of the shards' files (default:
    /// OUTPUT.parts beside the output).
    #[arg(long, value_name = "DIR", requires = "shard", help_heading = heading::PERFORMANCE)]
    pub parts: Option<PathBuf>,
}

/// `cdvol prep-merge`.
#[derive(Args, Debug)]
pub struct PrepMergeArgs {
    /// The parts directory of `prep --shard K/N --pass 2` (every shard's
    /// part), or the part files.
    #[arg(required = true, help_heading = heading::INPUT)]
    pub parts: Vec<PathBuf>,
    /// Packed output file.
    #[arg(short, long, help_heading = heading::OUTPUT)]
    pub output: PathBuf,
}

/// How prep classifies and packs (shared by prep and prep-batch). The
/// fields are in the order of their `--help` headings.
#[derive(Args, Debug)]
pub struct PrepSettings {
    /// Iso value (e.g. HU): a 1-cell has a vertex value >= T.
    ///
    /// Rescaled units, e.g. HU: a cell is a 1-cell when its largest vertex
    /// value is >= T.
    #[arg(
        long,
        value_name = "T",
        conflicts_with_all = ["classify_tf", "preset", "envelope"],
        allow_negative_numbers = true,
        help_heading = heading::CLASSIFY
    )]
    pub iso: Option<f64>,
    /// One file for a whole exploration: ct, mr, auto, presets or iso
    /// values.
    ///
    /// The iso classification that holds every item, so `render
    /// --iso`/`--tf`/`--preset` cover them all without another prep.
    /// Items: iso values, presets, or a modality (`ct`, `mr`: all its
    /// presets), comma-separated; e.g. `--envelope ct` or `--envelope
    /// ct-bone,ct-muscle,500`. `auto`: the envelope of the input's
    /// modality, CT or MR (as the input says, --modality, or guessed from
    /// its values), MR presets placed on the input's values — per input in
    /// prep-batch.
    #[arg(
        long,
        value_name = "ITEMS",
        value_delimiter = ',',
        conflicts_with_all = ["classify_tf", "preset"],
        allow_negative_numbers = true,
        help_heading = heading::CLASSIFY
    )]
    pub envelope: Vec<String>,
    /// Transfer function (JSON): a 1-cell is one it makes visible.
    ///
    /// A cell is a 1-cell when its opacity is non-zero anywhere between
    /// the min and max of its vertex values.
    #[arg(long, value_name = "FILE", conflicts_with = "preset",
          help_heading = heading::CLASSIFY)]
    pub classify_tf: Option<PathBuf>,
    /// A named preset's transfer function (`cdvol presets` lists them).
    ///
    /// As --classify-tf with that function, placed on the input's values
    /// when it is an MR preset; the file's default look in render and
    /// serve. A preset of another modality than the input's is refused.
    #[arg(long, value_name = "NAME", help_heading = heading::CLASSIFY)]
    pub preset: Option<String>,
    /// Take a preset of another modality than the input's.
    #[arg(long, help_heading = heading::CLASSIFY)]
    pub force: bool,
    /// The input is a label map (a segmentation): integers, 0 = none.
    ///
    /// Writes a label file for `render --labels`: classified by the union
    /// of its labels, every label kept exactly, the labels and their
    /// sample counts recorded (`cdvol info`). The input must have an
    /// integer type, values 0..=65535 and no rescale.
    #[arg(
        long,
        conflicts_with_all = ["iso", "classify_tf", "preset", "envelope"],
        help_heading = heading::CLASSIFY
    )]
    pub labels: bool,
    /// With --labels: the colour table to record (ITK-SNAP label
    /// description, FreeSurfer *LUT.txt or JSON).
    #[arg(long, value_name = "FILE", requires = "labels", help_heading = heading::CLASSIFY)]
    pub lut: Option<PathBuf>,
    /// The input's modality, when it does not say and the guess is wrong.
    ///
    /// For NIfTI, NRRD and raw inputs, whose modality is guessed from their
    /// values (below -500: CT).
    #[arg(long, value_enum, help_heading = heading::INPUT)]
    pub modality: Option<ModalityArg>,
    /// Keep every sample next to a 1-cell: true smooth normals.
    ///
    /// Embed only codes >= 2, so every sample within one cell of a 1-cell
    /// keeps its value: smooth normals read true central differences
    /// everywhere (docs/TRADEOFFS.md, "Normals").
    #[arg(long, help_heading = heading::OUTPUT)]
    pub gradient_halo: bool,
    /// Write the file even when the classification selects no cell.
    ///
    /// It renders empty; without this flag such a prep fails before
    /// writing.
    #[arg(long, help_heading = heading::OUTPUT)]
    pub allow_empty: bool,
    /// Also compute anisotropic (octant) codes: renders 10-15 % faster.
    ///
    /// Paper section 4.2.1; `render` then uses them by default (traversal
    /// cd-aniso): the same images, surface and MIP frames 10-15 % faster,
    /// the file 5-24 % larger and the prep slower (docs/TRADEOFFS.md,
    /// "Octant codes").
    #[arg(long, help_heading = heading::PERFORMANCE)]
    pub aniso: bool,
    /// Directory for the temporary spill (default: beside the output).
    #[arg(long, help_heading = heading::PERFORMANCE)]
    pub temp_dir: Option<PathBuf>,
    /// Memory prep may plan to use, in MiB (default: 3/4 of RAM).
    ///
    /// A prep whose planned peak (docs/RELIABILITY.md, "Memory") is above
    /// it is refused before it allocates.
    #[arg(long, value_name = "MIB", help_heading = heading::PERFORMANCE)]
    pub mem_limit: Option<u64>,
    /// Cells per brick edge (multiple of 4).
    #[arg(long, default_value_t = 32, help_heading = heading::TUNING, hide_short_help = true)]
    pub brick: usize,
    /// zstd compression level of brick payloads.
    #[arg(long, default_value_t = 3, allow_negative_numbers = true,
          help_heading = heading::TUNING, hide_short_help = true)]
    pub zstd_level: i32,
    /// Format version to write: 3 (the default) stores sample words as
    /// byte planes, smaller and faster to decode; 2 is the layout cdvol
    /// builds before byte planes read (docs/FORMAT.md).
    #[arg(long, value_name = "N", default_value_t = cdvol::format::FORMAT_VERSION,
          help_heading = heading::TUNING, hide_short_help = true)]
    pub format_version: u32,
    /// Also store extra city-block and chamfer distance planes for the DDA
    /// traversals (paper section 3), 2 bytes per cell.
    #[arg(long, help_heading = heading::TUNING, hide_short_help = true)]
    pub dda: bool,
}

impl PrepSettings {
    /// The checked prep options; errors name the flags.
    pub fn to_options(&self) -> anyhow::Result<cdvol::prep::PrepOptions> {
        use cdvol::classify::{Classification, TransferFunction};
        let auto = self.envelope.len() == 1 && self.envelope[0].eq_ignore_ascii_case("auto");
        if !self.envelope.is_empty() && !auto {
            // Checked now, placed on the input's values by prep.
            cdvol::presets::envelope(&self.envelope, cdvol::presets::all())
                .map_err(|e| anyhow::anyhow!("option --envelope: {e}"))?;
        }
        if let Some(name) = &self.preset {
            cdvol::presets::get(name).map_err(|e| anyhow::anyhow!("option --preset: {e}"))?;
        }
        let classification = match (self.iso, &self.classify_tf) {
            _ if self.labels => Classification::Iso { iso: 0.5 },
            _ if !self.envelope.is_empty() || self.preset.is_some() => {
                // Replaced by prep once it has seen the input.
                Classification::Iso { iso: 0.0 }
            }
            (Some(iso), None) => {
                if !iso.is_finite() {
                    anyhow::bail!("option --iso: {iso}, expected a finite number");
                }
                Classification::Iso { iso }
            }
            (None, Some(tf)) => Classification::TransferFunction {
                tf: TransferFunction::load(tf)?,
            },
            (None, None) => anyhow::bail!(
                "prep needs --iso T, --classify-tf FILE, --preset NAME, --envelope ITEMS or \
                 --labels to decide which cells are objects"
            ),
            _ => anyhow::bail!(
                "--iso, --classify-tf and --preset each choose the classification: give one"
            ),
        };
        let mut opts = self.with(classification)?;
        opts.envelope = self.envelope.clone();
        opts.preset = self.preset.clone();
        opts.modality = self.modality.map(Into::into);
        opts.force = self.force;
        opts.labels = self.labels;
        opts.label_table = match &self.lut {
            Some(p) => Some(cdvol::labels::LabelTable::load(p)?),
            None => None,
        };
        Ok(opts)
    }

    /// The checked prep options with `classification`.
    fn with(
        &self,
        classification: cdvol::classify::Classification,
    ) -> anyhow::Result<cdvol::prep::PrepOptions> {
        let opts = cdvol::prep::PrepOptions {
            brick_size: self.brick,
            zstd_level: self.zstd_level,
            aniso: self.aniso,
            dda: self.dda,
            gradient_halo: self.gradient_halo,
            temp_dir: self.temp_dir.clone(),
            mem_limit: self.mem_limit.map(crate::cli::mem_limit),
            format_version: self.format_version,
            allow_empty: self.allow_empty,
            ..cdvol::prep::PrepOptions::new(classification)
        };
        opts.check().map_err(prep_error)?;
        Ok(opts)
    }
}

/// `--modality`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModalityArg {
    Ct,
    Mr,
}

impl From<ModalityArg> for cdvol::presets::Modality {
    fn from(m: ModalityArg) -> Self {
        match m {
            ModalityArg::Ct => cdvol::presets::Modality::Ct,
            ModalityArg::Mr => cdvol::presets::Modality::Mr,
        }
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
            "shard" => "--shard",
            "aniso" => "--aniso",
            "dda" => "--dda",
            other => other,
        };
        return anyhow::anyhow!("option {flag}: {e}");
    }
    match e {
        PrepError::Input(i) => input_error(i),
        e => e.into(),
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
    #[arg(help_heading = heading::INPUT, display_order = 0)]
    pub input: PathBuf,
    // The settings first, so that the headings come in their order (the
    // first argument under a heading places it).
    #[command(flatten)]
    pub settings: PrepSettings,
    /// Directory for the packed files and the summary (batch.json).
    #[arg(short, long, help_heading = heading::OUTPUT, display_order = 0)]
    pub output: PathBuf,
    /// Remove the orphans: outputs the previous summary listed whose input
    /// is gone.
    ///
    /// They are reported either way; nothing else is removed.
    #[arg(long, help_heading = heading::OUTPUT)]
    pub prune: bool,
    /// Inputs prepared at once (memory grows with it: one prep each).
    #[arg(long, default_value_t = 1, help_heading = heading::PERFORMANCE)]
    pub jobs: usize,
    /// Process input i (sorted by path) when i % N == K.
    #[arg(long, value_parser = cdvol::render::Shard::parse,
          help_heading = heading::PERFORMANCE)]
    pub shard: Option<cdvol::render::Shard>,
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
