//! Brick streaming for the renderer: decoded bricks in one cache shared
//! by all threads, bounded by a byte budget with LRU eviction, and a
//! per-tile accessor that keeps the last brick in front of the cache
//! (OpenVDB's `ValueAccessor`), so most steps never touch a lock.
//!
//! A brick is read (positioned read, CRC check, zstd) only when a ray asks
//! for one of its cells, so a scene loads only the bricks it needs.

use std::sync::{Arc, Mutex};

use crate::classify::CellClass;
use crate::classify::Classification;
use crate::format::brick::{
    dda_planes, decode_samples, decode_words, octant_codes, SampleTable, Values, SAMPLE_ABOVE,
};
use crate::format::reader::PackedVolume;
use crate::format::FormatError;

use super::held::{self, Held};
use super::samples::{Samples, WordValues};

/// A sample value as the renderer holds it: rounded to f32 and saturated
/// to the finite f32 range (+-inf and values beyond it become +-f32::MAX,
/// so the trilinear interpolant stays finite); NaN stays NaN. Monotone, so
/// a value `>= iso` stays `>= to_f32(iso)`: the renderer compares against
/// the iso value mapped the same way, and every 1-cell keeps a vertex at
/// or above it.
#[inline]
pub fn to_f32(v: f64) -> f32 {
    if v.is_nan() {
        f32::NAN
    } else {
        (v as f32).clamp(-f32::MAX, f32::MAX)
    }
}

/// Code of a 1-cell in the decoded code plane (the traversal's constant).
pub use super::traverse::OBJECT;

/// A brick as the renderer uses it: a dense byte plane of cell codes
/// (255 = 1-cell) and the rescaled sample values, as f32 or as the stored
/// words with their table ([`Samples`]; NaN where the word held a code:
/// those samples are vertices of no 1-cell).
#[derive(Debug)]
pub struct RBrick {
    /// Global index of the first cell (= first sample).
    pub first: [u32; 3],
    /// Cells per axis.
    pub cells: [u32; 3],
    pub codes: Codes,
    /// Rescaled sample values, `(cells + 1)` per axis, x fastest; empty for
    /// uniform bricks and bricks without 1-cells. f32, or the stored 8- or
    /// 16-bit words with the file's table of their values
    /// ([`Samples`]).
    pub values: Samples,
    /// Per 4^3 block, the 8 octant codes (anisotropic files only).
    pub octants: Vec<[u8; 8]>,
    /// Octree levels inside the brick ([`Planes::octree`] only):
    /// `levels[l - 1]` flags which nodes of `2^l` cells per axis hold no
    /// 1-cell, x fastest.
    pub levels: Vec<Vec<bool>>,
    /// Bytes this brick holds (for the cache budget).
    pub bytes: usize,
    /// DDA planes `[city block, chamfer 3-4-5]`, one byte per cell, x
    /// fastest (files prepared with `--dda`); empty for uniform bricks and
    /// files without them.
    pub dda: [Vec<u8>; 2],
    /// Per block of [`BLOCK`]^3 cells (x fastest, `cells.div_ceil(BLOCK)`
    /// blocks per axis), the largest vertex value of the block's cells,
    /// NaN ignored (`f32::NEG_INFINITY` if all are NaN). Built only with
    /// [`Planes::block_max`] and only for bricks with values; empty
    /// otherwise.
    pub block_max: Vec<f32>,
    /// Per sample, its vertex gradient ([`Planes::grads`],
    /// `gradient::brick_gradients`): for the
    /// shaded composite, bricks with values only; empty otherwise.
    pub grads: Vec<glam::Vec3>,
}

/// Cells per edge of a [`RBrick::block_max`] block.
pub const BLOCK: u32 = 4;

#[derive(Debug)]
pub enum Codes {
    /// Every cell a 0-cell with this code.
    Uniform(u8),
    Plane(Vec<u8>),
}

impl RBrick {
    /// Code of local cell `l` (255 = 1-cell).
    #[inline]
    pub fn code(&self, l: [u32; 3]) -> u8 {
        match &self.codes {
            Codes::Uniform(c) => *c,
            Codes::Plane(p) => p[((l[2] * self.cells[1] + l[1]) * self.cells[0] + l[0]) as usize],
        }
    }

    /// Octant code of local cell `l` (its block's), or the isotropic code
    /// when the file has no anisotropic codes.
    #[inline]
    pub fn octant_code(&self, l: [u32; 3], octant: usize) -> u8 {
        match &self.codes {
            Codes::Uniform(c) => *c,
            Codes::Plane(_) if self.octants.is_empty() => self.code(l),
            Codes::Plane(_) => {
                let g = crate::dt::ANISO_BLOCK as u32;
                let nb = self.cells.map(|c| c.div_ceil(g));
                let b = ((l[2] / g * nb[1] + l[1] / g) * nb[0] + l[0] / g) as usize;
                self.octants[b][octant]
            }
        }
    }

    /// The largest vertex value (NaN ignored) of the [`BLOCK`]^3 block
    /// holding local cell `l`: an upper bound of every value the
    /// trilinear interpolant takes in the block's cells.
    /// `f32::NEG_INFINITY` when the block's vertices are all NaN;
    /// `f32::INFINITY` (no bound known) for a brick without the plane
    /// (not built, or a brick without values).
    #[inline]
    pub fn block_max(&self, l: [u32; 3]) -> f32 {
        if self.block_max.is_empty() {
            return f32::INFINITY;
        }
        let nb = self.cells.map(|c| c.div_ceil(BLOCK));
        let b = ((l[2] / BLOCK * nb[1] + l[1] / BLOCK) * nb[0] + l[0] / BLOCK) as usize;
        self.block_max[b]
    }

    /// The 8 vertex values of local cell `l`, x fastest.
    #[inline(always)]
    pub fn vertices(&self, l: [u32; 3]) -> [f32; 8] {
        self.values.gather(self.corner_offsets(l))
    }

    /// An upper bound of the 8 vertex values of local cell `l`
    /// ([`Samples::top`]): their largest, NaN left out, or NaN for no
    /// bound.
    #[inline(always)]
    pub fn vertex_top(&self, l: [u32; 3]) -> f32 {
        self.values.top(self.corner_offsets(l))
    }

    /// The 8 vertices of local cell `l` in the brick's sample planes: its
    /// minimum corner's sample index and the row and slice steps.
    #[inline(always)]
    fn corner_offsets(&self, l: [u32; 3]) -> super::samples::Corners {
        let sx = (self.cells[0] + 1) as usize;
        let sy = (self.cells[1] + 1) as usize;
        let base = (l[2] as usize * sy + l[1] as usize) * sx + l[0] as usize;
        super::samples::Corners {
            base,
            sx,
            z: sx * sy,
        }
    }

