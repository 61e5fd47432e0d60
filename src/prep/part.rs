//! A sharded prep's part files ([`super::shard`]): one shard's bricks in
//! the order of the packed file, and a trailer with the header and the
//! counts, written through a temporary file and renamed when complete;
//! read back one brick at a time by the merge; and the plan every file of
//! one sharded prep records.

use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::passes::{EmitStats, ScanStats};
use super::slab::BrickOut;
use super::{PrepError, PrepOptions};
use crate::format::writer::PackedWriter;
use crate::format::Header;
use crate::input::SliceSource;

const PART_MAGIC: &[u8; 8] = b"CDVPART1";
const PART_END: &[u8; 8] = b"CDVPEND1";
/// Bytes of a part record before its payload ([`PartWriter`]).
const RECORD_LEN: usize = 27;

/// What every file of one sharded prep agrees on: the input, its shape,
/// the options that change a byte of the output, and N.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(super) struct Plan {
    source: String,
    dims: [usize; 3],
    dtype: String,
    pub(super) n: u32,
    brick_size: usize,
    zstd_level: i32,
    format_version: u32,
    gradient_halo: bool,
    allow_empty: bool,
    labels: bool,
    /// The resolved classification, preset, look and landmarks, as JSON.
    decided: String,
}

impl Plan {
    pub(super) fn of(src: &dyn SliceSource, opts: &PrepOptions, n: u32) -> Plan {
        let meta = src.meta();
        Plan {
            source: meta.origin_desc.clone(),
            dims: meta.dims(),
            dtype: meta.dtype.name().to_string(),
            n,
            brick_size: opts.brick_size,
            zstd_level: opts.zstd_level,
            format_version: opts.format_version,
            gradient_halo: opts.gradient_halo,
            allow_empty: opts.allow_empty,
            labels: opts.labels,
            decided: serde_json::to_string(&(
                &opts.classification,
                opts.decided
                    .as_ref()
                    .map(|d| (&d.modality, &d.landmarks, &d.look)),
                &opts.label_table,
                &opts.stamp,
            ))
            .unwrap_or_default(),
        }
    }

    /// The first field where `other` differs, for the error.
    pub(super) fn differs(&self, other: &Plan) -> Option<String> {
        let a = serde_json::to_value(self).ok()?;
        let b = serde_json::to_value(other).ok()?;
        let (a, b) = (a.as_object()?, b.as_object()?);
        a.iter().find(|(k, v)| b.get(*k) != Some(*v)).map(|(k, v)| {
            format!(
                "{k} is {}, expected {v} (as this shard's input and options give it)",
                b.get(k).map(|v| v.to_string()).unwrap_or_default()
            )
        })
    }
}

/// An I/O error on `path`, for `map_err`.
pub(super) fn io_err(
    path: &Path,
    what: &'static str,
) -> impl Fn(std::io::Error) -> PrepError + use<> {
    let path = path.to_path_buf();
    move |source| PrepError::Io {
        path: path.clone(),
        what,
        source,
    }
}

/// The JSON at the end of a part file.
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct PartTrailer {
    pub(super) plan: Plan,
    pub(super) k: u32,
    pub(super) layers: [usize; 2],
    /// The file's header, summary left out (every shard computes it alike).
    pub(super) header: Header,
    /// Pass 1's counts of the whole volume (merged from the scans).
    pub(super) scan: ScanStats,
    /// Pass 2's counts of this shard.
    pub(super) emit: EmitStats,
    /// Records and bytes of compressed payload in the part.
    pub(super) bricks: u64,
    pub(super) payload_bytes: u64,
}

/// A part file: `CDVPART1`, one record per brick in file order, the
/// trailer's JSON, its length (u64) and `CDVPEND1`. A record is the
/// brick id (u64), its kind (u8: 0 uniform, 1 payload), a code (u32: the
/// uniform code, or the smallest code of a brick without 1-cells), the
/// no-object flag (u8), the largest value (u8 flag, f64 bits) and the
/// compressed payload (u32 length, bytes). Integers little-endian.
pub(super) struct PartWriter {
    target: PathBuf,
    tmp: BufWriter<tempfile::NamedTempFile>,
    bricks: u64,
    payload_bytes: u64,
}

