//! Raw stacks: one file, or one file per z slice, memory-mapped and read
//! slice by slice. The only `unsafe` of the input side lives here.

use std::path::{Path, PathBuf};

use memmap2::Mmap;
use rayon::prelude::*;

use super::sidecar::{parse_sidecar, DataFiles, Sidecar};
use super::{Dtype, Endian, InputError, SliceSource, VolumeMeta};

/// A raw stack described by a sidecar, memory-mapped.
pub struct RawSource {
    meta: VolumeMeta,
    sidecar: Sidecar,
    maps: Vec<Mmap>,
    slice_bytes: u64,
    /// Warnings for the user ([`SliceSource::report`]): data files longer
    /// than the samples they hold.
    notes: Vec<String>,
}

impl RawSource {
    /// Opens the sidecar at `path`, then checks and maps every data file.
    pub fn open(path: &Path) -> Result<RawSource, InputError> {
        RawSource::from_sidecar(parse_sidecar(path)?)
    }

    /// Checks and maps the data files of a parsed sidecar (or of another
    /// header format's equivalent, e.g. a raw-encoded NRRD or NIfTI file,
    /// whose `path` names the header in error messages).
    pub fn from_sidecar(sidecar: Sidecar) -> Result<RawSource, InputError> {
        let path = &sidecar.path.clone();
        let [nx, ny, nz] = sidecar.dims;
        let slice_bytes = (nx as u64)
            .checked_mul(ny as u64)
            .and_then(|n| n.checked_mul(sidecar.dtype.size() as u64))
            .ok_or_else(|| InputError::field(path, "dims", "slice size overflows 64 bits"))?;
        let per_slice_need = sidecar
            .header_bytes
            .checked_add(slice_bytes)
            .ok_or_else(|| {
                InputError::field(
                    path,
                    "header_bytes",
                    "header_bytes + slice size overflows 64 bits",
                )
            })?;
        let files: Vec<(String, PathBuf, u64, String)> = match &sidecar.data {
            DataFiles::One(f) => vec![(
                "data".to_string(),
                f.clone(),
                (slice_bytes.checked_mul(nz as u64))
                    .and_then(|b| b.checked_add(sidecar.header_bytes))
                    .ok_or_else(|| {
                        InputError::field(path, "dims", "volume size overflows 64 bits")
                    })?,
                format!(
                    "header_bytes {} + {nx} x {ny} x {nz} samples of {}",
                    sidecar.header_bytes,
                    sidecar.dtype.name()
                ),
            )],
            DataFiles::PerSlice(list) => list
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    (
                        format!("data[{i}]"),
                        f.clone(),
                        per_slice_need,
                        format!(
                            "header_bytes {} + one {nx} x {ny} slice of {}",
                            sidecar.header_bytes,
                            sidecar.dtype.name()
                        ),
                    )
                })
                .collect(),
        };
        let mut maps = Vec::with_capacity(files.len());
        // Data files longer than needed: (file, actual, expected, why) of
        // the first, and how many.
        let mut longer: Option<(PathBuf, u64, u64, String)> = None;
        let mut n_longer = 0usize;
        for (field, file, need, why) in files {
            let data_err = |what| {
                let (path, field, sidecar) = (file.clone(), field.clone(), path.to_path_buf());
                move |source| InputError::DataFile {
                    path,
                    sidecar,
                    field,
                    what,
                    source,
                }
            };
            let f =
                crate::fsutil::open_regular(&file).map_err(data_err("cannot open data file"))?;
            let len = f
                .metadata()
                .map_err(data_err("cannot stat data file"))?
                .len();
            if len < need {
                return Err(InputError::TooShort {
                    path: file,
                    sidecar: path.to_path_buf(),
                    actual: len,
                    expected: need,
                    why,
                });
            }
            if len > need {
                n_longer += 1;
                if longer.is_none() {
                    longer = Some((file.clone(), len, need, why));
                }
            }
            // SAFETY: the map is read-only and we only read it. The caller
            // must not truncate or rewrite the input while cdvol runs; if
            // it does, reads may fault (SIGBUS), as with any mmap reader.
            let map = unsafe { Mmap::map(&f) }.map_err(data_err("cannot memory-map data file"))?;
            #[cfg(unix)]
            let _ = map.advise(memmap2::Advice::Sequential);
            maps.push(map);
        }
        // Kept (a file may carry a trailer), but said: a wrong dims or
        // dtype can also leave bytes over.
        let notes = longer
            .map(|(file, actual, expected, why)| {
                format!(
                    "warning: {}: {actual} bytes, expected {expected} ({why}; from {}); \
                     the last {} bytes are not read{}",
                    file.display(),
                    path.display(),
                    actual - expected,
                    if n_longer > 1 {
                        format!(" ({} more data files are longer than needed)", n_longer - 1)
                    } else {
                        String::new()
                    }
                )
            })
            .into_iter()
            .collect();
        let meta = VolumeMeta {
            grid: sidecar.grid.clone(),
            dtype: sidecar.dtype,
            rescale: sidecar.rescale,
            origin_desc: path.display().to_string(),
            orientation: sidecar.orientation.clone(),
        };
        Ok(RawSource {
            meta,
            sidecar,
            maps,
            slice_bytes,
            notes,
        })
    }

    /// The checked sidecar.
    pub fn sidecar(&self) -> &Sidecar {
        &self.sidecar
    }

    /// The map and byte range holding slice `z`.
    fn slice_range(&self, z: usize) -> (&Mmap, std::ops::Range<usize>) {
        let h = self.sidecar.header_bytes as usize;
        let sb = self.slice_bytes as usize;
        if self.maps.len() == 1 {
            let start = h + z * sb;
            (&self.maps[0], start..start + sb)
        } else {
            (&self.maps[z], h..h + sb)
        }
    }
}

