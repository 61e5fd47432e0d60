//! DICOM series through dicom-rs (`dicom-object` for the data sets,
//! `dicom-pixeldata` for pixel data in any transfer syntax it decodes).
//!
//! `open_dir` reads the headers of every file under a directory (any
//! names, any order, nested), groups the slices by SeriesInstanceUID,
//! sorts them by their position along the slice normal (the cross product
//! of the two ImageOrientationPatient directions, dotted with
//! ImagePositionPatient) and makes those positions the z axis, rectilinear
//! wherever the spacing varies: no resampling. The row, column and normal
//! directions are recorded as the volume's patient orientation (LPS,
//! crate::orient). Pixel data are decoded one
//! slice at a time, when prep asks for it.
//!
//! Refused, naming the file and the tag: files that start like DICOM but
//! do not parse; several series and none chosen; slices that disagree
//! with the first on Rows, Columns, PixelSpacing, ImageOrientationPatient,
//! BitsAllocated, PixelRepresentation or the rescale; a stack whose slices
//! are displaced off their normal (gantry tilt: it would need resampling);
//! two slices at the same position; multi-frame or colour images; pixel
//! data the decoder cannot decode (the transfer syntax is named); an image
//! of the series without ImagePositionPatient (it would leave a gap);
//! sequences nested deeper than [`MAX_NESTING`], malformed RLE
//! headers and any panic inside dicom-rs (the private module `guard`); a slice
//! larger than the memory limit; a PixelSpacing below
//! [`MIN_SPACING_MM`](crate::grid::MIN_SPACING_MM) and a rescale that
//! is not finite or has slope 0.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, OpenFileOptions};
use dicom_pixeldata::PixelDecoder;

mod guard;

pub use guard::MAX_NESTING;

use super::raw::decode_samples;
use super::{Dtype, Endian, InputError, Rescale, SliceSource, VolumeMeta};
use crate::grid::{Axis, Grid};

/// One slice file's header values.
#[derive(Debug, Clone)]
struct SliceInfo {
    path: PathBuf,
    series: String,
    rows: u32,
    cols: u32,
    /// PixelSpacing: between rows, between columns (mm).
    spacing: [f64; 2],
    orientation: [f64; 6],
    position: [f64; 3],
    bits: u16,
    signed: bool,
    /// Modality (0008,0060), when present.
    modality: Option<String>,
    rescale: [f64; 2],
    frames: u32,
    samples_per_pixel: u16,
}

/// A DICOM series as a slice source.
pub struct DicomSource {
    meta: VolumeMeta,
    /// Slice files in z order.
    files: Vec<PathBuf>,
    slice_bytes: usize,
    report: Vec<String>,
    /// The first slice's Modality.
    modality: Option<String>,
}

impl DicomSource {
    /// Lines on the z spacing for a radiologist: the most common gap and
    /// every place where it differs, between which two files.
    pub fn spacing_report(&self) -> &[String] {
        &self.report
    }
}

fn err(path: &Path, tag: &str, msg: impl Into<String>) -> InputError {
    InputError::field(path, tag, msg)
}

/// Whether the file has the DICOM magic after a 128-byte preamble (never
/// true of a FIFO, socket or device, which are not opened).
pub fn looks_dicom(path: &Path) -> bool {
    sniff(path).unwrap_or(false)
}

/// [`looks_dicom`], with the error when the file cannot be opened or
/// read (a file shorter than the magic is simply not DICOM).
pub fn sniff(path: &Path) -> std::io::Result<bool> {
    use std::io::Read;
    let mut b = [0u8; 132];
    match crate::fsutil::open_regular(path)?.read_exact(&mut b) {
        Ok(()) => Ok(&b[128..132] == b"DICM"),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(false),
        Err(e) => Err(e),
    }
}

