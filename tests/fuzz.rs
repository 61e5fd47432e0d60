//! Fuzz targets, driven by proptest.
//!
//! (a) The packed-file reader: three small valid files (prep'd once: u8
//! with anisotropic codes, f32 with NaN/inf and a rectilinear z, i16 over
//! the whole range classified by a transfer function) are mutated (bit
//! flips, byte overwrites, truncation, appended bytes, footer and index
//! fields, JSON header fields set to huge/negative/ill-typed values, raw
//! text spliced into the header, brick payloads replaced by new zstd
//! frames of random or code-word content, and consistent re-geometries
//! with many uniform bricks). Checksums are recomputed where a mutation
//! means to get past them. Opening the result, `info`, reading bricks,
//! rendering a tiny image in every mode with FVT and CD, and `export` must
//! return `Ok` or `Err`, never panic; an open error must name the file.
//! No single allocation may exceed [`ALLOC_LIMIT`] (a counting global
//! allocator below records the largest request): the bases are a few KiB
//! and every legal size is bounded by the file, so anything larger means a
//! size taken from the file without a bound. The unmutated bases must open
//! and render.
//!
//! (b) The traversal: random rectilinear grids (sane ones, grids whose
//! coordinates are arbitrary f64 bit patterns, cells one ulp thick, one
//! long axis) with random 1-cells in a `MemVolume`, and rays whose origin
//! and direction components are arbitrary f64 bit patterns (NaN, inf,
//! subnormal, huge) or near the grid, from arbitrary `t_min`.
//! `render::traverse::trace` in f64 and f32, FVT and CD, must not panic;
//! a ray `Ray::check` refuses (or a non-finite `t_min`) visits nothing in
//! no steps; otherwise every visit is a 1-cell with finite `t_enter <
//! t_exit`, visits never go back in `t` (nor, in f64, before `t_min`),
//! steps <= `MemVolume::step_bound()`, and CD visits exactly what FVT
//! visits (in each arithmetic).
//!
//! (c)-(f) The input readers, each through `cdvol::input::open` as `prep`
//! opens its input: NRRD (`fuzz_readers_nrrd`: attached raw, attached
//! gzip, detached `.nhdr` with raw and with gzip data; header fields set
//! to huge, negative, overflowing, non-finite or ill-typed values, lines
//! inserted and deleted, bytes of the header, of the samples and of the
//! stored (gzip) data flipped, set, cut, spliced and appended, gzip
//! member headers, deflate data and trailers corrupted), NIfTI-1
//! (`fuzz_readers_nifti`: `.nii` and `.nii.gz`, little and big endian;
//! dim, datatype, bitpix, pixdim, vox_offset, scl_slope/inter,
//! qform/sform codes and rows, magic set at their offsets to special
//! values or arbitrary bits, bytes flipped, cut and spliced, gzip
//! corrupted), raw stack sidecars (`fuzz_readers_sidecar`: one data file
//! and one per slice; dims, dtype, endian, header_bytes, axes,
//! spacing, positions, origin, rescale, orientation and data set to
//! extreme or ill-typed JSON, keys removed, raw text spliced, data files
//! cut short or made longer) and DICOM (`fuzz_readers_dicom`: a 3-slice
//! series written by `dicom::write_slice`, one slice's header or pixel
//! data bytes mutated, Rows, Columns, BitsAllocated and the other US
//! elements, PixelSpacing, positions, orientation, rescale, series and
//! transfer syntax UIDs overwritten, element lengths set). Each case is
//! opened and, if it opens, every slice is read: `Ok` or `Err`, never a
//! panic; every error contains the name of the case's file (or of the
//! data file the header names; for DICOM a slice or the series
//! directory); an opened volume holds no more sample bytes than 1032
//! times the input bytes (deflate's most); no allocation (counted on the
//! target's own thread, apart from the other targets) above
//! [`ALLOC_LIMIT`]; the unmutated bases open and read back their samples
//! exactly. `CDVOL_FUZZ_TRACE_ALLOC=1` prints a backtrace for each
//! allocation above the limit.
//!
//! Found by this fuzz and not fixed yet (the reader tests fail until they
//! are; the cases are in tests/fuzz.proptest-regressions): a DICOM slice
//! with 9 zero bytes inserted just before its PixelData element makes
//! dicom-parser (`read_value_ob`, `smallvec![0u8; len]`, reached from the
//! header read of `input::dicom`) allocate what a garbage 32-bit length
//! says (276 MB here, up to 4 GiB) for a 2.7 KB file; an NRRD with
//! `encoding: gzip` and an empty `data file:` is refused with an error
//! that names the directory only (not the header, not the field).
//!
//! Found by this fuzz and fixed (each keeps a regression test below,
//! `found_*`): `t` overflowing to inf on grids spanning ~1e300 mm (axes
//! and ray origins are now bounded by `MAX_COORD_MM`, directions by
//! `MAX_DIR`), visits emptied by the underflow of the reported `t` for
//! directions above 2^1022 (refused now), and `Info::to_text` overflowing
//! on code-histogram counts near 2^64 (saturating now).
//!
//! Cases per test: `CDVOL_FUZZ_CASES` (default 64). Failures are persisted
//! by proptest to tests/fuzz.proptest-regressions and replayed first on
//! every run. `tools/fuzz.sh [SECONDS]` runs these with many cases; CI
//! (.ci/run) runs the reader targets with more cases under a 4 GiB
//! address-space limit.

#[path = "all/common/mod.rs"]
mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::OnceLock;

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::export::{export, ExportWhat};
use cdvol::format::reader::{BrickData, PackedVolume};
use cdvol::format::word::Word;
use cdvol::format::{Header, IndexEntry, FLAG_NO_OBJECT, FLAG_UNIFORM, INDEX_ENTRY_LEN};
use cdvol::grid::Axis;
use cdvol::info::Info;
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::{Method, Ray, TGrid, Visit};
use cdvol::render::view::camera::Camera;
use cdvol::render::{render, Mode, RenderError, RenderOptions};
use cdvol::tools::corpus::{self, MemVolume};
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

use common::mix;

// ---- allocation watch ----

/// Largest single allocation a reader case may make. The base files are
/// a few KiB, their bricks decode to well under 1 MiB, the largest legal
/// re-geometry (below) to a few MiB; 64 MiB is far above all of that and
/// far below the many GiB an unchecked size from the file would ask for.
const ALLOC_LIMIT: usize = 64 << 20;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

struct Watch;

/// Set (from `CDVOL_FUZZ_TRACE_ALLOC`) to print where each allocation
/// above [`ALLOC_LIMIT`] is made.
static TRACE_BIG: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn trace_big(size: usize) {
    if size > ALLOC_LIMIT && TRACE_BIG.load(Ordering::Relaxed) {
        // The backtrace's own allocations are small: no recursion here.
        eprintln!(
            "cdvol-fuzz: allocation of {size} bytes:\n{}",
            std::backtrace::Backtrace::force_capture()
        );
    }
}

thread_local! {
    /// On the thread of an input-reader target (which reads on that
    /// thread only): the largest allocation of its current case, kept
    /// apart from [`LARGEST`] so that targets running in parallel do not
    /// charge each other. `None` elsewhere.
    static LOCAL_LARGEST: std::cell::Cell<Option<usize>> = const { std::cell::Cell::new(None) };
}

fn record(size: usize) {
    let local = LOCAL_LARGEST
        .try_with(|c| match c.get() {
            Some(m) => {
                c.set(Some(m.max(size)));
                true
            }
            None => false,
        })
        .unwrap_or(false);
    if !local {
        LARGEST.fetch_max(size, Ordering::Relaxed);
    }
    trace_big(size);
}

unsafe impl GlobalAlloc for Watch {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        record(l.size());
        System.alloc(l)
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        record(l.size());
        System.alloc_zeroed(l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        record(new);
        System.realloc(p, l, new)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
}

#[global_allocator]
static GLOBAL: Watch = Watch;

// ---- running ----

fn cases() -> u32 {
    if std::env::var_os("CDVOL_FUZZ_TRACE_ALLOC").is_some() {
        TRACE_BIG.store(true, Ordering::Relaxed);
    }
    std::env::var("CDVOL_FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(64)
}

/// Runs `test` on `strategy` with the file-persisted proptest config and
/// prints how many cases ran (tools/fuzz.sh adds these up).
fn fuzz<S: Strategy>(
    name: &'static str,
    strategy: S,
    test: impl Fn(S::Value) -> Result<(), TestCaseError>,
) where
    S::Value: std::fmt::Debug,
{
    let mut config = Config::with_cases(cases());
    config.source_file = Some(file!());
    config.test_name = Some(name);
    config.max_shrink_iters = 4000;
    let count = AtomicU64::new(0);
    let mut runner = TestRunner::new(config);
    let result = runner.run(&strategy, |v| {
        count.fetch_add(1, Ordering::Relaxed);
        test(v)
    });
    eprintln!(
        "cdvol-fuzz: {name}: {} cases",
        count.load(Ordering::Relaxed)
    );
    if let Err(e) = result {
        panic!("{e}\n{runner}");
    }
}

// ---- (a) the packed-file reader ----

/// A valid packed file and what it holds.
struct Base {
    name: &'static str,
    bytes: Vec<u8>,
    header: Header,
    index: Vec<IndexEntry>,
}

fn bases() -> &'static [Base] {
    static B: OnceLock<Vec<Base>> = OnceLock::new();
    B.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let mut out = Vec::new();
        let ball = |dims: [usize; 3], peak: f64| -> Vec<f64> {
            let mut v = Vec::new();
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let d = ((x as f64 - 6.0).powi(2)
                            + (y as f64 - 5.0).powi(2)
                            + (z as f64 - 4.0).powi(2))
                        .sqrt();
                        v.push((peak * (1.0 - d / 7.0)).max(0.0).round());
                    }
                }
            }
            v
        };
        let tf = TransferFunction {
            points: vec![
                TfPoint {
                    value: 0.0,
                    opacity: 0.0,
                    color: [1.0; 3],
                },
                TfPoint {
                    value: 10000.0,
                    opacity: 0.6,
                    color: [1.0, 0.5, 0.2],
                },
            ],
        };
        // (name, dims, dtype, values, classification, aniso, sidecar extra)
        type Spec<'a> = (
            &'static str,
            [usize; 3],
            &'a str,
            Vec<f64>,
            Classification,
            bool,
            &'a str,
        );
        let specs: Vec<Spec> = vec![
            (
                "u8-aniso",
                [14, 11, 9],
                "u8",
                ball([14, 11, 9], 200.0),
                Classification::Iso { iso: 100.0 },
                true,
                "1",
            ),
            (
                "f32-nan-inf",
                [10, 9, 12],
                "f32",
                ball([10, 9, 12], 3.0)
                    .iter()
                    .enumerate()
                    .map(|(i, &x)| match mix(i as u64) % 16 {
                        0 => f64::NAN,
                        1 => f64::INFINITY,
                        2 => f64::NEG_INFINITY,
                        _ => x * 0.25,
                    })
                    .collect(),
                Classification::Iso { iso: 0.5 },
                false,
                "{\"spacing\": [1, 0.5, 2, 1, 1, 0.25, 3, 1, 1, 1, 0.5]}",
            ),
            (
                "i16-tf",
                [17, 9, 6],
                "i16",
                {
                    let mut v: Vec<f64> = ball([17, 9, 6], 32767.0)
                        .iter()
                        .map(|x| x * 2.0 - 32768.0)
                        .collect();
                    v[5] = 32767.0;
                    v
                },
                Classification::TransferFunction { tf },
                false,
                "2",
            ),
        ];
        for (name, dims, dtype, values, cls, aniso, z) in specs {
            let side =
                common::write_stack(dir.path(), name, dims, dtype, &values, ["1", "0.75", z], "");
            let src = RawSource::open(&side).unwrap();
            let path = dir.path().join(format!("{name}.cdv"));
            let mut o = PrepOptions::new(cls);
            o.brick_size = 4;
            o.aniso = aniso;
            prep(&src, &path, &o, &NoProgress).unwrap();
            let vol = PackedVolume::open(&path).unwrap();
            assert!(vol.header().brick_count() > 4);
            assert!(vol.index().iter().any(|e| !e.is_uniform()));
            out.push(Base {
                name,
                bytes: std::fs::read(&path).unwrap(),
                header: vol.header().clone(),
                index: vol.index().to_vec(),
            });
        }
        out
    })
}

