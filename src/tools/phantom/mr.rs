//! The T1-weighted-like MR head (module docs of [`phantom`](super)).
//!
//! The anatomy is a handful of smooth shapes, each with an approximate
//! signed distance (mm, positive outside): the head (skin, subcutaneous
//! fat, muscle below the cranium; a smooth union of vault, brow, face,
//! nose, ears and neck), the cervical spine (marrow, canal, cord), the
//! cranium (cortical tables with a diploe between), the subarachnoid
//! CSF, a cortex folded by a low-frequency perturbation of its depth,
//! white matter, deep grey nuclei, ventricles, the interhemispheric
//! fissure, and two eyes in orbital fat. Tissues are painted from the outside in, each over the
//! ones before by the fraction of the sample inside its surface (a linear
//! ramp of the signed distance: partial volume). The signal is then
//! multiplied by a smooth bias field and by `--scale`, and Rician noise
//! (the magnitude of the signal plus complex Gaussian noise) is added, so
//! the air around the head is a Rayleigh-distributed floor, not 0.

use std::path::{Path, PathBuf};

use crate::fsutil::FileSet;
use crate::input::sidecar::{AxisSpec, SidecarOut};
use crate::input::Endian;
use crate::progress::Progress;

// The shared plumbing of mod.rs: errors, the writer, the generator.
use super::*;

/// Sample type of the [`mr`] phantom.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MrDtype {
    /// `u16`, rounded and clamped to `0..=65535`.
    #[default]
    U16,
    /// `i16`, rounded and clamped to `0..=32767`.
    I16,
    /// `f32`, not rounded.
    F32,
}

/// Options of [`mr`].
#[derive(Debug, Clone, PartialEq)]
pub struct MrOptions {
    /// Samples along x, y, z; each at least 2. The field of view is a
    /// 192 mm cube whatever the dims (spacing `192 / n` mm per axis).
    pub dims: [usize; 3],
    pub dtype: MrDtype,
    /// The white matter intensity (positive, finite): every tissue is a
    /// fraction of it (fat above it). Non-round by default, so that
    /// nothing can assume a 0..255 or 0..1024 scale.
    pub scale: f64,
    /// Standard deviation of each component of the complex Gaussian
    /// noise, as a fraction of `scale` (0 ..= 1; 0: no noise).
    pub noise: f64,
    /// Amplitude of the multiplicative bias field (0 ..= 0.5): the signal
    /// is multiplied by `1 - bias ..= 1 + bias` across the head.
    pub bias: f64,
    /// Brain only: every sample outside the brain mask (the cranial cavity
    /// less 1 mm, without the orbits) is exactly 0, as in skull-stripped
    /// files.
    pub skull_stripped: bool,
    /// Seed of the noise.
    pub seed: u64,
}

impl Default for MrOptions {
    fn default() -> Self {
        MrOptions {
            dims: [128, 128, 96],
            dtype: MrDtype::U16,
            scale: 713.0,
            noise: 0.03,
            bias: 0.12,
            skull_stripped: false,
            seed: 1,
        }
    }
}

/// What [`mr`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct MrInfo {
    /// The raw stack (`<stem>.raw`).
    pub raw_path: PathBuf,
    /// Its size in bytes.
    pub bytes: u64,
    /// An iso value for the skin surface (or, skull-stripped, the brain's):
    /// [`MR_SURFACE_ISO`] times the scale.
    pub surface_iso: f64,
}

/// Suggested iso value of the [`mr`] head's outer surface, as a fraction of
/// the scale: above the noise floor (a Rayleigh tail reaches 5 to 6 noise
/// sigmas, 0.15 to 0.18 at the default noise), below skin, fat and CSF.
pub const MR_SURFACE_ISO: f64 = 0.3;

/// Side of the field of view, mm, on every axis.
const FOV_MM: f64 = 192.0;

/// The tissues of the phantom. T1-weighted intensities relative to white
/// matter are [`Tissue::t1`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Tissue {
    Air,
    Skin,
    Fat,
    Muscle,
    Bone,
    Diploe,
    Csf,
    Gm,
    DeepGm,
    Wm,
    Vitreous,
    Marrow,
    Cord,
}

