//! Sharded prep of one volume (docs/DESIGN.md, "Sharded prep"): shard K
//! of N holds the brick layers `K * L / N .. (K + 1) * L / N` of the `L`
//! layers, and three steps, each one process per shard or one in all,
//! write the file one prep writes, byte for byte:
//!
//! 1. [`scan`] (`prep --shard K/N --pass 1`, one per shard): pass 1 over
//!    the shard's slices, from its own 1-cells alone; its forward spill
//!    stays in the parts directory, and a scan file records what it
//!    counted and its two seam planes ([`crate::dt::seam`]).
//! 2. [`bricks`] (`prep --shard K/N --pass 2`, one per shard, after every
//!    scan): reads the N scans' counts, carries the seam planes of the
//!    shards within 254 cell slices across the shards below and above
//!    it, corrects its spill for the 1-cells below and runs pass 2 into a
//!    part file: the bricks in file order, with the header every shard
//!    computes alike.
//! 3. [`merge`] (`prep-merge`, one): the parts, top shard first, streamed
//!    into the packed file, one brick in memory at a time.
//!
//! A scan or part records the plan it belongs to (input, dimensions,
//! options, N); the later steps refuse a file of another plan by name.

use std::io::Read;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::part::{copy_part, io_err, read_trailer, PartTrailer, PartWriter, Plan};
use super::passes::{self, EmitStats, ScanStats};
use super::{checked, header_for, summary_of, PrepError, PrepOptions, StageTimes};
use crate::dt::{self, FileSpill, ForwardDt, SeamChain, FAR};
use crate::format::writer::PackedWriter;
use crate::format::Header;
use crate::input::SliceSource;
use crate::progress::Progress;

const SCAN_MAGIC: &[u8; 8] = b"CDVSCAN1";

/// The parts directory of an output: `OUT.cdv.parts`.
pub fn parts_dir(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".parts");
    PathBuf::from(s)
}

/// A file of shard `k` of `n` in `dir`: `shard-K-of-N.EXT`.
pub fn shard_file(dir: &Path, k: u32, n: u32, ext: &str) -> PathBuf {
    dir.join(format!("shard-{k:04}-of-{n:04}.{ext}"))
}

/// The brick layers of shard `k` of `n` among `layers`; refuses more
/// shards than layers.
pub fn shard_layers(layers: usize, k: u32, n: u32) -> Result<Range<usize>, PrepError> {
    let (k, n) = (k as usize, n as usize);
    if n == 0 || k >= n || n > layers {
        return Err(PrepError::Option {
            field: "shard",
            value: format!("{k}/{n}"),
            msg: format!(
                "expected K/N with 0 <= K < N <= {layers}, the volume's brick layers (a shard \
                 holds at least one)"
            ),
        });
    }
    Ok(k * layers / n..(k + 1) * layers / n)
}

/// The JSON of a scan file, before its two planes.
#[derive(serde::Serialize, serde::Deserialize)]
struct ScanRecord {
    plan: Plan,
    k: u32,
    layers: [usize; 2],
    stats: ScanStats,
}

/// What a shard's step did.
#[derive(Debug, Clone)]
pub struct ShardReport {
    /// The file written (scan or part).
    pub path: PathBuf,
    pub cells: Range<usize>,
    pub seconds: f64,
    pub stages: StageTimes,
    /// Pass 2: slices of the spill corrected for the 1-cells below.
    pub fixed_slices: usize,
}

fn refuse_unsharded_options(opts: &PrepOptions) -> Result<(), PrepError> {
    for (on, field) in [(opts.aniso, "aniso"), (opts.dda, "dda")] {
        if on {
            return Err(PrepError::Option {
                field,
                value: "on".into(),
                msg: "not with --shard: the octant and DDA planes have seams of their own; \
                      prepare such a file in one process"
                    .into(),
            });
        }
    }
    Ok(())
}

