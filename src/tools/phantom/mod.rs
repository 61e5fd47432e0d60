//! Test scenes, generated slice by slice: a raw stack plus a JSON sidecar in
//! the input schema ([`SidecarOut`](crate::input::sidecar::SidecarOut),
//! docs/FORMAT.md), never the whole volume in memory.
//!
//! - [`spheres`]: the phantom scenes of the paper's section 5.1 ("Comparison
//!   of Hierarchical and Distance Acceleration Techniques"). The volume's box
//!   in mm is cut into `N x N x N` equal subregions and one sphere is placed
//!   at a random position inside each; all spheres share one radius, chosen
//!   so that the total sphere volume is the same for every `N` (20 % of the
//!   box). Samples are a clamped linear ramp of the signed distance to the
//!   nearest sphere, so the iso surface 1000 of the trilinear interpolant
//!   lies close to the analytic spheres, which are written beside the stack
//!   (`<stem>.spheres.json`) for checking ray-surface intersections. Axes
//!   may be rectilinear ([`SpacingSpec::Linear`]).
//! - [`ct`]: a CT-like head in Hounsfield units (air, scalp, skull, brain,
//!   ventricles, eyes, neck with a spine) whose slice thickness varies along
//!   z like the paper's data set 2 (section 4.3: thin slices through the
//!   central part of the skull, 4x thicker ones at the top). Tissue
//!   boundaries are partial-volume ramps about 1.5 sample spacings wide.
//! - [`mr`]: a T1-weighted-like MR head on an arbitrary intensity scale
//!   (white matter = `scale`): scalp fat bright, skull and CSF dark, grey
//!   below white matter, a folded cortex, ventricles, eyes; partial-volume
//!   boundaries, a smooth bias field and Rician noise (the air is a
//!   Rayleigh floor, not 0), optionally skull-stripped (exact 0 outside
//!   the brain).
//!
//! All write to temporary files beside the target and rename them into
//! place together at the end (fsutil::FileSet), so a failure leaves
//! nothing partial behind. Slices are
//! computed in batches, rows in parallel (rayon), and written sequentially.
//!
//! ```text
//! spheres.rs  the sphere scenes and their spacing specs
//! ct.rs       the CT-like head
//! mr.rs       the MR head
//! here        errors, the shared writer (temporary files, slices in
//!             batches, the sidecar) and the seeded generator
//! ```

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;
use tempfile::NamedTempFile;

use crate::fsutil::{OutputError, WriteError};

use crate::progress::Progress;

mod ct;
mod mr;
mod spheres;

pub use ct::{ct, CtDtype, CtInfo, CtOptions};
pub use mr::{mr, MrDtype, MrInfo, MrOptions, MR_SURFACE_ISO};
pub use spheres::{
    load_spheres, parse_spacing3, spheres, SpacingError, SpacingSpec, Sphere, SpheresInfo,
    SpheresOptions,
};

/// The iso value of the sphere scenes: samples are `>= 1000` inside a sphere.
pub const SPHERES_ISO: f64 = 1000.0;

/// Suggested iso value (HU) for the skull (and spine) of the [`ct`] head.
pub const CT_BONE_ISO: f64 = 300.0;

/// Suggested iso value (HU) for the skin surface of the [`ct`] head.
pub const CT_SKIN_ISO: f64 = -300.0;

/// Largest number of subregions per axis of a sphere scene (`N^3` spheres
/// are kept in memory; the paper uses `N <= 21`).
pub const MAX_PER_AXIS: usize = 256;

/// Largest size of one z slice in bytes (one batch of slices is in memory).
const MAX_SLICE_BYTES: u64 = 1 << 32;

/// Slices computed per batch, at most (fewer when slices are large).
const BATCH_SLICES: usize = 8;

/// Memory budget of one batch of slices.
const BATCH_BYTES: usize = 64 << 20;

