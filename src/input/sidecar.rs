//! The JSON sidecar that describes a raw stack (the contract in
//! docs/FORMAT.md, "Raw stack sidecar"). Parsed by hand from a
//! `serde_json::Value` so that every refusal names the field at fault.
//!
//! Axis conventions: a number is a uniform spacing starting at `origin`;
//! `{"spacing": [...]}` gives the `n - 1` gaps starting at `origin`;
//! `{"positions": [...]}` gives absolute positions (the origin is ignored
//! for that axis, as DICOM positions are absolute).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::{Dtype, Endian, InputError, Rescale};
use crate::grid::{Axis, Grid};

/// A sidecar after checking, before any data file is opened.
#[derive(Debug, Clone, PartialEq)]
pub struct Sidecar {
    /// The sidecar's own path.
    pub path: PathBuf,
    /// One file, or one file per z slice, resolved against the sidecar.
    pub data: DataFiles,
    pub dims: [usize; 3],
    pub dtype: Dtype,
    pub endian: Endian,
    pub header_bytes: u64,
    pub grid: Grid,
    pub rescale: Rescale,
    /// Optional key `orientation`: which way the axes point in the patient.
    pub orientation: Option<crate::orient::Orientation>,
    /// Optional key `modality`: `"CT"` or `"MR"`.
    pub modality: Option<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum DataFiles {
    One(PathBuf),
    PerSlice(Vec<PathBuf>),
}

/// How one axis is written in a sidecar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum AxisSpec {
    Uniform(f64),
    Positions { positions: Vec<f64> },
    Spacing { spacing: Vec<f64> },
}

/// A sidecar as other tools write it; used by the writers in this crate
/// (phantoms, export) so they produce exactly the documented schema.
#[derive(Debug, Clone, Serialize)]
pub struct SidecarOut {
    pub data: String,
    pub dims: [usize; 3],
    pub dtype: &'static str,
    pub endian: Endian,
    pub header_bytes: u64,
    pub x: AxisSpec,
    pub y: AxisSpec,
    pub z: AxisSpec,
    pub origin: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rescale: Option<Rescale>,
}

impl SidecarOut {
    /// Axis specs for a grid: uniform axes as a number, others as positions.
    pub fn axes_of(grid: &Grid) -> ([AxisSpec; 3], [f64; 3]) {
        let origin = grid.axes.each_ref().map(|a| a.coords()[0]);
        let spec = |a: &Axis| {
            if a.is_uniform() {
                AxisSpec::Uniform((a.coords()[a.cells()] - a.coords()[0]) / a.cells() as f64)
            } else {
                AxisSpec::Positions {
                    positions: a.coords().to_vec(),
                }
            }
        };
        (grid.axes.each_ref().map(spec), origin)
    }
}

const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// Smallest spacing a sidecar may give, in mm: the one every reader
/// checks ([`crate::grid::check_spacing`]).
pub use crate::grid::MIN_SPACING_MM;

/// Largest sidecar file read, in bytes (64 MiB): checked on the file's
/// size before it is read, and the read stops there (a FIFO has no size).
/// A sidecar listing a position and a file name for each of a million
/// slices stays far below it.
pub const MAX_SIDECAR_BYTES: u64 = 64 << 20;

/// The text of the sidecar at `path`, refused by its size before it is
/// read and read through a bounded reader.
pub(crate) fn read_bounded(path: &Path) -> Result<String, InputError> {
    use std::io::Read;
    let io = |source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot read sidecar",
        source,
    };
    let too_big = |actual: String| InputError::TooLarge {
        path: path.to_path_buf(),
        what: "the sidecar",
        actual,
        limit: MAX_SIDECAR_BYTES,
    };
    let f = crate::fsutil::open_regular(path).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    if len > MAX_SIDECAR_BYTES {
        return Err(too_big(len.to_string()));
    }
    let mut b = Vec::with_capacity(len as usize);
    f.take(MAX_SIDECAR_BYTES + 1)
        .read_to_end(&mut b)
        .map_err(io)?;
    if b.len() as u64 > MAX_SIDECAR_BYTES {
        return Err(too_big(format!("more than {MAX_SIDECAR_BYTES}")));
    }
    String::from_utf8(b).map_err(|e| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            e.utf8_error(),
        ))
    })
}

