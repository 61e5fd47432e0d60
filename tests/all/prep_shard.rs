//! Sharded prep (`prep --shard K/N --pass 1|2`, `prep-merge`): the merged
//! file equals the single prep's byte for byte, on random volumes against
//! the breadth-first oracle, on codes that reach across many shards
//! thinner than the codes, on every classification and storage, and on
//! the real CT; parts that do not make one whole are refused by name.

use std::path::{Path, PathBuf};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::input::SliceSource;
use cdvol::prep::shard::{bricks, merge, parts_dir, scan, shard_file};
use cdvol::prep::{prep, PrepError, PrepOptions};
use cdvol::progress::NoProgress;
use proptest::prelude::*;

use crate::common::*;

/// Prepares `src` in `n` shards into `out`: every scan, then every part
/// (top shard first, to show the order does not matter), then the merge.
fn sharded(src: &dyn SliceSource, opts: &PrepOptions, n: u32, out: &Path) {
    let parts = parts_dir(out);
    for k in 0..n {
        scan(src, &parts, k, n, opts, &NoProgress).unwrap();
    }
    for k in (0..n).rev() {
        bricks(src, &parts, k, n, opts, &NoProgress).unwrap();
        assert!(
            !shard_file(&parts, k, n, "spill").exists(),
            "pass 2 removes its spill"
        );
    }
    let files: Vec<PathBuf> = (0..n).map(|k| shard_file(&parts, k, n, "part")).collect();
    merge(&files, out, &NoProgress).unwrap();
}

/// Single prep and an `n`-shard prep of `src` write the same bytes;
/// returns the single prep's file.
fn same_bytes(dir: &Path, src: &dyn SliceSource, opts: &PrepOptions, n: u32) -> PathBuf {
    let one = dir.join("one.cdv");
    prep(src, &one, opts, &NoProgress).unwrap();
    let out = dir.join(format!("sharded{n}.cdv"));
    sharded(src, opts, n, &out);
    let (a, b) = (std::fs::read(&one).unwrap(), std::fs::read(&out).unwrap());
    assert!(
        a == b,
        "{n} shards: {} bytes differ from one prep's ({} vs {} bytes)",
        a.iter().zip(&b).filter(|(x, y)| x != y).count(),
        a.len(),
        b.len()
    );
    one
}

fn stack(dir: &Path, dims: [usize; 3], dtype: &str, values: &[f64]) -> RawSource {
    let side = write_stack(dir, "v", dims, dtype, values, ["1", "0.5", "1.25"], "");
    RawSource::open(&side).unwrap()
}

/// The codes and 1-cells of a packed file equal the oracle's.
fn check_oracle(file: &Path, values: &[f64], dims: [usize; 3], iso: f64) {
    let vol = PackedVolume::open(file).unwrap();
    let obj = classify_iso(values, dims, iso);
    let dist = chessboard_bfs(&obj, dims.map(|d| d - 1));
    let back = read_back(&vol, values);
    assert_eq!(
        back.codes,
        expected_codes(&dist, vol.header().codes.max_code()),
        "codes differ from the BFS oracle"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Random volumes of up to 10 brick layers, any shard count up to one
    /// layer a shard: the bytes of one prep and the oracle's codes.
    #[test]
    fn random_volumes_shard_to_the_same_bytes(
        (dims, values, brick) in random_volume([14, 13, 42], 6),
        n_pick in 0u32..1000,
        dtype in prop_oneof![Just("u8"), Just("i16"), Just("f32")],
        halo in proptest::bool::ANY,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let v: Vec<f64> = values
            .iter()
            .enumerate()
            .map(|(i, &x)| match dtype {
                "i16" => x * 10.0 - 1024.0,
                "f32" if i % 11 == 5 => f64::NAN,
                _ => x,
            })
            .collect();
        let iso = if dtype == "i16" { 976.0 } else { 150.0 };
        let src = stack(dir.path(), dims, dtype, &v);
        let layers = (dims[2] - 1).div_ceil(brick) as u32;
        let n = 1 + n_pick % layers;
        let mut opts = PrepOptions::new(Classification::Iso { iso });
        opts.brick_size = brick;
        opts.gradient_halo = halo;
        let one = same_bytes(dir.path(), &src, &opts, n);
        if !halo {
            check_oracle(&one, &v, dims, iso);
        }
    }
}

/// Two single 1-cells far apart in a tall stack: codes of up to 120 cells
/// reach across tens of shards of 4 cells, and the empty stretch beyond
/// the last object saturates at 254 across shards that hold no 1-cell.
#[test]
fn codes_reach_across_many_thin_shards() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [9, 8, 560];
    let mut v = vec![0.0; dims[0] * dims[1] * dims[2]];
    let at = |x: usize, y: usize, z: usize| (z * dims[1] + y) * dims[0] + x;
    v[at(2, 3, 4)] = 200.0;
    v[at(6, 1, 245)] = 200.0;
    let src = stack(dir.path(), dims, "u8", &v);
    let mut opts = PrepOptions::new(Classification::Iso { iso: 150.0 });
    opts.brick_size = 4;
    for n in [2, 7, 40, 140] {
        let sub = dir.path().join(format!("n{n}"));
        std::fs::create_dir(&sub).unwrap();
        let one = same_bytes(&sub, &src, &opts, n);
        if n == 2 {
            check_oracle(&one, &v, dims, 150.0);
            let s = PackedVolume::open(&one).unwrap().header().summary.clone();
            assert!(
                s.code_histogram[254..].iter().sum::<u64>() > 0,
                "codes saturate"
            );
        }
    }
}

