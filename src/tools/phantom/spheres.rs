//! The sphere scenes of the paper's section 5.1 (module docs of
//! [`phantom`](super)), and the spacing specs of their axes.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::fsutil::FileSet;

use crate::grid::{Axis, AxisError, MAX_SAMPLES_PER_AXIS};
use crate::input::sidecar::{AxisSpec, SidecarOut};
use crate::input::Endian;
use crate::progress::Progress;

// The shared plumbing of mod.rs: errors, the writer, the generator.
use super::*;

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

#[cfg(test)]
mod tests {
    use super::super::tests::read_all;
    use super::*;
    use crate::input::raw::RawSource;
    use crate::input::SliceSource;
    use crate::progress::NoProgress;

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
}