/// Reads and checks a sidecar. Data files are not opened here.
pub fn parse_sidecar(path: &Path) -> Result<Sidecar, InputError> {
    let obj = read_object(path)?;
    let obj = &obj;
    let err = |field: &str, msg: String| InputError::field(path, field, msg);
    let get = |field: &str| obj.get(field).filter(|v| !v.is_null());

    // dims
    let dims_v = get("dims").ok_or_else(|| err("dims", "missing; expected [nx, ny, nz]".into()))?;
    let dims_a = dims_v
        .as_array()
        .filter(|a| a.len() == 3)
        .ok_or_else(|| err("dims", format!("{dims_v}, expected [nx, ny, nz]")))?;
    let mut dims = [0usize; 3];
    for (i, d) in dims_a.iter().enumerate() {
        let n = d.as_u64().ok_or_else(|| {
            err(
                &format!("dims[{i}]"),
                format!("{d}, expected a whole number >= 2"),
            )
        })?;
        if n < 2 {
            return Err(err(
                &format!("dims[{i}]"),
                format!(
                    "{n} samples along {}, expected at least 2 (one cell)",
                    AXIS_NAMES[i]
                ),
            ));
        }
        if n > crate::grid::MAX_SAMPLES_PER_AXIS as u64 {
            return Err(err(
                &format!("dims[{i}]"),
                format!(
                    "{n}, expected at most {}",
                    crate::grid::MAX_SAMPLES_PER_AXIS
                ),
            ));
        }
        dims[i] = n as usize;
    }

    // dtype, endian, header_bytes
    let dtype_v = get("dtype").ok_or_else(|| {
        err(
            "dtype",
            format!("missing; expected one of {}", Dtype::SIDECAR_NAMES),
        )
    })?;
    let dtype = dtype_v
        .as_str()
        .and_then(Dtype::from_sidecar_name)
        .ok_or_else(|| {
            err(
                "dtype",
                format!("{dtype_v}, expected one of {}", Dtype::SIDECAR_NAMES),
            )
        })?;
    let endian = match get("endian") {
        None => Endian::Little,
        Some(Value::String(s)) if s == "little" => Endian::Little,
        Some(Value::String(s)) if s == "big" => Endian::Big,
        Some(e) => {
            return Err(err(
                "endian",
                format!("{e}, expected \"little\" or \"big\""),
            ))
        }
    };
    let header_bytes = match get("header_bytes") {
        None => 0,
        Some(h) => h
            .as_u64()
            .ok_or_else(|| err("header_bytes", format!("{h}, expected a whole number >= 0")))?,
    };

    // origin
    let origin = parse_origin(path, get("origin"))?;

    // axes
    let mut axes = Vec::with_capacity(3);
    for (i, name) in AXIS_NAMES.iter().enumerate() {
        axes.push(parse_axis(path, name, get(name), dims[i], origin[i])?);
    }
    let axes: [Axis; 3] = axes.try_into().expect("three axes");

    // rescale
    let rescale = match get("rescale") {
        None => Rescale::IDENTITY,
        Some(r) => {
            let num = |k: &str, default: f64| -> Result<f64, InputError> {
                match r.get(k) {
                    None => Ok(default),
                    Some(x) => x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                        err(
                            &format!("rescale.{k}"),
                            format!("{x}, expected a finite number"),
                        )
                    }),
                }
            };
            if !r.is_object() {
                return Err(err(
                    "rescale",
                    format!("{r}, expected {{\"slope\": s, \"intercept\": i}}"),
                ));
            }
            let slope = num("slope", 1.0)?;
            if slope == 0.0 {
                return Err(err("rescale.slope", "0, expected a non-zero number".into()));
            }
            Rescale {
                slope,
                intercept: num("intercept", 0.0)?,
            }
        }
    };

    // data
    let base = path.parent().unwrap_or(Path::new("."));
    let data_v = get("data").ok_or_else(|| {
        err(
            "data",
            "missing; expected a file name or a list of one file per z slice".into(),
        )
    })?;
    let data = match data_v {
        Value::String(s) => DataFiles::One(base.join(s)),
        Value::Array(list) => {
            if list.len() != dims[2] {
                return Err(err(
                    "data",
                    format!(
                        "{} files, expected one per z slice ({} = dims[2])",
                        list.len(),
                        dims[2]
                    ),
                ));
            }
            let mut files = Vec::with_capacity(list.len());
            for (i, f) in list.iter().enumerate() {
                let s = f.as_str().ok_or_else(|| {
                    err(&format!("data[{i}]"), format!("{f}, expected a file name"))
                })?;
                files.push(base.join(s));
            }
            DataFiles::PerSlice(files)
        }
        other => {
            return Err(err(
                "data",
                format!("{other}, expected a file name or a list of file names"),
            ))
        }
    };

    Ok(Sidecar {
        path: path.to_path_buf(),
        data,
        dims,
        dtype,
        endian,
        header_bytes,
        grid: Grid { axes },
        rescale,
        orientation: parse_orientation(path, get("orientation"))?,
        modality: match get("modality") {
            None | Some(Value::Null) => None,
            Some(Value::String(m)) if matches!(m.to_ascii_uppercase().as_str(), "CT" | "MR") => {
                Some(m.to_ascii_uppercase())
            }
            Some(v) => return Err(err("modality", format!("{v}, expected \"CT\" or \"MR\""))),
        },
    })
}

