//! A decoded brick as the renderer holds it ([`RBrick`]): the dense code
//! plane and the values decoded from the payload, and the planes built on
//! them when the cache asks ([`Planes`](super::Planes)).

use std::sync::Arc;

use crate::classify::CellClass;
use crate::classify::Classification;
use crate::format::brick::{
    dda_planes, decode_samples, decode_words, octant_codes, SampleTable, Values, SAMPLE_ABOVE,
};
use crate::format::reader::PackedVolume;
use crate::format::FormatError;

use super::{to_f32, GradPlane, Planes, OBJECT};
use crate::render::samples::{Samples, WordValues};

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
    /// Per sample, its vertex gradient ([`Planes::grads`]): for the
    /// shaded composite, bricks with values only; empty otherwise. The
    /// inner samples are set at decode (`gradient::brick_gradients`), the
    /// outer layer on first use ([`GradPlane`]).
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
    fn corner_offsets(&self, l: [u32; 3]) -> crate::render::samples::Corners {
        let sx = (self.cells[0] + 1) as usize;
        let sy = (self.cells[1] + 1) as usize;
        let base = (l[2] as usize * sy + l[1] as usize) * sx + l[0] as usize;
        crate::render::samples::Corners {
            base,
            sx,
            z: sx * sy,
        }
    }

    /// The gradient plane's entries ([`RBrick::grads`], set or not) at
    /// the vertices of local cell `l`, x fastest: loads at fixed offsets.
    #[inline(always)]
    pub fn grad_corners(&self, l: [u32; 3]) -> [glam::Vec3; 8] {
        self.grads.corners(self.corner_offsets(l))
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
        RBrick::decode_as(vol, id, planes, scene_free, false)
    }

    /// Brick `id` with its codes and values, for the file's own
    /// classification, even when the index says it holds no 1-cell (which
    /// [`RBrick::decode`] reads for its codes only): smooth normals read
    /// the samples of such a brick next to the object
    /// (render/gradient.rs, "Which brick a sample is read from").
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
            let edge = crate::render::scene::Edge::of(vol, id, iso);
            if scene_free {
                crate::render::scene::tighten(&mut b, &edge);
            } else {
                crate::render::scene::narrow(&mut b, iso, h.gradient_halo, &edge);
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
                return crate::render::tf_cells::decode(h, id, no_object, raw, planes)
                    .unwrap_or_else(|| {
                        RBrick::from_payload_reference(h, id, no_object, raw, planes)
                    })
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
            b.block_max = block_maxima(&b.values.to_f32(), b.cells);
        }
        if planes.grads && !b.values.is_empty() {
            let axes: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
            let v = b.values.to_f32();
            let g = crate::render::gradient::brick_gradients(&v, b.first, b.cells, axes);
            b.grads = GradPlane::inner(&g, b.cells.map(|c| c as usize));
        }
        b.bytes = std::mem::size_of::<RBrick>()
            + b.codes.len()
            + b.values.bytes()
            + b.octants.len() * 8
            + b.dda[0].len()
            + b.dda[1].len()
            + b.levels.iter().map(Vec::len).sum::<usize>()
            + b.block_max.len() * 4
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

#[cfg(test)]
mod tests {
    use super::{Codes, Planes, RBrick, Samples, OBJECT};
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
                crate::render::tf_cells::decode(&h, 0, false, &raw, Planes::NONE).expect("fast");
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
            let ran = crate::render::tf_cells::decode(&h, 0, no_object, raw, Planes::NONE).is_some();
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
    }
}
