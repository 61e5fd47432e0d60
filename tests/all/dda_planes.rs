//! `cdvol prep --dda`: the city-block and chamfer 3-4-5 planes read back
//! through the renderer's brick cache equal brute-force oracles on the
//! classified cells (uniform bricks answer the chessboard lower bound),
//! and a file prepared without them reads and renders as before.

use std::path::Path;

use crate::common::*;
use cdvol::classify::Classification;
use cdvol::format::reader::{BrickData, PackedVolume};
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::cache::{Accessor, BrickCache};
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::{CodeSource, DistKind, Method};
use cdvol::render::{render, Mode, RenderOptions};
use proptest::prelude::*;

const KINDS: [DistKind; 3] = [DistKind::Cityblock, DistKind::Chessboard, DistKind::Chamfer];

/// Preps the stack at `side` twice, with and without `--dda`.
fn prep_both(
    dir: &Path,
    side: &Path,
    iso: f64,
    brick: usize,
    aniso: bool,
) -> (PackedVolume, PackedVolume) {
    let src = RawSource::open(side).unwrap();
    let mut opts = PrepOptions::new(Classification::Iso { iso });
    opts.brick_size = brick;
    opts.aniso = aniso;
    let plain = dir.join("plain.cdv");
    prep(&src, &plain, &opts, &NoProgress).unwrap();
    opts.dda = true;
    let dda = dir.join("dda.cdv");
    let r = prep(&src, &dda, &opts, &NoProgress).unwrap();
    assert!(r.header.dda);
    (
        PackedVolume::open(&dda).unwrap(),
        PackedVolume::open(&plain).unwrap(),
    )
}

/// Brute force over the 1-cells, in stored units: `[city block,
/// chessboard, chamfer 3-4-5]` per cell, saturated at 254 (the chessboard
/// at 255, as the codes are: code = distance - 1, at most 254). Chamfer by its
/// closed form: offsets sorted `a >= b >= c`, `3(a-b) + 4(b-c) + 5c`.
fn brute(obj: &[u8], cells: [usize; 3]) -> [Vec<u8>; 3] {
    let [cx, cy, _] = cells;
    let pos = |i: usize| [(i % cx) as i64, (i / cx % cy) as i64, (i / cx / cy) as i64];
    let objs: Vec<[i64; 3]> = (0..obj.len()).filter(|&i| obj[i] != 0).map(pos).collect();
    let mut out = [
        vec![0u8; obj.len()],
        vec![0u8; obj.len()],
        vec![0u8; obj.len()],
    ];
    for i in 0..obj.len() {
        let v = pos(i);
        let mut best = [254i64, 255, 254];
        for q in &objs {
            let mut d = [0, 1, 2].map(|k| (q[k] - v[k]).abs());
            d.sort_unstable_by(|a, b| b.cmp(a));
            let l1 = d[0] + d[1] + d[2];
            let ch = 3 * (d[0] - d[1]) + 4 * (d[1] - d[2]) + 5 * d[2];
            best = [best[0].min(l1), best[1].min(d[0]), best[2].min(ch)];
        }
        for (o, b) in out.iter_mut().zip(best) {
            o[i] = b as u8;
        }
    }
    out
}

/// Checks every cell's `distance()` through the cache. Returns the number
/// of uniform bricks and of cells in them.
fn check_distances(vol: &PackedVolume, obj: &[u8]) -> (u64, u64) {
    let h = vol.header();
    let cells = h.cells().map(|c| c as usize);
    let [cx, cy, _] = cells;
    let want = brute(obj, cells);
    let max_code = h.codes.max_code();
    let cache = BrickCache::new(vol, 64 << 20);
    let mut acc = Accessor::new(&cache);
    let (mut uniform_bricks, mut uniform_cells) = (0, 0);
    for id in 0..h.brick_count() {
        let e = vol.index()[id as usize];
        let c = h.brick_coords(id);
        let ranges: [(u64, u64); 3] = std::array::from_fn(|k| h.brick_cells(k, c[k]));
        if e.is_uniform() {
            uniform_bricks += 1;
        }
        for z in ranges[2].0..ranges[2].1 {
            for y in ranges[1].0..ranges[1].1 {
                for x in ranges[0].0..ranges[0].1 {
                    let i = (z as usize * cy + y as usize) * cx + x as usize;
                    let cell = [x as u32, y as u32, z as u32];
                    // The chessboard bound from the stored (saturated) code.
                    let code = if want[1][i] == 0 {
                        None
                    } else {
                        Some((want[1][i] as u32 - 1).min(max_code))
                    };
                    if e.is_uniform() {
                        uniform_cells += 1;
                        assert_eq!(code, Some(e.uniform_code), "uniform brick {id}");
                    }
                    for (k, kind) in KINDS.into_iter().enumerate() {
                        let bound = code.map_or(0, |n| ((n + 1) * kind.unit()).min(254) as u8);
                        let expect = if kind == DistKind::Chessboard || e.is_uniform() {
                            bound
                        } else {
                            want[k][i]
                        };
                        assert_eq!(
                            acc.distance(cell, kind),
                            expect,
                            "{kind:?} at {cell:?}, brick {id} (uniform {})",
                            e.is_uniform()
                        );
                    }
                }
            }
        }
    }
    assert!(acc.error.is_none());
    (uniform_bricks, uniform_cells)
}

