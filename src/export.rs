//! `cdvol export`: full-resolution arrays back out of a packed file, as a
//! raw stack plus a sidecar in the input schema, streamed one brick slab
//! at a time.
//!
//! - `values`: every sample, in the input type. A sample whose word was
//!   replaced by a code is written as the fill value: NaN for float data,
//!   the smallest raw value of the input (`summary.raw_min`) for integers.
//! - `codes`: one `u8` per cell: the isotropic code of each 0-cell, and
//!   [`OBJECT_MARKER`] (255) for 1-cells. Axes are the cell centres.
//! - `classes`: one `u8` per cell, 1 for 1-cells and 0 otherwise.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::format::reader::{Brick, CellClass, PackedVolume, Sample};
use crate::format::FormatError;
use crate::fsutil::{FileSet, OutputError, WriteError};
use crate::input::sidecar::{AxisSpec, SidecarOut};
use crate::input::{Dtype, Endian};
use crate::progress::Progress;

/// The `codes` export's value for 1-cells.
pub const OBJECT_MARKER: u8 = 255;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportWhat {
    Values,
    Codes,
    Classes,
}

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Format(#[from] FormatError),
    /// An output cannot be written, or is the packed file read.
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("{}: {what}: {source}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        source: std::io::Error,
    },
}

/// Sidecars and NRRD headers larger than this are not read to find the
/// data files they name (a sidecar is a few KiB; see
/// [`packed_sources`]).
const MAX_SOURCE_HEADER_BYTES: u64 = 16 << 20;

/// The files the packed file at `packed` (header `h`) was prepared from,
/// as far as they can be found cheaply: every file of the input identity
/// `prep-batch` records, and the header's `source` (as given, so relative
/// to the working directory, then beside the packed file, then its bare
/// name beside the packed file) with the data files it names when it is
/// a sidecar or an NRRD header. A DICOM series' `source` names no file.
/// Paths that do not exist are left out.
pub fn packed_sources(packed: &Path, h: &crate::format::Header) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = Vec::new();
    if let Some(stamp) = &h.input {
        v.extend(stamp.files.iter().map(|f| f.path.clone()));
    }
    if h.source.is_empty() {
        return v;
    }
    let src = Path::new(&h.source);
    let dir = crate::fsutil::dir_of(packed);
    let mut candidates = vec![src.to_path_buf()];
    if !src.is_absolute() {
        candidates.push(dir.join(src));
        if let Some(name) = src.file_name() {
            candidates.push(dir.join(name));
        }
    }
    for c in candidates {
        if v.contains(&c) {
            continue;
        }
        // By type first: a FIFO or device is never opened.
        let Ok(m) = std::fs::metadata(&c) else {
            continue;
        };
        if !m.is_file() {
            continue;
        }
        let data = if m.len() <= MAX_SOURCE_HEADER_BYTES {
            data_files_of(&c)
        } else {
            Vec::new()
        };
        v.push(c);
        v.extend(data);
    }
    v
}

/// The data files a sidecar or detached NRRD header names; none for
/// other files (or any that does not parse).
fn data_files_of(path: &Path) -> Vec<PathBuf> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
        match crate::input::nrrd::parse(path) {
            Ok(h) if h.data != path => vec![h.data],
            _ => Vec::new(),
        }
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        Vec::new()
    } else {
        match crate::input::sidecar::parse_sidecar(path) {
            Ok(s) => match s.data {
                crate::input::sidecar::DataFiles::One(f) => vec![f],
                crate::input::sidecar::DataFiles::PerSlice(list) => list,
            },
            Err(_) => Vec::new(),
        }
    }
}

/// Checks, before any work, the outputs of a command that reads the
/// packed file `vol`: none may be the packed file itself, nor the scan it
/// was prepared from ([`packed_sources`]); each must be writable
/// ([`crate::fsutil::check_outputs`]).
pub fn check_packed_outputs(vol: &PackedVolume, outputs: &[PathBuf]) -> Result<(), OutputError> {
    crate::fsutil::check_outputs(outputs, &[vol.path().to_path_buf()], None)?;
    check_not_sources(
        outputs,
        &packed_sources(vol.path(), vol.header()),
        vol.path(),
    )
}

