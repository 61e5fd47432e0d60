//! gzip-compressed sample data (NRRD `encoding: gzip`, `.nii.gz`),
//! decompressed as a stream: one slice in memory at a time. A gzip stream
//! cannot seek, and prep reads the volume twice (the second time from the
//! top slab down), so every slice decompressed is also appended to an
//! unnamed temporary file (in `TMPDIR`; as large as the decompressed
//! samples, deleted when the source is dropped) and later reads of it are
//! positioned reads from there: each byte is decompressed once.

use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::os::unix::fs::FileExt;
use std::path::PathBuf;
use std::sync::Mutex;

use flate2::read::MultiGzDecoder;

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
}

type Stream = MultiGzDecoder<BufReader<File>>;

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
            .ok_or_else(|| InputError::field(&layout.header, "sizes", "slice size overflows"))?;
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
        let mut first = vec![0.0; nx * ny];
        src.read_slice(0, &mut first)?;
        Ok(src)
    }

    fn start(&self) -> Result<Stream, InputError> {
        let l = &self.layout;
        let mut f = crate::fsutil::open_regular(&l.file).map_err(|source| InputError::Io {
            path: l.file.clone(),
            what: "cannot open gzip data file",
            source,
        })?;
        std::io::Seek::seek(&mut f, std::io::SeekFrom::Start(l.file_offset)).map_err(|source| {
            InputError::Io {
                path: l.file.clone(),
                what: "cannot seek to the gzip data",
                source,
            }
        })?;
        let mut s = MultiGzDecoder::new(BufReader::with_capacity(1 << 20, f));
        let skipped = std::io::copy(&mut (&mut s).take(l.skip), &mut std::io::sink())
            .map_err(|e| self.gz_err(e))?;
        if skipped < l.skip {
            return Err(self.short(0));
        }
        Ok(s)
    }

    fn gz_err(&self, source: std::io::Error) -> InputError {
        InputError::Io {
            path: self.layout.file.clone(),
            what: "cannot decompress gzip data",
            source,
        }
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
                st.stream = None;
            }
        }
        decode_samples(&buf, self.layout.dtype, self.layout.endian, out);
        Ok(())
    }
}
