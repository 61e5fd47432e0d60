//! Cameras: orthographic (the paper's parallel projection) or perspective,
//! placed by an orbit around the volume centre or exactly by eye, target
//! and up, all in mm, so rectilinear volumes look undistorted.

use super::shade::{cross, dot, normalize};
use super::traverse::Ray;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Parallel rays; the frame is this many mm high.
    Ortho { frame_mm: f64 },
    /// Rays from the eye; vertical field of view in degrees.
    Persp { fov_deg: f64 },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub eye: [f64; 3],
    /// Unit viewing direction, right and up vectors.
    pub forward: [f64; 3],
    pub right: [f64; 3],
    pub up: [f64; 3],
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
    ) -> Result<Camera, String> {
        // Every pixel's ray must pass `Ray::check` (a refused ray would
        // leave a silently empty pixel): eye and target within half of
        // MAX_COORD_MM, and the corner rays checked below.
        let lim = 0.5 * crate::grid::MAX_COORD_MM;
        for (name, p) in [("--eye", eye), ("--target", target)] {
            if p.iter().any(|x| !(x.abs() <= lim)) {
                return Err(format!(
                    "{name} {p:?}, expected finite mm within {lim:e} of 0"
                ));
            }
        }
        let f = std::array::from_fn(|k| target[k] - eye[k]);
        if !(dot(f, f) > 0.0) || f.iter().any(|x| !x.is_finite()) {
            return Err(format!(
                "--eye {eye:?} and --target {target:?} (or the orbit) must differ and be finite"
            ));
        }
        let forward = normalize(f);
        let r = cross(forward, up);
        if !(dot(r, r) > 1e-20) {
            return Err(format!(
                "--up {up:?} is parallel to the view direction or zero"
            ));
        }
        let right = normalize(r);
        let up = cross(right, forward);
        if width == 0 || height == 0 {
            return Err(format!(
                "--width {width} --height {height}, expected at least 1 each"
            ));
        }
        match projection {
            Projection::Ortho { frame_mm } if !(frame_mm > 0.0 && frame_mm.is_finite()) => {
                return Err(format!("--frame {frame_mm} mm, expected > 0"))
            }
            Projection::Persp { fov_deg } if !(fov_deg > 0.0 && fov_deg < 180.0) => {
                return Err(format!("--fov {fov_deg} degrees, expected 0 < fov < 180"))
            }
            _ => {}
        }
        let cam = Camera {
            eye,
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
            if let Err(e) = cam.ray(px, py).check() {
                return Err(format!("the view reaches too far (--frame or --eye): {e}"));
            }
        }
        Ok(cam)
    }

    /// Orbits the centre of the box `[lo, hi]`: azimuth about +z (0 looks
    /// along +y, i.e. at the face of a supine head), elevation above the
    /// xy plane. Orthographic views frame the whole volume unless
    /// `frame_mm` is given; the eye stays outside the volume.
    pub fn orbit(
        bounds: ([f64; 3], [f64; 3]),
        az_deg: f64,
        el_deg: f64,
        persp_fov: Option<f64>,
        frame_mm: Option<f64>,
        width: u32,
        height: u32,
    ) -> Result<Camera, String> {
        let (lo, hi) = bounds;
        let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let radius = 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
        let back = [el.cos() * az.sin(), -el.cos() * az.cos(), el.sin()];
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
        let up = if el.cos().abs() < 1e-9 {
            [0.0, 1.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        Camera::look_at(eye, centre, up, projection, width, height)
    }

    /// The ray through the centre of pixel `(px, py)` (row 0 at the top),
    /// with a unit direction, so `t` is in mm.
    pub fn ray(&self, px: u32, py: u32) -> Ray {
        let (w, h) = (self.width as f64, self.height as f64);
        let sx = (px as f64 + 0.5) / w * 2.0 - 1.0;
        let sy = 1.0 - (py as f64 + 0.5) / h * 2.0;
        match self.projection {
            Projection::Ortho { frame_mm } => {
                let half_h = 0.5 * frame_mm;
                let half_w = half_h * w / h;
                Ray {
                    origin: std::array::from_fn(|k| {
                        self.eye[k] + sx * half_w * self.right[k] + sy * half_h * self.up[k]
                    }),
                    dir: self.forward,
                }
            }
            Projection::Persp { fov_deg } => {
                let half_h = (0.5 * fov_deg).to_radians().tan();
                let half_w = half_h * w / h;
                let d = std::array::from_fn(|k| {
                    self.forward[k] + sx * half_w * self.right[k] + sy * half_h * self.up[k]
                });
                Ray {
                    origin: self.eye,
                    dir: normalize(d),
                }
            }
        }
    }
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
        assert!(e.contains("too far"), "{e}");
        // A wide image stretches the frame sideways: 4e14 * 16 / 2 > 1e15.
        let e = Camera::look_at([0.0; 3], [1.0, 0.0, 0.0], up, ortho(4e14), 16, 1).unwrap_err();
        assert!(e.contains("too far"), "{e}");
        let e = Camera::look_at([1e15, 0.0, 0.0], [0.0; 3], up, ortho(1.0), 8, 8).unwrap_err();
        assert!(e.contains("--eye"), "{e}");
        // At the limits, every pixel's ray passes Ray::check.
        let c = Camera::look_at([4e14, 0.0, 0.0], [0.0; 3], up, ortho(1e14), 64, 48).unwrap();
        for (x, y) in [(0, 0), (63, 47), (31, 20)] {
            assert!(c.ray(x, y).check().is_ok());
        }
    }
}