/// Trailer offset, header length and index length from the footer, when
/// they describe the file.
fn layout(b: &[u8]) -> Option<(usize, usize, usize)> {
    let n = b.len();
    if n < 56 {
        return None;
    }
    let f = &b[n - 40..];
    let u = |i: usize| u64::from_le_bytes(f[i..i + 8].try_into().unwrap());
    let (t, h, i) = (u(0), u(8), u(16));
    let end = t.checked_add(h)?.checked_add(i)?.checked_add(40)?;
    (end == n as u64 && t >= 16).then_some((t as usize, h as usize, i as usize))
}

/// A file from its parts with a fresh footer; `crc` false keeps the old
/// (now likely wrong) checksum.
fn assemble(b: &[u8], payloads: &[u8], header: &[u8], index: &[u8], crc: bool) -> Vec<u8> {
    let n = b.len();
    let old = &b[n - 40..];
    let mut out = payloads.to_vec();
    out.extend_from_slice(header);
    out.extend_from_slice(index);
    out.extend_from_slice(&(payloads.len() as u64).to_le_bytes());
    out.extend_from_slice(&(header.len() as u64).to_le_bytes());
    out.extend_from_slice(&(index.len() as u64).to_le_bytes());
    if crc {
        let mut h = crc32fast::Hasher::new();
        h.update(header);
        h.update(index);
        out.extend_from_slice(&h.finalize().to_le_bytes());
    } else {
        out.extend_from_slice(&old[24..28]);
    }
    out.extend_from_slice(&old[28..40]);
    out
}

/// JSON text to set a header field to.
const JSON_VALUES: &[&str] = &[
    "0",
    "1",
    "-1",
    "2",
    "3",
    "4",
    "7",
    "1020",
    "1024",
    "1048576",
    "1048577",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775808",
    "1e308",
    "-1e308",
    "5e-324",
    "0.5",
    "null",
    "true",
    "\"NaN\"",
    "\"u8\"",
    "\"f32\"",
    "\"f64\"",
    "\"i64\"",
    "\"u16\"",
    "[]",
    "{}",
    "[1, 2]",
    "[0, 0, 0]",
    "[2, 2, 2]",
    "[1, 1, 1]",
    "[1048576, 2, 2]",
    "[18446744073709551615, 1, 1]",
    "[4294967296, 4294967296, 4294967296]",
    "[0, 1e-300, 2e-300]",
    "[-1e308, 0, 1e308]",
    "{\"kind\": \"int_range\", \"base\": -9223372036854775808, \"max\": 4294967295}",
    "{\"kind\": \"int_range\", \"base\": 9223372036854775807, \"max\": 254}",
    "{\"kind\": \"nan_payload\", \"max\": 4294967295}",
    "{\"iso\": {\"iso\": 1e308}}",
    "{\"iso\": {\"iso\": -1e308}}",
    "{\"transfer_function\": {\"tf\": {\"points\": [{\"value\": 0, \"opacity\": 1}]}}}",
    concat!(
        "{\"transfer_function\": {\"tf\": {\"points\": [",
        "{\"value\": -1e308, \"opacity\": 0}, {\"value\": 1e308, \"opacity\": 1}]}}}"
    ),
    "[18446744073709551615, 18446744073709551615]",
    "{\"slope\": -1e308, \"intercept\": 1e308}",
    "{\"slope\": 5e-324, \"intercept\": 0}",
];

/// JSON pointers of the header fields to set.
const JSON_FIELDS: &[&str] = &[
    "/format_version",
    "/dims",
    "/dims/0",
    "/dims/2",
    "/axes",
    "/axes/0",
    "/axes/1/0",
    "/axes/2/1",
    "/dtype",
    "/storage",
    "/rescale",
    "/rescale/slope",
    "/rescale/intercept",
    "/classification",
    "/classification/iso/iso",
    "/codes",
    "/codes/base",
    "/codes/max",
    "/codes/kind",
    "/brick_size",
    "/bricks",
    "/bricks/0",
    "/aniso_block",
    "/zstd_level",
    "/source",
    "/summary",
    "/summary/cells",
    "/summary/one_cells",
    "/summary/code_histogram",
    "/summary/code_histogram/0",
    "/summary/uniform_bricks",
    "/summary/raw_min",
    "/summary/raw_max",
    "/summary/nan_samples",
    "/summary/input_bytes",
];

/// Raw text spliced into the header JSON.
const SPLICES: &[&str] = &[
    "NaN",
    "-NaN",
    "Infinity",
    "-1",
    "-0",
    "1e999",
    "-1e999",
    "99999999999999999999999999999",
    "18446744073709551615",
    "0",
    "null",
    "\"",
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\\u0000",
    "\\ud800",
    "\u{feff}",
    "\"dims\": [1048576, 1048576, 1048576], ",
    "\"bricks\": [4294967296, 4294967296, 1], ",
    "\"brick_size\": 0, ",
    "\"brick_size\": 4294967295, ",
    "\"format_version\": 1, \"format_version\": 1, ",
];

#[derive(Debug, Clone)]
enum Payload {
    /// Random bytes of the right decompressed size plus `delta`.
    Random { delta: i64, seed: u64 },
    /// Sample words drawn from code words of every code and special
    /// values; octant bytes random.
    Palette { seed: u64 },
    /// Not a zstd frame.
    Garbage(Vec<u8>),
}

#[derive(Debug, Clone)]
enum Mutation {
    FlipBit {
        at: Index,
        bit: u8,
    },
    SetByte {
        at: Index,
        value: u8,
    },
    /// A bit in the last 4 KiB (header, index, footer).
    FlipTail {
        back: usize,
        bit: u8,
    },
    Truncate {
        keep: Index,
    },
    Append(Vec<u8>),
    FooterField {
        field: usize,
        value: u64,
    },
    HeaderField {
        field: usize,
        value: usize,
        crc: bool,
    },
    HeaderSplice {
        at: Index,
        del: usize,
        text: String,
        crc: bool,
    },
    IndexField {
        brick: Index,
        field: usize,
        value: u64,
        crc: bool,
    },
    Payload {
        brick: Index,
        content: Payload,
    },
    /// New dims, axes, brick size and a consistent index.
    Reshape {
        dims: [u64; 3],
        brick: u32,
        entries: ReshapeIndex,
        rectilinear: bool,
    },
}

#[derive(Debug, Clone)]
enum ReshapeIndex {
    /// Every brick uniform with this code (and maybe the no-object flag).
    Uniform { code: u32, no_object: bool },
    /// The base file's entries, cycled.
    Cycle,
}

fn special_u64() -> impl Strategy<Value = u64> {
    prop_oneof![
        3 => any::<u64>(),
        1 => prop::sample::select(vec![
            0u64, 1, 2, 3, 16, 40, 254, 255, 256, u32::MAX as u64, 1 << 32, (1 << 28) + 1,
            u64::MAX, u64::MAX - 39, i64::MAX as u64,
        ]),
        2 => 0u64..4096,
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        3 => (any::<Index>(), 0u8..8).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
        2 => (any::<Index>(), any::<u8>()).prop_map(|(at, value)| Mutation::SetByte { at, value }),
        3 => (1usize..4096, 0u8..8).prop_map(|(back, bit)| Mutation::FlipTail { back, bit }),
        2 => any::<Index>().prop_map(|keep| Mutation::Truncate { keep }),
        1 => proptest::collection::vec(any::<u8>(), 1..64).prop_map(Mutation::Append),
        2 => (0usize..6, special_u64())
            .prop_map(|(field, value)| Mutation::FooterField { field, value }),
        6 => (0..JSON_FIELDS.len(), 0..JSON_VALUES.len(), prop::bool::weighted(0.9))
            .prop_map(|(field, value, crc)| Mutation::HeaderField { field, value, crc }),
        3 => (
            any::<Index>(),
            0usize..24,
            prop_oneof![
                3 => prop::sample::select(SPLICES).prop_map(String::from),
                1 => "[ -~]{0,12}",
            ],
            prop::bool::weighted(0.9),
        )
            .prop_map(|(at, del, text, crc)| Mutation::HeaderSplice { at, del, text, crc }),
        4 => (any::<Index>(), 0usize..6, special_u64(), prop::bool::weighted(0.9))
            .prop_map(|(brick, field, value, crc)| Mutation::IndexField {
                brick,
                field,
                value,
                crc,
            }),
        4 => (
            any::<Index>(),
            prop_oneof![
                2 => (
                    prop_oneof![4 => Just(0i64), 1 => -9i64..9, 1 => Just(i64::MIN)],
                    any::<u64>(),
                )
                    .prop_map(|(delta, seed)| Payload::Random { delta, seed }),
                3 => any::<u64>().prop_map(|seed| Payload::Palette { seed }),
                1 => proptest::collection::vec(any::<u8>(), 0..64).prop_map(Payload::Garbage),
            ],
        )
            .prop_map(|(brick, content)| Mutation::Payload { brick, content }),
        2 => (
            prop_oneof![
                3 => [2u64..24, 2u64..24, 2u64..24],
                1 => [2u64..3000, 2u64..4, 2u64..4],
                1 => [2u64..4, 2u64..4, 2u64..3000],
            ],
            prop::sample::select(vec![4u32, 8, 12, 64, 1020]),
            prop_oneof![
                3 => (0u32..300, any::<bool>())
                    .prop_map(|(code, no_object)| ReshapeIndex::Uniform { code, no_object }),
                1 => Just(ReshapeIndex::Cycle),
            ],
            any::<bool>(),
        )
            .prop_map(|(dims, brick, entries, rectilinear)| Mutation::Reshape {
                dims,
                brick,
                entries,
                rectilinear,
            }),
    ]
}

/// Sets the field at JSON pointer `ptr` (creating the last key of an
/// object when missing).
fn set_json(v: &mut serde_json::Value, ptr: &str, new: serde_json::Value) {
    if let Some(x) = v.pointer_mut(ptr) {
        *x = new;
        return;
    }
    let (parent, key) = ptr.rsplit_once('/').expect("pointer");
    if let Some(serde_json::Value::Object(o)) = v.pointer_mut(parent) {
        o.insert(key.to_string(), new);
    }
}

