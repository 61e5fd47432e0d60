//! Sharded rendering: `cdvol render --shard K/N` renders tile `i` (Morton
//! order) when `i % N == K` (or, with `--shard-layout blocks`, the K-th
//! contiguous run of the Morton curve) into a part file; `cdvol assemble`
//! checks that
//! the parts belong to one render (same file contents, camera, options and
//! N), that every shard and every tile is there exactly once, and colours
//! the image with the same code as a single-process render
//! (`tiles::finish`), so the bytes are the same.
//! A single-process render never comes here: it calls the tile scheduler
//! and the image output directly.
//!
//! Part file (little-endian): magic `CDVPART\x02`, u64 length of a JSON
//! header (`PartHeader`: the [`RenderKey`], the shard, its [`Stats`] and
//! the tile rectangles), the header, then per tile in header order its
//! pixels row by row, 25 bytes each (3 f32 colour, f32 alpha, f32 depth,
//! u32 steps, u8 hit), then a u32 CRC-32 of everything before it. Written to a
//! temporary file and renamed when complete.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use super::tiles::TilePx;
use super::tiles::{finish, render_shard, Shard, ShardLayout};
use crate::classify::TransferFunction;
use crate::format::reader::PackedVolume;
use crate::fsutil::{write_atomic, WriteError};
use crate::progress::Progress;
use crate::render::cache::BrickCache;
use crate::render::error::RenderError;
use crate::render::integrate::Px;
use crate::render::options::{Mode, RenderOptions};
pub use crate::render::output::colour::Colouring;
use crate::render::output::Frame;
use crate::render::stats::Stats;
use crate::render::view::camera::{Camera, Projection};

/// Renders the tiles of `shard` (pixels before colouring, and their
/// counters): one part of a render for [`assemble`].
pub fn render_part(
    vol: &PackedVolume,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<Part, RenderError> {
    let cache = crate::render::cache_for(vol, opts);
    render_part_in(vol, &cache, camera, opts, shard, progress)
}

/// [`render_part`] with a brick cache from [`crate::render::cache_for`]
/// (with another cache the result is the same, only slower or larger).
pub fn render_part_in(
    vol: &PackedVolume,
    cache: &BrickCache,
    camera: &Camera,
    opts: &RenderOptions,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<Part, RenderError> {
    let (tiles, stats) = render_shard(vol, cache, camera, opts, shard, progress)?;
    Ok(Part {
        key: RenderKey::new(vol, camera, opts, shard.n, shard.layout),
        shard,
        tiles,
        stats,
    })
}

/// The camera as a part key stores it: the placed frame (unit forward,
/// right and up) and the projection, in mm and degrees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraKey {
    pub eye: [f64; 3],
    pub forward: [f64; 3],
    pub right: [f64; 3],
    pub up: [f64; 3],
    /// `ortho` or `persp`.
    pub projection: String,
    /// Orthographic frame height in mm.
    pub frame_mm: Option<f64>,
    /// Perspective vertical field of view in degrees.
    pub fov_deg: Option<f64>,
    pub width: u32,
    pub height: u32,
}

impl CameraKey {
    pub fn new(c: &Camera) -> CameraKey {
        let (projection, frame_mm, fov_deg) = match c.projection {
            Projection::Ortho { frame_mm } => ("ortho", Some(frame_mm), None),
            Projection::Persp { fov_deg } => ("persp", None, Some(fov_deg)),
        };
        CameraKey {
            eye: c.eye.to_array(),
            forward: c.forward.to_array(),
            right: c.right.to_array(),
            up: c.up.to_array(),
            projection: projection.into(),
            frame_mm,
            fov_deg,
            width: c.width,
            height: c.height,
        }
    }
}

/// The render options as a part key stores them, by stable names (the
/// cache budget left out: it never changes the output).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OptionsKey {
    /// [`Mode::name`].
    pub mode: String,
    /// Surface and depth: [`HitMethod::name`](crate::render::sample::hit::HitMethod::name).
    pub hit: Option<String>,
    /// Surface: shadow rays.
    pub shadows: Option<bool>,
    /// Composite: the transfer function and the sample distance.
    pub tf: Option<TransferFunction>,
    pub step_mm: Option<f64>,
    /// [`Method::name`](crate::render::traverse::Method::name).
    pub method: String,
    pub bisect_iters: u32,
    pub newton_iters: u32,
    pub newton_tol: f64,
    /// [`Precision::name`](crate::render::Precision::name).
    pub precision: String,
    pub tile: u32,
    pub cd_lazy_min: Option<u8>,
    /// Composite: the sampler's arithmetic, the early-stop opacity and
    /// the look.
    pub sampling: Option<String>,
    /// Composite and MIP: `--integrate` other than `step` (absent from
    /// manifests written before it existed, which integrated by steps).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrate: Option<String>,
    /// Composite: `--sample-batches` (absent from manifests written
    /// before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_batches: Option<bool>,
    pub early_stop: Option<f64>,
    pub look: Option<crate::render::CompositeLook>,
    /// Surface and composite: [`Normals::name`](crate::render::Normals::name).
    pub normals: Option<String>,
    /// The scene's iso value (`render --iso`), when given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iso: Option<f64>,
    /// Labels: the chosen labels, their colours and opacities (debug
    /// text, which round-trips floats).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<String>,
}

