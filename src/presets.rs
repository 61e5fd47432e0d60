//! Named transfer functions shipped with the crate (`presets/*.json`,
//! embedded at build time; docs/PRESETS.md lists them with their sources).
//!
//! Each preset is a transfer function in the format of `--classify-tf`
//! files (docs/FORMAT.md), with what the published preset it comes from
//! says beside it: whether it is shaded, and where given, a surface iso
//! value and a MIP window. The numbers are those of 3D Slicer's
//! volume-rendering and window/level presets and InVesalius's threshold
//! and ray-casting presets; each preset's `sources` names the file,
//! commit and preset every figure comes from, and `source_curves` keeps
//! the published curves in Slicer's notation (`"N x1 y1 x2 y2 ..."` for
//! opacity, `"N x1 r1 g1 b1 ..."` for colour), from which the unit tests
//! check the transfer function point by point.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};

use crate::classify::{Classification, TransferFunction};

/// The imaging modality a preset's values are meant for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Modality {
    /// Hounsfield units.
    #[serde(rename = "CT")]
    Ct,
    /// MR intensities (no absolute scale: the preset's numbers suit data
    /// of the scale the source assumed).
    #[serde(rename = "MR")]
    Mr,
}

impl Modality {
    /// The smallest value below which data is CT: air is -1000 HU, and MR
    /// intensities are not negative.
    pub const CT_BELOW: f64 = -500.0;

    /// The modality of data whose smallest (rescaled) value is `lo`, when
    /// nothing says: CT below [`Modality::CT_BELOW`], else MR; with the
    /// figure that decided it, for the user.
    pub fn guess(lo: f64) -> (Modality, String) {
        if lo < Self::CT_BELOW {
            (
                Modality::Ct,
                format!("the smallest value {lo} is below -500 (air in HU)"),
            )
        } else {
            (
                Modality::Mr,
                format!("the smallest value {lo} is not below -500"),
            )
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Modality::Ct => "CT",
            Modality::Mr => "MR",
        }
    }
}

/// A landmark of a file's value histogram (`format::histogram::Landmarks`)
/// that an MR preset's values are placed on: MR intensities have no
/// absolute scale, so a preset's numbers mean something only relative to
/// the file's own background and tissue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Landmark {
    /// The boundary between background (air, noise) and the object.
    Threshold,
    /// The median of the object's values (those at or above the threshold).
    P50,
    /// The 95th percentile of the object's values.
    P95,
    /// The 99th percentile of the object's values.
    P99,
}

impl Landmark {
    pub fn name(self) -> &'static str {
        match self {
            Landmark::Threshold => "threshold",
            Landmark::P50 => "p50",
            Landmark::P95 => "p95",
            Landmark::P99 => "p99",
        }
    }
}

/// One anchor of a preset's fit: the preset's `value` is placed at the
/// file's landmark `to`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    pub value: f64,
    pub to: Landmark,
}

/// A MIP grey window: values `level - width / 2 .. level + width / 2`
/// map to black .. white.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MipWindow {
    pub width: f64,
    pub level: f64,
}

/// The published curves a preset's transfer function was converted from,
/// in 3D Slicer's notation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceCurves {
    /// `"N x1 a1 x2 a2 ..."`: N numbers, (value, opacity) pairs.
    pub scalar_opacity: String,
    /// `"N x1 r1 g1 b1 ..."`: N numbers, (value, r, g, b) quadruples.
    pub color_transfer: String,
}

/// One named preset (a `presets/*.json` file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preset {
    /// Lower-case, dash-separated (`ct-bone`).
    pub name: String,
    pub modality: Modality,
    pub description: String,
    /// The transfer function (the `--classify-tf` file format).
    pub tf: TransferFunction,
    /// The source shades its volume rendering.
    #[serde(default)]
    pub shade: bool,
    /// A surface iso value for surface mode, where a source gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iso: Option<f64>,
    /// A MIP window, where a source gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<MipWindow>,
    /// How the preset's values move to a file's scale (MR presets): the
    /// affine map that takes each anchor's value to the file's landmark
    /// ([`Preset::fitted`]). `None`: the values are absolute (HU).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<[Anchor; 2]>,
    /// The published curves `tf` was converted from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_curves: Option<SourceCurves>,
    /// Where cdvol departs from the source, and why: keys `color` (the
    /// colours are not the source curves'), `opacity` (the opacities are
    /// not) and `shade` (shading differs from the source's); the check
    /// against the source curves skips what is changed.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub changes: BTreeMap<String, String>,
    /// Where each figure comes from: the keys `tf`, `shade`, and `iso` and
    /// `window` where present, each naming a repository, file, commit and
    /// preset.
    pub sources: BTreeMap<String, String>,
}