/// Errors of the phantom generators.
#[derive(Debug, thiserror::Error)]
pub enum PhantomError {
    /// An I/O error on a named file.
    #[error("{}: {what}: {source}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        source: std::io::Error,
    },
    /// An option is out of range.
    #[error("option {option}: {msg}")]
    Option { option: &'static str, msg: String },
    /// A sphere list is not valid JSON or not in the expected schema.
    #[error("{}: not a valid sphere list: {source}", path.display())]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// An output cannot be written (checked before any work).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The finished files could not be renamed into place.
    #[error(transparent)]
    Write(#[from] WriteError),
}

impl PhantomError {
    fn option(option: &'static str, msg: impl Into<String>) -> PhantomError {
        PhantomError::Option {
            option,
            msg: msg.into(),
        }
    }
}

// ---------------------------------------------------------------------------
// Shared plumbing
// ---------------------------------------------------------------------------

/// The files a generator writes, derived from the sidecar path.
struct Outputs {
    json: PathBuf,
    raw_name: String,
    raw: PathBuf,
    spheres: PathBuf,
}

impl Outputs {
    /// The files of a generator writing the sidecar `out_json` (and the
    /// sphere list with `spheres`), checked before any work
    /// (fsutil::check_outputs).
    fn of(out_json: &Path, spheres: bool) -> Result<Outputs, PhantomError> {
        let stem = out_json
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .filter(|s| !s.is_empty())
            .ok_or_else(|| {
                PhantomError::option(
                    "output",
                    format!(
                        "{}: expected a file name for the sidecar",
                        out_json.display()
                    ),
                )
            })?;
        if out_json.extension().is_some_and(|e| e == "raw") {
            return Err(PhantomError::option(
                "output",
                format!(
                    "{}: the sidecar would overwrite its own raw data ({stem}.raw); \
                     use a .json name",
                    out_json.display()
                ),
            ));
        }
        let dir = match out_json.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&dir).map_err(|source| PhantomError::Io {
            path: dir.clone(),
            what: "cannot create the output directory",
            source,
        })?;
        let raw_name = format!("{stem}.raw");
        let out = Outputs {
            raw: dir.join(&raw_name),
            spheres: dir.join(format!("{stem}.spheres.json")),
            json: out_json.to_path_buf(),
            raw_name,
        };
        let mut files = vec![out.json.clone(), out.raw.clone()];
        if spheres {
            files.push(out.spheres.clone());
        }
        crate::fsutil::check_outputs(&files, &[], None)?;
        Ok(out)
    }
}

/// Refuses a volume with fewer than 2 or more than
/// [`MAX_SAMPLES_PER_AXIS`](crate::grid::MAX_SAMPLES_PER_AXIS) samples along an axis (option `dims`).
fn check_dims(dims: [usize; 3]) -> Result<(), PhantomError> {
    use crate::grid::MAX_SAMPLES_PER_AXIS;
    for (d, name) in dims.into_iter().zip(["x", "y", "z"]) {
        let expected = if d < 2 {
            "expected at least 2".to_string()
        } else if d > MAX_SAMPLES_PER_AXIS {
            format!("expected at most {MAX_SAMPLES_PER_AXIS}")
        } else {
            continue;
        };
        return Err(PhantomError::option(
            "dims",
            format!("{d} samples along {name}, {expected}"),
        ));
    }
    Ok(())
}

/// Refuses slices larger than [`MAX_SLICE_BYTES`] (a batch is in memory)
/// and volumes whose size overflows.
fn check_slice_size(
    option: &'static str,
    dims: [usize; 3],
    sample_bytes: usize,
) -> Result<(), PhantomError> {
    let slice = (dims[0] as u64)
        .checked_mul(dims[1] as u64)
        .and_then(|s| s.checked_mul(sample_bytes as u64));
    match slice {
        Some(s) if s <= MAX_SLICE_BYTES && s.checked_mul(dims[2] as u64).is_some() => Ok(()),
        _ => Err(PhantomError::option(
            option,
            format!(
                "{} x {} samples per slice, expected at most {} bytes per slice",
                dims[0], dims[1], MAX_SLICE_BYTES
            ),
        )),
    }
}

