//! Sharded rendering: `cdvol render --shard K/N` renders tile `i` (Morton
//! order) when `i % N == K` (or, with `--shard-layout blocks`, the K-th
//! contiguous run of the Morton curve) into a part file; `cdvol assemble`
//! checks that
//! the parts belong to one render (same file contents, camera, options and
//! N), that every shard and every tile is there exactly once, and colours
//! the image with the same code as a single-process render, so the bytes
//! are the same.
//!
//! Part file (little-endian): magic `CDVPART\x01`, u64 length of a JSON
//! header ([`PartHeader`]), the header, then per tile in header order its
//! pixels row by row, 21 bytes each (3 f32 colour, f32 depth, u32 steps,
//! u8 hit), then a u32 CRC-32 of everything before it. Written to a
//! temporary file and renamed when complete.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::camera::Camera;
use super::{colour, mip_range, Frame, Mode, Px, RenderOptions, Shard, ShardLayout, Stats};
use crate::format::reader::PackedVolume;

/// How pixels become colours: the only part of the mode colouring needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Colouring {
    /// Surface and composite: the pixel's colour as it is.
    Rgb,
    /// Grey from `lo` to `hi`.
    Mip { lo: f64, hi: f64 },
    /// Heat map scaled to the largest step count of the whole image.
    Cost,
    /// Grey scaled to the depth range of the whole image.
    Depth,
}

/// What makes two parts parts of the same render.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderKey {
    /// Name, length and header+index checksum of the packed file.
    pub volume: String,
    pub volume_bytes: u64,
    pub volume_crc: u32,
    /// The camera and the options (cache budget left out: it never
    /// changes the output), as Rust debug text, which round-trips floats.
    pub camera: String,
    pub options: String,
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
        let colouring = match opts.mode {
            Mode::Surface { .. } | Mode::Composite { .. } => Colouring::Rgb,
            Mode::Mip => {
                let [lo, hi] = mip_range(vol);
                Colouring::Mip { lo, hi }
            }
            Mode::Cost => Colouring::Cost,
            Mode::Depth { .. } => Colouring::Depth,
        };
        RenderKey {
            volume: vol
                .path()
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            volume_bytes: vol.file_len(),
            volume_crc: vol.checksum(),
            camera: format!("{camera:?}"),
            options: format!(
                "{:?}",
                RenderOptions {
                    cache_bytes: 0,
                    ..opts.clone()
                }
            ),
            width: camera.width,
            height: camera.height,
            tile: opts.tile,
            shards: n,
            layout,
            colouring,
        }
    }
}

/// One tile's pixels before colouring.
#[derive(Debug, Clone, PartialEq)]
pub struct TilePx {
    pub x0: u32,
    pub y0: u32,
    pub w: u32,
    pub(super) pixels: Vec<Px>,
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

const MAGIC: &[u8; 8] = b"CDVPART\x01";
const PX_BYTES: usize = 21;

impl Part {
    /// Writes the part to `path` (temporary file beside it, renamed when
    /// complete).
    pub fn write(&self, path: &Path) -> Result<(), String> {
        let header = PartHeader {
            key: self.key.clone(),
            shard: self.shard,
            stats: self.stats.clone(),
            tiles: self
                .tiles
                .iter()
                .map(|t| [t.x0, t.y0, t.w, t.pixels.len() as u32 / t.w.max(1)])
                .collect(),
        };
        let json = serde_json::to_vec(&header).map_err(|e| e.to_string())?;
        let mut b = Vec::with_capacity(16 + json.len() + self.stats.rays as usize * PX_BYTES + 4);
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&(json.len() as u64).to_le_bytes());
        b.extend_from_slice(&json);
        for t in &self.tiles {
            for p in &t.pixels {
                for c in p.rgb {
                    b.extend_from_slice(&c.to_le_bytes());
                }
                b.extend_from_slice(&p.depth.to_le_bytes());
                b.extend_from_slice(&p.steps.to_le_bytes());
                b.push(p.hit as u8);
            }
        }
        let crc = crc32fast::hash(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        super::write_atomic(path, &b)
    }

