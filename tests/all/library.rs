//! The library's front door (issue 52, item 5): `Volume::open`, a
//! `Renderer` that owns its cache, `render(&View, &Look) -> Image`. Its
//! images are those `cdvol render` writes for the same view and look,
//! byte for byte; one renderer serves threads at once and keeps its cache
//! across frames; its errors name what was refused.

use std::path::Path;

use cdvol::look::ModeKind;
use cdvol::{Error, Look, Renderer, View, Volume};

use crate::common::{cdvol, ok, prepared_ct_phantom};

/// The PNG `cdvol render FILE ARGS` writes.
fn cli_png(dir: &Path, file: &Path, name: &str, args: &[&str]) -> Vec<u8> {
    let out = dir.join(format!("cli-{name}.png"));
    ok(cdvol()
        .args(["-q", "render"])
        .arg(file)
        .arg("-o")
        .arg(&out)
        .args(args));
    std::fs::read(out).unwrap()
}

/// The PNG the library writes for `view` and `look`, through `r`.
fn lib_png(dir: &Path, r: &Renderer, name: &str, view: &View, look: &Look) -> Vec<u8> {
    let out = dir.join(format!("lib-{name}.png"));
    r.render(view, look).unwrap().save(&out).unwrap();
    std::fs::read(out).unwrap()
}

#[test]
fn the_library_draws_what_the_cli_draws() {
    let d = tempfile::tempdir().unwrap();
    let looked = prepared_ct_phantom(d.path(), "looked", &["--preset", "ct-bone"]);
    let plain = prepared_ct_phantom(d.path(), "plain", &["--envelope", "auto"]);
    let size = ["--width", "96", "--height", "80"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        size.iter().chain(extra).copied().collect()
    };
    let view = |az, el| View::orbit(az, el, 96, 80);
    let mip = Look::preset_in("ct-bone", ModeKind::Mip);
    let mut shadows = Look::surface(400.0);
    shadows.ask.shadows = true;
    let cases: Vec<(&str, &Path, Vec<&str>, View, Look)> = vec![
        // The file's look: a shaded composite of ct-bone.
        ("look", &looked, with(&[]), view(0.0, 0.0), Look::default()),
        (
            "side",
            &looked,
            with(&["--view", "90,20"]),
            view(90.0, 20.0),
            Look::default(),
        ),
        // The plain file: a surface at its own iso value.
        (
            "surface",
            &plain,
            with(&[]),
            view(0.0, 0.0),
            Look::default(),
        ),
        (
            "iso",
            &plain,
            with(&["--iso", "400", "--shadows", "--view", "30,10"]),
            view(30.0, 10.0),
            shadows,
        ),
        (
            "mip",
            &plain,
            with(&["--preset", "ct-bone", "--mode", "mip"]),
            view(0.0, 0.0),
            mip,
        ),
        (
            "skin",
            &plain,
            with(&["--preset", "ct-skin"]),
            view(0.0, 0.0),
            Look::preset("ct-skin"),
        ),
        (
            "composite",
            &plain,
            with(&[
                "--preset",
                "ct-skin",
                "--mode",
                "composite",
                "--view",
                "30,10",
            ]),
            view(30.0, 10.0),
            Look::preset_in("ct-skin", ModeKind::Composite),
        ),
    ];
    let vols = [
        Volume::open(&looked).unwrap(),
        Volume::open(&plain).unwrap(),
    ];
    let renderers = vols.each_ref().map(|v| v.renderer());
    for (name, file, args, v, look) in &cases {
        let r = &renderers[(*file == plain.as_path()) as usize];
        let want = cli_png(d.path(), file, name, args);
        let got = lib_png(d.path(), r, name, v, look);
        assert!(
            got == want,
            "{name}: the library's PNG differs from cdvol render's"
        );
    }
}