    /// The 8 entries of per-sample plane `v` (the values, or the gradient
    /// plane) at the vertices of local cell `l`, x fastest: loads at fixed
    /// offsets.
    #[inline(always)]
    pub fn corners<T: Copy>(&self, v: &[T], l: [u32; 3]) -> [T; 8] {
        super::samples::gather8(v, self.corner_offsets(l), |x| x)
    }

    /// A brick without payload: every cell a 0-cell with `code` (a
    /// uniform brick, or one stood in by its index code).
    pub(super) fn uniform(h: &crate::format::Header, id: u64, code: u32) -> RBrick {
        let coords = h.brick_coords(id);
        RBrick {
            first: std::array::from_fn(|k| (coords[k] * h.brick_size as u64) as u32),
            cells: h.brick_samples(coords).map(|s| (s - 1) as u32),
            codes: Codes::Uniform(code.min(254) as u8),
            values: Samples::Empty,
            octants: Vec::new(),
            levels: Vec::new(),
            bytes: std::mem::size_of::<RBrick>(),
            dda: [Vec::new(), Vec::new()],
            block_max: Vec::new(),
            grads: Vec::new(),
        }
    }

    /// Reads and decodes brick `id` with the format's decoder
    /// ([`crate::format::brick`]), then builds what rendering adds on top:
    /// the dense code plane, f32 values and the planes `planes` asks for.
    /// With [`Planes::narrow`] the brick is rewritten for the scene
    /// (render/scene.rs) before the planes built from codes and values;
    /// `scene_free`: the index says the scene has no 1-cell in it, so only
    /// its codes are decoded. Returns the brick and its decompressed
    /// payload size. The payload is read into per-thread buffers with a
    /// per-thread zstd context: no allocation per brick but the brick's
    /// own planes.
    pub fn decode(
        vol: &PackedVolume,
        id: u64,
        planes: Planes,
        scene_free: bool,
    ) -> Result<(RBrick, u64), FormatError> {
        let h = vol.header();
        let e = vol.index()[id as usize];
        let read = READ.with_borrow_mut(|r| {
            if r.dctx.is_none() {
                // Only fails when zstd cannot allocate its context: then
                // the reader's own path reports that on this brick.
                r.dctx = zstd::bulk::Decompressor::new().ok();
            }
            let ReadScratch { dctx, comp, raw } = r;
            let Some(dctx) = dctx else {
                return vol.read_payload(id).map(|p| p.map(|p| *raw = p).is_some());
            };
            vol.read_payload_into(id, dctx, comp, raw)
        })?;
        if !read {
            return Ok((RBrick::uniform(h, id, e.uniform_code), 0));
        }
        Ok(READ.with_borrow(|r| {
            let len = r.raw.len() as u64;
            // A brick free of the scene needs its codes only.
            let no_object = e.has_no_object() || scene_free;
            let Some(iso) = planes.narrow else {
                return (RBrick::from_payload(h, id, no_object, &r.raw, planes), len);
            };
            // Narrowed: codes and values for the file's classification,
            // rewritten for the scene (render/scene.rs), then the planes
            // built from them.
            let first = Planes {
                narrow: None,
                octree: false,
                block_max: false,
                grads: false,
                ..planes
            };
            let mut b = RBrick::from_payload(h, id, no_object, &r.raw, first);
            let edge = super::scene::Edge::of(vol, id, iso);
            if scene_free {
                super::scene::tighten(&mut b, &edge);
            } else {
                super::scene::narrow(&mut b, iso, h.gradient_halo, &edge);
            }
            let rest = Planes {
                octants: false,
                dda: false,
                narrow: None,
                ..planes
            };
            b.add_planes(h, id, &[], rest);
            (b, len)
        }))
    }

    /// Brick `id` from its decompressed payload `raw`, for the file's own
    /// classification (`planes.narrow` is [`RBrick::decode`]'s business):
    /// the fast path of [`RBrick::decode`]. Equal, plane for plane and bit for bit, to
    /// [`RBrick::from_payload_reference`] (the per-cell rule
    /// [`Classification::cell_of_words`] over f64 words; a unit test
    /// checks it on random bricks of every storage type).
    ///
    /// For an iso classification, the format's [`decode_samples`] gives
    /// per sample its code (0 for a value) and two bits, "is a code" and
    /// "is a value `>= iso`". The rule then reads: the cell's code is the
    /// code at its minimum corner, unless the OR of its 8 vertices' bits
    /// is exactly "`>= iso`" (no code, some vertex at or above the iso
    /// value: a 1-cell). The OR is taken separably (x, then y, then z)
    /// over whole rows. 8- and 16-bit words go through a per-thread
    /// [`SampleTable`]. A brick the index marks as holding no 1-cell needs
    /// only the corner codes and no values (through the table, only the
    /// corner words are read). The values of 8- and 16-bit words are
    /// kept as words unless a plane derived from them is asked for
    /// (render/samples.rs). Transfer functions take
    /// render/tf_cells.rs where it can, else the reference path.
    ///
    /// [`Classification::cell_of_words`]: crate::classify::Classification::cell_of_words
    pub fn from_payload(
        h: &crate::format::Header,
        id: u64,
        no_object: bool,
        raw: &[u8],
        planes: Planes,
    ) -> RBrick {
        let iso = match h.classification {
            Classification::Iso { iso } => iso,
            Classification::TransferFunction { .. } => {
                return super::tf_cells::decode(h, id, no_object, raw, planes).unwrap_or_else(
                    || RBrick::from_payload_reference(h, id, no_object, raw, planes),
                )
            }
        };
        let mut b = RBrick::uniform(h, id, 0);
        let [sx, sy, sz] = b.cells.map(|c| (c + 1) as usize);
        let n = sx * sy * sz;
        let (cx, cy, cz) = (sx - 1, sy - 1, sz - 1);
        let mut plane = Vec::with_capacity(cx * cy * cz);
        FAST.with_borrow_mut(|f| {
            let FastScratch {
                kinds,
                codes,
                or_x,
                or_xy,
                table,
                words,
            } = f;
            if table.as_ref().is_none_or(|t| !t.fits(h, Some(iso))) {
                *table = SampleTable::new(h, Some(iso), to_f32);
                *words = table.as_ref().and_then(|t| WordValues::of(t.values()));
            }
            if let (true, Some(t)) = (no_object, &table) {
                t.corner_codes(raw, [sx, sy, sz], &mut plane);
                return;
            }
            if no_object {
                decode_samples(h, raw, n, None, kinds, codes, None::<(_, fn(f64) -> f32)>);
                for z in 0..cz {
                    for y in 0..cy {
                        let r = (z * sy + y) * sx;
                        plane.extend_from_slice(&codes[r..r + cx]);
                    }
                }
                return;
            }
            // Planes derived from the values want them in f32.
            let keep_words = !planes.block_max && !planes.grads;
            b.values = match (table, words) {
                (Some(t), Some(WordValues::W8(v, order))) if keep_words => {
                    let mut w = Vec::new();
                    t.decode_words::<u8>(raw, n, kinds, codes, &mut w);
                    Samples::Words8(w, Arc::clone(v), *order)
                }
                (Some(t), Some(WordValues::W16(v, order))) if keep_words => {
                    let mut w = Vec::new();
                    t.decode_words::<u16>(raw, n, kinds, codes, &mut w);
                    Samples::Words16(w, Arc::clone(v), *order)
                }
                (Some(t), _) => {
                    let mut v = Vec::new();
                    t.decode(raw, n, kinds, codes, &mut v);
                    Samples::F32(v)
                }
                (None, _) => {
                    let mut v = Vec::new();
                    decode_samples(h, raw, n, Some(iso), kinds, codes, Some((&mut v, to_f32)));
                    Samples::F32(v)
                }
            };
            // OR of the two samples of each x edge, per sample row.
            or_x.clear();
            for row in kinds.chunks_exact(sx) {
                or_x.extend(row.windows(2).map(|w| w[0] | w[1]));
            }
            // ... of the four of each xy face, per sample slice.
            or_xy.clear();
            for z in 0..sz {
                let s = &or_x[z * sy * cx..(z + 1) * sy * cx];
                for y in 0..cy {
                    let (r0, r1) = (&s[y * cx..(y + 1) * cx], &s[(y + 1) * cx..(y + 2) * cx]);
                    or_xy.extend(r0.iter().zip(r1).map(|(a, b)| a | b));
                }
            }
            // ... of the eight of each cell; the class.
            for z in 0..cz {
                let (s0, s1) = (
                    &or_xy[z * cy * cx..(z + 1) * cy * cx],
                    &or_xy[(z + 1) * cy * cx..(z + 2) * cy * cx],
                );
                for y in 0..cy {
                    let corner = &codes[(z * sy + y) * sx..(z * sy + y) * sx + cx];
                    let (a, b) = (&s0[y * cx..(y + 1) * cx], &s1[y * cx..(y + 1) * cx]);
                    plane.extend(a.iter().zip(b).zip(corner).map(|((a, b), &c)| {
                        if a | b == SAMPLE_ABOVE {
                            OBJECT
                        } else {
                            c
                        }
                    }));
                }
            }
        });
        b.codes = Codes::Plane(plane);
        b.add_planes(h, id, raw, planes);
        b
    }

