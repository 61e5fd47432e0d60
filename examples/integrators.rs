//! The accuracy harness of the composite and MIP integrators
//! (docs/TRADEOFFS.md, "Integrators"; tools/integrators.sh runs it).
//!
//! `cargo run --release --example integrators -- CT.cdv MR.cdv SIZE OUT_DIR [ONLY]`,
//! or `-- --plot OUT_DIR` to redraw the plot from the CSV (and
//! OUT_DIR/integrators-vtk.csv, VTK's rows, when it is there).
//!
//! For every transfer function (each CT composite preset on CT.cdv, one
//! deliberately sharp peak and the peers' skin-bone function on CT.cdv,
//! `mr-default` on MR.cdv) and eight
//! views (oblique ones included), renders the f64 reference
//! (`Integrate::Reference`, 1/64-cell substeps, no early stop) and each
//! integrator: steps of 1, 0.5, 0.25 and 0.125 mm, and segments at four
//! tolerances (the default among them). The MIP (`ct-mip`, `mr-mip`) takes the reference, the face
//! samples (`step`) and the exact maximum (`segment`). Per image, over
//! the pixels either image covers: mean, RMSE, 99th percentile and
//! maximum of |difference| in grey levels (0-255, the largest channel,
//! before rounding); per integrator the warm frame time (best of 3).
//! The reference's convergence: the same at 128 substeps against 64.
//!
//! Writes OUT_DIR/integrators.csv (one row per image) and
//! OUT_DIR/integrators.svg (p99 error against time, one point per
//! integrator and transfer function), and prints the summary table.
//!
//! With `INTEGRATORS_EXPORT=DIR`, also writes each composite reference
//! for other renderers to be measured against it
//! (tools/peers/vtk_integrators.py puts VTK through the same metrics):
//! `DIR/NN-V.f32`, the image as f32 RGBA over black, row by row from the
//! top, and `DIR/NN-V.json`, the case, the file, the camera the view was
//! placed at and the transfer function with its look.

use std::error::Error;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use cdvol::classify::{TfPoint, TransferFunction};
use cdvol::look::ModeKind;
use cdvol::render::{Background, CompositeLook, Integrate};
use cdvol::{Look, View, Volume};

/// The eight views: azimuth, elevation in degrees.
const VIEWS: [(f64, f64); 8] = [
    (0.0, 0.0),
    (45.0, 20.0),
    (90.0, 0.0),
    (150.0, 20.0),
    (200.0, -30.0),
    (270.0, 45.0),
    (315.0, -15.0),
    (30.0, 70.0),
];

/// A transfer function of the harness: its name, file and look.
struct Case {
    name: String,
    file: usize,
    look: Look,
    mip: bool,
}

fn integrators(mip: bool) -> Vec<(String, Look)> {
    let step = |mm: f64| {
        let mut l = Look {
            integrate: Some(Integrate::Step),
            ..Look::default()
        };
        l.ask.step_mm = mm;
        (format!("step {mm} mm"), l)
    };
    let seg = |tol: f64| {
        let l = Look {
            integrate: Some(Integrate::Segment { tol }),
            ..Look::default()
        };
        (format!("segment tol {tol}"), l)
    };
    if mip {
        let (mut faces, mut exact) = (Look::default(), Look::default());
        faces.integrate = Some(Integrate::Step);
        exact.integrate = Some(Integrate::Segment {
            tol: Integrate::SEGMENT_TOL,
        });
        return vec![("faces".into(), faces), ("exact".into(), exact)];
    }
    vec![
        step(1.0),
        step(0.5),
        step(0.25),
        step(0.125),
        seg(0.5),
        seg(0.05),
        seg(Integrate::SEGMENT_TOL),
        seg(0.005),
    ]
}

/// `base` with the integration of `how`.
fn with(base: &Look, how: &Look) -> Look {
    let mut l = base.clone();
    l.integrate = how.integrate;
    l.ask.step_mm = how.ask.step_mm;
    l.unrounded = true;
    l
}