/// The `--dda` file holds the plain file's payloads followed by the two
/// planes, the same index flags and the same summary but for payload sizes.
fn check_extends_plain(dda: &PackedVolume, plain: &PackedVolume) {
    let (hd, hp) = (dda.header(), plain.header());
    assert!(hd.dda && !hp.dda);
    let mut sd = hd.summary.clone();
    sd.payload_bytes = hp.summary.payload_bytes;
    sd.raw_payload_bytes = hp.summary.raw_payload_bytes;
    assert_eq!(sd, hp.summary);
    for id in 0..hp.brick_count() {
        let (ed, ep) = (dda.index()[id as usize], plain.index()[id as usize]);
        assert_eq!(
            (ed.flags, ed.uniform_code),
            (ep.flags, ep.uniform_code),
            "brick {id}"
        );
        let (pd, pp) = (
            dda.read_payload(id).unwrap(),
            plain.read_payload(id).unwrap(),
        );
        match (pd, pp) {
            (None, None) => {}
            (Some(d), Some(p)) => {
                let c = hd.brick_coords(id);
                let n: u64 = hd.brick_samples(c).iter().map(|s| s - 1).product();
                assert_eq!(d.len() as u64, p.len() as u64 + 2 * n, "brick {id}");
                assert_eq!(&d[..p.len()], &p[..], "brick {id}");
                let b = dda.read_brick(id).unwrap();
                let BrickData::Words {
                    dda: Some(planes), ..
                } = &b.data
                else {
                    panic!("brick {id}: no DDA planes");
                };
                assert_eq!(&planes[0][..], &d[p.len()..p.len() + n as usize]);
                assert_eq!(&planes[1][..], &d[p.len() + n as usize..]);
                let BrickData::Words { dda: None, .. } = plain.read_brick(id).unwrap().data else {
                    panic!("brick {id}: planes in a plain file");
                };
            }
            _ => panic!("brick {id}: uniform in one file only"),
        }
    }
}

