//! NRRD volumes (teem's format, written by 3D Slicer, ITK and others):
//! `.nrrd` with the data attached after the header, or `.nhdr` naming a
//! detached data file; `raw` and `gzip` encodings; spacing from `space
//! directions` (axis-aligned only) or `spacings`.
//!
//! The header is plain text: a magic line `NRRD000N`, then `field: value`
//! lines (`key:=value` pairs and `#` comments are ignored) up to an empty
//! line or the end of a detached header. Axis-aligned direction vectors
//! with a negative component give the absolute spacing: the samples are
//! kept in file order, so such an axis is mirrored relative to the
//! patient, as it is in the file. With a patient `space`
//! (`left-posterior-superior`, `right-anterior-superior`,
//! `left-anterior-superior` or their short names LPS, RAS, LAS) the signs
//! of the directions give the volume's patient orientation
//! (crate::orient); any other space, or none, leaves it unknown.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use super::gz::{GzLayout, GzSource};
use super::raw::RawSource;
use super::sidecar::{DataFiles, Sidecar};
use super::{Dtype, Endian, InputError, Rescale, SliceSource, VolumeMeta};
use crate::grid::{check_spacing, Axis, Grid, MAX_COORD_MM, MAX_SAMPLES_PER_AXIS};
use crate::orient::Orientation;

/// Headers longer than this are refused (a real one is a few hundred
/// bytes); the header is read through a reader that stops there, so a
/// file that is one long line costs no more memory than this.
const MAX_HEADER: u64 = 1 << 20;

const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// Opens an NRRD header (`.nrrd` or `.nhdr`) as a slice source.
pub fn open(path: &Path) -> Result<Box<dyn SliceSource>, InputError> {
    let h = parse(path)?;
    let meta = VolumeMeta {
        grid: h.grid.clone(),
        dtype: h.dtype,
        rescale: Rescale::IDENTITY,
        origin_desc: path.display().to_string(),
        orientation: h.orientation.clone(),
    };
    if h.gzip {
        let layout = GzLayout {
            file: h.data,
            header: path.to_path_buf(),
            file_offset: h.file_offset,
            skip: h.skip,
            dtype: h.dtype,
            endian: h.endian,
            dims_field: "sizes",
            skip_field: "byte skip",
        };
        Ok(Box::new(GzSource::open(meta, layout)?))
    } else {
        let sidecar = Sidecar {
            path: path.to_path_buf(),
            data: DataFiles::One(h.data),
            dims: h.dims,
            dtype: h.dtype,
            endian: h.endian,
            header_bytes: h.file_offset.saturating_add(h.skip),
            grid: h.grid,
            rescale: Rescale::IDENTITY,
            orientation: h.orientation,
            modality: None,
        };
        Ok(Box::new(RawSource::from_sidecar(sidecar)?))
    }
}

/// What an NRRD header says.
#[derive(Debug, Clone, PartialEq)]
pub struct NrrdHeader {
    pub dims: [usize; 3],
    pub dtype: Dtype,
    pub endian: Endian,
    pub grid: Grid,
    /// The file holding the samples (the header itself when attached).
    pub data: PathBuf,
    /// File bytes before the data: the attached header, or 0.
    pub file_offset: u64,
    /// `byte skip`: bytes before the first sample (in the decompressed
    /// stream for gzip); `byte skip: -1` (raw only) is resolved to the
    /// skip that puts the samples at the end of the file.
    pub skip: u64,
    pub gzip: bool,
    /// From `space` and the signs of `space directions`; `None` when the
    /// space is not a patient space (or absent).
    pub orientation: Option<Orientation>,
}

