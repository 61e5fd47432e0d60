//! Patient orientation: which way each sample axis points in the patient.
//!
//! Recorded in the packed header (docs/FORMAT.md, `orientation`) as the
//! unit direction of the +x, +y and +z sample axes in **LPS** patient
//! coordinates, as DICOM uses them: +x towards the patient's Left, +y
//! Posterior, +z Superior (head). NIfTI's RAS is converted by negating the
//! first two components. cdvol never resamples: samples stay in file
//! order, and the renderer places its camera in patient terms through the
//! nearest signed permutation of the axes ([`Orientation::nearest`]). An
//! oblique orientation (not close to such a permutation) is rendered as
//! the nearest one, and the angle between them is stated.

use serde::{Deserialize, Serialize};

/// Rotation angle (degrees) from the nearest axis-aligned orientation
/// above which an orientation is called oblique.
pub const OBLIQUE_DEG: f64 = 0.5;

/// Largest |cos| between two axis directions accepted as orthogonal
/// (about 0.6 degrees off a right angle).
const ORTHO_TOL: f64 = 1e-2;

/// The voxel-to-patient axes of a volume and where they came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Orientation {
    /// `axes_lps[k]`: unit direction of sample axis k (x, y, z) in LPS.
    pub axes_lps: [[f64; 3]; 3],
    /// Where it came from (`DICOM ImageOrientationPatient`, `NIfTI sform`,
    /// `NRRD space directions`, `sidecar orientation`).
    pub source: String,
}

/// Why a set of directions is not an orientation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OrientationError {
    #[error("axis {axis} direction {dir:?} is not a finite non-zero vector")]
    Degenerate { axis: char, dir: [f64; 3] },
    #[error(
        "axes {a} and {b} are not orthogonal (cosine {cos:.4}), expected \
         orthogonal directions"
    )]
    NotOrthogonal { a: char, b: char, cos: f64 },
    #[error(
        "{code:?}, expected three letters, one of L/R, one of P/A and one of S/I \
         (such as LPS or RAS)"
    )]
    Code { code: String },
}

const AXIS: [char; 3] = ['x', 'y', 'z'];

/// A signed permutation: sample axis `k` points along patient (LPS) axis
/// `perm[k]`, in direction `sign[k]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisMap {
    pub perm: [usize; 3],
    pub sign: [f64; 3],
}

impl AxisMap {
    pub const IDENTITY: AxisMap = AxisMap {
        perm: [0, 1, 2],
        sign: [1.0; 3],
    };

    /// A patient (LPS) vector in sample axes. Exact: only swaps and signs.
    pub fn to_sample(&self, v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| self.sign[k] * v[self.perm[k]])
    }

    /// +1 when the sample axes are right-handed in the patient, -1 when
    /// they are mirrored.
    pub fn det(&self) -> f64 {
        let [a, b, c] = self.perm;
        // Parity of the permutation: even for the three rotations.
        let even = (a, b, c) == (0, 1, 2) || (a, b, c) == (1, 2, 0) || (a, b, c) == (2, 0, 1);
        let p = if even { 1.0 } else { -1.0 };
        p * self.sign.iter().product::<f64>()
    }

    /// The patient letters the +x, +y, +z sample axes point to (`LPS`,
    /// `RAS`, `LIP`, ...).
    pub fn code(&self) -> String {
        (0..3)
            .map(|k| {
                let pos = self.sign[k] > 0.0;
                match (self.perm[k], pos) {
                    (0, true) => 'L',
                    (0, false) => 'R',
                    (1, true) => 'P',
                    (1, false) => 'A',
                    (2, true) => 'S',
                    _ => 'I',
                }
            })
            .collect()
    }
}

