//! `cdvol prep`: streams a [`SliceSource`] into a packed file.
//!
//! Pass 1 runs forward over z: read a sample slice, reduce it to per-cell
//! extrema, classify the cell slice between it and the previous one, and
//! feed the forward distance transform, which spills one byte per cell to
//! a temporary file. Pass 2 runs backward over z in slabs of one brick
//! depth: finish the distance transform, re-read the slab's samples,
//! embed the codes, cut the slab into bricks, compress them in parallel and
//! append them. Memory is bounded by one slab (docs/BENCHMARKS.md, "Prep:
//! whole program, and the regression check", has the formula); nothing
//! grows with nz. The passes themselves are in `passes.rs`; a sharded prep
//! ([`shard`]) runs them over one shard's slices per process and merges
//! the parts into the same file.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::classify::Classification;
use crate::dt::{self, FileSpill, ForwardDt, ANISO_BLOCK};
use crate::format::word::choose_encoding;
use crate::format::writer::PackedWriter;
use crate::format::{FormatError, Header, Summary, FORMAT_VERSION, OLDEST_WRITE_VERSION};
use crate::input::{InputError, SliceSource};
use crate::progress::Progress;

mod decide;
mod part;
mod passes;
pub mod shard;
mod slab;

pub use decide::{guess_modality, modality, sampled_landmarks, Decided, LANDMARK_SLICES};

use slab::BrickOut;

/// Options of `cdvol prep`.
#[derive(Debug, Clone)]
pub struct PrepOptions {
    pub classification: Classification,
    /// Cells per brick edge (multiple of 4, 4..=1024).
    pub brick_size: usize,
    pub zstd_level: i32,
    /// Also compute the anisotropic octant codes (section 4.2.1).
    pub aniso: bool,
    /// Also compute the city-block and chamfer 3-4-5 distance planes of
    /// the DDA traversals (paper section 3): 2 bytes per cell.
    pub dda: bool,
    /// Embed only codes >= 2 (a gradient halo): every sample within one
    /// cell of a 1-cell keeps its value, so central differences at a
    /// 1-cell's vertices never read a code (docs/DESIGN.md, "Embedding").
    /// Code-1 cells then read back as code 0 (conservative).
    pub gradient_halo: bool,
    /// Where the one-byte-per-cell spill goes (default: beside the output).
    pub temp_dir: Option<PathBuf>,
    /// The input's identity, recorded in the header (`prep-batch`).
    pub stamp: Option<crate::identity::InputStamp>,
    /// Bytes prep may plan to use ([`prep_memory`]); None: the default,
    /// [`crate::memory::default_limit`] (3/4 of RAM).
    pub mem_limit: Option<u64>,
    /// `--envelope ITEMS`: classify by the iso value that holds every item
    /// (iso values, presets, `ct`, `mr`; [`crate::presets::envelope`]), or
    /// with `auto` alone, every preset of the input's modality; replaces
    /// `classification` ([`PrepOptions::resolved`]).
    pub envelope: Vec<String>,
    /// `--preset NAME`: classify by the preset's transfer function, placed
    /// on the input's values when it is an MR preset, and record it as
    /// the file's default look; replaces `classification`.
    pub preset: Option<String>,
    /// `--modality`: the input's modality, over what it says or a guess.
    pub modality: Option<crate::presets::Modality>,
    /// `--force`: take a preset of another modality than the input's.
    pub force: bool,
    /// What [`PrepOptions::resolved`] decided for the input (`None` until
    /// then; prep resolves options that are not).
    pub decided: Option<Decided>,
    /// Format version to write ([`OLDEST_WRITE_VERSION`] to
    /// [`FORMAT_VERSION`], the default): version 2 is read by cdvol
    /// builds before byte planes (`prep --format-version 2`).
    pub format_version: u32,
    /// Write a file whose classification selects no cell (it renders
    /// empty) instead of refusing it with [`PrepError::Empty`]. The
    /// library's default is true; `cdvol prep` and `prep-batch` refuse
    /// unless `--allow-empty` is given.
    pub allow_empty: bool,
    /// `--labels`: the input is a label map ([`crate::labels`]): integer
    /// samples 0..=65535 without rescale, classified by the union of its
    /// labels (any vertex not 0); replaces `classification`. The header
    /// records the labels and `label_table`.
    pub labels: bool,
    /// The colour table recorded in a label file (`prep --lut`).
    pub label_table: Option<crate::labels::LabelTable>,
}

