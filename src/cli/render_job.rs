//! What `cdvol render`'s arguments ask of the library: the transfer
//! function, look and traversal they name, the render job they make, and
//! render errors with the flag that set the bad value.

use clap::ValueEnum;

use cdvol::classify::TransferFunction;
use cdvol::format::reader::PackedVolume;
use cdvol::presets::Preset;
use cdvol::render::camera::CameraError;
use cdvol::render::job::{CameraSpec, JobError, RenderJob, View};
use cdvol::render::shade::HitParams;
use cdvol::render::traverse::{DistKind, Method};
use cdvol::render::{
    default_method, CompositeLook, Mode, RenderError, RenderOptions, Shard, Window,
};

use super::render::*;

impl RenderArgs {
    /// The text of `--tf`, read once (it may be a FIFO or `<(...)`,
    /// which cannot be read twice); `None` without `--tf`.
    pub fn tf_text(&self) -> anyhow::Result<Option<String>> {
        match &self.tf {
            Some(tf) => Ok(Some(cdvol::classify::read_tf_text(tf)?)),
            None => Ok(None),
        }
    }

    /// The preset of this render on `vol`: `--preset` (refused when it is
    /// of another modality than the file's, unless `--force`), or the
    /// file's look when no `--preset`, `--tf` or `--iso` is given; placed
    /// on the file's values ([`cdvol::look`]).
    pub fn preset(&self, vol: &PackedVolume) -> anyhow::Result<Option<Preset>> {
        let h = vol.header();
        Ok(match &self.preset {
            Some(name) => Some(
                match self.preset_range {
                    Some([lo, hi]) => cdvol::look::preset_in(h, name, self.force, [lo, hi]),
                    None => cdvol::look::preset(h, name, self.force),
                }
                .map_err(|e| anyhow::anyhow!("option --preset: {e}"))?,
            ),
            None if self.tf.is_none() && self.iso.is_none() => cdvol::look::default_look(h),
            None => None,
        })
    }

    /// `--mode`, or without it surface, or the mode of the file's look
    /// (`preset` came from it when `--preset` is absent).
    pub fn mode_arg(&self, preset: Option<&Preset>) -> ModeArg {
        match (self.mode, preset) {
            (Some(m), _) => m,
            (None, Some(p)) if self.preset.is_none() => {
                if p.window.is_some() && p.name.ends_with("-mip") {
                    ModeArg::Mip
                } else {
                    ModeArg::Composite
                }
            }
            (None, _) => ModeArg::Surface,
        }
    }

    /// The mode, with the hit method, shadows and transfer function it
    /// takes (the composite mode parses `tf_text`, the text of `--tf`).
    pub fn mode(
        &self,
        mode: ModeArg,
        preset: Option<&Preset>,
        tf_text: Option<&str>,
    ) -> anyhow::Result<Mode> {
        let hit = self.hit.into();
        Ok(match mode {
            ModeArg::Surface => Mode::Surface {
                hit,
                shadows: self.shadows,
            },
            ModeArg::Mip => Mode::Mip,
            ModeArg::Cost => Mode::Cost,
            ModeArg::Depth => Mode::Depth { hit },
            ModeArg::Composite => {
                let tf = match (self.tf.as_deref().zip(tf_text), preset) {
                    (Some((tf, text)), _) => TransferFunction::from_text(tf, text)?,
                    (None, Some(p)) => p.tf.clone(),
                    (None, None) => {
                        anyhow::bail!("--mode composite needs --tf FILE or --preset NAME")
                    }
                };
                Mode::Composite {
                    tf,
                    step_mm: self.step,
                }
            }
        })
    }