impl OptionsKey {
    pub fn new(o: &RenderOptions) -> OptionsKey {
        let (mut hit, mut shadows, mut tf, mut step_mm) = (None, None, None, None);
        let mut labels = None;
        match &o.mode {
            Mode::Surface { hit: h, shadows: s } => {
                hit = Some(h.name().to_string());
                shadows = Some(*s);
            }
            Mode::Depth { hit: h } => hit = Some(h.name().to_string()),
            Mode::Composite { tf: t, step_mm: s } => {
                tf = Some(t.clone());
                step_mm = Some(*s);
            }
            Mode::Labels { hit: h, style } => {
                hit = Some(h.name().to_string());
                labels = Some(format!("{style:?}"));
            }
            Mode::Mip | Mode::Cost => {}
        }
        let composite = matches!(o.mode, Mode::Composite { .. });
        OptionsKey {
            mode: o.mode.name().into(),
            hit,
            shadows,
            tf,
            step_mm,
            method: o.method.name(),
            bisect_iters: o.hit_params.bisect_iters,
            newton_iters: o.hit_params.newton_iters,
            newton_tol: o.hit_params.newton_tol,
            precision: o.precision.name().into(),
            tile: o.tile,
            cd_lazy_min: o.cd_lazy_min,
            sampling: composite.then(|| o.sampling.name().into()),
            integrate: ((composite || o.mode == Mode::Mip)
                && o.integrate != crate::render::Integrate::Step)
                .then(|| format!("{:?}", o.integrate)),
            sample_batches: composite.then_some(o.sample_batches),
            early_stop: composite.then_some(o.early_stop),
            look: composite.then(|| o.look.clone()),
            normals: (composite || matches!(o.mode, Mode::Surface { .. }))
                .then(|| o.normals.name().into()),
            iso: o.iso,
            labels,
        }
    }
}

/// What makes two parts parts of the same render. Floats are stored as
/// JSON numbers, which round-trip exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderKey {
    /// Name, length and header+index checksum of the packed file. Parts
    /// match by content: the length and the checksum (which covers every
    /// brick's CRC in the index), not the name, so parts rendered from
    /// byte-identical copies under other names assemble.
    pub volume: String,
    pub volume_bytes: u64,
    pub volume_crc: u32,
    pub camera: CameraKey,
    pub options: OptionsKey,
    pub width: u32,
    pub height: u32,
    pub tile: u32,
    pub shards: u32,
    pub layout: ShardLayout,
    pub colouring: Colouring,
}

impl RenderKey {
    pub fn new(
        vol: &PackedVolume,
        camera: &Camera,
        opts: &RenderOptions,
        n: u32,
        layout: ShardLayout,
    ) -> RenderKey {
        RenderKey {
            volume: vol
                .path()
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            volume_bytes: vol.file_len(),
            volume_crc: vol.checksum(),
            camera: CameraKey::new(camera),
            options: OptionsKey::new(opts),
            width: camera.width,
            height: camera.height,
            tile: opts.tile,
            shards: n,
            layout,
            colouring: Colouring::of(vol, opts),
        }
    }
}

