//! Label maps (issue 55): a label phantom of analytic spheres on a
//! rectilinear grid, prepared with `--labels`. Its codes against the
//! brute-force chessboard transform of the union of the labels, every
//! label read back exactly, each label's surface against its analytic
//! sphere, translucent labels composited front to back, and every bad
//! input refused by name with nothing written.

use std::path::{Path, PathBuf};

use cdvol::format::reader::PackedVolume;
use cdvol::labels::LabelStyle;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::Method;
use cdvol::render::view::camera::Camera;
use cdvol::render::{render_part, Mode, Shard};
use glam::DVec3;

use crate::common::{
    axis_json, cdvol, chessboard_bfs, classify_iso, expected_codes, fails, ok, read_back,
    test_opts, write_stack,
};

/// The phantom's spheres: label, centre (mm), radius (mm). Label 4 lies
/// inside label 1; labels 2 and 3 touch.
const SPHERES: [(u16, [f64; 3], f64); 4] = [
    (4, [30.0, 20.0, 17.0], 4.0),
    (1, [30.0, 20.0, 17.0], 10.0),
    (2, [10.0, 10.0, 17.0], 6.0),
    (3, [10.0, 22.0, 17.0], 6.0),
];

const DIMS: [usize; 3] = [46, 36, 26];

/// Sample positions per axis: x 1 mm, y 1.1 mm, z from 0.8 to 1.7 mm
/// gaps (rectilinear).
fn positions() -> [Vec<f64>; 3] {
    let x = (0..DIMS[0]).map(|i| i as f64).collect();
    let y = (0..DIMS[1]).map(|i| i as f64 * 1.1).collect();
    let mut z = vec![0.0];
    for i in 1..DIMS[2] {
        let gap = 0.8 + 0.9 * ((i * 7) % 5) as f64 / 4.0;
        z.push(z[i - 1] + gap);
    }
    [x, y, z]
}

