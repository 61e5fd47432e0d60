//! A whole `cdvol render` job, as the CLI asks for it: place the camera
//! (an orbit, or eye/target/up framed to the volume), then render one
//! image, one part of a sharded render (shard.rs), or a turntable of
//! numbered frames sharing one brick cache, and write the images, parts
//! and statistics. The CLI only converts its arguments into a
//! [`RenderJob`].
//!
//! ```text
//! tiles.rs  one frame: Morton-ordered tiles, one rayon task each, a ray
//!           per pixel through the integrators
//! shard.rs  parts of a sharded render: write, read, assemble
//! here      the job: camera framing, turntables, numbered frames
//! ```

pub mod shard;
pub(crate) mod tiles;

use std::path::{Path, PathBuf};

use crate::format::reader::PackedVolume;
use crate::fsutil::{FileSet, OutputError, WriteError};
use crate::orient::{AxisMap, NamedView, Orientation};
use crate::progress::Progress;
use crate::render::cache::BrickCache;
use crate::render::error::RenderError;
use crate::render::job::shard::{render_part, PartError};
use crate::render::job::tiles::{render, render_in, Shard};
use crate::render::options::Mode;
use crate::render::options::RenderOptions;
use crate::render::output::scalebar::{ScaleBar, ScaleBarError};
use crate::render::output::{image_files, stage_on, Bits, ImageSpec, SaveError};
use crate::render::stats::Stats;
use crate::render::template::render_template;
use crate::render::traverse::TGrid;
use crate::render::view::camera::{orbit_dirs, Camera, CameraError, Projection};
use crate::render::view::framing::Framing;

/// Where the camera stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Aim {
    /// Around the centre of the object's box (the volume's for a scene
    /// with no 1-cell; render/view/framing.rs), degrees: in patient axes (LPS:
    /// 0,0 looks at the face, head up) when the file records its
    /// orientation, else in the file's sample axes.
    Orbit { az_deg: f64, el_deg: f64 },
    /// A view in patient terms; needs a file that records its orientation.
    Named(NamedView),
    /// Exactly, in mm ([`Camera::look_at`]); an orthographic frame then
    /// defaults to the volume's diagonal.
    LookAt {
        eye: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
    },
}

/// The camera of a job, before it is placed against the volume.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    pub aim: Aim,
    /// Perspective with this vertical field of view in degrees; `None`
    /// for orthographic.
    pub persp_fov_deg: Option<f64>,
    /// Orthographic frame height in mm (default: the object fits,
    /// render/view/framing.rs).
    pub frame_mm: Option<f64>,
    pub width: u32,
    pub height: u32,
}