impl PrepOptions {
    pub fn new(classification: Classification) -> PrepOptions {
        PrepOptions {
            classification,
            brick_size: 32,
            zstd_level: 3,
            aniso: false,
            dda: false,
            gradient_halo: false,
            temp_dir: None,
            stamp: None,
            mem_limit: None,
            envelope: Vec::new(),
            preset: None,
            modality: None,
            force: false,
            decided: None,
            format_version: FORMAT_VERSION,
            allow_empty: true,
            labels: false,
            label_table: None,
        }
    }

    /// Checks the ranges [`prep`] needs before it reads anything:
    /// `brick_size` a multiple of 4 in 4..=1024, `zstd_level` in -7..=22,
    /// `format_version` one prep writes.
    pub fn check(&self) -> Result<(), PrepError> {
        let b = self.brick_size;
        if !(4..=1024).contains(&b) || !b.is_multiple_of(ANISO_BLOCK) {
            return Err(PrepError::Option {
                field: "brick_size",
                value: b.to_string(),
                msg: format!("expected a multiple of {ANISO_BLOCK} in 4..=1024"),
            });
        }
        if !(-7..=22).contains(&self.zstd_level) {
            return Err(PrepError::Option {
                field: "zstd_level",
                value: self.zstd_level.to_string(),
                msg: "expected -7..=22".into(),
            });
        }
        if !(OLDEST_WRITE_VERSION..=FORMAT_VERSION).contains(&self.format_version) {
            return Err(PrepError::Option {
                field: "format_version",
                value: self.format_version.to_string(),
                msg: format!("expected {OLDEST_WRITE_VERSION} to {FORMAT_VERSION}"),
            });
        }
        Ok(())
    }
}

impl PrepOptions {
    /// The options of a label map ([`PrepOptions::labels`]): classified
    /// by the union of its labels, after checking that the input can be
    /// one (an integer type, no rescale) and that no other classification
    /// was asked for.
    fn for_labels(&self, meta: &crate::input::VolumeMeta) -> Result<PrepOptions, PrepError> {
        let bad = |field: &'static str, msg: String| {
            PrepError::Labels(crate::labels::LabelError::Volume {
                source_desc: meta.origin_desc.clone(),
                field,
                msg,
            })
        };
        if meta.dtype.is_float() {
            return Err(bad(
                "dtype",
                format!(
                    "{}, expected an integer type (u8, u16, i16, ...): a label map holds a whole \
                     number per sample",
                    meta.dtype.name()
                ),
            ));
        }
        let r = meta.rescale;
        if r.slope != 1.0 || r.intercept != 0.0 {
            return Err(bad(
                "rescale",
                format!(
                    "slope {} intercept {}, expected none (slope 1, intercept 0): labels are \
                     numbers, not measurements",
                    r.slope, r.intercept
                ),
            ));
        }
        if self.preset.is_some() || !self.envelope.is_empty() {
            return Err(PrepError::Option {
                field: "labels",
                value: "on".into(),
                msg: "a label map is classified by its labels: no --preset or --envelope".into(),
            });
        }
        let mut o = self.clone();
        o.classification = Classification::Iso { iso: 0.5 };
        o.decided = None;
        Ok(o)
    }
}

/// What prep did.
#[derive(Debug, Clone)]
pub struct PrepReport {
    pub header: Header,
    pub seconds: f64,
    pub file_bytes: u64,
    /// Bytes of temporary disk used for the spill.
    pub temp_bytes: u64,
    /// Wall seconds per stage.
    pub stages: StageTimes,
    /// The classification selected no cells or nearly all of them.
    pub selection: Option<SelectionWarning>,
}

/// Share of 1-cells above which [`selection_warning`] says a
/// classification selects nearly all cells.
pub const NEARLY_ALL_CELLS: f64 = 0.95;

/// A classification that selects no cells (the file renders empty) or
/// nearly all of them (the distance codes cannot leap): what selected
/// them and the data range they were chosen from.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SelectionWarning {
    pub one_cells: u64,
    pub cells: u64,
    /// The figure that selected them: `iso 5000`, or the transfer
    /// function's non-zero opacity range.
    pub classification: String,
    /// The data's smallest and largest value, rescaled (NaN left out);
    /// `None` when every sample is NaN.
    pub range: Option<[f64; 2]>,
}

