//! Tests of batch.rs: the kernel against a sample-by-sample f64 walk
//! (unshaded, shaded and with gradient opacity, uniform and rectilinear
//! grids), and the index maps' cells against the planes.

use super::*;
use crate::classify::{TfPoint, TransferFunction};
use crate::render::brick::samples::Order;
use crate::render::brick::GradPlane;
use crate::render::options::{CompositeLook, GradientPoint};
use proptest::prelude::*;

fn tf() -> TransferFunction {
    let p = |value: f64, opacity: f64, color: [f64; 3]| TfPoint {
        value,
        opacity,
        color,
    };
    TransferFunction {
        points: vec![
            p(20.0, 0.0, [1.0, 0.2, 0.1]),
            p(90.0, 0.3, [0.9, 0.8, 0.2]),
            p(160.0, 0.05, [0.2, 0.6, 1.0]),
        ],
    }
}

fn brick(first: [u32; 3], cells: [u32; 3], values: Samples, codes: Vec<u8>) -> RBrick {
    RBrick::bare(first, cells, Codes::Plane(codes), values)
}

/// A [`Source`] of one brick whose cells' gradients come from `grads`
/// (per sample of the brick, x fastest; none: no gradients asked for),
/// counting the cells asked for.
struct One<'a> {
    b: &'a RBrick,
    grads: Option<&'a [glam::Vec3]>,
    asked: Vec<[u32; 3]>,
}

impl Source for One<'_> {
    fn brick(&mut self) -> &RBrick {
        self.b
    }

    fn gradients(&mut self, cell: [u32; 3]) -> [Vec3A; 8] {
        self.asked.push(cell);
        let g = self.grads.expect("gradients asked for");
        let s = self.b.cells.map(|c| c as usize + 1);
        let l: [usize; 3] = std::array::from_fn(|a| (cell[a] - self.b.first[a]) as usize);
        std::array::from_fn(|v| {
            let at = [l[0] + (v & 1), l[1] + (v >> 1 & 1), l[2] + (v >> 2)];
            Vec3A::from(g[(at[2] * s[1] + at[1]) * s[0] + at[0]])
        })
    }
}

/// [`run_on`] of brick `b` from sample 0 with nothing composited yet.
fn run_one(
    x: &Batches,
    b: &RBrick,
    grads: Option<&[glam::Vec3]>,
    avx2: bool,
) -> ((u64, End), Vec4, Vec<[u32; 3]>) {
    let mut src = One {
        b,
        grads,
        asked: Vec::new(),
    };
    let mut acc = Vec4::ZERO;
    let got = run_on(x, &mut src, 0.0, &mut acc, avx2);
    (got, acc, src.asked)
}

/// A brick of `cells` at `first` with random whole values below 200
/// and random codes (mostly 1-cells; codes 0, 1, 2 and 5), on a grid
/// from `s0` whose axis `a` is uniform of spacing `h[a]` where
/// `uniform[a]`, else of random gaps from `h[a] / 4` to `2 h[a]`, and
/// a unit ray from the point at fraction `at` of the brick along
/// `dir`.
struct Scene {
    vals: Vec<f32>,
    codes: Vec<u8>,
    coords: [Vec<f64>; 3],
    map: IndexMap,
    ray: Ray,
}

/// A scene's brick: its cells, first cell, which axes are uniform, the
/// mean spacing and the first sample's position per axis.
struct Shape {
    cells: [u32; 3],
    first: [u32; 3],
    uniform: [bool; 3],
    h: [f64; 3],
    s0: [f64; 3],
}

