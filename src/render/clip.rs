//! Crop box and clipping planes: the part of the volume a render keeps.
//!
//! A crop box keeps `[x0, x1] x [y0, y1] x [z0, z1]` (mm, the file's
//! coordinates, those of `--eye` and `--target`); a clipping plane `(n, D)`
//! keeps the closed half-space `n . p >= D`, the side its normal points
//! into. Both only shorten each ray's interval before the traversal
//! ([`Clip::span`]): the walk starts where the ray enters the kept region
//! and stops where it leaves it, so the cells outside are never visited
//! and the bricks wholly outside are never read (the cover leaves them out,
//! render/view/cull.rs). It sits beside the options, which carry it. Inside the interval every integrator does what it
//! does without a clip; the composite's samples stay on their lattice.
//!
//! Faces of the crop box on or outside the volume's box cut nothing and
//! are dropped ([`Clip::within`]), so a crop box equal to the volume's box
//! is no clip at all and draws the image of no crop, byte for byte.

use glam::DVec3;

use crate::render::traverse::{Ray, Visit};

/// A half-space `normal . p >= d` (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub d: f64,
}

/// Crop box and clipping planes of a render; the default keeps
/// everything.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Clip {
    /// `[[x0, x1], [y0, y1], [z0, z1]]` in mm.
    pub crop: Option<[[f64; 2]; 3]>,
    /// At most [`MAX_PLANES`] half-spaces, all kept at once.
    pub planes: Vec<Plane>,
}

/// Most clipping planes a render takes (as VTK's mappers).
pub const MAX_PLANES: usize = 6;

/// Where a ray's kept interval starts and ends, and what it starts on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// First `t` kept (at least the caller's start).
    pub start: f64,
    /// Last `t` kept (infinite when nothing cuts the ray's far side).
    pub end: f64,
    /// The outward normal of the cut face the ray enters the kept region
    /// through at `start`, facing the ray (`dir . cut < 0`); `None` when
    /// `start` is not on a cut.
    pub cut: Option<DVec3>,
}

impl Span {
    /// The whole ray from `start` on: no clip.
    pub fn from(start: f64) -> Span {
        Span {
            start,
            end: f64::INFINITY,
            cut: None,
        }
    }

    /// Whether `t` lies past the kept interval.
    #[inline]
    pub fn past(&self, t: f64) -> bool {
        t > self.end
    }

    /// Visit `v` cut to the span.
    #[inline]
    pub fn cut(&self, v: &Visit) -> Cut {
        if self.past(v.t_enter) {
            return Cut::Past;
        }
        let (t_enter, t_exit) = (v.t_enter.max(self.start), v.t_exit.min(self.end));
        if t_enter <= t_exit {
            Cut::Kept(Visit {
                cell: v.cell,
                t_enter,
                t_exit,
            })
        } else {
            Cut::Empty
        }
    }
}

/// A visit cut to a [`Span`] ([`Span::cut`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cut {
    /// The part of the visit the span keeps.
    Kept(Visit),
    /// Nothing of it is kept (it ends before the span starts).
    Empty,
    /// It starts past the span's end: the walk is over.
    Past,
}

/// A crop box or plane that is no region.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClipError {
    #[error("crop {axis} {lo}:{hi}: expected finite bounds with {lo} < {hi}")]
    EmptyCrop { axis: char, lo: f64, hi: f64 },
    #[error(
        "crop {x0}:{x1},{y0}:{y1},{z0}:{z1} lies outside the volume, \
         {vx0}:{vx1},{vy0}:{vy1},{vz0}:{vz1} mm"
    )]
    OutsideCrop {
        x0: f64,
        x1: f64,
        y0: f64,
        y1: f64,
        z0: f64,
        z1: f64,
        vx0: f64,
        vx1: f64,
        vy0: f64,
        vy1: f64,
        vz0: f64,
        vz1: f64,
    },
    #[error("clip plane {index}: normal {normal:?}, D {d}: expected a finite non-zero normal and a finite D")]
    BadPlane {
        index: usize,
        normal: [f64; 3],
        d: f64,
    },
    #[error("{0} clip planes: expected at most {MAX_PLANES}")]
    TooMany(usize),
}

