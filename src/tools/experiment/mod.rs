//! `cdvol experiment tradeoffs`: the speed/accuracy trade, measured.
//!
//! Renders a sphere phantom (analytic ground truth) and, when given, the
//! real CT with every hit method and traversal precision (surface mode)
//! and every composite step size, and writes a Markdown report
//! (docs/TRADEOFFS.md), a CSV of the same rows and an SVG plot of error
//! against time. Times are medians of several runs, reported as ratios to
//! the fastest setting of the same table (the machines are shared and
//! noisy; ratios measured in one run are what carry over).

pub mod paper;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::classify::{Classification, TfPoint, TransferFunction};
use crate::format::reader::PackedVolume;
use crate::input::raw::RawSource;
use crate::prep::{prep, PrepOptions};
use crate::progress::{NoProgress, Progress};
use crate::render::sample::hit::{HitMethod, HitParams};
use crate::render::traverse::{Method, Ray, TGrid};
use crate::render::view::camera::Camera;
use crate::render::{render, Frame, Mode, Precision, RenderOptions};
use crate::tools::corpus::{self, MemVolume};
use crate::tools::phantom;

/// Options of [`tradeoffs`].
#[derive(Debug, Clone)]
pub struct TradeoffOptions {
    /// The Markdown report; the CSV and SVG go beside it
    /// (`tradeoffs.csv`, `tradeoffs.svg`).
    pub out: PathBuf,
    /// Sidecar of the real CT (tools/fetch-ct.sh); left out: spheres only.
    pub ct: Option<PathBuf>,
    /// Image edge in pixels.
    pub size: u32,
    /// Runs per setting (the median is reported).
    pub runs: usize,
}

/// One measured setting.
#[derive(Debug, Clone)]
pub struct Row {
    pub dataset: &'static str,
    pub kind: &'static str,
    pub setting: String,
    pub precision: &'static str,
    pub median_s: f64,
    /// Median time over the fastest median of the same table.
    pub ratio: f64,
    /// Surface position error in mm (mean, max) and rays that meet the
    /// reference surface squarely but found no hit.
    pub pos_err: Option<(f64, f64, u64)>,
    /// Image RMSE (8-bit levels) and PSNR (dB) against the reference.
    pub rmse: f64,
    pub psnr: f64,
}

#[derive(Clone)]
struct Surface {
    name: &'static str,
    hit: HitMethod,
    params: HitParams,
}

fn surfaces() -> Vec<Surface> {
    let p = HitParams::default();
    let s = |name, hit, params| Surface { name, hit, params };
    vec![
        s("int", HitMethod::Int, p),
        s(
            "bisect-8",
            HitMethod::Bisect,
            HitParams {
                bisect_iters: 8,
                ..p
            },
        ),
        s("bisect-30", HitMethod::Bisect, p),
        s(
            "newton-1",
            HitMethod::Newton,
            HitParams {
                newton_iters: 1,
                ..p
            },
        ),
        s("newton-8", HitMethod::Newton, p),
        s("exact", HitMethod::Exact, p),
    ]
}

/// Composite sample distances in mm, and the reference's.
const STEPS: [f64; 5] = [0.125, 0.25, 0.5, 1.0, 2.0];
const REF_STEP: f64 = 1.0 / 32.0;

const PRECISIONS: [(Precision, &str); 2] = [(Precision::F64, "f64"), (Precision::F32, "f32")];

struct Dataset {
    name: &'static str,
    vol: PackedVolume,
    tf: TransferFunction,
    spheres: Option<Vec<phantom::Sphere>>,
    camera: Camera,
}

