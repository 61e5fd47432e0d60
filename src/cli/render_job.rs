//! What `cdvol render`'s arguments ask of the library: the transfer
//! function, look and traversal they name, the render job they make, and
//! render errors with the flag that set the bad value.

use clap::ValueEnum;

use cdvol::classify::TransferFunction;
use cdvol::format::reader::PackedVolume;
use cdvol::look::{resolve, Ask, ModeKind, ResolveError};
use cdvol::render::job::{Aim, JobError, RenderJob, View};
use cdvol::render::traverse::{DistKind, Method};
use cdvol::render::view::camera::CameraError;
use cdvol::render::HitParams;
use cdvol::render::{default_method, CompositeLook, RenderError, RenderOptions, Shard, Window};

use super::render::*;

impl RenderArgs {
    /// What these arguments ask of the look ([`cdvol::look::resolve`]):
    /// the transfer function of `--tf` is read (once: it may be a FIFO or
    /// `<(...)`) unless another mode than composite is asked for. Given
    /// without `--mode`, it keeps the file's look out, as `--iso` does.
    pub fn ask(&self) -> anyhow::Result<Ask> {
        let tf = match (self.mode, &self.tf) {
            (None | Some(ModeArg::Composite), Some(path)) => {
                let text = cdvol::classify::read_tf_text(path)?;
                Some((
                    TransferFunction::from_text(path, &text)?,
                    CompositeLook::from_text(path, &text)?,
                ))
            }
            _ => None,
        };
        Ok(Ask {
            mode: self.mode.map(|m| match m {
                ModeArg::Surface => ModeKind::Surface,
                ModeArg::Mip => ModeKind::Mip,
                ModeArg::Composite => ModeKind::Composite,
                ModeArg::Cost => ModeKind::Cost,
                ModeArg::Depth => ModeKind::Depth,
            }),
            preset: self.preset.clone(),
            preset_range: self.preset_range,
            force: self.force,
            iso: self.iso,
            tf,
            window: self.window()?,
            shade: self.shade,
            hit: self.hit.into(),
            shadows: self.shadows,
            step_mm: self.step.unwrap_or(cdvol::render::DEFAULT_STEP_MM),
            // With --overlay, --labels and --lut are the overlay's.
            labels: self.labels.clone().filter(|_| self.overlay.is_none()),
            lut: match &self.lut {
                Some(p) if self.overlay.is_none() => Some(cdvol::labels::LabelTable::load(p)?),
                _ => None,
            },
        })
    }

    /// The label file of `--overlay` with the labels of `--labels` (all
    /// by default) in the colours of `--lut` or its own table.
    fn overlay(&self) -> anyhow::Result<Option<cdvol::render::Overlay>> {
        let Some(path) = &self.overlay else {
            return Ok(None);
        };
        let vol = cdvol::format::reader::PackedVolume::open(path)?;
        let Some(info) = vol.header().labels.clone() else {
            anyhow::bail!(
                "{}: --overlay draws a label file, and this file holds no labels: prepare the \
                 segmentation with `cdvol prep --labels`",
                path.display()
            );
        };
        let lut = match &self.lut {
            Some(p) => Some(cdvol::labels::LabelTable::load(p)?),
            None => None,
        };
        let spec = self.labels.as_deref().unwrap_or("all");
        let style = cdvol::labels::LabelStyle::parse(spec, &info, lut.as_ref())
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(Some(cdvol::render::Overlay::new(
            vol,
            style,
            self.hit.into(),
            self.cache_mb.saturating_mul(1 << 20),
        )))
    }

    /// The MIP window of `--window` and `--level`; `None` for `auto` (the
    /// preset's window, else automatic).
    pub fn window(&self) -> anyhow::Result<Option<Window>> {
        Ok(match (self.window.as_str(), self.level) {
            ("auto", None) => None,
            ("full", None) => Some(Window::Full),
            ("auto" | "full", Some(_)) => {
                anyhow::bail!(
                    "--level goes with a numeric --window W, not --window {}",
                    self.window
                )
            }
            (w, Some(level)) => Some(Window::Fixed {
                width: w.parse().map_err(|_| {
                    anyhow::anyhow!("--window {w:?}: expected auto, full or a width (a number)")
                })?,
                level,
            }),
            (w, None) => {
                anyhow::bail!("--window {w}: a numeric window needs --level L (its centre)")
            }
        })
    }

