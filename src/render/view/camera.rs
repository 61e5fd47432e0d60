//! Cameras: orthographic (the paper's parallel projection) or perspective,
//! placed by an orbit (around the object's centre, render/view/framing.rs)
//! or exactly by eye, target and up, all in mm, so rectilinear volumes
//! look undistorted.

use glam::DVec3;

use crate::render::stats::CameraUsed;
use crate::render::traverse::{Ray, RayError};

/// Why a camera cannot be placed. Fields are named as in [`Camera::look_at`]
/// and [`Camera::orbit`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// The eye or the target is not finite or too far from the origin.
    #[error("{what} {value:?}, expected finite mm within {limit:e} of 0")]
    FarPoint {
        what: &'static str,
        value: [f64; 3],
        limit: f64,
    },
    /// Eye and target coincide (or their difference overflows).
    #[error("eye {eye:?} and target {target:?} (or the orbit) must differ and be finite")]
    SamePoint { eye: [f64; 3], target: [f64; 3] },
    /// `up` is zero or parallel to the viewing direction.
    #[error("up {up:?} is parallel to the view direction or zero")]
    UpParallel { up: [f64; 3] },
    #[error("width x height {width} x {height}, expected at least 1 each")]
    EmptyImage { width: u32, height: u32 },
    #[error("frame_mm {frame_mm} mm, expected > 0")]
    Frame { frame_mm: f64 },
    #[error("fov_deg {fov_deg} degrees, expected 0 < fov < 180")]
    Fov { fov_deg: f64 },
    /// A named view on a file that does not record its orientation.
    #[error(
        "view {view} is in patient terms, but the file does not record its patient \
         orientation (info: orientation unknown); use --view AZ,EL in the file's sample \
         axes, or prepare from an input that gives one (DICOM, NIfTI, NRRD with a \
         patient space, or a sidecar with \"orientation\": \"LPS\" or the code that fits)"
    )]
    NoOrientation { view: &'static str },
    /// A corner pixel's ray fails [`Ray::check`].
    #[error("the view reaches too far (frame or eye): {source}")]
    TooFar { source: RayError },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Parallel rays; the frame is this many mm high.
    Ortho { frame_mm: f64 },
    /// Rays from the eye; vertical field of view in degrees.
    Persp { fov_deg: f64 },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub eye: DVec3,
    /// Unit viewing direction, right and up vectors.
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub projection: Projection,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Looks from `eye` at `target` with `up` (not parallel to the view).
    pub fn look_at(
        eye: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
        projection: Projection,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        // Every pixel's ray must pass `Ray::check` (a refused ray would
        // leave a silently empty pixel): eye and target within half of
        // MAX_COORD_MM, and the corner rays checked below.
        let lim = 0.5 * crate::grid::MAX_COORD_MM;
        for (what, p) in [("eye", eye), ("target", target)] {
            if p.iter().any(|x| !(x.abs() <= lim)) {
                return Err(CameraError::FarPoint {
                    what,
                    value: p,
                    limit: lim,
                });
            }
        }
        let f = DVec3::from_array(target) - DVec3::from_array(eye);
        if !(f.dot(f) > 0.0) || !f.is_finite() {
            return Err(CameraError::SamePoint { eye, target });
        }
        // `v / |v|`, not `normalize` (a multiplication by the reciprocal):
        // the same bits as ever.
        let forward = f / f.length();
        let r = forward.cross(DVec3::from_array(up));
        if !(r.dot(r) > 1e-20) {
            return Err(CameraError::UpParallel { up });
        }
        let right = r / r.length();
        let up = right.cross(forward);
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyImage { width, height });
        }
        match projection {
            Projection::Ortho { frame_mm } if !(frame_mm > 0.0 && frame_mm.is_finite()) => {
                return Err(CameraError::Frame { frame_mm })
            }
            Projection::Persp { fov_deg } if !(fov_deg > 0.0 && fov_deg < 180.0) => {
                return Err(CameraError::Fov { fov_deg })
            }
            _ => {}
        }
        let cam = Camera {
            eye: DVec3::from_array(eye),
            forward,
            right,
            up,
            projection,
            width,
            height,
        };
        // Ray origins are affine in the pixel, so the four corner pixels
        // bound them all.
        for (px, py) in [
            (0, 0),
            (width - 1, 0),
            (0, height - 1),
            (width - 1, height - 1),
        ] {
            if let Err(source) = cam.ray(px, py).check() {
                return Err(CameraError::TooFar { source });
            }
        }
        Ok(cam)
    }

    /// Orbits the centre of the box `[lo, hi]`: azimuth about +z (0 looks
    /// along +y, i.e. at the face of a supine head), elevation above the
    /// xy plane. Orthographic views frame the whole volume unless
    /// `frame_mm` is given; the eye stays outside the volume. (`cdvol
    /// render` and `cdvol serve` frame the object instead:
    /// [`super::framing`].)
    pub fn orbit(
        bounds: ([f64; 3], [f64; 3]),
        az_deg: f64,
        el_deg: f64,
        persp_fov: Option<f64>,
        frame_mm: Option<f64>,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        let (back, up) = orbit_dirs(az_deg, el_deg);
        Camera::orbit_dir(bounds, back, up, persp_fov, frame_mm, width, height)
    }

    /// [`Camera::orbit`] with the eye in direction `back` from the centre
    /// (a unit vector) and `up` (not parallel to `back`).
    pub fn orbit_dir(
        bounds: ([f64; 3], [f64; 3]),
        back: [f64; 3],
        up: [f64; 3],
        persp_fov: Option<f64>,
        frame_mm: Option<f64>,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        let (lo, hi) = bounds;
        let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let radius = 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let (projection, dist) = match persp_fov {
            Some(fov) => {
                let half = (0.5 * fov).to_radians();
                (
                    Projection::Persp { fov_deg: fov },
                    radius / half.sin().max(1e-6) * 1.05,
                )
            }
            None => (
                Projection::Ortho {
                    frame_mm: frame_mm.unwrap_or(2.0 * radius * 1.02),
                },
                2.0 * radius,
            ),
        };
        let eye = std::array::from_fn(|k| centre[k] + dist * back[k]);
        Camera::look_at(eye, centre, up, projection, width, height)
    }

    /// How this camera is spelled as `render --eye --target --up` with
    /// `--frame` or `--persp --fov` (the `camera` of `--stats`), the target
    /// 1 mm ahead of the eye.
    pub fn used(&self) -> CameraUsed {
        let (frame_mm, fov_deg) = match self.projection {
            Projection::Ortho { frame_mm } => (Some(frame_mm), None),
            Projection::Persp { fov_deg } => (None, Some(fov_deg)),
        };
        CameraUsed {
            eye: self.eye.to_array(),
            target: (self.eye + self.forward).to_array(),
            up: self.up.to_array(),
            frame_mm,
            fov_deg,
        }
    }

    /// Mirrors the image left to right (the right vector reversed): for
    /// sample axes that are mirrored in the patient, so that the image
    /// shows the patient as a viewer would see them.
    pub fn mirrored(mut self) -> Camera {
        self.right = -self.right;
        self
    }

    /// The ray through the centre of pixel `(px, py)` (row 0 at the top),
    /// with a unit direction, so `t` is in mm.
    pub fn ray(&self, px: u32, py: u32) -> Ray {
        let (w, h) = (self.width as f64, self.height as f64);
        let sx = (px as f64 + 0.5) / w * 2.0 - 1.0;
        let sy = 1.0 - (py as f64 + 0.5) / h * 2.0;
        let (half_w, half_h) = self.half_extents();
        match self.projection {
            Projection::Ortho { .. } => Ray {
                origin: self.eye + sx * half_w * self.right + sy * half_h * self.up,
                dir: self.forward,
            },
            Projection::Persp { .. } => {
                let d = self.forward + sx * half_w * self.right + sy * half_h * self.up;
                Ray {
                    origin: self.eye,
                    dir: d / d.length(),
                }
            }
        }
    }

    /// Half the screen across and up, which [`Camera::ray`] scales its
    /// screen coordinates in `[-1, 1]` by: mm (orthographic) or the
    /// tangents of the half angles of view (perspective).
    pub(crate) fn half_extents(&self) -> (f64, f64) {
        let half_h = match self.projection {
            Projection::Ortho { frame_mm } => 0.5 * frame_mm,
            Projection::Persp { fov_deg } => (0.5 * fov_deg).to_radians().tan(),
        };
        (half_h * self.width as f64 / self.height as f64, half_h)
    }
}