impl Orientation {
    /// From the directions of the three sample axes in LPS, normalised;
    /// refused unless finite, non-zero and orthogonal.
    pub fn from_lps(axes: [[f64; 3]; 3], source: &str) -> Result<Orientation, OrientationError> {
        let mut out = [[0.0; 3]; 3];
        for k in 0..3 {
            let d = axes[k];
            let n = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(n.is_finite() && n > 0.0) {
                return Err(OrientationError::Degenerate {
                    axis: AXIS[k],
                    dir: d,
                });
            }
            out[k] = d.map(|x| x / n);
        }
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let cos: f64 = (0..3).map(|j| out[a][j] * out[b][j]).sum();
            if cos.abs() > ORTHO_TOL {
                return Err(OrientationError::NotOrthogonal {
                    a: AXIS[a],
                    b: AXIS[b],
                    cos,
                });
            }
        }
        Ok(Orientation {
            axes_lps: out,
            source: source.to_string(),
        })
    }

    /// From directions in RAS (NIfTI's world space).
    pub fn from_ras(axes: [[f64; 3]; 3], source: &str) -> Result<Orientation, OrientationError> {
        Orientation::from_lps(axes.map(|d| [-d[0], -d[1], d[2]]), source)
    }

    /// From a three-letter code such as `LPS` or `RAS`: the patient
    /// direction each of +x, +y, +z points to.
    pub fn from_code(code: &str, source: &str) -> Result<Orientation, OrientationError> {
        let bad = || OrientationError::Code {
            code: code.to_string(),
        };
        let letters: Vec<char> = code
            .trim()
            .chars()
            .map(|c| c.to_ascii_uppercase())
            .collect();
        if letters.len() != 3 {
            return Err(bad());
        }
        let mut axes = [[0.0; 3]; 3];
        let mut seen = [false; 3];
        for (k, c) in letters.iter().enumerate() {
            let (j, s) = match c {
                'L' => (0, 1.0),
                'R' => (0, -1.0),
                'P' => (1, 1.0),
                'A' => (1, -1.0),
                'S' => (2, 1.0),
                'I' => (2, -1.0),
                _ => return Err(bad()),
            };
            if seen[j] {
                return Err(bad());
            }
            seen[j] = true;
            axes[k][j] = s;
        }
        Orientation::from_lps(axes, source)
    }

    /// Checks a header's orientation (finite, unit, orthogonal).
    pub fn check(&self) -> Result<(), OrientationError> {
        Orientation::from_lps(self.axes_lps, &self.source)?;
        for (axis, dir) in AXIS.into_iter().zip(self.axes_lps) {
            let n: f64 = dir.iter().map(|x| x * x).sum();
            if (n - 1.0).abs() > 1e-6 {
                return Err(OrientationError::Degenerate { axis, dir });
            }
        }
        Ok(())
    }

    /// The nearest signed permutation: each sample axis to the patient
    /// axis it is closest to (largest components first, so two sample
    /// axes never share one).
    pub fn nearest(&self) -> AxisMap {
        let m = &self.axes_lps;
        let mut perm = [usize::MAX; 3];
        let mut sign = [1.0; 3];
        let (mut used_k, mut used_j) = ([false; 3], [false; 3]);
        for _ in 0..3 {
            let mut best: Option<(usize, usize, f64)> = None;
            for k in (0..3).filter(|&k| !used_k[k]) {
                for j in (0..3).filter(|&j| !used_j[j]) {
                    let a = m[k][j].abs();
                    if best.is_none_or(|b| a > b.2) {
                        best = Some((k, j, a));
                    }
                }
            }
            // Three rounds over a 3x3 matrix: a free pair always remains.
            let Some((k, j, _)) = best else { break };
            used_k[k] = true;
            used_j[j] = true;
            perm[k] = j;
            sign[k] = if m[k][j] < 0.0 { -1.0 } else { 1.0 };
        }
        AxisMap { perm, sign }
    }

    /// Degrees of rotation between the axes and [`Orientation::nearest`].
    pub fn oblique_deg(&self) -> f64 {
        let p = self.nearest();
        // trace(P^T D) = sum over k of sign[k] * D[k][perm[k]].
        let tr: f64 = (0..3)
            .map(|k| p.sign[k] * self.axes_lps[k][p.perm[k]])
            .sum();
        ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// `LPS from DICOM ImageOrientationPatient`, with the angle when
    /// oblique.
    pub fn describe(&self) -> String {
        let code = self.nearest().code();
        let deg = self.oblique_deg();
        if deg > OBLIQUE_DEG {
            format!(
                "oblique, {deg:.1} degrees from {code} (rendered as {code}) from {}",
                self.source
            )
        } else {
            format!("{code} from {}", self.source)
        }
    }
}

