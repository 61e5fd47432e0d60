//! `cdvol prep-batch`: prepares every volume under a directory.
//!
//! Inputs are raw-stack sidecars (`.json` objects with `dims`), NRRD
//! (`.nrrd`, `.nhdr`), NIfTI-1 (`.nii`, `.nii.gz`) and DICOM series
//! (DICOM files grouped by SeriesInstanceUID wherever they lie, named
//! after the deepest directory holding all of a series' files). They are
//! sorted by their path relative to the input directory; each output is
//! named after that path (see [`output_names`]).
//!
//! Each output records its input's identity (every file's path, size,
//! modification time and content fingerprint: [`crate::identity`]) in its
//! header. An output that opens cleanly (its trailer CRC checks), was made
//! with the same options (the header's classification, brick size, aniso,
//! dda, gradient halo and zstd level) and whose recorded identity matches
//! the input now is skipped; any other is redone, and the row says why
//! (`reason`). So a re-run after a crash resumes:
//! outputs are written to a temporary file and renamed when complete, so a
//! crash never leaves one that looks complete. A failing input is recorded
//! and the batch goes on. `--shard K/N` takes input `i` when
//! `i % N == K`; `--jobs J` prepares J inputs at once (each bounded as one
//! prep is, so memory is J times one prep's); every prep uses all cores
//! either way.
//!
//! An output whose input is gone (renamed or deleted) is an orphan: the
//! previous summary lists it and no current input maps to its name
//! ([`orphans`]). It is reported, as a row of status `orphan`, and
//! `--prune` removes it ([`prune`]); nothing else in the output directory
//! is ever removed.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::format::reader::PackedVolume;
use crate::identity::InputStamp;
use crate::input::InputError;
use crate::prep::{prep, PrepOptions};
use crate::progress::NoProgress;

/// Errors that stop a whole batch (a failing input only fails its row).
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The output directory cannot be created.
    #[error("{}: cannot create the output directory: {source}", path.display())]
    OutputDir {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// One input of a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchInput {
    /// File, NRRD/NIfTI/sidecar, or the DICOM directory.
    pub path: PathBuf,
    /// The DICOM series (SeriesInstanceUID).
    pub series: Option<String>,
    /// The DICOM series' files (anywhere under the batch directory).
    pub files: Vec<PathBuf>,
    /// Path relative to the batch directory (plus the series), for names.
    pub name: String,
    /// Why the walk could not take this entry (a directory that cannot be
    /// listed, a file that cannot be read, a FIFO with a volume's name):
    /// it fails as one input, the batch goes on.
    pub error: Option<String>,
}

/// A row of the summary.
#[derive(Debug, Clone, Serialize)]
pub struct BatchRow {
    pub input: String,
    pub output: String,
    pub dims: Option<[u64; 3]>,
    pub slices: Option<u64>,
    pub rectilinear: Option<bool>,
    pub seconds: f64,
    pub output_bytes: Option<u64>,
    /// `done`, `skipped` (up to date), or `failed`.
    pub status: String,
    /// Why the input was prepared or skipped: `new`, `redo: options
    /// changed (iso 300 -> 500)`, `redo: input changed (size ...)`,
    /// `skip: unchanged`.
    pub reason: Option<String>,
    pub error: Option<String>,
    /// The classification selected no cells or nearly all of them
    /// ([`crate::prep::selection_warning`]).
    pub warning: Option<String>,
    /// `--envelope auto`: the modality chosen for this input, why, and
    /// its envelope's iso value ([`PrepOptions::resolved`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modality: Option<String>,
}

