//! The `cdvol` binary: parse arguments, call the library, map errors to
//! exit codes. Progress bars live here (indicatif on stderr).

mod cli;
mod demo;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};

use cdvol::classify::TransferFunction;
use cdvol::export::export;
use cdvol::format::reader::PackedVolume;
use cdvol::info::Info;
use cdvol::prep::{prep, PrepReport};
use cdvol::progress::{NoProgress, Progress};
use cdvol::render::camera::{Camera, Projection};
use cdvol::render::shade::{HitMethod, HitParams};
use cdvol::render::traverse::{DistKind, Method, TGrid};
use cdvol::render::{render, render_part, Mode, Precision, RenderOptions, Stats};
use cdvol::tools::phantom;
use cli::{Cli, Command, PhantomCmd};

/// indicatif bars on stderr; hidden when stderr is not a terminal.
struct Bars {
    bar: Mutex<Option<ProgressBar>>,
}

impl Progress for Bars {
    fn begin(&self, stage: &str, total: u64) {
        let pb = ProgressBar::new(total);
        pb.set_style(
            ProgressStyle::with_template(
                "{msg:28} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        pb.set_message(stage.to_string());
        if let Ok(mut b) = self.bar.lock() {
            *b = Some(pb);
        }
    }
    fn advance(&self, n: u64) {
        if let Ok(b) = self.bar.lock() {
            if let Some(pb) = b.as_ref() {
                pb.inc(n);
            }
        }
    }
    fn end(&self) {
        if let Ok(mut b) = self.bar.lock() {
            if let Some(pb) = b.take() {
                pb.finish_and_clear();
            }
        }
    }
    fn println(&self, line: &str) {
        match self.bar.lock().ok().as_ref().and_then(|b| b.as_ref()) {
            Some(pb) if !pb.is_hidden() => pb.println(line),
            _ => println!("{line}"),
        }
    }
}

fn main() -> ExitCode {
    cdvol::memory::bound_heap_fragmentation();
    let cli = Cli::parse();
    let bars = Bars {
        bar: Mutex::new(None),
    };
    let progress: &dyn Progress = if cli.quiet { &NoProgress } else { &bars };
    match run(cli.command, progress) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // A closed pipe (`cdvol info f | head`) is not a failure.
            if let Some(io) = e.downcast_ref::<std::io::Error>() {
                if io.kind() == std::io::ErrorKind::BrokenPipe {
                    return ExitCode::SUCCESS;
                }
            }
            // Causes whose text the message already shows are not repeated.
            let mut msg = e.to_string();
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !msg.contains(&c) {
                    msg = format!("{msg}: {c}");
                }
            }
            eprintln!("cdvol: error: {msg}");
            ExitCode::FAILURE
        }
    }
}

