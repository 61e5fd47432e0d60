//! Rendering: every traversal gives bit-identical images, depth matches
//! the analytic spheres, and the output does not depend on the cache
//! budget, thread count or tile size.

use crate::common::{self, orbit, packed, packed_with, same_frame, white_tf};

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::Method;
use cdvol::render::view::camera::Camera;
use cdvol::render::{
    lazy_min_for, render, render_in, Frame, Mode, RenderOptions, Stats, LAZY_MIN_CODE_SPARSE,
};
use cdvol::tools::phantom;

fn run(vol: &PackedVolume, c: &Camera, mode: &Mode, method: Method) -> (Frame, Stats) {
    let o = common::test_opts(mode.clone(), method);
    render(vol, c, &o, &NoProgress).unwrap()
}

/// Renders every mode from several views with FVT and each CD variant
/// and requires identical bytes. Returns (fvt steps, cd steps).
fn all_identical(vol: &PackedVolume, aniso: bool) -> (u64, u64) {
    let tf = TransferFunction {
        points: vec![
            TfPoint {
                value: -1e9,
                opacity: 0.0,
                color: [1.0; 3],
            },
            TfPoint {
                value: iso(vol),
                opacity: 0.0,
                color: [1.0, 0.8, 0.6],
            },
            TfPoint {
                value: iso(vol) + 500.0,
                opacity: 0.3,
                color: [1.0, 1.0, 1.0],
            },
        ],
    };
    let modes = [
        Mode::Surface {
            hit: HitMethod::Int,
            shadows: false,
        },
        Mode::Surface {
            hit: HitMethod::Newton,
            shadows: true,
        },
        Mode::Mip,
        Mode::Depth {
            hit: HitMethod::Bisect,
        },
        Mode::Composite { tf, step_mm: 0.7 },
    ];
    let mut methods = vec![Method::Cd { min_leap: 1 }, Method::Cd { min_leap: 3 }];
    if aniso {
        methods.push(Method::CdAniso { min_leap: 1 });
    }
    let (mut fvt_steps, mut cd_steps) = (0, 0);
    for (view, persp) in [
        ([0.0, 0.0], false),
        ([90.0, 0.0], false),
        ([0.0, 90.0], false),
        ([37.0, 23.0], false),
        ([-120.0, -40.0], true),
    ] {
        let c = orbit(vol, view, persp.then_some(35.0), 48, 48);
        for mode in &modes {
            let (want, ws) = run(vol, &c, mode, Method::Fvt);
            for &m in &methods {
                let (got, gs) = run(vol, &c, mode, m);
                assert!(
                    same_frame(&got, &want),
                    "{m:?} differs from fvt: {mode:?} view {view:?} persp {persp}"
                );
                assert_eq!(gs.hits, ws.hits);
                if m == (Method::Cd { min_leap: 1 }) {
                    fvt_steps += ws.steps;
                    cd_steps += gs.steps;
                }
            }
        }
    }
    (fvt_steps, cd_steps)
}

fn iso(vol: &PackedVolume) -> f64 {
    match vol.header().classification {
        Classification::Iso { iso } => iso,
        _ => unreachable!(),
    }
}

#[test]
fn traversals_identical_on_sphere_phantoms() {
    let dir = tempfile::tempdir().unwrap();
    for (n, spacing) in [(2, "1"), (5, "0.8,1,0.5:2"), (9, "1,1,2")] {
        let side = dir.path().join(format!("s{n}.json"));
        let info = phantom::spheres(
            &side,
            &phantom::SpheresOptions {
                size: 40,
                per_axis: n,
                seed: 11,
                spacing: phantom::parse_spacing3(spacing).unwrap(),
            },
            &NoProgress,
        )
        .unwrap();
        let vol = packed_with(
            &side,
            &dir.path().join(format!("s{n}.cdv")),
            info.iso,
            |o| o.aniso = true,
        );
        let (fvt, cd) = all_identical(&vol, true);
        assert!(cd < fvt, "N = {n}: CD took {cd} steps, FVT {fvt}");
    }
}

