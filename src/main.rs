//! The `cdvol` binary: parse arguments, call the library, map errors to
//! exit codes. Progress bars live here (indicatif on stderr).

mod cli;
mod demo;

use std::io::Write;
use std::path::Path;
use std::process::ExitCode;
use std::sync::Mutex;

use anyhow::{bail, Result};
use indicatif::{ProgressBar, ProgressStyle};

use cdvol::export::export;
use cdvol::format::reader::PackedVolume;
use cdvol::fsutil::check_outputs;
use cdvol::info::Info;
use cdvol::prep::{prep, PrepReport};
use cdvol::progress::{NoProgress, Progress};
use cdvol::tools::phantom;
use cli::{Command, PhantomCmd};

/// Brick planes come from a pool of 2 MiB huge-page chunks, reused from
/// brick to brick; everything else from the system allocator
/// (cdvol::memory::pool).
#[cfg(target_os = "linux")]
#[global_allocator]
static ALLOC: cdvol::memory::pool::PlanePool = cdvol::memory::pool::PlanePool::new();

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
    #[cfg(target_os = "linux")]
    ALLOC.register();
    let cli = cli::parse();
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
            // The transfer function is an input too (prep checks the
            // volume's own files).
            if let Some(tf) = &a.settings.classify_tf {
                check_outputs(
                    std::slice::from_ref(&a.output),
                    std::slice::from_ref(tf),
                    None,
                )?;
            }
            let src =
                cdvol::input::open_with(&a.input, a.series.as_deref()).map_err(cli::input_error)?;
            for line in src.report() {
                match line.strip_prefix("warning: ") {
                    Some(w) => eprintln!("cdvol: warning: {w}"),
                    None => println!("{line}"),
                }
            }
            if let (Some(shard), Some(pass)) = (a.shard, a.pass) {
                let parts = a
                    .parts
                    .clone()
                    .unwrap_or_else(|| cdvol::prep::shard::parts_dir(&a.output));
                let step = match pass {
                    1 => cdvol::prep::shard::scan,
                    _ => cdvol::prep::shard::bricks,
                };
                let r = step(src.as_ref(), &parts, shard.k, shard.n, &opts, progress)
                    .map_err(cli::prep_error)?;
                print_shard(&r, src.meta(), pass);
            } else {
                let report =
                    prep(src.as_ref(), &a.output, &opts, progress).map_err(cli::prep_error)?;
                print_prep(&a.output, &report)?;
            }
        }
        Command::PrepMerge(a) => {
            let parts = match a.parts.as_slice() {
                [dir] if dir.is_dir() => cdvol::prep::shard::find_parts(dir)?,
                files => files.to_vec(),
            };
            let r =
                cdvol::prep::shard::merge(&parts, &a.output, progress).map_err(cli::prep_error)?;
            let s = &r.header.summary;
            println!(
                "wrote {} ({:.2} MiB) from {} parts in {:.2} s ({:.1} MB/s of samples); {} of {} \
                 cells are 1-cells",
                a.output.display(),
                r.file_bytes as f64 / 1048576.0,
                r.parts,
                r.seconds,
                s.input_bytes as f64 / 1e6 / r.seconds.max(1e-9),
                s.one_cells,
                s.cells
            );
        }
        Command::PrepBatch(a) => prep_batch(a, progress)?,
        Command::Info(a) => {
            use cdvol::input::kind::{sniff, Kind};
            let kind = if a.file.is_dir() {
                let tiff = std::fs::read_dir(&a.file)
                    .map(|rd| {
                        rd.flatten()
                            .any(|e| cdvol::input::tiff::is_tiff_name(&e.path()))
                    })
                    .unwrap_or(false);
                Some(if tiff { "TIFF stack" } else { "DICOM series" })
            } else {
                match sniff(&a.file) {
                    Ok(Kind::Packed) | Err(_) => None,
                    Ok(Kind::Sidecar) if cdvol::input::tiff::TiffSource::is_sidecar(&a.file) => {
                        Some("TIFF stack (JSON sidecar)")
                    }
                    Ok(k) => Some(k.name()),
                }
            };
            let mut out = std::io::stdout().lock();
            match kind {
                // A packed file (or one that cannot be read: its error).
                None => {
                    let vol = PackedVolume::open(&a.file)?;
                    let info = Info::of(&vol);
                    if a.json {
                        serde_json::to_writer_pretty(&mut out, &info)?;
                        writeln!(out)?;
                    } else {
                        write!(out, "{}", info.to_text())?;
                    }
                }
                // An input, before prep.
                Some(kind) => {
                    let src = cdvol::input::open(&a.file).map_err(cli::input_error)?;
                    let info = cdvol::input::describe::InputInfo::of(
                        &a.file,
                        kind,
                        src.as_ref(),
                        progress,
                    )?;
                    if a.json {
                        serde_json::to_writer_pretty(&mut out, &info)?;
                        writeln!(out)?;
                    } else {
                        write!(out, "{}", info.to_text())?;
                    }
                }
            }
        }
        Command::Histogram(a) => {
            // The extension first: a bad one needs no file read.
            cdvol::plot::histogram::PlotFormat::of(&a.output)?;
            let vol = PackedVolume::open(&a.file)?;
            // Neither the packed file nor the scan it came from.
            cdvol::export::check_packed_outputs(&vol, std::slice::from_ref(&a.output))?;
            let h = vol.header();
            let min = h.summary.histogram.as_ref().and_then(|x| x.min);
            let opts = cdvol::plot::histogram::PlotOptions {
                width: a.width,
                height: a.height,
                presets: a.presets(min)?,
                title: a
                    .file
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            };
            cdvol::plot::histogram::plot(h, &a.file, &a.output, &opts)?;
            println!("wrote {}", a.output.display());
        }
        Command::Presets(a) => print_presets(&a)?,
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
        Command::Phantom(PhantomCmd::Mr(a)) => {
            let info =
                phantom::mr(&a.output, &(&a).into(), progress).map_err(cli::phantom_error)?;
            println!(
                "wrote {} and {} ({:.1} MiB); the outer surface is at iso {}",
                a.output.display(),
                info.raw_path.display(),
                info.bytes as f64 / 1048576.0,
                info.surface_iso
            );
        }
        Command::Segment(a) => {
            let s = cdvol::tools::segment::segment_ct(&a.input, &a.output, progress)?;
            println!(
                "wrote {}, {} and {}: {} soft tissue, {} bone and {} air-space samples",
                s.sidecar.display(),
                s.raw.display(),
                s.lut.display(),
                s.counts[1],
                s.counts[2],
                s.counts[3]
            );
        }
        Command::Render(a) => render(&a, progress)?,
        Command::Demo(a) => demo::run(&a.dir, progress)?,
        Command::Assemble(a) => {
            // Outputs first (none may be a part), then the depth mode's
            // companions once the parts say which mode they are.
            let outputs = |depth| -> Result<Vec<_>> {
                let mut v = cdvol::render::image_files(&a.output, depth, a.image().bits)?;
                v.extend(a.stats.iter().cloned());
                Ok(v)
            };
            check_outputs(&outputs(false)?, &a.parts, None)?;
            a.image().check(&a.output)?;
            let parts = a
                .parts
                .iter()
                .map(|p| cdvol::render::job::shard::Part::read(p))
                .collect::<Result<Vec<_>, _>>()?;
            let (frame, stats) = cdvol::render::job::shard::assemble(&parts, &a.parts)?;
            if frame.depth.is_some() {
                check_outputs(&outputs(true)?, &a.parts, None)?;
            }
            // The image (and depth files) and the statistics as one set.
            let mut set = cdvol::fsutil::FileSet::new();
            cdvol::render::stage_on(&frame, &a.output, &mut set, a.image())?;
            if let Some(p) = &a.stats {
                set.add_bytes(p, &serde_json::to_vec_pretty(&stats)?)?;
            }
            for f in set.commit()? {
                println!("wrote {}", f.display());
            }
        }
        Command::Experiment(cli::ExperimentCmd::Render(a)) => render(&a.into_render(), progress)?,
        Command::Experiment(cli::ExperimentCmd::Tradeoffs(a)) => {
            check_experiment_out(&a.out, a.ct.as_deref())?;
            let rows = cdvol::tools::experiment::tradeoffs(&a.to_options()?, progress)?;
            println!(
                "{} settings measured; wrote {}",
                rows.len(),
                a.out.display()
            );
        }
        Command::Experiment(e) => {
            let job = e.paper_job()?;
            check_experiment_out(&job.out, e.ct())?;
            let path = cdvol::tools::experiment::paper::run(&job, progress)?;
            println!("wrote {}", path.display());
        }
        Command::Serve(a) => serve(&a.config())?,
    }
    Ok(())
}