/// Finds the inputs under `dir`, sorted by name. The walk
/// (fsutil::walk) visits each directory once by device and inode, so
/// symlink loops add nothing; an entry it cannot read becomes an input
/// that fails with the reason; special files are never opened.
pub fn find_inputs(dir: &Path) -> Result<Vec<BatchInput>, InputError> {
    let mut out = Vec::new();
    let mut dicom = Vec::new();
    walk(dir, &mut out, &mut dicom)?;
    // DICOM files by series, wherever they are: a series is one input,
    // named after the deepest directory holding all its files.
    // A file whose header cannot be read has no series: it fails the
    // series whose directory holds it (the series would have a gap), or
    // else fails as an input of its own.
    let mut series: std::collections::BTreeMap<String, Vec<PathBuf>> = Default::default();
    let mut unreadable = Vec::new();
    for f in dicom {
        match crate::input::dicom::series_of(&f) {
            Ok(Some(uid)) => series.entry(uid).or_default().push(f),
            Ok(None) => {}
            Err(e) => unreadable.push((f, e.to_string())),
        }
    }
    let mut per_dir: std::collections::BTreeMap<PathBuf, usize> = Default::default();
    let common: Vec<(String, PathBuf, Vec<PathBuf>)> = series
        .into_iter()
        .map(|(uid, files)| {
            let mut d = files[0].parent().unwrap_or(dir).to_path_buf();
            while !files.iter().all(|f| f.starts_with(&d)) {
                d = d.parent().unwrap_or(dir).to_path_buf();
            }
            *per_dir.entry(d.clone()).or_default() += 1;
            (uid, d, files)
        })
        .collect();
    for (uid, d, files) in common {
        let name = rel(dir, &d);
        let name = if name.is_empty() {
            ".".to_string()
        } else {
            name
        };
        let name = if per_dir[&d] > 1 {
            format!("{name}/{uid}")
        } else {
            name
        };
        let bad: Vec<&String> = unreadable
            .iter()
            .filter(|(f, _)| f.starts_with(&d))
            .map(|(_, e)| e)
            .collect();
        let error = (!bad.is_empty()).then(|| {
            format!(
                "{} of the series' directory cannot be read: {}",
                if bad.len() == 1 {
                    "a DICOM file"
                } else {
                    "DICOM files"
                },
                bad.iter()
                    .map(|e| e.as_str())
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        });
        out.push(BatchInput {
            path: d,
            series: Some(uid),
            files,
            name,
            error,
        });
    }
    for (f, e) in unreadable {
        let covered = out
            .iter()
            .any(|i| i.series.is_some() && f.starts_with(&i.path));
        if !covered {
            out.push(BatchInput {
                name: rel(dir, &f),
                path: f,
                series: None,
                files: Vec::new(),
                error: Some(e),
            });
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

fn rel(root: &Path, p: &Path) -> String {
    p.strip_prefix(root)
        .unwrap_or(p)
        .to_string_lossy()
        .into_owned()
}

/// Whether a file's name says it is a volume (a `.json` still has to be
/// a sidecar).
fn volume_name(p: &Path) -> bool {
    let lower = p
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    [".nrrd", ".nhdr", ".nii", ".nii.gz", ".json"]
        .iter()
        .any(|e| lower.ends_with(e))
}

fn walk(
    root: &Path,
    out: &mut Vec<BatchInput>,
    dicom: &mut Vec<PathBuf>,
) -> Result<(), InputError> {
    let w = crate::fsutil::walk(root).map_err(|source| InputError::Io {
        path: root.to_path_buf(),
        what: "cannot list the directory",
        source,
    })?;
    let failed = |p: &Path, msg: String| BatchInput {
        name: rel(root, p),
        path: p.to_path_buf(),
        series: None,
        files: Vec::new(),
        error: Some(format!("{}: {msg}", p.display())),
    };
    for (p, e) in &w.unlistable {
        out.push(failed(p, format!("cannot list the directory: {e}")));
    }
    // A dangling symlink is an input only if named like one.
    for (p, e) in &w.unreadable {
        if volume_name(p) || e.kind() != std::io::ErrorKind::NotFound {
            out.push(failed(p, format!("cannot read: {e}")));
        }
    }
    // Special files are never opened: one named like a volume fails, any
    // other cannot be a DICOM file and is left out.
    for (p, kind) in &w.special {
        if volume_name(p) {
            out.push(failed(p, format!("{kind}, not a regular file")));
        }
    }
    for p in w.files {
        let lower = p.to_string_lossy().to_ascii_lowercase();
        if volume_name(&p) {
            if !lower.ends_with(".json") {
                out.push(BatchInput {
                    name: rel(root, &p),
                    path: p,
                    series: None,
                    files: Vec::new(),
                    error: None,
                });
                continue;
            }
            match is_sidecar(&p) {
                Ok(true) => out.push(BatchInput {
                    name: rel(root, &p),
                    path: p,
                    series: None,
                    files: Vec::new(),
                    error: None,
                }),
                Ok(false) => {}
                Err(e) => out.push(failed(&p, format!("cannot read: {e}"))),
            }
        } else {
            match crate::input::dicom::sniff(&p) {
                Ok(true) => dicom.push(p),
                Ok(false) => {}
                Err(e) => out.push(failed(&p, format!("cannot read: {e}"))),
            }
        }
    }
    Ok(())
}

/// A JSON object with `dims`: a raw-stack sidecar (other JSON, such as a
/// sphere list or render statistics, is not an input). An error if the
/// file cannot be read.
fn is_sidecar(p: &Path) -> std::io::Result<bool> {
    let b = crate::fsutil::read_regular(p)?;
    Ok(serde_json::from_slice::<serde_json::Value>(&b)
        .ok()
        .is_some_and(|v| v.get("dims").is_some()))
}

/// The output files of `inputs` in `out_dir`: each input's name with
/// `/` turned into `_` and `.cdv` appended (extensions kept, so
/// `vol.nrrd` and `vol.nii.gz` stay apart). Where two inputs' names would
/// still meet (`b/vol.nrrd` and `b_vol.nrrd`), each of them gets
/// `~XXXXXXXX`, the CRC-32 of its own name, so the name depends on the
/// input and the set of inputs, never on their order or age. Computed
/// over all inputs, so every shard of a batch names the same input alike.
pub fn output_names(out_dir: &Path, inputs: &[BatchInput]) -> Vec<PathBuf> {
    let flat = |input: &BatchInput| -> String {
        match input.name.as_str() {
            "." => "dicom".into(),
            n => n
                .chars()
                .map(|c| if c == '/' || c == '\\' { '_' } else { c })
                .collect(),
        }
    };
    let mut count: std::collections::HashMap<String, usize> = Default::default();
    for i in inputs {
        *count.entry(flat(i)).or_default() += 1;
    }
    let mut seen = std::collections::HashSet::new();
    inputs
        .iter()
        .map(|input| {
            let base = flat(input);
            let mut name = if count[&base] > 1 {
                format!("{base}~{:08x}.cdv", crc32fast::hash(input.name.as_bytes()))
            } else {
                format!("{base}.cdv")
            };
            // Only a contrived set (a name that is another's hashed name)
            // still meets: number it in input order.
            let mut k = 1;
            while !seen.insert(name.clone()) {
                k += 1;
                name = format!("{base}~{k}.cdv");
            }
            out_dir.join(name)
        })
        .collect()
}

/// How the options that made `h` differ from `opts`, one `what old ->
/// new` a difference (empty when the same output would be made).
pub fn options_differ(h: &crate::format::Header, opts: &PrepOptions) -> Vec<String> {
    use crate::classify::Classification as C;
    let mut d = Vec::new();
    let yn = |b: bool| if b { "yes" } else { "no" };
    match (&h.classification, &opts.classification) {
        (C::Iso { iso: a }, C::Iso { iso: b }) if a.to_bits() != b.to_bits() => {
            d.push(format!("iso {a} -> {b}"))
        }
        (C::Iso { iso }, C::TransferFunction { .. }) => {
            d.push(format!("iso {iso} -> transfer function"))
        }
        (C::TransferFunction { .. }, C::Iso { iso }) => {
            d.push(format!("transfer function -> iso {iso}"))
        }
        (C::TransferFunction { tf: a }, C::TransferFunction { tf: b }) if a != b => {
            d.push("transfer function changed".into())
        }
        _ => {}
    }
    if h.brick_size as usize != opts.brick_size {
        d.push(format!("brick {} -> {}", h.brick_size, opts.brick_size));
    }
    if h.aniso_block.is_some() != opts.aniso {
        d.push(format!(
            "aniso {} -> {}",
            yn(h.aniso_block.is_some()),
            yn(opts.aniso)
        ));
    }
    if h.dda != opts.dda {
        d.push(format!("dda {} -> {}", yn(h.dda), yn(opts.dda)));
    }
    if h.gradient_halo != opts.gradient_halo {
        d.push(format!(
            "gradient-halo {} -> {}",
            yn(h.gradient_halo),
            yn(opts.gradient_halo)
        ));
    }
    // A file of an older version reads as well as a new one: only one
    // newer than asked for (`--format-version 2` for older readers) is
    // remade.
    if h.format_version > opts.format_version {
        d.push(format!(
            "format-version {} -> {}",
            h.format_version, opts.format_version
        ));
    }
    if h.zstd_level != opts.zstd_level {
        d.push(format!(
            "zstd-level {} -> {}",
            h.zstd_level, opts.zstd_level
        ));
    }
    d
}

/// What a batch does with one input.
enum Verdict {
    /// The output is up to date.
    Skip(Box<PackedVolume>),
    /// Prepare it, for this reason (`new`, `redo: ...`).
    Redo(String),
}

/// Whether `out` must be (re)made from an input whose identity is now
/// `stamp` with `opts`.
fn verdict(out: &Path, stamp: &InputStamp, opts: &PrepOptions) -> Verdict {
    if std::fs::symlink_metadata(out).is_err() {
        return Verdict::Redo("new".into());
    }
    let v = match PackedVolume::open(out) {
        Ok(v) => v,
        Err(e) => return Verdict::Redo(format!("redo: output unreadable ({e})")),
    };
    let d = options_differ(v.header(), opts);
    if !d.is_empty() {
        return Verdict::Redo(format!("redo: options changed ({})", d.join(", ")));
    }
    match &v.header().input {
        None => Verdict::Redo("redo: the output records no input identity".into()),
        Some(was) => match was.differs(stamp) {
            Some(why) => Verdict::Redo(format!("redo: input changed ({why})")),
            None => Verdict::Skip(Box::new(v)),
        },
    }
}

/// Prepares `inputs` (those of `shard`) into `out_dir`, `jobs` at a time,
/// calling `done` with each finished row (in completion order); returns
/// the rows in input order.
pub fn run(
    inputs: &[BatchInput],
    out_dir: &Path,
    opts: &PrepOptions,
    jobs: usize,
    shard: (u32, u32),
    done: &(dyn Fn(&BatchRow) + Sync),
) -> Result<Vec<BatchRow>, BatchError> {
    std::fs::create_dir_all(out_dir).map_err(|source| BatchError::OutputDir {
        path: out_dir.to_path_buf(),
        source,
    })?;
    let outs = output_names(out_dir, inputs);
    let mine: Vec<(&BatchInput, &PathBuf)> = inputs
        .iter()
        .zip(&outs)
        .enumerate()
        .filter(|(i, _)| *i as u64 % shard.1 as u64 == shard.0 as u64)
        .map(|(_, x)| x)
        .collect();
    // J workers take inputs in order; each prep runs on rayon's global
    // pool, so a single job still uses every core.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: std::sync::Mutex<Vec<Option<BatchRow>>> =
        std::sync::Mutex::new(vec![None; mine.len()]);
    std::thread::scope(|s| {
        for _ in 0..jobs.clamp(1, mine.len().max(1)) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(&(input, out)) = mine.get(i) else {
                    break;
                };
                let row = one(input, out, opts);
                done(&row);
                slots.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(row);
            });
        }
    });
    Ok(slots
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .flatten()
        .collect())
}

/// Largest summary read back to find orphans (a row is a few hundred
/// bytes).
pub const MAX_SUMMARY_BYTES: u64 = 256 << 20;

/// An output an earlier summary listed whose input is gone.
#[derive(Debug, Clone, PartialEq)]
pub struct Orphan {
    /// The input the earlier summary named (relative to the batch
    /// directory).
    pub input: String,
    /// The output file, in the output directory.
    pub output: PathBuf,
}

impl Orphan {
    /// The orphan's row of the summary, of status `orphan`, or `pruned`
    /// once removed.
    pub fn row(&self, pruned: bool) -> BatchRow {
        BatchRow {
            input: self.input.clone(),
            output: self.output.display().to_string(),
            dims: None,
            slices: None,
            rectilinear: None,
            seconds: 0.0,
            output_bytes: None,
            status: if pruned { "pruned" } else { "orphan" }.into(),
            reason: Some(if pruned {
                "input gone: removed (--prune)".into()
            } else {
                "input gone: remove the output, or run again with --prune".into()
            }),
            error: None,
            warning: None,
            modality: None,
        }
    }
}

/// The orphans of a batch writing into `out_dir`: outputs that the
/// earlier summary `summary` listed, that still exist there as regular
/// files, and that no current input maps to (`outs`, every current
/// output name: [`output_names`] over all inputs, so shards agree).
/// No summary yet gives none; one that cannot be read gives an error
/// saying why, for a warning.
pub fn orphans(
    summary: &Path,
    out_dir: &Path,
    outs: &[PathBuf],
) -> Result<Vec<Orphan>, OrphanError> {
    let path = || summary.to_path_buf();
    let m = match std::fs::metadata(summary) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => {
            return Err(OrphanError::Io {
                path: path(),
                source,
            })
        }
    };
    if m.len() > MAX_SUMMARY_BYTES {
        return Err(OrphanError::TooLarge {
            path: path(),
            len: m.len(),
        });
    }
    let bytes = crate::fsutil::read_regular(summary).map_err(|source| OrphanError::Io {
        path: path(),
        source,
    })?;
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&bytes).map_err(|source| OrphanError::Json {
            path: path(),
            source,
        })?;
    let current: std::collections::HashSet<&std::ffi::OsStr> =
        outs.iter().filter_map(|o| o.file_name()).collect();
    let mut found: Vec<Orphan> = Vec::new();
    for row in &rows {
        let Some(listed) = row.get("output").and_then(|o| o.as_str()) else {
            continue;
        };
        // Outputs lie in the output directory itself: take the name only.
        let Some(name) = Path::new(listed).file_name() else {
            continue;
        };
        if !name.to_string_lossy().ends_with(".cdv") || current.contains(name) {
            continue;
        }
        let output = out_dir.join(name);
        if found.iter().any(|o| o.output == output) {
            continue;
        }
        if !std::fs::symlink_metadata(&output).is_ok_and(|m| m.is_file()) {
            continue;
        }
        found.push(Orphan {
            input: row
                .get("input")
                .and_then(|i| i.as_str())
                .unwrap_or_default()
                .to_string(),
            output,
        });
    }
    Ok(found)
}