/// One shard of a render.
#[derive(Debug, Clone)]
pub struct Part {
    pub key: RenderKey,
    pub shard: Shard,
    pub tiles: Vec<TilePx>,
    /// Counters of this shard's tiles.
    pub stats: Stats,
}

/// The JSON header of a part file.
#[derive(Serialize, Deserialize)]
struct PartHeader {
    key: RenderKey,
    shard: Shard,
    stats: Stats,
    /// `[x0, y0, w, h]` per tile, in the order of the pixel records.
    tiles: Vec<[u32; 4]>,
}

/// Part format 2: pixels carry their coverage (alpha) since issue 16.
const MAGIC: &[u8; 8] = b"CDVPART\x02";
const PX_BYTES: usize = 25;

/// Why a part file could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The first 8 bytes are not the magic (or the file is shorter than a
    /// header).
    #[error(
        "{}: not a cdvol part file of this version (magic CDVPART\\x02 expected; parts of \
         older versions cannot be mixed with new ones: render them again)",
        path.display()
    )]
    Magic { path: PathBuf },
    /// The trailing CRC-32 does not match the bytes before it.
    #[error(
        "{}: checksum mismatch: the part file is damaged or truncated \
         (stored CRC-32 {stored:#010x}, computed {computed:#010x})",
        path.display()
    )]
    Checksum {
        path: PathBuf,
        stored: u32,
        computed: u32,
    },
    /// The JSON header's length field points past the end of the file.
    #[error("{}: header length {length} exceeds the file ({available} bytes)", path.display())]
    HeaderLength {
        path: PathBuf,
        length: u64,
        available: usize,
    },
    /// The JSON header could not be encoded (write) or decoded (read).
    #[error("{}: header: {source}", path.display())]
    Header {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// A tile rectangle of the header lies outside the image.
    #[error(
        "{}: tile [{x0}, {y0}, {w}, {h}] lies outside the {width}x{height} image",
        path.display()
    )]
    TileOutside {
        path: PathBuf,
        x0: u32,
        y0: u32,
        w: u32,
        h: u32,
        width: u32,
        height: u32,
    },
    /// Fewer pixel records than the header's tiles hold.
    #[error(
        "{}: pixel records end early ({found} bytes left, expected {expected})",
        path.display()
    )]
    Short {
        path: PathBuf,
        found: usize,
        expected: usize,
    },
    /// Bytes after the last tile's pixel records.
    #[error("{}: {extra} bytes after the last tile", path.display())]
    Trailing { path: PathBuf, extra: usize },
    #[error(transparent)]
    Write(#[from] WriteError),
}

impl Part {
    /// Writes the part to `path` (temporary file beside it, renamed when
    /// complete).
    pub fn write(&self, path: &Path) -> Result<(), PartError> {
        Ok(write_atomic(path, &self.to_bytes(path)?)?)
    }

    /// The bytes of the part file (`path` names it in errors).
    pub fn to_bytes(&self, path: &Path) -> Result<Vec<u8>, PartError> {
        let header = PartHeader {
            key: self.key.clone(),
            shard: self.shard,
            stats: self.stats.clone(),
            tiles: self.tiles.iter().map(|t| [t.x0, t.y0, t.w, t.h]).collect(),
        };
        let json = serde_json::to_vec(&header).map_err(|source| PartError::Header {
            path: path.to_path_buf(),
            source,
        })?;
        let mut b = Vec::with_capacity(16 + json.len() + self.stats.rays as usize * PX_BYTES + 4);
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&(json.len() as u64).to_le_bytes());
        b.extend_from_slice(&json);
        for t in &self.tiles {
            for p in t.px() {
                for c in p.rgb {
                    b.extend_from_slice(&c.to_le_bytes());
                }
                b.extend_from_slice(&p.alpha.to_le_bytes());
                b.extend_from_slice(&p.depth.to_le_bytes());
                b.extend_from_slice(&p.steps.to_le_bytes());
                b.push(p.hit as u8);
            }
        }
        let crc = crc32fast::hash(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        Ok(b)
    }

