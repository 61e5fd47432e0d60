//! Image output, the last stage of a render: a coloured [`Frame`]
//! (render/colour.rs makes it from the pixels by the mode's
//! [`Colouring`]) is written by [`save`] as PNG, TIFF or JPEG by the
//! output's extension (plus raw f32 and 16-bit PNG depth in the depth
//! mode).

use std::path::{Path, PathBuf};

pub use super::colour::Colouring;
use crate::fsutil::{FileSet, WriteError};

/// A rendered image: RGB8 for display, its colour in f32 for 16-bit and
/// float outputs, plus per-pixel data of the depth, MIP and cost modes.
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Colour over black (composite colours are premultiplied by their
    /// coverage).
    pub rgb: Vec<u8>,
    /// Coverage per pixel, 0..=255: the composite's opacity; 255 on a
    /// hit and 0 on a miss otherwise; 255 everywhere in a cost map. The
    /// output's [`Background`] shows through the rest.
    pub alpha: Vec<u8>,
    /// `rgb` and `alpha` before rounding, 4 a pixel (red, green, blue
    /// premultiplied, coverage), each in [0, 1]: `--bit-depth 16` rounds
    /// these to 16 bits and `--bit-depth 32` writes them as they are.
    pub linear: Vec<f32>,
    /// Depth mode: hit distance in mm, NaN where the ray misses.
    pub depth: Option<Vec<f32>>,
    /// What a float32 TIFF of MIP or cost holds, one a pixel: the MIP
    /// maximum (rescaled data units, whatever the window), NaN where the
    /// ray misses, or the cost map's steps. `None` in the other modes (the
    /// depth mode's TIFF holds `depth`).
    pub values: Option<Vec<f32>>,
    /// Steps per pixel.
    pub steps: Vec<u32>,
}

/// Why [`save`] wrote no image.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    /// The depth mode writes its raw f32 beside the PNG with `.f32`.
    #[error(
        "{}: the depth mode writes its raw f32 beside the PNG with the extension .f32; \
         use a .png name",
        path.display()
    )]
    F32Name { path: PathBuf },
    /// The frame's pixel buffer does not hold `width x height` pixels.
    #[error(
        "{}: frame of {width} x {height} pixels holds {found} {what} values, expected {expected}",
        path.display()
    )]
    Size {
        path: PathBuf,
        what: &'static str,
        width: u32,
        height: u32,
        found: usize,
        expected: usize,
    },
    /// The output's extension names no format [`save`] writes.
    #[error(
        "{}: extension {found:?}: expected .png, .tif, .tiff, .jpg or .jpeg (the format \
         follows the extension)",
        path.display()
    )]
    Extension { path: PathBuf, found: String },
    /// 16 bits per channel in a format without them.
    #[error("{}: JPEG has 8 bits per channel for --bit-depth 16; use .png or .tif", path.display())]
    No16Bit { path: PathBuf },
    /// A transparent background in a format without alpha.
    #[error(
        "{}: JPEG has no alpha channel for --background transparent; use .png or .tif",
        path.display()
    )]
    NoAlpha { path: PathBuf },
    /// A depth image must be PNG (its 16-bit and f32 companions are), or
    /// a float32 TIFF of the depths themselves.
    #[error(
        "{}: the depth mode writes a PNG (and .f32 and .depth16.png beside it) or, with \
         --bit-depth 32, a float32 TIFF of the depths in mm; use a .png name or --bit-depth 32",
        path.display()
    )]
    DepthFormat { path: PathBuf },
    /// 32-bit float channels in a format without them.
    #[error("{}: --bit-depth 32 (float) is written as TIFF only; use .tif or .tiff", path.display())]
    NoFloat { path: PathBuf },
    /// Float TIFF encoding failed.
    #[error("{}: cannot encode the float32 TIFF: {source}", path.display())]
    EncodeFloat {
        path: PathBuf,
        source: tiff::TiffError,
    },
    /// Image encoding failed.
    #[error("{}: cannot encode the image: {source}", path.display())]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// The format of an image at `path`, from its extension (case ignored):
/// PNG, TIFF or JPEG; any other is refused, so `-o x.jpg` never holds PNG
/// bytes.
pub fn image_format(path: &Path) -> Result<image::ImageFormat, SaveError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "png" => Ok(image::ImageFormat::Png),
        "tif" | "tiff" => Ok(image::ImageFormat::Tiff),
        "jpg" | "jpeg" => Ok(image::ImageFormat::Jpeg),
        _ => Err(SaveError::Extension {
            path: path.to_path_buf(),
            found: ext,
        }),
    }
}