    /// `--integrate` and `--segment-tol`; without `--integrate`, steps
    /// when `--step` is given, else the library's default.
    pub fn integrate(&self) -> cdvol::render::Integrate {
        use crate::cli::render::IntegrateArg;
        use cdvol::render::Integrate;
        match self.integrate {
            None if self.step.is_some() => Integrate::Step,
            None => match Integrate::default() {
                Integrate::Segment { .. } => Integrate::Segment {
                    tol: self.segment_tol,
                },
                other => other,
            },
            Some(IntegrateArg::Step) => Integrate::Step,
            Some(IntegrateArg::Segment) => Integrate::Segment {
                tol: self.segment_tol,
            },
            Some(IntegrateArg::Reference) => Integrate::Reference {
                substeps: Integrate::REFERENCE_SUBSTEPS,
            },
        }
    }

    /// The traversal for `vol`; `template` leaps like `cd` (its renderer
    /// is chosen by [`RenderJob::template`]); none named, the file's
    /// default ([`cdvol::render::default_method`]) with `--min-leap`.
    pub fn method(&self, vol: &PackedVolume) -> Method {
        let min_leap = self
            .switch_fvt_at
            .map_or(self.min_leap, |d| d.saturating_add(1));
        let dda = |kind| Method::Dda {
            kind,
            switch_fvt: !self.no_switch_fvt,
        };
        let traversal = self
            .traversal
            .unwrap_or(match default_method(vol.header()) {
                Method::CdAniso { .. } => TraversalArg::CdAniso,
                _ => TraversalArg::Cd,
            });
        match traversal {
            TraversalArg::Fvt => Method::Fvt,
            TraversalArg::Cd | TraversalArg::Template => Method::Cd { min_leap },
            TraversalArg::CdAniso => Method::CdAniso { min_leap },
            TraversalArg::Octree => Method::Octree,
            TraversalArg::DdaCityblock => dda(DistKind::Cityblock),
            TraversalArg::DdaChessboard => dda(DistKind::Chessboard),
            TraversalArg::DdaChamfer => dda(DistKind::Chamfer),
        }
    }

    /// The crop box and planes of `--crop`, `--clip` and `--clip-half`.
    fn clip(&self, vol: &PackedVolume) -> anyhow::Result<cdvol::render::clip::Clip> {
        use cdvol::render::clip::{half, Clip, Plane, HALVES};
        let h = vol.header();
        let lo = h.axes.each_ref().map(|a| a.coords()[0]);
        let hi = h.axes.each_ref().map(|a| a.coords()[a.coords().len() - 1]);
        let mut planes: Vec<Plane> = self
            .clip
            .iter()
            .map(|p| Plane {
                normal: [p[0], p[1], p[2]],
                d: p[3],
            })
            .collect();
        for side in &self.clip_half {
            let Some(o) = h.orientation.as_ref() else {
                anyhow::bail!(
                    "option --clip-half {side}: the file does not record which way its axes \
                     point in the patient (`cdvol info`); use --clip NX,NY,NZ,D"
                );
            };
            planes.push(half(side, lo, hi, o).ok_or_else(|| {
                anyhow::anyhow!("option --clip-half {side:?}: expected one of {HALVES}")
            })?);
        }
        Ok(Clip {
            crop: self.crop,
            planes,
        })
    }