/// The patient directions `--clip-half` names, in LPS.
pub const HALVES: &str = "left, right, anterior, posterior, superior, inferior";

/// The plane through the centre of the box `lo..hi` that keeps the half
/// on the patient's `side` (one of [`HALVES`]), for a file whose axes
/// point as `orientation` says; `None` for an unknown side.
pub fn half(
    side: &str,
    lo: [f64; 3],
    hi: [f64; 3],
    orientation: &crate::orient::Orientation,
) -> Option<Plane> {
    let u = match side.trim().to_ascii_lowercase().as_str() {
        "left" => [1.0, 0.0, 0.0],
        "right" => [-1.0, 0.0, 0.0],
        "posterior" => [0.0, 1.0, 0.0],
        "anterior" => [0.0, -1.0, 0.0],
        "superior" => [0.0, 0.0, 1.0],
        "inferior" => [0.0, 0.0, -1.0],
        _ => return None,
    };
    // Sample axis k points along axes_lps[k]: the direction u is
    // (axes_lps[k] . u) in the file's coordinates.
    let a = orientation.axes_lps;
    let normal: [f64; 3] = std::array::from_fn(|k| (0..3).map(|j| a[k][j] * u[j]).sum());
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let d = (0..3).map(|k| normal[k] * centre[k]).sum();
    Some(Plane { normal, d })
}

impl Clip {
    /// Whether this keeps everything.
    pub fn is_none(&self) -> bool {
        self.crop.is_none() && self.planes.is_empty()
    }

    /// Checks the crop box and planes against the volume's box `lo..hi`:
    /// a crop with finite bounds, each low below its high, that meets the
    /// volume; planes with a finite non-zero normal and a finite `d`; at
    /// most [`MAX_PLANES`].
    pub fn check(&self, lo: [f64; 3], hi: [f64; 3]) -> Result<(), ClipError> {
        if self.planes.len() > MAX_PLANES {
            return Err(ClipError::TooMany(self.planes.len()));
        }
        for (index, p) in self.planes.iter().enumerate() {
            let n = DVec3::from_array(p.normal);
            if !(n.is_finite() && n != DVec3::ZERO && p.d.is_finite()) {
                return Err(ClipError::BadPlane {
                    index,
                    normal: p.normal,
                    d: p.d,
                });
            }
        }
        if let Some(c) = self.crop {
            for (k, [a, b]) in c.iter().enumerate() {
                if !(a.is_finite() && b.is_finite() && a < b) {
                    return Err(ClipError::EmptyCrop {
                        axis: ['x', 'y', 'z'][k],
                        lo: *a,
                        hi: *b,
                    });
                }
            }
            if (0..3).any(|k| c[k][1] < lo[k] || c[k][0] > hi[k]) {
                return Err(ClipError::OutsideCrop {
                    x0: c[0][0],
                    x1: c[0][1],
                    y0: c[1][0],
                    y1: c[1][1],
                    z0: c[2][0],
                    z1: c[2][1],
                    vx0: lo[0],
                    vx1: hi[0],
                    vy0: lo[1],
                    vy1: hi[1],
                    vz0: lo[2],
                    vz1: hi[2],
                });
            }
        }
        Ok(())
    }

    /// This clip on a volume whose box is `lo..hi`: the crop box's faces
    /// on or outside the volume's box dropped (they cut nothing), and no
    /// crop at all when none is left. Renders use this form, so a crop box
    /// equal to the volume's is exactly no clip.
    pub fn within(&self, lo: [f64; 3], hi: [f64; 3]) -> Clip {
        let crop = self.crop.map(|c| {
            std::array::from_fn(|k| {
                [
                    if c[k][0] <= lo[k] {
                        f64::NEG_INFINITY
                    } else {
                        c[k][0]
                    },
                    if c[k][1] >= hi[k] {
                        f64::INFINITY
                    } else {
                        c[k][1]
                    },
                ]
            })
        });
        let crop =
            crop.filter(|c: &[[f64; 2]; 3]| c.iter().any(|[a, b]| a.is_finite() || b.is_finite()));
        Clip {
            crop,
            planes: self.planes.clone(),
        }
    }

