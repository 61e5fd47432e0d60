//! A volume in the caller's memory: a numpy array in the Python package,
//! or any buffer of samples indexed `[z, y, x]` with byte strides.
//!
//! Slices are read straight from the buffer, or from one buffer a slice
//! (no copy of the volume), in any layout: C order reads a slice as one
//! run, Fortran order and other strides element by element. When the
//! slices lie apart in shared mappings of a file (a C-order
//! `numpy.memmap` opened `r` or `r+`), each slice's pages are given back
//! after it is read, as the raw reader does, so resident memory stays a
//! few slices whatever the volume's size.
//!
//! 64-bit integers (numpy's default integer type) are stored as the
//! smallest of u8, i8, u16, i16, u32 and i32 that holds their range; the
//! range is read once when the source is made. A range no 32-bit type
//! holds is refused.

use std::path::PathBuf;

use crate::grid::Grid;
use crate::input::raw::decode_samples;
use crate::input::{Dtype, Endian, InputError, Rescale, SliceSource, VolumeMeta};

/// The type of one element in memory (native byte order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Element {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl Element {
    /// Parses a numpy dtype name: `uint8`, `int16`, `float32`, ...;
    /// `bool` is read as `uint8`.
    pub fn parse(name: &str) -> Option<Element> {
        Some(match name {
            "uint8" | "bool" => Element::U8,
            "int8" => Element::I8,
            "uint16" => Element::U16,
            "int16" => Element::I16,
            "uint32" => Element::U32,
            "int32" => Element::I32,
            "uint64" => Element::U64,
            "int64" => Element::I64,
            "float32" => Element::F32,
            "float64" => Element::F64,
            _ => return None,
        })
    }

    /// The element types [`Element::parse`] takes, for messages.
    pub const NAMES: &'static str =
        "bool, uint8, int8, uint16, int16, uint32, int32, uint64, int64, float32, float64";

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Element::U8 | Element::I8 => 1,
            Element::U16 | Element::I16 => 2,
            Element::U32 | Element::I32 | Element::F32 => 4,
            Element::U64 | Element::I64 | Element::F64 => 8,
        }
    }

    /// The stored type of the same name; `None` for the 64-bit integers,
    /// which are narrowed by their range.
    fn dtype(self) -> Option<Dtype> {
        Some(match self {
            Element::U8 => Dtype::U8,
            Element::I8 => Dtype::I8,
            Element::U16 => Dtype::U16,
            Element::I16 => Dtype::I16,
            Element::U32 => Dtype::U32,
            Element::I32 => Dtype::I32,
            Element::F32 => Dtype::F32,
            Element::F64 => Dtype::F64,
            Element::U64 | Element::I64 => return None,
        })
    }

    /// Element `i` of `b` (native order) as f64; exact for every type but
    /// 64-bit integers beyond 2^53, which [`narrowest`] refuses first.
    #[inline]
    fn read(self, b: &[u8]) -> f64 {
        macro_rules! get {
            ($t:ty) => {{
                let mut a = [0u8; std::mem::size_of::<$t>()];
                a.copy_from_slice(&b[..std::mem::size_of::<$t>()]);
                <$t>::from_ne_bytes(a) as f64
            }};
        }
        match self {
            Element::U8 => b[0] as f64,
            Element::I8 => b[0] as i8 as f64,
            Element::U16 => get!(u16),
            Element::I16 => get!(i16),
            Element::U32 => get!(u32),
            Element::I32 => get!(i32),
            Element::U64 => get!(u64),
            Element::I64 => get!(i64),
            Element::F32 => get!(f32),
            Element::F64 => get!(f64),
        }
    }
}

/// The smallest integer type of u8, i8, u16, i16, u32, i32 that holds
/// `[lo, hi]`.
pub fn narrowest(lo: f64, hi: f64) -> Option<Dtype> {
    [
        Dtype::U8,
        Dtype::I8,
        Dtype::U16,
        Dtype::I16,
        Dtype::U32,
        Dtype::I32,
    ]
    .into_iter()
    .find(|d| {
        let (a, b) = d.int_range();
        lo >= a as f64 && hi <= b as f64
    })
}

/// A `[z, y, x]` volume in memory, read as a [`SliceSource`]: one buffer
/// with byte strides ([`ArraySource::new`]) or one buffer a slice
/// ([`ArraySource::from_planes`]).
pub struct ArraySource<'a> {
    /// Slice `z`'s bytes, from its element `[y, x] = [0, 0]` to its last.
    planes: Vec<&'a [u8]>,
    element: Element,
    /// `[nz, ny, nx]`.
    shape: [usize; 3],
    /// Bytes between neighbours along y and x within a slice.
    strides: [usize; 2],
    meta: VolumeMeta,
    files: Vec<PathBuf>,
    modality: Option<String>,
    /// Give each slice's pages back after reading it: every slice lies in
    /// a shared file mapping ([`shared_file_mapping`]) and no two overlap.
    release: bool,
}