/// `cdvol render` (and `cdvol experiment render`): renders, says what it
/// wrote and what the render took.
fn render(a: &cli::RenderArgs, progress: &dyn Progress) -> Result<()> {
    let vol = PackedVolume::open(&a.file)?;
    let job = a.job(&vol)?;
    // The transfer function is an input too, and the scan the
    // packed file came from is never replaced (the job checks the
    // packed file itself).
    let outputs = job.outputs().map_err(cli::render_error)?;
    if let Some(tf) = &a.tf {
        check_outputs(&outputs, std::slice::from_ref(tf), None)?;
    }
    cdvol::export::check_not_sources(
        &outputs,
        &cdvol::export::packed_sources(vol.path(), vol.header()),
        vol.path(),
    )?;
    let (files, stats) =
        cdvol::render::job::run(&vol, &job, progress).map_err(cli::render_error)?;
    for f in files {
        println!("wrote {}", f.display());
    }
    if stats.hits == 0 && stats.rays > 0 {
        eprintln!(
            "cdvol: warning: {}: no ray met the scene ({} mode{}); the image is empty",
            a.file.display(),
            stats.mode,
            match job.options.iso {
                Some(v) => format!(", iso {v}"),
                None => String::new(),
            }
        );
    }
    println!(
        "{} rays, {} steps ({:.1} per ray: {} macro, {} single-cell), {} hits, {} of {} bricks read ({} reads), {:.2} s \
         (thread seconds: decode {:.2}, traverse {:.2}, sample {:.2}; kernel {:.2} s, {} page faults{})",
        stats.rays,
        stats.steps,
        stats.steps as f64 / stats.rays.max(1) as f64,
        stats.macro_steps,
        stats.cell_steps,
        stats.hits,
        stats.bricks_distinct,
        stats.bricks_total,
        stats.bricks_read,
        stats.seconds_total,
        stats.seconds_decode,
        stats.seconds_traverse,
        stats.seconds_sample,
        stats.seconds_system,
        stats.page_faults,
        match (stats.huge_pages, stats.huge_pages_slow) {
            (0, _) => String::new(),
            (n, s) => format!(
                ", {n} huge page{}{}",
                if n == 1 { "" } else { "s" },
                if s > 0 { format!(", {s} slow") } else { String::new() }
            ),
        },
    );
    Ok(())
}

