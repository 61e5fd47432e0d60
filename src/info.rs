//! `cdvol info`: what a packed file holds, from its header and index.

use serde::Serialize;

use crate::format::histogram::ValueHistogram;
use crate::format::reader::PackedVolume;
use crate::format::{CodeEncoding, Header};

/// Spacing figures of one axis.
#[derive(Debug, Clone, Serialize)]
pub struct AxisInfo {
    pub samples: u64,
    pub min_spacing_mm: f64,
    pub max_spacing_mm: f64,
    pub uniform: bool,
    pub extent_mm: [f64; 2],
}

/// Everything `cdvol info` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Info {
    pub file: String,
    pub file_bytes: u64,
    /// The file's format version (docs/FORMAT.md).
    pub format_version: u32,
    pub source: String,
    /// The input's notes (a DICOM series' z spacing report).
    pub notes: Vec<String>,
    /// The patient orientation as `LPS from DICOM ImageOrientationPatient`
    /// (with the angle when oblique), or `unknown`.
    pub orientation: String,
    /// The directions behind it (LPS), when known.
    pub orientation_axes_lps: Option<[[f64; 3]; 3]>,
    /// `CT` or `MR`, and where that came from (`modality_source`).
    pub modality: String,
    pub modality_source: String,
    /// The values MR presets are placed on (docs/PRESETS.md).
    pub landmarks: Option<crate::format::landmarks::Landmarks>,
    /// The file's default look: the preset it was prepared with.
    pub look: Option<String>,
    pub dims: [u64; 3],
    pub cells: [u64; 3],
    pub axes: [AxisInfo; 3],
    pub dtype: String,
    pub storage: String,
    pub codes: CodeEncoding,
    pub classification: serde_json::Value,
    /// The classification in words, for the text form.
    #[serde(skip)]
    pub classification_text: String,
    /// What renders from this file without another prep (issue 16).
    pub envelope: EnvelopeInfo,
    pub brick_size: u32,
    pub bricks: [u64; 3],
    pub brick_count: u64,
    pub uniform_bricks: u64,
    pub one_cells: u64,
    pub one_cell_fraction: f64,
    /// `[code, count]` for every code that occurs.
    pub code_histogram: Vec<[u64; 2]>,
    pub aniso_block: Option<u32>,
    /// City-block and chamfer distance planes present (`--dda`).
    pub dda: bool,
    /// Codes embedded only where >= 2 (`--gradient-halo`).
    pub gradient_halo: bool,
    pub input_bytes: u64,
    pub payload_bytes: u64,
    /// Input sample bytes divided by file bytes.
    pub compression_ratio: f64,
    pub raw_min: Option<f64>,
    pub raw_max: Option<f64>,
    pub nan_samples: u64,
    /// Histogram and percentiles of the rescaled values (files prepared
    /// before it was recorded have none).
    pub histogram: Option<ValueHistogram>,
    /// The classification selected no cells or nearly all of them.
    pub selection_warning: Option<String>,
    /// A label file's labels, counts and colour table (`prep --labels`).
    pub labels: Option<crate::labels::LabelInfo>,
}

/// `x` to about four significant digits, for the text form.
fn short(x: f64) -> String {
    match x.abs() {
        a if a >= 1000.0 => format!("{x:.0}"),
        a if a >= 10.0 => format!("{x:.1}"),
        a if a >= 0.1 => format!("{x:.3}"),
        _ => format!("{x:.3e}"),
    }
}

