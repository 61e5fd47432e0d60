//! Label maps (issue 55): integer volumes in which each sample holds the
//! number of the structure it belongs to (0 = background), as
//! TotalSegmentator, FreeSurfer's aseg, ITK-SNAP and 3D Slicer write them.
//!
//! **Prep** (`prep --labels`) writes a label file: an integer volume
//! classified by the union of its labels. A cell is a 1-cell when any of
//! its 8 vertices holds a label other than 0 (the packed header's
//! classification is `iso 0.5` on the unrescaled integers), so the
//! distance codes leap everything that is background. Codes are embedded
//! only in samples that are vertices of no 1-cell, which are all label 0,
//! and a uniform brick holds only label 0: every label reads back exactly
//! (a code word or a missing sample *is* label 0). The header's `labels`
//! ([`LabelInfo`]) lists the labels present with their sample counts, and
//! the colour table when prep was given one.
//!
//! **Render** (`render --labels 1,5-9`): each chosen label's surface is the
//! 0.5 level of its smoothed indicator ([`smoothed`]), drawn in its
//! colour and opacity (render/integrate/labels.rs).
//!
//! **Colour tables** ([`LabelTable::load`]): an ITK-SNAP label description
//! file, a FreeSurfer `*LUT.txt`, or JSON (`{"labels": [{"id", "name",
//! "color", "opacity"}]}`); a label the table does not name is drawn in
//! [`default_colour`].

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The largest label: labels are 0..=65535 (16 bits: ITK-SNAP's limit;
/// FreeSurfer's colour table stops at 14175, TotalSegmentator at 117).
pub const MAX_LABEL: u32 = 65535;

/// Largest colour table read (FreeSurfer's full LUT is about 500 KiB).
pub const MAX_TABLE_BYTES: u64 = 16 << 20;

/// How far the smoothed indicator of a label is kept from 0.5 at a
/// vertex: at least `0.5 + MARGIN` at the label's own samples and at
/// most `0.5 - MARGIN` elsewhere ([`smoothed`]). An isolated labelled
/// sample then draws a blob about 0.2 cells in radius, a one-sample
/// sheet a slab about 2/3 of a cell thick.
pub const MARGIN: f64 = 0.125;

/// What the header of a label file records (`labels`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelInfo {
    /// The labels other than 0 the volume holds, ascending, with their
    /// sample counts: `[[label, samples], ...]`.
    pub counts: Vec<(u32, u64)>,
    /// Samples of label 0.
    pub background: u64,
    /// The colour table prep was given (`prep --lut`); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<LabelTable>,
}

impl LabelInfo {
    /// Whether label `id` occurs in the volume.
    pub fn holds(&self, id: u32) -> bool {
        self.counts.binary_search_by_key(&id, |c| c.0).is_ok()
    }
}

/// One label's name, colour and opacity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelEntry {
    pub id: u32,
    pub name: String,
    /// Colour in [0, 1].
    pub color: [f64; 3],
    /// Opacity in [0, 1]; 1 when left out.
    #[serde(default = "one")]
    pub opacity: f64,
}

fn one() -> f64 {
    1.0
}

/// A colour table: entries by ascending id, each id once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelTable {
    pub labels: Vec<LabelEntry>,
}

/// Why a label map, a colour table or a label choice was refused: the
/// file (or option) and what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum LabelError {
    /// A colour table that cannot be read or does not parse.
    #[error("{}: {msg}", path.display())]
    Table { path: PathBuf, msg: String },
    /// A label volume that is not one: its file, the field and why.
    #[error("{source_desc}: {field}: {msg}")]
    Volume {
        source_desc: String,
        field: &'static str,
        msg: String,
    },
    /// A `--labels` choice that names no label of the file.
    #[error("--labels {spec}: {msg}")]
    Choice { spec: String, msg: String },
}

