//! Crop boxes and clipping planes (issue 55): each ray's kept interval
//! against a brute-force test of points along it, a crop of the whole
//! volume drawing the same bytes as none, every exact traversal drawing
//! the same image under a clip, bricks wholly outside never read, and the
//! bad forms refused before any work.

use cdvol::look::ModeKind;
use cdvol::render::clip::{Clip, Plane};
use cdvol::render::traverse::{Method, Ray};
use cdvol::{Look, View, Volume};
use glam::DVec3;
use proptest::prelude::*;

use crate::common::{cdvol, fails, prepared_ct_phantom};

/// How far inside every constraint of `c` the point `p` lies (mm; negative
/// outside one).
fn slack(c: &Clip, p: DVec3) -> f64 {
    let mut s = f64::INFINITY;
    if let Some(b) = c.crop {
        for k in 0..3 {
            s = s.min(p[k] - b[k][0]).min(b[k][1] - p[k]);
        }
    }
    for pl in &c.planes {
        let n = DVec3::from_array(pl.normal);
        s = s.min((n.dot(p) - pl.d) / n.length());
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Points well inside every constraint lie in the span, points well
    /// outside one do not: the span is exactly where the ray is kept.
    #[test]
    fn the_span_is_where_the_ray_is_kept(
        lo in prop::array::uniform3(-10.0..0.0f64),
        ext in prop::array::uniform3(0.5..10.0f64),
        crop_on in any::<bool>(),
        planes in prop::collection::vec(
            (prop::array::uniform3(-1.0..1.0f64), -5.0..5.0f64), 0..4),
        o in prop::array::uniform3(-20.0..20.0f64),
        d in prop::array::uniform3(-1.0..1.0f64),
        axis in 0usize..4,
    ) {
        // Some rays run along an axis, parallel to the crop's faces.
        let mut d = d;
        if axis < 3 {
            d = [0.0; 3];
            d[axis] = if o[axis] > 0.0 { -1.0 } else { 1.0 };
        }
        let dir = DVec3::from_array(d);
        prop_assume!(dir.length() > 1e-3);
        let clip = Clip {
            crop: crop_on.then(|| std::array::from_fn(|k| [lo[k], lo[k] + ext[k]])),
            planes: planes
                .iter()
                .filter(|(n, _)| DVec3::from_array(*n).length() > 1e-3)
                .map(|&(normal, d)| Plane { normal, d })
                .collect(),
        };
        let ray = Ray { origin: DVec3::from_array(o), dir };
        let span = clip.span(&ray, 0.0);
        let eps = 1e-7;
        for i in 0..=4000 {
            let t = i as f64 * 0.02;
            let s = slack(&clip, ray.origin + t * dir);
            let in_span = span.is_some_and(|sp| sp.start <= t && t <= sp.end);
            if s > eps {
                prop_assert!(in_span, "t {} kept (slack {}) but outside {:?}", t, s, span);
            } else if s < -eps {
                prop_assert!(!in_span, "t {} cut (slack {}) but inside {:?}", t, s, span);
            }
        }
        if let Some(sp) = span {
            // Its ends lie on the region's boundary (or at the ray's start).
            prop_assert!(slack(&clip, ray.origin + sp.start * dir) >= -1e-9 * (1.0 + sp.start));
            if let Some(cut) = sp.cut {
                prop_assert!(cut.dot(dir) < 0.0, "the cut faces the ray");
            }
        }
    }
}

#[test]
fn rays_along_a_face_are_kept_on_it_and_cut_off_it() {
    let plane = |d| Clip {
        crop: None,
        planes: vec![Plane {
            normal: [1.0, 0.0, 0.0],
            d,
        }],
    };
    let ray = Ray {
        origin: DVec3::new(2.0, 0.0, 0.0),
        dir: DVec3::new(0.0, 1.0, 0.0),
    };
    // The ray runs in the plane x = 2: a point on a face is kept.
    let on = plane(2.0).span(&ray, 0.0).unwrap();
    assert_eq!((on.start, on.end, on.cut), (0.0, f64::INFINITY, None));
    assert!(plane(2.0 + 1e-12).span(&ray, 0.0).is_none());
    // Entering through the plane: the cut is its outward normal.
    let across = Ray {
        origin: DVec3::new(-1.0, 0.0, 0.0),
        dir: DVec3::new(2.0, 0.0, 0.0),
    };
    let s = plane(2.0).span(&across, 0.0).unwrap();
    assert_eq!(s.start, 1.5);
    assert_eq!(s.cut, Some(DVec3::new(-1.0, 0.0, 0.0)));
}

/// The volume's box in mm.
fn bounds(vol: &Volume) -> ([f64; 3], [f64; 3]) {
    let a = &vol.header().axes;
    (
        a.each_ref().map(|x| x.coords()[0]),
        a.each_ref().map(|x| x.coords()[x.coords().len() - 1]),
    )
}

fn looks() -> Vec<(&'static str, Look)> {
    let mut uncapped = Look::surface(300.0);
    uncapped.uncapped = true;
    let mut depth = Look::surface(300.0);
    depth.ask.mode = Some(ModeKind::Depth);
    vec![
        ("surface", Look::surface(300.0)),
        ("uncapped", uncapped),
        ("depth", depth),
        ("composite", Look::preset_in("ct-skin", ModeKind::Composite)),
        ("mip", Look::preset_in("ct-mip", ModeKind::Mip)),
    ]
}

fn same(a: &cdvol::Image, b: &cdvol::Image) -> bool {
    a.frame.rgb == b.frame.rgb
        && a.frame.alpha == b.frame.alpha
        && a.frame
            .depth
            .as_ref()
            .map(|d| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
            == b.frame
                .depth
                .as_ref()
                .map(|d| d.iter().map(|x| x.to_bits()).collect())
}

#[test]
fn a_crop_of_the_whole_volume_draws_the_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    let f = prepared_ct_phantom(d.path(), "whole", &["--envelope", "ct"]);
    let vol = Volume::open(&f).unwrap();
    let (lo, hi) = bounds(&vol);
    let r = vol.renderer();
    for (name, look) in looks() {
        for (az, el) in [(0.0, 0.0), (35.0, 20.0), (90.0, 89.0)] {
            let view = View::orbit(az, el, 64, 48);
            let mut cropped = look.clone();
            cropped.clip.crop = Some(std::array::from_fn(|k| [lo[k], hi[k]]));
            let (a, b) = (
                r.render(&view, &look).unwrap(),
                r.render(&view, &cropped).unwrap(),
            );
            assert!(same(&a, &b), "{name} at {az},{el}");
            assert!(
                a.frame.alpha.iter().any(|&x| x > 0),
                "{name}: something is drawn"
            );
        }
    }
}

#[test]
fn every_exact_traversal_draws_the_same_clipped_image() {
    let d = tempfile::tempdir().unwrap();
    let f = prepared_ct_phantom(
        d.path(),
        "aniso",
        &["--envelope", "ct", "--aniso", "--brick", "8"],
    );
    let vol = Volume::open(&f).unwrap();
    let (lo, hi) = bounds(&vol);
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    // An oblique plane through the centre and a crop off the top and side.
    let clip = Clip {
        crop: Some([
            [lo[0] + 3.0, hi[0]],
            [lo[1], hi[1] - 5.0],
            [lo[2] - 1.0, c[2] + 4.0],
        ]),
        planes: vec![Plane {
            normal: [0.3, 0.8, -0.2],
            d: 0.3 * c[0] + 0.8 * c[1] - 0.2 * c[2],
        }],
    };
    let methods = [
        Method::Fvt,
        Method::Cd { min_leap: 1 },
        Method::CdAniso { min_leap: 1 },
        Method::Octree,
    ];
    for (name, look) in looks() {
        for (az, el) in [(20.0, 10.0), (200.0, -30.0)] {
            let view = View::orbit(az, el, 64, 48);
            let images: Vec<cdvol::Image> = methods
                .iter()
                .map(|&m| {
                    let mut l = look.clone();
                    l.clip = clip.clone();
                    l.method = Some(m);
                    vol.renderer().render(&view, &l).unwrap()
                })
                .collect();
            assert!(
                images[0].frame.alpha.iter().any(|&x| x > 0),
                "{name}: drawn"
            );
            for (m, im) in methods.iter().zip(&images).skip(1) {
                assert!(
                    same(&images[0], im),
                    "{name} at {az},{el}: {m:?} differs from FVT"
                );
            }
        }
    }
}

#[test]
fn bricks_wholly_outside_are_never_read() {
    let d = tempfile::tempdir().unwrap();
    let f = prepared_ct_phantom(d.path(), "b8", &["--envelope", "ct", "--brick", "8"]);
    let vol = Volume::open(&f).unwrap();
    let (lo, hi) = bounds(&vol);
    let h = vol.header();
    // A box of about a tenth of the cells, off centre.
    let crop: [[f64; 2]; 3] = std::array::from_fn(|k| {
        let w = hi[k] - lo[k];
        [lo[k] + 0.3 * w, lo[k] + 0.76 * w]
    });
    // The bricks that meet it, from the grid alone.
    let meets = (0..h.brick_count())
        .filter(|&id| {
            let b = h.brick_coords(id);
            (0..3).all(|k| {
                let (c0, c1) = h.brick_cells(k, b[k]);
                let s = h.axes[k].coords();
                s[c1 as usize] >= crop[k][0] && s[c0 as usize] <= crop[k][1]
            })
        })
        .count() as u64;
    for (name, look) in looks() {
        let view = View::orbit(30.0, 20.0, 96, 96);
        let whole = vol.renderer().render(&view, &look).unwrap().stats;
        let mut l = look.clone();
        l.clip.crop = Some(crop);
        let cut = vol.renderer().render(&view, &l).unwrap().stats;
        assert!(
            cut.bricks_distinct <= meets && meets < whole.bricks_distinct,
            "{name}: {} bricks read with the crop, {meets} meet it, {} without",
            cut.bricks_distinct,
            whole.bricks_distinct
        );
        // A plane that keeps nothing of the volume reads no brick.
        let mut none = look.clone();
        none.clip.planes = vec![Plane {
            normal: [1.0, 0.0, 0.0],
            d: hi[0] + 1.0,
        }];
        let empty = vol.renderer().render(&view, &none).unwrap();
        assert_eq!(empty.stats.bricks_distinct, 0, "{name}");
        assert!(empty.frame.alpha.iter().all(|&x| x == 0), "{name}");
    }
}

#[test]
fn bad_crops_and_planes_are_refused_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let f = prepared_ct_phantom(d.path(), "bad", &["--iso", "300"]);
    let out = d.path().join("x.png");
    for (args, says) in [
        (vec!["--crop", "5:5,0:100,0:100"], "crop x 5:5"),
        (vec!["--crop", "500:600,0:10,0:10"], "outside the volume"),
        (vec!["--crop", "0:10,0:10"], "expected X0:X1,Y0:Y1,Z0:Z1"),
        (vec!["--clip", "0,0,0,1"], "non-zero normal"),
        (vec!["--clip", "1,0,0"], "expected NX,NY,NZ,D"),
        (vec!["--clip-half", "left"], "does not record which way"),
        (
            vec![
                "--clip", "1,0,0,0", "--clip", "1,0,0,0", "--clip", "1,0,0,0", "--clip", "1,0,0,0",
                "--clip", "1,0,0,0", "--clip", "1,0,0,0", "--clip", "1,0,0,0",
            ],
            "at most 6",
        ),
    ] {
        let e = fails(
            cdvol()
                .arg("render")
                .arg(&f)
                .arg("-o")
                .arg(&out)
                .args(&args),
        );
        assert!(e.contains(says), "{args:?}: {e}");
        assert!(!out.exists(), "{args:?} wrote an image");
    }
}

