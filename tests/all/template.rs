//! Template-based CD traversal (src/render/template/): the template's
//! shape, the exactness of the CD leap, the images against the FVT/CD
//! ray caster, the 26-connected template's skipped cells, and refusals.

use crate::common::{self, orbit, packed};

use std::path::Path;

use cdvol::format::reader::PackedVolume;
use cdvol::grid::Axis;
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::template::{
    render_template, render_template_with, walk, Template, TemplateOptions, Warp,
};
use cdvol::render::traverse::{trace, Flow, Method, Ray, TGrid};
use cdvol::render::view::camera::{Camera, Projection};
use cdvol::render::{render, Frame, Mode, RenderError, RenderOptions, Stats};
use cdvol::tools::corpus::MemVolume;
use cdvol::tools::phantom;
use proptest::prelude::*;
use proptest::strategy::ValueTree;

/// Directions: generic, axis-aligned (signed, including -0.0), diagonal
/// (two or three equal components) and near-degenerate (components almost
/// equal, or almost zero).
fn direction() -> impl Strategy<Value = [f64; 3]> {
    let sign = prop_oneof![Just(1.0f64), Just(-1.0f64)];
    let unit = -1.0f64..1.0;
    prop_oneof![
        [unit.clone(), unit.clone(), unit.clone()]
            .prop_filter("non-zero", |d| d.iter().any(|x| x.abs() > 1e-3)),
        (0usize..3, sign.clone(), prop_oneof![Just(0.0), Just(-0.0)]).prop_map(|(k, s, z)| {
            let mut d = [z; 3];
            d[k] = s;
            d
        }),
        (sign.clone(), sign.clone(), sign.clone(), 0usize..4).prop_map(|(a, b, c, zero)| {
            let mut d = [a, b, c];
            if zero < 3 {
                d[zero] = 0.0;
            }
            d
        }),
        (
            sign.clone(),
            sign.clone(),
            sign,
            prop_oneof![Just(1e-15), Just(1e-9), Just(-1e-12), Just(1e-300)],
            0usize..3,
            any::<bool>(),
        )
            .prop_map(|(a, b, c, e, k, near_equal)| {
                let mut d = [a, b, c];
                if near_equal {
                    // One component a hair above or below the others.
                    d[k] *= 1.0 + e;
                } else {
                    d[k] = e;
                }
                d
            }),
    ]
}