/// The label of the point `p`: the first sphere holding it, else 0.
fn label_at(p: [f64; 3]) -> u16 {
    SPHERES
        .iter()
        .find(|(_, c, r)| (0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>() <= r * r)
        .map_or(0, |s| s.0)
}

/// The phantom's labels (x fastest) and its sidecar in `dir`.
fn phantom(dir: &Path, dtype: &str) -> (Vec<f64>, PathBuf) {
    let [xs, ys, zs] = positions();
    let mut v = Vec::new();
    for z in &zs {
        for y in &ys {
            for x in &xs {
                v.push(label_at([*x, *y, *z]) as f64);
            }
        }
    }
    let ax = [axis_json(&xs), axis_json(&ys), axis_json(&zs)];
    let p = write_stack(dir, "seg", DIMS, dtype, &v, [&ax[0], &ax[1], &ax[2]], "");
    (v, p)
}

fn prepared(dir: &Path) -> (Vec<f64>, PackedVolume) {
    let (v, input) = phantom(dir, "u8");
    let out = dir.join("seg.cdv");
    let src = cdvol::input::open(&input).unwrap();
    let mut o = PrepOptions::new(cdvol::classify::Classification::Iso { iso: 0.0 });
    o.labels = true;
    o.brick_size = 8;
    prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
    (v, PackedVolume::open(&out).unwrap())
}

#[test]
fn codes_are_those_of_the_union_and_labels_read_back_exactly() {
    let d = tempfile::tempdir().unwrap();
    let (v, vol) = prepared(d.path());
    let h = vol.header();
    let info = h.labels.as_ref().expect("a label file records its labels");
    // The counts against the samples.
    for (id, n) in &info.counts {
        let want = v.iter().filter(|&&x| x == *id as f64).count() as u64;
        assert_eq!(*n, want, "label {id}");
    }
    assert_eq!(
        info.counts.iter().map(|c| c.0).collect::<Vec<_>>(),
        [1, 2, 3, 4]
    );
    assert_eq!(
        info.background,
        v.iter().filter(|&&x| x == 0.0).count() as u64
    );
    // Classes: any vertex not 0; codes: the brute-force chessboard
    // distance to them. `read_back` also checks every 1-cell's 8 words.
    let cells = DIMS.map(|n| n - 1);
    let obj = classify_iso(&v, DIMS, 0.5);
    let rb = read_back(&vol, &v);
    let max = match h.codes {
        cdvol::format::CodeEncoding::IntRange { max, .. } => max,
        ref c => panic!("{c:?}"),
    };
    assert_eq!(rb.codes, expected_codes(&chessboard_bfs(&obj, cells), max));
    assert!(rb.checked_one_cells > 1000, "{}", rb.checked_one_cells);
    // Every sample's label, codes and uniform bricks included.
    let api = cdvol::Volume::open(vol.path()).unwrap();
    let values = api
        .export(cdvol::export::ExportWhat::Values, &NoProgress)
        .unwrap();
    let want: Vec<u8> = v.iter().map(|&x| x as u8).collect();
    assert_eq!(values, want);
}

/// An orthographic camera along `dir` over the whole volume, 96 pixels
/// square.
fn camera(dir: [f64; 3]) -> Camera {
    let [xs, ys, zs] = positions();
    let lo = DVec3::new(xs[0], ys[0], zs[0]);
    let hi = DVec3::new(xs[DIMS[0] - 1], ys[DIMS[1] - 1], zs[DIMS[2] - 1]);
    let c = 0.5 * (lo + hi);
    let d = DVec3::from_array(dir).normalize();
    let up = if d.z.abs() > 0.9 { DVec3::Y } else { DVec3::Z };
    let ortho = cdvol::render::view::camera::Projection::Ortho { frame_mm: 52.0 };
    Camera::look_at(
        (c - 100.0 * d).to_array(),
        c.to_array(),
        up.to_array(),
        ortho,
        96,
        96,
    )
    .unwrap()
}

/// The depth and coverage of each pixel of a label render, row by row.
fn draw(vol: &PackedVolume, cam: &Camera, spec: &str, hit: HitMethod) -> (Vec<f32>, Vec<f32>) {
    let style = LabelStyle::parse(spec, vol.header().labels.as_ref().unwrap(), None).unwrap();
    draw_style(vol, cam, style, hit)
}

fn draw_style(
    vol: &PackedVolume,
    cam: &Camera,
    style: LabelStyle,
    hit: HitMethod,
) -> (Vec<f32>, Vec<f32>) {
    let mode = Mode::Labels {
        hit,
        style: std::sync::Arc::new(style),
    };
    let opts = test_opts(mode, Method::Cd { min_leap: 1 });
    let part = render_part(vol, cam, &opts, Shard::WHOLE, &NoProgress).unwrap();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (mut depth, mut cover) = (vec![f32::NAN; w * h], vec![0.0; w * h]);
    for t in &part.tiles {
        for (i, (d, a)) in t.depths().into_iter().zip(t.coverage()).enumerate() {
            let (x, y) = (
                t.x0 as usize + i % t.w as usize,
                t.y0 as usize + i / t.w as usize,
            );
            depth[y * w + x] = d;
            cover[y * w + x] = a;
        }
    }
    (depth, cover)
}

/// Where `ray` enters the sphere `(c, r)`, with the cosine of its angle to
/// the surface's normal there; `None` when it misses.
fn enters(o: DVec3, d: DVec3, c: [f64; 3], r: f64) -> Option<(f64, f64)> {
    let oc = o - DVec3::from_array(c);
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - r * r);
    (disc >= 0.0).then(|| {
        let t = -b - disc.sqrt();
        let n = (o + t * d - DVec3::from_array(c)) / r;
        (t, -n.dot(d))
    })
}

