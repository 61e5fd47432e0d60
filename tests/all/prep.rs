//! End-to-end prep on random small volumes: the codes read back from the
//! packed file equal a breadth-first chessboard oracle, every 1-cell keeps
//! its 8 exact vertex values, and the anisotropic block codes equal a
//! brute-force octant search.

use crate::common::*;
use cdvol::classify::Classification;
use cdvol::dt::ANISO_BLOCK;
use cdvol::format::reader::{BrickData, PackedVolume};
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use proptest::prelude::*;

fn prep_values(
    dir: &std::path::Path,
    dims: [usize; 3],
    dtype: &str,
    values: &[f64],
    iso: f64,
    brick: usize,
    aniso: bool,
) -> PackedVolume {
    let side = write_stack(
        dir,
        "v",
        dims,
        dtype,
        values,
        ["1", "0.5", "{\"spacing\": null}"],
        "",
    )
    .to_path_buf();
    // Rectilinear z: replace the placeholder with real gaps.
    let gaps: Vec<String> = (0..dims[2] - 1)
        .map(|i| format!("{}", 1.0 + i as f64 * 0.1 + 1.0 / 3.0))
        .collect();
    let text = std::fs::read_to_string(&side).unwrap().replace(
        "{\"spacing\": null}",
        &format!("{{\"spacing\": [{}]}}", gaps.join(",")),
    );
    std::fs::write(&side, text).unwrap();
    let src = RawSource::open(&side).unwrap();
    let out = dir.join("v.cdv");
    let axes_in = cdvol::input::SliceSource::meta(&src).grid.axes.clone();
    let mut opts = PrepOptions::new(Classification::Iso { iso });
    opts.brick_size = brick;
    opts.aniso = aniso;
    prep(&src, &out, &opts, &NoProgress).unwrap();
    let vol = PackedVolume::open(&out).unwrap();
    // Axis positions survive the JSON header bit for bit.
    for (k, (got, want)) in vol.header().axes.iter().zip(&axes_in).enumerate() {
        let same = got
            .coords()
            .iter()
            .zip(want.coords())
            .all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "axis {k} changed");
    }
    vol
}

fn check(dims: [usize; 3], dtype: &str, values: &[f64], iso: f64, brick: usize, aniso: bool) {
    let dir = tempfile::tempdir().unwrap();
    let vol = prep_values(dir.path(), dims, dtype, values, iso, brick, aniso);
    let cells = dims.map(|d| d - 1);
    let obj = classify_iso(values, dims, iso);
    let dist = chessboard_bfs(&obj, cells);
    let max_code = vol.header().codes.max_code();
    let back = read_back(&vol, values);
    assert_eq!(
        back.codes,
        expected_codes(&dist, max_code),
        "codes differ from the BFS oracle"
    );
    assert_eq!(
        back.checked_one_cells,
        obj.iter().filter(|&&o| o != 0).count()
    );
    let s = &vol.header().summary;
    assert_eq!(s.one_cells as usize, back.checked_one_cells);
    assert_eq!(s.code_histogram.iter().sum::<u64>() + s.one_cells, s.cells);
    if aniso {
        check_octants(&vol, &obj, cells, max_code);
    }
}