fn scene(shape: Shape, at: [f64; 3], dir: [f64; 3], next: &mut impl FnMut() -> u32) -> Scene {
    let Shape {
        cells,
        first,
        uniform,
        h,
        s0,
    } = shape;
    let len = dir.iter().map(|d| d * d).sum::<f64>().sqrt();
    let c = cells.map(|c| c as usize);
    let samples = (c[0] + 1) * (c[1] + 1) * (c[2] + 1);
    let vals: Vec<f32> = (0..samples).map(|_| (next() % 200) as f32).collect();
    let codes: Vec<u8> = (0..c[0] * c[1] * c[2])
        .map(|_| match next() % 12 {
            0 => 0,
            1 => 1,
            2 => 2,
            3 => 5,
            _ => OBJECT,
        })
        .collect();
    let n: [usize; 3] = std::array::from_fn(|a| (first[a] + cells[a]) as usize + 3);
    let coords: [Vec<f64>; 3] = std::array::from_fn(|a| {
        let mut p = vec![s0[a]];
        for i in 0..n[a] {
            let gap = if uniform[a] {
                h[a]
            } else {
                h[a] * (0.25 + (next() % 1000) as f64 * 0.00175)
            };
            p.push(if uniform[a] {
                s0[a] + (i + 1) as f64 * gap
            } else {
                p[i] + gap
            });
        }
        p
    });
    let map = IndexMap::of([&coords[0], &coords[1], &coords[2]], uniform).unwrap();
    // The ray starts inside the brick.
    let origin: [f64; 3] = std::array::from_fn(|a| {
        let (lo, hi) = (
            coords[a][first[a] as usize],
            coords[a][(first[a] + cells[a]) as usize],
        );
        lo + at[a] * (hi - lo)
    });
    let ray = Ray::new(origin, dir.map(|d| d / len)).unwrap();
    Scene {
        vals,
        codes,
        coords,
        map,
        ray,
    }
}

/// A pseudo-random sequence from `seed`.
fn rng(seed: u64) -> impl FnMut() -> u32 {
    let mut r = seed;
    move || {
        r = r
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (r >> 33) as u32
    }
}

/// What [`run`] should do, sample by sample in f64: the cell by
/// `floor` of the index coordinate, the code, the trilinear value, the
/// f64 table, with `grads` (per vertex, x fastest) the gradient opacity
/// and the headlight shading of `Look::apply` from the trilinear
/// gradient, front-to-back compositing. `None` when a
/// sample lies within 1e-4 of a cell face, where f32 and f64 may pick
/// different cells, has a value within 1e-3 of the table's
/// transparent end, or a gradient shorter than 0.01, where f32 and
/// f64 may shade it differently.
fn reference(
    b: &RBrick,
    bx: &Batches,
    sc: &Scene,
    grads: Option<&[[f64; 3]]>,
) -> Option<(u64, End, [f64; 4])> {
    let (ray, step, lut) = (&sc.ray, bx.step, bx.lut);
    let c = b.cells.map(|c| c as usize);
    let (sx, sy) = (c[0] + 1, c[1] + 1);
    let mut acc = [0.0f64; 4];
    let l = |a: f64, b: f64, t: f64| a + t * (b - a);
    let tri = |v: &dyn Fn(usize) -> f64, u: [f64; 3]| {
        l(
            l(l(v(0), v(1), u[0]), l(v(2), v(3), u[0]), u[1]),
            l(l(v(4), v(5), u[0]), l(v(6), v(7), u[0]), u[1]),
            u[2],
        )
    };
    for k in 0u64.. {
        let t = k as f64 * step;
        // Per axis the cell by the planes (the largest with its
        // lower plane at or before the position; -1 before the grid),
        // less `first`, and the local coordinate.
        let mut cell = [0i64; 3];
        let mut u = [0.0f64; 3];
        for a in 0..3 {
            let s = &sc.coords[a];
            let p = ray.origin[a] + t * ray.dir[a];
            let g = s.partition_point(|&x| x <= p) as i64 - 1;
            if g < 0 || g as usize >= s.len() - 1 {
                cell[a] = -1;
                continue;
            }
            let g = g as usize;
            u[a] = (p - s[g]) / (s[g + 1] - s[g]);
            if u[a] < 1e-4 || u[a] > 1.0 - 1e-4 {
                return None;
            }
            cell[a] = g as i64 - b.first[a] as i64;
        }
        if (0..3).any(|a| cell[a] < 0 || cell[a] >= c[a] as i64) {
            return Some((k, End::Brick, acc));
        }
        let [x, y, z] = cell.map(|x| x as usize);
        let ci = (z * c[1] + y) * c[0] + x;
        let code = sc.codes[ci];
        if code != OBJECT && code >= 2 {
            return Some((k, End::Leap, acc));
        }
        if code != OBJECT {
            continue;
        }
        let vertex = |i: usize| ((z + i / 4) * sy + y + i / 2 % 2) * sx + x + i % 2;
        let value = tri(&|i| sc.vals[vertex(i)] as f64, u);
        if (value - tf().points[0].value).abs() < 1e-3 {
            return None;
        }
        let mut s = lut.sample(value);
        if s[3] == 0.0 {
            continue;
        }
        if let Some(grads) = grads {
            let g: [f64; 3] = std::array::from_fn(|a| tri(&|i| grads[vertex(i)][a], u));
            let len = g.iter().map(|v| v * v).sum::<f64>().sqrt();
            if len < 0.01 {
                return None;
            }
            if let Some(look) = bx.gradient_opacity {
                let f = look.gradient_factor(len);
                s = s.map(|v| v * f);
            }
            if let Some(e) = bx.shade {
                let dot = g[0] * e.x as f64 + g[1] * e.y as f64 + g[2] * e.z as f64;
                let ndl = (dot.abs() / len).min(1.0);
                let spec = (2.0 * ndl * ndl - 1.0).max(0.0).powi(32);
                let kd = 0.12 + 0.75 * ndl;
                let a = s[3];
                s = [s[0] * kd, s[1] * kd, s[2] * kd, 0.0].map(|v| v + 0.25 * spec * a);
                s[3] = a;
            }
        }
        let w = 1.0 - acc[3];
        for ch in 0..4 {
            acc[ch] += w * s[ch];
        }
        if acc[3] > bx.stop as f64 {
            return Some((k + 1, End::Stop, acc));
        }
    }
    unreachable!()
}

