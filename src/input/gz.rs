//! gzip-compressed sample data (NRRD `encoding: gzip`, `.nii.gz`),
//! decompressed as a stream: one slice in memory at a time. A gzip stream
//! cannot seek, and prep reads the volume twice (the second time from the
//! top slab down), so every slice decompressed is also appended to an
//! unnamed temporary file (in `TMPDIR`; as large as the decompressed
//! samples, deleted when the source is dropped) and later reads of it are
//! positioned reads from there: each byte is decompressed once.
//!
//! Every gzip member is checked against its trailer (CRC-32 and ISIZE):
//! after the last slice the stream is read to its end, so a corrupt file
//! is refused, never prepared with altered samples. Bytes after the last
//! member must be another member or zero padding (as gzip(1) accepts).
//! The decompressed size a header claims is bounded by what the
//! compressed bytes can hold (deflate expands at most 1032 times) before
//! anything is allocated for it.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::FileExt;
use std::path::PathBuf;
use std::sync::Mutex;

use flate2::bufread::GzDecoder;

use super::raw::decode_samples;
use super::{Dtype, Endian, InputError, SliceSource, VolumeMeta};

/// Where the samples are in a gzip stream.
#[derive(Debug, Clone)]
pub struct GzLayout {
    /// The compressed file.
    pub file: PathBuf,
    /// The header that names it (for messages).
    pub header: PathBuf,
    /// File bytes before the gzip stream (an attached NRRD header).
    pub file_offset: u64,
    /// Decompressed bytes before the first sample.
    pub skip: u64,
    pub dtype: Dtype,
    pub endian: Endian,
    /// The header field that gives the dims (`sizes`, `dim`), for messages.
    pub dims_field: &'static str,
    /// The header field that gives `skip` (`byte skip`, `vox_offset`).
    pub skip_field: &'static str,
}

impl GzLayout {
    /// The error of opening the compressed file: it names the header too
    /// when the data are detached (an NRRD `data file`).
    fn open_err(&self, what: &'static str, source: std::io::Error) -> InputError {
        if self.file == self.header {
            InputError::Io {
                path: self.file.clone(),
                what,
                source,
            }
        } else {
            InputError::DataFile {
                path: self.file.clone(),
                sidecar: self.header.clone(),
                field: "data file".into(),
                what,
                source,
            }
        }
    }
}

/// Most bytes one compressed byte of deflate data inflates to (a run of
/// 258 bytes costs at least two bits, plus block overhead): the bound on
/// the decompressed size of a gzip file.
pub const MAX_INFLATE_RATIO: u64 = 1032;

/// Decompressed bytes [`GzSource::open`] reads to check that the stream
/// starts well (the whole first slice when smaller).
const PROBE_BYTES: usize = 16 << 20;

/// Why a gzip stream is refused, beyond what flate2 reports.
#[derive(Debug, thiserror::Error)]
enum GzIssue {
    #[error("gzip CRC-32 mismatch: the file is corrupt (the checksum or the length in a gzip trailer does not match the decompressed data)")]
    Checksum,
    #[error("bytes after the end of the gzip data that are neither another gzip member nor zero padding: the file is corrupt")]
    Trailing,
    #[error("the gzip stream is truncated (it ends before its trailer): the file is corrupt")]
    Truncated,
}

/// The gzip members of a file, one after another (like flate2's
/// `MultiGzDecoder`), each checked against its trailer, with zero padding
/// after the last one allowed.
struct Stream {
    /// `None` once the stream has ended.
    member: Option<GzDecoder<BufReader<File>>>,
}

impl Stream {
    fn new(r: BufReader<File>) -> Stream {
        Stream {
            member: Some(GzDecoder::new(r)),
        }
    }
}

/// flate2's error, or one of [`GzIssue`] where flate2's words would
/// mislead (its checksum error names no trailer; a truncated stream is
/// "unexpected end of file").
fn classify(e: std::io::Error) -> std::io::Error {
    use std::io::ErrorKind;
    if e.kind() == ErrorKind::UnexpectedEof {
        return std::io::Error::new(ErrorKind::InvalidData, GzIssue::Truncated);
    }
    if e.to_string().contains("checksum") {
        return std::io::Error::new(ErrorKind::InvalidData, GzIssue::Checksum);
    }
    e
}

