//! Test scenes, generated slice by slice: a raw stack plus a JSON sidecar in
//! the input schema ([`SidecarOut`], docs/FORMAT.md), never the whole volume
//! in memory.
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
//!
//! Both write to temporary files beside the target and rename them into
//! place together at the end (fsutil::FileSet), so a failure leaves
//! nothing partial behind. Slices are
//! computed in batches, rows in parallel (rayon), and written sequentially.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tempfile::NamedTempFile;

use crate::fsutil::{FileSet, OutputError, WriteError};

use crate::grid::{Axis, AxisError, MAX_SAMPLES_PER_AXIS};
use crate::input::sidecar::{AxisSpec, SidecarOut};
use crate::input::{Endian, Rescale};
use crate::progress::Progress;

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

/// Why a spacing spec (`"0.5"`, `"0.5:2"`, `"1,1,0.5:2"`) is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpacingError {
    /// A part is not a positive number of mm.
    #[error(
        "{spec:?}: {part:?} is not a spacing; expected a number of mm > 0, \
         or A:B for a gap varying linearly from A to B"
    )]
    NotASpacing { spec: String, part: String },
    /// Neither one spec nor three.
    #[error("{spec:?}: {count} specs, expected one for all axes or three (X,Y,Z)")]
    Count { spec: String, count: usize },
    /// A gap of a [`SpacingSpec`] built in code is not finite and > 0.
    #[error("{spec:?}, expected finite gaps > 0 mm")]
    BadGap { spec: SpacingSpec },
    /// The positions the spec gives are not a valid axis.
    #[error(transparent)]
    Axis(#[from] AxisError),
}

// ---------------------------------------------------------------------------
// Sphere scenes (paper section 5.1)
// ---------------------------------------------------------------------------

/// The sample spacing along one axis of a sphere scene, in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpacingSpec {
    /// Every gap is the same.
    Uniform(f64),
    /// The gap varies linearly from the first value (first gap) to the
    /// second (last gap) along the axis: a rectilinear axis. With only two
    /// samples the single gap is the first value.
    Linear(f64, f64),
}

impl SpacingSpec {
    /// Parses `"0.5"` (uniform) or `"0.5:2"` (linear from 0.5 to 2 mm).
    pub fn parse(s: &str) -> Result<SpacingSpec, SpacingError> {
        let num = |p: &str| -> Result<f64, SpacingError> {
            let p = p.trim();
            match p.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
                _ => Err(SpacingError::NotASpacing {
                    spec: s.to_string(),
                    part: p.to_string(),
                }),
            }
        };
        match s.split_once(':') {
            None => Ok(SpacingSpec::Uniform(num(s)?)),
            Some((a, b)) => Ok(SpacingSpec::Linear(num(a)?, num(b)?)),
        }
    }

    /// The gaps of an axis of `n >= 2` samples.
    fn gap(&self, i: usize, n: usize) -> f64 {
        match *self {
            SpacingSpec::Uniform(s) => s,
            SpacingSpec::Linear(a, b) if n > 2 => a + (b - a) * i as f64 / (n - 2) as f64,
            SpacingSpec::Linear(a, _) => a,
        }
    }

    fn check(&self) -> Result<(), SpacingError> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        match *self {
            SpacingSpec::Uniform(s) if ok(s) => Ok(()),
            SpacingSpec::Linear(a, b) if ok(a) && ok(b) => Ok(()),
            spec => Err(SpacingError::BadGap { spec }),
        }
    }

    /// The axis of `n` samples starting at 0 mm, and how a sidecar writes it.
    fn axis(&self, n: usize) -> Result<(Axis, AxisSpec), SpacingError> {
        match *self {
            SpacingSpec::Uniform(s) => {
                let axis = Axis::uniform(0.0, s, n)?;
                Ok((axis, AxisSpec::Uniform(s)))
            }
            SpacingSpec::Linear(..) => {
                let mut coords = Vec::with_capacity(n);
                let mut c = 0.0;
                coords.push(c);
                for i in 0..n - 1 {
                    c += self.gap(i, n);
                    coords.push(c);
                }
                let axis = Axis::from_coords(coords.clone())?;
                Ok((axis, AxisSpec::Positions { positions: coords }))
            }
        }
    }
}

/// Parses `"1"` (one spec for all three axes) or `"1,1,0.5:2"` (x, y, z);
/// each spec as in [`SpacingSpec::parse`].
pub fn parse_spacing3(s: &str) -> Result<[SpacingSpec; 3], SpacingError> {
    let parts: Vec<&str> = s.split(',').collect();
    match parts.as_slice() {
        [one] => Ok([SpacingSpec::parse(one)?; 3]),
        [x, y, z] => Ok([
            SpacingSpec::parse(x)?,
            SpacingSpec::parse(y)?,
            SpacingSpec::parse(z)?,
        ]),
        _ => Err(SpacingError::Count {
            spec: s.to_string(),
            count: parts.len(),
        }),
    }
}

/// Options of [`spheres`].
#[derive(Debug, Clone, PartialEq)]
pub struct SpheresOptions {
    /// Samples per axis (the paper uses 128). At least 2.
    pub size: usize,
    /// Subregions per axis, `N`; the scene holds `N^3` spheres.
    /// `1 <= N <= size / 2` and `N <=` [`MAX_PER_AXIS`].
    pub per_axis: usize,
    /// Seed of the sphere positions.
    pub seed: u64,
    /// Spacing along x, y and z.
    pub spacing: [SpacingSpec; 3],
}

impl Default for SpheresOptions {
    fn default() -> Self {
        SpheresOptions {
            size: 128,
            per_axis: 2,
            seed: 1,
            spacing: [SpacingSpec::Uniform(1.0); 3],
        }
    }
}

/// One analytic sphere, in mm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sphere {
    pub center: [f64; 3],
    pub radius: f64,
}