    /// [`RBrick::from_payload`] the way it was first written, kept as the
    /// reference the fast paths are tested against (and the path of
    /// transfer-function files those cannot take): [`decode_words`] into
    /// f64 values and
    /// `Option` codes, then [`RBrick::assemble`] cell by cell.
    #[doc(hidden)]
    pub fn from_payload_reference(
        h: &crate::format::Header,
        id: u64,
        no_object: bool,
        raw: &[u8],
        planes: Planes,
    ) -> RBrick {
        let n = h.brick_samples(h.brick_coords(id)).iter().product::<u64>() as usize;
        // A brick without 1-cells needs only its codes: a cell is coded at
        // its minimum corner or has code 0; no values, no classification.
        let mode = if no_object {
            Values::Skip
        } else {
            Values::Rescaled
        };
        // Per-thread scratch for the decoded words: no large transient
        // allocations per brick, which would fragment the heap between
        // the cache's long-lived buffers (docs/BENCHMARKS.md, "Larger
        // than RAM").
        let mut b = SCRATCH.with_borrow_mut(|(vals, codes)| {
            decode_words(h, raw, n, mode, vals, codes);
            RBrick::assemble(h, id, no_object, vals, codes)
        });
        b.add_planes(h, id, raw, planes);
        b
    }

    /// The planes beside codes and values that `planes` asks for, and the
    /// brick's byte count.
    pub(super) fn add_planes(
        &mut self,
        h: &crate::format::Header,
        id: u64,
        raw: &[u8],
        planes: Planes,
    ) {
        let coords = h.brick_coords(id);
        let b = self;
        if planes.octants {
            if let Some(o) = octant_codes(h, coords, raw) {
                b.octants = o.into_iter().map(|c| c.map(|x| x.min(254))).collect();
            }
        }
        if planes.dda {
            if let Some(d) = dda_planes(h, coords, raw) {
                b.dda = d;
            }
        }
        if let (true, Codes::Plane(p)) = (planes.octree, &b.codes) {
            b.levels = octree_levels(p, b.cells, h.brick_size.trailing_zeros());
        }
        if planes.block_max && !b.values.is_empty() {
            b.block_max = block_maxima(&b.values.to_f32(), b.cells);
        }
        if planes.grads && !b.values.is_empty() {
            let axes: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
            let v = b.values.to_f32();
            b.grads = super::gradient::brick_gradients(&v, b.first, b.cells, axes);
        }
        b.bytes = std::mem::size_of::<RBrick>()
            + b.codes.len()
            + b.values.bytes()
            + b.octants.len() * 8
            + b.dda[0].len()
            + b.dda[1].len()
            + b.levels.iter().map(Vec::len).sum::<usize>()
            + b.block_max.len() * 4
            + b.grads.len() * std::mem::size_of::<glam::Vec3>();
    }

    /// The code plane and f32 values of brick `id` from its decoded words:
    /// `vals` (rescaled, f64) and `codes` (the code a word carries). Each
    /// cell's class comes from [`Classification::cell_of_words`], the one
    /// rule; a brick the index marks as holding no 1-cell skips it (each
    /// of its cells is coded at its minimum corner or has code 0).
    ///
    /// [`Classification::cell_of_words`]: crate::classify::Classification::cell_of_words
    fn assemble(
        h: &crate::format::Header,
        id: u64,
        no_object: bool,
        vals: &[f64],
        codes: &[Option<u32>],
    ) -> RBrick {
        let mut b = RBrick::uniform(h, id, 0);
        let [sx, sy, sz] = b.cells.map(|c| (c + 1) as usize);
        let cls = &h.classification;
        let mut plane = Vec::with_capacity((sx - 1) * (sy - 1) * (sz - 1));
        let offs = [
            0,
            1,
            sx,
            sx + 1,
            sx * sy,
            sx * sy + 1,
            sx * sy + sx,
            sx * sy + sx + 1,
        ];
        for z in 0..sz - 1 {
            for y in 0..sy - 1 {
                for x in 0..sx - 1 {
                    let i = (z * sy + y) * sx + x;
                    let class = if no_object {
                        CellClass::Empty(codes[i].unwrap_or(0))
                    } else {
                        cls.cell_of_words(offs.map(|o| codes[i + o]), offs.map(|o| vals[i + o]))
                    };
                    plane.push(match class {
                        CellClass::Object => OBJECT,
                        CellClass::Empty(c) => c.min(254) as u8,
                    });
                }
            }
        }
        if !no_object {
            b.values = Samples::F32(
                vals.iter()
                    .zip(codes)
                    .map(|(&v, c)| if c.is_none() { to_f32(v) } else { f32::NAN })
                    .collect(),
            );
        }
        b.codes = Codes::Plane(plane);
        b
    }
}

