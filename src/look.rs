//! What a named preset means for one packed file: the one place that
//! decides which presets a file offers, refuses a preset of another
//! modality, places MR presets on the file's values, and picks the file's
//! default look. `render`, `serve` and `info` all ask here.
//!
//! - A file's modality is recorded at prep ([`Header::modality`]): from the
//!   input's header, `prep --modality`, or a guess from its values.
//! - CT presets are in Hounsfield units and apply as published. MR presets
//!   are placed on the file's landmarks ([`Header::landmarks`],
//!   [`Preset::fitted`]), since MR values have no absolute scale.
//! - A preset of another modality is refused with the presets that fit;
//!   `force` takes it anyway (as published, unplaced).
//! - [`resolve`] turns what a render asks for (a mode, a preset, an iso
//!   value, a transfer function, a window) into the mode, iso value,
//!   window and composite look it draws: `cdvol render` and `serve` both
//!   call it.

use crate::classify::TransferFunction;
use crate::format::landmarks::Landmarks;
use crate::format::{Header, ModalityRecord};
use crate::presets::{Modality, Preset, PresetError};
use crate::render::HitMethod;
use crate::render::{CompositeLook, Mode, Window};

/// Why a preset cannot be used on a file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LookError {
    #[error(transparent)]
    Preset(#[from] PresetError),
    /// The preset is for the other modality.
    #[error(
        "preset {preset} is for {want} data, but this file is {have} ({source_note}); \
         presets for it: {fitting}. Add --force to use {preset} anyway, or prepare the \
         input with --modality {want_flag} if it is {want}"
    )]
    WrongModality {
        preset: String,
        want: &'static str,
        want_flag: &'static str,
        have: &'static str,
        source_note: String,
        fitting: String,
    },
}

/// Every shipped preset as it applies to the file: MR presets placed on
/// its landmarks (unplaced when the file has none), CT presets as they are.
pub fn placed(h: &Header) -> Vec<Preset> {
    place(h.landmarks().as_ref())
}

/// Every shipped preset, MR presets placed on `landmarks` when given.
pub fn place(landmarks: Option<&Landmarks>) -> Vec<Preset> {
    crate::presets::all()
        .iter()
        .map(|p| match landmarks {
            Some(l) if p.modality == Modality::Mr => p.fitted(|m| l.at(m)),
            _ => p.clone(),
        })
        .collect()
}

/// Refuses `wanted` on data of modality `have` when it is of another
/// (unless `force`), naming the presets that fit (`fitting`).
pub fn check_modality(
    wanted: &Preset,
    have: &ModalityRecord,
    fitting: &str,
    force: bool,
) -> Result<(), LookError> {
    if wanted.modality == have.modality || force {
        return Ok(());
    }
    Err(LookError::WrongModality {
        preset: wanted.name.clone(),
        want: wanted.modality.name(),
        want_flag: flag(wanted.modality),
        have: have.modality.name(),
        source_note: have.source.clone(),
        fitting: fitting.into(),
    })
}

/// The presets the file offers: those of its modality, placed.
pub fn offered(h: &Header) -> Vec<Preset> {
    let m = h.modality().modality;
    placed(h).into_iter().filter(|p| p.modality == m).collect()
}

/// The names of [`offered`], comma-separated.
pub fn offered_names(h: &Header) -> String {
    offered(h)
        .iter()
        .map(|p| p.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Preset `name` for the file: refused when it is of another modality
/// (unless `force`), placed on the file's values.
pub fn preset(h: &Header, name: &str, force: bool) -> Result<Preset, LookError> {
    let wanted = checked(h, name, force)?;
    Ok(placed(h)
        .into_iter()
        .find(|p| p.name == wanted.name)
        .unwrap_or(wanted))
}

/// [`preset`] with its two fit anchors placed at `range` (`[low, high]`,
/// the file's values) instead of the file's landmarks (`render
/// --preset-range`); a preset without a fit is as published.
pub fn preset_in(
    h: &Header,
    name: &str,
    force: bool,
    range: [f64; 2],
) -> Result<Preset, LookError> {
    let wanted = checked(h, name, force)?;
    let Some([a, _]) = wanted.fit else {
        return Ok(wanted);
    };
    Ok(wanted.fitted(|l| if l == a.to { range[0] } else { range[1] }))
}

/// The iso value of `p`'s surface on this file: [`Preset::surface_iso`],
/// or where the file cannot render that value (a file classified by a
/// transfer function holds only values where it has opacity) the lowest
/// point of its transfer function above it that it can.
pub fn surface_iso(h: &Header, p: &Preset) -> Option<f64> {
    let v = p.surface_iso()?;
    let c = &h.classification;
    if c.holds_iso(v) {
        return Some(v);
    }
    match c {
        crate::classify::Classification::TransferFunction { tf } => tf
            .points
            .iter()
            .map(|q| q.value)
            .find(|&x| x >= v && c.holds_iso(x))
            .or(Some(v)),
        crate::classify::Classification::Iso { .. } => Some(v),
    }
}

/// The file's default look: the preset it was prepared with, when it
/// still names one.
pub fn default_look(h: &Header) -> Option<Preset> {
    preset(h, h.look.as_deref()?, true).ok()
}

/// Preset `name` as published, refused when it is of another modality
/// than the file's (unless `force`).
fn checked(h: &Header, name: &str, force: bool) -> Result<Preset, LookError> {
    let wanted = crate::presets::get(name)?;
    check_modality(&wanted, &h.modality(), &offered_names(h), force)?;
    Ok(wanted)
}

fn flag(m: Modality) -> &'static str {
    match m {
        Modality::Ct => "ct",
        Modality::Mr => "mr",
    }
}

/// The kind of render asked for, before a preset or the file's look
/// fills in its transfer function, iso value or window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModeKind {
    Surface,
    Mip,
    Composite,
    Cost,
    Depth,
}

