//! The composite mode's run marcher and samplers against a brute-force
//! oracle that knows nothing of traversals, runs or bricks: every sample
//! `t = k * step` of every ray, its cell found from its position, the
//! transfer function evaluated exactly ([`exact_sample`]) wherever that
//! cell is a 1-cell of the transfer-function classification. Plus the
//! samplers' agreement with each other and across traversals, the
//! early-stop knob at its ends, and the MIP window.

use proptest::prelude::*;

use crate::common::{self, orbit, write_stack};
use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::sample::lut::exact_sample;
use cdvol::render::traverse::Method;
use cdvol::render::view::camera::Camera;
use cdvol::render::{render, render_in, Frame, Integrate, Mode, Precision, RenderOptions, Window};

/// A transfer function transparent below 40 and above 180, coloured so
/// the channels differ.
fn tf() -> TransferFunction {
    let p = |value: f64, opacity: f64, color: [f64; 3]| TfPoint {
        value,
        opacity,
        color,
    };
    TransferFunction {
        points: vec![
            p(40.0, 0.0, [1.0, 0.2, 0.1]),
            p(90.0, 0.35, [0.9, 0.8, 0.2]),
            p(140.0, 0.05, [0.2, 0.6, 1.0]),
            p(180.0, 0.0, [0.5, 0.5, 0.5]),
        ],
    }
}

/// `values` (x fastest) on axes with the given sample positions, prepared
/// by the transfer function with 8-sample bricks.
fn packed_tf(
    dir: &std::path::Path,
    dims: [usize; 3],
    values: &[f64],
    pos: &[Vec<f64>; 3],
) -> PackedVolume {
    let [ax, ay, az] = [0, 1, 2].map(|k| common::axis_json(&pos[k]));
    let side = write_stack(dir, "v", dims, "u8", values, [&ax, &ay, &az], "");
    let src = cdvol::input::open(&side).unwrap();
    let mut o = PrepOptions::new(Classification::TransferFunction { tf: tf() });
    o.brick_size = 8;
    let out = dir.join("v.cdv");
    prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
    PackedVolume::open(&out).unwrap()
}

