//! Smooth shading normals (issue 15; src/render/sample/normals.rs) and the
//! gradient halo (`prep --gradient-halo`, docs/FORMAT.md):
//!
//! - an oracle: on random rectilinear volumes, the vertex gradients read
//!   from a packed file equal a brute-force central difference of the raw
//!   samples, with the one-sided rule exactly where a neighbour is missing
//!   (outside the volume, a code word, or a brick the cache holds without
//!   values); with a halo no neighbour of a 1-cell's vertex is a code, and
//!   codes read back as the true ones with code 1 as 0;
//! - angle error against analytic sphere normals: smooth beats cell by a
//!   measured margin, with and without halo;
//! - exactness: fvt, cd and cd-aniso give the same bytes with smooth
//!   normals, on files with and without halo.

use proptest::prelude::*;

use crate::common::{self, chessboard_bfs, classify_iso, orbit, same_frame};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::input::raw::RawSource;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::cache::{Accessor, BrickCache};
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::sample::normals::{vertex_gradients, vertex_gradients_uncached};
use cdvol::render::traverse::Method;
use cdvol::render::{render, Mode, Normals};
use cdvol::tools::normals::{sphere_normal_errors, summary};
use cdvol::tools::phantom;

const ISO: f64 = 100.0;

/// Positions from gaps: 0, g0, g0 + g1, ...
fn positions(gaps: &[f64], n: usize) -> Vec<f64> {
    let mut x = vec![0.0];
    for g in &gaps[..n - 1] {
        x.push(x[x.len() - 1] + g);
    }
    x
}