/// The cell slices of `layers` and the sample slices whose counts are the
/// shard's (the one it shares with the shard above is counted there).
fn slices_of(
    src: &dyn SliceSource,
    b: usize,
    layers: &Range<usize>,
) -> (Range<usize>, Range<usize>) {
    let [_, _, nz] = src.meta().dims();
    let ncz = src.meta().grid.cells()[2];
    let cells = layers.start * b..(layers.end * b).min(ncz);
    let counted = cells.start..if cells.end == ncz { nz } else { cells.end };
    (cells, counted)
}

/// Step 1, `prep --shard K/N --pass 1`: pass 1 over shard `k` of `n`
/// into `parts` (its spill and scan file).
pub fn scan(
    src: &dyn SliceSource,
    parts: &Path,
    k: u32,
    n: u32,
    opts: &PrepOptions,
    progress: &dyn Progress,
) -> Result<ShardReport, PrepError> {
    let t0 = Instant::now();
    let scan_path = shard_file(parts, k, n, "scan");
    let spill_path = shard_file(parts, k, n, "spill");
    std::fs::create_dir_all(parts).map_err(io_err(parts, "cannot create the parts directory"))?;
    let opts = &checked(src, &[scan_path.clone(), spill_path.clone()], opts)?;
    refuse_unsharded_options(opts)?;
    let [ncx, ncy, ncz] = src.meta().grid.cells();
    let b = opts.brick_size;
    let layers = shard_layers(ncz.div_ceil(b), k, n)?;
    let (cells, counted) = slices_of(src, b, &layers);
    let file = std::fs::File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&spill_path)
        .map_err(io_err(&spill_path, "cannot create the shard's spill"))?;
    let spill_err = io_err(&spill_path, "shard spill");
    let mut spill = FileSpill::at(file, dt::spill_record(ncx * ncy, false), cells.start);
    let mut fwd = ForwardDt::new(ncx, ncy, false).starting_at(cells.start, None);
    let mut st = StageTimes::default();
    let stats = passes::scan(
        src,
        opts,
        cells.clone(),
        counted,
        &mut fwd,
        &mut spill,
        None,
        &spill_err,
        progress,
        &mut st,
    )?;
    drop(fwd);
    let t = Instant::now();
    let mut top = vec![0u8; ncx * ncy];
    dt::Spill::get(&mut spill, cells.end - 1, &mut top).map_err(&spill_err)?;
    let bottom =
        dt::local_bottom(&mut spill, cells.start, cells.end, ncx, ncy).map_err(&spill_err)?;
    st.backward += t.elapsed().as_secs_f64();
    let record = ScanRecord {
        plan: Plan::of(src, opts, n),
        k,
        layers: [layers.start, layers.end],
        stats,
    };
    let json = serde_json::to_vec(&record).map_err(|e| PrepError::Shard {
        path: scan_path.clone(),
        msg: e.to_string(),
    })?;
    let mut bytes = Vec::with_capacity(16 + json.len() + 2 * top.len());
    bytes.extend_from_slice(SCAN_MAGIC);
    bytes.extend_from_slice(&(json.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&json);
    bytes.extend_from_slice(&top);
    bytes.extend_from_slice(&bottom);
    let t = Instant::now();
    crate::fsutil::write_atomic(&scan_path, &bytes).map_err(|e| PrepError::Shard {
        path: scan_path.clone(),
        msg: e.to_string(),
    })?;
    st.write += t.elapsed().as_secs_f64();
    Ok(ShardReport {
        path: scan_path,
        cells,
        seconds: t0.elapsed().as_secs_f64(),
        stages: st,
        fixed_slices: 0,
    })
}