/// The files [`save`] writes for an image at `path` with `bits` per
/// channel: the image and, in the depth mode (`depth`) at 8 or 16 bits,
/// `path` with `.f32` and `.depth16.png` (a float32 TIFF holds the depths
/// itself). A depth image may not be named `*.f32`.
pub fn image_files(path: &Path, depth: bool, bits: Bits) -> Result<Vec<PathBuf>, SaveError> {
    if depth && path.extension().is_some_and(|e| e == "f32") {
        return Err(SaveError::F32Name {
            path: path.to_path_buf(),
        });
    }
    let format = image_format(path)?;
    if !depth || (bits == Bits::Float && format == image::ImageFormat::Tiff) {
        return Ok(vec![path.to_path_buf()]);
    }
    if format != image::ImageFormat::Png {
        return Err(SaveError::DepthFormat {
            path: path.to_path_buf(),
        });
    }
    Ok(vec![
        path.to_path_buf(),
        path.with_extension("f32"),
        path.with_extension("depth16.png"),
    ])
}

/// Writes `frame` to `path` as PNG, TIFF or JPEG by its extension
/// ([`image_format`]; 8-bit RGB); the depth mode (PNG) also writes `path`
/// with `.f32` (raw little-endian f32, NaN = miss) and a 16-bit PNG
/// `*.depth16.png` ([`image_files`]). The files are committed as one set
/// (fsutil::FileSet): all are written to temporary files first, then
/// renamed, so a failure replaces none of an older set.
pub fn save(frame: &Frame, path: &Path) -> Result<Vec<PathBuf>, SaveError> {
    save_on(frame, path, ImageSpec::default())
}

/// [`save`] as `spec` says ([`ImageSpec`]).
pub fn save_on(frame: &Frame, path: &Path, spec: ImageSpec) -> Result<Vec<PathBuf>, SaveError> {
    let mut set = FileSet::new();
    let files = stage_on(frame, path, &mut set, spec)?;
    set.commit()?;
    Ok(files)
}

/// What shows where rays cover less than the whole pixel (`render
/// --background`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Background {
    /// This colour, composited under the image (black by default, which
    /// leaves the image as rendered).
    Colour([u8; 3]),
    /// None: an RGBA image whose alpha is the coverage (PNG and TIFF).
    Transparent,
}

impl Default for Background {
    fn default() -> Background {
        Background::BLACK
    }
}

impl Background {
    pub const BLACK: Background = Background::Colour([0, 0, 0]);

    /// Parses `black`, `white`, `transparent`, `R,G,B` (0..=255) or
    /// `#rrggbb`.
    pub fn parse(s: &str) -> Result<Background, BackgroundError> {
        let t = s.trim().to_ascii_lowercase();
        let bad = || BackgroundError {
            found: s.to_string(),
        };
        match t.as_str() {
            "black" => return Ok(Background::BLACK),
            "white" => return Ok(Background::Colour([255; 3])),
            "transparent" | "none" => return Ok(Background::Transparent),
            _ => {}
        }
        if let Some(hex) = t.strip_prefix('#') {
            if hex.len() != 6 {
                return Err(bad());
            }
            let c: Result<Vec<u8>, _> = (0..3)
                .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16))
                .collect();
            let c = c.map_err(|_| bad())?;
            return Ok(Background::Colour([c[0], c[1], c[2]]));
        }
        let c: Vec<u8> = t
            .split(',')
            .map(|x| x.trim().parse::<u8>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        match c[..] {
            [r, g, b] => Ok(Background::Colour([r, g, b])),
            _ => Err(bad()),
        }
    }

    /// Refuses a transparent background for a format without alpha.
    pub fn check(self, path: &Path) -> Result<(), SaveError> {
        if self == Background::Transparent && image_format(path)? == image::ImageFormat::Jpeg {
            return Err(SaveError::NoAlpha {
                path: path.to_path_buf(),
            });
        }
        Ok(())
    }
}

/// Bits per channel of an output image (`--bit-depth 8|16|32`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Bits {
    /// 8-bit integers (every format).
    #[default]
    Eight,
    /// 16-bit integers (PNG and TIFF): the same colours rounded to 16 bits.
    Sixteen,
    /// 32-bit floats (TIFF only). Surface and composite: the colour in
    /// [0, 1] before any rounding. Depth, MIP and cost: one channel of
    /// data ([`Frame::values`]: mm, data units, steps), NaN where a ray
    /// misses, no background.
    Float,
}

