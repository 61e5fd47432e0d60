//! The two passes of prep over a run of cell slices: the whole volume
//! ([`super::prep`]) or one shard of it ([`super::shard`]).
//!
//! [`scan`] is pass 1: read sample slices, count what the header records
//! ([`ScanStats`]), classify and run the forward transform into a spill.
//! [`emit`] is pass 2: the backward transform, slab by slab of one brick
//! depth from the top down, each slab's bricks cut, compressed and handed
//! to a sink in the order one prep writes them.

use std::ops::Range;
use std::time::Instant;

use rayon::prelude::*;

use super::slab::{emit_slab, BrickOut, SlabCtx, SlabScratch};
use super::{PrepError, PrepOptions, StageTimes};
use crate::classify::{classify_slice, slice_extrema, slice_iso_flags, Classification};
use crate::dt::{self, BackwardDt, ForwardDt, OctantBlocks, ANISO_BLOCK, FAR};
use crate::format::histogram::HistogramBuilder;
use crate::format::Header;
use crate::input::{SliceSource, VolumeMeta};
use crate::progress::Progress;
use crate::with_word;

/// What pass 1 counts of the sample slices it is given: merged over the
/// shards of a sharded prep ([`ScanStats::merge`]), it is what one pass
/// over the whole volume counts.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScanStats {
    pub one_cells: u64,
    pub nan_samples: u64,
    /// Smallest and largest raw sample (NaN left out; +inf / -inf when
    /// none was seen).
    #[serde(with = "crate::json::f64_bits")]
    pub raw_min: f64,
    #[serde(with = "crate::json::f64_bits")]
    pub raw_max: f64,
    pub values: HistogramBuilder,
    /// Samples per label 0..=65535, for a label map.
    pub labels: Option<Vec<u64>>,
}

impl ScanStats {
    pub fn new(meta: &VolumeMeta, labels: bool) -> ScanStats {
        ScanStats {
            one_cells: 0,
            nan_samples: 0,
            raw_min: f64::INFINITY,
            raw_max: f64::NEG_INFINITY,
            values: HistogramBuilder::new(meta.dtype),
            labels: labels.then(|| vec![0; crate::labels::MAX_LABEL as usize + 1]),
        }
    }

    /// Adds the counts of other sample slices.
    pub fn merge(&mut self, o: &ScanStats) {
        self.one_cells += o.one_cells;
        self.nan_samples += o.nan_samples;
        self.raw_min = self.raw_min.min(o.raw_min);
        self.raw_max = self.raw_max.max(o.raw_max);
        self.values.merge(&o.values);
        if let (Some(a), Some(b)) = (self.labels.as_mut(), o.labels.as_ref()) {
            a.iter_mut().zip(b).for_each(|(a, &b)| *a += b);
        }
    }

    /// The raw range, `None` when every sample is NaN.
    pub fn range(&self) -> Option<(f64, f64)> {
        (self.raw_min <= self.raw_max).then_some((self.raw_min, self.raw_max))
    }
}

