//! Sampling, hit detection and shading, shared by every traversal (so CD
//! and FVT images can only differ if their cell sequences differ).
//!
//! Values inside a cell come from the trilinear interpolant of its 8
//! vertex values, all exact in a 1-cell; gradients are the interpolant's
//! own derivative, never central differences, which would read samples
//! whose words carry distance codes.

use super::traverse::{Ray, Visit};

/// How the ray/iso-surface intersection inside a 1-cell is found (paper
/// section 5.3, Fig. 22).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HitMethod {
    /// Linear interpolation between the two face samples that straddle the
    /// iso value (non-iterative).
    Int,
    /// Bisection on the trilinear interpolant along the ray.
    Bisect,
    /// Newton-Raphson on the trilinear interpolant (continuous derivative
    /// inside the cell), safeguarded by the bracket.
    Newton,
}

/// Iterations of bisection (relative bracket 2^-30) and at most Newton.
pub const BISECT_ITERS: u32 = 30;
pub const NEWTON_ITERS: u32 = 8;

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
    fn local(&self, p: [f64; 3]) -> [f64; 3] {
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
    pub fn value(&self, p: [f64; 3]) -> f64 {
        self.value_local(self.local(p))
    }

    /// Gradient of the trilinear interpolant at `p`, per mm.
    pub fn gradient(&self, p: [f64; 3]) -> [f64; 3] {
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
        [dx / self.size[0], dy / self.size[1], dz / self.size[2]]
    }
}

#[inline]
pub fn at(ray: &Ray, t: f64) -> [f64; 3] {
    std::array::from_fn(|k| ray.origin[k] + t * ray.dir[k])
}

/// The first `t` in `[t_enter, t_exit]` where the interpolant reaches
/// `iso`, judged from the face samples (paper section 5.3): a hit when the
/// entry sample is already >= iso, or the exit sample is.
pub fn find_hit(ray: &Ray, v: &Visit, c: &CellEval, iso: f64, method: HitMethod) -> Option<f64> {
    let g = |t: f64| c.value(at(ray, t)) - iso;
    let (t0, t1) = (v.t_enter, v.t_exit);
    let (g0, g1) = (g(t0), g(t1));
    if g0 >= 0.0 {
        return Some(t0);
    }
    if !(g1 >= 0.0) {
        return None;
    }
    let t_int = t0 + (t1 - t0) * (-g0 / (g1 - g0));
    Some(match method {
        HitMethod::Int => t_int.clamp(t0, t1),
        HitMethod::Bisect => {
            let (mut a, mut b) = (t0, t1);
            for _ in 0..BISECT_ITERS {
                let m = 0.5 * (a + b);
                if g(m) >= 0.0 {
                    b = m;
                } else {
                    a = m;
                }
            }
            0.5 * (a + b)
        }
        HitMethod::Newton => {
            // Newton on g(t), kept inside the shrinking bracket [a, b]
            // (g(a) < 0 <= g(b)); a step that leaves it bisects instead.
            let (mut a, mut b) = (t0, t1);
            let mut t = t_int.clamp(t0, t1);
            for _ in 0..NEWTON_ITERS {
                let gt = g(t);
                if gt.abs() <= 1e-12 * iso.abs().max(1.0) {
                    break;
                }
                if gt > 0.0 {
                    b = t;
                } else {
                    a = t;
                }
                let gr = c.gradient(at(ray, t));
                let dg = gr[0] * ray.dir[0] + gr[1] * ray.dir[1] + gr[2] * ray.dir[2];
                let nt = t - gt / dg;
                t = if nt.is_finite() && nt >= a && nt <= b {
                    nt
                } else {
                    0.5 * (a + b)
                };
                if b - a <= 1e-12 * (t1 - t0) {
                    break;
                }
            }
            t
        }
    })
}

