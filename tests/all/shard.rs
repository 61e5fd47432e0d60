//! Sharded rendering: parts written to files and assembled give the bytes
//! of the single-process render in every mode, for any shard count, tile
//! size and image size; assembly refuses parts that do not make one whole
//! render; the CLI's `--shard`, `assemble` and `--frames` agree with a
//! plain `render`.

use std::path::{Path, PathBuf};
use std::process::Command;

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::job::shard::{assemble, Part};
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::Method;
use cdvol::render::view::camera::Camera;
use cdvol::render::{
    render, render_part, Frame, Mode, RenderOptions, Shard, ShardLayout, Stats, Window,
};
use cdvol::tools::phantom;
use proptest::prelude::*;

use crate::common::{cdvol, fails, ok, orbit, packed, same_frame};

/// A small rectilinear sphere phantom, prepared; returns (volume, iso).
fn phantom(dir: &Path, name: &str) -> (PackedVolume, f64) {
    let side = dir.join(format!("{name}.json"));
    let info = phantom::spheres(
        &side,
        &phantom::SpheresOptions {
            size: 36,
            per_axis: 3,
            seed: 5,
            spacing: phantom::parse_spacing3("0.8,1,0.5:2").unwrap(),
        },
        &NoProgress,
    )
    .unwrap();
    let out = dir.join(format!("{name}.cdv"));
    (packed(&side, &out, info.iso), info.iso)
}

fn options(mode: Mode, tile: u32) -> RenderOptions {
    RenderOptions {
        tile,
        cache_bytes: 16 << 20,
        cd_lazy_min: Some(4),
        ..RenderOptions::new(mode, Method::Cd { min_leap: 1 })
    }
}

fn modes(iso: f64) -> Vec<Mode> {
    let tf = TransferFunction {
        points: vec![
            TfPoint {
                value: iso,
                opacity: 0.0,
                color: [1.0; 3],
            },
            TfPoint {
                value: iso + 300.0,
                opacity: 0.4,
                color: [1.0, 0.7, 0.5],
            },
        ],
    };
    vec![
        Mode::Surface {
            hit: HitMethod::Newton,
            shadows: true,
        },
        Mode::Composite { tf, step_mm: 0.6 },
        Mode::Mip,
        Mode::Cost,
        Mode::Depth {
            hit: HitMethod::Bisect,
        },
    ]
}

/// Shard `k` of `n`, interleaved.
fn sh(k: u32, n: u32) -> Shard {
    Shard {
        k,
        n,
        layout: ShardLayout::Interleaved,
    }
}

/// Renders `n` parts through files, in scrambled order, and assembles.
fn sharded(
    vol: &PackedVolume,
    cam: &Camera,
    opts: &RenderOptions,
    n: u32,
    layout: ShardLayout,
    dir: &Path,
) -> Result<(Frame, Stats), String> {
    let mut names: Vec<PathBuf> = (0..n)
        .map(|k| {
            let shard = Shard { k, n, layout };
            let part = render_part(vol, cam, opts, shard, &NoProgress).unwrap();
            let p = dir.join(format!("p{k}of{n}.cdvpart"));
            part.write(&p).unwrap();
            p
        })
        .collect();
    names.reverse();
    names.rotate_left(n as usize / 2);
    let parts: Vec<Part> = names.iter().map(|p| Part::read(p).unwrap()).collect();
    assemble(&parts, &names).map_err(|e| e.to_string())
}

/// Every plane of an assembled frame and a whole one, floats by their
/// bits (an assembly always keeps the unrounded colour; the whole render
/// when asked).
fn assert_planes_equal(got: &Frame, want: &Frame) {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(got.alpha, want.alpha);
    assert_eq!(got.steps, want.steps);
    if !want.linear.is_empty() {
        assert_eq!(bits(&got.linear), bits(&want.linear));
    }
    assert_eq!(
        got.values.as_deref().map(bits),
        want.values.as_deref().map(bits)
    );
}

fn assert_counters_equal(got: &Stats, want: &Stats) {
    assert_eq!(got.rays, want.rays);
    assert_eq!(got.steps, want.steps);
    assert_eq!(got.macro_steps, want.macro_steps);
    assert_eq!(got.cell_steps, want.cell_steps);
    assert_eq!(got.hits, want.hits);
    assert_eq!((got.width, got.height), (want.width, want.height));
}