/// Removes orphan `o` (`--prune`), only if it is still a packed file
/// cdvol can open: a file put under that name since is never removed.
pub fn prune(o: &Orphan) -> Result<(), OrphanError> {
    let path = || o.output.clone();
    PackedVolume::open(&o.output).map_err(|source| OrphanError::NotPacked {
        path: path(),
        source: Box::new(source),
    })?;
    std::fs::remove_file(&o.output).map_err(|source| OrphanError::Remove {
        path: path(),
        source,
    })
}

/// Why the orphans of a batch could not be listed, or one removed.
#[derive(Debug, thiserror::Error)]
pub enum OrphanError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{}: {len} bytes, expected a summary of at most {} MiB",
        path.display(),
        MAX_SUMMARY_BYTES >> 20
    )]
    TooLarge { path: PathBuf, len: u64 },
    #[error("{}: expected the JSON array of rows prep-batch writes: {source}", path.display())]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("{}: not removed, not a packed file any more: {source}", path.display())]
    NotPacked {
        path: PathBuf,
        source: Box<crate::format::FormatError>,
    },
    #[error("{}: cannot remove: {source}", path.display())]
    Remove {
        path: PathBuf,
        source: std::io::Error,
    },
}

fn one(input: &BatchInput, out: &Path, opts: &PrepOptions) -> BatchRow {
    let out = out.to_path_buf();
    let t0 = Instant::now();
    let mut row = BatchRow {
        input: input.name.clone(),
        output: out.display().to_string(),
        dims: None,
        slices: None,
        rectilinear: None,
        seconds: 0.0,
        output_bytes: None,
        status: "done".into(),
        reason: None,
        error: None,
        warning: None,
        modality: None,
    };
    let describe = |row: &mut BatchRow, vol: &PackedVolume| {
        let h = vol.header();
        row.dims = Some(h.dims);
        row.slices = Some(h.dims[2]);
        row.rectilinear = Some(h.axes.iter().any(|a| !a.is_uniform()));
        row.output_bytes = Some(vol.file_len());
        row.warning = crate::prep::selection_warning(h).map(|w| w.to_string());
    };
    if let Some(e) = &input.error {
        row.status = "failed".into();
        row.error = Some(e.clone());
        return row;
    }
    let opened = if !input.files.is_empty() {
        crate::input::dicom::open_files(&input.path, input.files.clone(), input.series.as_deref())
            .map(|s| Box::new(s) as Box<dyn crate::input::SliceSource>)
    } else {
        crate::input::open(&input.path)
    };
    let result = opened.map_err(|e| e.to_string()).and_then(|src| {
        let stamp = InputStamp::of(&src.files()).map_err(|e| {
            format!(
                "{}: cannot fingerprint the input: {e}",
                input.path.display()
            )
        })?;
        let opts = &opts.resolved(src.as_ref()).map_err(|e| e.to_string())?;
        row.modality = opts.decided.as_ref().and_then(|d| d.note.clone());
        match verdict(&out, &stamp, opts) {
            Verdict::Skip(v) => Ok((*v, false)),
            Verdict::Redo(why) => {
                row.reason = Some(why);
                let opts = PrepOptions {
                    stamp: Some(stamp),
                    ..opts.clone()
                };
                prep(src.as_ref(), &out, &opts, &NoProgress).map_err(|e| e.to_string())?;
                PackedVolume::open(&out)
                    .map(|v| (v, true))
                    .map_err(|e| e.to_string())
            }
        }
    });
    row.seconds = t0.elapsed().as_secs_f64();
    match result {
        Ok((v, made)) => {
            describe(&mut row, &v);
            if !made {
                row.status = "skipped".into();
                row.reason = Some("skip: unchanged".into());
            }
        }
        Err(e) => {
            row.status = "failed".into();
            row.error = Some(e);
        }
    }
    row
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_names_never_meet() {
        let input = |name: &str| BatchInput {
            path: PathBuf::from(name),
            series: None,
            files: Vec::new(),
            name: name.into(),
            error: None,
        };
        let names = [
            "b/vol.nrrd",
            "b_vol.nrrd",
            "vol.nii.gz",
            "vol.nrrd",
            "series",
            "series.json",
            ".",
        ];
        let inputs: Vec<BatchInput> = names.iter().map(|n| input(n)).collect();
        let got: Vec<String> = output_names(Path::new("o"), &inputs)
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_ne!(got[0], got[1]);
        assert_eq!(
            got[0],
            format!("b_vol.nrrd~{:08x}.cdv", crc32fast::hash(b"b/vol.nrrd"))
        );
        let got: Vec<String> = got
            .iter()
            .map(|n| match n.find('~') {
                Some(i) => format!("{}~HASH.cdv", &n[..i]),
                None => n.clone(),
            })
            .collect();
        assert_eq!(
            got,
            [
                "b_vol.nrrd~HASH.cdv",
                "b_vol.nrrd~HASH.cdv",
                "vol.nii.gz.cdv",
                "vol.nrrd.cdv",
                "series.cdv",
                "series.json.cdv",
                "dicom.cdv"
            ]
        );
    }
}