    /// Reads and checks a part file.
    pub fn read(path: &Path) -> Result<Part, String> {
        let e = |msg: String| format!("{}: {msg}", path.display());
        let b = std::fs::read(path).map_err(|x| e(format!("cannot read: {x}")))?;
        if b.len() < 20 || &b[..8] != MAGIC {
            return Err(e(
                "not a cdvol part file (magic CDVPART\\x01 expected)".into()
            ));
        }
        let (body, tail) = b.split_at(b.len() - 4);
        let crc = u32::from_le_bytes(tail.try_into().expect("4 bytes"));
        if crc32fast::hash(body) != crc {
            return Err(e(
                "checksum mismatch: the part file is damaged or truncated".into(),
            ));
        }
        let jl = u64::from_le_bytes(body[8..16].try_into().expect("8 bytes"));
        let jl = usize::try_from(jl)
            .ok()
            .filter(|&l| l <= body.len() - 16)
            .ok_or_else(|| e(format!("header length {jl} exceeds the file")))?;
        let h: PartHeader =
            serde_json::from_slice(&body[16..16 + jl]).map_err(|x| e(format!("header: {x}")))?;
        let mut rest = &body[16 + jl..];
        let mut tiles = Vec::with_capacity(h.tiles.len());
        for &[x0, y0, w, th] in &h.tiles {
            let inside = w >= 1
                && th >= 1
                && x0.checked_add(w).is_some_and(|x| x <= h.key.width)
                && y0.checked_add(th).is_some_and(|y| y <= h.key.height);
            if !inside {
                return Err(e(format!(
                    "tile [{x0}, {y0}, {w}, {th}] lies outside the {}x{} image",
                    h.key.width, h.key.height
                )));
            }
            let n = w as usize * th as usize;
            if rest.len() < n * PX_BYTES {
                return Err(e("pixel records end early".into()));
            }
            let f = |r: &[u8], i: usize| f32::from_le_bytes(r[i..i + 4].try_into().expect("4"));
            let pixels = rest[..n * PX_BYTES]
                .chunks_exact(PX_BYTES)
                .map(|r| Px {
                    rgb: [f(r, 0), f(r, 4), f(r, 8)],
                    depth: f(r, 12),
                    steps: u32::from_le_bytes(r[16..20].try_into().expect("4")),
                    hit: r[20] != 0,
                })
                .collect();
            rest = &rest[n * PX_BYTES..];
            tiles.push(TilePx { x0, y0, w, pixels });
        }
        if !rest.is_empty() {
            return Err(e(format!("{} bytes after the last tile", rest.len())));
        }
        Ok(Part {
            key: h.key,
            shard: h.shard,
            tiles,
            stats: h.stats,
        })
    }
}

/// Places the tiles and colours the image; `stats` are the summed
/// counters. Shared by [`super::render`] and [`assemble`].
/// Tiles given by value are dropped as soon as they are placed, so a
/// render holds about one copy of the pixels, not two.
pub(super) fn finish<T: std::borrow::Borrow<TilePx>>(
    key: &RenderKey,
    tiles: impl IntoIterator<Item = T>,
    mut stats: Stats,
) -> (Frame, Stats) {
    let (w, h) = (key.width, key.height);
    let mut px = vec![Px::default(); w as usize * h as usize];
    for t in tiles {
        let t = t.borrow();
        for (i, p) in t.pixels.iter().enumerate() {
            let (lx, ly) = (i as u32 % t.w, i as u32 / t.w);
            px[((t.y0 + ly) * w + t.x0 + lx) as usize] = *p;
        }
    }
    let frame = colour(&key.colouring, w, h, &px);
    stats.rays = w as u64 * h as u64;
    (frame, stats)
}

/// Checks that `parts` (read from `names`) make one whole render and
/// assembles it: the image a single process would have written, and the
/// counters summed (`peak_cache_bytes` the largest part's,
/// `seconds_total` the sum of the parts' seconds).
pub fn assemble(parts: &[Part], names: &[PathBuf]) -> Result<(Frame, Stats), String> {
    let name = |i: usize| {
        names
            .get(i)
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| format!("part {i}"))
    };
    let first = parts.first().ok_or("no parts to assemble")?;
    let key = &first.key;
    for (i, p) in parts.iter().enumerate().skip(1) {
        if p.key != key.clone() {
            let field = differing_field(key, &p.key);
            return Err(format!(
                "{} and {} are parts of different renders: {field} differs",
                name(0),
                name(i)
            ));
        }
    }
    let n = key.shards;
    let mut seen: BTreeMap<u32, usize> = BTreeMap::new();
    for (i, p) in parts.iter().enumerate() {
        if p.shard.n != n || p.shard.k >= n || p.shard.layout != key.layout {
            return Err(format!(
                "{}: shard {}/{} in a render of {n} shards",
                name(i),
                p.shard.k,
                p.shard.n
            ));
        }
        if let Some(j) = seen.insert(p.shard.k, i) {
            return Err(format!(
                "{} and {} are both shard {}/{n}",
                name(j),
                name(i),
                p.shard.k
            ));
        }
    }
    let missing: Vec<String> = (0..n)
        .filter(|k| !seen.contains_key(k))
        .map(|k| format!("{k}/{n}"))
        .collect();
    if !missing.is_empty() {
        return Err(format!("shards missing: {}", missing.join(", ")));
    }
    // Every tile of the image exactly once.
    let ts = key.tile.max(1);
    let (ntx, nty) = (key.width.div_ceil(ts), key.height.div_ceil(ts));
    let mut have = vec![false; ntx as usize * nty as usize];
    let mut tiles = Vec::new();
    for (i, p) in parts.iter().enumerate() {
        for t in &p.tiles {
            let th = t.pixels.len() as u32 / t.w.max(1);
            let aligned = t.x0 % ts == 0
                && t.y0 % ts == 0
                && t.w == ts.min(key.width - t.x0)
                && th == ts.min(key.height - t.y0);
            if !aligned {
                return Err(format!(
                    "{}: tile at ({}, {}) is not a tile of this render",
                    name(i),
                    t.x0,
                    t.y0
                ));
            }
            let idx = (t.y0 / ts * ntx + t.x0 / ts) as usize;
            if std::mem::replace(&mut have[idx], true) {
                return Err(format!(
                    "{}: tile at ({}, {}) appears twice",
                    name(i),
                    t.x0,
                    t.y0
                ));
            }
            tiles.push(t);
        }
    }
    if let Some(i) = have.iter().position(|h| !h) {
        let (tx, ty) = (i as u32 % ntx, i as u32 / ntx);
        return Err(format!("tile at ({}, {}) is in no part", tx * ts, ty * ts));
    }
    let mut stats = first.stats.clone();
    for p in &parts[1..] {
        stats.merge(&p.stats);
    }
    Ok(finish(key, tiles, stats))
}

fn differing_field(a: &RenderKey, b: &RenderKey) -> &'static str {
    if a.volume != b.volume || a.volume_bytes != b.volume_bytes || a.volume_crc != b.volume_crc {
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
