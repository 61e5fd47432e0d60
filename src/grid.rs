//! Rectilinear grids: the sample coordinates along each axis (paper eqs. 4-7).
//!
//! Samples sit on grid points; cell `i` along an axis spans samples `i` and
//! `i + 1`, so an axis of `n` samples has `n - 1` cells. Coordinates are f64
//! millimetres and strictly increasing. A uniform axis is only a flag on the
//! same type (paper eq. 6), so every consumer handles the rectilinear case.

use serde::{Deserialize, Serialize};

/// Largest number of samples the format allows along one axis (2^20).
/// The header lists every sample position, so this keeps a header below
/// 100 MB; it is 500 times the slices of any CT series, and small enough
/// that the extreme-case suite reaches it with a thin slab
/// (tests/all/extremes.rs). Cell and brick indices fit in `u32`.
pub const MAX_SAMPLES_PER_AXIS: usize = 1 << 20;

/// Largest |position| in mm an axis may hold (10^15 mm, a million km):
/// with ray origins bounded alike ([`crate::render::traverse::Ray::new`])
/// and directions within 2^+-600, every ray parameter the traversal
/// reports stays a finite, normal f64, and positions stay finite in f32.
pub const MAX_COORD_MM: f64 = 1e15;

/// Smallest spacing an input may give, in mm (1 nm): the spacing of a
/// uniform axis, or the mean gap of a listed one (single gaps may be
/// smaller). A smaller one (5e-324 was accepted) puts every sample at one
/// point and renders nothing. Every reader checks it with [`check_spacing`].
pub const MIN_SPACING_MM: f64 = 1e-6;

/// Checks a spacing read from an input file (in mm, after any unit
/// conversion): a finite number of at least [`MIN_SPACING_MM`]. (Too
/// large a spacing puts a sample past [`MAX_COORD_MM`], which the axis
/// refuses.) Returns the spacing; the error says what was found and what
/// was expected, for the reader to prefix with the file and the field.
pub fn check_spacing(spacing_mm: f64) -> Result<f64, SpacingError> {
    if !spacing_mm.is_finite() {
        return Err(SpacingError::NotFinite { value: spacing_mm });
    }
    if spacing_mm < MIN_SPACING_MM {
        return Err(SpacingError::TooSmall { value: spacing_mm });
    }
    Ok(spacing_mm)
}

/// Why a spacing is refused ([`check_spacing`]).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SpacingError {
    /// NaN or infinite.
    #[error("spacing {value} mm, expected a finite spacing >= {MIN_SPACING_MM:e} mm")]
    NotFinite { value: f64 },
    /// Below [`MIN_SPACING_MM`] (zero and negative included).
    #[error("spacing {value:e} mm, expected a spacing >= {MIN_SPACING_MM:e} mm")]
    TooSmall { value: f64 },
}

/// Checks a number of samples along one axis read from an input file,
/// before anything is allocated for it: from 2 to
/// [`MAX_SAMPLES_PER_AXIS`]. Takes a `u64` so that a reader can pass a
/// count wider than `usize` (or a negative one cast) unchanged.
pub fn check_samples(n: u64) -> Result<usize, AxisError> {
    if n < 2 {
        return Err(AxisError::TooShort { len: n as usize });
    }
    if n > MAX_SAMPLES_PER_AXIS as u64 {
        return Err(AxisError::TooLong { len: n as usize });
    }
    Ok(n as usize)
}

/// Why a list of sample positions is not a valid axis. Each variant names
/// the position's index and value where one is at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AxisError {
    /// Fewer than 2 samples: no cell.
    #[error("{len} samples, expected at least 2")]
    TooShort { len: usize },
    /// More than [`MAX_SAMPLES_PER_AXIS`] samples.
    #[error("{len} samples, expected at most {MAX_SAMPLES_PER_AXIS}")]
    TooLong { len: usize },
    /// A position is NaN or infinite.
    #[error("coordinate {index} is {value}, expected a finite number")]
    NotFinite { index: usize, value: f64 },
    /// A position is farther than [`MAX_COORD_MM`] from 0.
    #[error("coordinate {index} is {value:e} mm, expected at most {MAX_COORD_MM:e} mm from 0")]
    TooFar { index: usize, value: f64 },
    /// A position is not larger than the one before it.
    #[error(
        "coordinate {index} is {value} mm after {prev} mm, \
         expected strictly increasing positions (gap > 0)"
    )]
    NotIncreasing { index: usize, prev: f64, value: f64 },
}

/// One axis of a rectilinear grid: the positions `S[0..n]` of its samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Vec<f64>", into = "Vec<f64>")]
pub struct Axis {
    coords: Vec<f64>,
    uniform: bool,
}