/// The oracle's pixel: every sample of the ray inside the grid, in
/// order; a sample counts when the cell holding it (per axis the largest
/// `j` with `S[j] <= p`) has a vertex range on which the transfer
/// function has opacity; trilinear value in f64, exact table entry,
/// front-to-back until the opacity exceeds 0.99. Where a sample whose
/// opacity is not faint follows a faint one, the lattice restarts at the
/// onset between them, or at the top of the ramp the ray then crosses
/// within a step (integrate/refine.rs); the faint sample just before the
/// onset then stands only for the part of its step before the restarted
/// samples begin.
fn oracle_pixel(
    cam: &Camera,
    x: u32,
    y: u32,
    dims: [usize; 3],
    values: &[f64],
    pos: &[Vec<f64>; 3],
    step: f64,
) -> [f64; 3] {
    let tf = tf();
    let ray = cam.ray(x, y);
    // Slab entry and exit.
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        let (lo, hi) = (pos[a][0], pos[a][dims[a] - 1]);
        let (o, d) = (ray.origin[a], ray.dir[a]);
        if d == 0.0 {
            if o < lo || o > hi {
                return [0.0; 3];
            }
        } else {
            let (ta, tb) = ((lo - o) / d, (hi - o) / d);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    // The value at `t`: none outside the grid and in cells on whose
    // vertex range the transfer function is transparent.
    let value_at = |t: f64| -> Option<f64> {
        if !(t0..=t1).contains(&t) {
            return None;
        }
        let p: [f64; 3] = std::array::from_fn(|a| ray.origin[a] + t * ray.dir[a]);
        let cell: [usize; 3] = std::array::from_fn(|a| {
            pos[a].partition_point(|&s| s <= p[a]).clamp(1, dims[a] - 1) - 1
        });
        let at = |i: usize, j: usize, l: usize| values[(l * dims[1] + j) * dims[0] + i];
        let f: [f64; 8] = std::array::from_fn(|v| {
            at(
                cell[0] + (v & 1),
                cell[1] + ((v >> 1) & 1),
                cell[2] + ((v >> 2) & 1),
            )
        });
        let (lo, hi) = f
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        if !tf.nonzero_on(lo, hi) {
            return None;
        }
        let u: [f64; 3] = std::array::from_fn(|a| {
            let (s0, s1) = (pos[a][cell[a]], pos[a][cell[a] + 1]);
            ((p[a] - s0) / (s1 - s0)).clamp(0.0, 1.0)
        });
        let l = |a: f64, b: f64, w: f64| a + w * (b - a);
        Some(l(
            l(l(f[0], f[1], u[0]), l(f[2], f[3], u[0]), u[1]),
            l(l(f[4], f[5], u[0]), l(f[6], f[7], u[0]), u[1]),
            u[2],
        ))
    };
    let alpha_at = |v: Option<f64>| v.map_or(0.0, |v| exact_sample(&tf, step, v).1);
    let mut col = [0.0; 3];
    let mut alpha = 0.0;
    let mut k = (t0 / step).ceil();
    // Onsets: the last sample was faint (opacity below 1/8 per mm), and
    // from which lattice index a sample after it is refined.
    let faint = 1.0 - (1.0 - 0.125f64).powf(step);
    let (mut clear, mut from) = (true, f64::NEG_INFINITY);
    // The last sample if it was composited as faint: its index, colour,
    // opacity and the transmittance before it.
    let mut last: Option<(f64, [f64; 3], f64, f64)> = None;
    while k * step < t1 {
        let t = k * step;
        let ks = k;
        k += 1.0;
        let Some(v) = value_at(t) else {
            (clear, last) = (true, None);
            continue;
        };
        let (rgb, a) = exact_sample(&tf, step, v);
        if a == 0.0 {
            (clear, last) = (true, None);
            continue;
        }
        if a >= faint && clear && ks > from {
            // An onset: the lattice restarts where the opacity reaches
            // the faint threshold (to 1/64 of the step), or, when the ray
            // passes the transfer function's next point within a step,
            // at that point (to 1/1024) after a partial sample for the
            // ramp between.
            let onset_at = |t: f64| alpha_at(value_at(t)) >= faint;
            let onset = bisect((t - step, t), 6, &onset_at);
            let mut top = None;
            if let Some(need) = value_at(onset.1).and_then(|v_on| ramp_top(&tf, step, faint, v_on))
            {
                let past = |t: f64| alpha_at(value_at(t)) >= need;
                let end = onset.1 + step;
                if past(t) {
                    top = Some(bisect((onset.0, t), 10, &past).1);
                } else if past(end) {
                    top = Some(bisect((onset.1, end), 10, &past).1);
                }
            }
            // The faint sample before: only the part of its step before
            // the restarted samples' first.
            let starts = match top {
                Some(top) if top <= onset.1 => top,
                _ => onset.1,
            };
            if let Some((kl, rgb, a, w)) = last.take().filter(|l| (ks - l.0 - 1.0).abs() < 0.25) {
                let keep = ((starts - kl * step) / step).clamp(0.0, 1.0);
                let b = 1.0 - (1.0 - a).powf(keep);
                for c in 0..3 {
                    col[c] -= w * rgb[c] * (a - b);
                }
                alpha = 1.0 - w * (1.0 - b);
            }
            match top {
                Some(top) if top > onset.1 => {
                    let mid = 0.5 * (onset.1 + top);
                    if let Some(v) = value_at(mid) {
                        let (rgb, a) = exact_sample(&tf, step, v);
                        let b = 1.0 - (1.0 - a).powf((top - onset.1) / step);
                        let w = 1.0 - alpha;
                        for c in 0..3 {
                            col[c] += w * rgb[c] * b;
                        }
                        alpha += w * b;
                        if alpha > 0.99 {
                            break;
                        }
                    }
                    k = top / step;
                }
                Some(top) => k = top / step,
                None => k = onset.1 / step,
            }
            from = k + 1.5;
            continue;
        }
        clear = a < faint;
        let w = 1.0 - alpha;
        for c in 0..3 {
            col[c] += w * rgb[c] * a;
        }
        alpha += w * a;
        last = clear.then_some((ks, rgb, a, w));
        if alpha > 0.99 {
            break;
        }
    }
    col
}

/// `(lo, hi)` after `iters` bisection steps towards where `yes` turns
/// true.
fn bisect((mut lo, mut hi): (f64, f64), iters: u32, yes: &dyn Fn(f64) -> bool) -> (f64, f64) {
    for _ in 0..iters {
        let mid = 0.5 * (lo + hi);
        if yes(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (lo, hi)
}

/// The top of the ramp a ray climbs at an onset with value `v`: the end
/// of `tf`'s segment holding `v` towards which its opacity rises, as the
/// opacity a sample needs to be past it (its own less 1e-3 of it);
/// `None` outside the points, on a flat segment, or when that is
/// `faint`.
fn ramp_top(tf: &TransferFunction, step: f64, faint: f64, v: f64) -> Option<f64> {
    let p = &tf.points;
    let j = p.iter().position(|q| q.value > v)?;
    let (lo, hi) = (p.get(j.checked_sub(1)?)?, &p[j]);
    let top = if hi.opacity > lo.opacity {
        hi
    } else if hi.opacity < lo.opacity {
        lo
    } else {
        return None;
    };
    let need = (1.0 - 1e-3) * exact_sample(tf, step, top.value).1;
    (need >= faint).then_some(need)
}

/// The oracle's 24 x 24 image, 8-bit RGB.
fn oracle_image(
    cam: &Camera,
    dims: [usize; 3],
    values: &[f64],
    pos: &[Vec<f64>; 3],
    step: f64,
) -> Vec<u8> {
    let mut want = vec![0u8; 24 * 24 * 3];
    for y in 0..24 {
        for x in 0..24 {
            let c = oracle_pixel(cam, x, y, dims, values, pos, step);
            for (k, ch) in c.iter().enumerate() {
                want[(y * 24 + x) as usize * 3 + k] =
                    (ch.clamp(0.0, 1.0) as f32 * 255.0).round() as u8;
            }
        }
    }
    want
}

/// The step composite (`--integrate step`), which the oracles model.
fn opts(method: Method, sampling: Precision, step: f64) -> RenderOptions {
    RenderOptions {
        sampling,
        integrate: Integrate::Step,
        ..common::test_opts(
            Mode::Composite {
                tf: tf(),
                step_mm: step,
            },
            method,
        )
    }
}

fn draw(vol: &PackedVolume, cam: &Camera, o: &RenderOptions) -> Frame {
    render(vol, cam, o, &NoProgress).unwrap().0
}

/// Blobs of values in the transfer function's support in a background
/// of 0 (transparent), so rays cross runs of 1-cells, thin 0-cells and
/// empty regions to leap.
fn volume() -> impl Strategy<Value = ([usize; 3], Vec<f64>, [Vec<f64>; 3])> {
    let axis = |n: usize| {
        proptest::collection::vec(0.3f64..2.5, n - 1).prop_map(|gaps| {
            let mut p = vec![0.0];
            for g in gaps {
                p.push(p[p.len() - 1] + g);
            }
            p
        })
    };
    (6usize..18, 6usize..18, 6usize..14).prop_flat_map(move |(x, y, z)| {
        let n = x * y * z;
        (
            Just([x, y, z]),
            proptest::collection::vec(
                (0u32..100).prop_map(|r| match r {
                    0..=54 => 0.0,
                    55..=69 => 200.0,
                    _ => (30 + (r * 37) % 150) as f64,
                }),
                n,
            ),
            (axis(x), axis(y), axis(z)).prop_map(|(a, b, c)| [a, b, c]),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// The f64 sampler equals the brute-force oracle to 1/255 on every
    /// channel of every pixel, for FVT and CD, on random rectilinear
    /// volumes and views; f32 to 2/255.
    #[test]
    fn composite_matches_the_brute_force_oracle(
        (dims, values, pos) in volume(),
        az in -180.0f64..180.0,
        el in -80.0f64..80.0,
        step in prop_oneof![Just(0.37), Just(0.5), Just(1.3)],
    ) {
        let dir = tempfile::tempdir().unwrap();
        let vol = packed_tf(dir.path(), dims, &values, &pos);
        let cam = orbit(&vol, [az, el], None, 24, 24);
        let want = oracle_image(&cam, dims, &values, &pos, step);
        for (method, sampling, tol) in [
            (Method::Fvt, Precision::F64, 1),
            (Method::Cd { min_leap: 1 }, Precision::F64, 1),
            (Method::Cd { min_leap: 1 }, Precision::F32, 2),
        ] {
            let got = draw(&vol, &cam, &opts(method, sampling, step));
            let worst = got.rgb.iter().zip(&want).map(|(&a, &b)| a.abs_diff(b)).max().unwrap();
            prop_assert!(worst <= tol, "{method:?} {sampling:?}: channel off by {worst}");
        }
    }
}

/// Uniform axes of `n` samples with random spacings, one per axis.
fn uniform_volume() -> impl Strategy<Value = ([usize; 3], Vec<f64>, [Vec<f64>; 3])> {
    (
        volume(),
        proptest::array::uniform3(0.3f64..2.5),
        proptest::array::uniform3(-4.0f64..4.0),
    )
        .prop_map(|((dims, values, _), h, s0)| {
            let pos =
                std::array::from_fn(|a| (0..dims[a]).map(|i| s0[a] + i as f64 * h[a]).collect());
            (dims, values, pos)
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// The f32 sampler takes its samples in batches of eight, their cells
    /// by position (integrate/batch.rs), on uniform and rectilinear axes,
    /// shaded (smooth normals), with gradient opacity, both or neither:
    /// it equals the one-at-a-time f32
    /// sampler to 2/255 (a sample on a face may take the neighbouring
    /// cell; opacity is carried as transmittance), unshaded also the
    /// brute-force oracle to 2/255, and FVT, CD and the octree draw the
    /// same bytes. A second frame from the same cache, whose gradient
    /// planes the first frame filled, draws the bytes of the first: the
    /// batches do not depend on which cells the planes had set, so
    /// neither on which thread set them first.
    #[test]
    fn batched_composite_matches_the_oracle_and_one_sample_at_a_time(
        (dims, values, pos) in prop_oneof![uniform_volume(), volume()],
        az in -180.0f64..180.0,
        el in -80.0f64..80.0,
        step in prop_oneof![Just(0.13), Just(0.5), Just(1.3), Just(3.7)],
        shade in any::<bool>(),
        gradient_opacity in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let vol = packed_tf(dir.path(), dims, &values, &pos);
        let cam = orbit(&vol, [az, el], None, 24, 24);
        let p = |gradient: f64, opacity: f64| cdvol::render::GradientPoint { gradient, opacity };
        let look = cdvol::render::CompositeLook {
            shade,
            gradient_opacity: if gradient_opacity {
                vec![p(5.0, 0.2), p(60.0, 1.0)]
            } else {
                vec![]
            },
        };
        let with = |o: RenderOptions, batches: bool| RenderOptions {
            look: look.clone(),
            sample_batches: batches,
            ..o
        };
        let want = look.gradient_opacity.is_empty() && !shade;
        let want = want.then(|| oracle_image(&cam, dims, &values, &pos, step));
        let one = with(opts(Method::Cd { min_leap: 1 }, Precision::F32, step), false);
        let single = draw(&vol, &cam, &one);
        let mut first: Option<Frame> = None;
        for method in [Method::Fvt, Method::Cd { min_leap: 1 }, Method::Octree] {
            let got = draw(&vol, &cam, &with(opts(method, Precision::F32, step), true));
            let off = |w: &[u8]| got.rgb.iter().zip(w).map(|(&a, &b)| a.abs_diff(b)).max().unwrap();
            if let Some(want) = &want {
                prop_assert!(off(want) <= 2, "{method:?}: channel off the oracle by {}", off(want));
            }
            prop_assert!(off(&single.rgb) <= 2, "{method:?}: off one at a time by {}", off(&single.rgb));
            // The batches start where the runs start, which every exact
            // traversal finds alike: the same bytes.
            match &first {
                None => first = Some(got),
                Some(f) => prop_assert!(f.rgb == got.rgb, "{method:?} differs from FVT"),
            }
        }
        let o = with(opts(Method::Cd { min_leap: 1 }, Precision::F32, step), true);
        let cache = cdvol::render::cache_for(&vol, &o);
        let frame = || render_in(&vol, &cache, &cam, &o, &NoProgress).unwrap().0;
        let (cold, warm) = (frame(), frame());
        prop_assert!(cold.rgb == warm.rgb, "a second frame differs from the first");
        prop_assert!(first.is_some_and(|f| f.rgb == cold.rgb), "one cache's frame differs");
    }
}

/// Every exact traversal gives the same composite bytes with either
/// sampler, shaded or not, with gradient opacity, at any early stop.
#[test]
fn composite_is_the_same_for_every_traversal_and_look() {
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("head.json");
    cdvol::tools::phantom::ct(
        &side,
        &cdvol::tools::phantom::CtOptions {
            dims: [40, 36, 30],
            seed: 7,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let src = cdvol::input::open(&side).unwrap();
    let skin = common::white_tf(&[(-300.0, 0.0), (-100.0, 0.05), (400.0, 0.4)]);
    let mut o = PrepOptions::new(Classification::TransferFunction { tf: skin.clone() });
    o.brick_size = 8;
    o.aniso = true;
    let out = dir.path().join("ct.cdv");
    prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
    let vol = PackedVolume::open(&out).unwrap();
    let cam = orbit(&vol, [30.0, 20.0], None, 40, 40);
    let looks = [
        cdvol::render::CompositeLook::default(),
        cdvol::render::CompositeLook {
            shade: true,
            gradient_opacity: vec![],
        },
        cdvol::render::CompositeLook {
            shade: true,
            gradient_opacity: vec![
                cdvol::render::GradientPoint {
                    gradient: 0.0,
                    opacity: 0.0,
                },
                cdvol::render::GradientPoint {
                    gradient: 50.0,
                    opacity: 1.0,
                },
            ],
        },
    ];
    let mut images = Vec::new();
    for integrate in [Integrate::Step, Integrate::Segment { tol: 0.01 }] {
        for look in &looks {
            for sampling in [Precision::F32, Precision::F64] {
                for early_stop in [0.5, 0.99, 1.0] {
                    let mut first: Option<Frame> = None;
                    for method in [
                        Method::Fvt,
                        Method::Cd { min_leap: 1 },
                        Method::Cd { min_leap: 3 },
                        Method::CdAniso { min_leap: 1 },
                        Method::Octree,
                    ] {
                        let o = RenderOptions {
                            sampling,
                            early_stop,
                            integrate,
                            look: look.clone(),
                            ..common::test_opts(
                                Mode::Composite {
                                    tf: skin.clone(),
                                    step_mm: 0.6,
                                },
                                method,
                            )
                        };
                        let f = draw(&vol, &cam, &o);
                        match &first {
                            None => first = Some(f),
                            Some(w) => assert!(
                                w.rgb == f.rgb,
                                "{method:?} {integrate:?} {sampling:?} stop {early_stop} {look:?} \
                             differs from FVT"
                            ),
                        }
                    }
                    images.push(first.unwrap().rgb);
                }
            }
        }
    }
    // The knobs do something, under each integrator (18 images each):
    // shading, gradient opacity and the early stop each change the
    // picture, and so does the integrator.
    let lit = |i: usize| images[i].iter().map(|&x| x as u64).sum::<u64>();
    for k in [0, 18] {
        assert!(images[k + 1] != images[k + 7], "shading changes the image");
        assert!(
            images[k + 7] != images[k + 13],
            "gradient opacity changes the image"
        );
        assert!(
            lit(k) < lit(k + 1),
            "stopping at opacity 0.5 leaves less colour than at 0.99"
        );
    }
    assert!(images[1] != images[19], "the integrator changes the image");
    assert!(images.iter().any(|i| i.iter().any(|&x| x > 0)));
}

/// The early stop at its ends: 1 never stops (the ray composites every
/// sample), and a stop below any single sample's opacity keeps exactly the
/// first sample; out-of-range values are refused by name.
#[test]
fn early_stop_extremes() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [12, 12, 12];
    let values: Vec<f64> = (0..12 * 12 * 12).map(|_| 90.0).collect();
    let pos = [0, 1, 2].map(|_| (0..12).map(|i| i as f64).collect::<Vec<_>>());
    let vol = packed_tf(dir.path(), dims, &values, &pos);
    let cam = orbit(&vol, [0.0, 0.0], None, 8, 8);
    let base = opts(Method::Cd { min_leap: 1 }, Precision::F64, 0.5);
    let at = |stop: f64| {
        draw(
            &vol,
            &cam,
            &RenderOptions {
                early_stop: stop,
                ..base.clone()
            },
        )
    };
    // Value 90 everywhere: opacity 0.35 per mm, 1 - 0.65^0.5 per sample.
    let a = 1.0 - 0.65f64.sqrt();
    let first = at(1e-9);
    let centre = ((4 * 8 + 4) * 3) as usize;
    let want = (0.8 * a * 255.0).round() as u8;
    assert_eq!(first.rgb[centre + 1], want, "one sample of green 0.8");
    let all = at(1.0);
    let never = at(0.99);
    assert!(all.rgb[centre + 1] >= never.rgb[centre + 1]);
    for bad in [0.0, -1.0, 1.5, f64::NAN] {
        let e = render(
            &vol,
            &cam,
            &RenderOptions {
                early_stop: bad,
                ..base.clone()
            },
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("early_stop"), "{bad}: {e}");
    }
}

/// MIP windows: `full` maps the file's value range, a fixed window maps
/// its ends to black and white, and the automatic one spreads the image's
/// values (1st to 99.9th percentile) over the grey range.
#[test]
fn mip_windows() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [10, 10, 10];
    let values: Vec<f64> = (0..1000)
        .map(|i| {
            if (i * 7) % 10 < 4 {
                60.0 + (i % 50) as f64
            } else {
                0.0
            }
        })
        .collect();
    let side = write_stack(dir.path(), "m", dims, "u8", &values, ["1", "1", "1"], "");
    let vol = common::packed(&side, &dir.path().join("m.cdv"), 50.0);
    let cam = orbit(&vol, [10.0, 5.0], None, 16, 16);
    let with = |window: Window| {
        let o = RenderOptions {
            window,
            ..common::test_opts(Mode::Mip, Method::Cd { min_leap: 1 })
        };
        draw(&vol, &cam, &o)
    };
    let auto = with(Window::Auto);
    let grey: Vec<u8> = auto.rgb.iter().step_by(3).cloned().collect();
    assert_eq!(*grey.iter().max().unwrap(), 255, "auto: the top is white");
    // `full` is the file's value range, 0..109 here: the same as that
    // window given by width and level.
    let full = with(Window::Full);
    assert!(full.rgb.iter().any(|&x| x > 0));
    let same = with(Window::Fixed {
        width: 109.0,
        level: 54.5,
    });
    assert_eq!(full.rgb, same.rgb);
    assert_ne!(full.rgb, auto.rgb, "auto spreads the values differently");
    // A window below every value the rays meet (face samples of 1-cells
    // are >= 0): a hit pixel is white unless its maximum is below 1.
    let low = with(Window::Fixed {
        width: 1.0,
        level: -0.5,
    });
    let hit = |f: &Frame| f.rgb.iter().step_by(3).filter(|&&x| x > 0).count();
    assert!(hit(&low) >= hit(&full));
    assert!(low.rgb.iter().all(|&x| x == 0 || x == 255));
    let e = render(
        &vol,
        &cam,
        &RenderOptions {
            window: Window::Fixed {
                width: 0.0,
                level: 1.0,
            },
            ..common::test_opts(Mode::Mip, Method::Cd { min_leap: 1 })
        },
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("window"), "{e}");
}