/// Parses and checks the header at `path`.
pub fn parse(path: &Path) -> Result<NrrdHeader, InputError> {
    let io = |what| {
        move |source| InputError::Io {
            path: path.to_path_buf(),
            what,
            source,
        }
    };
    let bad = |field: &str, msg: String| InputError::field(path, field, msg);
    let f = crate::fsutil::open_regular(path).map_err(io("cannot open NRRD header"))?;
    let mut r = BufReader::new(f.take(MAX_HEADER + 1));
    let mut fields: BTreeMap<String, String> = BTreeMap::new();
    let mut consumed = 0u64;
    let mut attached = false;
    let mut line = Vec::new();
    let mut first = true;
    loop {
        line.clear();
        let n = r
            .read_until(b'\n', &mut line)
            .map_err(io("cannot read NRRD header"))?;
        if n == 0 {
            break;
        }
        consumed += n as u64;
        if consumed > MAX_HEADER {
            return Err(bad(
                "header",
                format!("no end of the header within {MAX_HEADER} bytes"),
            ));
        }
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end_matches(['\n', '\r']);
        if first {
            first = false;
            if !(text.len() == 8 && text.starts_with("NRRD000")) {
                return Err(bad(
                    "magic",
                    format!("{text:?}, expected NRRD0001 .. NRRD0005 on the first line"),
                ));
            }
            continue;
        }
        if text.is_empty() {
            attached = true;
            break;
        }
        if text.starts_with('#') || text.contains(":=") {
            continue;
        }
        let Some((k, v)) = text.split_once(": ") else {
            return Err(bad(
                "header",
                format!("line {text:?}, expected \"field: value\""),
            ));
        };
        fields.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
    }
    let get = |k: &str| fields.get(k).map(String::as_str);
    let need = |k: &str| get(k).ok_or_else(|| bad(k, "missing".into()));

    let dimension = need("dimension")?;
    if dimension != "3" {
        return Err(bad(
            "dimension",
            format!("{dimension}, expected 3 (a scalar volume)"),
        ));
    }
    let sizes = need("sizes")?;
    let words: Vec<&str> = sizes.split_whitespace().collect();
    if words.len() != 3 {
        return Err(bad(
            "sizes",
            format!(
                "{} numbers, expected 3 (samples along x, y and z)",
                words.len()
            ),
        ));
    }
    // Bounded before anything is allocated for an axis.
    let mut dims = [0usize; 3];
    for (k, w) in words.iter().enumerate() {
        let axis = AXIS_NAMES[k];
        let n = w.parse::<u64>().map_err(|_| {
            bad(
                "sizes",
                format!(
                    "{w:?} along {axis}, expected a whole number of samples \
                     from 2 to {MAX_SAMPLES_PER_AXIS}"
                ),
            )
        })?;
        if n < 2 {
            return Err(bad(
                "sizes",
                format!("{n} samples along {axis}, expected at least 2"),
            ));
        }
        if n > MAX_SAMPLES_PER_AXIS as u64 {
            return Err(bad(
                "sizes",
                format!("{n} samples along {axis}, expected at most {MAX_SAMPLES_PER_AXIS}"),
            ));
        }
        dims[k] = n as usize;
    }
    let ty = need("type")?;
    let dtype = dtype_of(ty).ok_or_else(|| {
        bad(
            "type",
            format!("{ty:?}, expected one of int8, uint8, int16, uint16, int32, uint32, int64, float, double (or their C names)"),
        )
    })?;
    let encoding = need("encoding")?.to_ascii_lowercase();
    let gzip = match encoding.as_str() {
        "raw" => false,
        "gzip" | "gz" => true,
        e => {
            return Err(bad(
                "encoding",
                format!("{e:?} is not supported, expected raw or gzip"),
            ))
        }
    };
    let endian = match get("endian").map(str::to_ascii_lowercase).as_deref() {
        Some("little") => Endian::Little,
        Some("big") => Endian::Big,
        None if dtype.size() == 1 => Endian::Little,
        None => return Err(bad("endian", format!("missing, needed for {ty}"))),
        Some(e) => return Err(bad("endian", format!("{e:?}, expected little or big"))),
    };
    let (spacing, spacing_field) = spacings(&fields, path)?;
    let orientation = orientation(&fields, path)?;
    let origin = match get("space origin") {
        Some(v) => vector(v)
            .filter(|o| o.iter().all(|c| c.abs() <= MAX_COORD_MM))
            .ok_or_else(|| {
                bad(
                    "space origin",
                    format!(
                        "{v:?}, expected (x,y,z) in finite numbers of mm, \
                         at most {MAX_COORD_MM:e} from 0"
                    ),
                )
            })?,
        None => [0.0; 3],
    };
    let mut axes = Vec::with_capacity(3);
    for k in 0..3 {
        axes.push(
            Axis::uniform(origin[k], spacing[k], dims[k])
                .map_err(|e| bad(spacing_field, format!("axis {k}: {e}")))?,
        );
    }
    let [ax, ay, az]: [Axis; 3] = axes
        .try_into()
        .map_err(|_| bad("sizes", "expected three axes".into()))?;
    let grid = Grid { axes: [ax, ay, az] };
    if let Some(ls) = get("line skip") {
        if ls != "0" {
            return Err(bad(
                "line skip",
                format!("{ls:?}, expected 0 (skipping lines is not supported)"),
            ));
        }
    }
    // `byte skip`: a byte count, or -1 (raw only): the samples end the
    // file. Resolved against the data file's length below.
    let skip_given: Option<u64> = match get("byte skip") {
        None => Some(0),
        Some("-1") if gzip => {
            return Err(bad(
                "byte skip",
                "-1 (the samples end the file) is allowed for raw encoding only, \
                 expected a byte count >= 0 for gzip"
                    .into(),
            ))
        }
        Some("-1") => None,
        Some(v) => Some(v.parse::<u64>().map_err(|_| {
            bad(
                "byte skip",
                format!(
                    "{v:?}, expected a byte count >= 0, or -1 (the samples end the file, \
                     raw encoding only)"
                ),
            )
        })?),
    };
    let (data, file_offset) = match get("data file").or(get("datafile")) {
        None if attached => (path.to_path_buf(), consumed),
        None => {
            return Err(bad(
                "data file",
                "missing, and no data follows the header (no empty line)".into(),
            ))
        }
        Some(v) => {
            if v.trim().is_empty() {
                return Err(bad("data file", "empty, expected a file name".into()));
            }
            if v.starts_with("LIST") || v.split_whitespace().count() > 1 {
                return Err(bad(
                    "data file",
                    format!("{v:?}: lists of data files are not supported, expected one file name"),
                ));
            }
            let dir = path.parent().unwrap_or(Path::new("."));
            (dir.join(v), 0)
        }
    };
    let byte_skip = if gzip {
        // In the decompressed stream: checked as it is read (gz.rs).
        skip_given.unwrap_or(0)
    } else {
        raw_skip(path, &data, file_offset, skip_given, dims, dtype)?
    };
    Ok(NrrdHeader {
        dims,
        dtype,
        endian,
        grid,
        data,
        file_offset,
        skip: byte_skip,
        gzip,
        orientation,
    })
}