#[test]
fn one_renderer_serves_threads_and_keeps_its_cache() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Renderer>();
    send_sync::<Volume>();
    let d = tempfile::tempdir().unwrap();
    let file = prepared_ct_phantom(d.path(), "plain", &["--envelope", "auto"]);
    let r = Volume::open(&file).unwrap().renderer();
    let views: Vec<View> = (0..6)
        .map(|k| View::orbit(60.0 * k as f64, 15.0, 64, 64))
        .collect();
    let alone: Vec<Vec<u8>> = views
        .iter()
        .map(|v| r.render(v, &Look::default()).unwrap().frame.rgb)
        .collect();
    // The same views again, one thread each, all at once through the one
    // renderer: the same pixels, and (warm) no brick read again.
    let together: Vec<(Vec<u8>, u64)> = std::thread::scope(|s| {
        let hs: Vec<_> = views
            .iter()
            .map(|v| {
                let r = &r;
                s.spawn(move || {
                    let i = r.render(v, &Look::default()).unwrap();
                    (i.frame.rgb, i.stats.cache_misses)
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (k, ((rgb, misses), want)) in together.iter().zip(&alone).enumerate() {
        assert!(rgb == want, "view {k}: a threaded render differs");
        assert_eq!(*misses, 0, "view {k}: the warm cache read bricks again");
    }
}

/// The camera a render reports (`Stats::camera`, `render --stats`) draws
/// the same image again as an exact camera, orthographic and perspective,
/// from oblique orbits whose placement depends on the object's box.
#[test]
fn the_reported_camera_draws_the_same_image() {
    let d = tempfile::tempdir().unwrap();
    let file = prepared_ct_phantom(d.path(), "plain", &["--envelope", "auto"]);
    let r = Volume::open(&file).unwrap().renderer();
    for (az, el, persp) in [(35.0, 15.0, None), (200.0, -40.0, Some(30.0))] {
        let mut view = View::orbit(az, el, 72, 64);
        view.persp_fov_deg = persp;
        let first = r.render(&view, &Look::default()).unwrap();
        let cam = first.stats.camera.clone().expect("a placed camera");
        assert_eq!(
            (cam.frame_mm.is_some(), cam.fov_deg),
            (persp.is_none(), persp)
        );
        let exact = View {
            aim: cdvol::Aim::LookAt {
                eye: cam.eye,
                target: cam.target,
                up: cam.up,
            },
            persp_fov_deg: cam.fov_deg,
            frame_mm: cam.frame_mm,
            width: 72,
            height: 64,
        };
        let again = r.render(&exact, &Look::default()).unwrap();
        assert!(
            first.frame.rgb.iter().any(|&x| x > 0),
            "{az},{el}: an empty image"
        );
        assert!(
            again.frame.rgb == first.frame.rgb,
            "{az},{el}: the reported camera draws another image"
        );
        let back = again.stats.camera.expect("a placed camera");
        let near = |a: [f64; 3], b: [f64; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-9);
        assert!(
            near(back.eye, cam.eye) && near(back.target, cam.target) && near(back.up, cam.up),
            "{az},{el}: {back:?} reported against {cam:?}"
        );
    }
}

#[test]
fn library_errors_say_what_was_refused() {
    let d = tempfile::tempdir().unwrap();
    let missing = d.path().join("nothing.cdv");
    let e = Volume::open(&missing)
        .err()
        .expect("a missing file is refused");
    assert!(matches!(e, Error::Format(_)), "{e:?}");
    assert!(e.to_string().contains("nothing.cdv"), "{e}");

    let file = prepared_ct_phantom(d.path(), "plain", &["--envelope", "auto"]);
    let r = Volume::open(&file).unwrap().renderer();
    // An MR preset on a CT file.
    let e = r
        .render(&View::orbit(0.0, 0.0, 32, 32), &Look::preset("mr-brain"))
        .expect_err("an MR preset on CT is refused");
    assert!(matches!(e, Error::Look(_)), "{e:?}");
    assert!(e.to_string().contains("mr-brain"), "{e}");
    // An empty image.
    let e = r
        .render(&View::orbit(0.0, 0.0, 0, 32), &Look::default())
        .expect_err("a 0-pixel image is refused");
    assert!(matches!(e, Error::View(_)), "{e:?}");
}
