//! Data extremes, end to end: raw stack + sidecar -> `prep` ->
//! `PackedVolume::open` -> `render`.
//!
//! Cases: iso at the data type's minimum and maximum (u8 0 and 255, i16
//! -32768 and 32767, u16 65535), iso exactly equal to sample values in the
//! data, float data with NaN, +inf and -inf samples, all-empty and all-full
//! volumes, a thin slab at the format's largest axis (2^20 samples along
//! x), and z positions 1e-9 mm apart at an offset of 1e6 mm.
//!
//! Every case says in a comment whether prep accepts it or which field it
//! refuses. For every accepted case:
//!
//! * the number of 1-cells in the header summary equals a brute-force
//!   count with the rule of docs/FORMAT.md (a cell is a 1-cell when the
//!   largest of its 8 vertex values, NaN left out, is >= iso), and the codes
//!   read back equal a breadth-first chessboard oracle (tests/common);
//! * NaN/inf, as src/classify.rs treats them (`slice_iso_flags`:
//!   `rescale.apply(v) >= iso` per sample; the renderer's brick decode uses
//!   the same comparison on f64 values): NaN never reaches an iso value
//!   (every comparison with NaN is false) and is left out of the max;
//!   +inf reaches every finite iso, so a cell with a +inf vertex is a
//!   1-cell; -inf reaches no finite iso. `common::classify_iso` (`v >=
//!   iso` per vertex) is exactly that rule;
//! * every mode (surface with hit `int` and `exact`, depth with both,
//!   mip, cost) renders with `Method::Fvt` and `Method::Cd { min_leap: 1 }`
//!   from several views: the RGB bytes (and depth bits) of FVT and CD are
//!   identical, except in cost mode, which shows the steps each traversal
//!   takes (there the hit counts must agree); no hit pixel has a
//!   non-finite depth, and a hit lies on the ray's chord through the
//!   volume's box; no ray takes more than `ncx + ncy + ncz - 2` steps;
//!   all-empty volumes render no hit; all-full volumes hit in every pixel
//!   whose ray enters the box.
//!
//! Two bugs this suite found broke the all-full contract and are fixed;
//! their cases are the last tests of this file: values at iso that the
//! renderer's f32 copy rounded below iso (f64 data, u32 above 2^24), and
//! +inf samples, whose cells are 1-cells but whose interpolant was NaN.
//!
//! Tolerances (all in mm along the ray):
//! * "enters the box": the ray's chord through the box (slab test in f64)
//!   is longer than `TOL_REL * box diagonal + TOL_REL * |t|`, with `TOL_REL
//!   = 1e-9`. Rays whose chord length is within that band of zero (grazing
//!   a face, edge or corner) are "unsure" and left out of the per-pixel
//!   expectations: the traversal's own plane crossings carry a relative
//!   error of a few ulps (src/render/traverse.rs), so a ray grazing the
//!   box may go either way. 1e-9 is many ulps (2^-52 = 2.2e-16) above
//!   that and far below any chord that matters (the thinnest cell here
//!   is ~1e-9 mm, but the box is never thinner than 1 mm).
//! * a hit's depth lies in the chord `[t_in, t_out]` within the same band
//!   plus the f32 rounding of the stored depth (`Frame::depth` is f32:
//!   half an ulp, `|t| * 2^-24`).
//! * the thin slab's analytic depth: 0.04 mm, the f32 rounding of a depth
//!   of ~5.2e5 mm (ulp 2^-4 = 0.0625 mm above 2^19, so half an ulp is
//!   0.03125 mm) plus slack for the f64 root (~1e-10 mm there).

use std::path::Path;

use crate::common::{chessboard_bfs, classify_iso, expected_codes, mix, read_back, write_stack};
use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::grid::MAX_SAMPLES_PER_AXIS;
use cdvol::input::raw::RawSource;
use cdvol::input::Dtype;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::{Method, Ray, TGrid};
use cdvol::render::view::camera::{Camera, Projection};
use cdvol::render::{render, Frame, Mode, RenderOptions, Stats};

const TOL_REL: f64 = 1e-9;

/// What the renders of a case must show.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Expect {
    /// Some 1-cells, some 0-cells: only the general invariants.
    Mixed,
    /// No sample reaches iso: no 1-cell, no hit in any mode.
    Empty,
    /// Every cell a 1-cell. `every_sample`: every sample is >= iso too, so
    /// the interpolant is >= iso everywhere and surface, depth and cost
    /// must hit at the entry of every ray that enters the box; otherwise
    /// only MIP (which reports any visited 1-cell) must.
    Full { every_sample: bool },
}

