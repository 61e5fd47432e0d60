//! Oracles of the distance transforms: brute-force chessboard, octant and
//! DDA distances on random and extreme volumes (proptest), against the
//! streaming passes and the whole-volume functions of the module root.

use super::*;
use proptest::prelude::*;

/// Brute force: min over 1-cells of the chessboard distance, saturated.
/// With `octant`, only 1-cells in that closed octant of each cell.
fn brute(obj: &[u8], dims: [usize; 3], octant: Option<usize>) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let objs: Vec<[isize; 3]> = (0..obj.len())
        .filter(|&i| obj[i] != 0)
        .map(|i| {
            [
                (i % nx) as isize,
                (i / nx % ny) as isize,
                (i / nx / ny) as isize,
            ]
        })
        .collect();
    let mut out = vec![FAR; obj.len()];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let v = [x as isize, y as isize, z as isize];
                let mut best = FAR as isize;
                for q in &objs {
                    let ok = match octant {
                        None => true,
                        Some(o) => (0..3).all(|k| {
                            let d = q[k] - v[k];
                            if octant_negative(o, k) {
                                d <= 0
                            } else {
                                d >= 0
                            }
                        }),
                    };
                    if ok {
                        let d = (0..3).map(|k| (q[k] - v[k]).abs()).max().unwrap();
                        best = best.min(d);
                    }
                }
                out[(z * ny + y) * nx + x] = best as u8;
            }
        }
    }
    out
}

fn brute_blocks(obj: &[u8], dims: [usize; 3], o: usize) -> Vec<u8> {
    let d = brute(obj, dims, Some(o));
    let [nx, ny, nz] = dims;
    let g = ANISO_BLOCK;
    let (bx, by, bz) = (nx.div_ceil(g), ny.div_ceil(g), nz.div_ceil(g));
    let mut out = vec![u8::MAX; bx * by * bz];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let b = &mut out[((z / g) * by + y / g) * bx + x / g];
                *b = (*b).min(d[(z * ny + y) * nx + x].max(1) - 1);
            }
        }
    }
    out
}

/// The distances of octant `o` per cell: [`octant_slice`] chained over z
/// in the octant's z order (towards higher z when the region extends to
/// lower z).
fn octant_cells(obj: &[u8], dims: [usize; 3], o: usize) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let n = nx * ny;
    let dist: Vec<u8> = obj.iter().map(|&c| if c != 0 { 0 } else { 1 }).collect();
    let zs: Vec<usize> = if octant_negative(o, 2) {
        (0..nz).collect()
    } else {
        (0..nz).rev().collect()
    };
    let mut out = vec![0u8; obj.len()];
    let mut prev: Option<Vec<u8>> = None;
    for z in zs {
        let mut cur = vec![0u8; n];
        octant_slice(
            o,
            &dist[z * n..(z + 1) * n],
            prev.as_deref(),
            nx,
            ny,
            &mut cur,
        );
        out[z * n..(z + 1) * n].copy_from_slice(&cur);
        prev = Some(cur);
    }
    out
}