impl Codes {
    /// Bytes of the code plane.
    fn len(&self) -> usize {
        match self {
            Codes::Uniform(_) => 0,
            Codes::Plane(p) => p.len(),
        }
    }
}

/// The [`RBrick::block_max`] plane of a brick with `cells` per axis from
/// its sample `values` (`cells + 1` per axis, x fastest): per block of
/// [`BLOCK`]^3 cells, the largest of its vertices' values, NaN ignored.
pub fn block_maxima(values: &[f32], cells: [u32; 3]) -> Vec<f32> {
    let [sx, sy, _] = cells.map(|c| c as usize + 1);
    let nb = cells.map(|c| c.div_ceil(BLOCK) as usize);
    let bs = BLOCK as usize;
    let mut out = vec![f32::NEG_INFINITY; nb[0] * nb[1] * nb[2]];
    // Samples 4b..=4b+4 (clipped) along each axis are the vertices of
    // block b's cells; the shared face samples count for both blocks.
    let span = |b: usize, k: usize| b * bs..=(b * bs + bs).min(cells[k] as usize);
    for bz in 0..nb[2] {
        for by in 0..nb[1] {
            for bx in 0..nb[0] {
                let mut m = f32::NEG_INFINITY;
                for z in span(bz, 2) {
                    for y in span(by, 1) {
                        let row = (z * sy + y) * sx;
                        for &v in
                            &values[row + bx * bs..=row + (bx * bs + bs).min(cells[0] as usize)]
                        {
                            // NaN compares false: ignored.
                            if v > m {
                                m = v;
                            }
                        }
                    }
                }
                out[(bz * nb[1] + by) * nb[0] + bx] = m;
            }
        }
    }
    out
}

/// Octree levels `1..=lb` of a brick's code plane (`cells` per axis):
/// level 1 from the cells, each further level from the one below (a node
/// is empty when all its children inside the brick are).
pub fn octree_levels(plane: &[u8], cells: [u32; 3], lb: u32) -> Vec<Vec<bool>> {
    let mut levels: Vec<Vec<bool>> = Vec::with_capacity(lb as usize);
    let mut below: Vec<bool> = plane.iter().map(|&c| c != OBJECT).collect();
    let mut dims = cells;
    for _ in 0..lb {
        let up = dims.map(|d| d.div_ceil(2));
        let mut cur = vec![true; (up[0] * up[1] * up[2]) as usize];
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    if !below[((z * dims[1] + y) * dims[0] + x) as usize] {
                        cur[(((z / 2) * up[1] + y / 2) * up[0] + x / 2) as usize] = false;
                    }
                }
            }
        }
        levels.push(cur.clone());
        below = cur;
        dims = up;
    }
    levels
}

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

type Scratch = (Vec<f64>, Vec<Option<u32>>);

/// Per-thread buffers of [`RBrick::decode`]'s read.
#[derive(Default)]
struct ReadScratch {
    dctx: Option<zstd::bulk::Decompressor<'static>>,
    comp: Vec<u8>,
    raw: Vec<u8>,
}

/// Per-thread buffers of [`RBrick::from_payload`].
#[derive(Default)]
struct FastScratch {
    kinds: Vec<u8>,
    codes: Vec<u8>,
    or_x: Vec<u8>,
    or_xy: Vec<u8>,
    table: Option<SampleTable>,
    /// `table`'s values as bricks keep them.
    words: Option<WordValues>,
}

thread_local! {
    static READ: std::cell::RefCell<ReadScratch> = std::cell::RefCell::new(ReadScratch::default());
    static FAST: std::cell::RefCell<FastScratch> = std::cell::RefCell::new(FastScratch::default());
    static SCRATCH: std::cell::RefCell<Scratch> = const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// Counters of one tile (summed at the end; no atomics in the hot loop).
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
pub struct CacheCounters {
    pub bricks_read: u64,
    /// Bricks without 1-cells stood in by their smallest code, unread.
    pub bricks_skipped: u64,
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
        self.cache_hits += o.cache_hits;
        self.cache_misses += o.cache_misses;
        self.bytes_decompressed += o.bytes_decompressed;
        self.decode_seconds += o.decode_seconds;
    }
}

/// Least-recently-used map under a byte budget, for keys below a bound
/// known up front (a brick id times 2, plus 1 for a stand-in): O(1) per
/// lookup, insertion and eviction, and no hashing. Keys index a table of
/// slots; the slots form a doubly linked list in recency order. A lookup
/// runs under the shared cache's lock on every brick an accessor's own
/// few do not hold (docs/BENCHMARKS.md, "Render-time iso": the
/// recency-ordered B-tree this replaces took 15 % of a cold frame).
struct Lru<V> {
    /// key -> slot in `slots`, or [`NIL`].
    index: Vec<u32>,
    slots: Vec<Slot<V>>,
    /// Slots of evicted entries, for reuse.
    free: Vec<u32>,
    /// Most and least recently used slots ([`NIL`] when empty).
    newest: u32,
    oldest: u32,
    bytes: usize,
    peak: usize,
    /// Keys ever inserted, one bit each.
    seen: Vec<u64>,
}

/// No slot.
const NIL: u32 = u32::MAX;

struct Slot<V> {
    key: u64,
    value: Option<V>,
    bytes: usize,
    /// Towards the newest and the oldest entry.
    newer: u32,
    older: u32,
}

impl<V: Clone> Lru<V> {
    /// An empty map for keys `0..keys`.
    fn new(keys: u64) -> Lru<V> {
        Lru {
            index: vec![NIL; keys as usize],
            slots: Vec::new(),
            free: Vec::new(),
            newest: NIL,
            oldest: NIL,
            bytes: 0,
            peak: 0,
            seen: vec![0; (keys as usize).div_ceil(64)],
        }
    }

    /// Takes slot `i` out of the recency list.
    fn unlink(&mut self, i: u32) {
        let (newer, older) = (self.slots[i as usize].newer, self.slots[i as usize].older);
        match newer {
            NIL => self.newest = older,
            n => self.slots[n as usize].older = older,
        }
        match older {
            NIL => self.oldest = newer,
            o => self.slots[o as usize].newer = newer,
        }
    }

    /// Puts slot `i` at the newest end of the recency list.
    fn push_newest(&mut self, i: u32) {
        let s = &mut self.slots[i as usize];
        s.newer = NIL;
        s.older = self.newest;
        match self.newest {
            NIL => self.oldest = i,
            n => self.slots[n as usize].newer = i,
        }
        self.newest = i;
    }

    /// The value of `key`, now the most recently used.
    fn get(&mut self, key: u64) -> Option<V> {
        let i = *self.index.get(key as usize)?;
        if i == NIL {
            return None;
        }
        if self.newest != i {
            self.unlink(i);
            self.push_newest(i);
        }
        self.slots[i as usize].value.clone()
    }

