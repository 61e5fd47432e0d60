//! TIFF stacks, as reconstruction software writes them: a directory of
//! one TIFF per z slice, or one multi-page TIFF whose pages are the
//! slices. Read slice by slice through the `tiff` crate (strips or tiles,
//! either byte order, classic or BigTIFF, uncompressed, LZW, deflate or
//! PackBits), one grey channel of 8, 16 or 32-bit integers or 32 or
//! 64-bit floats.
//!
//! The voxel size comes from the first page's metadata: ImageJ's
//! (`ImageDescription` starting `ImageJ=`, with `spacing=` for z, `unit=`,
//! and the X/YResolution tags in pixels per unit) or OME-XML's (`Pixels`
//! attributes `PhysicalSizeX/Y/Z` and their units, micrometres by
//! default). Without either, 1 mm, said in the report. A JSON sidecar
//! (`{"tiff": "slices/", "z": {"positions": [...]}}`,
//! [`TiffSource::open_sidecar`]) names a stack and gives the axes, the
//! slice positions of a stack whose slices are not evenly spaced above all.
//!
//! A directory's files are ordered by the last number in their names
//! (natural order: `s2.tif` before `s10.tif`); two files with the same
//! number, or a number missing between the first and the last, are
//! refused by name: a slice lost in a copy would otherwise shift every
//! slice above it.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

use super::{Dtype, InputError, Rescale, SliceSource, VolumeMeta};
use crate::grid::{Axis, Grid};

type Dec = Decoder<BufReader<File>>;

/// A TIFF stack.
pub struct TiffSource {
    meta: VolumeMeta,
    pages: Pages,
    notes: Vec<String>,
    /// The JSON sidecar that named the stack and gave its axes, if any.
    sidecar: Option<PathBuf>,
}

enum Pages {
    /// One file per slice, in z order.
    Files(Vec<PathBuf>),
    /// One file whose page z is slice z; the decoder keeps the pages'
    /// offsets once it has walked them.
    Pages { path: PathBuf, dec: Box<Mutex<Dec>> },
}

fn tiff_err(path: &Path, field: &str, e: impl std::fmt::Display) -> InputError {
    InputError::field(path, field, e.to_string())
}

fn decoder(path: &Path) -> Result<Dec, InputError> {
    let f = crate::fsutil::open_regular(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot open the TIFF file",
        source,
    })?;
    Decoder::new(BufReader::new(f)).map_err(|e| tiff_err(path, "TIFF header", e))
}

/// The sample type of the decoder's current page, from its colour type
/// and SampleFormat tag.
fn page_dtype(dec: &mut Dec, path: &Path) -> Result<Dtype, InputError> {
    use tiff::ColorType;
    let ct = dec
        .colortype()
        .map_err(|e| tiff_err(path, "PhotometricInterpretation", e))?;
    let bits = match ct {
        ColorType::Gray(b) => b,
        other => {
            return Err(InputError::field(
                path,
                "SamplesPerPixel",
                format!("{other:?}, expected one grey channel (a scan slice)"),
            ))
        }
    };
    // SampleFormat: 1 unsigned (the default), 2 signed, 3 float.
    let format = dec
        .find_tag_unsigned::<u16>(Tag::SampleFormat)
        .map_err(|e| tiff_err(path, "SampleFormat", e))?
        .unwrap_or(1);
    Ok(match (format, bits) {
        (1, 8) => Dtype::U8,
        (2, 8) => Dtype::I8,
        (1, 16) => Dtype::U16,
        (2, 16) => Dtype::I16,
        (1, 32) => Dtype::U32,
        (2, 32) => Dtype::I32,
        (3, 32) => Dtype::F32,
        (3, 64) => Dtype::F64,
        _ => {
            return Err(InputError::field(
                path,
                "BitsPerSample",
                format!(
                    "{bits} bits of SampleFormat {format}, expected 8, 16 or 32-bit integers \
                     (SampleFormat 1 or 2) or 32 or 64-bit floats (SampleFormat 3)"
                ),
            ))
        }
    })
}

/// Width, height and sample type of the decoder's current page.
fn page_shape(dec: &mut Dec, path: &Path) -> Result<(usize, usize, Dtype), InputError> {
    let (w, h) = dec
        .dimensions()
        .map_err(|e| tiff_err(path, "ImageWidth", e))?;
    Ok((w as usize, h as usize, page_dtype(dec, path)?))
}