fn volume() -> impl Strategy<Value = (Vec<u8>, [usize; 3])> {
    (1usize..12, 1usize..12, 1usize..12, 0u32..=100).prop_flat_map(|(x, y, z, pct)| {
        let n = x * y * z;
        (
            proptest::collection::vec((0u32..100).prop_map(move |r| (r < pct / 8) as u8), n),
            Just([x, y, z]),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    #[test]
    fn isotropic_equals_brute_force((obj, dims) in volume()) {
        prop_assert_eq!(chessboard_3d(&obj, dims), brute(&obj, dims, None));
    }

    /// Every cell's one-sided distance, slice by slice in the octant's z
    /// order, before any reduction to blocks.
    #[test]
    fn octant_slices_equal_brute_force((obj, dims) in volume(), o in 0usize..8) {
        prop_assert_eq!(octant_cells(&obj, dims, o), brute(&obj, dims, Some(o)));
    }

    /// Rows of up to 69 cells, few of them: long runs for the row scan
    /// between 1-cells and the volume's ends.
    #[test]
    fn octant_slices_of_long_rows_equal_brute_force(
        (obj, dims) in (1usize..70, 1usize..4, 1usize..4, 0u32..=100).prop_flat_map(|(x, y, z, pct)| {
            (
                proptest::collection::vec((0u32..100).prop_map(move |r| (r < pct / 8) as u8), x * y * z),
                Just([x, y, z]),
            )
        }),
        o in 0usize..8,
    ) {
        prop_assert_eq!(octant_cells(&obj, dims, o), brute(&obj, dims, Some(o)));
    }

    #[test]
    fn octant_blocks_equal_brute_force((obj, dims) in volume()) {
        let got = octant_blocks_3d(&obj, dims);
        for (o, g) in got.iter().enumerate() {
            prop_assert_eq!(g, &brute_blocks(&obj, dims, o), "octant {}", o);
        }
    }
}

#[test]
fn empty_full_and_single_cells() {
    for dims in [[1, 1, 1], [5, 1, 7], [3, 4, 5]] {
        let n = dims.iter().product();
        assert_eq!(chessboard_3d(&vec![0; n], dims), vec![FAR; n]);
        assert_eq!(chessboard_3d(&vec![1; n], dims), vec![0; n]);
    }
    // One 1-cell in the corner of a long thin volume saturates far away.
    let dims = [300, 2, 2];
    let mut obj = vec![0; 1200];
    obj[0] = 1;
    let d = chessboard_3d(&obj, dims);
    assert_eq!(d, brute(&obj, dims, None));
    assert_eq!(d[254], 254);
    assert_eq!(d[255], FAR);
    assert_eq!(d[299], FAR);
}

#[test]
fn one_cell_thick_plane() {
    let dims = [9, 10, 11];
    let mut obj = vec![0; 990];
    for y in 0..10 {
        for x in 0..9 {
            obj[(5 * 10 + y) * 9 + x] = 1;
        }
    }
    let d = chessboard_3d(&obj, dims);
    assert_eq!(d, brute(&obj, dims, None));
    assert_eq!(d[3 * 9 + 3], 5);
    assert_eq!(d[(10 * 10 + 3) * 9 + 3], 5);
}

// ---- DDA planes (city block, chamfer 3-4-5) ----

fn objects(obj: &[u8], dims: [usize; 3]) -> Vec<[i64; 3]> {
    let [nx, ny, _] = dims;
    (0..obj.len())
        .filter(|&i| obj[i] != 0)
        .map(|i| [(i % nx) as i64, (i / nx % ny) as i64, (i / nx / ny) as i64])
        .collect()
}

/// Closed form of the chamfer 3-4-5 distance between two cells: with
/// the absolute offsets sorted `a >= b >= c`, `3(a-b) + 4(b-c) + 5c`.
fn chamfer_closed(d: [i64; 3]) -> i64 {
    let mut d = d.map(i64::abs);
    d.sort_unstable_by(|x, y| y.cmp(x));
    3 * (d[0] - d[1]) + 4 * (d[1] - d[2]) + 5 * d[2]
}

/// Brute force over the 1-cells: `metric(offset)` minimised, saturated
/// at DDA_FAR.
fn brute_dda(obj: &[u8], dims: [usize; 3], metric: fn([i64; 3]) -> i64) -> Vec<u8> {
    let [nx, ny, _] = dims;
    let objs = objects(obj, dims);
    (0..obj.len())
        .map(|i| {
            let v = [(i % nx) as i64, (i / nx % ny) as i64, (i / nx / ny) as i64];
            objs.iter()
                .map(|q| metric([q[0] - v[0], q[1] - v[1], q[2] - v[2]]))
                .min()
                .unwrap_or(i64::MAX)
                .min(DDA_FAR as i64) as u8
        })
        .collect()
}

fn l1(d: [i64; 3]) -> i64 {
    d.iter().map(|v| v.abs()).sum()
}

/// Multi-source Dijkstra over the 26-neighbour graph of the volume's
/// cells with weights 3 (face), 4 (edge), 5 (corner), saturated at
/// DDA_FAR. Independent of the two-pass recurrence.
fn dijkstra_chamfer(obj: &[u8], dims: [usize; 3]) -> Vec<u8> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let [nx, ny, nz] = dims;
    let mut dist = vec![u32::MAX; obj.len()];
    let mut heap = BinaryHeap::new();
    for (i, &o) in obj.iter().enumerate() {
        if o != 0 {
            dist[i] = 0;
            heap.push(Reverse((0u32, i)));
        }
    }
    while let Some(Reverse((d, i))) = heap.pop() {
        if d > dist[i] {
            continue;
        }
        let v = [(i % nx) as i64, (i / nx % ny) as i64, (i / nx / ny) as i64];
        for dz in -1i64..=1 {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let k = dx.abs() + dy.abs() + dz.abs();
                    if k == 0 {
                        continue;
                    }
                    let w = [0, 3, 4, 5][k as usize];
                    let u = [v[0] + dx, v[1] + dy, v[2] + dz];
                    if u[0] < 0
                        || u[1] < 0
                        || u[2] < 0
                        || u[0] >= nx as i64
                        || u[1] >= ny as i64
                        || u[2] >= nz as i64
                    {
                        continue;
                    }
                    let j = (u[2] as usize * ny + u[1] as usize) * nx + u[0] as usize;
                    if d + w < dist[j] {
                        dist[j] = d + w;
                        heap.push(Reverse((d + w, j)));
                    }
                }
            }
        }
    }
    dist.iter().map(|&d| d.min(DDA_FAR as u32) as u8).collect()
}