/// The `byte skip` of raw data in `data` (whose samples start after
/// `file_offset` bytes of attached header): the one given, checked against
/// the file's length, or for -1 (`given` is `None`) the one that puts the
/// samples at the end of the file. A data file that cannot be examined is
/// left for the raw reader to report (it names the file and the field).
fn raw_skip(
    path: &Path,
    data: &Path,
    file_offset: u64,
    given: Option<u64>,
    dims: [usize; 3],
    dtype: Dtype,
) -> Result<u64, InputError> {
    let bad = |msg: String| InputError::field(path, "byte skip", msg);
    let len = match std::fs::metadata(data) {
        Ok(m) => Some(m.len()),
        Err(_) if given.is_some() => None,
        Err(source) => {
            return Err(InputError::DataFile {
                path: data.to_path_buf(),
                sidecar: path.to_path_buf(),
                field: "data file".into(),
                what: "cannot open data file",
                source,
            })
        }
    };
    let Some(len) = len else {
        return Ok(given.unwrap_or(0));
    };
    let after_header = len.saturating_sub(file_offset);
    match given {
        Some(skip) => {
            if skip > after_header {
                return Err(bad(format!(
                    "{skip} bytes, past the end of {} ({after_header} bytes{})",
                    data.display(),
                    if file_offset > 0 {
                        " after the header"
                    } else {
                        ""
                    }
                )));
            }
            Ok(skip)
        }
        None => {
            let need = dims
                .iter()
                .try_fold(dtype.size() as u64, |acc, &d| acc.checked_mul(d as u64));
            match need {
                Some(need) if need <= after_header => Ok(after_header - need),
                _ => Err(bad(format!(
                    "-1 (the samples end the file), but {} holds {after_header} bytes{}, \
                     fewer than the {} x {} x {} samples of {} need",
                    data.display(),
                    if file_offset > 0 {
                        " after the header"
                    } else {
                        ""
                    },
                    dims[0],
                    dims[1],
                    dims[2],
                    dtype.name()
                ))),
            }
        }
    }
}