/// Writes `what` of `vol` as `<out_json stem>.raw` plus the sidecar
/// `out_json`, committed together (fsutil::FileSet). Both are checked
/// before any work: neither may be the packed file read. Returns the raw
/// file's path.
pub fn export(
    vol: &PackedVolume,
    what: ExportWhat,
    out_json: &Path,
    progress: &dyn Progress,
) -> Result<PathBuf, ExportError> {
    let h = vol.header();
    let dir = match out_json.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let stem = out_json
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "export".into());
    let raw_name = format!("{stem}.raw");
    let raw_path = dir.join(&raw_name);
    if raw_path == out_json {
        return Err(ExportError::Io {
            path: out_json.to_path_buf(),
            what: "the sidecar would overwrite its own raw data; use a .json name",
            source: std::io::Error::from(std::io::ErrorKind::InvalidInput),
        });
    }
    check_packed_outputs(vol, &[out_json.to_path_buf(), raw_path.clone()])?;
    let io = |path: &Path, what| {
        let path = path.to_path_buf();
        move |source| ExportError::Io { path, what, source }
    };
    let tmp = crate::fsutil::temp_beside(&raw_path).map_err(io(
        &raw_path,
        "cannot create a temporary file beside the output",
    ))?;
    let mut w = BufWriter::with_capacity(1 << 20, tmp);
    write_raw(vol, what, &mut w, progress).map_err(|e| match e {
        RawError::Format(e) => ExportError::Format(e),
        RawError::Write(source) => ExportError::Io {
            path: raw_path.clone(),
            what: "cannot write",
            source,
        },
    })?;
    let tmp = w.into_inner().map_err(|e| ExportError::Io {
        path: raw_path.clone(),
        what: "cannot flush",
        source: e.into_error(),
    })?;
    // Both files are renamed into place together, after both are written.
    let mut set = FileSet::new();
    set.add(tmp, &raw_path);

    let [nx, ny, nz] = h.dims.map(|d| d as usize);
    let [ncx, ncy, ncz] = h.cells().map(|c| c as usize);
    // The sidecar.
    let (dims, dtype, axes): ([usize; 3], &'static str, [Vec<f64>; 3]) = match what {
        ExportWhat::Values => (
            [nx, ny, nz],
            h.dtype.name(),
            h.axes.each_ref().map(|a| a.coords().to_vec()),
        ),
        _ => (
            [ncx, ncy, ncz],
            "u8",
            h.axes
                .each_ref()
                .map(|a| a.coords().windows(2).map(|w| 0.5 * (w[0] + w[1])).collect()),
        ),
    };
    let spec = |c: &Vec<f64>| {
        let first = c.get(1).map(|x| x - c[0]);
        match first {
            Some(g)
                if c.windows(2)
                    .all(|w| ((w[1] - w[0]) - g).abs() <= 1e-9 * g.abs()) =>
            {
                AxisSpec::Uniform(g)
            }
            _ => AxisSpec::Positions {
                positions: c.clone(),
            },
        }
    };
    let [sx, sy, sz] = axes.each_ref().map(spec);
    let origin = axes.each_ref().map(|c| c[0]);
    let side = SidecarOut {
        data: raw_name,
        dims,
        dtype,
        endian: Endian::Little,
        header_bytes: 0,
        x: sx,
        y: sy,
        z: sz,
        origin,
        rescale: (what == ExportWhat::Values).then_some(h.rescale),
    };
    let json = serde_json::to_vec_pretty(&side).map_err(|e| ExportError::Io {
        path: out_json.to_path_buf(),
        what: "cannot write sidecar",
        source: e.into(),
    })?;
    set.add_bytes(out_json, &json)?;
    set.commit()?;
    Ok(raw_path)
}

/// Why [`write_raw`] stopped: a brick that does not decode, or the
/// writer's error.
#[derive(Debug, thiserror::Error)]
pub enum RawError {
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error("cannot write: {0}")]
    Write(std::io::Error),
}