/// What [`spheres`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SpheresInfo {
    /// The iso value whose surface approximates the spheres ([`SPHERES_ISO`]).
    pub iso: f64,
    /// The `N^3` spheres, x fastest over the subregions.
    pub spheres: Vec<Sphere>,
    /// The raw stack (`<stem>.raw`).
    pub raw_path: PathBuf,
    /// The sphere list (`<stem>.spheres.json`).
    pub spheres_path: PathBuf,
}

/// The sphere list as written beside a scene.
#[derive(Serialize)]
struct SpheresFileOut<'a> {
    iso: f64,
    spheres: &'a [Sphere],
    per_axis: usize,
    seed: u64,
}

#[derive(Deserialize)]
struct SpheresFileIn {
    iso: f64,
    spheres: Vec<Sphere>,
}

/// Reads a sphere list written by [`spheres`]: the iso value and the spheres.
/// Numbers come back to within an ulp of what was written (serde_json's
/// default float parsing).
pub fn load_spheres(path: &Path) -> Result<(f64, Vec<Sphere>), PhantomError> {
    let text = std::fs::read_to_string(path).map_err(|source| PhantomError::Io {
        path: path.to_path_buf(),
        what: "cannot read sphere list",
        source,
    })?;
    let bad = |source| PhantomError::Json {
        path: path.to_path_buf(),
        source,
    };
    let f: SpheresFileIn = serde_json::from_str(&text).map_err(bad)?;
    let custom = |msg: String| bad(<serde_json::Error as serde::de::Error>::custom(msg));
    if !f.iso.is_finite() {
        return Err(custom(format!("iso {}, expected a finite number", f.iso)));
    }
    for (i, s) in f.spheres.iter().enumerate() {
        if !(s.center.iter().all(|c| c.is_finite()) && s.radius.is_finite() && s.radius > 0.0) {
            return Err(custom(format!(
                "sphere {i}: {s:?}, expected a finite centre and a radius > 0"
            )));
        }
    }
    Ok((f.iso, f.spheres))
}