/// Brute force: per block, per octant, the smallest code of its cells.
fn check_octants(vol: &PackedVolume, obj: &[u8], cells: [usize; 3], max_code: u32) {
    let [cx, cy, cz] = cells;
    let objs: Vec<[i64; 3]> = (0..obj.len())
        .filter(|&i| obj[i] != 0)
        .map(|i| [(i % cx) as i64, (i / cx % cy) as i64, (i / cx / cy) as i64])
        .collect();
    let h = vol.header();
    let g = ANISO_BLOCK;
    for id in 0..h.brick_count() {
        let b = vol.read_brick(id).unwrap();
        let BrickData::Words {
            octants: Some(oct), ..
        } = &b.data
        else {
            // Uniform bricks: every cell is far from objects in all octants
            // at least as much as isotropically, which the codes check
            // already covers.
            continue;
        };
        let nb = h.brick_blocks(b.coords).unwrap().map(|n| n as usize);
        for kz in 0..nb[2] {
            for ky in 0..nb[1] {
                for kx in 0..nb[0] {
                    let got = oct[(kz * nb[1] + ky) * nb[0] + kx];
                    for (o, &got_o) in got.iter().enumerate() {
                        let mut want = u32::MAX;
                        for z in 0..g {
                            for y in 0..g {
                                for x in 0..g {
                                    let v = [
                                        (b.first[0] as usize + kx * g + x) as i64,
                                        (b.first[1] as usize + ky * g + y) as i64,
                                        (b.first[2] as usize + kz * g + z) as i64,
                                    ];
                                    if v[0] >= cx as i64 || v[1] >= cy as i64 || v[2] >= cz as i64 {
                                        continue;
                                    }
                                    let mut d = 255i64;
                                    for q in &objs {
                                        let inside = (0..3).all(|k| {
                                            let dd = q[k] - v[k];
                                            if o >> k & 1 == 1 {
                                                dd <= 0
                                            } else {
                                                dd >= 0
                                            }
                                        });
                                        if inside {
                                            d = d.min(
                                                (0..3).map(|k| (q[k] - v[k]).abs()).max().unwrap(),
                                            );
                                        }
                                    }
                                    want = want.min((d.max(1) - 1) as u32);
                                }
                            }
                        }
                        assert_eq!(
                            got_o as u32,
                            want.min(max_code),
                            "brick {id} block {kx},{ky},{kz} octant {o}"
                        );
                    }
                }
            }
        }
    }
}

fn volume() -> impl Strategy<Value = ([usize; 3], Vec<f64>, usize)> {
    random_volume([19, 17, 15], 30)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]
    #[test]
    fn random_volumes_u8((dims, values, brick) in volume()) {
        check(dims, "u8", &values, 150.0, brick, false);
    }

    #[test]
    fn random_volumes_i16_aniso((dims, values, brick) in volume()) {
        let v: Vec<f64> = values.iter().map(|x| x * 10.0 - 1024.0).collect();
        check(dims, "i16", &v, 976.0, brick, true);
    }

    #[test]
    fn random_volumes_f32((dims, values, brick) in volume()) {
        // Every 7th sample NaN: background by policy.
        let v: Vec<f64> = values.iter().enumerate().map(|(i, x)| if i % 7 == 3 { f64::NAN } else { (x / 3.0) as f32 as f64 }).collect();
        check(dims, "f32", &v, 60.0, brick, false);
    }
}

#[test]
fn all_empty_and_all_full() {
    let dims = [13, 9, 11];
    let n = 13 * 9 * 11;
    // All empty: every brick uniform at the saturated code.
    let dir = tempfile::tempdir().unwrap();
    let vol = prep_values(dir.path(), dims, "u8", &vec![0.0; n], 1.0, 4, true);
    let h = vol.header();
    assert_eq!(h.summary.uniform_bricks, h.brick_count());
    assert_eq!(h.summary.one_cells, 0);
    check(dims, "u8", &vec![0.0; n], 1.0, 4, true);
    // All full.
    check(dims, "u8", &vec![5.0; n], 1.0, 8, true);
}

#[test]
fn one_cell_thick_objects_and_single_cells() {
    let dims = [37, 5, 9];
    let mut v = vec![0.0; 37 * 5 * 9];
    v[(4 * 5 + 2) * 37 + 18] = 255.0; // one sample -> 8  1-cells around it
    check(dims, "u8", &v, 200.0, 8, true);
    // One cell along an axis (2 samples).
    let dims = [2, 40, 3];
    let mut v = vec![0.0; 2 * 40 * 3];
    v[(40 + 39) * 2 + 1] = 9.0;
    check(dims, "u16", &v, 9.0, 4, true);
}