/// The regular files under `dir`, each once (fsutil::walk: symlink loops
/// add nothing). Special files are left out (they cannot be DICOM files
/// and are never opened); a subdirectory that cannot be listed is an
/// error, since the series could be incomplete.
fn files_under(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), InputError> {
    let io = |path: &Path, source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot list the directory",
        source,
    };
    let w = crate::fsutil::walk(dir).map_err(|e| io(dir, e))?;
    if let Some((p, e)) = w.unlistable.into_iter().next() {
        return Err(io(&p, e));
    }
    out.extend(w.files);
    Ok(())
}

/// What a file's header says it is.
enum Header {
    /// An image slice with a position.
    Slice(Box<SliceInfo>),
    /// An image (it has Rows) of this series without ImagePositionPatient:
    /// no place in the stack.
    Unplaced { series: String },
    /// DICOMDIR and other non-image objects.
    Other,
}

fn header_of(path: &Path) -> Result<Header, InputError> {
    guard::check_structure(path, true)?;
    let obj = guard::no_panic(path, "file", || {
        OpenFileOptions::new()
            .read_until(tags::PIXEL_DATA)
            .open_file(path)
            .map_err(|e| err(path, "file", format!("not a readable DICOM file: {e}")))
    })?;
    let has = |tag| obj.element_opt(tag).ok().flatten().is_some();
    if !has(tags::IMAGE_POSITION_PATIENT) {
        if !has(tags::ROWS) {
            return Ok(Header::Other);
        }
        let series = obj
            .element_opt(tags::SERIES_INSTANCE_UID)
            .ok()
            .flatten()
            .and_then(|e| {
                e.to_str()
                    .ok()
                    .map(|s| s.trim_end_matches('\0').trim().to_string())
            })
            .unwrap_or_default();
        return Ok(Header::Unplaced { series });
    }
    let s = |tag, name: &str| -> Result<String, InputError> {
        let e = obj.element(tag).map_err(|_| err(path, name, "missing"))?;
        Ok(e.to_str()
            .map_err(|x| err(path, name, format!("{x}")))?
            .trim_end_matches('\0')
            .trim()
            .to_string())
    };
    let floats = |tag, name: &str, n: usize| -> Result<Vec<f64>, InputError> {
        let v = obj
            .element(tag)
            .map_err(|_| err(path, name, "missing"))?
            .to_multi_float64()
            .map_err(|x| err(path, name, format!("{x}")))?;
        if v.len() != n || v.iter().any(|x| !x.is_finite()) {
            return Err(err(
                path,
                name,
                format!("{}, expected {n} finite numbers", numbers(&v)),
            ));
        }
        Ok(v)
    };
    let int = |tag, name: &str, default: Option<i64>| -> Result<i64, InputError> {
        match obj.element_opt(tag).ok().flatten() {
            Some(e) => e
                .to_int::<i64>()
                .map_err(|x| err(path, name, format!("{x}"))),
            None => default.ok_or_else(|| err(path, name, "missing")),
        }
    };
    let opt_float = |tag, name: &str, default: f64| -> Result<f64, InputError> {
        let v = match obj.element_opt(tag).ok().flatten() {
            Some(e) => e
                .to_float64()
                .map_err(|x| err(path, name, format!("{x}")))?,
            None => default,
        };
        if !v.is_finite() || (name == "RescaleSlope" && v == 0.0) {
            let want = if name == "RescaleSlope" {
                "a finite, non-zero number"
            } else {
                "a finite number"
            };
            return Err(err(path, name, format!("{v}, expected {want}")));
        }
        Ok(v)
    };
    // Rows and Columns are US (1..=65535); NumberOfFrames is checked to
    // be 1 later, BitsAllocated against 8, 16 and 32.
    let size = |tag, name: &str, default: Option<i64>| -> Result<u32, InputError> {
        let v = int(tag, name, default)?;
        u32::try_from(v)
            .ok()
            .filter(|&v| (1..=65535).contains(&v))
            .ok_or_else(|| err(path, name, format!("{v}, expected 1 to 65535")))
    };
    let spacing = floats(tags::PIXEL_SPACING, "PixelSpacing", 2)?;
    let min = crate::grid::MIN_SPACING_MM;
    if spacing.iter().any(|&s| s < min) {
        return Err(err(
            path,
            "PixelSpacing",
            format!("{}, expected spacings >= {min:e} mm", numbers(&spacing)),
        ));
    }
    let orientation = floats(
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
        6,
    )?;
    let position = floats(tags::IMAGE_POSITION_PATIENT, "ImagePositionPatient", 3)?;
    let small = |tag, name: &str, default: Option<i64>| -> Result<u16, InputError> {
        let v = int(tag, name, default)?;
        u16::try_from(v).map_err(|_| {
            err(
                path,
                name,
                format!("{v}, expected a number from 0 to 65535"),
            )
        })
    };
    let rows = size(tags::ROWS, "Rows", None)?;
    let cols = size(tags::COLUMNS, "Columns", None)?;
    let bits = small(tags::BITS_ALLOCATED, "BitsAllocated", None)?;
    // Native pixel data are in the file: a file too short for Rows x
    // Columns is refused before a slice of that size is allocated.
    if NATIVE.contains(&obj.meta().transfer_syntax()) {
        let need = rows as u64 * cols as u64 * (bits as u64).div_ceil(8);
        let have = std::fs::metadata(path).map(|m| m.len()).unwrap_or(u64::MAX);
        if have < need {
            return Err(err(
                path,
                "Rows/Columns",
                format!(
                    "{rows} x {cols} samples of {bits} bits need {need} bytes of pixel data, \
                     but the file has {have} bytes"
                ),
            ));
        }
    }
    Ok(Header::Slice(Box::new(SliceInfo {
        path: path.to_path_buf(),
        series: s(tags::SERIES_INSTANCE_UID, "SeriesInstanceUID")?,
        rows,
        cols,
        spacing: [spacing[0], spacing[1]],
        orientation: [0, 1, 2, 3, 4, 5].map(|i| orientation[i]),
        position: [position[0], position[1], position[2]],
        bits,
        signed: int(tags::PIXEL_REPRESENTATION, "PixelRepresentation", Some(0))? == 1,
        modality: s(tags::MODALITY, "Modality").ok().filter(|m| !m.is_empty()),
        rescale: [
            opt_float(tags::RESCALE_SLOPE, "RescaleSlope", 1.0)?,
            opt_float(tags::RESCALE_INTERCEPT, "RescaleIntercept", 0.0)?,
        ],
        frames: size(tags::NUMBER_OF_FRAMES, "NumberOfFrames", Some(1))?,
        samples_per_pixel: small(tags::SAMPLES_PER_PIXEL, "SamplesPerPixel", Some(1))?,
    })))
}