/// Writes a sphere scene of the paper's section 5.1: `out_json` (sidecar),
/// `<stem>.raw` (u16 samples, little-endian) and `<stem>.spheres.json`.
///
/// The box `[0, L]^3` (mm) is cut into `N^3` equal subregions. Every sphere
/// has the radius `R = cbrt(0.2 V / (N^3 4/3 pi))` (total sphere volume 20 %
/// of the box for every `N`), reduced if needed so that a sphere fits its
/// smallest subregion with a margin `m` of one largest gap (`m` is reduced to
/// a quarter of the subregion when the grid is too coarse for that). Each
/// centre is uniform in `[lo + R + m, hi - R - m]` per axis, from a
/// splitmix64 stream of `seed`.
///
/// A sample at distance `d` from the nearest centre is
/// `clamp(1000 + 100 (R - d) / h, 0, 2000)`, rounded, with `h` the smallest
/// gap of the grid: a ramp of the signed distance, 100 per `h` mm, that
/// reaches 0 at `R + 10 h`. Every sphere within that reach is considered.
pub fn spheres(
    out_json: &Path,
    opts: &SpheresOptions,
    progress: &dyn Progress,
) -> Result<SpheresInfo, PhantomError> {
    let n = opts.size;
    let per = opts.per_axis;
    if n < 2 {
        return Err(PhantomError::option(
            "size",
            format!("{n} samples per axis, expected at least 2"),
        ));
    }
    if n > MAX_SAMPLES_PER_AXIS {
        return Err(PhantomError::option(
            "size",
            format!("{n} samples per axis, expected at most {MAX_SAMPLES_PER_AXIS}"),
        ));
    }
    if !(1..=n / 2).contains(&per) {
        return Err(PhantomError::option(
            "per_axis",
            format!(
                "{per} subregions per axis, expected 1 to size / 2 = {} \
                 (at least 2 samples across each subregion)",
                n / 2
            ),
        ));
    }
    if per > MAX_PER_AXIS {
        return Err(PhantomError::option(
            "per_axis",
            format!("{per} subregions per axis ({per}^3 spheres), expected at most {MAX_PER_AXIS}"),
        ));
    }
    let built = [0, 1, 2].map(|k| {
        let name = ["x", "y", "z"][k];
        let spec = &opts.spacing[k];
        spec.check()
            .and_then(|()| spec.axis(n))
            .map_err(|m| PhantomError::option("spacing", format!("{name}: {m}")))
    });
    let [bx, by, bz] = built;
    let ((ax_x, sx), (ax_y, sy), (ax_z, sz)) = (bx?, by?, bz?);
    let axes = [ax_x, ax_y, ax_z];
    let dims = [n; 3];
    check_slice_size("size", dims, 2)?;
    let out = Outputs::of(out_json, true)?;

    // The box, the radius and the centres.
    let lens: [f64; 3] = [0, 1, 2].map(|k| axes[k].coords()[n - 1]);
    let h = axes
        .iter()
        .map(|a| a.spacing_range().0)
        .fold(f64::INFINITY, f64::min);
    let max_gap = axes.iter().map(|a| a.spacing_range().1).fold(0.0, f64::max);
    let nf = per as f64;
    let width_min = lens.iter().fold(f64::INFINITY, |m, l| m.min(l / nf));
    let volume = lens[0] * lens[1] * lens[2];
    let r_target = (0.2 * volume / (nf * nf * nf * 4.0 / 3.0 * std::f64::consts::PI)).cbrt();
    let margin = max_gap.min(0.25 * width_min);
    let radius = r_target.min(0.5 * width_min - margin);
    if !(volume.is_finite() && radius.is_finite() && radius > 0.0 && h > 0.0) {
        return Err(PhantomError::option(
            "spacing",
            format!(
                "the box of {} x {} x {} mm gives no usable sphere radius ({radius} mm)",
                lens[0], lens[1], lens[2]
            ),
        ));
    }
    let bounds = |k: usize, j: usize| (j as f64 * lens[k] / nf, (j + 1) as f64 * lens[k] / nf);
    // Where the centres of subregion j may lie, per axis.
    let centre_ranges: [Vec<(f64, f64)>; 3] = [0, 1, 2].map(|k| {
        (0..per)
            .map(|j| {
                let (lo, hi) = bounds(k, j);
                let (a, b) = (lo + radius + margin, hi - radius - margin);
                if b > a {
                    (a, b)
                } else {
                    let mid = 0.5 * (lo + hi);
                    (mid, mid)
                }
            })
            .collect()
    });
    let mut rng = SplitMix64::new(opts.seed);
    let mut spheres = Vec::with_capacity(per * per * per);
    for cz in 0..per {
        for cy in 0..per {
            for cx in 0..per {
                let c = [cx, cy, cz];
                let center = [0, 1, 2].map(|k| {
                    let (a, b) = centre_ranges[k][c[k]];
                    a + rng.next_f64() * (b - a)
                });
                spheres.push(Sphere { center, radius });
            }
        }
    }

    // Which subregions can reach each sample, per axis.
    let reach = radius + 10.0 * h;
    let cand: [Vec<(usize, usize)>; 3] = [0, 1, 2].map(|k| {
        let ranges = &centre_ranges[k];
        axes[k]
            .coords()
            .iter()
            .map(|&c| {
                let start = ranges.partition_point(|&(_, b)| b <= c - reach);
                let end = ranges.partition_point(|&(a, _)| a < c + reach);
                (start, end.max(start))
            })
            .collect()
    });

    let xs = axes[0].coords();
    let ys = axes[1].coords();
    let zs = axes[2].coords();
    let spheres_ref = &spheres;
    let cand_ref = &cand;
    let reach2 = reach * reach;
    // Per row: for every candidate (cz, cy) pair and every cx, the y-z part
    // of the squared distance and the centre's x.
    let fill = |scratch: &mut Vec<(f64, f64)>, z: usize, y: usize, row: &mut [u8]| {
        scratch.clear();
        let (zy0, zy1) = cand_ref[2][z];
        let (yy0, yy1) = cand_ref[1][y];
        for cz in zy0..zy1 {
            for cy in yy0..yy1 {
                let base = (cz * per + cy) * per;
                for s in &spheres_ref[base..base + per] {
                    let dy = ys[y] - s.center[1];
                    let dz = zs[z] - s.center[2];
                    scratch.push((dy * dy + dz * dz, s.center[0]));
                }
            }
        }
        let pairs = scratch.len() / per;
        for (x, out) in row.chunks_exact_mut(2).enumerate() {
            let (x0, x1) = cand_ref[0][x];
            let mut best = reach2;
            for p in 0..pairs {
                for &(dyz2, cxp) in &scratch[p * per + x0..p * per + x1] {
                    let dx = xs[x] - cxp;
                    let d2 = dyz2 + dx * dx;
                    if d2 < best {
                        best = d2;
                    }
                }
            }
            let v = sphere_value(radius, best.sqrt(), h);
            out.copy_from_slice(&v.to_le_bytes());
        }
    };
    let (raw_tmp, _) = write_stack(&out, dims, 2, "phantom spheres", progress, fill)?;

    let list = SpheresFileOut {
        iso: SPHERES_ISO,
        spheres: &spheres,
        per_axis: per,
        seed: opts.seed,
    };
    let list_tmp = write_json(&out.spheres, &list, "cannot write sphere list")?;
    let side = SidecarOut {
        data: out.raw_name.clone(),
        dims,
        dtype: "u16",
        endian: Endian::Little,
        header_bytes: 0,
        x: sx,
        y: sy,
        z: sz,
        origin: [0.0; 3],
        rescale: None,
    };
    let side_tmp = write_json(&out.json, &side, "cannot write sidecar")?;
    let mut set = FileSet::new();
    set.add(raw_tmp, &out.raw);
    set.add(list_tmp, &out.spheres);
    set.add(side_tmp, &out.json);
    set.commit()?;
    Ok(SpheresInfo {
        iso: SPHERES_ISO,
        spheres,
        raw_path: out.raw,
        spheres_path: out.spheres,
    })
}

/// The sample value at distance `d` (mm) from the centre of a sphere of
/// radius `r`, on a grid whose smallest gap is `h`.
#[inline]
fn sphere_value(r: f64, d: f64, h: f64) -> u16 {
    (SPHERES_ISO + 100.0 * (r - d) / h)
        .clamp(0.0, 2000.0)
        .round() as u16
}

// ---------------------------------------------------------------------------
// CT-like head (paper section 4.3, data set 2)
// ---------------------------------------------------------------------------

/// Sample type of the [`ct`] phantom.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CtDtype {
    /// `i16` in HU.
    #[default]
    I16,
    /// `u16` holding HU + 1024, with rescale intercept -1024 in the sidecar.
    U16,
}

/// Options of [`ct`].
#[derive(Debug, Clone, PartialEq)]
pub struct CtOptions {
    /// Samples along x, y, z; each at least 2.
    pub dims: [usize; 3],
    pub dtype: CtDtype,
    /// Seed of the per-sample noise.
    pub seed: u64,
    /// Multiplies the 2, 1 and 4 mm slice gaps (positive, finite): tall
    /// stacks keep a head's proportions with `160 / nz`.
    pub z_scale: f64,
}

impl Default for CtOptions {
    fn default() -> Self {
        CtOptions {
            dims: [256, 256, 160],
            dtype: CtDtype::I16,
            seed: 1,
            z_scale: 1.0,
        }
    }
}

/// What [`ct`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct CtInfo {
    /// The raw stack (`<stem>.raw`).
    pub raw_path: PathBuf,
    /// Its size in bytes.
    pub bytes: u64,
}

const HU_AIR: f32 = -1000.0;
const HU_SOFT: f32 = 40.0;
const HU_BRAIN: f32 = 35.0;
const HU_CSF: f32 = 5.0;
const HU_EYE: f32 = 10.0;
const HU_SPINE: f32 = 700.0;
const NOISE_HU: u64 = 12;

