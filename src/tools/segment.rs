//! `cdvol segment`: a label map of a CT made by thresholds, for trying
//! label rendering on real data (issue 55's demo) without a segmentation
//! tool: 1 soft tissue (HU -400 .. 250), 2 bone (HU >= 250) and 3 air
//! spaces (HU < -400 that the outside air does not reach through
//! 6-connected air: sinuses, airways closed within the scan, the ear
//! canals' inner parts). Written as a u8 raw stack with a sidecar on the
//! input's grid and orientation, and a colour table (`<stem>.lut.json`:
//! soft tissue translucent), ready for `cdvol prep --labels --lut`.
//!
//! The whole label volume is held in memory (one byte a sample, plus one
//! for the flood fill): it is a demonstration, not a segmentation tool.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use crate::input::sidecar::SidecarOut;
use crate::input::Endian;
use crate::input::InputError;
use crate::labels::{LabelEntry, LabelTable};
use crate::progress::Progress;

/// Below this (HU) a sample is air.
pub const AIR_HU: f64 = -400.0;
/// At or above this (HU) a sample is bone.
pub const BONE_HU: f64 = 250.0;

/// Why `segment` wrote nothing.
#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Output(#[from] crate::fsutil::OutputError),
    #[error(transparent)]
    Write(#[from] crate::fsutil::WriteError),
    /// The volume is too large to hold in memory here.
    #[error("{input}: {samples} samples; segment holds the whole label volume and stops at {max}")]
    TooLarge {
        input: String,
        samples: u64,
        max: u64,
    },
}

/// Largest volume segmented (4 Gi samples: 8 GiB with the flood fill).
pub const MAX_SAMPLES: u64 = 1 << 32;

/// What `segment` wrote: the sidecar, the raw stack and the colour table,
/// and the samples of each label (0 to 3).
#[derive(Debug, Clone)]
pub struct Segmented {
    pub sidecar: PathBuf,
    pub raw: PathBuf,
    pub lut: PathBuf,
    pub counts: [u64; 4],
}

/// The colour table `segment` writes.
pub fn ct_table() -> LabelTable {
    let e = |id, name: &str, color, opacity| LabelEntry {
        id,
        name: name.into(),
        color,
        opacity,
    };
    LabelTable {
        labels: vec![
            e(1, "soft-tissue", [0.96, 0.72, 0.62], 0.25),
            e(2, "bone", [0.95, 0.93, 0.84], 1.0),
            e(3, "air-spaces", [0.35, 0.65, 1.0], 1.0),
        ],
    }
}

/// Segments the CT `input` (any input `prep` reads, in HU after its
/// rescale) into the sidecar `out_json` (with `<stem>.raw` and
/// `<stem>.lut.json` beside it).
pub fn segment_ct(
    input: &Path,
    out_json: &Path,
    progress: &dyn Progress,
) -> Result<Segmented, SegmentError> {
    let src = crate::input::open(input)?;
    let meta = src.meta().clone();
    let [nx, ny, nz] = meta.dims();
    let n = nx as u64 * ny as u64 * nz as u64;
    if n > MAX_SAMPLES {
        return Err(SegmentError::TooLarge {
            input: meta.origin_desc.clone(),
            samples: n,
            max: MAX_SAMPLES,
        });
    }
    let stem = out_json
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "labels".into());
    let dir = crate::fsutil::dir_of(out_json);
    let raw = dir.join(format!("{stem}.raw"));
    let lut = dir.join(format!("{stem}.lut.json"));
    let outs = [out_json.to_path_buf(), raw.clone(), lut.clone()];
    crate::fsutil::check_outputs(&outs, &src.files(), Some(&meta.origin_desc))?;
    // 0 background air, 1 soft tissue, 2 bone; air that the outside
    // reaches is found below.
    let slice = nx * ny;
    let mut labels = vec![0u8; n as usize];
    let mut buf = vec![0.0f64; slice];
    progress.begin("segment: thresholds", nz as u64);
    for z in 0..nz {
        src.read_slice(z, &mut buf)?;
        for (o, &v) in labels[z * slice..(z + 1) * slice].iter_mut().zip(&buf) {
            let hu = meta.rescale.apply(v);
            *o = if hu >= BONE_HU {
                2
            } else if hu >= AIR_HU {
                1
            } else {
                0
            };
        }
        progress.advance(1);
    }
    progress.end();
    // Air reached from the volume's faces through 6-connected air.
    let mut outside = vec![false; n as usize];
    let mut q = VecDeque::new();
    let idx = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let face = x == 0 || y == 0 || z == 0 || x + 1 == nx || y + 1 == ny || z + 1 == nz;
                let i = idx(x, y, z);
                if face && labels[i] == 0 {
                    outside[i] = true;
                    q.push_back(i);
                }
            }
        }
    }
    while let Some(i) = q.pop_front() {
        let (x, y, z) = (i % nx, i / nx % ny, i / slice);
        let mut go = |j: usize| {
            if labels[j] == 0 && !outside[j] {
                outside[j] = true;
                q.push_back(j);
            }
        };
        if x > 0 {
            go(i - 1);
        }
        if x + 1 < nx {
            go(i + 1);
        }
        if y > 0 {
            go(i - nx);
        }
        if y + 1 < ny {
            go(i + nx);
        }
        if z > 0 {
            go(i - slice);
        }
        if z + 1 < nz {
            go(i + slice);
        }
    }
    let mut counts = [0u64; 4];
    for (l, &out) in labels.iter_mut().zip(&outside) {
        if *l == 0 && !out {
            *l = 3;
        }
        counts[*l as usize] += 1;
    }
    drop(outside);
    let (axes, origin) = SidecarOut::axes_of(&meta.grid);
    let [x, y, z] = axes;
    let side = SidecarOut {
        data: format!("{stem}.raw"),
        dims: [nx, ny, nz],
        dtype: "u8",
        endian: Endian::Little,
        header_bytes: 0,
        x,
        y,
        z,
        origin,
        rescale: None,
    };
    let mut json = serde_json::to_value(&side).expect("a sidecar serialises");
    if let Some(o) = &meta.orientation {
        json["orientation"] = serde_json::json!({ "lps": o.axes_lps });
    }
    let mut set = crate::fsutil::FileSet::new();
    set.add_bytes(&raw, &labels)?;
    let text = serde_json::to_string_pretty(&json).expect("JSON");
    set.add_bytes(out_json, text.as_bytes())?;
    let table = serde_json::to_string_pretty(&ct_table()).expect("JSON");
    set.add_bytes(&lut, table.as_bytes())?;
    set.commit()?;
    Ok(Segmented {
        sidecar: out_json.to_path_buf(),
        raw,
        lut,
        counts,
    })
}