fn tmp_beside(target: &Path) -> Result<NamedTempFile, PhantomError> {
    crate::fsutil::temp_beside(target).map_err(|source| PhantomError::Io {
        path: target.to_path_buf(),
        what: "cannot create a temporary file beside the output",
        source,
    })
}

fn write_json<T: Serialize>(
    target: &Path,
    value: &T,
    what: &'static str,
) -> Result<NamedTempFile, PhantomError> {
    let tmp = tmp_beside(target)?;
    let io = |source| PhantomError::Io {
        path: target.to_path_buf(),
        what,
        source,
    };
    let mut w = BufWriter::new(tmp.as_file());
    serde_json::to_writer_pretty(&mut w, value).map_err(|e| io(e.into()))?;
    w.write_all(b"\n").map_err(io)?;
    w.flush().map_err(io)?;
    drop(w);
    Ok(tmp)
}

/// Streams a stack of `dims` samples of `sample_bytes` bytes to a temporary
/// file beside `out.raw`: batches of z slices, rows filled in parallel by
/// `fill_row(scratch, z, y, row_bytes)`, written in order. Returns the
/// (not yet persisted) file and the bytes written.
fn write_stack<S, F>(
    out: &Outputs,
    dims: [usize; 3],
    sample_bytes: usize,
    stage: &str,
    progress: &dyn Progress,
    fill_row: F,
) -> Result<(NamedTempFile, u64), PhantomError>
where
    S: Default + Send,
    F: Fn(&mut S, usize, usize, &mut [u8]) + Sync,
{
    let [nx, ny, nz] = dims;
    let row_bytes = nx * sample_bytes;
    let slice_bytes = row_bytes * ny;
    let batch = (BATCH_BYTES / slice_bytes).clamp(1, BATCH_SLICES).min(nz);
    let tmp = tmp_beside(&out.raw)?;
    let mut w = BufWriter::with_capacity(1 << 20, tmp);
    let mut buf = vec![0u8; batch * slice_bytes];
    let io = |what| {
        move |source| PhantomError::Io {
            path: out.raw.clone(),
            what,
            source,
        }
    };

    progress.begin(stage, nz as u64);
    let mut run = || -> Result<(), PhantomError> {
        let mut z0 = 0;
        while z0 < nz {
            let n = batch.min(nz - z0);
            let part = &mut buf[..n * slice_bytes];
            part.par_chunks_mut(row_bytes)
                .with_min_len(4)
                .enumerate()
                .for_each_init(S::default, |scratch, (r, row)| {
                    fill_row(scratch, z0 + r / ny, r % ny, row)
                });
            w.write_all(part).map_err(io("cannot write"))?;
            for _ in 0..n {
                progress.advance(1);
            }
            z0 += n;
        }
        Ok(())
    };
    let result = run();
    progress.end();
    result?;
    let tmp = w.into_inner().map_err(|e| PhantomError::Io {
        path: out.raw.clone(),
        what: "cannot flush",
        source: e.into_error(),
    })?;
    Ok((tmp, (slice_bytes as u64) * nz as u64))
}

