//! Inputs: everything that turns a scan on disk into a stream of z slices.
//!
//! First stage of the pipeline. A [`SliceSource`] knows the grid (three
//! axes in mm), the sample type and the rescale, and hands out one z slice
//! of raw sample values at a time. Nothing downstream knows the file format.
//! Today the raw stack with a JSON sidecar ([`sidecar`]) implements it.

pub mod array;
pub mod describe;
pub mod dicom;
pub mod gz;
pub mod kind;
pub mod nifti;
pub mod nrrd;
pub mod raw;
pub mod sidecar;
pub mod tiff;

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::grid::Grid;

/// Sample type of an input stack (and of the stored words).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dtype {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    I64,
    F32,
    F64,
}

impl Dtype {
    /// The names a sidecar may use (`i64` is a storage type only).
    pub const SIDECAR_NAMES: &'static str = "u8, i8, u16, i16, u32, i32, f32, f64";

    /// Parses a sidecar dtype name.
    pub fn from_sidecar_name(s: &str) -> Option<Dtype> {
        Some(match s {
            "u8" => Dtype::U8,
            "i8" => Dtype::I8,
            "u16" => Dtype::U16,
            "i16" => Dtype::I16,
            "u32" => Dtype::U32,
            "i32" => Dtype::I32,
            "f32" => Dtype::F32,
            "f64" => Dtype::F64,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Dtype::U8 => "u8",
            Dtype::I8 => "i8",
            Dtype::U16 => "u16",
            Dtype::I16 => "i16",
            Dtype::U32 => "u32",
            Dtype::I32 => "i32",
            Dtype::I64 => "i64",
            Dtype::F32 => "f32",
            Dtype::F64 => "f64",
        }
    }

    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            Dtype::U8 | Dtype::I8 => 1,
            Dtype::U16 | Dtype::I16 => 2,
            Dtype::U32 | Dtype::I32 | Dtype::F32 => 4,
            Dtype::I64 | Dtype::F64 => 8,
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, Dtype::F32 | Dtype::F64)
    }

    /// Smallest and largest representable integer value (floats: infinite).
    pub fn int_range(self) -> (i64, i64) {
        match self {
            Dtype::U8 => (0, u8::MAX as i64),
            Dtype::I8 => (i8::MIN as i64, i8::MAX as i64),
            Dtype::U16 => (0, u16::MAX as i64),
            Dtype::I16 => (i16::MIN as i64, i16::MAX as i64),
            Dtype::U32 => (0, u32::MAX as i64),
            Dtype::I32 => (i32::MIN as i64, i32::MAX as i64),
            Dtype::I64 => (i64::MIN, i64::MAX),
            Dtype::F32 | Dtype::F64 => (i64::MIN, i64::MAX),
        }
    }

    /// The next wider integer type, used when a type has no spare range
    /// for distance codes.
    pub fn widened(self) -> Dtype {
        match self {
            Dtype::U8 | Dtype::I8 => Dtype::I16,
            Dtype::U16 | Dtype::I16 => Dtype::I32,
            Dtype::U32 | Dtype::I32 | Dtype::I64 => Dtype::I64,
            f => f,
        }
    }
}

/// Byte order of the samples in the input files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Endian {
    Little,
    Big,
}

/// `value = raw * slope + intercept` (HU for CT).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rescale {
    pub slope: f64,
    pub intercept: f64,
}

impl Rescale {
    pub const IDENTITY: Rescale = Rescale {
        slope: 1.0,
        intercept: 0.0,
    };

    #[inline]
    pub fn apply(&self, raw: f64) -> f64 {
        raw * self.slope + self.intercept
    }
}

/// What a source knows about its volume.
#[derive(Debug, Clone, PartialEq)]
pub struct VolumeMeta {
    pub grid: Grid,
    pub dtype: Dtype,
    pub rescale: Rescale,
    /// Where the volume came from (for error messages and the header).
    pub origin_desc: String,
    /// Which way the sample axes point in the patient; `None` when the
    /// input does not say.
    pub orientation: Option<crate::orient::Orientation>,
}

impl VolumeMeta {
    pub fn dims(&self) -> [usize; 3] {
        self.grid.dims()
    }
}

/// Opens any supported input by its name: a directory of DICOM files (one
/// series) or of TIFF slices, a multi-page TIFF, a raw-stack sidecar
/// (`.json`), NRRD (`.nrrd`, `.nhdr`) or NIfTI-1 (`.nii`, `.nii.gz`). Anything else that is not a regular file
/// (a FIFO, socket or device) is refused without being opened.
pub fn open(path: &std::path::Path) -> Result<Box<dyn SliceSource>, InputError> {
    open_with(path, None)
}