    /// The scene's iso value: `--iso`, or the preset's in surface, depth
    /// and cost modes ([`cdvol::look::surface_iso`]).
    pub fn iso(
        &self,
        vol: &PackedVolume,
        mode: ModeArg,
        preset: Option<&Preset>,
    ) -> anyhow::Result<Option<f64>> {
        let Some(p) = preset else {
            return Ok(self.iso);
        };
        if !matches!(mode, ModeArg::Surface | ModeArg::Depth | ModeArg::Cost) {
            return Ok(None);
        }
        match cdvol::look::surface_iso(vol.header(), p) {
            Some(v) => Ok(Some(v)),
            None => anyhow::bail!(
                "preset {} has no iso value for --mode {}; render it with --mode composite",
                p.name,
                format!("{mode:?}").to_lowercase(),
            ),
        }
    }

    /// The MIP window of `--window` and `--level`.
    pub fn window(&self, preset: Option<&Preset>) -> anyhow::Result<Window> {
        Ok(match (self.window.as_str(), self.level) {
            ("auto", None) => match preset.and_then(|p| p.window) {
                Some(w) => Window::Fixed {
                    width: w.width,
                    level: w.level,
                },
                None => Window::Auto,
            },
            ("full", None) => Window::Full,
            ("auto" | "full", Some(_)) => {
                anyhow::bail!(
                    "--level goes with a numeric --window W, not --window {}",
                    self.window
                )
            }
            (w, Some(level)) => Window::Fixed {
                width: w.parse().map_err(|_| {
                    anyhow::anyhow!("--window {w:?}: expected auto, full or a width (a number)")
                })?,
                level,
            },
            (w, None) => {
                anyhow::bail!("--window {w}: a numeric window needs --level L (its centre)")
            }
        })
    }

    /// The composite look: the --tf file's `shade` and
    /// `gradient_opacity` keys (from `tf_text`, its text), `--shade` on
    /// top.
    pub fn look(
        &self,
        mode: ModeArg,
        preset: Option<&Preset>,
        tf_text: Option<&str>,
    ) -> anyhow::Result<CompositeLook> {
        let mut look = match (self.tf.as_deref().zip(tf_text), mode) {
            (Some((tf, text)), ModeArg::Composite) => CompositeLook::from_text(tf, text)?,
            (None, ModeArg::Composite) => CompositeLook {
                shade: preset.is_some_and(|p| p.shade),
                ..CompositeLook::default()
            },
            _ => CompositeLook::default(),
        };
        look.shade |= self.shade;
        Ok(look)
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
        let traversal = self.traversal.unwrap_or(match default_method(vol) {
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
        let view = match (self.eye, self.target, self.up) {
            (Some(eye), Some(target), Some(up)) => View::LookAt { eye, target, up },
            (None, None, None) => match self.view.unwrap_or(ViewArg::Angles([0.0, 0.0])) {
                ViewArg::Angles([az_deg, el_deg]) => View::Orbit { az_deg, el_deg },
                ViewArg::Named(v) => View::Named(v),
            },
            _ => anyhow::bail!("--eye, --target and --up go together: give all three or none"),
        };
        let preset = self.preset(vol)?;
        let preset = preset.as_ref();
        let mode = self.mode_arg(preset);
        // Read once: mode and look both come from this text.
        let tf_text = match mode {
            ModeArg::Composite => self.tf_text()?,
            _ => None,
        };
        let tf_text = tf_text.as_deref();
        Ok(RenderJob {
            camera: CameraSpec {
                view,
                persp_fov_deg: self.persp.then_some(self.fov),
                frame_mm: self.frame,
                width: self.width,
                height: self.height,
            },
            options: RenderOptions {
                mode: self.mode(mode, preset, tf_text)?,
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
                look: self.look(mode, preset, tf_text)?,
                window: self.window(preset)?,
                normals: match self.normals {
                    NormalsArg::Smooth => cdvol::render::Normals::Smooth,
                    NormalsArg::Cell => cdvol::render::Normals::Cell,
                },
                iso: self.iso(vol, mode, preset)?,
                unrounded: self.bit_depth != cdvol::render::Bits::Eight,
                cull: !self.no_cull,
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
