//! MIP maxima against a brute-force oracle that knows nothing of
//! traversals, bricks, codes or shared faces: for every pixel's ray, every
//! 1-cell of the iso classification whose slab interval along the ray has
//! positive length, the trilinear interpolant of the input values at the
//! interval's two ends (`--integrate step`), or at 2,001 points along it
//! (the exact maximum of `--integrate segment`, the default); the pixel's
//! value is the largest of those (NaN vertices give NaN, which the
//! maximum ignores). Random rectilinear volumes with NaN samples,
//! orthographic and perspective cameras, FVT, CD and the octree.

use proptest::prelude::*;

use crate::common::{self, write_stack};
use cdvol::progress::NoProgress;
use cdvol::render::traverse::{Method, Ray, TGrid};
use cdvol::render::view::camera::Camera;
use cdvol::render::{render, Integrate, Mode, RenderOptions};

const ISO: f64 = 50.0;

/// The oracle's maximum along `ray` (`-inf` when it meets no value): at
/// each 1-cell's entry and exit, and with `inner` that many points
/// between them.
fn oracle(
    values: &[f64],
    dims: [usize; 3],
    pos: &[Vec<f64>; 3],
    ones: &[u8],
    ray: &Ray,
    inner: usize,
) -> f64 {
    let [nx, ny, _] = dims;
    let c = [dims[0] - 1, dims[1] - 1, dims[2] - 1];
    let mut best = f64::NEG_INFINITY;
    for z in 0..c[2] {
        for y in 0..c[1] {
            for x in 0..c[0] {
                if ones[(z * c[1] + y) * c[0] + x] == 0 {
                    continue;
                }
                let cell = [x, y, z];
                let lo: [f64; 3] = std::array::from_fn(|k| pos[k][cell[k]]);
                let hi: [f64; 3] = std::array::from_fn(|k| pos[k][cell[k] + 1]);
                let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                for k in 0..3 {
                    let (o, d) = (ray.origin[k], ray.dir[k]);
                    if d == 0.0 {
                        if !(lo[k] <= o && o <= hi[k]) {
                            t1 = f64::NEG_INFINITY;
                        }
                    } else {
                        let (a, b) = ((lo[k] - o) / d, (hi[k] - o) / d);
                        t0 = t0.max(a.min(b));
                        t1 = t1.min(a.max(b));
                    }
                }
                if t1 <= t0 {
                    continue;
                }
                let f: [f64; 8] = std::array::from_fn(|i| {
                    values[((z + (i >> 2)) * ny + y + (i >> 1 & 1)) * nx + x + (i & 1)]
                });
                let ts = (0..=inner + 1).map(|j| t0 + (t1 - t0) * j as f64 / (inner + 1) as f64);
                for t in ts {
                    let u: [f64; 3] = std::array::from_fn(|k| {
                        ((ray.origin[k] + t * ray.dir[k] - lo[k]) / (hi[k] - lo[k])).clamp(0.0, 1.0)
                    });
                    let lerp = |a: f64, b: f64, s: f64| a + s * (b - a);
                    let v = lerp(
                        lerp(lerp(f[0], f[1], u[0]), lerp(f[2], f[3], u[0]), u[1]),
                        lerp(lerp(f[4], f[5], u[0]), lerp(f[6], f[7], u[0]), u[1]),
                        u[2],
                    );
                    best = best.max(v);
                }
            }
        }
    }
    best
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn mip_is_the_largest_value_along_the_rays_1_cells(
        (dims, values) in (3usize..9, 3usize..9, 3usize..7).prop_flat_map(|(x, y, z)| {
            (
                Just([x, y, z]),
                proptest::collection::vec(
                    prop_oneof![1 => Just(f64::NAN), 19 => (0u32..1000).prop_map(|v| v as f64 / 10.0)],
                    x * y * z,
                ),
            )
        }),
        gaps in proptest::collection::vec(0.4f64..2.0, 24),
        az in -180.0f64..180.0,
        el in -80.0f64..80.0,
        fov in prop_oneof![Just(None), (20.0f64..70.0).prop_map(Some)],
    ) {
        let dir = tempfile::tempdir().unwrap();
        let pos: [Vec<f64>; 3] = std::array::from_fn(|k| {
            let mut p = vec![0.0];
            for i in 1..dims[k] {
                p.push(p[i - 1] + gaps[8 * k + i - 1]);
            }
            p
        });
        let ax = pos.clone().map(|p| common::axis_json(&p));
        let side = write_stack(dir.path(), "v", dims, "f32", &values, [&ax[0], &ax[1], &ax[2]], "");
        let vol = common::packed_with(&side, &dir.path().join("v.cdv"), ISO, |o| o.brick_size = 4);
        let ones = common::classify_iso(&values, dims, ISO);
        let g = TGrid::<f64>::new(&vol.header().axes);
        let cam = Camera::orbit(g.bounds(), az, el, fov, None, 11, 9).unwrap();
        for (integrate, inner) in [(Integrate::Step, 0), (Integrate::Segment { tol: 0.01 }, 2000)] {
            let want: Vec<f64> = (0..cam.height)
                .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
                .map(|(x, y)| oracle(&values, dims, &pos, &ones, &cam.ray(x, y), inner))
                .collect();
            for method in [Method::Fvt, Method::Cd { min_leap: 1 }, Method::Octree] {
                let o = RenderOptions {
                    integrate,
                    ..common::test_opts(Mode::Mip, method)
                };
                let (frame, _) = render(&vol, &cam, &o, &NoProgress).unwrap();
                let got = frame.values.expect("MIP frames carry their values");
                for (i, (&v, &want)) in got.iter().zip(&want).enumerate() {
                    let (x, y) = (i as u32 % cam.width, i as u32 / cam.width);
                    if want == f64::NEG_INFINITY {
                        prop_assert!(v.is_nan(), "{method:?} ({x}, {y}): {v}, expected a miss");
                    } else if inner == 0 {
                        prop_assert!(
                            (v as f64 - want).abs() <= 1e-5 * (1.0 + want.abs()),
                            "{method:?} faces ({x}, {y}): {v}, expected {want}"
                        );
                    } else {
                        // Never below a point of the interpolant (but for
                        // f32 rounding), and above the densest sampling
                        // only by what it can miss between its points.
                        prop_assert!(
                            v as f64 >= want - 1e-5 * (1.0 + want.abs()) && (v as f64) <= want + 0.02,
                            "{method:?} exact ({x}, {y}): {v}, expected {want} (+0.02)"
                        );
                    }
                }
            }
        }
    }
}

