//! Culling by the brick index (render/view/cull.rs) leaves untraced only pixels
//! whose rays meet no 1-cell: the culled render is the traced one, image
//! and depth bit for bit, on random sparse volumes with rectilinear axes,
//! random bricks, orthographic and perspective cameras from any side,
//! zoomed in and out, every mode that culls, and every exact traversal.
//! The oracle is the same render with culling off, which traces every
//! pixel's ray; a test with one small object checks that most pixels are
//! in fact culled, so the comparison is not vacuous. A second frame on the
//! same cache (a turntable's later frames) culls by the decoded bricks'
//! sub-blocks, more finely than the index can: checked the same way.

use proptest::prelude::*;

use crate::common::{self, write_stack};
use cdvol::classify::{TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::{Method, TGrid};
use cdvol::render::view::camera::{Camera, Projection};
use cdvol::render::{render, render_in, Frame, Mode, Stats};

fn tf() -> TransferFunction {
    let p = |value: f64, opacity: f64| TfPoint {
        value,
        opacity,
        color: [0.9, 0.7, 0.4],
    };
    TransferFunction {
        points: vec![p(100.0, 0.0), p(150.0, 0.3), p(250.0, 0.6)],
    }
}

fn modes() -> Vec<Mode> {
    vec![
        Mode::Surface {
            hit: HitMethod::Int,
            shadows: true,
        },
        Mode::Depth {
            hit: HitMethod::Newton,
        },
        Mode::Mip,
        Mode::Composite {
            tf: tf(),
            step_mm: 0.7,
        },
    ]
}

/// `vol` by `cam` in `mode` by `method`, culled or not.
fn draw(
    vol: &PackedVolume,
    cam: &Camera,
    mode: &Mode,
    method: Method,
    cull: bool,
) -> (Frame, Stats) {
    draw_at(vol, cam, mode, method, cull, None)
}

/// [`draw`] at the scene iso value `iso` (`render --iso`).
fn draw_at(
    vol: &PackedVolume,
    cam: &Camera,
    mode: &Mode,
    method: Method,
    cull: bool,
    iso: Option<f64>,
) -> (Frame, Stats) {
    draw_opts(
        vol,
        cam,
        &cdvol::render::RenderOptions {
            cull,
            iso,
            ..common::test_opts(mode.clone(), method)
        },
    )
}

/// `vol` by `cam` with the options `o`.
fn draw_opts(vol: &PackedVolume, cam: &Camera, o: &cdvol::render::RenderOptions) -> (Frame, Stats) {
    render(vol, cam, o, &NoProgress).unwrap_or_else(|e| panic!("{:?} {:?}: {e}", o.mode, o.method))
}

/// [`draw_at`] culled, as the second frame of one cache: the first frame
/// decodes the bricks, the second culls by their sub-blocks. Both frames'
/// stats.
fn draw_twice(
    vol: &PackedVolume,
    cam: &Camera,
    mode: &Mode,
    method: Method,
    iso: Option<f64>,
) -> (Frame, Stats, Stats) {
    let o = cdvol::render::RenderOptions {
        iso,
        ..common::test_opts(mode.clone(), method)
    };
    let cache = cdvol::render::cache_for(vol, &o).with_occupancy();
    let run = || {
        render_in(vol, &cache, cam, &o, &NoProgress)
            .unwrap_or_else(|e| panic!("{mode:?} {method:?}: {e}"))
    };
    let (_, first) = run();
    let (f, second) = run();
    (f, first, second)
}

/// Culled against traced, every mode and traversal; the culled rays.
fn check(vol: &PackedVolume, cam: &Camera) -> Result<u64, TestCaseError> {
    let mut culled = None;
    for mode in modes() {
        for method in [Method::Fvt, Method::Cd { min_leap: 1 }, Method::Octree] {
            let (fc, sc) = draw(vol, cam, &mode, method, true);
            let (ft, st) = draw(vol, cam, &mode, method, false);
            prop_assert!(
                common::same_frame(&fc, &ft),
                "{mode:?} {method:?}: images differ"
            );
            // Coverage and the MIP maxima (f32 bits) too.
            prop_assert_eq!(&fc.alpha, &ft.alpha, "{:?} {:?}", mode, method);
            let bits = |f: &Frame| {
                f.values
                    .as_ref()
                    .map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
            };
            prop_assert_eq!(bits(&fc), bits(&ft), "{:?} {:?}", mode, method);
            prop_assert_eq!(sc.hits, st.hits);
            prop_assert_eq!(st.rays_culled, 0);
            // A traced pixel's ray starts where the cover says no 1-cell
            // can begin before (render/view/cull.rs, `Cover::start`): FVT, one
            // cell at a time, takes at most the steps it takes from the
            // volume's entry. (CD and the octree leap from wherever they
            // start, so theirs may differ either way by a few; the image
            // above is what must not.)
            if method == Method::Fvt {
                for (c, t) in fc.steps.iter().zip(&ft.steps) {
                    prop_assert!(c <= t, "{:?}: {} steps, {} traced", mode, c, t);
                }
                prop_assert!(sc.steps <= st.steps);
                prop_assert!(sc.bricks_read <= st.bricks_read);
            }
            // Small tiles: many wholly culled, drawn without pixels; the
            // same frame, planes and counts.
            for tile in [1, 3] {
                let o = cdvol::render::RenderOptions {
                    tile,
                    ..common::test_opts(mode.clone(), method)
                };
                let (fs, ss) = draw_opts(vol, cam, &o);
                prop_assert!(
                    common::same_frame(&fs, &ft),
                    "{:?} {:?} tile {}",
                    mode,
                    method,
                    tile
                );
                prop_assert_eq!(&fs.alpha, &ft.alpha);
                prop_assert_eq!(&fs.steps, &fc.steps);
                prop_assert_eq!(bits(&fs), bits(&ft));
                prop_assert_eq!(
                    (ss.rays, ss.rays_culled, ss.hits),
                    (sc.rays, sc.rays_culled, sc.hits)
                );
            }
            // A first frame's cover depends on the file and camera only.
            prop_assert_eq!(*culled.get_or_insert(sc.rays_culled), sc.rays_culled);
            // A second frame culls by the decoded bricks' sub-blocks: the
            // same image, at least the rays the first frame culled.
            let (fw, s1, s2) = draw_twice(vol, cam, &mode, method, None);
            prop_assert!(
                common::same_frame(&fw, &ft),
                "{mode:?} {method:?}: second frame differs"
            );
            prop_assert_eq!(bits(&fw), bits(&ft), "{:?} {:?}", mode, method);
            prop_assert_eq!(s1.rays_culled, sc.rays_culled);
            prop_assert!(s2.rays_culled >= s1.rays_culled);
            prop_assert_eq!(s2.hits, st.hits);
        }
    }
    // A narrowed scene (render/brick/envelope.rs) culls also the bricks whose
    // index maximum lies below its iso value.
    for mode in [
        Mode::Mip,
        Mode::Depth {
            hit: HitMethod::Int,
        },
    ] {
        let method = Method::Cd { min_leap: 1 };
        let (fc, sc) = draw_at(vol, cam, &mode, method, true, Some(150.0));
        let (ft, st) = draw_at(vol, cam, &mode, method, false, Some(150.0));
        prop_assert!(
            common::same_frame(&fc, &ft),
            "{mode:?} at 150: images differ"
        );
        prop_assert_eq!(sc.hits, st.hits);
        prop_assert!(sc.rays_culled >= culled.unwrap_or(0));
        // The narrowed scene's sub-blocks are its own 1-cells'.
        let (fw, _, s2) = draw_twice(vol, cam, &mode, method, Some(150.0));
        prop_assert!(
            common::same_frame(&fw, &ft),
            "{mode:?} at 150: second frame differs"
        );
        prop_assert!(s2.rays_culled >= sc.rays_culled);
    }
    // The cost map traces every ray.
    let (_, s) = draw(vol, cam, &Mode::Cost, Method::Cd { min_leap: 1 }, true);
    prop_assert_eq!(s.rays_culled, 0);
    Ok(culled.unwrap_or(0))
}

/// Sample positions from gaps (mm), starting at `o`.
fn positions(o: f64, gaps: &[f64]) -> String {
    let mut p = vec![o];
    for g in gaps {
        p.push(p[p.len() - 1] + g);
    }
    common::axis_json(&p)
}

/// A random sparse volume: a few boxes of value 120 or 200 (one of them
/// can be a single sample) in values below the iso value of 100, on
/// rectilinear axes.
fn sparse() -> impl Strategy<Value = ([usize; 3], Vec<f64>, [Vec<f64>; 3])> {
    (6usize..22, 6usize..22, 4usize..16)
        .prop_flat_map(|(x, y, z)| {
            let boxes = proptest::collection::vec(
                (
                    0..x,
                    0..y,
                    0..z,
                    1usize..4,
                    1usize..4,
                    1usize..4,
                    prop_oneof![Just(120.0), Just(200.0)],
                ),
                0..4,
            );
            let gaps = |n: usize| proptest::collection::vec(0.3f64..2.5, n - 1);
            (Just([x, y, z]), boxes, gaps(x), gaps(y), gaps(z), 0u32..100)
        })
        .prop_map(|(d, boxes, gx, gy, gz, seed)| {
            let mut v: Vec<f64> = (0..d[0] * d[1] * d[2])
                .map(|i| ((i as u64 * 2654435761 + seed as u64) % 90) as f64)
                .collect();
            for (x0, y0, z0, sx, sy, sz, value) in boxes {
                for z in z0..(z0 + sz).min(d[2]) {
                    for y in y0..(y0 + sy).min(d[1]) {
                        for x in x0..(x0 + sx).min(d[0]) {
                            v[(z * d[1] + y) * d[0] + x] = value;
                        }
                    }
                }
            }
            (d, v, [gx, gy, gz])
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn culled_renders_are_the_traced_ones(
        (dims, values, gaps) in sparse(),
        brick in prop_oneof![Just(4usize), Just(8)],
        az in -180.0f64..180.0,
        el in -89.0f64..89.0,
        fov in prop_oneof![Just(None), (10.0f64..100.0).prop_map(Some)],
        zoom in prop_oneof![Just(1.0), 0.2f64..1.0],
        (w, h) in (1u32..40, 1u32..40),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let ax = gaps.clone().map(|g| positions(-3.0, &g));
        let side = write_stack(dir.path(), "v", dims, "u8", &values, [&ax[0], &ax[1], &ax[2]], "");
        let vol = common::packed_with(&side, &dir.path().join("v.cdv"), 100.0, |o| o.brick_size = brick);
        let g = TGrid::<f64>::new(&vol.header().axes);
        let b = g.bounds();
        let radius = 0.5 * (0..3).map(|k| (b.1[k] - b.0[k]).powi(2)).sum::<f64>().sqrt();
        let frame = (fov.is_none() && zoom < 1.0).then_some(2.0 * radius * zoom);
        let cam = Camera::orbit(b, az, el, fov, frame, w, h).unwrap();
        check(&vol, &cam)?;
    }

    /// A perspective eye inside the volume (where some bricks' boxes
    /// cannot be projected) and just outside it.
    #[test]
    fn eyes_inside_and_near(
        (dims, values, gaps) in sparse(),
        at in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
        look in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
        out in prop_oneof![Just(0.0), 0.0f64..0.3],
        fov in 20.0f64..120.0,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let ax = gaps.clone().map(|g| positions(0.0, &g));
        let side = write_stack(dir.path(), "v", dims, "u8", &values, [&ax[0], &ax[1], &ax[2]], "");
        let vol = common::packed_with(&side, &dir.path().join("v.cdv"), 100.0, |o| o.brick_size = 4);
        let g = TGrid::<f64>::new(&vol.header().axes);
        let (lo, hi) = g.bounds();
        let f = [at.0, at.1, at.2];
        let eye: [f64; 3] = std::array::from_fn(|k| {
            lo[k] + (hi[k] - lo[k]) * (f[k] * (1.0 + 2.0 * out) - out)
        });
        let target = [eye[0] + look.0, eye[1] + look.1, eye[2] + look.2 + 1e-3];
        let Ok(cam) = Camera::look_at(eye, target, [0.3, 0.2, 1.0], Projection::Persp { fov_deg: fov }, 17, 13) else {
            return Ok(());
        };
        check(&vol, &cam)?;
    }
}

/// One small object in a corner of a 48^3 volume of 8-cell bricks: most
/// pixels are culled, the image is the traced one, and the culled render
/// takes fewer steps and reads fewer bricks.
#[test]
fn a_small_object_culls_most_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let n = 48;
    let mut v = vec![10.0; n * n * n];
    for z in 3..6 {
        for y in 3..6 {
            for x in 3..6 {
                v[(z * n + y) * n + x] = 200.0;
            }
        }
    }
    let side = write_stack(
        dir.path(),
        "v",
        [n, n, n],
        "u8",
        &v,
        ["1.0", "1.0", "2.0"],
        "",
    );
    let vol = common::packed_with(&side, &dir.path().join("v.cdv"), 100.0, |o| {
        o.brick_size = 8
    });
    for fov in [None, Some(40.0)] {
        let cam = common::orbit(&vol, [30.0, 20.0], fov, 64, 64);
        let culled = check(&vol, &cam).unwrap();
        assert!(culled > 64 * 64 / 2, "{fov:?}: {culled} of 4096 culled");
        let mode = Mode::Surface {
            hit: HitMethod::Int,
            shadows: false,
        };
        let (fc, sc) = draw(&vol, &cam, &mode, Method::Cd { min_leap: 1 }, true);
        let (_, st) = draw(&vol, &cam, &mode, Method::Cd { min_leap: 1 }, false);
        assert!(sc.hits > 0, "the object is in view");
        assert!(fc.rgb.iter().any(|&c| c > 0));
        assert!(sc.steps < st.steps, "{} against {}", sc.steps, st.steps);
        // The second frame's cover is the object's own cells, not its
        // brick: it culls more.
        let (fw, s1, s2) = draw_twice(&vol, &cam, &mode, Method::Cd { min_leap: 1 }, None);
        assert!(common::same_frame(&fw, &fc));
        assert!(
            s2.rays_culled > s1.rays_culled,
            "{fov:?}: {} against {}",
            s2.rays_culled,
            s1.rays_culled
        );
    }
}