/// What a render asks for (`cdvol render`'s flags, `serve`'s request):
/// [`resolve`] turns it into the mode, iso value, window and composite
/// look, the one place where presets and the file's look are applied.
#[derive(Debug, Clone)]
pub struct Ask {
    /// The mode; `None`: the file's look's mode when no preset, transfer
    /// function or iso value is given (composite, or MIP for a `-mip`
    /// preset), else surface.
    pub mode: Option<ModeKind>,
    /// A preset name, with its fit anchors placed at `preset_range` when
    /// given instead of the file's landmarks.
    pub preset: Option<String>,
    pub preset_range: Option<[f64; 2]>,
    /// Take a preset of another modality.
    pub force: bool,
    /// An iso value given directly (surface, depth and cost).
    pub iso: Option<f64>,
    /// A transfer function given directly, with its look keys (`--tf`).
    pub tf: Option<(TransferFunction, CompositeLook)>,
    /// A window given directly; `None`: the preset's, else automatic.
    pub window: Option<Window>,
    /// Shade the composite whatever the preset says.
    pub shade: bool,
    pub hit: HitMethod,
    pub shadows: bool,
    pub step_mm: f64,
    /// The labels to draw of a label file ([`crate::labels::LabelStyle::parse`]:
    /// `all`, `1,5-9`, names); `None`: all of them when the file is a
    /// label file and nothing else is asked.
    pub labels: Option<String>,
    /// A colour table over the label file's own (`--lut`).
    pub lut: Option<crate::labels::LabelTable>,
}

impl Default for Ask {
    /// What `cdvol render FILE` asks with no options: the file's look, or
    /// a surface at its iso value; `--hit int`, no shadows, 0.5 mm steps.
    fn default() -> Ask {
        Ask {
            mode: None,
            preset: None,
            preset_range: None,
            force: false,
            iso: None,
            tf: None,
            window: None,
            shade: false,
            hit: HitMethod::Int,
            shadows: false,
            step_mm: 0.5,
            labels: None,
            lut: None,
        }
    }
}

/// What [`resolve`] decided: the fields of
/// [`RenderOptions`](crate::render::RenderOptions) a look decides, and the
/// preset behind them.
#[derive(Debug, Clone)]
pub struct Resolved {
    pub mode: Mode,
    pub iso: Option<f64>,
    pub window: Window,
    pub look: CompositeLook,
    pub preset: Option<Preset>,
}

impl Resolved {
    /// The colours of a surface's cut faces (render/clip.rs): its
    /// preset's transfer function, when a surface has one.
    pub fn cap_colours(&self) -> Option<TransferFunction> {
        match self.mode {
            Mode::Surface { .. } => self.preset.as_ref().map(|p| p.tf.clone()),
            _ => None,
        }
    }
}