/// How an image is written beyond its format: the background and the bits
/// per channel (`render --background`, `--bit-depth`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImageSpec {
    pub background: Background,
    pub bits: Bits,
}

impl ImageSpec {
    /// Refuses what the format of `path` cannot hold: alpha or 16 bits in
    /// JPEG, floats outside TIFF.
    pub fn check(self, path: &Path) -> Result<(), SaveError> {
        self.background.check(path)?;
        let format = image_format(path)?;
        if self.bits == Bits::Sixteen && format == image::ImageFormat::Jpeg {
            return Err(SaveError::No16Bit {
                path: path.to_path_buf(),
            });
        }
        if self.bits == Bits::Float && format != image::ImageFormat::Tiff {
            return Err(SaveError::NoFloat {
                path: path.to_path_buf(),
            });
        }
        Ok(())
    }
}

/// A `--background` that is none of the forms [`Background::parse`] takes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("background {found:?}: expected black, white, transparent, R,G,B (0..=255) or #rrggbb")]
pub struct BackgroundError {
    /// The text given.
    pub found: String,
}

/// `frame`'s colour over `bg` at 8 or 16 bits per channel: RGB over a
/// colour (`rgb + (1 - alpha) * bg`, the premultiplied "over"), or
/// straight (not premultiplied) RGBA.
fn composited(frame: &Frame, bg: Background, sixteen_bit: bool) -> image::DynamicImage {
    use image::DynamicImage as D;
    let (w, h) = (frame.width, frame.height);
    if sixteen_bit {
        let to16 = |x: &f32| (x * 65535.0).round() as u64;
        let rgb: Vec<u64> = frame
            .linear
            .chunks_exact(4)
            .flat_map(|c| c[..3].iter().map(to16))
            .collect();
        let alpha: Vec<u64> = frame.linear.chunks_exact(4).map(|c| to16(&c[3])).collect();
        let (px, rgba) = over(&rgb, &alpha, 65535, bg);
        let px: Vec<u16> = px.into_iter().map(|x| x as u16).collect();
        match rgba {
            false => D::ImageRgb16(image::ImageBuffer::from_raw(w, h, px).unwrap_or_default()),
            true => D::ImageRgba16(image::ImageBuffer::from_raw(w, h, px).unwrap_or_default()),
        }
    } else {
        let widen = |v: &[u8]| v.iter().map(|&x| x as u64).collect::<Vec<_>>();
        let (px, rgba) = over(&widen(&frame.rgb), &widen(&frame.alpha), 255, bg);
        let px: Vec<u8> = px.into_iter().map(|x| x as u8).collect();
        match rgba {
            false => D::ImageRgb8(image::ImageBuffer::from_raw(w, h, px).unwrap_or_default()),
            true => D::ImageRgba8(image::ImageBuffer::from_raw(w, h, px).unwrap_or_default()),
        }
    }
}

/// The float32 TIFF of `frame` (`--bit-depth 32`): its data values in
/// one channel when the mode has them ([`Frame::values`], or the
/// depths), else its
/// colour over `bg` as in [`composited`] but unrounded.
fn float_tiff(frame: &Frame, bg: Background) -> Result<Vec<u8>, tiff::TiffError> {
    use tiff::encoder::{colortype, TiffEncoder};
    let (w, h) = (frame.width, frame.height);
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut enc = TiffEncoder::new(&mut buf)?;
    if let Some(v) = frame.values.as_ref().or(frame.depth.as_ref()) {
        enc.write_image::<colortype::Gray32Float>(w, h, v)?;
        return Ok(buf.into_inner());
    }
    let px = frame.linear.chunks_exact(4);
    match bg {
        Background::Colour(c) => {
            let c = c.map(|x| x as f32 / 255.0);
            let out: Vec<f32> = px
                .flat_map(|p| (0..3).map(move |k| (p[k] + (1.0 - p[3]) * c[k]).min(1.0)))
                .collect();
            enc.write_image::<colortype::RGB32Float>(w, h, &out)?;
        }
        Background::Transparent => {
            let out: Vec<f32> = px
                .flat_map(|p| {
                    let a = p[3];
                    let straight = move |x: f32| if a > 0.0 { (x / a).min(1.0) } else { 0.0 };
                    [straight(p[0]), straight(p[1]), straight(p[2]), a]
                })
                .collect();
            enc.write_image::<colortype::RGBA32Float>(w, h, &out)?;
        }
    }
    Ok(buf.into_inner())
}

