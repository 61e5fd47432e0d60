//! NIfTI-1 volumes (`.nii`, `.nii.gz`): the header through the `nifti`
//! crate; samples memory-mapped (`.nii`) or decompressed as a stream
//! (`.nii.gz`), one slice at a time.
//!
//! Spacing is `pixdim[1..=3]` (absolute values, read as the shortest
//! decimal of the stored f32; units from `xyzt_units`,
//! millimetres unless it says metres or micrometres), the origin the
//! sform/qform offset, and `scl_slope`/`scl_inter` the rescale (slope 0
//! means none, as the standard says). The voxel-to-world rotation is not
//! applied to the samples, which stay in file order like every input of
//! cdvol (no resampling); its axis directions are recorded as the
//! volume's patient orientation (crate::orient), from the sform when
//! `sform_code > 0` and its columns are orthogonal, else from the qform
//! when `qform_code > 0`, else unknown.

use std::path::Path;

use nifti::{Endianness, NiftiHeader, NiftiType};

use super::gz::{GzLayout, GzSource};
use super::raw::RawSource;
use super::sidecar::{DataFiles, Sidecar};
use super::{Dtype, Endian, InputError, Rescale, SliceSource, VolumeMeta};
use crate::grid::{check_spacing, Axis, Grid, MAX_COORD_MM};
use crate::orient::Orientation;

/// Opens a `.nii` or `.nii.gz` file as a slice source.
pub fn open(path: &Path) -> Result<Box<dyn SliceSource>, InputError> {
    let bad = |field: &str, msg: String| InputError::field(path, field, msg);
    // The nifti crate opens the file itself: check its type first.
    crate::fsutil::check_regular(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot open NIfTI file",
        source,
    })?;
    let h = NiftiHeader::from_file(path).map_err(|e| bad("header", format!("{e}")))?;
    if &h.magic != b"n+1\0" {
        return Err(bad(
            "magic",
            format!(
                "{:?}, expected \"n+1\" (a single-file .nii; .hdr/.img pairs are not supported)",
                String::from_utf8_lossy(&h.magic)
            ),
        ));
    }
    // NIfTI stores dims as signed 16-bit numbers; the crate reads them
    // unsigned, so a negative one is read back as such here.
    let dim = h.dim.map(|d| d as i16);
    let nd = dim[0];
    if !(3..=7).contains(&nd) {
        return Err(bad(
            "dim",
            format!(
                "dim[0] is {nd}, expected a 3D volume (dim[0] = 3, or up to 7 with every \
                 extra dimension 1)"
            ),
        ));
    }
    if let Some(k) = (4..=nd as usize).find(|&k| dim[k] != 1) {
        return Err(bad(
            "dim",
            format!(
                "dim[{k}] is {}, expected 1 (a 3D volume: every dimension after the third is 1)",
                dim[k]
            ),
        ));
    }
    let mut dims = [0usize; 3];
    for k in 0..3 {
        let d = dim[k + 1];
        if d < 2 {
            return Err(bad(
                "dim",
                format!(
                    "dim[{}] is {d}, expected at least 2 samples along {}",
                    k + 1,
                    ["x", "y", "z"][k]
                ),
            ));
        }
        dims[k] = d as usize;
    }
    let dtype = match h.data_type() {
        Ok(NiftiType::Uint8) => Dtype::U8,
        Ok(NiftiType::Int8) => Dtype::I8,
        Ok(NiftiType::Uint16) => Dtype::U16,
        Ok(NiftiType::Int16) => Dtype::I16,
        Ok(NiftiType::Uint32) => Dtype::U32,
        Ok(NiftiType::Int32) => Dtype::I32,
        Ok(NiftiType::Int64) => Dtype::I64,
        Ok(NiftiType::Float32) => Dtype::F32,
        Ok(NiftiType::Float64) => Dtype::F64,
        Ok(t) => {
            return Err(bad(
                "datatype",
                format!("{t:?} is not supported, expected a scalar integer or float type"),
            ))
        }
        Err(e) => return Err(bad("datatype", format!("{} : {e}", h.datatype))),
    };
    // Units: NIFTI_UNITS_METER 1, MM 2, MICRON 3 (in the low 3 bits).
    let unit_mm = match h.xyzt_units & 7 {
        1 => 1000.0,
        3 => 0.001,
        _ => 1.0,
    };
    let (origin, origin_names) = if h.sform_code > 0 {
        (
            [h.srow_x[3], h.srow_y[3], h.srow_z[3]],
            ["srow_x[3]", "srow_y[3]", "srow_z[3]"],
        )
    } else {
        (
            [h.quatern_x, h.quatern_y, h.quatern_z],
            ["qoffset_x", "qoffset_y", "qoffset_z"],
        )
    };
    let mut axes = Vec::with_capacity(3);
    for k in 0..3 {
        let field = format!("pixdim[{}]", k + 1);
        let s = check_spacing(dec(h.pixdim[k + 1]).abs() * unit_mm)
            .map_err(|e| bad(&field, e.to_string()))?;
        let o = dec(origin[k]) * unit_mm;
        if !(o.is_finite() && o.abs() <= MAX_COORD_MM) {
            return Err(bad(
                origin_names[k],
                format!(
                    "{} mm, expected a finite origin at most {MAX_COORD_MM:e} mm from 0",
                    origin[k]
                ),
            ));
        }
        axes.push(Axis::uniform(o, s, dims[k]).map_err(|e| bad(&field, e.to_string()))?);
    }
    let [ax, ay, az]: [Axis; 3] = axes
        .try_into()
        .map_err(|_| bad("dim", "expected three axes".into()))?;
    let grid = Grid { axes: [ax, ay, az] };
    // A slope of 0 means no rescale (the standard); NaN or infinity is
    // read the same way, as nibabel reads it, but not silently.
    let mut notes = Vec::new();
    if !h.scl_slope.is_finite() {
        notes.push(format!(
            "warning: {}: scl_slope {}: read as no rescale (slope 1, intercept 0), as nibabel does",
            path.display(),
            h.scl_slope
        ));
    }
    let rescale = if h.scl_slope == 0.0 || !h.scl_slope.is_finite() {
        Rescale::IDENTITY
    } else {
        Rescale {
            slope: dec(h.scl_slope),
            intercept: if h.scl_inter.is_finite() {
                dec(h.scl_inter)
            } else {
                0.0
            },
        }
    };
    let endian = match h.endianness {
        Endianness::Little => Endian::Little,
        Endianness::Big => Endian::Big,
    };
    // vox_offset: a whole number of bytes after the 348-byte header, and
    // (uncompressed) within the file; a compressed stream's skip is
    // bounded by gz.rs against what the stream holds.
    let vo = h.vox_offset;
    if !(vo.is_finite() && vo >= 348.0 && vo.fract() == 0.0) {
        return Err(bad(
            "vox_offset",
            format!("{vo}, expected a whole number of bytes >= 348"),
        ));
    }
    let skip = vo as u64;
    let gz = path
        .file_name()
        .is_some_and(|n| n.to_string_lossy().to_ascii_lowercase().ends_with(".gz"));
    if !gz {
        let len = std::fs::metadata(path)
            .map_err(|source| InputError::Io {
                path: path.to_path_buf(),
                what: "cannot open NIfTI file",
                source,
            })?
            .len();
        if skip > len {
            return Err(bad(
                "vox_offset",
                format!("{skip}, past the end of the file ({len} bytes)"),
            ));
        }
    }
    let meta = VolumeMeta {
        grid: grid.clone(),
        dtype,
        rescale,
        origin_desc: path.display().to_string(),
        orientation: orientation(&h),
    };
    if gz {
        let layout = GzLayout {
            file: path.to_path_buf(),
            header: path.to_path_buf(),
            file_offset: 0,
            skip,
            dtype,
            endian,
            dims_field: "dim",
            skip_field: "vox_offset",
        };
        noted(Box::new(GzSource::open(meta, layout)?), notes)
    } else {
        noted(
            Box::new(RawSource::from_sidecar(Sidecar {
                path: path.to_path_buf(),
                data: DataFiles::One(path.to_path_buf()),
                dims,
                dtype,
                endian,
                header_bytes: skip,
                grid,
                rescale,
                orientation: meta.orientation,
                modality: None,
            })?),
            notes,
        )
    }
}