/// Voxel size in mm, `[x, y, z]`, from ImageJ or OME-XML metadata, and
/// where it came from; `None` when the file has neither.
fn voxel_size(dec: &mut Dec) -> Option<([f64; 3], &'static str)> {
    let desc = match dec.get_tag_ascii_string(Tag::ImageDescription) {
        Ok(d) => d,
        Err(_) => return None,
    };
    if desc.contains("<OME") {
        return ome_voxel(&desc).map(|v| (v, "OME-XML PhysicalSizeX/Y/Z"));
    }
    if desc.starts_with("ImageJ=") {
        let mut unit = 1.0;
        let mut z = None;
        for line in desc.lines() {
            if let Some((k, v)) = line.split_once('=') {
                match k.trim() {
                    "unit" => unit = unit_mm(v.trim())?,
                    "spacing" => z = v.trim().parse::<f64>().ok(),
                    _ => {}
                }
            }
        }
        let mut res = |tag| -> Option<f64> {
            match dec.get_tag(tag).ok()? {
                tiff::decoder::ifd::Value::Rational(n, d) if n > 0 => Some(d as f64 / n as f64),
                _ => None,
            }
        };
        let x = res(Tag::XResolution).unwrap_or(1.0);
        let y = res(Tag::YResolution).unwrap_or(x);
        let z = z.unwrap_or(x);
        return Some((
            [x * unit, y * unit, z * unit],
            "ImageJ (X/YResolution, spacing, unit)",
        ));
    }
    None
}

/// Millimetres per unit of a length unit as ImageJ and OME write them.
fn unit_mm(u: &str) -> Option<f64> {
    Some(match u {
        "mm" | "millimeter" | "millimetre" => 1.0,
        "cm" | "centimeter" | "centimetre" => 10.0,
        "m" | "meter" | "metre" => 1000.0,
        "micron" | "microns" | "um" | "µm" | "\u{3bc}m" | "micrometer" | "micrometre" => 1e-3,
        "\\u00B5m" => 1e-3,
        "nm" | "nanometer" | "nanometre" => 1e-6,
        _ => return None,
    })
}

/// `PhysicalSizeX/Y/Z` (and `...Unit`, micrometres by default) of the
/// first `<Pixels` element of an OME-XML description.
fn ome_voxel(xml: &str) -> Option<[f64; 3]> {
    let start = xml.find("<Pixels")?;
    let end = start + xml[start..].find('>')?;
    let el = &xml[start..end];
    let attr = |name: &str| -> Option<&str> {
        let key = format!(" {name}=\"");
        let i = el.find(&key)? + key.len();
        let j = el[i..].find('"')?;
        Some(&el[i..i + j])
    };
    let mut out = [0.0; 3];
    for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
        let v: f64 = attr(&format!("PhysicalSize{axis}"))?.parse().ok()?;
        let unit = match attr(&format!("PhysicalSize{axis}Unit")) {
            Some(u) => unit_mm(u)?,
            None => 1e-3,
        };
        out[k] = v * unit;
    }
    Some(out)
}

/// The last run of digits in a file name's stem, and the name around it.
fn numbered(name: &str) -> Option<(String, u64, String)> {
    let stem_end = name.rfind('.').unwrap_or(name.len());
    let stem = &name[..stem_end];
    let end = stem.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = stem[..end]
        .rfind(|c: char| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    let n = stem[start..end].parse().ok()?;
    Some((stem[..start].to_string(), n, name[end..].to_string()))
}

/// The TIFF files of a directory in slice order: by the last number in
/// their names; a name without one, two with the same number, names of
/// two patterns, and a number missing in the run are refused by name.
pub fn stack_files(dir: &Path) -> Result<Vec<PathBuf>, InputError> {
    let rd = std::fs::read_dir(dir).map_err(|source| InputError::Io {
        path: dir.to_path_buf(),
        what: "cannot list the directory",
        source,
    })?;
    let mut files = Vec::new();
    for e in rd {
        let e = e.map_err(|source| InputError::Io {
            path: dir.to_path_buf(),
            what: "cannot list the directory",
            source,
        })?;
        let p = e.path();
        if is_tiff_name(&p) && p.is_file() {
            files.push(p);
        }
    }
    let mut keyed = Vec::with_capacity(files.len());
    for p in files {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (pre, n, post) = numbered(&name).ok_or_else(|| {
            InputError::field(
                &p,
                "file name",
                "no number in the name, expected one number per slice (slice_0001.tif, ...)",
            )
        })?;
        keyed.push(((pre, post), n, p));
    }
    keyed.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    let Some(first) = keyed.first() else {
        return Err(InputError::field(
            dir,
            "directory",
            "no .tif or .tiff files",
        ));
    };
    let pattern = first.0.clone();
    for w in keyed.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if b.0 != pattern {
            return Err(InputError::field(
                &b.2,
                "file name",
                format!(
                    "named unlike {} ({}N{} against {}N{}): one stack a directory",
                    first.2.display(),
                    b.0 .0,
                    b.0 .1,
                    pattern.0,
                    pattern.1
                ),
            ));
        }
        if b.1 == a.1 {
            return Err(InputError::field(
                &b.2,
                "file name",
                format!("slice number {} again (also {})", b.1, a.2.display()),
            ));
        }
        if b.1 != a.1 + 1 {
            return Err(InputError::field(
                &b.2,
                "file name",
                format!(
                    "slice number {} follows {} ({}): {} missing",
                    b.1,
                    a.1,
                    a.2.display(),
                    if b.1 == a.1 + 2 {
                        format!("slice {} is", a.1 + 1)
                    } else {
                        format!("slices {}..={} are", a.1 + 1, b.1 - 1)
                    }
                ),
            ));
        }
    }
    Ok(keyed.into_iter().map(|k| k.2).collect())
}

