//! Image output, the last stage of a render: a coloured [`Frame`]
//! (colour.rs makes it from the pixels by the mode's
//! [`Colouring`](crate::render::Colouring)) is written by [`save`] as
//! PNG, TIFF or JPEG by the output's extension (plus raw f32 and 16-bit
//! PNG depth in the depth mode).
//!
//! ```text
//! colour.rs    pixels -> colours by the mode (grey, TF, depth, cost)
//! canvas.rs    a tile's pixels painted into the frame
//! scalebar.rs  the scale bar drawn into a frame
//! grain.rs     the wood-grain measure of a composite image
//! here         the frame, its bit depths and the atomic save
//! ```

pub(crate) mod canvas;
pub(crate) mod colour;
pub mod grain;
pub mod scalebar;

use std::path::{Path, PathBuf};

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
    /// Empty unless the render kept them
    /// ([`RenderOptions::unrounded`](crate::render::RenderOptions::unrounded)).
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
    /// A 16-bit or float image of a frame rendered without its unrounded
    /// colour.
    #[error(
        "{}: a {what} image needs the frame's unrounded colour, which this render did not keep \
         (RenderOptions::unrounded)",
        path.display()
    )]
    Rounded { path: PathBuf, what: &'static str },
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
/// (`image_format`; 8-bit RGB); the depth mode (PNG) also writes `path`
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
///
/// One pass from the frame's planes into the image's own buffer: no
/// widened copy of the planes (a 1024^2 frame once took about 60 MB of
/// fresh temporaries here; docs/BENCHMARKS.md, "Per-frame memory").
fn composited(frame: &Frame, bg: Background, sixteen_bit: bool) -> image::DynamicImage {
    use image::DynamicImage as D;
    let (w, h) = (frame.width, frame.height);
    if sixteen_bit {
        let to16 = |x: f32| (x * 65535.0).round() as u64;
        let px = frame
            .linear
            .chunks_exact(4)
            .map(|c| ([to16(c[0]), to16(c[1]), to16(c[2])], to16(c[3])));
        let (px, rgba) = over(px, 65535, bg, |x| x as u16);
        match rgba {
            false => D::ImageRgb16(image::ImageBuffer::from_raw(w, h, px).unwrap_or_default()),
            true => D::ImageRgba16(image::ImageBuffer::from_raw(w, h, px).unwrap_or_default()),
        }
    } else {
        let px = frame
            .rgb
            .chunks_exact(3)
            .zip(&frame.alpha)
            .map(|(c, &a)| ([c[0], c[1], c[2]].map(u64::from), u64::from(a)));
        let (px, rgba) = over(px, 255, bg, |x| x as u8);
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
    let px = float_rgba(frame, bg);
    match bg {
        Background::Colour(_) => {
            let out: Vec<f32> = px
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            enc.write_image::<colortype::RGB32Float>(w, h, &out)?;
        }
        Background::Transparent => enc.write_image::<colortype::RGBA32Float>(w, h, &px)?,
    }
    Ok(buf.into_inner())
}

/// The colour of `frame` at 8 bits as [`save`] writes it, four channels
/// a pixel: the colour over `bg` and the coverage, or with a transparent
/// background the straight RGBA of the PNG.
pub fn rgba8(frame: &Frame, bg: Background) -> Vec<u8> {
    match composited(frame, bg, false) {
        image::DynamicImage::ImageRgba8(b) => b.into_raw(),
        img => img
            .into_rgb8()
            .into_raw()
            .chunks_exact(3)
            .zip(&frame.alpha)
            .flat_map(|(c, &a)| [c[0], c[1], c[2], a])
            .collect(),
    }
}

/// The colour of `frame` unrounded, four channels a pixel, as the
/// float32 TIFF of `--bit-depth 32` holds it: the colour over `bg` and the
/// coverage, or with a transparent background straight RGBA. Empty when
/// the render did not keep it ([`Frame::linear`]).
pub fn float_rgba(frame: &Frame, bg: Background) -> Vec<f32> {
    let px = frame.linear.chunks_exact(4);
    match bg {
        Background::Colour(c) => {
            let c = c.map(|x| x as f32 / 255.0);
            px.flat_map(|p| {
                let over = |k: usize| (p[k] + (1.0 - p[3]) * c[k]).min(1.0);
                [over(0), over(1), over(2), p[3]]
            })
            .collect()
        }
        Background::Transparent => px
            .flat_map(|p| {
                let a = p[3];
                let straight = move |x: f32| if a > 0.0 { (x / a).min(1.0) } else { 0.0 };
                [straight(p[0]), straight(p[1]), straight(p[2]), a]
            })
            .collect(),
    }
}

/// Pixels `(rgb, alpha)` (colour premultiplied by the coverage, both in
/// `0..=max`) over `bg`: the output channels, each at most `max`, cast
/// by `cast`, and whether they are RGBA (a transparent background)
/// rather than RGB.
fn over<T>(
    px: impl Iterator<Item = ([u64; 3], u64)>,
    max: u64,
    bg: Background,
    cast: impl Fn(u64) -> T,
) -> (Vec<T>, bool) {
    let n = px.size_hint().0;
    match bg {
        Background::Colour(c) => {
            // The background's 8-bit channels at `max` (255 -> 65535).
            let c = c.map(|x| x as u64 * max / 255);
            let mut out = Vec::with_capacity(3 * n);
            for (p, a) in px {
                for k in 0..3 {
                    out.push(cast((p[k] + ((max - a) * c[k] + max / 2) / max).min(max)));
                }
            }
            (out, false)
        }
        Background::Transparent => {
            let mut out = Vec::with_capacity(4 * n);
            for (p, a) in px {
                for v in p {
                    let straight = match a {
                        0 => 0,
                        a if a == max => v,
                        a => (v * max + a / 2) / a,
                    };
                    out.push(cast(straight.min(max)));
                }
                out.push(cast(a));
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
    // 16 bits, and floats of a colour (not of data values), read `linear`.
    let what = match spec.bits {
        Bits::Sixteen => Some("16-bit"),
        Bits::Float if frame.values.is_none() && frame.depth.is_none() => Some("float"),
        _ => None,
    };
    if let Some(what) = what.filter(|_| frame.linear.is_empty()) {
        return Err(SaveError::Rounded {
            path: path.to_path_buf(),
            what,
        });
    }
    if !frame.linear.is_empty() && frame.linear.len() != n * 4 {
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

#[cfg(test)]
mod tests {
    use super::{composited, Background, Frame};
    use proptest::prelude::*;

    /// The composition as it was before it went from the planes straight
    /// into the image buffer: both planes widened to `u64`, composited,
    /// then narrowed. The oracle of the one-pass [`composited`].
    fn composited_reference(frame: &Frame, bg: Background, sixteen_bit: bool) -> Vec<u16> {
        let over = |rgb: &[u64], alpha: &[u64], max: u64| -> Vec<u64> {
            let px = rgb.chunks_exact(3).zip(alpha);
            match bg {
                Background::Colour(c) => {
                    let c = c.map(|x| x as u64 * max / 255);
                    let mut out = Vec::new();
                    for (p, &a) in px {
                        for k in 0..3 {
                            out.push((p[k] + ((max - a) * c[k] + max / 2) / max).min(max));
                        }
                    }
                    out
                }
                Background::Transparent => {
                    let mut out = Vec::new();
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
                    out
                }
            }
        };
        let out = if sixteen_bit {
            let to16 = |x: &f32| (x * 65535.0).round() as u64;
            let rgb: Vec<u64> = frame
                .linear
                .chunks_exact(4)
                .flat_map(|c| c[..3].iter().map(to16))
                .collect();
            let alpha: Vec<u64> = frame.linear.chunks_exact(4).map(|c| to16(&c[3])).collect();
            over(&rgb, &alpha, 65535)
        } else {
            let widen = |v: &[u8]| v.iter().map(|&x| x as u64).collect::<Vec<_>>();
            over(&widen(&frame.rgb), &widen(&frame.alpha), 255)
        };
        out.into_iter().map(|x| x as u16).collect()
    }

    /// An f32 channel as the colouring leaves it: in [0, 1], or NaN.
    fn unit() -> impl Strategy<Value = f32> {
        prop_oneof![
            8 => 0.0f32..=1.0,
            1 => Just(0.0f32),
            1 => Just(1.0f32),
            1 => Just(f32::NAN),
        ]
    }

    fn background() -> impl Strategy<Value = Background> {
        prop_oneof![
            Just(Background::BLACK),
            Just(Background::Transparent),
            any::<[u8; 3]>().prop_map(Background::Colour),
        ]
    }

    /// A frame rendered without its unrounded colour saves at 8 bits, and
    /// refuses 16 bits and float colour by name; float data values (MIP,
    /// cost, depth) do not need it.
    #[test]
    fn frames_without_the_unrounded_colour() {
        use super::{save_on, Bits, ImageSpec, SaveError};
        let dir = tempfile::tempdir().expect("temporary directory");
        let (w, h) = (3u32, 2u32);
        let n = (w * h) as usize;
        let frame = Frame {
            width: w,
            height: h,
            rgb: vec![200; 3 * n],
            alpha: vec![255; n],
            linear: Vec::new(),
            depth: None,
            values: None,
            steps: vec![0; n],
        };
        let spec = |bits| ImageSpec {
            background: Background::BLACK,
            bits,
        };
        let png = dir.path().join("a.png");
        save_on(&frame, &png, spec(Bits::Eight)).expect("8-bit PNG");
        let img = image::open(&png).expect("readable PNG").to_rgb8();
        assert!(img.pixels().all(|p| p.0 == [200; 3]));
        for (path, bits, what) in [
            ("b.png", Bits::Sixteen, "16-bit"),
            ("c.tif", Bits::Float, "float"),
        ] {
            let path = dir.path().join(path);
            match save_on(&frame, &path, spec(bits)) {
                Err(e @ SaveError::Rounded { .. }) => {
                    let text = e.to_string();
                    assert!(
                        text.contains(what) && text.contains(&*path.to_string_lossy()),
                        "{text}"
                    );
                }
                other => panic!("{bits:?}: expected SaveError::Rounded, got {other:?}"),
            }
            assert!(!path.exists(), "{bits:?}: nothing written");
        }
        let mip = Frame {
            values: Some(vec![1.5; n]),
            ..frame
        };
        let tif = dir.path().join("d.tif");
        save_on(&mip, &tif, spec(Bits::Float)).expect("float TIFF of data values");
        assert!(tif.exists());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn composited_equals_the_widened_composition(
            (w, h, rgb, alpha, linear) in (1u32..12, 1u32..12).prop_flat_map(|(w, h)| {
                let n = (w * h) as usize;
                (
                    Just(w),
                    Just(h),
                    proptest::collection::vec(any::<u8>(), 3 * n),
                    // Coverage often at its ends, where the straight colour
                    // takes its special cases.
                    proptest::collection::vec(prop_oneof![Just(0u8), Just(255u8), any::<u8>()], n),
                    proptest::collection::vec(unit(), 4 * n),
                )
            }),
            bg in background(),
            sixteen_bit in any::<bool>(),
        ) {
            let frame = Frame {
                width: w,
                height: h,
                rgb,
                alpha,
                linear,
                depth: None,
                values: None,
                steps: vec![0; (w * h) as usize],
            };
            let img = composited(&frame, bg, sixteen_bit);
            let got: Vec<u16> = if sixteen_bit {
                img.as_bytes()
                    .chunks_exact(2)
                    .map(|b| u16::from_ne_bytes([b[0], b[1]]))
                    .collect()
            } else {
                img.as_bytes().iter().map(|&b| b as u16).collect()
            };
            prop_assert_eq!(img.width(), w);
            prop_assert_eq!(img.height(), h);
            prop_assert_eq!(img.color().has_alpha(), bg == Background::Transparent);
            prop_assert_eq!(got, composited_reference(&frame, bg, sixteen_bit));
        }
    }
}