impl Info {
    pub fn of(vol: &PackedVolume) -> Info {
        let h: &Header = vol.header();
        let s = &h.summary;
        let axes = std::array::from_fn(|k| {
            let a = &h.axes[k];
            let (lo, hi) = a.spacing_range();
            AxisInfo {
                samples: a.samples() as u64,
                min_spacing_mm: lo,
                max_spacing_mm: hi,
                uniform: a.is_uniform(),
                extent_mm: [a.coords()[0], a.coords()[a.cells()]],
            }
        });
        Info {
            file: vol.path().display().to_string(),
            file_bytes: vol.file_len(),
            format_version: h.format_version,
            source: h.source.clone(),
            notes: h.notes.clone(),
            orientation: h
                .orientation
                .as_ref()
                .map_or_else(|| "unknown".to_string(), |o| o.describe()),
            orientation_axes_lps: h.orientation.as_ref().map(|o| o.axes_lps),
            modality: h.modality().modality.name().into(),
            modality_source: h.modality().source,
            landmarks: h.landmarks(),
            look: h.look.clone(),
            dims: h.dims,
            cells: h.cells(),
            axes,
            dtype: h.dtype.name().into(),
            storage: h.storage.name().into(),
            codes: h.codes,
            classification: serde_json::to_value(&h.classification).unwrap_or_default(),
            classification_text: h.classification.to_string(),
            envelope: EnvelopeInfo::of(&h.classification, &crate::look::offered(h)),
            brick_size: h.brick_size,
            bricks: h.bricks,
            brick_count: h.brick_count(),
            uniform_bricks: s.uniform_bricks,
            one_cells: s.one_cells,
            one_cell_fraction: s.one_cells as f64 / s.cells.max(1) as f64,
            code_histogram: s
                .code_histogram
                .iter()
                .enumerate()
                .filter(|(_, &n)| n > 0)
                .map(|(c, &n)| [c as u64, n])
                .collect(),
            aniso_block: h.aniso_block,
            dda: h.dda,
            gradient_halo: h.gradient_halo,
            input_bytes: s.input_bytes,
            payload_bytes: s.payload_bytes,
            compression_ratio: s.input_bytes as f64 / vol.file_len().max(1) as f64,
            raw_min: s.raw_min,
            raw_max: s.raw_max,
            nan_samples: s.nan_samples,
            histogram: s.histogram.clone(),
            selection_warning: crate::prep::selection_warning(h).map(|w| w.to_string()),
            labels: h.labels.clone(),
        }
    }