#[test]
fn traversals_identical_on_ct_phantom_and_real_ct() {
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("head.json");
    phantom::ct(
        &side,
        &phantom::CtOptions {
            dims: [64, 60, 48],
            dtype: phantom::CtDtype::I16,
            seed: 2,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let vol = packed_with(&side, &dir.path().join("head.cdv"), 300.0, |o| {
        o.aniso = true
    });
    all_identical(&vol, true);
    let ct = common::real_ct();
    let vol = packed(&ct, &dir.path().join("ct.cdv"), -300.0);
    let (fvt, cd) = all_identical(&vol, false);
    assert!(cd * 2 < fvt, "real CT: CD took {cd} steps, FVT {fvt}");
}

/// Depth of the sphere phantom against analytic ray/sphere intersections.
#[test]
fn depth_matches_analytic_spheres() {
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("s.json");
    let info = phantom::spheres(
        &side,
        &phantom::SpheresOptions {
            size: 64,
            per_axis: 2,
            seed: 5,
            spacing: phantom::parse_spacing3("1,1,1.5").unwrap(),
        },
        &NoProgress,
    )
    .unwrap();
    let vol = packed(&side, &dir.path().join("s.cdv"), info.iso);
    // Tolerances in mm (grid spacing 1 x 1 x 1.5 mm). Measured: mean
    // 0.027-0.029 mm, max 0.090-0.103 mm for all three methods: the error is
    // that of the phantom's trilinear iso-surface against the true sphere
    // (its profile is linear in distance, sampled on the grid), which `int`
    // barely adds to on these near-linear cells. Bounds: 0.04 / 0.15 mm.
    for (hit, tol_mean, tol_max) in [
        (HitMethod::Int, 0.04, 0.15),
        (HitMethod::Bisect, 0.04, 0.15),
        (HitMethod::Newton, 0.04, 0.15),
    ] {
        for view in [[0.0, 0.0], [33.0, 21.0]] {
            let c = orbit(&vol, view, None, 96, 96);
            let (f, _) = run(&vol, &c, &Mode::Depth { hit }, Method::Cd { min_leap: 1 });
            let d = f.depth.unwrap();
            let (mut n, mut sum, mut max, mut missed) = (0usize, 0.0f64, 0.0f64, 0usize);
            for py in 0..96 {
                for px in 0..96 {
                    let r = c.ray(px, py);
                    // Nearest analytic hit, and how squarely the ray meets it.
                    let mut best: Option<(f64, f64)> = None;
                    for s in &info.spheres {
                        let oc: [f64; 3] = std::array::from_fn(|k| r.origin[k] - s.center[k]);
                        let b = (0..3).map(|k| oc[k] * r.dir[k]).sum::<f64>();
                        let cc = (0..3).map(|k| oc[k] * oc[k]).sum::<f64>() - s.radius * s.radius;
                        let disc = b * b - cc;
                        if disc > 0.0 {
                            let t = -b - disc.sqrt();
                            let cos = disc.sqrt() / s.radius;
                            if best.is_none_or(|(bt, _)| t < bt) {
                                best = Some((t, cos));
                            }
                        }
                    }
                    let got = d[(py * 96 + px) as usize];
                    if let Some((t, cos)) = best {
                        // A ray that meets a sphere squarely must hit it.
                        missed += (cos > 0.3 && !got.is_finite()) as usize;
                        if cos > 0.3 && got.is_finite() {
                            let e = (got as f64 - t).abs();
                            n += 1;
                            sum += e;
                            max = max.max(e);
                        }
                    }
                }
            }
            let mean = sum / n as f64;
            eprintln!(
                "{hit:?} view {view:?}: {n} pixels, mean error {mean:.4} mm, max {max:.4} mm"
            );
            assert!(n > 500, "too few hits ({n})");
            assert_eq!(
                missed, 0,
                "{hit:?}: {missed} rays missed a sphere they meet squarely"
            );
            assert!(
                mean < tol_mean && max < tol_max,
                "{hit:?}: mean {mean}, max {max}"
            );
        }
    }
}

#[test]
fn same_image_whatever_cache_threads_and_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let vol = packed(&ct, &dir.path().join("ct.cdv"), 300.0);
    let c = orbit(&vol, [30.0, 20.0], None, 96, 96);
    let mode = Mode::Surface {
        hit: HitMethod::Int,
        shadows: true,
    };
    let big = RenderOptions {
        tile: 32,
        cache_bytes: 512 << 20,
        cd_lazy_min: Some(16),
        ..RenderOptions::new(mode.clone(), Method::Cd { min_leap: 1 })
    };
    let (want, ws) = render(&vol, &c, &big, &NoProgress).unwrap();
    // A budget of about two bricks.
    let small = RenderOptions {
        cache_bytes: 100_000,
        tile: 7,
        ..big.clone()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let (got, gs) = pool
        .install(|| render(&vol, &c, &small, &NoProgress))
        .unwrap();
    assert!(
        same_frame(&got, &want),
        "image depends on cache budget, tile size or threads"
    );
    assert!(
        gs.peak_cache_bytes <= 100_000,
        "peak {} > budget",
        gs.peak_cache_bytes
    );
    assert!(
        gs.bricks_read > ws.bricks_read,
        "a small cache must re-read bricks"
    );
    // Without evictions every brick is read once, racing threads or not;
    // the set of bricks a scene needs does not depend on the budget.
    assert_eq!(ws.bricks_read, ws.bricks_distinct);
    assert_eq!(gs.bricks_distinct, ws.bricks_distinct);
    assert!(0 < ws.bricks_distinct && ws.bricks_distinct <= ws.bricks_total);
    // Frames sharing one cache (turntables): the same image, and a second
    // frame of the same view reads nothing; a small shared cache re-reads.
    for o in [&big, &small] {
        let shared = cdvol::render::cache_for(&vol, o);
        let (f1, s1) = render_in(&vol, &shared, &c, o, &NoProgress).unwrap();
        let (f2, s2) = render_in(&vol, &shared, &c, o, &NoProgress).unwrap();
        assert!(same_frame(&f1, &want) && same_frame(&f2, &want));
        assert!(s1.bricks_read > 0);
        if o.cache_bytes == big.cache_bytes {
            assert_eq!(s2.bricks_read, 0);
        } else {
            assert!(s2.bricks_read > 0);
        }
    }
}

/// Without a threshold given, CD's stand-in threshold follows the rays'
/// density (`lazy_min_for`): on the real CT packed in bricks of 16 cells
/// (finest spacing 0.957 mm, about 15 mm a brick) a brick spans more than
/// 64 pixels of a 2048^2 view of the whole head and a few of a 64^2 one,
/// so the first reads the bricks whose smallest code is below 16 and the
/// second only those below 4. The images are the same whichever
/// threshold: a stand-in is exact.
#[test]
fn the_stand_in_threshold_follows_the_ray_density() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let vol = packed(&ct, &dir.path().join("ct.cdv"), 300.0);
    let h = vol.header();
    assert_eq!(h.brick_size, 16);
    let dense = orbit(&vol, [30.0, 20.0], None, 2048, 2048);
    let sparse = orbit(&vol, [30.0, 20.0], None, 64, 64);
    assert_eq!(lazy_min_for(h, &dense), 16);
    assert_eq!(lazy_min_for(h, &sparse), LAZY_MIN_CODE_SPARSE);
    assert_eq!(LAZY_MIN_CODE_SPARSE, 4);
    let run = |lazy: Option<u8>| {
        let o = RenderOptions {
            tile: 16,
            cd_lazy_min: lazy,
            ..RenderOptions::new(Mode::Mip, Method::Cd { min_leap: 1 })
        };
        render(&vol, &sparse, &o, &NoProgress).unwrap()
    };
    let (auto, sa) = run(None);
    let (four, s4) = run(Some(4));
    let (sixteen, s16) = run(Some(16));
    assert!(same_frame(&auto, &four) && same_frame(&auto, &sixteen));
    assert_eq!((sa.bricks_read, sa.steps), (s4.bricks_read, s4.steps));
    assert!(
        s4.bricks_read < s16.bricks_read,
        "threshold 4 reads {} bricks, 16 reads {}",
        s4.bricks_read,
        s16.bricks_read
    );
}

#[test]
fn corrupt_brick_is_an_error_not_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let path = dir.path().join("ct.cdv");
    let vol = packed(&ct, &path, 300.0);
    // Damage the payload of every non-uniform brick in the middle.
    let mut bytes = std::fs::read(&path).unwrap();
    for e in vol.index().iter().filter(|e| !e.is_uniform()) {
        bytes[(e.offset + e.length as u64 / 2) as usize] ^= 0x40;
    }
    drop(vol);
    std::fs::write(&path, &bytes).unwrap();
    let vol = PackedVolume::open(&path).unwrap();
    let c = orbit(&vol, [0.0, 0.0], None, 32, 32);
    let o = RenderOptions {
        tile: 16,
        cache_bytes: 1 << 20,
        cd_lazy_min: Some(16),
        ..RenderOptions::new(Mode::Mip, Method::Cd { min_leap: 1 })
    };
    let e = render(&vol, &c, &o, &NoProgress).unwrap_err().to_string();
    assert!(
        e.contains("ct.cdv") && e.contains("brick") && e.contains("checksum"),
        "{e}"
    );
}

