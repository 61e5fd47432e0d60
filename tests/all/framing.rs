//! The default frame (render/view/framing.rs, issue 51 item 6): a view without
//! `--frame` fits the box of the scene's 1-cells, centred, so the object
//! fills 80-95 % of the image along the side that binds it (the frame is
//! the box's projection plus 5 % a side: 91 % for a view along an axis).
//! On the real head CT the default view used to show the head across
//! 58 % of the image (the volume's bounding sphere), now 90.6 %; a small
//! off-centre ball 10.5 %, now 85 %.
//!
//! Fill is measured on the images `cdvol render` writes: the extent of the
//! non-black pixels along each side, as a share of that side.

use std::path::Path;

use cdvol::format::reader::{CellClass, PackedVolume, Sample};
use cdvol::render::job::{Aim, View};
use cdvol::render::traverse::{Method, TGrid};
use cdvol::render::view::camera::{orbit_dirs, Camera, Projection};
use cdvol::render::view::framing::{object_box, Framing, MmBox};
use cdvol::render::{Mode, RenderOptions};

use crate::common::*;

/// Share of the image's width and height that the non-black pixels of
/// `png` span, and the centre of their extent in pixels.
fn fill(png: &Path) -> ([f64; 2], [f64; 2]) {
    let img = image::open(png)
        .unwrap_or_else(|e| panic!("{}: {e}", png.display()))
        .to_rgb8();
    let (mut lo, mut hi) = ([u32::MAX; 2], [0u32; 2]);
    for (x, y, p) in img.enumerate_pixels() {
        if p.0 != [0, 0, 0] {
            lo = [lo[0].min(x), lo[1].min(y)];
            hi = [hi[0].max(x), hi[1].max(y)];
        }
    }
    assert!(lo[0] <= hi[0], "{}: an empty image", png.display());
    let size = [img.width() as f64, img.height() as f64];
    (
        std::array::from_fn(|k| (hi[k] - lo[k] + 1) as f64 / size[k]),
        std::array::from_fn(|k| 0.5 * (lo[k] + hi[k] + 1) as f64),
    )
}

/// `cdvol render FILE -o OUT --width W --height H` plus `args`; the fill
/// ([`fill`]) of the image.
fn render(file: &Path, out: &Path, w: u32, h: u32, args: &[&str]) -> ([f64; 2], [f64; 2]) {
    ok(cdvol()
        .arg("render")
        .arg(file)
        .arg("-o")
        .arg(out)
        .args(["--width", &w.to_string(), "--height", &h.to_string(), "-q"])
        .args(args));
    fill(out)
}

fn assert_fills(what: &str, share: f64) {
    assert!(
        (0.80..=0.95).contains(&share),
        "{what}: the object spans {:.1} % of the image, expected 80-95 %",
        share * 100.0
    );
}

/// A 96 x 96 x 64 stack (1 x 1 x 2 mm) of 0 with a ball of 200 of radius
/// 10 mm at (62, 30, 90) mm: off the volume's centre (47.5, 47.5, 63) and
/// about a ninth of its diagonal.
fn small_ball(dir: &Path) -> std::path::PathBuf {
    let dims = [96, 96, 64];
    let mut v = vec![0.0; dims[0] * dims[1] * dims[2]];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let d = [x as f64 - 62.0, y as f64 - 30.0, 2.0 * z as f64 - 90.0];
                if d.iter().map(|d| d * d).sum::<f64>() <= 100.0 {
                    v[(z * dims[1] + y) * dims[0] + x] = 200.0;
                }
            }
        }
    }
    write_stack(dir, "ball", dims, "u8", &v, ["1", "1", "2"], "")
}

/// The box of the 1-cells of `vol` (with a vertex at or above `iso` when
/// given, in f32 as render/brick/envelope.rs compares), by reading every brick: the
/// oracle of [`object_box`].
fn brute_box(vol: &PackedVolume, iso: Option<f64>) -> Option<MmBox> {
    let h = vol.header();
    let (mut lo, mut hi) = ([u64::MAX; 3], [0u64; 3]);
    for id in 0..h.brick_count() {
        let b = vol.read_brick(id).unwrap();
        let [sx, sy, sz] = b.samples;
        for l in (0..sz - 1)
            .flat_map(|z| (0..sy - 1).flat_map(move |y| (0..sx - 1).map(move |x| [x, y, z])))
        {
            if vol.cell_class(&b, l) != CellClass::Object {
                continue;
            }
            if let Some(iso) = iso {
                let top = b.vertices(l).unwrap().iter().any(|s| match s {
                    Sample::Value(v) => h.rescale.apply(*v) as f32 >= iso as f32,
                    Sample::Code(_) => false,
                });
                if !top {
                    continue;
                }
            }
            for k in 0..3 {
                let g = b.first[k] + l[k] as u64;
                lo[k] = lo[k].min(g);
                hi[k] = hi[k].max(g);
            }
        }
    }
    (lo[0] != u64::MAX).then(|| {
        let c = |k: usize, i: u64| h.axes[k].coords()[i as usize];
        (
            std::array::from_fn(|k| c(k, lo[k])),
            std::array::from_fn(|k| c(k, hi[k] + 1)),
        )
    })
}