/// A scan file's record, and where its two planes start.
fn read_scan(path: &Path, plane: usize) -> Result<(ScanRecord, u64), PrepError> {
    let bad = |msg: String| PrepError::Shard {
        path: path.to_path_buf(),
        msg,
    };
    let mut f = crate::fsutil::open_regular(path).map_err(|e| {
        bad(format!(
            "cannot read the scan of this shard ({e}): run `prep --shard K/N --pass 1` for \
             every shard first"
        ))
    })?;
    let size = f
        .metadata()
        .map_err(|e| bad(format!("cannot stat: {e}")))?
        .len();
    let mut head = [0u8; 16];
    if size < 16 || f.read_exact(&mut head).is_err() || &head[..8] != SCAN_MAGIC {
        return Err(bad("not a cdvol shard scan (magic CDVSCAN1)".into()));
    }
    let len = u64::from_le_bytes(head[8..16].try_into().expect("8 bytes"));
    let end = 16u64.saturating_add(len);
    let want = end.saturating_add(2 * plane as u64);
    if size != want {
        return Err(bad(format!(
            "{size} bytes, expected {want} (a record of {len} bytes and two planes of {plane} cells)"
        )));
    }
    let mut json = vec![0u8; len as usize];
    f.read_exact(&mut json)
        .map_err(|e| bad(format!("cannot read the record: {e}")))?;
    let record: ScanRecord =
        serde_json::from_slice(&json).map_err(|e| bad(format!("record: {e}")))?;
    Ok((record, end))
}

/// Plane `which` (0: top, 1: bottom) of a scan file whose planes start at
/// `at`.
fn read_plane(path: &Path, at: u64, plane: usize, which: u64) -> Result<Vec<u8>, PrepError> {
    use std::os::unix::fs::FileExt;
    let f = crate::fsutil::open_regular(path).map_err(io_err(path, "cannot open the scan"))?;
    let mut out = vec![0u8; plane];
    f.read_exact_at(&mut out, at + which * plane as u64)
        .map_err(io_err(path, "cannot read a seam plane of the scan"))?;
    Ok(out)
}