    /// Human-readable report.
    pub fn to_text(&self) -> String {
        use std::fmt::Write;
        let mut o = String::new();
        let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
        let _ = writeln!(
            o,
            "file         {} ({:.2} MiB)",
            self.file,
            mib(self.file_bytes)
        );
        let layout = if self.format_version >= crate::format::BYTE_PLANES_VERSION {
            "sample words as byte planes"
        } else {
            "sample words interleaved"
        };
        let _ = writeln!(o, "format       version {} ({layout})", self.format_version);
        let _ = writeln!(o, "source       {}", self.source);
        for n in &self.notes {
            let _ = writeln!(o, "             {n}");
        }
        let unknown = if self.orientation == "unknown" {
            ": the file does not say which way its axes point in the patient, left and right \
             included; named views are refused"
        } else {
            ""
        };
        let _ = writeln!(o, "orientation  {}{unknown}", self.orientation);
        if let Some(l) = &self.labels {
            // A label map has no modality, landmarks or presets.
            label_text(&mut o, l);
        } else {
            let _ = writeln!(
                o,
                "modality     {} ({})",
                self.modality, self.modality_source
            );
        }
        if let Some(l) = self.landmarks.as_ref().filter(|_| self.labels.is_none()) {
            let _ = writeln!(
                o,
                "landmarks    threshold {} (object above), object p50 {}, p95 {}, p99 {}; \
                 MR presets are placed on them ({})",
                short(l.threshold),
                short(l.p50),
                short(l.p95),
                short(l.p99),
                l.measured_on
            );
        }
        if let Some(look) = &self.look {
            let _ = writeln!(
                o,
                "look         {look} (prep --preset; render and serve use it by default)"
            );
        }
        let _ = writeln!(
            o,
            "dims         {} x {} x {} samples, {} x {} x {} cells",
            self.dims[0], self.dims[1], self.dims[2], self.cells[0], self.cells[1], self.cells[2]
        );
        for (name, a) in ["x", "y", "z"].iter().zip(&self.axes) {
            let kind = if a.uniform { "uniform" } else { "rectilinear" };
            let _ = writeln!(
                o,
                "spacing {name}    {:.4} .. {:.4} mm ({kind}), extent {:.3} .. {:.3} mm",
                a.min_spacing_mm, a.max_spacing_mm, a.extent_mm[0], a.extent_mm[1]
            );
        }
        let _ = writeln!(o, "samples      {} stored as {}", self.dtype, self.storage);
        if self.labels.is_some() {
            let _ = writeln!(
                o,
                "classify     the union of the labels (a cell with any vertex not 0)"
            );
        } else {
            let _ = writeln!(o, "classify     {}", self.classification_text);
            let e = &self.envelope;
            let _ = writeln!(o, "envelope     {}", e.statement);
            let list = |v: &[String]| {
                if v.is_empty() {
                    "none".to_string()
                } else {
                    v.join(", ")
                }
            };
            let _ = writeln!(
                o,
                "  presets    composite/--tf: {}",
                list(&e.composite_presets)
            );
            let _ = writeln!(
                o,
                "             surface/--iso:  {}",
                list(&e.surface_presets)
            );
        }
        let _ = writeln!(o, "codes        {}", self.codes);
        let _ = writeln!(
            o,
            "bricks       {} ({} x {} x {} of {}^3 cells), {} uniform (no payload)",
            self.brick_count,
            self.bricks[0],
            self.bricks[1],
            self.bricks[2],
            self.brick_size,
            self.uniform_bricks
        );
        if let Some(g) = self.aniso_block {
            let _ = writeln!(
                o,
                "aniso codes  8 octants per {g}^3 block (render's default traversal: cd-aniso)"
            );
        }
        if self.dda {
            let _ = writeln!(
                o,
                "dda planes   city block + chamfer 3-4-5, 1 byte each per cell"
            );
        }
        if self.gradient_halo {
            let _ = writeln!(
                o,
                "grad. halo   codes embedded only where >= 2 (samples near 1-cells kept)"
            );
        }
        let _ = writeln!(
            o,
            "1-cells      {} ({:.4} % of cells)",
            self.one_cells,
            100.0 * self.one_cell_fraction
        );
        let _ = writeln!(
            o,
            "size         input {:.2} MiB, payload {:.2} MiB, file {:.2} MiB, ratio {:.2}:1",
            mib(self.input_bytes),
            mib(self.payload_bytes),
            mib(self.file_bytes),
            self.compression_ratio
        );
        if let (Some(lo), Some(hi)) = (self.raw_min, self.raw_max) {
            let _ = writeln!(
                o,
                "raw range    {lo} .. {hi} ({} NaN samples)",
                self.nan_samples
            );
        }
        if let Some(w) = &self.selection_warning {
            let _ = writeln!(o, "warning      {w}");
        }
        if let Some(h) = &self.histogram {
            value_histogram_text(&mut o, h);
        }
        let _ = writeln!(
            o,
            "code histogram (0-cells per code range; --json has every code)"
        );
        // Saturating: a crafted header may hold any u64 counts.
        let total: u64 = self
            .code_histogram
            .iter()
            .fold(0u64, |s, c| s.saturating_add(c[1]));
        // Buckets 0, 1, 2-3, 4-7, ... so the text stays short.
        let mut buckets: Vec<(u64, u64, u64)> = Vec::new();
        for &[code, n] in &self.code_histogram {
            let lo = if code == 0 {
                0
            } else {
                1u64 << (63 - code.leading_zeros())
            };
            match buckets.last_mut() {
                Some(b) if b.0 == lo => b.2 = b.2.saturating_add(n),
                _ => buckets.push((lo, (2 * lo).max(1) - 1, n)),
            }
        }
        for (lo, hi, n) in buckets {
            let range = if lo == hi {
                format!("{lo}")
            } else {
                format!("{lo}-{hi}")
            };
            let frac = (n as f64 / total.max(1) as f64).min(1.0);
            let _ = writeln!(
                o,
                "  {range:>9}: {n:>12} {:5.1} % {}",
                100.0 * frac,
                "#".repeat((40.0 * frac) as usize)
            );
        }
        o
    }
}

/// Rows of the text histogram of values.
const VALUE_ROWS: usize = 16;