/// Runs the experiment and writes the report; returns the rows.
pub fn tradeoffs(o: &TradeoffOptions, progress: &dyn Progress) -> anyhow::Result<Vec<Row>> {
    anyhow::ensure!(o.runs >= 1, "runs 0: expected at least 1");
    anyhow::ensure!(
        (16..=4096).contains(&o.size),
        "size {}: expected 16..=4096 pixels",
        o.size
    );
    let work = tempfile::tempdir()?;
    let mut sets = Vec::new();

    // The sphere phantom: 5^3 spheres on a 128^3 grid, z gaps growing
    // from 0.8 to 2 mm (rectilinear), samples a ramp of the distance.
    let side = work.path().join("spheres.json");
    let info = phantom::spheres(
        &side,
        &phantom::SpheresOptions {
            size: 128,
            per_axis: 5,
            seed: 7,
            spacing: phantom::parse_spacing3("1,1,0.8:2")?,
        },
        &NoProgress,
    )?;
    let vol = packed(&side, &work.path().join("spheres.cdv"), info.iso)?;
    sets.push(Dataset {
        name: "spheres",
        camera: camera(&vol, o.size)?,
        tf: ramp(info.iso, 2000.0),
        spheres: Some(info.spheres),
        vol,
    });
    if let Some(ct) = &o.ct {
        // Bone at 150 HU and above.
        let iso = 150.0;
        let vol = packed(ct, &work.path().join("ct.cdv"), iso)?;
        sets.push(Dataset {
            name: "ct",
            camera: camera(&vol, o.size)?,
            tf: ramp(iso, 1500.0),
            spheres: None,
            vol,
        });
    }

    let per_set = (surfaces().len() * (o.runs + 1) + STEPS.len() * o.runs + 2) * 2;
    progress.begin("tradeoffs", (per_set * sets.len()) as u64);
    let mut rows = Vec::new();
    for d in &sets {
        rows.extend(surface_rows(d, o, progress)?);
        rows.extend(composite_rows(d, o, progress)?);
    }
    progress.end();

    let diffs = f32_corpus_diffs();
    let dir = match o.out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let csv = dir.join("tradeoffs.csv");
    let svg = dir.join("tradeoffs.svg");
    write_atomic(&csv, to_csv(&rows).as_bytes())?;
    let svg_text = plot(&rows)?;
    write_atomic(&svg, svg_text.as_bytes())?;
    write_atomic(&o.out, report(&rows, o, &diffs).as_bytes())?;
    Ok(rows)
}

fn packed(sidecar: &Path, out: &Path, iso: f64) -> anyhow::Result<PackedVolume> {
    let src = RawSource::open(sidecar)?;
    prep(
        &src,
        out,
        &PrepOptions::new(Classification::Iso { iso }),
        &NoProgress,
    )?;
    Ok(PackedVolume::open(out)?)
}

fn camera(vol: &PackedVolume, size: u32) -> anyhow::Result<Camera> {
    let g = TGrid::<f64>::new(&vol.header().axes);
    Camera::orbit(g.bounds(), 30.0, 20.0, None, None, size, size).map_err(anyhow::Error::msg)
}

/// Transparent below `iso`, rising to 0.6 per mm at `hi`.
fn ramp(iso: f64, hi: f64) -> TransferFunction {
    TransferFunction {
        points: vec![
            TfPoint {
                value: iso,
                opacity: 0.0,
                color: [1.0, 0.85, 0.7],
            },
            TfPoint {
                value: hi,
                opacity: 0.6,
                color: [1.0, 1.0, 1.0],
            },
        ],
    }
}

fn opts(mode: Mode, precision: Precision, hit_params: HitParams) -> RenderOptions {
    RenderOptions {
        precision,
        hit_params,
        // The paper's figures count the steps of every ray.
        cull: false,
        ..RenderOptions::new(mode, Method::Cd { min_leap: 1 })
    }
}

/// Median wall time of `runs` renders of every setting, and each
/// setting's frame. The settings take turns (one render of each per
/// round), so a slow spell of the shared machine hits them all alike.
fn timed(
    d: &Dataset,
    settings: &[RenderOptions],
    runs: usize,
    progress: &dyn Progress,
) -> anyhow::Result<Vec<(f64, Frame)>> {
    let mut times = vec![Vec::with_capacity(runs); settings.len()];
    let mut frames: Vec<Option<Frame>> = vec![None; settings.len()];
    for _ in 0..runs {
        for (i, o) in settings.iter().enumerate() {
            let t0 = Instant::now();
            let (f, _) = render(&d.vol, &d.camera, o, &NoProgress)?;
            times[i].push(t0.elapsed().as_secs_f64());
            frames[i] = Some(f);
            progress.advance(1);
        }
    }
    Ok(times
        .into_iter()
        .zip(frames)
        .map(|(mut t, f)| {
            t.sort_by(f64::total_cmp);
            (t[t.len() / 2], f.expect("runs >= 1"))
        })
        .collect())
}