/// Why a preset was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PresetError {
    /// No preset has this name.
    #[error("unknown preset {name:?}, expected one of: {known}")]
    Unknown { name: String, known: String },
    /// An `--envelope` item that is no number, preset or modality.
    #[error(
        "envelope item {item:?}: expected an iso value, a modality (ct, mr) or a preset \
         ({known})"
    )]
    EnvelopeItem { item: String, known: String },
    /// A preset an iso classification cannot hold (opacity below its
    /// first point).
    #[error(
        "preset {name} gives opacity to every value below its first point, so no iso \
         value holds it: prepare with --preset {name} or --classify-tf"
    )]
    Unbounded { name: String },
    /// A preset breaks an invariant of [`Preset::check`] (a bug in the
    /// shipped data, caught by the unit tests).
    #[error("preset {name}: field `{field}`: {found}, expected {expected}")]
    Invalid {
        name: String,
        field: String,
        found: String,
        expected: String,
    },
}

/// The shipped preset files, in the order `cdvol presets` lists them.
const FILES: &[(&str, &str)] = &[
    ("ct-bone", include_str!("../presets/ct-bone.json")),
    ("ct-skin", include_str!("../presets/ct-skin.json")),
    (
        "ct-soft-tissue",
        include_str!("../presets/ct-soft-tissue.json"),
    ),
    ("ct-muscle", include_str!("../presets/ct-muscle.json")),
    ("ct-lung", include_str!("../presets/ct-lung.json")),
    ("ct-vessels", include_str!("../presets/ct-vessels.json")),
    ("ct-mip", include_str!("../presets/ct-mip.json")),
    ("mr-default", include_str!("../presets/mr-default.json")),
    ("mr-brain", include_str!("../presets/mr-brain.json")),
    ("mr-angio", include_str!("../presets/mr-angio.json")),
    ("mr-mip", include_str!("../presets/mr-mip.json")),
];

/// Parses and checks one shipped preset file.
fn parse(file: &str, text: &str) -> Result<Preset, PresetError> {
    let p: Preset = serde_json::from_str(text).map_err(|e| PresetError::Invalid {
        name: file.into(),
        field: "(file)".into(),
        found: e.to_string(),
        expected: "a preset JSON object".into(),
    })?;
    if p.name != file {
        return Err(PresetError::Invalid {
            name: file.into(),
            field: "name".into(),
            found: p.name.clone(),
            expected: format!("{file} (the file's name)"),
        });
    }
    p.check()?;
    Ok(p)
}

/// Every shipped preset. The files are parsed once; a file that does not
/// parse or check is left out (the unit tests require all of them).
pub fn all() -> &'static [Preset] {
    static ALL: OnceLock<Vec<Preset>> = OnceLock::new();
    ALL.get_or_init(|| {
        FILES
            .iter()
            .filter_map(|(file, text)| parse(file, text).ok())
            .collect()
    })
}