/// The z positions of a CT-like stack of `nz` slices (paper section 4.3,
/// data set 2): the lower 30 % of the slices 2 mm apart, the middle 45 %
/// 1 mm apart (thin slices through the central skull), the top 25 % 4 mm.
fn ct_z_positions(nz: usize) -> Vec<f64> {
    let n_low = (0.30 * nz as f64).round() as usize;
    let n_mid = (0.45 * nz as f64).round() as usize;
    let mut z = Vec::with_capacity(nz);
    let mut c = 0.0;
    z.push(c);
    for i in 0..nz - 1 {
        c += if i < n_low {
            2.0
        } else if i < n_low + n_mid {
            1.0
        } else {
            4.0
        };
        z.push(c);
    }
    z
}

/// An axis-aligned ellipsoid (or, with `semi[2]` infinite, a vertical
/// elliptic cylinder) with the normalised radius
/// `r(p) = sqrt(sum ((p - centre) / semi)^2)`.
///
/// The signed distance (mm, positive outside) of `p` to the level set
/// `r = r0` is approximated by the implicit value over its gradient norm,
/// `(r - r0) / |grad r| = (r - r0) r / G` with
/// `G = sqrt(sum ((p - centre) / semi^2)^2)`: exact along the semi-axes and
/// to first order at the surface, linear in `r` along every ray from the
/// centre (so monotone across the surface), and `r / G` lies between the
/// smallest and largest (finite) semi-axis, so `|d| >= |r - r0| min_semi`.
#[derive(Clone, Copy)]
struct Ellipsoid {
    centre: [f64; 3],
    semi: [f64; 3],
}

impl Ellipsoid {
    /// One axis' part of `r^2`.
    #[inline]
    fn term(&self, k: usize, p: f64) -> f32 {
        let t = (p - self.centre[k]) / self.semi[k];
        (t * t) as f32
    }

    /// One axis' part of `G^2` (0 along an infinite semi-axis).
    #[inline]
    fn grad_term(&self, k: usize, p: f64) -> f32 {
        let t = (p - self.centre[k]) / (self.semi[k] * self.semi[k]);
        (t * t) as f32
    }
}

/// An [`Ellipsoid`] with the x parts of `r^2` and `G^2` precomputed per
/// column, for the fractions of samples inside its level sets.
struct Shape {
    e: Ellipsoid,
    /// The smallest and largest finite semi-axis: the range of `r / G`.
    semi_lo: f32,
    semi_hi: f32,
    r2_x: Vec<f32>,
    g2_x: Vec<f32>,
}

/// The part of a [`Shape`] shared by one row of samples.
#[derive(Clone, Copy)]
struct ShapeRow {
    /// The y and z parts of `r^2` and `G^2`.
    r2: f32,
    g2: f32,
    /// Samples with `r^2 >= out2` are beyond the ramp of the outermost
    /// level, those with `r^2 <= in2` inside the ramp of the innermost one.
    out2: f32,
    in2: f32,
}

impl Shape {
    fn new(e: Ellipsoid, xs: &[f64]) -> Shape {
        let finite = || e.semi.iter().copied().filter(|s| s.is_finite());
        Shape {
            e,
            semi_lo: finite().fold(f64::INFINITY, f64::min) as f32,
            semi_hi: finite().fold(0.0, f64::max) as f32,
            r2_x: xs.iter().map(|&x| e.term(0, x)).collect(),
            g2_x: xs.iter().map(|&x| e.grad_term(0, x)).collect(),
        }
    }

    /// The row at `(py, pz)`, for the levels `r = lo ..= hi` blended over
    /// ramps of half width `hw` mm.
    fn row(&self, py: f64, pz: f64, lo: f32, hi: f32, hw: f32) -> ShapeRow {
        let m = hw / self.semi_lo;
        ShapeRow {
            r2: self.e.term(1, py) + self.e.term(2, pz),
            g2: self.e.grad_term(1, py) + self.e.grad_term(2, pz),
            out2: (hi + m) * (hi + m),
            in2: if lo > m { (lo - m) * (lo - m) } else { -1.0 },
        }
    }

    /// `r` and `r / G` of sample `x` of a row, given its `r^2`: the signed
    /// distance to the level `r0` is `(r - r0) * (r / G)`.
    #[inline]
    fn radius_scale(&self, row: &ShapeRow, r2: f32, x: usize) -> (f32, f32) {
        let r = r2.sqrt();
        let g = (row.g2 + self.g2_x[x]).sqrt();
        let s = if g > 0.0 {
            (r / g).clamp(self.semi_lo, self.semi_hi)
        } else {
            self.semi_lo
        };
        (r, s)
    }

    /// The fraction of sample `x` of a row inside the surface `r = 1`
    /// (a row made with `lo = hi = 1`), for ramps of width `1 / inv_w`.
    #[inline]
    fn inside(&self, row: &ShapeRow, x: usize, inv_w: f32) -> f32 {
        let r2 = row.r2 + self.r2_x[x];
        if r2 >= row.out2 {
            0.0
        } else if r2 <= row.in2 {
            1.0
        } else {
            let (r, s) = self.radius_scale(row, r2, x);
            ramp((r - 1.0) * s, inv_w)
        }
    }
}

/// The fraction inside a surface of a sample at signed distance `d` (mm,
/// positive outside): a clamped linear ramp of width `1 / inv_w` centred on
/// the surface (partial volume).
#[inline]
fn ramp(d: f32, inv_w: f32) -> f32 {
    (0.5 - d * inv_w).clamp(0.0, 1.0)
}