#[test]
fn each_label_surface_lies_on_its_sphere() {
    let d = tempfile::tempdir().unwrap();
    let (_, vol) = prepared(d.path());
    let mut report = Vec::new();
    for dir in [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, -0.5, 0.62]] {
        let cam = camera(dir);
        for &(id, c, r) in &SPHERES {
            let (depth, _) = draw(&vol, &cam, &id.to_string(), HitMethod::Exact);
            let (mut n, mut sum, mut worst) = (0usize, 0.0f64, 0.0f64);
            for py in 0..cam.height {
                for px in 0..cam.width {
                    let ray = cam.ray(px, py);
                    let got = depth[(py * cam.width + px) as usize];
                    match enters(ray.origin, ray.dir, c, r) {
                        // Off the rim, where a sample more or less
                        // decides, both may hit or miss.
                        Some((t, cos)) if cos > 0.5 => {
                            assert!(
                                got.is_finite(),
                                "label {id} from {dir:?}: pixel ({px}, {py}) misses"
                            );
                            let e = (got as f64 - t).abs();
                            n += 1;
                            sum += e;
                            worst = worst.max(e);
                        }
                        Some(_) => {}
                        None => {
                            // Well off the sphere, nothing of this label.
                            let o = ray.origin - DVec3::from_array(c);
                            let miss = (o - o.dot(ray.dir) * ray.dir).length() - r;
                            if miss > 2.0 {
                                assert!(
                                    got.is_nan(),
                                    "label {id} from {dir:?}: pixel ({px}, {py}) {miss} mm off \
                                     the sphere hits at {got}"
                                );
                            }
                        }
                    }
                }
            }
            assert!(n > 50, "label {id}: {n} pixels");
            let mean = sum / n as f64;
            report.push(format!("{id} {dir:?}: mean {mean:.3} max {worst:.3} mm"));
            // Samples are 1 to 1.7 mm apart and the surface lies between
            // a sample of the label and one outside it; measured: at most
            // 1.19 mm off, 0.16 to 0.30 mm on average.
            assert!(worst <= 1.3, "label {id} from {dir:?}: off by {worst} mm");
            assert!(
                mean <= 0.35,
                "label {id} from {dir:?}: {mean} mm off on average"
            );
        }
    }
    eprintln!("{}", report.join("\n"));
}

#[test]
fn translucent_labels_show_what_lies_inside_them() {
    let d = tempfile::tempdir().unwrap();
    let (_, vol) = prepared(d.path());
    let cam = camera([0.0, 0.0, 1.0]);
    let table = cdvol::labels::LabelTable {
        labels: vec![cdvol::labels::LabelEntry {
            id: 1,
            name: "shell".into(),
            color: [1.0, 0.5, 0.5],
            opacity: 0.3,
        }],
    };
    let info = vol.header().labels.clone().unwrap();
    let style = LabelStyle::parse("1,4", &info, Some(&table)).unwrap();
    let (depth, cover) = draw_style(&vol, &cam, style, HitMethod::Exact);
    let (d1, _) = draw(&vol, &cam, "1", HitMethod::Exact);
    let (mut inner, mut shell) = (0, 0);
    for py in 0..cam.height {
        for px in 0..cam.width {
            let ray = cam.ray(px, py);
            let i = (py * cam.width + px) as usize;
            let (_, c1, r1) = SPHERES[1];
            let (_, c4, r4) = SPHERES[0];
            let on1 = enters(ray.origin, ray.dir, c1, r1 - 2.0).is_some();
            let on4 = enters(ray.origin, ray.dir, c4, r4 - 1.5).is_some();
            let off4 = enters(ray.origin, ray.dir, c4, r4 + 1.5).is_none();
            if on4 {
                // Through the shell onto the opaque core: covered.
                assert!((cover[i] - 1.0).abs() < 1e-6, "({px}, {py}): {}", cover[i]);
                inner += 1;
            } else if on1 && off4 {
                // The shell alone, entered once.
                assert!((cover[i] - 0.3).abs() < 1e-6, "({px}, {py}): {}", cover[i]);
                shell += 1;
            }
            // The first surface is the shell's either way.
            if on1 {
                assert_eq!(depth[i].to_bits(), d1[i].to_bits(), "({px}, {py})");
            }
        }
    }
    assert!(inner > 20 && shell > 100, "{inner} {shell}");
}