    /// Inserts `key` (absent, below the bound) holding `bytes`, first
    /// evicting least recently used entries until it fits in `budget`; a
    /// value larger than the whole budget is not kept.
    fn insert(&mut self, key: u64, v: V, bytes: usize, budget: usize) {
        let k = key as usize;
        if k >= self.index.len() || self.index[k] != NIL {
            return;
        }
        self.seen[k / 64] |= 1 << (k % 64);
        if bytes > budget {
            return;
        }
        while self.bytes + bytes > budget && self.oldest != NIL {
            let o = self.oldest;
            self.unlink(o);
            let s = &mut self.slots[o as usize];
            self.index[s.key as usize] = NIL;
            s.value = None;
            self.bytes -= s.bytes;
            self.free.push(o);
        }
        let slot = Slot {
            key,
            value: Some(v),
            bytes,
            newer: NIL,
            older: NIL,
        };
        let i = match self.free.pop() {
            Some(i) => {
                self.slots[i as usize] = slot;
                i
            }
            None => {
                self.slots.push(slot);
                (self.slots.len() - 1) as u32
            }
        };
        self.push_newest(i);
        self.index[k] = i;
        self.bytes += bytes;
        self.peak = self.peak.max(self.bytes);
    }

    /// Keys ever inserted that satisfy `f`.
    fn count_seen(&self, f: impl Fn(u64) -> bool) -> u64 {
        let mut n = 0;
        for (w, &bits) in self.seen.iter().enumerate() {
            let mut b = bits;
            while b != 0 {
                let k = w as u64 * 64 + b.trailing_zeros() as u64;
                n += u64::from(f(k));
                b &= b - 1;
            }
        }
        n
    }

    /// The keys held, oldest first.
    #[cfg(test)]
    fn by_age(&self) -> Vec<u64> {
        let mut v = Vec::new();
        let mut i = self.oldest;
        while i != NIL {
            v.push(self.slots[i as usize].key);
            i = self.slots[i as usize].newer;
        }
        v
    }
}

/// What one cache entry costs besides its brick: the `Arc` counts (16)
/// and its slot (48), rounded up generously (the table of slots by key,
/// 4 bytes a key, is the volume's, not the entries'). Counted against the budget because
/// uniform and lazily stood-in bricks are tiny and a big volume crosses
/// hundreds of thousands of them.
const ENTRY_BYTES: usize = 128;

/// Which planes the cache builds beside each decoded brick's codes and
/// values. On read, a plane not built answers as if the file had none
/// (the isotropic code, the chessboard bound, single-cell octree levels),
/// which is always conservative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Planes {
    /// The octant codes of anisotropic files (section 4.2.1).
    pub octants: bool,
    /// The city-block and chamfer planes of files prepared with `--dda`.
    pub dda: bool,
    /// Octree levels inside each brick and, for power-of-two brick sizes,
    /// above the bricks from the index (section 5.1).
    pub octree: bool,
    /// The largest vertex value per block of [`BLOCK`]^3 cells
    /// ([`RBrick::block_max`]), for bricks with values.
    pub block_max: bool,
    /// Each sample's vertex gradient ([`RBrick::grads`]), for bricks with
    /// values: the shaded composite with smooth normals.
    pub grads: bool,
    /// The scene's iso value when it is narrower than the file's
    /// classification (`render --iso`): each brick is rewritten for it
    /// (render/scene.rs) before any other plane is built.
    pub narrow: Option<f32>,
}

impl Planes {
    /// Codes and values only.
    pub const NONE: Planes = Planes {
        octants: false,
        dda: false,
        octree: false,
        block_max: false,
        grads: false,
        narrow: None,
    };

    /// Every plane the file has; no octree.
    pub const FILE: Planes = Planes {
        octants: true,
        dda: true,
        octree: false,
        block_max: false,
        grads: false,
        narrow: None,
    };
}

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
pub struct BrickCache<'v> {
    vol: &'v PackedVolume,
    budget: usize,
    lru: Mutex<Lru<Arc<RBrick>>>,
    planes: Planes,
    /// The levels above the bricks, when `planes.octree` and the brick
    /// size is a power of two (bricks are then octree nodes).
    pyramid: Option<BrickPyramid>,
    /// Unique in the process: what memos of derived data (render/
    /// gradient.rs) key on, so no two caches' bricks are ever confused.
    id: u64,
}