/// The names of every preset, comma-separated (for messages).
pub fn names() -> String {
    all()
        .iter()
        .map(|p| p.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The preset called `name` (case-insensitive).
pub fn get(name: &str) -> Result<Preset, PresetError> {
    all()
        .iter()
        .find(|p| p.name.eq_ignore_ascii_case(name.trim()))
        .cloned()
        .ok_or_else(|| PresetError::Unknown {
            name: name.into(),
            known: names(),
        })
}

/// Parses a Slicer curve string `"N v1 v2 ..."` into tuples of `k`
/// numbers.
fn slicer_curve(s: &str, k: usize) -> Option<Vec<Vec<f64>>> {
    let v: Vec<f64> = s
        .split_whitespace()
        .map(|x| x.parse::<f64>().ok())
        .collect::<Option<_>>()?;
    let (n, rest) = v.split_first()?;
    if *n != rest.len() as f64 || rest.is_empty() || rest.len() % k != 0 {
        return None;
    }
    Some(rest.chunks(k).map(<[f64]>::to_vec).collect())
}

/// A piecewise-linear curve of tuples `(x, y...)` at `x`, constant beyond
/// its ends.
fn curve_at(c: &[Vec<f64>], x: f64) -> Vec<f64> {
    let first = &c[0];
    let last = &c[c.len() - 1];
    if x <= first[0] {
        return first[1..].to_vec();
    }
    if x >= last[0] {
        return last[1..].to_vec();
    }
    let i = c.partition_point(|p| p[0] <= x);
    let (a, b) = (&c[i - 1], &c[i]);
    let f = (x - a[0]) / (b[0] - a[0]);
    (1..a.len()).map(|j| a[j] + f * (b[j] - a[j])).collect()
}

impl Preset {
    /// The classification prep uses for `--preset`: this transfer function.
    pub fn classification(&self) -> Classification {
        Classification::TransferFunction {
            tf: self.tf.clone(),
        }
    }

    /// This preset placed on a file whose landmarks are `at` (the file's
    /// value of each [`Landmark`]): every value of the transfer function,
    /// the iso value and the window go through the affine map that takes
    /// the two anchors' values to their landmarks; opacities and colours
    /// stay. Presets without a fit, or landmarks that do not increase
    /// with the anchors, come back unchanged. The copy has no fit (it is
    /// placed) and no source curves (its values are no longer theirs).
    pub fn fitted(&self, at: impl Fn(Landmark) -> f64) -> Preset {
        let Some([a, b]) = self.fit else {
            return self.clone();
        };
        let (ya, yb) = (at(a.to), at(b.to));
        if !(ya.is_finite() && yb.is_finite() && yb > ya) {
            return self.clone();
        }
        let slope = (yb - ya) / (b.value - a.value);
        let map = |x: f64| ya + (x - a.value) * slope;
        let mut p = self.clone();
        for q in &mut p.tf.points {
            q.value = map(q.value);
        }
        p.iso = p.iso.map(map);
        p.window = p.window.map(|w| MipWindow {
            width: w.width * slope,
            level: map(w.level),
        });
        p.fit = None;
        p.source_curves = None;
        p
    }

    /// The iso value of this preset's surface: its own where a source (or
    /// its fit) gives one, else the lowest value its transfer function
    /// gives opacity, where what it shows begins.
    pub fn surface_iso(&self) -> Option<f64> {
        self.iso.or_else(|| self.tf.iso_floor())
    }

    /// The hull of values with non-zero opacity ([`TransferFunction::support`]).
    pub fn support(&self) -> Option<(f64, f64)> {
        self.tf.support()
    }

    /// Checks the invariants the crate relies on: a valid transfer
    /// function with some opacity, a finite iso, a window of positive
    /// width, a source for every figure, and the transfer function equal
    /// to its source curves at every point of either.
    pub fn check(&self) -> Result<(), PresetError> {
        let bad = |field: &str, found: String, expected: &str| {
            Err(PresetError::Invalid {
                name: self.name.clone(),
                field: field.into(),
                found,
                expected: expected.into(),
            })
        };
        let name_ok = !self.name.is_empty()
            && self
                .name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
        if !name_ok {
            return bad(
                "name",
                self.name.clone(),
                "lower-case letters, digits and -",
            );
        }
        if let Err(e) = self.tf.check() {
            return bad(&format!("tf.{}", e.field), e.found, e.expected);
        }
        if self.tf.support().is_none() {
            return bad("tf", "zero opacity everywhere".into(), "some opacity");
        }
        if let Some(iso) = self.iso {
            if !iso.is_finite() {
                return bad("iso", iso.to_string(), "a finite number");
            }
        }
        if let Some(w) = self.window {
            if !(w.width > 0.0 && w.width.is_finite() && w.level.is_finite()) {
                return bad(
                    "window",
                    format!("width {} level {}", w.width, w.level),
                    "a finite width > 0 and a finite level",
                );
            }
        }
        match (self.modality, self.fit) {
            (Modality::Mr, None) => {
                return bad(
                    "fit",
                    "missing".into(),
                    "two anchors (MR values have no scale)",
                )
            }
            (_, Some([a, b]))
                if !(a.value.is_finite()
                    && b.value.is_finite()
                    && a.value < b.value
                    && a.to < b.to) =>
            {
                return bad(
                    "fit",
                    format!(
                        "{} -> {}, {} -> {}",
                        a.value,
                        a.to.name(),
                        b.value,
                        b.to.name()
                    ),
                    "finite anchor values and landmarks, both increasing",
                );
            }
            _ => {}
        }
        let mut need = vec!["tf", "shade"];
        if self.fit.is_some() {
            need.push("fit");
        }
        if self.iso.is_some() {
            need.push("iso");
        }
        if self.window.is_some() {
            need.push("window");
        }
        for (k, why) in &self.changes {
            if !matches!(k.as_str(), "color" | "opacity" | "shade") || why.trim().is_empty() {
                return bad(
                    &format!("changes.{k}"),
                    why.clone(),
                    "a reason under the key color, opacity or shade",
                );
            }
        }
        for k in need {
            if self.sources.get(k).is_none_or(|s| s.trim().is_empty()) {
                return bad(
                    &format!("sources.{k}"),
                    "missing".into(),
                    "where it comes from",
                );
            }
        }
        if let Some(c) = &self.source_curves {
            let Some(op) = slicer_curve(&c.scalar_opacity, 2) else {
                return bad(
                    "source_curves.scalar_opacity",
                    c.scalar_opacity.clone(),
                    "\"N x1 a1 x2 a2 ...\" with N numbers",
                );
            };
            let Some(col) = slicer_curve(&c.color_transfer, 4) else {
                return bad(
                    "source_curves.color_transfer",
                    c.color_transfer.clone(),
                    "\"N x1 r1 g1 b1 ...\" with N numbers",
                );
            };
            // Both are piecewise linear, so agreeing at every point of
            // either (and being linear between them) is agreeing everywhere.
            let xs = op.iter().chain(&col).map(|p| p[0]);
            let xs = xs.chain(self.tf.points.iter().map(|p| p.value));
            for x in xs {
                let a = curve_at(&op, x)[0];
                let rgb = curve_at(&col, x);
                let got_a = self.tf.opacity(x);
                let got_rgb = tf_color(&self.tf, x);
                let own_colour = self.changes.contains_key("color");
                let own_opacity = self.changes.contains_key("opacity");
                let close = (own_opacity || (a - got_a).abs() <= 1e-9)
                    && (own_colour || rgb.iter().zip(got_rgb).all(|(p, q)| (p - q).abs() <= 1e-9));
                if !close {
                    return bad(
                        "tf.points",
                        format!("opacity {got_a}, colour {got_rgb:?} at {x}"),
                        "the source curves' opacity and colour there",
                    );
                }
            }
        }
        Ok(())
    }
}

/// The colour of `tf` at `x`: linear between points, constant beyond.
fn tf_color(tf: &TransferFunction, x: f64) -> [f64; 3] {
    let c: Vec<Vec<f64>> = tf
        .points
        .iter()
        .map(|p| vec![p.value, p.color[0], p.color[1], p.color[2]])
        .collect();
    let v = curve_at(&c, x);
    [v[0], v[1], v[2]]
}

/// The classification one prep needs so that every item renders from its
/// file without another prep (`prep --envelope`): the lowest of the items'
/// iso values, where an item is an iso value, a preset (its transfer
/// function's lowest value with opacity, see
/// [`TransferFunction::iso_floor`], and its surface iso value) or a
/// modality (`ct`, `mr`: all of its presets). `presets` are the presets
/// as they apply to the file ([`all`], MR ones [`Preset::fitted`] to it).
/// Returns the iso value and the presets it covers.
pub fn envelope(items: &[String], presets: &[Preset]) -> Result<(f64, Vec<String>), PresetError> {
    let mut iso = f64::INFINITY;
    let mut covers = Vec::new();
    for item in items.iter().map(|i| i.trim()) {
        if let Ok(v) = item.parse::<f64>() {
            if v.is_finite() {
                iso = iso.min(v);
                continue;
            }
        }
        let of = |m: Modality| presets.iter().filter(|p| p.modality == m).collect();
        let group: Vec<&Preset> = match item.to_ascii_lowercase().as_str() {
            "ct" => of(Modality::Ct),
            "mr" => of(Modality::Mr),
            _ => match presets.iter().find(|p| p.name.eq_ignore_ascii_case(item)) {
                Some(p) => vec![p],
                None => {
                    return Err(PresetError::EnvelopeItem {
                        item: item.into(),
                        known: names(),
                    })
                }
            },
        };
        for p in group {
            let floor = p.tf.iso_floor().ok_or_else(|| PresetError::Unbounded {
                name: p.name.clone(),
            })?;
            iso = iso.min(floor).min(p.iso.unwrap_or(f64::INFINITY));
            covers.push(p.name.clone());
        }
    }
    if !iso.is_finite() {
        return Err(PresetError::EnvelopeItem {
            item: items.join(","),
            known: names(),
        });
    }
    Ok((iso, covers))
}

/// What a file classified by `c` renders without another prep, of
/// `presets` (as they apply to the file): the presets whose transfer
/// function fits (composite) and those whose iso value fits (surface),
/// by name.
pub fn covered(c: &Classification, presets: &[Preset]) -> (Vec<String>, Vec<String>) {
    let mut composite = Vec::new();
    let mut surface = Vec::new();
    for p in presets {
        let tf_ok = match c {
            Classification::Iso { iso } => !p.tf.nonzero_on(f64::MIN, iso.next_down()),
            Classification::TransferFunction { tf } => p.tf.outside(tf).is_none(),
        };
        if tf_ok {
            composite.push(p.name.clone());
        }
        if p.surface_iso().is_some_and(|v| c.holds_iso(v)) {
            surface.push(p.name.clone());
        }
    }
    (composite, surface)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_parses_and_checks() {
        for (file, text) in FILES {
            let p = parse(file, text).unwrap_or_else(|e| panic!("{e}"));
            p.tf.check().unwrap();
        }
        assert_eq!(all().len(), FILES.len());
        for want in [
            "ct-bone",
            "ct-skin",
            "ct-soft-tissue",
            "ct-muscle",
            "ct-lung",
            "ct-vessels",
            "ct-mip",
            "mr-default",
            "mr-brain",
            "mr-mip",
        ] {
            assert_eq!(get(want).unwrap().name, want);
        }
    }

    #[test]
    fn unknown_names_list_the_known_ones() {
        let e = get("ct-bones").unwrap_err().to_string();
        assert!(
            e.contains("\"ct-bones\"") && e.contains("ct-bone, ct-skin"),
            "{e}"
        );
        assert_eq!(get("CT-Bone").unwrap().name, "ct-bone");
    }

    #[test]
    fn check_catches_a_point_off_the_source_curves() {
        let mut p = get("ct-bone").unwrap();
        p.check().unwrap();
        p.tf.points[2].opacity += 0.01;
        let e = p.check().unwrap_err().to_string();
        assert!(e.contains("tf.points"), "{e}");
        let mut p = get("ct-bone").unwrap();
        p.sources.remove("window");
        assert!(p
            .check()
            .unwrap_err()
            .to_string()
            .contains("sources.window"));
        // MR presets need their fit, in increasing order.
        let mut p = get("mr-brain").unwrap();
        p.fit = None;
        assert!(p.check().unwrap_err().to_string().contains("fit"));
        let mut p = get("mr-brain").unwrap();
        p.fit.as_mut().unwrap().swap(0, 1);
        assert!(p.check().unwrap_err().to_string().contains("fit"));
    }

    #[test]
    fn fitting_maps_the_anchors_to_the_landmarks() {
        let p = get("mr-default").unwrap();
        let [a, b] = p.fit.unwrap();
        let at = |l: Landmark| match l {
            Landmark::Threshold => 100.0,
            Landmark::P50 => 400.0,
            Landmark::P95 => 700.0,
            Landmark::P99 => 900.0,
        };
        let q = p.fitted(at);
        let find = |pr: &Preset, v: f64| pr.tf.points.iter().position(|x| x.value == v);
        let (ia, ib) = (find(&p, a.value).unwrap(), find(&p, b.value).unwrap());
        assert_eq!(q.tf.points[ia].value, at(a.to));
        assert_eq!(q.tf.points[ib].value, at(b.to));
        assert_eq!(q.iso, Some(at(a.to)), "mr-default's iso is its low anchor");
        assert_eq!(q.tf.points[ia].opacity, p.tf.points[ia].opacity);
        q.tf.check().unwrap();
        // CT presets stay as published.
        assert_eq!(get("ct-bone").unwrap().fitted(at), get("ct-bone").unwrap());
    }

    #[test]
    fn slicer_curves_need_their_count() {
        assert_eq!(slicer_curve("4 0 0 1 1", 2).unwrap().len(), 2);
        assert!(slicer_curve("6 0 0 1 1", 2).is_none());
        assert!(slicer_curve("3 0 0 1", 2).is_none());
        assert!(slicer_curve("2 0 x", 2).is_none());
    }
}
