//! `cdvol info INPUT`: an input described before it is prepared (issue
//! 51, item 7): what kind of file it is, its grid (dims, spacing or slice
//! positions, extent), sample type, rescale and orientation, and the value
//! range, from one pass over its slices, so that an iso value or a window
//! can be chosen before `prep`.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::{InputError, SliceSource};
use crate::progress::Progress;

/// One axis: samples, smallest and largest gap, extent (mm).
#[derive(Debug, Clone, Serialize)]
pub struct InputAxis {
    pub samples: usize,
    pub spacing_min: f64,
    pub spacing_max: f64,
    pub uniform: bool,
    pub extent: [f64; 2],
}

/// What `cdvol info` prints of an input that is not a packed file.
#[derive(Debug, Clone, Serialize)]
pub struct InputInfo {
    pub input: String,
    /// `DICOM series`, `NRRD`, `NIfTI-1` or `raw stack (JSON sidecar)`.
    pub kind: String,
    /// Where the volume comes from, as prep records it.
    pub source: String,
    pub axes: [InputAxis; 3],
    pub dtype: String,
    /// Stored value to data value: `slope * raw + intercept`.
    pub rescale: [f64; 2],
    /// The patient orientation of the sample axes, or why it is unknown.
    pub orientation: String,
    /// Smallest and largest data value (rescaled), NaN left out; `None`
    /// when every sample is NaN.
    pub value_range: Option<[f64; 2]>,
    /// CT or MR, and where that came from: what the input states, or a
    /// guess from the smallest value ([`crate::presets::Modality::guess`]), as
    /// `prep` decides it (`prep --modality` overrides).
    pub modality: String,
    pub nan_samples: u64,
    /// What the reader noticed (slice gaps, warnings).
    pub notes: Vec<String>,
}

impl InputInfo {
    /// Describes `src`, opened from `path` as `kind`, reading every slice
    /// once (`progress` counts them).
    pub fn of(
        path: &Path,
        kind: &str,
        src: &dyn SliceSource,
        progress: &dyn Progress,
    ) -> Result<InputInfo, InputError> {
        let meta = src.meta();
        let [nx, ny, nz] = meta.dims();
        let mut buf = vec![0.0; nx * ny];
        let (mut lo, mut hi, mut nan) = (f64::INFINITY, f64::NEG_INFINITY, 0u64);
        progress.begin("reading slices", nz as u64);
        for z in 0..nz {
            src.read_slice(z, &mut buf)?;
            for &v in &buf {
                if v.is_nan() {
                    nan += 1;
                } else {
                    let v = meta.rescale.apply(v);
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            progress.advance(1);
        }
        progress.end();
        let axes = std::array::from_fn(|k| {
            let a = &meta.grid.axes[k];
            let (smin, smax) = a.spacing_range();
            let c = a.coords();
            InputAxis {
                samples: a.samples(),
                spacing_min: smin,
                spacing_max: smax,
                uniform: a.is_uniform(),
                extent: [c[0], c[c.len() - 1]],
            }
        });
        Ok(InputInfo {
            input: path.display().to_string(),
            kind: kind.to_string(),
            source: meta.origin_desc.clone(),
            axes,
            dtype: meta.dtype.name().to_string(),
            rescale: [meta.rescale.slope, meta.rescale.intercept],
            orientation: match &meta.orientation {
                Some(o) => o.describe(),
                None => "unknown: the input does not say which way the axes point in the \
                         patient (left and right too); named views need it"
                    .into(),
            },
            value_range: (lo <= hi).then_some([lo, hi]),
            modality: match src.modality() {
                Some((m, place)) => format!("{m} ({place})"),
                None => {
                    let (m, why) = crate::presets::Modality::guess(lo);
                    format!("{} (guessed: {why}; prep --modality sets it)", m.name())
                }
            },
            nan_samples: nan,
            notes: src.report(),
        })
    }

    /// The text `cdvol info` prints.
    pub fn to_text(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(
            o,
            "input        {} ({}, not prepared)",
            self.input, self.kind
        );
        let _ = writeln!(o, "source       {}", self.source);
        for n in &self.notes {
            let _ = writeln!(o, "             {n}");
        }
        let _ = writeln!(o, "orientation  {}", self.orientation);
        let _ = writeln!(o, "modality     {}", self.modality);
        let d = self.axes.each_ref().map(|a| a.samples);
        let _ = writeln!(o, "dims         {} x {} x {} samples", d[0], d[1], d[2]);
        for (name, a) in ["x", "y", "z"].iter().zip(&self.axes) {
            let kind = if a.uniform { "uniform" } else { "rectilinear" };
            let _ = writeln!(
                o,
                "spacing {name}    {:.4} .. {:.4} mm ({kind}), extent {:.3} .. {:.3} mm",
                a.spacing_min, a.spacing_max, a.extent[0], a.extent[1]
            );
        }
        let _ = writeln!(
            o,
            "samples      {}, rescale {} x stored + {}",
            self.dtype, self.rescale[0], self.rescale[1]
        );
        match self.value_range {
            Some([a, b]) => {
                let _ = writeln!(
                    o,
                    "values       {a} .. {b} (rescaled), {} NaN samples",
                    self.nan_samples
                );
            }
            None => {
                let _ = writeln!(o, "values       every sample is NaN");
            }
        }
        let _ = writeln!(
            o,
            "next         cdvol prep {} -o OUT.cdv --iso V | --preset NAME | --envelope auto",
            self.input
        );
        o
    }
}