/// The uncompressed transfer syntaxes: implicit VR little endian,
/// explicit VR little and big endian.
const NATIVE: [&str; 3] = [
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.1",
    "1.2.840.10008.1.2.2",
];

/// `1, 2.5, 3e-300` for a message (exponents where plain digits would
/// run long).
fn numbers(v: &[f64]) -> String {
    let one = |x: &f64| {
        let a = x.abs();
        if a != 0.0 && !(1e-4..1e15).contains(&a) {
            format!("{x:e}")
        } else {
            x.to_string()
        }
    };
    v.iter().map(one).collect::<Vec<_>>().join(", ")
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

/// The SeriesInstanceUID of a DICOM image file (`None` if it is not an
/// image slice), or why its header cannot be read.
pub fn series_of(path: &Path) -> Result<Option<String>, InputError> {
    Ok(match header_of(path)? {
        Header::Slice(s) => Some(s.series),
        Header::Unplaced { series } => Some(series),
        Header::Other => None,
    })
}

fn dicom_files(dir: &Path) -> Result<Vec<PathBuf>, InputError> {
    let mut files = Vec::new();
    files_under(dir, &mut files)?;
    files.sort();
    files.retain(|f| looks_dicom(f));
    Ok(files)
}

/// Opens the series in `dir` and its subdirectories (the only one, or
/// `series`).
pub fn open_dir(dir: &Path, series: Option<&str>) -> Result<DicomSource, InputError> {
    open_files(dir, dicom_files(dir)?, series)
}

/// Opens the series made of `files` (`dir` names it in messages).
pub fn open_files(
    dir: &Path,
    files: Vec<PathBuf>,
    series: Option<&str>,
) -> Result<DicomSource, InputError> {
    let mut slices = Vec::new();
    let mut unplaced = Vec::new();
    for f in &files {
        match header_of(f)? {
            Header::Slice(s) => slices.push(*s),
            Header::Unplaced { series } => unplaced.push((f, series)),
            Header::Other => {}
        }
    }
    let mut by_series: BTreeMap<String, Vec<SliceInfo>> = BTreeMap::new();
    for s in slices {
        by_series.entry(s.series.clone()).or_default().push(s);
    }
    let mut slices = match (by_series.len(), series) {
        (0, _) => return Err(err(
            dir,
            "directory",
            "no DICOM image slices found (files with the DICM magic and an ImagePositionPatient)",
        )),
        (_, Some(uid)) => by_series
            .remove(uid)
            .ok_or_else(|| InputError::NoSuchSeries {
                path: dir.to_path_buf(),
                uid: uid.to_string(),
                available: by_series.keys().cloned().collect(),
            })?,
        (1, None) => by_series.into_values().next().expect("one"),
        (_, None) => {
            return Err(InputError::SeveralSeries {
                path: dir.to_path_buf(),
                series: by_series
                    .iter()
                    .map(|(k, v)| format!("{k} ({} slices)", v.len()))
                    .collect(),
            });
        }
    };
    if let Some((f, _)) = unplaced.iter().find(|(_, s)| *s == slices[0].series) {
        return Err(err(
            f,
            "ImagePositionPatient",
            format!(
                "missing in an image of series {}: cdvol places each slice by its \
                 position, and without it this slice would be left out as a gap",
                slices[0].series
            ),
        ));
    }
    let first = slices[0].clone();
    let row_dir = [
        first.orientation[0],
        first.orientation[1],
        first.orientation[2],
    ];
    let col_dir = [
        first.orientation[3],
        first.orientation[4],
        first.orientation[5],
    ];
    let normal = cross(row_dir, col_dir);
    if (dot(normal, normal) - 1.0).abs() > 1e-3 || dot(row_dir, col_dir).abs() > 1e-3 {
        return Err(err(
            &first.path,
            "ImageOrientationPatient",
            format!(
                "{} is not two orthogonal unit vectors",
                numbers(&first.orientation)
            ),
        ));
    }
    for s in &slices {
        let p = &s.path;
        if s.frames != 1 {
            return Err(err(
                p,
                "NumberOfFrames",
                format!("{}, expected 1 (one slice per file)", s.frames),
            ));
        }
        if s.samples_per_pixel != 1 {
            return Err(err(
                p,
                "SamplesPerPixel",
                format!("{}, expected 1 (greyscale)", s.samples_per_pixel),
            ));
        }
        let same = |a: String, b: String, tag: &str| {
            if a == b {
                Ok(())
            } else {
                Err(err(
                    p,
                    tag,
                    format!(
                        "{a}, but {} has {b}: the slices of a series must agree",
                        name(&first.path)
                    ),
                ))
            }
        };
        same(s.rows.to_string(), first.rows.to_string(), "Rows")?;
        same(s.cols.to_string(), first.cols.to_string(), "Columns")?;
        same(numbers(&s.spacing), numbers(&first.spacing), "PixelSpacing")?;
        let o_diff = s
            .orientation
            .iter()
            .zip(&first.orientation)
            .any(|(a, b)| (a - b).abs() > 1e-4);
        if o_diff {
            same(
                numbers(&s.orientation),
                numbers(&first.orientation),
                "ImageOrientationPatient",
            )?;
        }
        same(s.bits.to_string(), first.bits.to_string(), "BitsAllocated")?;
        same(
            s.signed.to_string(),
            first.signed.to_string(),
            "PixelRepresentation",
        )?;
        same(
            numbers(&s.rescale),
            numbers(&first.rescale),
            "RescaleSlope/RescaleIntercept",
        )?;
    }
    // Sort along the normal.
    let along = |s: &SliceInfo| dot(s.position, normal);
    slices.sort_by(|a, b| along(a).total_cmp(&along(b)));
    let z: Vec<f64> = slices.iter().map(along).collect();
    for i in 1..slices.len() {
        let (a, b) = (&slices[i - 1], &slices[i]);
        let gap = z[i] - z[i - 1];
        if gap.abs() < 1e-6 {
            return Err(err(
                &b.path,
                "ImagePositionPatient",
                format!(
                    "{}: the same position as {} (a duplicate slice?)",
                    numbers(&b.position),
                    name(&a.path)
                ),
            ));
        }
        let d = [0, 1, 2].map(|k| b.position[k] - a.position[k]);
        let off = [0, 1, 2].map(|k| d[k] - gap * normal[k]);
        if dot(off, off).sqrt() > 1e-3 * gap.abs().max(1.0) {
            return Err(err(
                &b.path,
                "ImagePositionPatient",
                format!(
                    "displaced {:.3} mm within the slice plane from {}: a tilted stack \
                     (gantry tilt) would need resampling, which cdvol does not do",
                    dot(off, off).sqrt(),
                    name(&a.path)
                ),
            ));
        }
    }
    if slices.len() < 2 {
        return Err(err(dir, "directory", "one slice, expected at least 2"));
    }
    let dtype = match (first.bits, first.signed) {
        (8, false) => Dtype::U8,
        (8, true) => Dtype::I8,
        (16, false) => Dtype::U16,
        (16, true) => Dtype::I16,
        (32, false) => Dtype::U32,
        (32, true) => Dtype::I32,
        (b, _) => {
            return Err(err(
                &first.path,
                "BitsAllocated",
                format!("{b}, expected 8, 16 or 32"),
            ))
        }
    };
    let (nx, ny) = (first.cols as usize, first.rows as usize);
    // A slice is decoded whole (its pixel data, then f64 samples): bound
    // it before the first decode below allocates it. Rows and Columns are
    // at most 65535, so the product fits.
    let slice_mem = (nx * ny) as u64 * (dtype.size() as u64 + 8);
    let limit = crate::memory::default_limit();
    if slice_mem > limit {
        return Err(err(
            &first.path,
            "Rows/Columns",
            format!(
                "{ny} x {nx} samples: one slice needs about {} to decode, above the \
                 memory limit of {}",
                crate::memory::human(slice_mem),
                crate::memory::describe_limit(limit, false)
            ),
        ));
    }
    let ox = dot(first.position, row_dir);
    let oy = dot(first.position, col_dir);
    let ax = Axis::uniform(ox, first.spacing[1], nx)
        .map_err(|e| err(&first.path, "PixelSpacing", format!("{e}")))?;
    let ay = Axis::uniform(oy, first.spacing[0], ny)
        .map_err(|e| err(&first.path, "PixelSpacing", format!("{e}")))?;
    let az = Axis::from_coords(z.clone())
        .map_err(|e| err(dir, "ImagePositionPatient", format!("{e}")))?;
    let report = spacing_report(&slices, &z);
    let meta = VolumeMeta {
        grid: Grid { axes: [ax, ay, az] },
        dtype,
        rescale: Rescale {
            slope: first.rescale[0],
            intercept: first.rescale[1],
        },
        origin_desc: format!("DICOM series {} in {}", first.series, dir.display()),
        // x along the rows, y down the columns, z along the normal (the
        // slices are sorted that way): DICOM's patient space is LPS.
        orientation: Some(
            crate::orient::Orientation::from_lps(
                [row_dir, col_dir, normal],
                "DICOM ImageOrientationPatient",
            )
            .map_err(|e| err(&first.path, "ImageOrientationPatient", e.to_string()))?,
        ),
    };
    let modality = slices.first().and_then(|s| s.modality.clone());
    let src = DicomSource {
        modality,
        meta,
        files: slices.into_iter().map(|s| s.path).collect(),
        slice_bytes: nx * ny * dtype.size(),
        report,
    };
    // Decode the first slice now: an undecodable transfer syntax fails here.
    let mut buf = vec![0.0; nx * ny];
    src.read_slice(0, &mut buf)?;
    Ok(src)
}

/// The most common gap (to 0.01 mm) and each gap that differs from it.
fn spacing_report(slices: &[SliceInfo], z: &[f64]) -> Vec<String> {
    let gaps: Vec<f64> = z.windows(2).map(|w| w[1] - w[0]).collect();
    let mut count: BTreeMap<i64, usize> = BTreeMap::new();
    for g in &gaps {
        *count.entry((g * 100.0).round() as i64).or_default() += 1;
    }
    let (&mode, &n) = count.iter().max_by_key(|(_, &c)| c).expect("gaps");
    let common = mode as f64 / 100.0;
    let mut out = vec![format!(
        "z: {} slices, most common spacing {common:.2} mm ({n} of {} gaps)",
        z.len(),
        gaps.len()
    )];
    for (i, g) in gaps.iter().enumerate() {
        if ((g * 100.0).round() as i64) != mode {
            out.push(format!(
                "{common:.2} mm expected, {g:.2} mm found between {} and {}: kept as a \
                 rectilinear z axis, no resampling",
                name(&slices[i].path),
                name(&slices[i + 1].path)
            ));
        }
    }
    out
}

impl SliceSource for DicomSource {
    fn meta(&self) -> &VolumeMeta {
        &self.meta
    }

    fn files(&self) -> Vec<PathBuf> {
        self.files.clone()
    }

    fn report(&self) -> Vec<String> {
        self.report.clone()
    }

    fn modality(&self) -> Option<(String, String)> {
        let m = self.modality.clone()?;
        Some((m, "DICOM Modality (0008,0060)".into()))
    }

    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError> {
        let p = &self.files[z];
        guard::check_structure(p, false)?;
        let obj: DefaultDicomObject = guard::no_panic(p, "file", || {
            dicom_object::open_file(p)
                .map_err(|e| err(p, "file", format!("not a readable DICOM file: {e}")))
        })?;
        // The slice may have changed since its header was read: the
        // decoder allocates what this file's Rows and Columns say.
        let (ny, nx) = (
            self.meta.grid.axes[1].samples(),
            self.meta.grid.axes[0].samples(),
        );
        for (tag, name, want) in [(tags::ROWS, "Rows", ny), (tags::COLUMNS, "Columns", nx)] {
            let got = obj.element(tag).ok().and_then(|e| e.to_int::<i64>().ok());
            if got != Some(want as i64) {
                return Err(err(
                    p,
                    name,
                    format!("changed since the series was opened, expected {want}"),
                ));
            }
        }
        guard::check_rle(p, &obj, self.meta.dtype.size())?;
        let ts = obj
            .meta()
            .transfer_syntax()
            .trim_end_matches('\0')
            .to_string();
        let px = guard::no_panic(p, "PixelData", || {
            obj.decode_pixel_data().map_err(|e| {
                err(
                    p,
                    "PixelData",
                    format!("cannot decode (transfer syntax {ts}): {e}"),
                )
            })
        })?;
        let data = px.data();
        if data.len() < self.slice_bytes {
            return Err(err(
                p,
                "PixelData",
                format!("{} bytes, expected {}", data.len(), self.slice_bytes),
            ));
        }
        let endian = if cfg!(target_endian = "big") {
            Endian::Big
        } else {
            Endian::Little
        };
        decode_samples(&data[..self.slice_bytes], self.meta.dtype, endian, out);
        Ok(())
    }
}

/// What [`write_slice`] writes into a CT image slice.
#[derive(Debug, Clone)]
pub struct SliceHeader<'a> {
    pub series: &'a str,
    /// InstanceNumber (1-based) and part of the SOPInstanceUID.
    pub instance: usize,
    pub rows: usize,
    pub cols: usize,
    /// PixelSpacing: between rows, between columns (mm).
    pub spacing: [f64; 2],
    pub position: [f64; 3],
    /// ImageOrientationPatient; `[1, 0, 0, 0, 1, 0]` for axial slices.
    pub orientation: [f64; 6],
    /// Stored values are signed (PixelRepresentation 1).
    pub signed: bool,
    pub rescale: Rescale,
    /// Transfer syntax UID; the pixel data are written native, so it must
    /// be an uncompressed one unless a test wants an undecodable file.
    pub transfer_syntax: &'a str,
}