/// The colour of a label a table does not name: hues a golden angle apart
/// (label `i` and `i + 1` differ by 137.5 degrees), fairly saturated and
/// bright, so neighbouring numbers look different.
pub fn default_colour(id: u32) -> [f64; 3] {
    let h = (id as f64 * 0.618_033_988_749_895 + 0.05).fract() * 6.0;
    let (s, v) = (0.6, 0.92);
    let f = h.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match h as u32 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

impl LabelTable {
    /// The entry of label `id`.
    pub fn get(&self, id: u32) -> Option<&LabelEntry> {
        self.labels
            .binary_search_by_key(&id, |e| e.id)
            .ok()
            .map(|i| &self.labels[i])
    }

    /// Reads a colour table: JSON (a `.json` name, or text starting with
    /// `{`), an ITK-SNAP label description (lines with a quoted name), or
    /// a FreeSurfer colour LUT (`id name R G B A`).
    pub fn load(path: &Path) -> Result<LabelTable, LabelError> {
        let text = crate::classify::read_tf_text(path).map_err(|e| LabelError::Table {
            path: path.to_path_buf(),
            msg: e.msg,
        })?;
        LabelTable::parse(path, &text)
    }

    /// [`LabelTable::load`] of `text`, the contents of `path`.
    pub fn parse(path: &Path, text: &str) -> Result<LabelTable, LabelError> {
        let e = |msg: String| LabelError::Table {
            path: path.to_path_buf(),
            msg,
        };
        let json =
            path.extension().is_some_and(|x| x == "json") || text.trim_start().starts_with('{');
        let mut table = if json {
            if let Some(key) = crate::json::duplicate_key(text) {
                return Err(e(format!("{key}: duplicate key, expected each key once")));
            }
            serde_json::from_str::<LabelTable>(text).map_err(|x| {
                e(format!(
                    "expected {{\"labels\": [{{\"id\", \"name\", \"color\": [r, g, b] in 0..1, \
                     \"opacity\"}}, ...]}}: {x}"
                ))
            })?
        } else {
            let itk = text
                .lines()
                .any(|l| !l.trim_start().starts_with('#') && l.contains('"'));
            parse_lines(path, text, itk)?
        };
        table.labels.sort_by_key(|l| l.id);
        table.check(path)?;
        Ok(table)
    }

    /// Every id in 0..=[`MAX_LABEL`] and once; colours and opacities in
    /// [0, 1]; names not empty. Errors name `path`.
    fn check(&self, path: &Path) -> Result<(), LabelError> {
        let fail = |msg: String| {
            Err(LabelError::Table {
                path: path.to_path_buf(),
                msg,
            })
        };
        for (i, l) in self.labels.iter().enumerate() {
            let at = format!("label {}", l.id);
            if l.id > MAX_LABEL {
                return fail(format!("{at}: expected a label in 0..={MAX_LABEL}"));
            }
            if i > 0 && self.labels[i - 1].id == l.id {
                return fail(format!("{at}: given twice, expected each label once"));
            }
            if l.color.iter().any(|c| !(0.0..=1.0).contains(c)) {
                return fail(format!(
                    "{at}: color {:?}, expected three numbers in 0..=1",
                    l.color
                ));
            }
            if !(0.0..=1.0).contains(&l.opacity) {
                return fail(format!("{at}: opacity {}, expected 0..=1", l.opacity));
            }
            if l.name.trim().is_empty() {
                return fail(format!("{at}: empty name"));
            }
        }
        Ok(())
    }
}

/// An ITK-SNAP label description (`itk`: `IDX R G B A VIS MSH "NAME"`,
/// colours 0..255, A the opacity 0..1, VIS 0 hides the label) or a
/// FreeSurfer LUT (`ID NAME R G B A`, A the transparency 0..255, 0 =
/// opaque). `#` starts a comment.
fn parse_lines(path: &Path, text: &str, itk: bool) -> Result<LabelTable, LabelError> {
    let err = |msg: String| LabelError::Table {
        path: path.to_path_buf(),
        msg,
    };
    let mut labels = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let at = |field: &str, found: &str, expected: &str| {
            err(format!(
                "line {}: field {field}: found {found:?}, expected {expected}",
                n + 1
            ))
        };
        let (fields, name) = if itk {
            let q = line.find('"').ok_or_else(|| {
                at(
                    "LABEL",
                    line,
                    "a quoted name at the end (ITK-SNAP: IDX R G B A VIS MSH \"NAME\")",
                )
            })?;
            let name = line[q + 1..].trim_end().trim_end_matches('"').to_string();
            (line[..q].split_whitespace().collect::<Vec<_>>(), name)
        } else {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() < 5 {
                return Err(at(
                    "line",
                    line,
                    "ID NAME R G B [A] (a FreeSurfer colour LUT), or an ITK-SNAP or JSON table",
                ));
            }
            let name = f[1].to_string();
            let mut rest = vec![f[0]];
            rest.extend_from_slice(&f[2..]);
            (rest, name)
        };
        let want = if itk { 7 } else { 4 };
        if fields.len() < want {
            return Err(at(
                "line",
                line,
                if itk {
                    "IDX R G B A VIS MSH \"NAME\" (ITK-SNAP)"
                } else {
                    "ID NAME R G B [A] (FreeSurfer)"
                },
            ));
        }
        let id: u32 = fields[0]
            .parse()
            .map_err(|_| at("ID", fields[0], &format!("a label in 0..={MAX_LABEL}")))?;
        let byte = |i: usize, f: &str| -> Result<f64, LabelError> {
            match fields[i].parse::<u32>() {
                Ok(v) if v <= 255 => Ok(v as f64 / 255.0),
                _ => Err(at(f, fields[i], "an integer in 0..=255")),
            }
        };
        let color = [byte(1, "R")?, byte(2, "G")?, byte(3, "B")?];
        let opacity = if itk {
            let a: f64 = fields[4]
                .parse()
                .ok()
                .filter(|a: &f64| (0.0..=1.0).contains(a))
                .ok_or_else(|| at("A", fields[4], "an opacity in 0..=1"))?;
            let vis: u32 = fields[5]
                .parse()
                .ok()
                .filter(|v| *v <= 1)
                .ok_or_else(|| at("VIS", fields[5], "0 or 1"))?;
            if vis == 0 {
                0.0
            } else {
                a
            }
        } else if fields.len() > 4 {
            1.0 - byte(4, "A")?
        } else {
            1.0
        };
        labels.push(LabelEntry {
            id,
            name,
            color,
            opacity,
        });
    }
    if labels.is_empty() {
        return Err(err(
            "no label lines, expected an ITK-SNAP, FreeSurfer or JSON colour table".into(),
        ));
    }
    Ok(LabelTable { labels })
}

