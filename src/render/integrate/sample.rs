//! What a composite sample is made of beside the transfer function: the
//! f32 sampler's cell interpolant ([`Trilinear32`]) and the look of a
//! ray ([`Look`]: gradient opacity and headlight shading).

use glam::{Vec3, Vec3A, Vec4};

use crate::render::options::CompositeLook;
use crate::render::sample::normals::Normals;
use crate::render::traverse::Ray;

/// A cell's trilinear interpolant in f32 at local coordinates: the vertex
/// values and their differences along x, taken once per cell.
pub(super) struct Trilinear32 {
    /// `f0, f1 - f0, f2, f3 - f2, f4, f5 - f4, f6, f7 - f6`.
    pub f: [f32; 8],
}

impl Trilinear32 {
    #[inline(always)]
    pub fn new(f: [f32; 8]) -> Trilinear32 {
        Trilinear32 {
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

    #[inline(always)]
    pub fn value(&self, u: Vec3) -> f32 {
        let f = &self.f;
        let x00 = f[0] + u.x * f[1];
        let x10 = f[2] + u.x * f[3];
        let x01 = f[4] + u.x * f[5];
        let x11 = f[6] + u.x * f[7];
        let y0 = x00 + u.y * (x10 - x00);
        let y1 = x01 + u.y * (x11 - x01);
        y0 + u.z * (y1 - y0)
    }

    /// The interpolant's derivative by the local coordinates (times the
    /// inverse cell sizes it is the gradient per mm).
    #[inline(always)]
    pub fn gradient(&self, u: Vec3) -> Vec3 {
        let f = &self.f;
        let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
        // Vertex values back from the differences.
        let v = [
            f[0],
            f[0] + f[1],
            f[2],
            f[2] + f[3],
            f[4],
            f[4] + f[5],
            f[6],
            f[6] + f[7],
        ];
        Vec3::new(
            lerp(lerp(f[1], f[3], u.y), lerp(f[5], f[7], u.y), u.z),
            lerp(
                lerp(v[2] - v[0], v[3] - v[1], u.x),
                lerp(v[6] - v[4], v[7] - v[5], u.x),
                u.z,
            ),
            lerp(
                lerp(v[4] - v[0], v[5] - v[1], u.x),
                lerp(v[6] - v[2], v[7] - v[3], u.x),
                u.y,
            ),
        )
    }
}

/// [`CompositeLook`] for one ray: the headlight and whether anything
/// beyond the transfer function applies.
pub(super) struct Look<'a> {
    pub look: &'a CompositeLook,
    /// Shading or gradient opacity is on.
    pub on: bool,
    /// Gradients from the smooth normals (else the cell interpolant's).
    pub smooth: bool,
    pub to_eye: Vec3A,
}

impl<'a> Look<'a> {
    pub fn new(look: &'a CompositeLook, normals: Normals, ray: &Ray) -> Look<'a> {
        Look {
            look,
            on: look.shade || !look.gradient_opacity.is_empty(),
            smooth: normals == Normals::Smooth,
            to_eye: Vec3A::from((-ray.dir).as_vec3()),
        }
    }

    /// Whether the batches can take this look's samples: shading and
    /// gradient opacity by smooth normals ([`batch::run`](super::batch::run) weights and
    /// lights them as [`Look::apply`] does).
    pub fn batches(&self) -> bool {
        self.on && self.smooth
    }

    /// Sample `s` (premultiplied colour, opacity) with gradient `g` (per
    /// mm): opacity and colour scaled by the gradient opacity, the colour
    /// lit by the surface mode's headlight model
    /// ([`shade`](crate::render::sample::shade::shade): ambient 0.12, diffuse
    /// 0.75, white specular 0.25 with exponent 32, two-sided). Lane by
    /// lane, as four scalar expressions would round. Always inlined: as
    /// a call it cost the shaded composite 7 % when the unshaded marcher
    /// grew (docs/DECISIONS.md, "`Look::apply` left to the compiler's
    /// inlining").
    #[inline(always)]
    pub fn apply(&self, s: Vec4, g: Vec3A) -> Vec4 {
        let len = g.length();
        let mut s = s;
        if !self.look.gradient_opacity.is_empty() {
            let k = self.look.gradient_factor(len as f64) as f32;
            s *= k;
        }
        if !self.look.shade {
            return s;
        }
        self.lit(s, g, len)
    }

    /// The shading of [`Look::apply`] alone: premultiplied sample `s` lit
    /// through gradient `g` of length `len` (the segment integrator
    /// scales the extinction, not the opacity, by the gradient opacity).
    #[inline(always)]
    pub fn lit(&self, s: Vec4, g: Vec3A, len: f32) -> Vec4 {
        const AMBIENT: f32 = 0.12;
        let (diffuse, spec) = if len > 0.0 {
            // The light is at the eye: n.l = |g.e| / |g| for the normal
            // facing the eye, and r.e = 2 (n.l)^2 - 1.
            let ndl = (g.dot(self.to_eye).abs() / len).min(1.0);
            let re = (2.0 * ndl * ndl - 1.0).max(0.0);
            (ndl, re.powi(32))
        } else {
            // No gradient: as the surface mode's flat fallback.
            (0.5, 0.0)
        };
        let k = AMBIENT + 0.75 * diffuse;
        let sp = 0.25 * spec * s.w;
        (s * k + Vec4::splat(sp)).with_w(s.w)
    }
}
