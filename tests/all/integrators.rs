//! The composite's integrators against the f64 reference (issue 54):
//! `Integrate::Reference` substeps each cell at 1/64 of its width and of
//! the transfer function's narrowest gap, with the function evaluated
//! exactly and no early stop; it knows nothing of segments, chords or
//! the integral table. On a CT phantom (rectilinear z), a sharp peak of
//! opacity (the case fixed steps draw as wood grain) and a shaded ramp:
//! - the reference converges: twice its substeps move no pixel by more
//!   than 0.05 grey levels at the 99th percentile;
//! - without the early stop (which the reference does not take),
//!   segments converge to it as the tolerance falls: p99 within 1.5 grey
//!   levels at the default tolerance, 0.5 at 0.002; with it, no pixel is
//!   further off than the light the stop leaves behind (2.55 levels) and
//!   the chords' error; and segments are closer than steps of 0.5 mm on
//!   the sharp peak;
//! - every traversal draws the same segment image, byte for byte (also
//!   tests/all/composite.rs, with every look and early stop).

use crate::common;
use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::PackedVolume;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::traverse::{Method, TGrid};
use cdvol::render::view::camera::Camera;
use cdvol::render::{render, CompositeLook, Integrate, Mode, RenderOptions, EARLY_STOP};

/// The phantom, prepared for transfer functions opaque above -300 HU.
fn phantom(dir: &std::path::Path) -> PackedVolume {
    let side = dir.join("head.json");
    cdvol::tools::phantom::ct(
        &side,
        &cdvol::tools::phantom::CtOptions {
            dims: [48, 44, 36],
            seed: 3,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let src = cdvol::input::open(&side).unwrap();
    let mut o = PrepOptions::new(Classification::Iso { iso: -300.0 });
    o.brick_size = 8;
    let out = dir.join("ct.cdv");
    prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
    PackedVolume::open(&out).unwrap()
}

fn point(value: f64, opacity: f64, color: [f64; 3]) -> TfPoint {
    TfPoint {
        value,
        opacity,
        color,
    }
}

/// Opaque white only within 10 HU of 300 HU (unshaded).
fn peak() -> (TransferFunction, CompositeLook) {
    let w = [1.0, 0.95, 0.85];
    (
        TransferFunction {
            points: vec![
                point(290.0, 0.0, w),
                point(300.0, 0.9, w),
                point(310.0, 0.0, w),
            ],
        },
        CompositeLook::default(),
    )
}

/// Skin to bone, shaded: a ramp of opacity and colour.
fn ramp() -> (TransferFunction, CompositeLook) {
    (
        TransferFunction {
            points: vec![
                point(-250.0, 0.0, [0.8, 0.5, 0.4]),
                point(0.0, 0.3, [0.9, 0.6, 0.5]),
                point(400.0, 0.8, [1.0, 1.0, 0.9]),
            ],
        },
        CompositeLook {
            shade: true,
            gradient_opacity: vec![],
        },
    )
}

/// The unrounded image (premultiplied RGB and coverage, 4 a pixel).
fn image(
    vol: &PackedVolume,
    cam: &Camera,
    (tf, look): &(TransferFunction, CompositeLook),
    integrate: Integrate,
    method: Method,
    early_stop: f64,
) -> Vec<f32> {
    let o = RenderOptions {
        integrate,
        early_stop,
        look: look.clone(),
        unrounded: true,
        ..common::test_opts(
            Mode::Composite {
                tf: tf.clone(),
                step_mm: 0.5,
            },
            method,
        )
    };
    render(vol, cam, &o, &NoProgress).unwrap().0.linear
}

/// The 99th percentile and maximum of |a - b| in grey levels (the
/// largest channel) over pixels either covers.
fn error(a: &[f32], b: &[f32]) -> (f64, f64) {
    let mut d: Vec<f64> = a
        .chunks_exact(4)
        .zip(b.chunks_exact(4))
        .filter(|(p, q)| p[3].max(q[3]) > 0.5 / 255.0)
        .map(|(p, q)| {
            (0..3)
                .map(|k| (p[k] - q[k]).abs() as f64 * 255.0)
                .fold(0.0, f64::max)
        })
        .collect();
    assert!(d.len() > 100, "the images cover too little: {}", d.len());
    d.sort_by(f64::total_cmp);
    (d[d.len() * 99 / 100], d[d.len() - 1])
}

#[test]
fn segments_converge_to_the_reference_and_beat_steps_on_a_sharp_peak() {
    let dir = tempfile::tempdir().unwrap();
    let vol = phantom(dir.path());
    let g = TGrid::<f64>::new(&vol.header().axes);
    let cd = Method::Cd { min_leap: 1 };
    for (name, tf) in [("peak", peak()), ("ramp", ramp())] {
        for (az, el) in [(30.0, 20.0), (200.0, -35.0)] {
            let cam = Camera::orbit(g.bounds(), az, el, None, None, 40, 40).unwrap();
            let reference = image(
                &vol,
                &cam,
                &tf,
                Integrate::Reference { substeps: 64 },
                cd,
                1.0,
            );
            let finer = image(
                &vol,
                &cam,
                &tf,
                Integrate::Reference { substeps: 128 },
                cd,
                1.0,
            );
            let (p99, _) = error(&finer, &reference);
            assert!(
                p99 <= 0.05,
                "{name} {az}: the reference moves {p99} at twice the substeps"
            );
            // Without the early stop (which the reference does not
            // take), segments converge as the tolerance falls.
            let mut last = f64::INFINITY;
            for tol in [0.5, 0.05, Integrate::SEGMENT_TOL, 0.002] {
                let seg = image(&vol, &cam, &tf, Integrate::Segment { tol }, cd, 1.0);
                let (p99, max) = error(&seg, &reference);
                eprintln!("{name} {az},{el}: tol {tol}: p99 {p99:.3}, max {max:.2}");
                assert!(
                    p99 <= last + 0.05,
                    "{name} {az}: tol {tol} p99 {p99} after {last}"
                );
                if tol == Integrate::SEGMENT_TOL {
                    assert!(p99 <= 1.5, "{name} {az}: segment p99 {p99} at the default");
                }
                last = p99;
            }
            assert!(last <= 0.5, "{name} {az}: segment p99 {last} at tol 0.002");
            // The early stop leaves up to 1 - 0.99 of the light behind:
            // 2.55 levels at most.
            let seg = image(&vol, &cam, &tf, Integrate::default(), cd, EARLY_STOP);
            let (p99, max) = error(&seg, &reference);
            assert!(
                max <= 255.0 * (1.0 - EARLY_STOP) + 2.0 * last + 0.1,
                "{name} {az}: max {max}, p99 {p99} with the early stop"
            );
            if name == "peak" {
                let step = image(&vol, &cam, &tf, Integrate::Step, cd, EARLY_STOP);
                let (p99, _) = error(&step, &reference);
                assert!(
                    p99 > 5.0 * last.max(0.2),
                    "steps p99 {p99} against segments' {last}"
                );
            }
        }
    }
}

#[test]
fn segment_images_are_the_same_for_every_traversal() {
    let dir = tempfile::tempdir().unwrap();
    let vol = phantom(dir.path());
    let g = TGrid::<f64>::new(&vol.header().axes);
    let cam = Camera::orbit(g.bounds(), 120.0, 40.0, Some(35.0), None, 36, 30).unwrap();
    for tf in [peak(), ramp()] {
        let seg = Integrate::Segment { tol: 0.01 };
        let fvt = image(&vol, &cam, &tf, seg, Method::Fvt, EARLY_STOP);
        assert!(fvt.chunks_exact(4).any(|p| p[3] > 0.1));
        for m in [
            Method::Cd { min_leap: 1 },
            Method::Cd { min_leap: 3 },
            Method::Octree,
        ] {
            let other = image(&vol, &cam, &tf, seg, m, EARLY_STOP);
            assert!(
                fvt.iter()
                    .zip(&other)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{m:?} differs from FVT"
            );
        }
    }
}