impl Tissue {
    /// T1-weighted signal relative to white matter.
    fn t1(self) -> f64 {
        match self {
            Tissue::Air => 0.0,
            Tissue::Skin => 0.7,
            Tissue::Fat => 1.2,
            Tissue::Muscle => 0.6,
            Tissue::Bone => 0.07,
            Tissue::Diploe => 0.5,
            Tissue::Csf => 0.25,
            Tissue::Gm => 0.68,
            Tissue::DeepGm => 0.8,
            Tissue::Wm => 1.0,
            Tissue::Vitreous => 0.15,
            Tissue::Marrow => 0.75,
            Tissue::Cord => 0.85,
        }
    }
}

/// An axis-aligned ellipsoid with an approximate signed distance: with
/// `q = (p - centre) / semi`, `d = |q| (|q| - 1) / |q / semi|`, exact along
/// the semi-axes and to first order at the surface, monotone along every
/// ray from the centre.
#[derive(Debug, Clone, Copy)]
struct Ellipsoid {
    centre: [f64; 3],
    semi: [f64; 3],
}

impl Ellipsoid {
    fn sdf(&self, p: [f64; 3]) -> f64 {
        let (mut k0, mut k1) = (0.0, 0.0);
        for ((&p, &c), &a) in p.iter().zip(&self.centre).zip(&self.semi) {
            let q = (p - c) / a;
            k0 += q * q;
            k1 += (q / a) * (q / a);
        }
        let (k0, k1) = (k0.sqrt(), k1.sqrt());
        if k1 < 1e-12 {
            return -self.semi.iter().cloned().fold(f64::INFINITY, f64::min);
        }
        k0 * (k0 - 1.0) / k1
    }

    /// The unit direction of `p` from the centre in the ellipsoid's
    /// normalised frame (`[0, 0, 1]` at the centre).
    fn direction(&self, p: [f64; 3]) -> [f64; 3] {
        let q: [f64; 3] = std::array::from_fn(|k| (p[k] - self.centre[k]) / self.semi[k]);
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        if n < 1e-12 {
            [0.0, 0.0, 1.0]
        } else {
            q.map(|c| c / n)
        }
    }
}

/// A sample's noiseless T1 signal (relative to white matter, before the
/// bias field) while tissues are painted over it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Paint {
    /// The signal.
    pub(super) v: f64,
    /// The last tissue painted over the whole sample.
    pub(super) tissue: Tissue,
    /// A tissue was painted over part of the sample since.
    pub(super) mixed: bool,
}

impl Paint {
    /// Paints `t` over the fraction `f` (0 ..= 1) of the sample.
    #[inline]
    fn over(&mut self, t: Tissue, f: f64) {
        if f >= 1.0 {
            *self = Paint {
                v: t.t1(),
                tissue: t,
                mixed: false,
            };
        } else if f > 0.0 {
            self.v += (t.t1() - self.v) * f;
            self.mixed = true;
        }
    }

    /// The tissue when the sample holds one tissue only.
    #[cfg_attr(not(test), allow(dead_code))]
    pub(super) fn pure(&self) -> Option<Tissue> {
        (!self.mixed).then_some(self.tissue)
    }
}

/// The head's shapes, in mm on a grid of the given dims.
pub(super) struct Head {
    /// The outer surface (skin): the smooth union of these parts (the
    /// cranial vault, the brow and cheeks, the face and jaw, the nose, the
    /// ears) and of the neck, a vertical elliptic cylinder ending at
    /// `neck_top`.
    parts: [Ellipsoid; 6],
    neck: Ellipsoid,
    neck_top: f64,
    /// The cervical spine, vertical cylinders ending at `spine_top`: the
    /// vertebral bodies (marrow in a 1.5 mm cortical rim) in front of the
    /// spinal canal (CSF around the cord).
    vertebrae: Ellipsoid,
    canal: Ellipsoid,
    cord: Ellipsoid,
    spine_top: f64,
    /// The cranial cavity (the inner surface of the skull).
    cranium: Ellipsoid,
    ventricles: [Ellipsoid; 3],
    thalami: [Ellipsoid; 2],
    putamina: [Ellipsoid; 2],
    eyes: [Ellipsoid; 2],
    orbits: [Ellipsoid; 2],
    /// Width of the partial-volume ramps, mm.
    ramp: f64,
    /// Highest z of the lateral ventricles (the fissure reaches down to it).
    fissure_floor: f64,
}