/// Pass 1 over the cell slices `cells` (reading sample slices
/// `cells.start ..= cells.end`): the sample slices in `counted` are
/// counted into the returned stats (a shard counts the slice it shares
/// with the shard above only once, there), the cells are classified and
/// fed to `fwd`, which spills their forward distances.
#[allow(clippy::too_many_arguments)]
pub fn scan(
    src: &dyn SliceSource,
    opts: &PrepOptions,
    cells: Range<usize>,
    counted: Range<usize>,
    fwd: &mut ForwardDt,
    spill: &mut dyn dt::Spill,
    mut block_spill: Option<&mut dyn dt::Spill>,
    spill_err: &dyn Fn(std::io::Error) -> PrepError,
    progress: &dyn Progress,
    st: &mut StageTimes,
) -> Result<ScanStats, PrepError> {
    let meta = src.meta();
    let [nx, ny, _] = meta.dims();
    let [ncx, ncy, ncz] = meta.grid.cells();
    let n_cells_slice = ncx * ncy;
    let cls = &opts.classification;
    let mut buf = vec![0.0f64; nx * ny];
    // Per-column flags (iso) or extrema (transfer function) of the last
    // two sample slices.
    let is_tf = matches!(cls, Classification::TransferFunction { .. });
    let planes_len = if is_tf { n_cells_slice } else { 0 };
    let mut planes = [vec![0.0f64; planes_len], vec![0.0f64; planes_len]];
    let mut min_planes = [vec![0.0f64; planes_len], vec![0.0f64; planes_len]];
    let flags_len = if is_tf { 0 } else { n_cells_slice };
    let mut flags = [vec![0u8; flags_len], vec![0u8; flags_len]];
    let mut obj = vec![0u8; n_cells_slice];
    let mut stats = ScanStats::new(meta, opts.labels);
    let mut label_counter = opts
        .labels
        .then(|| crate::labels::LabelCounter::new(&meta.origin_desc));
    let lap = |t: &mut Instant| {
        let e = t.elapsed().as_secs_f64();
        *t = Instant::now();
        e
    };
    let mut t = Instant::now();
    progress.begin(
        "classify + forward DT",
        (cells.end + 1 - cells.start) as u64,
    );
    for z in cells.start..=cells.end {
        src.read_slice(z, &mut buf)?;
        st.read1 += lap(&mut t);
        let count = counted.contains(&z);
        if meta.dtype.is_float() && count {
            stats.nan_samples += buf.par_iter().filter(|v| v.is_nan()).count() as u64;
        }
        if let (Some(c), true) = (label_counter.as_mut(), count) {
            c.add_slice(&buf, nx, z)?;
        }
        let cur = z % 2;
        let (lo, hi) = match cls {
            Classification::Iso { iso } => {
                slice_iso_flags(&buf, nx, ny, meta.rescale, *iso, &mut flags[cur])
            }
            Classification::TransferFunction { .. } => {
                slice_extrema(&buf, nx, ny, &mut planes[cur], &mut min_planes[cur])
            }
        };
        if count {
            stats.raw_min = stats.raw_min.min(lo);
            stats.raw_max = stats.raw_max.max(hi);
        }
        st.classify_forward += lap(&mut t);
        if count {
            stats.values.add_slice(&buf, (lo <= hi).then_some((lo, hi)));
        }
        st.histogram += lap(&mut t);
        if z > cells.start {
            let prev = 1 - cur;
            stats.one_cells += match cls {
                Classification::Iso { .. } => or_planes(&flags[prev], &flags[cur], &mut obj),
                Classification::TransferFunction { .. } => classify_slice(
                    cls,
                    meta.rescale,
                    [&planes[prev], &planes[cur]],
                    [&min_planes[prev], &min_planes[cur]],
                    ncx,
                    &mut obj,
                ),
            };
            fwd.push(
                &obj,
                z == ncz,
                spill,
                block_spill.as_mut().map(|s| &mut **s as &mut dyn dt::Spill),
            )
            .map_err(spill_err)?;
        }
        st.classify_forward += lap(&mut t);
        progress.advance(1);
    }
    progress.end();
    if let (Some(c), Some(l)) = (label_counter, stats.labels.as_mut()) {
        l.copy_from_slice(c.counts());
    }
    Ok(stats)
}

/// `obj = a | b` (cells flagged from the slice below or above); returns the
/// number of 1-cells.
fn or_planes(a: &[u8], b: &[u8], obj: &mut [u8]) -> u64 {
    obj.par_chunks_mut(1 << 16)
        .zip(a.par_chunks(1 << 16).zip(b.par_chunks(1 << 16)))
        .map(|(o, (a, b))| {
            let mut n = 0u64;
            for ((o, &a), &b) in o.iter_mut().zip(a).zip(b) {
                *o = a | b;
                n += *o as u64;
            }
            n
        })
        .sum()
}

/// What pass 2 counts for the summary.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EmitStats {
    /// 0-cells per code (saturated at the encoding's maximum).
    pub code_histogram: Vec<u64>,
    pub uniform_bricks: u64,
    pub raw_payload_bytes: u64,
}

impl EmitStats {
    pub fn merge(&mut self, o: &EmitStats) {
        if self.code_histogram.len() < o.code_histogram.len() {
            self.code_histogram.resize(o.code_histogram.len(), 0);
        }
        self.code_histogram
            .iter_mut()
            .zip(&o.code_histogram)
            .for_each(|(a, &b)| *a += b);
        self.uniform_bricks += o.uniform_bricks;
        self.raw_payload_bytes += o.raw_payload_bytes;
    }
}

/// Receives pass 2's bricks in the order of the file.
pub type BrickSink<'a> = dyn FnMut(u64, BrickOut) -> Result<(), PrepError> + 'a;