fn apply(b: Vec<u8>, m: &Mutation, base: &Base) -> Vec<u8> {
    let mut b = b;
    let n = b.len();
    match m {
        Mutation::FlipBit { at, bit } if n > 0 => b[at.index(n)] ^= 1 << bit,
        Mutation::SetByte { at, value } if n > 0 => b[at.index(n)] = *value,
        Mutation::FlipTail { back, bit } if n > 0 => {
            let i = n - 1 - (*back).min(n - 1);
            b[i] ^= 1 << bit;
        }
        Mutation::Truncate { keep } if n > 0 => b.truncate(keep.index(n)),
        Mutation::Append(x) => b.extend_from_slice(x),
        Mutation::FooterField { field, value } if n >= 40 => {
            let f = n - 40;
            match field {
                0..=2 => b[f + 8 * field..f + 8 * field + 8].copy_from_slice(&value.to_le_bytes()),
                3 => b[f + 24..f + 28].copy_from_slice(&(*value as u32).to_le_bytes()),
                4 => b[f + 28..f + 32].copy_from_slice(&(*value as u32).to_le_bytes()),
                _ => b[f + 32 + (*value as usize % 8)] ^= 0x20,
            }
        }
        Mutation::HeaderField { field, value, crc } => {
            let Some((t, h, _)) = layout(&b) else {
                return b;
            };
            let Ok(mut json) = serde_json::from_slice::<serde_json::Value>(&b[t..t + h]) else {
                return b;
            };
            let new: serde_json::Value = serde_json::from_str(JSON_VALUES[*value]).unwrap();
            set_json(&mut json, JSON_FIELDS[*field], new);
            let text = serde_json::to_vec(&json).unwrap();
            return assemble(&b, &b[..t], &text, &b[t + h..n - 40], *crc);
        }
        Mutation::HeaderSplice { at, del, text, crc } => {
            let Some((t, h, _)) = layout(&b) else {
                return b;
            };
            let mut json = b[t..t + h].to_vec();
            let i = if h == 0 { 0 } else { at.index(h) };
            let j = (i + del).min(h);
            json.splice(i..j, text.bytes());
            return assemble(&b, &b[..t], &json, &b[t + h..n - 40], *crc);
        }
        Mutation::IndexField {
            brick,
            field,
            value,
            crc,
        } => {
            let Some((t, h, il)) = layout(&b) else {
                return b;
            };
            let count = il / INDEX_ENTRY_LEN;
            if count == 0 {
                return b;
            }
            let mut idx = b[t + h..t + h + il].to_vec();
            let e = brick.index(count) * INDEX_ENTRY_LEN;
            let (off, len) = [(0, 8), (8, 4), (12, 4), (16, 4), (20, 4), (24, 8)][*field];
            idx[e + off..e + off + len].copy_from_slice(&value.to_le_bytes()[..len]);
            return assemble(&b, &b[..t], &b[t..t + h], &idx, *crc);
        }
        Mutation::Payload { brick, content } => {
            let Some((t, h, il)) = layout(&b) else {
                return b;
            };
            let count = il / INDEX_ENTRY_LEN;
            if count == 0 {
                return b;
            }
            let id = brick.index(count);
            let hd = &base.header;
            let want = if (id as u64) < hd.brick_count() {
                hd.payload_len(hd.brick_coords(id as u64)) as usize
            } else {
                64
            };
            let frame = match content {
                Payload::Random { delta, seed } => {
                    let len = (want as i64).saturating_add(*delta).clamp(0, 1 << 20) as usize;
                    let raw: Vec<u8> = (0..len).map(|i| mix(seed ^ i as u64) as u8).collect();
                    zstd::bulk::compress(&raw, 1).unwrap()
                }
                Payload::Palette { seed } => {
                    let words = if (id as u64) < hd.brick_count() {
                        hd.brick_samples(hd.brick_coords(id as u64))
                            .iter()
                            .product::<u64>() as usize
                    } else {
                        8
                    };
                    let mut raw = palette_words(hd, words, *seed);
                    if hd.byte_planes() {
                        // Stored as the file's layout stores words, so they
                        // read back as the palette's words.
                        let mut planes = Vec::with_capacity(raw.len());
                        cdvol::format::planes::split(&raw, hd.storage.size(), &mut planes);
                        raw = planes;
                    }
                    while raw.len() < want {
                        raw.push(mix(seed ^ raw.len() as u64) as u8);
                    }
                    zstd::bulk::compress(&raw, 1).unwrap()
                }
                Payload::Garbage(g) => g.clone(),
            };
            let mut idx = b[t + h..t + h + il].to_vec();
            let e = id * INDEX_ENTRY_LEN;
            let mut entry = IndexEntry::from_bytes(&idx[e..e + INDEX_ENTRY_LEN]);
            entry.offset = t as u64;
            entry.length = frame.len() as u32;
            entry.crc32 = crc32fast::hash(&frame);
            entry.flags &= !FLAG_UNIFORM;
            idx[e..e + INDEX_ENTRY_LEN].copy_from_slice(&entry.to_bytes());
            let mut payloads = b[..t].to_vec();
            payloads.extend_from_slice(&frame);
            return assemble(&b, &payloads, &b[t..t + h], &idx, true);
        }
        Mutation::Reshape {
            dims,
            brick,
            entries,
            rectilinear,
        } => {
            let Some((t, h, _)) = layout(&b) else {
                return b;
            };
            let Ok(mut json) = serde_json::from_slice::<serde_json::Value>(&b[t..t + h]) else {
                return b;
            };
            if !json.is_object() {
                return b;
            }
            let axes: Vec<Vec<f64>> = (0..3)
                .map(|k| {
                    let mut c = vec![-3.0];
                    for i in 1..dims[k] {
                        let g = if *rectilinear {
                            0.25 + (mix(i * 3 + k as u64) % 8) as f64 * 0.5
                        } else {
                            0.5
                        };
                        c.push(c[c.len() - 1] + g);
                    }
                    c
                })
                .collect();
            let bricks: Vec<u64> = dims
                .iter()
                .map(|d| (d - 1).div_ceil(*brick as u64))
                .collect();
            json["dims"] = serde_json::json!(dims);
            json["axes"] = serde_json::json!(axes);
            json["brick_size"] = serde_json::json!(brick);
            json["bricks"] = serde_json::json!(bricks);
            let count = bricks.iter().product::<u64>() as usize;
            let mut idx = Vec::with_capacity(count * INDEX_ENTRY_LEN);
            for i in 0..count {
                let e = match entries {
                    ReshapeIndex::Uniform { code, no_object } => IndexEntry {
                        flags: FLAG_UNIFORM | if *no_object { FLAG_NO_OBJECT } else { 0 },
                        uniform_code: *code,
                        ..IndexEntry::default()
                    },
                    ReshapeIndex::Cycle => base.index[i % base.index.len()],
                };
                idx.extend_from_slice(&e.to_bytes());
            }
            let text = serde_json::to_vec(&json).unwrap();
            return assemble(&b, &b[..t], &text, &idx, true);
        }
        _ => {}
    }
    b
}

/// `n` sample words of the header's storage type: every code word, the
/// canonical NaN, infinities, the type's extremes, values near the iso.
fn palette_words(h: &Header, n: usize, seed: u64) -> Vec<u8> {
    let enc = h.codes;
    let iso = match h.classification {
        Classification::Iso { iso } => iso,
        _ => 0.0,
    };
    let (lo, hi) = h.storage.int_range();
    let specials = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        0.0,
        -0.0,
        iso,
        iso - 1.0,
        iso + 1.0,
        lo as f64,
        hi as f64,
        f64::MAX,
        5e-324,
    ];
    let mut out = Vec::new();
    cdvol::with_word!(h.storage, W => {
        let words: Vec<W> = (0..n)
            .map(|i| {
                let r = mix(seed.wrapping_add(i as u64));
                if r.is_multiple_of(3) {
                    W::code(&enc, (r >> 8) as u32 % (enc.max_code() + 1))
                } else {
                    W::from_raw(specials[(r >> 8) as usize % specials.len()])
                }
            })
            .collect();
        out.extend_from_slice(bytemuck::cast_slice(&words));
    });
    out
}

fn reader_case() -> impl Strategy<Value = (usize, Vec<Mutation>)> {
    (0usize..3, proptest::collection::vec(mutation(), 0..4))
}

/// Opens, inspects, reads, renders and exports `bytes` (as `path`);
/// everything must be `Ok` or `Err`. With `must_work` (the unmutated
/// base), everything must be `Ok`.
fn exercise(path: &Path, bytes: &[u8], must_work: bool) -> Result<(), TestCaseError> {
    let file = path.file_name().unwrap().to_string_lossy().into_owned();
    std::fs::write(path, bytes).unwrap();
    let vol = match PackedVolume::open(path) {
        Ok(v) => v,
        Err(e) => {
            tally(OPEN_ERR);
            let m = e.to_string();
            prop_assert!(!must_work, "base refused: {m}");
            prop_assert!(m.contains(&file), "open error names no file: {m}");
            return Ok(());
        }
    };
    tally(OPENED);
    let info = Info::of(&vol);
    let _ = info.to_text();
    let _ = serde_json::to_string(&info);
    let h = vol.header().clone();
    // Read and classify a bounded number of bricks.
    for id in 0..h.brick_count().min(64) {
        match vol.read_brick(id) {
            Ok(b) => {
                if let BrickData::Words { .. } = b.data {
                    let [sx, sy, sz] = b.samples;
                    for z in 0..sz - 1 {
                        for y in 0..sy - 1 {
                            for x in 0..sx - 1 {
                                let _ = vol.cell_class(&b, [x, y, z]);
                            }
                        }
                    }
                }
            }
            Err(e) => {
                prop_assert!(!must_work, "base brick {id}: {e}");
                prop_assert!(
                    e.to_string().contains(&file),
                    "brick error names no file: {e}"
                );
            }
        }
    }
    // Render a tiny image in every mode.
    let bounds = TGrid::<f64>::new(&h.axes).bounds();
    if let Ok(cam) = Camera::orbit(bounds, 33.0, 21.0, None, None, 6, 5) {
        let tf = match &h.classification {
            Classification::Iso { iso } => TransferFunction {
                points: vec![
                    TfPoint {
                        value: *iso,
                        opacity: 0.0,
                        color: [1.0; 3],
                    },
                    TfPoint {
                        value: iso + iso.abs().max(1.0) * 1e-3,
                        opacity: 0.5,
                        color: [1.0; 3],
                    },
                ],
            },
            Classification::TransferFunction { tf } => tf.clone(),
        };
        let span = (0..3)
            .map(|k| bounds.1[k] - bounds.0[k])
            .fold(0.0, f64::max);
        let modes = [
            Mode::Mip,
            Mode::Cost,
            Mode::Depth {
                hit: HitMethod::Int,
            },
            Mode::Surface {
                hit: HitMethod::Exact,
                shadows: true,
            },
            Mode::Composite {
                tf,
                step_mm: (span / 16.0).max(0.05),
            },
        ];
        let mut methods = vec![Method::Fvt, Method::Cd { min_leap: 1 }];
        if h.aniso_block.is_some() {
            methods.push(Method::CdAniso { min_leap: 1 });
        }
        for mode in &modes {
            for &method in &methods {
                let o = RenderOptions {
                    mode: mode.clone(),
                    method,
                    tile: 4,
                    cache_bytes: 256 << 10,
                    cd_lazy_min: Some(4),
                    ..RenderOptions::new(mode.clone(), method)
                };
                match render(&vol, &cam, &o, &NoProgress) {
                    Ok((f, _)) => {
                        tally(RENDER_OK);
                        prop_assert_eq!(f.rgb.len(), 6 * 5 * 3)
                    }
                    Err(e) => {
                        tally(RENDER_ERR);
                        let m = e.to_string();
                        let refusal = matches!(e, RenderError::Incompatible { .. })
                            && matches!(
                                (mode, &h.classification),
                                (
                                    Mode::Surface { .. } | Mode::Depth { .. },
                                    Classification::TransferFunction { .. }
                                )
                            );
                        prop_assert!(!must_work || refusal, "base render {mode:?}: {m}");
                        if let RenderError::Format(_) = e {
                            prop_assert!(m.contains(&file), "render error names no file: {m}");
                        }
                    }
                }
            }
        }
    } else {
        prop_assert!(!must_work, "no camera for the base");
    }
    // Export, when small.
    let cells: u64 = h.cells().iter().product();
    if cells <= 200_000 {
        for (what, name) in [
            (ExportWhat::Values, "values.json"),
            (ExportWhat::Codes, "codes.json"),
            (ExportWhat::Classes, "classes.json"),
        ] {
            let out = path.with_file_name(name);
            match export(&vol, what, &out, &NoProgress) {
                Ok(_) => tally(EXPORT_OK),
                Err(e) => prop_assert!(!must_work, "base export {what:?}: {e}"),
            }
        }
    }
    Ok(())
}

/// Whether `Info::to_text`'s u64 arithmetic on the code histogram
/// overflows: the sum of the counts, or 40 times one of them.
/// How deep the reader cases got: open refused, opened, renders that
/// worked and that failed, exports that worked.
static OUTCOMES: [AtomicU64; 5] = [const { AtomicU64::new(0) }; 5];
const OPEN_ERR: usize = 0;
const OPENED: usize = 1;
const RENDER_OK: usize = 2;
const RENDER_ERR: usize = 3;
const EXPORT_OK: usize = 4;

fn tally(i: usize) {
    OUTCOMES[i].fetch_add(1, Ordering::Relaxed);
}

/// Found by this fuzz, fixed (saturating sums, bars from fractions):
/// `cdvol info`'s text (src/info.rs, `Info::to_text`) added up and scaled
/// the header's code histogram in u64 unchecked: a header (valid CRC) whose
/// `summary.code_histogram` holds counts near 2^64 panics with "attempt to
/// add with overflow" (line 164, the `sum()`) or "attempt to multiply with
/// overflow" (line 188, `40 * n`) where overflow checks are on (debug and
/// test builds). In release builds the sum wraps instead, and `"#".repeat(
/// (40 * n) / total)` then asks for as many bytes as the wrapped numbers
/// say: with counts [2^28, 2^64 - 2^28 + 1] the total wraps to 1 and the
/// first bar is 40 * 2^28 bytes (10 GiB).
#[test]
fn found_info_text_overflow_is_fixed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.cdv");
    for hist in [
        vec![u64::MAX, 1],
        vec![u64::MAX / 2],
        vec![1 << 28, u64::MAX - (1 << 28) + 2],
    ] {
        let b = &bases()[0];
        let (t, h, _) = layout(&b.bytes).unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&b.bytes[t..t + h]).unwrap();
        json["summary"]["code_histogram"] = serde_json::json!(hist);
        let text = serde_json::to_vec(&json).unwrap();
        let n = b.bytes.len();
        std::fs::write(
            &path,
            assemble(
                &b.bytes,
                &b.bytes[..t],
                &text,
                &b.bytes[t + h..n - 40],
                true,
            ),
        )
        .unwrap();
        let vol = PackedVolume::open(&path).unwrap();
        let text = std::panic::catch_unwind(|| Info::of(&vol).to_text());
        let text = text.unwrap_or_else(|_| panic!("to_text panicked on {hist:?}"));
        // Bars are at most 40 characters: the text stays small.
        assert!(text.len() < 64 * 1024, "{} bytes for {hist:?}", text.len());
    }
}

