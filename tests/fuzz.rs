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
//! Found by this fuzz and fixed (each keeps a regression test below,
//! `found_*`): `t` overflowing to inf on grids spanning ~1e300 mm (axes
//! and ray origins are now bounded by `MAX_COORD_MM`, directions by
//! `MAX_DIR`), visits emptied by the underflow of the reported `t` for
//! directions above 2^1022 (refused now), and `Info::to_text` overflowing
//! on code-histogram counts near 2^64 (saturating now).
//!
//! Cases per test: `CDVOL_FUZZ_CASES` (default 64). Failures are persisted
//! by proptest to tests/fuzz.proptest-regressions and replayed first on
//! every run. `tools/fuzz.sh [SECONDS]` runs these with many cases.

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
use cdvol::render::camera::Camera;
use cdvol::render::shade::HitMethod;
use cdvol::render::traverse::{Method, Ray, TGrid, Visit};
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

unsafe impl GlobalAlloc for Watch {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        LARGEST.fetch_max(l.size(), Ordering::Relaxed);
        System.alloc(l)
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        LARGEST.fetch_max(l.size(), Ordering::Relaxed);
        System.alloc_zeroed(l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        LARGEST.fetch_max(new, Ordering::Relaxed);
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