/// Counts the labels of a volume slice by slice, refusing a value that
/// is not a label.
pub struct LabelCounter {
    counts: Vec<u64>,
    source_desc: String,
}

impl LabelCounter {
    /// A counter for the volume `source_desc` names (for errors).
    pub fn new(source_desc: &str) -> LabelCounter {
        LabelCounter {
            counts: vec![0; MAX_LABEL as usize + 1],
            source_desc: source_desc.to_string(),
        }
    }

    /// Counts slice `z` (samples x fastest, `nx` a row; raw values):
    /// every value must be a whole number in 0..=[`MAX_LABEL`].
    pub fn add_slice(&mut self, values: &[f64], nx: usize, z: usize) -> Result<(), LabelError> {
        for (i, &v) in values.iter().enumerate() {
            if v >= 0.0 && v <= MAX_LABEL as f64 && v.fract() == 0.0 {
                self.counts[v as usize] += 1;
            } else {
                return Err(LabelError::Volume {
                    source_desc: self.source_desc.clone(),
                    field: "labels",
                    msg: format!(
                        "value {v} at sample ({}, {}, {z}), expected a label in 0..={MAX_LABEL}",
                        i % nx.max(1),
                        i / nx.max(1)
                    ),
                });
            }
        }
        Ok(())
    }