fn spacing() -> impl Strategy<Value = [f64; 3]> {
    prop_oneof![
        Just([1.0; 3]),
        [0.3f64..3.0, 0.3f64..3.0, 0.3f64..3.0],
        Just([1.0, 1.0, 2.5]),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// One entry per major cell; consecutive entries step exactly one cell
    /// along the major axis and at most one along the others; each entry
    /// is the cell within half a cell (per minor axis) of the true line
    /// through the start centre at the middle of its slab.
    #[test]
    fn template_is_a_26_connected_line_near_the_ray(
        d in direction(),
        h in spacing(),
        n in [1u32..300, 1u32..300, 1u32..300],
    ) {
        let r: [f64; 3] = std::array::from_fn(|k| d[k] / h[k]);
        let t = Template::new(r, n).expect("usable direction");
        let m = t.major;
        prop_assert!((0..3).all(|k| r[k].abs() <= r[m].abs()));
        prop_assert_eq!(t.offsets.len(), n[m] as usize);
        let off = t.signed_offsets();
        prop_assert_eq!(off[0][m], 0);
        for w in off.windows(2) {
            for k in 0..3 {
                let step = (w[1][k] - w[0][k]).abs();
                if k == m {
                    prop_assert_eq!(step, 1, "major step in {:?}", w);
                } else {
                    prop_assert!(step <= 1, "minor step in {:?}", w);
                }
            }
        }
        for (s, o) in off.iter().enumerate() {
            let along = (s as f64 + 0.5) / r[m].abs();
            prop_assert_eq!(o[m] as f64, (s as f64) * r[m].signum());
            for k in t.minor {
                let line = along * r[k];
                prop_assert!(
                    (o[k] as f64 - line).abs() <= 0.5 + 1e-9,
                    "entry {} axis {}: offset {} vs line {}", s, k, o[k], line
                );
            }
        }
    }
}

/// A small volume of uniform axes with random 1-cells (by density).
fn mem_volume() -> impl Strategy<Value = MemVolume> {
    (
        [2u32..14, 2u32..14, 2u32..14],
        spacing(),
        0.0f64..0.08,
        any::<u64>(),
    )
        .prop_map(|(n, h, density, seed)| {
            let axes = std::array::from_fn(|k| {
                Axis::uniform(-3.0, h[k], n[k] as usize + 1).expect("axis")
            });
            let mut s = seed;
            let mut rnd = || {
                s = s.wrapping_add(0x9e37_79b9_7f4a_7c15);
                let mut z = s;
                z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
                ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
            };
            let mut objects = Vec::new();
            for z in 0..n[2] {
                for y in 0..n[1] {
                    for x in 0..n[0] {
                        if rnd() < density {
                            objects.push([x, y, z]);
                        }
                    }
                }
            }
            MemVolume::new(axes, objects)
        })
}

/// Mirrored start indices of every ray of the extended base plane, and
/// one more on each side (rays that miss the volume).
fn starts(t: &Template, n: [u32; 3]) -> Vec<[i64; 2]> {
    let [a, b] = t.minor;
    let mut v = Vec::new();
    for i in -(t.drift(a) as i64) - 1..=n[a] as i64 {
        for j in -(t.drift(b) as i64) - 1..=n[b] as i64 {
            v.push([i, j]);
        }
    }
    v
}

/// The 1-cells a template walk reports, in order.
fn template_cells(
    vol: &MemVolume,
    t: &Template,
    start: [i64; 2],
    leap: Option<u8>,
) -> Vec<[u32; 3]> {
    let mut cells = Vec::new();
    let mut src = vol;
    walk(t, vol.ncells, start, leap, &mut src, |_, c, _| {
        cells.push(c);
        Flow::Continue
    });
    cells
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(192))]

    /// CD leaps over the template yield exactly the 1-cells of the walk that
    /// reads every entry, on every ray of the (extended) base plane, and
    /// every reported cell is a 1-cell; with `min_leap` 1 and 3.
    #[test]
    fn leaps_yield_the_same_one_cells_as_single_steps(vol in mem_volume(), d in direction()) {
        let h: [f64; 3] = std::array::from_fn(|k| vol.axes[k].coords()[1] - vol.axes[k].coords()[0]);
        let r: [f64; 3] = std::array::from_fn(|k| d[k] / h[k]);
        let t = Template::new(r, vol.ncells).expect("usable direction");
        let (mut leaps, mut steps) = (0u64, 0u64);
        for start in starts(&t, vol.ncells) {
            let all = template_cells(&vol, &t, start, None);
            prop_assert!(all.iter().all(|c| vol.is_object(*c)));
            for min_leap in [1, 3] {
                let cd = template_cells(&vol, &t, start, Some(min_leap));
                prop_assert_eq!(&cd, &all, "start {:?} min_leap {}", start, min_leap);
            }
            let mut src = &vol;
            let s1 = walk(&t, vol.ncells, start, Some(1), &mut src, |_, _, _| Flow::Continue);
            let s0 = walk(&t, vol.ncells, start, None, &mut src, |_, _, _| Flow::Continue);
            prop_assert!(s1.steps <= s0.steps);
            prop_assert_eq!(s0.macro_steps, 0);
            leaps += s1.macro_steps;
            steps += s0.steps;
        }
        prop_assert!(leaps <= steps);
    }
}

/// The true ray of template start `start` in `vol` (independent of the
/// library's setup): origin at the centre of the start cell on the base
/// plane, in mm.
fn true_ray(vol: &MemVolume, t: &Template, dir: [f64; 3], start: [i64; 2]) -> Ray {
    let m = t.major;
    let c = |k: usize| vol.axes[k].coords();
    let mut origin = [0.0; 3];
    origin[m] = if t.mirror[m] {
        c(m)[vol.ncells[m] as usize]
    } else {
        c(m)[0]
    };
    for (q, &k) in t.minor.iter().enumerate() {
        let h = c(k)[1] - c(k)[0];
        let u = start[q] as f64 + 0.5;
        let u = if t.mirror[k] {
            vol.ncells[k] as f64 - u
        } else {
            u
        };
        origin[k] = c(k)[0] + u * h;
    }
    Ray {
        origin: origin.into(),
        dir: dir.into(),
    }
}