impl std::fmt::Display for SelectionWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let range = match self.range {
            Some([a, b]) => format!("the data range is {a} .. {b}"),
            None => "every sample is NaN".into(),
        };
        if self.one_cells == 0 {
            write!(
                f,
                "{} selects no cells ({range}): every cell is a 0-cell and renders empty",
                self.classification
            )
        } else {
            write!(
                f,
                "{} selects {:.1} % of the cells ({} of {}; {range}): \
                 nearly every cell is a 1-cell, so rays cannot leap",
                self.classification,
                100.0 * self.one_cells as f64 / self.cells.max(1) as f64,
                self.one_cells,
                self.cells
            )
        }
    }
}

/// What a classification is, in words for messages: `iso 300`, or the
/// value range where a transfer function's opacity is not zero.
pub fn describe_classification(c: &Classification) -> String {
    match c {
        Classification::Iso { iso } => format!("iso {iso}"),
        Classification::TransferFunction { tf } => match tf.support() {
            None => "the transfer function (zero opacity everywhere)".into(),
            Some((a, b)) => {
                let end = |v: f64| {
                    if v.is_finite() {
                        v.to_string()
                    } else if v < 0.0 {
                        "-inf".into()
                    } else {
                        "inf".into()
                    }
                };
                format!(
                    "the transfer function (opacity > 0 on {} .. {})",
                    end(a),
                    end(b)
                )
            }
        },
    }
}

/// A warning when the file's classification selected no cells or more
/// than [`NEARLY_ALL_CELLS`] of them; `None` otherwise.
pub fn selection_warning(h: &Header) -> Option<SelectionWarning> {
    let s = &h.summary;
    let frac = s.one_cells as f64 / s.cells.max(1) as f64;
    if s.one_cells > 0 && frac <= NEARLY_ALL_CELLS {
        return None;
    }
    Some(SelectionWarning {
        one_cells: s.one_cells,
        cells: s.cells,
        classification: describe_classification(&h.classification),
        range: h.value_range().map(|(a, b)| [a, b]),
    })
}

/// Wall seconds spent in each stage of prep.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct StageTimes {
    /// Pass 1: reading and decoding sample slices.
    pub read1: f64,
    /// Pass 1: extrema, classification and the forward transform.
    pub classify_forward: f64,
    /// Pass 1: the value histogram.
    pub histogram: f64,
    /// Pass 2: the backward transform and the code histogram.
    pub backward: f64,
    /// Pass 2: re-reading samples, embedding codes.
    pub embed: f64,
    /// Pass 2: cutting and compressing bricks.
    pub compress: f64,
    /// Pass 2: appending payloads to the file, trailer, sync, rename.
    pub write: f64,
}

/// Errors of `cdvol prep`.
#[derive(Debug, thiserror::Error)]
pub enum PrepError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The output cannot be written, or is one of the input's files.
    #[error(transparent)]
    Output(#[from] crate::fsutil::OutputError),
    #[error("{}: {what}: {source}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        source: std::io::Error,
    },
    /// The planned memory ([`prep_memory`]) is above the limit.
    #[error(
        "{source_desc}: prep needs about {} ({per_sample} bytes per slice sample x {nx} x {ny} \
         samples, plus {} fixed), above the memory limit of {limit}",
        crate::memory::human(*needed),
        crate::memory::human(PREP_FIXED_BYTES)
    )]
    Memory {
        source_desc: String,
        needed: u64,
        per_sample: u64,
        nx: u64,
        ny: u64,
        limit: String,
    },
    /// The classification selects no cell: the file would render empty.
    /// Refused after the first pass, before anything is written, unless
    /// [`PrepOptions::allow_empty`].
    #[error(
        "{source_desc}: {warning}; nothing written. Choose a classification inside the data \
         range (`cdvol info` or `cdvol histogram` of a packed file shows it), or pass \
         --allow-empty to write the empty file"
    )]
    Empty {
        source_desc: String,
        warning: SelectionWarning,
    },
    /// A label map that is not one (`--labels`).
    #[error(transparent)]
    Labels(#[from] crate::labels::LabelError),
    /// A file of a sharded prep ([`shard`]) that does not fit the others
    /// or the input: the file and what is wrong.
    #[error("{}: {msg}", path.display())]
    Shard { path: PathBuf, msg: String },
    /// A [`PrepOptions`] field is out of range: the field, its value, and
    /// what was expected.
    #[error("{field} {value}: {msg}")]
    Option {
        field: &'static str,
        value: String,
        msg: String,
    },
}