#[test]
fn composite_refuses_a_transfer_function_the_file_cannot_honour() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let vol = packed(&ct, &dir.path().join("ct.cdv"), 300.0);
    let tf = white_tf(&[(-200.0, 0.0), (0.0, 0.1)]);
    let c = orbit(&vol, [0.0, 0.0], None, 16, 16);
    let o = RenderOptions {
        tile: 16,
        cache_bytes: 1 << 20,
        cd_lazy_min: Some(16),
        ..RenderOptions::new(Mode::Composite { tf, step_mm: 1.0 }, Method::Fvt)
    };
    let e = render(&vol, &c, &o, &NoProgress).unwrap_err().to_string();
    assert!(
        e.contains("opacity to values below 300") && e.contains("classified as empty"),
        "{e}"
    );
}

/// Float data with NaN regions: composite and surface renders work (NaN
/// samples are background and never reach the transfer function as NaN).
#[test]
fn nan_samples_render() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [20, 18, 16];
    let mut v: Vec<f64> = (0..20 * 18 * 16).map(|i| ((i * 37) % 50) as f64).collect();
    for (i, x) in v.iter_mut().enumerate() {
        if i % 5 == 0 || (i / 20 % 18) < 6 {
            *x = f64::NAN;
        }
    }
    let side = common::write_stack(dir.path(), "nan", dims, "f32", &v, ["1", "1", "1"], "");
    let tf = white_tf(&[(30.0, 0.0), (45.0, 0.5)]);
    let src = RawSource::open(&side).unwrap();
    let out = dir.path().join("nan.cdv");
    let mut o = PrepOptions::new(Classification::TransferFunction { tf: tf.clone() });
    o.brick_size = 8;
    prep(&src, &out, &o, &NoProgress).unwrap();
    let vol = PackedVolume::open(&out).unwrap();
    let c = orbit(&vol, [20.0, 10.0], None, 32, 32);
    let (f, s) = run(
        &vol,
        &c,
        &Mode::Composite { tf, step_mm: 0.3 },
        Method::Cd { min_leap: 1 },
    );
    assert!(s.hits > 0 && f.rgb.iter().any(|&x| x > 0));
    let vol = packed(&side, &dir.path().join("iso.cdv"), 45.0);
    let (f, s) = run(
        &vol,
        &c,
        &Mode::Surface {
            hit: HitMethod::Newton,
            shadows: true,
        },
        Method::Cd { min_leap: 1 },
    );
    assert!(s.hits > 0 && f.rgb.iter().any(|&x| x > 0));
}

