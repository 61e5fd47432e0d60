//! The library's front door: open a packed file, render views of it.
//!
//! ```no_run
//! use cdvol::{Look, View, Volume};
//!
//! let vol = Volume::open("head.cdv".as_ref())?;
//! let renderer = vol.renderer();
//! for (name, az) in [("front", 0.0), ("side", 90.0)] {
//!     let image = renderer.render(&View::orbit(az, 0.0, 512, 512), &Look::default())?;
//!     image.save(format!("{name}.png").as_ref())?;
//! }
//! # Ok::<(), cdvol::Error>(())
//! ```
//!
//! A [`Renderer`] owns its brick cache: it borrows nothing, it is `Send`
//! and `Sync`, and the bricks one render decodes are there for the next
//! (a loop over views is warm). A [`Look`] is resolved against the file
//! at each render ([`look::resolve`](crate::look::resolve), as `cdvol
//! render` and `serve` do): a preset is checked against the file's
//! modality and placed on its values, and a file prepared with a preset
//! is drawn in that preset's look when the look asks for nothing else.
//! The images are those `cdvol render` writes for the same view and look
//! (tests/all/library.rs).

use std::path::Path;
use std::sync::{Arc, Mutex};

use crate::export::{write_raw, ExportWhat, RawError};
use crate::format::histogram::ValueHistogram;
use crate::format::reader::PackedVolume;
use crate::format::{FormatError, Header};
use crate::info::Info;
use crate::look::{resolve, Ask, ResolveError};
use crate::presets::Preset;
use crate::progress::{NoProgress, Progress};
use crate::render::cache::BrickCache;
use crate::render::clip::Clip;
use crate::render::job::{Aim, View};
use crate::render::traverse::Method;
use crate::render::view::camera::CameraError;
use crate::render::{
    default_method, float_rgba, planes_for, render_in, rgba8, Background, Frame, RenderError,
    RenderOptions, SaveError, Stats,
};