/// [`open`], picking DICOM series `series` when a directory holds several.
pub fn open_with(
    path: &std::path::Path,
    series: Option<&str>,
) -> Result<Box<dyn SliceSource>, InputError> {
    // By type before anything is opened: a FIFO would block the open.
    let m = std::fs::metadata(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot open the input",
        source,
    })?;
    if m.is_dir() {
        // A directory of TIFF slices, else a DICOM series.
        let has_tiff = std::fs::read_dir(path)
            .map(|rd| rd.flatten().any(|e| tiff::is_tiff_name(&e.path())))
            .unwrap_or(false);
        if has_tiff && series.is_none() {
            return Ok(Box::new(tiff::TiffSource::open_dir(path)?));
        }
        return Ok(Box::new(dicom::open_dir(path, series)?));
    }
    crate::fsutil::check_regular(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        what: "expected a volume file or a DICOM directory",
        source,
    })?;
    // By content, not by name (kind.rs).
    let kind = kind::sniff(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot read the input",
        source,
    })?;
    match kind {
        kind::Kind::Nrrd => nrrd::open(path),
        kind::Kind::Nifti => nifti::open(path),
        kind::Kind::Sidecar if tiff::TiffSource::is_sidecar(path) => {
            Ok(Box::new(tiff::TiffSource::open_sidecar(path)?))
        }
        kind::Kind::Sidecar => Ok(Box::new(raw::RawSource::open(path)?)),
        kind::Kind::Tiff => Ok(Box::new(tiff::TiffSource::open_file(path)?)),
        kind::Kind::Packed => Err(InputError::Unsupported {
            path: path.to_path_buf(),
            what: "a cdvol packed file, already prepared (render, info or export it)",
        }),
        kind::Kind::Unsupported(what) => Err(InputError::Unsupported {
            path: path.to_path_buf(),
            what,
        }),
    }
}

/// A volume that streams its z slices.
pub trait SliceSource: Send + Sync {
    fn meta(&self) -> &VolumeMeta;

    /// Fills `out` (`nx * ny` entries, x fastest) with the raw sample values
    /// of slice `z`, before rescale. Integers are exact in f64; float NaNs
    /// are passed through.
    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError>;

    /// Lines worth telling the user about the input (a DICOM series' z
    /// spacing, say); none by default.
    fn report(&self) -> Vec<String> {
        Vec::new()
    }

    /// The modality the input states, as it states it (`CT`, `MR`, ...),
    /// with where it says so (`DICOM Modality (0008,0060)`); `None` when
    /// it does not say (NIfTI and NRRD have no such field).
    fn modality(&self) -> Option<(String, String)> {
        None
    }

    /// Every file the source reads: the header or sidecar, then the data
    /// files it names (or a DICOM series' slices). Prep refuses an output
    /// that is one of them.
    fn files(&self) -> Vec<PathBuf>;
}

/// Errors while reading an input volume. Each names the file and, where
/// one is at fault, the field and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// An array given in memory (the Python package's numpy arrays) has
    /// a bad shape, dtype or strides.
    #[error("array {name}: {field}: {msg}")]
    Array {
        name: String,
        field: String,
        msg: String,
    },
    /// A sidecar field is missing or has a bad value.
    #[error("{}: field `{field}`: {msg}", path.display())]
    Field {
        path: PathBuf,
        field: String,
        msg: String,
    },
    /// The sidecar is not valid JSON.
    #[error("{}: not valid JSON: {source}", path.display())]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// A data file is shorter than the sidecar says it must be.
    #[error(
        "{}: file is {actual} bytes, expected at least {expected} \
         ({why}; from sidecar {})",
        path.display(),
        sidecar.display()
    )]
    TooShort {
        path: PathBuf,
        sidecar: PathBuf,
        actual: u64,
        expected: u64,
        why: String,
    },
    /// A data file named in the sidecar cannot be opened or mapped.
    #[error(
        "{}: {what} (named in field `{field}` of {}): {source}",
        path.display(),
        sidecar.display()
    )]
    DataFile {
        path: PathBuf,
        sidecar: PathBuf,
        field: String,
        what: &'static str,
        source: std::io::Error,
    },
    /// A file is larger than its kind may be (a sidecar, say); refused
    /// before it is read.
    #[error("{}: {what} is {actual} bytes, expected at most {limit} bytes", path.display())]
    TooLarge {
        path: PathBuf,
        what: &'static str,
        /// The size found (`more than N` when read through a bound).
        actual: String,
        limit: u64,
    },
    /// A file of a kind cdvol does not read, named by its content.
    #[error("{}: {what}: {}", path.display(), kind::READS)]
    Unsupported { path: PathBuf, what: &'static str },
    /// An I/O error on a named file.
    #[error("{}: {what}: {source}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        source: std::io::Error,
    },
    /// The DICOM series asked for (by SeriesInstanceUID) is not in the
    /// directory.
    #[error(
        "{}: SeriesInstanceUID {uid} is not here; the series are: {}",
        path.display(),
        available.join(", ")
    )]
    NoSuchSeries {
        path: PathBuf,
        uid: String,
        available: Vec<String>,
    },
    /// A directory holds several DICOM series and none was chosen.
    #[error(
        "{}: {} series in one directory: {}; choose one by its SeriesInstanceUID",
        path.display(),
        series.len(),
        series.join(", ")
    )]
    SeveralSeries {
        path: PathBuf,
        /// `UID (N slices)` for each series.
        series: Vec<String>,
    },
}

impl InputError {
    pub(crate) fn field(
        path: &std::path::Path,
        field: impl Into<String>,
        msg: impl Into<String>,
    ) -> InputError {
        InputError::Field {
            path: path.to_path_buf(),
            field: field.into(),
            msg: msg.into(),
        }
    }
}
