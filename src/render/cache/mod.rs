//! Brick streaming for the renderer: decoded bricks in one cache shared
//! by all threads, bounded by a byte budget with LRU eviction, and a
//! per-tile accessor that keeps the last brick in front of the cache
//! (OpenVDB's `ValueAccessor`), so most steps never touch a lock.
//!
//! A brick is read (positioned read, CRC check, zstd) only when a ray asks
//! for one of its cells, so a scene loads only the bricks it needs.
//!
//! ```text
//! brick.rs  a decoded brick (RBrick): codes, values, the planes built on them
//!           (its tests in brick_tests.rs)
//! grads.rs  the shaded composite's gradient plane, its outer layer filled
//!           on first use
//! lru.rs    the shared cache's recency order under the byte budget
//! here      the cache (BrickCache), the policy it serves, and the
//!           per-tile front (Accessor)
//! ```

use std::sync::{Arc, Mutex};

use crate::format::reader::PackedVolume;
use crate::format::FormatError;

use crate::render::brick::samples::Samples;
use crate::render::brick::{occupancy, to_f32, Codes, Occupancy, Planes, RBrick};
use crate::render::traverse::OBJECT;
use held::Held;

pub(crate) mod held;
mod lru;

use lru::Lru;

/// The octree above the bricks (paper section 5.1, SMART): level `j`
/// flags which nodes of `2^j` bricks per axis hold no 1-cell, from the
/// index alone (no brick is read). Only for power-of-two brick sizes,
/// where bricks are octree nodes.
#[derive(Debug)]
struct BrickPyramid {
    /// `levels[j]`: dims and flags, x fastest.
    levels: Vec<([u64; 3], Vec<bool>)>,
}

impl BrickPyramid {
    fn new(vol: &PackedVolume) -> BrickPyramid {
        let h = vol.header();
        let mut dims = h.bricks;
        let mut cur: Vec<bool> = vol.index().iter().map(|e| e.has_no_object()).collect();
        let mut levels = vec![(dims, cur.clone())];
        while dims.iter().any(|&d| d > 1) {
            let up = dims.map(|d| d.div_ceil(2));
            let mut next = vec![true; (up[0] * up[1] * up[2]) as usize];
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        if !cur[((z * dims[1] + y) * dims[0] + x) as usize] {
                            next[(((z / 2) * up[1] + y / 2) * up[0] + x / 2) as usize] = false;
                        }
                    }
                }
            }
            levels.push((up, next.clone()));
            cur = next;
            dims = up;
        }
        BrickPyramid { levels }
    }

    /// Highest level whose node holding brick `b` is empty, top-down.
    #[inline]
    fn empty_level(&self, b: [u64; 3]) -> Option<u32> {
        for (j, (d, f)) in self.levels.iter().enumerate().rev() {
            let n = b.map(|x| x >> j);
            if f[((n[2] * d[1] + n[1]) * d[0] + n[0]) as usize] {
                return Some(j as u32);
            }
        }
        None
    }
}

/// Counters of one tile (summed at the end; no atomics in the hot loop).
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
pub struct CacheCounters {
    pub bricks_read: u64,
    /// Bricks without 1-cells stood in by their smallest code, unread.
    pub bricks_skipped: u64,
    /// Bricks read again with their values ([`BrickCache::get_values`]);
    /// not in `bricks_read`.
    pub bricks_read_values: u64,
    pub cache_hits: u64,
    pub cache_misses: u64,
    pub bytes_decompressed: u64,
    /// Seconds spent in [`RBrick::decode`] (read, zstd, values, codes,
    /// planes), summed over threads; includes a decode lost to another
    /// thread's race for the same brick.
    pub decode_seconds: f64,
}

impl CacheCounters {
    pub fn add(&mut self, o: &CacheCounters) {
        self.bricks_read += o.bricks_read;
        self.bricks_skipped += o.bricks_skipped;
        self.bricks_read_values += o.bricks_read_values;
        self.cache_hits += o.cache_hits;
        self.cache_misses += o.cache_misses;
        self.bytes_decompressed += o.bytes_decompressed;
        self.decode_seconds += o.decode_seconds;
    }
}