/// A smooth blob (distance from an off-centre point, 0 at the far corner,
/// `peak` at the centre) so renders have a real surface.
fn blob(dims: [usize; 3], peak: f64) -> Vec<f64> {
    let c = dims.map(|d| d as f64 * 0.45);
    let r = dims.iter().map(|&d| d as f64).fold(0.0, f64::max) * 0.6;
    let mut v = Vec::with_capacity(dims.iter().product());
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let d = ((x as f64 - c[0]).powi(2)
                    + (y as f64 - c[1]).powi(2)
                    + (z as f64 - c[2]).powi(2))
                .sqrt();
                v.push((peak * (1.0 - d / r)).max(0.0).round());
            }
        }
    }
    v
}

const DIMS: [usize; 3] = [12, 10, 9];
const N: usize = 12 * 10 * 9;

fn uniform_axes() -> [String; 3] {
    [
        "1".into(),
        "0.75".into(),
        "{\"spacing\": [1, 2, 0.5, 1, 1.5, 1, 1, 0.25]}".into(),
    ]
}

fn prep_file(
    dir: &Path,
    name: &str,
    dims: [usize; 3],
    (dtype, values): (&str, &[f64]),
    axes: &[String; 3],
    iso: f64,
    brick: usize,
) -> Result<PackedVolume, String> {
    let side = write_stack(
        dir,
        name,
        dims,
        dtype,
        values,
        [&axes[0], &axes[1], &axes[2]],
        "",
    );
    let src = RawSource::open(&side).map_err(|e| e.to_string())?;
    let out = dir.join(format!("{name}.cdv"));
    let mut o = PrepOptions::new(Classification::Iso { iso });
    o.brick_size = brick;
    prep(&src, &out, &o, &NoProgress).map_err(|e| e.to_string())?;
    PackedVolume::open(&out).map_err(|e| e.to_string())
}

/// Header summary and codes against the brute-force oracles.
fn check_classification(vol: &PackedVolume, dims: [usize; 3], values: &[f64], iso: f64) {
    let obj = classify_iso(values, dims, iso);
    let ones = obj.iter().filter(|&&o| o != 0).count() as u64;
    let s = &vol.header().summary;
    assert_eq!(s.one_cells, ones, "summary one_cells vs brute force");
    assert_eq!(s.cells, obj.len() as u64);
    assert_eq!(s.code_histogram.iter().sum::<u64>() + s.one_cells, s.cells);
    let back = read_back(vol, values);
    assert_eq!(back.checked_one_cells as u64, ones);
    let cells = dims.map(|d| d - 1);
    assert!(
        back.codes == expected_codes(&chessboard_bfs(&obj, cells), vol.header().codes.max_code()),
        "codes differ from the BFS oracle"
    );
}

/// Where a ray meets the box `[lo, hi]`.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Enters {
    Yes { t_in: f64, t_out: f64 },
    No,
    Unsure,
}

fn enters(ray: &Ray, lo: [f64; 3], hi: [f64; 3]) -> Enters {
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let (mut t_in, mut t_out) = (0.0f64, f64::INFINITY);
    let mut unsure_parallel = false;
    for k in 0..3 {
        let (o, d) = (ray.origin[k], ray.dir[k]);
        if d == 0.0 {
            let margin = (o - lo[k]).min(hi[k] - o);
            if margin < -TOL_REL * diag {
                return Enters::No;
            }
            unsure_parallel |= margin <= TOL_REL * diag;
            continue;
        }
        let (a, b) = ((lo[k] - o) / d, (hi[k] - o) / d);
        t_in = t_in.max(a.min(b));
        t_out = t_out.min(a.max(b));
    }
    let band = TOL_REL * diag + TOL_REL * t_in.abs().max(t_out.abs()).min(1e300);
    let len = t_out - t_in;
    if unsure_parallel || len.abs() <= band {
        Enters::Unsure
    } else if len > band {
        Enters::Yes { t_in, t_out }
    } else {
        Enters::No
    }
}

fn opts(mode: &Mode, method: Method) -> RenderOptions {
    RenderOptions {
        mode: mode.clone(),
        method,
        tile: 8,
        cache_bytes: 16 << 20,
        cd_lazy_min: Some(4),
        ..RenderOptions::new(mode.clone(), method)
    }
}