proptest! {
    /// [`run`] takes the samples a one-at-a-time walk by position
    /// takes, ends where it ends (leaving the brick, at a leap code,
    /// once opaque) and composites the same colour to f32 accuracy, on
    /// uniform and rectilinear grids; its AVX2 build gives the
    /// baseline build's bits.
    #[test]
    fn batches_take_the_samples_one_at_a_time_would(
        cells in proptest::array::uniform3(1u32..9),
        first in proptest::array::uniform3(0u32..20),
        uniform in prop_oneof![Just([true; 3]), proptest::array::uniform3(any::<bool>())],
        h in proptest::array::uniform3(0.3f64..2.5),
        s0 in proptest::array::uniform3(-5.0f64..5.0),
        at in proptest::array::uniform3(0.0f64..1.0),
        dir in proptest::array::uniform3(-1.0f64..1.0),
        step in prop_oneof![Just(0.07), Just(0.37), Just(1.3), Just(4.0)],
        stop in prop_oneof![Just(0.6), Just(0.99), Just(1.0)],
        seed in any::<u64>(),
    ) {
        prop_assume!(dir.iter().map(|d| d * d).sum::<f64>() > 1e-3);
        let sc = scene(
            Shape { cells, first, uniform, h, s0 },
            at,
            dir,
            &mut rng(seed),
        );
        let (vals, codes) = (&sc.vals, &sc.codes);
        let b = brick(first, cells, Samples::F32(vals.clone()), codes.clone());
        let lut = TfLut::new(&tf(), step);
        let off = Onset::off();
        let x = Batches { map: &sc.map, coords: sc.coords.each_ref().map(|c| &c[..]), ray: &sc.ray, step, lut: &lut, resume: 2, stop: stop as f32, shade: None, gradient_opacity: None, onset: &off, last: &Default::default(), again: Default::default() };
        let Some((want_n, want_end, want)) = reference(&b, &x, &sc, None) else {
            return Err(TestCaseError::reject("a sample on a cell face"));
        };
        let ((got_n, got_end), acc, _) = run_one(&x, &b, None, false);
        prop_assert_eq!((got_n, got_end), (want_n, want_end));
        for ch in 0..4 {
            prop_assert!((acc[ch] as f64 - want[ch]).abs() < 1e-4, "{acc} {want:?}");
        }
        // The same values as 16-bit words and a table, and as 8-bit
        // ones (the values are whole numbers below 200): the same bits.
        let table16: Vec<f32> = (0..65536).map(|w| w as f32).collect();
        let table16: std::sync::Arc<[f32; 65536]> = std::sync::Arc::<[f32]>::from(table16).try_into().unwrap();
        let table8: std::sync::Arc<[f32; 256]> = std::sync::Arc::new(std::array::from_fn(|w| w as f32));
        for values in [
            Samples::Words16(vals.iter().map(|&v| v as u16).collect(), table16, Order::Unsigned),
            Samples::Words8(vals.iter().map(|&v| v as u8).collect(), table8, Order::Unsigned),
        ] {
            let w = brick(first, cells, values, codes.clone());
            let (got_w, acc_w, _) = run_one(&x, &w, None, false);
            prop_assert_eq!(got_w, (got_n, got_end));
            prop_assert_eq!(acc_w.to_array().map(f32::to_bits), acc.to_array().map(f32::to_bits));
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let (got2, acc2, _) = run_one(&x, &b, None, true);
            prop_assert_eq!(got2, (got_n, got_end));
            prop_assert_eq!(acc2.to_array().map(f32::to_bits), acc.to_array().map(f32::to_bits));
        }
    }

    /// Shaded, with gradient opacity or both, [`run`] weights and
    /// lights each sample as `Look::apply` does with the trilinear
    /// gradient of the brick's gradient plane (to f32 accuracy against
    /// f64). Where the plane has not set a cell, it asks its source for
    /// that cell's gradients, only for such cells, and gives the bits of
    /// a plane with every cell set. Its AVX2 build gives the baseline
    /// build's bits.
    #[test]
    fn shaded_batches_light_samples_as_one_at_a_time_would(
        cells in proptest::array::uniform3(1u32..9),
        first in proptest::array::uniform3(0u32..20),
        uniform in prop_oneof![Just([true; 3]), proptest::array::uniform3(any::<bool>())],
        h in proptest::array::uniform3(0.3f64..2.5),
        s0 in proptest::array::uniform3(-5.0f64..5.0),
        at in proptest::array::uniform3(0.0f64..1.0),
        dir in proptest::array::uniform3(-1.0f64..1.0),
        eye in proptest::array::uniform3(-1.0f64..1.0),
        step in prop_oneof![Just(0.07), Just(0.37), Just(1.3)],
        stop in prop_oneof![Just(0.6), Just(1.0)],
        unset in 0u32..4,
        // 0: shaded; 1: gradient opacity; 2: both.
        look in 0u8..3,
        seed in any::<u64>(),
    ) {
        prop_assume!(dir.iter().map(|d| d * d).sum::<f64>() > 1e-3);
        prop_assume!(eye.iter().map(|d| d * d).sum::<f64>() > 1e-3);
        let mut next = rng(seed);
        let sc = scene(
            Shape { cells, first, uniform, h, s0 },
            at,
            dir,
            &mut next,
        );
        // Whole-number gradients in [-20, 20] per vertex; the plane
        // has the inner ones, then every cell but about one in
        // `unset + 1` (none with 0) is filled.
        let c = cells.map(|c| c as usize);
        let samples = (c[0] + 1) * (c[1] + 1) * (c[2] + 1);
        let grads: Vec<[f64; 3]> =
            (0..samples).map(|_| [0, 1, 2].map(|_| (next() % 41) as f64 - 20.0)).collect();
        let g32: Vec<glam::Vec3> =
            grads.iter().map(|g| glam::Vec3::from_array(g.map(|v| v as f32))).collect();
        // The plane with every cell set, and with about one cell in
        // `unset + 1` not set (none with 0).
        let plane = |leave: &mut dyn FnMut() -> bool| {
            let p = GradPlane::inner(&g32, c);
            for z in 0..cells[2] {
                for y in 0..cells[1] {
                    for x in 0..cells[0] {
                        if leave() {
                            continue;
                        }
                        let i = |dx: u32, dy: u32, dz: u32| {
                            g32[(((z + dz) as usize * (c[1] + 1)) + (y + dy) as usize) * (c[0] + 1)
                                + (x + dx) as usize]
                        };
                        p.fill([x, y, z], [
                            i(0, 0, 0), i(1, 0, 0), i(0, 1, 0), i(1, 1, 0),
                            i(0, 0, 1), i(1, 0, 1), i(0, 1, 1), i(1, 1, 1),
                        ]);
                    }
                }
            }
            p
        };
        let mut b = brick(first, cells, Samples::F32(sc.vals.clone()), sc.codes.clone());
        b.grads = plane(&mut || false);
        let mut part = brick(first, cells, Samples::F32(sc.vals.clone()), sc.codes.clone());
        part.grads = plane(&mut || unset > 0 && next().is_multiple_of(unset + 1));
        let len = eye.iter().map(|d| d * d).sum::<f64>().sqrt();
        let to_eye = Vec3A::from_array(eye.map(|e| (e / len) as f32));
        let lut = TfLut::new(&tf(), step);
        // Gradient lengths here reach about 35: opacity from 0.1 at 2 up to
        // 1 at 15 and down to 0.4 at 40.
        let p = |gradient: f64, opacity: f64| GradientPoint { gradient, opacity };
        let go = CompositeLook {
            shade: look != 1,
            gradient_opacity: vec![p(2.0, 0.1), p(15.0, 1.0), p(40.0, 0.4)],
        };
        let off = Onset::off();
        let x = Batches {
            map: &sc.map, coords: sc.coords.each_ref().map(|c| &c[..]), ray: &sc.ray, step, lut: &lut, resume: 2, stop: stop as f32,
            shade: (look != 1).then_some(to_eye),
            gradient_opacity: (look != 0).then_some(&go),
            onset: &off,
            last: &Default::default(),
            again: Default::default(),
        };
        let Some((want_n, want_end, want)) = reference(&b, &x, &sc, Some(&grads)) else {
            return Err(TestCaseError::reject("a sample on a face, or ill-conditioned"));
        };
        let (got, acc, asked) = run_one(&x, &b, Some(&g32), false);
        prop_assert_eq!(got, (want_n, want_end));
        prop_assert!(asked.is_empty());
        for ch in 0..4 {
            prop_assert!((acc[ch] as f64 - want[ch]).abs() < 1e-4, "{acc} {want:?}");
        }
        let bits = acc.to_array().map(f32::to_bits);
        let (got_part, acc_part, asked) = run_one(&x, &part, Some(&g32), false);
        prop_assert_eq!(got_part, got);
        prop_assert_eq!(acc_part.to_array().map(f32::to_bits), bits);
        for cell in asked {
            let l: [u32; 3] = std::array::from_fn(|a| cell[a] - first[a]);
            prop_assert!(part.grads.cell(l).is_none(), "asked for set cell {l:?}");
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            for p in [&b, &part] {
                let (got2, acc2, _) = run_one(&x, p, Some(&g32), true);
                prop_assert_eq!(got2, got);
                prop_assert_eq!(acc2.to_array().map(f32::to_bits), bits);
            }
        }
    }
}

