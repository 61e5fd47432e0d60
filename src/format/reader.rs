//! Reads packed files: checks the footer, header and index when opening,
//! and each brick's checksum and size when it is read. Header numbers are
//! untrusted: every size is checked against the file before use.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use super::brick::{dda_planes, decode_words, octant_codes, Values};
use super::{
    FormatError, Header, IndexEntry, END_MAGIC, FOOTER_LEN, FORMAT_VERSION, INDEX_ENTRY_LEN, MAGIC,
    MAX_HEADER_LEN, OLDEST_READ_VERSION, PREAMBLE_LEN,
};
pub use crate::classify::CellClass;

/// An open packed file. Brick payloads are read on demand with positioned
/// reads (`pread`), so only the bricks asked for are ever read, and
/// resident memory is what the caller keeps, not what it has touched (a
/// memory map would count every page read towards RSS).
///
/// A handle: cloning it is cheap and shares the open file, its header and
/// its index, so a brick cache or a [`Renderer`](crate::Renderer) owns
/// one instead of borrowing it.
#[derive(Clone)]
pub struct PackedVolume {
    inner: std::sync::Arc<Packed>,
}

/// What a [`PackedVolume`] shares between its clones.
struct Packed {
    path: PathBuf,
    file: File,
    len: u64,
    header: Header,
    index: Vec<IndexEntry>,
    /// CRC-32 of header and index, from the trailer (checked on open).
    crc: u32,
}

/// What a sample word of a brick holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sample {
    /// An exact raw sample value (before rescale).
    Value(f64),
    /// The distance code of the cell whose minimum corner this sample is.
    Code(u32),
}

/// A decoded brick.
#[derive(Debug, Clone)]
pub struct Brick {
    /// Brick coordinates.
    pub coords: [u64; 3],
    /// Global index of its first sample (= first cell).
    pub first: [u64; 3],
    /// Samples per axis (cells + 1).
    pub samples: [usize; 3],
    pub data: BrickData,
}

#[derive(Debug, Clone)]
pub enum BrickData {
    /// No payload: every cell is a 0-cell with this code.
    Uniform(u32),
    Words {
        samples: Vec<Sample>,
        /// Per anisotropic block (x fastest): the 8 octant codes.
        octants: Option<Vec<[u8; 8]>>,
        /// DDA planes: `[city block, chamfer 3-4-5]`, one byte per cell of
        /// the brick, x fastest (files prepared with `--dda`).
        dda: Option<[Vec<u8>; 2]>,
    },
}

impl Brick {
    /// The word at local sample `(x, y, z)`. Uniform bricks have codes at
    /// every cell corner and no values.
    pub fn sample(&self, l: [usize; 3]) -> Option<Sample> {
        match &self.data {
            BrickData::Uniform(_) => None,
            BrickData::Words { samples, .. } => {
                let [sx, sy, _] = self.samples;
                Some(samples[(l[2] * sy + l[1]) * sx + l[0]])
            }
        }
    }

    /// The 8 vertex words of local cell `l`, x fastest.
    pub fn vertices(&self, l: [usize; 3]) -> Option<[Sample; 8]> {
        let mut out = [Sample::Code(0); 8];
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.sample([l[0] + (i & 1), l[1] + (i >> 1 & 1), l[2] + (i >> 2)])?;
        }
        Some(out)
    }
}

