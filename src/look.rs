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

use crate::format::landmarks::Landmarks;
use crate::format::{Header, ModalityRecord};
use crate::presets::{Modality, Preset, PresetError};

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