/// Per-process scratch directory under target/tmp; removed when the test
/// passes, so after a crash (abort) it holds the input that caused it.
fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("cdvol-fuzz-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn fuzz_packed_reader() {
    let dir = scratch("reader");
    let path = dir.join("case.cdv");
    let bases = bases();
    // The unmutated bases work.
    for b in bases {
        LARGEST.store(0, Ordering::Relaxed);
        exercise(&path, &b.bytes, true).unwrap_or_else(|e| panic!("{}: {e}", b.name));
    }
    fuzz(
        "fuzz::fuzz_packed_reader",
        reader_case(),
        |(which, muts)| {
            let base = &bases[which];
            let mut bytes = base.bytes.clone();
            for m in &muts {
                bytes = apply(bytes, m, base);
            }
            LARGEST.store(0, Ordering::Relaxed);
            exercise(&path, &bytes, bytes == base.bytes)?;
            let largest = LARGEST.load(Ordering::Relaxed);
            prop_assert!(
                largest <= ALLOC_LIMIT,
                "an allocation of {largest} bytes ({} file bytes)",
                bytes.len()
            );
            Ok(())
        },
    );
    let o = OUTCOMES.each_ref().map(|a| a.load(Ordering::Relaxed));
    eprintln!(
        "cdvol-fuzz: fuzz::fuzz_packed_reader: outcomes: {} refused at open, {} opened, \
         {} renders ok, {} renders refused, {} exports ok",
        o[OPEN_ERR], o[OPENED], o[RENDER_OK], o[RENDER_ERR], o[EXPORT_OK]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

// ---- (b) the traversal ----

/// An f64 from any bit pattern, weighted towards the special ones.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => any::<u64>().prop_map(f64::from_bits),
        1 => prop::sample::select(vec![
            0.0, -0.0, f64::NAN, -f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX, -f64::MAX,
            f64::MIN_POSITIVE, -f64::MIN_POSITIVE, 5e-324, -5e-324, 1e-300, 1e300,
            cdvol::render::traverse::MIN_DIR, cdvol::render::traverse::MIN_DIR * 0.5,
            f64::from_bits(0x7ff0_0000_0000_0001), // signalling NaN
        ]),
    ]
}

/// Strictly increasing coordinates of one axis with `n` samples.
fn axis(n: usize) -> impl Strategy<Value = Vec<f64>> {
    let gap = prop_oneof![
        4 => 0.05f64..4.0,
        1 => Just(1e-9),
        1 => Just(1e4),
        1 => 1e-6f64..1e-3,
    ];
    prop_oneof![
        // Sane: an offset and gaps.
        4 => (
            prop_oneof![3 => -10.0f64..10.0, 1 => Just(1e6), 1 => Just(-1e6), 1 => Just(1e12)],
            proptest::collection::vec(gap, n - 1),
        )
            .prop_map(|(o, g)| {
                let mut c = vec![o];
                for x in g {
                    c.push(c[c.len() - 1] + x);
                }
                c
            }),
        // Wild: arbitrary bit patterns, sorted.
        1 => proptest::collection::vec(any_f64(), n..n + 4),
        // One ulp apart around a random value.
        1 => (-1e9f64..1e9).prop_map(move |x| {
            let mut c = vec![x];
            for _ in 1..n {
                let l = c[c.len() - 1];
                c.push(if l == 0.0 {
                    5e-324
                } else if l > 0.0 {
                    f64::from_bits(l.to_bits() + 1)
                } else {
                    f64::from_bits(l.to_bits() - 1)
                });
            }
            c
        }),
    ]
    .prop_map(|mut c| {
        c.retain(|x| x.is_finite());
        c.sort_by(f64::total_cmp);
        c.dedup_by(|a, b| a == b);
        while c.len() < 2 {
            // A second coordinate that differs from the first: halving
            // (|l| > 1) or adding 1 (|l| <= 1) always changes l.
            let l = c.last().copied().unwrap_or(0.0);
            c.push(if l.abs() > 1.0 { l * 0.5 } else { l + 1.0 });
            c.sort_by(f64::total_cmp);
            c.dedup_by(|a, b| a == b);
        }
        c
    })
}

#[derive(Debug, Clone)]
struct TraceCase {
    axes: [Vec<f64>; 3],
    objects: Vec<[u32; 3]>,
    rays: Vec<([f64; 3], [f64; 3], f64)>,
}

fn trace_case() -> impl Strategy<Value = TraceCase> {
    prop_oneof![
        4 => (2usize..9, 2usize..9, 2usize..9),
        1 => (2usize..3000, 2usize..4, 2usize..4),
        1 => (2usize..4, 2usize..4, 2usize..3000),
    ]
    .prop_flat_map(|(x, y, z)| (axis(x), axis(y), axis(z), 0u32..101, any::<u64>()))
    .prop_flat_map(|(ax, ay, az, pct, seed)| {
        let n = [ax.len() - 1, ay.len() - 1, az.len() - 1].map(|c| c as u32);
        let total = n[0] as u64 * n[1] as u64 * n[2] as u64;
        // Dense volumes get their 1-cells by density, long ones a few.
        let objects: Vec<[u32; 3]> = if total <= 512 {
            (0..total)
                .filter(|&i| mix(seed ^ i) % 100 < pct as u64)
                .map(|i| {
                    let i = i as u32;
                    [i % n[0], i / n[0] % n[1], i / (n[0] * n[1])]
                })
                .collect()
        } else {
            (0..(pct as u64 % 12))
                .map(|j| {
                    let r = mix(seed ^ (j * 7919));
                    [
                        (r % n[0] as u64) as u32,
                        (r >> 20) as u32 % n[1],
                        (r >> 40) as u32 % n[2],
                    ]
                })
                .collect()
        };
        let axes = [ax, ay, az];
        let near = |a: &Vec<f64>| {
            let (lo, hi) = (a[0], a[a.len() - 1]);
            let c = a.clone();
            prop_oneof![
                2 => (0.0f64..1.0).prop_map(move |f| lo + f * (hi - lo)),
                2 => (0..c.len()).prop_map(move |i| c[i]),
                1 => Just(lo - 1e9),
                2 => any_f64(),
            ]
        };
        let origin = [near(&axes[0]), near(&axes[1]), near(&axes[2])];
        let dcomp = || {
            prop_oneof![
                3 => -1.0f64..1.0,
                1 => Just(0.0),
                1 => Just(-0.0),
                3 => any_f64(),
            ]
        };
        let t_min = prop_oneof![6 => Just(0.0), 1 => -1e3f64..1e3, 1 => any_f64()];
        let rays = proptest::collection::vec((origin, [dcomp(), dcomp(), dcomp()], t_min), 1..10);
        (Just(axes), Just(objects), rays)
    })
    .prop_map(|(axes, objects, rays)| TraceCase {
        axes,
        objects,
        rays,
    })
}

static REFUSED_GRIDS: AtomicU64 = AtomicU64::new(0);

fn check_trace_case(c: &TraceCase) -> Result<(), TestCaseError> {
    let axes: Result<Vec<Axis>, _> = c
        .axes
        .iter()
        .map(|a| Axis::from_coords(a.clone()))
        .collect();
    let Ok(axes) = axes else {
        // Positions beyond MAX_COORD_MM: refused, as prep refuses them.
        REFUSED_GRIDS.fetch_add(1, Ordering::Relaxed);
        return Ok(());
    };
    let axes: [Axis; 3] = axes.try_into().expect("three axes");
    let vol = MemVolume::new(axes, c.objects.clone());
    let g64 = TGrid::<f64>::new(&vol.axes);
    let g32 = TGrid::<f32>::new(&vol.axes);
    for &(origin, dir, t_min) in &c.rays {
        let ray = Ray {
            origin: origin.into(),
            dir: dir.into(),
        };
        let valid = ray.check().is_ok() && t_min.is_finite();
        let what = format!("ray {ray:?} t_min {t_min}");
        let mut first: [Option<Vec<Visit>>; 2] = [None, None];
        for m in [
            Method::Fvt,
            Method::Cd { min_leap: 1 },
            Method::Cd { min_leap: 3 },
        ] {
            let w64 = corpus::walk_from(&vol, &g64, &ray, t_min, m);
            let w32 = corpus::walk_from(&vol, &g32, &ray, t_min, m);
            for (w, arith) in [(&w64, "f64"), (&w32, "f32")] {
                let what = format!("{what} {m:?} {arith}");
                if !valid {
                    prop_assert!(
                        w.visits.is_empty() && w.steps == 0,
                        "{what}: refused ray walked {} steps, {} visits",
                        w.steps,
                        w.visits.len()
                    );
                } else {
                    let t_min = (arith == "f64").then_some(t_min);
                    if let Err(e) = corpus::check_walk(&vol, w, t_min) {
                        return Err(TestCaseError::fail(format!("{what}: {e}")));
                    }
                }
            }
            for (slot, w) in first.iter_mut().zip([w64, w32]) {
                match slot {
                    None => *slot = Some(w.visits),
                    Some(f) => prop_assert!(*f == w.visits, "{what}: {m:?} visits differ from FVT"),
                }
            }
        }
    }
    Ok(())
}

#[test]
fn fuzz_traversal() {
    fuzz("fuzz::fuzz_traversal", trace_case(), |c| {
        check_trace_case(&c)
    });
    eprintln!(
        "cdvol-fuzz: fuzz::fuzz_traversal: {} grids refused (positions beyond MAX_COORD_MM)",
        REFUSED_GRIDS.load(Ordering::Relaxed)
    );
}

/// Found by this fuzz: `trace` reported `t_exit = inf` for grids spanning
/// ~1e300 mm (a plane crossing beyond f64::MAX), and empty visits
/// (`t_enter == t_exit == 0`) for directions above 2^1022, whose
/// parameter was rescaled and underflowed when reported. Now positions
/// and origins beyond `MAX_COORD_MM` and directions outside
/// [`MIN_DIR`, `MAX_DIR`] are refused with errors that say so, and at
/// those limits every visit has a finite, positive-length `t` interval.
#[test]
fn found_t_overflow_and_underflow_are_fixed() {
    use cdvol::grid::MAX_COORD_MM;
    use cdvol::render::traverse::{MAX_DIR, MIN_DIR};
    let e = Axis::from_coords(vec![0.0, 1e300]).unwrap_err();
    assert!(e.to_string().contains("expected at most"), "{e}");
    let e = Ray::new([0.5; 3], [0.0, f64::MAX, 0.0]).unwrap_err();
    assert!(e.to_string().contains("too long"), "{e}");
    let e = Ray::new([-1e308, 0.5, 0.5], [1.0, 0.0, 0.0]).unwrap_err();
    assert!(e.to_string().contains("from 0"), "{e}");
    let unit = || Axis::from_coords(vec![0.0, 1.0]).unwrap();
    // The widest grid, crossed as slowly as allowed: t near 2^651.
    let wide = Axis::from_coords(vec![-MAX_COORD_MM, 0.0, MAX_COORD_MM]).unwrap();
    let vol = MemVolume::new([wide, unit(), unit()], vec![[0, 0, 0], [1, 0, 0]]);
    let g = TGrid::<f64>::new(&vol.axes);
    let ray = Ray::new([-MAX_COORD_MM, 0.5, 0.5], [MIN_DIR, 0.0, 0.0]).unwrap();
    let w = corpus::walk(&vol, &g, &ray, Method::Fvt);
    assert_eq!(w.visits.len(), 2, "{:?}", w.visits);
    for v in &w.visits {
        assert!(v.t_exit.is_finite() && v.t_enter < v.t_exit, "{v:?}");
    }
    // The fastest direction over the thinnest cells: t near 2^-600 * 1e-20.
    let y = Axis::from_coords(vec![0.0, 1e-20, 2e-20]).unwrap();
    let vol = MemVolume::new([unit(), y, unit()], vec![[0, 0, 0], [0, 1, 0]]);
    let g = TGrid::<f64>::new(&vol.axes);
    let ray = Ray::new([0.5, -1e-20, 0.5], [0.0, MAX_DIR, 0.0]).unwrap();
    let w = corpus::walk(&vol, &g, &ray, Method::Fvt);
    assert_eq!(w.visits.len(), 2, "{:?}", w.visits);
    for v in &w.visits {
        assert!(v.t_enter < v.t_exit && v.t_enter > 0.0, "{v:?}");
    }
}