/// A `.tif` or `.tiff` name (any case).
pub fn is_tiff_name(p: &Path) -> bool {
    p.extension()
        .map(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"))
        .unwrap_or(false)
}

/// The grid of a stack of `nz` slices of `nx x ny` with voxel size `v`.
fn grid(path: &Path, [nx, ny, nz]: [usize; 3], v: [f64; 3]) -> Result<Grid, InputError> {
    let axis = |n: usize, s: f64, name: &str| {
        Axis::uniform(0.0, s, n).map_err(|e| InputError::field(path, name, e.to_string()))
    };
    Ok(Grid {
        axes: [
            axis(nx, v[0], "x (width)")?,
            axis(ny, v[1], "y (height)")?,
            axis(nz, v[2], "z (slices)")?,
        ],
    })
}

impl TiffSource {
    /// A directory of one TIFF per slice ([`stack_files`]).
    pub fn open_dir(dir: &Path) -> Result<TiffSource, InputError> {
        let files = stack_files(dir)?;
        let mut dec = decoder(&files[0])?;
        let (nx, ny, dtype) = page_shape(&mut dec, &files[0])?;
        // Every file's first page: the same shape and type, checked now
        // (a few hundred bytes each) so prep does not fail half-way.
        for f in &files[1..] {
            let shape = page_shape(&mut decoder(f)?, f)?;
            if shape != (nx, ny, dtype) {
                return Err(InputError::field(
                    f,
                    "ImageWidth",
                    format!(
                        "{} x {} of {}, expected {nx} x {ny} of {} as {}",
                        shape.0,
                        shape.1,
                        shape.2.name(),
                        dtype.name(),
                        files[0].display()
                    ),
                ));
            }
        }
        let nz = files.len();
        let desc = dir.display().to_string();
        TiffSource::finish(
            dir,
            &mut dec,
            [nx, ny, nz],
            dtype,
            desc,
            Pages::Files(files),
        )
    }

    /// One multi-page TIFF file, a page per slice.
    pub fn open_file(path: &Path) -> Result<TiffSource, InputError> {
        let mut dec = decoder(path)?;
        let (nx, ny, dtype) = page_shape(&mut dec, path)?;
        let mut nz = 1;
        while dec.more_images() {
            dec.next_image()
                .map_err(|e| tiff_err(path, &format!("page {nz}"), e))?;
            let shape = page_shape(&mut dec, path)?;
            if shape != (nx, ny, dtype) {
                return Err(InputError::field(
                    path,
                    format!("page {nz}"),
                    format!(
                        "{} x {} of {}, expected {nx} x {ny} of {} as page 0",
                        shape.0,
                        shape.1,
                        shape.2.name(),
                        dtype.name()
                    ),
                ));
            }
            nz += 1;
        }
        dec.seek_to_image(0)
            .map_err(|e| tiff_err(path, "page 0", e))?;
        let desc = path.display().to_string();
        let mut meta_dec = decoder(path)?;
        TiffSource::finish(
            path,
            &mut meta_dec,
            [nx, ny, nz],
            dtype,
            desc,
            Pages::Pages {
                path: path.to_path_buf(),
                dec: Box::new(Mutex::new(dec)),
            },
        )
    }

    fn finish(
        path: &Path,
        first: &mut Dec,
        dims: [usize; 3],
        dtype: Dtype,
        origin_desc: String,
        pages: Pages,
    ) -> Result<TiffSource, InputError> {
        if dims[2] < 2 {
            return Err(InputError::field(
                path,
                "slices",
                "1 slice, expected at least 2 (one cell)",
            ));
        }
        let mut notes = vec![match &pages {
            Pages::Files(f) => format!("{} TIFF slices, one a file", f.len()),
            Pages::Pages { .. } => format!("{} TIFF pages, one a slice", dims[2]),
        }];
        let v = match voxel_size(first) {
            Some((v, from)) => {
                notes.push(format!(
                    "voxel size {} x {} x {} mm from {from}",
                    v[0], v[1], v[2]
                ));
                v
            }
            None => {
                notes.push(
                    "warning: the TIFF says no voxel size (no ImageJ or OME-XML metadata): \
                     1 x 1 x 1 mm"
                        .into(),
                );
                [1.0; 3]
            }
        };
        Ok(TiffSource {
            meta: VolumeMeta {
                grid: grid(path, dims, v)?,
                dtype,
                rescale: Rescale::IDENTITY,
                origin_desc,
                orientation: None,
            },
            pages,
            notes,
            sidecar: None,
        })
    }

    /// A JSON sidecar that names a TIFF stack and gives the axes its
    /// metadata does not (slice positions, above all, for a stack whose
    /// slices are not evenly spaced): `{"tiff": "slices/", "z":
    /// {"positions": [...]}}`. Key `tiff`: the directory or multi-page
    /// file, relative to the sidecar; keys `x`, `y`, `z` as in a raw
    /// stack's sidecar (a spacing in mm, `{"spacing": [...]}` or
    /// `{"positions": [...]}`), each replacing what the TIFF says; key
    /// `origin` (mm). Other keys are refused by name.
    pub fn open_sidecar(path: &Path) -> Result<TiffSource, InputError> {
        use serde_json::Value;
        let obj = super::sidecar::read_object(path)?;
        for k in obj.keys() {
            if !["tiff", "x", "y", "z", "origin"].contains(&k.as_str()) {
                return Err(InputError::field(
                    path,
                    k.as_str(),
                    "not a key of a TIFF stack's sidecar, expected tiff, x, y, z or origin",
                ));
            }
        }
        let name = obj.get("tiff").and_then(Value::as_str).ok_or_else(|| {
            InputError::field(path, "tiff", "expected the stack's directory or file name")
        })?;
        let target = path.parent().unwrap_or(Path::new(".")).join(name);
        let mut src = if target.is_dir() {
            TiffSource::open_dir(&target)?
        } else {
            TiffSource::open_file(&target)?
        };
        let origin = super::sidecar::parse_origin(path, obj.get("origin"))?;
        let dims = src.meta.dims();
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            let given = obj.get(*axis);
            let a = match given {
                Some(_) => super::sidecar::parse_axis(path, axis, given, dims[i], origin[i])?,
                None => {
                    let c = src.meta.grid.axes[i].coords();
                    let step = c[1] - c[0];
                    Axis::uniform(origin[i], step, dims[i])
                        .map_err(|e| InputError::field(path, *axis, e.to_string()))?
                }
            };
            if given.is_some() {
                src.notes
                    .push(format!("{axis} axis from {}", path.display()));
            }
            src.meta.grid.axes[i] = a;
        }
        src.sidecar = Some(path.to_path_buf());
        Ok(src)
    }

    /// Whether the JSON file `path` is a TIFF stack's sidecar (has a
    /// top-level key `tiff`); false for anything else, which the raw
    /// sidecar's reader then explains.
    pub fn is_sidecar(path: &Path) -> bool {
        super::sidecar::read_bounded(path)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .is_some_and(|v| v.get("tiff").is_some())
    }
}

