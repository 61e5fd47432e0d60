//! Rays in millimetres, checked before any walk: the one input every
//! traversal shares.

use glam::DVec3;

use crate::grid::MAX_COORD_MM;

/// A ray in mm: `origin + t * dir`, `t >= t_min`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub dir: DVec3,
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
    ///
    /// Takes arrays, as rays are usually written down; build a [`Ray`]
    /// literal to pass [`DVec3`]s.
    pub fn new(origin: [f64; 3], dir: [f64; 3]) -> Result<Ray, RayError> {
        let r = Ray {
            origin: DVec3::from_array(origin),
            dir: DVec3::from_array(dir),
        };
        r.check()?;
        Ok(r)
    }

    /// The checks of [`Ray::new`]; [`trace`](super::trace) visits nothing on a ray that
    /// fails them.
    pub fn check(&self) -> Result<(), RayError> {
        let (origin, dir) = (self.origin.to_array(), self.dir.to_array());
        if !origin.iter().all(|x| x.is_finite()) {
            return Err(RayError::NotFinite {
                what: "origin",
                value: origin,
            });
        }
        if !dir.iter().all(|x| x.is_finite()) {
            return Err(RayError::NotFinite {
                what: "direction",
                value: dir,
            });
        }
        let m = dir.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        if m == 0.0 {
            return Err(RayError::ZeroDirection(dir));
        }
        if m < MIN_DIR {
            return Err(RayError::TinyDirection(dir));
        }
        if m > MAX_DIR {
            return Err(RayError::HugeDirection(dir));
        }
        if origin.iter().any(|x| x.abs() > MAX_COORD_MM) {
            return Err(RayError::FarOrigin(origin));
        }
        Ok(())
    }
}