/// `--stats` splits the tiles' time into decode, traversal and sampling
/// (render/clock.rs): the three add up to the tiles' time, and a scene with
/// hits spends time in each.
#[test]
fn stats_split_the_tiles_time() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let vol = packed(&ct, &dir.path().join("ct.cdv"), 300.0);
    let c = orbit(&vol, [30.0, 20.0], None, 64, 64);
    let modes = [
        Mode::Surface {
            hit: HitMethod::Int,
            shadows: true,
        },
        Mode::Depth {
            hit: HitMethod::Newton,
        },
        Mode::Mip,
        Mode::Composite {
            tf: white_tf(&[(300.0, 0.0), (1500.0, 0.6)]),
            step_mm: 0.5,
        },
    ];
    for mode in modes {
        let (_, s) = run(&vol, &c, &mode, Method::Cd { min_leap: 1 });
        let sum = s.seconds_decode + s.seconds_traverse + s.seconds_sample;
        assert!(
            (sum - s.seconds_tiles).abs() <= 1e-9 * s.seconds_tiles.max(1.0),
            "{mode:?}: decode + traverse + sample = {sum} != tiles {}",
            s.seconds_tiles
        );
        assert!(
            s.seconds_decode > 0.0 && s.seconds_traverse > 0.0 && s.seconds_sample > 0.0,
            "{mode:?}: {s:?}"
        );
    }
}

/// A CT phantom of `dims` voxels prepared at iso 300 and rendered at
/// 128^2 on one thread as a two-frame turntable at one view (a cold frame,
/// then a warm one), in a process of its own: the frames' `--stats` and
/// the summary line.
#[cfg(target_os = "linux")]
fn cold_and_warm_frame(dims: &str) -> (Vec<Stats>, String) {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_owned();
    common::ok(common::cdvol().args(["phantom", "ct", "--dims", dims, "-o", &p("ct.json")]));
    common::ok(common::cdvol().args(["prep", &p("ct.json"), "-o", &p("ct.cdv"), "--iso", "300"]));
    let out = common::ok(common::cdvol().args([
        "render",
        &p("ct.cdv"),
        "-o",
        &p("ct.png"),
        "--width",
        "128",
        "--height",
        "128",
        "--threads",
        "1",
        "--frames",
        "2",
        "--orbit",
        "0",
        "--stats",
        &p("s.json"),
    ]));
    let s: Vec<Stats> = serde_json::from_slice(&std::fs::read(p("s.json")).unwrap()).unwrap();
    assert_eq!(s.len(), 2);
    (s, out)
}