impl PackedVolume {
    /// Opens and checks a packed file.
    pub fn open(path: &Path) -> Result<PackedVolume, FormatError> {
        let p = || path.to_path_buf();
        let f = crate::fsutil::open_regular(path).map_err(|source| FormatError::Io {
            path: p(),
            what: "cannot open packed file",
            source,
        })?;
        let len = f
            .metadata()
            .map_err(|source| FormatError::Io {
                path: p(),
                what: "cannot stat packed file",
                source,
            })?
            .len();
        let read = |off: u64, n: u64, what: &'static str| -> Result<Vec<u8>, FormatError> {
            let mut buf = vec![0u8; n as usize];
            f.read_exact_at(&mut buf, off)
                .map_err(|source| FormatError::Io {
                    path: p(),
                    what,
                    source,
                })?;
            Ok(buf)
        };
        let pre = read(0, len.min(PREAMBLE_LEN), "cannot read preamble")?;
        if len < 8 || &pre[..8] != MAGIC {
            return Err(FormatError::NotPacked {
                path: p(),
                found: pre[..pre.len().min(8)].to_vec(),
            });
        }
        if len < PREAMBLE_LEN + FOOTER_LEN {
            return Err(FormatError::Truncated {
                path: p(),
                msg: format!("{len} bytes, shorter than preamble and footer"),
            });
        }
        let version = u32::from_le_bytes(pre[8..12].try_into().expect("4 bytes"));
        if !(OLDEST_READ_VERSION..=FORMAT_VERSION).contains(&version) {
            return Err(FormatError::Version {
                path: p(),
                found: version,
            });
        }
        let foot = read(len - FOOTER_LEN, FOOTER_LEN, "cannot read footer")?;
        if &foot[32..40] != END_MAGIC {
            return Err(FormatError::Truncated {
                path: p(),
                msg: "no footer at the end of the file (was the write interrupted?)".into(),
            });
        }
        let foot_version = u32::from_le_bytes(foot[28..32].try_into().expect("4 bytes"));
        if foot_version != version {
            return Err(FormatError::Truncated {
                path: p(),
                msg: format!("footer says format version {foot_version}, preamble {version}"),
            });
        }
        let u64_at = |i: usize| u64::from_le_bytes(foot[i..i + 8].try_into().expect("8 bytes"));
        let (trailer, hlen, ilen) = (u64_at(0), u64_at(8), u64_at(16));
        let crc = u32::from_le_bytes(foot[24..28].try_into().expect("4 bytes"));
        let consistent = trailer >= PREAMBLE_LEN
            && hlen <= MAX_HEADER_LEN
            && trailer
                .checked_add(hlen)
                .and_then(|x| x.checked_add(ilen))
                .and_then(|x| x.checked_add(FOOTER_LEN))
                == Some(len);
        if !consistent {
            return Err(FormatError::Truncated {
                path: p(),
                msg: format!(
                    "footer says trailer at {trailer} with {hlen} + {ilen} bytes, \
                     but the file has {len} bytes"
                ),
            });
        }
        let json = read(trailer, hlen, "cannot read header")?;
        let idx = read(trailer + hlen, ilen, "cannot read brick index")?;
        let mut h = crc32fast::Hasher::new();
        h.update(&json);
        h.update(&idx);
        let found = h.finalize();
        if found != crc {
            return Err(FormatError::Header {
                path: p(),
                msg: format!("trailer checksum {found:08x}, expected {crc:08x}"),
            });
        }
        let header: Header = serde_json::from_slice(&json).map_err(|e| FormatError::Header {
            path: p(),
            msg: e.to_string(),
        })?;
        check_header(&header).map_err(|e| FormatError::Header {
            path: p(),
            msg: e.to_string(),
        })?;
        if header.format_version != version {
            return Err(FormatError::Header {
                path: p(),
                msg: format!(
                    "header says format version {}, preamble {version}",
                    header.format_version
                ),
            });
        }
        if ilen != header.brick_count() * INDEX_ENTRY_LEN as u64 {
            return Err(FormatError::Header {
                path: p(),
                msg: format!(
                    "brick index has {ilen} bytes, expected {} for {} bricks",
                    header.brick_count() * INDEX_ENTRY_LEN as u64,
                    header.brick_count()
                ),
            });
        }
        let index: Vec<IndexEntry> = idx
            .chunks_exact(INDEX_ENTRY_LEN)
            .map(IndexEntry::from_bytes)
            .collect();
        let max_code = header.codes.max_code();
        for (i, e) in index.iter().enumerate() {
            let mut known = super::FLAG_UNIFORM | super::FLAG_NO_OBJECT;
            if version >= 2 {
                known |= super::FLAG_VALUE_MAX;
            }
            let entry_err = if e.flags & !known != 0 {
                Some(format!(
                    "index flags {:#x}, expected bits of {known:#x} (format version {version})",
                    e.flags
                ))
            } else if e.value_max().is_none() && e.value_max != 0 {
                Some(format!(
                    "index value maximum {:#x} without its flag, expected 0",
                    e.value_max
                ))
            } else if e.value_max().is_some_and(f64::is_nan) {
                Some("index value maximum NaN, expected a number".into())
            } else if e.value_max().is_some() && (e.is_uniform() || e.has_no_object()) {
                Some(format!(
                    "index flags {:#x}: a value maximum on a brick without 1-cells",
                    e.flags
                ))
            } else if e.is_uniform() && (e.length != 0 || e.crc32 != 0 || !e.has_no_object()) {
                Some(format!(
                    "uniform brick with length {}, crc {:08x}, flags {:#x}: expected \
                     length 0, crc 0 and the no-object flag",
                    e.length, e.crc32, e.flags
                ))
            } else if !e.is_uniform() && e.length == 0 {
                Some("a stored brick of 0 bytes".into())
            } else if (e.is_uniform() || e.has_no_object()) && e.uniform_code > max_code {
                Some(format!(
                    "index code {}, expected at most codes.max {max_code}",
                    e.uniform_code
                ))
            } else {
                None
            };
            if let Some(msg) = entry_err {
                return Err(FormatError::Brick {
                    path: p(),
                    brick: i as u64,
                    coords: header.brick_coords(i as u64),
                    msg,
                });
            }
            let end = e.offset.checked_add(e.length as u64);
            if !e.is_uniform() && (e.offset < PREAMBLE_LEN || end.is_none_or(|end| end > trailer)) {
                return Err(FormatError::Brick {
                    path: p(),
                    brick: i as u64,
                    coords: header.brick_coords(i as u64),
                    msg: format!(
                        "payload at {}..{} lies outside the payload area {PREAMBLE_LEN}..{trailer}",
                        e.offset,
                        e.offset.saturating_add(e.length as u64)
                    ),
                });
            }
        }
        Ok(PackedVolume {
            inner: std::sync::Arc::new(Packed {
                path: p(),
                file: f,
                len,
                header,
                index,
                crc,
            }),
        })
    }

    /// CRC-32 of the header and index (the trailer's, checked on open):
    /// identifies the file's contents, e.g. across the parts of a sharded
    /// render.
    pub fn checksum(&self) -> u32 {
        self.inner.crc
    }

    pub fn path(&self) -> &Path {
        &self.inner.path
    }

    pub fn header(&self) -> &Header {
        &self.inner.header
    }

    pub fn index(&self) -> &[IndexEntry] {
        &self.inner.index
    }

    pub fn file_len(&self) -> u64 {
        self.inner.len
    }

    fn brick_err(&self, id: u64, msg: String) -> FormatError {
        FormatError::Brick {
            path: self.inner.path.clone(),
            brick: id,
            coords: self.inner.header.brick_coords(id),
            msg,
        }
    }

    /// Reads, checks and decompresses the payload bytes of brick `id`
    /// (`None` for a uniform brick).
    pub fn read_payload(&self, id: u64) -> Result<Option<Vec<u8>>, FormatError> {
        let mut dctx = zstd::bulk::Decompressor::new()
            .map_err(|x| self.brick_err(id, format!("cannot decompress: {x}")))?;
        let mut raw = Vec::new();
        Ok(self
            .read_payload_into(id, &mut dctx, &mut Vec::new(), &mut raw)?
            .then_some(raw))
    }

    /// [`read_payload`](Self::read_payload) into buffers the caller keeps
    /// (`comp`: the stored bytes, `raw`: the decompressed payload, both
    /// cleared and refilled) with the caller's decompression context, so
    /// a reader of many bricks allocates nothing per brick. `raw` gets the
    /// sample words interleaved whatever the file's layout
    /// ([`Header::byte_planes`]); `comp` is then scratch. Returns false
    /// for a uniform brick (no payload; both buffers left empty).
    pub fn read_payload_into(
        &self,
        id: u64,
        dctx: &mut zstd::bulk::Decompressor<'_>,
        comp: &mut Vec<u8>,
        raw: &mut Vec<u8>,
    ) -> Result<bool, FormatError> {
        let e = *self.inner.index.get(id as usize).ok_or_else(|| {
            self.brick_err(
                id,
                format!("no such brick (file has {})", self.inner.index.len()),
            )
        })?;
        comp.clear();
        raw.clear();
        if e.is_uniform() {
            return Ok(false);
        }
        comp.resize(e.length as usize, 0);
        self.inner
            .file
            .read_exact_at(comp, e.offset)
            .map_err(|source| FormatError::Io {
                path: self.inner.path.clone(),
                what: "cannot read brick payload",
                source,
            })?;
        let crc = crc32fast::hash(comp);
        if crc != e.crc32 {
            return Err(self.brick_err(
                id,
                format!(
                    "checksum {crc:08x}, expected {:08x}: the payload is corrupt",
                    e.crc32
                ),
            ));
        }
        let want = self
            .inner
            .header
            .payload_len(self.inner.header.brick_coords(id)) as usize;
        raw.reserve_exact(want);
        dctx.decompress_to_buffer(comp.as_slice(), raw)
            .map_err(|x| self.brick_err(id, format!("cannot decompress: {x}")))?;
        if raw.len() != want {
            return Err(self.brick_err(
                id,
                format!("payload is {} bytes, expected {want}", raw.len()),
            ));
        }
        if self.inner.header.byte_planes() {
            // The stored bytes are no longer needed: the words are joined
            // from `raw` into that buffer, the rest of the payload (octant
            // codes, DDA planes) follows them, and the two trade places.
            let n = self
                .inner
                .header
                .words_len(self.inner.header.brick_coords(id)) as usize;
            comp.clear();
            comp.reserve_exact(raw.len());
            super::planes::join_into(&raw[..n], self.inner.header.storage.size(), comp);
            comp.extend_from_slice(&raw[n..]);
            std::mem::swap(comp, raw);
        }
        Ok(true)
    }

    /// Reads and decodes brick `id`.
    pub fn read_brick(&self, id: u64) -> Result<Brick, FormatError> {
        let h = &self.inner.header;
        let coords = h.brick_coords(id);
        let first = std::array::from_fn(|k| coords[k] * h.brick_size as u64);
        let samples = h.brick_samples(coords).map(|s| s as usize);
        let data = match self.read_payload(id)? {
            None => BrickData::Uniform(self.inner.index[id as usize].uniform_code),
            Some(raw) => {
                let n = samples.iter().product::<usize>();
                let (mut values, mut codes) = (Vec::new(), Vec::new());
                decode_words(h, &raw, n, Values::Raw, &mut values, &mut codes);
                let samples_v = values
                    .iter()
                    .zip(&codes)
                    .map(|(&v, &c)| c.map_or(Sample::Value(v), Sample::Code))
                    .collect();
                BrickData::Words {
                    samples: samples_v,
                    octants: octant_codes(h, coords, &raw),
                    dda: dda_planes(h, coords, &raw),
                }
            }
        };
        Ok(Brick {
            coords,
            first,
            samples,
            data,
        })
    }

    /// Class of local cell `l` of a decoded brick: a code word at its
    /// minimum corner makes it a 0-cell with that code; otherwise the
    /// classification decides from its 8 exact vertex values (a 0-cell
    /// there has code 0).
    pub fn cell_class(&self, brick: &Brick, l: [usize; 3]) -> CellClass {
        match &brick.data {
            BrickData::Uniform(c) => CellClass::Empty(*c),
            BrickData::Words { .. } => {
                let v = brick.vertices(l).expect("words brick");
                let rs = self.inner.header.rescale;
                let codes = v.map(|s| match s {
                    Sample::Code(c) => Some(c),
                    Sample::Value(_) => None,
                });
                let values = v.map(|s| match s {
                    Sample::Value(x) => rs.apply(x),
                    Sample::Code(_) => f64::NAN,
                });
                self.inner
                    .header
                    .classification
                    .cell_of_words(codes, values)
            }
        }
    }
}