impl View {
    /// What this camera frames on `vol` for `opts`'s scene
    /// (render/view/framing.rs): the object's box ([`Framing::of`]), fitted to
    /// the directions of all `frames` frames of a turntable over
    /// `orbit_deg` degrees (1 and 0 for a single image), so that one frame
    /// fits them all; only the volume for an exact eye (no brick read).
    pub fn framing(
        &self,
        vol: &PackedVolume,
        opts: &RenderOptions,
        frames: u32,
        orbit_deg: f64,
        orientation: Option<&Orientation>,
    ) -> Result<Framing, CameraError> {
        if let Aim::LookAt { .. } = self.aim {
            return Ok(Framing::volume(
                TGrid::<f64>::new(&vol.header().axes).bounds(),
            ));
        }
        let framing = Framing::of(vol, opts);
        if framing.object.is_none() {
            return Ok(framing);
        }
        // More frames are refused later (`outputs`).
        let n = frames.clamp(1, MAX_FRAMES);
        let dirs = (0..n)
            .map(|f| match f {
                0 => self.direction(0.0, orientation),
                _ => self.direction(orbit_deg * f as f64 / n as f64, orientation),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(framing.fitted(&dirs, self.persp_fov_deg, self.width, self.height))
    }

    /// The camera for `framing`, turned by `az_turn_deg` of azimuth
    /// (turntables; 0 for a single image). Orbits and named views look at
    /// the centre of the object's box with the frame `framing` fits
    /// ([`crate::render::view::framing::orbit`]; `frame_mm` when given). With an
    /// `orientation`, orbits and named views are in patient axes: placed
    /// in LPS, then turned into sample axes through the nearest signed
    /// permutation (and mirrored when the sample axes are mirrored in the
    /// patient). Eye, target and up stay in sample-axis mm, an
    /// orthographic frame defaulting to the volume's diagonal.
    pub fn place(
        &self,
        framing: &Framing,
        az_turn_deg: f64,
        orientation: Option<&Orientation>,
    ) -> Result<Camera, CameraError> {
        if let Aim::LookAt { eye, target, up } = self.aim {
            let projection = match self.persp_fov_deg {
                Some(fov_deg) => Projection::Persp { fov_deg },
                None => {
                    let (lo, hi) = framing.volume;
                    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
                    Projection::Ortho {
                        frame_mm: self.frame_mm.unwrap_or(diag * 1.02),
                    }
                }
            };
            return Camera::look_at(eye, target, up, projection, self.width, self.height);
        }
        let map = orientation.map_or(AxisMap::IDENTITY, Orientation::nearest);
        let cam = crate::render::view::framing::orbit(
            framing,
            self.direction(az_turn_deg, orientation)?,
            self.persp_fov_deg,
            self.frame_mm,
            self.width,
            self.height,
        )?;
        Ok(if map.det() < 0.0 { cam.mirrored() } else { cam })
    }

    /// The direction from the centre to the eye and the up vector of an
    /// orbit or named view turned by `az_turn_deg`, in sample axes.
    fn direction(
        &self,
        az_turn_deg: f64,
        orientation: Option<&Orientation>,
    ) -> Result<crate::render::view::framing::Dir, CameraError> {
        let (back, up) = match (self.aim, orientation) {
            (Aim::Named(v), None) => return Err(CameraError::NoOrientation { view: v.name() }),
            (Aim::Named(v), Some(_)) => {
                let (az, el) = v.az_el();
                let (back, up) = orbit_dirs(az + az_turn_deg, el);
                if v.is_axial() {
                    // Anterior (the face) at the top of the image.
                    let a = (az + az_turn_deg).to_radians();
                    let s = -el.signum();
                    (back, [s * a.sin(), -s * a.cos(), 0.0])
                } else {
                    (back, up)
                }
            }
            (Aim::Orbit { az_deg, el_deg }, _) => orbit_dirs(az_deg + az_turn_deg, el_deg),
            // `place` places exact eyes itself.
            (Aim::LookAt { .. }, _) => orbit_dirs(az_turn_deg, 0.0),
        };
        let map = orientation.map_or(AxisMap::IDENTITY, Orientation::nearest);
        Ok((map.to_sample(back), map.to_sample(up)))
    }
}

/// One `cdvol render` run.
#[derive(Debug, Clone)]
pub struct RenderJob {
    pub camera: View,
    pub options: RenderOptions,
    /// Template-based CD (paper section 4.2.2, render/template/) instead of the
    /// tile renderer; leaps like `options.method`.
    pub template: bool,
    /// The PNG (or, with `shard` and one frame, the part file `*.cdvpart`);
    /// a turntable writes `NAME.0000.png` ...
    pub output: PathBuf,
    /// Where to write the statistics as JSON (per frame for turntables).
    pub stats: Option<PathBuf>,
    /// Frames of a turntable (1: a single image).
    pub frames: u32,
    /// Degrees of azimuth the turntable covers.
    pub orbit_deg: f64,
    /// One image: render only these tiles, into a part file. A turntable:
    /// render frame `f` when `f % n == k`.
    pub shard: Option<Shard>,
    /// Worker threads (`None`: rayon's default, all cores).
    pub threads: Option<usize>,
    /// The background where rays cover less than the pixel (black: the
    /// image as rendered) and the bits per channel.
    pub image: ImageSpec,
    /// Bytes the render may plan to use ([`render_memory`]); None: the
    /// default, [`crate::memory::default_limit`] (3/4 of RAM).
    pub mem_limit: Option<u64>,
    /// A scale bar in the images (orthographic views only).
    pub scale_bar: Option<ScaleBar>,
}

/// Why a render job failed. Fields are named as in [`RenderJob`].
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("camera: {0}")]
    Camera(#[from] CameraError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Save(#[from] SaveError),
    #[error(transparent)]
    Part(#[from] PartError),
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("{}: cannot encode statistics: {source}", path.display())]
    StatsJson {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("frames 0, expected at least 1")]
    NoFrames,
    /// More frames than a turntable may have ([`MAX_FRAMES`]).
    #[error("frames {frames}, expected at most {MAX_FRAMES}")]
    TooManyFrames { frames: u32 },
    /// An output cannot be written or is the packed file read (checked
    /// before any ray).
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(transparent)]
    ScaleBar(#[from] ScaleBarError),
    /// Turntables orbit the volume; an exact eye cannot turn.
    #[error("frames {frames}: a turntable orbits the volume, so its view must be an orbit, not eye, target and up")]
    TurntableLookAt { frames: u32 },
    #[error("the template traversal renders whole images: it takes no shard")]
    TemplateShard,
    #[error("the template traversal renders the whole volume: it takes no crop or clip")]
    TemplateClip,
    /// A part file is a piece of an image; `cdvol assemble` has no camera.
    #[error("--scale-bar: a shard of one image is a part file; draw the bar on a whole image")]
    ScaleBarShard,
    /// A single image's shard is written as a part file.
    #[error("{}: a shard's output is a part file for `cdvol assemble`; name it NAME.cdvpart", path.display())]
    PartName { path: PathBuf },
    #[error("cannot start the thread pool: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
    /// The planned memory ([`render_memory`]) is above the limit.
    #[error(
        "the render needs about {} (cache {} + {width} x {height} pixels x \
         {per_pixel} bytes + {} fixed), above the memory limit of {limit}",
        crate::memory::human(*needed),
        crate::memory::human(*cache as u64),
        crate::memory::human(RENDER_FIXED_BYTES)
    )]
    Memory {
        needed: u64,
        cache: usize,
        width: u32,
        height: u32,
        /// Bytes a pixel ([`render_bytes_per_pixel`]).
        per_pixel: u64,
        limit: String,
    },
    /// A job field out of its range (`threads`, `orbit_deg`).
    #[error("{field} {value}, expected {expected}")]
    Bound {
        field: &'static str,
        value: String,
        expected: String,
    },
}