fn surface_rows(d: &Dataset, o: &TradeoffOptions, pr: &dyn Progress) -> anyhow::Result<Vec<Row>> {
    let exact = |p| {
        opts(
            Mode::Surface {
                hit: HitMethod::Exact,
                shadows: false,
            },
            p,
            HitParams::default(),
        )
    };
    let (reference, _) = render(&d.vol, &d.camera, &exact(Precision::F64), &NoProgress)?;
    let ref_depth = render(
        &d.vol,
        &d.camera,
        &opts(
            Mode::Depth {
                hit: HitMethod::Exact,
            },
            Precision::F64,
            HitParams::default(),
        ),
        &NoProgress,
    )?
    .0
    .depth
    .unwrap_or_default();
    pr.advance(2);
    let combos: Vec<(Surface, Precision, &str)> = surfaces()
        .into_iter()
        .flat_map(|s| PRECISIONS.map(|(p, pn)| (s.clone(), p, pn)))
        .collect();
    let settings: Vec<RenderOptions> = combos
        .iter()
        .map(|(s, p, _)| {
            opts(
                Mode::Surface {
                    hit: s.hit,
                    shadows: false,
                },
                *p,
                s.params,
            )
        })
        .collect();
    let measured = timed(d, &settings, o.runs, pr)?;
    let mut rows = Vec::new();
    for ((s, p, pn), (t, frame)) in combos.into_iter().zip(measured) {
        {
            let depth_o = opts(Mode::Depth { hit: s.hit }, p, s.params);
            let depth = render(&d.vol, &d.camera, &depth_o, &NoProgress)?
                .0
                .depth
                .unwrap_or_default();
            pr.advance(1);
            let pos_err = match &d.spheres {
                Some(sp) => analytic_error(&d.camera, sp, &depth),
                None => depth_error(&ref_depth, &depth),
            };
            let (rmse, psnr) = rmse_psnr(&reference.rgb, &frame.rgb);
            rows.push(Row {
                dataset: d.name,
                kind: "surface",
                setting: s.name.to_string(),
                precision: pn,
                median_s: t,
                ratio: 0.0,
                pos_err: Some(pos_err),
                rmse,
                psnr,
            });
        }
    }
    set_ratios(&mut rows);
    Ok(rows)
}

fn composite_rows(d: &Dataset, o: &TradeoffOptions, pr: &dyn Progress) -> anyhow::Result<Vec<Row>> {
    // The step integrator's rows (docs/TRADEOFFS.md, "Integrators",
    // measures the segments against the f64 reference).
    let comp = |step_mm, p| RenderOptions {
        integrate: crate::render::Integrate::Step,
        ..opts(
            Mode::Composite {
                tf: d.tf.clone(),
                step_mm,
            },
            p,
            HitParams::default(),
        )
    };
    let (reference, _) = render(
        &d.vol,
        &d.camera,
        &comp(REF_STEP, Precision::F64),
        &NoProgress,
    )?;
    let combos: Vec<(f64, Precision, &str)> = STEPS
        .iter()
        .flat_map(|&step| PRECISIONS.map(|(p, pn)| (step, p, pn)))
        .collect();
    let settings: Vec<RenderOptions> = combos.iter().map(|&(st, p, _)| comp(st, p)).collect();
    let measured = timed(d, &settings, o.runs, pr)?;
    let mut rows = Vec::new();
    for ((step, _, pn), (t, frame)) in combos.into_iter().zip(measured) {
        {
            let (rmse, psnr) = rmse_psnr(&reference.rgb, &frame.rgb);
            rows.push(Row {
                dataset: d.name,
                kind: "composite",
                setting: format!("step {step} mm"),
                precision: pn,
                median_s: t,
                ratio: 0.0,
                pos_err: None,
                rmse,
                psnr,
            });
        }
    }
    set_ratios(&mut rows);
    Ok(rows)
}

fn set_ratios(rows: &mut [Row]) {
    let fastest = rows
        .iter()
        .map(|r| r.median_s)
        .fold(f64::INFINITY, f64::min);
    for r in rows {
        r.ratio = r.median_s / fastest;
    }
}

