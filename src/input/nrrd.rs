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
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use super::gz::{GzLayout, GzSource};
use super::raw::RawSource;
use super::sidecar::{DataFiles, Sidecar};
use super::{Dtype, Endian, InputError, Rescale, SliceSource, VolumeMeta};
use crate::grid::{Axis, Grid};
use crate::orient::Orientation;

/// Headers longer than this are refused (a real one is a few hundred bytes).
const MAX_HEADER: u64 = 1 << 20;

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
        };
        Ok(Box::new(GzSource::open(meta, layout)?))
    } else {
        let sidecar = Sidecar {
            path: path.to_path_buf(),
            data: DataFiles::One(h.data),
            dims: h.dims,
            dtype: h.dtype,
            endian: h.endian,
            header_bytes: h.file_offset + h.skip,
            grid: h.grid,
            rescale: Rescale::IDENTITY,
            orientation: h.orientation,
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
    /// stream for gzip).
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
    let mut r = BufReader::new(f);
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
    let sizes: Vec<usize> = need("sizes")?
        .split_whitespace()
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad("sizes", "expected three whole numbers".into()))?;
    let dims: [usize; 3] = sizes
        .clone()
        .try_into()
        .map_err(|_| bad("sizes", format!("{} numbers, expected 3", sizes.len())))?;
    if let Some(d) = dims.iter().find(|&&d| d < 2) {
        return Err(bad(
            "sizes",
            format!("{d} samples, expected at least 2 per axis"),
        ));
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
    let spacing = spacings(&fields, path)?;
    let orientation = orientation(&fields, path)?;
    let origin = match get("space origin") {
        Some(v) => vector(v).ok_or_else(|| {
            bad(
                "space origin",
                format!("{v:?}, expected (x,y,z) in finite numbers"),
            )
        })?,
        None => [0.0; 3],
    };
    let mut axes = Vec::with_capacity(3);
    for k in 0..3 {
        axes.push(
            Axis::uniform(origin[k], spacing[k], dims[k])
                .map_err(|e| bad("spacing", format!("axis {k}: {e}")))?,
        );
    }
    let grid = Grid {
        axes: axes.try_into().expect("three axes"),
    };
    if let Some(ls) = get("line skip") {
        if ls != "0" {
            return Err(bad("line skip", format!("{ls}, only 0 is supported")));
        }
    }
    let byte_skip = match get("byte skip") {
        None => 0,
        Some(v) => v.parse::<u64>().map_err(|_| {
            bad(
                "byte skip",
                format!("{v:?}, expected a byte count >= 0 (-1 is not supported)"),
            )
        })?,
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
/// `spacings`.
fn spacings(fields: &BTreeMap<String, String>, path: &Path) -> Result<[f64; 3], InputError> {
    let bad = |field: &str, msg: String| InputError::field(path, field, msg);
    if let Some(v) = fields.get("space directions") {
        let vs: Vec<&str> = v.split_whitespace().collect();
        if vs.len() != 3 {
            return Err(bad(
                "space directions",
                format!("{} vectors, expected 3 of the form (x,y,z)", vs.len()),
            ));
        }
        let mut out = [0.0; 3];
        for (k, s) in vs.iter().enumerate() {
            let d = vector(s).ok_or_else(|| {
                bad(
                    "space directions",
                    format!("axis {k}: {s:?}, expected (x,y,z) in finite numbers"),
                )
            })?;
            let off: f64 = (0..3).filter(|&j| j != k).map(|j| d[j].abs()).sum();
            if off != 0.0 || d[k] == 0.0 {
                return Err(bad(
                    "space directions",
                    format!(
                        "axis {k}: {s} is not along axis {k}; oblique or permuted volumes \
                         are not supported (cdvol does not resample): reslice the volume first"
                    ),
                ));
            }
            out[k] = d[k].abs();
        }
        return Ok(out);
    }
    if let Some(v) = fields.get("spacings") {
        let s: Vec<f64> = v
            .split_whitespace()
            .map(|x| x.parse::<f64>().ok().filter(|f| f.is_finite() && *f != 0.0))
            .collect::<Option<_>>()
            .ok_or_else(|| {
                bad(
                    "spacings",
                    format!("{v:?}, expected three non-zero finite numbers"),
                )
            })?;
        let s: [f64; 3] = s
            .try_into()
            .map_err(|_| bad("spacings", format!("{v:?}, expected three numbers")))?;
        return Ok(s.map(f64::abs));
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