impl TryFrom<Vec<f64>> for Axis {
    type Error = AxisError;
    fn try_from(coords: Vec<f64>) -> Result<Self, AxisError> {
        Axis::from_coords(coords)
    }
}

impl From<Axis> for Vec<f64> {
    fn from(a: Axis) -> Vec<f64> {
        a.coords
    }
}

impl Axis {
    /// Checks and wraps sample positions in mm.
    pub fn from_coords(coords: Vec<f64>) -> Result<Axis, AxisError> {
        if coords.len() < 2 {
            return Err(AxisError::TooShort { len: coords.len() });
        }
        if coords.len() > MAX_SAMPLES_PER_AXIS {
            return Err(AxisError::TooLong { len: coords.len() });
        }
        for (index, &value) in coords.iter().enumerate() {
            if !value.is_finite() {
                return Err(AxisError::NotFinite { index, value });
            }
            if value.abs() > MAX_COORD_MM {
                return Err(AxisError::TooFar { index, value });
            }
            if index > 0 && value <= coords[index - 1] {
                let prev = coords[index - 1];
                return Err(AxisError::NotIncreasing { index, prev, value });
            }
        }
        let uniform = is_uniform(&coords);
        Ok(Axis { coords, uniform })
    }

    /// A uniform axis of `n` samples (paper eq. 6). `n` is checked before
    /// any allocation.
    pub fn uniform(origin_mm: f64, spacing_mm: f64, n: usize) -> Result<Axis, AxisError> {
        check_samples(n as u64)?;
        Axis::from_coords((0..n).map(|i| origin_mm + spacing_mm * i as f64).collect())
    }

    /// Sample positions in mm.
    pub fn coords(&self) -> &[f64] {
        &self.coords
    }

    /// Number of samples.
    pub fn samples(&self) -> usize {
        self.coords.len()
    }

    /// Number of cells (`samples - 1`).
    pub fn cells(&self) -> usize {
        self.coords.len() - 1
    }

    /// True when every gap equals the first one to 1e-9 relative.
    pub fn is_uniform(&self) -> bool {
        self.uniform
    }

    /// Smallest and largest gap between neighbouring samples, in mm.
    pub fn spacing_range(&self) -> (f64, f64) {
        self.coords
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), g| {
                (lo.min(g), hi.max(g))
            })
    }
}

fn is_uniform(coords: &[f64]) -> bool {
    let first = coords[1] - coords[0];
    coords
        .windows(2)
        .all(|w| ((w[1] - w[0]) - first).abs() <= 1e-9 * first.abs())
}

/// The three axes of a rectilinear grid, x fastest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    pub axes: [Axis; 3],
}

impl Grid {
    /// Samples per axis.
    pub fn dims(&self) -> [usize; 3] {
        [
            self.axes[0].samples(),
            self.axes[1].samples(),
            self.axes[2].samples(),
        ]
    }

    /// Cells per axis.
    pub fn cells(&self) -> [usize; 3] {
        let d = self.dims();
        [d[0] - 1, d[1] - 1, d[2] - 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_bad_axes_with_the_index() {
        assert_eq!(
            Axis::from_coords(vec![0.0]),
            Err(AxisError::TooShort { len: 1 })
        );
        let e = Axis::from_coords(vec![0.0, 1.0, 1.0]).unwrap_err();
        assert!(e.to_string().contains("coordinate 2"), "{e}");
        assert!(e.to_string().contains("strictly increasing"), "{e}");
        let e = Axis::from_coords(vec![0.0, f64::NAN]).unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
    }

    #[test]
    fn checks_spacings_and_sample_counts_before_allocating() {
        assert_eq!(check_spacing(0.5), Ok(0.5));
        for bad in [0.0, -1.0, 1e-45, 1e-300, f64::NAN, f64::INFINITY] {
            let e = check_spacing(bad).unwrap_err().to_string();
            assert!(e.contains("expected"), "{bad}: {e}");
        }
        assert!(check_samples(u64::MAX).is_err());
        assert!(check_samples(1).is_err());
        assert_eq!(check_samples(2), Ok(2));
        // Refused by its count, not by a failed allocation.
        assert_eq!(
            Axis::uniform(0.0, 1.0, usize::MAX),
            Err(AxisError::TooLong { len: usize::MAX })
        );
    }

    #[test]
    fn detects_uniform_and_rectilinear() {
        assert!(Axis::uniform(-3.0, 0.25, 9).unwrap().is_uniform());
        let a = Axis::from_coords(vec![0.0, 1.0, 2.5]).unwrap();
        assert!(!a.is_uniform());
        assert_eq!(a.spacing_range(), (1.0, 1.5));
        assert_eq!(a.cells(), 2);
    }
}