/// Copies a decoded page into `out` as f64.
fn to_f64(img: DecodingResult, out: &mut [f64], path: &Path, z: usize) -> Result<(), InputError> {
    fn copy<T: Copy + Into<f64>>(v: &[T], out: &mut [f64]) -> bool {
        if v.len() != out.len() {
            return false;
        }
        out.iter_mut().zip(v).for_each(|(o, &x)| *o = x.into());
        true
    }
    let ok = match &img {
        DecodingResult::U8(v) => copy(v, out),
        DecodingResult::I8(v) => copy(v, out),
        DecodingResult::U16(v) => copy(v, out),
        DecodingResult::I16(v) => copy(v, out),
        DecodingResult::U32(v) => copy(v, out),
        DecodingResult::I32(v) => copy(v, out),
        DecodingResult::F32(v) => copy(v, out),
        DecodingResult::F64(v) => copy(v, out),
        _ => false,
    };
    if ok {
        Ok(())
    } else {
        Err(InputError::field(
            path,
            format!("slice {z}"),
            format!(
                "decoded to another size or type than page 0 ({} samples expected)",
                out.len()
            ),
        ))
    }
}

impl SliceSource for TiffSource {
    fn meta(&self) -> &VolumeMeta {
        &self.meta
    }

    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError> {
        match &self.pages {
            Pages::Files(files) => {
                let path = &files[z];
                let mut dec = decoder(path)?;
                let img = dec
                    .read_image()
                    .map_err(|e| tiff_err(path, "image data", e))?;
                to_f64(img, out, path, z)
            }
            Pages::Pages { path, dec } => {
                let mut dec = dec.lock().unwrap_or_else(|e| e.into_inner());
                dec.seek_to_image(z)
                    .map_err(|e| tiff_err(path, &format!("page {z}"), e))?;
                let img = dec
                    .read_image()
                    .map_err(|e| tiff_err(path, &format!("page {z}"), e))?;
                to_f64(img, out, path, z)
            }
        }
    }