#[test]
fn assembled_parts_equal_the_single_render_in_every_mode() {
    let dir = tempfile::tempdir().unwrap();
    let (vol, iso) = phantom(dir.path(), "s");
    for (view, persp) in [([30.0, 20.0], false), ([-100.0, -35.0], true)] {
        // 50x37 with 16-pixel tiles: ragged edge tiles on both axes.
        let cam = orbit(&vol, view, persp.then_some(40.0), 50, 37);
        // Tiles of 4 as well: many wholly culled, drawn without pixels
        // (written to the parts as misses). A whole render's tiles colour
        // their own pixels where the colours do not depend on the whole
        // image (surface, composite, MIP with a given window; render/
        // canvas.rs), parts are coloured together: every plane agrees.
        let variants = |mode: Mode, tile: u32| {
            let o = options(mode.clone(), tile);
            match mode {
                Mode::Mip => vec![
                    o.clone(),
                    RenderOptions {
                        window: Window::Full,
                        ..o.clone()
                    },
                    RenderOptions {
                        window: Window::Fixed {
                            width: 300.0,
                            level: iso,
                        },
                        ..o
                    },
                ],
                Mode::Surface { .. } | Mode::Composite { .. } => {
                    vec![
                        o.clone(),
                        RenderOptions {
                            unrounded: true,
                            ..o
                        },
                    ]
                }
                _ => vec![o],
            }
        };
        for (mode, opts) in modes(iso)
            .into_iter()
            .flat_map(|m| [(m.clone(), 16), (m, 4)])
            .flat_map(|(m, tile)| {
                variants(m.clone(), tile)
                    .into_iter()
                    .map(move |o| (m.clone(), o))
            })
        {
            let tile = opts.tile;
            let (want, ws) = render(&vol, &cam, &opts, &NoProgress).unwrap();
            // More shards than the 12 tiles leaves some parts empty.
            for n in [1, 2, 3, 5, 16] {
                for layout in [ShardLayout::Interleaved, ShardLayout::Blocks] {
                    let (got, gs) = sharded(&vol, &cam, &opts, n, layout, dir.path()).unwrap();
                    assert!(
                        same_frame(&got, &want),
                        "{mode:?} view {view:?} tile {tile}: N = {n} {layout:?} differs"
                    );
                    assert_planes_equal(&got, &want);
                    assert_counters_equal(&gs, &ws);
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]
    /// Any image size, tile size and shard count.
    #[test]
    fn any_split_assembles_to_the_same_bytes(
        w in 1u32..70, h in 1u32..70, tile in 1u32..40, n in 1u32..9,
        az in -180.0f64..180.0, el in -89.0f64..89.0, blocks in any::<bool>(),
    ) {
        let layout = if blocks { ShardLayout::Blocks } else { ShardLayout::Interleaved };
        let dir = tempfile::tempdir().unwrap();
        let (vol, _) = phantom(dir.path(), "s");
        let cam = orbit(&vol, [az, el], None, w, h);
        let opts = options(Mode::Cost, tile);
        let (want, ws) = render(&vol, &cam, &opts, &NoProgress).unwrap();
        let (got, gs) = sharded(&vol, &cam, &opts, n, layout, dir.path()).unwrap();
        prop_assert!(same_frame(&got, &want));
        prop_assert_eq!(gs.steps, ws.steps);
        prop_assert_eq!(gs.rays, ws.rays);
    }
}

/// Writes the parts of a 3-shard surface render; returns their paths.
fn three_parts(vol: &PackedVolume, cam: &Camera, opts: &RenderOptions, dir: &Path) -> Vec<PathBuf> {
    (0..3)
        .map(|k| {
            let p = dir.join(format!("part{k}.cdvpart"));
            render_part(vol, cam, opts, sh(k, 3), &NoProgress)
                .unwrap()
                .write(&p)
                .unwrap();
            p
        })
        .collect()
}

fn assemble_files(names: &[PathBuf]) -> Result<(Frame, Stats), String> {
    let parts = names
        .iter()
        .map(|p| Part::read(p))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())?;
    assemble(&parts, names).map_err(|e| e.to_string())
}

fn refused(r: Result<(Frame, Stats), String>, words: &[&str]) {
    let msg = match r {
        Ok(_) => panic!("assembled, expected an error naming {words:?}"),
        Err(m) => m,
    };
    for w in words {
        assert!(msg.contains(w), "{msg:?} does not mention {w:?}");
    }
}

#[test]
fn assembly_refuses_parts_that_do_not_make_one_render() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (vol, _) = phantom(d, "s");
    let cam = orbit(&vol, [10.0, 10.0], None, 40, 40);
    let surface = Mode::Surface {
        hit: HitMethod::Int,
        shadows: false,
    };
    let opts = options(surface.clone(), 16);
    let p = three_parts(&vol, &cam, &opts, d);
    assert!(assemble_files(&p).is_ok());

    // A shard missing, a shard twice.
    refused(assemble_files(&p[..2]), &["shards missing", "2/3"]);
    let twice = vec![p[0].clone(), p[1].clone(), p[1].clone()];
    refused(assemble_files(&twice), &["part1.cdvpart", "both shard 1/3"]);

    // A part of another render: camera, options, shard count, volume.
    let other =
        |name: &str, cam: &Camera, opts: &RenderOptions, shard: Shard, vol: &PackedVolume| {
            let q = d.join(name);
            render_part(vol, cam, opts, shard, &NoProgress)
                .unwrap()
                .write(&q)
                .unwrap();
            vec![p[0].clone(), p[1].clone(), q]
        };
    let cam2 = orbit(&vol, [11.0, 10.0], None, 40, 40);
    refused(
        assemble_files(&other("c.cdvpart", &cam2, &opts, sh(2, 3), &vol)),
        &["part0.cdvpart", "c.cdvpart", "different renders", "camera"],
    );
    let opts2 = options(
        Mode::Surface {
            hit: HitMethod::Int,
            shadows: true,
        },
        16,
    );
    refused(
        assemble_files(&other("o.cdvpart", &cam, &opts2, sh(2, 3), &vol)),
        &["o.cdvpart", "render options"],
    );
    refused(
        assemble_files(&other(
            "t.cdvpart",
            &cam,
            &options(surface.clone(), 8),
            sh(2, 3),
            &vol,
        )),
        &["t.cdvpart", "render options"],
    );
    refused(
        assemble_files(&other("n.cdvpart", &cam, &opts, sh(2, 4), &vol)),
        &["n.cdvpart", "number of shards"],
    );
    let blocks = Shard {
        layout: ShardLayout::Blocks,
        ..sh(2, 3)
    };
    refused(
        assemble_files(&other("l.cdvpart", &cam, &opts, blocks, &vol)),
        &["l.cdvpart", "shard layout"],
    );
    // A byte-identical copy under another name is the same file: its
    // part assembles with the others (identity from content, not path).
    let copy = d.join("copy-of-s.cdv");
    std::fs::copy(vol.path(), &copy).unwrap();
    let vol_copy = PackedVolume::open(&copy).unwrap();
    let from_copy = other("k.cdvpart", &cam, &opts, sh(2, 3), &vol_copy);
    let (a, _) = assemble_files(&from_copy).unwrap();
    let (b, _) = assemble_files(&p).unwrap();
    assert_eq!(a.rgb, b.rgb);
    // Same name, different contents: a re-prepared file is noticed.
    phantom(d, "s2");
    std::fs::create_dir(d.join("sub")).unwrap();
    let mut o = PrepOptions::new(Classification::Iso { iso: 1.0 });
    o.brick_size = 16;
    let src = RawSource::open(&d.join("s2.json")).unwrap();
    prep(&src, &d.join("sub/s.cdv"), &o, &NoProgress).unwrap();
    let vol3 = PackedVolume::open(&d.join("sub/s.cdv")).unwrap();
    refused(
        assemble_files(&other("v.cdvpart", &cam, &opts, sh(2, 3), &vol3)),
        &["v.cdvpart", "packed file"],
    );

    // Damaged part files: truncated, a flipped bit, not a part at all.
    let bytes = std::fs::read(&p[2]).unwrap();
    let bad = d.join("bad.cdvpart");
    let with_bad = vec![p[0].clone(), p[1].clone(), bad.clone()];
    std::fs::write(&bad, &bytes[..bytes.len() - 100]).unwrap();
    refused(
        assemble_files(&with_bad),
        &["bad.cdvpart", "damaged or truncated"],
    );
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x10;
    std::fs::write(&bad, &flipped).unwrap();
    refused(assemble_files(&with_bad), &["bad.cdvpart", "checksum"]);
    std::fs::write(&bad, b"P6\n1 1\n255\n\0\0\0").unwrap();
    refused(
        assemble_files(&with_bad),
        &["bad.cdvpart", "not a cdvol part file"],
    );
    std::fs::write(&bad, b"").unwrap();
    refused(
        assemble_files(&with_bad),
        &["bad.cdvpart", "not a cdvol part file"],
    );
    refused(
        assemble_files(&[p[0].clone(), d.join("nowhere.cdvpart")]),
        &["nowhere.cdvpart", "cannot read"],
    );
}

#[test]
fn render_refuses_a_shard_outside_its_count() {
    let dir = tempfile::tempdir().unwrap();
    let (vol, _) = phantom(dir.path(), "s");
    let cam = orbit(&vol, [0.0, 0.0], None, 8, 8);
    for s in [sh(3, 3), sh(0, 0)] {
        let e = render_part(&vol, &cam, &options(Mode::Mip, 4), s, &NoProgress).unwrap_err();
        let want = format!("shard {}/{}, expected K/N with 0 <= K < N", s.k, s.n);
        assert!(e.to_string().contains(&want), "{e}");
    }
    for s in ["3/3", "1", "a/2", "0/0", "-1/2", "1/2/3"] {
        assert!(Shard::parse(s).is_err(), "{s}");
    }
    assert_eq!(Shard::parse("2/5"), Ok(sh(2, 5)));
}

fn render_cli(vol: &Path, out: &Path, extra: &[&str]) -> Command {
    render_at(vol, out, 25.0, extra)
}

fn render_at(vol: &Path, out: &Path, az: f64, extra: &[&str]) -> Command {
    let mut c = cdvol();
    c.args([
        "render", "-q", "--width", "45", "--height", "30", "--tile", "8",
    ])
    .args([
        "--view",
        &format!("{az},15"),
        "--mode",
        "surface",
        "--shadows",
    ])
    .arg(vol)
    .arg("-o")
    .arg(out)
    .args(extra);
    c
}

#[test]
fn cli_shards_assemble_and_turntables() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (vol, _) = phantom(d, "s");
    let vp = vol.path().to_path_buf();

    // --shard K/N x 4, then assemble: the same PNG bytes as one render.
    ok(&mut render_cli(
        &vp,
        &d.join("whole.png"),
        &["--stats", d.join("whole.json").to_str().unwrap()],
    ));
    let parts: Vec<PathBuf> = (0..4).map(|k| d.join(format!("s{k}.cdvpart"))).collect();
    for (k, p) in parts.iter().enumerate() {
        ok(&mut render_cli(&vp, p, &["--shard", &format!("{k}/4")]));
    }
    ok(cdvol()
        .arg("assemble")
        .args(&parts)
        .arg("-o")
        .arg(d.join("joined.png"))
        .arg("--stats")
        .arg(d.join("joined.json")));
    let png = |n: &str| std::fs::read(d.join(n)).unwrap();
    assert_eq!(png("whole.png"), png("joined.png"));
    let stat = |n: &str| -> serde_json::Value { serde_json::from_slice(&png(n)).unwrap() };
    for k in ["rays", "steps", "hits", "macro_steps", "cell_steps"] {
        assert_eq!(stat("whole.json")[k], stat("joined.json")[k], "{k}");
    }

    // The same with contiguous blocks of tiles.
    let blocks: Vec<PathBuf> = (0..3).map(|k| d.join(format!("b{k}.cdvpart"))).collect();
    for (k, p) in blocks.iter().enumerate() {
        let s = format!("{k}/3");
        ok(&mut render_cli(
            &vp,
            p,
            &["--shard", &s, "--shard-layout", "blocks"],
        ));
    }
    ok(cdvol()
        .arg("assemble")
        .args(&blocks)
        .arg("-o")
        .arg(d.join("joined-blocks.png")));
    assert_eq!(png("whole.png"), png("joined-blocks.png"));

    // A missing shard: non-zero exit, the missing shard named, no image.
    let err = fails(
        cdvol()
            .arg("assemble")
            .args(&parts[..3])
            .arg("-o")
            .arg(d.join("partial.png")),
    );
    assert!(err.contains("3/4"));
    assert!(!d.join("partial.png").exists());

    // --shard with an image name is refused before rendering.
    let err = fails(&mut render_cli(&vp, &d.join("x.png"), &["--shard", "0/2"]));
    assert!(err.contains(".cdvpart"));
    let err = fails(&mut render_cli(
        &vp,
        &d.join("x.cdvpart"),
        &["--shard", "2/2"],
    ));
    assert!(err.contains("0 <= K < N"));

    // A turntable of 5 frames, whole and split over 2 shards of frames.
    ok(&mut render_cli(&vp, &d.join("tt.png"), &["--frames", "5"]));
    std::fs::create_dir(d.join("split")).unwrap();
    for k in 0..2 {
        ok(&mut render_cli(
            &vp,
            &d.join("split/tt.png"),
            &["--frames", "5", "--shard", &format!("{k}/2")],
        ));
    }
    for f in 0..5 {
        let name = format!("tt.{f:04}.png");
        assert_eq!(png(&name), png(&format!("split/{name}")), "frame {f}");
    }
    // Its frames share one frame, fitted to all five directions
    // (render/view/framing.rs); given the same --frame, frame f is the single
    // render at azimuth 25 + f * 72.
    let frame = ["--frame", "40"];
    ok(&mut render_cli(
        &vp,
        &d.join("ttf.png"),
        &["--frames", "5", frame[0], frame[1]],
    ));
    ok(&mut render_at(
        &vp,
        &d.join("f3.png"),
        25.0 + 3.0 * 72.0,
        &frame,
    ));
    assert_eq!(png("f3.png"), png("ttf.0003.png"));
    assert_ne!(png("tt.0000.png"), png("tt.0003.png"));
}