fn dtype_of(t: &str) -> Option<Dtype> {
    let t = t.to_ascii_lowercase();
    Some(match t.as_str() {
        "signed char" | "int8" | "int8_t" => Dtype::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Dtype::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            Dtype::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Dtype::U16,
        "int" | "signed int" | "int32" | "int32_t" => Dtype::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Dtype::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Dtype::I64,
        "float" => Dtype::F32,
        "double" => Dtype::F64,
        _ => return None,
    })
}

/// `(a,b,c)` as three finite numbers.
fn vector(s: &str) -> Option<[f64; 3]> {
    let inner = s.trim().strip_prefix('(')?.strip_suffix(')')?;
    let v: Vec<f64> = inner
        .split(',')
        .map(|x| x.trim().parse::<f64>().ok().filter(|f| f.is_finite()))
        .collect::<Option<_>>()?;
    v.try_into().ok()
}

/// Spacing per axis from `space directions` (axis-aligned vectors) or
/// `spacings`, each checked by [`check_spacing`], and the field it came
/// from.
fn spacings(
    fields: &BTreeMap<String, String>,
    path: &Path,
) -> Result<([f64; 3], &'static str), InputError> {
    let bad = |field: &str, msg: String| InputError::field(path, field, msg);
    if let Some(v) = fields.get("space directions") {
        let field = "space directions";
        let vs: Vec<&str> = v.split_whitespace().collect();
        if vs.len() != 3 {
            return Err(bad(
                field,
                format!("{} vectors, expected 3 of the form (x,y,z)", vs.len()),
            ));
        }
        let mut out = [0.0; 3];
        for (k, s) in vs.iter().enumerate() {
            let d = vector(s).ok_or_else(|| {
                bad(
                    field,
                    format!("axis {k}: {s:?}, expected (x,y,z) in finite numbers"),
                )
            })?;
            let off: f64 = (0..3).filter(|&j| j != k).map(|j| d[j].abs()).sum();
            if off != 0.0 || d[k] == 0.0 {
                return Err(bad(
                    field,
                    format!(
                        "axis {k}: {s} is not along axis {k}; oblique or permuted volumes \
                         are not supported (cdvol does not resample): reslice the volume first"
                    ),
                ));
            }
            out[k] = check_spacing(d[k].abs()).map_err(|e| bad(field, format!("axis {k}: {e}")))?;
        }
        return Ok((out, field));
    }
    if let Some(v) = fields.get("spacings") {
        let field = "spacings";
        let s: Vec<f64> = v
            .split_whitespace()
            .map(|x| x.parse::<f64>().ok())
            .collect::<Option<_>>()
            .ok_or_else(|| bad(field, format!("{v:?}, expected three numbers (mm)")))?;
        let s: [f64; 3] = s
            .try_into()
            .map_err(|_| bad(field, format!("{v:?}, expected three numbers (mm)")))?;
        let mut out = [0.0; 3];
        for k in 0..3 {
            out[k] = check_spacing(s[k].abs()).map_err(|e| bad(field, format!("axis {k}: {e}")))?;
        }
        return Ok((out, field));
    }
    Err(bad(
        "space directions",
        "missing (and no `spacings`): the sample spacing is unknown".into(),
    ))
}

/// The patient orientation from `space` and the signs of the
/// (axis-aligned, already checked by [`spacings`]) `space directions`.
fn orientation(
    fields: &BTreeMap<String, String>,
    path: &Path,
) -> Result<Option<Orientation>, InputError> {
    // The sign that turns each space axis into LPS.
    let to_lps = match fields
        .get("space")
        .map(|s| s.to_ascii_lowercase())
        .as_deref()
    {
        Some("left-posterior-superior" | "lps") => [1.0, 1.0, 1.0],
        Some("right-anterior-superior" | "ras") => [-1.0, -1.0, 1.0],
        Some("left-anterior-superior" | "las") => [1.0, -1.0, 1.0],
        _ => return Ok(None),
    };
    let Some(v) = fields.get("space directions") else {
        return Ok(None);
    };
    let mut axes = [[0.0; 3]; 3];
    for (k, s) in v.split_whitespace().enumerate().take(3) {
        let d = vector(s).unwrap_or([0.0; 3]);
        axes[k] = std::array::from_fn(|j| d[j] * to_lps[j]);
    }
    Orientation::from_lps(axes, "NRRD space directions")
        .map(Some)
        .map_err(|e| InputError::field(path, "space directions", e.to_string()))
}