    /// The interval of `t >= start` in which `ray` is kept, with the cut
    /// it enters through; `None` when it keeps none of it. Closed: a point
    /// on a face is kept.
    pub fn span(&self, ray: &Ray, start: f64) -> Option<Span> {
        let mut s = Span::from(start);
        let o = ray.origin;
        let d = ray.dir;
        // Keeps `a * t >= b`; `normal` is the half-space's inward normal.
        let mut keep = |a: f64, b: f64, normal: DVec3| -> bool {
            if a > 0.0 {
                let t = b / a;
                if t > s.start {
                    s.start = t;
                    s.cut = Some(-normal);
                }
            } else if a < 0.0 {
                s.end = s.end.min(b / a);
            } else if b > 0.0 {
                // Parallel to the face and outside it.
                return false;
            }
            true
        };
        if let Some(c) = &self.crop {
            for k in 0..3 {
                let e = DVec3::from_array(std::array::from_fn(|j| (j == k) as u8 as f64));
                // x_k >= lo and -x_k >= -hi.
                if c[k][0].is_finite() && !keep(d[k], c[k][0] - o[k], e) {
                    return None;
                }
                if c[k][1].is_finite() && !keep(-d[k], o[k] - c[k][1], -e) {
                    return None;
                }
            }
        }
        for p in &self.planes {
            let n = DVec3::from_array(p.normal);
            if !keep(n.dot(d), p.d - n.dot(o), n) {
                return None;
            }
        }
        (s.start <= s.end).then_some(s)
    }

    /// Whether any point of the box `lo..hi` is kept (a brick wholly
    /// outside is never read).
    pub fn keeps_box(&self, lo: DVec3, hi: DVec3) -> bool {
        if let Some(c) = &self.crop {
            if (0..3).any(|k| hi[k] < c[k][0] || lo[k] > c[k][1]) {
                return false;
            }
        }
        // The corner furthest along each normal.
        self.planes.iter().all(|p| {
            let n = DVec3::from_array(p.normal);
            let far = DVec3::new(
                if n.x >= 0.0 { hi.x } else { lo.x },
                if n.y >= 0.0 { hi.y } else { lo.y },
                if n.z >= 0.0 { hi.z } else { lo.z },
            );
            n.dot(far) >= p.d
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crop_equal_to_the_volume_is_no_clip() {
        let c = Clip {
            crop: Some([[0.0, 10.0], [-1.0, 5.0], [2.0, 3.0]]),
            planes: Vec::new(),
        };
        assert!(c.within([0.0, -1.0, 2.0], [10.0, 5.0, 3.0]).is_none());
        assert!(c.within([-1.0, -2.0, 0.0], [11.0, 6.0, 4.0]).crop.is_some());
    }

    #[test]
    fn refuses_empty_crops_outside_crops_and_zero_normals() {
        let (lo, hi) = ([0.0; 3], [10.0; 3]);
        let crop = |c| Clip {
            crop: Some(c),
            planes: Vec::new(),
        };
        let e = crop([[5.0, 5.0], [0.0, 1.0], [0.0, 1.0]])
            .check(lo, hi)
            .unwrap_err();
        assert!(e.to_string().contains("crop x 5:5"), "{e}");
        let e = crop([[11.0, 12.0], [0.0, 1.0], [0.0, 1.0]])
            .check(lo, hi)
            .unwrap_err();
        assert!(e.to_string().contains("outside the volume, 0:10"), "{e}");
        let plane = Clip {
            crop: None,
            planes: vec![Plane {
                normal: [0.0; 3],
                d: 1.0,
            }],
        };
        assert!(plane
            .check(lo, hi)
            .unwrap_err()
            .to_string()
            .contains("non-zero normal"));
    }
}