/// Cache keys per brick: `id * KEYS_PER_BRICK` + 0 for the brick as
/// decoded, 1 for its stand-in ([`BrickCache::get`]), 2 for the brick
/// with its values ([`BrickCache::get_values`]).
const KEYS_PER_BRICK: u64 = 3;

/// What one cache entry costs besides its brick: the `Arc` counts (16)
/// and its slot (48), rounded up generously (the table of slots by key,
/// 4 bytes a key, is the volume's, not the entries'). Counted against the budget because
/// uniform and lazily stood-in bricks are tiny and a big volume crosses
/// hundreds of thousands of them.
const ENTRY_BYTES: usize = 128;

/// What a traversal needs of the bricks, as plain data: the cache never
/// sees the traversal method (the render maps a method to its policy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrickPolicy {
    pub planes: Planes,
    /// Whether a brick without 1-cells may stand in unread, as a uniform
    /// brick of the smallest code in its index entry: `Some(m)` when that
    /// code is at least `m` (`Some(0)`: always), `None`: read every brick
    /// the ray enters. See [`BrickCache::get`].
    pub stand_in_min: Option<u8>,
}

/// Decoded bricks under a byte budget, shared by all threads.
pub struct BrickCache {
    /// A handle on the file (shared, cheap to clone): the cache owns it,
    /// so it borrows nothing.
    vol: PackedVolume,
    budget: usize,
    lru: Mutex<Lru<Arc<RBrick>>>,
    planes: Planes,
    /// The levels above the bricks, when `planes.octree` and the brick
    /// size is a power of two (bricks are then octree nodes).
    pyramid: Option<BrickPyramid>,
    /// Unique in the process: what memos of derived data (render/sample/
    /// normals.rs) key on, so no two caches' bricks are ever confused.
    id: u64,
    /// With [`BrickCache::with_occupancy`], per brick which of its
    /// sub-blocks hold a 1-cell of the scene, taken when the brick is
    /// first decoded ([`BrickCache::occupied`]).
    occupied: Option<Box<[std::sync::OnceLock<Occupancy>]>>,
}