/// Measures the cost of 26-connectivity: along the true rays of the
/// template starts, the 1-cells FVT passes through with positive length
/// that the single-step template walk skips. Every template 1-cell is one
/// FVT visits (generic directions), and the template misses a bounded
/// share of FVT's (printed; the bound only catches a broken template).
#[test]
fn template_skips_some_cells_fvt_visits() {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let (mut fvt_total, mut skipped, mut extra) = (0u64, 0u64, 0u64);
    let unit = -1.0f64..1.0;
    let strat = (mem_volume(), [unit.clone(), unit.clone(), unit]);
    for _ in 0..300 {
        let (vol, d) = strat.new_tree(&mut runner).expect("case").current();
        if d.iter().all(|x| x.abs() < 1e-3) {
            continue;
        }
        let h: [f64; 3] =
            std::array::from_fn(|k| vol.axes[k].coords()[1] - vol.axes[k].coords()[0]);
        let r: [f64; 3] = std::array::from_fn(|k| d[k] / h[k]);
        let t = Template::new(r, vol.ncells).expect("usable");
        let grid = TGrid::<f64>::new(&vol.axes);
        for start in starts(&t, vol.ncells) {
            let ray = true_ray(&vol, &t, d, start);
            let tc = template_cells(&vol, &t, start, None);
            let mut fc = Vec::new();
            let mut src = &vol;
            trace(&grid, &ray, 0.0, Method::Fvt, &mut src, |v, _| {
                fc.push(v.cell);
                Flow::Continue
            });
            fvt_total += fc.len() as u64;
            skipped += fc.iter().filter(|c| !tc.contains(c)).count() as u64;
            extra += tc.iter().filter(|c| !fc.contains(c)).count() as u64;
        }
    }
    let share = skipped as f64 / fvt_total.max(1) as f64;
    eprintln!(
        "26-connected template: skipped {skipped} of {fvt_total} FVT 1-cell visits \
         ({:.1} %), {extra} template 1-cells FVT does not visit",
        100.0 * share
    );
    assert!(fvt_total > 1000, "too few 1-cell visits ({fvt_total})");
    assert_eq!(extra, 0, "the template visited cells the ray does not pass");
    // A 6-connected walk through a 26-connected one's slabs visits at most
    // 3 cells per slab, so at most 2/3 are skipped; random directions give
    // far fewer.
    assert!(share > 0.0 && share < 0.6, "skipped share {share}");
}

// ---------------------------------------------------------------------------
// Images against the ray caster
// ---------------------------------------------------------------------------

fn spheres(dir: &Path, name: &str, size: usize, spacing: &str) -> PackedVolume {
    let side = dir.join(format!("{name}.json"));
    let info = phantom::spheres(
        &side,
        &phantom::SpheresOptions {
            size,
            per_axis: 2,
            seed: 7,
            spacing: phantom::parse_spacing3(spacing).unwrap(),
        },
        &NoProgress,
    )
    .unwrap();
    packed(&side, &dir.join(format!("{name}.cdv")), info.iso)
}

fn opts(mode: Mode, method: Method) -> RenderOptions {
    common::test_opts(mode, method)
}

/// Depth comparison of two depth frames.
struct Cmp {
    /// Share of pixels where one hits and the other misses.
    differ: f64,
    /// Pixels both hit.
    both: usize,
    /// Median and 95th percentile of `|depth difference|`, mm.
    med: f64,
    p95: f64,
    /// Share of the pixels both hit whose depths differ by more than `far`.
    far_share: f64,
}

fn compare(a: &Frame, b: &Frame, far: f64) -> Cmp {
    let (da, db) = (a.depth.as_ref().unwrap(), b.depth.as_ref().unwrap());
    let mut differ = 0usize;
    let mut diffs = Vec::new();
    for (x, y) in da.iter().zip(db) {
        match (x.is_finite(), y.is_finite()) {
            (true, true) => diffs.push((x - y).abs() as f64),
            (p, q) => differ += (p != q) as usize,
        }
    }
    diffs.sort_by(f64::total_cmp);
    let q = |f: f64| diffs[((diffs.len() - 1) as f64 * f) as usize];
    Cmp {
        differ: differ as f64 / da.len() as f64,
        both: diffs.len(),
        med: q(0.5),
        p95: q(0.95),
        far_share: diffs.iter().filter(|&&d| d > far).count() as f64 / diffs.len() as f64,
    }
}