/// The unit direction from the centre to the eye of an orbit, and its up
/// vector: azimuth about +z (0 puts the eye on the -y side), elevation
/// towards +z; up is +z, or +y when looking straight along z.
pub fn orbit_dirs(az_deg: f64, el_deg: f64) -> ([f64; 3], [f64; 3]) {
    let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
    let back = [el.cos() * az.sin(), -el.cos() * az.cos(), el.sin()];
    let up = if el.cos().abs() < 1e-9 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    (back, up)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_whose_rays_the_traversal_would_refuse_are_refused() {
        let ortho = |frame_mm| Projection::Ortho { frame_mm };
        let up = [0.0, 0.0, 1.0];
        // A frame so wide that the corner rays start beyond 1e15 mm.
        let e = Camera::look_at([0.0; 3], [1.0, 0.0, 0.0], up, ortho(1e16), 8, 8).unwrap_err();
        assert!(matches!(e, CameraError::TooFar { .. }), "{e}");
        assert!(e.to_string().contains("too far"), "{e}");
        // A wide image stretches the frame sideways: 4e14 * 16 / 2 > 1e15.
        let e = Camera::look_at([0.0; 3], [1.0, 0.0, 0.0], up, ortho(4e14), 16, 1).unwrap_err();
        assert!(matches!(e, CameraError::TooFar { .. }), "{e}");
        assert!(e.to_string().contains("too far"), "{e}");
        let e = Camera::look_at([1e15, 0.0, 0.0], [0.0; 3], up, ortho(1.0), 8, 8).unwrap_err();
        assert!(
            matches!(e, CameraError::FarPoint { what: "eye", .. }),
            "{e}"
        );
        // At the limits, every pixel's ray passes Ray::check.
        let c = Camera::look_at([4e14, 0.0, 0.0], [0.0; 3], up, ortho(1e14), 64, 48).unwrap();
        for (x, y) in [(0, 0), (63, 47), (31, 20)] {
            assert!(c.ray(x, y).check().is_ok());
        }
    }
}