impl Read for Stream {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        loop {
            let Some(m) = self.member.as_mut() else {
                return Ok(0);
            };
            if buf.is_empty() {
                return Ok(0);
            }
            let n = m.read(buf).map_err(classify)?;
            if n > 0 {
                return Ok(n);
            }
            // The member ended and its trailer matched. What follows?
            let r = m.get_mut();
            let rest = r.fill_buf()?;
            if rest.is_empty() {
                self.member = None;
                return Ok(0);
            }
            if rest[0] == 0 {
                // Zero padding, to the end of the file.
                loop {
                    let rest = r.fill_buf()?;
                    if rest.is_empty() {
                        break;
                    }
                    if rest.iter().any(|&b| b != 0) {
                        return Err(std::io::Error::new(
                            std::io::ErrorKind::InvalidData,
                            GzIssue::Trailing,
                        ));
                    }
                    let k = rest.len();
                    r.consume(k);
                }
                self.member = None;
                return Ok(0);
            }
            if rest[0] != 0x1f {
                // Not the first byte of a gzip member (0x1f 0x8b).
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    GzIssue::Trailing,
                ));
            }
            let Some(m) = self.member.take() else {
                return Ok(0);
            };
            self.member = Some(GzDecoder::new(m.into_inner()));
        }
    }
}

/// A volume whose samples are a gzip stream.
pub struct GzSource {
    meta: VolumeMeta,
    layout: GzLayout,
    slice_bytes: usize,
    state: Mutex<State>,
}

struct State {
    /// Slices decompressed so far (all of them are in `spill`).
    done: usize,
    stream: Option<Stream>,
    spill: Option<File>,
}

impl GzSource {
    /// Opens the stream and checks that the first slice decompresses.
    pub fn open(meta: VolumeMeta, layout: GzLayout) -> Result<GzSource, InputError> {
        let [nx, ny, _] = meta.grid.dims();
        let slice_bytes = nx
            .checked_mul(ny)
            .and_then(|n| n.checked_mul(layout.dtype.size()))
            .ok_or_else(|| {
                InputError::field(&layout.header, layout.dims_field, "slice size overflows")
            })?;
        check_inflated_size(&meta, &layout, slice_bytes)?;
        let src = GzSource {
            meta,
            layout,
            slice_bytes,
            state: Mutex::new(State {
                done: 0,
                stream: None,
                spill: None,
            }),
        };
        // The start of the first slice decompresses (without allocating a
        // whole slice, which prep's memory check has not seen yet).
        let mut s = src.start()?;
        let mut probe = vec![0u8; slice_bytes.min(PROBE_BYTES)];
        let mut got = 0;
        while got < probe.len() {
            match s.read(&mut probe[got..]) {
                Ok(0) => return Err(src.short(0)),
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(src.gz_err(e)),
            }
        }
        Ok(src)
    }

    fn start(&self) -> Result<Stream, InputError> {
        let l = &self.layout;
        let mut f = crate::fsutil::open_regular(&l.file)
            .map_err(|source| l.open_err("cannot open gzip data file", source))?;
        std::io::Seek::seek(&mut f, std::io::SeekFrom::Start(l.file_offset))
            .map_err(|source| l.open_err("cannot seek to the gzip data", source))?;
        let mut s = Stream::new(BufReader::with_capacity(1 << 20, f));
        let skipped = std::io::copy(&mut (&mut s).take(l.skip), &mut std::io::sink())
            .map_err(|e| self.gz_err(e))?;
        if skipped < l.skip {
            return Err(InputError::Field {
                path: l.header.clone(),
                field: l.skip_field.into(),
                msg: format!(
                    "{} bytes to skip, past the end of the decompressed data of {} \
                     ({skipped} bytes)",
                    l.skip,
                    l.file.display()
                ),
            });
        }
        Ok(s)
    }

    fn gz_err(&self, source: std::io::Error) -> InputError {
        let is_issue = source
            .get_ref()
            .is_some_and(|e| e.downcast_ref::<GzIssue>().is_some());
        let l = &self.layout;
        if is_issue {
            let of = if l.file == l.header {
                String::new()
            } else {
                format!(" (the data file of {})", l.header.display())
            };
            return InputError::Field {
                path: l.file.clone(),
                field: "data".into(),
                msg: format!("{source}{of}"),
            };
        }
        l.open_err("cannot decompress gzip data", source)
    }