    /// Reads and checks a part file.
    pub fn read(path: &Path) -> Result<Part, PartError> {
        let p = || path.to_path_buf();
        let b = crate::fsutil::read_regular(path)
            .map_err(|source| PartError::Read { path: p(), source })?;
        if b.len() < 20 || &b[..8] != MAGIC {
            return Err(PartError::Magic { path: p() });
        }
        let (body, tail) = b.split_at(b.len() - 4);
        let stored = u32::from_le_bytes(tail.try_into().expect("4 bytes"));
        let computed = crc32fast::hash(body);
        if computed != stored {
            return Err(PartError::Checksum {
                path: p(),
                stored,
                computed,
            });
        }
        let jl = u64::from_le_bytes(body[8..16].try_into().expect("8 bytes"));
        let available = body.len() - 16;
        let jl = usize::try_from(jl).ok().filter(|&l| l <= available).ok_or(
            PartError::HeaderLength {
                path: p(),
                length: jl,
                available,
            },
        )?;
        let h: PartHeader = serde_json::from_slice(&body[16..16 + jl])
            .map_err(|source| PartError::Header { path: p(), source })?;
        let mut rest = &body[16 + jl..];
        let mut tiles = Vec::with_capacity(h.tiles.len());
        for &[x0, y0, w, th] in &h.tiles {
            let inside = w >= 1
                && th >= 1
                && x0.checked_add(w).is_some_and(|x| x <= h.key.width)
                && y0.checked_add(th).is_some_and(|y| y <= h.key.height);
            if !inside {
                return Err(PartError::TileOutside {
                    path: p(),
                    x0,
                    y0,
                    w,
                    h: th,
                    width: h.key.width,
                    height: h.key.height,
                });
            }
            let n = w as usize * th as usize;
            if rest.len() < n * PX_BYTES {
                return Err(PartError::Short {
                    path: p(),
                    found: rest.len(),
                    expected: n * PX_BYTES,
                });
            }
            let f = |r: &[u8], i: usize| f32::from_le_bytes(r[i..i + 4].try_into().expect("4"));
            let pixels = rest[..n * PX_BYTES]
                .chunks_exact(PX_BYTES)
                .map(|r| Px {
                    rgb: [f(r, 0), f(r, 4), f(r, 8)],
                    alpha: f(r, 12),
                    depth: f(r, 16),
                    steps: u32::from_le_bytes(r[20..24].try_into().expect("4")),
                    hit: r[24] != 0,
                })
                .collect();
            rest = &rest[n * PX_BYTES..];
            tiles.push(TilePx {
                x0,
                y0,
                w,
                h: th,
                pixels,
            });
        }
        if !rest.is_empty() {
            return Err(PartError::Trailing {
                path: p(),
                extra: rest.len(),
            });
        }
        Ok(Part {
            key: h.key,
            shard: h.shard,
            tiles,
            stats: h.stats,
        })
    }
}

/// Why parts do not make one whole render. Parts are named by the file
/// names given to [`assemble`] (or `part I` beyond them).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssembleError {
    #[error("no parts to assemble")]
    NoParts,
    /// Two parts' keys differ; `field` says in what (the packed file, the
    /// camera, the number of shards, the shard layout, the render options).
    #[error("{first} and {other} are parts of different renders: {field} differs")]
    DifferentRenders {
        first: String,
        other: String,
        field: &'static str,
    },
    /// A part's shard does not fit the render's shard count or layout.
    #[error("{part}: shard {k}/{n} in a render of {shards} shards")]
    ForeignShard {
        part: String,
        k: u32,
        n: u32,
        shards: u32,
    },
    #[error("{first} and {other} are both shard {k}/{n}")]
    DuplicateShard {
        first: String,
        other: String,
        k: u32,
        n: u32,
    },
    /// Shards `K/N` no part holds.
    #[error("shards missing: {}", missing.join(", "))]
    MissingShards { missing: Vec<String> },
    #[error("{part}: tile at ({x0}, {y0}) is not a tile of this render")]
    NotATile { part: String, x0: u32, y0: u32 },
    #[error("{part}: tile at ({x0}, {y0}) appears twice")]
    DuplicateTile { part: String, x0: u32, y0: u32 },
    #[error("tile at ({x0}, {y0}) is in no part")]
    MissingTile { x0: u32, y0: u32 },
}