/// The next [`BrickCache`]'s id.
static NEXT_CACHE_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl BrickCache {
    /// A cache that builds every plane the file has, and no octree.
    pub fn new(vol: &PackedVolume, budget_bytes: usize) -> BrickCache {
        BrickCache::with_planes(vol, budget_bytes, Planes::FILE)
    }

    /// A cache that builds `planes`. With the octree, the levels above the
    /// bricks are built now from the index (no brick read), those inside
    /// a brick with each decoded brick (one byte per node, ~1/7 byte per
    /// cell, counted against the budget).
    pub fn with_planes(vol: &PackedVolume, budget_bytes: usize, planes: Planes) -> BrickCache {
        let bs = vol.header().brick_size;
        BrickCache {
            vol: vol.clone(),
            budget: budget_bytes,
            lru: Mutex::new(Lru::new(vol.header().brick_count() * KEYS_PER_BRICK)),
            planes,
            pyramid: (planes.octree && bs.is_power_of_two()).then(|| BrickPyramid::new(vol)),
            id: NEXT_CACHE_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            occupied: None,
        }
    }

    /// This cache, also taking each decoded brick's [`Occupancy`] for the
    /// culling of later frames (render/view/cull.rs): for caches that serve
    /// more than one frame (turntables, `cdvol serve`). It scans each
    /// brick with 1-cells once, on its first decoding: about 60,000
    /// instructions a 32^3 brick (docs/BENCHMARKS.md, "Later frames cull
    /// by sub-blocks").
    pub fn with_occupancy(mut self) -> BrickCache {
        let n = self.vol.header().brick_count();
        self.occupied = Some((0..n).map(|_| std::sync::OnceLock::new()).collect());
        self
    }

    /// Which sub-blocks of brick `id` hold a 1-cell of the scene, from
    /// its codes when it was first decoded; `None` when this cache does
    /// not take them or has not decoded the brick. The mask is the
    /// scene's: a brick is decoded for this cache's scene only
    /// (narrowing, transfer-function cells).
    pub fn occupied(&self, id: u64) -> Option<&Occupancy> {
        self.occupied.as_ref()?.get(id as usize)?.get()
    }

    /// This cache, also building the octree ([`Planes::octree`]).
    pub fn with_octree(self) -> BrickCache {
        let planes = Planes {
            octree: true,
            ..self.planes
        };
        BrickCache::with_planes(&self.vol, self.budget, planes)
    }

    pub fn volume(&self) -> &PackedVolume {
        &self.vol
    }

    /// The planes this cache builds beside each brick.
    pub fn planes(&self) -> Planes {
        self.planes
    }

    /// Distinct bricks whose payload was read.
    pub fn distinct_read(&self) -> u64 {
        let l = self.lru.lock().unwrap_or_else(|e| e.into_inner());
        // Keys: see `KEYS_PER_BRICK`. Stand-ins read nothing; reads for
        // the values alone are not counted.
        l.count_seen(|k| k % KEYS_PER_BRICK == 0)
    }

    /// Largest number of bytes the cache held at once.
    pub fn peak_bytes(&self) -> usize {
        self.lru.lock().map(|l| l.peak).unwrap_or(0)
    }

    /// The decoded brick `id`, from the cache or read now. Decoding happens
    /// outside the lock; two threads may decode the same brick at once, and
    /// the first to insert wins.
    ///
    /// With `lazy_min = Some(m)`, a brick that holds no 1-cell and whose
    /// smallest code is at least `m` is not read at all: it stands in as a
    /// uniform brick of that smallest code, which is conservative (every
    /// cell's empty cube is at least that large) and needs no payload.
    pub fn get(
        &self,
        id: u64,
        lazy_min: Option<u8>,
        c: &mut CacheCounters,
    ) -> Result<Arc<RBrick>, FormatError> {
        let e = self.vol.index()[id as usize];
        let lazy = !e.is_uniform()
            && e.has_no_object()
            && lazy_min.is_some_and(|m| e.uniform_code >= m as u32);
        let key = id * KEYS_PER_BRICK + lazy as u64;
        let (b, inserted) = self.cached(key, c, |c| {
            if lazy {
                c.bricks_skipped += 1;
                return Ok(RBrick::uniform(self.vol.header(), id, e.uniform_code));
            }
            // A brick whose largest value lies below the scene's iso value
            // holds none of the scene's 1-cells: it is read for its codes
            // only (render/brick/envelope.rs, `tighten`). The index gives a maximum
            // only to bricks with 1-cells, never to those `lazy` stands in.
            let free = match (self.planes.narrow, e.value_max()) {
                (Some(iso), Some(m)) => to_f32(m) < iso,
                _ => false,
            };
            decoded(c, || RBrick::decode(&self.vol, id, self.planes, free))
        })?;
        if inserted && !lazy {
            c.bricks_read += 1;
            // Once per brick with 1-cells, whichever frame decodes it
            // (an evicted brick keeps its mask): the bricks a frame knows
            // are those earlier frames' rays entered, whatever the
            // threads and the budget.
            if let Some(slot) = self.occupied.as_ref().and_then(|o| o.get(id as usize)) {
                if !e.has_no_object() {
                    slot.get_or_init(|| occupancy(&b, self.vol.header().brick_size));
                }
            }
        }
        Ok(b)
    }

    /// Brick `id` decoded with its values even if the index says it holds
    /// no 1-cell ([`RBrick::decode_values`]), from the cache or read now;
    /// counted as [`BrickCache::get`] counts, but in
    /// [`CacheCounters::bricks_read_values`] instead of `bricks_read`.
    pub fn get_values(&self, id: u64, c: &mut CacheCounters) -> Result<Arc<RBrick>, FormatError> {
        let key = id * KEYS_PER_BRICK + 2;
        let (b, inserted) = self.cached(key, c, |c| {
            decoded(c, || RBrick::decode_values(&self.vol, id))
        })?;
        if inserted {
            c.bricks_read_values += 1;
        }
        Ok(b)
    }

    /// Entry `key` from the cache (a hit), or made by `make` outside the
    /// lock (a miss) and inserted; `true` when this call inserted it.
    /// Two threads may make the same entry at once: the first to insert
    /// wins, and only its read is counted by the caller.
    fn cached(
        &self,
        key: u64,
        c: &mut CacheCounters,
        make: impl FnOnce(&mut CacheCounters) -> Result<RBrick, FormatError>,
    ) -> Result<(Arc<RBrick>, bool), FormatError> {
        if let Some(b) = self.lru.lock().unwrap_or_else(|e| e.into_inner()).get(key) {
            c.cache_hits += 1;
            return Ok((b, false));
        }
        c.cache_misses += 1;
        let b = Arc::new(make(c)?);
        let mut l = self.lru.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(first) = l.get(key) {
            return Ok((first, false));
        }
        l.insert(key, b.clone(), b.bytes + ENTRY_BYTES, self.budget);
        Ok((b, true))
    }
}