    fn report(&self) -> Vec<String> {
        self.notes.clone()
    }

    fn files(&self) -> Vec<PathBuf> {
        let mut out: Vec<PathBuf> = self.sidecar.iter().cloned().collect();
        match &self.pages {
            Pages::Files(f) => out.extend(f.iter().cloned()),
            Pages::Pages { path, .. } => out.push(path.clone()),
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_number_their_slices() {
        assert_eq!(
            numbered("slice_0012.tif"),
            Some(("slice_".into(), 12, ".tif".into()))
        );
        assert_eq!(
            numbered("a3b10.tiff"),
            Some(("a3b".into(), 10, ".tiff".into()))
        );
        assert_eq!(
            numbered("rec2.0007.TIF"),
            Some(("rec2.".into(), 7, ".TIF".into()))
        );
        assert_eq!(numbered("flat.tif"), None);
    }

    #[test]
    fn ome_and_imagej_units() {
        let xml = r#"<?xml version="1.0"?><OME><Image><Pixels DimensionOrder="XYZCT" PhysicalSizeX="0.5" PhysicalSizeY="0.25" PhysicalSizeZ="2" PhysicalSizeZUnit="mm" SizeX="4"></Pixels></Image></OME>"#;
        assert_eq!(ome_voxel(xml), Some([0.5e-3, 0.25e-3, 2.0]));
        assert_eq!(unit_mm("micron"), Some(1e-3));
        assert_eq!(unit_mm("furlong"), None);
    }

    fn write_slices(dir: &Path, names: &[&str]) {
        for n in names {
            let f = File::create(dir.join(n)).unwrap();
            let mut enc = tiff::encoder::TiffEncoder::new(f).unwrap();
            enc.write_image::<tiff::encoder::colortype::Gray16>(3, 2, &[1, 2, 3, 4, 5, 6])
                .unwrap();
        }
    }

    #[test]
    fn gaps_duplicates_and_strangers_are_refused_by_name() {
        let d = tempfile::tempdir().unwrap();
        write_slices(d.path(), &["s1.tif", "s2.tif", "s10.tif", "s3.tif"]);
        let e = stack_files(d.path()).unwrap_err().to_string();
        assert!(
            e.contains("s10.tif") && e.contains("slices 4..=9 are missing"),
            "{e}"
        );
        let d = tempfile::tempdir().unwrap();
        write_slices(d.path(), &["s1.tif", "s2.tif", "s02.tif"]);
        let e = stack_files(d.path()).unwrap_err().to_string();
        assert!(e.contains("slice number 2 again"), "{e}");
        let d = tempfile::tempdir().unwrap();
        write_slices(d.path(), &["s1.tif", "s2.tif", "t3.tif"]);
        let e = stack_files(d.path()).unwrap_err().to_string();
        assert!(
            e.contains("t3.tif") && e.contains("one stack a directory"),
            "{e}"
        );
        let d = tempfile::tempdir().unwrap();
        write_slices(d.path(), &["s9.tif", "s10.tif", "s11.tif"]);
        let order: Vec<String> = stack_files(d.path())
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(order, ["s9.tif", "s10.tif", "s11.tif"]);
        let src = TiffSource::open_dir(d.path()).unwrap();
        assert_eq!(src.meta().dims(), [3, 2, 3]);
        let mut out = vec![0.0; 6];
        src.read_slice(2, &mut out).unwrap();
        assert_eq!(out, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }
}