/// Bytes of prep's fixed overhead in [`prep_memory`] (threads, zstd
/// contexts, the binary).
pub const PREP_FIXED_BYTES: u64 = 64 << 20;

/// Prep's planned peak memory, an upper bound of what it allocates:
/// `(per_sample, total)` with `total = per_sample * nx * ny + index +`
/// [`PREP_FIXED_BYTES`]. Per slice sample (`nx * ny`), with `w` the
/// stored word's bytes (the input type's, or the next wider integer's)
/// and `s = min(brick, nz - 1) + 1` the sample slices of a slab:
///
/// * pass 1: the slice as f64 (8), the cell flags of two slices (2; 32
///   for a transfer function's extrema), the object plane (1), the
///   forward transform's planes (2; 3 more with `--dda`);
/// * pass 2, after pass 1's buffers are freed: the backward transform's
///   planes (2; 3 more with `--dda`), a slab's distances (`s`), its words
///   (`s * w'`, with `w'` the wider type's bytes in case prep must
///   widen), its bricks compressed (`s * w`: compression to at most the
///   input's size), one slice as f64 (8), and with `--dda` two planes per
///   slab cell slice (`2 * brick`);
///
/// and `per_sample` is the larger of the two.
///
/// The index adds 32 bytes a brick. docs/RELIABILITY.md ("Memory")
/// compares this with measured peaks.
pub fn prep_memory(meta: &crate::input::VolumeMeta, opts: &PrepOptions) -> (u64, u64) {
    let [nx, ny, nz] = meta.dims().map(|d| d as u64);
    let b = opts.brick_size as u64;
    let w = meta.dtype.size() as u64;
    let w_wide = meta.dtype.size().max(meta.dtype.widened().size()) as u64;
    let s = b.min(nz.saturating_sub(1)) + 1;
    // A preset classifies by its transfer function once resolved.
    let tf = matches!(opts.classification, Classification::TransferFunction { .. })
        || opts.preset.is_some();
    let dda = |x: u64| if opts.dda { x } else { 0 };
    let pass1 = 8 + if tf { 32 } else { 2 } + 1 + 2 + dda(3);
    let pass2 = 2 + dda(3 + 2 * b) + s + s * w_wide + s * w + 8;
    let per_sample = pass1.max(pass2);
    let bricks = [nx, ny, nz].map(|n| n.saturating_sub(1).div_ceil(b.max(1)));
    let total = per_sample
        .saturating_mul(nx)
        .saturating_mul(ny)
        .saturating_add(
            32u64
                .saturating_mul(bricks[0])
                .saturating_mul(bricks[1])
                .saturating_mul(bricks[2]),
        )
        .saturating_add(PREP_FIXED_BYTES);
    (per_sample, total)
}