/// A long, thin u8 volume: a ball and a lone hot sample at the low x end,
/// so the bricks at the high x end are uniform (codes saturate at 63 for
/// data in 0..=191).
#[test]
fn planes_through_the_cache_with_uniform_bricks() {
    let dims = [121usize, 14, 13];
    let mut values = vec![0.0f64; dims.iter().product()];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let i = (z * dims[1] + y) * dims[0] + x;
                let r2 =
                    (x as f64 - 5.0).powi(2) + (y as f64 - 6.0).powi(2) + (z as f64 - 6.5).powi(2);
                values[i] = if r2 <= 9.0 {
                    191.0
                } else {
                    ((i * 7) % 140) as f64
                };
            }
        }
    }
    values[(10 * dims[1] + 2) * dims[0] + 30] = 160.0;
    let dir = tempfile::tempdir().unwrap();
    let side = write_stack(dir.path(), "v", dims, "u8", &values, ["1", "1", "1"], "");
    let (dda, plain) = prep_both(dir.path(), &side, 150.0, 8, false);
    assert_eq!(dda.header().codes.max_code(), 63);
    let obj = classify_iso(&values, dims, 150.0);
    let (ub, uc) = check_distances(&dda, &obj);
    assert!(ub >= 2, "expected uniform bricks, got {ub}");
    println!(
        "{ub} of {} bricks uniform ({uc} cells answer the chessboard bound)",
        dda.header().brick_count()
    );
    check_extends_plain(&dda, &plain);
    // The plain file answers the chessboard bound everywhere.
    let cache = BrickCache::new(&plain, 64 << 20);
    let mut acc = Accessor::new(&cache);
    let cells = plain.header().cells();
    for (i, &o) in obj.iter().enumerate() {
        let c = [
            (i as u64 % cells[0]) as u32,
            (i as u64 / cells[0] % cells[1]) as u32,
            (i as u64 / cells[0] / cells[1]) as u32,
        ];
        let cb = acc.distance(c, DistKind::Chessboard);
        assert_eq!(cb == 0, o != 0);
        assert_eq!(acc.distance(c, DistKind::Cityblock), cb);
        assert_eq!(
            acc.distance(c, DistKind::Chamfer),
            (cb as u32 * 3).min(254) as u8
        );
    }
    // Same images from both files.
    for (view, persp) in [([0.0, 0.0], false), ([37.0, 23.0], true)] {
        let cam = orbit(&dda, view, persp.then_some(35.0), 40, 40);
        for method in [Method::Fvt, Method::Cd { min_leap: 1 }] {
            for mode in [
                Mode::Mip,
                Mode::Surface {
                    hit: HitMethod::Int,
                    shadows: true,
                },
            ] {
                let o = RenderOptions {
                    tile: 8,
                    cache_bytes: 1 << 20,
                    cd_lazy_min: Some(4),
                    ..RenderOptions::new(mode, method)
                };
                let (a, sa) = render(&dda, &cam, &o, &NoProgress).unwrap();
                let (b, sb) = render(&plain, &cam, &o, &NoProgress).unwrap();
                assert_eq!(a.rgb, b.rgb);
                assert_eq!(sa.hits, sb.hits);
            }
        }
    }
}

fn volume() -> impl Strategy<Value = ([usize; 3], Vec<f64>, usize)> {
    random_volume([17, 15, 13], 40)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn random_volumes(
        (dims, values, brick) in volume(),
        dtype in prop_oneof![Just("u8"), Just("i16"), Just("f32")],
        aniso in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let side = write_stack(dir.path(), "v", dims, dtype, &values, ["1", "0.5", "2"], "");
        let (dda, plain) = prep_both(dir.path(), &side, 150.0, brick, aniso);
        let obj = classify_iso(&values, dims, 150.0);
        check_distances(&dda, &obj);
        check_extends_plain(&dda, &plain);
        // The codes read back are the plain file's.
        prop_assert_eq!(read_back(&dda, &values).codes, read_back(&plain, &values).codes);
    }
}

/// A traversal the file cannot serve is refused by name (issue 51, item
/// 7): `--traversal dda-chamfer` (or `dda-cityblock`) on a file prepared
/// without `--dda` used to run silently.
#[test]
fn dda_traversals_without_their_planes_are_refused_by_name() {
    use crate::common::{cdvol, fails, ok, write_stack};
    let d = tempfile::tempdir().unwrap();
    let v: Vec<f64> = (0..8 * 8 * 8).map(|i| ((i * 37) % 101) as f64).collect();
    write_stack(d.path(), "v", [8, 8, 8], "u8", &v, ["1", "1", "1"], "");
    let prep = |out: &str, extra: &[&str]| {
        ok(cdvol()
            .current_dir(d.path())
            .args(["prep", "-q", "v.json", "-o", out, "--iso", "90"])
            .args(extra));
    };
    prep("plain.cdv", &[]);
    prep("dda.cdv", &["--dda"]);
    for t in ["dda-chamfer", "dda-cityblock"] {
        let render = |file: &str| {
            let mut c = cdvol();
            c.current_dir(d.path()).args([
                "experiment",
                "render",
                "-q",
                file,
                "-o",
                "x.png",
                "--width",
                "16",
                "--height",
                "16",
                "--traversal",
                t,
            ]);
            c
        };
        let e = fails(&mut render("plain.cdv"));
        for w in ["plain.cdv", t, "--dda"] {
            assert!(e.contains(w), "{w:?} not in {e}");
        }
        ok(&mut render("dda.cdv"));
    }
}