fn run(vol: &PackedVolume, cam: &Camera, mode: &Mode, method: Method) -> (Frame, Stats) {
    render(vol, cam, &opts(mode, method), &NoProgress)
        .unwrap_or_else(|e| panic!("{mode:?} {method:?}: {e}"))
}

fn cameras(vol: &PackedVolume, size: u32) -> Vec<(String, Camera)> {
    let b = TGrid::<f64>::new(&vol.header().axes).bounds();
    let mut out = Vec::new();
    for (view, persp) in [
        ([0.0, 0.0], false),
        ([37.0, 23.0], false),
        ([0.0, 90.0], false),
        ([-120.0, -40.0], true),
    ] {
        let c =
            Camera::orbit(b, view[0], view[1], persp.then_some(35.0), None, size, size).unwrap();
        out.push((format!("view {view:?} persp {persp}"), c));
    }
    out
}

fn modes() -> Vec<(&'static str, Mode)> {
    vec![
        (
            "surface-int",
            Mode::Surface {
                hit: HitMethod::Int,
                shadows: false,
            },
        ),
        (
            "surface-exact",
            Mode::Surface {
                hit: HitMethod::Exact,
                shadows: false,
            },
        ),
        (
            "surface-int-shadows",
            Mode::Surface {
                hit: HitMethod::Int,
                shadows: true,
            },
        ),
        (
            "depth-int",
            Mode::Depth {
                hit: HitMethod::Int,
            },
        ),
        (
            "depth-exact",
            Mode::Depth {
                hit: HitMethod::Exact,
            },
        ),
        ("mip", Mode::Mip),
        ("cost", Mode::Cost),
    ]
}

/// Total steps of FVT and CD over all renders (cost mode).
#[derive(Default, Debug)]
struct Totals {
    fvt_steps: u64,
    cd_steps: u64,
    hits: u64,
}