/// Depth against the analytic spheres, over rays that meet a sphere
/// squarely (cosine of incidence > 0.3: at grazing incidence a sub-voxel
/// offset of the sampled surface moves the hit by millimetres, which
/// measures the phantom, not the hit method). Mean, max, and such rays
/// that found no hit.
fn analytic_error(cam: &Camera, spheres: &[phantom::Sphere], depth: &[f32]) -> (f64, f64, u64) {
    let mut err = DepthErr::default();
    for py in 0..cam.height {
        for px in 0..cam.width {
            let r: Ray = cam.ray(px, py);
            let mut best: Option<(f64, f64)> = None;
            for s in spheres {
                let oc: [f64; 3] = std::array::from_fn(|k| r.origin[k] - s.center[k]);
                let b: f64 = (0..3).map(|k| oc[k] * r.dir[k]).sum();
                let c: f64 = (0..3).map(|k| oc[k] * oc[k]).sum::<f64>() - s.radius * s.radius;
                let disc = b * b - c;
                if disc > 0.0 {
                    let t = -b - disc.sqrt();
                    if best.is_none_or(|(bt, _)| t < bt) {
                        best = Some((t, disc.sqrt() / s.radius));
                    }
                }
            }
            if let Some((t, cos)) = best {
                if cos > 0.3 {
                    err.add(t, depth[(py * cam.width + px) as usize]);
                }
            }
        }
    }
    err.result()
}

/// Depth errors against a reference: mean, max, and references missed.
#[derive(Default)]
struct DepthErr {
    n: u64,
    sum: f64,
    max: f64,
    missed: u64,
}

impl DepthErr {
    /// One pixel whose reference depth is `want`; a non-finite `got` is
    /// a miss.
    fn add(&mut self, want: f64, got: f32) {
        if got.is_finite() {
            let e = (got as f64 - want).abs();
            self.n += 1;
            self.sum += e;
            self.max = self.max.max(e);
        } else {
            self.missed += 1;
        }
    }

    fn result(&self) -> (f64, f64, u64) {
        (self.sum / self.n.max(1) as f64, self.max, self.missed)
    }
}

/// Depth against the reference depth, over pixels where the reference
/// hits; a reference hit without a hit here counts as missed.
fn depth_error(reference: &[f32], depth: &[f32]) -> (f64, f64, u64) {
    let mut err = DepthErr::default();
    for (r, d) in reference.iter().zip(depth) {
        if r.is_finite() {
            err.add(*r as f64, *d);
        }
    }
    err.result()
}

/// RMSE in 8-bit levels and PSNR in dB (infinite when identical).
fn rmse_psnr(a: &[u8], b: &[u8]) -> (f64, f64) {
    let se: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum();
    let rmse = (se / a.len().max(1) as f64).sqrt();
    (rmse, 20.0 * (255.0 / rmse).log10())
}

/// f32 against f64 on the named corpus of src/tools/corpus.rs (FVT): rays, rays
/// whose 1-cell sequence differs, 1-cells f64 visits and f32 misses, rays
/// whose first 1-cell differs.
pub fn f32_corpus_diffs() -> [u64; 4] {
    let mut t = [0u64; 4];
    for g in corpus::grids(false) {
        let n = g.axes.each_ref().map(|a| a.cells() as u32);
        let rays = corpus::rays(&g.axes);
        let (g64, g32) = (TGrid::<f64>::new(&g.axes), TGrid::<f32>::new(&g.axes));
        for (_, objs) in corpus::objects(n) {
            let vol = MemVolume::new(g.axes.clone(), objs);
            for (_, ray) in &rays {
                let cells = |w: corpus::Walked| w.visits.iter().map(|v| v.cell).collect::<Vec<_>>();
                let a = cells(corpus::walk(&vol, &g64, ray, Method::Fvt));
                let b = cells(corpus::walk(&vol, &g32, ray, Method::Fvt));
                t[0] += 1;
                if a != b {
                    t[1] += 1;
                    t[2] += a.iter().filter(|c| !b.contains(c)).count() as u64;
                }
                t[3] += (a.first() != b.first()) as u64;
            }
        }
    }
    t
}