/// Channels `rgb` (premultiplied, 3 a pixel) with coverage `alpha`, both
/// in `0..=max`, over `bg`: the output channels, each at most `max`, and
/// whether they are RGBA (a transparent background) rather than RGB.
fn over(rgb: &[u64], alpha: &[u64], max: u64, bg: Background) -> (Vec<u64>, bool) {
    let px = rgb.chunks_exact(3).zip(alpha);
    match bg {
        Background::Colour(c) => {
            // The background's 8-bit channels at `max` (255 -> 65535).
            let c = c.map(|x| x as u64 * max / 255);
            let mut out = Vec::with_capacity(rgb.len());
            for (p, &a) in px {
                for k in 0..3 {
                    out.push((p[k] + ((max - a) * c[k] + max / 2) / max).min(max));
                }
            }
            (out, false)
        }
        Background::Transparent => {
            let mut out = Vec::with_capacity(rgb.len() / 3 * 4);
            for (p, &a) in px {
                for &v in p {
                    let straight = match a {
                        0 => 0,
                        a if a == max => v,
                        a => (v * max + a / 2) / a,
                    };
                    out.push(straight.min(max));
                }
                out.push(a);
            }
            (out, true)
        }
    }
}

/// [`save`] into `set`: the files are written to temporary files and
/// renamed when the caller commits the set (a turntable commits all its
/// frames at once).
pub fn stage(frame: &Frame, path: &Path, set: &mut FileSet) -> Result<Vec<PathBuf>, SaveError> {
    stage_on(frame, path, set, ImageSpec::default())
}

/// [`stage`] as `spec` says ([`ImageSpec`]: background, bits).
pub fn stage_on(
    frame: &Frame,
    path: &Path,
    set: &mut FileSet,
    spec: ImageSpec,
) -> Result<Vec<PathBuf>, SaveError> {
    spec.check(path)?;
    let encode = |img: image::DynamicImage, to: &Path| -> Result<Vec<u8>, SaveError> {
        let mut buf = std::io::Cursor::new(Vec::new());
        img.write_to(&mut buf, image_format(to)?)
            .map_err(|source| SaveError::Encode {
                path: to.to_path_buf(),
                source,
            })?;
        Ok(buf.into_inner())
    };
    let size = |what, found: usize, per_px: usize| SaveError::Size {
        path: path.to_path_buf(),
        what,
        width: frame.width,
        height: frame.height,
        found,
        expected: frame.width as usize * frame.height as usize * per_px,
    };
    let files = image_files(path, frame.depth.is_some(), spec.bits)?;
    let n = frame.width as usize * frame.height as usize;
    if frame.rgb.len() != n * 3 {
        return Err(size("rgb", frame.rgb.len(), 3));
    }
    if frame.alpha.len() != n {
        return Err(size("alpha", frame.alpha.len(), 1));
    }
    if frame.linear.len() != n * 4 {
        return Err(size("linear", frame.linear.len(), 4));
    }
    for (what, v) in [("values", &frame.values), ("depth", &frame.depth)] {
        if let Some(v) = v.as_ref().filter(|v| v.len() != n) {
            return Err(size(what, v.len(), 1));
        }
    }
    if spec.bits == Bits::Float {
        let bytes =
            float_tiff(frame, spec.background).map_err(|source| SaveError::EncodeFloat {
                path: path.to_path_buf(),
                source,
            })?;
        set.add_bytes(path, &bytes)?;
        return Ok(files);
    }
    let img = composited(frame, spec.background, spec.bits == Bits::Sixteen);
    set.add_bytes(path, &encode(img, path)?)?;
    if let Some(d) = &frame.depth {
        let raw: Vec<u8> = d.iter().flat_map(|x| x.to_le_bytes()).collect();
        set.add_bytes(&files[1], &raw)?;
        let (lo, hi) = d
            .iter()
            .filter(|x| x.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let px16: Vec<u16> = d
            .iter()
            .map(|&x| {
                if x.is_finite() {
                    1 + ((x - lo) / (hi - lo).max(1e-30) * 65534.0) as u16
                } else {
                    0
                }
            })
            .collect();
        let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
            frame.width,
            frame.height,
            px16,
        )
        .ok_or_else(|| size("depth", d.len(), 1))?;
        let p16 = &files[2];
        set.add_bytes(p16, &encode(image::DynamicImage::ImageLuma16(img), p16)?)?;
    }
    Ok(files)
}