/// `values` (u8, x fastest) on axes with gaps `gaps` written as a stack
/// in `dir`: the sidecar and the sample positions.
fn rectilinear_stack(
    dir: &std::path::Path,
    dims: [usize; 3],
    values: &[f64],
    gaps: &[Vec<f64>; 3],
) -> (std::path::PathBuf, [Vec<f64>; 3]) {
    let xs: [Vec<f64>; 3] = std::array::from_fn(|k| positions(&gaps[k], dims[k]));
    let axis = |k: usize| {
        let p: Vec<String> = xs[k].iter().map(|v| format!("{v:?}")).collect();
        format!(r#"{{"positions": [{}]}}"#, p.join(", "))
    };
    let (ax, ay, az) = (axis(0), axis(1), axis(2));
    let side = common::write_stack(dir, "v", dims, "u8", values, [&ax, &ay, &az], "");
    (side, xs)
}

/// The brute-force gradients at the 8 vertices of `cell`, from the raw
/// samples; `avail(s)` says whether the renderer may read sample `s`.
fn brute_force(
    values: &[f64],
    xs: &[Vec<f64>; 3],
    cell: [usize; 3],
    avail: &dyn Fn([usize; 3]) -> bool,
) -> [[f64; 3]; 8] {
    let n = [xs[0].len(), xs[1].len(), xs[2].len()];
    let val = |s: [usize; 3]| values[(s[2] * n[1] + s[1]) * n[0] + s[0]] as f32 as f64;
    std::array::from_fn(|v| {
        let s0 = [
            cell[0] + (v & 1),
            cell[1] + (v >> 1 & 1),
            cell[2] + (v >> 2),
        ];
        std::array::from_fn(|k| {
            let x = &xs[k];
            let f0 = val(s0);
            let minus = (s0[k] >= 1).then(|| {
                let mut s = s0;
                s[k] -= 1;
                s
            });
            let plus = (s0[k] + 1 < n[k]).then(|| {
                let mut s = s0;
                s[k] += 1;
                s
            });
            let minus = minus.filter(|&s| avail(s));
            let plus = plus.filter(|&s| avail(s));
            match (minus, plus) {
                (Some(m), Some(p)) => {
                    let (hm, hp) = (x[s0[k]] - x[m[k]], x[p[k]] - x[s0[k]]);
                    let (sm, sp) = ((f0 - val(m)) / hm, (val(p) - f0) / hp);
                    (hm * sp + hp * sm) / (hm + hp)
                }
                (Some(m), None) => (f0 - val(m)) / (x[s0[k]] - x[m[k]]),
                (None, Some(p)) => (val(p) - f0) / (x[p[k]] - x[s0[k]]),
                (None, None) => panic!("vertex {s0:?} axis {k}: no neighbour"),
            }
        })
    })
}

/// Checks one packed file of `values` against the oracle.
fn check_file(
    values: &[f64],
    dims: [usize; 3],
    xs: &[Vec<f64>; 3],
    vol: &PackedVolume,
    halo: bool,
) -> Result<(), TestCaseError> {
    let cells = dims.map(|d| d - 1);
    let obj = classify_iso(values, dims, ISO);
    let dist = chessboard_bfs(&obj, cells);
    let h = vol.header();
    prop_assert_eq!(h.gradient_halo, halo);
    let b = h.brick_size as usize;
    let ci = |c: [usize; 3]| (c[2] * cells[1] + c[1]) * cells[0] + c[0];
    let bricks = cells.map(|c| c.div_ceil(b));
    // Words carrying a code: minimum corners of cells at distance >= 2
    // (>= 3 with a halo).
    let embed_min = if halo { 3 } else { 2 };
    let coded = |s: [usize; 3]| (0..3).all(|k| s[k] < cells[k]) && dist[ci(s)] >= embed_min;

    // Codes read back: the true ones, code 1 as 0 in stored bricks with
    // a halo.
    let back = common::read_back(vol, values);
    for z in 0..cells[2] {
        for y in 0..cells[1] {
            for x in 0..cells[0] {
                let c = [x, y, z];
                let d = dist[ci(c)];
                let id = ((z / b) * bricks[1] + y / b) * bricks[0] + x / b;
                let want = match d {
                    0 => 255,
                    2 if halo && !vol.index()[id].is_uniform() => 0,
                    d => (d as u32 - 1).min(h.codes.max_code()) as u8,
                };
                prop_assert_eq!(back.codes[ci(c)], want, "cell {:?} at distance {}", c, d);
            }
        }
    }

    let coords: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
    for k in 0..3 {
        prop_assert_eq!(coords[k], &xs[k][..]);
    }
    let cache = BrickCache::new(vol, 64 << 20);
    let mut acc = Accessor::new(&cache);
    acc.remember_gradients(true);
    for z in 0..cells[2] {
        for y in 0..cells[1] {
            for x in 0..cells[0] {
                let cell = [x, y, z];
                if obj[ci(cell)] == 0 {
                    continue;
                }
                // Every sample whose word is a value is read as that
                // value, whichever brick holds it.
                let avail = |s: [usize; 3]| -> bool { !coded(s) };
                if halo {
                    // The halo invariant: no neighbour of a vertex is a code.
                    for v in 0..8 {
                        let s0 = [x + (v & 1), y + (v >> 1 & 1), z + (v >> 2)];
                        for k in 0..3 {
                            for s in [s0[k].wrapping_sub(1), s0[k] + 1] {
                                if s < dims[k] {
                                    let mut t = s0;
                                    t[k] = s;
                                    prop_assert!(!coded(t), "halo: {:?} is a code", t);
                                }
                            }
                        }
                    }
                }
                let want = brute_force(values, xs, cell, &avail);
                let got = vertex_gradients(&mut acc, coords, cell.map(|c| c as u32));
                // Asked again, the thread's memo of vertex gradients
                // answers (render/sample/normals.rs): the same, field by field.
                let again = vertex_gradients(&mut acc, coords, cell.map(|c| c as u32));
                prop_assert_eq!(again, got, "cell {:?}: the memo's answer", cell);
                for (v, (gv, wv)) in got.g.iter().zip(&want).enumerate() {
                    for (k, &w) in wv.iter().enumerate() {
                        let g = gv[k];
                        prop_assert!(
                            (g - w).abs() <= 1e-9 * w.abs().max(1.0),
                            "cell {:?} vertex {} axis {}: {} from the file, {} brute force",
                            cell,
                            v,
                            k,
                            g,
                            w
                        );
                    }
                }
            }
        }
    }
    // The memo against the computation, bit for bit, with the 1-cells
    // taken in the other order: a vertex on a brick face is then often
    // in the memo from a cell of the other brick, whose samples there may
    // differ (render/sample/normals.rs, "Which brick a sample is read from").
    let bits = |g: &cdvol::render::sample::normals::VertexGradients| {
        (g.g.map(|v| v.to_array().map(f64::to_bits)), g.one_sided)
    };
    for z in (0..cells[2]).rev() {
        for y in (0..cells[1]).rev() {
            for x in (0..cells[0]).rev() {
                let cell = [x as u32, y as u32, z as u32];
                if obj[ci([x, y, z])] == 0 {
                    continue;
                }
                let memo = vertex_gradients(&mut acc, coords, cell);
                let computed = vertex_gradients_uncached(&mut acc, coords, cell);
                prop_assert_eq!(bits(&memo), bits(&computed), "cell {:?}", cell);
            }
        }
    }
    prop_assert!(acc.error.is_none());
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Vertex gradients from packed files (with and without halo) equal
    /// the brute-force central differences of the raw samples on random
    /// rectilinear volumes, one-sided exactly where a neighbour is
    /// missing.
    #[test]
    fn smooth_gradients_match_brute_force(
        (dims, values, brick) in common::random_volume([11, 11, 11], 350),
        gaps in prop::array::uniform3(proptest::collection::vec(0.3f64..2.5, 10)),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let (side, xs) = rectilinear_stack(dir.path(), dims, &values, &gaps);
        for halo in [false, true] {
            let out = dir.path().join(format!("v{halo}.cdv"));
            let vol = common::packed_with(&side, &out, ISO, |o| {
                o.brick_size = brick;
                o.gradient_halo = halo;
            });
            check_file(&values, dims, &xs, &vol, halo)?;
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Where the bricks are cut does not show: the same random
    /// rectilinear volume prepared with bricks of 4, 8 and 16 cells (and
    /// with and without a halo) renders byte-identical surfaces with
    /// smooth normals and shadows (at the file's iso value and narrowed
    /// to a higher one), and byte-identical shaded composites sampled
    /// one at a time, from a random view. Before bricks without 1-cells
    /// were read for their values at faces (render/sample/normals.rs), normals
    /// at brick faces could go one-sided in one layout and not in
    /// another. The composite's sample batches (the default) end at
    /// brick faces and find a sample's cell by its position, so a sample
    /// within rounding of a cell face may take the neighbouring cell
    /// (docs/TRADEOFFS.md, "Sample batches"): with them the composites
    /// of two brick sizes agree within one grey level.
    #[test]
    fn images_do_not_depend_on_the_brick_size(
        (dims, values, _) in common::random_volume([14, 14, 14], 350),
        gaps in prop::array::uniform3(proptest::collection::vec(0.3f64..2.5, 13)),
        view in (-180.0f64..180.0, -80.0f64..80.0),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let (side, _) = rectilinear_stack(dir.path(), dims, &values, &gaps);
        let tf = common::white_tf(&[(100.0, 0.0), (140.0, 0.3), (220.0, 0.9)]);
        for halo in [false, true] {
            let mut first: Option<Vec<cdvol::render::Frame>> = None;
            for brick in [4, 8, 16] {
                let out = dir.path().join(format!("v{halo}{brick}.cdv"));
                let vol = common::packed_with(&side, &out, ISO, |o| {
                    o.brick_size = brick;
                    o.gradient_halo = halo;
                });
                let cam = orbit(&vol, [view.0, view.1], None, 24, 24);
                let surface = Mode::Surface { hit: HitMethod::Newton, shadows: true };
                let composite = Mode::Composite { tf: tf.clone(), step_mm: 0.4 };
                // The surface at the file's iso and, narrowed, at 150; the
                // shaded composite one sample at a time and in batches.
                let frames: Vec<cdvol::render::Frame> = [
                    (surface.clone(), None, false),
                    (surface, Some(150.0), false),
                    (composite.clone(), None, false),
                    (composite, None, true),
                ]
                .into_iter()
                .map(|(mode, iso, batches)| {
                    let mut o = common::test_opts(mode, Method::Cd { min_leap: 1 });
                    o.look.shade = true;
                    o.iso = iso;
                    o.sample_batches = batches;
                    render(&vol, &cam, &o, &NoProgress).unwrap().0
                })
                .collect();
                match &first {
                    None => first = Some(frames),
                    Some(f) => {
                        for (m, (a, b)) in f.iter().zip(&frames).enumerate() {
                            if m == 3 {
                                let planes = a.rgb.iter().chain(&a.alpha).zip(b.rgb.iter().chain(&b.alpha));
                                let most = planes.map(|(x, y)| x.abs_diff(*y)).max();
                                prop_assert!(
                                    most.unwrap_or(0) <= 1 && a.alpha.len() == b.alpha.len(),
                                    "halo {}: batched composites of bricks of 4 and {} differ by {:?}",
                                    halo, brick, most
                                );
                                continue;
                            }
                            prop_assert!(
                                same_frame(a, b),
                                "halo {}: mode {} differs between bricks of 4 and {}",
                                halo, m, brick
                            );
                        }
                    }
                }
            }
        }
    }
}

/// A sphere scene of the paper's section 5.1 prepared with and without a
/// halo, rectilinear along y.
fn sphere_files(dir: &std::path::Path, size: usize, aniso: bool) -> [(PackedVolume, bool); 2] {
    let side = dir.join("s.json");
    phantom::spheres(
        &side,
        &phantom::SpheresOptions {
            size,
            per_axis: 2,
            seed: 5,
            spacing: [
                phantom::SpacingSpec::Uniform(1.0),
                phantom::SpacingSpec::parse("0.6:1.4").unwrap(),
                phantom::SpacingSpec::Uniform(1.5),
            ],
        },
        &NoProgress,
    )
    .unwrap();
    [false, true].map(|halo| {
        let out = dir.join(format!("s{halo}.cdv"));
        let mut o = PrepOptions::new(Classification::Iso {
            iso: phantom::SPHERES_ISO,
        });
        o.brick_size = 16;
        o.aniso = aniso;
        o.gradient_halo = halo;
        prep(&RawSource::open(&side).unwrap(), &out, &o, &NoProgress).unwrap();
        (PackedVolume::open(&out).unwrap(), halo)
    })
}

/// Angle error against the analytic spheres. Measured on this scene
/// (64^3, rectilinear, 2 x 96^2 rays, 3978 hits; the figures are printed
/// with `--nocapture`): cell mean 1.64 deg, p95 2.90 deg; smooth mean
/// 0.093 / 0.091 deg, p95 0.18 / 0.17 deg without / with halo, about 17x
/// better. Asserted with a margin of 4x on that ratio and 2x on the mean:
/// smooth below a quarter of cell (mean and p95), and its mean below
/// 0.2 deg.
#[test]
fn smooth_normals_are_closer_to_the_spheres() {
    let dir = tempfile::tempdir().unwrap();
    let list = dir.path().join("s.spheres.json");
    for (vol, halo) in sphere_files(dir.path(), 64, false) {
        let (_, spheres) = phantom::load_spheres(&list).unwrap();
        let e = sphere_normal_errors(&vol, &spheres, &[[30.0, 20.0], [200.0, -40.0]], 96).unwrap();
        let (c, s) = (summary(&e.cell), summary(&e.smooth));
        println!(
            "halo {halo}: {} hits ({} one-sided); cell mean/median/p95 {c:.3?}, smooth {s:.3?}",
            e.cell.len(),
            e.one_sided_hits
        );
        assert!(e.cell.len() > 2000, "{} hits", e.cell.len());
        assert!(
            s[0] * 4.0 < c[0] && s[2] * 4.0 < c[2],
            "cell {c:?} smooth {s:?}"
        );
        assert!(s[0] < 0.2, "smooth mean {} deg", s[0]);
    }
}

/// fvt, cd and cd-aniso give the same bytes with smooth normals (with
/// shadows), on files with and without halo; smooth and cell differ.
#[test]
fn traversals_agree_with_smooth_normals() {
    let dir = tempfile::tempdir().unwrap();
    for (vol, halo) in sphere_files(dir.path(), 40, true) {
        let cam = orbit(&vol, [35.0, 25.0], None, 64, 64);
        let frame = |method: Method, normals: Normals| {
            let mode = Mode::Surface {
                hit: HitMethod::Newton,
                shadows: true,
            };
            let o = cdvol::render::RenderOptions {
                normals,
                ..common::test_opts(mode, method)
            };
            render(&vol, &cam, &o, &NoProgress).unwrap().0
        };
        let fvt = frame(Method::Fvt, Normals::Smooth);
        for m in [Method::Cd { min_leap: 1 }, Method::CdAniso { min_leap: 1 }] {
            assert!(
                same_frame(&fvt, &frame(m, Normals::Smooth)),
                "halo {halo}: {m:?} differs from fvt"
            );
        }
        let cell = frame(Method::Fvt, Normals::Cell);
        assert_ne!(
            fvt.rgb, cell.rgb,
            "halo {halo}: smooth and cell normals agree"
        );
    }
}

/// The command line: `prep --gradient-halo` is recorded and shown by
/// `info` (text and JSON), a file without it says nothing (old files read
/// as no halo), `render --normals` takes `smooth` and `cell` and refuses
/// anything else by naming the flag.
#[test]
fn cli_flags() {
    use common::{cdvol, fails, ok};
    let dir = tempfile::tempdir().unwrap();
    let side = dir.path().join("s.json");
    ok(cdvol()
        .args(["phantom", "spheres", "-q", "--size", "24", "-o"])
        .arg(&side));
    for halo in [false, true] {
        let out = dir.path().join(format!("s{halo}.cdv"));
        let mut prep = cdvol();
        prep.args(["prep", "-q", "--iso", "1000", "-o"])
            .arg(&out)
            .arg(&side);
        if halo {
            prep.arg("--gradient-halo");
        }
        ok(&mut prep);
        let info = ok(cdvol().arg("info").arg(&out));
        assert_eq!(info.contains("grad. halo"), halo, "{info}");
        let json = ok(cdvol().args(["info", "--json"]).arg(&out));
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["gradient_halo"], serde_json::Value::Bool(halo), "{json}");
        for n in ["smooth", "cell"] {
            ok(cdvol()
                .arg("render")
                .arg(&out)
                .arg("-o")
                .arg(dir.path().join(format!("{halo}-{n}.png")))
                .args(["--width", "32", "--height", "32", "-q", "--normals", n]));
        }
        let e = fails(
            cdvol()
                .arg("render")
                .arg(&out)
                .arg("-o")
                .arg(dir.path().join("x.png"))
                .args(["--normals", "central"]),
        );
        assert!(e.contains("--normals"), "{e}");
    }
}

/// Which brick a shared sample is read from (src/render/sample/normals.rs,
/// "Which brick a sample is read from"): a sample on a brick's face is
/// stored in both bricks with the same word, but a brick without 1-cells
/// is held without values (decoded for its codes only), so its copy of a
/// value is missing. Every vertex gradient of every 1-cell is finite
/// (each axis has at least the slope to the cell's other vertex), and
/// the sample a face vertex's neighbour brick holds reads, through
/// [`Accessor::brick_with_values`], as the 1-cell's own brick's copy, bit
/// for bit: so the gradients do not depend on where the bricks are cut.
/// On the real CT, classified by a skin-and-bone transfer function and by
/// an iso value, with 16-cell bricks; the test also requires that such
/// neighbours held without values occur.
#[test]
fn face_samples_read_the_same_from_either_brick() {
    let dir = tempfile::tempdir().unwrap();
    let ct = common::real_ct();
    let skin = common::white_tf(&[(-300.0, 0.0), (-100.0, 0.02), (300.0, 0.0), (600.0, 0.08)]);
    for (name, class) in [
        ("skin-bone", Classification::TransferFunction { tf: skin }),
        ("iso 300", Classification::Iso { iso: 300.0 }),
    ] {
        let mut o = PrepOptions::new(class);
        o.brick_size = 16;
        let out = dir.path().join(format!("{}.cdv", name.replace(' ', "-")));
        let src = cdvol::input::open(&ct).unwrap();
        prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
        let vol = PackedVolume::open(&out).unwrap();
        let h = vol.header();
        let coords: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
        let n: [usize; 3] = std::array::from_fn(|k| coords[k].len());
        let cache = BrickCache::new(&vol, 256 << 20);
        let mut acc = Accessor::new(&cache);
        let (mut one_cells, mut without_values) = (0u64, 0u64);
        for z in 0..n[2] as u32 - 1 {
            for y in 0..n[1] as u32 - 1 {
                for x in 0..n[0] as u32 - 1 {
                    let c = [x, y, z];
                    let (b, l) = acc.brick(c);
                    if b.code(l) != cdvol::render::traverse::OBJECT {
                        continue;
                    }
                    one_cells += 1;
                    let cells = b.cells;
                    let own = b.vertices(l);
                    // Vertices on this brick's far faces, and their copy in
                    // the brick of the cell they are the minimum corner of.
                    for (v, own_v) in own.iter().enumerate() {
                        let off: [u32; 3] = std::array::from_fn(|k| (v >> k & 1) as u32);
                        let far = (0..3).any(|k| l[k] + off[k] == cells[k]);
                        let s: [usize; 3] = std::array::from_fn(|k| (c[k] + off[k]) as usize);
                        if !far || (0..3).any(|k| s[k] + 1 >= n[k]) {
                            continue;
                        }
                        let at: [u32; 3] = std::array::from_fn(|k| s[k] as u32);
                        let (nb, _) = acc.brick(at);
                        if nb.values.is_empty() {
                            without_values += 1;
                        }
                        let (wb, wl) = acc.brick_with_values(at);
                        assert_eq!(
                            wb.vertices(wl)[0].to_bits(),
                            own_v.to_bits(),
                            "{name}: cell {c:?} vertex {v}: the copy next door"
                        );
                    }
                    let g = vertex_gradients(&mut acc, coords, c).g;
                    for (v, gv) in g.iter().enumerate() {
                        assert!(
                            gv.is_finite(),
                            "{name}: cell {c:?} vertex {v}: gradient {gv:?}"
                        );
                    }
                }
            }
        }
        assert!(one_cells > 10_000, "{name}: {one_cells} 1-cells");
        assert!(
            without_values > 0,
            "{name}: no face vertex has a neighbour brick held without values"
        );
    }
}