    /// The library's render job for these arguments on `vol`.
    pub fn job(&self, vol: &PackedVolume) -> anyhow::Result<RenderJob> {
        if let Some(t) = self.traversal.filter(|t| !t.exact() && !self.experiment) {
            let name = t
                .to_possible_value()
                .map_or(String::new(), |v| v.get_name().to_string());
            anyhow::bail!(
                "option --traversal {name}: not exact (it misses 1-cells, so it draws wrong \
                 images); for measurements: cdvol experiment render --traversal {name}"
            );
        }
        if self.cache_mb < 1 {
            anyhow::bail!(
                "option --cache-mb: {} MiB, expected at least 1 (with no cache every brick \
                 is decoded again at each visit)",
                self.cache_mb
            );
        }
        let aim = match (self.eye, self.target, self.up) {
            (Some(eye), Some(target), Some(up)) => Aim::LookAt { eye, target, up },
            (None, None, None) => match self.view.unwrap_or(ViewArg::Angles([0.0, 0.0])) {
                ViewArg::Angles([az_deg, el_deg]) => Aim::Orbit { az_deg, el_deg },
                ViewArg::Named(v) => Aim::Named(v),
            },
            _ => anyhow::bail!("--eye, --target and --up go together: give all three or none"),
        };
        let look = resolve(vol.header(), &self.ask()?).map_err(|e| match e {
            ResolveError::Preset(e) => anyhow::anyhow!("option --preset: {e}"),
            ResolveError::NoTransferFunction => {
                anyhow::anyhow!("--mode composite needs --tf FILE or --preset NAME")
            }
            ResolveError::NoIso { preset, mode } => anyhow::anyhow!(
                "preset {preset} has no iso value for --mode {mode}; render it with --mode \
                 composite"
            ),
            ResolveError::Labels(m) => anyhow::anyhow!("{}: {m}", vol.path().display()),
        })?;
        let cap_colours = look.cap_colours();
        Ok(RenderJob {
            camera: View {
                aim,
                persp_fov_deg: self.persp.then_some(self.fov),
                frame_mm: self.frame,
                width: self.width,
                height: self.height,
            },
            options: RenderOptions {
                mode: look.mode,
                method: self.method(vol),
                tile: self.tile,
                cache_bytes: self.cache_mb.saturating_mul(1 << 20),
                cd_lazy_min: self.cd_lazy_min,
                hit_params: HitParams {
                    bisect_iters: self.bisect_iters,
                    newton_iters: self.newton_iters,
                    newton_tol: self.newton_tol,
                },
                precision: self.precision.into(),
                sampling: self.sample_precision.into(),
                sample_batches: self.sample_batches == OnOff::On,
                early_stop: self.early_stop,
                integrate: self.integrate(),
                look: look.look,
                window: look.window,
                normals: match self.normals {
                    NormalsArg::Smooth => cdvol::render::Normals::Smooth,
                    NormalsArg::Cell => cdvol::render::Normals::Cell,
                },
                iso: look.iso,
                unrounded: self.bit_depth != cdvol::render::Bits::Eight,
                cull: !self.no_cull,
                clip: self.clip(vol)?,
                cap: !self.no_cap,
                cap_colours,
                overlay: self.overlay()?,
            },
            template: self.traversal == Some(TraversalArg::Template),
            output: self.output.clone(),
            stats: self.stats.clone(),
            frames: self.frames,
            orbit_deg: self.orbit,
            shard: self.shard.map(|s| Shard {
                layout: self.shard_layout.into(),
                ..s
            }),
            threads: self.threads,
            image: cdvol::render::ImageSpec {
                background: self.background,
                bits: self.bit_depth,
            },
            mem_limit: self.mem_limit.map(crate::cli::mem_limit),
            scale_bar: self.scale_bar,
        })
    }
}

/// The `cdvol render` flag of a library field name, for error messages.
fn render_flag(field: &str) -> Option<&'static str> {
    Some(match field {
        "tile" => "--tile",
        "step_mm" => "--step",
        "early_stop" => "--early-stop",
        "window" => "--window",
        "newton_tol" => "--newton-tol",
        "bisect_iters" => "--bisect-iters",
        "newton_iters" => "--newton-iters",
        "width x height" => "--width/--height",
        "shard" => "--shard",
        "clip" => "--crop/--clip",
        _ => return None,
    })
}

/// A render job's error as the CLI reports it: with the flag that set
/// the bad value.
pub fn render_error(e: JobError) -> anyhow::Error {
    let flag = match &e {
        JobError::Render(RenderError::Option { field, .. }) => render_flag(field),
        JobError::NoFrames | JobError::TooManyFrames { .. } | JobError::TurntableLookAt { .. } => {
            Some("--frames")
        }
        JobError::TemplateShard => Some("--traversal template"),
        JobError::Memory { .. } => Some("--mem-limit"),
        JobError::Bound { field, .. } => Some(match *field {
            "threads" => "--threads",
            "orbit_deg" => "--orbit",
            _ => *field,
        }),
        JobError::PartName { .. } => Some("--shard"),
        JobError::Camera(c) => Some(match c {
            CameraError::FarPoint { what: "eye", .. } => "--eye",
            CameraError::FarPoint { .. } => "--target",
            CameraError::SamePoint { .. } => "--eye/--target/--view",
            CameraError::UpParallel { .. } => "--up",
            CameraError::EmptyImage { .. } => "--width/--height",
            CameraError::Frame { .. } => "--frame",
            CameraError::Fov { .. } => "--fov",
            CameraError::TooFar { .. } => "--frame/--eye",
            CameraError::NoOrientation { .. } => "--view",
        }),
        _ => None,
    };
    match flag {
        Some(f) => anyhow::Error::new(e).context(format!("option {f}")),
        None => e.into(),
    }
}
