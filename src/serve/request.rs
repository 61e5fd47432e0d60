//! What a browser may ask of `cdvol serve`: the query string of an image
//! request parsed into a checked [`ViewRequest`], every number bounded, and
//! its conversion into the renderer's [`View`] and
//! [`RenderOptions`] with the defaults of `cdvol render` (so the image is
//! the one `cdvol render` writes for [`ViewRequest::command`]).
//!
//! Files are addressed by their index on the server's command line: no
//! text of the URL ever names a path.

use crate::format::reader::PackedVolume;
use crate::format::Header;
use crate::orient::NamedView;
use crate::render::job::{Aim, View};
use crate::render::traverse::TGrid;
use crate::render::view::camera::Camera;
use crate::render::HitMethod;
use crate::render::{RenderOptions, Window};

/// Largest image edge the server renders: a frame then needs at most
/// 1024^2 x [`RENDER_BYTES_PER_PIXEL`](crate::render::job::RENDER_BYTES_PER_PIXEL)
/// = 64 MiB besides the cache (`cdvol render` makes bigger images).
pub const MAX_SIDE: u32 = 1024;
/// Longest query string accepted.
pub const MAX_QUERY: usize = 2048;
/// Angles beyond this many degrees are refused (no view needs them).
pub const MAX_ANGLE_DEG: f64 = 3600.0;
/// Composite sample distances, mm.
pub const STEP_MM: (f64, f64) = (0.05, 20.0);

/// Most composite samples one request may ask for, estimated as pixels
/// x (the volume's diagonal / step): about 2.6 times a 1024^2 composite of
/// the real CT at the default 0.5 mm step (7.6e8). A 1024^2 composite at
/// 0.05 mm (7.6e9) held the server for 14.6 s before this bound.
pub const MAX_SAMPLES: f64 = 2e9;

/// An image request that failed its checks: the 400 message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// A parameter the server does not know.
    #[error("unknown parameter {name:?}; known: {KNOWN}")]
    Unknown { name: String },
    /// A parameter given twice.
    #[error("parameter {name:?} given twice, expected once")]
    Repeated { name: String },
    /// A value out of its range or of the wrong form.
    #[error("{name}={value:?}: expected {expected}")]
    Bad {
        name: &'static str,
        value: String,
        expected: String,
    },
    /// The query string is longer than [`MAX_QUERY`].
    #[error("query of {len} bytes, expected at most {MAX_QUERY}")]
    TooLong { len: usize },
    /// Two parameters that exclude each other.
    #[error("{0}")]
    Conflict(String),
    /// A composite whose estimated samples are above [`MAX_SAMPLES`].
    #[error(
        "a composite of about {samples:.1e} samples ({width} x {height} pixels x {path_mm:.0} mm \
         / step {step_mm} mm), above the bound of {MAX_SAMPLES:.1e}: raise step, or lower w and h"
    )]
    TooCostly {
        samples: f64,
        width: u32,
        height: u32,
        path_mm: f64,
        step_mm: f64,
    },
}

const KNOWN: &str = "file, mode, preset, iso, window, level, shadows, hit, view, az, el, \
                     frame, pan, crop, clip, w, h, step, format, quality, session";

/// Image encodings the page may choose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// The bytes `cdvol render -o x.png` writes.
    Png,
    /// Lossy, with this quality (1..=100).
    Jpeg(u8),
    /// Lossless WebP (the `image` crate's encoder is lossless only).
    WebP,
}

/// A checked image request.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewRequest {
    /// Index of the file on the server's command line.
    pub file: usize,
    /// `surface`, `mip`, `composite` or `cost`.
    pub mode: String,
    pub preset: Option<String>,
    pub iso: Option<f64>,
    /// MIP window width and level.
    pub window: Option<(f64, f64)>,
    pub shadows: bool,
    pub hit: HitMethod,
    /// A named view, else `az`/`el`.
    pub view: Option<NamedView>,
    pub az_deg: f64,
    pub el_deg: f64,
    /// Orthographic frame height (zoom), mm; `None`: the object fits
    /// (render/view/framing.rs).
    pub frame_mm: Option<f64>,
    /// Pan in mm along the image's right and up.
    pub pan_mm: Option<[f64; 2]>,
    /// Crop box, mm (`render --crop`).
    pub crop: Option<[[f64; 2]; 3]>,
    /// One clipping plane `[nx, ny, nz, d]` (`render --clip`).
    pub clip: Option<[f64; 4]>,
    pub width: u32,
    pub height: u32,
    pub step_mm: f64,
    /// `step` was given: the composite and MIP integrate by steps
    /// (`render --step` without `--integrate`), else per cell segment.
    pub step_given: bool,
    pub encoding: Encoding,
    /// The client's session: a newer request of it cancels this one.
    pub session: Option<String>,
}