/// Against FVT on a sphere phantom (cubic and regular grids; axis,
/// oblique and diagonal views), with the default bilinear warp and gap
/// refinement: hit/miss agrees on > 98.5 % of pixels (measured 0.65-1.02 %
/// differ), the median depth difference is below a tenth of the largest
/// gap (measured 0.03-0.09 mm; the nearest warp, 0.19-0.31 mm, would fail),
/// the 95th percentile below twice the largest gap (measured 0.63-1.23
/// mm), and under 12 % of the pixels
/// both hit differ by more than the smallest gap (measured 2.7-7.2 %: near
/// silhouettes, where the surface is steep, so depth changes by more than
/// a gap within the half cell between a pixel's ray and the intermediate
/// rays; and where the warp takes a ray that meets another sphere). The
/// template with CD leaps gives the same image as the single-step
/// template, with fewer steps. All variants' numbers are printed.
#[test]
fn depth_against_fvt_on_spheres() {
    let dir = tempfile::tempdir().unwrap();
    for (name, spacing, hmin, hmax) in
        [("cubic", "1", 1.0, 1.0), ("regular", "0.8,1,1.5", 0.8, 1.5)]
    {
        let vol = spheres(dir.path(), name, 48, spacing);
        for view in [[0.0, 0.0], [33.0, 21.0], [45.0, 35.264], [-130.0, -60.0]] {
            let c = orbit(&vol, view, None, 96, 96);
            let mode = Mode::Depth {
                hit: HitMethod::Newton,
            };
            let (fvt, _) = render(&vol, &c, &opts(mode.clone(), Method::Fvt), &NoProgress).unwrap();
            let (tcd, scd) = render_template(
                &vol,
                &c,
                &opts(mode.clone(), Method::Cd { min_leap: 1 }),
                &NoProgress,
            )
            .unwrap();
            let (tfvt, sfvt) =
                render_template(&vol, &c, &opts(mode.clone(), Method::Fvt), &NoProgress).unwrap();
            assert_eq!(tcd.rgb, tfvt.rgb, "leaps changed the image");
            assert_eq!(scd.hits, sfvt.hits);
            assert_eq!(scd.rays, sfvt.rays);
            assert!(scd.steps < sfvt.steps, "{} vs {}", scd.steps, sfvt.steps);
            assert!(scd.macro_steps > 0 && sfvt.macro_steps == 0);
            let variant = |warp, refine| {
                let o = TemplateOptions { warp, refine };
                let cd = opts(mode.clone(), Method::Cd { min_leap: 1 });
                render_template_with(&vol, &c, &cd, o, &NoProgress)
                    .unwrap()
                    .0
            };
            let b = compare(&tcd, &fvt, hmin);
            let show = |what: &str, x: &Cmp| {
                eprintln!(
                    "  {what:<22} hit/miss differs {:5.2} %; |depth diff| median {:.3} mm, \
                     p95 {:.3} mm, {:5.2} % above one gap ({} pixels both hit)",
                    100.0 * x.differ,
                    x.med,
                    x.p95,
                    100.0 * x.far_share,
                    x.both
                )
            };
            eprintln!(
                "{name} view {view:?}: steps template-cd {} template-fvt {} (hits {})",
                scd.steps, sfvt.steps, scd.hits
            );
            show("bilinear + refine", &b);
            show(
                "nearest + refine",
                &compare(&variant(Warp::Nearest, true), &fvt, hmin),
            );
            show(
                "bilinear, no refine",
                &compare(&variant(Warp::Bilinear, false), &fvt, hmin),
            );
            show(
                "nearest, no refine",
                &compare(&variant(Warp::Nearest, false), &fvt, hmin),
            );
            assert!(b.both > 1000, "too few hits ({})", b.both);
            assert!(
                b.differ < 0.015,
                "{name} {view:?}: hit/miss differs on {}",
                b.differ
            );
            assert!(
                b.med < 0.1 * hmax,
                "{name} {view:?}: median depth diff {}",
                b.med
            );
            assert!(
                b.p95 < 2.0 * hmax,
                "{name} {view:?}: p95 depth diff {}",
                b.p95
            );
            assert!(
                b.far_share < 0.12,
                "{name} {view:?}: {} beyond a gap",
                b.far_share
            );
        }
    }
}