/// Bytes a pixel of one frame costs at most in [`render_memory`] when the
/// pixels are kept until the whole image is made (cost and depth maps,
/// the automatic MIP window, 16-bit and float outputs, parts, the
/// template renderer): the tiles' pixels before colouring (28), the RGB
/// bytes, coverage, depth or values and step counts (3 + 1 + 4 + 4), the
/// unrounded colour when kept (16), and the encoder's copy. Measured:
/// 20.5 bytes a pixel for a 4096^2 depth render of the head CT, 23.0 for
/// a 16-bit surface render (docs/RELIABILITY.md, "Memory").
pub const RENDER_BYTES_PER_PIXEL: u64 = 64;

/// Bytes a pixel of one frame costs at most in [`render_memory`] when the
/// tiles colour their own pixels into 8-bit planes (render/output/canvas.rs:
/// surface, composite, MIP with a given window) and keep none: the RGB
/// bytes, coverage and step counts (3 + 1 + 4), a MIP's values (4), the
/// encoder's copy (4) and the PNG's bytes (at most about 4). Measured: 7.1
/// (surface), 6.6 (composite) and 11.2 (MIP) bytes a pixel for 4096^2
/// renders of the head CT.
pub const PAINTED_BYTES_PER_PIXEL: u64 = 24;

/// [`PAINTED_BYTES_PER_PIXEL`] when a render of `vol` with `opts` (to an
/// 8-bit image: `opts.unrounded` not set) colours its pixels in its tiles,
/// else [`RENDER_BYTES_PER_PIXEL`]. `painted`: whether the job renders
/// whole images by tiles at all (not the template renderer, not the part
/// file of a shard).
pub fn render_bytes_per_pixel(vol: &PackedVolume, opts: &RenderOptions, painted: bool) -> u64 {
    let paints = painted
        && !opts.unrounded
        && crate::render::output::colour::Colouring::of(vol, opts).paints();
    match paints {
        true => PAINTED_BYTES_PER_PIXEL,
        false => RENDER_BYTES_PER_PIXEL,
    }
}