/// Thickness of the skull, of the scalp (skin and fat) and of the skin, mm.
const SKULL_MM: f64 = 7.0;
const SCALP_MM: f64 = 5.5;
const SKIN_MM: f64 = 1.5;

/// Width over which the parts of the head's surface blend, mm.
const BLEND_MM: f64 = 12.0;

/// A smooth minimum of two signed distances (a polynomial blend over
/// `k` mm): the union of two shapes with a rounded seam.
#[inline]
fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - 0.25 * h * h * k
}

impl Head {
    /// The head on a grid with `spacing` mm spanning `extent` mm per axis.
    pub(super) fn new(spacing: [f64; 3], extent: [f64; 3]) -> Head {
        let [lx, ly, lz] = extent;
        let (cx, cy) = (0.5 * lx, 0.5 * ly);
        let e = |centre, semi| Ellipsoid { centre, semi };
        // The cranial cavity; the vertex (skull and scalp above it) 8 mm
        // below the top of the field of view.
        let cav = [56.0, 72.0, 62.0];
        let cover = SKULL_MM + SCALP_MM;
        let cz = lz - 8.0 - cav[2] - cover;
        let cranium = e([cx, cy, cz], cav);
        // The vault follows the cavity at the thickness of skull and
        // scalp; the face and jaw below its front, the neck below its
        // back, the nose and ears on the surface.
        let vault = e([cx, cy, cz], cav.map(|a| a + cover));
        let brow = e([cx, cy - 45.0, cz - 25.0], [64.0, 40.0, 40.0]);
        let face = e([cx, cy - 13.0, cz - 50.0], [55.0, 65.0, 50.0]);
        let nose = e([cx, cy - 81.0, cz - 45.0], [9.0, 12.0, 20.0]);
        let ears = [-1.0, 1.0].map(|s| e([cx + s * 68.0, cy + 8.0, cz - 22.0], [6.0, 13.0, 24.0]));
        let neck = e([cx, cy + 15.0, 0.0], [45.0, 50.0, f64::INFINITY]);
        let ventricles = [
            e([cx - 8.0, cy + 2.0, cz + 6.0], [6.0, 24.0, 9.0]),
            e([cx + 8.0, cy + 2.0, cz + 6.0], [6.0, 24.0, 9.0]),
            e([cx, cy + 8.0, cz - 10.0], [1.5, 10.0, 8.0]),
        ];
        let thalami =
            [-1.0, 1.0].map(|s| e([cx + s * 10.0, cy + 10.0, cz - 6.0], [9.0, 13.0, 9.0]));
        let putamina =
            [-1.0, 1.0].map(|s| e([cx + s * 24.0, cy - 4.0, cz - 4.0], [6.0, 16.0, 10.0]));
        let ramp = (spacing[0] * spacing[1] * spacing[2]).cbrt().max(1.0);
        let mut head = Head {
            parts: [vault, brow, face, nose, ears[0], ears[1]],
            neck,
            neck_top: cz - 30.0,
            vertebrae: e([cx, cy + 8.0, 0.0], [13.0, 10.0, f64::INFINITY]),
            canal: e([cx, cy + 28.0, 0.0], [8.0, 7.0, f64::INFINITY]),
            cord: e([cx, cy + 28.0, 0.0], [5.0, 4.0, f64::INFINITY]),
            spine_top: cz - 52.0,
            cranium,
            ventricles,
            thalami,
            putamina,
            eyes: [cranium; 2],
            orbits: [cranium; 2],
            ramp,
            fissure_floor: cz + 15.0,
        };
        // Eyes 31 mm from the midline, 30 mm below the cranium's centre,
        // their fronts 2.5 mm under the skin; the orbital fat behind.
        let (ex, ez) = (cx + 31.0, cz - 30.0);
        let mut skin_y = cy;
        while skin_y > 0.0 && head.skin_sdf([ex, skin_y, ez]) < 0.0 {
            skin_y -= 0.25;
        }
        let eye_r = 11.5;
        let ey = skin_y + 2.5 + eye_r;
        head.eyes = [-1.0, 1.0].map(|s| e([cx + s * 31.0, ey, ez], [eye_r; 3]));
        head.orbits = [-1.0, 1.0].map(|s| e([cx + s * 31.0, ey + 7.0, ez], [16.0, 14.0, 14.0]));
        head
    }