/// Why a library call failed: the file, the look, the view, the render or
/// the save, each with the message of the step that refused.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error(transparent)]
    Look(#[from] ResolveError),
    #[error(transparent)]
    View(#[from] CameraError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Save(#[from] SaveError),
    /// An array export whose brick does not decode.
    #[error(transparent)]
    Export(#[from] RawError),
}

/// A packed file, open. Cloning it is cheap and shares the open file.
#[derive(Clone)]
pub struct Volume {
    packed: PackedVolume,
}

impl Volume {
    /// Opens and checks a packed file (`cdvol prep`'s output).
    pub fn open(path: &Path) -> Result<Volume, Error> {
        Ok(Volume {
            packed: PackedVolume::open(path)?,
        })
    }

    /// The file's header: grid, classification, modality, look.
    pub fn header(&self) -> &Header {
        self.packed.header()
    }

    /// The presets this file offers: those of its modality, MR presets
    /// placed on its values.
    pub fn presets(&self) -> Vec<Preset> {
        crate::look::offered(self.header())
    }

    /// A renderer of this file with the default cache budget (512 MiB).
    pub fn renderer(&self) -> Renderer {
        Renderer::new(self)
    }

    /// What `cdvol info` reports of the file (`cdvol info --json` prints
    /// it as JSON).
    pub fn info(&self) -> Info {
        Info::of(&self.packed)
    }

    /// The histogram of the file's rescaled values that prep recorded;
    /// `None` for files written before it was.
    pub fn histogram(&self) -> Option<&ValueHistogram> {
        self.header().summary.histogram.as_ref()
    }

    /// `what` of the whole volume as `cdvol export` writes its raw file
    /// (little-endian, x fastest): the samples (`header().dims`) in the
    /// file's type (`header().dtype`), or one `u8` per cell for codes and
    /// classes (`header().cells()`). Decoded one brick slab at a time
    /// into the array returned.
    pub fn export(&self, what: ExportWhat, progress: &dyn Progress) -> Result<Vec<u8>, Error> {
        let h = self.header();
        let (n, size) = match what {
            ExportWhat::Values => (h.dims, h.dtype.size() as u64),
            _ => (h.cells(), 1),
        };
        let mut out = Vec::with_capacity((n.iter().product::<u64>() * size) as usize);
        write_raw(&self.packed, what, &mut out, progress)?;
        Ok(out)
    }

    /// The reader underneath, for the lower-level calls of
    /// [`render`](crate::render).
    pub fn packed(&self) -> &PackedVolume {
        &self.packed
    }
}

/// How a view looks: what [`look::resolve`](crate::look::resolve) takes
/// (mode, preset, iso value, transfer function, window, shading), and the
/// traversal. `Look::default()` is what `cdvol render FILE` draws with no
/// options: the file's own look if it was prepared with a preset, else a
/// surface at its iso value.
#[derive(Debug, Clone, Default)]
pub struct Look {
    pub ask: Ask,
    /// The traversal; `None`: the file's default (CD on the grid it was
    /// prepared for, [`default_method`]).
    pub method: Option<Method>,
    /// Keep the colour before rounding ([`Image::rgba_f32`], `render
    /// --bit-depth 16` and `32`).
    pub unrounded: bool,
    /// The crop box and clipping planes (`render --crop`, `--clip`); the
    /// default keeps everything.
    pub clip: Clip,
    /// Leave surfaces cut by the clip open (`render --no-cap`) instead of
    /// showing their cut faces.
    pub uncapped: bool,
    /// A label file drawn inside a surface or composite (`render
    /// --overlay`); `ask.labels` chooses the labels of a label file
    /// rendered on its own.
    pub overlay: Option<crate::render::Overlay>,
    /// How composites and MIPs integrate along a ray (`render
    /// --integrate`); `None`: the default
    /// ([`Integrate::default`](crate::render::Integrate)).
    pub integrate: Option<crate::render::Integrate>,
}

impl Look {
    /// Preset `name`, as `cdvol render --preset NAME`: a surface at the
    /// preset's iso value; set `ask.mode` for its composite or MIP look
    /// ([`Look::preset_in`]).
    pub fn preset(name: &str) -> Look {
        let mut l = Look::default();
        l.ask.preset = Some(name.into());
        l
    }

    /// Preset `name` in `mode` (`cdvol render --mode MODE --preset NAME`):
    /// its transfer function for a composite, its window for a MIP.
    pub fn preset_in(name: &str, mode: crate::look::ModeKind) -> Look {
        let mut l = Look::preset(name);
        l.ask.mode = Some(mode);
        l
    }

    /// A shaded surface at iso value `iso`.
    pub fn surface(iso: f64) -> Look {
        let mut l = Look::default();
        l.ask.mode = Some(crate::look::ModeKind::Surface);
        l.ask.iso = Some(iso);
        l
    }
}

impl View {
    /// An orbit view around the object's box, framed on it: azimuth and
    /// elevation in degrees (patient axes when the file records its
    /// orientation), orthographic, `width` x `height` pixels.
    pub fn orbit(az_deg: f64, el_deg: f64, width: u32, height: u32) -> View {
        View {
            aim: Aim::Orbit { az_deg, el_deg },
            persp_fov_deg: None,
            frame_mm: None,
            width,
            height,
        }
    }
}

/// A rendered image and the statistics of its render.
#[derive(Debug, Clone)]
pub struct Image {
    pub frame: Frame,
    pub stats: Stats,
}

impl Image {
    /// The image at 8 bits a channel, four a pixel, row by row from the
    /// top: the colour `save` writes over `background` (a PNG's bytes) and
    /// the coverage; with [`Background::Transparent`] the PNG's straight
    /// RGBA.
    pub fn rgba8(&self, background: Background) -> Vec<u8> {
        rgba8(&self.frame, background)
    }

    /// [`Image::rgba8`] unrounded, as `--bit-depth 32` writes it; empty
    /// unless the look kept it ([`Look::unrounded`]).
    pub fn rgba_f32(&self, background: Background) -> Vec<f32> {
        float_rgba(&self.frame, background)
    }

    /// Writes the image (PNG, TIFF or JPEG by the extension) through a
    /// temporary file renamed when complete.
    pub fn save(&self, path: &Path) -> Result<(), Error> {
        crate::render::save(&self.frame, path)?;
        Ok(())
    }
}

/// Renders views of one file through a brick cache it owns.
pub struct Renderer {
    vol: PackedVolume,
    cache_bytes: usize,
    /// The cache of the last scene: kept while later renders need the
    /// same planes beside each brick, rebuilt (the old one dropped first)
    /// when they need others.
    cache: Mutex<Option<Arc<BrickCache>>>,
}

impl Renderer {
    /// A renderer of `vol` with the default cache budget (512 MiB).
    pub fn new(vol: &Volume) -> Renderer {
        Renderer {
            vol: vol.packed.clone(),
            cache_bytes: crate::render::DEFAULT_CACHE_BYTES,
            cache: Mutex::new(None),
        }
    }

    /// This renderer with a cache of at most `bytes` of decoded bricks.
    pub fn with_cache_bytes(mut self, bytes: usize) -> Renderer {
        self.cache_bytes = bytes;
        self
    }

    /// The options `look` resolves to on this file, as `cdvol render`
    /// resolves its flags.
    pub fn options(&self, look: &Look) -> Result<RenderOptions, Error> {
        let h = self.vol.header();
        let r = resolve(h, &look.ask)?;
        let cap_colours = r.cap_colours();
        let mut opts = RenderOptions::new(r.mode, look.method.unwrap_or_else(|| default_method(h)));
        opts.iso = r.iso;
        opts.window = r.window;
        opts.cap_colours = cap_colours;
        opts.look = r.look;
        opts.unrounded = look.unrounded;
        opts.clip = look.clip.clone();
        opts.cap = !look.uncapped;
        opts.overlay = look.overlay.clone();
        if let Some(i) = look.integrate {
            opts.integrate = i;
        }
        opts.cache_bytes = self.cache_bytes;
        Ok(opts)
    }

    /// Renders `view` of the file in `look`.
    pub fn render(&self, view: &View, look: &Look) -> Result<Image, Error> {
        let opts = self.options(look)?;
        let orientation = self.vol.header().orientation.as_ref();
        let framing = view.framing(&self.vol, &opts, 1, 0.0, orientation)?;
        let camera = view.place(&framing, 0.0, orientation)?;
        let cache = self.cache_for(&opts);
        let (frame, stats) = render_in(&self.vol, &cache, &camera, &opts, &NoProgress)?;
        Ok(Image { frame, stats })
    }

    /// The cache for a render with `opts`: the last one when it carries
    /// the same planes, else a new one (later views cull by the
    /// sub-blocks earlier ones decoded).
    fn cache_for(&self, opts: &RenderOptions) -> Arc<BrickCache> {
        let planes = planes_for(&self.vol, opts);
        let mut slot = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = slot.as_ref().filter(|c| c.planes() == planes) {
            return Arc::clone(c);
        }
        // Free the old scene's bricks before the new ones come in.
        *slot = None;
        let c =
            Arc::new(BrickCache::with_planes(&self.vol, self.cache_bytes, planes).with_occupancy());
        *slot = Some(Arc::clone(&c));
        c
    }
}
