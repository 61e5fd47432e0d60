//! The renderer behind `cdvol serve`: the files named on the command
//! line, one brick cache shared by every request, one render at a time,
//! and per-session cancellation.
//!
//! **One render at a time.** A render already uses every worker thread
//! (one rayon task a tile), so running two at once would only interleave
//! them; the render slot is a mutex that also owns the cache. Memory is
//! then the cache budget plus one frame's buffers (at most
//! [`MAX_SIDE`](super::request::MAX_SIDE)^2 pixels) plus the encoded
//! images being sent.
//!
//! **One cache.** A brick cache is built for a scene: the file, and the
//! iso value a render-time `iso` narrows the bricks to (render/brick/envelope.rs),
//! which decides the planes its bricks hold. While requests ask for the
//! same scene they share it; a request for another scene drops it and
//! builds the new scene's cache with the whole budget (docs/SERVE.md).
//!
//! **Cancellation, per session.** Each request of a page carries its
//! session; a newer request of the same session sets the older one's stop
//! flag, so the older render skips every tile it has not started
//! (`render_in_until`) and its client gets 409. Sessions never cancel each
//! other.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use crate::format::reader::PackedVolume;
use crate::format::FormatError;
use crate::progress::NoProgress;
use crate::render::brick::to_f32;
use crate::render::cache::BrickCache;
use crate::render::{render_in_until, Frame, RenderError};

use super::request::{Encoding, RequestError, ViewRequest};

/// A file the server was started with.
pub struct Served {
    /// As named on the command line (shown to the page and in commands).
    pub name: String,
    pub vol: PackedVolume,
}

/// Opens every file of `paths`, in order.
pub fn open_files(paths: &[PathBuf]) -> Result<Vec<Served>, FormatError> {
    paths
        .iter()
        .map(|p: &PathBuf| {
            Ok(Served {
                name: p.display().to_string(),
                vol: PackedVolume::open(Path::new(p))?,
            })
        })
        .collect()
}

/// Why an image request produced no image.
#[derive(Debug, thiserror::Error)]
pub enum Failure {
    /// The request's parameters (400).
    #[error(transparent)]
    Request(#[from] RequestError),
    /// The renderer refused the options, e.g. an iso value outside the
    /// file's classification (400), or failed reading the file (500).
    #[error(transparent)]
    Render(#[from] RenderError),
    /// A newer request of the same session superseded it (409).
    #[error("cancelled: a newer request of session {session} superseded this one")]
    Cancelled { session: String },
    /// The image encoder failed (500).
    #[error("cannot encode the image: {0}")]
    Encode(#[from] image::ImageError),
}

impl Failure {
    /// The HTTP status of the failure.
    pub fn status(&self) -> u16 {
        match self {
            Failure::Request(_) => 400,
            Failure::Render(RenderError::Format(_)) => 500,
            Failure::Render(_) => 400,
            Failure::Cancelled { .. } => 409,
            Failure::Encode(_) => 500,
        }
    }
}

/// An encoded image and what the page shows about it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Rendered {
    #[serde(skip)]
    pub bytes: Vec<u8>,
    #[serde(skip)]
    pub content_type: &'static str,
    pub width: u32,
    pub height: u32,
    /// The height of the view in mm (orthographic), as placed: the page
    /// zooms and pans from it.
    pub frame_mm: Option<f64>,
    /// Seconds rendering (tiles and colouring), encoding, and waiting for
    /// the render slot.
    pub seconds_render: f64,
    pub seconds_encode: f64,
    pub seconds_wait: f64,
    pub rays: u64,
    pub bricks_read: u64,
    pub cache_hits: u64,
    pub cache_misses: u64,
    /// Bytes the shared cache holds at most so far.
    pub peak_cache_bytes: u64,
    /// Whether this request built a new cache (a new scene).
    pub new_cache: bool,
    /// The `cdvol render` command writing this image (PNG).
    pub command: String,
}

/// Counters of the server's life (`/api/status`).
#[derive(Debug, Default, serde::Serialize)]
pub struct Counters {
    pub frames: AtomicU64,
    pub cancelled: AtomicU64,
    pub refused: AtomicU64,
    /// Renders running now (0 or 1: one render slot): a client or test
    /// can tell that a request has started rendering.
    pub rendering: AtomicU64,
}

/// The scene a cache is built for: the file, the scene's iso value (f32
/// bits, as the cache narrows bricks to it), and whether its bricks carry
/// the shaded composite's gradient plane
/// ([`gradient_plane`](crate::render::gradient_plane)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SceneKey {
    file: usize,
    iso_bits: Option<u32>,
    grads: bool,
}

/// The renderer shared by all request handlers.
pub struct Engine<'v> {
    pub files: &'v [Served],
    pub cache_bytes: usize,
    slot: Mutex<Option<(SceneKey, BrickCache)>>,
    sessions: Mutex<HashMap<String, Arc<AtomicBool>>>,
    pool: rayon::ThreadPool,
    pub counters: Counters,
}