/// Step 2, `prep --shard K/N --pass 2`: the part file of shard `k` of
/// `n` from the N scans in `parts`. Removes the shard's spill when the
/// part is written.
pub fn bricks(
    src: &dyn SliceSource,
    parts: &Path,
    k: u32,
    n: u32,
    opts: &PrepOptions,
    progress: &dyn Progress,
) -> Result<ShardReport, PrepError> {
    let t0 = Instant::now();
    let part_path = shard_file(parts, k, n, "part");
    let spill_path = shard_file(parts, k, n, "spill");
    let opts = &checked(src, std::slice::from_ref(&part_path), opts)?;
    refuse_unsharded_options(opts)?;
    let [ncx, ncy, ncz] = src.meta().grid.cells();
    let plane = ncx * ncy;
    let b = opts.brick_size;
    let layers = shard_layers(ncz.div_ceil(b), k, n)?;
    let (cells, _) = slices_of(src, b, &layers);
    let plan = Plan::of(src, opts, n);
    let mut st = StageTimes::default();
    // Every scan's record: the plan, the shard, its counts.
    let t = Instant::now();
    let mut stats: Option<ScanStats> = None;
    let mut depths = Vec::with_capacity(n as usize);
    let mut planes_at = Vec::with_capacity(n as usize);
    for j in 0..n {
        let path = shard_file(parts, j, n, "scan");
        let (rec, at) = read_scan(&path, plane)?;
        if let Some(d) = plan.differs(&rec.plan) {
            return Err(PrepError::Shard { path, msg: d });
        }
        let want = shard_layers(ncz.div_ceil(b), j, n)?;
        if rec.k != j || rec.layers != [want.start, want.end] {
            return Err(PrepError::Shard {
                path,
                msg: format!(
                    "shard {} with layers {:?}, expected shard {j} with layers {want:?}",
                    rec.k, rec.layers
                ),
            });
        }
        depths.push(slices_of(src, b, &want).0.len());
        planes_at.push(at);
        match stats.as_mut() {
            None => stats = Some(rec.stats),
            Some(s) => s.merge(&rec.stats),
        }
    }
    let stats = stats.expect("n >= 1 scans");
    // The seams, from the shards within reach: a plane carried through
    // FAR slices or more is FAR everywhere, so only the shards whose
    // nearer end lies within 254 slices of this one count.
    let (k, n) = (k as usize, n as usize);
    let plane_of = |j: usize, which: u64| {
        read_plane(
            &shard_file(parts, j as u32, n as u32, "scan"),
            planes_at[j],
            plane,
            which,
        )
    };
    let mut lo = k;
    while lo > 0 && depths[lo..k].iter().sum::<usize>() < FAR as usize {
        lo -= 1;
    }
    let mut hi = k;
    while hi + 1 < n && depths[k + 1..=hi].iter().sum::<usize>() < FAR as usize {
        hi += 1;
    }
    // Up: F under this shard, then over it.
    let mut up = SeamChain::new(ncx, ncy);
    for (j, &depth) in depths.iter().enumerate().take(k).skip(lo) {
        up.cross(&plane_of(j, 0)?, depth);
    }
    let below = up.plane().map(<[u8]>::to_vec);
    up.cross(&plane_of(k, 0)?, depths[k]);
    // Down: the distance from this shard's top to the 1-cells above it.
    let mut down = SeamChain::new(ncx, ncy);
    for j in (k + 1..=hi).rev() {
        down.cross(&plane_of(j, 1)?, depths[j]);
    }
    // The final distances of the cell slice over the shard: its 1-cells
    // above, and those at or below through the slice under it.
    let above = down.plane().map(|g| {
        let f_top = up.plane().expect("crossed this shard");
        let from_below = dt::propagate(f_top, ncx, ncy, 1);
        g.iter()
            .zip(&from_below)
            .map(|(&a, &b)| a.min(b))
            .collect::<Vec<u8>>()
    });
    let k = k as u32;
    let header = header_for(src, opts, &stats)?;
    let file = std::fs::File::options()
        .read(true)
        .write(true)
        .open(&spill_path)
        .map_err(io_err(
            &spill_path,
            "cannot open the shard's spill: run `prep --shard K/N --pass 1` again",
        ))?;
    let spill_err = io_err(&spill_path, "shard spill");
    let mut spill = FileSpill::at(file, dt::spill_record(plane, false), cells.start);
    let fixed = match &below {
        Some(p) => {
            dt::fix_forward(&mut spill, p, cells.start, cells.end, ncx, ncy).map_err(&spill_err)?
        }
        None => 0,
    };
    st.backward += t.elapsed().as_secs_f64();
    let mut part = PartWriter::create(&part_path)?;
    let emitted = passes::emit(
        &header,
        src,
        opts,
        layers.clone(),
        above.as_deref(),
        &mut spill,
        None,
        &spill_err,
        &mut |id, o| part.put(id, &o),
        progress,
        &mut st,
    )?;
    let t = Instant::now();
    part.finish(&PartTrailer {
        plan,
        k,
        layers: [layers.start, layers.end],
        header,
        scan: stats,
        emit: emitted,
        bricks: 0,
        payload_bytes: 0,
    })?;
    drop(spill);
    // The part is written: the spill is not needed again.
    let _ = std::fs::remove_file(&spill_path);
    st.write += t.elapsed().as_secs_f64();
    Ok(ShardReport {
        path: part_path,
        cells,
        seconds: t0.elapsed().as_secs_f64(),
        stages: st,
        fixed_slices: fixed,
    })
}

/// What [`merge`] wrote.
#[derive(Debug, Clone)]
pub struct MergeReport {
    pub header: Header,
    pub parts: u32,
    pub file_bytes: u64,
    pub seconds: f64,
}