/// Checks that `parts` (read from `names`) make one whole render and
/// assembles it: the image a single process would have written, and the
/// counters summed (`peak_cache_bytes` the largest part's,
/// `seconds_total` the sum of the parts' seconds).
pub fn assemble(parts: &[Part], names: &[PathBuf]) -> Result<(Frame, Stats), AssembleError> {
    let name = |i: usize| {
        names
            .get(i)
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| format!("part {i}"))
    };
    let first = parts.first().ok_or(AssembleError::NoParts)?;
    let key = &first.key;
    for (i, p) in parts.iter().enumerate().skip(1) {
        if !same_render(&p.key, key) {
            return Err(AssembleError::DifferentRenders {
                first: name(0),
                other: name(i),
                field: differing_field(key, &p.key),
            });
        }
    }
    let n = key.shards;
    let mut seen: BTreeMap<u32, usize> = BTreeMap::new();
    for (i, p) in parts.iter().enumerate() {
        if p.shard.n != n || p.shard.k >= n || p.shard.layout != key.layout {
            return Err(AssembleError::ForeignShard {
                part: name(i),
                k: p.shard.k,
                n: p.shard.n,
                shards: n,
            });
        }
        if let Some(j) = seen.insert(p.shard.k, i) {
            return Err(AssembleError::DuplicateShard {
                first: name(j),
                other: name(i),
                k: p.shard.k,
                n,
            });
        }
    }
    let missing: Vec<String> = (0..n)
        .filter(|k| !seen.contains_key(k))
        .map(|k| format!("{k}/{n}"))
        .collect();
    if !missing.is_empty() {
        return Err(AssembleError::MissingShards { missing });
    }
    // Every tile of the image exactly once.
    let ts = key.tile.max(1);
    let (ntx, nty) = (key.width.div_ceil(ts), key.height.div_ceil(ts));
    let mut have = vec![false; ntx as usize * nty as usize];
    let mut tiles = Vec::new();
    for (i, p) in parts.iter().enumerate() {
        for t in &p.tiles {
            let th = t.h;
            let aligned = t.x0 % ts == 0
                && t.y0 % ts == 0
                && t.w == ts.min(key.width - t.x0)
                && th == ts.min(key.height - t.y0);
            if !aligned {
                return Err(AssembleError::NotATile {
                    part: name(i),
                    x0: t.x0,
                    y0: t.y0,
                });
            }
            let idx = (t.y0 / ts * ntx + t.x0 / ts) as usize;
            if std::mem::replace(&mut have[idx], true) {
                return Err(AssembleError::DuplicateTile {
                    part: name(i),
                    x0: t.x0,
                    y0: t.y0,
                });
            }
            tiles.push(t);
        }
    }
    if let Some(i) = have.iter().position(|h| !h) {
        let (tx, ty) = (i as u32 % ntx, i as u32 / ntx);
        return Err(AssembleError::MissingTile {
            x0: tx * ts,
            y0: ty * ts,
        });
    }
    let mut stats = first.stats.clone();
    for p in &parts[1..] {
        stats.merge(&p.stats);
    }
    // The parts' bits per channel are the assembler's choice: keep the
    // unrounded colour for 16-bit and float outputs.
    Ok(finish(
        &key.colouring,
        key.width,
        key.height,
        tiles,
        stats,
        true,
    ))
}

/// Whether two parts' keys are of one render: every field but the packed
/// file's name.
fn same_render(a: &RenderKey, b: &RenderKey) -> bool {
    let named = RenderKey {
        volume: a.volume.clone(),
        ..b.clone()
    };
    *a == named
}

fn differing_field(a: &RenderKey, b: &RenderKey) -> &'static str {
    if a.volume_bytes != b.volume_bytes || a.volume_crc != b.volume_crc {
        "the packed file"
    } else if a.camera != b.camera || a.width != b.width || a.height != b.height {
        "the camera"
    } else if a.shards != b.shards {
        "the number of shards"
    } else if a.layout != b.layout {
        "the shard layout"
    } else {
        "the render options"
    }
}