/// A named view in patient terms (`render --view anterior`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NamedView {
    /// Looking at the face, head up.
    Anterior,
    /// Looking at the back of the head, head up.
    Posterior,
    /// Looking at the patient's left side, head up.
    Left,
    /// Looking at the patient's right side, head up.
    Right,
    /// Looking down on the top of the head, face up in the image.
    Superior,
    /// Looking up from the feet, face up in the image.
    Inferior,
}

impl NamedView {
    pub const NAMES: &'static str = "anterior, posterior, left, right, superior, inferior";

    pub fn parse(s: &str) -> Option<NamedView> {
        Some(match s.trim().to_ascii_lowercase().as_str() {
            "anterior" => NamedView::Anterior,
            "posterior" => NamedView::Posterior,
            "left" => NamedView::Left,
            "right" => NamedView::Right,
            "superior" => NamedView::Superior,
            "inferior" => NamedView::Inferior,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            NamedView::Anterior => "anterior",
            NamedView::Posterior => "posterior",
            NamedView::Left => "left",
            NamedView::Right => "right",
            NamedView::Superior => "superior",
            NamedView::Inferior => "inferior",
        }
    }

    /// Azimuth and elevation in patient axes (degrees): where a turntable
    /// from this view starts.
    pub fn az_el(self) -> (f64, f64) {
        match self {
            NamedView::Anterior => (0.0, 0.0),
            NamedView::Left => (90.0, 0.0),
            NamedView::Posterior => (180.0, 0.0),
            NamedView::Right => (270.0, 0.0),
            NamedView::Superior => (180.0, 90.0),
            NamedView::Inferior => (0.0, -90.0),
        }
    }

    /// Whether the view looks along the head-foot axis (its up is then
    /// anterior, not superior).
    pub fn is_axial(self) -> bool {
        matches!(self, NamedView::Superior | NamedView::Inferior)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_permutations_and_handedness() {
        let lps = Orientation::from_code("LPS", "t").unwrap();
        assert_eq!(lps.nearest(), AxisMap::IDENTITY);
        assert_eq!(lps.nearest().det(), 1.0);
        let ras = Orientation::from_code("ras", "t").unwrap();
        assert_eq!(
            ras.axes_lps,
            [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert_eq!(ras.nearest().code(), "RAS");
        assert_eq!(ras.nearest().det(), 1.0);
        let las = Orientation::from_code("LAS", "t").unwrap();
        assert_eq!(las.nearest().det(), -1.0);
        let pil = Orientation::from_code("PIL", "t").unwrap();
        let m = pil.nearest();
        assert_eq!(m.code(), "PIL");
        // Patient superior is sample -y.
        assert_eq!(m.to_sample([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0]);
        for bad in ["LPP", "LP", "XYZ", "LPSS"] {
            assert!(Orientation::from_code(bad, "t").is_err(), "{bad}");
        }
    }

    #[test]
    fn oblique_angle_and_nearest_axes() {
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        // Rotated 30 degrees about z.
        let o = Orientation::from_lps([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]], "t").unwrap();
        assert_eq!(o.nearest(), AxisMap::IDENTITY);
        assert!((o.oblique_deg() - 30.0).abs() < 1e-9);
        assert!(o.describe().contains("oblique, 30.0 degrees from LPS"));
        let e = Orientation::from_lps([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "t");
        assert!(matches!(e, Err(OrientationError::NotOrthogonal { .. })));
        let e = Orientation::from_lps(
            [[f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            "t",
        );
        assert!(matches!(e, Err(OrientationError::Degenerate { .. })));
    }
}