/// A batch taken again after a miss starts from the transmittance it
/// started with: long rays through bricks of 1-cells whose gradient plane
/// has no cell set (a slab 2 cells thick has no inner cell), so that
/// nearly every cell the ray enters misses, at every transmittance down
/// the ray. The bits equal those of a plane with every cell set.
#[test]
fn batches_taken_again_keep_the_carried_transmittance() {
    let cells = [8u32, 8, 2];
    let c = cells.map(|c| c as usize);
    let samples = (c[0] + 1) * (c[1] + 1) * (c[2] + 1);
    let mut misses = 0;
    for seed in 0..48u64 {
        let mut next = rng(seed);
        let at = [0.02, 0.03 + 0.01 * (seed % 5) as f64, 0.5];
        let dir = [1.0, 0.6 + 0.05 * (seed % 7) as f64, 0.01];
        let mut sc = scene(
            Shape {
                cells,
                first: [0; 3],
                uniform: [true; 3],
                h: [1.0; 3],
                s0: [0.0; 3],
            },
            at,
            dir,
            &mut next,
        );
        sc.codes = vec![OBJECT; c[0] * c[1] * c[2]];
        let g32: Vec<glam::Vec3> = (0..samples)
            .map(|_| glam::Vec3::from_array([0, 1, 2].map(|_| (next() % 41) as f32 - 20.0)))
            .collect();
        let values = || Samples::F32(sc.vals.clone());
        let mut full = brick([0; 3], cells, values(), sc.codes.clone());
        full.grads = GradPlane::inner(&g32, c);
        for z in 0..cells[2] {
            for y in 0..cells[1] {
                for x in 0..cells[0] {
                    let i = |v: usize| {
                        let at = [
                            x as usize + (v & 1),
                            y as usize + (v >> 1 & 1),
                            z as usize + (v >> 2),
                        ];
                        g32[(at[2] * (c[1] + 1) + at[1]) * (c[0] + 1) + at[0]]
                    };
                    full.grads.fill([x, y, z], std::array::from_fn(i));
                }
            }
        }
        let mut none = brick([0; 3], cells, values(), sc.codes.clone());
        none.grads = GradPlane::inner(&g32, c);
        let lut = TfLut::new(&tf(), 0.07);
        let e = Vec3A::new(0.3, -0.5, 0.8).normalize();
        let off = Onset::off();
        let x = Batches {
            map: &sc.map,
            coords: sc.coords.each_ref().map(|c| &c[..]),
            ray: &sc.ray,
            step: 0.07,
            lut: &lut,
            resume: 2,
            stop: 1.0,
            shade: Some(e),
            gradient_opacity: None,
            onset: &off,
            last: &Default::default(),
            again: Default::default(),
        };
        let (want, acc, _) = run_one(&x, &full, Some(&g32), false);
        for avx2 in [false, true] {
            let (got, got_acc, asked) = run_one(&x, &none, Some(&g32), avx2);
            assert_eq!(got, want, "seed {seed}");
            assert_eq!(
                got_acc.to_array().map(f32::to_bits),
                acc.to_array().map(f32::to_bits),
                "seed {seed}"
            );
            misses += asked.len();
        }
    }
    // The rays cross about 10 cells each.
    assert!(misses > 48 * 2 * 5, "{misses} misses");
}