/// The next [`BrickCache`]'s id.
static NEXT_CACHE_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl<'v> BrickCache<'v> {
    /// A cache that builds every plane the file has, and no octree.
    pub fn new(vol: &'v PackedVolume, budget_bytes: usize) -> BrickCache<'v> {
        BrickCache::with_planes(vol, budget_bytes, Planes::FILE)
    }

    /// A cache that builds `planes`. With the octree, the levels above the
    /// bricks are built now from the index (no brick read), those inside
    /// a brick with each decoded brick (one byte per node, ~1/7 byte per
    /// cell, counted against the budget).
    pub fn with_planes(
        vol: &'v PackedVolume,
        budget_bytes: usize,
        planes: Planes,
    ) -> BrickCache<'v> {
        let bs = vol.header().brick_size;
        BrickCache {
            vol,
            budget: budget_bytes,
            lru: Mutex::new(Lru::new(vol.header().brick_count() * 2)),
            planes,
            pyramid: (planes.octree && bs.is_power_of_two()).then(|| BrickPyramid::new(vol)),
            id: NEXT_CACHE_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// This cache, also building the octree ([`Planes::octree`]).
    pub fn with_octree(self) -> BrickCache<'v> {
        let planes = Planes {
            octree: true,
            ..self.planes
        };
        BrickCache::with_planes(self.vol, self.budget, planes)
    }

    pub fn volume(&self) -> &PackedVolume {
        self.vol
    }

    /// Distinct bricks whose payload was read.
    pub fn distinct_read(&self) -> u64 {
        let l = self.lru.lock().unwrap_or_else(|e| e.into_inner());
        // Keys are id * 2 + lazy; lazy stand-ins read nothing.
        l.count_seen(|k| k % 2 == 0)
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
        let key = id * 2 + lazy as u64;
        if let Some(b) = self.lru.lock().unwrap_or_else(|e| e.into_inner()).get(key) {
            c.cache_hits += 1;
            return Ok(b);
        }
        c.cache_misses += 1;
        // A brick whose largest value lies below the scene's iso value
        // holds none of the scene's 1-cells: it is read for its codes
        // only (render/scene.rs, `tighten`). The index gives a maximum
        // only to bricks with 1-cells, never to those `lazy` stands in.
        let free = match (self.planes.narrow, e.value_max()) {
            (Some(iso), Some(m)) => to_f32(m) < iso,
            _ => false,
        };
        let b = if lazy {
            c.bricks_skipped += 1;
            RBrick::uniform(self.vol.header(), id, e.uniform_code)
        } else {
            let t = std::time::Instant::now();
            let r = RBrick::decode(self.vol, id, self.planes, free);
            c.decode_seconds += t.elapsed().as_secs_f64();
            let (b, raw) = r?;
            c.bytes_decompressed += raw;
            b
        };
        let b = Arc::new(b);
        let mut l = self.lru.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(first) = l.get(key) {
            // Another thread decoded it meanwhile: its copy wins (and its
            // read is the one counted).
            return Ok(first);
        }
        if !lazy {
            c.bricks_read += 1;
        }
        l.insert(key, b.clone(), b.bytes + ENTRY_BYTES, self.budget);
        Ok(b)
    }
}

/// Per-tile front of the cache: the current brick and the first error.
pub struct Accessor<'a, 'v> {
    cache: &'a BrickCache<'v>,
    brick_size: u32,
    bricks: [u64; 3],
    cur_id: u64,
    /// Slot of `held` holding the current brick ([`held::NONE`]: none,
    /// after an error). An index, not an `Arc`: switching bricks touches
    /// no reference count shared with other threads.
    cur: usize,
    /// The bricks this accessor used (up to [`held::HELD`]), tried before
    /// the shared cache, whose every lookup takes its lock: the rays of a
    /// tile cross the same bricks over and over (render/held.rs).
    held: Held<RBrick>,
    /// See [`BrickCache::get`].
    lazy_min: Option<u8>,
    pub counters: CacheCounters,
    pub error: Option<FormatError>,
    /// Smooth-normal gradients go through the thread's per-cell memo
    /// (render/gradient.rs).
    memo_gradients: bool,
}

/// Bricks an [`Accessor`] keeps besides the shared cache's budget (at
/// most this many per accessor, i.e. per tile in flight; they are also
/// counted in the budget while the shared cache holds them).
pub const HELD: usize = held::HELD;

/// Default smallest code for which CD stands an unread brick in by its
/// smallest code: below it, reading the brick's own (larger) codes pays
/// off (docs/BENCHMARKS.md, "Render levers").
pub const LAZY_MIN_CODE_CD: u8 = 16;

impl<'a, 'v> Accessor<'a, 'v> {
    /// An accessor that decodes every brick it enters.
    pub fn new(cache: &'a BrickCache<'v>) -> Accessor<'a, 'v> {
        Accessor::with_lazy(cache, None)
    }

    /// An accessor that stands bricks in as `policy` allows (its planes
    /// are the cache's business).
    pub fn for_policy(cache: &'a BrickCache<'v>, policy: &BrickPolicy) -> Accessor<'a, 'v> {
        Accessor::with_lazy(cache, policy.stand_in_min)
    }

    /// An accessor that stands in a brick without 1-cells by its index
    /// code when that code is at least `lazy_min` (see [`BrickCache::get`]).
    pub fn with_lazy(cache: &'a BrickCache<'v>, lazy_min: Option<u8>) -> Accessor<'a, 'v> {
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
        }
    }

    /// Whether smooth-normal gradients read through this accessor are
    /// remembered per cell in the thread's memo and answered from it
    /// ([`vertex_gradients`](super::gradient::vertex_gradients); the same
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

impl super::traverse::CodeSource for Accessor<'_, '_> {
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
    fn distance(&mut self, c: [u32; 3], kind: super::traverse::DistKind) -> u8 {
        use super::traverse::DistKind;
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

impl Accessor<'_, '_> {
    /// The 8 vertex values of global cell `c`, x fastest (all finite or
    /// NaN as stored; exact for a 1-cell).
    #[inline]
    pub fn vertices(&mut self, c: [u32; 3]) -> [f32; 8] {
        let (b, l) = self.brick(c);
        b.vertices(l)
    }
}

static EMPTY: RBrick = RBrick {
    first: [0; 3],
    cells: [1; 3],
    codes: Codes::Uniform(0),
    values: Samples::Empty,
    octants: Vec::new(),
    levels: Vec::new(),
    bytes: 0,
    dda: [Vec::new(), Vec::new()],
    block_max: Vec::new(),
    grads: Vec::new(),
};

#[cfg(test)]
mod tests {
    use super::{Codes, Lru, Planes, RBrick, Samples, OBJECT};
    use crate::classify::{Classification, TfPoint, TransferFunction};
    use crate::format::word::Word;
    use crate::format::{CodeEncoding, Header};
    use crate::input::{Dtype, Rescale};
    use proptest::prelude::*;

    /// A one-brick file's header: `dims` samples, words of `storage`.
    fn header(
        storage: Dtype,
        codes: CodeEncoding,
        rescale: Rescale,
        iso: f64,
        dims: [u64; 3],
    ) -> Header {
        let axis = |n: u64| crate::grid::Axis::uniform(0.0, 1.0, n as usize).expect("axis");
        Header {
            format_version: 1,
            dims,
            axes: [axis(dims[0]), axis(dims[1]), axis(dims[2])],
            dtype: storage,
            storage,
            rescale,
            classification: Classification::Iso { iso },
            codes,
            brick_size: 32,
            bricks: [1, 1, 1],
            aniso_block: None,
            dda: false,
            gradient_halo: false,
            zstd_level: 3,
            source: String::new(),
            notes: Vec::new(),
            orientation: None,
            input: None,
            summary: Default::default(),
        }
    }

    /// `n` words of type `W` from `pick`: 0..3 a code word (code from the
    /// low byte), 4 a special value (for floats NaN, +-inf, a foreign
    /// NaN; for integers the type's ends), else the raw bits.
    fn words<W: Word>(enc: &CodeEncoding, max: u32, pick: &[(u8, u64)], n: usize) -> Vec<u8> {
        let size = std::mem::size_of::<W>();
        let mut out = Vec::with_capacity(n * size);
        for &(k, bits) in pick.iter().cycle().take(n) {
            let w: W = match k % 8 {
                0..=2 => W::code(enc, (bits % (max as u64 + 1)) as u32),
                3 => W::from_raw(
                    [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0, -0.0][bits as usize % 5],
                ),
                _ => bytemuck::pod_read_unaligned(&bits.to_le_bytes()[..size]),
            };
            out.extend_from_slice(bytemuck::bytes_of(&w));
        }
        out
    }

    /// Storage type `ty` of the nine and a code encoding for it with
    /// codes up to `max` (an integer range placed by `base_pick`).
    fn storage_of(ty: usize, max: u32, base_pick: u64) -> (Dtype, CodeEncoding) {
        let storage = [
            Dtype::U8,
            Dtype::I8,
            Dtype::U16,
            Dtype::I16,
            Dtype::U32,
            Dtype::I32,
            Dtype::I64,
            Dtype::F32,
            Dtype::F64,
        ][ty];
        let enc = if storage.is_float() {
            CodeEncoding::NanPayload { max }
        } else {
            let (lo, hi) = storage.int_range();
            let span = (hi as i128 - lo as i128 - max as i128).max(1);
            let base = (lo as i128 + (base_pick as i128 % span)) as i64;
            CodeEncoding::IntRange { base, max }
        };
        (storage, enc)
    }

    /// A brick's code plane (one code for a uniform brick).
    fn plane_of(b: &RBrick) -> Vec<u8> {
        match &b.codes {
            Codes::Plane(p) => p.clone(),
            Codes::Uniform(c) => vec![*c],
        }
    }

    /// A brick's values as f32 bits.
    fn value_bits(b: &RBrick) -> Vec<u32> {
        b.values.to_f32().iter().map(|v| v.to_bits()).collect()
    }

    /// 16-bit tables decode kinds and codes by two range tests wherever
    /// the words allow (unsigned and signed words, rising and falling
    /// rescales, the iso value below, among and above the values, codes
    /// at either end of the words), and give the lookup's bytes for all
    /// 65536 words.
    #[test]
    fn range_tests_equal_the_lookup_for_every_word() {
        use crate::format::brick::SampleTable;
        let cases = [
            (Dtype::U16, 65000, 1.0, 0.0, 300.0),
            (Dtype::U16, 0, 1.0, -1024.0, 300.0),
            (Dtype::I16, -32768, 1.0, 0.0, 300.0),
            (Dtype::I16, 32000, -2.0, 5.0, 300.0),
            (Dtype::I16, 100, 0.5, 0.0, -1e9),
            (Dtype::U16, 1000, 1.0, 0.0, 1e9),
            (Dtype::I16, 0, 1.0, 0.0, -32768.0),
        ];
        let words: Vec<u16> = (0..=u16::MAX).collect();
        let raw: &[u8] = bytemuck::cast_slice(&words);
        for (storage, base, slope, intercept, iso) in cases {
            let enc = CodeEncoding::IntRange { base, max: 300 };
            let h = header(storage, enc, Rescale { slope, intercept }, iso, [2, 2, 2]);
            let t = SampleTable::new(&h, Some(iso), super::to_f32).unwrap();
            assert!(
                t.uses_ranges(),
                "{storage:?} base {base} slope {slope} iso {iso}"
            );
            let decode = |t: &SampleTable| {
                let (mut k, mut c, mut w) = (Vec::new(), Vec::new(), Vec::<u16>::new());
                t.decode_words(raw, words.len(), &mut k, &mut c, &mut w);
                let mut v = Vec::new();
                t.decode(raw, words.len(), &mut k, &mut c, &mut v);
                (k, c, w, v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
            };
            let slow = SampleTable::new(&h, Some(iso), super::to_f32)
                .unwrap()
                .without_ranges();
            let fast = decode(&t);
            assert!(
                fast.0.contains(&2) && fast.1.contains(&254),
                "codes saturate"
            );
            assert!(fast == decode(&slow), "{storage:?} {slope} {iso}");
            // The cells' minimum-corner codes of a 64 x 32 x 32 brick of all
            // the words.
            let (mut a, mut b) = (Vec::new(), Vec::new());
            t.corner_codes(raw, [64, 32, 32], &mut a);
            slow.corner_codes(raw, [64, 32, 32], &mut b);
            assert_eq!(a.len(), 63 * 31 * 31);
            assert!(a == b, "corner codes, {storage:?} {slope} {iso}");
        }
    }

    proptest! {
        /// The fast decode equals the reference (decode_words + the
        /// per-cell rule) on random bricks of every storage type: codes,
        /// values bit for bit (NaN included), with and without the
        /// no-1-cell flag, aligned and unaligned payloads. (Checked to
        /// fail with the class rule mutated.)
        #[test]
        fn fast_decode_equals_reference(
            ty in 0usize..9,
            samples in proptest::array::uniform3(2u64..8),
            pick in proptest::collection::vec((any::<u8>(), any::<u64>()), 1..400),
            base_pick in any::<u64>(),
            max in 0u32..=254,
            slope in prop_oneof![Just(1.0), Just(-1.0), Just(0.5), Just(1e30), -4.0f64..4.0],
            intercept in prop_oneof![Just(0.0), Just(-1024.0), -1e3f64..1e3],
            iso_pick in 0usize..400,
            iso_off in prop_oneof![Just(0.0), Just(1e-9), Just(-1e-9), -10.0f64..10.0],
            no_object in any::<bool>(),
            offset in 0usize..2,
            block_max in any::<bool>(),
        ) {
            let (storage, enc) = storage_of(ty, max, base_pick);
            let n = samples.iter().product::<u64>() as usize;
            let payload = crate::with_word!(storage, W => words::<W>(&enc, max, &pick, n));
            let rescale = Rescale { slope, intercept };
            // The iso value near a sample's rescaled value, to hit ties.
            let probe = header(storage, enc, rescale, 0.0, samples);
            let (mut vals, mut codes) = (Vec::new(), Vec::new());
            crate::format::brick::decode_words(&probe, &payload, n, crate::format::brick::Values::Rescaled, &mut vals, &mut codes);
            let v = vals[iso_pick % n];
            let iso = if v.is_finite() { v + iso_off } else { iso_off };
            let h = header(storage, enc, rescale, iso, samples);
            let mut buf = vec![0u8; offset];
            buf.extend_from_slice(&payload);
            let raw = &buf[offset..];
            // Values as words, or (a plane derived from them) in f32.
            let planes = Planes { block_max, ..Planes::NONE };
            let fast = RBrick::from_payload(&h, 0, no_object, raw, planes);
            let slow = RBrick::from_payload_reference(&h, 0, no_object, raw, planes);
            prop_assert_eq!(plane_of(&fast), plane_of(&slow));
            prop_assert_eq!(value_bits(&fast), value_bits(&slow));
            let words = matches!(fast.values, Samples::Words8(..) | Samples::Words16(..));
            prop_assert_eq!(
                words,
                storage.size() <= 2 && !block_max && !fast.values.is_empty()
            );
            // The same planes but for the width of the values.
            let f32_bytes = |b: &RBrick| b.bytes - b.values.bytes() + 4 * b.values.len();
            prop_assert_eq!(f32_bytes(&fast), slow.bytes);
            prop_assert_eq!(&fast.block_max, &slow.block_max);
        }
    }

    /// A cell whose largest value sits on a control point with opacity,
    /// after a point without: a 1-cell by its top value alone (no point
    /// with opacity lies strictly inside its range), which the fast path
    /// must see as the reference does.
    #[test]
    fn tf_cell_by_its_top_value() {
        let enc = CodeEncoding::IntRange { base: 200, max: 50 };
        let rescale = Rescale {
            slope: 1.0,
            intercept: 0.0,
        };
        let mut h = header(Dtype::U8, enc, rescale, 0.0, [2, 2, 2]);
        let point = |value, opacity| TfPoint {
            value,
            opacity,
            color: [1.0; 3],
        };
        h.classification = Classification::TransferFunction {
            tf: TransferFunction {
                points: vec![point(7.0, 0.0), point(10.0, 1.0)],
            },
        };
        for (words, class) in [([5u8, 10], OBJECT), ([5, 6], 0), ([8, 9], OBJECT)] {
            let raw: Vec<u8> = words.iter().copied().cycle().take(8).collect();
            let fast =
                super::super::tf_cells::decode(&h, 0, false, &raw, Planes::NONE).expect("fast");
            let slow = RBrick::from_payload_reference(&h, 0, false, &raw, Planes::NONE);
            for b in [&fast, &slow] {
                assert!(
                    matches!(&b.codes, Codes::Plane(p) if p[..] == [class]),
                    "{words:?}"
                );
            }
        }
    }

    proptest! {
        /// The transfer-function fast path (render/tf_cells.rs) equals
        /// the reference on random bricks of every storage type: codes
        /// and values bit for bit, control points on, just off and between
        /// sample values, zero and positive opacities, both slopes. It
        /// runs whenever the values rise with the words (a slope >= 0 and
        /// words of at most 16 bits).
        #[test]
        fn tf_decode_equals_reference(
            ty in 0usize..9,
            samples in proptest::array::uniform3(2u64..8),
            pick in proptest::collection::vec((any::<u8>(), any::<u64>()), 1..400),
            base_pick in any::<u64>(),
            max in 0u32..=254,
            slope in prop_oneof![Just(1.0), Just(-1.0), Just(0.5), Just(1e30), Just(0.0), -4.0f64..4.0],
            intercept in prop_oneof![Just(0.0), Just(-1024.0), -1e3f64..1e3],
            points in proptest::collection::vec(
                (0usize..400, prop_oneof![Just(0.0), Just(1e-9), Just(-1e-9), -10.0f64..10.0],
                 prop_oneof![Just(0.0), Just(0.0), Just(0.5), Just(1.0)]),
                1..6),
            no_object in any::<bool>(),
            offset in 0usize..2,
            few_codes in any::<bool>(),
        ) {
            let (storage, enc) = storage_of(ty, max, base_pick);
            let n = samples.iter().product::<u64>() as usize;
            // Mostly value words, so that many cells are decided by the
            // transfer function (a code word among the 8 decides alone).
            let pick: Vec<(u8, u64)> = pick
                .iter()
                .enumerate()
                .map(|(i, &(k, b))| (if few_codes && i % 16 != 0 { 4 + k % 4 } else { k }, b))
                .collect();
            let payload = crate::with_word!(storage, W => words::<W>(&enc, max, &pick, n));
            let rescale = Rescale { slope, intercept };
            let mut h = header(storage, enc, rescale, 0.0, samples);
            let (mut vals, mut codes) = (Vec::new(), Vec::new());
            crate::format::brick::decode_words(&h, &payload, n, crate::format::brick::Values::Rescaled, &mut vals, &mut codes);
            // Control points at sample values (ties), just off them, or
            // between; strictly increasing.
            let mut tf: Vec<TfPoint> = points
                .iter()
                .map(|&(i, off, opacity)| {
                    let v = vals[i % n];
                    let value = if v.is_finite() { v + off } else { off };
                    TfPoint { value, opacity, color: [1.0; 3] }
                })
                .collect();
            tf.sort_by(|a, b| a.value.total_cmp(&b.value));
            tf.dedup_by(|a, b| a.value == b.value);
            h.classification = Classification::TransferFunction {
                tf: TransferFunction { points: tf },
            };
            let mut buf = vec![0u8; offset];
            buf.extend_from_slice(&payload);
            let raw = &buf[offset..];
            let fast = RBrick::from_payload(&h, 0, no_object, raw, Planes::NONE);
            let slow = RBrick::from_payload_reference(&h, 0, no_object, raw, Planes::NONE);
            prop_assert_eq!(plane_of(&fast), plane_of(&slow));
            prop_assert_eq!(value_bits(&fast), value_bits(&slow));
            prop_assert_eq!(fast.bytes, slow.bytes);
            let ran = super::super::tf_cells::decode(&h, 0, no_object, raw, Planes::NONE).is_some();
            if storage.size() <= 2 && slope >= 0.0 {
                prop_assert!(ran);
            }
        }
    }

    proptest! {
        /// Against the definition: each cell's 8 vertices, NaN ignored,
        /// folded into its block's maximum.
        #[test]
        fn block_maxima_bound_each_cells_vertices(
            cells in proptest::array::uniform3(1u32..11),
            seed in proptest::collection::vec(prop_oneof![
                3 => -1e3f32..1e3,
                1 => Just(f32::NAN),
                1 => Just(f32::INFINITY),
                1 => Just(f32::NEG_INFINITY),
            ], 1331),
        ) {
            let [sx, sy, sz] = cells.map(|c| c as usize + 1);
            let values: Vec<f32> = (0..sx * sy * sz).map(|i| seed[i % seed.len()]).collect();
            let got = super::block_maxima(&values, cells);
            let nb = cells.map(|c| c.div_ceil(super::BLOCK) as usize);
            let mut want = vec![f32::NEG_INFINITY; nb[0] * nb[1] * nb[2]];
            for z in 0..sz - 1 {
                for y in 0..sy - 1 {
                    for x in 0..sx - 1 {
                        let b = ((z / 4) * nb[1] + y / 4) * nb[0] + x / 4;
                        for d in 0..8 {
                            let v = values[((z + d / 4) * sy + y + d / 2 % 2) * sx + x + d % 2];
                            if v > want[b] {
                                want[b] = v;
                            }
                        }
                    }
                }
            }
            prop_assert_eq!(got, want);
        }

        /// Against a model that keeps (key, bytes) in recency order and
        /// evicts from the front: same contents after every operation,
        /// never above the budget.
        #[test]
        fn lru_matches_a_recency_list(
            budget in 1usize..64,
            ops in proptest::collection::vec((any::<bool>(), 0u64..12, 1usize..20), 1..200),
        ) {
            let mut lru: Lru<u64> = Lru::new(12);
            let mut model: Vec<(u64, usize)> = Vec::new();
            for (is_get, key, bytes) in ops {
                let pos = model.iter().position(|e| e.0 == key);
                if is_get || pos.is_some() {
                    let got = lru.get(key);
                    prop_assert_eq!(got, pos.map(|_| key * 10));
                    if let Some(p) = pos {
                        let e = model.remove(p);
                        model.push(e);
                    }
                } else {
                    lru.insert(key, key * 10, bytes, budget);
                    if bytes <= budget {
                        while model.iter().map(|e| e.1).sum::<usize>() + bytes > budget {
                            model.remove(0);
                        }
                        model.push((key, bytes));
                    }
                }
                let model_age: Vec<u64> = model.iter().map(|e| e.0).collect();
                prop_assert_eq!(lru.by_age(), model_age);
                let held = (0..12).filter(|&k| lru.index[k as usize] != super::NIL).count();
                prop_assert_eq!(held, model.len());
                prop_assert_eq!(lru.bytes, model.iter().map(|e| e.1).sum::<usize>());
                prop_assert!(lru.bytes <= budget && lru.peak <= budget);
            }
        }
    }
}