    /// The approximate signed distance to the skin.
    fn skin_sdf(&self, p: [f64; 3]) -> f64 {
        let neck = self.neck.sdf(p).max(p[2] - self.neck_top);
        self.parts
            .iter()
            .fold(neck, |d, e| smin(d, e.sdf(p), BLEND_MM))
    }

    /// The fraction of a sample at signed distance `d` inside the surface.
    #[inline]
    fn inside(&self, d: f64) -> f64 {
        (0.5 - d / self.ramp).clamp(0.0, 1.0)
    }

    /// The cortex's fold at direction `u` from the cranium's centre:
    /// 0 on the crown of a gyrus, 1 at the bottom of a sulcus. Products
    /// of plane waves of about 25 mm wavelength on the brain's surface.
    fn fold(u: [f64; 3]) -> f64 {
        let a = (17.0 * u[0] + 7.0 * u[1] + 1.1).sin() * (15.0 * u[1] - 0.6).cos();
        let b = (14.0 * u[2] + 10.0 * u[1] + 0.3).sin() * (13.0 * u[0] - 6.0 * u[2]).cos();
        let g = (a + 0.8 * b) / 1.8;
        (0.5 * (g + 1.0)).clamp(0.0, 1.0)
    }

    /// The painted signal at `p` (mm) and whether `p` is inside the brain
    /// mask of a skull-stripped volume.
    pub(super) fn paint(&self, p: [f64; 3]) -> (Paint, bool) {
        let mut s = Paint {
            v: 0.0,
            tissue: Tissue::Air,
            mixed: false,
        };
        let d_head = self.skin_sdf(p);
        let reach = self.ramp;
        if d_head >= 0.5 * reach {
            return (s, false);
        }
        s.over(Tissue::Skin, self.inside(d_head));
        s.over(Tissue::Fat, self.inside(d_head + SKIN_MM));
        s.over(Tissue::Muscle, self.inside(d_head + SCALP_MM + 0.5));
        // The skull, thinned where the cranium comes closer than the
        // scalp to the skin: 2.5 mm tables around 2 mm of diploe.
        let d_c = self.cranium.sdf(p);
        let d_skull = (d_c - SKULL_MM).max(d_head + SCALP_MM);
        if d_skull < 0.5 * reach {
            s.over(Tissue::Bone, self.inside(d_skull));
            let d_diploe = ((d_c - 0.5 * SKULL_MM).abs() - 1.0).max(d_skull + 2.5);
            s.over(Tissue::Diploe, self.inside(d_diploe));
        }
        // The spine, ending inside the cranial cavity (the brain covers it).
        let cap = p[2] - self.spine_top;
        if cap < 0.5 * reach {
            let d_vertebrae = self.vertebrae.sdf(p).max(cap);
            s.over(Tissue::Bone, self.inside(d_vertebrae));
            s.over(Tissue::Marrow, self.inside(d_vertebrae + 1.5));
            s.over(Tissue::Csf, self.inside(self.canal.sdf(p).max(cap)));
            s.over(Tissue::Cord, self.inside(self.cord.sdf(p).max(cap)));
        }
        let mut mask = false;
        if d_c < 0.5 * reach {
            s.over(Tissue::Csf, self.inside(d_c));
            let fold = Self::fold(self.cranium.direction(p));
            // Gyri 1.5 mm under the skull, sulci up to 10 mm deep and
            // narrower than the gyri; grey matter 2.5 to 5 mm thick.
            let d_pial = d_c + 1.5 + 8.5 * fold * fold * fold;
            s.over(Tissue::Gm, self.inside(d_pial));
            s.over(Tissue::Wm, self.inside(d_pial + 2.5 + 2.5 * fold));
            for e in self.thalami.iter().chain(&self.putamina) {
                s.over(Tissue::DeepGm, self.inside(e.sdf(p)));
            }
            for e in &self.ventricles {
                s.over(Tissue::Csf, self.inside(e.sdf(p)));
            }
            // The interhemispheric fissure: a 2 mm sheet of CSF on the
            // midline, from the top down to the ventricles, 30 mm deep.
            let d_fissure = ((p[0] - self.cranium.centre[0]).abs() - 1.0)
                .max(self.fissure_floor - p[2])
                .max(-d_c - 30.0)
                .max(d_c);
            s.over(Tissue::Csf, self.inside(d_fissure));
            mask = d_c <= -1.0;
        }
        let d_eyes = self.eyes.map(|e| e.sdf(p));
        let d_orbits = self.orbits.map(|e| e.sdf(p));
        let d_orbit = d_orbits[0].min(d_orbits[1]);
        if d_orbit < 0.5 * reach {
            // Under the skin only.
            s.over(Tissue::Fat, self.inside(d_orbit.max(d_head + SKIN_MM)));
            let d_eye = d_eyes[0].min(d_eyes[1]).max(d_head + SKIN_MM);
            s.over(Tissue::Vitreous, self.inside(d_eye));
        }
        mask &= d_orbit > 0.5 * reach;
        (s, mask)
    }

