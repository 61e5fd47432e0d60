//! `cdvol experiment fig16|fig17|fig18|fig20|fig22|table1|table2|all`:
//! the ray-generator comparisons of the paper's section 5, reproduced on
//! cdvol's own generators (docs/EXPERIMENTS.md).
//!
//! Every experiment writes a CSV and (where the paper has a graph) an SVG
//! plot under the report's directory, and returns a Markdown section;
//! `all` joins the sections into docs/EXPERIMENTS.md. Times are medians
//! of `runs` interleaved repetitions on one thread (the machines are
//! shared and noisy), and every comparison is stated as a ratio measured
//! in the same run. The paper's figures are from a 1990s HP workstation:
//! compare shapes and ratios, not seconds.
//!
//! ```text
//! sweep.rs  Figs. 16, 18 and 20 and Table 2: one sweep of background
//!           traversals over the sphere scenes
//! fig22.rs  Fig. 22: surface detection on face samples against
//!           equidistant ones
//! ct.rs     Table 1 and Fig. 17 on the real CT made rectilinear
//! here      the options, the scenes, timing and plotting helpers, and
//!           the run that joins the sections
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::classify::Classification;
use crate::format::reader::PackedVolume;
use crate::input::raw::RawSource;
use crate::prep::{prep, PrepOptions};
use crate::progress::{NoProgress, Progress};
use crate::render::brick_policy;
use crate::render::cache::{Accessor, BrickCache, LAZY_MIN_CODE_CD};
use crate::render::traverse::OBJECT;
use crate::render::traverse::{trace, CodeSource, DistKind, Flow, Method, Ray, StepCounts, TGrid};
use crate::render::view::camera::{Camera, Projection};
use crate::tools::phantom;

mod ct;
mod fig22;
mod sweep;

pub use ct::{fig17, rectilinear_ct, table1, CT_ISO};
pub use fig22::fig22;
pub use sweep::{sweep, sweep_methods, Sweep};

/// Options shared by the paper experiments.
#[derive(Debug, Clone)]
pub struct PaperOptions {
    /// Directory of the CSV and SVG files (docs/experiments).
    pub dir: PathBuf,
    /// Sphere scenes: `N` subregions per axis (paper: 2..=21).
    pub ns: Vec<usize>,
    /// Scene edge in samples (paper: 128).
    pub size: usize,
    /// Image edge in rays (paper: 250).
    pub rays: u32,
    /// Repetitions per setting; the median is reported.
    pub runs: usize,
    /// Sidecar of the real CT (table1, fig17); skipped without it.
    pub ct: Option<PathBuf>,
}

/// One sphere scene, packed with every plane the generators need.
struct Scene {
    n: usize,
    svr: f64,
    objects: u64,
    vol: PackedVolume,
    iso: f64,
}

fn dda(kind: DistKind, switch_fvt: bool) -> Method {
    Method::Dda { kind, switch_fvt }
}

/// Short names, as `--traversal` spells them.
pub fn name(m: Method) -> String {
    match m {
        Method::Fvt => "fvt".into(),
        Method::Cd { min_leap: 1 } => "cd".into(),
        Method::Cd { min_leap } => format!("cd-switch-at-{}", min_leap - 1),
        Method::CdAniso { .. } => "cd-aniso".into(),
        Method::Octree => "octree".into(),
        Method::Dda { kind, switch_fvt } => format!(
            "dda-{}{}",
            match kind {
                DistKind::Cityblock => "cityblock",
                DistKind::Chessboard => "chessboard",
                DistKind::Chamfer => "chamfer",
            },
            if switch_fvt { "" } else { "-noswitch" }
        ),
    }
}

fn scenes(o: &PaperOptions, tmp: &Path, pr: &dyn Progress) -> anyhow::Result<Vec<Scene>> {
    pr.begin("sphere scenes", o.ns.len() as u64);
    let mut out = Vec::new();
    for &n in &o.ns {
        let side = tmp.join(format!("n{n}.json"));
        let so = phantom::SpheresOptions {
            size: o.size,
            per_axis: n,
            seed: 1,
            spacing: phantom::parse_spacing3("1")?,
        };
        let info = phantom::spheres(&side, &so, &NoProgress)?;
        let src = RawSource::open(&side)?;
        let packed = tmp.join(format!("n{n}.cdv"));
        let mut po = PrepOptions::new(Classification::Iso { iso: info.iso });
        po.aniso = true;
        po.dda = true;
        prep(&src, &packed, &po, &NoProgress)?;
        let vol = PackedVolume::open(&packed)?;
        let (svr, objects) = surface_to_volume(&vol);
        out.push(Scene {
            n,
            svr,
            objects,
            vol,
            iso: info.iso,
        });
        pr.advance(1);
    }
    pr.end();
    Ok(out)
}