// ---- (c)-(f) the input readers ----

/// A byte-level mutation of one file (or one region of it).
#[derive(Debug, Clone)]
enum ByteMut {
    Flip {
        at: Index,
        bit: u8,
    },
    Set {
        at: Index,
        value: u8,
    },
    Truncate {
        keep: Index,
    },
    Append(Vec<u8>),
    /// `del` bytes at `at` replaced by `bytes`.
    Splice {
        at: Index,
        del: usize,
        bytes: Vec<u8>,
    },
}

fn byte_mut() -> impl Strategy<Value = ByteMut> {
    let bytes = prop_oneof![
        3 => proptest::collection::vec(any::<u8>(), 0..16),
        1 => proptest::collection::vec(prop::sample::select(vec![0u8, 0xff, b'\n', b' ', b'-', b'9']), 1..8),
    ];
    prop_oneof![
        3 => (any::<Index>(), 0u8..8).prop_map(|(at, bit)| ByteMut::Flip { at, bit }),
        3 => (any::<Index>(), any::<u8>()).prop_map(|(at, value)| ByteMut::Set { at, value }),
        1 => any::<Index>().prop_map(|keep| ByteMut::Truncate { keep }),
        1 => proptest::collection::vec(any::<u8>(), 1..48).prop_map(ByteMut::Append),
        2 => (any::<Index>(), 0usize..8, bytes)
            .prop_map(|(at, del, bytes)| ByteMut::Splice { at, del, bytes }),
    ]
}

fn apply_bytes(b: &mut Vec<u8>, m: &ByteMut) {
    let n = b.len();
    match m {
        ByteMut::Flip { at, bit } if n > 0 => b[at.index(n)] ^= 1 << bit,
        ByteMut::Set { at, value } if n > 0 => b[at.index(n)] = *value,
        ByteMut::Truncate { keep } if n > 0 => b.truncate(keep.index(n)),
        ByteMut::Append(x) => b.extend_from_slice(x),
        ByteMut::Splice { at, del, bytes } => {
            let i = if n == 0 { 0 } else { at.index(n) };
            let j = (i + del).min(n);
            b.splice(i..j, bytes.iter().copied());
        }
        _ => {}
    }
}

/// `m` applied to `b[range]` only (a truncation cuts the region short,
/// keeping what follows it).
fn apply_region(b: &mut Vec<u8>, range: std::ops::Range<usize>, m: &ByteMut) {
    let (lo, hi) = (range.start.min(b.len()), range.end.min(b.len()));
    let mut mid = b[lo..hi].to_vec();
    apply_bytes(&mut mid, m);
    b.splice(lo..hi, mid);
}

/// Corruption of a gzip stream: its 10-byte member header, its deflate
/// data or its 8-byte trailer (CRC-32, ISIZE).
#[derive(Debug, Clone)]
struct GzMut {
    part: u8,
    at: Index,
    value: u8,
}

fn gz_mut() -> impl Strategy<Value = GzMut> {
    (0u8..3, any::<Index>(), any::<u8>()).prop_map(|(part, at, value)| GzMut { part, at, value })
}

fn apply_gz(b: &mut [u8], m: &GzMut) {
    let n = b.len();
    if n < 18 {
        return;
    }
    let (lo, hi) = match m.part {
        0 => (0, 10),
        1 => (10, n - 8),
        _ => (n - 8, n),
    };
    if hi > lo {
        b[lo + m.at.index(hi - lo)] = m.value;
    }
}

fn gzip(b: &[u8]) -> Vec<u8> {
    common::gz(b)
}

/// How deep the cases of one reader target got.
struct ReaderTally {
    refused: AtomicU64,
    opened: AtomicU64,
    read: AtomicU64,
    read_refused: AtomicU64,
}

impl ReaderTally {
    const fn new() -> ReaderTally {
        ReaderTally {
            refused: AtomicU64::new(0),
            opened: AtomicU64::new(0),
            read: AtomicU64::new(0),
            read_refused: AtomicU64::new(0),
        }
    }

    fn report(&self, name: &str) {
        let l = |a: &AtomicU64| a.load(Ordering::Relaxed);
        eprintln!(
            "cdvol-fuzz: {name}: outcomes: {} refused at open, {} opened, {} read whole, \
             {} refused while reading",
            l(&self.refused),
            l(&self.opened),
            l(&self.read),
            l(&self.read_refused)
        );
    }
}

/// Opens `path` with `cdvol::input::open` and, if it opens, reads every
/// slice. Everything must be `Ok` or `Err` (a panic fails the case); an
/// error must contain one of `names` (the file names of the case); an
/// opened volume may not hold more sample bytes than `input_bytes` can
/// (1032 times, what deflate can expand to); no allocation may exceed
/// [`ALLOC_LIMIT`]. With `expect` (an unmutated base), the volume must
/// open and read back exactly those raw samples.
fn read_input(
    path: &Path,
    names: &[String],
    input_bytes: u64,
    expect: Option<&[f64]>,
    tally: &ReaderTally,
) -> Result<(), TestCaseError> {
    LOCAL_LARGEST.with(|c| c.set(Some(0)));
    let r = read_input_inner(path, names, input_bytes, expect, tally);
    let largest = LOCAL_LARGEST.with(|c| c.get()).unwrap_or(0);
    prop_assert!(
        largest <= ALLOC_LIMIT,
        "an allocation of {largest} bytes ({input_bytes} input bytes)"
    );
    r
}

fn read_input_inner(
    path: &Path,
    names: &[String],
    input_bytes: u64,
    expect: Option<&[f64]>,
    tally: &ReaderTally,
) -> Result<(), TestCaseError> {
    let named = |m: &str| names.iter().any(|n| m.contains(n.as_str()));
    let src = match cdvol::input::open(path) {
        Ok(s) => s,
        Err(e) => {
            tally.refused.fetch_add(1, Ordering::Relaxed);
            let m = e.to_string();
            prop_assert!(expect.is_none(), "base refused: {m}");
            prop_assert!(named(&m), "open error names none of {names:?}: {m}");
            return Ok(());
        }
    };
    tally.opened.fetch_add(1, Ordering::Relaxed);
    let meta = src.meta().clone();
    let [nx, ny, nz] = meta.dims();
    let bytes = (nx as u128) * (ny as u128) * (nz as u128) * meta.dtype.size() as u128;
    prop_assert!(
        bytes <= input_bytes as u128 * 1032,
        "opened {nx} x {ny} x {nz} samples of {} from {input_bytes} input bytes",
        meta.dtype.name()
    );
    let _ = (src.report(), src.files());
    let mut all = Vec::new();
    let mut slice = vec![0.0; nx * ny];
    for z in 0..nz {
        if let Err(e) = src.read_slice(z, &mut slice) {
            tally.read_refused.fetch_add(1, Ordering::Relaxed);
            let m = e.to_string();
            prop_assert!(expect.is_none(), "base slice {z}: {m}");
            prop_assert!(named(&m), "slice {z} error names none of {names:?}: {m}");
            return Ok(());
        }
        if expect.is_some() {
            all.extend_from_slice(&slice);
        }
    }
    tally.read.fetch_add(1, Ordering::Relaxed);
    if let Some(want) = expect {
        let same = all.len() == want.len()
            && all
                .iter()
                .zip(want)
                .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()));
        prop_assert!(same, "base samples differ: {all:?} != {want:?}");
    }
    Ok(())
}

/// Sample values of a small base volume: a ramp with the type's extremes.
fn base_values(n: usize, lo: f64, hi: f64, float: bool) -> Vec<f64> {
    (0..n)
        .map(|i| match i % 11 {
            0 => lo,
            5 => hi,
            _ if float => (i as f64 - 7.0) * 0.375,
            _ => ((mix(i as u64) % 97) as f64 + lo.max(-40.0)).min(hi),
        })
        .collect()
}

/// `values` as samples of `dtype` ("u8", "i16", "i32", "f32", "f64").
fn encode(values: &[f64], dtype: &str, big: bool) -> Vec<u8> {
    let mut out = Vec::new();
    for &v in values {
        let b: Vec<u8> = match (dtype, big) {
            ("u8", _) => vec![v as u8],
            ("i16", false) => (v as i16).to_le_bytes().to_vec(),
            ("i16", true) => (v as i16).to_be_bytes().to_vec(),
            ("i32", false) => (v as i32).to_le_bytes().to_vec(),
            ("i32", true) => (v as i32).to_be_bytes().to_vec(),
            ("f32", false) => (v as f32).to_le_bytes().to_vec(),
            ("f32", true) => (v as f32).to_be_bytes().to_vec(),
            ("f64", false) => v.to_le_bytes().to_vec(),
            ("f64", true) => v.to_be_bytes().to_vec(),
            _ => panic!("dtype {dtype}"),
        };
        out.extend_from_slice(&b);
    }
    out
}

// -- (c) NRRD --

/// A valid NRRD input: header lines (magic first), the samples (after
/// `skip` junk bytes), and whether they are gzip'd and detached.
struct NrrdBase {
    lines: Vec<String>,
    /// The decompressed data stream: skipped bytes, then the samples.
    stream: Vec<u8>,
    values: Vec<f64>,
    gzip: bool,
    detached: bool,
}

fn nrrd_bases() -> &'static [NrrdBase] {
    static B: OnceLock<Vec<NrrdBase>> = OnceLock::new();
    B.get_or_init(|| {
        let base = |fields: &[(&str, &str)],
                    dims: [usize; 3],
                    dtype: &str,
                    big: bool,
                    skip: &[u8],
                    gzip: bool,
                    detached: bool| {
            let (lo, hi, float) = match dtype {
                "u8" => (0.0, 255.0, false),
                "i16" => (-32768.0, 32767.0, false),
                "i32" => (-2147483648.0, 2147483647.0, false),
                _ => (f32::MIN as f64, f32::MAX as f64, true),
            };
            let values = base_values(dims.iter().product(), lo, hi, float);
            let mut stream = skip.to_vec();
            stream.extend_from_slice(&encode(&values, dtype, big));
            let mut lines = vec!["NRRD0004".to_string(), "# cdvol fuzz base".to_string()];
            lines.extend(fields.iter().map(|(k, v)| format!("{k}: {v}")));
            NrrdBase {
                lines,
                stream,
                values,
                gzip,
                detached,
            }
        };
        vec![
            base(
                &[
                    ("type", "short"),
                    ("dimension", "3"),
                    ("space", "left-posterior-superior"),
                    ("sizes", "5 4 3"),
                    ("space directions", "(0.5,0,0) (0,-0.75,0) (0,0,2)"),
                    ("kinds", "domain domain domain"),
                    ("endian", "little"),
                    ("encoding", "raw"),
                    ("space origin", "(-10,5,3)"),
                ],
                [5, 4, 3],
                "i16",
                false,
                &[],
                false,
                false,
            ),
            base(
                &[
                    ("type", "float"),
                    ("dimension", "3"),
                    ("sizes", "4 3 3"),
                    ("spacings", "1 1.5 0.25"),
                    ("endian", "big"),
                    ("encoding", "gzip"),
                    ("byte skip", "3"),
                ],
                [4, 3, 3],
                "f32",
                true,
                b"abc",
                true,
                false,
            ),
            base(
                &[
                    ("type", "uchar"),
                    ("dimension", "3"),
                    ("sizes", "6 3 2"),
                    ("spacings", "1 1 1"),
                    ("encoding", "raw"),
                    ("byte skip", "7"),
                    ("line skip", "0"),
                    ("data file", "case.raw"),
                ],
                [6, 3, 2],
                "u8",
                false,
                b"skipped",
                false,
                true,
            ),
            base(
                &[
                    ("type", "int"),
                    ("dimension", "3"),
                    ("sizes", "3 3 4"),
                    ("space", "RAS"),
                    ("space directions", "(-1,0,0) (0,2,0) (0,0,0.5)"),
                    ("endian", "little"),
                    ("encoding", "gz"),
                    ("datafile", "case.raw"),
                ],
                [3, 3, 4],
                "i32",
                false,
                &[],
                true,
                true,
            ),
        ]
    })
}