impl<'a> ArraySource<'a> {
    /// A source over `data`, whose element `[z, y, x]` starts at byte
    /// `z * strides[0] + y * strides[1] + x * strides[2]`. `grid` gives the
    /// sample positions (x fastest, so its dims are `[nx, ny, nz]`);
    /// `name` names the array in messages and in the packed file's
    /// header. Refused: a grid whose dims are not the shape's, strides
    /// that reach past the buffer, and 64-bit integers whose range no
    /// 32-bit type holds.
    pub fn new(
        data: &'a [u8],
        element: Element,
        shape: [usize; 3],
        strides: [usize; 3],
        grid: Grid,
        name: &str,
    ) -> Result<ArraySource<'a>, InputError> {
        let [nz, ny, nx] = shape;
        let plane = plane_extent(element, [ny, nx], [strides[1], strides[2]]);
        let last = plane.and_then(|p| (nz.max(1) - 1).checked_mul(strides[0])?.checked_add(p));
        let (Some(plane), Some(end)) = (plane, last) else {
            return Err(strides_error(name, &strides, &shape, data.len()));
        };
        if end > data.len() {
            return Err(strides_error(name, &strides, &shape, data.len()));
        }
        let planes = (0..nz)
            .map(|z| &data[z * strides[0]..z * strides[0] + plane])
            .collect();
        ArraySource::from_planes(
            planes,
            element,
            [ny, nx],
            [strides[1], strides[2]],
            grid,
            name,
        )
    }

    /// A source over one buffer a slice (z ascending), each holding
    /// element `[y, x]` at byte `y * strides[0] + x * strides[1]`: slices
    /// read one by one, stacked without a copy. Refused as [`new`]
    /// refuses, and a slice too short for `shape` and `strides`.
    ///
    /// [`new`]: ArraySource::new
    pub fn from_planes(
        planes: Vec<&'a [u8]>,
        element: Element,
        shape: [usize; 2],
        strides: [usize; 2],
        grid: Grid,
        name: &str,
    ) -> Result<ArraySource<'a>, InputError> {
        let bad = |field: &str, msg: String| InputError::Array {
            name: name.to_string(),
            field: field.to_string(),
            msg,
        };
        let [ny, nx] = shape;
        let nz = planes.len();
        if grid.dims() != [nx, ny, nz] {
            let [gx, gy, gz] = grid.dims();
            return Err(bad(
                "shape",
                format!(
                    "(z, y, x) = ({nz}, {ny}, {nx}), but the spacing and positions give \
                     ({gz}, {gy}, {gx}) samples"
                ),
            ));
        }
        let extent = plane_extent(element, shape, strides);
        if let Some(z) = planes
            .iter()
            .position(|p| extent.is_none_or(|e| p.len() < e))
        {
            return Err(bad(
                "strides",
                format!(
                    "slice {z}: strides {strides:?} bytes over shape {shape:?} reach past its {} \
                     bytes",
                    planes[z].len()
                ),
            ));
        }
        let mut src = ArraySource {
            planes,
            element,
            shape: [nz, ny, nx],
            strides,
            meta: VolumeMeta {
                grid,
                dtype: Dtype::U8,
                rescale: Rescale::IDENTITY,
                origin_desc: name.to_string(),
                orientation: None,
            },
            files: Vec::new(),
            modality: None,
            release: false,
        };
        // Before the range scan below, which gives pages back too.
        src.release = disjoint(&src.planes) && shared_file_mapping(&src.planes);
        src.meta.dtype = match element.dtype() {
            Some(d) => d,
            None => {
                let (lo, hi) = src.range();
                narrowest(lo, hi).ok_or_else(|| {
                    bad(
                        "dtype",
                        format!(
                            "{element:?} values from {lo} to {hi}: no integer type of 32 bits \
                             or fewer holds them; expected values within int32 or uint32"
                        ),
                    )
                })?
            }
        };
        Ok(src)
    }

    /// The files behind the buffer (a memmap's file): prep refuses to
    /// write over them.
    pub fn with_files(mut self, files: Vec<PathBuf>) -> ArraySource<'a> {
        self.files = files;
        self
    }

    /// The modality the caller states (`CT`, `MR`); by default it is
    /// guessed from the values, as for raw stacks.
    pub fn with_modality(mut self, modality: Option<String>) -> ArraySource<'a> {
        self.modality = modality;
        self
    }

    /// `value = raw * slope + intercept`.
    pub fn with_rescale(mut self, rescale: Rescale) -> ArraySource<'a> {
        self.meta.rescale = rescale;
        self
    }

    /// Whether slices' pages are given back after reading (the buffer is
    /// a shared mapping of a file).
    pub fn releases_pages(&self) -> bool {
        self.release
    }

    /// Smallest and largest element (NaNs left out).
    fn range(&self) -> (f64, f64) {
        let mut row = vec![0.0; self.shape[2]];
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for z in 0..self.shape[0] {
            for y in 0..self.shape[1] {
                self.read_row(z, y, &mut row);
                for &v in &row {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            self.release_slice(z);
        }
        (lo, hi)
    }

    /// Row `y` of slice `z` into `out` (`nx` values).
    fn read_row(&self, z: usize, y: usize, out: &mut [f64]) {
        let plane = self.planes[z];
        let base = y * self.strides[0];
        let size = self.element.size();
        if self.strides[1] == size {
            let bytes = &plane[base..base + out.len() * size];
            match self.element.dtype() {
                Some(d) => decode_samples(bytes, d, NATIVE, out),
                None => {
                    for (o, b) in out.iter_mut().zip(bytes.chunks_exact(size)) {
                        *o = self.element.read(b);
                    }
                }
            }
        } else {
            for (x, o) in out.iter_mut().enumerate() {
                *o = self.element.read(&plane[base + x * self.strides[1]..]);
            }
        }
    }

    /// Gives back the pages wholly inside slice `z` when the slices lie
    /// apart in shared file mappings.
    fn release_slice(&self, z: usize) {
        if self.release {
            release_pages(self.planes[z]);
        }
    }
}

/// Bytes from a slice's first element to the end of its last, `None` on
/// overflow.
fn plane_extent(element: Element, shape: [usize; 2], strides: [usize; 2]) -> Option<usize> {
    shape
        .iter()
        .zip(strides)
        .try_fold(element.size(), |acc, (&n, s)| {
            (n.max(1) - 1).checked_mul(s)?.checked_add(acc)
        })
}

fn strides_error(name: &str, strides: &[usize; 3], shape: &[usize; 3], len: usize) -> InputError {
    InputError::Array {
        name: name.to_string(),
        field: "strides".into(),
        msg: format!(
            "strides {strides:?} bytes over shape {shape:?} reach past the {len} bytes of the buffer"
        ),
    }
}

/// Whether no two of `planes` share a byte (then giving one's pages back
/// never costs another its pages).
fn disjoint(planes: &[&[u8]]) -> bool {
    let mut spans: Vec<(usize, usize)> = planes
        .iter()
        .map(|p| (p.as_ptr() as usize, p.as_ptr() as usize + p.len()))
        .collect();
    spans.sort_unstable();
    spans.windows(2).all(|w| w[0].1 <= w[1].0)
}

#[cfg(target_endian = "little")]
const NATIVE: Endian = Endian::Little;
#[cfg(target_endian = "big")]
const NATIVE: Endian = Endian::Big;

impl SliceSource for ArraySource<'_> {
    fn meta(&self) -> &VolumeMeta {
        &self.meta
    }

    fn read_slice(&self, z: usize, out: &mut [f64]) -> Result<(), InputError> {
        let [_, ny, nx] = self.shape;
        let size = self.element.size();
        match self.element.dtype() {
            // A C-order slice: one run.
            Some(d) if self.strides == [nx * size, size] => {
                decode_samples(&self.planes[z][..nx * ny * size], d, NATIVE, out);
            }
            _ => {
                for (y, row) in out.chunks_exact_mut(nx).enumerate() {
                    self.read_row(z, y, row);
                }
            }
        }
        self.release_slice(z);
        Ok(())
    }

    fn modality(&self) -> Option<(String, String)> {
        let m = self.modality.clone()?;
        Some((m, "the caller".into()))
    }

    fn files(&self) -> Vec<PathBuf> {
        self.files.clone()
    }
}