/// Pass 2 over the brick layers `layers`, from the top down: the backward
/// transform (from `above`, the final distances of the cell slice over
/// the top layer, when there is one), each slab's words with codes
/// embedded, cut into bricks, compressed, and given to `sink`.
#[allow(clippy::too_many_arguments)]
pub fn emit(
    header: &Header,
    src: &dyn SliceSource,
    opts: &PrepOptions,
    layers: Range<usize>,
    above: Option<&[u8]>,
    spill: &mut dyn dt::Spill,
    mut block_spill: Option<&mut dyn dt::Spill>,
    spill_err: &dyn Fn(std::io::Error) -> PrepError,
    sink: &mut BrickSink,
    progress: &dyn Progress,
    st: &mut StageTimes,
) -> Result<EmitStats, PrepError> {
    let b = header.brick_size as usize;
    let [ncx, ncy, ncz] = header.cells().map(|c| c as usize);
    let n_cells_slice = ncx * ncy;
    let codes = header.codes;
    let mut out = EmitStats {
        code_histogram: vec![0u64; codes.max_code() as usize + 1],
        ..EmitStats::default()
    };
    let mut bwd = BackwardDt::new(ncx, ncy, ncz, opts.aniso).with_dda(opts.dda);
    // Distances of cell slices z0..=z1 of the current slab (the last one
    // is the first slice of the slab above, kept from the previous round,
    // or `above`). (A volume of one slab has no slab above: no slot for
    // its slice.)
    let slab_slices = if ncz > b { b + 1 } else { ncz };
    let mut slab_dist = vec![FAR; slab_slices * n_cells_slice];
    if let Some(a) = above {
        bwd = bwd.seeded(a);
        slab_dist[b * n_cells_slice..].copy_from_slice(a);
    }
    let mut slab_blocks: Vec<Option<OctantBlocks>> = vec![None; b / ANISO_BLOCK];
    // City-block and chamfer planes of cell slices z0..z1 (with --dda).
    let dda_len = if opts.dda { b * n_cells_slice } else { 0 };
    let mut slab_dda = [vec![0u8; dda_len], vec![0u8; dda_len]];
    let mut scratch = SlabScratch::default();
    let lap = |t: &mut Instant| {
        let e = t.elapsed().as_secs_f64();
        *t = Instant::now();
        e
    };
    let mut t = Instant::now();
    let first_cell = layers.start * b;
    let end_cell = (layers.end * b).min(ncz);
    progress.begin("backward DT + bricks", (end_cell - first_cell) as u64);
    for bz in layers.clone().rev() {
        let z0 = bz * b;
        let z1 = (z0 + b).min(ncz);
        for z in (z0..z1).rev() {
            let (g, blocks) = bwd
                .step(
                    z,
                    spill,
                    block_spill.as_mut().map(|s| &mut **s as &mut dyn dt::Spill),
                )
                .map_err(spill_err)?;
            slab_dist[(z - z0) * n_cells_slice..(z - z0 + 1) * n_cells_slice].copy_from_slice(g);
            let counts = g
                .par_chunks(1 << 16)
                .map(|c| {
                    let mut h = [0u64; 256];
                    c.iter().for_each(|&d| h[d as usize] += 1);
                    h
                })
                .reduce(|| [0u64; 256], |a, b| std::array::from_fn(|i| a[i] + b[i]));
            for (d, &n) in counts.iter().enumerate().skip(1) {
                out.code_histogram[(d - 1).min(codes.max_code() as usize)] += n;
            }
            if let Some(bl) = blocks {
                slab_blocks[(z - z0) / ANISO_BLOCK] = Some(bl);
            }
            if let Some(planes) = bwd.dda() {
                let at = (z - z0) * n_cells_slice..(z - z0 + 1) * n_cells_slice;
                for (s, p) in slab_dda.iter_mut().zip(planes) {
                    s[at.clone()].copy_from_slice(p);
                }
            }
            progress.advance(1);
        }
        st.backward += lap(&mut t);
        let ctx = SlabCtx {
            header,
            src,
            dist: &slab_dist,
            blocks: &slab_blocks,
            dda: opts.dda.then_some([&slab_dda[0][..], &slab_dda[1][..]]),
            z0,
            z1,
            has_upper: z1 < ncz,
        };
        let (outs, embed_s) =
            with_word!(header.storage, W => emit_slab::<W>(&ctx, opts.zstd_level, &mut scratch)?);
        st.embed += embed_s;
        st.compress += lap(&mut t) - embed_s;
        for (id, o) in outs {
            match &o {
                BrickOut::Uniform(_) => out.uniform_bricks += 1,
                BrickOut::Payload { raw_len, .. } => out.raw_payload_bytes += raw_len,
            }
            sink(id, o)?;
        }
        // The first slice of this slab is the upper slice of the next one.
        if bz > layers.start {
            slab_dist.copy_within(0..n_cells_slice, b * n_cells_slice);
        }
        st.write += lap(&mut t);
    }
    progress.end();
    Ok(out)
}