/// `--stats` reports the plane pool's huge pages: a cold frame that fills
/// more than `SMALL_CHUNKS` chunks of one size class (the 256^3 phantom's
/// bricks with values: 72 KiB words, 28 to a chunk) asks for at least one;
/// how many of them are slow is the host's business. A warm frame maps no
/// chunk.
#[cfg(target_os = "linux")]
#[test]
fn stats_report_the_plane_pools_huge_pages() {
    let (s, out) = cold_and_warm_frame("256,256,256");
    assert!(s[0].huge_pages >= 1, "cold frame: {:?}", s[0]);
    assert!(s[0].huge_pages_slow <= s[0].huge_pages, "{:?}", s[0]);
    assert_eq!(
        (s[1].huge_pages, s[1].huge_pages_slow),
        (0, 0),
        "warm frame: {:?}",
        s[1]
    );
    assert!(out.contains(" huge page"), "{out}");
}

/// `--stats` reports the kernel's share of each frame: a cold frame of a
/// fresh process decodes its bricks into fresh memory, which the kernel
/// maps in (page faults); a warm frame of the same process decodes
/// nothing. Process-wide figures, read in a process of its own.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn stats_report_the_kernel_share_of_a_cold_frame() {
    let (s, _) = cold_and_warm_frame("96,96,96");
    assert!(s[0].bricks_read > 0, "{:?}", s[0]);
    assert!(s[0].page_faults > 0, "cold frame: {:?}", s[0]);
    assert_eq!(s[1].bricks_read, 0, "warm frame: {:?}", s[1]);
    for f in &s {
        assert!(
            f.seconds_system.is_finite() && f.seconds_system >= 0.0,
            "{f:?}"
        );
    }
}

/// Without `--traversal`, `cdvol render` walks a file prepared with
/// `--aniso` by CD with its octant codes and any other file by CD: the
/// stats name the traversal, the octant codes take fewer steps, and the
/// image is byte for byte the one `--traversal cd` draws of the same file
/// (and of the file without octant codes). `--min-leap` still applies.
#[test]
fn the_default_traversal_uses_the_files_octant_codes() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_owned();
    common::ok(common::cdvol().args(["phantom", "ct", "--dims", "80,72,64", "-o", &p("ct.json")]));
    common::ok(common::cdvol().args(["prep", &p("ct.json"), "-o", &p("iso.cdv"), "--iso", "300"]));
    common::ok(common::cdvol().args([
        "prep",
        &p("ct.json"),
        "-o",
        &p("an.cdv"),
        "--iso",
        "300",
        "--aniso",
    ]));
    let render = |file: &str, name: &str, more: &[&str]| -> Stats {
        let (png, json) = (p(&format!("{name}.png")), p(&format!("{name}.json")));
        common::ok(
            common::cdvol()
                .args(["render", &p(file), "-o", &png, "--stats", &json])
                .args(["--width", "96", "--height", "96", "--view", "30,20"])
                .args(more),
        );
        serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap()
    };
    let auto_an = render("an.cdv", "auto-an", &[]);
    let cd_an = render("an.cdv", "cd-an", &["--traversal", "cd"]);
    let auto_iso = render("iso.cdv", "auto-iso", &[]);
    let leap_an = render("an.cdv", "leap-an", &["--min-leap", "3"]);
    assert_eq!(auto_an.traversal, "cd-aniso");
    assert_eq!(cd_an.traversal, "cd");
    assert_eq!(auto_iso.traversal, "cd");
    assert_eq!(leap_an.traversal, "cd-aniso min_leap=3");
    assert!(
        auto_an.steps < cd_an.steps,
        "octant codes: {} steps, CD {}",
        auto_an.steps,
        cd_an.steps
    );
    let png = |n: &str| std::fs::read(p(&format!("{n}.png"))).unwrap();
    assert!(auto_an.hits > 0);
    assert_eq!(png("auto-an"), png("cd-an"));
    assert_eq!(png("auto-an"), png("auto-iso"));
    assert_eq!(png("auto-an"), png("leap-an"));
}