/// Whether every byte of every one of `spans` lies in a shared,
/// file-backed mapping (`/proc/self/maps`: an `s` permission and an
/// inode), where giving pages back loses nothing: they stay in the page
/// cache and fault back in. On private or anonymous memory it would zero
/// them, so anything else, or a system without `/proc`, says no.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn shared_file_mapping(spans: &[&[u8]]) -> bool {
    let Ok(maps) = std::fs::read_to_string("/proc/self/maps") else {
        return false;
    };
    // (start, end, shared and file-backed), in address order.
    let mut regions = Vec::new();
    for line in maps.lines() {
        let mut f = line.split_whitespace();
        let (Some(range), Some(perms), _, _, Some(inode)) =
            (f.next(), f.next(), f.next(), f.next(), f.next())
        else {
            return false;
        };
        let Some((a, b)) = range.split_once('-') else {
            return false;
        };
        let (Ok(a), Ok(b)) = (usize::from_str_radix(a, 16), usize::from_str_radix(b, 16)) else {
            return false;
        };
        regions.push((a, b, perms.ends_with('s') && inode != "0"));
    }
    spans.iter().all(|data| {
        let (mut at, end) = (data.as_ptr() as usize, data.as_ptr() as usize + data.len());
        for &(a, b, shared) in &regions {
            if b <= at || a > at {
                continue;
            }
            if !shared {
                return false;
            }
            at = b;
            if at >= end {
                return true;
            }
        }
        false
    })
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn shared_file_mapping(_spans: &[&[u8]]) -> bool {
    false
}