/// Bytes of a render's fixed overhead in [`render_memory`].
pub const RENDER_FIXED_BYTES: u64 = 64 << 20;

/// Bytes a sample of the volume costs at most in the brick cache (f32
/// values with the brick apron, codes, levels, octants, DDA planes).
pub const CACHE_BYTES_PER_SAMPLE: u64 = 16;

/// A render's planned peak memory: the brick cache (its budget, or the
/// whole volume decoded at [`CACHE_BYTES_PER_SAMPLE`] if that is less:
/// `cache_bytes` here is that smaller figure), plus `per_pixel` bytes
/// ([`render_bytes_per_pixel`]) per pixel of one frame (turntables render
/// one frame at a time), plus [`RENDER_FIXED_BYTES`].
pub fn render_memory(cache_bytes: usize, width: u32, height: u32, per_pixel: u64) -> u64 {
    (cache_bytes as u64)
        .saturating_add(per_pixel.saturating_mul(width as u64 * height as u64))
        .saturating_add(RENDER_FIXED_BYTES)
}

/// Most worker threads of a render.
pub const MAX_THREADS: usize = 1024;

/// Most frames of a turntable (all are committed together at the end).
pub const MAX_FRAMES: u32 = 100_000;

impl RenderJob {
    /// Every file the job writes: the image (with the depth mode's
    /// companions), the part file of a shard, or each frame of a
    /// turntable (those of its shard), then the statistics.
    pub fn outputs(&self) -> Result<Vec<PathBuf>, JobError> {
        if self.frames > MAX_FRAMES {
            return Err(JobError::TooManyFrames {
                frames: self.frames,
            });
        }
        let depth = matches!(self.options.mode, Mode::Depth { .. });
        let mut v = Vec::new();
        if self.frames > 1 {
            for f in 0..self.frames {
                if self.shard.is_none_or(|s| f % s.n == s.k) {
                    v.extend(image_files(
                        &numbered(&self.output, f),
                        depth,
                        self.image.bits,
                    )?);
                }
            }
        } else if self.shard.is_some() {
            v.push(self.output.clone());
        } else {
            v.extend(image_files(&self.output, depth, self.image.bits)?);
        }
        if self.shard.is_none() || self.frames > 1 {
            self.image.check(&self.output)?;
        }
        v.extend(self.stats.iter().cloned());
        Ok(v)
    }
}