/// Prepares `src` into the packed file `out`. Before any work, `out` is
/// checked ([`crate::fsutil::check_outputs`]): not one of the files `src`
/// reads, not a directory, in a directory that can be written.
pub fn prep(
    src: &dyn SliceSource,
    out: &Path,
    opts: &PrepOptions,
    progress: &dyn Progress,
) -> Result<PrepReport, PrepError> {
    let t0 = Instant::now();
    let opts = &checked(src, &[out.to_path_buf()], opts)?;
    let meta = src.meta().clone();
    let nz = meta.dims()[2];
    let [ncx, ncy, ncz] = meta.grid.cells();
    let n_cells_slice = ncx * ncy;
    let temp_dir = temp_dir_for(opts, out);
    let spill_err = |source| PrepError::Io {
        path: temp_dir.clone(),
        what: "temporary spill file",
        source,
    };
    let mut spill = FileSpill::new_in(&temp_dir, dt::spill_record(n_cells_slice, opts.dda))
        .map_err(spill_err)?;
    let nb_slice = ncx.div_ceil(ANISO_BLOCK) * ncy.div_ceil(ANISO_BLOCK);
    let mut block_spill = if opts.aniso {
        Some(FileSpill::new_in(&temp_dir, 4 * nb_slice).map_err(spill_err)?)
    } else {
        None
    };

    // ---- Pass 1: classify and run the forward transform. ----
    let mut st = StageTimes::default();
    let mut fwd = ForwardDt::new(ncx, ncy, opts.aniso).with_dda(opts.dda);
    let stats = passes::scan(
        src,
        opts,
        0..ncz,
        0..nz,
        &mut fwd,
        &mut spill,
        block_spill.as_mut().map(|s| s as &mut dyn dt::Spill),
        &spill_err,
        progress,
        &mut st,
    )?;
    // Pass 1's planes are not needed any more: free them before pass 2
    // allocates its slabs (docs/RELIABILITY.md, "Memory").
    drop(fwd);
    let mut header = header_for(src, opts, &stats)?;

    // ---- Pass 2: backward transform, embed codes, write bricks. ----
    let mut t = Instant::now();
    let mut writer = PackedWriter::create(out, header.brick_count(), header.format_version)?;
    st.write += t.elapsed().as_secs_f64();
    let emitted = passes::emit(
        &header,
        src,
        opts,
        0..header.bricks[2] as usize,
        None,
        &mut spill,
        block_spill.as_mut().map(|s| s as &mut dyn dt::Spill),
        &spill_err,
        &mut |id, o| put_brick(&mut writer, id, o),
        progress,
        &mut st,
    )?;
    t = Instant::now();
    header.summary = summary_of(&header, &stats, &emitted, writer.payload_bytes());
    writer.finish(&header)?;
    st.write += t.elapsed().as_secs_f64();
    let file_bytes = std::fs::metadata(out)
        .map_err(|source| PrepError::Io {
            path: out.to_path_buf(),
            what: "cannot stat the written file",
            source,
        })?
        .len();
    let temp_bytes = header.summary.cells * if opts.dda { 3 } else { 1 }
        + if opts.aniso {
            4 * nb_slice as u64 * ncz.div_ceil(ANISO_BLOCK) as u64
        } else {
            0
        };
    Ok(PrepReport {
        selection: selection_warning(&header),
        header,
        seconds: t0.elapsed().as_secs_f64(),
        file_bytes,
        temp_bytes,
        stages: st,
    })
}

/// What every prep checks before it reads a slice (the options, the
/// outputs against the input's files, the planned memory, the rescale),
/// and the options resolved for the input.
fn checked(
    src: &dyn SliceSource,
    outputs: &[PathBuf],
    opts: &PrepOptions,
) -> Result<PrepOptions, PrepError> {
    opts.check()?;
    let meta = src.meta();
    crate::fsutil::check_outputs(outputs, &src.files(), Some(&meta.origin_desc))?;
    let (per_sample, needed) = prep_memory(meta, opts);
    let limit = opts.mem_limit.unwrap_or_else(crate::memory::default_limit);
    if needed > limit {
        let [nx, ny, _] = meta.dims().map(|d| d as u64);
        return Err(PrepError::Memory {
            source_desc: meta.origin_desc.clone(),
            needed,
            per_sample,
            nx,
            ny,
            limit: crate::memory::describe_limit(limit, opts.mem_limit.is_some()),
        });
    }
    // Readers refuse such a header (format::reader), so refuse it here
    // (a DICOM RescaleSlope of 0, say) before any work.
    if !(meta.rescale.slope.is_finite()
        && meta.rescale.slope != 0.0
        && meta.rescale.intercept.is_finite())
    {
        return Err(PrepError::Input(InputError::field(
            Path::new(&meta.origin_desc),
            "rescale",
            format!(
                "slope {} intercept {}, expected a finite non-zero slope and a finite intercept",
                meta.rescale.slope, meta.rescale.intercept
            ),
        )));
    }
    // Decided after the checks above: it reads slices (the modality's
    // guess, an MR preset's landmarks). A label map has no modality and
    // is classified by its labels.
    if opts.labels {
        opts.for_labels(meta)
    } else {
        opts.resolved(src)
    }
}

/// Where the spill goes: `--temp-dir`, or beside the output.
fn temp_dir_for(opts: &PrepOptions, out: &Path) -> PathBuf {
    match &opts.temp_dir {
        Some(d) => d.clone(),
        None => match out.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        },
    }
}

/// Writes one of pass 2's bricks.
fn put_brick(writer: &mut PackedWriter, id: u64, o: BrickOut) -> Result<(), PrepError> {
    match o {
        BrickOut::Uniform(c) => writer.put_uniform(id, c),
        BrickOut::Payload {
            compressed,
            no_object,
            min_code,
            value_max,
            ..
        } => writer.put_brick(id, &compressed, no_object.then_some(min_code), value_max)?,
    }
    Ok(())
}