/// MIP leaps out of nodes of the bricks' max pyramid that cannot raise a
/// ray's maximum (integrate/mip.rs), and the maxima stay FVT's (which
/// never leaps) bit for bit. A volume of 1-cells only, so without those
/// leaps CD would step through every cell as FVT does: values 60 with
/// sparse spikes up to 100 on rectilinear axes, bricks of 4, 8, 12 and 16
/// cells, orthographic and perspective views from several sides.
#[test]
fn mip_leaps_out_of_nodes_below_the_rays_maximum_and_keeps_fvts_maxima() {
    let dims = [33usize, 29, 25];
    let n = dims[0] * dims[1] * dims[2];
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let values: Vec<f64> = (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            if state.is_multiple_of(1499) {
                60.0 + (state >> 20) as f64 % 40.0
            } else {
                60.0
            }
        })
        .collect();
    let pos: [Vec<f64>; 3] = std::array::from_fn(|k| {
        (0..dims[k])
            .map(|i| i as f64 * 0.9 + 0.05 * (i * i % 7) as f64)
            .collect()
    });
    let ax = pos.clone().map(|p| common::axis_json(&p));
    for brick in [4usize, 8, 12, 16] {
        let dir = tempfile::tempdir().unwrap();
        let side = write_stack(
            dir.path(),
            "v",
            dims,
            "f32",
            &values,
            [&ax[0], &ax[1], &ax[2]],
            "",
        );
        let vol = common::packed_with(&side, &dir.path().join("v.cdv"), ISO, |o| {
            o.brick_size = brick
        });
        for (view, fov) in [
            ([30.0, 20.0], None),
            ([-120.0, -45.0], Some(40.0)),
            ([90.0, 0.0], None),
        ] {
            let cam = common::orbit(&vol, view, fov, 24, 18);
            let run = |method| {
                let (frame, stats) = render(
                    &vol,
                    &cam,
                    &common::test_opts(Mode::Mip, method),
                    &NoProgress,
                )
                .unwrap();
                (frame.values.expect("MIP frames carry their values"), stats)
            };
            let (want, fvt) = run(Method::Fvt);
            assert_eq!(fvt.macro_steps, 0, "FVT does not leap");
            for method in [Method::Cd { min_leap: 1 }, Method::Octree] {
                let (got, s) = run(method);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "{method:?}, bricks of {brick}, view {view:?}"
                );
                assert!(
                    2 * s.steps < fvt.steps,
                    "{method:?}, bricks of {brick}, view {view:?}: {} steps against FVT's {}",
                    s.steps,
                    fvt.steps
                );
            }
        }
    }
}