/// An experiment's report must not replace the `--ct` scan it reads (its
/// sidecar or data files); checked before the long run.
fn check_experiment_out(out: &Path, ct: Option<&Path>) -> Result<()> {
    let Some(ct) = ct else {
        return Ok(());
    };
    // The sidecar alone when it cannot be opened (the experiment says why).
    let read = match cdvol::input::open(ct) {
        Ok(src) => src.files(),
        Err(_) => vec![ct.to_path_buf()],
    };
    check_outputs(&[out.to_path_buf()], &read, None)?;
    Ok(())
}

/// `cdvol serve`: opens the files, binds, says where on stderr, and
/// answers until Ctrl-C or SIGTERM.
fn serve(cfg: &cdvol::serve::ServeConfig) -> Result<()> {
    cfg.check()?;
    let files = cdvol::serve::open_files(&cfg.files)?;
    let server = cdvol::serve::Server::bind(&files, cfg)?;
    cdvol::serve::stop_on_signals(server.stop_flag())?;
    // One write, so a reader of the pipe never sees half an address.
    let line = format!(
        "cdvol serve: listening on http://{}/\n",
        server.local_addr()
    );
    {
        use std::io::Write;
        let mut err = std::io::stderr().lock();
        // Best effort, like eprintln!, but without its panic on a closed stderr.
        let _ = err.write_all(line.as_bytes()).and_then(|()| err.flush());
    }
    server.run();
    eprintln!("cdvol serve: stopped");
    Ok(())
}