/// Lambert + Phong shading of a hit with the interpolant's gradient.
/// `to_light` and `to_eye` are unit vectors; returns grey in [0, 1].
pub fn shade(normal_grad: [f64; 3], to_light: [f64; 3], to_eye: [f64; 3], lit: bool) -> f64 {
    let len = (normal_grad[0].powi(2) + normal_grad[1].powi(2) + normal_grad[2].powi(2)).sqrt();
    const AMBIENT: f64 = 0.12;
    if !(len > 0.0) {
        return AMBIENT + 0.5;
    }
    // Outward normal: values rise into the object, so it is -grad; face it
    // towards the eye.
    let mut n = normal_grad.map(|g| -g / len);
    if dot(n, to_eye) < 0.0 {
        n = n.map(|x| -x);
    }
    if !lit {
        return AMBIENT;
    }
    let ndl = dot(n, to_light).max(0.0);
    let r = std::array::from_fn::<f64, 3, _>(|k| 2.0 * ndl * n[k] - to_light[k]);
    let spec = if ndl > 0.0 {
        dot(r, to_eye).max(0.0).powi(32)
    } else {
        0.0
    };
    (AMBIENT + 0.75 * ndl + 0.25 * spec).min(1.0)
}

#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    a.map(|x| x / l)
}

pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

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
            assert!((c.value(p) - lin(p)).abs() < 1e-5);
            let g = c.gradient(p);
            assert!(
                (g[0] - 2.0).abs() < 1e-5 && (g[1] + 3.0).abs() < 1e-5 && (g[2] - 0.5).abs() < 1e-5,
                "{g:?}"
            );
        }
    }

    #[test]
    fn hit_methods_agree_on_a_linear_field() {
        // f = x along x in [0, 1]; iso 0.3; ray along +x.
        let coords: [Vec<f64>; 3] = [vec![0.0, 1.0], vec![0.0, 1.0], vec![0.0, 1.0]];
        let f = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], f);
        let ray = Ray {
            origin: [-1.0, 0.5, 0.5],
            dir: [1.0, 0.0, 0.0],
        };
        let v = Visit {
            cell: [0; 3],
            t_enter: 1.0,
            t_exit: 2.0,
        };
        for m in [HitMethod::Int, HitMethod::Bisect, HitMethod::Newton] {
            let t = find_hit(&ray, &v, &c, 0.3, m).unwrap();
            assert!((t - 1.3).abs() < 1e-7, "{m:?}: {t}");
        }
        assert_eq!(find_hit(&ray, &v, &c, 1.5, HitMethod::Int), None);
    }

    #[test]
    fn newton_and_bisect_agree_on_a_nonlinear_field() {
        // A distance-like field: the trilinear interpolant is not linear
        // along the ray, so the three methods differ; Newton and bisection
        // must converge to the same root, including when the linear guess
        // is already the root.
        let coords: [Vec<f64>; 3] = [vec![0.0, 1.0], vec![0.0, 1.0], vec![0.0, 1.5]];
        let fun = |p: [f64; 3]| {
            10.0 - ((p[0] - 3.0).powi(2) + (p[1] + 1.0).powi(2) + (p[2] - 0.2).powi(2)).sqrt()
        };
        let mut f = [0f32; 8];
        for (i, v) in f.iter_mut().enumerate() {
            *v = fun([coords[0][i & 1], coords[1][i >> 1 & 1], coords[2][i >> 2]]) as f32;
        }
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], f);
        let ray = Ray {
            origin: [-1.0, 0.3, 0.4],
            dir: normalize([1.0, 0.1, 0.2]),
        };
        let v = Visit {
            cell: [0; 3],
            t_enter: 1.0 / ray.dir[0],
            t_exit: 2.0 / ray.dir[0],
        };
        for frac in [0.1, 0.5, 0.93] {
            let iso = c.value(at(&ray, (1.0 + frac) / ray.dir[0]));
            let tb = find_hit(&ray, &v, &c, iso, HitMethod::Bisect).unwrap();
            let tn = find_hit(&ray, &v, &c, iso, HitMethod::Newton).unwrap();
            assert!((tb - tn).abs() < 1e-8, "bisect {tb} newton {tn}");
            assert!((c.value(at(&ray, tn)) - iso).abs() < 1e-9);
        }
        // The linear guess is exact on a linear field: Newton must keep it.
        let lin = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let c = CellEval::new([&coords[0], &coords[1], &coords[2]], [0, 0, 0], lin);
        let ray = Ray {
            origin: [-1.0, 0.5, 0.5],
            dir: [1.0, 0.0, 0.0],
        };
        let v = Visit {
            cell: [0; 3],
            t_enter: 1.0,
            t_exit: 2.0,
        };
        assert_eq!(find_hit(&ray, &v, &c, 0.25, HitMethod::Newton), Some(1.25));
    }
}