/// A sidecar's JSON object: read within the size bound, parsed, and
/// refused when a key is repeated or the top level is not an object.
pub(crate) fn read_object(path: &Path) -> Result<serde_json::Map<String, Value>, InputError> {
    let text = read_bounded(path)?;
    let v: Value = serde_json::from_str(&text).map_err(|source| InputError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    if let Some(key) = crate::json::duplicate_key(&text) {
        return Err(InputError::field(
            path,
            key,
            "duplicate key, expected each key once",
        ));
    }
    match v {
        Value::Object(m) => Ok(m),
        _ => Err(InputError::field(
            path,
            "(top level)",
            "expected a JSON object",
        )),
    }
}

/// Key `origin`: `[x, y, z]` in mm, `[0, 0, 0]` when absent.
pub(crate) fn parse_origin(path: &Path, o: Option<&Value>) -> Result<[f64; 3], InputError> {
    let Some(o) = o else {
        return Ok([0.0; 3]);
    };
    let a = o.as_array().filter(|a| a.len() == 3).ok_or_else(|| {
        InputError::field(path, "origin", format!("{o}, expected [x, y, z] in mm"))
    })?;
    let mut out = [0.0; 3];
    for (i, c) in a.iter().enumerate() {
        out[i] = c.as_f64().filter(|c| c.is_finite()).ok_or_else(|| {
            InputError::field(
                path,
                format!("origin[{i}]"),
                format!("{c}, expected a finite number (mm)"),
            )
        })?;
    }
    Ok(out)
}

pub(crate) fn parse_axis(
    path: &Path,
    name: &str,
    v: Option<&Value>,
    n: usize,
    origin: f64,
) -> Result<Axis, InputError> {
    let expected = "expected a spacing in mm, {\"positions\": [...]} or {\"spacing\": [...]}";
    let v = v.ok_or_else(|| InputError::field(path, name, format!("missing; {expected}")))?;
    let numbers = |field: &str, a: &Value, want: usize| -> Result<Vec<f64>, InputError> {
        let a = a.as_array().ok_or_else(|| {
            InputError::field(path, field, format!("{a}, expected a list of numbers"))
        })?;
        if a.len() != want {
            return Err(InputError::field(
                path,
                field,
                format!(
                    "{} entries, expected {want} (from dims = {n} samples)",
                    a.len()
                ),
            ));
        }
        a.iter()
            .enumerate()
            .map(|(i, x)| {
                x.as_f64().ok_or_else(|| {
                    InputError::field(
                        path,
                        format!("{field}[{i}]"),
                        format!("{x}, expected a number"),
                    )
                })
            })
            .collect()
    };
    // The mean gap of a listed axis: single gaps may be far smaller (slices
    // 1e-9 mm apart render, data_extremes::slices_1e_9_apart_at_1e6), but
    // an axis that is all tiny gaps is a mistake that renders nothing.
    let mean_gap = |field: &str, c: &[f64]| -> Result<(), InputError> {
        let (Some(first), Some(last)) = (c.first(), c.last()) else {
            return Ok(());
        };
        let mean = (last - first) / (c.len() - 1).max(1) as f64;
        if c.len() > 1 && mean < MIN_SPACING_MM {
            return Err(InputError::field(
                path,
                field,
                format!(
                    "from {first} to {last} mm, a mean gap of {mean:e} mm, \
                     expected a mean gap >= {MIN_SPACING_MM:e} mm"
                ),
            ));
        }
        Ok(())
    };
    let axis_err =
        |field: &str, p: crate::grid::AxisError| InputError::field(path, field, p.to_string());
    match v {
        Value::Number(_) => {
            let s = crate::grid::check_spacing(v.as_f64().unwrap_or(f64::NAN))
                .map_err(|e| InputError::field(path, name, e.to_string()))?;
            Axis::uniform(origin, s, n).map_err(|p| axis_err(name, p))
        }
        Value::Object(o) => {
            if o.contains_key("positions") && o.contains_key("spacing") {
                return Err(InputError::field(
                    path,
                    name,
                    "both positions and spacing given, expected one of them",
                ));
            }
            if let Some(p) = o.get("positions") {
                let field = format!("{name}.positions");
                let coords = numbers(&field, p, n)?;
                mean_gap(&field, &coords)?;
                Axis::from_coords(coords).map_err(|e| axis_err(&field, e))
            } else if let Some(s) = o.get("spacing") {
                let field = format!("{name}.spacing");
                let gaps = numbers(&field, s, n - 1)?;
                let mut coords = Vec::with_capacity(n);
                coords.push(origin);
                for (i, g) in gaps.iter().enumerate() {
                    if !(g.is_finite() && *g > 0.0) {
                        return Err(InputError::field(
                            path,
                            format!("{field}[{i}]"),
                            format!("gap {g} mm, expected a finite gap > 0"),
                        ));
                    }
                    coords.push(coords[i] + g);
                }
                mean_gap(&field, &coords)?;
                Axis::from_coords(coords).map_err(|e| axis_err(&field, e))
            } else {
                Err(InputError::field(path, name, format!("{v}, {expected}")))
            }
        }
        _ => Err(InputError::field(path, name, format!("{v}, {expected}"))),
    }
}

/// The optional `orientation` key: a code such as `"LPS"` or `"RAS"` (the
/// patient direction of +x, +y, +z), or `{"lps": [[..], [..], [..]]}` or
/// `{"ras": ...}`, the three axis directions. Absent: unknown.
fn parse_orientation(
    path: &Path,
    v: Option<&Value>,
) -> Result<Option<crate::orient::Orientation>, InputError> {
    use crate::orient::Orientation;
    const SOURCE: &str = "sidecar orientation";
    let expected = "expected a code such as \"LPS\" or \"RAS\", or {\"lps\": [[x], [y], [z]]} \
                    with the directions of the three axes";
    let bad = |field: &str, msg: String| InputError::field(path, field, msg);
    let Some(v) = v else { return Ok(None) };
    let o = match v {
        Value::String(code) => Orientation::from_code(code, SOURCE),
        Value::Object(o) if o.len() == 1 => {
            let (key, m) = o
                .iter()
                .next()
                .ok_or_else(|| bad("orientation", format!("{v}, {expected}")))?;
            let field = format!("orientation.{key}");
            let rows = m
                .as_array()
                .filter(|a| a.len() == 3)
                .ok_or_else(|| bad(&field, format!("{m}, expected three [x, y, z] directions")))?;
            let mut axes = [[0.0; 3]; 3];
            for (k, r) in rows.iter().enumerate() {
                let r = r.as_array().filter(|a| a.len() == 3).ok_or_else(|| {
                    bad(&format!("{field}[{k}]"), format!("{r}, expected [x, y, z]"))
                })?;
                for (j, x) in r.iter().enumerate() {
                    axes[k][j] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                        bad(
                            &format!("{field}[{k}][{j}]"),
                            format!("{x}, expected a finite number"),
                        )
                    })?;
                }
            }
            match key.as_str() {
                "lps" => Orientation::from_lps(axes, SOURCE),
                "ras" => Orientation::from_ras(axes, SOURCE),
                _ => return Err(bad("orientation", format!("key {key:?}, {expected}"))),
            }
        }
        _ => return Err(bad("orientation", format!("{v}, {expected}"))),
    };
    o.map(Some).map_err(|e| bad("orientation", e.to_string()))
}