impl PartWriter {
    pub(super) fn create(target: &Path) -> Result<PartWriter, PrepError> {
        let tmp = crate::fsutil::temp_beside(target).map_err(io_err(
            target,
            "cannot create a temporary file beside the part",
        ))?;
        let mut tmp = BufWriter::with_capacity(1 << 20, tmp);
        tmp.write_all(PART_MAGIC)
            .map_err(io_err(target, "cannot write the part"))?;
        Ok(PartWriter {
            target: target.to_path_buf(),
            tmp,
            bricks: 0,
            payload_bytes: 0,
        })
    }

    pub(super) fn put(&mut self, id: u64, o: &BrickOut) -> Result<(), PrepError> {
        let mut rec = Vec::with_capacity(32);
        rec.extend_from_slice(&id.to_le_bytes());
        let payload: &[u8] = match o {
            BrickOut::Uniform(code) => {
                rec.push(0);
                rec.extend_from_slice(&code.to_le_bytes());
                rec.extend_from_slice(&[0, 0]);
                rec.extend_from_slice(&0u64.to_le_bytes());
                &[]
            }
            BrickOut::Payload {
                compressed,
                no_object,
                min_code,
                value_max,
                ..
            } => {
                rec.push(1);
                rec.extend_from_slice(&min_code.to_le_bytes());
                rec.push(*no_object as u8);
                rec.push(value_max.is_some() as u8);
                rec.extend_from_slice(&value_max.unwrap_or(0.0).to_bits().to_le_bytes());
                compressed
            }
        };
        let len = u32::try_from(payload.len()).map_err(|_| PrepError::Shard {
            path: self.target.clone(),
            msg: format!(
                "brick {id}: a payload of {} bytes exceeds 4 GiB",
                payload.len()
            ),
        })?;
        rec.extend_from_slice(&len.to_le_bytes());
        debug_assert_eq!(rec.len(), RECORD_LEN);
        let io = io_err(&self.target, "cannot write the part");
        self.tmp.write_all(&rec).map_err(&io)?;
        self.tmp.write_all(payload).map_err(&io)?;
        self.bricks += 1;
        self.payload_bytes += payload.len() as u64;
        Ok(())
    }

    pub(super) fn finish(mut self, trailer: &PartTrailer) -> Result<(), PrepError> {
        let trailer = PartTrailer {
            bricks: self.bricks,
            payload_bytes: self.payload_bytes,
            plan: trailer.plan.clone(),
            k: trailer.k,
            layers: trailer.layers,
            header: trailer.header.clone(),
            scan: trailer.scan.clone(),
            emit: trailer.emit.clone(),
        };
        let json = serde_json::to_vec(&trailer).map_err(|e| PrepError::Shard {
            path: self.target.clone(),
            msg: e.to_string(),
        })?;
        let io = io_err(&self.target, "cannot write the part");
        self.tmp.write_all(&json).map_err(&io)?;
        self.tmp
            .write_all(&(json.len() as u64).to_le_bytes())
            .map_err(&io)?;
        self.tmp.write_all(PART_END).map_err(&io)?;
        let tmp = self
            .tmp
            .into_inner()
            .map_err(|e| io_err(&self.target, "cannot flush the part")(e.into_error()))?;
        tmp.as_file()
            .sync_all()
            .map_err(io_err(&self.target, "cannot sync the part"))?;
        crate::fsutil::commit(tmp, &self.target).map_err(|e| PrepError::Shard {
            path: self.target.clone(),
            msg: e.to_string(),
        })
    }
}