/// Surface-to-volume ratio (paper section 5.1): 1-cells with a 0-cell
/// (or the outside) in their 26-neighbourhood, over all 1-cells.
fn surface_to_volume(vol: &PackedVolume) -> (f64, u64) {
    let cache = BrickCache::new(vol, 1 << 30);
    let mut acc = Accessor::new(&cache);
    let n = vol.header().cells().map(|c| c as i64);
    let (mut obj, mut surf) = (0u64, 0u64);
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                if acc.code([x as u32, y as u32, z as u32], None) != OBJECT {
                    continue;
                }
                obj += 1;
                let mut s = false;
                'nb: for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let q = [x + dx, y + dy, z + dz];
                            if (0..3).any(|k| q[k] < 0 || q[k] >= n[k])
                                || acc.code(q.map(|v| v as u32), None) != OBJECT
                            {
                                s = true;
                                break 'nb;
                            }
                        }
                    }
                }
                surf += s as u64;
            }
        }
    }
    (surf as f64 / obj.max(1) as f64, obj)
}

/// The paper's view: parallel rays along +y through the whole scene.
fn front_camera(vol: &PackedVolume, rays: u32) -> anyhow::Result<Camera> {
    let (lo, hi) = TGrid::<f64>::new(&vol.header().axes).bounds();
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    Camera::look_at(
        [c[0], lo[1] - 10.0, c[2]],
        c,
        [0.0, 0.0, 1.0],
        Projection::Ortho {
            frame_mm: hi[2] - lo[2],
        },
        rays,
        rays,
    )
    .map_err(anyhow::Error::msg)
}

fn all_rays(cam: &Camera) -> Vec<Ray> {
    (0..cam.height)
        .flat_map(|y| (0..cam.width).map(move |x| cam.ray(x, y)))
        .collect()
}

fn cache_for(vol: &PackedVolume, m: Method) -> BrickCache {
    let planes = brick_policy(m, LAZY_MIN_CODE_CD).planes;
    BrickCache::with_planes(vol, 1 << 30, planes)
}

/// Background traversal of every ray to its first 1-cell (no shading),
/// as in Fig. 16: per ray, the steps and the traversed length in mm.
struct Background {
    seconds: f64,
    counts: StepCounts,
    /// Sum over rays of the length from volume entry to the first 1-cell
    /// (or the exit).
    length_mm: f64,
    rays: u64,
    /// The first 1-cell of every ray (None: it found none).
    first: Vec<Option<[u32; 3]>>,
}

fn slab(lo: [f64; 3], hi: [f64; 3], r: &Ray) -> Option<(f64, f64)> {
    let (mut a, mut b) = (0.0f64, f64::INFINITY);
    for k in 0..3 {
        if r.dir[k] == 0.0 {
            if r.origin[k] < lo[k] || r.origin[k] > hi[k] {
                return None;
            }
        } else {
            let (t0, t1) = (
                (lo[k] - r.origin[k]) / r.dir[k],
                (hi[k] - r.origin[k]) / r.dir[k],
            );
            a = a.max(t0.min(t1));
            b = b.min(t0.max(t1));
        }
    }
    (a < b).then_some((a, b))
}

/// Times `methods` over `rays` (median of `runs`, interleaved, caches
/// warm), and counts steps and lengths once.
fn background(
    vol: &PackedVolume,
    rays: &[Ray],
    methods: &[Method],
    runs: usize,
) -> Vec<Background> {
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let (lo, hi) = grid.bounds();
    let caches: Vec<BrickCache> = methods.iter().map(|&m| cache_for(vol, m)).collect();
    let pass = |i: usize, count: bool| -> (f64, StepCounts, f64, Vec<Option<[u32; 3]>>) {
        let m = methods[i];
        let mut acc = Accessor::for_policy(&caches[i], &brick_policy(m, LAZY_MIN_CODE_CD));
        let mut counts = StepCounts::default();
        let mut length = 0.0;
        let mut cells = Vec::new();
        let t0 = Instant::now();
        for r in rays {
            let mut first = None;
            let c = trace(&grid, r, 0.0, m, &mut acc, |v, _| {
                first = Some((v.t_enter, v.cell));
                Flow::Stop
            });
            counts.add(&c);
            if count {
                if let Some((a, b)) = slab(lo, hi, r) {
                    length += first.map_or(b, |f| f.0) - a;
                }
                cells.push(first.map(|f| f.1));
            }
        }
        (t0.elapsed().as_secs_f64(), counts, length, cells)
    };
    let mut out: Vec<Background> = (0..methods.len())
        .map(|i| {
            let (_, counts, length_mm, first) = pass(i, true);
            Background {
                seconds: 0.0,
                counts,
                length_mm,
                rays: rays.len() as u64,
                first,
            }
        })
        .collect();
    let mut times = vec![Vec::new(); methods.len()];
    for _ in 0..runs.max(1) {
        for (i, t) in times.iter_mut().enumerate() {
            t.push(pass(i, false).0);
        }
    }
    for (b, t) in out.iter_mut().zip(times) {
        b.seconds = median(t);
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A CSV table: header and rows, written atomically.
fn write_csv(path: &Path, header: &str, rows: &[String]) -> anyhow::Result<()> {
    let mut s = String::from(header);
    s.push('\n');
    for r in rows {
        s.push_str(r);
        s.push('\n');
    }
    super::write_atomic(path, s.as_bytes())
}

/// Line plot of `series` (name, points) as SVG.
fn line_plot(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    crate::plot::font::register();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 500)).into_drawing_area();
        root.fill(&WHITE)?;
        let pts = series.iter().flat_map(|s| s.1.iter());
        let (mut x0, mut x1, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for &(x, y) in pts {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y1 = y1.max(y);
        }
        let pad = (x1 - x0).max(1e-9) * 0.04;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((x0 - pad)..(x1 + pad), 0.0..y1 * 1.08)?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .draw()?;
        for (i, (name, p)) in series.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(p.iter().copied(), colour.stroke_width(2)))?
                .label(name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
            chart.draw_series(p.iter().map(|&q| Circle::new(q, 3, colour.filled())))?;
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.85))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
    }
    super::write_atomic(path, svg.as_bytes())
}