/// A number for a table or a plot label: integers without decimals,
/// others with up to 3 decimals.
pub(crate) fn num(v: f64) -> String {
    if v == v.round() && v.abs() < 1e15 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// The value range, percentiles and a coarse histogram (bars on a log
/// scale, so the small peaks show beside air).
fn value_histogram_text(o: &mut String, h: &ValueHistogram) {
    use std::fmt::Write;
    if let (Some(lo), Some(hi)) = (h.min, h.max) {
        let _ = writeln!(
            o,
            "values       {} .. {} (rescaled), {} samples, {} NaN{}",
            num(lo),
            num(hi),
            h.samples,
            h.nan,
            if h.infinite > 0 {
                format!(", {} infinite", h.infinite)
            } else {
                String::new()
            }
        );
    } else {
        let _ = writeln!(o, "values       none finite ({} NaN)", h.nan);
        return;
    }
    let ps: Vec<String> = h
        .percentiles
        .iter()
        .map(|p| format!("p{}={}", num(p[0]), num(p[1])))
        .collect();
    let _ = writeln!(
        o,
        "percentiles  {} ({})",
        ps.join(" "),
        if h.exact { "exact" } else { "within one bin" }
    );
    let _ = writeln!(
        o,
        "value histogram ({} bins of {}; rows of samples, bar log scale; --json has every bin, \
         `cdvol histogram` plots it)",
        h.counts.len(),
        num(h.bin_width)
    );
    let rows = h.coarse(VALUE_ROWS);
    let top = rows.iter().map(|r| r.2).max().unwrap_or(0).max(1);
    let total = h.samples.max(1);
    for (a, b, n) in rows {
        // Exact bins hold one value each: show the first and last value.
        let (a, b) = if h.exact {
            (a + h.bin_width / 2.0, b - h.bin_width / 2.0)
        } else {
            (a, b)
        };
        let bar = if n == 0 {
            0
        } else {
            (1.0 + 39.0 * (n as f64).ln() / (top as f64).ln().max(1e-9)).round() as usize
        };
        let _ = writeln!(
            o,
            "  {:>9} .. {:<9} {n:>12} {:5.1} % {}",
            num(a),
            num(b),
            100.0 * (n as f64 / total as f64).min(1.0),
            "#".repeat(bar.min(40))
        );
    }
}

/// A label file's labels for the text form: how many, then a line each
/// (at most 40) with its samples, name and colour.
fn label_text(o: &mut String, l: &crate::labels::LabelInfo) {
    use std::fmt::Write;
    let total: u64 = l.counts.iter().map(|c| c.1).sum::<u64>() + l.background;
    let _ = writeln!(
        o,
        "labels       {} labels besides 0 (render --labels; colours {})",
        l.counts.len(),
        if l.table.is_some() {
            "from the table given to prep --lut"
        } else {
            "from the default palette"
        }
    );
    for &(id, n) in l.counts.iter().take(40) {
        let e = l.table.as_ref().and_then(|t| t.get(id));
        let c = e.map_or(crate::labels::default_colour(id), |e| e.color);
        let _ = writeln!(
            o,
            "  {id:>6}     {n:>10} samples ({:.2} %){}  #{:02x}{:02x}{:02x}{}",
            100.0 * n as f64 / total.max(1) as f64,
            e.map_or(String::new(), |e| format!("  {}", e.name)),
            (c[0] * 255.0).round() as u8,
            (c[1] * 255.0).round() as u8,
            (c[2] * 255.0).round() as u8,
            e.filter(|e| e.opacity < 1.0)
                .map_or(String::new(), |e| format!(", opacity {}", e.opacity))
        );
    }
    if l.counts.len() > 40 {
        let _ = writeln!(
            o,
            "  ... ({} more; --json lists them all)",
            l.counts.len() - 40
        );
    }
}

/// The file's classification as an envelope: what `render` may ask of it
/// without another prep.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct EnvelopeInfo {
    /// In words: which iso values and transfer functions fit.
    pub statement: String,
    /// Presets whose transfer function fits (composite, `--preset`).
    pub composite_presets: Vec<String>,
    /// Presets whose iso value fits (surface, `--preset`).
    pub surface_presets: Vec<String>,
}

impl EnvelopeInfo {
    /// What renders from a file classified by `c`, of the presets it
    /// `offers` ([`crate::look::offered`]).
    fn of(c: &crate::classify::Classification, offers: &[crate::presets::Preset]) -> EnvelopeInfo {
        use crate::classify::Classification;
        let statement = match c {
            Classification::Iso { iso } => {
                format!("render --iso V for any V >= {iso}; --tf with no opacity below {iso}")
            }
            Classification::TransferFunction { tf } => {
                let p = &tf.points;
                let from = match p.iter().rposition(|q| q.opacity == 0.0) {
                    None => "V of any value".to_string(),
                    Some(i) if i + 1 == p.len() => "none (the function ends at zero)".to_string(),
                    Some(i) => format!("V > {}", p[i].value),
                };
                format!(
                    "render --tf with opacity only where the file's transfer function has some; \
                     --iso {from}"
                )
            }
        };
        let (composite_presets, surface_presets) = crate::presets::covered(c, offers);
        EnvelopeInfo {
            statement,
            composite_presets,
            surface_presets,
        }
    }
}