const NRRD_FIELDS: &[&str] = &[
    "dimension",
    "type",
    "sizes",
    "encoding",
    "endian",
    "byte skip",
    "line skip",
    "spacings",
    "space directions",
    "space origin",
    "space",
    "data file",
    "datafile",
    "kinds",
];

const NRRD_VALUES: &[&str] = &[
    "18446744073709551615",
    "18446744073709551616",
    "9223372036854775807",
    "-9223372036854775808",
    "4294967296",
    "-1",
    "-0",
    "0",
    "1",
    "2",
    "3",
    "4",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "",
    "x",
    "3 3",
    "5 4 3",
    "6 3 2",
    "2 2 2",
    "2 2 2 2",
    "1048576 1048576 1048576",
    "1048577 2 2",
    "65535 65535 65535",
    "2 2 18446744073709551615",
    "4294967296 4294967296 4294967296",
    "-5 4 3",
    "1e308 2 2",
    "1 1 1",
    "1e308 1e308 1e308",
    "nan nan nan",
    "inf 1 1",
    "-1 -1 -1",
    "0 0 0",
    "1e-300 1 1",
    "5e-324 1 1",
    "(1,0,0) (0,1,0) (0,0,1)",
    "(1e308,0,0) (0,1e308,0) (0,0,1e308)",
    "(nan,0,0) (0,1,0) (0,0,1)",
    "(inf,0,0) (0,1,0) (0,0,1)",
    "(0,0,0) (0,1,0) (0,0,1)",
    "(-1,0,0) (0,-1,0) (0,0,-1)",
    "(1,1,0) (0,1,0) (0,0,1)",
    "(1e-300,0,0) (0,1,0) (0,0,1)",
    "none (1,0,0) (0,1,0)",
    "(1,0,0) (0,1,0)",
    "(1,0) (0,1) (0,0)",
    "(1,0,0",
    "(1e308,1e308,1e308)",
    "(-1e308,0,0)",
    "(nan,nan,nan)",
    "(1,2)",
    "()",
    "uchar",
    "signed char",
    "short",
    "ushort",
    "int",
    "uint",
    "int64",
    "uint64",
    "float",
    "double",
    "block",
    "raw",
    "gzip",
    "gz",
    "bzip2",
    "ascii",
    "hex",
    "little",
    "big",
    "middle",
    "case.raw",
    "case.nrrd",
    "case.nhdr",
    "missing.raw",
    "/",
    ".",
    "..",
    "/dev/null",
    "/dev/zero",
    "LIST",
    "LIST 2",
    "case-%d.raw 0 2 1",
    "LPS",
    "RAS",
    "left-anterior-superior",
    "scanner-xyz",
];

/// Odd lines inserted into an NRRD header.
const NRRD_LINES: &[&str] = &[
    "",
    "#",
    "sizes: 5 4 3",
    "sizes: 18446744073709551615 2 2",
    "type: float",
    "encoding: gzip",
    "byte skip: -1",
    "byte skip: 18446744073709551615",
    "data file: case.raw",
    "space directions: (1,0,0) (0,1,0) (0,0,1)",
    "key:=value",
    "no colon here",
    ": empty key",
    "sizes:",
    "NRRD0004",
    "\u{feff}type: short",
    "dimension: 3\r",
    "line skip: 1",
];

#[derive(Debug, Clone)]
enum NrrdMut {
    /// `field: value` replacing the field's line (or added).
    Field {
        field: usize,
        value: usize,
    },
    InsertLine {
        at: Index,
        line: String,
    },
    DeleteLine {
        at: Index,
    },
    /// Bytes of the header text (with its end: the empty line, when
    /// attached).
    Header(ByteMut),
    /// Bytes of the decompressed data stream (skipped bytes and samples).
    Samples(ByteMut),
    /// Bytes of the stored data (the gzip stream when gzip'd).
    Stored(ByteMut),
    Gz(GzMut),
}

fn nrrd_mut() -> impl Strategy<Value = NrrdMut> {
    prop_oneof![
        8 => (0..NRRD_FIELDS.len(), 0..NRRD_VALUES.len())
            .prop_map(|(field, value)| NrrdMut::Field { field, value }),
        2 => (
            any::<Index>(),
            prop_oneof![
                3 => prop::sample::select(NRRD_LINES).prop_map(String::from),
                1 => "[ -~]{0,16}",
            ],
        )
            .prop_map(|(at, line)| NrrdMut::InsertLine { at, line }),
        2 => any::<Index>().prop_map(|at| NrrdMut::DeleteLine { at }),
        3 => byte_mut().prop_map(NrrdMut::Header),
        2 => byte_mut().prop_map(NrrdMut::Samples),
        2 => byte_mut().prop_map(NrrdMut::Stored),
        2 => gz_mut().prop_map(NrrdMut::Gz),
    ]
}

/// The files of an NRRD case: (file name, bytes), the header first.
fn nrrd_files(base: &NrrdBase, muts: &[NrrdMut]) -> Vec<(String, Vec<u8>)> {
    let mut lines = base.lines.clone();
    for m in muts {
        match m {
            NrrdMut::Field { field, value } => {
                let (k, v) = (NRRD_FIELDS[*field], NRRD_VALUES[*value]);
                let line = format!("{k}: {v}");
                let prefix = format!("{k}:");
                match lines.iter().position(|l| l.starts_with(&prefix)) {
                    Some(i) => lines[i] = line,
                    None => lines.push(line),
                }
            }
            NrrdMut::InsertLine { at, line } => {
                let i = at.index(lines.len() + 1);
                lines.insert(i, line.clone());
            }
            NrrdMut::DeleteLine { at } if !lines.is_empty() => {
                lines.remove(at.index(lines.len()));
            }
            _ => {}
        }
    }
    let mut header = lines.join("\n").into_bytes();
    header.extend_from_slice(if base.detached { b"\n" } else { b"\n\n" });
    let mut stream = base.stream.clone();
    for m in muts {
        match m {
            NrrdMut::Header(b) => apply_bytes(&mut header, b),
            NrrdMut::Samples(b) => apply_bytes(&mut stream, b),
            _ => {}
        }
    }
    let mut stored = if base.gzip { gzip(&stream) } else { stream };
    for m in muts {
        match m {
            NrrdMut::Stored(b) => apply_bytes(&mut stored, b),
            NrrdMut::Gz(g) if base.gzip => apply_gz(&mut stored, g),
            _ => {}
        }
    }
    if base.detached {
        vec![("case.nhdr".into(), header), ("case.raw".into(), stored)]
    } else {
        header.extend_from_slice(&stored);
        vec![("case.nrrd".into(), header)]
    }
}

/// The file name in the last `data file` line of an NRRD header, if any.
fn nrrd_data_name(header: &[u8]) -> Option<String> {
    let text = String::from_utf8_lossy(header);
    text.lines()
        .filter_map(|l| {
            let l = l.trim_end_matches('\r');
            l.strip_prefix("data file: ")
                .or_else(|| l.strip_prefix("datafile: "))
        })
        .next_back()
        .and_then(|v| Path::new(v.trim()).file_name())
        .map(|n| n.to_string_lossy().into_owned())
}

/// Writes `files` into `dir` (emptied of earlier cases' files first) and
/// returns their total size.
fn write_case(dir: &Path, files: &[(String, Vec<u8>)]) -> u64 {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            std::fs::remove_dir_all(&p).unwrap();
        } else {
            std::fs::remove_file(&p).unwrap();
        }
    }
    let mut total = 0;
    for (name, bytes) in files {
        let p = dir.join(name);
        if let Some(d) = p.parent() {
            std::fs::create_dir_all(d).unwrap();
        }
        std::fs::write(&p, bytes).unwrap();
        total += bytes.len() as u64;
    }
    total
}

static NRRD_TALLY: ReaderTally = ReaderTally::new();

fn nrrd_case(dir: &Path, which: usize, muts: &[NrrdMut]) -> Result<(), TestCaseError> {
    let base = &nrrd_bases()[which];
    let files = nrrd_files(base, muts);
    let total = write_case(dir, &files);
    // An error names the header, or the data file the header names.
    let mut names = vec![files[0].0.clone()];
    names.extend(nrrd_data_name(&files[0].1));
    let expect = muts.is_empty().then_some(&base.values[..]);
    read_input(&dir.join(&files[0].0), &names, total, expect, &NRRD_TALLY)
}

#[test]
fn fuzz_readers_nrrd() {
    let dir = scratch("nrrd");
    for which in 0..nrrd_bases().len() {
        nrrd_case(&dir, which, &[]).unwrap_or_else(|e| panic!("NRRD base {which}: {e}"));
    }
    fuzz(
        "fuzz::fuzz_readers_nrrd",
        (
            0..nrrd_bases().len(),
            proptest::collection::vec(nrrd_mut(), 1..5),
        ),
        |(which, muts)| nrrd_case(&dir, which, &muts),
    );
    NRRD_TALLY.report("fuzz::fuzz_readers_nrrd");
    let _ = std::fs::remove_dir_all(&dir);
}

// -- (d) NIfTI --

/// A valid NIfTI-1 file's bytes (uncompressed), how it is stored, and its
/// samples.
struct NiftiBase {
    bytes: Vec<u8>,
    big: bool,
    gz: bool,
    values: Vec<f64>,
}

fn nifti_bases() -> &'static [NiftiBase] {
    static B: OnceLock<Vec<NiftiBase>> = OnceLock::new();
    B.get_or_init(|| {
        let make = |big: bool, dtype: &str, dims: [i16; 3], gz: bool| {
            let mut h = vec![0u8; 352];
            let w16 = |h: &mut Vec<u8>, at: usize, v: i16| {
                let b = if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                };
                h[at..at + 2].copy_from_slice(&b);
            };
            let w32 = |h: &mut Vec<u8>, at: usize, v: f32| {
                let b = if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                };
                h[at..at + 4].copy_from_slice(&b);
            };
            let sz = if big {
                348i32.to_be_bytes()
            } else {
                348i32.to_le_bytes()
            };
            h[0..4].copy_from_slice(&sz);
            for (k, d) in [3, dims[0], dims[1], dims[2], 1, 1, 1, 1]
                .iter()
                .enumerate()
            {
                w16(&mut h, 40 + 2 * k, *d);
            }
            let (code, bits, lo, hi, float) = match dtype {
                "i16" => (4, 16, -32768.0, 32767.0, false),
                "f32" => (16, 32, f32::MIN as f64, f32::MAX as f64, true),
                _ => panic!(),
            };
            w16(&mut h, 70, code);
            w16(&mut h, 72, bits);
            for (k, p) in [-1.0, 0.75, 1.25, 2.5, 1.0, 0.0, 0.0, 0.0]
                .iter()
                .enumerate()
            {
                w32(&mut h, 76 + 4 * k, *p);
            }
            w32(&mut h, 108, 352.0);
            if !float {
                w32(&mut h, 112, 2.0);
                w32(&mut h, 116, -5.0);
            }
            h[123] = 2; // mm
            w16(&mut h, 252, 1); // qform_code
            w16(&mut h, 254, if float { 0 } else { 1 }); // sform_code
            w32(&mut h, 264, 1.0); // quatern_d: 180 degrees about z
            for (k, o) in [12.5, -3.0, 40.0].iter().enumerate() {
                w32(&mut h, 268 + 4 * k, *o);
            }
            let srow = [
                [-0.75, 0.0, 0.0, 12.5],
                [0.0, -1.25, 0.0, -3.0],
                [0.0, 0.0, 2.5, 40.0],
            ];
            for (r, row) in srow.iter().enumerate() {
                for (c, v) in row.iter().enumerate() {
                    w32(&mut h, 280 + 16 * r + 4 * c, *v);
                }
            }
            h[344..348].copy_from_slice(b"n+1\0");
            let n = dims.iter().map(|&d| d as usize).product();
            let values = base_values(n, lo, hi, float);
            h.extend_from_slice(&encode(&values, dtype, big));
            NiftiBase {
                bytes: h,
                big,
                gz,
                values,
            }
        };
        vec![
            make(false, "i16", [5, 4, 3], false),
            make(false, "i16", [5, 4, 3], true),
            make(true, "f32", [3, 4, 2], false),
            make(true, "f32", [3, 4, 2], true),
        ]
    })
}

#[derive(Debug, Clone, Copy)]
enum Kind {
    I16,
    I32,
    F32,
    U8,
}

