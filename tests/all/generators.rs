//! Every ray generator of the paper's section 5 renders the real CT and
//! the sphere phantom through the shared sampling and shading code: the
//! exact ones give images and depths bit-identical to FVT (also with
//! shadows, which start rays inside the volume), the others agree with it
//! on nearly every pixel, and the generators that need a regular grid
//! refuse a rectilinear one by name.

use crate::common::{self, orbit, packed_with};

use cdvol::format::reader::PackedVolume;
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::template::render_template;
use cdvol::render::traverse::{DistKind, Method};
use cdvol::render::view::camera::Camera;
use cdvol::render::{render, Frame, Mode, RenderError, RenderOptions};
use cdvol::tools::phantom;

fn opts(mode: Mode, method: Method) -> RenderOptions {
    common::test_opts(mode, method)
}

fn depth() -> Mode {
    Mode::Depth {
        hit: HitMethod::Newton,
    }
}

fn dda(kind: DistKind, switch_fvt: bool) -> Method {
    Method::Dda { kind, switch_fvt }
}

const EXACT: [Method; 6] = [
    Method::Cd { min_leap: 1 },
    Method::Cd { min_leap: 3 },
    Method::CdAniso { min_leap: 1 },
    Method::Octree,
    Method::Dda {
        kind: DistKind::Chessboard,
        switch_fvt: true,
    },
    Method::Fvt,
];

/// Share of pixels whose hit/miss differs from FVT's.
fn hit_mismatch(a: &Frame, b: &Frame) -> f64 {
    let (da, db) = (a.depth.as_ref().unwrap(), b.depth.as_ref().unwrap());
    let n = da
        .iter()
        .zip(db)
        .filter(|(x, y)| x.is_nan() != y.is_nan())
        .count();
    n as f64 / da.len() as f64
}

fn check_all(vol: &PackedVolume, cams: &[Camera], what: &str) {
    for c in cams {
        let (want, _) = render(vol, c, &opts(depth(), Method::Fvt), &NoProgress).unwrap();
        let bits = |f: &Frame| -> Vec<u32> {
            f.depth
                .as_ref()
                .unwrap()
                .iter()
                .map(|x| x.to_bits())
                .collect()
        };
        assert!(
            want.depth.as_ref().unwrap().iter().any(|d| !d.is_nan()),
            "{what}: fvt hits"
        );
        for m in EXACT {
            let (got, _) = render(vol, c, &opts(depth(), m), &NoProgress).unwrap();
            assert_eq!(bits(&got), bits(&want), "{what}: {m:?} depth");
            assert_eq!(got.rgb, want.rgb, "{what}: {m:?} image");
        }
        for m in [
            dda(DistKind::Cityblock, true),
            dda(DistKind::Chamfer, true),
            dda(DistKind::Cityblock, false),
            dda(DistKind::Chessboard, false),
            dda(DistKind::Chamfer, false),
        ] {
            let (got, _) = render(vol, c, &opts(depth(), m), &NoProgress).unwrap();
            let miss = hit_mismatch(&got, &want);
            assert!(
                miss <= 0.01,
                "{what}: {m:?} differs from fvt on {miss} of the pixels"
            );
        }
        // Template-based CD: 26-connected rays from a base plane, warped.
        let (got, _) = render_template(
            vol,
            c,
            &opts(depth(), Method::Cd { min_leap: 1 }),
            &NoProgress,
        )
        .unwrap();
        let miss = hit_mismatch(&got, &want);
        assert!(
            miss <= 0.02,
            "{what}: template differs from fvt on {miss} of the pixels"
        );
        // Shaded surface with shadows: secondary rays start inside.
        let shaded = Mode::Surface {
            hit: HitMethod::Int,
            shadows: true,
        };
        let (want, _) = render(vol, c, &opts(shaded.clone(), Method::Fvt), &NoProgress).unwrap();
        for m in EXACT {
            let (got, _) = render(vol, c, &opts(shaded.clone(), m), &NoProgress).unwrap();
            assert_eq!(got.rgb, want.rgb, "{what}: {m:?} shadows");
        }
    }
}

fn views(vol: &PackedVolume, size: u32) -> Vec<Camera> {
    [[0.0, 0.0], [35.0, 15.0], [200.0, -50.0]]
        .into_iter()
        .map(|v| orbit(vol, v, None, size, size))
        .collect()
}

#[test]
fn every_generator_renders_the_real_ct() {
    let dir = tempfile::tempdir().unwrap();
    let vol = packed_with(&common::real_ct(), &dir.path().join("ct.cdv"), 300.0, |o| {
        o.aniso = true;
        o.dda = true;
    });
    check_all(&vol, &views(&vol, 96), "real CT");
}

#[test]
fn every_generator_renders_the_sphere_phantom() {
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("s.json");
    let so = phantom::SpheresOptions {
        size: 64,
        per_axis: 3,
        seed: 7,
        // A regular grid (the DDA and templates need one), anisotropic.
        spacing: phantom::parse_spacing3("0.8,1,1.5").unwrap(),
    };
    let info = phantom::spheres(&side, &so, &NoProgress).unwrap();
    let vol = packed_with(&side, &dir.path().join("s.cdv"), info.iso, |o| {
        o.aniso = true;
        o.dda = true;
    });
    check_all(&vol, &views(&vol, 80), "spheres");
}

#[test]
fn regular_grid_generators_refuse_rectilinear_grids() {
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("r.json");
    let so = phantom::SpheresOptions {
        size: 32,
        per_axis: 2,
        seed: 1,
        spacing: phantom::parse_spacing3("1,1,0.5:2").unwrap(),
    };
    let info = phantom::spheres(&side, &so, &NoProgress).unwrap();
    let vol = packed_with(&side, &dir.path().join("r.cdv"), info.iso, |o| {
        o.aniso = true;
        o.dda = true;
    });
    let c = &views(&vol, 16)[1];
    for kind in [DistKind::Cityblock, DistKind::Chessboard, DistKind::Chamfer] {
        let e = render(&vol, c, &opts(depth(), dda(kind, true)), &NoProgress).unwrap_err();
        assert!(matches!(e, RenderError::Incompatible { .. }), "{e}");
        assert!(e.to_string().contains("axis z"), "{e}");
    }
    let e = render_template(
        &vol,
        c,
        &opts(depth(), Method::Cd { min_leap: 1 }),
        &NoProgress,
    )
    .unwrap_err();
    assert!(e.to_string().contains("axis z"), "{e}");
    // The exact generators render it, identically.
    let (want, _) = render(&vol, c, &opts(depth(), Method::Fvt), &NoProgress).unwrap();
    for m in [Method::Octree, Method::Cd { min_leap: 2 }] {
        let (got, _) = render(&vol, c, &opts(depth(), m), &NoProgress).unwrap();
        assert_eq!(got.rgb, want.rgb, "{m:?}");
    }
}