impl ViewRequest {
    /// Parses the query string `q` (without `?`), for a server of `files`
    /// files.
    pub fn parse(q: &str, files: usize) -> Result<ViewRequest, RequestError> {
        if q.len() > MAX_QUERY {
            return Err(RequestError::TooLong { len: q.len() });
        }
        let mut r = ViewRequest {
            file: 0,
            mode: "surface".into(),
            preset: None,
            iso: None,
            window: None,
            shadows: false,
            hit: HitMethod::Int,
            view: None,
            az_deg: 0.0,
            el_deg: 0.0,
            frame_mm: None,
            pan_mm: None,
            crop: None,
            clip: None,
            width: 512,
            height: 512,
            step_mm: 0.5,
            step_given: false,
            encoding: Encoding::Png,
            session: None,
        };
        let mut seen = Vec::new();
        let (mut window, mut level, mut quality) = (None, None, None);
        for pair in q.split('&').filter(|p| !p.is_empty()) {
            let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
            let v = decode(v);
            if seen.contains(&k) {
                return Err(RequestError::Repeated { name: k.into() });
            }
            seen.push(k);
            match k {
                "file" => r.file = int(k, &v, 0, files.saturating_sub(1) as u64)? as usize,
                "mode" => r.mode = one_of("mode", &v, &["surface", "mip", "composite", "cost"])?,
                "preset" => r.preset = Some(preset(&v)?),
                "iso" => r.iso = Some(num("iso", &v, f64::MAX)?),
                "window" => window = Some(num("window", &v, f64::MAX)?),
                "level" => level = Some(num("level", &v, f64::MAX)?),
                "shadows" => r.shadows = one_of("shadows", &v, &["0", "1"])? == "1",
                "hit" => r.hit = hit(&v)?,
                "view" => r.view = Some(view(&v)?),
                "az" => r.az_deg = num("az", &v, MAX_ANGLE_DEG)?,
                "el" => r.el_deg = num("el", &v, MAX_ANGLE_DEG)?,
                "frame" => r.frame_mm = Some(positive("frame", &v)?),
                "pan" => r.pan_mm = Some(pan(&v)?),
                "crop" => r.crop = Some(crop(&v)?),
                "clip" => r.clip = Some(plane(&v)?),
                "w" => r.width = int("w", &v, 1, MAX_SIDE as u64)? as u32,
                "h" => r.height = int("h", &v, 1, MAX_SIDE as u64)? as u32,
                "step" => (r.step_mm, r.step_given) = (step(&v)?, true),
                "format" => {
                    r.encoding = match one_of("format", &v, &["png", "jpeg", "webp"])?.as_str() {
                        "jpeg" => Encoding::Jpeg(85),
                        "webp" => Encoding::WebP,
                        _ => Encoding::Png,
                    }
                }
                "quality" => quality = Some(int("quality", &v, 1, 100)? as u8),
                "session" => r.session = Some(session(&v)?),
                _ => return Err(RequestError::Unknown { name: k.into() }),
            }
        }
        if !seen.contains(&"file") && files == 0 {
            return Err(RequestError::Conflict("the server has no files".into()));
        }
        r.window = match (window, level) {
            (Some(w), Some(l)) if w > 0.0 => Some((w, l)),
            (None, None) => None,
            _ => {
                return Err(RequestError::Conflict(
                    "window and level go together, the width positive".into(),
                ))
            }
        };
        if let Some(q) = quality {
            match r.encoding {
                Encoding::Jpeg(_) => r.encoding = Encoding::Jpeg(q),
                _ => {
                    return Err(RequestError::Conflict(
                        "quality goes with format=jpeg".into(),
                    ))
                }
            }
        }
        if r.preset.is_some() && r.iso.is_some() {
            return Err(RequestError::Conflict(
                "preset and iso exclude each other: a preset brings its iso value".into(),
            ));
        }
        if r.view.is_some() && (seen.contains(&"az") || seen.contains(&"el")) {
            return Err(RequestError::Conflict(
                "view (a named view) excludes az and el".into(),
            ));
        }
        Ok(r)
    }