/// Runs `job` on `vol`: the files written, and the statistics (summed
/// over the frames of a turntable). Every output is checked before any
/// ray ([`RenderJob::outputs`], fsutil::check_outputs: none may be the
/// packed file read, a directory, or in a directory that cannot be
/// written), and all of a job's files are committed together after the
/// last one is written: a failure replaces none of them.
pub fn run(
    vol: &PackedVolume,
    job: &RenderJob,
    progress: &dyn Progress,
) -> Result<(Vec<PathBuf>, Stats), JobError> {
    if job.frames > 1 && matches!(job.camera.aim, Aim::LookAt { .. }) {
        return Err(JobError::TurntableLookAt { frames: job.frames });
    }
    let orientation = vol.header().orientation.as_ref();
    // One frame for all of a turntable's frames (render/view/framing.rs).
    let framing = job
        .camera
        .framing(vol, &job.options, job.frames, job.orbit_deg, orientation)?;
    let camera = job.camera.place(&framing, 0.0, orientation)?;
    if job.template && job.shard.is_some() {
        return Err(JobError::TemplateShard);
    }
    if job.template && !job.options.clip.is_none() {
        return Err(JobError::TemplateClip);
    }
    if job.frames == 0 {
        return Err(JobError::NoFrames);
    }
    let (width, height) = (job.camera.width, job.camera.height);
    let samples = vol.header().dims.iter().product::<u64>();
    let cache =
        (job.options.cache_bytes as u64).min(CACHE_BYTES_PER_SAMPLE.saturating_mul(samples));
    let cache = usize::try_from(cache).unwrap_or(usize::MAX);
    let opts = RenderOptions {
        unrounded: job.options.unrounded || job.image.bits != Bits::Eight,
        ..job.options.clone()
    };
    // A shard of one image writes its pixels to a part file; a shard of
    // a turntable renders whole frames.
    let whole = job.shard.is_none() || job.frames > 1;
    let per_pixel = render_bytes_per_pixel(vol, &opts, !job.template && whole);
    let needed = render_memory(cache, width, height, per_pixel);
    let limit = job.mem_limit.unwrap_or_else(crate::memory::default_limit);
    if needed > limit {
        return Err(JobError::Memory {
            needed,
            cache,
            width,
            height,
            per_pixel,
            limit: crate::memory::describe_limit(limit, job.mem_limit.is_some()),
        });
    }
    if let Some(n) = job.threads.filter(|n| !(1..=MAX_THREADS).contains(n)) {
        return Err(JobError::Bound {
            field: "threads",
            value: n.to_string(),
            expected: format!("1..={MAX_THREADS}"),
        });
    }
    if job.frames > 1 && !job.orbit_deg.is_finite() {
        return Err(JobError::Bound {
            field: "orbit_deg",
            value: job.orbit_deg.to_string(),
            expected: "a finite number of degrees".into(),
        });
    }
    if job.frames == 1
        && job.shard.is_some()
        && job.output.extension().is_none_or(|e| e != "cdvpart")
    {
        return Err(JobError::PartName {
            path: job.output.clone(),
        });
    }
    if job.scale_bar.is_some() {
        if job.camera.persp_fov_deg.is_some() {
            return Err(ScaleBarError::Perspective.into());
        }
        let data = match job.options.mode {
            Mode::Depth { .. } => Some("depth"),
            Mode::Mip => Some("MIP"),
            Mode::Cost => Some("cost"),
            _ => None,
        };
        if let Some(mode) = data.filter(|_| job.image.bits == Bits::Float) {
            return Err(ScaleBarError::Data { mode }.into());
        }
        if job.shard.is_some() && job.frames == 1 {
            return Err(JobError::ScaleBarShard);
        }
        // The bar must fit before any ray.
        if let Some((mm, mm_per_px)) = bar_scale(job.scale_bar, &camera) {
            crate::render::output::scalebar::layout(mm, mm_per_px, width, height)?;
        }
    }
    crate::fsutil::check_outputs(&job.outputs()?, &[vol.path().to_path_buf()], None)?;
    let work = || {
        if job.frames > 1 {
            turntable(vol, job, &framing, progress)
        } else if let Some(shard) = job.shard {
            part(vol, job, &camera, shard, progress)
        } else {
            image(vol, job, &camera, progress)
        }
    };
    match job.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()?
            .install(work),
        None => work(),
    }
}

/// Renders by the job's renderer (template or tiles).
fn render_one(
    vol: &PackedVolume,
    cache: Option<&BrickCache>,
    cam: &Camera,
    job: &RenderJob,
    progress: &dyn Progress,
) -> Result<(crate::render::Frame, Stats), RenderError> {
    // 16-bit and float outputs need the frame's unrounded colour.
    let opts = if job.image.bits != Bits::Eight && !job.options.unrounded {
        std::borrow::Cow::Owned(RenderOptions {
            unrounded: true,
            ..job.options.clone()
        })
    } else {
        std::borrow::Cow::Borrowed(&job.options)
    };
    match (job.template, cache) {
        (true, _) => render_template(vol, cam, &opts, progress),
        (false, Some(cache)) => render_in(vol, cache, cam, &opts, progress),
        (false, None) => render(vol, cam, &opts, progress),
    }
}