/// A brick decoded by `decode`, its seconds and decompressed bytes
/// counted in `c`.
fn decoded(
    c: &mut CacheCounters,
    decode: impl FnOnce() -> Result<(RBrick, u64), FormatError>,
) -> Result<RBrick, FormatError> {
    let t = std::time::Instant::now();
    let r = decode();
    c.decode_seconds += t.elapsed().as_secs_f64();
    let (b, raw) = r?;
    c.bytes_decompressed += raw;
    Ok(b)
}

/// Per-tile front of the cache: the current brick and the first error.
pub struct Accessor<'a> {
    cache: &'a BrickCache,
    brick_size: u32,
    bricks: [u64; 3],
    cur_id: u64,
    /// Slot of `held` holding the current brick ([`held::NONE`]: none,
    /// after an error). An index, not an `Arc`: switching bricks touches
    /// no reference count shared with other threads.
    cur: usize,
    /// The bricks this accessor used (up to [`held::HELD`]), tried before
    /// the shared cache, whose every lookup takes its lock: the rays of a
    /// tile cross the same bricks over and over (render/cache/held.rs).
    held: Held<RBrick>,
    /// See [`BrickCache::get`].
    lazy_min: Option<u8>,
    pub counters: CacheCounters,
    pub error: Option<FormatError>,
    /// Smooth-normal gradients go through the thread's per-cell memo
    /// (render/sample/normals.rs).
    memo_gradients: bool,
    /// The last brick [`Accessor::brick_with_values`] had to read for
    /// its values, and its id.
    values: Option<(u64, Arc<RBrick>)>,
}

/// Bricks an [`Accessor`] keeps besides the shared cache's budget (at
/// most this many per accessor, i.e. per tile in flight; they are also
/// counted in the budget while the shared cache holds them).
pub const HELD: usize = held::HELD;

/// Default smallest code for which CD stands an unread brick in by its
/// smallest code: below it, reading the brick's own (larger) codes pays
/// off (docs/BENCHMARKS.md, "Render levers").
pub const LAZY_MIN_CODE_CD: u8 = 16;