/// Header fields: (name, byte offset, kind).
const NIFTI_FIELDS: &[(&str, usize, Kind)] = &[
    ("sizeof_hdr", 0, Kind::I32),
    ("dim[0]", 40, Kind::I16),
    ("dim[1]", 42, Kind::I16),
    ("dim[2]", 44, Kind::I16),
    ("dim[3]", 46, Kind::I16),
    ("dim[4]", 48, Kind::I16),
    ("dim[7]", 54, Kind::I16),
    ("datatype", 70, Kind::I16),
    ("bitpix", 72, Kind::I16),
    ("pixdim[0]", 76, Kind::F32),
    ("pixdim[1]", 80, Kind::F32),
    ("pixdim[2]", 84, Kind::F32),
    ("pixdim[3]", 88, Kind::F32),
    ("vox_offset", 108, Kind::F32),
    ("scl_slope", 112, Kind::F32),
    ("scl_inter", 116, Kind::F32),
    ("xyzt_units", 123, Kind::U8),
    ("qform_code", 252, Kind::I16),
    ("sform_code", 254, Kind::I16),
    ("quatern_b", 256, Kind::F32),
    ("quatern_d", 264, Kind::F32),
    ("qoffset_x", 268, Kind::F32),
    ("qoffset_z", 276, Kind::F32),
    ("srow_x[0]", 280, Kind::F32),
    ("srow_x[3]", 292, Kind::F32),
    ("srow_y[1]", 300, Kind::F32),
    ("srow_z[2]", 320, Kind::F32),
    ("srow_z[3]", 324, Kind::F32),
    ("magic", 344, Kind::I32),
];

const NIFTI_I16: &[i16] = &[
    0, 1, 2, 3, 4, 5, 7, 8, 16, 32, 64, 128, 256, 512, 768, 1024, 1280, 1536, 1792, 2048, 2304, -1,
    -2, -32768, 32767, 255, 348,
];

const NIFTI_F32: &[f32] = &[
    0.0,
    -0.0,
    1.0,
    -1.0,
    0.5,
    2.0,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MAX,
    f32::MIN,
    1e38,
    1e-45,
    1e-30,
    1e-10,
    348.0,
    351.0,
    352.0,
    352.5,
    353.0,
    356.0,
    1e6,
    4294967296.0,
    1.8446744e19,
];

const NIFTI_I32: &[i32] = &[0, 348, 540, -1, i32::MIN, i32::MAX, 0x6e2b3100, 0x6e693100];

#[derive(Debug, Clone)]
enum NiftiMut {
    /// A header field set to one of its kind's special values.
    Field {
        field: usize,
        value: Index,
    },
    /// A header field set to an arbitrary bit pattern.
    FieldBits {
        field: usize,
        bits: u32,
    },
    /// Bytes of the 352-byte header only.
    HeaderByte {
        at: usize,
        value: u8,
    },
    /// Bytes of the whole (uncompressed) file.
    Bytes(ByteMut),
    /// Bytes of the gzip stream (`.nii.gz`).
    Stored(ByteMut),
    Gz(GzMut),
}

fn nifti_mut() -> impl Strategy<Value = NiftiMut> {
    prop_oneof![
        8 => (0..NIFTI_FIELDS.len(), any::<Index>())
            .prop_map(|(field, value)| NiftiMut::Field { field, value }),
        2 => (0..NIFTI_FIELDS.len(), any::<u32>())
            .prop_map(|(field, bits)| NiftiMut::FieldBits { field, bits }),
        2 => (0usize..352, any::<u8>()).prop_map(|(at, value)| NiftiMut::HeaderByte { at, value }),
        3 => byte_mut().prop_map(NiftiMut::Bytes),
        2 => byte_mut().prop_map(NiftiMut::Stored),
        2 => gz_mut().prop_map(NiftiMut::Gz),
    ]
}

fn nifti_file(base: &NiftiBase, muts: &[NiftiMut]) -> Vec<u8> {
    let mut b = base.bytes.clone();
    let put = |b: &mut Vec<u8>, at: usize, le: &[u8]| {
        if b.len() < at + le.len() {
            return;
        }
        let mut v = le.to_vec();
        if base.big {
            v.reverse();
        }
        b[at..at + v.len()].copy_from_slice(&v);
    };
    for m in muts {
        match m {
            NiftiMut::Field { field, value } => {
                let (_, at, kind) = NIFTI_FIELDS[*field];
                match kind {
                    Kind::I16 => put(&mut b, at, &value.get(NIFTI_I16).to_le_bytes()),
                    Kind::I32 => put(&mut b, at, &value.get(NIFTI_I32).to_le_bytes()),
                    Kind::F32 => put(&mut b, at, &value.get(NIFTI_F32).to_le_bytes()),
                    Kind::U8 => put(&mut b, at, &[[0u8, 1, 2, 3, 7, 255][value.index(6)]]),
                }
            }
            NiftiMut::FieldBits { field, bits } => {
                let (_, at, kind) = NIFTI_FIELDS[*field];
                let n = match kind {
                    Kind::I16 => 2,
                    Kind::I32 | Kind::F32 => 4,
                    Kind::U8 => 1,
                };
                put(&mut b, at, &bits.to_le_bytes()[..n]);
            }
            NiftiMut::HeaderByte { at, value } if *at < b.len() => b[*at] = *value,
            NiftiMut::Bytes(m) => apply_bytes(&mut b, m),
            _ => {}
        }
    }
    if !base.gz {
        return b;
    }
    let mut z = gzip(&b);
    for m in muts {
        match m {
            NiftiMut::Stored(m) => apply_bytes(&mut z, m),
            NiftiMut::Gz(g) => apply_gz(&mut z, g),
            _ => {}
        }
    }
    z
}

static NIFTI_TALLY: ReaderTally = ReaderTally::new();

fn nifti_case(dir: &Path, which: usize, muts: &[NiftiMut]) -> Result<(), TestCaseError> {
    let base = &nifti_bases()[which];
    let name = if base.gz { "case.nii.gz" } else { "case.nii" };
    let files = vec![(name.to_string(), nifti_file(base, muts))];
    let total = write_case(dir, &files);
    let expect = muts.is_empty().then_some(&base.values[..]);
    read_input(
        &dir.join(name),
        &[name.to_string()],
        total,
        expect,
        &NIFTI_TALLY,
    )
}

#[test]
fn fuzz_readers_nifti() {
    let dir = scratch("nifti");
    for which in 0..nifti_bases().len() {
        nifti_case(&dir, which, &[]).unwrap_or_else(|e| panic!("NIfTI base {which}: {e}"));
    }
    fuzz(
        "fuzz::fuzz_readers_nifti",
        (
            0..nifti_bases().len(),
            proptest::collection::vec(nifti_mut(), 1..5),
        ),
        |(which, muts)| nifti_case(&dir, which, &muts),
    );
    NIFTI_TALLY.report("fuzz::fuzz_readers_nifti");
    let _ = std::fs::remove_dir_all(&dir);
}

// -- (e) raw stack sidecars --

/// A valid sidecar (JSON) and its data files.
struct SidecarBase {
    json: serde_json::Value,
    data: Vec<(String, Vec<u8>)>,
    values: Vec<f64>,
}

fn sidecar_bases() -> &'static [SidecarBase] {
    static B: OnceLock<Vec<SidecarBase>> = OnceLock::new();
    B.get_or_init(|| {
        let values = base_values(5 * 4 * 3, -32768.0, 32767.0, false);
        let mut one = b"HDR!".to_vec();
        one.extend_from_slice(&encode(&values, "i16", false));
        let a = SidecarBase {
            json: serde_json::json!({
                "data": "case.raw",
                "dims": [5, 4, 3],
                "dtype": "i16",
                "endian": "little",
                "header_bytes": 4,
                "x": 0.5,
                "y": {"spacing": [1, 0.25, 2]},
                "z": {"positions": [-3, 1e-3, 7.5]},
                "origin": [1, -2, 3],
                "rescale": {"slope": 0.5, "intercept": -1024},
                "orientation": "LPS",
            }),
            data: vec![("case.raw".into(), one)],
            values,
        };
        let fvalues = base_values(3 * 2 * 3, f32::MIN as f64, f32::MAX as f64, true);
        let per = encode(&fvalues, "f32", true);
        let b = SidecarBase {
            json: serde_json::json!({
                "data": ["s0.raw", "s1.raw", "s2.raw"],
                "dims": [3, 2, 3],
                "dtype": "f32",
                "endian": "big",
                "x": {"positions": [0, 1, 3]},
                "y": 2,
                "z": 1.5,
                "orientation": {"lps": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]},
            }),
            data: (0..3)
                .map(|k| (format!("s{k}.raw"), per[24 * k..24 * (k + 1)].to_vec()))
                .collect(),
            values: fvalues,
        };
        vec![a, b]
    })
}

const SIDECAR_FIELDS: &[&str] = &[
    "/data",
    "/data/0",
    "/data/2",
    "/dims",
    "/dims/0",
    "/dims/1",
    "/dims/2",
    "/dtype",
    "/endian",
    "/header_bytes",
    "/x",
    "/y",
    "/y/spacing",
    "/y/spacing/1",
    "/z",
    "/z/positions",
    "/z/positions/1",
    "/x/positions",
    "/x/positions/2",
    "/origin",
    "/origin/0",
    "/rescale",
    "/rescale/slope",
    "/rescale/intercept",
    "/orientation",
    "/orientation/lps",
    "/orientation/lps/1",
];

/// Values for sidecar fields beyond the packed header's [`JSON_VALUES`].
const SIDECAR_VALUES: &[&str] = &[
    "\"case.raw\"",
    "\"s0.raw\"",
    "\"case.json\"",
    "\"missing.raw\"",
    "\"\"",
    "\"/\"",
    "\"..\"",
    "\"/dev/zero\"",
    "[\"s0.raw\", \"s0.raw\", \"s0.raw\"]",
    "[\"case.raw\", \"case.raw\", \"case.raw\"]",
    "[\"s0.raw\", 1, null]",
    "\"i16\"",
    "\"i8\"",
    "\"u32\"",
    "\"big\"",
    "\"little\"",
    "\"middle\"",
    "\"LPS\"",
    "\"RAS\"",
    "\"LLL\"",
    "\"XYZ\"",
    "{\"lps\": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}",
    "{\"ras\": [[1e308, 0, 0], [0, 1, 0], [0, 0, 1]]}",
    "{\"xyz\": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}",
    "{\"positions\": [0, 0, 0]}",
    "{\"positions\": [0, 1e308, -1e308]}",
    "{\"positions\": [0, 1e-300, 2e-300]}",
    "{\"positions\": [0, 1, 2, 3, 4]}",
    "{\"spacing\": [1e308, 1e308]}",
    "{\"spacing\": [1e308, 1e308, 1e308, 1e308]}",
    "{\"spacing\": [-1, 1]}",
    "{\"spacing\": [0, 0]}",
    "{\"positions\": [0, 1, 2], \"spacing\": [1, 1]}",
    "{\"other\": 1}",
    "[0, \"1\", 2]",
    "[1, 2, \"x\"]",
    "[5, 4, 3]",
    "[3, 2, 3]",
    "[5, 4, 1048576]",
    "[65535, 65535, 3]",
    "1e-300",
    "-0.0",
    "\"1\"",
];

#[derive(Debug, Clone)]
enum SidecarMut {
    Field {
        field: usize,
        value: usize,
    },
    Remove {
        field: usize,
    },
    /// Raw text spliced into the sidecar.
    Splice {
        at: Index,
        del: usize,
        text: String,
    },
    /// A data file cut short or made longer by `delta` bytes.
    DataLen {
        file: Index,
        delta: i64,
    },
    Data {
        file: Index,
        m: ByteMut,
    },
}

fn sidecar_mut() -> impl Strategy<Value = SidecarMut> {
    let n_values = JSON_VALUES.len() + SIDECAR_VALUES.len();
    prop_oneof![
        8 => (0..SIDECAR_FIELDS.len(), 0..n_values)
            .prop_map(|(field, value)| SidecarMut::Field { field, value }),
        1 => (0..SIDECAR_FIELDS.len()).prop_map(|field| SidecarMut::Remove { field }),
        3 => (
            any::<Index>(),
            0usize..12,
            prop_oneof![
                3 => prop::sample::select(SPLICES).prop_map(String::from),
                1 => "[ -~]{0,12}",
            ],
        )
            .prop_map(|(at, del, text)| SidecarMut::Splice { at, del, text }),
        3 => (
            any::<Index>(),
            prop_oneof![-40i64..40, Just(-1), Just(1), Just(-100_000), Just(4096)],
        )
            .prop_map(|(file, delta)| SidecarMut::DataLen { file, delta }),
        1 => (any::<Index>(), byte_mut()).prop_map(|(file, m)| SidecarMut::Data { file, m }),
    ]
}