/// The part files (`shard-K-of-N.part`) in `dir`, sorted.
pub fn find_parts(dir: &Path) -> Result<Vec<PathBuf>, PrepError> {
    let rd = std::fs::read_dir(dir).map_err(io_err(dir, "cannot list the parts directory"))?;
    let mut out = Vec::new();
    for e in rd {
        let e = e.map_err(io_err(dir, "cannot list the parts directory"))?;
        let name = e.file_name();
        let name = name.to_string_lossy();
        if name.starts_with("shard-") && name.ends_with(".part") {
            out.push(e.path());
        }
    }
    out.sort();
    Ok(out)
}

/// Step 3, `prep-merge`: the parts of one sharded prep (every shard once)
/// into the packed file `out`, streamed top shard first, as one prep
/// writes it. Memory: one brick and the file's index.
pub fn merge(
    parts: &[PathBuf],
    out: &Path,
    progress: &dyn Progress,
) -> Result<MergeReport, PrepError> {
    let t0 = Instant::now();
    crate::fsutil::check_outputs(&[out.to_path_buf()], parts, None)?;
    let first = parts.first().ok_or_else(|| PrepError::Option {
        field: "parts",
        value: "none".into(),
        msg: "expected the part files of `prep --shard K/N --pass 2`".into(),
    })?;
    let (t0_trailer, _) = read_trailer(first)?;
    let n = t0_trailer.plan.n;
    let mut by_k: Vec<Option<(PathBuf, PartTrailer, u64)>> = (0..n).map(|_| None).collect();
    for p in parts {
        let (t, end) = read_trailer(p)?;
        if let Some(d) = t0_trailer.plan.differs(&t.plan) {
            return Err(PrepError::Shard {
                path: p.clone(),
                msg: format!(
                    "{d}; it belongs to another sharded prep than {}",
                    first.display()
                ),
            });
        }
        if t.header != t0_trailer.header || t.scan != t0_trailer.scan {
            return Err(PrepError::Shard {
                path: p.clone(),
                msg: format!(
                    "its header differs from that of {}: the parts come from different scans",
                    first.display()
                ),
            });
        }
        let k = t.k as usize;
        if k >= n as usize {
            return Err(PrepError::Shard {
                path: p.clone(),
                msg: format!("shard {k} of {n}"),
            });
        }
        if let Some((q, _, _)) = &by_k[k] {
            return Err(PrepError::Shard {
                path: p.clone(),
                msg: format!("shard {k} of {n} again (also {})", q.display()),
            });
        }
        by_k[k] = Some((p.clone(), t, end));
    }
    if let Some(k) = by_k.iter().position(Option::is_none) {
        return Err(PrepError::Shard {
            path: first.clone(),
            msg: format!(
                "shard {k} of {n} is missing: run `prep --shard {k}/{n} --pass 2` (expected {})",
                shard_file(
                    first.parent().unwrap_or(Path::new(".")),
                    k as u32,
                    n,
                    "part"
                )
                .display()
            ),
        });
    }
    let mut header = t0_trailer.header.clone();
    let mut writer = PackedWriter::create(out, header.brick_count(), header.format_version)?;
    let mut seen = vec![false; header.brick_count() as usize];
    let mut emit = EmitStats::default();
    progress.begin("merge parts", n as u64);
    for (path, t, end) in by_k.iter().rev().flatten() {
        copy_part(path, t, *end, &mut writer, &mut seen)?;
        emit.merge(&t.emit);
        progress.advance(1);
    }
    progress.end();
    if let Some(id) = seen.iter().position(|s| !s) {
        return Err(PrepError::Shard {
            path: first.clone(),
            msg: format!("no part holds brick {id}"),
        });
    }
    header.summary = summary_of(&header, &t0_trailer.scan, &emit, writer.payload_bytes());
    writer.finish(&header)?;
    let file_bytes = std::fs::metadata(out)
        .map_err(io_err(out, "cannot stat the written file"))?
        .len();
    Ok(MergeReport {
        header,
        parts: n,
        file_bytes,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