/// The textbook whole-volume two-pass raster transform, with explicit
/// half masks (no slices, no streaming).
fn whole_volume_two_pass(obj: &[u8], dims: [usize; 3], chamfer: bool) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let mut d: Vec<u32> = obj
        .iter()
        .map(|&o| if o != 0 { 0 } else { DDA_FAR as u32 })
        .collect();
    // Forward half mask: neighbours before the cell in raster order.
    let mut fwd: Vec<([i64; 3], u32)> = Vec::new();
    for dz in -1i64..=1 {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let before = (dz, dy, dx) < (0, 0, 0);
                let k = dx.abs() + dy.abs() + dz.abs();
                if !before || (!chamfer && k != 1) {
                    continue;
                }
                let w = if chamfer { [0, 3, 4, 5][k as usize] } else { 1 };
                fwd.push(([dx, dy, dz], w));
            }
        }
    }
    let at = |x: i64, y: i64, z: i64| -> Option<usize> {
        (x >= 0 && y >= 0 && z >= 0 && x < nx as i64 && y < ny as i64 && z < nz as i64)
            .then(|| (z as usize * ny + y as usize) * nx + x as usize)
    };
    let total = obj.len();
    for pass in 0..2 {
        for r in 0..total {
            let i = if pass == 0 { r } else { total - 1 - r };
            let v = [(i % nx) as i64, (i / nx % ny) as i64, (i / nx / ny) as i64];
            let sign = if pass == 0 { 1 } else { -1 };
            for &(o, w) in &fwd {
                if let Some(j) = at(v[0] + sign * o[0], v[1] + sign * o[1], v[2] + sign * o[2]) {
                    d[i] = d[i].min(d[j] + w);
                }
            }
        }
    }
    d.iter().map(|&v| v.min(DDA_FAR as u32) as u8).collect()
}