/// Mean, RMSE, p99 and max of |a - b| in grey levels over pixels either
/// covers, and how many.
fn metrics(a: &[f32], b: &[f32]) -> [f64; 5] {
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
    if d.is_empty() {
        return [0.0; 5];
    }
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let rmse = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    d.sort_by(f64::total_cmp);
    let p99 = d[((n * 0.99) as usize).min(d.len() - 1)];
    [mean, rmse, p99, d[d.len() - 1], n]
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() == 2 && args[0] == "--plot" {
        // Redraw OUT_DIR/integrators.svg from OUT_DIR/integrators.csv.
        return replot(&PathBuf::from(&args[1]));
    }
    if args.len() < 4 {
        return Err("usage: integrators CT.cdv MR.cdv SIZE OUT_DIR".into());
    }
    let vols = [
        Volume::open(&PathBuf::from(&args[0]))?,
        Volume::open(&PathBuf::from(&args[1]))?,
    ];
    let size: u32 = args[2].parse()?;
    let out = PathBuf::from(&args[3]);
    let renderers = [vols[0].renderer(), vols[1].renderer()];
    // An optional fifth argument keeps the functions whose name holds it.
    let only = args.get(4).cloned().unwrap_or_default();

    let mut cases = Vec::new();
    for p in [
        "ct-bone",
        "ct-skin",
        "ct-soft-tissue",
        "ct-muscle",
        "ct-lung",
        "ct-vessels",
    ] {
        cases.push(Case {
            name: p.into(),
            file: 0,
            look: Look::preset_in(p, ModeKind::Composite),
            mip: false,
        });
    }
    // A sharp peak: opaque white only within 10 HU of 300 HU.
    let point = |value: f64, opacity: f64| TfPoint {
        value,
        opacity,
        color: [1.0, 0.95, 0.85],
    };
    let mut peak = Look::default();
    peak.ask.mode = Some(ModeKind::Composite);
    peak.ask.tf = Some((
        TransferFunction {
            points: vec![point(290.0, 0.0), point(300.0, 0.9), point(310.0, 0.0)],
        },
        CompositeLook::default(),
    ));
    cases.push(Case {
        name: "sharp peak 290-310 HU".into(),
        file: 0,
        look: peak,
        mip: false,
    });
    // The peers' function (tools/peers/skin-bone-tf.json, unshaded): the
    // one `tools/peers/run.sh` times against VTK.
    let peers =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/peers/skin-bone-tf.json");
    let mut skin_bone = Look::default();
    skin_bone.ask.mode = Some(ModeKind::Composite);
    skin_bone.ask.tf = Some((TransferFunction::load(&peers)?, CompositeLook::default()));
    cases.push(Case {
        name: "peers skin-bone".into(),
        file: 0,
        look: skin_bone,
        mip: false,
    });
    cases.push(Case {
        name: "mr-default (MR)".into(),
        file: 1,
        look: Look::preset_in("mr-default", ModeKind::Composite),
        mip: false,
    });
    for (p, file) in [("ct-mip", 0), ("mr-mip", 1)] {
        cases.push(Case {
            name: format!("{p}{}", if file == 1 { " (MR)" } else { "" }),
            file,
            look: Look::preset_in(p, ModeKind::Mip),
            mip: true,
        });
    }

    let reference = |substeps| Look {
        integrate: Some(Integrate::Reference { substeps }),
        ..Look::default()
    };
    let mut csv = std::fs::File::create(out.join("integrators.csv"))?;
    writeln!(
        csv,
        "function,view,integrator,seconds,mean,rmse,p99,max,pixels"
    )?;
    // Per case and integrator: seconds, mean, rmse, p99, max summed or
    // maxed over views.
    let mut rows: Vec<(String, String, [f64; 5])> = Vec::new();
    let export = std::env::var_os("INTEGRATORS_EXPORT").map(PathBuf::from);
    for (ci, case) in cases
        .iter()
        .enumerate()
        .filter(|c| c.1.name.contains(&only))
    {
        let r = &renderers[case.file];
        let mut sums: Vec<[f64; 5]> = vec![[0.0; 5]; integrators(case.mip).len() + 1];
        for (vi, &(az, el)) in VIEWS.iter().enumerate() {
            let view = View::orbit(az, el, size, size);
            let t = Instant::now();
            let refi = r.render(&view, &with(&case.look, &reference(64)))?;
            let ref_s = t.elapsed().as_secs_f64();
            let refp = refi.rgba_f32(Background::BLACK);
            if let (Some(dir), false) = (&export, case.mip) {
                let opts = r.options(&with(&case.look, &reference(64)))?;
                let tf = match &opts.mode {
                    cdvol::render::Mode::Composite { tf, .. } => tf.clone(),
                    _ => return Err(format!("{}: not a composite", case.name).into()),
                };
                let meta = serde_json::json!({
                    "case": case.name, "file": &args[case.file], "view": [az, el],
                    "size": size, "camera": refi.stats.camera,
                    "points": tf.points, "shade": opts.look.shade,
                    "gradient_opacity": opts.look.gradient_opacity,
                });
                let stem = dir.join(format!("{ci:02}-{vi}"));
                std::fs::write(
                    stem.with_extension("json"),
                    serde_json::to_vec_pretty(&meta)?,
                )?;
                std::fs::write(stem.with_extension("f32"), bytemuck::cast_slice(&refp))?;
            }
            let mut list = integrators(case.mip);
            if vi < 2 {
                // The reference's convergence: twice the substeps.
                list.push(("reference x2".into(), reference(128)));
            }
            for (k, (name, how)) in list.iter().enumerate() {
                let look = with(&case.look, how);
                let runs = if name.starts_with("reference") { 1 } else { 3 };
                let mut best = f64::INFINITY;
                let mut img = None;
                for _ in 0..runs {
                    let t = Instant::now();
                    let i = r.render(&view, &look)?;
                    best = best.min(t.elapsed().as_secs_f64());
                    img = Some(i);
                }
                let Some(img) = img else { continue };
                let m = metrics(&img.rgba_f32(Background::BLACK), &refp);
                writeln!(
                    csv,
                    "{},{az}/{el},{name},{best:.5},{:.4},{:.4},{:.3},{:.3},{}",
                    case.name, m[0], m[1], m[2], m[3], m[4]
                )?;
                let s = &mut sums[k];
                s[0] += best;
                s[1] += m[0];
                s[2] += m[1] * m[1];
                s[3] = s[3].max(m[2]);
                s[4] = s[4].max(m[3]);
            }
            eprintln!("{} view {az},{el}: reference {ref_s:.1} s", case.name);
        }
        for (k, (name, _)) in integrators(case.mip)
            .iter()
            .chain(std::iter::once(&(
                "reference x2".to_string(),
                Look::default(),
            )))
            .enumerate()
        {
            let views = if k == integrators(case.mip).len() {
                2.0
            } else {
                VIEWS.len() as f64
            };
            let s = sums[k];
            rows.push((
                case.name.clone(),
                name.clone(),
                [
                    s[0] / views,
                    s[1] / views,
                    (s[2] / views).sqrt(),
                    s[3],
                    s[4],
                ],
            ));
        }
    }
    println!("| function | integrator | frame s (mean of views) | mean | RMSE | p99 (worst view) | max |");
    println!("|---|---|---|---|---|---|---|");
    for (f, i, s) in &rows {
        println!(
            "| {f} | {i} | {:.4} | {:.3} | {:.3} | {:.2} | {:.1} |",
            s[0], s[1], s[2], s[3], s[4]
        );
    }
    plot(&out.join("integrators.svg"), &rows)?;
    Ok(())
}