/// Drops the whole pages of `bytes` from this process (a shared file
/// mapping, checked by [`shared_file_mapping`]).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn release_pages(bytes: &[u8]) {
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(1) as usize;
    let start = (bytes.as_ptr() as usize).div_ceil(page) * page;
    let end = (bytes.as_ptr() as usize + bytes.len()) / page * page;
    if end > start {
        // SAFETY: the range lies inside a shared file mapping
        // (shared_file_mapping), where MADV_DONTNEED only unmaps pages that
        // stay in the page cache; no reference into them is held here, and
        // a later read faults them back in with the same contents.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_DONTNEED);
        }
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn release_pages(_bytes: &[u8]) {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

    fn grid(nx: usize, ny: usize, nz: usize) -> Grid {
        Grid {
            axes: [nx, ny, nz].map(|n| Axis::uniform(0.0, 1.0, n).unwrap()),
        }
    }

    #[test]
    fn reads_c_and_fortran_order_alike() {
        let (nx, ny, nz) = (5, 4, 3);
        let v = |x: usize, y: usize, z: usize| (x + 10 * y + 100 * z) as i16 - 50;
        let mut c = Vec::new();
        let mut f = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    c.extend_from_slice(&v(x, y, z).to_ne_bytes());
                }
            }
        }
        for x in 0..nx {
            for y in 0..ny {
                for z in 0..nz {
                    f.extend_from_slice(&v(x, y, z).to_ne_bytes());
                }
            }
        }
        let sc = ArraySource::new(
            &c,
            Element::I16,
            [nz, ny, nx],
            [2 * nx * ny, 2 * nx, 2],
            grid(nx, ny, nz),
            "c",
        )
        .unwrap();
        let sf = ArraySource::new(
            &f,
            Element::I16,
            [nz, ny, nx],
            [2, 2 * nz, 2 * nz * ny],
            grid(nx, ny, nz),
            "f",
        )
        .unwrap();
        assert!(!sc.releases_pages(), "a Vec is not a file mapping");
        let (mut a, mut b) = (vec![0.0; nx * ny], vec![0.0; nx * ny]);
        for z in 0..nz {
            sc.read_slice(z, &mut a).unwrap();
            sf.read_slice(z, &mut b).unwrap();
            let want: Vec<f64> = (0..ny)
                .flat_map(|y| (0..nx).map(move |x| v(x, y, z) as f64))
                .collect();
            assert_eq!(a, want);
            assert_eq!(b, want);
        }
    }

    #[test]
    fn slices_apart_read_as_one_buffer() {
        let (nx, ny, nz) = (4, 3, 5);
        let one: Vec<u8> = (0..nx * ny * nz).map(|i| (i * 7 % 256) as u8).collect();
        let slices: Vec<Vec<u8>> = one.chunks(nx * ny).map(<[u8]>::to_vec).collect();
        let a = ArraySource::new(
            &one,
            Element::U8,
            [nz, ny, nx],
            [nx * ny, nx, 1],
            grid(nx, ny, nz),
            "a",
        )
        .unwrap();
        let planes = slices.iter().map(Vec::as_slice).collect();
        let b = ArraySource::from_planes(
            planes,
            Element::U8,
            [ny, nx],
            [nx, 1],
            grid(nx, ny, nz),
            "b",
        )
        .unwrap();
        let (mut x, mut y) = (vec![0.0; nx * ny], vec![0.0; nx * ny]);
        for z in 0..nz {
            a.read_slice(z, &mut x).unwrap();
            b.read_slice(z, &mut y).unwrap();
            assert_eq!(x, y);
        }
        let short = vec![one.as_slice(), &one[..5]];
        let e =
            ArraySource::from_planes(short, Element::U8, [ny, nx], [nx, 1], grid(nx, ny, 2), "s")
                .err()
                .unwrap()
                .to_string();
        assert!(e.contains("slice 1") && e.contains("5 bytes"), "{e}");
        assert!(disjoint(&[&one[..4], &one[4..8]]) && !disjoint(&[&one[..5], &one[4..8]]));
    }

    #[test]
    fn narrows_64_bit_integers_by_range_and_refuses_wider() {
        let values = [-1024i64, 3071, 0, 5, 1, 2, 3, 4];
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_ne_bytes()).collect();
        let s = ArraySource::new(
            &data,
            Element::I64,
            [2, 2, 2],
            [32, 16, 8],
            grid(2, 2, 2),
            "a",
        )
        .unwrap();
        assert_eq!(s.meta().dtype, Dtype::I16);
        let mut out = vec![0.0; 4];
        s.read_slice(0, &mut out).unwrap();
        assert_eq!(out, [-1024.0, 3071.0, 0.0, 5.0]);
        let wide: Vec<u8> = [0u64, 1 << 40, 0, 0, 0, 0, 0, 0]
            .iter()
            .flat_map(|v| v.to_ne_bytes())
            .collect();
        let e = ArraySource::new(
            &wide,
            Element::U64,
            [2, 2, 2],
            [32, 16, 8],
            grid(2, 2, 2),
            "w",
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("dtype") && e.contains("1099511627776"), "{e}");
        assert_eq!(narrowest(0.0, 255.0), Some(Dtype::U8));
        assert_eq!(narrowest(-1.0, 200.0), Some(Dtype::I16));
        assert_eq!(narrowest(0.0, 70000.0), Some(Dtype::U32));
    }

    #[test]
    fn refuses_strides_past_the_buffer_and_a_grid_of_another_shape() {
        let data = vec![0u8; 24];
        let e = ArraySource::new(
            &data,
            Element::U8,
            [2, 3, 4],
            [13, 4, 1],
            grid(4, 3, 2),
            "s",
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("strides") && e.contains("24 bytes"), "{e}");
        let e = ArraySource::new(
            &data,
            Element::U8,
            [2, 3, 4],
            [12, 4, 1],
            grid(4, 3, 3),
            "g",
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("shape") && e.contains("(3, 3, 4)"), "{e}");
        let e = ArraySource::new(
            &data,
            Element::U8,
            [2, 3, 4],
            [usize::MAX, 4, 1],
            grid(4, 3, 2),
            "o",
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("strides"), "{e}");
    }

    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn gives_pages_back_only_on_a_shared_file_mapping() {
        use std::io::Write;
        let mut f = tempfile::tempfile().unwrap();
        let bytes: Vec<u8> = (0..3 * 4096u32).map(|i| (i % 251) as u8).collect();
        f.write_all(&bytes).unwrap();
        // SAFETY: a private temporary file nobody else writes.
        let map = unsafe { memmap2::Mmap::map(&f) }.unwrap();
        let s = ArraySource::new(
            &map,
            Element::U8,
            [3, 64, 64],
            [4096, 64, 1],
            grid(64, 64, 3),
            "m",
        )
        .unwrap();
        assert!(s.releases_pages());
        let mut out = vec![0.0; 4096];
        for z in [0, 2, 0] {
            s.read_slice(z, &mut out).unwrap();
            assert!(out
                .iter()
                .zip(&bytes[z * 4096..])
                .all(|(&o, &b)| o == b as f64));
        }
        // Fortran order: every slice spans the whole file, so giving one
        // slice's pages back would take the others' too.
        let f_order = ArraySource::new(
            &map,
            Element::U8,
            [64, 64, 3],
            [1, 64, 4096],
            grid(3, 64, 64),
            "f",
        )
        .unwrap();
        assert!(!f_order.releases_pages());
        let private = unsafe { memmap2::MmapOptions::new().map_copy_read_only(&f) }.unwrap();
        let p = ArraySource::new(
            &private,
            Element::U8,
            [3, 64, 64],
            [4096, 64, 1],
            grid(64, 64, 3),
            "p",
        )
        .unwrap();
        assert!(!p.releases_pages(), "a private mapping loses written pages");
    }
}