#[test]
fn u8_using_the_whole_range_is_widened_and_exact() {
    let dims = [9, 8, 7];
    let v: Vec<f64> = (0..9 * 8 * 7).map(|i| ((i * 37) % 256) as f64).collect();
    let dir = tempfile::tempdir().unwrap();
    let vol = prep_values(dir.path(), dims, "u8", &v, 250.0, 4, false);
    assert_eq!(vol.header().storage, cdvol::input::Dtype::I16);
    check(dims, "u8", &v, 250.0, 4, false);
}

#[test]
fn same_bytes_whatever_the_thread_count() {
    let dims = [40, 33, 35];
    let v: Vec<f64> = (0..40 * 33 * 35)
        .map(|i| ((i * 7919) % 1000) as f64 / 4.0)
        .collect();
    let mut files = Vec::new();
    let dir = tempfile::tempdir().unwrap();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| prep_values(dir.path(), dims, "u16", &v, 249.0, 8, true));
        files.push(std::fs::read(dir.path().join("v.cdv")).unwrap());
    }
    assert!(
        files[0] == files[1],
        "prep output depends on the thread count"
    );
}

/// Transfer-function classification against an oracle that samples the
/// opacity densely over each cell's [min, max] (NaN skipped).
#[test]
fn transfer_function_classification() {
    let tf = white_tf(&[
        (10.0, 0.0),
        (20.0, 0.5),
        (30.0, 0.0),
        (70.0, 0.0),
        (80.0, 1.0),
    ]);
    let dims = [17, 13, 11];
    let n = 17 * 13 * 11;
    let values: Vec<f64> = (0..n)
        .map(|i| {
            if i % 13 == 5 {
                f64::NAN
            } else {
                ((i * 7919 + i / 3) % 97) as f64
            }
        })
        .map(|v: f64| if v.is_nan() { v } else { (v as f32) as f64 })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let side = write_stack(dir.path(), "tf", dims, "f32", &values, ["1", "1", "1"], "");
    let src = RawSource::open(&side).unwrap();
    let out = dir.path().join("tf.cdv");
    let mut opts = PrepOptions::new(Classification::TransferFunction { tf: tf.clone() });
    opts.brick_size = 8;
    prep(&src, &out, &opts, &NoProgress).unwrap();
    let vol = PackedVolume::open(&out).unwrap();
    let [nx, ny, _] = dims;
    let cells = dims.map(|d| d - 1);
    let mut obj = vec![0u8; cells.iter().product()];
    for z in 0..cells[2] {
        for y in 0..cells[1] {
            for x in 0..cells[0] {
                let vs: Vec<f64> = (0..8)
                    .map(|i| values[((z + (i >> 2)) * ny + y + (i >> 1 & 1)) * nx + x + (i & 1)])
                    .filter(|v| !v.is_nan())
                    .collect();
                let hit = if vs.is_empty() {
                    false
                } else {
                    let lo = vs.iter().cloned().fold(f64::INFINITY, f64::min);
                    let hi = vs.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                    (0..=2000).any(|k| tf.opacity(lo + (hi - lo) * k as f64 / 2000.0) > 0.0)
                };
                obj[(z * cells[1] + y) * cells[0] + x] = hit as u8;
            }
        }
    }
    assert!(obj.contains(&1) && obj.contains(&0));
    let back = read_back(&vol, &values);
    let dist = chessboard_bfs(&obj, cells);
    assert_eq!(
        back.codes,
        expected_codes(&dist, vol.header().codes.max_code())
    );
}