/// `src` with `notes` added to its report (a warning of the header's).
fn noted(
    src: Box<dyn SliceSource>,
    notes: Vec<String>,
) -> Result<Box<dyn SliceSource>, InputError> {
    if notes.is_empty() {
        return Ok(src);
    }
    Ok(Box::new(Noted { src, notes }))
}

struct Noted {
    src: Box<dyn SliceSource>,
    notes: Vec<String>,
}

impl SliceSource for Noted {
    fn meta(&self) -> &VolumeMeta {
        self.src.meta()
    }

    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError> {
        self.src.read_slice(z, out)
    }

    fn report(&self) -> Vec<String> {
        let mut r = self.src.report();
        r.extend(self.notes.iter().cloned());
        r
    }

    fn files(&self) -> Vec<std::path::PathBuf> {
        self.src.files()
    }
}

/// The f64 nearest to the shortest decimal that reads back as `x`: NIfTI
/// stores spacings, offsets and rescales as f32, and `0.9f32` means 0.9,
/// not 0.89999997615814208984375.
fn dec(x: f32) -> f64 {
    format!("{x}").parse().unwrap_or(x as f64)
}

/// The patient orientation of the sform (`sform_code > 0`), else of the
/// qform (`qform_code > 0`); `None` when neither is set or usable (a
/// sheared or degenerate sform falls back to the qform).
fn orientation(h: &NiftiHeader) -> Option<Orientation> {
    if h.sform_code > 0 {
        let rows = [h.srow_x, h.srow_y, h.srow_z];
        let axes = std::array::from_fn(|k| std::array::from_fn(|j| rows[j][k] as f64));
        if let Ok(o) = Orientation::from_ras(axes, "NIfTI sform") {
            return Some(o);
        }
    }
    if h.qform_code > 0 {
        let [b, c, d] = [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from);
        let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
        let r = [
            [
                a * a + b * b - c * c - d * d,
                2.0 * (b * c - a * d),
                2.0 * (b * d + a * c),
            ],
            [
                2.0 * (b * c + a * d),
                a * a + c * c - b * b - d * d,
                2.0 * (c * d - a * b),
            ],
            [
                2.0 * (b * d - a * c),
                2.0 * (c * d + a * b),
                a * a + d * d - b * b - c * c,
            ],
        ];
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let axes = std::array::from_fn(|k| {
            let s = if k == 2 { qfac } else { 1.0 };
            std::array::from_fn(|j| r[j][k] * s)
        });
        return Orientation::from_ras(axes, "NIfTI qform").ok();
    }
    None
}