fn surface(iso: Option<f64>) -> RenderOptions {
    RenderOptions {
        iso,
        ..RenderOptions::new(
            Mode::Surface {
                hit: cdvol::render::sample::hit::HitMethod::Int,
                shadows: false,
            },
            Method::Cd { min_leap: 1 },
        )
    }
}

#[test]
fn real_ct_head_fills_the_default_view() {
    let dir = tempfile::tempdir().unwrap();
    let cdv = dir.path().join("ct.cdv");
    ok(cdvol()
        .args(["prep", "-q"])
        .arg(real_ct())
        .arg("-o")
        .arg(&cdv)
        .args(["--iso", "-300"]));
    // The default view (0,0), square: the head's width binds (90.6 %; the
    // volume's sphere framed it at 58 %).
    let (share, centre) = render(&cdv, &dir.path().join("front.png"), 256, 256, &[]);
    assert_fills("CT, default view", share[0].max(share[1]));
    assert!(
        (centre[0] - 128.0).abs() <= 3.0,
        "centred across: {centre:?}"
    );
    // A wide image: the shorter side (the height) binds.
    let (share, _) = render(&cdv, &dir.path().join("wide.png"), 400, 150, &[]);
    assert_fills("CT, 400 x 150, height", share[1]);
    assert!(share[0] < 0.95, "{share:?}");
    // The reference view (120,10): the outline of whole bricks (30 mm
    // here) is framed, the head within it (71.5 %; 59.4 % before).
    let (share, _) = render(
        &cdv,
        &dir.path().join("oblique.png"),
        256,
        256,
        &["--view", "120,10"],
    );
    let s = share[0].max(share[1]);
    assert!((0.68..=0.95).contains(&s), "CT at 120,10: {share:?}");
    // A narrower scene (bone, render --iso) frames its own 1-cells, as
    // the index and the bricks at the box's faces give them exactly.
    let vol = PackedVolume::open(&cdv).unwrap();
    for iso in [None, Some(300.0), Some(1500.0)] {
        assert_eq!(
            object_box(&vol, &surface(iso)),
            brute_box(&vol, iso),
            "iso {iso:?}"
        );
    }
}

#[test]
fn small_off_centre_object_fills_the_default_view() {
    let dir = tempfile::tempdir().unwrap();
    let cdv = dir.path().join("ball.cdv");
    ok(cdvol()
        .args(["prep", "-q"])
        .arg(small_ball(dir.path()))
        .arg("-o")
        .arg(&cdv)
        .args(["--iso", "100", "--brick", "16"]));
    let vol = PackedVolume::open(&cdv).unwrap();
    let b = object_box(&vol, &surface(None));
    assert_eq!(b, brute_box(&vol, None));
    let (lo, hi) = b.unwrap();
    assert!(hi[0] - lo[0] <= 22.0 && hi[2] - lo[2] <= 24.0, "{b:?}");
    // The default view, and one along z on a tall image (the shorter
    // side, the width, binds): the box's projection is the ball's extent,
    // one cell more a side. Obliquely the box's corners stand out beyond
    // the ball: framed, it fills less, but still centred.
    for (view, w, h, fills) in [
        ("0,0", 128, 128, 0.80),
        ("90,-90", 96, 128, 0.80),
        ("35,25", 128, 96, 0.50),
    ] {
        let out = dir.path().join(format!("ball-{view}.png"));
        let (share, centre) = render(&cdv, &out, w, h, &["--view", view]);
        let s = share[0].max(share[1]);
        assert!(
            (fills..=0.95).contains(&s),
            "ball at {view}, {w} x {h}: the ball spans {share:?} of the image, expected \
             {fills} to 0.95 along one side"
        );
        let mid = [w as f64 / 2.0, h as f64 / 2.0];
        assert!(
            (0..2).all(|k| (centre[k] - mid[k]).abs() <= 3.0),
            "ball at {view}: centred at {centre:?}, image centre {mid:?}"
        );
    }
    // Perspective: the eye stands back until the box's corners fit; the
    // near ones bind, 44 mm from a 22 mm box, so the ball spans 62 %
    // (the volume's sphere: 11 %).
    let (share, _) = render(
        &cdv,
        &dir.path().join("persp.png"),
        128,
        128,
        &["--persp", "--fov", "40"],
    );
    let s = share[0].max(share[1]);
    assert!((0.55..=0.95).contains(&s), "ball in perspective: {share:?}");
    // --frame sets the frame (20 mm of ball in 80 mm: a quarter) about the
    // ball's centre.
    let (share, centre) = render(
        &cdv,
        &dir.path().join("frame.png"),
        128,
        128,
        &["--frame", "80"],
    );
    assert!((0.20..=0.27).contains(&share[0]), "--frame 80: {share:?}");
    assert!((centre[0] - 64.0).abs() <= 4.0, "--frame 80: {centre:?}");
    // An exact eye frames the volume's diagonal, as before.
    let (share, _) = render(
        &cdv,
        &dir.path().join("eye.png"),
        128,
        128,
        &[
            "--eye",
            "44,-200,70",
            "--target",
            "44,18,70",
            "--up",
            "0,0,1",
        ],
    );
    assert!(share[0] < 0.2, "--eye: {share:?}");
}