    /// The render options: `cdvol render`'s defaults with this request's
    /// mode, scene and window, the look resolved as `cdvol render`
    /// resolves it ([`crate::look::resolve`]) and the file's default
    /// traversal ([`crate::render::default_method`]).
    pub fn options(&self, h: &Header, cache_bytes: usize) -> Result<RenderOptions, RequestError> {
        use crate::look::{resolve, Ask, LookError, ModeKind, ResolveError};
        let ask = Ask {
            mode: Some(match self.mode.as_str() {
                "mip" => ModeKind::Mip,
                "cost" => ModeKind::Cost,
                "composite" => ModeKind::Composite,
                _ => ModeKind::Surface,
            }),
            preset: self.preset.clone(),
            preset_range: None,
            force: false,
            iso: self.iso,
            tf: None,
            window: self
                .window
                .map(|(width, level)| Window::Fixed { width, level }),
            shade: false,
            hit: self.hit,
            shadows: self.shadows,
            step_mm: self.step_mm,
            labels: None,
            lut: None,
        };
        let bad_preset = |expected: String| RequestError::Bad {
            name: "preset",
            value: self.preset.clone().unwrap_or_default(),
            expected,
        };
        let look = resolve(h, &ask).map_err(|e| match e {
            ResolveError::Preset(e @ LookError::WrongModality { .. }) => bad_preset(e.to_string()),
            ResolveError::Preset(_) => {
                bad_preset(format!("a preset: {}", crate::look::offered_names(h)))
            }
            ResolveError::NoTransferFunction => RequestError::Conflict(
                "mode=composite needs a preset (its transfer function)".into(),
            ),
            ResolveError::NoIso { .. } => {
                bad_preset(format!("a preset with an iso value for mode={}", self.mode))
            }
            ResolveError::Labels(m) => RequestError::Conflict(m),
        })?;
        let cap_colours = look.cap_colours();
        let mut o = RenderOptions::new(look.mode, crate::render::default_method(h));
        o.cache_bytes = cache_bytes;
        o.iso = look.iso;
        o.window = look.window;
        o.cap_colours = cap_colours;
        o.look = look.look;
        if self.step_given {
            o.integrate = crate::render::Integrate::Step;
        }
        o.clip = crate::render::clip::Clip {
            crop: self.crop,
            planes: self
                .clip
                .map(|p| crate::render::clip::Plane {
                    normal: [p[0], p[1], p[2]],
                    d: p[3],
                })
                .into_iter()
                .collect(),
        };
        let axes = &h.axes;
        let lo = axes.each_ref().map(|a| a.coords()[0]);
        let hi = axes.each_ref().map(|a| a.coords()[a.coords().len() - 1]);
        o.clip.check(lo, hi).map_err(|e| {
            let (name, value) = match (&e, self.clip) {
                (crate::render::clip::ClipError::BadPlane { .. }, Some(p)) => {
                    ("clip", format!("{},{},{},{}", p[0], p[1], p[2], p[3]))
                }
                _ => ("crop", String::new()),
            };
            RequestError::Bad {
                name,
                value,
                expected: e.to_string(),
            }
        })?;
        Ok(o)
    }