fn sidecar_value(i: usize) -> serde_json::Value {
    let text = JSON_VALUES
        .get(i)
        .copied()
        .unwrap_or_else(|| SIDECAR_VALUES[i - JSON_VALUES.len()]);
    serde_json::from_str(text).unwrap()
}

fn sidecar_files(base: &SidecarBase, muts: &[SidecarMut]) -> Vec<(String, Vec<u8>)> {
    let mut json = base.json.clone();
    for m in muts {
        match m {
            SidecarMut::Field { field, value } => {
                set_json(&mut json, SIDECAR_FIELDS[*field], sidecar_value(*value))
            }
            SidecarMut::Remove { field } => {
                let (parent, key) = SIDECAR_FIELDS[*field].rsplit_once('/').unwrap();
                if let Some(serde_json::Value::Object(o)) = json.pointer_mut(parent) {
                    o.remove(key);
                }
            }
            _ => {}
        }
    }
    let mut text = serde_json::to_vec_pretty(&json).unwrap();
    let mut data = base.data.clone();
    for m in muts {
        match m {
            SidecarMut::Splice { at, del, text: t } => {
                let i = at.index(text.len());
                let j = (i + del).min(text.len());
                text.splice(i..j, t.bytes());
            }
            SidecarMut::DataLen { file, delta } => {
                let d = &mut data[file.index(base.data.len())].1;
                let n = (d.len() as i64 + delta).max(0) as usize;
                let fill = d.len();
                d.resize(n, 0);
                for (i, x) in d.iter_mut().enumerate().skip(fill) {
                    *x = mix(i as u64) as u8;
                }
            }
            SidecarMut::Data { file, m } => {
                apply_bytes(&mut data[file.index(base.data.len())].1, m)
            }
            _ => {}
        }
    }
    let mut files = vec![("case.json".to_string(), text)];
    files.extend(data);
    files
}

static SIDECAR_TALLY: ReaderTally = ReaderTally::new();

fn sidecar_case(dir: &Path, which: usize, muts: &[SidecarMut]) -> Result<(), TestCaseError> {
    let base = &sidecar_bases()[which];
    let files = sidecar_files(base, muts);
    let total = write_case(dir, &files);
    let expect = muts.is_empty().then_some(&base.values[..]);
    read_input(
        &dir.join("case.json"),
        &["case.json".to_string()],
        total,
        expect,
        &SIDECAR_TALLY,
    )
}

#[test]
fn fuzz_readers_sidecar() {
    let dir = scratch("sidecar");
    for which in 0..sidecar_bases().len() {
        sidecar_case(&dir, which, &[]).unwrap_or_else(|e| panic!("sidecar base {which}: {e}"));
    }
    fuzz(
        "fuzz::fuzz_readers_sidecar",
        (
            0..sidecar_bases().len(),
            proptest::collection::vec(sidecar_mut(), 1..5),
        ),
        |(which, muts)| sidecar_case(&dir, which, &muts),
    );
    SIDECAR_TALLY.report("fuzz::fuzz_readers_sidecar");
    let _ = std::fs::remove_dir_all(&dir);
}

// -- (f) DICOM --

/// Rows of the base slices (Columns are `dicom_series::NX`).
const DICOM_ROWS: usize = 4;

/// A valid 3-slice series: each file's bytes, and the stored samples.
fn dicom_base() -> &'static (Vec<Vec<u8>>, Vec<f64>) {
    static B: OnceLock<(Vec<Vec<u8>>, Vec<f64>)> = OnceLock::new();
    B.get_or_init(|| {
        use common::dicom_series as ds;
        let dir = tempfile::tempdir().unwrap();
        let mut files = Vec::new();
        let mut values = Vec::new();
        for k in 0..3 {
            let p = dir.path().join(format!("s{k}.dcm"));
            ds::write_slice(
                &p,
                &ds::Slice {
                    k,
                    series: ds::SERIES,
                    rows: DICOM_ROWS,
                    position: [10.0, -5.0, ds::z_positions()[k]],
                    ts: ds::EXPLICIT_LE,
                },
            );
            files.push(std::fs::read(&p).unwrap());
            values.extend(
                ds::slice(k)[..ds::NX * DICOM_ROWS]
                    .iter()
                    .map(|&v| v as f64),
            );
        }
        (files, values)
    })
}

/// Elements to overwrite: (name, group, element).
const DICOM_US: &[(&str, u16, u16)] = &[
    ("SamplesPerPixel", 0x0028, 0x0002),
    ("Rows", 0x0028, 0x0010),
    ("Columns", 0x0028, 0x0011),
    ("BitsAllocated", 0x0028, 0x0100),
    ("BitsStored", 0x0028, 0x0101),
    ("HighBit", 0x0028, 0x0102),
    ("PixelRepresentation", 0x0028, 0x0103),
];

const DICOM_TEXT: &[(&str, u16, u16)] = &[
    ("PixelSpacing", 0x0028, 0x0030),
    ("ImagePositionPatient", 0x0020, 0x0032),
    ("ImageOrientationPatient", 0x0020, 0x0037),
    ("RescaleIntercept", 0x0028, 0x1052),
    ("RescaleSlope", 0x0028, 0x1053),
    ("SeriesInstanceUID", 0x0020, 0x000e),
    ("TransferSyntaxUID", 0x0002, 0x0010),
];

const DICOM_US_VALUES: &[u16] = &[
    0, 1, 2, 3, 4, 7, 8, 12, 15, 16, 17, 32, 33, 64, 255, 0x8000, 65535,
];

const DICOM_TEXTS: &[&str] = &[
    "",
    "0",
    "1",
    "-1",
    "0\\0",
    "1e308\\1e308",
    "-1e308\\1",
    "nan\\nan",
    "inf\\1",
    "1e-300\\1",
    "5e-324\\5e-324",
    "0.8\\0.7",
    "0.8\\0.7\\0.6",
    "1\\2\\3\\4\\5\\6\\7",
    "1\\0\\0\\0\\1\\0",
    "1\\0\\0\\1\\0\\0",
    "0\\0\\0\\0\\0\\0",
    "1\\0\\0\\0\\0\\1",
    "nan\\0\\0\\0\\1\\0",
    "10\\-5\\-40",
    "10\\-5\\-38",
    "11\\-5\\-38",
    "10\\-5\\1e308",
    "abc",
    "1.2.3",
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.2",
    "1.2.840.10008.1.2.1.99",
    "1.2.840.10008.1.2.5",
    "1.2.840.10008.1.2.4.50",
    "1.2.840.10008.1.2.4.90",
    "1.2.826.0.1.3680043.9.7777.2",
];

#[derive(Debug, Clone)]
enum DicomMut {
    /// Bytes of the header (before PixelData), of the pixel data element,
    /// or of the whole file.
    Bytes { region: u8, m: ByteMut },
    /// A US element's value.
    Us { elem: usize, value: u16 },
    /// A text element (DS, UI) replaced, its length updated.
    Text { elem: usize, text: usize },
    /// An element's length field overwritten.
    Len { elem: usize, value: u32 },
}

fn dicom_mut() -> impl Strategy<Value = DicomMut> {
    prop_oneof![
        5 => (0u8..3, byte_mut()).prop_map(|(region, m)| DicomMut::Bytes { region, m }),
        3 => (
            0..DICOM_US.len(),
            prop_oneof![3 => prop::sample::select(DICOM_US_VALUES), 1 => any::<u16>()],
        )
            .prop_map(|(elem, value)| DicomMut::Us { elem, value }),
        3 => (0..DICOM_TEXT.len(), 0..DICOM_TEXTS.len())
            .prop_map(|(elem, text)| DicomMut::Text { elem, text }),
        2 => (
            0..DICOM_US.len() + DICOM_TEXT.len() + 1,
            prop_oneof![
                2 => prop::sample::select(vec![0u32, 1, 2, 3, 0xfffe, 0xffff, 0xffff_ffff, 0x7fff_ffff, 264, 266]),
                1 => any::<u32>(),
            ],
        )
            .prop_map(|(elem, value)| DicomMut::Len { elem, value }),
    ]
}

/// Offset of element (`group`, `elem`) in explicit VR little endian.
fn find_elem(b: &[u8], group: u16, elem: u16) -> Option<usize> {
    let mut tag = group.to_le_bytes().to_vec();
    tag.extend_from_slice(&elem.to_le_bytes());
    // The first whose VR bytes are upper-case letters.
    b.windows(6)
        .position(|w| w[..4] == tag[..] && w[4].is_ascii_uppercase() && w[5].is_ascii_uppercase())
}

const PIXEL_DATA: (u16, u16) = (0x7fe0, 0x0010);

fn dicom_file(base: &[u8], muts: &[DicomMut]) -> Vec<u8> {
    let mut b = base.to_vec();
    for m in muts {
        let pix = find_elem(&b, PIXEL_DATA.0, PIXEL_DATA.1).unwrap_or(b.len());
        match m {
            DicomMut::Bytes { region, m } => {
                let range = match region {
                    0 => 0..pix,
                    1 => pix..b.len(),
                    _ => 0..b.len(),
                };
                apply_region(&mut b, range, m);
            }
            DicomMut::Us { elem, value } => {
                let (_, g, e) = DICOM_US[*elem];
                if let Some(i) = find_elem(&b, g, e) {
                    if i + 10 <= b.len() {
                        b[i + 8..i + 10].copy_from_slice(&value.to_le_bytes());
                    }
                }
            }
            DicomMut::Text { elem, text } => {
                let (_, g, e) = DICOM_TEXT[*elem];
                if let Some(i) = find_elem(&b, g, e) {
                    if i + 8 <= b.len() {
                        let old = u16::from_le_bytes([b[i + 6], b[i + 7]]) as usize;
                        let end = (i + 8 + old).min(b.len());
                        let mut t = DICOM_TEXTS[*text].as_bytes().to_vec();
                        if t.len() % 2 == 1 {
                            t.push(if g == 0x0002 || e == 0x000e { 0 } else { b' ' });
                        }
                        b[i + 6..i + 8].copy_from_slice(&(t.len() as u16).to_le_bytes());
                        b.splice(i + 8..end, t);
                    }
                }
            }
            DicomMut::Len { elem, value } => {
                let (g, e) = if *elem < DICOM_US.len() {
                    (DICOM_US[*elem].1, DICOM_US[*elem].2)
                } else if *elem < DICOM_US.len() + DICOM_TEXT.len() {
                    let t = DICOM_TEXT[*elem - DICOM_US.len()];
                    (t.1, t.2)
                } else {
                    PIXEL_DATA
                };
                if let Some(i) = find_elem(&b, g, e) {
                    if (g, e) == PIXEL_DATA {
                        if i + 12 <= b.len() {
                            b[i + 8..i + 12].copy_from_slice(&value.to_le_bytes());
                        }
                    } else if i + 8 <= b.len() {
                        b[i + 6..i + 8].copy_from_slice(&(*value as u16).to_le_bytes());
                    }
                }
            }
        }
    }
    b
}

static DICOM_TALLY: ReaderTally = ReaderTally::new();

fn dicom_case(dir: &Path, which: usize, muts: &[DicomMut]) -> Result<(), TestCaseError> {
    let (bases, values) = dicom_base();
    let files: Vec<(String, Vec<u8>)> = bases
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let bytes = if k == which {
                dicom_file(b, muts)
            } else {
                b.clone()
            };
            (format!("dcmdir/s{k}.dcm"), bytes)
        })
        .collect();
    let total = write_case(dir, &files);
    // An error names a slice file, or the series directory when it is
    // about the series as a whole.
    let mut names: Vec<String> = (0..3).map(|k| format!("s{k}.dcm")).collect();
    names.push("dcmdir".into());
    let expect = muts.is_empty().then_some(&values[..]);
    read_input(&dir.join("dcmdir"), &names, total, expect, &DICOM_TALLY)
}

#[test]
fn fuzz_readers_dicom() {
    let dir = scratch("dicom");
    dicom_case(&dir, 0, &[]).unwrap_or_else(|e| panic!("DICOM base: {e}"));
    fuzz(
        "fuzz::fuzz_readers_dicom",
        (0usize..3, proptest::collection::vec(dicom_mut(), 1..4)),
        |(which, muts)| dicom_case(&dir, which, &muts),
    );
    DICOM_TALLY.report("fuzz::fuzz_readers_dicom");
    let _ = std::fs::remove_dir_all(&dir);
}