/// `cdvol presets`: a table, JSON, or one transfer function.
fn print_presets(a: &cli::PresetsArgs) -> Result<()> {
    let mut out = std::io::stdout().lock();
    if let Some(name) = &a.tf {
        let p = cdvol::presets::get(name).map_err(|e| anyhow::anyhow!("option --tf: {e}"))?;
        serde_json::to_writer_pretty(&mut out, &p.tf)?;
        writeln!(out)?;
        return Ok(());
    }
    let all = cdvol::presets::all();
    if a.json {
        serde_json::to_writer_pretty(&mut out, all)?;
        writeln!(out)?;
        return Ok(());
    }
    let end = |v: f64| {
        if v.is_finite() {
            // At most 3 decimals: a table, not the data (--json has it).
            let s = format!("{v:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else if v < 0.0 {
            "-inf".into()
        } else {
            "inf".into()
        }
    };
    writeln!(
        out,
        "{:<15} {:<3} {:<22} {:>6} {:<16} description",
        "name", "mod", "opacity > 0 on", "iso", "MIP window W/L"
    )?;
    for p in all {
        let support = p
            .support()
            .map(|(a, b)| format!("{} .. {}", end(a), end(b)))
            .unwrap_or_else(|| "-".into());
        let iso = p.iso.map(|v| v.to_string()).unwrap_or_else(|| "-".into());
        let window = p
            .window
            .map(|w| format!("{}/{}", w.width, w.level))
            .unwrap_or_else(|| "-".into());
        writeln!(
            out,
            "{:<15} {:<3} {:<22} {:>6} {:<16} {}",
            p.name,
            p.modality.name(),
            support,
            iso,
            window,
            p.description
        )?;
    }
    writeln!(
        out,
        "(values in rescaled units: HU for CT; sources in --json and docs/PRESETS.md)"
    )?;
    Ok(())
}

/// Writes `value` as pretty JSON to `p` (temporary file, renamed).
fn write_json(p: &Path, value: &impl serde::Serialize) -> Result<()> {
    let bytes = serde_json::to_vec_pretty(value)?;
    Ok(cdvol::fsutil::write_atomic(p, &bytes)?)
}

/// `cdvol prep-batch`: prepares every input, prints a table, writes the
/// summary JSON; fails when any input failed.
fn prep_batch(a: cli::PrepBatchArgs, progress: &dyn Progress) -> Result<()> {
    a.check()?;
    let opts = a.settings.to_options()?;
    let inputs = cdvol::batch::find_inputs(&a.input)?;
    // The summary must not replace an input (the output directory may be
    // the input directory); the packed files are checked by each prep.
    std::fs::create_dir_all(&a.output).map_err(|source| cdvol::batch::BatchError::OutputDir {
        path: a.output.clone(),
        source,
    })?;
    let mut read: Vec<std::path::PathBuf> = Vec::new();
    for i in &inputs {
        read.push(i.path.clone());
        read.extend(i.files.iter().cloned());
    }
    if let Some(tf) = &a.settings.classify_tf {
        read.push(tf.clone());
    }
    check_outputs(&[a.summary_path()], &read, None)?;
    if inputs.is_empty() {
        bail!(
            "{}: no volumes found (DICOM series, .nrrd, .nhdr, .nii, .nii.gz, raw-stack .json)",
            a.input.display()
        );
    }
    // Outputs of inputs that are gone, from the summary about to be
    // replaced (before the run: it is rewritten at the end).
    let orphans = match cdvol::batch::orphans(
        &a.summary_path(),
        &a.output,
        &cdvol::batch::output_names(&a.output, &inputs),
    ) {
        Ok(o) => o,
        Err(w) => {
            eprintln!("cdvol: warning: {w}; orphaned outputs are not looked for");
            Vec::new()
        }
    };
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
            "{:7} {} -> {} ({:.1} s){}{}{}{}",
            r.status,
            r.input,
            r.output,
            r.seconds,
            r.modality
                .as_deref()
                .map(|m| format!(" [{m}]"))
                .unwrap_or_default(),
            r.reason
                .as_deref()
                .map(|e| format!(" {e}"))
                .unwrap_or_default(),
            r.error
                .as_deref()
                .map(|e| format!(": {e}"))
                .unwrap_or_default(),
            r.warning
                .as_deref()
                .map(|w| format!("; warning: {w}"))
                .unwrap_or_default()
        ));
        progress.advance(1);
    })?;
    progress.end();
    let mut rows = rows;
    let mut orphan_lines = Vec::new();
    for o in &orphans {
        let pruned = if a.prune {
            match cdvol::batch::prune(o) {
                Ok(()) => true,
                Err(e) => {
                    eprintln!("cdvol: warning: {e}");
                    false
                }
            }
        } else {
            false
        };
        let why = if inputs.iter().any(|i| i.name == o.input) {
            format!("{} is now prepared under another name", o.input)
        } else {
            format!("its input {} is gone", o.input)
        };
        orphan_lines.push(if pruned {
            format!("pruned: {} ({why})", o.output.display())
        } else {
            format!(
                "orphan: {} ({why}; remove it, or run again with --prune)",
                o.output.display()
            )
        });
        // A row for an input that is gone; an input still here whose
        // output name changed (another input now flattens alike) keeps
        // its one row, and its old output is reported above only.
        if !inputs.iter().any(|i| i.name == o.input) {
            rows.push(o.row(pruned));
        }
    }
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
    for r in rows.iter().filter(|r| r.warning.is_some()) {
        let w = r.warning.as_deref().unwrap_or_default();
        println!("warning: {}: {w}", r.input);
        eprintln!("cdvol: warning: {}: {w}", r.input);
    }
    for line in &orphan_lines {
        println!("{line}");
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
/// What a shard's pass of a sharded prep wrote, with its rate and stages.
fn print_shard(r: &cdvol::prep::shard::ShardReport, meta: &cdvol::input::VolumeMeta, pass: u8) {
    let [nx, ny, _] = meta.dims();
    let bytes = (nx * ny * r.cells.len()) as f64 * meta.dtype.size() as f64;
    println!(
        "wrote {} (pass {pass}, cell slices {}..{}) in {:.2} s ({:.1} MB/s of samples){}",
        r.path.display(),
        r.cells.start,
        r.cells.end,
        r.seconds,
        bytes / 1e6 / r.seconds.max(1e-9),
        if pass == 2 {
            format!(
                "; {} spill slices corrected for the shards below",
                r.fixed_slices
            )
        } else {
            String::new()
        }
    );
    let t = &r.stages;
    println!(
        "stages (s): read {:.2}, classify+forward DT {:.2}, histogram {:.2}, backward DT {:.2}, \
         re-read+embed {:.2}, bricks+zstd {:.2}, write {:.2}",
        t.read1, t.classify_forward, t.histogram, t.backward, t.embed, t.compress, t.write
    );
}

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
        "stages (s): read {:.2}, classify+forward DT {:.2}, histogram {:.2}, backward DT {:.2}, \
         re-read+embed {:.2}, bricks+zstd {:.2}, write {:.2}",
        t.read1, t.classify_forward, t.histogram, t.backward, t.embed, t.compress, t.write
    );
    if let Some(w) = &r.selection {
        println!("warning: {w}");
        eprintln!("cdvol: warning: {w}");
    }
    Ok(())
}
