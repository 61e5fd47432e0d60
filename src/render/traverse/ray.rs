//! Rays in millimetres, checked before any walk: the one input every
//! traversal shares.

use crate::grid::MAX_COORD_MM;

/// A ray in mm: `origin + t * dir`, `t >= t_min`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: [f64; 3],
    pub dir: [f64; 3],
}

/// Smallest largest-component of a direction [`Ray::new`] accepts
/// (2^-600). With [`MAX_DIR`] and origins and positions within
/// [`MAX_COORD_MM`] (< 2^50), every `t` the walk reports is at most
/// `2^51 / m <= 2^651`: finite; and f64 walks need no rescaling, so
/// distinct crossings are reported distinct.
pub const MIN_DIR: f64 = 2.409919865102884e-181;
/// Largest largest-component of a direction [`Ray::new`] accepts (2^600).
pub const MAX_DIR: f64 = 4.149515568880993e180;

/// Why a ray cannot be traced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RayError {
    #[error("ray direction {0:?} is zero, expected a non-zero direction")]
    ZeroDirection([f64; 3]),
    #[error("ray direction {0:?} is too short (largest component below {MIN_DIR:e}); scale it up")]
    TinyDirection([f64; 3]),
    #[error(
        "ray direction {0:?} is too long (largest component above {MAX_DIR:e}); scale it down"
    )]
    HugeDirection([f64; 3]),
    #[error("ray origin {0:?} is more than {MAX_COORD_MM:e} mm from 0 along an axis")]
    FarOrigin([f64; 3]),
    #[error("ray {what} {value:?} is not finite, expected finite numbers")]
    NotFinite { what: &'static str, value: [f64; 3] },
}

impl Ray {
    /// A checked ray: a finite origin within [`MAX_COORD_MM`] of 0 on every
    /// axis, and a finite direction whose largest component is in
    /// [[`MIN_DIR`], [`MAX_DIR`]]. Directions need not be normalised; other
    /// components may be 0.0, -0.0, subnormal or tiny.
    pub fn new(origin: [f64; 3], dir: [f64; 3]) -> Result<Ray, RayError> {
        let r = Ray { origin, dir };
        r.check()?;
        Ok(r)
    }

    /// The checks of [`Ray::new`]; [`trace`](super::trace) visits nothing on a ray that
    /// fails them.
    pub fn check(&self) -> Result<(), RayError> {
        if !self.origin.iter().all(|x| x.is_finite()) {
            return Err(RayError::NotFinite {
                what: "origin",
                value: self.origin,
            });
        }
        if !self.dir.iter().all(|x| x.is_finite()) {
            return Err(RayError::NotFinite {
                what: "direction",
                value: self.dir,
            });
        }
        let m = self.dir.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        if m == 0.0 {
            return Err(RayError::ZeroDirection(self.dir));
        }
        if m < MIN_DIR {
            return Err(RayError::TinyDirection(self.dir));
        }
        if m > MAX_DIR {
            return Err(RayError::HugeDirection(self.dir));
        }
        if self.origin.iter().any(|x| x.abs() > MAX_COORD_MM) {
            return Err(RayError::FarOrigin(self.origin));
        }
        Ok(())
    }
}