#[test]
fn index_maps_find_the_cells_of_positions() {
    let u: Vec<f64> = (0..5).map(|i| i as f64 * 0.5).collect();
    let m = IndexMap::of([&u, &u, &u], [true; 3]).unwrap();
    assert!(m.rect.is_none());
    assert_eq!(m.cell(0, 1.2, 4), 2);
    assert_eq!(m.cell(0, -3.0, 4), 0);
    assert_eq!(m.cell(0, 99.0, 4), 3);
    assert_eq!(m.cell(0, f64::NAN, 4), 0);
    // Rectilinear: gaps 1, 0.25, 3, 0.5 from -2; the cell of every
    // position away from the planes is the planes' own.
    let r = vec![-2.0, -1.0, -0.75, 2.25, 2.75];
    let m = IndexMap::of([&r, &u, &u], [false, true, true]).unwrap();
    assert!(m.rect.is_some());
    for i in 0..=600 {
        let p = -2.5 + i as f64 * 0.01;
        if r.iter().any(|&s| (s - p).abs() < 1e-6) {
            continue;
        }
        let want = (r.partition_point(|&s| s <= p).max(1) - 1).min(3) as u32;
        assert_eq!(m.cell(0, p, 4), want, "{p}");
        // The lanes' answer: the same cell, and none before the axis.
        let (c, u) = m.rect.as_ref().unwrap()[0]
            .as_ref()
            .unwrap()
            .cell((p + 2.0) as f32, 0);
        if p < -2.0 {
            assert_eq!(c, u32::MAX, "{p}");
        } else if p < 2.75 {
            assert_eq!(c, want, "{p}");
            let w = (p - r[c as usize]) / (r[c as usize + 1] - r[c as usize]);
            assert!((u as f64 - w).abs() < 1e-5, "{p}: {u} against {w}");
        } else {
            assert!(c >= 4, "{p}");
        }
    }
    assert_eq!(m.cell(0, f64::NAN, 4), 0);
    // An axis whose thinnest cell would need too many buckets.
    let fine = vec![0.0, 1e-9, 1000.0];
    assert!(IndexMap::of([&fine, &u, &u], [false, true, true]).is_none());
    assert!(IndexMap::of([&[0.0][..], &u, &u], [true; 3]).is_none());
}

