//! The CT-like head (module docs of [`phantom`](super)).

use std::path::{Path, PathBuf};

use crate::fsutil::FileSet;

use crate::input::sidecar::{AxisSpec, SidecarOut};
use crate::input::{Endian, Rescale};
use crate::progress::Progress;

// The shared plumbing of mod.rs: errors, the writer, the generator.
use super::*;

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
pub(super) fn ct_z_positions(nz: usize) -> Vec<f64> {
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
    check_dims(dims)?;
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

#[cfg(test)]
mod tests {
    use super::super::tests::read_all;
    use super::*;
    use crate::input::raw::RawSource;
    use crate::input::SliceSource;
    use crate::progress::NoProgress;

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
}