/// The header of the file pass 1 found `stats` for (its summary left for
/// [`summary_of`]): the storage and code encoding the value range allows,
/// the modality, landmarks and labels. Refuses a classification that
/// selected no cell unless [`PrepOptions::allow_empty`], and bricks too
/// large for the format.
fn header_for(
    src: &dyn SliceSource,
    opts: &PrepOptions,
    stats: &passes::ScanStats,
) -> Result<Header, PrepError> {
    let meta = src.meta();
    let cls = &opts.classification;
    let decided = opts.decided.as_ref();
    let b = opts.brick_size;
    let [nx, ny, nz] = meta.dims();
    let range = stats.range();
    if stats.one_cells == 0 && !opts.allow_empty {
        let [ncx, ncy, ncz] = meta.grid.cells();
        return Err(PrepError::Empty {
            source_desc: meta.origin_desc.clone(),
            warning: SelectionWarning {
                one_cells: 0,
                cells: (ncx * ncy) as u64 * ncz as u64,
                classification: if opts.labels {
                    "the labels (every sample is 0)".into()
                } else {
                    describe_classification(cls)
                },
                range: range.map(|(a, b)| {
                    let (a, b) = (meta.rescale.apply(a), meta.rescale.apply(b));
                    [a.min(b), a.max(b)]
                }),
            },
        });
    }
    let (storage, codes) = choose_encoding(meta.dtype, range);
    let histogram = stats.values.finish(meta.rescale);
    let bricks = meta.grid.cells().map(|c| c.div_ceil(b) as u64);
    let header = Header {
        format_version: opts.format_version,
        dims: [nx as u64, ny as u64, nz as u64],
        axes: meta.grid.axes.clone(),
        dtype: meta.dtype,
        storage,
        rescale: meta.rescale,
        classification: cls.clone(),
        codes,
        brick_size: b as u32,
        bricks,
        aniso_block: opts.aniso.then_some(ANISO_BLOCK as u32),
        dda: opts.dda,
        gradient_halo: opts.gradient_halo,
        zstd_level: opts.zstd_level,
        source: meta.origin_desc.clone(),
        notes: src.report(),
        orientation: meta.orientation.clone(),
        input: opts.stamp.clone(),
        modality: decided.map(|d| d.modality.clone()),
        landmarks: decided.and_then(|d| d.landmarks.clone()).or_else(|| {
            // An MR file records the landmarks of its whole histogram.
            let mr = decided.is_some_and(|d| d.modality.modality == crate::presets::Modality::Mr);
            let h = histogram.as_ref().filter(|_| mr)?;
            crate::format::landmarks::Landmarks::of(h, "the file's value histogram")
        }),
        look: decided.and_then(|d| d.look.clone()),
        labels: stats.labels.as_ref().map(|counts| {
            crate::labels::LabelCounter::from_counts(&meta.origin_desc, counts.clone())
                .finish(opts.label_table.clone())
        }),
        summary: Summary::default(),
    };
    if header.max_payload_len() > crate::format::MAX_PAYLOAD_LEN {
        return Err(PrepError::Option {
            field: "brick_size",
            value: b.to_string(),
            msg: format!(
                "gives bricks of {} bytes of {} words, expected at most {}; \
                 use a smaller brick_size",
                header.max_payload_len(),
                storage.name(),
                crate::format::MAX_PAYLOAD_LEN
            ),
        });
    }
    Ok(header)
}

/// The file's summary from what the two passes counted and the bytes of
/// payload written.
fn summary_of(
    header: &Header,
    scan: &passes::ScanStats,
    emit: &passes::EmitStats,
    payload_bytes: u64,
) -> Summary {
    let range = scan.range();
    Summary {
        cells: header.cells().iter().product(),
        one_cells: scan.one_cells,
        code_histogram: emit.code_histogram.clone(),
        uniform_bricks: emit.uniform_bricks,
        raw_min: range.map(|r| r.0),
        raw_max: range.map(|r| r.1),
        nan_samples: scan.nan_samples,
        input_bytes: header.dims.iter().product::<u64>() * header.dtype.size() as u64,
        payload_bytes,
        raw_payload_bytes: emit.raw_payload_bytes,
        histogram: scan.values.finish(header.rescale),
    }
}