fn run(cmd: Command, progress: &dyn Progress) -> Result<()> {
    match cmd {
        Command::Prep(a) => {
            let opts = a.settings.to_options()?;
            let src =
                cdvol::input::open_with(&a.input, a.series.as_deref()).map_err(cli::input_error)?;
            for line in src.report() {
                println!("{line}");
            }
            let report = prep(src.as_ref(), &a.output, &opts, progress).map_err(cli::prep_error)?;
            print_prep(&a.output, &report)?;
        }
        Command::PrepBatch(a) => prep_batch(a, progress)?,
        Command::Info(a) => {
            let vol = PackedVolume::open(&a.file)?;
            let info = Info::of(&vol);
            let mut out = std::io::stdout().lock();
            if a.json {
                serde_json::to_writer_pretty(&mut out, &info)?;
                writeln!(out)?;
            } else {
                write!(out, "{}", info.to_text())?;
            }
        }
        Command::Export(a) => {
            let vol = PackedVolume::open(&a.file)?;
            let raw = export(&vol, a.what.into(), &a.output, progress)?;
            println!("wrote {} and {}", a.output.display(), raw.display());
        }
        Command::Phantom(PhantomCmd::Spheres(a)) => {
            let info = phantom::spheres(&a.output, &a.to_options()?, progress)
                .map_err(cli::phantom_error)?;
            println!(
                "wrote {} ({} spheres, iso {}), {} and {}",
                a.output.display(),
                info.spheres.len(),
                info.iso,
                info.raw_path.display(),
                info.spheres_path.display()
            );
        }
        Command::Phantom(PhantomCmd::Ct(a)) => {
            let info =
                phantom::ct(&a.output, &(&a).into(), progress).map_err(cli::phantom_error)?;
            println!(
                "wrote {} and {} ({:.1} MiB)",
                a.output.display(),
                info.raw_path.display(),
                info.bytes as f64 / 1048576.0
            );
        }
        Command::Render(a) => {
            let (files, stats) = render_cmd(&a, progress)?;
            for f in files {
                println!("wrote {}", f.display());
            }
            println!(
                "{} rays, {} steps ({:.1} per ray: {} macro, {} single-cell), {} hits, {} of {} bricks read ({} reads), {:.2} s",
                stats.rays,
                stats.steps,
                stats.steps as f64 / stats.rays.max(1) as f64,
                stats.macro_steps,
                stats.cell_steps,
                stats.hits,
                stats.bricks_distinct,
                stats.bricks_total,
                stats.bricks_read,
                stats.seconds_total
            );
        }
        Command::Demo(a) => demo::run(&a.dir, progress)?,
        Command::Assemble(a) => {
            let parts = a
                .parts
                .iter()
                .map(|p| cdvol::render::shard::Part::read(p))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            let (frame, stats) =
                cdvol::render::shard::assemble(&parts, &a.parts).map_err(anyhow::Error::msg)?;
            for f in cdvol::render::save(&frame, &a.output).map_err(anyhow::Error::msg)? {
                println!("wrote {}", f.display());
            }
            if let Some(p) = &a.stats {
                write_json(p, &stats)?;
                println!("wrote {}", p.display());
            }
        }
        Command::Experiment(cli::ExperimentCmd::Tradeoffs(a)) => {
            let rows = cdvol::tools::experiment::tradeoffs(&a.to_options()?, progress)?;
            println!(
                "{} settings measured; wrote {}",
                rows.len(),
                a.out.display()
            );
        }
        Command::Experiment(e) => {
            let path = cdvol::tools::experiment::paper::run(&e.paper_job()?, progress)?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

fn render_cmd(
    a: &cli::RenderArgs,
    progress: &dyn Progress,
) -> Result<(Vec<std::path::PathBuf>, Stats)> {
    let vol = PackedVolume::open(&a.file)?;
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let projection = if a.persp {
        Projection::Persp { fov_deg: a.fov }
    } else {
        Projection::Ortho { frame_mm: 1.0 }
    };
    // The camera, turned by `az_turn` degrees of azimuth (turntables).
    let camera_at = |az_turn: f64| -> Result<Camera> {
        match (a.eye, a.target, a.up) {
            (Some(eye), Some(target), Some(up)) => {
                if a.frames > 1 {
                    bail!("--frames orbits the volume: give --view AZ,EL, not --eye/--target/--up");
                }
                let projection = match projection {
                    Projection::Ortho { .. } => {
                        let (lo, hi) = grid.bounds();
                        let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
                        Projection::Ortho {
                            frame_mm: a.frame.unwrap_or(diag * 1.02),
                        }
                    }
                    p => p,
                };
                Camera::look_at(eye, target, up, projection, a.width, a.height)
            }
            (None, None, None) => {
                let [az, el] = a.view.unwrap_or([0.0, 0.0]);
                Camera::orbit(
                    grid.bounds(),
                    az + az_turn,
                    el,
                    a.persp.then_some(a.fov),
                    a.frame,
                    a.width,
                    a.height,
                )
            }
            _ => bail!("--eye, --target and --up go together: give all three or none"),
        }
        .map_err(|e| anyhow::anyhow!("camera: {e}"))
    };
    let camera = camera_at(0.0)?;
    let hit = match a.hit {
        cli::HitArg::Int => HitMethod::Int,
        cli::HitArg::Bisect => HitMethod::Bisect,
        cli::HitArg::Newton => HitMethod::Newton,
        cli::HitArg::Exact => HitMethod::Exact,
    };
    let mode = match a.mode {
        cli::ModeArg::Surface => Mode::Surface {
            hit,
            shadows: a.shadows,
        },
        cli::ModeArg::Mip => Mode::Mip,
        cli::ModeArg::Cost => Mode::Cost,
        cli::ModeArg::Depth => Mode::Depth { hit },
        cli::ModeArg::Composite => {
            let tf =
                a.tf.as_ref()
                    .ok_or_else(|| anyhow::anyhow!("--mode composite needs --tf FILE"))?;
            Mode::Composite {
                tf: TransferFunction::load(tf)?,
                step_mm: a.step,
            }
        }
    };
    let min_leap = a.switch_fvt_at.map_or(a.min_leap, |d| d.saturating_add(1));
    let dda = |kind| Method::Dda {
        kind,
        switch_fvt: !a.no_switch_fvt,
    };
    let method = match a.traversal {
        cli::TraversalArg::Fvt => Method::Fvt,
        cli::TraversalArg::Cd => Method::Cd { min_leap },
        cli::TraversalArg::CdAniso => Method::CdAniso { min_leap },
        cli::TraversalArg::Octree => Method::Octree,
        cli::TraversalArg::DdaCityblock => dda(DistKind::Cityblock),
        cli::TraversalArg::DdaChessboard => dda(DistKind::Chessboard),
        cli::TraversalArg::DdaChamfer => dda(DistKind::Chamfer),
        // Template-based CD (section 4.2.2): its own renderer, leaping
        // like cd.
        cli::TraversalArg::Template => Method::Cd { min_leap },
    };
    let template = a.traversal == cli::TraversalArg::Template;
    if template && a.shard.is_some() {
        bail!("--traversal template renders whole images: drop --shard");
    }
    let render = |vol: &PackedVolume, cam: &Camera, opts: &RenderOptions, pr: &dyn Progress| {
        if template {
            cdvol::render::template::render_template(vol, cam, opts, pr)
        } else {
            render(vol, cam, opts, pr)
        }
    };
    let opts = RenderOptions {
        mode,
        method,
        tile: a.tile,
        cache_bytes: a.cache_mb.saturating_mul(1 << 20),
        cd_lazy_min: a.cd_lazy_min,
        hit_params: HitParams {
            bisect_iters: a.bisect_iters,
            newton_iters: a.newton_iters,
            newton_tol: a.newton_tol,
        },
        precision: match a.precision {
            cli::PrecisionArg::F32 => Precision::F32,
            cli::PrecisionArg::F64 => Precision::F64,
        },
    };
    if a.frames == 0 {
        bail!("--frames 0, expected at least 1");
    }
    let work = || -> Result<(Vec<PathBuf>, Stats)> {
        if a.frames > 1 {
            // A turntable; --shard splits the frames.
            let (mut files, mut total, mut per_frame) = (Vec::new(), Stats::default(), Vec::new());
            // One cache for every frame: later frames reuse decoded bricks.
            let cache = cdvol::render::policy::cache_for(&vol, &opts);
            for f in 0..a.frames {
                if a.shard.is_some_and(|s| f % s.n != s.k) {
                    continue;
                }
                let cam = camera_at(a.orbit * f as f64 / a.frames as f64)?;
                let (frame, stats) = if template {
                    render(&vol, &cam, &opts, progress)?
                } else {
                    cdvol::render::render_in(&vol, &cache, &cam, &opts, progress)?
                };
                let path = numbered(&a.output, f);
                files.extend(cdvol::render::save(&frame, &path).map_err(anyhow::Error::msg)?);
                total.merge(&stats);
                per_frame.push(stats);
            }
            // The frames shared one cache: its own count is exact.
            if !template {
                total.bricks_distinct = cache.distinct_read();
            }
            total.bricks_total = vol.header().brick_count();
            if let Some(p) = &a.stats {
                write_json(p, &per_frame)?;
                files.push(p.clone());
            }
            return Ok((files, total));
        }
        if let Some(mut shard) = a.shard {
            shard.layout = match a.shard_layout {
                cli::ShardLayoutArg::Interleaved => cdvol::render::ShardLayout::Interleaved,
                cli::ShardLayoutArg::Blocks => cdvol::render::ShardLayout::Blocks,
            };
            if a.output.extension().is_none_or(|e| e != "cdvpart") {
                bail!(
                    "{}: with --shard the output is a part file for `cdvol assemble`; \
                     name it NAME.cdvpart",
                    a.output.display()
                );
            }
            let part = render_part(&vol, &camera, &opts, shard, progress)?;
            part.write(&a.output).map_err(anyhow::Error::msg)?;
            let mut files = vec![a.output.clone()];
            if let Some(p) = &a.stats {
                write_json(p, &part.stats)?;
                files.push(p.clone());
            }
            return Ok((files, part.stats));
        }
        let (frame, stats) = render(&vol, &camera, &opts, progress)?;
        let mut files = cdvol::render::save(&frame, &a.output).map_err(anyhow::Error::msg)?;
        if let Some(p) = &a.stats {
            write_json(p, &stats)?;
            files.push(p.clone());
        }
        Ok((files, stats))
    };
    match a.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .context("cannot start the thread pool")?
            .install(work),
        None => work(),
    }
}

/// `out.png` -> `out.0007.png`.
fn numbered(path: &Path, f: u32) -> PathBuf {
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_else(|| "png".into());
    path.with_file_name(format!("{stem}.{f:04}.{ext}"))
}

/// Writes `value` as pretty JSON to `p` (temporary file, renamed).
fn write_json(p: &Path, value: &impl serde::Serialize) -> Result<()> {
    let bytes = serde_json::to_vec_pretty(value)?;
    cdvol::render::write_atomic(p, &bytes).map_err(anyhow::Error::msg)
}

/// `cdvol prep-batch`: prepares every input, prints a table, writes the
/// summary JSON; fails when any input failed.
fn prep_batch(a: cli::PrepBatchArgs, progress: &dyn Progress) -> Result<()> {
    let opts = a.settings.to_options()?;
    let inputs = cdvol::batch::find_inputs(&a.input)?;
    if inputs.is_empty() {
        bail!(
            "{}: no volumes found (DICOM series, .nrrd, .nhdr, .nii, .nii.gz, raw-stack .json)",
            a.input.display()
        );
    }
    let shard = a.shard();
    let total = inputs
        .iter()
        .enumerate()
        .filter(|(i, _)| *i as u32 % shard.1 == shard.0)
        .count();
    progress.begin("prep-batch", total as u64);
    let line = Mutex::new(());
    let rows = cdvol::batch::run(&inputs, &a.output, &opts, a.jobs, shard, &|r| {
        let _g = line.lock();
        progress.println(&format!(
            "{:7} {} -> {} ({:.1} s){}",
            r.status,
            r.input,
            r.output,
            r.seconds,
            r.error
                .as_deref()
                .map(|e| format!(": {e}"))
                .unwrap_or_default()
        ));
        progress.advance(1);
    })?;
    progress.end();
    println!("| input | dims | slices | rectilinear | seconds | output MiB | status |");
    println!("|---|---|---|---|---|---|---|");
    for r in &rows {
        let dims = r
            .dims
            .map(|d| format!("{}x{}x{}", d[0], d[1], d[2]))
            .unwrap_or_else(|| "-".into());
        println!(
            "| {} | {dims} | {} | {} | {:.1} | {} | {} |",
            r.input,
            r.slices
                .map(|s| s.to_string())
                .unwrap_or_else(|| "-".into()),
            r.rectilinear
                .map(|b| if b { "yes" } else { "no" })
                .unwrap_or("-"),
            r.seconds,
            r.output_bytes
                .map(|b| format!("{:.2}", b as f64 / 1048576.0))
                .unwrap_or_else(|| "-".into()),
            r.status
        );
    }
    let summary = a.summary_path();
    write_json(&summary, &rows)?;
    println!("wrote {}", summary.display());
    let failed = rows.iter().filter(|r| r.status == "failed").count();
    if failed > 0 {
        bail!(
            "{failed} of {} inputs failed (see the table and {})",
            rows.len(),
            summary.display()
        );
    }
    Ok(())
}

/// Prints what prep wrote and how long each stage took.
pub(crate) fn print_prep(output: &Path, r: &PrepReport) -> Result<()> {
    let s = &r.header.summary;
    let mb = s.input_bytes as f64 / 1048576.0;
    println!(
        "wrote {} ({:.2} MiB from {:.2} MiB of samples, {:.2}:1) in {:.2} s ({:.1} MB/s); \
         {} of {} cells are 1-cells; {} of {} bricks uniform; temp {:.2} MiB",
        output.display(),
        r.file_bytes as f64 / 1048576.0,
        mb,
        s.input_bytes as f64 / r.file_bytes.max(1) as f64,
        r.seconds,
        s.input_bytes as f64 / 1e6 / r.seconds.max(1e-9),
        s.one_cells,
        s.cells,
        s.uniform_bricks,
        r.header.brick_count(),
        r.temp_bytes as f64 / 1048576.0
    );
    let t = &r.stages;
    println!(
        "stages (s): read {:.2}, classify+forward DT {:.2}, backward DT {:.2}, \
         re-read+embed {:.2}, bricks+zstd {:.2}, write {:.2}",
        t.read1, t.classify_forward, t.backward, t.embed, t.compress, t.write
    );
    Ok(())
}