/// Reads a part's trailer; returns it and where the records end.
pub(super) fn read_trailer(path: &Path) -> Result<(PartTrailer, u64), PrepError> {
    let bad = |msg: String| PrepError::Shard {
        path: path.to_path_buf(),
        msg,
    };
    let mut f = crate::fsutil::open_regular(path).map_err(|e| bad(format!("cannot open: {e}")))?;
    let len = f
        .seek(SeekFrom::End(0))
        .map_err(|e| bad(format!("cannot seek: {e}")))?;
    if len < 32 {
        return Err(bad(format!("{len} bytes: not a cdvol part (too short)")));
    }
    let mut head = [0u8; 8];
    f.seek(SeekFrom::Start(0))
        .and_then(|_| f.read_exact(&mut head))
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    let mut tail = [0u8; 16];
    f.seek(SeekFrom::Start(len - 16))
        .and_then(|_| f.read_exact(&mut tail))
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    if &head != PART_MAGIC || &tail[8..] != PART_END {
        return Err(bad(
            "not a complete cdvol part (magic CDVPART1 ... CDVPEND1)".into(),
        ));
    }
    let json_len = u64::from_le_bytes(tail[..8].try_into().expect("8 bytes"));
    let records_end = (len - 16)
        .checked_sub(json_len)
        .filter(|&e| e >= 8)
        .ok_or_else(|| bad(format!("a trailer of {json_len} bytes in a file of {len}")))?;
    let mut json = vec![0u8; json_len as usize];
    f.seek(SeekFrom::Start(records_end))
        .and_then(|_| f.read_exact(&mut json))
        .map_err(|e| bad(format!("cannot read the trailer: {e}")))?;
    let t: PartTrailer = serde_json::from_slice(&json).map_err(|e| bad(format!("trailer: {e}")))?;
    Ok((t, records_end))
}

/// Streams the records of one part into `writer`.
pub(super) fn copy_part(
    path: &Path,
    t: &PartTrailer,
    end: u64,
    writer: &mut PackedWriter,
    seen: &mut [bool],
) -> Result<(), PrepError> {
    let bad = |msg: String| PrepError::Shard {
        path: path.to_path_buf(),
        msg,
    };
    let f = crate::fsutil::open_regular(path).map_err(|e| bad(format!("cannot open: {e}")))?;
    let mut r = BufReader::with_capacity(1 << 20, f);
    r.seek(SeekFrom::Start(8))
        .map_err(|e| bad(format!("cannot seek: {e}")))?;
    let mut pos = 8u64;
    let mut payload = Vec::new();
    for i in 0..t.bricks {
        let mut rec = [0u8; RECORD_LEN];
        r.read_exact(&mut rec)
            .map_err(|e| bad(format!("record {i}: {e}")))?;
        let id = u64::from_le_bytes(rec[0..8].try_into().expect("8"));
        let kind = rec[8];
        let code = u32::from_le_bytes(rec[9..13].try_into().expect("4"));
        let no_object = rec[13] != 0;
        let has_max = rec[14] != 0;
        let vmax = f64::from_bits(u64::from_le_bytes(rec[15..23].try_into().expect("8")));
        let len = u32::from_le_bytes(rec[23..27].try_into().expect("4")) as usize;
        let slot = seen
            .get_mut(id as usize)
            .ok_or_else(|| bad(format!("record {i}: brick {id} is not in the volume")))?;
        if std::mem::replace(slot, true) {
            return Err(bad(format!("record {i}: brick {id} again")));
        }
        pos += (RECORD_LEN + len) as u64;
        if pos > end {
            return Err(bad(format!("record {i} runs past the records' end")));
        }
        match kind {
            0 => writer.put_uniform(id, code),
            1 => {
                payload.resize(len, 0);
                r.read_exact(&mut payload)
                    .map_err(|e| bad(format!("record {i}: {e}")))?;
                writer.put_brick(
                    id,
                    &payload,
                    no_object.then_some(code),
                    has_max.then_some(vmax),
                )?;
            }
            other => return Err(bad(format!("record {i}: kind {other}, expected 0 or 1"))),
        }
    }
    if pos != end {
        return Err(bad(format!(
            "{} bytes of records, the trailer says {} records end at {end}",
            pos, t.bricks
        )));
    }
    Ok(())
}
