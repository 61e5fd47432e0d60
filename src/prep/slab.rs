//! Pass 2's output, one slab of brick depth at a time: the slab's sample
//! words with the distance codes embedded (docs/DESIGN.md, "Embedding"),
//! cut into bricks and compressed in parallel ([`emit_slab`]). The module
//! root (`prep/mod.rs`) drives the two passes.

use std::time::Instant;

use rayon::prelude::*;

use super::PrepError;
use crate::dt::{OctantBlocks, ANISO_BLOCK};
use crate::format::word::Word;
use crate::format::{CodeEncoding, Header};
use crate::input::SliceSource;

/// Buffers reused from slab to slab.
#[derive(Default)]
pub(super) struct SlabScratch {
    /// Backing store of the slab's words (u64 for alignment of any type).
    words: Vec<u64>,
    raw: Vec<f64>,
}

pub(super) struct SlabCtx<'a> {
    pub(super) header: &'a Header,
    pub(super) src: &'a dyn SliceSource,
    /// Distances: slab-local cell slice k at `k * ncx * ncy`; slot `b`
    /// holds cell slice z1 when `has_upper`.
    pub(super) dist: &'a [u8],
    pub(super) blocks: &'a [Option<OctantBlocks>],
    /// City-block and chamfer planes, slab-local cell slice k at
    /// `k * ncx * ncy` (with --dda).
    pub(super) dda: Option<[&'a [u8]; 2]>,
    pub(super) z0: usize,
    pub(super) z1: usize,
    pub(super) has_upper: bool,
}

pub(super) enum BrickOut {
    Uniform(u32),
    Payload {
        compressed: Vec<u8>,
        raw_len: u64,
        no_object: bool,
        min_code: u32,
        value_max: Option<f64>,
    },
}