fn to_csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "dataset,kind,setting,precision,median_s,ratio,pos_err_mean_mm,pos_err_max_mm,missed,rmse,psnr_db\n",
    );
    for r in rows {
        let (a, b, m) = r.pos_err.map_or((f64::NAN, f64::NAN, 0), |x| x);
        let _ = writeln!(
            s,
            "{},{},{},{},{:.6},{:.3},{:.5},{:.5},{},{:.4},{:.2}",
            r.dataset, r.kind, r.setting, r.precision, r.median_s, r.ratio, a, b, m, r.rmse, r.psnr
        );
    }
    s
}

fn report(rows: &[Row], o: &TradeoffOptions, diffs: &[u64; 4]) -> String {
    let mut s = String::new();
    let threads = rayon::current_num_threads();
    let _ = writeln!(
        s,
        "# Speed and accuracy: what each setting costs\n\n\
         Produced by `cdvol experiment tradeoffs{}` (tools/tradeoffs.sh) with {} \
         threads, {}x{} images, median of {} runs per setting. Do not edit by hand: \
         rerun the command. Plot: [tradeoffs.svg](tradeoffs.svg) (a zero error, the reference itself, is drawn at 1e-4); rows as CSV: \
         [tradeoffs.csv](tradeoffs.csv).\n",
        o.ct.as_ref()
            .map(|p| format!(" --ct {}", p.display()))
            .unwrap_or_default(),
        threads,
        o.size,
        o.size,
        o.runs
    );
    s.push_str(
        "Times are per frame, from opening the brick cache to the finished image \
         (bricks read and decoded each time from the page-cached file, as a batch \
         render does), as ratios to the fastest setting of the same table (absolute \
         seconds in the CSV); the machine is shared, so only ratios from one run \
         carry over. \
         Traversal: CD (min leap 1). `f32`/`f64` is the arithmetic of the traversal \
         (`--precision`); hits and shading are always f64.\n\n\
         - **spheres**: `phantom spheres` 128^3, 5^3 spheres, x/y gaps 1 mm, z gaps \
         growing from 0.8 to 2 mm (rectilinear), iso 1000. Surface position error is \
         against the analytic spheres, over rays meeting a sphere at cosine > 0.3 \
         (missed = such rays with no hit).\n\
         - **ct**: the invesalius head CT (256x256x108, int16 HU), iso 150 HU (bone). \
         Surface position error is against the `exact`/f64 depth.\n\
         - Image RMSE (8-bit levels) and PSNR are against `exact`/f64 (surface) or \
         composite at step 1/32 mm in f64 (composite).\n\n",
    );
    for ds in ["spheres", "ct"] {
        for kind in ["surface", "composite"] {
            let rs: Vec<&Row> = rows
                .iter()
                .filter(|r| r.dataset == ds && r.kind == kind)
                .collect();
            if rs.is_empty() {
                continue;
            }
            let _ = writeln!(s, "## {ds}: {kind}\n");
            if kind == "surface" {
                s.push_str(
                    "| hit | precision | time (x fastest) | Mrays/s | position error mean / max (mm) | missed | RMSE | PSNR (dB) |\n\
                     |---|---|---|---|---|---|---|---|\n",
                );
            } else {
                s.push_str(
                    "| step | precision | time (x fastest) | Mrays/s | RMSE | PSNR (dB) |\n\
                     |---|---|---|---|---|---|\n",
                );
            }
            for r in rs {
                let mrays = (o.size as f64).powi(2) / r.median_s / 1e6;
                let psnr = if r.psnr.is_finite() {
                    format!("{:.1}", r.psnr)
                } else {
                    "identical".into()
                };
                match r.pos_err {
                    Some((mean, max, missed)) => {
                        let _ = writeln!(
                            s,
                            "| {} | {} | {:.2} | {:.2} | {:.4} / {:.4} | {} | {:.3} | {} |",
                            r.setting, r.precision, r.ratio, mrays, mean, max, missed, r.rmse, psnr
                        );
                    }
                    None => {
                        let _ = writeln!(
                            s,
                            "| {} | {} | {:.2} | {:.2} | {:.3} | {} |",
                            r.setting, r.precision, r.ratio, mrays, r.rmse, psnr
                        );
                    }
                }
            }
            s.push('\n');
        }
    }
    let _ = writeln!(
        s,
        "## f32 against f64 on the extreme-case corpus\n\n\
         The named corpus of src/tools/corpus.rs (grids with one-cell axes, spacing ratios \
         of 1e4, offsets of 1e6 mm, gaps of 1e-9 mm; origins on samples, faces, edges \
         and 1e9 mm away; directions with 0.0/-0.0, 1e-30, subnormal and huge \
         components), walked by FVT: {} rays; the f32 walk gives a different 1-cell \
         sequence on {} of them, misses {} 1-cells that f64 visits, and has a \
         different first 1-cell on {}. f64 matches an exact rational oracle on every \
         one (tests/all/extremes.rs), so f64 is the default.\n",
        diffs[0], diffs[1], diffs[2], diffs[3]
    );
    s
}