/// Pass 2 reads the seam planes of the shards within 254 slices only: a
/// 1-cell at the top of shard 0 is 253 cells from shard 2, across a shard
/// of 252 slices, so shard 2 must read shard 0's plane (with 256 slices
/// between, it would be too far to count).
#[test]
fn seams_reach_exactly_as_far_as_the_codes() {
    let dir = tempfile::tempdir().unwrap();
    // Bricks of 4, 189 layers: 3 shards of 63 layers, 252 cells each.
    let dims = [6, 5, 757];
    let mut v = vec![0.0; dims[0] * dims[1] * dims[2]];
    v[(251 * dims[1] + 2) * dims[0] + 3] = 200.0;
    let src = stack(dir.path(), dims, "u8", &v);
    let mut opts = PrepOptions::new(Classification::Iso { iso: 150.0 });
    opts.brick_size = 4;
    let one = same_bytes(dir.path(), &src, &opts, 3);
    check_oracle(&one, &v, dims, 150.0);
    let s = PackedVolume::open(&one).unwrap().header().summary.clone();
    assert!(s.code_histogram[252] > 0, "codes of 252 reach shard 2");
}

/// Transfer-function classification, a label map and format version 2.
#[test]
fn every_classification_and_format_shards_alike() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [20, 18, 49];
    let values: Vec<f64> = (0..dims.iter().product::<usize>())
        .map(|i| (mix(i as u64) % 5) as f64 * (mix(i as u64 * 7).is_multiple_of(3)) as u64 as f64)
        .collect();
    let src = stack(dir.path(), dims, "u16", &values);
    let tf = Classification::TransferFunction {
        tf: white_tf(&[(2.5, 0.0), (3.0, 0.7), (3.5, 0.0)]),
    };
    let cases: Vec<(&str, PrepOptions)> = vec![
        ("transfer function", {
            let mut o = PrepOptions::new(tf);
            o.brick_size = 8;
            o
        }),
        ("labels", {
            let mut o = PrepOptions::new(Classification::Iso { iso: 0.5 });
            o.labels = true;
            o.brick_size = 4;
            o
        }),
        ("format 2", {
            let mut o = PrepOptions::new(Classification::Iso { iso: 3.5 });
            o.format_version = 2;
            o.brick_size = 4;
            o
        }),
    ];
    for (what, opts) in cases {
        let sub = dir.path().join(what.replace(' ', "-"));
        std::fs::create_dir(&sub).unwrap();
        let one = same_bytes(&sub, &src, &opts, 5);
        let h = PackedVolume::open(&one).unwrap().header().clone();
        assert!(h.summary.one_cells > 0, "{what}: the fixture has 1-cells");
        if what == "labels" {
            assert!(h.labels.is_some(), "labels recorded");
        }
    }
}

/// The real CT (256 x 256 x 108, i16) with an iso and a preset.
#[test]
fn the_real_ct_shards_to_the_same_bytes() {
    let ct = real_ct();
    let dir = tempfile::tempdir().unwrap();
    let src = cdvol::input::open(&ct).unwrap();
    let iso = PrepOptions::new(Classification::Iso { iso: 300.0 });
    same_bytes(dir.path(), src.as_ref(), &iso, 3);
    let sub = dir.path().join("preset");
    std::fs::create_dir(&sub).unwrap();
    let mut skin = PrepOptions::new(Classification::Iso { iso: 0.0 });
    skin.preset = Some("ct-skin".into());
    same_bytes(&sub, src.as_ref(), &skin, 4);
}