#[test]
fn a_turntable_shares_one_frame_that_fits_every_frame() {
    // A rod 40 x 8 x 8 mm along x, off-centre: 4 frames a quarter turn
    // apart see it broadside, end-on, broadside, end-on.
    let dir = tempfile::tempdir().unwrap();
    let dims = [64, 64, 32];
    let mut v = vec![0.0; dims[0] * dims[1] * dims[2]];
    for z in 20..28 {
        for y in 8..16 {
            for x in 10..50 {
                v[(z * dims[1] + y) * dims[0] + x] = 200.0;
            }
        }
    }
    let side = write_stack(dir.path(), "rod", dims, "u8", &v, ["1", "1", "1"], "");
    let cdv = dir.path().join("rod.cdv");
    ok(cdvol()
        .args(["prep", "-q"])
        .arg(&side)
        .arg("-o")
        .arg(&cdv)
        .args(["--iso", "100", "--brick", "16"]));
    let out = dir.path().join("turn.png");
    ok(cdvol().arg("render").arg(&cdv).arg("-o").arg(&out).args([
        "--width", "96", "--height", "96", "--frames", "4", "--orbit", "360", "-q",
    ]));
    let shares: Vec<[f64; 2]> = (0..4)
        .map(|f| fill(&dir.path().join(format!("turn.{f:04}.png"))).0)
        .collect();
    for f in [0, 2] {
        assert_fills(&format!("rod broadside, frame {f}"), shares[f][0]);
    }
    // End-on, the rod's 8 mm show in the frame fitted to its 40.
    for f in [1, 3] {
        assert!(shares[f][0] < 0.3, "rod end-on, frame {f}: {:?}", shares[f]);
    }
    // The same frame through the library, and a single image end-on fits
    // the rod's own end.
    let vol = PackedVolume::open(&cdv).unwrap();
    let spec = View {
        aim: Aim::Orbit {
            az_deg: 0.0,
            el_deg: 0.0,
        },
        persp_fov_deg: None,
        frame_mm: None,
        width: 96,
        height: 96,
    };
    let frame = |c: Camera| match c.projection {
        Projection::Ortho { frame_mm } => frame_mm,
        Projection::Persp { .. } => f64::NAN,
    };
    let turn = spec.framing(&vol, &surface(None), 4, 360.0, None).unwrap();
    let frames: Vec<f64> = (0..4)
        .map(|f| frame(spec.place(&turn, 90.0 * f as f64, None).unwrap()))
        .collect();
    assert!(frames.iter().all(|&f| f == frames[0]), "{frames:?}");
    let end_on = View {
        aim: Aim::Orbit {
            az_deg: 90.0,
            el_deg: 0.0,
        },
        ..spec
    };
    let one = end_on.framing(&vol, &surface(None), 1, 0.0, None).unwrap();
    let end_on = frame(end_on.place(&one, 0.0, None).unwrap());
    assert!(end_on < 0.5 * frames[0], "{end_on} vs {frames:?}");
}

#[test]
fn a_scene_without_1_cells_frames_the_volume_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let side = small_ball(dir.path());
    let cdv = dir.path().join("empty.cdv");
    ok(cdvol()
        .args(["prep", "-q"])
        .arg(&side)
        .arg("-o")
        .arg(&cdv)
        .args(["--iso", "250", "--allow-empty"]));
    let vol = PackedVolume::open(&cdv).unwrap();
    assert_eq!(object_box(&vol, &surface(None)), None);
    let framing = Framing::of(&vol, &surface(None));
    let bounds = TGrid::<f64>::new(&vol.header().axes).bounds();
    assert_eq!(framing, Framing::volume(bounds));
    let spec = View {
        aim: Aim::Orbit {
            az_deg: 30.0,
            el_deg: 20.0,
        },
        persp_fov_deg: None,
        frame_mm: None,
        width: 40,
        height: 30,
    };
    let (back, up) = orbit_dirs(30.0, 20.0);
    assert_eq!(
        spec.place(&framing, 0.0, None).unwrap(),
        Camera::orbit_dir(bounds, back, up, None, None, 40, 30).unwrap()
    );
}