#[test]
fn surface_and_cost_render() {
    let dir = tempfile::tempdir().unwrap();
    let vol = spheres(dir.path(), "s", 40, "1");
    let c = orbit(&vol, [20.0, 30.0], None, 64, 64);
    let surf = Mode::Surface {
        hit: HitMethod::Int,
        shadows: false,
    };
    let (f, s): (Frame, Stats) = render_template(
        &vol,
        &c,
        &opts(surf.clone(), Method::Cd { min_leap: 1 }),
        &NoProgress,
    )
    .unwrap();
    let (g, _) = render(
        &vol,
        &c,
        &opts(surf, Method::Cd { min_leap: 1 }),
        &NoProgress,
    )
    .unwrap();
    // Shaded pixels: same coverage, similar grey levels.
    let lit = |f: &Frame| f.rgb.chunks(3).filter(|p| p[0] > 0).count();
    let (a, b) = (lit(&f), lit(&g));
    assert!(
        a > 300 && (a as f64 - b as f64).abs() < 0.02 * b as f64,
        "{a} vs {b}"
    );
    let mean_abs: f64 = f
        .rgb
        .iter()
        .zip(&g.rgb)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / f.rgb.len() as f64;
    eprintln!("surface: mean |grey difference| {mean_abs:.2} of 255");
    assert!(mean_abs < 8.0, "surface differs by {mean_abs} on average");
    assert!(s.hits > 0 && s.rays > 0 && s.cache_misses > 0);
    let (cost, cs) = render_template(
        &vol,
        &c,
        &opts(Mode::Cost, Method::Cd { min_leap: 1 }),
        &NoProgress,
    )
    .unwrap();
    assert!(cost.steps.iter().any(|&x| x > 0));
    assert_eq!(cs.traversal, "template cd");
}

#[test]
fn refusals() {
    let dir = tempfile::tempdir().unwrap();
    let vol = spheres(dir.path(), "s", 24, "1");
    let depth = Mode::Depth {
        hit: HitMethod::Int,
    };
    let cd = Method::Cd { min_leap: 1 };
    let persp = orbit(&vol, [10.0, 10.0], Some(35.0), 16, 16);
    let msg = |r: Result<(Frame, Stats), RenderError>| match r {
        Err(e) => e.to_string(),
        Ok(_) => panic!("rendered"),
    };
    let e = msg(render_template(
        &vol,
        &persp,
        &opts(depth.clone(), cd),
        &NoProgress,
    ));
    assert!(e.contains("perspective"), "{e}");
    let c = orbit(&vol, [10.0, 10.0], None, 16, 16);
    for mode in [
        Mode::Mip,
        Mode::Surface {
            hit: HitMethod::Int,
            shadows: true,
        },
    ] {
        let e = msg(render_template(&vol, &c, &opts(mode, cd), &NoProgress));
        assert!(e.starts_with("template traversal:"), "{e}");
    }
    let e = msg(render_template(
        &vol,
        &c,
        &opts(depth.clone(), Method::CdAniso { min_leap: 1 }),
        &NoProgress,
    ));
    assert!(e.contains("cd-aniso"), "{e}");
    // An eye inside the volume.
    let inside = Camera::look_at(
        [10.0, 10.0, 10.0],
        [20.0, 20.0, 12.0],
        [0.0, 0.0, 1.0],
        Projection::Ortho { frame_mm: 30.0 },
        16,
        16,
    )
    .unwrap();
    let e = msg(render_template(
        &vol,
        &inside,
        &opts(depth.clone(), cd),
        &NoProgress,
    ));
    assert!(e.contains("not in front"), "{e}");
    // A rectilinear z axis is named.
    let rect = spheres(dir.path(), "r", 24, "1,1,0.5:2");
    let c = orbit(&rect, [10.0, 10.0], None, 16, 16);
    let e = msg(render_template(&rect, &c, &opts(depth, cd), &NoProgress));
    assert!(e.contains("axis z is rectilinear"), "{e}");
}