#[inline]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Writes a CT-like head phantom: `out_json` (sidecar) and `<stem>.raw`.
///
/// Hounsfield units: air -1000 outside; scalp +40 in an outer ellipsoid
/// shell; skull bone about +1050 to +1330 (varying smoothly with height and
/// side); brain +35 with two ventricles (+5); two eyes (+10) in front (at
/// smaller y); a neck (+40) with a spine (+700) below the head. Every sample
/// gets a deterministic noise of -12 to +12 HU from a hash of its position
/// and `seed`. Suggested iso values: [`CT_BONE_ISO`] (300 HU) for the skull,
/// [`CT_SKIN_ISO`] (-300 HU) for the skin.
///
/// Boundaries are partial-volume ramps, not steps: every surface (each
/// ellipsoid, shell and cylinder, and the planes ending the neck and the
/// spine) blends the layers on either side by a clamped linear ramp of the
/// approximate signed distance to it (see `Ellipsoid`), centred on the
/// surface, `1.5 x` the largest of the x and y spacings and the z gaps
/// beside the slice wide. The layers nest (brain and ventricles inside the
/// skull, inside the scalp, inside the head, over the neck and spine; the
/// eyes over everything), so the field is continuous and about linear
/// across each surface and iso surfaces of its trilinear interpolant are
/// smooth. Shells thinner than the ramp (the skull on coarse grids) keep
/// only part of their contrast, as in a real scan.
///
/// The x and y spacings are `0.9 mm * 256 / n` (a field of view of about
/// 230 mm for any dims); z positions have 2, 1 and 4 mm gaps over the
/// lower 30 %, middle 45 % and top 25 % of the slices (times
/// [`CtOptions::z_scale`]) and are written as
/// `{"positions": [...]}`. The head is centred at 55 % of the z extent with
/// a semi-axis of 40 % of it.
pub fn ct(
    out_json: &Path,
    opts: &CtOptions,
    progress: &dyn Progress,
) -> Result<CtInfo, PhantomError> {
    let dims = opts.dims;
    for (k, &d) in dims.iter().enumerate() {
        let name = ["x", "y", "z"][k];
        if d < 2 {
            return Err(PhantomError::option(
                "dims",
                format!("{d} samples along {name}, expected at least 2"),
            ));
        }
        if d > MAX_SAMPLES_PER_AXIS {
            return Err(PhantomError::option(
                "dims",
                format!("{d} samples along {name}, expected at most {MAX_SAMPLES_PER_AXIS}"),
            ));
        }
    }
    let (sample_bytes, dtype_name, rescale) = match opts.dtype {
        CtDtype::I16 => (2, "i16", None),
        CtDtype::U16 => (
            2,
            "u16",
            Some(Rescale {
                slope: 1.0,
                intercept: -1024.0,
            }),
        ),
    };
    check_slice_size("dims", dims, sample_bytes)?;
    if !(opts.z_scale.is_finite() && opts.z_scale > 0.0) {
        return Err(PhantomError::option(
            "z_scale",
            format!("{}, expected a positive finite factor", opts.z_scale),
        ));
    }
    let out = Outputs::of(out_json, false)?;
    let [nx, ny, nz] = dims;

    let sx = 0.9 * 256.0 / nx as f64;
    let sy = 0.9 * 256.0 / ny as f64;
    let zs: Vec<f64> = ct_z_positions(nz)
        .into_iter()
        .map(|z| z * opts.z_scale)
        .collect();
    let xs: Vec<f64> = (0..nx).map(|i| i as f64 * sx).collect();
    let ys: Vec<f64> = (0..ny).map(|i| i as f64 * sy).collect();
    let (lx, ly, lz) = (xs[nx - 1], ys[ny - 1], zs[nz - 1]);

    // Geometry, relative to the extent in mm.
    let (cx, cy, cz) = (0.5 * lx, 0.5 * ly, 0.55 * lz);
    let (ax, ay, az) = (0.33 * lx, 0.41 * ly, 0.40 * lz);
    let head = Ellipsoid {
        centre: [cx, cy, cz],
        semi: [ax, ay, az],
    };
    let neck = Ellipsoid {
        centre: [cx, cy + 0.1 * ay, 0.0],
        semi: [0.45 * ax, 0.5 * ay, f64::INFINITY],
    };
    let neck_top = cz - 0.6 * az;
    let spine = Ellipsoid {
        centre: [cx, cy + 0.3 * ay, 0.0],
        semi: [0.12 * ax, 0.12 * ax, f64::INFINITY],
    };
    let spine_top = cz - 0.75 * az;
    let eye_semi = [0.13 * ax, 0.11 * ay, 0.08 * az];
    let eyes = [-1.0, 1.0].map(|s| Ellipsoid {
        centre: [cx + s * 0.32 * ax, cy - 0.84 * ay, cz - 0.1 * az],
        semi: eye_semi,
    });
    let ventricle_semi = [0.08 * ax, 0.25 * ay, 0.12 * az];
    let ventricles = [-1.0, 1.0].map(|s| Ellipsoid {
        centre: [cx + s * 0.12 * ax, cy - 0.05 * ay, cz + 0.1 * az],
        semi: ventricle_semi,
    });

    // Per-column terms, shared by all rows.
    let head = Shape::new(head, &xs);
    let neck = Shape::new(neck, &xs);
    let spine = Shape::new(spine, &xs);
    let eyes = eyes.map(|e| Shape::new(e, &xs));
    let ventricles = ventricles.map(|e| Shape::new(e, &xs));
    // Half the ramp width per slice: 0.75 x the largest of the x and y
    // spacings and the z gaps on either side of the slice.
    let half_widths: Vec<f32> = (0..nz)
        .map(|z| {
            let below = if z > 0 { zs[z] - zs[z - 1] } else { 0.0 };
            let above = if z + 1 < nz { zs[z + 1] - zs[z] } else { 0.0 };
            (0.75 * sx.max(sy).max(below).max(above)) as f32
        })
        .collect();
    let seed_key = mix64(opts.seed ^ 0x5EED_C7C7_0000_0001);
    let u16_out = opts.dtype == CtDtype::U16;
    let (ys, zs_ref) = (&ys, &zs);

    let fill = |_: &mut (), z: usize, y: usize, row: &mut [u8]| {
        let (py, pz) = (ys[y], zs_ref[z]);
        let hw = half_widths[z];
        let inv_w = 0.5 / hw;
        // Per-row terms.
        let rel_z = ((pz - cz) / az).clamp(-1.0, 1.0) as f32;
        let scalp_t = 0.05f32;
        let skull_t = 0.06 + 0.02 * rel_z;
        let (scalp_in, skull_in) = (1.0 - scalp_t, 1.0 - scalp_t - skull_t);
        let bone_row = 1150.0 + 100.0 * rel_z;
        let head_row = head.row(py, pz, skull_in, 1.0, hw);
        // The neck and the spine end in planes (inside the head).
        let neck_cap = ramp((pz - neck_top) as f32, inv_w);
        let neck_row = neck.row(py, pz, 1.0, 1.0, hw);
        let spine_cap = ramp((pz - spine_top) as f32, inv_w);
        let spine_row = spine.row(py, pz, 1.0, 1.0, hw);
        let eye_rows = eyes.each_ref().map(|e| e.row(py, pz, 1.0, 1.0, hw));
        let eye_any = eye_rows.iter().any(|r| r.r2 < r.out2);
        let vent_rows = ventricles.each_ref().map(|e| e.row(py, pz, 1.0, 1.0, hw));
        let vent_any = vent_rows.iter().any(|r| r.r2 < r.out2);
        let row_key = mix64(seed_key ^ (((z as u64) << 32) | y as u64));

        // Outside the head: air, the neck, the spine.
        let outside = |x: usize| -> f32 {
            let f_neck = if neck_cap > 0.0 {
                neck_cap * neck.inside(&neck_row, x, inv_w)
            } else {
                0.0
            };
            if f_neck == 0.0 {
                return HU_AIR;
            }
            let f_spine = if spine_cap > 0.0 {
                spine_cap * spine.inside(&spine_row, x, inv_w)
            } else {
                0.0
            };
            lerp(HU_AIR, lerp(HU_SOFT, HU_SPINE, f_spine), f_neck)
        };
        // Inside the skull: brain and ventricles.
        let brain = |x: usize| -> f32 {
            if vent_any {
                let f = ventricles[0]
                    .inside(&vent_rows[0], x, inv_w)
                    .max(ventricles[1].inside(&vent_rows[1], x, inv_w));
                lerp(HU_BRAIN, HU_CSF, f)
            } else {
                HU_BRAIN
            }
        };

        for (x, out) in row.chunks_exact_mut(2).enumerate() {
            let hx = head.r2_x[x];
            let r2 = head_row.r2 + hx;
            let mut hu = if r2 >= head_row.out2 {
                outside(x)
            } else if r2 <= head_row.in2 {
                brain(x)
            } else {
                // Within the ramps of the skin, the scalp or the skull:
                // nested layers, blended from the inside out.
                let (r, s) = head.radius_scale(&head_row, r2, x);
                let f_brain = ramp((r - skull_in) * s, inv_w);
                let f_bone = ramp((r - scalp_in) * s, inv_w);
                let f_head = ramp((r - 1.0) * s, inv_w);
                let bone = bone_row + 80.0 * hx;
                let mut v = if f_brain > 0.0 {
                    lerp(bone, brain(x), f_brain)
                } else {
                    bone
                };
                v = lerp(HU_SOFT, v, f_bone);
                if f_head < 1.0 {
                    v = lerp(outside(x), v, f_head);
                }
                v
            };
            if eye_any {
                let f = eyes[0].inside(&eye_rows[0], x, inv_w).max(eyes[1].inside(
                    &eye_rows[1],
                    x,
                    inv_w,
                ));
                hu = lerp(hu, HU_EYE, f);
            }
            let noise = ((mix64(row_key ^ x as u64) >> 32) * (2 * NOISE_HU + 1)) >> 32;
            let v = hu.round() as i32 + noise as i32 - NOISE_HU as i32;
            let bytes = if u16_out {
                ((v + 1024).clamp(0, u16::MAX as i32) as u16).to_le_bytes()
            } else {
                (v.clamp(i16::MIN as i32, i16::MAX as i32) as i16).to_le_bytes()
            };
            out.copy_from_slice(&bytes);
        }
    };
    let (raw_tmp, bytes) = write_stack(&out, dims, sample_bytes, "phantom ct", progress, fill)?;

    let side = SidecarOut {
        data: out.raw_name.clone(),
        dims,
        dtype: dtype_name,
        endian: Endian::Little,
        header_bytes: 0,
        x: AxisSpec::Uniform(sx),
        y: AxisSpec::Uniform(sy),
        z: AxisSpec::Positions {
            positions: zs.clone(),
        },
        origin: [0.0; 3],
        rescale,
    };
    let side_tmp = write_json(&out.json, &side, "cannot write sidecar")?;
    let mut set = FileSet::new();
    set.add(raw_tmp, &out.raw);
    set.add(side_tmp, &out.json);
    set.commit()?;
    Ok(CtInfo {
        raw_path: out.raw,
        bytes,
    })
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
    use super::*;
    use crate::input::raw::RawSource;
    use crate::input::SliceSource;
    use crate::progress::NoProgress;

    /// All samples of a stack, as f64 (x fastest).
    fn read_all(src: &RawSource) -> Vec<f64> {
        let [nx, ny, nz] = src.meta().dims();
        let mut all = vec![0.0; nx * ny * nz];
        for (z, s) in all.chunks_exact_mut(nx * ny).enumerate() {
            src.read_slice(z, s).unwrap();
        }
        all
    }

    /// The sample values by brute force over every sphere.
    fn brute_force(src: &RawSource, spheres: &[Sphere]) -> Vec<f64> {
        let g = &src.meta().grid;
        let h = g
            .axes
            .iter()
            .map(|a| a.spacing_range().0)
            .fold(f64::INFINITY, f64::min);
        let [xs, ys, zs] = g.axes.each_ref().map(|a| a.coords());
        let mut out = Vec::new();
        for &z in zs {
            for &y in ys {
                for &x in xs {
                    let d = spheres
                        .iter()
                        .map(|s| {
                            let (dx, dy, dz) = (x - s.center[0], y - s.center[1], z - s.center[2]);
                            dy * dy + dz * dz + dx * dx
                        })
                        .fold(f64::INFINITY, f64::min)
                        .sqrt();
                    out.push(sphere_value(spheres[0].radius, d, h) as f64);
                }
            }
        }
        out
    }

    #[test]
    fn spheres_n2_size32() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("scene.json");
        let opts = SpheresOptions {
            size: 32,
            per_axis: 2,
            seed: 7,
            spacing: parse_spacing3("1").unwrap(),
        };
        let info = spheres(&side, &opts, &NoProgress).unwrap();
        assert_eq!(info.iso, 1000.0);
        assert_eq!(info.spheres.len(), 8);
        assert_eq!(info.raw_path, dir.path().join("scene.raw"));
        assert_eq!(info.spheres_path, dir.path().join("scene.spheres.json"));
        let len = std::fs::metadata(&info.raw_path).unwrap().len();
        assert_eq!(len, 32 * 32 * 32 * 2);
        // Nothing else (no partial files) in the directory.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);

        // Radius: 20 % of the (31 mm)^3 box in 8 spheres.
        let r = info.spheres[0].radius;
        let want = (0.2 * 31f64.powi(3) / (8.0 * 4.0 / 3.0 * std::f64::consts::PI)).cbrt();
        assert!((r - want).abs() < 1e-12, "{r} vs {want}");
        for s in &info.spheres {
            assert_eq!(s.radius, r);
        }

        let src = RawSource::open(&side).unwrap();
        assert_eq!(src.meta().dims(), [32; 3]);
        for a in &src.meta().grid.axes {
            assert!(a.is_uniform());
            assert_eq!(a.coords()[0], 0.0);
            assert_eq!(a.coords()[31], 31.0);
        }
        let all = read_all(&src);
        let at = |p: [usize; 3]| all[(p[2] * 32 + p[1]) * 32 + p[0]];
        // Near every centre the value is high (R ~ 5.6 mm of 1 mm samples).
        for s in &info.spheres {
            let p = s.center.map(|c| c.round() as usize);
            assert!(at(p) > 1450.0, "{} at {p:?}", at(p));
        }
        // The corner is outside every sphere.
        assert!(at([0, 0, 0]) < 1000.0);
        assert!(at([31, 31, 31]) < 1000.0);
        assert_eq!(all, brute_force(&src, &info.spheres));

        let (iso, back) = load_spheres(&info.spheres_path).unwrap();
        assert_eq!(iso, 1000.0);
        // serde_json parses floats to within an ulp (no `float_roundtrip`).
        assert_eq!(back.len(), info.spheres.len());
        for (a, b) in back.iter().zip(&info.spheres) {
            assert!((a.radius - b.radius).abs() < 1e-12);
            for k in 0..3 {
                assert!((a.center[k] - b.center[k]).abs() < 1e-12, "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn spheres_dense_scene_matches_brute_force_and_far_corner_is_zero() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("dense.json");
        let opts = SpheresOptions {
            size: 40,
            per_axis: 5,
            seed: 3,
            spacing: parse_spacing3("0.5").unwrap(),
        };
        let info = spheres(&side, &opts, &NoProgress).unwrap();
        assert_eq!(info.spheres.len(), 125);
        let src = RawSource::open(&side).unwrap();
        let all = read_all(&src);
        assert_eq!(all, brute_force(&src, &info.spheres));
        // Same seed, same scene; another seed, another scene.
        let again = spheres(&dir.path().join("again.json"), &opts, &NoProgress).unwrap();
        assert_eq!(again.spheres, info.spheres);
        let other = SpheresOptions { seed: 4, ..opts };
        let other = spheres(&dir.path().join("other.json"), &other, &NoProgress).unwrap();
        assert_ne!(other.spheres, info.spheres);
    }

    #[test]
    fn spheres_far_from_everything_is_zero() {
        // One small sphere (clamped radius) on a coarse grid, far corner
        // more than R + 10 h away.
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("one.json");
        let opts = SpheresOptions {
            size: 48,
            per_axis: 1,
            seed: 1,
            spacing: parse_spacing3("0.25:1").unwrap(),
        };
        let info = spheres(&side, &opts, &NoProgress).unwrap();
        let src = RawSource::open(&side).unwrap();
        let all = read_all(&src);
        assert_eq!(all[0], 0.0);
        assert_eq!(all, brute_force(&src, &info.spheres));
        assert!(all.contains(&2000.0));
    }

    #[test]
    fn rectilinear_spacing_gives_nonuniform_axes() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("rect.json");
        let opts = SpheresOptions {
            size: 24,
            per_axis: 3,
            seed: 1,
            spacing: parse_spacing3("1,0.75,0.5:2").unwrap(),
        };
        let info = spheres(&side, &opts, &NoProgress).unwrap();
        let src = RawSource::open(&side).unwrap();
        let axes = &src.meta().grid.axes;
        assert!(axes[0].is_uniform());
        assert!(axes[1].is_uniform());
        assert!(!axes[2].is_uniform());
        assert_eq!(axes[1].coords()[23], 23.0 * 0.75);
        let (lo, hi) = axes[2].spacing_range();
        assert!(
            (lo - 0.5).abs() < 1e-12 && (hi - 2.0).abs() < 1e-12,
            "{lo} {hi}"
        );
        let all = read_all(&src);
        assert_eq!(all, brute_force(&src, &info.spheres));
        // Every sphere lies inside the box.
        let lens = axes.each_ref().map(|a| a.coords()[23]);
        for s in &info.spheres {
            for (c, len) in s.center.iter().zip(lens) {
                assert!(c - s.radius > 0.0 && c + s.radius < len);
            }
        }
    }

    #[test]
    fn spacing_parsing() {
        assert_eq!(SpacingSpec::parse("0.5"), Ok(SpacingSpec::Uniform(0.5)));
        assert_eq!(
            SpacingSpec::parse(" 0.5 : 2 "),
            Ok(SpacingSpec::Linear(0.5, 2.0))
        );
        for bad in ["", "x", "0", "-1", "1:", ":1", "1:0", "inf", "NaN", "1:2:3"] {
            assert!(SpacingSpec::parse(bad).is_err(), "{bad:?}");
        }
        assert_eq!(
            parse_spacing3("1,1,0.5:2"),
            Ok([
                SpacingSpec::Uniform(1.0),
                SpacingSpec::Uniform(1.0),
                SpacingSpec::Linear(0.5, 2.0)
            ])
        );
        assert_eq!(parse_spacing3("2"), Ok([SpacingSpec::Uniform(2.0); 3]));
        let e = parse_spacing3("1,2").unwrap_err();
        assert!(matches!(e, SpacingError::Count { count: 2, .. }), "{e}");
        assert!(e.to_string().contains("three"), "{e}");
    }

    #[test]
    fn ct_small() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("head.json");
        let opts = CtOptions {
            dims: [40, 36, 30],
            dtype: CtDtype::I16,
            seed: 1,
            ..CtOptions::default()
        };
        let info = ct(&side, &opts, &NoProgress).unwrap();
        assert_eq!(info.bytes, 40 * 36 * 30 * 2);
        assert_eq!(std::fs::metadata(&info.raw_path).unwrap().len(), info.bytes);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
        let src = RawSource::open(&side).unwrap();
        assert_eq!(src.meta().dims(), [40, 36, 30]);
        let axes = &src.meta().grid.axes;
        assert!(axes[0].is_uniform() && axes[1].is_uniform());
        assert!((axes[0].coords()[1] - 0.9 * 256.0 / 40.0).abs() < 1e-12);
        assert!(!axes[2].is_uniform());
        assert_eq!(axes[2].spacing_range(), (1.0, 4.0));
        let all = read_all(&src);
        let min = all.iter().cloned().fold(f64::INFINITY, f64::min);
        let max = all.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        assert!((-1012.0..=-988.0).contains(&min), "min {min}");
        // The skull (about 4.4 mm) is thinner than its ramps on this coarse
        // grid (1.5 x 6.4 mm), so bone keeps only part of its contrast.
        assert!(max > 600.0 && max < 1400.0, "max {max}");
        // Air at a corner, bone and brain present.
        assert!(all[0] <= -988.0);
        assert!(all.iter().any(|v| (20.0..=50.0).contains(v)));
        assert!(all.iter().filter(|&&v| v > CT_BONE_ISO).count() > 20);
        // The top and bottom slices are outside the head ellipsoid, but the
        // neck reaches the bottom slice.
        let slice = 40 * 36;
        assert!(all[..slice].iter().any(|&v| v > CT_SKIN_ISO));
        assert!(all[29 * slice..].iter().all(|&v| v < CT_SKIN_ISO));

        // u16 = HU + 1024 with a rescale, the same HU after rescale.
        let side16 = dir.path().join("head16.json");
        let opts16 = CtOptions {
            dtype: CtDtype::U16,
            ..opts
        };
        ct(&side16, &opts16, &NoProgress).unwrap();
        let src16 = RawSource::open(&side16).unwrap();
        assert_eq!(src16.meta().rescale.intercept, -1024.0);
        let hu16: Vec<f64> = read_all(&src16)
            .iter()
            .map(|&v| src16.meta().rescale.apply(v))
            .collect();
        assert_eq!(hu16, all);
    }

    #[test]
    fn ct_boundaries_are_ramps() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("head.json");
        let opts = CtOptions {
            dims: [128, 128, 64],
            dtype: CtDtype::I16,
            seed: 5,
            ..CtOptions::default()
        };
        ct(&side, &opts, &NoProgress).unwrap();
        let all = read_all(&RawSource::open(&side).unwrap());
        let max = all.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        // Fine enough for the skull to reach full bone.
        assert!(max > 1000.0 && max < 1400.0, "max {max}");
        // Every surface ramps over at least 1.5 samples, so neighbours in x
        // and y differ by at most about 1300 / 1.5 HU plus the noise (hard
        // steps: 1040 from air to skin, more from skin to bone).
        let (nx, ny) = (128, 128);
        let mut step: f64 = 0.0;
        for (i, &v) in all.iter().enumerate() {
            if i % nx + 1 < nx {
                step = step.max((all[i + 1] - v).abs());
            }
            if (i / nx) % ny + 1 < ny {
                step = step.max((all[i + nx] - v).abs());
            }
        }
        assert!(step < 950.0, "largest x/y step {step}");
        // Partial-volume samples between air and skin.
        let between = all.iter().filter(|&&v| v > -900.0 && v < -100.0).count();
        assert!(between > 5000, "{between} samples between air and skin");
        // Deterministic.
        let again = dir.path().join("again.json");
        ct(&again, &opts, &NoProgress).unwrap();
        assert_eq!(read_all(&RawSource::open(&again).unwrap()), all);
    }

    #[test]
    fn z_positions_follow_data_set_2() {
        let z = ct_z_positions(160);
        let gaps: Vec<f64> = z.windows(2).map(|w| w[1] - w[0]).collect();
        assert_eq!(gaps.iter().filter(|&&g| g == 2.0).count(), 48);
        assert_eq!(gaps.iter().filter(|&&g| g == 1.0).count(), 72);
        assert_eq!(gaps.iter().filter(|&&g| g == 4.0).count(), 39);
        assert_eq!(ct_z_positions(2), vec![0.0, 2.0]);
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