/// Explicit VR little endian.
pub const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";

/// Writes one CT slice of 16-bit samples (`rows x cols`, x fastest; the
/// bit patterns of i16 when `signed`) with dicom-rs: the fixture writer of
/// the tests and of `tools/dicom-fixtures`.
pub fn write_slice(path: &Path, h: &SliceHeader, pixels: &[u16]) -> Result<(), InputError> {
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
    let ds = |v: &[f64]| PrimitiveValue::Strs(v.iter().map(|x| format!("{x}")).collect());
    let us = |v: u16| PrimitiveValue::from(v);
    let uid = format!("{}.{}", h.series, h.instance);
    let mut o = InMemDicomObject::new_empty();
    let mut put = |tag, vr, v: PrimitiveValue| {
        o.put(DataElement::new(tag, vr, v));
    };
    put(
        tags::SOP_CLASS_UID,
        VR::UI,
        "1.2.840.10008.5.1.4.1.1.2".into(),
    );
    put(tags::SOP_INSTANCE_UID, VR::UI, uid.as_str().into());
    put(tags::MODALITY, VR::CS, "CT".into());
    put(tags::SERIES_INSTANCE_UID, VR::UI, h.series.into());
    put(
        tags::INSTANCE_NUMBER,
        VR::IS,
        h.instance.to_string().as_str().into(),
    );
    put(tags::IMAGE_POSITION_PATIENT, VR::DS, ds(&h.position));
    put(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, ds(&h.orientation));
    put(tags::PIXEL_SPACING, VR::DS, ds(&h.spacing));
    put(tags::SAMPLES_PER_PIXEL, VR::US, us(1));
    put(
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        "MONOCHROME2".into(),
    );
    put(tags::ROWS, VR::US, us(h.rows as u16));
    put(tags::COLUMNS, VR::US, us(h.cols as u16));
    put(tags::BITS_ALLOCATED, VR::US, us(16));
    put(tags::BITS_STORED, VR::US, us(16));
    put(tags::HIGH_BIT, VR::US, us(15));
    put(tags::PIXEL_REPRESENTATION, VR::US, us(h.signed as u16));
    put(tags::RESCALE_INTERCEPT, VR::DS, ds(&[h.rescale.intercept]));
    put(tags::RESCALE_SLOPE, VR::DS, ds(&[h.rescale.slope]));
    put(
        tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(pixels.iter().copied().collect()),
    );
    let file = o
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(h.transfer_syntax)
                .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.2")
                .media_storage_sop_instance_uid(uid.as_str()),
        )
        .map_err(|e| err(path, "file meta", format!("{e}")))?;
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).map_err(|source| InputError::Io {
            path: d.to_path_buf(),
            what: "cannot create the directory",
            source,
        })?;
    }
    file.write_to_file(path)
        .map_err(|e| err(path, "file", format!("cannot write: {e}")))
}