#[test]
fn big_endian_and_per_slice_files_read_the_same_values() {
    let v: Vec<u16> = (0..60).map(|i| (i * 1000 + 7) as u16).collect();
    let dir = tempfile::tempdir().unwrap();
    let mut names = Vec::new();
    for z in 0..3 {
        let bytes: Vec<u8> = v[z * 20..(z + 1) * 20]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        let name = format!("s{z}.raw");
        let mut with_header = vec![0xAAu8; 6];
        with_header.extend(bytes);
        std::fs::write(dir.path().join(&name), with_header).unwrap();
        names.push(format!("\"{name}\""));
    }
    let side = dir.path().join("be.json");
    std::fs::write(
        &side,
        format!(
            r#"{{"data": [{}], "dims": [5, 4, 3], "dtype": "u16", "endian": "big", "header_bytes": 6,
                "x": 1, "y": 1, "z": {{"positions": [0, 1, 5]}}, "rescale": {{"slope": 2, "intercept": -3}}}}"#,
            names.join(",")
        ),
    )
    .unwrap();
    let src = RawSource::open(&side).unwrap();
    let mut buf = vec![0.0; 20];
    for z in 0..3 {
        cdvol::input::SliceSource::read_slice(&src, z, &mut buf).unwrap();
        let want: Vec<f64> = v[z * 20..(z + 1) * 20].iter().map(|&x| x as f64).collect();
        assert_eq!(buf, want);
    }
    let m = cdvol::input::SliceSource::meta(&src);
    assert_eq!(m.rescale.apply(7.0), 11.0);
    assert_eq!(m.grid.axes[2].coords(), &[0.0, 1.0, 5.0]);
}

#[test]
fn codes_saturate_inside_a_narrow_free_range() {
    // u8 data 0..=155 leaves 100 free words above: codes saturate at 99
    // without widening; a 130-cell run from one object reaches past it.
    let dims = [131, 2, 3];
    let mut v = vec![0.0; 131 * 2 * 3];
    v[0] = 155.0;
    let dir = tempfile::tempdir().unwrap();
    let vol = prep_values(dir.path(), dims, "u8", &v, 100.0, 8, false);
    assert_eq!(vol.header().storage, cdvol::input::Dtype::U8);
    assert_eq!(vol.header().codes.max_code(), 99);
    check(dims, "u8", &v, 100.0, 8, true);
}

/// Cells whose 8 samples are all NaN are background under both
/// classifications, even with a transfer function that is opaque beyond
/// its last point.
#[test]
fn all_nan_cells_are_background() {
    let dims = [12, 11, 10];
    let mut v: Vec<f64> = (0..12 * 11 * 10).map(|i| ((i * 37) % 50) as f64).collect();
    for z in 2..7 {
        for y in 3..8 {
            for x in 1..6 {
                v[(z * 11 + y) * 12 + x] = f64::NAN;
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let side = write_stack(dir.path(), "nan", dims, "f32", &v, ["1", "1", "1"], "");
    let tf = white_tf(&[(40.0, 0.0), (45.0, 1.0)]);
    for cls in [
        Classification::Iso { iso: 45.0 },
        Classification::TransferFunction { tf: tf.clone() },
    ] {
        let src = RawSource::open(&side).unwrap();
        let out = dir.path().join("nan.cdv");
        let mut opts = PrepOptions::new(cls.clone());
        opts.brick_size = 4;
        prep(&src, &out, &opts, &NoProgress).unwrap();
        let vol = PackedVolume::open(&out).unwrap();
        let back = read_back(&vol, &v);
        // Oracle: 1-cell when some non-NaN vertex reaches 45 (iso, and the
        // transfer function is non-zero exactly above 40 up to any value).
        let cells = dims.map(|d| d - 1);
        let mut obj = vec![0u8; cells.iter().product()];
        for z in 0..cells[2] {
            for y in 0..cells[1] {
                for x in 0..cells[0] {
                    let vs: Vec<f64> = (0..8)
                        .map(|i| v[((z + (i >> 2)) * 11 + y + (i >> 1 & 1)) * 12 + x + (i & 1)])
                        .filter(|x| !x.is_nan())
                        .collect();
                    let hit = match &cls {
                        Classification::Iso { iso } => vs.iter().any(|&x| x >= *iso),
                        _ => vs.iter().any(|&x| x > 40.0),
                    };
                    obj[(z * cells[1] + y) * cells[0] + x] = hit as u8;
                }
            }
        }
        assert_eq!(
            back.codes,
            expected_codes(&chessboard_bfs(&obj, cells), vol.header().codes.max_code())
        );
        // Cell (3, 5, 4) has 8 NaN vertices.
        assert_ne!(
            back.codes[(4 * cells[1] + 5) * cells[0] + 3],
            255,
            "all-NaN cell classified as a 1-cell"
        );
    }
}
