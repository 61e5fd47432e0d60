//! Cell evaluation along a ray and shading, shared by every traversal (so CD
//! and FVT images can only differ if their cell sequences differ).
//!
//! Values inside a cell come from the trilinear interpolant of its 8
//! vertex values, all exact in a 1-cell; [`CellEval::gradient`] is the
//! interpolant's own derivative (Newton's hit refinement, `--normals
//! cell`). Smooth shading normals, which read samples outside the cell,
//! are in [`super::normals`].
//!
//! Finding the hit inside a 1-cell (paper section 5.3) is in
//! [`super::hit`], which evaluates cells with this module: it imports
//! this one, never the other way.

use glam::DVec3;

use crate::render::traverse::Ray;

/// A cell's geometry and values, ready for evaluation along a ray.
pub struct CellEval {
    /// Lower corner and size of the cell in mm.
    pub lo: [f64; 3],
    pub size: [f64; 3],
    /// Vertex values, x fastest.
    pub f: [f64; 8],
}

impl CellEval {
    pub fn new(coords: [&[f64]; 3], cell: [u32; 3], f: [f32; 8]) -> CellEval {
        let lo = std::array::from_fn(|k| coords[k][cell[k] as usize]);
        let size =
            std::array::from_fn(|k| coords[k][cell[k] as usize + 1] - coords[k][cell[k] as usize]);
        CellEval {
            lo,
            size,
            f: f.map(|x| x as f64),
        }
    }

    /// Local coordinates in [0, 1]^3 of point `p` (clamped).
    #[inline]
    pub(super) fn local(&self, p: DVec3) -> [f64; 3] {
        std::array::from_fn(|k| ((p[k] - self.lo[k]) / self.size[k]).clamp(0.0, 1.0))
    }

    /// Trilinear value at local coordinates `u`.
    #[inline]
    pub fn value_local(&self, u: [f64; 3]) -> f64 {
        let f = &self.f;
        let x00 = f[0] + u[0] * (f[1] - f[0]);
        let x10 = f[2] + u[0] * (f[3] - f[2]);
        let x01 = f[4] + u[0] * (f[5] - f[4]);
        let x11 = f[6] + u[0] * (f[7] - f[6]);
        let y0 = x00 + u[1] * (x10 - x00);
        let y1 = x01 + u[1] * (x11 - x01);
        y0 + u[2] * (y1 - y0)
    }

    /// Trilinear value at point `p` (mm).
    #[inline]
    pub fn value(&self, p: DVec3) -> f64 {
        self.value_local(self.local(p))
    }

    /// Gradient of the trilinear interpolant at `p`, per mm.
    pub fn gradient(&self, p: DVec3) -> DVec3 {
        let u = self.local(p);
        let f = &self.f;
        let lerp = |a: f64, b: f64, t: f64| a + t * (b - a);
        // d/dx: differences along x, interpolated in y and z.
        let dx = lerp(
            lerp(f[1] - f[0], f[3] - f[2], u[1]),
            lerp(f[5] - f[4], f[7] - f[6], u[1]),
            u[2],
        );
        let dy = lerp(
            lerp(f[2] - f[0], f[3] - f[1], u[0]),
            lerp(f[6] - f[4], f[7] - f[5], u[0]),
            u[2],
        );
        let dz = lerp(
            lerp(f[4] - f[0], f[5] - f[1], u[0]),
            lerp(f[6] - f[2], f[7] - f[3], u[0]),
            u[1],
        );
        DVec3::new(dx / self.size[0], dy / self.size[1], dz / self.size[2])
    }
}

/// A cell's trilinear interpolant along one ray, for many samples: the
/// local coordinates are linear in `t`, `u_k = a_k + b_k t` with `a_k =
/// (o_k - lo_k) / size_k` and `b_k = d_k / size_k` computed once per cell
/// (one division per axis instead of one per axis and sample), and the
/// vertex differences along x are taken once. Agrees with
/// [`CellEval::value`] at `at(ray, t)` to rounding (the local coordinates
/// round differently: ~1e-16 times `(|o_k| + |t d_k|) / size_k`).
pub struct AlongRay {
    a: [f64; 3],
    b: [f64; 3],
    /// `f0, f1 - f0, f2, f3 - f2, f4, f5 - f4, f6, f7 - f6`.
    f: [f64; 8],
}