impl<'v> Engine<'v> {
    /// An engine over `files` with a cache of `cache_bytes` and `threads`
    /// workers (0: one per core).
    pub fn new(
        files: &'v [Served],
        cache_bytes: usize,
        threads: usize,
    ) -> Result<Engine<'v>, rayon::ThreadPoolBuildError> {
        Ok(Engine {
            files,
            cache_bytes,
            slot: Mutex::new(None),
            sessions: Mutex::new(HashMap::new()),
            pool: rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?,
            counters: Counters::default(),
        })
    }

    /// Renders and encodes `req`, unless a newer request of its session
    /// supersedes it first.
    pub fn render(&self, req: &ViewRequest) -> Result<Rendered, Failure> {
        let served = &self.files[req.file.min(self.files.len().saturating_sub(1))];
        let vol = &served.vol;
        req.check_cost(vol)?;
        let opts = req.options(vol.header(), self.cache_bytes)?;
        let spec = req.camera(vol)?;
        let camera = req.place(vol, &spec)?;
        let command = req.command(&served.name, &spec);
        let stop = self.enter(req.session.as_deref());
        let result = self.render_stoppable(req, vol, &opts, &camera, &stop, command);
        self.leave(req.session.as_deref(), &stop);
        match &result {
            Ok(_) => self.counters.frames.fetch_add(1, Ordering::Relaxed),
            Err(Failure::Cancelled { .. }) => {
                self.counters.cancelled.fetch_add(1, Ordering::Relaxed)
            }
            Err(_) => self.counters.refused.fetch_add(1, Ordering::Relaxed),
        };
        result
    }

    fn render_stoppable(
        &self,
        req: &ViewRequest,
        vol: &'v PackedVolume,
        opts: &crate::render::RenderOptions,
        camera: &crate::render::view::camera::Camera,
        stop: &AtomicBool,
        command: String,
    ) -> Result<Rendered, Failure> {
        let cancelled = || Failure::Cancelled {
            session: req.session.clone().unwrap_or_default(),
        };
        let t_wait = Instant::now();
        let mut slot = self.lock_slot();
        let seconds_wait = t_wait.elapsed().as_secs_f64();
        if stop.load(Ordering::Relaxed) {
            return Err(cancelled());
        }
        let key = SceneKey {
            file: req.file,
            iso_bits: opts.iso.map(|v| to_f32(v).to_bits()),
            grads: crate::render::gradient_plane(opts),
        };
        let new_cache = slot.as_ref().is_none_or(|(k, _)| *k != key);
        if new_cache {
            // Free the old scene's bricks before the new ones come in.
            *slot = None;
            // Later views cull by the sub-blocks of the bricks earlier
            // ones decoded (render/view/cull.rs).
            *slot = Some((key, crate::render::cache_for(vol, opts).with_occupancy()));
        }
        let Some((_, cache)) = slot.as_ref() else {
            return Err(cancelled());
        };
        let t0 = Instant::now();
        self.counters.rendering.fetch_add(1, Ordering::Relaxed);
        let out = self
            .pool
            .install(|| render_in_until(vol, cache, camera, opts, &NoProgress, stop));
        self.counters.rendering.fetch_sub(1, Ordering::Relaxed);
        let out = out?;
        let seconds_render = t0.elapsed().as_secs_f64();
        let Some((frame, stats)) = out else {
            return Err(cancelled());
        };
        let peak_cache_bytes = cache.peak_bytes() as u64;
        let t1 = Instant::now();
        let (bytes, content_type) = encode(&frame, req.encoding)?;
        drop(slot);
        Ok(Rendered {
            bytes,
            content_type,
            width: frame.width,
            height: frame.height,
            frame_mm: match camera.projection {
                crate::render::view::camera::Projection::Ortho { frame_mm } => Some(frame_mm),
                crate::render::view::camera::Projection::Persp { .. } => None,
            },
            seconds_render,
            seconds_encode: t1.elapsed().as_secs_f64(),
            seconds_wait,
            rays: stats.rays,
            bricks_read: stats.bricks_read,
            cache_hits: stats.cache_hits,
            cache_misses: stats.cache_misses,
            peak_cache_bytes,
            new_cache,
            command,
        })
    }

    /// The render slot; a handler that panicked while holding it left
    /// only a cache behind, which is dropped.
    fn lock_slot(&self) -> MutexGuard<'_, Option<(SceneKey, BrickCache)>> {
        self.slot.lock().unwrap_or_else(|poisoned| {
            let mut g = poisoned.into_inner();
            *g = None;
            g
        })
    }

    /// Registers a request of `session`, stopping the session's older
    /// one: the new request's stop flag.
    fn enter(&self, session: Option<&str>) -> Arc<AtomicBool> {
        let flag = Arc::new(AtomicBool::new(false));
        if let Some(s) = session {
            let mut map = self.sessions.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(old) = map.insert(s.to_string(), flag.clone()) {
                old.store(true, Ordering::Relaxed);
            }
        }
        flag
    }

    /// Unregisters `flag` if it is still its session's newest request
    /// (the map holds only requests in flight).
    fn leave(&self, session: Option<&str>, flag: &Arc<AtomicBool>) {
        if let Some(s) = session {
            let mut map = self.sessions.lock().unwrap_or_else(|p| p.into_inner());
            if map.get(s).is_some_and(|f| Arc::ptr_eq(f, flag)) {
                map.remove(s);
            }
        }
    }
}

/// `frame` over black at 8 bits, encoded: PNG with the encoder settings
/// `cdvol render` uses (the same bytes), JPEG or lossless WebP.
pub fn encode(frame: &Frame, enc: Encoding) -> Result<(Vec<u8>, &'static str), image::ImageError> {
    use image::ImageEncoder;
    let mut buf = std::io::Cursor::new(Vec::new());
    let (w, h) = (frame.width, frame.height);
    let rgb = image::ExtendedColorType::Rgb8;
    let kind = match enc {
        Encoding::Png => {
            // The encoder `DynamicImage::write_to` uses, on the frame's
            // plane as it is (no copy).
            image::codecs::png::PngEncoder::new(&mut buf).write_image(&frame.rgb, w, h, rgb)?;
            "image/png"
        }
        Encoding::Jpeg(q) => {
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, q)
                .write_image(&frame.rgb, w, h, rgb)?;
            "image/jpeg"
        }
        Encoding::WebP => {
            image::codecs::webp::WebPEncoder::new_lossless(&mut buf)
                .write_image(&frame.rgb, w, h, rgb)?;
            "image/webp"
        }
    };
    Ok((buf.into_inner(), kind))
}