    /// Samples per label so far, `0..=`[`MAX_LABEL`].
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// A counter holding `counts` (merged from the shards of a sharded
    /// prep): `counts.len()` must be [`MAX_LABEL`] + 1.
    pub fn from_counts(source_desc: &str, counts: Vec<u64>) -> LabelCounter {
        assert_eq!(counts.len(), MAX_LABEL as usize + 1, "a count per label");
        LabelCounter {
            counts,
            source_desc: source_desc.to_string(),
        }
    }

    /// The labels seen and their counts.
    pub fn finish(self, table: Option<LabelTable>) -> LabelInfo {
        LabelInfo {
            counts: self
                .counts
                .iter()
                .enumerate()
                .skip(1)
                .filter(|(_, &n)| n > 0)
                .map(|(i, &n)| (i as u32, n))
                .collect(),
            background: self.counts[0],
            table,
        }
    }
}

/// What a label render draws: the chosen labels, each with its colour
/// and opacity.
#[derive(Clone, PartialEq)]
pub struct LabelStyle {
    /// `slot[label]`: 0 when the label is not drawn, else 1 + its index
    /// in `ids`.
    slot: Vec<u16>,
    /// The chosen labels, ascending.
    pub ids: Vec<u32>,
    /// Colour per chosen label, in [0, 1].
    pub colour: Vec<[f32; 3]>,
    /// Opacity per chosen label, in (0, 1].
    pub opacity: Vec<f32>,
}

/// The chosen labels, colours and opacities (not the 64 Ki-entry slot
/// table): render part keys hold the options' debug text.
impl std::fmt::Debug for LabelStyle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LabelStyle")
            .field("ids", &self.ids)
            .field("colour", &self.colour)
            .field("opacity", &self.opacity)
            .finish()
    }
}

impl LabelStyle {
    /// The style of `spec` on a file with labels `info`: `all` (every
    /// label the table does not hide), or a comma-separated list of
    /// labels (`5`), ranges (`5-9`) and names from the table (`Brain-Stem`,
    /// any case). `table` replaces the file's own. A label given that the
    /// file does not hold is refused, naming those it holds.
    pub fn parse(
        spec: &str,
        info: &LabelInfo,
        table: Option<&LabelTable>,
    ) -> Result<LabelStyle, LabelError> {
        let table = table.or(info.table.as_ref());
        let e = |msg: String| LabelError::Choice {
            spec: spec.to_string(),
            msg,
        };
        let held = || {
            let all: Vec<String> = info.counts.iter().map(|c| c.0.to_string()).collect();
            if all.len() > 20 {
                format!(
                    "{} .. {} ({} labels)",
                    all[0],
                    all[all.len() - 1],
                    all.len()
                )
            } else if all.is_empty() {
                "none".into()
            } else {
                all.join(", ")
            }
        };
        let mut ids: Vec<u32> = Vec::new();
        if spec.trim() == "all" {
            ids = info
                .counts
                .iter()
                .map(|c| c.0)
                .filter(|&id| {
                    table
                        .and_then(|t| t.get(id))
                        .is_none_or(|l| l.opacity > 0.0)
                })
                .collect();
        } else {
            for item in spec.split(',').map(str::trim) {
                if item.is_empty() {
                    return Err(e("an empty item, expected labels, ranges or names".into()));
                }
                let num = |s: &str| s.trim().parse::<u32>().ok().filter(|&v| v <= MAX_LABEL);
                if let Some(v) = num(item) {
                    ids.push(v);
                } else if let Some((a, b)) = item
                    .split_once('-')
                    .and_then(|(a, b)| Some((num(a)?, num(b)?)))
                {
                    if a > b {
                        return Err(e(format!("range {item}: its start is above its end")));
                    }
                    let inside: Vec<u32> = info
                        .counts
                        .iter()
                        .map(|c| c.0)
                        .filter(|id| (a..=b).contains(id))
                        .collect();
                    if inside.is_empty() {
                        return Err(e(format!(
                            "range {item} holds no label of the file; it holds {}",
                            held()
                        )));
                    }
                    ids.extend(inside);
                } else {
                    let found = table.and_then(|t| {
                        t.labels
                            .iter()
                            .find(|l| l.name.eq_ignore_ascii_case(item))
                            .map(|l| l.id)
                    });
                    match found {
                        Some(id) => ids.push(id),
                        None => {
                            return Err(e(format!(
                                "{item:?} is neither a label in 0..={MAX_LABEL}, a range A-B, \
                                 nor a name in the colour table{}",
                                if table.is_none() {
                                    " (the file has none: give one with --lut)"
                                } else {
                                    ""
                                }
                            )))
                        }
                    }
                }
            }
        }
        ids.sort_unstable();
        ids.dedup();
        if let Some(&id) = ids.iter().find(|&&id| id == 0) {
            return Err(e(format!(
                "label {id} is the background, expected labels 1..={MAX_LABEL}"
            )));
        }
        if let Some(&id) = ids.iter().find(|&&id| !info.holds(id)) {
            return Err(e(format!(
                "label {id} does not occur in the file; it holds {}",
                held()
            )));
        }
        if ids.is_empty() {
            return Err(e(format!("no label to draw; the file holds {}", held())));
        }
        let entry = |id: u32| table.and_then(|t| t.get(id));
        let mut slot = vec![0u16; MAX_LABEL as usize + 1];
        for (i, &id) in ids.iter().enumerate() {
            slot[id as usize] = (i + 1) as u16;
        }
        Ok(LabelStyle {
            slot,
            colour: ids
                .iter()
                .map(|&id| {
                    entry(id)
                        .map_or(default_colour(id), |l| l.color)
                        .map(|c| c as f32)
                })
                .collect(),
            opacity: ids
                .iter()
                .map(|&id| {
                    entry(id).map_or(1.0, |l| if l.opacity > 0.0 { l.opacity } else { 1.0 }) as f32
                })
                .collect(),
            ids,
        })
    }