/// Which experiment to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Which {
    Fig16,
    Fig17,
    Fig18,
    Fig20,
    Fig22,
    Table1,
    Table2,
    All,
}

/// One `cdvol experiment` invocation.
#[derive(Debug, Clone)]
pub struct Job {
    pub which: Which,
    /// The Markdown report.
    pub out: PathBuf,
    pub opts: PaperOptions,
}

/// Runs `job` and writes its report (all: docs/EXPERIMENTS.md with every
/// section; one experiment: its section alone). Returns the report path.
pub fn run(job: &Job, pr: &dyn Progress) -> anyhow::Result<PathBuf> {
    let o = &job.opts;
    std::fs::create_dir_all(&o.dir)?;
    let want = |w: Which| job.which == w || job.which == Which::All;
    let need_ct = |what: &str| -> anyhow::Result<&Path> {
        o.ct.as_deref().ok_or_else(|| {
            anyhow::anyhow!(
                "{what} renders the real CT: ct is not set; expected its sidecar \
                 (tools/fetch-ct.sh DIR writes DIR/cranium.json)"
            )
        })
    };
    let mut sections = Vec::new();
    let sweep_needed = [Which::Fig16, Which::Fig18, Which::Fig20, Which::Table2]
        .iter()
        .any(|&w| want(w));
    if sweep_needed {
        let sw = sweep(o, pr)?;
        sw.csv(&o.dir)?;
        if want(Which::Fig16) {
            sections.push(sw.fig16(&o.dir)?);
        }
        if want(Which::Fig18) {
            sections.push(sw.fig18(&o.dir)?);
        }
        if want(Which::Fig20) {
            sections.push(sw.fig20(&o.dir)?);
        }
        if want(Which::Table2) {
            sections.push(sw.table2(&o.dir)?);
        }
    }
    if want(Which::Fig22) {
        sections.push(fig22(o, pr)?);
    }
    if want(Which::Table1) {
        if job.which == Which::All && o.ct.is_none() {
            sections.push("## Table 1\n\nSkipped: no --ct given.\n".into());
        } else {
            sections.push(table1(o, need_ct("table1")?, pr)?);
        }
    }
    if want(Which::Fig17) {
        if job.which == Which::All && o.ct.is_none() {
            sections.push("## Fig. 17\n\nSkipped: no --ct given.\n".into());
        } else {
            sections.push(fig17(o, need_ct("fig17")?, pr)?);
        }
    }
    let mut md = String::new();
    if job.which == Which::All {
        md.push_str(&header(o));
    }
    for s in sections {
        md.push_str(&s);
        md.push('\n');
    }
    super::write_atomic(&job.out, md.as_bytes())?;
    Ok(job.out.clone())
}

/// What every run states first: how it was made.
fn header(o: &PaperOptions) -> String {
    format!(
        "# Experiments: the paper's section 5, reproduced\n\n\
         Generated by `cdvol experiment all --ct CT --ns {} --size {} --rays {} --runs {}` \
         (tools/experiments.sh). Sphere scenes: {}^3 samples, N^3 spheres of equal total \
         volume (paper Fig. 15), 1 mm cubic cells, prepared with `--aniso --dda`; \
         {}x{} parallel rays along +y framing the scene; times are medians of {} \
         interleaved runs on one thread with every brick in the cache. The paper's \
         figures come from an HP 720 of 1999: compare shapes and ratios, not seconds. \
         CSV and plots are in docs/experiments/.\n\n",
        o.ns.iter()
            .map(|n| n.to_string())
            .collect::<Vec<_>>()
            .join(","),
        o.size,
        o.rays,
        o.runs,
        o.size,
        o.rays,
        o.rays,
        o.runs
    )
}