/// A single image and its statistics.
fn image(
    vol: &PackedVolume,
    job: &RenderJob,
    camera: &Camera,
    progress: &dyn Progress,
) -> Result<(Vec<PathBuf>, Stats), JobError> {
    let (mut frame, stats) = render_one(vol, None, camera, job, progress)?;
    add_scale_bar(&mut frame, camera, job.scale_bar)?;
    let mut set = FileSet::new();
    stage_on(&frame, &job.output, &mut set, job.image)?;
    if let Some(p) = &job.stats {
        add_json(&mut set, p, &stats)?;
    }
    Ok((set.commit()?, stats))
}

/// The length in mm of `bar` in `cam`'s image and the mm a pixel spans;
/// `None` without a bar or in a perspective view (refused in [`run`]).
fn bar_scale(bar: Option<ScaleBar>, cam: &Camera) -> Option<(f64, f64)> {
    let (Some(bar), Projection::Ortho { frame_mm }) = (bar, cam.projection) else {
        return None;
    };
    let mm_per_px = frame_mm / cam.height as f64;
    Some((bar.length_mm(cam.width, mm_per_px), mm_per_px))
}

/// Draws `bar` into `frame` as seen by `cam`.
fn add_scale_bar(
    frame: &mut crate::render::Frame,
    cam: &Camera,
    bar: Option<ScaleBar>,
) -> Result<(), ScaleBarError> {
    if let Some((mm, mm_per_px)) = bar_scale(bar, cam) {
        crate::render::output::scalebar::draw(frame, mm, mm_per_px)?;
    }
    Ok(())
}

/// One shard of a single image, as a part file.
fn part(
    vol: &PackedVolume,
    job: &RenderJob,
    camera: &Camera,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<(Vec<PathBuf>, Stats), JobError> {
    let part = render_part(vol, camera, &job.options, shard, progress)?;
    let mut set = FileSet::new();
    set.add_bytes(&job.output, &part.to_bytes(&job.output)?)?;
    if let Some(p) = &job.stats {
        add_json(&mut set, p, &part.stats)?;
    }
    Ok((set.commit()?, part.stats))
}

/// A turntable: frame `f` at azimuth `orbit_deg * f / frames` past the
/// view, all frames through one cache (later frames reuse decoded
/// bricks); a shard renders its frames only.
fn turntable(
    vol: &PackedVolume,
    job: &RenderJob,
    framing: &Framing,
    progress: &dyn Progress,
) -> Result<(Vec<PathBuf>, Stats), JobError> {
    let (mut set, mut total, mut per_frame) = (FileSet::new(), Stats::default(), Vec::new());
    // Later frames cull by the sub-blocks of the bricks earlier ones
    // decoded (render/view/cull.rs).
    let cache = crate::render::cache_for(vol, &job.options).with_occupancy();
    for f in 0..job.frames {
        if job.shard.is_some_and(|s| f % s.n != s.k) {
            continue;
        }
        let cam = job.camera.place(
            framing,
            job.orbit_deg * f as f64 / job.frames as f64,
            vol.header().orientation.as_ref(),
        )?;
        let (mut frame, stats) = render_one(vol, Some(&cache), &cam, job, progress)?;
        add_scale_bar(&mut frame, &cam, job.scale_bar)?;
        stage_on(&frame, &numbered(&job.output, f), &mut set, job.image)?;
        total.merge(&stats);
        per_frame.push(stats);
    }
    // The frames shared one cache: its own count is exact.
    if !job.template {
        total.bricks_distinct = cache.distinct_read();
    }
    total.bricks_total = vol.header().brick_count();
    if let Some(p) = &job.stats {
        add_json(&mut set, p, &per_frame)?;
    }
    Ok((set.commit()?, total))
}

/// `out.png` -> `out.0007.png`: frame `f` of a turntable.
pub fn numbered(path: &Path, f: u32) -> PathBuf {
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_else(|| "png".into());
    path.with_file_name(format!("{stem}.{f:04}.{ext}"))
}

/// Adds `value` as pretty JSON for `p` to `set`.
fn add_json(set: &mut FileSet, p: &Path, value: &impl serde::Serialize) -> Result<(), JobError> {
    let bytes = serde_json::to_vec_pretty(value).map_err(|source| JobError::StatsJson {
        path: p.to_path_buf(),
        source,
    })?;
    Ok(set.add_bytes(p, &bytes)?)
}