/// The plot of the rows in `dir`'s CSV: per function and integrator,
/// the mean time and worst p99 over its views.
fn replot(dir: &std::path::Path) -> Result<(), Box<dyn Error>> {
    let mut text = std::fs::read_to_string(dir.join("integrators.csv"))?;
    // VTK's rows (tools/peers/vtk_integrators.py), when there are some.
    if let Ok(vtk) = std::fs::read_to_string(dir.join("integrators-vtk.csv")) {
        text.extend(vtk.lines().skip(1).map(|l| format!("{l}\n")));
    }
    let mut rows: Vec<(String, String, [f64; 5])> = Vec::new();
    let mut views: Vec<f64> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < 9 {
            return Err(format!("integrators.csv: bad row {line:?}").into());
        }
        let (t, p99): (f64, f64) = (f[3].parse()?, f[6].parse()?);
        match rows.iter().position(|r| r.0 == f[0] && r.1 == f[2]) {
            Some(i) => {
                rows[i].2[0] += t;
                rows[i].2[3] = rows[i].2[3].max(p99);
                views[i] += 1.0;
            }
            None => {
                rows.push((f[0].into(), f[2].into(), [t, 0.0, 0.0, p99, 0.0]));
                views.push(1.0);
            }
        }
    }
    for (r, n) in rows.iter_mut().zip(&views) {
        r.2[0] /= n;
    }
    plot(&dir.join("integrators.svg"), &rows)
}

/// p99 error against frame time, one series per integrator family.
fn plot(path: &std::path::Path, rows: &[(String, String, [f64; 5])]) -> Result<(), Box<dyn Error>> {
    use plotters::prelude::*;
    cdvol::plot::font::register();
    let pts: Vec<_> = rows
        .iter()
        .filter(|r| !r.1.starts_with("reference"))
        .map(|r| (r.2[0].max(1e-4), r.2[3].max(0.05), r.1.clone(), r.0.clone()))
        .collect();
    let (tmax, emax) = pts
        .iter()
        .fold((0.0f64, 0.0f64), |a, p| (a.0.max(p.0), a.1.max(p.1)));
    let tmin = pts.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Composite and MIP integrators: p99 error against the f64 reference (0 drawn at 0.05)",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (tmin * 0.8..tmax * 1.25).log_scale(),
            (0.05..emax * 1.5).log_scale(),
        )?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_y_mesh()
        .x_label_formatter(&|x| format!("{x:.3}"))
        .y_label_formatter(&|y| format!("{y}"))
        .x_desc("frame seconds (mean over 8 views)")
        .y_desc("p99 |error|, grey levels (worst view)")
        .draw()?;
    let families = ["step", "segment", "faces", "exact", "vtk"];
    let colours = [RED, BLUE, MAGENTA, GREEN, BLACK];
    for (f, c) in families.iter().zip(colours) {
        let series: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| p.2.starts_with(f))
            .map(|p| (p.0, p.1))
            .collect();
        chart
            .draw_series(
                series
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 4, c.filled())),
            )?
            .label(*f)
            .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