impl<'a> Accessor<'a> {
    /// An accessor that decodes every brick it enters.
    pub fn new(cache: &'a BrickCache) -> Accessor<'a> {
        Accessor::with_lazy(cache, None)
    }

    /// An accessor that stands bricks in as `policy` allows (its planes
    /// are the cache's business).
    pub fn for_policy(cache: &'a BrickCache, policy: &BrickPolicy) -> Accessor<'a> {
        Accessor::with_lazy(cache, policy.stand_in_min)
    }

    /// An accessor that stands in a brick without 1-cells by its index
    /// code when that code is at least `lazy_min` (see [`BrickCache::get`]).
    pub fn with_lazy(cache: &'a BrickCache, lazy_min: Option<u8>) -> Accessor<'a> {
        let h = cache.volume().header();
        Accessor {
            cache,
            brick_size: h.brick_size,
            bricks: h.bricks,
            cur_id: u64::MAX,
            cur: held::NONE,
            held: Held::new(),
            lazy_min,
            counters: CacheCounters::default(),
            error: None,
            memo_gradients: false,
            values: None,
        }
    }

    /// Whether smooth-normal gradients read through this accessor are
    /// remembered per cell in the thread's memo and answered from it
    /// ([`vertex_gradients`](crate::render::sample::normals::vertex_gradients); the same
    /// values either way). Off by default; the renderer turns it on where
    /// rays are denser than the cells.
    pub fn remember_gradients(&mut self, on: bool) {
        self.memo_gradients = on;
    }

    /// See [`Accessor::remember_gradients`].
    #[inline]
    pub(crate) fn remembers_gradients(&self) -> bool {
        self.memo_gradients
    }

    /// Cells per edge of the file's bricks.
    #[inline]
    pub fn brick_size(&self) -> u32 {
        self.brick_size
    }

    /// The process-unique id of the cache behind this accessor.
    #[inline]
    pub(crate) fn cache_id(&self) -> u64 {
        self.cache.id
    }

    /// The brick holding global cell `c` and the cell's local index. After
    /// an error (recorded once) every cell reads as an empty 0-cell, so the
    /// traversal finishes and the caller reports the error instead of an
    /// image.
    #[inline]
    pub fn brick(&mut self, c: [u32; 3]) -> (&RBrick, [u32; 3]) {
        // Fast path: the cell is in the current brick (no division).
        if let Some(b) = self.held.get(self.cur) {
            let l = [
                c[0].wrapping_sub(b.first[0]),
                c[1].wrapping_sub(b.first[1]),
                c[2].wrapping_sub(b.first[2]),
            ];
            if l[0] < b.cells[0] && l[1] < b.cells[1] && l[2] < b.cells[2] {
                return (self.held.get(self.cur).expect("checked"), l);
            }
        }
        self.brick_slow(c)
    }

    #[cold]
    fn brick_slow(&mut self, c: [u32; 3]) -> (&RBrick, [u32; 3]) {
        let bs = self.brick_size;
        let bc = [c[0] / bs, c[1] / bs, c[2] / bs];
        let id = (bc[2] as u64 * self.bricks[1] + bc[1] as u64) * self.bricks[0] + bc[0] as u64;
        if id != self.cur_id {
            self.cur_id = id;
            if let Some(i) = self.held.find(id) {
                self.counters.cache_hits += 1;
                self.cur = i;
            } else {
                self.cur = match self.cache.get(id, self.lazy_min, &mut self.counters) {
                    Ok(b) => self.held.insert(id, b),
                    Err(e) => {
                        if self.error.is_none() {
                            self.error = Some(e);
                        }
                        held::NONE
                    }
                };
            }
        }
        let l = [c[0] - bc[0] * bs, c[1] - bc[1] * bs, c[2] - bc[2] * bs];
        match self.held.get(self.cur) {
            Some(b) => (b, l),
            None => (&EMPTY, [0; 3]),
        }
    }
}

impl Accessor<'_> {
    /// [`Accessor::brick`] as a shared handle, which the caller may keep
    /// while it reads other bricks through the accessor; `None` after a
    /// read error. It clones the `Arc` (an atomic count other threads
    /// share), so it is for cold paths only: the gradients of a cell the
    /// plane does not hold yet (render/sample/normals.rs).
    pub fn brick_arc(&mut self, c: [u32; 3]) -> Option<(Arc<RBrick>, [u32; 3])> {
        let (_, l) = self.brick(c);
        self.held.get_arc(self.cur).map(|b| (Arc::clone(b), l))
    }

    /// [`Accessor::brick`], but a brick without values that has a
    /// payload (one the index marks as holding no 1-cell, decoded for its
    /// codes only, or stood in) comes decoded with its values
    /// ([`BrickCache::get_values`]), so that every sample whose word is a
    /// value reads as that value whichever brick it is read from. For the
    /// smooth normals' neighbour samples (render/sample/normals.rs); the
    /// traversal keeps reading the brick as decoded.
    pub fn brick_with_values(&mut self, c: [u32; 3]) -> (&RBrick, [u32; 3]) {
        let (has, l) = {
            let (b, l) = self.brick(c);
            (!b.values.is_empty(), l)
        };
        let id = self.cur_id;
        let held = self.held.get(self.cur).is_some();
        if !has && held && !self.cache.vol.index()[id as usize].is_uniform() {
            if self.values.as_ref().is_none_or(|(i, _)| *i != id) {
                match self.cache.get_values(id, &mut self.counters) {
                    Ok(b) => self.values = Some((id, b)),
                    Err(e) => {
                        if self.error.is_none() {
                            self.error = Some(e);
                        }
                        return (&EMPTY, [0; 3]);
                    }
                }
            }
            if let Some((_, b)) = &self.values {
                return (b, l);
            }
        }
        // The brick as `brick` found it (no second lookup), or after an
        // error the empty one.
        match self.held.get(self.cur) {
            Some(b) => (b, l),
            None => (&EMPTY, [0; 3]),
        }
    }
}

impl crate::render::traverse::CodeSource for Accessor<'_> {
    #[inline(always)]
    fn code(&mut self, c: [u32; 3], octant: Option<usize>) -> u8 {
        let (b, l) = self.brick(c);
        let code = b.code(l);
        match octant {
            Some(o) if code != OBJECT => code.max(b.octant_code(l, o)),
            _ => code,
        }
    }

    /// Top-down through the octree: the levels above the bricks from the
    /// index (no read), then the brick's own levels. Without an octree
    /// in the cache, the trait's single-cell answer.
    #[inline]
    fn empty_level(&mut self, c: [u32; 3]) -> Option<u8> {
        if !self.cache.planes.octree {
            return (self.code(c, None) != OBJECT).then_some(0);
        }
        let lb = self.brick_size.trailing_zeros();
        if let Some(p) = &self.cache.pyramid {
            let bs = self.brick_size;
            if let Some(j) = p.empty_level([c[0] / bs, c[1] / bs, c[2] / bs].map(u64::from)) {
                return Some((lb + j) as u8);
            }
        }
        let (b, l) = self.brick(c);
        if b.code(l) == OBJECT {
            return None;
        }
        if let Codes::Uniform(_) = b.codes {
            return Some(lb as u8);
        }
        for (i, f) in b.levels.iter().enumerate().rev() {
            let s = i as u32 + 1;
            let d = b.cells.map(|n| n.div_ceil(1 << s));
            let n = l.map(|x| x >> s);
            if f[((n[2] * d[1] + n[1]) * d[0] + n[0]) as usize] {
                return Some(s as u8);
            }
        }
        Some(0)
    }

    /// From the brick's DDA planes when it has them, never below the
    /// chessboard lower bound (so a corrupt plane cannot stall a ray);
    /// otherwise the chessboard bound itself.
    #[inline]
    fn distance(&mut self, c: [u32; 3], kind: crate::render::traverse::DistKind) -> u8 {
        use crate::render::traverse::DistKind;
        let (b, l) = self.brick(c);
        let code = b.code(l);
        if code == OBJECT {
            return 0;
        }
        let bound = ((code as u32 + 1) * kind.unit()).min(254) as u8;
        let plane = match kind {
            DistKind::Chessboard => return bound,
            DistKind::Cityblock => &b.dda[0],
            DistKind::Chamfer => &b.dda[1],
        };
        if plane.is_empty() {
            return bound;
        }
        let i = ((l[2] * b.cells[1] + l[1]) * b.cells[0] + l[0]) as usize;
        plane[i].clamp(bound, 254)
    }
}

impl Accessor<'_> {
    /// The 8 vertex values of global cell `c`, x fastest (all finite or
    /// NaN as stored; exact for a 1-cell).
    #[inline]
    pub fn vertices(&mut self, c: [u32; 3]) -> [f32; 8] {
        let (b, l) = self.brick(c);
        b.vertices(l)
    }
}

static EMPTY: RBrick = RBrick::bare([0; 3], [1; 3], Codes::Uniform(0), Samples::Empty);
