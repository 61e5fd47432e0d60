//! The `cdvol` binary: parse arguments, call the library, map errors to
//! exit codes. Progress bars live here (indicatif on stderr).

mod cli;

use std::io::Write;
use std::path::Path;
use std::process::ExitCode;
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::export::{export, ExportWhat};
use cdvol::format::reader::PackedVolume;
use cdvol::info::Info;
use cdvol::phantom;
use cdvol::prep::{prep, PrepOptions, PrepReport};
use cdvol::progress::{NoProgress, Progress};
use cdvol::render::camera::Camera;
use cdvol::render::shade::{HitMethod, HitParams};
use cdvol::render::traverse::{Method, TGrid};
use cdvol::render::{render, Mode, Precision, RenderOptions};
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
            let opts = prep_options(a.settings)?;
            let src = cdvol::input::open_with(&a.input, a.series.as_deref())?;
            for line in src.report() {
                println!("{line}");
            }
            let report = prep(src.as_ref(), &a.output, &opts, progress)?;
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
            let what = match a.what {
                cli::What::Values => ExportWhat::Values,
                cli::What::Codes => ExportWhat::Codes,
                cli::What::Classes => ExportWhat::Classes,
            };
            let raw = export(&vol, what, &a.output, progress)?;
            println!("wrote {} and {}", a.output.display(), raw.display());
        }
        Command::Phantom(PhantomCmd::Spheres(a)) => {
            let spacing = phantom::parse_spacing3(&a.spacing)
                .map_err(|e| anyhow::anyhow!("option --spacing: {e}"))?;
            let opts = phantom::SpheresOptions {
                size: a.size,
                per_axis: a.per_axis,
                seed: a.seed,
                spacing,
            };
            let info = phantom::spheres(&a.output, &opts, progress)?;
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
            let opts = phantom::CtOptions {
                dims: a.dims,
                dtype: match a.dtype {
                    cli::CtType::I16 => phantom::CtDtype::I16,
                    cli::CtType::U16 => phantom::CtDtype::U16,
                },
                seed: a.seed,
                z_scale: a.z_scale,
            };
            let info = phantom::ct(&a.output, &opts, progress)?;
            println!(
                "wrote {} and {} ({:.1} MiB)",
                a.output.display(),
                info.raw_path.display(),
                info.bytes as f64 / 1048576.0
            );
        }
        Command::Render(a) => {
            let vol = PackedVolume::open(&a.file)?;
            let job = a.job()?;
            let (files, stats) =
                cdvol::render::job::run(&vol, &job, progress).map_err(cli::render_error)?;
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
        Command::Demo(a) => demo(&a.dir, progress)?,
        Command::Assemble(a) => {
            let parts = a
                .parts
                .iter()
                .map(|p| cdvol::render::shard::Part::read(p))
                .collect::<Result<Vec<_>, _>>()?;
            let (frame, stats) = cdvol::render::shard::assemble(&parts, &a.parts)?;
            for f in cdvol::render::save(&frame, &a.output)? {
                println!("wrote {}", f.display());
            }
            if let Some(p) = &a.stats {
                write_json(p, &stats)?;
                println!("wrote {}", p.display());
            }
        }
        Command::Experiment(cli::ExperimentCmd::Tradeoffs(a)) => {
            tradeoffs_cmd(&a, progress)?;
        }
        Command::Experiment(e) => {
            let path = cdvol::experiment::paper::run(&paper_job(&e)?, progress)?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// The paper experiment `e` names, with its options.
fn paper_job(e: &cli::ExperimentCmd) -> Result<cdvol::experiment::paper::Job> {
    use cdvol::experiment::paper::Which;
    let (which, a) = match e {
        cli::ExperimentCmd::Fig16(a) => (Which::Fig16, a),
        cli::ExperimentCmd::Fig17(a) => (Which::Fig17, a),
        cli::ExperimentCmd::Fig18(a) => (Which::Fig18, a),
        cli::ExperimentCmd::Fig20(a) => (Which::Fig20, a),
        cli::ExperimentCmd::Fig22(a) => (Which::Fig22, a),
        cli::ExperimentCmd::Table1(a) => (Which::Table1, a),
        cli::ExperimentCmd::Table2(a) => (Which::Table2, a),
        cli::ExperimentCmd::All(a) => (Which::All, a),
        cli::ExperimentCmd::Tradeoffs(_) => bail!("tradeoffs is not a paper experiment"),
    };
    Ok(cdvol::experiment::paper::Job {
        which,
        out: a.out.clone(),
        opts: cdvol::experiment::paper::PaperOptions {
            dir: a.out.parent().unwrap_or(Path::new(".")).join("experiments"),
            ns: a.ns.clone(),
            size: a.size,
            rays: a.rays,
            runs: a.runs,
            ct: a.ct.clone(),
        },
    })
}

fn tradeoffs_cmd(a: &cli::TradeoffsArgs, progress: &dyn Progress) -> Result<()> {
    let o = cdvol::experiment::TradeoffOptions {
        out: a.out.clone(),
        ct: a.ct.clone(),
        size: a.size,
        runs: a.runs,
    };
    let rows = cdvol::experiment::tradeoffs(&o, progress)?;
    println!(
        "{} settings measured; wrote {}",
        rows.len(),
        a.out.display()
    );
    Ok(())
}

/// Writes `value` as pretty JSON to `p` (temporary file, renamed).
fn write_json(p: &Path, value: &impl serde::Serialize) -> Result<()> {
    let bytes = serde_json::to_vec_pretty(value)?;
    cdvol::render::write_atomic(p, &bytes).map_err(anyhow::Error::msg)
}

/// Prep options from the command line.
fn prep_options(a: cli::PrepSettings) -> Result<PrepOptions> {
    let classification = match (a.iso, &a.classify_tf) {
        (Some(iso), None) => {
            if !iso.is_finite() {
                bail!("option --iso: {iso}, expected a finite number");
            }
            Classification::Iso { iso }
        }
        (None, Some(tf)) => Classification::TransferFunction {
            tf: TransferFunction::load(tf)?,
        },
        _ => bail!("prep needs --iso T or --classify-tf FILE to decide which cells are objects"),
    };
    Ok(PrepOptions {
        classification,
        brick_size: a.brick,
        zstd_level: a.zstd_level,
        aniso: a.aniso,
        dda: a.dda,
        temp_dir: a.temp_dir,
    })
}

fn prep_batch(a: cli::PrepBatchArgs, progress: &dyn Progress) -> Result<()> {
    let opts = prep_options(a.settings)?;
    let inputs = cdvol::batch::find_inputs(&a.input)?;
    if inputs.is_empty() {
        bail!(
            "{}: no volumes found (DICOM series, .nrrd, .nhdr, .nii, .nii.gz, raw-stack .json)",
            a.input.display()
        );
    }
    let shard = a.shard.map(|s| (s.k, s.n)).unwrap_or((0, 1));
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
    })
    .map_err(anyhow::Error::msg)?;
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
    let summary = a.output.join(match a.shard {
        Some(s) => format!("batch.{}of{}.json", s.k, s.n),
        None => "batch.json".into(),
    });
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

fn prep_file(
    input: &Path,
    output: &Path,
    opts: &PrepOptions,
    progress: &dyn Progress,
) -> Result<PrepReport> {
    let src = cdvol::input::open(input)?;
    Ok(prep(src.as_ref(), output, opts, progress)?)
}

fn print_prep(output: &Path, r: &PrepReport) -> Result<()> {
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

fn demo(dir: &Path, progress: &dyn Progress) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create demo directory", dir.display()))?;
    // The CT-like head: variable slice thickness, bone at 300 HU.
    let head = dir.join("head.json");
    let ct = phantom::ct(
        &head,
        &phantom::CtOptions {
            dims: [256, 256, 160],
            dtype: phantom::CtDtype::I16,
            seed: 1,
            ..Default::default()
        },
        progress,
    )?;
    println!(
        "phantom   {} ({:.1} MiB)",
        ct.raw_path.display(),
        ct.bytes as f64 / 1048576.0
    );
    let head_packed = dir.join("head.cdv");
    let r = prep_file(
        &head,
        &head_packed,
        &PrepOptions::new(Classification::Iso { iso: 300.0 }),
        progress,
    )?;
    print_prep(&head_packed, &r)?;
    // A sphere scene of the paper's section 5.1 (N = 5).
    let scene = dir.join("spheres.json");
    let sp = phantom::spheres(
        &scene,
        &phantom::SpheresOptions {
            size: 128,
            per_axis: 5,
            seed: 1,
            spacing: phantom::parse_spacing3("1").map_err(anyhow::Error::msg)?,
        },
        progress,
    )?;
    let scene_packed = dir.join("spheres.cdv");
    let r = prep_file(
        &scene,
        &scene_packed,
        &PrepOptions::new(Classification::Iso { iso: sp.iso }),
        progress,
    )?;
    print_prep(&scene_packed, &r)?;
    println!();
    let vol = PackedVolume::open(&head_packed)?;
    print!("{}", Info::of(&vol).to_text());
    println!();

    // Renders of the head: shaded bone with shadows, the traversal cost
    // map, and a composite of skin and bone from a transfer-function prep.
    let grid = TGrid::<f64>::new(&vol.header().axes);
    let camera = Camera::orbit(grid.bounds(), 35.0, 15.0, None, None, 768, 768)
        .map_err(anyhow::Error::msg)?;
    let mut outputs = Vec::new();
    let mut show = |name: &str, vol: &PackedVolume, mode: Mode| -> Result<()> {
        let opts = RenderOptions {
            mode,
            method: Method::Cd { min_leap: 1 },
            tile: 32,
            cache_bytes: 512 << 20,
            cd_lazy_min: cdvol::render::cache::LAZY_MIN_CODE_CD,
            precision: Precision::F64,
            hit_params: HitParams::default(),
        };
        let (frame, stats) = render(vol, &camera, &opts, progress)?;
        let path = dir.join(format!("{name}.png"));
        cdvol::render::save(&frame, &path).map_err(anyhow::Error::msg)?;
        println!(
            "render    {} ({} rays, {:.1} steps per ray, {} of {} bricks read, {:.2} s)",
            path.display(),
            stats.rays,
            stats.steps as f64 / stats.rays.max(1) as f64,
            stats.bricks_distinct,
            stats.bricks_total,
            stats.seconds_total
        );
        outputs.push(path);
        Ok(())
    };
    show(
        "head-surface",
        &vol,
        Mode::Surface {
            hit: HitMethod::Newton,
            shadows: true,
        },
    )?;
    show("head-cost", &vol, Mode::Cost)?;
    let tf = TransferFunction {
        points: vec![
            TfPoint {
                value: -300.0,
                opacity: 0.0,
                color: [0.9, 0.6, 0.5],
            },
            TfPoint {
                value: -100.0,
                opacity: 0.02,
                color: [0.9, 0.6, 0.5],
            },
            TfPoint {
                value: 100.0,
                opacity: 0.02,
                color: [0.9, 0.7, 0.6],
            },
            TfPoint {
                value: 300.0,
                opacity: 0.0,
                color: [1.0, 1.0, 0.9],
            },
            TfPoint {
                value: 600.0,
                opacity: 0.08,
                color: [1.0, 1.0, 0.95],
            },
        ],
    };
    let tf_path = dir.join("head-tf.json");
    std::fs::write(&tf_path, serde_json::to_vec_pretty(&tf)?)
        .with_context(|| format!("{}: cannot write", tf_path.display()))?;
    let tf_packed = dir.join("head-tf.cdv");
    let opts = PrepOptions::new(Classification::TransferFunction { tf: tf.clone() });
    let r = prep_file(&head, &tf_packed, &opts, progress)?;
    print_prep(&tf_packed, &r)?;
    let tf_vol = PackedVolume::open(&tf_packed)?;
    show(
        "head-composite",
        &tf_vol,
        Mode::Composite { tf, step_mm: 0.5 },
    )?;
    println!();
    println!(
        "Images: {}",
        outputs
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "Try: cdvol render {} -o view.png --view 120,30 --shadows",
        head_packed.display()
    );
    Ok(())
}