#[test]
fn bad_label_inputs_are_refused_by_name_and_nothing_is_written() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    let out = p.join("out.cdv");
    let prep_labels = |input: &Path| {
        fails(
            cdvol()
                .args(["-q", "prep", "--labels"])
                .arg(input)
                .arg("-o")
                .arg(&out),
        )
    };
    // Not integers.
    let (_, f32s) = phantom(p, "f32");
    let e = prep_labels(&f32s);
    assert!(
        e.contains("seg.json") && e.contains("dtype") && e.contains("integer"),
        "{e}"
    );
    // A negative label, a label above 65535.
    let dims = [3, 3, 3];
    let mut v = vec![0.0; 27];
    v[13] = -2.0;
    let ax = "1.0";
    let neg = write_stack(p, "neg", dims, "i16", &v, [ax, ax, ax], "");
    let e = prep_labels(&neg);
    assert!(
        e.contains("neg.json") && e.contains("value -2 at sample (1, 1, 1)"),
        "{e}"
    );
    v[13] = 70000.0;
    let big = write_stack(p, "big", dims, "u32", &v, [ax, ax, ax], "");
    let e = prep_labels(&big);
    assert!(e.contains("value 70000") && e.contains("0..=65535"), "{e}");
    // Rescaled.
    v[13] = 3.0;
    let scaled = write_stack(
        p,
        "scaled",
        dims,
        "u8",
        &v,
        [ax, ax, ax],
        r#", "rescale": {"slope": 2.0, "intercept": 0}"#,
    );
    let e = prep_labels(&scaled);
    assert!(e.contains("rescale") && e.contains("slope 2"), "{e}");
    // A colour table that does not parse.
    let lut = p.join("bad.txt");
    std::fs::write(&lut, "1 skin 255 0 0 0\n2 bone 255 255 x 0\n").unwrap();
    let (_, u8s) = phantom(p, "u8");
    let e = fails(
        cdvol()
            .args(["-q", "prep", "--labels", "--lut"])
            .arg(&lut)
            .arg(&u8s)
            .arg("-o")
            .arg(&out),
    );
    assert!(
        e.contains("bad.txt") && e.contains("line 2: field B"),
        "{e}"
    );
    assert!(!out.exists());
    // Labels of a file that has none, labels the file does not hold.
    let seg = p.join("seg.cdv");
    ok(cdvol()
        .args(["-q", "prep", "--labels"])
        .arg(&u8s)
        .arg("-o")
        .arg(&seg));
    let plain = p.join("plain.cdv");
    ok(cdvol()
        .args(["-q", "prep", "--iso", "0.5"])
        .arg(&u8s)
        .arg("-o")
        .arg(&plain));
    let png = p.join("x.png");
    let render = |file: &Path, extra: &[&str]| {
        fails(
            cdvol()
                .args(["-q", "render"])
                .arg(file)
                .args(extra)
                .arg("-o")
                .arg(&png),
        )
    };
    let e = render(&plain, &["--labels", "1"]);
    assert!(
        e.contains("plain.cdv") && e.contains("prep --labels"),
        "{e}"
    );
    let e = render(&seg, &["--labels", "7"]);
    assert!(
        e.contains("label 7 does not occur") && e.contains("1, 2, 3, 4"),
        "{e}"
    );
    let e = render(&seg, &["--labels", "skin"]);
    assert!(e.contains("--lut"), "{e}");
    assert!(!png.exists());
    // A label file renders its labels by default, and by name with a
    // table.
    let good = p.join("good.json");
    std::fs::write(
        &good,
        r#"{"labels": [{"id": 2, "name": "left", "color": [0, 0, 1]}, {"id": 3, "name": "right", "color": [0, 1, 0]}]}"#,
    )
    .unwrap();
    ok(cdvol().args(["-q", "render"]).arg(&seg).arg("-o").arg(&png));
    assert!(png.exists());
    ok(cdvol()
        .args(["-q", "render", "--labels", "left,right", "--lut"])
        .arg(&good)
        .arg(&seg)
        .arg("-o")
        .arg(p.join("named.png")));
}