impl AlongRay {
    #[inline]
    pub fn new(coords: [&[f64]; 3], cell: [u32; 3], f: [f32; 8], ray: &Ray) -> AlongRay {
        let mut a = [0.0; 3];
        let mut b = [0.0; 3];
        for k in 0..3 {
            let lo = coords[k][cell[k] as usize];
            let size = coords[k][cell[k] as usize + 1] - lo;
            a[k] = (ray.origin[k] - lo) / size;
            b[k] = ray.dir[k] / size;
        }
        let f = f.map(|x| x as f64);
        AlongRay {
            a,
            b,
            f: [
                f[0],
                f[1] - f[0],
                f[2],
                f[3] - f[2],
                f[4],
                f[5] - f[4],
                f[6],
                f[7] - f[6],
            ],
        }
    }

    /// Trilinear value at `t` along the ray (local coordinates clamped to
    /// the cell, as [`CellEval::value`]).
    #[inline]
    pub fn value(&self, t: f64) -> f64 {
        let u: [f64; 3] = std::array::from_fn(|k| (self.a[k] + t * self.b[k]).clamp(0.0, 1.0));
        let f = &self.f;
        let x00 = f[0] + u[0] * f[1];
        let x10 = f[2] + u[0] * f[3];
        let x01 = f[4] + u[0] * f[5];
        let x11 = f[6] + u[0] * f[7];
        let y0 = x00 + u[1] * (x10 - x00);
        let y1 = x01 + u[1] * (x11 - x01);
        y0 + u[2] * (y1 - y0)
    }
}

#[inline]
pub fn at(ray: &Ray, t: f64) -> DVec3 {
    ray.origin + t * ray.dir
}

/// Lambert + Phong shading of a hit with the interpolant's gradient.
/// `to_light` and `to_eye` are unit vectors; returns grey in [0, 1].
pub fn shade(normal_grad: DVec3, to_light: DVec3, to_eye: DVec3, lit: bool) -> f64 {
    let len = (normal_grad[0].powi(2) + normal_grad[1].powi(2) + normal_grad[2].powi(2)).sqrt();
    const AMBIENT: f64 = 0.12;
    if !(len > 0.0) {
        return AMBIENT + 0.5;
    }
    // Outward normal: values rise into the object, so it is -grad; face it
    // towards the eye.
    let mut n = -normal_grad / len;
    if n.dot(to_eye) < 0.0 {
        n = -n;
    }
    if !lit {
        return AMBIENT;
    }
    let ndl = n.dot(to_light).max(0.0);
    let r = 2.0 * ndl * n - to_light;
    let spec = if ndl > 0.0 {
        r.dot(to_eye).max(0.0).powi(32)
    } else {
        0.0
    };
    (AMBIENT + 0.75 * ndl + 0.25 * spec).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v3(a: [f64; 3]) -> DVec3 {
        DVec3::from_array(a)
    }

    #[test]
    fn trilinear_reproduces_vertices_and_linear_functions() {
        let coords: [Vec<f64>; 3] = [vec![0.0, 2.0], vec![1.0, 1.5], vec![-3.0, 1.0]];
        let lin = |p: [f64; 3]| 2.0 * p[0] - 3.0 * p[1] + 0.5 * p[2] + 1.0;
        let mut f = [0f32; 8];
        for (i, v) in f.iter_mut().enumerate() {
            *v = lin([coords[0][i & 1], coords[1][i >> 1 & 1], coords[2][i >> 2]]) as f32;
        }
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], f);
        for p in [[0.5, 1.2, 0.0], [1.9, 1.01, -2.5], [0.0, 1.0, -3.0]] {
            assert!((c.value(v3(p)) - lin(p)).abs() < 1e-5);
            let g = c.gradient(v3(p));
            assert!(
                (g[0] - 2.0).abs() < 1e-5 && (g[1] + 3.0).abs() < 1e-5 && (g[2] - 0.5).abs() < 1e-5,
                "{g:?}"
            );
        }
    }
}