/// A header field that breaks an invariant the reader relies on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} {found}, expected {expected}")]
pub struct HeaderInvalid {
    pub field: String,
    pub found: String,
    pub expected: String,
}

fn check_header(h: &Header) -> Result<(), HeaderInvalid> {
    let bad = |field: String, found: String, expected: String| {
        Err(HeaderInvalid {
            field,
            found,
            expected,
        })
    };
    if !(OLDEST_READ_VERSION..=FORMAT_VERSION).contains(&h.format_version) {
        return bad(
            "format_version".into(),
            h.format_version.to_string(),
            format!("{OLDEST_READ_VERSION} to {FORMAT_VERSION}"),
        );
    }
    for k in 0..3 {
        if h.dims[k] < 2 {
            return bad(format!("dims[{k}]"), h.dims[k].to_string(), ">= 2".into());
        }
        if h.axes[k].samples() as u64 != h.dims[k] {
            return bad(
                format!("axes[{k}]"),
                format!("{} positions", h.axes[k].samples()),
                format!("{} (dims[{k}])", h.dims[k]),
            );
        }
    }
    if h.brick_size < 4 || !h.brick_size.is_multiple_of(4) || h.brick_size > 1024 {
        return bad(
            "brick_size".into(),
            h.brick_size.to_string(),
            "a multiple of 4 in 4..=1024".into(),
        );
    }
    let want = h.cells().map(|c| c.div_ceil(h.brick_size as u64));
    if h.bricks != want {
        return bad(
            "bricks".into(),
            format!("{:?}", h.bricks),
            format!("{want:?} for the dims and brick size"),
        );
    }
    if let Some(g) = h.aniso_block {
        if g as usize != crate::dt::ANISO_BLOCK {
            return bad(
                "aniso_block".into(),
                g.to_string(),
                crate::dt::ANISO_BLOCK.to_string(),
            );
        }
    }
    if h.max_payload_len() > super::MAX_PAYLOAD_LEN {
        return bad(
            "brick_size".into(),
            format!(
                "{} with {} words ({} bytes per brick)",
                h.brick_size,
                h.storage.name(),
                h.max_payload_len()
            ),
            format!("at most {} bytes per brick", super::MAX_PAYLOAD_LEN),
        );
    }
    if let crate::classify::Classification::TransferFunction { tf } = &h.classification {
        if let Err(e) = tf.check() {
            return bad(
                format!("classification.tf.{}", e.field),
                e.found,
                e.expected.into(),
            );
        }
    }
    if let crate::classify::Classification::Iso { iso } = h.classification {
        if !iso.is_finite() {
            return bad(
                "classification.iso".into(),
                iso.to_string(),
                "a finite number".into(),
            );
        }
    }
    if let Some(hist) = &h.summary.histogram {
        if let Err(e) = hist.check() {
            return bad(
                format!("summary.histogram.{}", e.field),
                e.found,
                e.expected.into(),
            );
        }
    }
    if let Some(Err(e)) = h.orientation.as_ref().map(|o| o.check()) {
        return bad(
            "orientation.axes_lps".into(),
            e.to_string(),
            "unit orthogonal directions".into(),
        );
    }
    let r = h.rescale;
    if !(r.slope.is_finite() && r.slope != 0.0) {
        return bad(
            "rescale.slope".into(),
            r.slope.to_string(),
            "a finite, non-zero number".into(),
        );
    }
    if !r.intercept.is_finite() {
        return bad(
            "rescale.intercept".into(),
            r.intercept.to_string(),
            "a finite number".into(),
        );
    }
    if !(-7..=22).contains(&h.zstd_level) {
        return bad(
            "zstd_level".into(),
            h.zstd_level.to_string(),
            "-7..=22".into(),
        );
    }
    // The stored words are the input's type, or (integers) a wider one.
    let storage_fits = if h.dtype.is_float() {
        h.storage == h.dtype
    } else {
        !h.storage.is_float() && h.storage.size() >= h.dtype.size() && {
            let ((smin, smax), (dmin, dmax)) = (h.storage.int_range(), h.dtype.int_range());
            smin <= dmin && dmax <= smax
        }
    };
    if !storage_fits {
        return bad(
            "storage".into(),
            h.storage.name().into(),
            format!("the input type {} or a wider integer type", h.dtype.name()),
        );
    }
    let max_code = h.codes.max_code();
    if max_code > super::word::MAX_CODE {
        return bad(
            "codes.max".into(),
            max_code.to_string(),
            format!("at most {}", super::word::MAX_CODE),
        );
    }
    if let super::CodeEncoding::IntRange { base, max } = h.codes {
        let (tmin, tmax) = h.storage.int_range();
        if base < tmin || base.checked_add(max as i64).is_none_or(|top| top > tmax) {
            return bad(
                "codes.base".into(),
                format!(
                    "{base} (codes {base}..={})",
                    base.saturating_add(max as i64)
                ),
                format!("a code range inside {} ({tmin}..={tmax})", h.storage.name()),
            );
        }
    }
    if h.summary.code_histogram.len() > max_code as usize + 1 {
        return bad(
            "summary.code_histogram".into(),
            format!("{} entries", h.summary.code_histogram.len()),
            format!("at most {} (codes.max + 1)", max_code as u64 + 1),
        );
    }
    let storage_ok = match h.codes {
        super::CodeEncoding::IntRange { .. } => !h.storage.is_float(),
        super::CodeEncoding::NanPayload { .. } => h.storage.is_float(),
    };
    if !storage_ok {
        return bad(
            "codes".into(),
            h.codes.to_string(),
            format!("an encoding that fits storage {}", h.storage.name()),
        );
    }
    Ok(())
}
