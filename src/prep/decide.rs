//! What prep decides about an input before its first pass: the data's
//! modality (and where that came from), the landmarks MR presets are
//! placed on, and from those the classification of `--preset` and
//! `--envelope` and the file's default look.

use crate::format::histogram::HistogramBuilder;
use crate::format::landmarks::Landmarks;
use crate::format::ModalityRecord;
use crate::input::SliceSource;
use crate::presets::Modality;

use super::{PrepError, PrepOptions};

/// Slices read to place MR presets before the first pass: at most this
/// many, evenly spaced (the whole value histogram comes only with the
/// first pass, after the classification is needed).
pub const LANDMARK_SLICES: usize = 32;

/// What [`PrepOptions::resolved`] decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Decided {
    pub modality: ModalityRecord,
    /// Measured before the first pass when a preset had to be placed;
    /// otherwise prep records those of the whole histogram (MR files).
    pub landmarks: Option<Landmarks>,
    /// The preset recorded as the file's default look.
    pub look: Option<String>,
    /// What was decided, for the user (`--envelope auto`'s choice).
    pub note: Option<String>,
}

/// The modality of `src`: `flag` (`prep --modality`), else what the input
/// states when it is CT or MR, else a guess from its values
/// ([`guess_modality`]), said as such.
pub fn modality(
    src: &dyn SliceSource,
    flag: Option<Modality>,
) -> Result<ModalityRecord, PrepError> {
    if let Some(m) = flag {
        return Ok(ModalityRecord {
            modality: m,
            source: "prep --modality".into(),
        });
    }
    let stated = src.modality();
    let known = stated
        .as_ref()
        .and_then(|(m, _)| match m.to_ascii_uppercase().as_str() {
            "CT" => Some(Modality::Ct),
            "MR" | "MRI" => Some(Modality::Mr),
            _ => None,
        });
    if let (Some(m), Some((_, place))) = (known, &stated) {
        return Ok(ModalityRecord {
            modality: m,
            source: place.clone(),
        });
    }
    let (m, why) = guess_modality(src)?;
    let other = match &stated {
        Some((m, place)) => format!("; {place} says {m}, which no preset is for"),
        None => String::new(),
    };
    Ok(ModalityRecord {
        modality: m,
        source: format!("guessed from the values: {why}{other}; prep --modality sets it"),
    })
}

/// The modality of `src`'s data when it does not say: [`Modality::guess`]
/// from the smallest rescaled value of the middle slice. One slice is read.
/// Returns the modality and the figure that decided it.
pub fn guess_modality(src: &dyn SliceSource) -> Result<(Modality, String), PrepError> {
    let meta = src.meta();
    let [nx, ny, nz] = meta.dims();
    let z = nz / 2;
    let mut buf = vec![0.0f64; nx * ny];
    src.read_slice(z, &mut buf)?;
    let r = meta.rescale;
    let lo = buf
        .iter()
        .map(|&v| v * r.slope + r.intercept)
        .filter(|v| !v.is_nan())
        .fold(f64::INFINITY, f64::min);
    let (m, why) = Modality::guess(lo);
    Ok((m, format!("slice {z}: {why}")))
}

/// The landmarks of up to [`LANDMARK_SLICES`] evenly spaced slices of
/// `src` ([`Landmarks::of`]).
pub fn sampled_landmarks(src: &dyn SliceSource) -> Result<Option<Landmarks>, PrepError> {
    let meta = src.meta();
    let [nx, ny, nz] = meta.dims();
    let n = nz.min(LANDMARK_SLICES);
    let mut buf = vec![0.0f64; nx * ny];
    let mut hist = HistogramBuilder::new(meta.dtype);
    for i in 0..n {
        // Slice centres of n equal parts of the stack, in z order (a
        // gzip stream reads forward).
        let z = (2 * i + 1) * nz / (2 * n);
        src.read_slice(z, &mut buf)?;
        hist.add_slice(&buf, None);
    }
    let Some(h) = hist.finish(meta.rescale) else {
        return Ok(None);
    };
    Ok(Landmarks::of(
        &h,
        &format!("{n} of {nz} slices, sampled by prep to place its preset"),
    ))
}

impl PrepOptions {
    /// These options for `src`, decided ([`Decided`]): the modality, and
    /// with `preset` or `envelope` the classification they give on this
    /// input (MR presets placed on landmarks of sampled slices). A preset
    /// of another modality is refused unless `force`. Options already
    /// decided come back unchanged.
    pub fn resolved(&self, src: &dyn SliceSource) -> Result<PrepOptions, PrepError> {
        if self.decided.is_some() {
            return Ok(self.clone());
        }
        let modality = modality(src, self.modality)?;
        let mr = modality.modality == Modality::Mr;
        let landmarks = if mr && (self.preset.is_some() || !self.envelope.is_empty()) {
            sampled_landmarks(src)?
        } else {
            None
        };
        let presets = crate::look::place(landmarks.as_ref());
        let option = |field: &'static str, value: String, msg: String| PrepError::Option {
            field,
            value,
            msg,
        };
        let mut opts = self.clone();
        let mut note = None;
        let mut look = None;
        if let Some(name) = &self.preset {
            let p = crate::presets::get(name)
                .map_err(|e| option("preset", name.clone(), e.to_string()))?;
            let fitting: Vec<&str> = presets
                .iter()
                .filter(|q| q.modality == modality.modality)
                .map(|q| q.name.as_str())
                .collect();
            crate::look::check_modality(&p, &modality, &fitting.join(", "), self.force)
                .map_err(|e| option("preset", name.clone(), e.to_string()))?;
            let placed = presets.iter().find(|q| q.name == p.name).unwrap_or(&p);
            opts.classification = placed.classification();
            look = Some(p.name.clone());
        } else if !self.envelope.is_empty() {
            let auto = self.envelope.len() == 1 && self.envelope[0].eq_ignore_ascii_case("auto");
            let items = if auto {
                vec![modality.modality.name().to_ascii_lowercase()]
            } else {
                self.envelope.clone()
            };
            let (iso, _) = crate::presets::envelope(&items, &presets)
                .map_err(|e| option("envelope", self.envelope.join(","), e.to_string()))?;
            opts.classification = crate::classify::Classification::Iso { iso };
            if auto {
                note = Some(format!(
                    "{} ({}): iso {iso}",
                    modality.modality.name(),
                    modality.source
                ));
            }
        }
        opts.decided = Some(Decided {
            modality,
            landmarks,
            look,
            note,
        });
        Ok(opts)
    }
}