/// Parts that do not make one whole, and steps out of order, are refused
/// with the file and the reason.
#[test]
fn mismatched_missing_and_early_parts_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [10, 10, 33];
    let values: Vec<f64> = (0..1000 * 33 / 10)
        .map(|i| {
            if mix(i as u64).is_multiple_of(50) {
                200.0
            } else {
                0.0
            }
        })
        .collect();
    let src = stack(dir.path(), dims, "u8", &values);
    let mut opts = PrepOptions::new(Classification::Iso { iso: 150.0 });
    opts.brick_size = 4;
    let out = dir.path().join("v.cdv");
    let parts = parts_dir(&out);
    // Pass 2 before every pass 1: names the missing scan.
    scan(&src, &parts, 0, 3, &opts, &NoProgress).unwrap();
    let e = bricks(&src, &parts, 0, 3, &opts, &NoProgress).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("shard-0001-of-0003.scan") && msg.contains("--pass 1"),
        "{msg}"
    );
    scan(&src, &parts, 1, 3, &opts, &NoProgress).unwrap();
    // A scan of another classification: its file and the field.
    let mut other = opts.clone();
    other.classification = Classification::Iso { iso: 100.0 };
    scan(&src, &parts, 2, 3, &other, &NoProgress).unwrap();
    let e = bricks(&src, &parts, 0, 3, &opts, &NoProgress).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, PrepError::Shard { .. }), "{msg}");
    assert!(
        msg.contains("shard-0002-of-0003.scan") && msg.contains("decided"),
        "{msg}"
    );
    scan(&src, &parts, 2, 3, &opts, &NoProgress).unwrap();
    for k in 0..2 {
        bricks(&src, &parts, k, 3, &opts, &NoProgress).unwrap();
    }
    // A missing part: named, with the command that writes it.
    let files: Vec<PathBuf> = (0..2).map(|k| shard_file(&parts, k, 3, "part")).collect();
    let e = merge(&files, &out, &NoProgress).unwrap_err().to_string();
    assert!(
        e.contains("shard 2 of 3 is missing") && e.contains("--shard 2/3 --pass 2"),
        "{e}"
    );
    assert!(!out.exists(), "nothing written");
    // A part given twice.
    let twice = vec![files[0].clone(), files[0].clone(), files[1].clone()];
    let e = merge(&twice, &out, &NoProgress).unwrap_err().to_string();
    assert!(e.contains("shard 0 of 3 again"), "{e}");
    // A truncated part.
    bricks(&src, &parts, 2, 3, &opts, &NoProgress).unwrap();
    let p2 = shard_file(&parts, 2, 3, "part");
    let bytes = std::fs::read(&p2).unwrap();
    std::fs::write(&p2, &bytes[..bytes.len() - 5]).unwrap();
    let all: Vec<PathBuf> = (0..3).map(|k| shard_file(&parts, k, 3, "part")).collect();
    let e = merge(&all, &out, &NoProgress).unwrap_err().to_string();
    assert!(
        e.contains("shard-0002-of-0003.part") && e.contains("not a complete"),
        "{e}"
    );
    assert!(!out.exists(), "nothing written");
    // More shards than brick layers, and the octant codes.
    let e = scan(&src, &parts, 0, 9, &opts, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("shard") && e.contains("brick layers"), "{e}");
    let mut aniso = opts.clone();
    aniso.aniso = true;
    let e = scan(&src, &parts, 0, 3, &aniso, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("aniso") && e.contains("one process"), "{e}");
}

/// The command line: `prep --shard K/N --pass 1|2` then `prep-merge` of
/// the parts directory writes the file `prep` writes.
#[test]
fn cli_shards_and_merges_to_the_same_file() {
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("ct.json");
    ok(cdvol()
        .args(["phantom", "ct", "--dims", "40,36,50", "-o"])
        .arg(&side));
    let one = dir.path().join("one.cdv");
    ok(cdvol()
        .arg("prep")
        .arg(&side)
        .args(["--iso", "-500", "--brick", "8", "-o"])
        .arg(&one));
    let out = dir.path().join("four.cdv");
    for pass in ["1", "2"] {
        for k in 0..4 {
            let text = ok(cdvol()
                .arg("prep")
                .arg(&side)
                .args(["--iso", "-500", "--brick", "8", "--shard"])
                .arg(format!("{k}/4"))
                .args(["--pass", pass, "-o"])
                .arg(&out));
            assert!(text.contains(&format!("pass {pass}")), "{text}");
        }
    }
    let text = ok(cdvol()
        .arg("prep-merge")
        .arg(parts_dir(&out))
        .arg("-o")
        .arg(&out));
    assert!(text.contains("from 4 parts"), "{text}");
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&out).unwrap());
    // --pass without --shard is refused by clap.
    let e = fails(
        cdvol()
            .arg("prep")
            .arg(&side)
            .args(["--iso", "0", "--pass", "1", "-o"])
            .arg(&out),
    );
    assert!(e.contains("--shard"), "{e}");
}