/// A scan on the phantom's grid: 1000 in a lid over `x < 20` mm at the
/// top of the volume (`z > 24` mm), 0 elsewhere.
fn lidded_scan(dir: &Path) -> PackedVolume {
    let [xs, ys, zs] = positions();
    let mut v = Vec::new();
    for z in &zs {
        for _ in &ys {
            for x in &xs {
                v.push(if *x < 20.0 && *z > 24.0 { 1000.0 } else { 0.0 });
            }
        }
    }
    let ax = [axis_json(&xs), axis_json(&ys), axis_json(&zs)];
    let input = write_stack(dir, "scan", DIMS, "i16", &v, [&ax[0], &ax[1], &ax[2]], "");
    crate::common::packed(&input, &dir.join("scan.cdv"), 500.0)
}

#[test]
fn labels_over_a_scan_are_hidden_by_what_lies_in_front_of_them() {
    let d = tempfile::tempdir().unwrap();
    let (_, labels) = prepared(d.path());
    let scan = lidded_scan(d.path());
    // Looking down -z: the lid hides spheres 2 and 3, not 1.
    let cam = camera([0.0, 0.0, -1.0]);
    let info = labels.header().labels.clone().unwrap();
    let style = std::sync::Arc::new(LabelStyle::parse("all", &info, None).unwrap());
    let surface = Mode::Surface {
        hit: HitMethod::Exact,
        shadows: false,
    };
    let alone = test_opts(surface.clone(), Method::Cd { min_leap: 1 });
    let mut with = alone.clone();
    with.overlay = Some(cdvol::render::Overlay::new(
        labels.clone(),
        (*style).clone(),
        HitMethod::Exact,
        64 << 20,
    ));
    let depths = |vol: &PackedVolume, opts: &cdvol::render::RenderOptions| {
        let part = render_part(vol, &cam, opts, Shard::WHOLE, &NoProgress).unwrap();
        let w = cam.width as usize;
        let mut out = vec![f32::NAN; w * cam.height as usize];
        for t in &part.tiles {
            for (i, dd) in t.depths().into_iter().enumerate() {
                out[(t.y0 as usize + i / t.w as usize) * w + t.x0 as usize + i % t.w as usize] = dd;
            }
        }
        out
    };
    let frame = |vol: &PackedVolume, opts: &cdvol::render::RenderOptions| {
        cdvol::render::render(vol, &cam, opts, &NoProgress)
            .unwrap()
            .0
    };
    let (scan_d, lab_d) = (
        depths(&scan, &alone),
        draw_style(&labels, &cam, (*style).clone(), HitMethod::Exact).0,
    );
    let both_d = depths(&scan, &with);
    let (scan_f, both_f) = (frame(&scan, &alone), frame(&scan, &with));
    let lab_f = frame(
        &labels,
        &test_opts(
            Mode::Labels {
                hit: HitMethod::Exact,
                style,
            },
            Method::Cd { min_leap: 1 },
        ),
    );
    let (mut hidden, mut shown) = (0, 0);
    for i in 0..both_d.len() {
        let (s, l) = (scan_d[i], lab_d[i]);
        let px = |f: &cdvol::render::Frame| f.rgb[3 * i..3 * i + 3].to_vec();
        if s.is_finite() && (l.is_nan() || l >= s) {
            // The scan's surface is in front: it alone is drawn.
            assert_eq!(both_d[i].to_bits(), s.to_bits(), "pixel {i}");
            assert_eq!(px(&both_f), px(&scan_f), "pixel {i}");
            hidden += l.is_finite() as u32;
        } else if l.is_finite() {
            // The label is in front of (or without) any scan surface.
            assert_eq!(both_d[i].to_bits(), l.to_bits(), "pixel {i}");
            assert_eq!(px(&both_f), px(&lab_f), "pixel {i}");
            shown += 1;
        } else {
            assert!(both_d[i].is_nan(), "pixel {i}");
        }
    }
    // Spheres 2 and 3 lie under the lid; spheres 1 and 4 are seen.
    assert!(
        hidden > 300 && shown > 300,
        "{hidden} hidden, {shown} shown"
    );

    // Grids that differ are refused, naming both.
    let other = {
        let dd = d.path().join("o");
        std::fs::create_dir_all(&dd).unwrap();
        let v = vec![0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let input = write_stack(&dd, "o", [2, 2, 2], "u8", &v, ["1.0", "1.0", "1.0"], "");
        let out = dd.join("o.cdv");
        let src = cdvol::input::open(&input).unwrap();
        let mut o = PrepOptions::new(cdvol::classify::Classification::Iso { iso: 0.0 });
        o.labels = true;
        prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
        PackedVolume::open(&out).unwrap()
    };
    let info = other.header().labels.clone().unwrap();
    with.overlay = Some(cdvol::render::Overlay::new(
        other,
        LabelStyle::parse("all", &info, None).unwrap(),
        HitMethod::Exact,
        64 << 20,
    ));
    let e = cdvol::render::render(&scan, &cam, &with, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("o.cdv")
            && e.contains("2 x 2 x 2 samples")
            && e.contains("46 x 36 x 26 samples")
            && e.contains("(rectilinear z)"),
        "{e}"
    );
}

/// Every exact traversal draws the same label image, translucent labels,
/// a clip and a crop included: they visit the same 1-cells (FVT, one cell
/// at a time, is the reference).
#[test]
fn every_exact_traversal_draws_the_same_labels() {
    let d = tempfile::tempdir().unwrap();
    let (_, input) = phantom(d.path(), "u8");
    let out = d.path().join("aniso.cdv");
    let src = cdvol::input::open(&input).unwrap();
    let mut o = PrepOptions::new(cdvol::classify::Classification::Iso { iso: 0.0 });
    o.labels = true;
    o.brick_size = 8;
    o.aniso = true;
    prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
    let vol = cdvol::Volume::open(&out).unwrap();
    let table = d.path().join("t.json");
    std::fs::write(
        &table,
        r#"{"labels": [{"id": 1, "name": "shell", "color": [1, 0.6, 0.5], "opacity": 0.4}]}"#,
    )
    .unwrap();
    let methods = [
        Method::Fvt,
        Method::Cd { min_leap: 1 },
        Method::CdAniso { min_leap: 1 },
        Method::Octree,
    ];
    let cut = cdvol::render::clip::Clip {
        crop: Some([[2.0, 44.0], [1.0, 36.0], [0.5, 30.0]]),
        planes: vec![cdvol::render::clip::Plane {
            normal: [0.4, -0.3, 0.85],
            d: 5.0,
        }],
    };
    for clip in [cdvol::render::clip::Clip::default(), cut] {
        for (az, el) in [(30.0, 20.0), (200.0, -40.0), (95.0, 75.0)] {
            let view = cdvol::View::orbit(az, el, 64, 56);
            let images: Vec<cdvol::Image> = methods
                .iter()
                .map(|&m| {
                    let mut l = cdvol::Look::default();
                    l.ask.labels = Some("all".into());
                    l.ask.lut = Some(cdvol::labels::LabelTable::load(&table).unwrap());
                    l.method = Some(m);
                    l.clip = clip.clone();
                    vol.renderer().render(&view, &l).unwrap()
                })
                .collect();
            assert!(
                images[0].frame.alpha.iter().any(|&x| x > 0),
                "{az},{el}: drawn"
            );
            for (m, im) in methods.iter().zip(&images).skip(1) {
                assert!(
                    im.frame.rgb == images[0].frame.rgb && im.frame.alpha == images[0].frame.alpha,
                    "{az},{el} {clip:?}: {m:?} differs from FVT"
                );
            }
        }
    }
}