impl SliceSource for RawSource {
    fn meta(&self) -> &VolumeMeta {
        &self.meta
    }

    fn files(&self) -> Vec<PathBuf> {
        let mut v = vec![self.sidecar.path.clone()];
        match &self.sidecar.data {
            DataFiles::One(f) => v.push(f.clone()),
            DataFiles::PerSlice(list) => v.extend(list.iter().cloned()),
        }
        v
    }

    fn report(&self) -> Vec<String> {
        self.notes.clone()
    }

    fn modality(&self) -> Option<(String, String)> {
        let m = self.sidecar.modality.clone()?;
        Some((m, "the sidecar's modality".into()))
    }

    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError> {
        let (map, range) = self.slice_range(z);
        decode_samples(
            &map[range.clone()],
            self.meta.dtype,
            self.sidecar.endian,
            out,
        );
        // Drop the slice's pages from this process (they stay in the page
        // cache), so resident memory stays one slice, not the whole file.
        // SAFETY: the map is read-only and file-backed, and no reference
        // into this range outlives the decode above; a later read faults
        // the pages back in from the file.
        #[cfg(unix)]
        unsafe {
            let _ = map.unchecked_advise_range(
                memmap2::UncheckedAdvice::DontNeed,
                range.start,
                range.len(),
            );
        }
        Ok(())
    }
}

/// Decodes raw sample bytes into f64 (exact for every supported type).
pub fn decode_samples(bytes: &[u8], dtype: Dtype, endian: Endian, out: &mut [f64]) {
    let size = dtype.size();
    debug_assert_eq!(bytes.len(), out.len() * size);
    const CHUNK: usize = 1 << 16;
    out.par_chunks_mut(CHUNK)
        .zip(bytes.par_chunks(CHUNK * size))
        .for_each(|(o, b)| decode_chunk(b, dtype, endian, o));
}

fn decode_chunk(b: &[u8], dtype: Dtype, endian: Endian, out: &mut [f64]) {
    macro_rules! conv {
        ($t:ty, $n:expr) => {{
            for (o, c) in out.iter_mut().zip(b.chunks_exact($n)) {
                let a: [u8; $n] = c.try_into().expect("chunk size");
                *o = match endian {
                    Endian::Little => <$t>::from_le_bytes(a),
                    Endian::Big => <$t>::from_be_bytes(a),
                } as f64;
            }
        }};
    }
    match dtype {
        Dtype::U8 => out.iter_mut().zip(b).for_each(|(o, &v)| *o = v as f64),
        Dtype::I8 => out
            .iter_mut()
            .zip(b)
            .for_each(|(o, &v)| *o = v as i8 as f64),
        Dtype::U16 => conv!(u16, 2),
        Dtype::I16 => conv!(i16, 2),
        Dtype::U32 => conv!(u32, 4),
        Dtype::I32 => conv!(i32, 4),
        Dtype::I64 => conv!(i64, 8),
        Dtype::F32 => conv!(f32, 4),
        Dtype::F64 => conv!(f64, 8),
    }
}