/// The splitmix64 output function (a strong 64-bit mixer).
#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A tiny deterministic PRNG (splitmix64), so scenes are reproducible from
/// their seed without an extra crate.
struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    fn new(seed: u64) -> SplitMix64 {
        SplitMix64 { state: seed }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`.
    fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::ct::ct_z_positions;
    use super::*;
    use crate::input::raw::RawSource;
    use crate::input::SliceSource;
    use crate::progress::NoProgress;

    /// All samples of a stack, as f64 (x fastest).
    pub(super) fn read_all(src: &RawSource) -> Vec<f64> {
        let [nx, ny, nz] = src.meta().dims();
        let mut all = vec![0.0; nx * ny * nz];
        for (z, s) in all.chunks_exact_mut(nx * ny).enumerate() {
            src.read_slice(z, s).unwrap();
        }
        all
    }

    #[test]
    fn bad_options_name_the_option() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("bad.json");
        let sp = |size, per_axis, spacing: [SpacingSpec; 3]| SpheresOptions {
            size,
            per_axis,
            seed: 1,
            spacing,
        };
        let one = [SpacingSpec::Uniform(1.0); 3];
        let cases: Vec<(SpheresOptions, &str)> = vec![
            (sp(1, 1, one), "option size"),
            (sp(16, 0, one), "option per_axis"),
            (sp(16, 9, one), "option per_axis"),
            (
                sp(
                    16,
                    2,
                    [SpacingSpec::Uniform(1.0), SpacingSpec::Uniform(0.0), one[0]],
                ),
                "option spacing",
            ),
            (
                sp(16, 2, [one[0], one[0], SpacingSpec::Linear(1.0, f64::NAN)]),
                "option spacing",
            ),
            (
                sp(16, 2, [SpacingSpec::Uniform(1e300); 3]),
                "option spacing",
            ),
        ];
        for (opts, want) in cases {
            let e = spheres(&side, &opts, &NoProgress).unwrap_err().to_string();
            assert!(e.contains(want), "{opts:?}: {e}");
        }
        for dims in [[1, 10, 10], [10, 10, 0], [1 << 20, 1 << 20, 2]] {
            let opts = CtOptions {
                dims,
                ..CtOptions::default()
            };
            let e = ct(&side, &opts, &NoProgress).unwrap_err().to_string();
            assert!(e.contains("option dims"), "{dims:?}: {e}");
        }
        for z_scale in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let opts = CtOptions {
                dims: [4, 4, 4],
                z_scale,
                ..CtOptions::default()
            };
            let e = ct(&side, &opts, &NoProgress).unwrap_err().to_string();
            assert!(e.contains("option z_scale"), "{z_scale}: {e}");
        }
        // The scale multiplies the written positions.
        let scaled_dir = tempfile::tempdir().unwrap();
        let scaled = scaled_dir.path().join("scaled.json");
        let opts = CtOptions {
            dims: [4, 4, 20],
            z_scale: 0.25,
            ..CtOptions::default()
        };
        ct(&scaled, &opts, &NoProgress).unwrap();
        let got = RawSource::open(&scaled).unwrap().meta().grid.axes[2]
            .coords()
            .to_vec();
        let want: Vec<f64> = ct_z_positions(20).iter().map(|z| z * 0.25).collect();
        assert_eq!(got, want);
        let e = ct(
            &dir.path().join("x.raw"),
            &CtOptions::default(),
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("option output"), "{e}");
        // An output directory that cannot be created is an I/O error
        // naming it (a missing one is created).
        let other = tempfile::tempdir().unwrap();
        let blocker = other.path().join("plain-file");
        std::fs::write(&blocker, b"x").unwrap();
        let e = ct(
            &blocker.join("h.json"),
            &CtOptions {
                dims: [4, 4, 4],
                ..CtOptions::default()
            },
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("plain-file"), "{e}");
        // Nothing was left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        // Bad sphere lists name the file.
        let f = dir.path().join("s.spheres.json");
        std::fs::write(&f, "{\"iso\": 1000, \"spheres\": [{\"center\": [1, 2]}]}").unwrap();
        let e = load_spheres(&f).unwrap_err().to_string();
        assert!(e.contains("s.spheres.json"), "{e}");
        std::fs::write(
            &f,
            "{\"iso\": 1000, \"spheres\": [{\"center\": [1, 2, 3], \"radius\": -1}]}",
        )
        .unwrap();
        let e = load_spheres(&f).unwrap_err().to_string();
        assert!(e.contains("radius"), "{e}");
    }
}