/// The largest rescaled value among the words of a brick's samples
/// `x0..=x1`, `y0..=y1` and slab slices `0..=nzc` that are not codes
/// (NaN ignored); `None` when none is a number.
fn brick_value_max<W: Word>(
    h: &Header,
    words: &[W],
    [x0, x1]: [usize; 2],
    [y0, y1]: [usize; 2],
    nzc: usize,
) -> Option<f64> {
    let [nx, ny, _] = h.dims.map(|d| d as usize);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..=nzc {
        for y in y0..=y1 {
            let row = &words[(k * ny + y) * nx..];
            for w in &row[x0..=x1] {
                if w.as_code(&h.codes).is_none() {
                    let v = w.to_raw();
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
    }
    // The rescale may have a negative slope: the largest rescaled value
    // is that of one of the raw extremes.
    let m = h.rescale.apply(lo).max(h.rescale.apply(hi));
    (lo <= hi && !m.is_nan()).then_some(m)
}

/// Reads the slab's samples, embeds codes and compresses its bricks.
/// Returns the bricks and the seconds spent reading and embedding.
///
/// `scratch` keeps the slab's word and sample buffers from one slab to the
/// next, so the large allocations (and the kernel's page zeroing) happen
/// once, not once per slab.
pub(super) fn emit_slab<W: Word>(
    ctx: &SlabCtx,
    level: i32,
    scratch: &mut SlabScratch,
) -> Result<(Vec<(u64, BrickOut)>, f64), PrepError> {
    let t0 = Instant::now();
    let h = ctx.header;
    let [nx, ny, _] = h.dims.map(|d| d as usize);
    let [ncx, ncy, _] = h.cells().map(|c| c as usize);
    let b = h.brick_size as usize;
    let nsl = ctx.z1 - ctx.z0 + 1;
    let enc: CodeEncoding = h.codes;
    let max_code = enc.max_code();
    // Distances (code + 1) whose code is embedded: codes >= 1, or >= 2
    // with a gradient halo. Uniform bricks are unaffected: no sample a
    // gradient reads lies only in one (render/sample/normals.rs).
    let embed_min: u8 = if h.gradient_halo { 3 } else { 2 };
    let n_cells_slice = ncx * ncy;
    // Sample words of slices z0..=z1, codes embedded (every word below is
    // written before it is read).
    let n_words = nsl * nx * ny;
    let n_u64 = (n_words * std::mem::size_of::<W>()).div_ceil(8);
    if scratch.words.len() < n_u64 {
        scratch.words.resize(n_u64, 0);
    }
    let words: &mut [W] =
        &mut bytemuck::cast_slice_mut::<u64, W>(&mut scratch.words[..])[..n_words];
    scratch.raw.resize(nx * ny, 0.0);
    let raw = &mut scratch.raw;
    for k in 0..nsl {
        let zs = ctx.z0 + k;
        ctx.src.read_slice(zs, raw)?;
        // Cell slice whose minimum corners lie on this sample slice.
        let dist_slot = if zs < ctx.z1 {
            Some(k)
        } else if ctx.has_upper {
            Some(b)
        } else {
            None
        };
        let out = &mut words[k * nx * ny..(k + 1) * nx * ny];
        out.par_chunks_mut(nx).enumerate().for_each(|(y, row)| {
            let r = &raw[y * nx..(y + 1) * nx];
            for (w, &v) in row.iter_mut().zip(r) {
                *w = W::from_raw(v);
            }
            if let (Some(slot), true) = (dist_slot, y < ncy) {
                let d =
                    &ctx.dist[slot * n_cells_slice + y * ncx..slot * n_cells_slice + (y + 1) * ncx];
                for (w, &dd) in row.iter_mut().zip(d) {
                    if dd >= embed_min {
                        *w = W::code(&enc, (dd as u32 - 1).min(max_code));
                    }
                }
            }
        });
    }
    let embed_s = t0.elapsed().as_secs_f64();
    let bz = (ctx.z0 / b) as u64;
    let ids: Vec<u64> = (0..h.bricks[1])
        .flat_map(|by| (0..h.bricks[0]).map(move |bx| h.brick_id([bx, by, bz])))
        .collect();
    let words: &[W] = words;
    let outs: Vec<(u64, BrickOut)> = ids
        .par_iter()
        .map_init(
            || zstd::bulk::Compressor::new(level),
            |comp, &id| {
                let c = h.brick_coords(id);
                let (x0, x1) = h.brick_cells(0, c[0]);
                let (y0, y1) = h.brick_cells(1, c[1]);
                let (x0, x1, y0, y1) = (x0 as usize, x1 as usize, y0 as usize, y1 as usize);
                let nzc = ctx.z1 - ctx.z0;
                // Uniform: every cell a 0-cell with the same saturated code >= 1.
                let code_of = |d: u8| (d as u32 - 1).min(max_code);
                let first = ctx.dist[y0 * ncx + x0];
                let uniform = first >= 2
                    && (0..nzc).all(|k| {
                        (y0..y1).all(|y| {
                            let row = &ctx.dist[k * n_cells_slice + y * ncx..];
                            row[x0..x1]
                                .iter()
                                .all(|&d| d >= 2 && code_of(d) == code_of(first))
                        })
                    });
                if uniform {
                    return (id, BrickOut::Uniform(code_of(first)));
                }
                let n_bytes = h.payload_len(c) as usize;
                let mut bytes: Vec<u8> = Vec::with_capacity(n_bytes);
                for k in 0..=nzc {
                    for y in y0..=y1 {
                        let row = &words[(k * ny + y) * nx..];
                        bytes.extend_from_slice(bytemuck::cast_slice(&row[x0..=x1]));
                    }
                }
                if h.aniso_block.is_some() {
                    bytes.extend(octant_payload(ctx, c, max_code));
                }
                if let Some(planes) = ctx.dda {
                    // City block, then chamfer: the brick's cells, x fastest.
                    for p in planes {
                        for k in 0..nzc {
                            for y in y0..y1 {
                                let row = &p[k * n_cells_slice + y * ncx..];
                                bytes.extend_from_slice(&row[x0..x1]);
                            }
                        }
                    }
                }
                debug_assert_eq!(bytes.len(), n_bytes);
                let raw_len = bytes.len() as u64;
                let bytes = if h.byte_planes() {
                    let n = h.words_len(c) as usize;
                    let mut planes = Vec::with_capacity(n_bytes);
                    crate::format::planes::split(&bytes[..n], size_of::<W>(), &mut planes);
                    planes.extend_from_slice(&bytes[n..]);
                    planes
                } else {
                    bytes
                };
                // One compression context per rayon job, reused across bricks.
                let compressed = match comp {
                    Ok(c) => c.compress(&bytes),
                    Err(e) => Err(std::io::Error::other(e.to_string())),
                }
                .expect("zstd compresses into memory for any level prep accepts");
                // Smallest distance in the brick: 0 means it holds a 1-cell;
                // otherwise its code is the smallest code of its cells.
                let min_d = (0..nzc)
                    .flat_map(|k| (y0..y1).map(move |y| (k, y)))
                    .map(|(k, y)| {
                        let row = &ctx.dist[k * n_cells_slice + y * ncx..];
                        row[x0..x1].iter().copied().min().unwrap_or(u8::MAX)
                    })
                    .min()
                    .unwrap_or(u8::MAX);
                let no_object = min_d > 0;
                // The largest value of a brick with 1-cells (index flag
                // FLAG_VALUE_MAX): its words that are not codes, rescaled.
                let value_max = (!no_object)
                    .then(|| brick_value_max(h, words, [x0, x1], [y0, y1], nzc))
                    .flatten();
                // The smallest code the brick's cells read back as: a cell
                // whose code is not embedded reads as code 0.
                let min_code = if min_d >= embed_min {
                    code_of(min_d)
                } else {
                    0
                };
                (
                    id,
                    BrickOut::Payload {
                        compressed,
                        raw_len,
                        no_object,
                        min_code,
                        value_max,
                    },
                )
            },
        )
        .collect();
    Ok((outs, embed_s))
}

/// The 8 octant planes of brick `c`: plane-major, blocks x fastest.
fn octant_payload(ctx: &SlabCtx, c: [u64; 3], max_code: u32) -> Vec<u8> {
    let h = ctx.header;
    let g = ANISO_BLOCK;
    let nbx_slice = (h.cells()[0] as usize).div_ceil(g);
    let nb = h.brick_blocks(c).expect("aniso").map(|v| v as usize);
    let bpb = h.brick_size as usize / g;
    let mut out = Vec::with_capacity(8 * nb[0] * nb[1] * nb[2]);
    for o in 0..8 {
        for kz in 0..nb[2] {
            let slab = ctx.blocks[kz]
                .as_ref()
                .expect("octant blocks for every block slab");
            for ky in 0..nb[1] {
                for kx in 0..nb[0] {
                    let gx = c[0] as usize * bpb + kx;
                    let gy = c[1] as usize * bpb + ky;
                    out.push(slab[o][gy * nbx_slice + gx].min(max_code as u8));
                }
            }
        }
    }
    out
}