/// Writes `what` of `vol` to `w` as the raw array [`export`] writes
/// (little-endian, x fastest), one brick slab in memory at a time: the
/// samples (`dims`) in the file's type for `Values`, one `u8` per cell
/// for `Codes` and `Classes`.
pub fn write_raw(
    vol: &PackedVolume,
    what: ExportWhat,
    w: &mut impl Write,
    progress: &dyn Progress,
) -> Result<(), RawError> {
    let h = vol.header();

    let [nx, ny, nz] = h.dims.map(|d| d as usize);
    let [ncx, ncy, ncz] = h.cells().map(|c| c as usize);
    let b = h.brick_size as usize;
    let [nbx, nby, nbz] = h.bricks.map(|n| n as usize);
    let fill = if h.dtype.is_float() {
        f64::NAN
    } else {
        h.summary.raw_min.unwrap_or(0.0)
    };
    progress.begin("export", nbz as u64);
    for bz in 0..nbz {
        // Decode the slab's bricks in parallel (one slab in memory).
        let ids: Vec<u64> = (0..nby)
            .flat_map(|by| (0..nbx).map(move |bx| (bz * nby + by) * nbx + bx))
            .map(|i| i as u64)
            .collect();
        let bricks: Vec<Brick> = ids
            .par_iter()
            .map(|&id| vol.read_brick(id))
            .collect::<Result<_, _>>()?;
        let brick_at = |bx: usize, by: usize| &bricks[by * nbx + bx];
        let mut line: Vec<u8> = Vec::new();
        match what {
            ExportWhat::Values => {
                let z0 = bz * b;
                let z1 = if bz + 1 == nbz { nz } else { z0 + b };
                for z in z0..z1 {
                    for y in 0..ny {
                        line.clear();
                        let by = (y / b).min(nby - 1);
                        for x in 0..nx {
                            let bx = (x / b).min(nbx - 1);
                            let br = brick_at(bx, by);
                            let l = [x - bx * b, y - by * b, z - z0];
                            let v = match br.sample(l) {
                                Some(Sample::Value(v)) => v,
                                _ => fill,
                            };
                            push_value(&mut line, h.dtype, v);
                        }
                        w.write_all(&line).map_err(RawError::Write)?;
                    }
                }
            }
            ExportWhat::Codes | ExportWhat::Classes => {
                let z0 = bz * b;
                let z1 = (z0 + b).min(ncz);
                for z in z0..z1 {
                    for y in 0..ncy {
                        line.clear();
                        let by = y / b;
                        for x in 0..ncx {
                            let bx = x / b;
                            let l = [x - bx * b, y - by * b, z - z0];
                            let c = vol.cell_class(brick_at(bx, by), l);
                            line.push(match (what, c) {
                                (ExportWhat::Classes, CellClass::Object) => 1,
                                (ExportWhat::Classes, CellClass::Empty(_)) => 0,
                                (_, CellClass::Object) => OBJECT_MARKER,
                                (_, CellClass::Empty(code)) => code.min(254) as u8,
                            });
                        }
                        w.write_all(&line).map_err(RawError::Write)?;
                    }
                }
            }
        }
        drop(bricks);
        progress.advance(1);
    }
    progress.end();
    Ok(())
}

fn push_value(out: &mut Vec<u8>, dtype: Dtype, v: f64) {
    match dtype {
        Dtype::U8 => out.push(v as u8),
        Dtype::I8 => out.push(v as i8 as u8),
        Dtype::U16 => out.extend_from_slice(&(v as u16).to_le_bytes()),
        Dtype::I16 => out.extend_from_slice(&(v as i16).to_le_bytes()),
        Dtype::U32 => out.extend_from_slice(&(v as u32).to_le_bytes()),
        Dtype::I32 => out.extend_from_slice(&(v as i32).to_le_bytes()),
        Dtype::I64 => out.extend_from_slice(&(v as i64).to_le_bytes()),
        Dtype::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
        Dtype::F64 => out.extend_from_slice(&v.to_le_bytes()),
    }
}

/// Checks that none of `outputs` is one of `sources`, the files the
/// packed file `packed` was prepared from (same device and inode, as
/// [`check_outputs`](crate::fsutil::check_outputs) compares). Sources that do not exist are left out.
pub fn check_not_sources(
    outputs: &[PathBuf],
    sources: &[PathBuf],
    packed: &Path,
) -> Result<(), crate::fsutil::OutputError> {
    use std::os::unix::fs::MetadataExt;
    let ids = crate::fsutil::identities(sources);
    for out in outputs {
        let Ok(m) = std::fs::metadata(out) else {
            continue;
        };
        if let Some((_, scan)) = ids.iter().find(|(id, _)| *id == (m.dev(), m.ino())) {
            return Err(crate::fsutil::OutputError::IsSource {
                output: out.clone(),
                scan: scan.to_path_buf(),
                packed: packed.to_path_buf(),
            });
        }
    }
    Ok(())
}