    /// 1 + the index of `label` among the chosen, or 0 when it is not
    /// drawn.
    #[inline]
    pub fn slot(&self, label: u16) -> usize {
        self.slot[label as usize] as usize
    }

    /// A one-line description: `3 labels (1, 2, 5)`.
    pub fn describe(&self) -> String {
        let list: Vec<String> = self.ids.iter().take(8).map(u32::to_string).collect();
        format!(
            "{} label{} ({}{})",
            self.ids.len(),
            if self.ids.len() == 1 { "" } else { "s" },
            list.join(", "),
            if self.ids.len() > 8 { ", ..." } else { "" }
        )
    }
}

/// Weights of the smoothing kernel per axis, offsets -1, 0, +1: the
/// binomial [1, 2, 1] / 4.
const W: [f64; 3] = [0.25, 0.5, 0.25];

/// The smoothed indicator of `label` at sample `at` of the cubic block
/// `block` (edge `n`, x fastest; `at` at least one sample inside every
/// face): the binomial [1, 2, 1] / 4 filter of "this sample is `label`"
/// along each axis, then kept at least `0.5 + MARGIN` at samples of
/// `label` and at most `0.5 - MARGIN` at the others.
///
/// The clamp keeps the surface between every sample of the label and
/// every sample of another: the 0.5 level of the trilinear interpolant of
/// these values encloses exactly the label's samples, so a label is never
/// lost or grown by a sample, while the filter places the surface between
/// them smoothly (a flat boundary lies half-way, at 0.75 against 0.25; a
/// staircase is evened out). Only cells with a vertex of the label can
/// hold its surface, so the union of the labels' 1-cells holds them all.
#[inline]
pub fn smoothed(block: &[u16], n: usize, at: [usize; 3], label: u16) -> f64 {
    let s = filtered(block, n, at, label);
    if block[(at[2] * n + at[1]) * n + at[0]] == label {
        s.max(0.5 + MARGIN)
    } else {
        s.min(0.5 - MARGIN)
    }
}