/// Onsets (refine.rs): with the marcher's state on, the batches stop at
/// the first sample with opacity after a transparent one and composite
/// nothing of it, shaded or not, in either build; a sample the marcher
/// restarted at is not an onset; the state left is the last sample's.
#[test]
fn batches_stop_at_onsets() {
    let cells = [8u32, 1, 1];
    let mut sc = scene(
        Shape {
            cells,
            first: [0; 3],
            uniform: [true; 3],
            h: [1.0; 3],
            s0: [0.0; 3],
        },
        [0.01, 0.5, 0.5],
        [1.0, 0.0, 0.0],
        &mut rng(1),
    );
    // Transparent (10, below the table's 20) up to x = 3, then 100.
    let c = cells.map(|c| c as usize + 1);
    sc.vals = (0..c[0] * c[1] * c[2])
        .map(|i| if i % c[0] <= 3 { 10.0 } else { 100.0 })
        .collect();
    sc.codes = vec![OBJECT; 8];
    let samples = c[0] * c[1] * c[2];
    let g32 = vec![glam::Vec3::new(1.0, 0.5, 0.2); samples];
    let mut b = brick(
        [0; 3],
        cells,
        Samples::F32(sc.vals.clone()),
        sc.codes.clone(),
    );
    b.grads = GradPlane::inner(&g32, c.map(|n| n - 1));
    let step = 0.3;
    let lut = TfLut::new(&tf(), step);
    // The value passes 20 at x = 3 + 1/9, the ray starts at x = 0.08:
    // the first sample beyond.
    let first = ((3.0 + 1.0 / 9.0 - 0.08) / step).ceil() as u64;
    for shade in [None, Some(Vec3A::Z)] {
        for avx2 in [false, true] {
            let on = Onset::new(1e-9, 0.0);
            let x = Batches {
                map: &sc.map,
                coords: sc.coords.each_ref().map(|c| &c[..]),
                ray: &sc.ray,
                step,
                lut: &lut,
                resume: 2,
                stop: 0.99,
                shade,
                gradient_opacity: None,
                onset: &on,
                last: &Default::default(),
                again: Default::default(),
            };
            let (got, acc, _) = run_one(&x, &b, Some(&g32), avx2);
            assert_eq!(got, (first, End::Onset), "{shade:?} {avx2}");
            assert_eq!(acc, Vec4::ZERO);
            // Restarted there: the batches composite on to the brick's end.
            on.restarted(first as f64);
            let mut src = One {
                b: &b,
                grads: Some(&g32),
                asked: Vec::new(),
            };
            let mut acc = Vec4::ZERO;
            let (n, end) = run_on(&x, &mut src, first as f64, &mut acc, avx2);
            assert!(end != End::Onset && n > 0 && acc.w > 0.0, "{n} {end:?}");
            assert!(!on.clear.get(), "the last sample had opacity");
            // Off: no onset, the samples composited as before.
            let off = Onset::off();
            let y = Batches {
                onset: &off,
                last: &Default::default(),
                ..x.clone()
            };
            let (got, acc, _) = run_one(&y, &b, Some(&g32), avx2);
            assert!(got.1 != End::Onset && acc.w > 0.0);
        }
    }
}