/// Error against time, one panel per dataset and mode: surface position
/// error (log scale) and composite RMSE, f64 and f32 in two colours.
fn plot(rows: &[Row]) -> anyhow::Result<String> {
    use plotters::prelude::*;
    let sets: Vec<&str> = ["spheres", "ct"]
        .into_iter()
        .filter(|d| rows.iter().any(|r| r.dataset == *d))
        .collect();
    crate::plot::font::register();
    let mut svg = String::new();
    {
        let h = 400 * sets.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (1000, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let panels = root.split_evenly((sets.len(), 2));
        let series = |ds: &str, kind: &str, p: &str| -> Vec<(f64, f64, String)> {
            rows.iter()
                .filter(|r| r.kind == kind && r.precision == p && r.dataset == ds)
                .map(|r| {
                    let y = match r.pos_err {
                        Some((mean, _, _)) => mean,
                        None => r.rmse,
                    };
                    // A zero error (the reference itself) is drawn at 1e-4.
                    (r.ratio, y.max(1e-4), r.setting.clone())
                })
                .collect()
        };
        for (i, ds) in sets.iter().enumerate() {
            for (j, kind, ylabel) in [
                (0, "surface", "mean position error (mm)"),
                (1, "composite", "RMSE vs step 1/32 mm (8-bit levels)"),
            ] {
                let panel = &panels[2 * i + j];
                let pts = [series(ds, kind, "f64"), series(ds, kind, "f32")].concat();
                let xmax = pts.iter().map(|p| p.0).fold(1.0, f64::max) * 1.15;
                // Whole decades, so a log axis always has labelled ticks.
                let lo = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
                let hi = pts.iter().map(|p| p.1).fold(0.0, f64::max);
                let ymin = 10f64.powf((lo / 1.2).log10().floor());
                let ymax = 10f64.powf((hi * 1.2).log10().ceil());
                let mut chart = ChartBuilder::on(panel)
                    .caption(format!("{ds}: {kind}"), ("sans-serif", 18))
                    .margin(12)
                    .x_label_area_size(36)
                    .y_label_area_size(64)
                    .build_cartesian_2d(0.95f64..xmax, (ymin..ymax).log_scale())?;
                chart
                    .configure_mesh()
                    .x_desc("time per frame (x fastest)")
                    .y_desc(ylabel)
                    .y_label_formatter(&|y| tick(*y))
                    .draw()?;
                for (p, colour) in [("f64", BLUE), ("f32", RED)] {
                    let s = series(ds, kind, p);
                    chart
                        .draw_series(
                            s.iter()
                                .map(|(x, y, _)| Circle::new((*x, *y), 4, colour.filled())),
                        )?
                        .label(p)
                        .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
                    let font = ("sans-serif", 11).into_font().color(&colour);
                    chart.draw_series(
                        s.iter()
                            .map(|(x, y, name)| Text::new(name.clone(), (*x, *y), font.clone())),
                    )?;
                }
                chart
                    .configure_series_labels()
                    .border_style(BLACK)
                    .background_style(WHITE.mix(0.8))
                    .draw()?;
            }
        }
        root.present()?;
    }
    Ok(svg)
}

/// A short tick label: 3, 0.25, 1e-3.
fn tick(y: f64) -> String {
    if y >= 1.0 {
        format!("{y:.0}")
    } else if y >= 0.01 {
        format!("{y:.2}")
    } else {
        format!("{y:.0e}")
    }
}

fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    Ok(crate::fsutil::write_atomic(path, bytes)?)
}