    /// The multiplicative bias field at `p`: a smooth (linear) field
    /// `1 + bias * (0.55 X - 0.25 Y + 0.35 Z)` of the position relative to
    /// the cranium, `|X|, |Y|, |Z| <= 1` across the head.
    fn bias(&self, p: [f64; 3], bias: f64) -> f64 {
        let c = self.cranium.centre;
        let h = [70.0, 88.0, 100.0];
        let r = |k: usize| ((p[k] - c[k]) / h[k]).clamp(-1.0, 1.0);
        1.0 + bias * (0.55 * r(0) - 0.25 * r(1) + 0.35 * r(2))
    }
}

/// The sample positions (mm) of an axis of `n` samples in the field of
/// view, and their spacing.
fn axis(n: usize) -> (Vec<f64>, f64) {
    let s = FOV_MM / n as f64;
    ((0..n).map(|i| i as f64 * s).collect(), s)
}

/// Two independent standard normal numbers from a 64-bit hash
/// (Box-Muller).
#[inline]
fn gauss2(h: u64) -> (f64, f64) {
    let u1 = ((h >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64);
    let u2 = (mix64(h) >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
    let r = (-2.0 * u1.ln()).sqrt();
    let t = std::f64::consts::TAU * u2;
    (r * t.cos(), r * t.sin())
}

/// Writes a T1-weighted-like MR head phantom: `out_json` (sidecar) and
/// `<stem>.raw`.
///
/// Intensities relative to white matter (`scale`): white matter 1.0, grey
/// matter 0.68, deep grey nuclei (thalami, putamina) 0.8, CSF 0.25
/// (subarachnoid space, sulci, ventricles, fissure), subcutaneous and
/// orbital fat 1.2, skin 0.7, muscle 0.6 (below the cranium), cortical
/// bone 0.07 with a diploe of 0.5, vitreous 0.15, air 0. Boundaries are
/// partial-volume ramps of the signed distance, as wide as the geometric
/// mean of the spacings (at least 1 mm). The signal is multiplied by a
/// linear bias field of `1 +- bias` and by `scale`; then Rician noise of
/// sigma `noise * scale` per component is added (`|S + n1 + i n2|`), so
/// air reads as a Rayleigh floor of mean `sigma * sqrt(pi / 2)`. With
/// `skull_stripped`, samples outside the brain mask are exactly 0.
///
/// The field of view is a 192 mm cube: spacing `192 / n` per axis (1.5,
/// 1.5 and 2 mm at the default 128 x 128 x 96), x left to right, y front
/// (face, eyes at small y) to back, z up (the sidecar records no
/// orientation). The head, about 137 mm wide and 170 mm long without nose
/// and ears, reaches 8 mm under the top; the neck, with the cervical spine
/// (marrow 0.75, cord 0.85), is cut by the bottom of the box.
/// Deterministic for a seed (the anatomy and bias are fixed, the seed
/// drives the noise). Suggested iso for the skin surface:
/// [`MR_SURFACE_ISO`] times the scale ([`MrInfo::surface_iso`]).
pub fn mr(
    out_json: &Path,
    opts: &MrOptions,
    progress: &dyn Progress,
) -> Result<MrInfo, PhantomError> {
    let dims = opts.dims;
    check_dims(dims)?;
    if !(opts.noise.is_finite() && (0.0..=1.0).contains(&opts.noise)) {
        return Err(PhantomError::option(
            "noise",
            format!("{}, expected a fraction in 0 ..= 1", opts.noise),
        ));
    }
    if !(opts.bias.is_finite() && (0.0..=0.5).contains(&opts.bias)) {
        return Err(PhantomError::option(
            "bias",
            format!("{}, expected an amplitude in 0 ..= 0.5", opts.bias),
        ));
    }
    let (sample_bytes, dtype_name, max) = match opts.dtype {
        MrDtype::U16 => (2, "u16", u16::MAX as f64),
        MrDtype::I16 => (2, "i16", i16::MAX as f64),
        MrDtype::F32 => (4, "f32", f32::MAX as f64),
    };
    if !(opts.scale.is_finite() && opts.scale > 0.0) {
        return Err(PhantomError::option(
            "scale",
            format!("{}, expected a positive finite intensity", opts.scale),
        ));
    }
    // The brightest tissue (fat) at the bright end of the bias field, plus
    // eight noise sigmas, must fit the sample type.
    let peak = opts.scale * (Tissue::Fat.t1() * (1.0 + opts.bias) + 8.0 * opts.noise);
    if peak > max {
        return Err(PhantomError::option(
            "scale",
            format!(
                "{}: the brightest samples (about {peak:.0}) would not fit {dtype_name} \
                 (at most {max}); expected at most {:.0}, or f32 samples",
                opts.scale,
                opts.scale * max / peak
            ),
        ));
    }
    check_slice_size("dims", dims, sample_bytes)?;
    let out = Outputs::of(out_json, false)?;
    let [nx, ny, nz] = dims;

    let (xs, sx) = axis(nx);
    let (ys, sy) = axis(ny);
    let (zs, sz) = axis(nz);
    let head = Head::new([sx, sy, sz], [xs[nx - 1], ys[ny - 1], zs[nz - 1]]);
    let seed_key = mix64(opts.seed ^ 0x5EED_3A7D_0000_0002);
    let sigma = opts.noise * opts.scale;
    let (scale, bias, stripped, dtype) = (opts.scale, opts.bias, opts.skull_stripped, opts.dtype);
    let (xs_ref, ys_ref, zs_ref) = (&xs, &ys, &zs);
    let head_ref = &head;

    let fill = |_: &mut (), z: usize, y: usize, row: &mut [u8]| {
        let (py, pz) = (ys_ref[y], zs_ref[z]);
        let row_index = (z as u64 * ny as u64 + y as u64) * nx as u64;
        for (x, out) in row.chunks_exact_mut(sample_bytes).enumerate() {
            let p = [xs_ref[x], py, pz];
            let (paint, mask) = head_ref.paint(p);
            let v = if stripped && !mask {
                0.0
            } else {
                let s = paint.v * scale * head_ref.bias(p, bias);
                let h =
                    mix64(seed_key ^ (row_index + x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                let (n1, n2) = gauss2(h);
                ((s + sigma * n1).powi(2) + (sigma * n2).powi(2)).sqrt()
            };
            match dtype {
                MrDtype::U16 => {
                    out.copy_from_slice(&(v.round().clamp(0.0, max) as u16).to_le_bytes())
                }
                MrDtype::I16 => {
                    out.copy_from_slice(&(v.round().clamp(0.0, max) as i16).to_le_bytes())
                }
                MrDtype::F32 => out.copy_from_slice(&(v as f32).to_le_bytes()),
            }
        }
    };
    let (raw_tmp, bytes) = write_stack(&out, dims, sample_bytes, "phantom mr", progress, fill)?;

    let side = SidecarOut {
        data: out.raw_name.clone(),
        dims,
        dtype: dtype_name,
        endian: Endian::Little,
        header_bytes: 0,
        x: AxisSpec::Uniform(sx),
        y: AxisSpec::Uniform(sy),
        z: AxisSpec::Uniform(sz),
        origin: [0.0; 3],
        rescale: None,
    };
    let side_tmp = write_json(&out.json, &side, "cannot write sidecar")?;
    let mut set = FileSet::new();
    set.add(raw_tmp, &out.raw);
    set.add(side_tmp, &out.json);
    set.commit()?;
    Ok(MrInfo {
        raw_path: out.raw,
        bytes,
        surface_iso: MR_SURFACE_ISO * opts.scale,
    })
}

#[cfg(test)]
mod tests {
    use super::super::tests::read_all;
    use super::*;
    use crate::input::raw::RawSource;
    use crate::input::SliceSource;
    use crate::progress::NoProgress;

    /// Samples of the phantom written with `opts`, and the pure tissue (or
    /// `None` for mixed samples; bone when mostly bone) and brain mask of
    /// each.
    fn generate(opts: &MrOptions) -> (Vec<f64>, Vec<(Option<Tissue>, bool)>) {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("mr.json");
        let info = mr(&side, opts, &NoProgress).unwrap();
        let [nx, ny, nz] = opts.dims;
        let bytes = if opts.dtype == MrDtype::F32 { 4 } else { 2 };
        assert_eq!(info.bytes, (nx * ny * nz * bytes) as u64);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
        let src = RawSource::open(&side).unwrap();
        assert_eq!(src.meta().dims(), opts.dims);
        let all = read_all(&src);
        let (xs, sx) = axis(nx);
        let (ys, sy) = axis(ny);
        let (zs, sz) = axis(nz);
        let head = Head::new([sx, sy, sz], [xs[nx - 1], ys[ny - 1], zs[nz - 1]]);
        let mut labels = Vec::with_capacity(all.len());
        for &z in &zs {
            for &y in &ys {
                for &x in &xs {
                    let (p, mask) = head.paint([x, y, z]);
                    // The skull's tables are thinner than the ramps on
                    // coarse grids: samples darker than 0.1 (bone at most
                    // 30 % mixed with brighter tissue) count as bone.
                    let bone = p.v < 0.1 && p.tissue != Tissue::Air;
                    labels.push((p.pure().or(bone.then_some(Tissue::Bone)), mask));
                }
            }
        }
        (all, labels)
    }

    fn mean_of(all: &[f64], labels: &[(Option<Tissue>, bool)], t: Tissue) -> (f64, usize) {
        let v: Vec<f64> = all
            .iter()
            .zip(labels)
            .filter(|(_, l)| l.0 == Some(t))
            .map(|(&v, _)| v)
            .collect();
        (v.iter().sum::<f64>() / v.len().max(1) as f64, v.len())
    }

    /// Prints the mean of every tissue's samples.
    fn print_means(all: &[f64], labels: &[(Option<Tissue>, bool)], scale: f64) {
        use Tissue::*;
        for t in [
            Air, Skin, Fat, Muscle, Bone, Diploe, Csf, Gm, DeepGm, Wm, Vitreous, Marrow, Cord,
        ] {
            let (mean, n) = mean_of(all, labels, t);
            if n == 0 {
                continue;
            }
            let f = mean / scale;
            println!("{t:?}: mean {mean:.1} ({f:.3} of the scale), {n} samples");
        }
    }

    #[test]
    fn tissues_have_t1_contrast_and_air_a_rayleigh_floor() {
        let opts = MrOptions::default();
        let (all, labels) = generate(&opts);
        let m = |t| mean_of(&all, &labels, t);
        let scale = opts.scale;
        print_means(&all, &labels, scale);
        let [(wm, _), (gm, _), (csf, _), (fat, _), (bone, _), (air, n_air)] = [
            Tissue::Wm,
            Tissue::Gm,
            Tissue::Csf,
            Tissue::Fat,
            Tissue::Bone,
            Tissue::Air,
        ]
        .map(|t| {
            let (mean, n) = m(t);
            assert!(n > 100, "{n} {t:?} samples");
            (mean, n)
        });
        assert!((wm / scale - 1.0).abs() < 0.05, "wm {wm}");
        assert!(
            fat > wm && wm > gm && gm > csf && csf > bone,
            "{fat} {wm} {gm} {csf} {bone}"
        );
        assert!((gm / scale - 0.68).abs() < 0.06, "gm {gm}");
        assert!((csf / scale - 0.25).abs() < 0.05, "csf {csf}");
        // Rician noise of a zero signal: Rayleigh, mean sigma sqrt(pi / 2).
        let sigma = opts.noise * scale;
        let want = sigma * (std::f64::consts::PI / 2.0).sqrt();
        assert!(n_air > 100_000, "{n_air} air samples");
        assert!((air / want - 1.0).abs() < 0.02, "air {air}, want {want}");
        let var = all
            .iter()
            .zip(&labels)
            .filter(|(_, l)| l.0 == Some(Tissue::Air))
            .map(|(&v, _)| (v - air) * (v - air))
            .sum::<f64>()
            / n_air as f64;
        // Rayleigh variance (2 - pi / 2) sigma^2, plus 1/12 of rounding.
        let want_var = (2.0 - std::f64::consts::FRAC_PI_2) * sigma * sigma + 1.0 / 12.0;
        assert!((var / want_var - 1.0).abs() < 0.05, "{var} {want_var}");
        assert!(all.iter().all(|&v| v >= 0.0 && v < 1.6 * scale));
    }

    #[test]
    fn deterministic_for_a_seed_and_proportional_to_the_scale() {
        let opts = MrOptions {
            dims: [40, 36, 30],
            ..MrOptions::default()
        };
        let (a, _) = generate(&opts);
        let (b, _) = generate(&opts);
        assert_eq!(a, b);
        let (c, _) = generate(&MrOptions {
            seed: 2,
            ..opts.clone()
        });
        assert_ne!(a, c);
        // Without rounding, twice the scale is twice every sample.
        let f = MrOptions {
            dtype: MrDtype::F32,
            ..opts.clone()
        };
        let (one, _) = generate(&f);
        let (two, _) = generate(&MrOptions {
            scale: 2.0 * f.scale,
            ..f.clone()
        });
        for (x, y) in one.iter().zip(&two) {
            assert!((2.0 * x - y).abs() <= 1e-3 * y.abs().max(1.0), "{x} {y}");
        }
        // i16 holds the same rounded values as u16.
        let (i, _) = generate(&MrOptions {
            dtype: MrDtype::I16,
            ..opts
        });
        assert_eq!(i, a);
    }

    #[test]
    fn skull_stripped_is_exactly_zero_outside_the_brain() {
        let opts = MrOptions {
            skull_stripped: true,
            ..MrOptions::default()
        };
        let (all, labels) = generate(&opts);
        print_means(&all, &labels, opts.scale);
        let (mut inside, mut outside) = (0, 0);
        for (&v, &(t, mask)) in all.iter().zip(&labels) {
            if mask {
                inside += 1;
                assert!(v > 0.0, "{v} in the brain");
            } else {
                outside += 1;
                assert_eq!(v, 0.0, "{t:?}");
            }
            if matches!(
                t,
                Some(Tissue::Fat | Tissue::Bone | Tissue::Skin | Tissue::Air)
            ) {
                assert!(!mask, "{t:?} in the mask");
            }
        }
        assert!(inside > 10_000 && outside > inside, "{inside} {outside}");
        // The brain is kept whole: white matter is still about the scale.
        let (wm, _) = mean_of(&all, &labels, Tissue::Wm);
        assert!((wm / opts.scale - 1.0).abs() < 0.05, "wm {wm}");
    }

    #[test]
    fn bad_options_name_the_option() {
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("bad.json");
        let small = MrOptions {
            dims: [4, 4, 4],
            ..MrOptions::default()
        };
        type Set = fn(&mut MrOptions);
        let cases: [(Set, &str); 9] = [
            (|o| o.dims = [1, 4, 4], "option dims"),
            (|o| o.dims = [1 << 20, 1 << 20, 2], "option dims"),
            (|o| o.scale = 0.0, "option scale"),
            (|o| o.scale = f64::NAN, "option scale"),
            (|o| o.scale = 50000.0, "option scale"),
            (
                |o| (o.scale, o.dtype) = (30000.0, MrDtype::I16),
                "option scale",
            ),
            (|o| o.noise = -0.1, "option noise"),
            (|o| o.noise = f64::INFINITY, "option noise"),
            (|o| o.bias = 0.6, "option bias"),
        ];
        for (set, want) in cases {
            let mut opts = small.clone();
            set(&mut opts);
            let e = mr(&side, &opts, &NoProgress).unwrap_err().to_string();
            assert!(e.contains(want), "{opts:?}: {e}");
        }
        // A large scale fits f32.
        let f = MrOptions {
            scale: 30000.0,
            dtype: MrDtype::F32,
            ..small
        };
        mr(&side, &f, &NoProgress).unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}