#[test]
fn a_named_half_is_the_plane_through_the_centre() {
    let d = tempfile::tempdir().unwrap();
    prepared_ct_phantom(d.path(), "unused", &["--iso", "300"]);
    // The phantom's sidecar with an orientation: x points to the
    // patient's left (LPS).
    let side = d.path().join("ct.json");
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&side).unwrap()).unwrap();
    j["orientation"] = "LPS".into();
    let oriented = d.path().join("oriented.json");
    std::fs::write(&oriented, j.to_string()).unwrap();
    let f = d.path().join("oriented.cdv");
    crate::common::ok(
        cdvol()
            .args(["-q", "prep"])
            .arg(&oriented)
            .args(["--iso", "300", "-o"])
            .arg(&f),
    );
    let vol = Volume::open(&f).unwrap();
    let (lo, hi) = bounds(&vol);
    let cx = 0.5 * (lo[0] + hi[0]);
    let png = |name: &str, args: &[String]| {
        let out = d.path().join(name);
        crate::common::ok(
            cdvol()
                .args(["-q", "render"])
                .arg(&f)
                .arg("-o")
                .arg(&out)
                .args(["--view", "anterior", "--width", "64", "--height", "64"])
                .args(args),
        );
        std::fs::read(out).unwrap()
    };
    let named = png("named.png", &["--clip-half".into(), "left".into()]);
    let plane = png("plane.png", &["--clip".into(), format!("1,0,0,{cx}")]);
    let whole = png("whole.png", &[]);
    assert_eq!(
        named, plane,
        "--clip-half left is the plane x >= the centre"
    );
    assert_ne!(named, whole, "the half cuts something");
}
