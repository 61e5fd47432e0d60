//! A decoded brick as the renderer holds it ([`RBrick`]): the dense code
//! plane and the values decoded from the payload, and the planes built on
//! them when the cache asks ([`Planes`](crate::render::brick::Planes)).

use std::sync::Arc;

use crate::classify::CellClass;
use crate::classify::Classification;
use crate::format::brick::{
    dda_planes, decode_samples, decode_words, octant_codes, SampleTable, Values, SAMPLE_ABOVE,
};
use crate::format::reader::PackedVolume;
use crate::format::FormatError;

use super::samples::{Samples, WordValues};
use super::{to_f32, GradPlane, Planes};
use crate::render::traverse::OBJECT;

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
    /// A max pyramid: `block_max[i]` holds, per node of `BLOCK << i`
    /// cells per axis (x fastest, `cells.div_ceil(BLOCK << i)` nodes per
    /// axis), the largest vertex value of the node's cells, NaN ignored
    /// (`f32::NEG_INFINITY` if all are NaN); from [`BLOCK`]^3 blocks up to
    /// the largest power of two that divides the brick size, so that every
    /// node is one of the grid's aligned octree nodes. Built only with
    /// [`Planes::block_max`] and only for bricks with values; empty
    /// otherwise.
    pub block_max: Vec<Vec<f32>>,
    /// Per sample, its vertex gradient ([`Planes::grads`]): for the
    /// shaded composite, bricks with values only; empty otherwise. The
    /// inner samples are ready at decode (`gradients::brick_gradients`),
    /// the outer layer's on first use ([`GradPlane`]).
    pub grads: GradPlane,
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
            Codes::Plane(p) => p[self.cell_index(l)],
        }
    }

    /// Index of local cell `l` in the brick's per-cell planes (x fastest).
    #[inline(always)]
    pub fn cell_index(&self, l: [u32; 3]) -> usize {
        ((l[2] * self.cells[1] + l[1]) * self.cells[0] + l[0]) as usize
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

    /// The largest vertex value of the node of level `i` of
    /// [`RBrick::block_max`] (`BLOCK << i` cells per axis) holding local
    /// cell `l`: an upper bound of every value the trilinear interpolant
    /// takes in the node's cells (`f32::NEG_INFINITY` when all their
    /// vertices are NaN); `f32::INFINITY` (no bound) when that level is not
    /// built.
    #[inline(always)]
    pub fn node_max(&self, l: [u32; 3], i: usize) -> f32 {
        let Some(plane) = self.block_max.get(i) else {
            return f32::INFINITY;
        };
        let s = BLOCK.trailing_zeros() + i as u32;
        let n = self.cells.map(|c| c.div_ceil(1 << s));
        plane[(((l[2] >> s) * n[1] + (l[1] >> s)) * n[0] + (l[0] >> s)) as usize]
    }

    /// The largest level `L` (in cells per axis, `2^L`) of the pyramid
    /// [`RBrick::block_max`] whose node holding local cell `l` has no
    /// vertex value above `best`; `None` when even its [`BLOCK`]^3 block
    /// has one (or the pyramid is not built). The nodes nest, so the
    /// levels are tried upwards until one fails.
    #[inline]
    pub fn node_below(&self, l: [u32; 3], best: f64) -> Option<u8> {
        let mut found = None;
        for i in 0..self.block_max.len() {
            if self.node_max(l, i) as f64 > best {
                break;
            }
            found = Some((BLOCK.trailing_zeros() + i as u32) as u8);
        }
        found
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

    /// The gradients at the vertices of local cell `l` from the gradient
    /// plane ([`RBrick::grads`]), x fastest, when the plane holds them:
    /// loads at fixed offsets.
    #[inline(always)]
    pub fn grad_cell(&self, l: [u32; 3]) -> Option<[glam::Vec3A; 8]> {
        self.grads.cell(l)
    }

    /// Index of local sample `ls` (0 to `cells` per axis) in the brick's
    /// sample planes (x fastest).
    #[inline(always)]
    pub fn sample_index(&self, ls: [usize; 3]) -> usize {
        let (sx, sy) = (self.cells[0] as usize + 1, self.cells[1] as usize + 1);
        (ls[2] * sy + ls[1]) * sx + ls[0]
    }

    /// The sample indices of the vertices of local cell `l`, x fastest.
    #[inline]
    pub fn corner_indices(&self, l: [u32; 3]) -> [usize; 8] {
        self.corner_offsets(l).indices()
    }

    /// A brick without payload: every cell a 0-cell with `code` (a
    /// uniform brick, or one stood in by its index code).
    pub(in crate::render) fn uniform(h: &crate::format::Header, id: u64, code: u32) -> RBrick {
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
            grads: GradPlane::EMPTY,
        }
    }

    /// Reads and decodes brick `id` with the format's decoder
    /// ([`crate::format::brick`]), then builds what rendering adds on top:
    /// the dense code plane, f32 values and the planes `planes` asks for.
    /// With [`Planes::narrow`] the brick is rewritten for the scene
    /// (render/brick/envelope.rs) before the planes built from codes and values;
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
        RBrick::decode_as(vol, id, planes, scene_free, false)
    }

    /// Brick `id` with its codes and values, for the file's own
    /// classification, even when the index says it holds no 1-cell (which
    /// [`RBrick::decode`] reads for its codes only): smooth normals read
    /// the samples of such a brick next to the object
    /// (render/sample/normals.rs, "Which brick a sample is read from").
    pub fn decode_values(vol: &PackedVolume, id: u64) -> Result<(RBrick, u64), FormatError> {
        RBrick::decode_as(vol, id, Planes::NONE, false, true)
    }

    /// [`RBrick::decode`], with the values whatever the index says when
    /// `values`.
    fn decode_as(
        vol: &PackedVolume,
        id: u64,
        planes: Planes,
        scene_free: bool,
        values: bool,
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
            let no_object = (e.has_no_object() || scene_free) && !values;
            let Some(iso) = planes.narrow else {
                return (RBrick::from_payload(h, id, no_object, &r.raw, planes), len);
            };
            // Narrowed: codes and values for the file's classification,
            // rewritten for the scene (render/brick/envelope.rs), then the planes
            // built from them.
            let first = Planes {
                narrow: None,
                octree: false,
                block_max: false,
                grads: false,
                ..planes
            };
            let mut b = RBrick::from_payload(h, id, no_object, &r.raw, first);
            let edge = super::envelope::Edge::of(vol, id, iso);
            if scene_free {
                super::envelope::tighten(&mut b, &edge);
            } else {
                super::envelope::narrow(&mut b, iso, h.gradient_halo, &edge);
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
    /// (render/brick/samples.rs). Transfer functions take
    /// render/brick/tf_cells.rs where it can, else the reference path.
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
            let keep_words = !planes.grads;
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
    pub(in crate::render) fn add_planes(
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
            let base = block_maxima_of(&b.values, b.cells);
            b.block_max = max_pyramid(base, b.cells, h.brick_size);
        }
        if planes.grads && !b.values.is_empty() {
            let axes: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
            let v = b.values.to_f32();
            let g = super::gradients::brick_gradients(&v, b.first, b.cells, axes);
            b.grads = GradPlane::inner(&g, b.cells.map(|c| c as usize));
        }
        b.bytes = std::mem::size_of::<RBrick>()
            + b.codes.len()
            + b.values.bytes()
            + b.octants.len() * 8
            + b.dda[0].len()
            + b.dda[1].len()
            + b.levels.iter().map(Vec::len).sum::<usize>()
            + b.block_max.iter().map(|p| p.len() * 4).sum::<usize>()
            + b.grads.bytes();
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
    block_maxima_by(values, cells, |&v| v)
}

/// [`block_maxima`] of a brick's samples as it holds them: f32, or the
/// stored words looked up in their table (no f32 copy of the plane).
pub fn block_maxima_of(samples: &Samples, cells: [u32; 3]) -> Vec<f32> {
    match samples {
        Samples::Empty => Vec::new(),
        Samples::F32(v) => block_maxima(v, cells),
        Samples::Words8(w, t, _) => block_maxima_by(w, cells, |&x| t[x as usize]),
        Samples::Words16(w, t, _) => block_maxima_by(w, cells, |&x| t[x as usize]),
    }
}

/// [`block_maxima`] of a plane of entries `plane` whose values `value`
/// gives.
#[inline(always)]
fn block_maxima_by<W>(plane: &[W], cells: [u32; 3], value: impl Fn(&W) -> f32) -> Vec<f32> {
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
                        for w in &plane[row + bx * bs..=row + (bx * bs + bs).min(cells[0] as usize)]
                        {
                            let v = value(w);
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

/// The [`RBrick::block_max`] pyramid of a brick with `cells` per axis
/// from its [`BLOCK`]^3 maxima `base`: each level the maxima of the level
/// below's 2x2x2 children inside the brick, up to nodes of the largest
/// power of two dividing `brick_size` (bricks start at multiples of it).
pub fn max_pyramid(base: Vec<f32>, cells: [u32; 3], brick_size: u32) -> Vec<Vec<f32>> {
    let b0 = BLOCK.trailing_zeros();
    let top = brick_size.trailing_zeros();
    if top < b0 {
        return Vec::new();
    }
    let mut levels = vec![base];
    for s in b0 + 1..=top {
        let below = &levels[levels.len() - 1];
        let d = cells.map(|c| c.div_ceil(1 << (s - 1)) as usize);
        let up = cells.map(|c| c.div_ceil(1 << s) as usize);
        let mut out = vec![f32::NEG_INFINITY; up[0] * up[1] * up[2]];
        for z in 0..d[2] {
            for y in 0..d[1] {
                for x in 0..d[0] {
                    let v = below[(z * d[1] + y) * d[0] + x];
                    let o = &mut out[((z / 2) * up[1] + y / 2) * up[0] + x / 2];
                    // NaN never stored (block_maxima ignores it).
                    if v > *o {
                        *o = v;
                    }
                }
            }
        }
        levels.push(out);
    }
    levels
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

impl RBrick {
    /// A brick of `cells` at `first` with these codes and values and no
    /// other plane (the accessor's stand-in after an error; unit tests).
    pub(crate) const fn bare(
        first: [u32; 3],
        cells: [u32; 3],
        codes: Codes,
        values: Samples,
    ) -> RBrick {
        RBrick {
            first,
            cells,
            codes,
            values,
            octants: Vec::new(),
            levels: Vec::new(),
            bytes: 0,
            dda: [Vec::new(), Vec::new()],
            block_max: Vec::new(),
            grads: GradPlane::EMPTY,
        }
    }
}

#[cfg(test)]
#[path = "decode_tests.rs"]
mod tests;