/// Renders every mode from every camera with FVT and CD and checks the
/// invariants of the module docs.
fn check_renders(vol: &PackedVolume, cams: &[(String, Camera)], expect: Expect) -> Totals {
    let h = vol.header();
    let (lo, hi) = TGrid::<f64>::new(&h.axes).bounds();
    let cells = h.cells();
    let bound = (cells[0] + cells[1] + cells[2] - 2) as u32;
    let mut totals = Totals::default();
    for (cn, cam) in cams {
        let npx = (cam.width * cam.height) as usize;
        let ent: Vec<Enters> = (0..npx as u32)
            .map(|i| enters(&cam.ray(i % cam.width, i / cam.width), lo, hi))
            .collect();
        let n_yes = ent
            .iter()
            .filter(|e| matches!(e, Enters::Yes { .. }))
            .count() as u64;
        let n_unsure = ent.iter().filter(|e| **e == Enters::Unsure).count() as u64;
        let mut hit_sets: Vec<(&str, Vec<bool>)> = Vec::new();
        for (mn, mode) in modes() {
            let what = format!("{cn} {mn}");
            let (f, fs) = run(vol, cam, &mode, Method::Fvt);
            let (c, cs) = run(vol, cam, &mode, Method::Cd { min_leap: 1 });
            assert_eq!(fs.hits, cs.hits, "{what}: fvt and cd hit counts");
            if mn == "cost" {
                totals.fvt_steps += fs.steps;
                totals.cd_steps += cs.steps;
            } else {
                assert!(f.rgb == c.rgb, "{what}: cd image differs from fvt");
                let bits = |f: &Frame| {
                    f.depth
                        .as_ref()
                        .map(|d| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
                };
                assert_eq!(bits(&f), bits(&c), "{what}: cd depth differs from fvt");
            }
            totals.hits += fs.hits;
            if mn != "surface-int-shadows" {
                // One trace per pixel: the traversal's step bound holds.
                for fr in [&f, &c] {
                    let worst = fr.steps.iter().copied().max().unwrap_or(0);
                    assert!(worst <= bound, "{what}: {worst} steps > bound {bound}");
                }
            }
            // Per-pixel hits where the frame shows them.
            let hits: Option<Vec<bool>> = match &mode {
                Mode::Depth { .. } => {
                    let d = f.depth.as_ref().unwrap();
                    let finite = d.iter().filter(|x| x.is_finite()).count() as u64;
                    assert_eq!(
                        finite, fs.hits,
                        "{what}: a hit pixel has a non-finite depth"
                    );
                    for (i, &x) in d.iter().enumerate() {
                        if !x.is_finite() {
                            continue;
                        }
                        match ent[i] {
                            Enters::Yes { t_in, t_out } => {
                                let band =
                                    TOL_REL * (1.0 + t_out.abs()) + x.abs() as f64 * 2f64.powi(-24);
                                assert!(
                                    x as f64 >= t_in - band && x as f64 <= t_out + band,
                                    "{what}: pixel {i} depth {x} outside the chord \
                                     [{t_in}, {t_out}]"
                                );
                            }
                            Enters::No => {
                                panic!("{what}: pixel {i} hits at {x} but misses the box")
                            }
                            Enters::Unsure => {}
                        }
                    }
                    Some(d.iter().map(|x| x.is_finite()).collect())
                }
                // Shading is at least the ambient 0.12, so a hit is never
                // black; a miss is.
                Mode::Surface { .. } => {
                    let lit: Vec<bool> = f.rgb.chunks(3).map(|p| p != [0, 0, 0]).collect();
                    assert_eq!(lit.iter().filter(|&&b| b).count() as u64, fs.hits, "{what}");
                    Some(lit)
                }
                _ => None,
            };
            if let Some(hv) = &hits {
                hit_sets.push((mn, hv.clone()));
            }
            match expect {
                Expect::Mixed => {}
                Expect::Empty => {
                    assert_eq!(fs.hits, 0, "{what}: hits in an all-empty volume");
                    if mn != "cost" {
                        assert!(f.rgb.iter().all(|&b| b == 0), "{what}: non-black pixels");
                    }
                }
                Expect::Full { every_sample } => {
                    if every_sample || mn == "mip" {
                        // Every entering ray hits; an unsure one may.
                        assert!(
                            fs.hits >= n_yes && fs.hits <= n_yes + n_unsure,
                            "{what}: {} hits, {n_yes} rays enter (+{n_unsure} unsure)",
                            fs.hits
                        );
                        if let Some(hv) = &hits {
                            for (i, e) in ent.iter().enumerate() {
                                if matches!(e, Enters::Yes { .. }) {
                                    assert!(hv[i], "{what}: pixel {i} enters but misses");
                                }
                            }
                        }
                    }
                }
            }
        }
        // Surface and depth share the hit search: same pixels hit.
        let get = |n: &str| hit_sets.iter().find(|(m, _)| *m == n).map(|(_, v)| v);
        assert_eq!(
            get("surface-int"),
            get("depth-int"),
            "{cn}: surface vs depth (int)"
        );
        assert_eq!(
            get("surface-exact"),
            get("depth-exact"),
            "{cn}: surface vs depth (exact)"
        );
    }
    totals
}

/// A case of the table: prep must accept it (each case's comment says why
/// it is legal input), then every check runs.
struct Case {
    name: &'static str,
    dims: [usize; 3],
    dtype: &'static str,
    values: Vec<f64>,
    axes: [String; 3],
    iso: f64,
    brick: usize,
    expect: Expect,
    /// Storage type prep must choose (widening, docs/FORMAT.md).
    storage: Option<Dtype>,
}

fn case(
    name: &'static str,
    dtype: &'static str,
    values: Vec<f64>,
    iso: f64,
    expect: Expect,
    storage: Option<Dtype>,
) -> Case {
    Case {
        name,
        dims: DIMS,
        dtype,
        values,
        axes: uniform_axes(),
        iso,
        brick: 4,
        expect,
        storage,
    }
}

fn check_case(c: &Case) -> Totals {
    let dir = tempfile::tempdir().unwrap();
    let vol = prep_file(
        dir.path(),
        c.name,
        c.dims,
        (c.dtype, &c.values),
        &c.axes,
        c.iso,
        c.brick,
    )
    .unwrap_or_else(|e| panic!("{}: prep refused a legal input: {e}", c.name));
    if let Some(s) = c.storage {
        assert_eq!(vol.header().storage, s, "{}: storage type", c.name);
    }
    check_classification(&vol, c.dims, &c.values, c.iso);
    let ones = vol.header().summary.one_cells;
    match c.expect {
        Expect::Empty => assert_eq!(ones, 0, "{}", c.name),
        Expect::Full { .. } => assert_eq!(ones, vol.header().summary.cells, "{}", c.name),
        Expect::Mixed => assert!(ones > 0 && ones < vol.header().summary.cells, "{}", c.name),
    }
    let t = check_renders(&vol, &cameras(&vol, 20), c.expect);
    if c.expect != Expect::Empty {
        assert!(t.hits > 0, "{}: nothing rendered", c.name);
    }
    t
}

/// `values` with `v` at a few scattered samples.
fn with_peaks(mut values: Vec<f64>, v: f64, seed: u64) -> Vec<f64> {
    for k in 0..5 {
        let i = (mix(seed * 31 + k) % values.len() as u64) as usize;
        values[i] = v;
    }
    values
}

// ---- iso at the data type's limits ----

#[test]
fn u8_iso_at_0_and_255() {
    // Accepted: u8 data using the whole range 0..=255 (prep widens the
    // words to i16 to make room for codes).
    let full_range: Vec<f64> = (0..N as u64).map(|i| (mix(i) % 256) as f64).collect();
    // iso 0: every sample reaches it, every cell is a 1-cell.
    check_case(&case(
        "u8-iso-0",
        "u8",
        full_range,
        0.0,
        Expect::Full { every_sample: true },
        Some(Dtype::I16),
    ));
    // iso 255: only cells around the few 255 samples; the rest of the data
    // below, with 0 present so the range is full.
    let mut v: Vec<f64> = blob(DIMS, 254.0);
    v = with_peaks(v, 255.0, 1);
    check_case(&case(
        "u8-iso-255",
        "u8",
        v,
        255.0,
        Expect::Mixed,
        Some(Dtype::I16),
    ));
}

#[test]
fn i16_iso_at_min_and_max() {
    // Accepted: i16 over the whole range (widened to i32).
    let mut v: Vec<f64> = (0..N as u64)
        .map(|i| (mix(i + 7) % 65536) as f64 - 32768.0)
        .collect();
    v[0] = -32768.0;
    v[1] = 32767.0;
    check_case(&case(
        "i16-iso-min",
        "i16",
        v,
        -32768.0,
        Expect::Full { every_sample: true },
        Some(Dtype::I32),
    ));
    let v: Vec<f64> = blob(DIMS, 65535.0).iter().map(|x| x - 32768.0).collect();
    let v = with_peaks(v, 32767.0, 2);
    check_case(&case(
        "i16-iso-max",
        "i16",
        v,
        32767.0,
        Expect::Mixed,
        Some(Dtype::I32),
    ));
}

#[test]
fn u16_iso_at_max() {
    // Accepted: u16 blob up to 65534 plus a few 65535 samples (widened to
    // i32: no free range left).
    let v = with_peaks(blob(DIMS, 65534.0), 65535.0, 3);
    check_case(&case(
        "u16-iso-max",
        "u16",
        v,
        65535.0,
        Expect::Mixed,
        Some(Dtype::I32),
    ));
}

// ---- iso exactly at sample values ----

#[test]
fn iso_equal_to_sample_values() {
    // Accepted: u8 values on a 10-step ladder, iso 50 exactly one of them
    // (cells whose largest vertex is exactly 50 are 1-cells).
    let v: Vec<f64> = blob(DIMS, 100.0)
        .iter()
        .map(|x| (x / 10.0).round() * 10.0)
        .collect();
    assert!(v.contains(&50.0));
    check_case(&case(
        "u8-iso-equal",
        "u8",
        v,
        50.0,
        Expect::Mixed,
        Some(Dtype::U8),
    ));
    // Accepted: f32 values k * 0.1f32, iso = 0.3f32 exactly as stored
    // (0.30000001192092896 in f64): the comparison is on the widened f32.
    let iso = 0.3f32 as f64;
    let v: Vec<f64> = blob(DIMS, 6.0)
        .iter()
        .map(|x| (*x as f32 * 0.1f32) as f64)
        .collect();
    assert!(v.contains(&iso));
    check_case(&case(
        "f32-iso-equal",
        "f32",
        v,
        iso,
        Expect::Mixed,
        Some(Dtype::F32),
    ));
    // Accepted: a constant volume at exactly iso: every cell a 1-cell,
    // every sample on the surface value itself.
    check_case(&case(
        "u8-constant-at-iso",
        "u8",
        vec![7.0; N],
        7.0,
        Expect::Full { every_sample: true },
        Some(Dtype::U8),
    ));
}

// ---- NaN and infinities ----

#[test]
fn f32_nan_and_infinities() {
    // Accepted: f32 with NaN (background, left out of every max), +inf
    // (reaches the finite iso: its cells are 1-cells) and -inf (never
    // reaches it), on top of a blob.
    let mut v: Vec<f64> = blob(DIMS, 2.0).iter().map(|x| x * 0.5).collect();
    for (i, x) in v.iter_mut().enumerate() {
        match mix(i as u64 + 99) % 20 {
            0 | 1 => *x = f64::NAN,
            2 => *x = f64::INFINITY,
            3 => *x = f64::NEG_INFINITY,
            _ => {}
        }
    }
    let vol_case = case(
        "f32-nan-inf",
        "f32",
        v.clone(),
        0.5,
        Expect::Mixed,
        Some(Dtype::F32),
    );
    check_case(&vol_case);
    // The same as f64.
    check_case(&case(
        "f64-nan-inf",
        "f64",
        v,
        0.5,
        Expect::Mixed,
        Some(Dtype::F64),
    ));
}

// ---- all empty and all full ----

#[test]
fn all_empty_volumes() {
    // Accepted: no sample reaches iso. u8 zeros with iso 1.
    check_case(&case(
        "u8-zeros",
        "u8",
        vec![0.0; N],
        1.0,
        Expect::Empty,
        None,
    ));
    // Accepted: i16 all at the type minimum, iso one above it.
    check_case(&case(
        "i16-min",
        "i16",
        vec![-32768.0; N],
        -32767.0,
        Expect::Empty,
        None,
    ));
    // Accepted: f32 all NaN (every cell has 8 NaN vertices: background).
    check_case(&case(
        "f32-all-nan",
        "f32",
        vec![f64::NAN; N],
        0.0,
        Expect::Empty,
        Some(Dtype::F32),
    ));
    // Accepted: f32 all -inf, iso the lowest finite f32.
    check_case(&case(
        "f32-all-neg-inf",
        "f32",
        vec![f64::NEG_INFINITY; N],
        f32::MIN as f64,
        Expect::Empty,
        Some(Dtype::F32),
    ));
    // Accepted: NaN and -inf mixed, iso 0.
    let v: Vec<f64> = (0..N)
        .map(|i| {
            if i % 3 == 0 {
                f64::NAN
            } else {
                f64::NEG_INFINITY
            }
        })
        .collect();
    check_case(&case("f32-nan-neg-inf", "f32", v, 0.0, Expect::Empty, None));
}

#[test]
fn all_full_volumes() {
    // Accepted: every sample above iso (u8 200, iso 100).
    check_case(&case(
        "u8-all-above",
        "u8",
        vec![200.0; N],
        100.0,
        Expect::Full { every_sample: true },
        None,
    ));
    // Accepted: a 3-D checkerboard of 200 and 0 samples: every cell has 4
    // vertices at 200, so every cell is a 1-cell, but the interpolant dips
    // below iso inside cells: only MIP must hit every entering ray.
    let mut v = Vec::with_capacity(N);
    for z in 0..DIMS[2] {
        for y in 0..DIMS[1] {
            for x in 0..DIMS[0] {
                v.push(if (x + y + z) % 2 == 0 { 200.0 } else { 0.0 });
            }
        }
    }
    check_case(&case(
        "u8-checkerboard",
        "u8",
        v,
        100.0,
        Expect::Full {
            every_sample: false,
        },
        None,
    ));
    // Accepted: f32 with every sample finite and >= iso, a few exactly at
    // iso and some huge (3e38, near f32::MAX).
    let v: Vec<f64> = (0..N as u64)
        .map(|i| match mix(i) % 4 {
            0 => -1.5,
            1 => 3e38f32 as f64,
            _ => (mix(i + 1) % 1000) as f64,
        })
        .collect();
    check_case(&case(
        "f32-all-above",
        "f32",
        v,
        -1.5,
        Expect::Full { every_sample: true },
        None,
    ));
}

// ---- the format's largest axis ----

#[test]
fn thin_slab_at_the_format_maximum() {
    // Accepted: 2^20 samples along x (the limit), 2 along y and z, u8.
    // Samples (x0, 1, z) for both z are 200 at x0 = n/2 + 7 and at the
    // last sample x = n - 1; every other sample is 0; iso 100. The 1-cells
    // are x0 - 1, x0 and n - 2. In 1-cells near x0 the interpolant along a
    // ray at (y, z) is 200 * u * y (u the local x), so a ray hits where
    // 200 y >= 100.
    let n = MAX_SAMPLES_PER_AXIS;
    let dims = [n, 2, 2];
    let mut v = vec![0.0; 4 * n];
    let x0 = n / 2 + 7;
    for z in 0..2 {
        v[(z * 2 + 1) * n + x0] = 200.0;
        v[(z * 2 + 1) * n + n - 1] = 200.0;
    }
    let dir = tempfile::tempdir().unwrap();
    let axes = ["1".to_string(), "1".to_string(), "1".to_string()];
    let vol = prep_file(dir.path(), "slab", dims, ("u8", &v), &axes, 100.0, 64).unwrap();
    assert_eq!(vol.header().dims, [n as u64, 2, 2]);
    check_classification(&vol, dims, &v, 100.0);
    assert_eq!(vol.header().summary.one_cells, 3);

    // Rays along +x from x = -10 and along -x from x = n - 1 + 10, on a
    // 6 x 6 grid of (y, z) in {-0.125, 0.125, ..., 1.125}: 4 x 4 inside.
    let look = |eye_x: f64, target_x: f64| {
        Camera::look_at(
            [eye_x, 0.5, 0.5],
            [target_x, 0.5, 0.5],
            [0.0, 0.0, 1.0],
            Projection::Ortho { frame_mm: 1.5 },
            6,
            6,
        )
        .unwrap()
    };
    let last = (n - 1) as f64;
    let cams = vec![
        ("along +x".to_string(), look(-10.0, 0.0)),
        ("along -x".to_string(), look(last + 10.0, last)),
    ];
    for (_, c) in &cams {
        assert_eq!(c.ray(0, 0).dir.map(f64::abs), [1.0, 0.0, 0.0].into());
    }
    let t = check_renders(&vol, &cams, Expect::Mixed);
    // Codes saturate at 254 here (i16 words after widening), so CD needs
    // about n / 2 / 255 leaps where FVT takes n / 2 steps: at least 50x
    // fewer.
    assert!(
        t.cd_steps * 50 < t.fvt_steps,
        "CD {} steps vs FVT {}",
        t.cd_steps,
        t.fvt_steps
    );

    // Analytic depth and hits.
    for (cn, cam) in &cams {
        for hit in [HitMethod::Int, HitMethod::Exact] {
            let (f, _) = run(&vol, cam, &Mode::Depth { hit }, Method::Cd { min_leap: 1 });
            let (m, ms) = run(&vol, cam, &Mode::Mip, Method::Cd { min_leap: 1 });
            let d = f.depth.unwrap();
            let mut inside = 0;
            for py in 0..6 {
                for px in 0..6 {
                    let r = cam.ray(px, py);
                    let (y, z) = (r.origin[1], r.origin[2]);
                    let got = d[(py * 6 + px) as usize];
                    let is_inside = (0.0..=1.0).contains(&y) && (0.0..=1.0).contains(&z);
                    inside += is_inside as u32;
                    if !(is_inside && 200.0 * y >= 100.0) {
                        assert!(
                            got.is_nan(),
                            "{cn} {hit:?} ({y}, {z}): hit {got}, expected none"
                        );
                        continue;
                    }
                    // +x: the first 1-cell starts at x0 - 1, the
                    // interpolant reaches iso at u = 100 / (200 y); -x:
                    // the exit face of the last cell is already >= iso.
                    let want = if r.dir[0] > 0.0 {
                        (x0 - 1) as f64 + 100.0 / (200.0 * y) + 10.0
                    } else {
                        10.0
                    };
                    assert!(
                        (got as f64 - want).abs() <= 0.04,
                        "{cn} {hit:?} ({y}, {z}): depth {got}, expected {want}"
                    );
                }
            }
            assert_eq!(inside, 16);
            // MIP reports every ray that crosses a 1-cell: all 16 inside.
            assert_eq!(ms.hits, 16, "{cn}: mip hits");
            assert!(m.rgb.iter().any(|&b| b > 0));
        }
    }
}

// ---- neighbouring slices 1e-9 mm apart at 1e6 mm ----

#[test]
fn slices_1e_9_apart_at_1e6() {
    // Accepted: z positions 1e6, 1e6 + 1e-9, ... are finite and strictly
    // increasing in f64 (ulp(1e6) = 1.16e-10 mm), so cdvol takes them.
    let z: [f64; 7] = [
        1e6,
        1e6 + 1e-9,
        1e6 + 1.0,
        1e6 + 1.0 + 1e-9,
        1e6 + 1.0 + 2e-9,
        1e6 + 2.5,
        1e6 + 3.0,
    ];
    assert!(z.windows(2).all(|w| w[1] > w[0]));
    let dims = [9, 8, z.len()];
    let v = blob(dims, 120.0);
    let zs: Vec<String> = z.iter().map(|x| format!("{x:?}")).collect();
    let axes = [
        "1".to_string(),
        "0.5".to_string(),
        format!("{{\"positions\": [{}]}}", zs.join(", ")),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (iso, brick) in [(60.0, 4), (1.0, 8)] {
        let vol = prep_file(dir.path(), "thin", dims, ("u8", &v), &axes, iso, brick).unwrap();
        // The positions survive the header bit for bit.
        let got = vol.header().axes[2].coords();
        assert!(got.iter().zip(&z).all(|(a, b)| a.to_bits() == b.to_bits()));
        check_classification(&vol, dims, &v, iso);
        let t = check_renders(&vol, &cameras(&vol, 20), Expect::Mixed);
        assert!(t.hits > 0);
    }
}

// ---- inputs past the limits are refused, naming the field ----

#[test]
fn past_the_limits_is_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let refuse = |name: &str, dims: [usize; 3], axes: [&str; 3], extra: &str| -> String {
        let n: usize = dims.iter().product();
        let side = write_stack(dir.path(), name, dims, "u8", &vec![0.0; n], axes, extra);
        match RawSource::open(&side) {
            Ok(_) => panic!("{name}: accepted"),
            Err(e) => {
                let m = e.to_string();
                assert!(
                    m.contains(&format!("{name}.json")),
                    "{name}: no file in {m}"
                );
                m
            }
        }
    };
    // Refused: one sample past 2^20 along x -> field `dims[0]`.
    let m = refuse(
        "wide",
        [MAX_SAMPLES_PER_AXIS + 1, 2, 2],
        ["1", "1", "1"],
        "",
    );
    assert!(
        m.contains("field `dims[0]`") && m.contains("at most 1048576"),
        "{m}"
    );
    // Refused: a z gap of 1e-3 mm at 1e14 mm is below half ulp(1e14)
    // (0.0156 mm): the two positions round to the same number -> field
    // `z.spacing`, not strictly increasing. (A gap below MIN_SPACING_MM,
    // 1e-6 mm, is refused first: harden_json.)
    let m = refuse(
        "gap",
        [2, 2, 3],
        ["1", "1", "{\"spacing\": [1e-3, 1]}"],
        ", \"origin\": [0, 0, 1e14]",
    );
    assert!(
        m.contains("field `z.spacing`") && m.contains("strictly increasing"),
        "{m}"
    );
    // Refused: positions beyond MAX_COORD_MM (1e15 mm) -> field `x`; a
    // spacing of 1e308 would also overflow, but the bound comes first.
    let m = refuse("huge", [4, 2, 2], ["1e308", "1", "1"], "");
    assert!(
        m.contains("field `x`") && m.contains("expected at most 1e15 mm"),
        "{m}"
    );
    let m = refuse(
        "far",
        [2, 2, 2],
        ["1", "1", "1"],
        ", \"origin\": [0, 2e15, 0]",
    );
    assert!(
        m.contains("field `y`") && m.contains("expected at most 1e15 mm"),
        "{m}"
    );
}

// ---- found by this suite, fixed ----
//
// Each volume below is all-full with every sample >= iso, so by the
// contract of this file every entering ray must hit in surface, depth and
// cost mode.

/// The renderer keeps sample values as f32 while prep classified the f64
/// values: a value at iso that rounds down in f32 (f64 0.7 -> 0.699999988,
/// u32 16777217 -> 16777216) was a 1-cell whose surface was never found.
/// Fixed: the renderer compares against the iso value mapped to f32 the
/// same (monotone) way (src/render/cache/mod.rs, `to_f32`).
#[test]
fn values_at_iso_beyond_f32_precision_render() {
    // Accepted: f64 data all 0.7, iso 0.7 (0.7 as f32 is below 0.7).
    check_case(&case(
        "f64-at-iso",
        "f64",
        vec![0.7; N],
        0.7,
        Expect::Full { every_sample: true },
        None,
    ));
    // Accepted: u32 data all 2^24 + 1, iso 2^24 + 1.
    check_case(&case(
        "u32-at-iso",
        "u32",
        vec![16777217.0; N],
        16777217.0,
        Expect::Full { every_sample: true },
        None,
    ));
}

/// +inf samples reach every finite iso, so their cells are 1-cells
/// (classify.rs), but the trilinear interpolant gave NaN for inf - inf
/// and 0 * inf: an all-+inf volume rendered no pixel. Fixed: the renderer
/// saturates +-inf to +-f32::MAX (src/render/cache/mod.rs, `to_f32`).
#[test]
fn all_pos_inf_renders() {
    // Accepted: f32 all +inf, iso 0.
    check_case(&case(
        "f32-all-pos-inf",
        "f32",
        vec![f64::INFINITY; N],
        0.0,
        Expect::Full { every_sample: true },
        None,
    ));
}