fn dda_volume() -> impl Strategy<Value = (Vec<u8>, [usize; 3])> {
    (1usize..10, 1usize..10, 1usize..10, 0u32..=100).prop_flat_map(|(x, y, z, pct)| {
        let n = x * y * z;
        (
            proptest::collection::vec((0u32..100).prop_map(move |r| (r < pct / 4) as u8), n),
            Just([x, y, z]),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    #[test]
    fn dda_planes_equal_oracles((obj, dims) in dda_volume()) {
        let [cb, ch] = dda_3d(&obj, dims);
        prop_assert_eq!(&cb, &brute_dda(&obj, dims, l1), "city block");
        let dij = dijkstra_chamfer(&obj, dims);
        prop_assert_eq!(&ch, &dij, "chamfer vs Dijkstra");
        prop_assert_eq!(&dij, &brute_dda(&obj, dims, chamfer_closed), "closed form");
        prop_assert_eq!(&cb, &whole_volume_two_pass(&obj, dims, false));
        prop_assert_eq!(&ch, &whole_volume_two_pass(&obj, dims, true));
    }

    /// The chessboard distances and octant blocks are unchanged when the
    /// spill also carries the DDA planes.
    #[test]
    fn dda_leaves_chessboard_alone((obj, dims) in dda_volume()) {
        let [ncx, ncy, ncz] = dims;
        let n = ncx * ncy;
        let (mut spill, mut bspill) = (MemSpill::default(), MemSpill::default());
        let mut fwd = ForwardDt::new(ncx, ncy, true).with_dda(true);
        for z in 0..ncz {
            fwd.push(&obj[z * n..(z + 1) * n], z + 1 == ncz, &mut spill, Some(&mut bspill))
                .unwrap();
        }
        let mut g = vec![0u8; n * ncz];
        let mut bwd = BackwardDt::new(ncx, ncy, ncz, true).with_dda(true);
        for z in (0..ncz).rev() {
            let (d, _) = bwd.step(z, &mut spill, Some(&mut bspill)).unwrap();
            g[z * n..(z + 1) * n].copy_from_slice(d);
        }
        prop_assert_eq!(g, chessboard_3d(&obj, dims));
    }
}

#[test]
fn dda_empty_full_single_and_saturated() {
    for dims in [[1, 1, 1], [5, 1, 7], [3, 4, 5], [1, 9, 1]] {
        let n: usize = dims.iter().product();
        let [cb, ch] = dda_3d(&vec![0; n], dims);
        assert_eq!((cb, ch), (vec![DDA_FAR; n], vec![DDA_FAR; n]));
        let [cb, ch] = dda_3d(&vec![1; n], dims);
        assert_eq!((cb, ch), (vec![0; n], vec![0; n]));
        for i in [0, n / 2, n - 1] {
            let mut obj = vec![0; n];
            obj[i] = 1;
            let [cb, ch] = dda_3d(&obj, dims);
            assert_eq!(cb, brute_dda(&obj, dims, l1));
            assert_eq!(ch, brute_dda(&obj, dims, chamfer_closed));
            assert_eq!(ch, dijkstra_chamfer(&obj, dims));
        }
    }
    // Long thin volumes: saturation at 254 along each axis and a
    // diagonal (corner steps of 5).
    let dims = [300, 2, 2];
    let mut obj = vec![0; 1200];
    obj[0] = 1;
    let [cb, ch] = dda_3d(&obj, dims);
    assert_eq!(cb, brute_dda(&obj, dims, l1));
    assert_eq!(ch, dijkstra_chamfer(&obj, dims));
    assert_eq!((cb[254], cb[255], cb[299]), (254, 254, 254));
    assert_eq!((ch[84], ch[85], ch[299]), (252, 254, 254));
    // (1, 1, 0): one edge step; (1, 1, 1): one corner step.
    assert_eq!((ch[301], ch[901]), (4, 5));
    let dims = [40, 40, 40];
    let mut obj = vec![0; 64000];
    obj[0] = 1;
    let [cb, ch] = dda_3d(&obj, dims);
    assert_eq!(cb, brute_dda(&obj, dims, l1));
    assert_eq!(ch, brute_dda(&obj, dims, chamfer_closed));
    assert_eq!(ch[(39 * 40 + 39) * 40 + 39], 195);
    assert_eq!(cb[(39 * 40 + 39) * 40 + 39], 117);
}