    fn short(&self, z: usize) -> InputError {
        let [nx, ny, nz] = self.meta.grid.dims();
        InputError::Field {
            path: self.layout.file.clone(),
            field: "data".into(),
            msg: format!(
                "the gzip stream ends in slice {z}: expected {} bytes after {} \
                 ({nx} x {ny} x {nz} samples of {}, from {})",
                self.slice_bytes as u64 * nz as u64,
                self.layout.skip,
                self.layout.dtype.name(),
                self.layout.header.display()
            ),
        }
    }
}

impl SliceSource for GzSource {
    fn meta(&self) -> &VolumeMeta {
        &self.meta
    }

    fn files(&self) -> Vec<PathBuf> {
        let mut v = vec![self.layout.header.clone()];
        if self.layout.file != self.layout.header {
            v.push(self.layout.file.clone());
        }
        v
    }

    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError> {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let st = &mut *st;
        let mut buf = vec![0u8; self.slice_bytes];
        let spill_err = |source| InputError::Io {
            path: std::env::temp_dir(),
            what: "cannot use the temporary copy of decompressed slices",
            source,
        };
        if z < st.done {
            let spill = st.spill.as_ref().expect("slices were spilled");
            spill
                .read_exact_at(&mut buf, z as u64 * self.slice_bytes as u64)
                .map_err(spill_err)?;
        } else {
            if st.stream.is_none() {
                st.stream = Some(self.start()?);
                st.spill = Some(tempfile::tempfile().map_err(spill_err)?);
            }
            let (s, spill) = (
                st.stream.as_mut().expect("started"),
                st.spill.as_mut().expect("started"),
            );
            while st.done <= z {
                let mut got = 0;
                while got < buf.len() {
                    match s.read(&mut buf[got..]) {
                        Ok(0) => return Err(self.short(st.done)),
                        Ok(n) => got += n,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(e) => return Err(self.gz_err(e)),
                    }
                }
                spill.write_all(&buf).map_err(spill_err)?;
                st.done += 1;
            }
            if st.done == self.meta.grid.dims()[2] {
                // Read to the end, so that every member's trailer is
                // checked (and nothing but padding follows).
                if let Some(mut s) = st.stream.take() {
                    std::io::copy(&mut s, &mut std::io::sink()).map_err(|e| self.gz_err(e))?;
                }
            }
        }
        decode_samples(&buf, self.layout.dtype, self.layout.endian, out);
        Ok(())
    }
}

/// Refuses a volume whose samples (after `skip`) need more decompressed
/// bytes than the compressed file can hold, before anything is allocated
/// for them.
fn check_inflated_size(
    meta: &VolumeMeta,
    layout: &GzLayout,
    slice_bytes: usize,
) -> Result<(), InputError> {
    let [nx, ny, nz] = meta.grid.dims();
    let len = std::fs::metadata(&layout.file)
        .map_err(|source| layout.open_err("cannot open gzip data file", source))?
        .len();
    let compressed = len.saturating_sub(layout.file_offset);
    let most = compressed.saturating_mul(MAX_INFLATE_RATIO);
    if layout.skip > most {
        return Err(InputError::field(
            &layout.header,
            layout.skip_field,
            format!(
                "{} bytes to skip, more than the {compressed} compressed bytes of {} can \
                 hold (at most {most}: deflate expands at most {MAX_INFLATE_RATIO} times)",
                layout.skip,
                layout.file.display()
            ),
        ));
    }
    let need = (slice_bytes as u64)
        .checked_mul(nz as u64)
        .and_then(|b| b.checked_add(layout.skip));
    match need {
        Some(need) if need <= most => Ok(()),
        _ => Err(InputError::field(
            &layout.header,
            layout.dims_field,
            format!(
                "{nx} x {ny} x {nz} samples of {} after {} bytes need {} bytes, \
                 more than the {compressed} compressed bytes of {} can hold \
                 (at most {most}: deflate expands at most {MAX_INFLATE_RATIO} times)",
                layout.dtype.name(),
                layout.skip,
                need.map_or_else(|| "more than 2^64".to_string(), |n| n.to_string()),
                layout.file.display()
            ),
        )),
    }
}