    /// The camera: an orbit or named view, or, when panned, the same
    /// view's eye and target shifted (`--eye --target --up`).
    pub fn camera(&self, vol: &PackedVolume) -> Result<View, RequestError> {
        let view = match self.view {
            Some(v) => Aim::Named(v),
            None => Aim::Orbit {
                az_deg: self.az_deg,
                el_deg: self.el_deg,
            },
        };
        let spec = View {
            aim: view,
            persp_fov_deg: None,
            frame_mm: self.frame_mm,
            width: self.width,
            height: self.height,
        };
        let Some([dx, dy]) = self.pan_mm.filter(|p| *p != [0.0, 0.0]) else {
            return Ok(spec);
        };
        let mirrored = vol
            .header()
            .orientation
            .as_ref()
            .is_some_and(|o| o.nearest().det() < 0.0);
        if mirrored {
            return Err(RequestError::Conflict(
                "pan: this file's sample axes are mirrored in the patient, and a mirrored \
                 view has no --eye/--target/--up equivalent; orbit and zoom only"
                    .into(),
            ));
        }
        let cam = self.place(vol, &spec)?;
        let bounds = TGrid::<f64>::new(&vol.header().axes).bounds();
        let shift = dx * cam.right + dy * cam.up;
        let eye = cam.eye + shift;
        let dist = (0..3)
            .map(|k| (bounds.1[k] - bounds.0[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let target = eye + cam.forward * dist;
        let frame = match cam.projection {
            crate::render::view::camera::Projection::Ortho { frame_mm } => frame_mm,
            crate::render::view::camera::Projection::Persp { .. } => dist,
        };
        Ok(View {
            aim: Aim::LookAt {
                eye: eye.to_array(),
                target: target.to_array(),
                up: cam.up.to_array(),
            },
            frame_mm: Some(frame),
            ..spec
        })
    }

    /// Refuses a composite whose estimated samples (pixels x the
    /// volume's diagonal / step: no ray samples more than that) are above
    /// [`MAX_SAMPLES`], before it holds the render slot.
    pub fn check_cost(&self, vol: &PackedVolume) -> Result<(), RequestError> {
        if self.mode != "composite" {
            return Ok(());
        }
        let (lo, hi) = TGrid::<f64>::new(&vol.header().axes).bounds();
        let path_mm = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let samples = self.width as f64 * self.height as f64 * (path_mm / self.step_mm).max(1.0);
        if samples > MAX_SAMPLES {
            return Err(RequestError::TooCostly {
                samples,
                width: self.width,
                height: self.height,
                path_mm,
                step_mm: self.step_mm,
            });
        }
        Ok(())
    }

    /// `spec` placed against `vol`, framing this request's scene as
    /// `cdvol render` does (render/view/framing.rs).
    pub fn place(&self, vol: &PackedVolume, spec: &View) -> Result<Camera, RequestError> {
        let orientation = vol.header().orientation.as_ref();
        spec.framing(vol, &self.options(vol.header(), 0)?, 1, 0.0, orientation)
            .and_then(|framing| spec.place(&framing, 0.0, orientation))
            .map_err(|e| self.bad_view(e.to_string()))
    }

    fn bad_view(&self, why: String) -> RequestError {
        RequestError::Bad {
            name: "view",
            value: format!(
                "{} az={} el={}{}{}",
                self.view.map_or("orbit", |v| v.name()),
                self.az_deg,
                self.el_deg,
                self.frame_mm
                    .map_or(String::new(), |f| format!(" frame={f}")),
                self.pan_mm
                    .map_or(String::new(), |[x, y]| format!(" pan={x},{y}"))
            ),
            expected: why,
        }
    }

    /// The `cdvol render` command that writes this image as `view.png`,
    /// `path` being the file as named on the server's command line.
    pub fn command(&self, path: &str, spec: &View) -> String {
        let mut a: Vec<String> = vec!["cdvol".into(), "render".into(), quote(path)];
        a.extend([
            "-o".into(),
            "view.png".into(),
            "--mode".into(),
            self.mode.clone(),
        ]);
        let mut flag = |f: &str, v: String| a.extend([f.to_string(), v]);
        if let Some(p) = &self.preset {
            flag("--preset", quote(p));
        }
        if let Some(v) = self.iso {
            flag("--iso", v.to_string());
        }
        if self.mode == "surface" && self.hit != HitMethod::Int {
            flag("--hit", hit_name(self.hit).into());
        }
        if let Some((w, l)) = self.window.filter(|_| self.mode == "mip") {
            flag("--window", w.to_string());
            flag("--level", l.to_string());
        }
        if self.mode == "composite" {
            flag("--step", self.step_mm.to_string());
        }
        flag("--width", self.width.to_string());
        flag("--height", self.height.to_string());
        match spec.aim {
            Aim::Named(v) => flag("--view", v.name().into()),
            Aim::Orbit { az_deg, el_deg } => flag("--view", format!("{az_deg},{el_deg}")),
            Aim::LookAt { eye, target, up } => {
                let t = |p: [f64; 3]| format!("{},{},{}", p[0], p[1], p[2]);
                flag("--eye", t(eye));
                flag("--target", t(target));
                flag("--up", t(up));
            }
        }
        if let Some(f) = spec.frame_mm {
            flag("--frame", f.to_string());
        }
        if let Some(c) = self.crop {
            flag(
                "--crop",
                format!(
                    "{}:{},{}:{},{}:{}",
                    c[0][0], c[0][1], c[1][0], c[1][1], c[2][0], c[2][1]
                ),
            );
        }
        if let Some(p) = self.clip {
            flag("--clip", format!("{},{},{},{}", p[0], p[1], p[2], p[3]));
        }
        if self.shadows && self.mode == "surface" {
            a.push("--shadows".into());
        }
        a.join(" ")
    }
}

/// `s` quoted for a POSIX shell when it needs it.
fn quote(s: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "/._-+,=:@".contains(c);
    if !s.is_empty() && s.chars().all(plain) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// Percent-decoding of a query value (`+` is a space); invalid escapes
/// stay as they are, and the value is then refused by its own check.
fn decode(v: &str) -> String {
    let b = v.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match b[i] {
            b'%' if i + 2 < b.len() => match (hex(b[i + 1]), hex(b[i + 2])) {
                (Some(h), Some(l)) => {
                    out.push((h * 16 + l) as u8);
                    i += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            c => out.push(c),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn bad(name: &'static str, v: &str, expected: impl Into<String>) -> RequestError {
    RequestError::Bad {
        name,
        value: v.chars().take(80).collect(),
        expected: expected.into(),
    }
}

fn int(name: &str, v: &str, lo: u64, hi: u64) -> Result<u64, RequestError> {
    let name = static_name(name);
    match v.parse::<u64>() {
        Ok(n) if (lo..=hi).contains(&n) => Ok(n),
        _ => Err(bad(name, v, format!("a whole number in {lo}..={hi}"))),
    }
}

/// The parameter's name as a `&'static str` (they are all in [`KNOWN`]).
fn static_name(name: &str) -> &'static str {
    KNOWN
        .split(", ")
        .find(|k| *k == name)
        .unwrap_or("parameter")
}

fn num(name: &'static str, v: &str, max_abs: f64) -> Result<f64, RequestError> {
    match v.parse::<f64>() {
        Ok(x) if x.is_finite() && x.abs() <= max_abs => Ok(x),
        _ => Err(bad(
            name,
            v,
            format!("a finite number of at most {max_abs:e} in size"),
        )),
    }
}

fn positive(name: &'static str, v: &str) -> Result<f64, RequestError> {
    match v.parse::<f64>() {
        Ok(x) if x > 0.0 && x <= 1e6 => Ok(x),
        _ => Err(bad(name, v, "a number of mm in (0, 1e6]")),
    }
}

fn step(v: &str) -> Result<f64, RequestError> {
    match v.parse::<f64>() {
        Ok(x) if (STEP_MM.0..=STEP_MM.1).contains(&x) => Ok(x),
        _ => Err(bad(
            "step",
            v,
            format!("mm in {}..={}", STEP_MM.0, STEP_MM.1),
        )),
    }
}

fn pan(v: &str) -> Result<[f64; 2], RequestError> {
    let p: Vec<f64> = v.split(',').filter_map(|x| x.trim().parse().ok()).collect();
    match p[..] {
        [x, y] if x.is_finite() && y.is_finite() && x.abs() <= 1e6 && y.abs() <= 1e6 => Ok([x, y]),
        _ => Err(bad("pan", v, "DX,DY in mm, each at most 1e6 in size")),
    }
}

/// `crop=X0:X1,Y0:Y1,Z0:Z1` (mm; checked against the file in `options`).
fn crop(v: &str) -> Result<[[f64; 2]; 3], RequestError> {
    let expected = "X0:X1,Y0:Y1,Z0:Z1 in mm, finite, each low below its high";
    let mut out = [[0.0; 2]; 3];
    let parts: Vec<&str> = v.split(',').collect();
    if parts.len() != 3 {
        return Err(bad("crop", v, expected));
    }
    for (k, p) in parts.iter().enumerate() {
        let ab: Vec<f64> = p.split(':').filter_map(|x| x.trim().parse().ok()).collect();
        match ab[..] {
            [a, b]
                if a.is_finite() && b.is_finite() && a < b && a.abs() <= 1e9 && b.abs() <= 1e9 =>
            {
                out[k] = [a, b]
            }
            _ => return Err(bad("crop", v, expected)),
        }
    }
    Ok(out)
}

/// `clip=NX,NY,NZ,D`: one plane, keeping `n . p >= D`.
fn plane(v: &str) -> Result<[f64; 4], RequestError> {
    let p: Vec<f64> = v.split(',').filter_map(|x| x.trim().parse().ok()).collect();
    match p[..] {
        [x, y, z, d]
            if [x, y, z, d].iter().all(|c| c.is_finite() && c.abs() <= 1e9)
                && [x, y, z] != [0.0; 3] =>
        {
            Ok([x, y, z, d])
        }
        _ => Err(bad(
            "clip",
            v,
            "NX,NY,NZ,D: a finite non-zero normal and a finite D",
        )),
    }
}

fn one_of(name: &'static str, v: &str, allowed: &[&str]) -> Result<String, RequestError> {
    if allowed.contains(&v) {
        Ok(v.to_string())
    } else {
        Err(bad(name, v, format!("one of {}", allowed.join(", "))))
    }
}

fn preset(v: &str) -> Result<String, RequestError> {
    crate::presets::get(v).map(|p| p.name).map_err(|_| {
        bad(
            "preset",
            v,
            format!("a preset: {}", crate::presets::names()),
        )
    })
}

fn hit(v: &str) -> Result<HitMethod, RequestError> {
    Ok(
        match one_of("hit", v, &["int", "bisect", "newton", "exact"])?.as_str() {
            "bisect" => HitMethod::Bisect,
            "newton" => HitMethod::Newton,
            "exact" => HitMethod::Exact,
            _ => HitMethod::Int,
        },
    )
}

/// The `cdvol render --hit` name of `h`.
pub fn hit_name(h: HitMethod) -> &'static str {
    match h {
        HitMethod::Int => "int",
        HitMethod::Bisect => "bisect",
        HitMethod::Newton => "newton",
        HitMethod::Exact => "exact",
    }
}

fn view(v: &str) -> Result<NamedView, RequestError> {
    NamedView::parse(v).ok_or_else(|| bad("view", v, NamedView::NAMES))
}

fn session(v: &str) -> Result<String, RequestError> {
    let ok = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '_';
    if (1..=64).contains(&v.len()) && v.chars().all(ok) {
        Ok(v.to_string())
    } else {
        Err(bad("session", v, "1 to 64 letters, digits, - or _"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_bounds() {
        let r = ViewRequest::parse("", 1).unwrap();
        assert_eq!((r.width, r.height, r.mode.as_str()), (512, 512, "surface"));
        for bad in [
            "w=0",
            "w=1025",
            "h=-3",
            "az=nan",
            "az=1e9",
            "frame=0",
            "file=1",
            "mode=depth",
            "hit=magic",
            "preset=..%2Fetc",
            "view=up",
            "pan=1",
            "step=0",
            "quality=50",
            "session=a%20b",
            "w=1&w=2",
            "path=/etc/passwd",
            "window=3",
            "iso=1&preset=ct-bone",
            "crop=1:2,3:4",
            "crop=2:1,0:1,0:1",
            "crop=0:1,0:1,0:nan",
            "clip=0,0,0,1",
            "clip=1,0,0",
            "clip=1,0,0,inf",
        ] {
            assert!(ViewRequest::parse(bad, 1).is_err(), "{bad} accepted");
        }
        let long = "a".repeat(MAX_QUERY + 1);
        assert!(matches!(
            ViewRequest::parse(&long, 1),
            Err(RequestError::TooLong { .. })
        ));
    }

    #[test]
    fn decodes_percent_and_plus() {
        assert_eq!(decode("a%2Cb+c%zz%4"), "a,b c%zz%4");
        let r = ViewRequest::parse("pan=1.5%2C-2&format=jpeg&quality=70", 1).unwrap();
        assert_eq!(r.pan_mm, Some([1.5, -2.0]));
        assert_eq!(r.encoding, Encoding::Jpeg(70));
    }

    #[test]
    fn takes_a_crop_box_and_a_plane() {
        let r = ViewRequest::parse("crop=0:10.5,-2:3,1:4&clip=0%2C1%2C0%2C-125", 1).unwrap();
        assert_eq!(r.crop, Some([[0.0, 10.5], [-2.0, 3.0], [1.0, 4.0]]));
        assert_eq!(r.clip, Some([0.0, 1.0, 0.0, -125.0]));
    }

    #[test]
    fn quotes_for_the_shell() {
        assert_eq!(quote("a/b.cdv"), "a/b.cdv");
        assert_eq!(quote("it's here"), "'it'\\''s here'");
    }
}