/// [`smoothed`] before the clamp: the binomial filter of the indicator
/// alone, whose gradient shades the surface (the clamp's kinks would show
/// as streaks).
#[inline]
pub fn filtered(block: &[u16], n: usize, at: [usize; 3], label: u16) -> f64 {
    let mut s = 0.0;
    for (dz, wz) in W.iter().enumerate() {
        for (dy, wy) in W.iter().enumerate() {
            let row = ((at[2] + dz - 1) * n + at[1] + dy - 1) * n + at[0] - 1;
            for (dx, wx) in W.iter().enumerate() {
                if block[row + dx] == label {
                    s += wx * wy * wz;
                }
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(ids: &[u32]) -> LabelInfo {
        LabelInfo {
            counts: ids.iter().map(|&i| (i, 10)).collect(),
            background: 100,
            table: None,
        }
    }

    #[test]
    fn itk_snap_table() {
        let text = "################################################\n\
                    # ITK-SnAP Label Description File\n\
                    #  IDX   -R-  -G-  -B-  -A--  VIS MSH  LABEL\n\
                    ################################################\n\
                        0     0    0    0        0  0  0    \"Clear Label\"\n\
                        1   255    0    0        1  1  1    \"Left ventricle\"\n\
                        7     0  255    0      0.5  1  1    \"Liver\"\n\
                        9     0    0  255        1  0  1    \"Hidden\"\n";
        let t = LabelTable::parse(Path::new("x.txt"), text).unwrap();
        assert_eq!(t.labels.len(), 4);
        let l = t.get(1).unwrap();
        assert_eq!(
            (l.name.as_str(), l.color, l.opacity),
            ("Left ventricle", [1.0, 0.0, 0.0], 1.0)
        );
        assert_eq!(t.get(7).unwrap().opacity, 0.5);
        assert_eq!(t.get(9).unwrap().opacity, 0.0);
    }

    #[test]
    fn freesurfer_table() {
        let text = "#$Id: FreeSurferColorLUT.txt\n\
                    #No. Label Name:                            R   G   B   A\n\
                    0   Unknown                                 0   0   0   0\n\
                    4   Left-Lateral-Ventricle                  120 18  134 0\n\
                    17  Left-Hippocampus                        220 216 20  0\n";
        let t = LabelTable::parse(Path::new("FreeSurferColorLUT.txt"), text).unwrap();
        let h = t.get(17).unwrap();
        assert_eq!(h.name, "Left-Hippocampus");
        assert_eq!(h.color, [220.0 / 255.0, 216.0 / 255.0, 20.0 / 255.0]);
        assert_eq!(h.opacity, 1.0);
    }

    #[test]
    fn json_table_and_errors() {
        let t = LabelTable::parse(
            Path::new("t.json"),
            r#"{"labels": [{"id": 2, "name": "bone", "color": [1, 1, 0.9]}, {"id": 1, "name": "skin", "color": [1, 0.8, 0.7], "opacity": 0.3}]}"#,
        )
        .unwrap();
        assert_eq!(t.labels[0].id, 1);
        assert_eq!(t.get(1).unwrap().opacity, 0.3);
        for (name, text, want) in [
            (
                "a.json",
                r#"{"labels": [{"id": 1, "name": "a", "color": [2, 0, 0]}]}"#,
                "color",
            ),
            (
                "a.json",
                r#"{"labels": [{"id": 70000, "name": "a", "color": [0, 0, 0]}]}"#,
                "0..=65535",
            ),
            (
                "a.json",
                r#"{"labels": [{"id": 1, "name": "a", "color": [0, 0, 0]}, {"id": 1, "name": "b", "color": [0, 0, 0]}]}"#,
                "twice",
            ),
            ("a.json", "{\"labels\": [", "expected"),
            ("a.txt", "1 skin 255 0\n", "line 1: field line"),
            ("a.txt", "1 skin 255 0 300 0\n", "line 1: field B"),
            ("a.txt", "1 255 0 0 1.5 1 1 \"x\"\n", "field A"),
            ("a.txt", "# only comments\n", "no label lines"),
        ] {
            let err = LabelTable::parse(Path::new(name), text)
                .unwrap_err()
                .to_string();
            assert!(err.starts_with(name) && err.contains(want), "{text}: {err}");
        }
    }

    #[test]
    fn choices() {
        let i = info(&[1, 2, 5, 6, 9, 300]);
        let s = LabelStyle::parse("1,5-9", &i, None).unwrap();
        assert_eq!(s.ids, vec![1, 5, 6, 9]);
        assert_eq!((s.slot(5), s.slot(2), s.slot(9)), (2, 0, 4));
        assert_eq!(LabelStyle::parse("all", &i, None).unwrap().ids.len(), 6);
        let t = LabelTable {
            labels: vec![LabelEntry {
                id: 300,
                name: "Brain-Stem".into(),
                color: [0.5, 0.5, 0.5],
                opacity: 0.4,
            }],
        };
        let s = LabelStyle::parse("brain-stem,2", &i, Some(&t)).unwrap();
        assert_eq!(s.ids, vec![2, 300]);
        assert_eq!(s.colour[1], [0.5; 3]);
        assert_eq!(s.opacity, vec![1.0, 0.4]);
        for (spec, want) in [
            ("3", "label 3 does not occur"),
            ("10-20", "holds no label"),
            ("0", "background"),
            ("bone", "the file has none"),
            ("1,,2", "empty item"),
            ("9-5", "start is above"),
        ] {
            let err = LabelStyle::parse(spec, &i, None).unwrap_err().to_string();
            assert!(err.contains(want), "{spec}: {err}");
        }
    }

    #[test]
    fn smoothing_keeps_the_labels_samples_inside() {
        // A flat boundary: the label fills z <= 0 of the block.
        let mut near = [0u16; 27];
        for (i, l) in near.iter_mut().enumerate() {
            if i / 9 <= 1 {
                *l = 3;
            }
        }
        assert_eq!(smoothed(&near, 3, [1; 3], 3), 0.75);
        // An isolated sample, and a sample beside a full block.
        let mut lone = [0u16; 27];
        lone[13] = 3;
        assert_eq!(smoothed(&lone, 3, [1; 3], 3), 0.5 + MARGIN);
        let mut hole = [3u16; 27];
        hole[13] = 0;
        assert_eq!(smoothed(&hole, 3, [1; 3], 3), 0.5 - MARGIN);
    }

    #[test]
    fn counter_refuses_what_is_no_label() {
        let mut c = LabelCounter::new("seg.nii");
        c.add_slice(&[0.0, 1.0, 1.0, 7.0], 2, 0).unwrap();
        let info = c.finish(None);
        assert_eq!(info.counts, vec![(1, 2), (7, 1)]);
        assert_eq!(info.background, 1);
        assert!(info.holds(7) && !info.holds(2));
        let mut c = LabelCounter::new("seg.nii");
        let err = c.add_slice(&[0.0, -1.0], 2, 4).unwrap_err().to_string();
        assert!(
            err.contains("seg.nii") && err.contains("value -1 at sample (1, 0, 4)"),
            "{err}"
        );
        let err = c.add_slice(&[70000.0], 2, 5).unwrap_err().to_string();
        assert!(err.contains("0..=65535"), "{err}");
        let err = c.add_slice(&[2.5], 2, 6).unwrap_err().to_string();
        assert!(err.contains("value 2.5"), "{err}");
    }

    #[test]
    fn default_colours_differ() {
        for id in 0..100 {
            let (a, b) = (default_colour(id), default_colour(id + 1));
            let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum();
            assert!(d > 0.2, "{id}: {a:?} {b:?}");
            assert!(a.iter().all(|c| (0.0..=1.0).contains(c)));
        }
    }
}