/// Why [`resolve`] cannot make a render of an [`Ask`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ResolveError {
    /// The preset is unknown or of another modality.
    #[error(transparent)]
    Preset(#[from] LookError),
    /// A composite without a transfer function: no preset, no `tf` and no
    /// look in the file.
    #[error("a composite needs a transfer function or a preset")]
    NoTransferFunction,
    /// The preset has no iso value for a surface, depth or cost render.
    #[error("preset {preset} has no iso value for mode {mode}")]
    NoIso { preset: String, mode: &'static str },
    /// Labels asked of a file that has none, or a choice that names none
    /// of its labels.
    #[error("{0}")]
    Labels(String),
}

/// The mode, iso value, window and composite look of `ask` on the file of
/// header `h`. A preset is checked against the file's modality and placed
/// on its values ([`preset`], [`preset_in`]); without a preset, a
/// transfer function or an iso value (for a composite, whatever the iso
/// value), the file's look ([`default_look`]) stands in, and without a
/// mode it also picks the mode. A preset then brings its iso value to
/// surface, depth and cost renders ([`surface_iso`]), its window to MIP
/// and its transfer function and shading to composites; what `ask` gives
/// directly (`iso` without a preset, `window`, `shade`) wins.
pub fn resolve(h: &Header, ask: &Ask) -> Result<Resolved, ResolveError> {
    // A label file draws its labels unless something else is asked.
    let plain = ask.mode.is_none() && ask.preset.is_none() && ask.tf.is_none() && ask.iso.is_none();
    let labels = match (&ask.labels, &h.labels) {
        (Some(_), None) => {
            return Err(ResolveError::Labels(
                "--labels draws the labels of a label file, and this file holds none: prepare \
                 the segmentation with `cdvol prep --labels`"
                    .into(),
            ))
        }
        (Some(spec), Some(info)) => Some((spec.as_str(), info)),
        (None, Some(info)) if plain => Some(("all", info)),
        (None, _) => None,
    };
    if let Some((spec, info)) = labels {
        if let Some(m) = ask.mode {
            return Err(ResolveError::Labels(format!(
                "--labels draws label surfaces, not mode {}: leave out --mode",
                format!("{m:?}").to_lowercase()
            )));
        }
        let style = crate::labels::LabelStyle::parse(spec, info, ask.lut.as_ref())
            .map_err(|e| ResolveError::Labels(e.to_string()))?;
        return Ok(Resolved {
            mode: Mode::Labels {
                hit: ask.hit,
                style: std::sync::Arc::new(style),
            },
            iso: None,
            window: Window::Auto,
            look: CompositeLook::default(),
            preset: None,
        });
    }
    let preset = match &ask.preset {
        Some(name) => Some(match ask.preset_range {
            Some(range) => preset_in(h, name, ask.force, range)?,
            None => preset(h, name, ask.force)?,
        }),
        None if ask.tf.is_none()
            && (ask.iso.is_none() || ask.mode == Some(ModeKind::Composite)) =>
        {
            default_look(h)
        }
        None => None,
    };
    let kind = match (ask.mode, &preset) {
        (Some(m), _) => m,
        (None, Some(p)) if ask.preset.is_none() => {
            if p.window.is_some() && p.name.ends_with("-mip") {
                ModeKind::Mip
            } else {
                ModeKind::Composite
            }
        }
        (None, _) => ModeKind::Surface,
    };
    let mode = match kind {
        ModeKind::Surface => Mode::Surface {
            hit: ask.hit,
            shadows: ask.shadows,
        },
        ModeKind::Mip => Mode::Mip,
        ModeKind::Cost => Mode::Cost,
        ModeKind::Depth => Mode::Depth { hit: ask.hit },
        ModeKind::Composite => Mode::Composite {
            tf: match (&ask.tf, &preset) {
                (Some((tf, _)), _) => tf.clone(),
                (None, Some(p)) => p.tf.clone(),
                (None, None) => return Err(ResolveError::NoTransferFunction),
            },
            step_mm: ask.step_mm,
        },
    };
    let iso = match (&preset, kind) {
        (None, _) => ask.iso,
        (Some(p), ModeKind::Surface | ModeKind::Depth | ModeKind::Cost) => {
            Some(surface_iso(h, p).ok_or_else(|| ResolveError::NoIso {
                preset: p.name.clone(),
                mode: mode.name(),
            })?)
        }
        (Some(_), _) => None,
    };
    let window = ask
        .window
        .unwrap_or_else(|| match preset.as_ref().and_then(|p| p.window) {
            Some(w) => Window::Fixed {
                width: w.width,
                level: w.level,
            },
            None => Window::Auto,
        });
    let mut look = match (&ask.tf, kind) {
        (Some((_, look)), ModeKind::Composite) => look.clone(),
        (None, ModeKind::Composite) => CompositeLook {
            shade: preset.as_ref().is_some_and(|p| p.shade),
            ..CompositeLook::default()
        },
        _ => CompositeLook::default(),
    };
    look.shade |= ask.shade;
    Ok(Resolved {
        mode,
        iso,
        window,
        look,
        preset,
    })
}
